// Fuzz target: the toolpath parsers (ParseGcode, the RS274/NGC interpreter,
// and ParseXyz) on arbitrary
// bytes. They must never crash, hang or hit undefined behaviour; an error
// is InvalidArgument "line N: ..."; a parsed toolpath keeps its invariants
// (finite points within the coordinate bound, counts consistent, bounds
// cover the points).

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "absl/strings/match.h"
#include "gcode/toolpath.h"
#include "tests/fuzz/fuzz_check.h"

namespace swarf::gcode {
namespace {

// Small, so that one input stays fast (32 bytes per point).
constexpr int64_t kMaxPoints = 1 << 16;
// The parsers' coordinate bound (kMaxCoordinate in core/workpiece.h).
constexpr double kMaxCoordinate = 1e9;

bool Within(const Interval& b, double v) { return b.lo <= v && v <= b.hi; }

void CheckToolpath(const Toolpath& tp, bool xyz) {
  const auto& pts = tp.points();
  FUZZ_CHECK(tp.point_count() <= kMaxPoints);
  FUZZ_CHECK(tp.move_count() == tp.point_count() - tp.run_count());
  FUZZ_CHECK(tp.move_count() >= 0);
  FUZZ_CHECK(tp.x_bounds().empty() == pts.empty());
  FUZZ_CHECK(tp.source_lines() >= 0);
  int64_t runs = 0;
  for (size_t k = 0; k < pts.size(); ++k) {
    const ToolpathPoint& p = pts[k];
    const Vec3& v = p.position;
    FUZZ_CHECK(IsFinite(v));
    FUZZ_CHECK(std::fabs(v.x) <= kMaxCoordinate &&
               std::fabs(v.y) <= kMaxCoordinate &&
               std::fabs(v.z) <= kMaxCoordinate);
    FUZZ_CHECK(Within(tp.x_bounds(), v.x) && Within(tp.y_bounds(), v.y) &&
               Within(tp.z_bounds(), v.z));
    // Points come from lines that were read (loops and calls go back).
    FUZZ_CHECK(p.line >= 1 && p.line <= tp.source_lines());
    if (k == 0) FUZZ_CHECK(p.starts_run);
    if (p.starts_run) ++runs;
    // No zero-length move: a repeated position within a run adds no point.
    if (k > 0 && !p.starts_run) {
      const Vec3& u = pts[k - 1].position;
      FUZZ_CHECK(u.x != v.x || u.y != v.y || u.z != v.z);
    }
    if (xyz) FUZZ_CHECK(p.tool == 0 && !p.rapid);
  }
  FUZZ_CHECK(runs == tp.run_count());
  if (xyz) FUZZ_CHECK(tp.run_count() <= 1);
  (void)tp.IgnoredSummary();
  (void)tp.Tools();
}

void CheckError(const absl::Status& s) {
  FUZZ_CHECK(s.code() == absl::StatusCode::kInvalidArgument);
  FUZZ_CHECK(absl::StartsWith(s.message(), "line "));
}

}  // namespace
}  // namespace swarf::gcode

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace swarf::gcode;
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  GcodeOptions options;
  options.max_points = kMaxPoints;
  // Endless loops and recursion stop here, quickly.
  options.max_blocks = 1 << 12;
  options.max_call_depth = 20;
  auto gcode = ParseGcode(text, options);
  if (gcode.ok()) {
    CheckToolpath(*gcode, /*xyz=*/false);
  } else {
    CheckError(gcode.status());
  }
  if (size % 2 == 1) {
    // A known start (--start) and a tool-change position (issue 27).
    GcodeOptions known = options;
    known.start_known = true;
    known.start[2] = 10;
    known.tool_change_position_known = true;
    known.tool_change_position[2] = 50;
    auto k = ParseGcode(text, known);
    if (k.ok()) {
      CheckToolpath(*k, /*xyz=*/false);
    } else {
      CheckError(k.status());
    }
  }
  auto xyz = ParseXyz(text, kMaxPoints);
  if (xyz.ok()) {
    CheckToolpath(*xyz, /*xyz=*/true);
  } else {
    CheckError(xyz.status());
  }
  (void)DetectToolpathFormat(text);
  // The bytes as a file name: only the extension matters.
  auto format = ToolpathFormatForPath(text);
  FUZZ_CHECK(format.ok() ||
             format.status().code() == absl::StatusCode::kInvalidArgument);
  return 0;
}
