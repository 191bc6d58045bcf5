// `swarf moves FILE`: the interpreted moves of a program as the simulator
// receives them, one a line (the interpreter's canonical commands, printed
// by a CanonSink): for debugging programs and for piping to other tools
// (scripts/linuxcnc-diff compares them with LinuxCNC's rs274).
#include <cinttypes>
#include <cstdio>
#include <iostream>
#include <set>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli/args.h"
#include "client/cli/commands.h"
#include "client/cli/tool_table.h"
#include "client/cli/toolpath_flags.h"
#include "gcode/canon.h"
#include "gcode/toolpath.h"

namespace swarf::cli {
namespace {

constexpr char kUsage[] =
    "usage: swarf moves FILE [--tool SPEC]... [--tools FILE] [--chords T] "
    "[--json]\n"
    "Prints the moves of a program (tool tip, machine mm), one a line:\n"
    "  FILE LINE KIND X Y Z [CX CY CZ AXIS TURNS]\n"
    "KIND: start (the position becomes known; no move reaches it), rapid,\n"
    "feed, arc (centre CX CY CZ, about AXIS X/Y/Z, TURNS: the signed number\n"
    "of turns begun, + counterclockwise seen from +AXIS, as LinuxCNC's\n"
    "rotation), tool (a tool change: X is the tool number, no position).\n"
    "  --tool, --tools, --tools-units  the tools (for G41/G42 radii)\n"
    "  --chords T                   arcs as feed chords within T mm\n"
    "  --json                       one JSON document, a move per line\n"
    "  --arc-tolerance T            (with --chords: the same as T)\n";

constexpr const char* kAxes = "XYZ";

class Printer final : public gcode::CanonSink {
 public:
  Printer(std::string file, bool json) : file_(std::move(file)), json_(json) {
    if (json_) std::printf("{\"moves\": [\n");
  }
  void Finish() {
    if (json_) std::printf("\n]}\n");
  }

  absl::Status Straight(const gcode::CanonStraight& m) override {
    Row(m.line, m.starts_run ? "start" : m.rapid ? "rapid" : "feed", m.end);
    End();
    return absl::OkStatus();
  }
  absl::Status ArcFeed(const gcode::CanonArc& a) override {
    Row(a.line, "arc", a.end);
    const Vec3 c = a.Centre();
    if (json_) {
      std::printf(", \"centre\": [%.6f, %.6f, %.6f], \"axis\": \"%c\", "
                  "\"turns\": %" PRId64,
                  c.x, c.y, c.z, kAxes[a.p2], a.Turns());
    } else {
      std::printf(" %.6f %.6f %.6f %c %" PRId64, c.x, c.y, c.z, kAxes[a.p2],
                  a.Turns());
    }
    End();
    return absl::OkStatus();
  }
  void ToolChange(int32_t line, int tool) override {
    Begin(line, "tool");
    if (json_) {
      std::printf(", \"tool\": %d", tool);
    } else {
      std::printf(" %d", tool);
    }
    End();
  }
  // Points of a parsed toolpath (--chords, XYZ files).
  void Point(const gcode::ToolpathPoint& p) {
    Row(p.line, p.starts_run ? "start" : p.rapid ? "rapid" : "feed",
        p.position);
    End();
  }

 private:
  void Begin(int32_t line, const char* kind) {
    if (json_) {
      std::printf("%s{\"file\": \"%s\", \"line\": %d, \"kind\": \"%s\"",
                  first_ ? "" : ",\n", JsonEscape(file_).c_str(), line, kind);
    } else {
      std::printf("%s %d %s", file_.c_str(), line, kind);
    }
    first_ = false;
  }
  void Row(int32_t line, const char* kind, const Vec3& p) {
    Begin(line, kind);
    if (json_) {
      std::printf(", \"end\": [%.6f, %.6f, %.6f]", p.x, p.y, p.z);
    } else {
      std::printf(" %.6f %.6f %.6f", p.x, p.y, p.z);
    }
  }
  void End() { std::printf(json_ ? "}" : "\n"); }
  static std::string JsonEscape(const std::string& s) {
    std::string out;
    for (const char c : s) {
      if (c == '"' || c == '\\') {
        out += '\\';
        out += c;
      } else if (static_cast<unsigned char>(c) < 0x20) {
        out += absl::StrFormat("\\u%04x", c);
      } else {
        out += c;
      }
    }
    return out;
  }

  std::string file_;
  bool json_;
  bool first_ = true;
};

}  // namespace

int MovesCommand(const std::vector<std::string>& argv) {
  std::set<std::string> valued = {"tool", "tools", "tools-units", "chords",
                                  "arc-tolerance"};
  valued.insert(std::begin(kToolpathFlags), std::end(kToolpathFlags));
  auto args = Args::Parse(argv, valued,
                          {"json", "help", kStrictFlag, kM6ForgetsFlag});
  auto fail = [](const absl::Status& s, int code) {
    std::cerr << "swarf moves: " << s.message() << "\n";
    return code;
  };
  if (!args.ok()) {
    std::cerr << "swarf moves: " << args.status().message() << "\n"
              << kUsage << kToolpathUsage;
    return 2;
  }
  if (args->Has("help")) {
    std::cout << kUsage << kToolpathUsage;
    return 0;
  }
  if (args->positional().size() != 1) {
    std::cerr << "swarf moves: give one toolpath FILE\n" << kUsage;
    return 2;
  }
  const std::string file = args->positional()[0];
  auto table = ReadToolsFlags(*args);
  if (!table.ok()) return fail(table.status(), 2);
  auto choices = ParseToolChoices(args->All("tool"), *std::move(table));
  if (!choices.ok()) return fail(choices.status(), 2);
  ToolpathFlags tflags;
  if (absl::Status st = ReadToolpathFlags(*args, &tflags); !st.ok()) {
    return fail(st, 2);
  }
  gcode::GcodeOptions& gopt = tflags.options;
  gopt.tool_radius = [&c = *choices](int t) -> std::optional<double> {
    const std::optional<Cutter> cutter = KnownTool(c, t);
    if (!cutter.has_value()) return std::nullopt;
    return cutter->radius;
  };
  std::optional<std::string> chords = args->Get("chords");
  if (!chords.has_value()) chords = args->Get("arc-tolerance");
  if (chords.has_value()) {
    if (!absl::SimpleAtod(*chords, &gopt.arc_tolerance) ||
        !(gopt.arc_tolerance > 0)) {
      return fail(absl::InvalidArgumentError(
                      "--chords must be a number > 0 (mm)"),
                  2);
    }
  }
  Printer printer(file, args->Has("json"));
  // Without --chords the canonical commands are printed as they come (an
  // XYZ file has no commands: its points are printed).
  const bool canon = !chords.has_value() &&
                     tflags.format != gcode::ToolpathFormat::kXyz;
  absl::StatusOr<gcode::Toolpath> path = gcode::ReadToolpathFile(
      file, gopt, tflags.format, canon ? &printer : nullptr);
  if (path.ok()) {
    for (const gcode::ToolpathPoint& p : path->points()) printer.Point(p);
  }
  printer.Finish();
  std::fflush(stdout);
  if (!path.ok()) return fail(path.status(), 1);
  for (const std::string& n : path->notes()) {
    std::cerr << "swarf moves: note: " << n << "\n";
  }
  if (path->dropped_moves() > 0) {
    std::cerr << "swarf moves: " << path->DroppedSummary() << "\n";
    if (tflags.strict) return 1;
  }
  return 0;
}

}  // namespace swarf::cli
