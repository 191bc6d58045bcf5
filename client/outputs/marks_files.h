// Cutting marks as files: marks.json (the schema of `swarf marks --json`)
// and marks.svg (the polylines in mm over the stock outline).
#ifndef SWARF_CLIENT_MARKS_FILES_H_
#define SWARF_CLIENT_MARKS_FILES_H_

#include <cstddef>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "core/cutting_marks.h"
#include "core/stock.h"

namespace swarf::cli {

// Which marks the files show. Seams between facets of one smooth surface
// meet at a fraction of a degree; rims and real creases at more.
struct MarkDisplayFilter {
  double min_angle_deg = 1;  // vertices below it are dropped...
  double min_length = 0.2;   // mm; ...and pieces shorter than this
};
inline constexpr MarkDisplayFilter kDefaultMarkDisplay;

// The parts of `marks` to display: each polyline is cut into its runs of
// consecutive vertices at min_angle_deg or more (a closed polyline with
// every vertex there stays closed; a run may wrap past its first vertex);
// runs of at least two vertices and min_length (3D length) are kept, with
// their owners, angles and vertex owners. Rims on the stock top (owner -1)
// are kept whatever their angle.
// Takes `marks` by value: a caller that moves them in holds them once
// (each polyline is freed once filtered).
std::vector<MarkPolyline> FilterMarks(std::vector<MarkPolyline> marks,
                                      const MarkDisplayFilter& filter);

// FilterMarks of one polyline: its pieces appended to *out, in the order
// FilterMarks gives them (FilterMarks is this over each polyline in turn).
void FilterMark(MarkPolyline mark, const MarkDisplayFilter& filter,
                std::vector<MarkPolyline>* out);

// Compact JSON, without a trailing newline:
// {"polylines":[{"closed":false,"owners":[a,b],"vertices":[[x,y,z],...],
// "angle_deg":[...]}]}, owner -1 for the stock top; with vertex_owners also
// "vertex_owners":[[a,b],...] per polyline. Doubles in shortest round-trip
// form (JsonWriter).
std::string MarksJson(const std::vector<MarkPolyline>& marks,
                      bool vertex_owners = false);

// MarksJson(marks) and a newline, as `swarf marks --json` prints it.
absl::Status WriteMarksJson(const std::vector<MarkPolyline>& marks,
                            const std::string& path);

class FileWriter;

// WriteMarksJson a batch of polylines at a time: after Append of batches
// whose concatenation is `marks`, then Finish, the file holds the bytes
// WriteMarksJson(marks, path) writes. Memory: the text of one batch (formatted
// in chunks on ThreadPool::Default()). Not thread-safe. An unfinished file
// (or one whose write failed) is removed; errors name the path and are
// sticky.
class MarksJsonWriter {
 public:
  explicit MarksJsonWriter(std::string path);
  ~MarksJsonWriter();
  MarksJsonWriter(const MarksJsonWriter&) = delete;
  MarksJsonWriter& operator=(const MarksJsonWriter&) = delete;

  absl::Status Append(std::span<const MarkPolyline> batch);
  absl::Status Finish();
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::unique_ptr<FileWriter> file_;
  size_t count_ = 0;
};

// SVG 1.1 in mm: viewBox the stock rectangle with y up (a scale(1,-1) group,
// so path coordinates are the marks' x and y), the stock outline as a
// <rect>, and one <path> per polyline (closed ones end in Z) stroked with
// AngleColor of its mean angle, carrying data-owners and data-angle-deg
// (mean) attributes and a <title>.
std::string MarksSvg(const StockSpec& stock,
                     const std::vector<MarkPolyline>& marks);
absl::Status WriteMarksSvg(const StockSpec& stock,
                           const std::vector<MarkPolyline>& marks,
                           const std::string& path);

// WriteMarksSvg a batch of polylines at a time, byte for byte (as
// MarksJsonWriter). The head counts the polylines, so the paths go to
// `path` + ".body" first; Finish writes the head then copies them after it
// and removes that file. Neither file stays when unfinished or failed.
class MarksSvgWriter {
 public:
  MarksSvgWriter(const StockSpec& stock, std::string path);
  ~MarksSvgWriter();
  MarksSvgWriter(const MarksSvgWriter&) = delete;
  MarksSvgWriter& operator=(const MarksSvgWriter&) = delete;

  absl::Status Append(std::span<const MarkPolyline> batch);
  absl::Status Finish();
  const std::string& path() const { return path_; }
  std::string body_path() const { return path_ + ".body"; }

 private:
  StockSpec stock_;
  std::string path_;
  std::unique_ptr<FileWriter> body_;
  size_t count_ = 0;
};

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_MARKS_FILES_H_
