// The RS274/NGC interpreter's internals, shared by its parts (not an API:
// ParseGcode in toolpath.h is). The interpreter is one class, Interpreter,
// whose methods are defined in five files, split the way LinuxCNC's rs274ngc
// is:
// - interpreter.cc: the loop (Run: lines, blocks, the program's end), errors
//   naming the line, the counts of ignored words, ParseGcode;
// - interp_read.cc: reading a line into a Block (words, numbers,
//   expressions, O-word lines) and the parameters (#n, #<name>, system);
// - interp_control.cc: O-word control flow (if, loops, sub, call, return,
//   Fanuc M98/M99) and external subroutine files;
// - interp_modal.cc: executing a block: modal settings (G-code groups,
//   units, planes, distance modes, offsets, G10/G28/G30/G92), M-codes, tool
//   changes, and the dispatch to motion;
// - interp_motion.cc: motion: end points (offsets, units, polar), lines,
//   arcs, canned cycles, and the canonical commands to the sink;
// - interp_comp.cc: cutter radius compensation (G40/G41/G42).
//
// Reading: the program text is read line by line, in place; control flow
// moves a cursor (file, byte offset, line number). Forward jumps (a false
// if, a sub definition, break) skip lines until the matching O-word, as
// LinuxCNC does; backward jumps (loops, calls) go to cursors recorded when
// the opening line ran. Lines without '#', '[' or O-words take the same
// scanning path as before the interpreter existed (numbers read in place).
//
// Coordinates: the interpreter keeps the tip's machine position (mm); a
// programmed position P maps to P * units + work offset (G54..G59.3) +
// G92/G52 offset (+ the G43.1 length offset on Z). Offsets default to zero,
// so a program that never sets one gets its own coordinates as output.
#ifndef SWARF_GCODE_INTERPRETER_H_
#define SWARF_GCODE_INTERPRETER_H_

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <string>
#include <deque>
#include <unordered_map>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/status_macros.h"
#include "gcode/expression.h"
#include "gcode/text.h"
#include "gcode/toolpath.h"

