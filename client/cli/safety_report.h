// `swarf run`'s safety checks and process facts (issue 30), gathered from
// the session's acknowledgements as the batches are applied: the server's
// events (rapid cuts, shank and holder contacts, plunges), each move's
// removed volume, and the checks on the tip itself (--floor, --limits),
// named by file and line.
#ifndef SWARF_CLIENT_SAFETY_REPORT_H_
#define SWARF_CLIENT_SAFETY_REPORT_H_

#include <array>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/cli/args.h"
#include "core/safety.h"
#include "gcode/toolpath.h"
#include "swarf/v1/swarf.pb.h"

namespace swarf::cli {
namespace pb = ::swarf::v1;
}  // namespace swarf::cli

namespace swarf::cli {

// The valued flags (documented in `swarf run`'s usage) and the boolean one.
inline constexpr const char* kSafetyFlags[] = {"floor", "limits", "rapid-rate"};
inline constexpr const char* kCheckFlag = "check";

struct SafetyOptions {
  std::optional<double> floor;                // --floor Z
  std::optional<std::array<double, 6>> limits;  // x0, y0, z0, x1, y1, z1
  double rapid_rate = 5000;                   // mm/min
};
// InvalidArgument naming the flag.
absl::StatusOr<SafetyOptions> ParseSafetyFlags(const Args& args);

struct SafetyItem {
  int32_t file = 0, line = 0;
  int64_t move_id = 0;
  double x = 0, y = 0, z = 0, depth = 0, volume_mm3 = 0;
};

class SafetyCollector {
 public:
  // `path`'s points (read by the constructor and OnAck only: the path may
  // go once the last batch is acknowledged); `file_starts` the first point
  // of each file (as run_command numbers them); `assemblies` by tool
  // number.
  SafetyCollector(const gcode::Toolpath& path,
                  const std::vector<int64_t>& file_starts,
                  std::vector<std::string> files,
                  std::map<int, ToolAssembly> assemblies,
                  const SafetyOptions& options);

  // Each acknowledged batch (first_move_id: the session's id of its first
  // move), in order.
  void OnAck(const pb::Ack& ack, int64_t first_move_id);

  // Kinds of findings, stats.json's names.
  static constexpr int kKinds = 6;
  static constexpr const char* kKindNames[kKinds] = {
      "rapid_cuts",     "shank_contacts", "holder_contacts",
      "center_plunges", "below_floor",    "outside_limits"};
  int64_t total() const;
  // One warning line per kind found (the first item and the count), and the
  // note on tools without an assembly.
  std::vector<std::string> Warnings() const;
  // stats.json's "safety" and "process" objects.
  std::string SafetyJson() const;
  std::string ProcessJson() const;
  // load.png: the removal rate (mm^3/min) against program time, the tool
  // changes marked and labelled. FailedPrecondition when the program's
  // time is not known (no feeds).
  absl::Status WriteLoadPng(const std::string& path) const;

  // Kept per kind (the count goes on).
  static constexpr size_t kMaxItems = 1000;

  // For the live viewer: with Follow(true), the findings and the air moves
  // (feed moves that removed nothing, as tip segments) since the last
  // TakeNew (at most kMaxItems findings a kind and kMaxAirSegments air
  // segments in all).
  static constexpr size_t kMaxAirSegments = 200000;
  struct NewFindings {
    std::vector<std::pair<int, SafetyItem>> items;  // kind, item
    std::vector<std::pair<Vec3, Vec3>> air;
  };
  void Follow(bool on) { follow_ = on; }
  NewFindings TakeNew();
  const std::vector<std::string>& files() const { return files_; }

 private:
  using LineKey = std::pair<int32_t, int32_t>;  // (file, line)
  struct Amount {
    double volume = 0, seconds = 0, mm = 0;
  };
  // The ten largest lines by an amount, kept as the moves come (largest
  // first; ties by file and line).
  struct TopLines {
    double Amount::*by;
    std::vector<std::pair<LineKey, Amount>> best;
    void Offer(const LineKey& key, const Amount& a);
  };
  // A line's amounts while its moves come one after another: a line the
  // program never comes back to is complete when the next line starts.
  struct Group {
    LineKey key{-1, -1};
    Amount line, air;
    bool has_line = false, has_air = false;
  };

  void Add(int kind, const SafetyItem& item);
  SafetyItem At(int64_t move_id) const;
  // The point that move `move_id` (< move_count_) ends at.
  int64_t PointOf(int64_t move_id) const;
  // The length (mm) of the move ending at `point`, and its duration at its
  // programmed feed (rapids and F0 at the rapid rate; 0 where the feed is
  // not known).
  double Length(int64_t point) const;
  double Seconds(int64_t point, double length) const;
  bool Repeated(const LineKey& key) const;
  // Hands a complete group's amounts to the top lists.
  static void Flush(const Group& g, TopLines* lines, TopLines* air);

  const gcode::Toolpath& path_;
  int64_t move_count_ = 0;
  // R[i] - i of the i-th point that starts a run (R[i]): move id m ends at
  // point m + (how many of these are <= m). No table of every move's point.
  std::vector<int64_t> run_starts_;
  std::vector<int64_t> file_starts_;
  std::vector<std::string> files_;
  std::map<int, ToolAssembly> assemblies_;
  SafetyOptions options_;
  std::array<std::vector<SafetyItem>, kKinds> items_;
  std::array<int64_t, kKinds> counts_{};
  // Process facts.
  double removed_ = 0, rapid_mm_ = 0, feed_mm_ = 0, air_mm_ = 0;
  double rapid_s_ = 0, cutting_s_ = 0, air_s_ = 0, unknown_feed_mm_ = 0;
  int64_t air_moves_ = 0, cutting_moves_ = 0, f0_moves_ = 0;
  std::map<int, Amount> by_tool_;
  // Lines the program comes back to (loops, subroutines, repeats), per
  // file, a byte a line number: 0 not met, 1 met once, 2 met again. Their
  // amounts are summed in maps; every other line's in groups.
  std::vector<std::vector<uint8_t>> line_seen_;
  std::map<LineKey, Amount> by_line_;  // repeated lines only
  std::map<LineKey, Amount> air_by_line_;
  Group group_;
  TopLines top_lines_{&Amount::volume, {}}, top_air_{&Amount::mm, {}};
  // load.png, drawn as the moves come: the removed volume per column of
  // equal program time (the program's time is known from the path).
  static constexpr int kLoadW = 1000, kLoadLeft = 70, kLoadRight = 20;
  static constexpr int kLoadPlotW = kLoadW - kLoadLeft - kLoadRight;
  double load_total_ = 0;  // seconds, every move's
  double load_t_ = 0;      // seconds before the next move
  int64_t load_moves_ = 0;
  int load_tool_ = 0;
  std::vector<double> load_vol_;
  std::vector<std::pair<double, int>> load_changes_;  // time, new tool
  bool follow_ = false;
  NewFindings new_;
  size_t air_taken_ = 0;  // air segments handed out so far
};

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_SAFETY_REPORT_H_
