#include "server/program.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"

namespace swarf::server {
namespace {

namespace pb = ::swarf::v1;

absl::Status PointOption(const pb::Point3& p, const char* field, bool* known,
                         double out[3]) {
  const double v[3] = {p.x(), p.y(), p.z()};
  for (int a = 0; a < 3; ++a) {
    if (!(std::fabs(v[a]) <= 1e9)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "program.options.", field, " must be finite machine mm within "
          "+-1e9, got (", v[0], ", ", v[1], ", ", v[2], ")"));
    }
  }
  *known = true;
  std::copy(v, v + 3, out);
  return absl::OkStatus();
}

const ToolSpec* FindTool(const SessionSpec& spec, int32_t id) {
  for (const ToolSpec& t : spec.tools) {
    if (t.id == id) return &t;
  }
  return nullptr;
}

}  // namespace

absl::StatusOr<InterpretedProgram> InterpretProgram(
    std::string_view text, const pb::ProgramOptions& options,
    const SessionSpec& spec, int64_t max_batch_points, int64_t max_points) {
  InterpretedProgram out;
  out.name = options.name().empty() ? "program" : options.name();
  gcode::GcodeOptions o;
  o.max_points = max_points;
  switch (options.dialect()) {
    case pb::DIALECT_UNSPECIFIED:
    case pb::DIALECT_LINUXCNC:
      o.dialect = gcode::Dialect::kLinuxCnc;
      break;
    case pb::DIALECT_FANUC:
      o.dialect = gcode::Dialect::kFanuc;
      break;
    case pb::DIALECT_GRBL:
      o.dialect = gcode::Dialect::kGrbl;
      break;
    default:
      return absl::InvalidArgumentError(absl::StrCat(
          "program.options.dialect ", options.dialect(),
          " is not a Dialect (1 linuxcnc, 2 fanuc, 3 grbl)"));
  }
  o.arc_tolerance = spec.arc_tolerance;
  if (options.has_arc_tolerance()) {
    o.arc_tolerance = options.arc_tolerance().value();
    if (!(o.arc_tolerance >= kMinArcTolerance &&
          o.arc_tolerance <= kMaxArcTolerance)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "program.options.arc_tolerance must be in [", kMinArcTolerance,
          ", ", kMaxArcTolerance, "] mm, got ", o.arc_tolerance));
    }
  }
  if (options.has_start()) {
    if (absl::Status s =
            PointOption(options.start(), "start", &o.start_known, o.start);
        !s.ok()) {
      return s;
    }
  }
  if (options.has_home()) {
    if (absl::Status s =
            PointOption(options.home(), "home", &o.home_known, o.home);
        !s.ok()) {
      return s;
    }
  }
  if (options.has_tool_change_position()) {
    if (absl::Status s = PointOption(options.tool_change_position(),
                                     "tool_change_position",
                                     &o.tool_change_position_known,
                                     o.tool_change_position);
        !s.ok()) {
      return s;
    }
  }
  o.m6_forgets_position = options.m6_forgets_position();
  if (options.max_blocks() < 0) {
    return absl::InvalidArgumentError(absl::StrCat(
        "program.options.max_blocks must be >= 0 (0: the default), got ",
        options.max_blocks()));
  }
  if (options.max_blocks() > 0) o.max_blocks = options.max_blocks();
  const int64_t batch_points = options.batch_points() == 0
                                   ? kDefaultProgramBatchPoints
                                   : options.batch_points();
  if (batch_points < 2 || batch_points > max_batch_points) {
    return absl::InvalidArgumentError(absl::StrCat(
        "program.options.batch_points must be in [2, ", max_batch_points,
        "] (the server's --max_batch_points; 0: ", kDefaultProgramBatchPoints,
        "), got ", batch_points));
  }
  for (const auto& [t, id] : options.tools()) {
    if (FindTool(spec, id) == nullptr) {
      return absl::InvalidArgumentError(
          absl::StrCat("program.options.tools[", t, "] = ", id,
                       " is not a tool of session ", spec.id));
    }
  }
  // T numbers to session tools: the map, the tool of that id, or the
  // session's only tool.
  auto tool_of = [&](int t) -> const ToolSpec* {
    auto it = options.tools().find(t);
    if (it != options.tools().end()) return FindTool(spec, it->second);
    if (const ToolSpec* same = FindTool(spec, t)) return same;
    return spec.tools.size() == 1 ? &spec.tools[0] : nullptr;
  };
  // Cutter compensation needs the radius of the tool it names.
  o.tool_radius = [&](int t) -> std::optional<double> {
    const ToolSpec* tool = tool_of(t);
    if (tool == nullptr) return std::nullopt;
    return tool->cutter.radius;
  };
  auto path = gcode::ParseGcode(text, o);
  if (!path.ok()) {
    return absl::Status(path.status().code(),
                        absl::StrCat(out.name, ": ", path.status().message()));
  }
  out.path = *std::move(path);
  const gcode::Toolpath& p = out.path;
  std::map<int, int32_t> ids;
  for (const int t : p.Tools()) {
    const ToolSpec* tool = tool_of(t);
    if (tool == nullptr) {
      int32_t line = 0;
      for (const gcode::ToolpathPoint& q : p.points()) {
        if (q.tool == t) {
          line = q.line;
          break;
        }
      }
      std::vector<int32_t> have;
      for (const ToolSpec& s : spec.tools) have.push_back(s.id);
      return absl::InvalidArgumentError(absl::StrCat(
          out.name, ": line ", p.ToolSelectedAt(t).value_or(line), ": T", t,
          " has no tool in session ", spec.id, " (its tools: ",
          absl::StrJoin(have, ", "), "): map it in program.options.tools"));
    }
    ids[t] = tool->id;
  }
  // What `swarf run` prints before it simulates (client/cli/toolpath_flags.cc).
  for (const std::string& note : p.notes()) {
    out.warnings.push_back(absl::StrCat(out.name, ": note: ", note));
  }
  if (!p.IgnoredSummary().empty()) {
    out.warnings.push_back(absl::StrCat(out.name, ": ", p.IgnoredSummary()));
  }
  const std::string dropped = p.DroppedSummary();
  if (!dropped.empty()) {
    if (options.strict()) {
      return absl::InvalidArgumentError(
          absl::StrCat(out.name, ": ", dropped, " (strict)"));
    }
    out.warnings.push_back(absl::StrCat(out.name, ": warning: ", dropped));
  }
  const StockSpec& s = spec.stock;
  const gcode::Excursion e =
      gcode::FarthestOutside(p, s.x0, s.y0, s.x1, s.y1, s.z_top);
  if (e.index >= 0) {
    const gcode::ToolpathPoint& q = p.points()[e.index];
    out.warnings.push_back(absl::StrFormat(
        "%s: warning: the cut leaves the stock by up to %.4g mm (line %d, at "
        "X%.4f Y%.4f Z%.4f): the cut outside the stock is not simulated",
        out.name, e.distance, q.line, q.position.x, q.position.y,
        q.position.z));
  }
  // The batches as the CLI's StreamPath cuts its runs.
  bool started = false;
  for (const gcode::ToolpathRun& run :
       gcode::SplitRuns(p, [&](int t) { return ids.at(t); })) {
    for (int64_t k = run.begin; k < run.end; k += batch_points) {
      ProgramBatch b;
      b.begin = k;
      b.end = std::min(run.end, k + batch_points);
      b.tool_id = run.tool_id;
      b.rapid = run.rapid;
      b.reposition = run.reposition && k == run.begin;
      // The very first point, and a repositioning one, only place the tool.
      b.moves = (b.end - b.begin) - (started && !b.reposition ? 0 : 1);
      started = true;
      out.moves += b.moves;
      out.batches.push_back(b);
    }
  }
  return out;
}

}  // namespace swarf::server
