#include "client/cli/toolpath_flags.h"

#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"

namespace swarf::cli {

absl::Status ReadToolpathFlags(const Args& args, ToolpathFlags* flags) {
  if (auto f = args.Get("format")) {
    if (*f == "gcode") {
      flags->format = gcode::ToolpathFormat::kGcode;
    } else if (*f == "xyz") {
      flags->format = gcode::ToolpathFormat::kXyz;
    } else {
      return absl::InvalidArgumentError("--format must be gcode or xyz");
    }
  }
  if (auto d = args.Get("dialect")) {
    if (*d == "linuxcnc") {
      flags->options.dialect = gcode::Dialect::kLinuxCnc;
    } else if (*d == "fanuc") {
      flags->options.dialect = gcode::Dialect::kFanuc;
    } else if (*d == "grbl") {
      flags->options.dialect = gcode::Dialect::kGrbl;
    } else {
      return absl::InvalidArgumentError(
          "--dialect must be linuxcnc, fanuc or grbl");
    }
  }
  // X,Y,Z in machine mm.
  const auto point = [&args](const char* name, bool* known,
                             double out[3]) -> absl::Status {
    auto h = args.Get(name);
    if (!h.has_value()) return absl::OkStatus();
    std::vector<std::string> f = absl::StrSplit(*h, ',');
    double v[3];
    if (f.size() != 3 || !absl::SimpleAtod(f[0], &v[0]) ||
        !absl::SimpleAtod(f[1], &v[1]) || !absl::SimpleAtod(f[2], &v[2]) ||
        !(std::fabs(v[0]) <= 1e9 && std::fabs(v[1]) <= 1e9 &&
          std::fabs(v[2]) <= 1e9)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "--", name, " must be X,Y,Z (three numbers, machine mm)"));
    }
    *known = true;
    for (int a = 0; a < 3; ++a) out[a] = v[a];
    return absl::OkStatus();
  };
  gcode::GcodeOptions& o = flags->options;
  if (absl::Status s = point("home", &o.home_known, o.home); !s.ok()) return s;
  if (absl::Status s = point("start", &o.start_known, o.start); !s.ok()) {
    return s;
  }
  if (absl::Status s = point("tool-change-position",
                             &o.tool_change_position_known,
                             o.tool_change_position);
      !s.ok()) {
    return s;
  }
  if (args.Has(kM6ForgetsFlag)) o.m6_forgets_position = true;
  if (auto m = args.Get("max-blocks")) {
    int64_t n;
    if (!absl::SimpleAtoi(*m, &n) || n < 1) {
      return absl::InvalidArgumentError("--max-blocks must be an integer >= 1");
    }
    flags->options.max_blocks = n;
  }
  flags->strict = args.Has(kStrictFlag);
  return absl::OkStatus();
}

absl::Status CheckToolpath(const gcode::Toolpath& path, bool strict,
                           const StockSpec* explicit_stock, RunReport* report,
                           std::vector<std::string>* warn) {
  report->dropped_moves = path.dropped_moves();
  report->dropped = path.DroppedSummary();
  if (!report->dropped.empty()) {
    if (strict) {
      return absl::InvalidArgumentError(
          absl::StrCat(report->dropped, " (--strict)"));
    }
    warn->push_back(absl::StrCat("warning: ", report->dropped));
  }
  if (explicit_stock != nullptr) {
    const StockSpec& s = *explicit_stock;
    const gcode::Excursion e =
        gcode::FarthestOutside(path, s.x0, s.y0, s.x1, s.y1, s.z_top);
    if (e.index >= 0) {
      const gcode::ToolpathPoint& p = path.points()[e.index];
      report->outside_mm = e.distance;
      report->outside_line = p.line;
      report->outside_stock = absl::StrFormat(
          "the cut leaves the stock by up to %.4g mm (line %d, at X%.4f "
          "Y%.4f Z%.4f): the cut outside the stock is not simulated",
          e.distance, p.line, p.position.x, p.position.y, p.position.z);
      warn->push_back("warning: " + report->outside_stock);
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::optional<ToolTable>> ReadToolsFlags(const Args& args) {
  const auto t = args.Get("tools");
  if (!t) return std::optional<ToolTable>();
  const std::string units = args.Get("tools-units").value_or("mm");
  if (units != "mm" && units != "inch") {
    return absl::InvalidArgumentError("--tools-units must be mm or inch");
  }
  auto read = ReadToolTableFile(*t, units == "inch" ? 25.4 : 1);
  if (!read.ok()) return read.status();
  return std::optional<ToolTable>(*std::move(read));
}

}  // namespace swarf::cli