namespace swarf::gcode::interp {

constexpr double kPi = std::numbers::pi;
constexpr double kMmPerInch = 25.4;
// Same bound as kMaxCoordinate in workpiece.h, so every point is a valid
// move end there.
constexpr double kMaxCoordinateMm = 1e9;

// Arc checks, after LinuxCNC (rs274ngc interp_internal.hh), in mm:
// - a radius below RADIUS_TOLERANCE_MM is a zero-radius arc, and an R arc
//   may fall short of half the chord by at most that much;
constexpr double kRadiusTolerance = 0.00127;
// - start and end radius of an I/J arc may differ by at most 0.1 % of the
//   radius, and never more than CENTER_ARC_RADIUS_TOLERANCE_MM. Unlike
//   LinuxCNC, differences up to 0.005 mm are always accepted: rounding of
//   3-decimal mm or 4-decimal inch output reaches ~0.0036 mm on small arcs.
//   An accepted difference is followed as a spiral (radius linear in angle),
//   as LinuxCNC does.
constexpr double kSpiralAbsMax = 0.02 * std::numbers::sqrt2;
constexpr double kSpiralAbsFloor = 0.005;
constexpr double kSpiralRel = 0.001;
// G73/G83: the rapid stops this far above the previous peck (LinuxCNC's
// G83_RAPID_DELTA, 0.010 inch).
constexpr double kPeckClearanceMm = 0.254;
// Cutter compensation: a concave corner sharper than this (radians, about
// the sine of the angle) whose offset moves don't meet is taken as
// tangent (rounded coordinates); LinuxCNC takes concave corners up to
// 0.05 rad as convex.
constexpr double kNearlyTangent = 1e-3;

constexpr uint32_t Bit(char letter) { return uint32_t{1} << (letter - 'A'); }
constexpr uint32_t kAxisWords = Bit('X') | Bit('Y') | Bit('Z');
constexpr uint32_t kArcWords = Bit('I') | Bit('J') | Bit('K') | Bit('R');
// Polar coordinates: '@' (radius) and '^' (angle, degrees) after the letters.
constexpr int kRadiusWord = 26;
constexpr int kAngleWord = 27;
constexpr uint32_t kPolarWords = (uint32_t{1} << kRadiusWord) |
                                 (uint32_t{1} << kAngleWord);
// Words that never move the tool unless a code uses them: feed, speed,
// length and radius offset numbers, cycle parameters, repeat counts, dwell.
constexpr uint32_t kIgnoredLetters = Bit('F') | Bit('S') | Bit('H') |
                                     Bit('D') | Bit('Q') | Bit('L') | Bit('P');
constexpr char kAxisName[3] = {'X', 'Y', 'Z'};

// G-codes are kept as integers x10 (G90.1 -> 901).
constexpr int32_t kGCodeLimit = 10000;
constexpr int32_t kMCodeCounted = 1000;  // larger M codes: counted in a map
constexpr int kMaxCodesPerLine = 32;
constexpr int kParameterCount = 5603;  // #1..#5602
constexpr size_t kMaxNamedParameters = 100'000;
constexpr size_t kMaxControlDepth = 1000;
constexpr size_t kMaxFiles = 64;

// System parameters (LinuxCNC numbering); values in mm.
constexpr int kG28Home = 5161;
constexpr int kG30Home = 5181;
constexpr int kG92On = 5210;
constexpr int kG92 = 5211;
constexpr int kCoordSystem = 5220;  // 1..9: G54..G59.3
constexpr int kCoordBase = 5201;    // + 20 * system
constexpr int kToolNumber = 5400;
constexpr int kToolLength = 5403;  // G43.1/G43.2 Z offset
constexpr int kPosition = 5420;    // 5420..5422, read only: program position

enum class OKind : uint8_t {
  kProgramNumber, kSub, kEndsub, kCall, kDo, kWhile, kEndwhile, kIf,
  kElseif, kElse, kEndif, kRepeat, kEndrepeat, kReturn, kBreak, kContinue
};
constexpr uint32_t KBit(OKind k) { return uint32_t{1} << static_cast<int>(k); }

inline const char* OName(OKind k) {
  static constexpr const char* kNames[] = {
      "",      "sub",    "endsub", "call",  "do",     "while",
      "endwhile", "if",  "elseif", "else",  "endif",  "repeat",
      "endrepeat", "return", "break", "continue"};
  return kNames[static_cast<int>(k)];
}

// The first word of a line after '/' and an N word: where an O-word is.
inline const char* Prelude(const char* p, const char* end) {
  p = SkipBlanks(p, end);
  if (p < end && *p == '/') p = SkipBlanks(p + 1, end);
  if (p < end && (*p == 'N' || *p == 'n')) {
    const char* q = SkipBlanks(p + 1, end);
    if (q < end && IsDigit(*q)) {
      while (q < end && (IsDigit(*q) || *q == '.')) ++q;
      p = SkipBlanks(q, end);
    }
  }
  return p;
}

// "o<name> keyword" / "o123 keyword" at p (p at the 'O'), without its
// expressions. *rest: after the keyword.
inline absl::Status ReadOWord(const char* p, const char* end, std::string* label,
                       OKind* kind, const char** rest) {
  p = SkipBlanks(p + 1, end);
  label->clear();
  if (p < end && *p == '<') {
    ++p;
    label->push_back('<');
    while (p < end && *p != '>') {
      if (!IsBlank(*p)) label->push_back(Lower(*p));
      ++p;
      if (label->size() > 256) break;
    }
    if (p >= end || *p != '>' || label->size() == 1) {
      return absl::InvalidArgumentError("O-word: bad name (o<name>)");
    }
    ++p;
  } else {
    const char* q = p;
    while (q < end && IsDigit(*q)) ++q;
    if (q == p) {
      return absl::InvalidArgumentError(
          "O-word needs a number or a <name>");
    }
    while (p < q - 1 && *p == '0') ++p;  // o010 is o10
    label->assign(p, q);
    p = q;
    if (label->size() > 12) {
      return absl::InvalidArgumentError("O-word number is too long");
    }
  }
  p = SkipBlanks(p, end);
  std::string w;
  while (p < end && ((*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z'))) {
    if (w.size() < 12) w += Lower(*p);
    ++p;
  }
  *rest = p;
  if (w.empty()) {
    if ((*label)[0] == '<') {
      return absl::InvalidArgumentError("O-word without a keyword");
    }
    *kind = OKind::kProgramNumber;
    return absl::OkStatus();
  }
  for (int k = 1; k <= static_cast<int>(OKind::kContinue); ++k) {
    if (w == OName(static_cast<OKind>(k))) {
      *kind = static_cast<OKind>(k);
      return absl::OkStatus();
    }
  }
  return absl::InvalidArgumentError(absl::StrCat("unknown O-word keyword '",
                                                 w, "'"));
}

inline std::string OLabel(const std::string& label) {
  return label[0] == '<' ? absl::StrCat("o", label, ">")
                         : absl::StrCat("o", label);
}

// The words of one line.
struct Block {
  // Bit(letter) of each word other than G, M, N, O; bits kRadiusWord and
  // kAngleWord for '@' and '^'.
  uint32_t words = 0;
  double value[28];
  int ng = 0;
  int32_t g[kMaxCodesPerLine];  // x10
  int nm = 0;
  int32_t m[kMaxCodesPerLine];
  bool block_delete = false;
  // An O-word line.
  bool has_o = false;
  OKind o_kind = OKind::kProgramNumber;
  std::string o_label;
  bool o_has_value = false;
  double o_value = 0;
  std::vector<double> o_args;
  // Parameter settings, applied after the line is read.
  struct Setting {
    ParamRef ref;
    double value;
  };
  std::vector<Setting> settings;

  bool empty() const {
    return words == 0 && ng == 0 && nm == 0 && !has_o && settings.empty();
  }
};

// Why a G-code we don't simulate is refused.
inline std::string UnsupportedG(int32_t c) {
  const std::string g = GName(c);
  // clang-format off
  switch (c) {
    case 410: case 411: case 420: case 421:
      return g + " (cutter radius compensation) is not simulated: give the "
                 "tool-centre path (compensation done by the CAM system)";
    case 760:
      return g + " (threading cycle) is a lathe cycle: not for 3-axis mills";
    case 50: case 51: case 52: case 53:
      return g + " (spline) is not supported";
    case 330: case 331:
      return g + " (spindle-synchronized motion) is not supported";
    case 382: case 383: case 384: case 385:
      return g + " (probing) is not supported: the probe's stop position "
                 "depends on the part";
    case 510: case 511:
      return g + " (scaling or mirroring) is not supported";
    case 680:
      return g + " (coordinate rotation) is not supported";
    case 160:
      return g + " (polar coordinates) is not supported";
    case 70:
      return g + " (lathe diameter mode) is not supported";
    case 171: case 181: case 191:
      return g + " (UVW plane) is not supported (3-axis: X, Y, Z only)";
    case 650: case 660:
      return g + " (macro call) is not supported";
    default:
      return "unsupported G-code " + g;
  }
  // clang-format on
}

inline bool IsCycle(int m) {
  return m == 730 || m == 740 || m == 760 ||
         (m >= 810 && m <= 890 && m % 10 == 0);
}

struct Cursor {
  int file = 0;
  size_t offset = 0;   // of the next line to read
  int64_t line = 0;    // lines read so far in that file
};

struct Control {
  OKind kind;
  std::string label;
  Cursor start;  // while: the while line; do, repeat: the line after
  int64_t remaining = 0;  // repeat
  int64_t line = 0;       // the opening line, for errors
};

struct ModalState {
  bool valid = false;
  bool inches, incremental, arc_absolute;
  int plane;
};

struct Frame {
  std::string label;  // empty: the main program
  Cursor ret;
  int64_t call_line = 0;
  int64_t main_line = 0;  // the main program's line of the outermost call
  double saved[31];       // the caller's #1..#30
  std::unordered_map<std::string, double> named;  // local #<name>
  std::vector<Control> control;
  ModalState autorestore;  // M73
  // Fanuc M98 P L: the subprogram's first line and the repeats left.
  bool fanuc = false;
  Cursor fanuc_start;
  int64_t repeats_left = 0;
};

// Cutter compensation: a move of the programmed path (XY plane) and the
// tool's path for it.
struct CompSeg {
  bool arc = false;
  bool rapid = false;
  int64_t line = 0;
  double s[3], e[3];  // programmed start and end (machine mm)
  double c[2] = {0, 0};  // arc centre
  double radius = 0;     // programmed arc radius
  double sweep = 0;      // signed, radians
  // The tool's path: a line ts -> te, or an arc about c of radius tr from
  // angle ta through tsweep; tangent directions of the programmed path at
  // both ends.
  double ts[2], te[2];
  double tr = 0, ta = 0, tsweep = 0;
  double dir_s[2], dir_e[2];
  // The entry move (a line from the uncompensated start): its corner with
  // the next move is found on its offset line, through os parallel to the
  // programmed move (as LinuxCNC), not on the tool's path from ts.
  bool entry = false;
  double os[2] = {0, 0};
  const double* LineStart() const { return entry ? os : ts; }
};

struct Source {
  std::string name;  // the path for external files; "" for the program
  std::string owned;
  std::string_view text;
  // sub label -> the line after its "sub"
  std::unordered_map<std::string, Cursor> subs;
  std::unordered_map<std::string, Cursor> programs;  // Fanuc O-numbers
  bool subs_scanned = false;
};

class Interpreter final : public ParameterSource {
 public:
  Interpreter(const GcodeOptions& options, CanonSink* sink)
      : options_(options),
        builder_(&path_, options.arc_tolerance, options.max_points),
        sink_(sink),
        params_(kParameterCount, 0.0),
        g_ignored_(kGCodeLimit),
        m_ignored_(kMCodeCounted) {}

  absl::StatusOr<Toolpath> Run(std::string_view text);

  // ParameterSource.
  absl::StatusOr<double> Numbered(int n) override;
  absl::StatusOr<double> Named(const std::string& name) override;
  bool Exists(const std::string& name) override;

 private:
  // Errors name the line (and the file when it isn't the program).
  absl::Status Err(const std::string& what) const;
  absl::Status Wrap(const absl::Status& s) const {
    return s.ok() ? s : Err(std::string(s.message()));
  }

  absl::Status ReadBlock(const char* p, const char* end, Block* b);
  absl::Status ReadValue(const char** p, const char* end, double* v);
  absl::Status ReadOLine(const char* p, const char* end, Block* b);
  absl::Status ApplySettings(const Block& b);
  absl::Status SetParameter(const ParamRef& ref, double v);

  // Control flow.
  absl::Status ExecuteO(const Block& b, bool arrived);
  void SkipTo(const std::string& label, uint32_t kinds);
  bool SkipMatches(const char* q, const char* eol, Block* b);
  absl::Status Call(const Block& b);
  absl::Status Return(bool has_value, double value);
  absl::Status FindSub(const std::string& label, bool fanuc, Cursor* body);
  void ScanSubs(int file);
  absl::Status FanucCall(const Block& b);
  absl::Status FanucReturn();
  Frame& frame() { return frames_.back(); }
  Control* TopControl(OKind kind, const std::string& label);

  // Words.
  absl::Status Execute(const Block& b);
  absl::Status ApplyGCodes(const Block& b, int* new_motion, int* nonmodal,
                           bool* g53, int* length_code, bool* motion_given);
  absl::Status NonModal(const Block& b, int code, uint32_t* used);
  absl::Status ToolLength(const Block& b, int code, uint32_t* used);
  absl::Status ToolChange();
  absl::Status BeginRun();
  absl::Status EndPoint(const Block& b, bool machine, double end[3]);
  absl::Status Linear(const Block& b, bool machine, bool rapid);
  absl::Status Arc(const Block& b);
  absl::Status Cycle(const Block& b, uint32_t* used);
  absl::Status MoveTo(double x, double y, double z, bool rapid);
  absl::Status Emit(double x, double y, double z, bool rapid);
  absl::Status ChordArc(int p0, int p1, int p2, double cx, double cy,
                        double r0, double r1, double a0, double sweep,
                        double z0, const double end[3], bool rapid);
  absl::Status Polar(const Block& b, double end[3]);
  // Cutter compensation (G41/G42, G17 only).
  absl::Status CompStart(const Block& b, int code);
  absl::Status CompAdd(CompSeg seg);
  absl::Status CompArcEntry(CompSeg seg);
  absl::Status CompFlush();
  absl::Status CompEmit(const CompSeg& seg);
  // Emits the point (u, v, w) of compensation's plane coordinates.
  absl::Status EmitPlane(double u, double v, double w, bool rapid) {
    double p[3];
    p[comp_axes_[0]] = u;
    p[comp_axes_[1]] = v;
    p[comp_axes_[2]] = w;
    return Emit(p[0], p[1], p[2], rapid);
  }
  absl::Status ChordPlaneArc(double cx, double cy, double r, double a0,
                             double sweep, double z0, const double uvw[3],
                             bool rapid) {
    double end[3];
    for (int k = 0; k < 3; ++k) end[comp_axes_[k]] = uvw[k];
    return ChordArc(comp_axes_[0], comp_axes_[1], comp_axes_[2], cx, cy, r, r,
                    a0, sweep, z0, end, rapid);
  }
  absl::Status CompJoin(CompSeg* a, CompSeg* b);
  void SaveModal(ModalState* s) const {
    *s = {true, inches_, incremental_, arc_absolute_, plane_};
  }
  void RestoreModal(const ModalState& s) {
    inches_ = s.inches;
    incremental_ = s.incremental;
    arc_absolute_ = s.arc_absolute;
    plane_ = s.plane;
  }

  double scale() const { return inches_ ? kMmPerInch : 1.0; }
  // Machine = program * scale + Offset(axis).
  // Cached: recomputed after any parameter may have changed.
  double Offset(int a) const {
    if (offsets_dirty_) {
      const int cs = std::clamp(static_cast<int>(params_[kCoordSystem]), 1, 9);
      for (int k = 0; k < 3; ++k) {
        double o = params_[kCoordBase + 20 * cs + k];
        if (params_[kG92On] != 0) o += params_[kG92 + k];
        if (k == 2) o += params_[kToolLength];
        offset_[k] = o;
      }
      offsets_dirty_ = false;
    }
    return offset_[a];
  }
  double ProgramPosition(int a) const {
    return (pos_[a] - Offset(a)) / scale();
  }
  void FinishCounts();

  const GcodeOptions options_;
  Toolpath path_;
  ToolpathBuilder builder_;  // the sink unless sink_ is set
  CanonSink* sink_;
  double last_[3] = {0, 0, 0};  // the last position emitted
  bool emitted_ = false;        // anything was
  bool start_pending_ = false;  // options_.start is to begin the first run
  std::vector<double> params_;
  mutable double offset_[3] = {0, 0, 0};
  mutable bool offsets_dirty_ = true;
  std::unordered_map<std::string, double> globals_;
  std::deque<Source> files_;  // stable addresses: views into owned text
  std::vector<Frame> frames_;
  Cursor cur_;
  Cursor line_start_;  // the cursor before the line being executed
  int64_t main_line_ = 0;   // the main program's line being executed
  int64_t max_main_line_ = 0;
  int64_t blocks_ = 0;
  // Forward skip to an O-word.
  bool skipping_ = false;
  bool arrived_ = false;  // the line being read ends a skip
  std::string skip_label_;
  uint32_t skip_kinds_ = 0;
  int64_t skip_from_ = 0;

  // Modal state.
  double pos_[3] = {0, 0, 0};  // machine, mm; meaningful where known_ says
  unsigned known_ = 0;         // bit a: axis a known
  bool in_run_ = false;        // a point of the current run was emitted
  int motion_ = -1;            // G-code x10 (0, 10, 20, 30, 800, 810...)
  bool inches_ = false;
  bool units_declared_ = false;
  bool incremental_ = false;   // G91
  bool arc_absolute_ = false;  // G90.1
  int plane_ = 17;
  bool retract_r_ = false;     // G99
  // The height before a series of canned cycles (LinuxCNC's initial
  // level): G98 retracts to it; set by a series' first cycle.
  bool cycle_il_set_ = false;
  double cycle_il_ = 0;
  int comp_side_ = 0;          // +1 G41 (tool left), -1 G42, 0 off
  // Compensation's plane: CompSeg coordinate k is machine axis
  // comp_axes_[k] (G17: X Y Z, G18: Z X Y, G19: Y Z X).
  int comp_axes_[3] = {0, 1, 2};
  double comp_r_ = 0;          // mm
  bool comp_pending_ = false;  // comp_seg_ waits for the next move
  int64_t emit_line_ = -1;     // >= 0: the line of the points emitted
  bool comp_entry_ = false;    // the next move is the entry move
  // After G40: moves without X or Y words keep the last offset X, Y (as
  // LinuxCNC); the first with them (the exit) starts there.
  bool comp_exit_ = false;
  int64_t comp_exit_block_ = 0;  // the G40 line's block: its move exits
  CompSeg comp_seg_;
  bool home_known_[2] = {false, false};  // G28, G30
  bool home_noted_ = false;
  bool offset_noted_ = false;
  // Sticky canned-cycle values (program units), NaN until given.
  double cycle_r_ = std::nan(""), cycle_z_ = std::nan(""),
         cycle_q_ = std::nan("");
  int32_t last_t_ = -1;
  bool had_m6_ = false;
  uint16_t tool_ = 0;
  double feed_ = 0;
  bool ended_ = false;  // M2 / M30
  bool grbl_noted_ = false;
  ModalState saved_modal_;  // M70

  // Ignored words, counted in flat arrays (a map lookup per word would
  // dominate the parse) and moved into the Toolpath at the end.
  std::vector<int64_t> g_ignored_;
  std::vector<int64_t> m_ignored_;
  int64_t letter_ignored_[26] = {};
  int64_t block_deletes_ = 0;
  int64_t program_numbers_ = 0;
  int64_t dollar_lines_ = 0;
  Block block_;
};

}  // namespace swarf::gcode::interp

#endif  // SWARF_GCODE_INTERPRETER_H_
