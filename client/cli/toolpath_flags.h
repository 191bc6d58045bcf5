// The `swarf run` flags that configure the G-code interpreter, and the
// checks of a parsed toolpath that must never stay silent (dropped moves,
// a cut that leaves the stock).
#ifndef SWARF_CLIENT_TOOLPATH_FLAGS_H_
#define SWARF_CLIENT_TOOLPATH_FLAGS_H_

#include <optional>
#include <string>

#include "absl/status/status.h"
#include "client/cli/args.h"
#include "client/cli/run_report.h"
#include "client/cli/tool_table.h"
#include "core/stock.h"
#include "gcode/toolpath.h"

namespace swarf::cli {

// Valued flags: --format --dialect --home --max-blocks --start
// --tool-change-position (--arc-tolerance is run_command's); the boolean
// ones: --strict, --m6-forgets-position.
inline constexpr const char* kToolpathFlags[] = {
    "format", "dialect", "home", "max-blocks", "start", "tool-change-position"};
inline constexpr char kStrictFlag[] = "strict";
inline constexpr char kM6ForgetsFlag[] = "m6-forgets-position";
inline constexpr char kToolpathUsage[] =
    "  --format gcode|xyz           the file's format (default: by content)\n"
    "  --dialect linuxcnc|fanuc|grbl  G-code dialect (default linuxcnc;\n"
    "                               fanuc: M98/M99; grbl: '$' lines ignored)\n"
    "  --home X,Y,Z                 the G28/G30 position (machine mm);\n"
    "                               default unknown\n"
    "  --max-blocks N               stop after N executed blocks (default\n"
    "                               200M: an endless loop is an error)\n"
    "  --start X,Y,Z                where the machine starts (machine mm);\n"
    "                               default unknown (G91 first is an error)\n"
    "  --tool-change-position X,Y,Z  M6 rapids there first (machine mm)\n"
    "  --m6-forgets-position        M6 makes the position unknown (swarf's\n"
    "                               old behaviour; default: it stays)\n"
    "  --strict                     dropped moves are an error\n";

struct ToolpathFlags {
  gcode::GcodeOptions options;
  std::optional<gcode::ToolpathFormat> format;
  bool strict = false;
};

// Reads the flags above into `flags` (options keep what they hold for
// flags not given). InvalidArgument naming the flag.
absl::Status ReadToolpathFlags(const Args& args, ToolpathFlags* flags);

// --tools FILE with --tools-units mm|inch (swarf run, swarf moves): the
// table, nullopt without --tools. InvalidArgument naming the flag, or the
// table's own error.
absl::StatusOr<std::optional<ToolTable>> ReadToolsFlags(const Args& args);

// The never-silent checks after parsing: dropped moves (an error under
// --strict), and, against an explicit stock, a cut leaving the stock's XY
// rectangle. Fills the report's fields; warnings go to `warn` (one line
// each, without the "swarf run: " prefix).
absl::Status CheckToolpath(const gcode::Toolpath& path, bool strict,
                           const StockSpec* explicit_stock, RunReport* report,
                           std::vector<std::string>* warn);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_TOOLPATH_FLAGS_H_
