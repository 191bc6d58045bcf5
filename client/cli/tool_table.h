// Tools as users give them: the `--tool` option, LinuxCNC tool tables
// (.tbl), CAMotics projects (.camotics), and the choice of a cutter for every
// tool number a program uses. Pure functions on text: no files are read here
// except by ReadToolTableFile / ReadCamoticsProject; no gRPC.
//
// Units: millimetres (inch tables are converted); angles in degrees. Users
// give diameters and INCLUDED angles, as tools are sold; the Cutter holds
// radii and half angles (core/cutter/cutter.h).
//
// Errors are InvalidArgument naming where: the option and its bad key
// (`--tool "vbit:d=6,angle=190": angle must be ...`), the table's file and
// line, the project's file and tool.
#ifndef SWARF_CLIENT_TOOL_TABLE_H_
#define SWARF_CLIENT_TOOL_TABLE_H_

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "core/cutter/cutter.h"
#include "core/safety.h"

namespace swarf::cli {

// One `--tool` value: "[T]N=SHAPE:KEY=V,..." or "SHAPE:KEY=V,...":
//   ball:d=D | ball:r=R        ball end
//   flat:d=D                   flat end
//   bull:d=D,r=RC              bull nose, corner radius RC (<= D/2)
//   vbit:d=D,angle=A[,tip=T]   V-bit / cone: included angle A in (0, 180),
//                              flat tip of diameter T (default 0, sharp)
//   taper:d=D,tip=T,angle=A    tapered ball: ball tip of diameter T,
//                              included taper angle A in (0, 180)
// and for every shape the tool's non-cutting parts (all optional, mm):
//   flute=L      flute length from the tip (the shank rubs above it)
//   shank=D      shank diameter (default: the cutter's)
//   holder=D     holder diameter, with
//   stickout=S   the stick-out from the holder's face down to the tip
//   center=0     the tool does not cut at its centre (no plunging)
// `number` is set when the value carries a tool number.
struct ToolOption {
  std::optional<int> number;
  Cutter cutter;
  ToolAssembly assembly;
};
absl::StatusOr<ToolOption> ParseToolOption(absl::string_view value);

// The cutter of SHAPE with KEY=VALUE pairs (strings as the user wrote
// them), as above. `where` prefixes every error, e.g. `--tool "..."` or
// "tools.tbl line 3". Keys are checked in the user's terms (diameters,
// included angles), then the cutter with ValidateCutter.
absl::StatusOr<Cutter> CutterFromKeys(
    absl::string_view shape,
    const std::vector<std::pair<std::string, std::string>>& keys,
    absl::string_view where);

// A tool of a table. `cutter` is an error (naming the tool) when the table
// describes a tool swarf cannot simulate (a CAMotics "spheroid", a LinuxCNC
// tool without a diameter): only using it is an error.
struct TableTool {
  absl::StatusOr<Cutter> cutter = Cutter{};
  ToolAssembly assembly;  // the comment's flute=... keys; CAMotics' length
  std::string source;  // "FILE line N" or "FILE tool \"N\""
};
struct ToolTable {
  std::string file;  // where it was read from
  std::map<int, TableTool> tools;
};

// A LinuxCNC tool table: lines "T1 P1 Z0.5 D6.0 ;comment" (T, P, the
// offsets X Y Z A B C U V W, D the diameter, lathe I J Q; blank and ';'
// lines skipped). The shape comes from the comment: its first word that
// names a shape (ball, ballnose, flat, endmill, bull, bullnose, vbit, v-bit,
// cone, taper, tapered) with the keys of `--tool` after it (d comes from D;
// a bare number after vbit/cone is its included angle: "vbit 90"). A
// comment naming no shape: a flat end mill, as LinuxCNC and CAMotics take an
// unknown tool. `inch_scale`: 25.4 for a table in inches, else 1.
// InvalidArgument naming FILE line N for a malformed line or a tool number
// given twice.
absl::StatusOr<ToolTable> ParseLinuxCncToolTable(absl::string_view text,
                                                 const std::string& file,
                                                 double inch_scale = 1);

// A CAMotics project (JSON). Its tools ({"1": {"shape", "diameter",
// "length", "snub_diameter", "units"}}; CAMotics' defaults where a key is
// missing: cylindrical, metric, diameter 2 mm, length 10 mm): cylindrical
// = flat, ballnose = ball, conical = a cone spanning its radius over its
// length (half angle atan(radius / length)), snubnose = a cone from the
// diameter down to a flat tip of snub_diameter over its length. Imperial
// tools are in inches. The workpiece's bounds (mm, as CAMotics stores them)
// are the stock when "automatic" is false (CAMotics then ignores the
// margin); when true the stock is found from the toolpath and grown by
// "margin" percent of its size on every side. `files` are absolute (made
// so from the project's directory), in order.
struct CamoticsProject {
  ToolTable tools;
  bool automatic = true;
  double margin_percent = 0;
  bool has_bounds = false;
  double min[3] = {0, 0, 0};
  double max[3] = {0, 0, 0};
  std::vector<std::string> files;
};
absl::StatusOr<CamoticsProject> ParseCamoticsProject(absl::string_view text,
                                                     const std::string& file);

// Reads and parses a project file. NotFound when it can't be read.
absl::StatusOr<CamoticsProject> ReadCamoticsProject(const std::string& file);
// Reads a tool table: a CAMotics project's tools when FILE ends in
// .camotics or its text starts with '{', else a LinuxCNC table (with
// `inch_scale`). NotFound when it can't be read.
absl::StatusOr<ToolTable> ReadToolTableFile(const std::string& file,
                                            double inch_scale = 1);

// Where a program first uses a tool number, for errors: "prog.nc line 12".
struct ToolUse {
  int number = 0;  // 0: no tool selected (no T word before)
  std::string where;
};

// The tools of a run: the --tool options, and the table of --tools or
// --project (if any).
struct ToolChoices {
  std::vector<ToolOption> options;
  std::optional<ToolTable> table;
};
absl::StatusOr<ToolChoices> ParseToolChoices(
    const std::vector<std::string>& tool_options,
    std::optional<ToolTable> table);

// The cutter for each tool number a program uses:
//  1. `--tool N=...` for N;
//  2. N = 0 (the program selects no tool): the unnumbered --tool, else the
//     table's only tool;
//  3. N > 0: the table's T N; without a table, the unnumbered --tool.
// Else InvalidArgument naming the use ("prog.nc line 12: T7 is not in the
// tool table tools.tbl (T1, T2)"), or the table's error for a tool it can't
// simulate.
absl::StatusOr<std::map<int, Cutter>> ChooseTools(
    const ToolChoices& choices, const std::vector<ToolUse>& uses);

// The cutter of tool number `n` if it is known before the program runs
// (for cutter compensation, G41/G42): rules 1-3 without errors.
std::optional<Cutter> KnownTool(const ToolChoices& choices, int n);

// Takes the assembly keys (flute, shank, holder, stickout, center) out of
// `keys` into `out`. InvalidArgument prefixed with `where` for a value that
// is not a positive number (center: 0 or 1), a key given twice, or a
// holder without a stick-out (or the reverse).
absl::Status TakeAssemblyKeys(
    std::vector<std::pair<std::string, std::string>>* keys, ToolAssembly* out,
    absl::string_view where);

// The assembly of tool number `n` (ChooseTools' rules 1-3); none known: a
// default ToolAssembly (no checks).
ToolAssembly KnownAssembly(const ToolChoices& choices, int n);

// "flute=15 holder=40 stickout=30", "" for an unknown assembly.
std::string AssemblySummary(const ToolAssembly& a);

// "ball d=6", "vbit d=6 angle=90 tip=0.2": a cutter in the user's terms.
std::string CutterSummary(const Cutter& c);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_TOOL_TABLE_H_
