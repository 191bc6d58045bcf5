// The RS274/NGC interpreter behind ParseGcode (contract in toolpath.h).
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

namespace swarf::gcode {
namespace {

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

const char* OName(OKind k) {
  static constexpr const char* kNames[] = {
      "",      "sub",    "endsub", "call",  "do",     "while",
      "endwhile", "if",  "elseif", "else",  "endif",  "repeat",
      "endrepeat", "return", "break", "continue"};
  return kNames[static_cast<int>(k)];
}

// The first word of a line after '/' and an N word: where an O-word is.
const char* Prelude(const char* p, const char* end) {
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
absl::Status ReadOWord(const char* p, const char* end, std::string* label,
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

std::string OLabel(const std::string& label) {
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
std::string UnsupportedG(int32_t c) {
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

bool IsCycle(int m) {
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

absl::Status Interpreter::Err(const std::string& what) const {
  if (cur_.file == 0) return LineError(cur_.line, what);
  return absl::InvalidArgumentError(absl::StrCat(
      "line ", cur_.line, " of ", files_[cur_.file].name, " (called from line ",
      main_line_, "): ", what));
}

// ------------------------------------------------------------- parameters

absl::StatusOr<double> Interpreter::Numbered(int n) {
  if (n >= kPosition && n < kPosition + 3) {
    if (!(known_ & (1u << (n - kPosition)))) return 0.0;
    return ProgramPosition(n - kPosition);
  }
  if (n == kToolNumber) return static_cast<double>(tool_);
  return params_[n];
}

absl::StatusOr<double> Interpreter::Named(const std::string& name) {
  if (name[0] == '_') {
    auto axis = [&](int a) -> double {
      return (known_ & (1u << a)) ? ProgramPosition(a) : 0.0;
    };
    // Read-only system parameters (LinuxCNC's names); then globals.
    if (name == "_x") return axis(0);
    if (name == "_y") return axis(1);
    if (name == "_z") return axis(2);
    if (name == "_abs_x") return pos_[0] / scale();
    if (name == "_abs_y") return pos_[1] / scale();
    if (name == "_abs_z") return pos_[2] / scale();
    if (name == "_line") return static_cast<double>(main_line_);
    if (name == "_motion_mode") return motion_ < 0 ? 800.0 : motion_ / 10.0;
    if (name == "_plane") return plane_ * 10.0;
    if (name == "_coord_system") {
      const int cs = static_cast<int>(params_[kCoordSystem]);
      return cs <= 6 ? 530.0 + 10 * cs : 590.0 + (cs - 6);
    }
    if (name == "_metric") return inches_ ? 0.0 : 1.0;
    if (name == "_imperial") return inches_ ? 1.0 : 0.0;
    if (name == "_absolute") return incremental_ ? 0.0 : 1.0;
    if (name == "_incremental") return incremental_ ? 1.0 : 0.0;
    if (name == "_retract_r_plane") return retract_r_ ? 1.0 : 0.0;
    if (name == "_retract_old_z") return retract_r_ ? 0.0 : 1.0;
    if (name == "_current_tool") return static_cast<double>(tool_);
    if (name == "_selected_tool") return static_cast<double>(last_t_);
    if (name == "_call_level") return static_cast<double>(frames_.size() - 1);
    if (name == "_feed") return feed_;
    if (name == "_tool_offset") return params_[kToolLength] / scale();
    auto it = globals_.find(name);
    if (it != globals_.end()) return it->second;
  } else {
    auto it = frame().named.find(name);
    if (it != frame().named.end()) return it->second;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("parameter #<", name, "> is not set"));
}

bool Interpreter::Exists(const std::string& name) {
  return Named(name).ok();
}

absl::Status Interpreter::SetParameter(const ParamRef& ref, double v) {
  if (!std::isfinite(v)) return Err("parameter value is not finite");
  if (!ref.named) {
    if ((ref.number >= kPosition && ref.number < kPosition + 9) ||
        ref.number == kToolNumber) {
      return Err(absl::StrCat("#", ref.number, " is read-only"));
    }
    params_[ref.number] = v;
    offsets_dirty_ = true;
    return absl::OkStatus();
  }
  auto& map = ref.name[0] == '_' ? globals_ : frame().named;
  if (ref.name[0] == '_' && ref.name != "_value" &&
      ref.name != "_value_returned" && !globals_.count(ref.name) &&
      Named(ref.name).ok()) {
    return Err(absl::StrCat("#<", ref.name, "> is read-only"));
  }
  if (map.size() >= kMaxNamedParameters && !map.count(ref.name)) {
    return Err(absl::StrCat("more than ", kMaxNamedParameters,
                            " named parameters"));
  }
  map[ref.name] = v;
  return absl::OkStatus();
}

// As LinuxCNC: every setting on a line takes effect after the whole line
// is read, so "#1=2 #2=#1" gives #2 the old #1.
absl::Status Interpreter::ApplySettings(const Block& b) {
  for (const Block::Setting& s : b.settings) {
    SWARF_RETURN_IF_ERROR(SetParameter(s.ref, s.value));
  }
  return absl::OkStatus();
}

// ------------------------------------------------------------- reading

absl::Status Interpreter::ReadValue(const char** p, const char* end,
                                    double* v) {
  // The common case first: a plain number.
  const char* q = ScanNumber(*p, end, v);
  if (q != nullptr) {
    if (q < end && *q == '.') return Err("malformed number");
    *p = q;
    return absl::OkStatus();
  }
  return Wrap(ReadReal(p, end, *this, v));
}

absl::Status Interpreter::ReadOLine(const char* p, const char* end,
                                    Block* b) {
  const char* rest;
  SWARF_RETURN_IF_ERROR(Wrap(ReadOWord(p, end, &b->o_label, &b->o_kind, &rest)));
  b->has_o = true;
  b->o_has_value = false;
  b->o_args.clear();
  p = SkipBlanks(rest, end);
  // A line reached by skipping only runs when it is an elseif or a
  // while: other values (an endsub's, ending a definition) aren't read.
  if (arrived_ && b->o_kind != OKind::kElseif &&
      b->o_kind != OKind::kWhile) {
    return absl::OkStatus();
  }
  switch (b->o_kind) {
    case OKind::kCall:
      while (p < end && *p == '[') {
        double v;
        SWARF_RETURN_IF_ERROR(Wrap(ReadReal(&p, end, *this, &v)));
        if (b->o_args.size() == 30) return Err("more than 30 call arguments");
        b->o_args.push_back(v);
        p = SkipBlanks(p, end);
      }
      break;
    case OKind::kIf: case OKind::kElseif: case OKind::kWhile:
    case OKind::kRepeat: case OKind::kReturn: case OKind::kEndsub:
      if (p < end && *p == '[') {
        SWARF_RETURN_IF_ERROR(Wrap(ReadReal(&p, end, *this, &b->o_value)));
        b->o_has_value = true;
      }
      break;
    default:
      break;
  }
  if (!OnlyComments(p, end)) {
    return Err(absl::StrCat("unexpected ", CharName(*SkipBlanks(p, end)),
                            " after ", OLabel(b->o_label), " ",
                            OName(b->o_kind)));
  }
  return absl::OkStatus();
}

// Splits [p, end) (one line, without its '\n') into words.
absl::Status Interpreter::ReadBlock(const char* p, const char* end, Block* b) {
  b->words = 0;
  b->ng = b->nm = 0;
  b->block_delete = false;
  b->has_o = false;
  b->settings.clear();
  p = SkipBlanks(p, end);
  if (p < end && *p == '/') {
    b->block_delete = true;
    ++p;
  }
  while (p < end) {
    const char c = *p;
    if (IsBlank(c)) {
      ++p;
      continue;
    }
    if (c == '(') {
      const void* close = std::memchr(p, ')', end - p);
      if (close == nullptr) return Err("comment '(' is not closed");
      p = static_cast<const char*>(close) + 1;
      continue;
    }
    if (c == ';') break;
    if (c == '#') {
      Block::Setting s;
      SWARF_RETURN_IF_ERROR(Wrap(ReadParamRef(&p, end, *this, &s.ref)));
      p = SkipBlanks(p, end);
      if (p >= end || *p != '=') {
        return Err("a parameter outside an expression must be set: #n=value");
      }
      ++p;
      SWARF_RETURN_IF_ERROR(ReadValue(&p, end, &s.value));
      if (b->settings.size() >= 256) return Err("too many settings on a line");
      b->settings.push_back(std::move(s));
      continue;
    }
    const char letter = static_cast<char>(c & ~0x20);  // upper case
    const int polar = c == '@' ? kRadiusWord : c == '^' ? kAngleWord : -1;
    if (polar < 0 && (letter < 'A' || letter > 'Z')) {
      switch (c) {
        case '[':
          return Err("an expression ('[') must follow a word letter");
        case '%':
          return Err("'%' must be alone on its line");
        default:
          return Err(absl::StrCat("unexpected ", CharName(c),
                                  " (expected a word letter)"));
      }
    }
    ++p;
    if (letter == 'O') {
      // Only an N word may come before an O-word.
      if (b->words != 0 || b->ng != 0 || b->nm != 0 || !b->settings.empty()) {
        return Err("an O-word must start its line");
      }
      return ReadOLine(p - 1, end, b);
    }
    double v;
    // The common case first: a plain number.
    const char* num = ScanNumber(p, end, &v);
    if (num != nullptr) {
      if (num < end && *num == '.') {
        return Err(absl::StrCat("malformed number in ", std::string(1, letter),
                                " word"));
      }
      p = num;
    } else {
      const char* q = SkipBlanks(p, end);
      if (q >= end || *q == '(' || *q == ';' ||
          ((*q & ~0x20) >= 'A' && (*q & ~0x20) <= 'Z' &&
           !(q + 1 < end && ((q[1] & ~0x20) >= 'A' && (q[1] & ~0x20) <= 'Z')))) {
        return Err(absl::StrCat(std::string(1, polar >= 0 ? c : letter),
                                " word has no number"));
      }
      SWARF_RETURN_IF_ERROR(Wrap(ReadReal(&p, end, *this, &v)));
    }
    if (polar >= 0) {
      const uint32_t bit = uint32_t{1} << polar;
      if (b->words & bit) {
        return Err(absl::StrCat("two ", std::string(1, c), " words on one line"));
      }
      b->words |= bit;
      b->value[polar] = v;
      continue;
    }
    switch (letter) {
      case 'G': {
        const double t = v * 10;
        const double r = std::round(t);
        if (!(v >= 0 && r < kGCodeLimit) || std::fabs(t - r) > 1e-6) {
          return Err(absl::StrCat("G", v, " is not a G-code"));
        }
        if (b->ng == kMaxCodesPerLine) return Err("too many G-codes on one line");
        b->g[b->ng++] = static_cast<int32_t>(r);
        break;
      }
      case 'M':
        if (!(v >= 0 && v < 1e6) || v != std::floor(v)) {
          return Err(absl::StrCat("M", v, " is not an M-code"));
        }
        if (b->nm == kMaxCodesPerLine) return Err("too many M-codes on one line");
        b->m[b->nm++] = static_cast<int32_t>(v);
        break;
      case 'N':  // line label
        break;
      case 'A': case 'B': case 'C': case 'U': case 'V': case 'W':
        return Err(absl::StrCat(std::string(1, letter),
                                " axis words are not supported (3-axis: X, "
                                "Y, Z only)"));
      case 'E':
        return Err("E words are not supported");
      default: {
        const uint32_t bit = Bit(letter);
        if (b->words & bit) {
          return Err(absl::StrCat("two ", std::string(1, letter),
                                  " words on one line"));
        }
        b->words |= bit;
        b->value[letter - 'A'] = v;
        break;
      }
    }
  }
  return absl::OkStatus();
}

// ------------------------------------------------------------- the loop

absl::StatusOr<Toolpath> Interpreter::Run(std::string_view text) {
  if (!(options_.arc_tolerance >= 1e-6 && options_.arc_tolerance <= 10)) {
    return absl::InvalidArgumentError(
        absl::StrCat("arc tolerance must be in [1e-6, 10] mm, got ",
                     options_.arc_tolerance));
  }
  if (options_.max_points < 1 || options_.max_blocks < 1 ||
      options_.max_call_depth < 1) {
    return absl::InvalidArgumentError(
        "max_points, max_blocks and max_call_depth must be positive");
  }
  for (int k = 0; k < 2; ++k) {
    home_known_[k] = options_.home_known;
    for (int a = 0; a < 3; ++a) {
      if (!(std::fabs(options_.home[a]) <= kMaxCoordinateMm)) {
        return absl::InvalidArgumentError("home position out of range");
      }
      params_[(k == 0 ? kG28Home : kG30Home) + a] = options_.home[a];
    }
  }
  params_[kCoordSystem] = 1;  // G54
  for (int a = 0; a < 3; ++a) {
    if (!(std::fabs(options_.start[a]) <= kMaxCoordinateMm &&
          std::fabs(options_.tool_change_position[a]) <= kMaxCoordinateMm)) {
      return absl::InvalidArgumentError(
          "start or tool-change position out of range");
    }
  }
  if (options_.start_known) {
    for (int a = 0; a < 3; ++a) pos_[a] = options_.start[a];
    known_ = 7;
    start_pending_ = true;
  }
  const char* begin = SkipBom(text.data(), text.data() + text.size());
  files_.emplace_back();
  files_[0].text = text.substr(begin - text.data());
  frames_.emplace_back();
  // A guess at the point count: a point per line (straight-line CAM
  // output) and a fifth more for arcs, within what Trim() keeps, so that
  // neither a reallocation nor a trim copies the points (copies fault in
  // fresh pages: the slowest part of parsing, see docs/benchmarks.md);
  // loops and long arcs grow the vector past it.
  const int64_t lines = std::count(text.begin(), text.end(), '\n') + 1;
  path_.Reserve(std::min<int64_t>(lines + lines / 5, options_.max_points));

  Block& block = block_;
  bool seen_content = false;   // a non-blank line was read
  bool percent_start = false;  // the program starts with '%'
  int64_t end_line = 0;        // where reading stopped early (M2/M30, '%')
  for (;;) {
    const std::string_view src = files_[cur_.file].text;
    if (cur_.offset >= src.size()) {
      if (skipping_) {
        return Err(absl::StrCat("no ", OLabel(skip_label_),
                                " line to end the block that starts on line ",
                                skip_from_));
      }
      if (frames_.size() > 1) {
        return Err(absl::StrCat("subroutine ", OLabel(frame().label),
                                " ends without endsub or return"));
      }
      if (!frame().control.empty()) {
        const Control& c = frame().control.back();
        return LineError(c.line, absl::StrCat(OLabel(c.label), " ",
                                              OName(c.kind),
                                              " is never closed"));
      }
      SWARF_RETURN_IF_ERROR(CompFlush());
      break;
    }
    line_start_ = cur_;
    const char* p = src.data() + cur_.offset;
    const char* const end = src.data() + src.size();
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
    if (eol == nullptr) eol = end;
    cur_.offset = (eol < end ? eol + 1 : end) - src.data();
    ++cur_.line;
    if (cur_.file == 0) {
      main_line_ = cur_.line;
      max_main_line_ = std::max(max_main_line_, main_line_);
      if (cur_.line > std::numeric_limits<int32_t>::max()) {
        return Err("too many lines");
      }
    }
    const char* q = SkipBlanks(p, eol);
    if (q == eol) continue;
    if (*q == '%') {
      if (!OnlyComments(q + 1, eol)) return Err("'%' must be alone on its line");
      if (cur_.file != 0) continue;
      // As LinuxCNC: a program that starts with '%' ends at the next one.
      if (!seen_content) {
        percent_start = true;
      } else if (percent_start) {
        end_line = cur_.line;
        break;
      }
      seen_content = true;
      continue;
    }
    seen_content = true;
    if (*q == '$') {
      if (options_.dialect != Dialect::kGrbl) {
        return Err("'$' lines are Grbl settings: use --dialect grbl");
      }
      ++dollar_lines_;
      if (!grbl_noted_) {
        grbl_noted_ = true;
        path_.AddNote("Grbl '$' lines (settings, homing, ...) are ignored");
      }
      continue;
    }
    bool arrived = false;
    if (skipping_) {
      if (!SkipMatches(q, eol, &block)) continue;
      skipping_ = false;
      arrived = true;
    }
    arrived_ = arrived;
    if (++blocks_ > options_.max_blocks) {
      return Err(absl::StrCat("more than ", options_.max_blocks,
                              " blocks executed (max_blocks): an endless "
                              "loop?"));
    }
    SWARF_RETURN_IF_ERROR(ReadBlock(q, eol, &block));
    if (block.empty()) {
      if (block.block_delete) ++block_deletes_;
      continue;
    }
    SWARF_RETURN_IF_ERROR(ApplySettings(block));
    if (block.has_o) {
      SWARF_RETURN_IF_ERROR(ExecuteO(block, arrived));
    } else {
      SWARF_RETURN_IF_ERROR(Execute(block));
    }
    if (ended_) {
      end_line = cur_.file == 0 ? cur_.line : main_line_;
      break;
    }
  }
  path_.set_source_lines(max_main_line_);
  path_.set_blocks_executed(blocks_);
  if (end_line > 0 && cur_.file == 0) {
    // Say so when something that looks like program text was not read.
    int64_t unread = 0;
    const char* const end = files_[0].text.data() + files_[0].text.size();
    for (const char* p = files_[0].text.data() + cur_.offset; p < end;) {
      const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
      if (eol == nullptr) eol = end;
      const char* q = SkipBlanks(p, eol);
      if (q < eol && *q != '%' && !OnlyComments(q, eol)) ++unread;
      p = eol < end ? eol + 1 : end;
    }
    if (unread > 0 && frames_.size() == 1) {
      path_.AddNote(absl::StrCat("the program ends on line ", end_line, "; ",
                                 unread, " lines after it were not read"));
    }
  }
  FinishCounts();
  path_.Trim();  // the reserve above was a guess
  return std::move(path_);
}

void Interpreter::FinishCounts() {
  for (int32_t c = 0; c < kGCodeLimit; ++c) {
    if (g_ignored_[c] > 0) path_.CountIgnored(GName(c), g_ignored_[c]);
  }
  for (int32_t c = 0; c < kMCodeCounted; ++c) {
    if (m_ignored_[c] > 0) {
      path_.CountIgnored(absl::StrCat("M", c), m_ignored_[c]);
    }
  }
  for (int i = 0; i < 26; ++i) {
    if (letter_ignored_[i] > 0) {
      path_.CountIgnored(std::string(1, static_cast<char>('A' + i)),
                         letter_ignored_[i]);
    }
  }
  if (block_deletes_ > 0) path_.CountIgnored("/", block_deletes_);
  if (program_numbers_ > 0) path_.CountIgnored("O", program_numbers_);
  if (dollar_lines_ > 0) path_.CountIgnored("$", dollar_lines_);
}

// ------------------------------------------------------------- control flow

void Interpreter::SkipTo(const std::string& label, uint32_t kinds) {
  skipping_ = true;
  skip_label_ = label;
  skip_kinds_ = kinds;
  skip_from_ = cur_.line;
}

// While skipping: true when the line is the awaited O-word.
bool Interpreter::SkipMatches(const char* q, const char* eol, Block* b) {
  const char* o = Prelude(q, eol);
  if (o >= eol || (*o != 'O' && *o != 'o')) return false;
  const char* rest;
  OKind kind;
  if (!ReadOWord(o, eol, &b->o_label, &kind, &rest).ok()) return false;
  if (b->o_label != skip_label_) return false;
  return (skip_kinds_ & KBit(kind)) != 0;
}

Control* Interpreter::TopControl(OKind kind, const std::string& label) {
  std::vector<Control>& c = frame().control;
  if (c.empty() || c.back().kind != kind || c.back().label != label) {
    return nullptr;
  }
  return &c.back();
}

absl::Status Interpreter::ExecuteO(const Block& b, bool arrived) {
  const std::string& label = b.o_label;
  const std::string name = absl::StrCat(OLabel(label), " ", OName(b.o_kind));
  std::vector<Control>& control = frame().control;
  if (control.size() >= kMaxControlDepth) {
    return Err(absl::StrCat("control structures nested deeper than ",
                            kMaxControlDepth));
  }
  const auto need_value = [&]() -> absl::Status {
    if (!b.o_has_value) return Err(name + " needs a [condition]");
    return absl::OkStatus();
  };
  const auto push = [&](OKind kind, Cursor start, int64_t remaining) {
    control.push_back({kind, label, start, remaining, cur_.line});
  };
  switch (b.o_kind) {
    case OKind::kProgramNumber:
      // A program number ("O1234 (NAME)"): its subprogram body, when
      // reached in sequence, runs as part of the program.
      ++program_numbers_;
      return absl::OkStatus();
    case OKind::kSub:
      files_[cur_.file].subs[label] = cur_;
      SkipTo(label, KBit(OKind::kEndsub));
      return absl::OkStatus();
    case OKind::kEndsub:
    case OKind::kReturn:
      if (arrived) return absl::OkStatus();  // the end of a definition
      if (frames_.size() == 1 || frame().fanuc) {
        return Err(name + " outside a subroutine");
      }
      if (frame().label != label) {
        // As LinuxCNC: a return may carry the label of a structure it is
        // in ("o1010 return" inside "o1010 if" in "o1000 sub").
        bool enclosing = false;
        if (b.o_kind == OKind::kReturn) {
          for (const Control& c : control) enclosing |= c.label == label;
        }
        if (!enclosing) {
          return Err(absl::StrCat(name, " inside subroutine ",
                                  OLabel(frame().label)));
        }
      }
      return Return(b.o_has_value, b.o_value);
    case OKind::kCall:
      return Call(b);
    case OKind::kIf:
      SWARF_RETURN_IF_ERROR(need_value());
      push(OKind::kIf, cur_, 0);
      if (b.o_value == 0) {
        SkipTo(label, KBit(OKind::kElseif) | KBit(OKind::kElse) |
                          KBit(OKind::kEndif));
      }
      return absl::OkStatus();
    case OKind::kElseif:
    case OKind::kElse:
      if (TopControl(OKind::kIf, label) == nullptr) {
        return Err(absl::StrCat(name, " without ", OLabel(label), " if"));
      }
      if (!arrived) {
        // A branch ran: on to the endif.
        SkipTo(label, KBit(OKind::kEndif));
        return absl::OkStatus();
      }
      if (b.o_kind == OKind::kElseif) {
        SWARF_RETURN_IF_ERROR(need_value());
        if (b.o_value == 0) {
          SkipTo(label, KBit(OKind::kElseif) | KBit(OKind::kElse) |
                            KBit(OKind::kEndif));
        }
      }
      return absl::OkStatus();
    case OKind::kEndif:
      if (TopControl(OKind::kIf, label) == nullptr) {
        return Err(absl::StrCat(name, " without ", OLabel(label), " if"));
      }
      control.pop_back();
      return absl::OkStatus();
    case OKind::kDo:
      push(OKind::kDo, cur_, 0);
      return absl::OkStatus();
    case OKind::kWhile: {
      if (Control* top = TopControl(OKind::kDo, label)) {
        // The end of a do-while loop (also reached by continue).
        SWARF_RETURN_IF_ERROR(need_value());
        if (b.o_value != 0) {
          cur_ = top->start;
        } else {
          control.pop_back();
        }
        return absl::OkStatus();
      }
      if (arrived) return absl::OkStatus();  // after a break out of a do
      SWARF_RETURN_IF_ERROR(need_value());
      if (b.o_value != 0) {
        push(OKind::kWhile, line_start_, 0);
      } else {
        SkipTo(label, KBit(OKind::kEndwhile));
      }
      return absl::OkStatus();
    }
    case OKind::kEndwhile: {
      Control* top = TopControl(OKind::kWhile, label);
      if (top == nullptr) {
        if (arrived) return absl::OkStatus();  // a false while, or a break
        return Err(absl::StrCat(name, " without ", OLabel(label), " while"));
      }
      const Cursor start = top->start;
      control.pop_back();
      cur_ = start;  // the while line evaluates its condition again
      return absl::OkStatus();
    }
    case OKind::kRepeat: {
      SWARF_RETURN_IF_ERROR(need_value());
      const double n = std::round(b.o_value);
      if (n >= 1) {
        push(OKind::kRepeat, cur_, static_cast<int64_t>(std::min(n, 9e18)));
      } else {
        SkipTo(label, KBit(OKind::kEndrepeat));
      }
      return absl::OkStatus();
    }
    case OKind::kEndrepeat: {
      Control* top = TopControl(OKind::kRepeat, label);
      if (top == nullptr) {
        if (arrived) return absl::OkStatus();
        return Err(absl::StrCat(name, " without ", OLabel(label), " repeat"));
      }
      if (--top->remaining > 0) {
        cur_ = top->start;
      } else {
        control.pop_back();
      }
      return absl::OkStatus();
    }
    case OKind::kBreak:
    case OKind::kContinue: {
      // The loop with this label; conditionals inside it end here.
      size_t k = control.size();
      while (k > 0 && !(control[k - 1].label == label &&
                        control[k - 1].kind != OKind::kIf)) {
        --k;
      }
      if (k == 0) {
        return Err(absl::StrCat(name, " outside an ", OLabel(label), " loop"));
      }
      const Control loop = control[k - 1];
      const bool brk = b.o_kind == OKind::kBreak;
      control.resize(brk ? k - 1 : k);
      const OKind end = loop.kind == OKind::kWhile ? OKind::kEndwhile
                        : loop.kind == OKind::kDo  ? OKind::kWhile
                                                   : OKind::kEndrepeat;
      if (!brk && loop.kind == OKind::kWhile) {
        control.pop_back();
        cur_ = loop.start;
        return absl::OkStatus();
      }
      SkipTo(label, KBit(end));
      return absl::OkStatus();
    }
  }
  return absl::OkStatus();
}

void Interpreter::ScanSubs(int file) {
  Source& s = files_[file];
  s.subs_scanned = true;
  const char* const base = s.text.data();
  const char* const end = base + s.text.size();
  int64_t line = 0;
  std::string label;
  for (const char* p = base; p < end;) {
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
    if (eol == nullptr) eol = end;
    const char* next = eol < end ? eol + 1 : end;
    ++line;
    const char* o = Prelude(p, eol);
    if (o < eol && (*o == 'O' || *o == 'o')) {
      OKind kind;
      const char* rest;
      if (ReadOWord(o, eol, &label, &kind, &rest).ok()) {
        const Cursor after{file, static_cast<size_t>(next - base), line};
        if (kind == OKind::kSub) s.subs.emplace(label, after);
        if (kind == OKind::kProgramNumber) s.programs.emplace(label, after);
      }
    }
    p = next;
  }
}

absl::Status Interpreter::FindSub(const std::string& label, bool fanuc,
                                  Cursor* body) {
  const std::string what =
      fanuc ? absl::StrCat("subprogram O", label)
            : absl::StrCat("subroutine ", OLabel(label));
  for (const int f : {cur_.file, 0}) {
    if (!files_[f].subs_scanned) ScanSubs(f);
    const auto& map = fanuc ? files_[f].programs : files_[f].subs;
    auto it = map.find(label);
    if (it != map.end()) {
      *body = it->second;
      return absl::OkStatus();
    }
  }
  if (options_.subroutine_dir.empty()) {
    return Err(what + " is not defined");
  }
  // As LinuxCNC: o<name> call reads name.ngc from the subroutine path.
  const std::string file = absl::StrCat(
      options_.subroutine_dir, "/",
      label[0] == '<' ? label.substr(1) : label, fanuc ? ".nc" : ".ngc");
  for (size_t f = 1; f < files_.size(); ++f) {
    if (files_[f].name == file) {
      return Err(absl::StrCat(file, " has no ", OLabel(label), " sub"));
    }
  }
  if (files_.size() >= kMaxFiles) {
    return Err(absl::StrCat("more than ", kMaxFiles, " subroutine files"));
  }
  absl::StatusOr<std::string> text = ReadWholeFile(file);
  if (!text.ok()) {
    return Err(absl::StrCat(what, " is not defined in the program, and ",
                            file, ": ", text.status().message()));
  }
  Source& s = files_.emplace_back();
  s.name = file;
  s.owned = std::move(*text);
  s.text = s.owned;
  const int index = static_cast<int>(files_.size() - 1);
  ScanSubs(index);
  const auto& map = fanuc ? s.programs : s.subs;
  auto it = map.find(label);
  if (it == map.end()) {
    if (fanuc) {
      *body = Cursor{index, 0, 0};  // the whole file
      return absl::OkStatus();
    }
    return Err(absl::StrCat(file, " has no ", OLabel(label), " sub"));
  }
  *body = it->second;
  return absl::OkStatus();
}

absl::Status Interpreter::Call(const Block& b) {
  if (static_cast<int>(frames_.size()) > options_.max_call_depth) {
    return Err(absl::StrCat("subroutine calls nested deeper than ",
                            options_.max_call_depth, " (endless recursion?)"));
  }
  Cursor body;
  SWARF_RETURN_IF_ERROR(FindSub(b.o_label, false, &body));
  Frame& f = frames_.emplace_back();
  f.label = b.o_label;
  f.ret = cur_;
  f.call_line = cur_.line;
  for (int i = 1; i <= 30; ++i) {
    f.saved[i] = params_[i];
    params_[i] = i <= static_cast<int>(b.o_args.size()) ? b.o_args[i - 1] : 0;
  }
  cur_ = body;
  return absl::OkStatus();
}

absl::Status Interpreter::Return(bool has_value, double value) {
  Frame& f = frame();
  if (!f.fanuc) {
    for (int i = 1; i <= 30; ++i) params_[i] = f.saved[i];
  }
  if (f.autorestore.valid) RestoreModal(f.autorestore);
  globals_["_value"] = has_value ? value : 0;
  globals_["_value_returned"] = has_value ? 1 : 0;
  const Cursor ret = f.ret;
  frames_.pop_back();
  cur_ = ret;
  return absl::OkStatus();
}

// Fanuc: M98 P<program> [L<repeats>] runs O<program>; M99 returns.
absl::Status Interpreter::FanucCall(const Block& b) {
  if (!(b.words & Bit('P'))) return Err("M98 needs P (the program number)");
  const double pv = b.value['P' - 'A'];
  if (!(pv >= 0 && pv < 1e9) || pv != std::floor(pv)) {
    return Err(absl::StrCat("M98 P", pv, " is not a program number"));
  }
  int64_t repeats = 1;
  if (b.words & Bit('L')) {
    const double l = b.value['L' - 'A'];
    if (!(l >= 1 && l <= 1e9) || l != std::floor(l)) {
      return Err(absl::StrCat("M98 L", l, " is not a repeat count"));
    }
    repeats = static_cast<int64_t>(l);
  }
  if (static_cast<int>(frames_.size()) > options_.max_call_depth) {
    return Err(absl::StrCat("subprogram calls nested deeper than ",
                            options_.max_call_depth, " (endless recursion?)"));
  }
  const std::string label = absl::StrCat(static_cast<int64_t>(pv));
  Cursor body;
  SWARF_RETURN_IF_ERROR(FindSub(label, true, &body));
  Frame& f = frames_.emplace_back();
  f.label = label;
  f.ret = cur_;
  f.call_line = cur_.line;
  f.fanuc = true;
  f.fanuc_start = body;
  f.repeats_left = repeats;
  cur_ = body;
  return absl::OkStatus();
}

absl::Status Interpreter::FanucReturn() {
  if (frames_.size() == 1 || !frame().fanuc) {
    // M99 in a main program repeats it forever on a Fanuc control; here
    // the program ends.
    path_.AddNote(absl::StrCat("M99 on line ", cur_.line,
                               " outside a subprogram: the program ends"));
    ended_ = true;
    return absl::OkStatus();
  }
  if (--frame().repeats_left > 0) {
    cur_ = frame().fanuc_start;
    return absl::OkStatus();
  }
  return Return(false, 0);
}

// ------------------------------------------------------------- execution

// In LinuxCNC's order of execution within a line: feed, speed, tool
// select, tool change, plane, units, tool length, coordinate system,
// distance mode, retract mode, non-modal codes (G10, G28, G92, ...),
// motion, stop.
absl::Status Interpreter::Execute(const Block& b) {
  if (b.block_delete) ++block_deletes_;
  if (b.words & Bit('F')) feed_ = b.value['F' - 'A'];

  int new_motion = -1, nonmodal = -1, length_code = -1;
  bool g53 = false, motion_given = false;
  if (b.ng > 0) {
    SWARF_RETURN_IF_ERROR(ApplyGCodes(b, &new_motion, &nonmodal, &g53,
                                      &length_code, &motion_given));
  }
  uint32_t used = 0;  // letters a code consumed
  if (b.words & Bit('T')) {
    const double t = b.value['T' - 'A'];
    if (!(t >= 0 && t <= 65535) || t != std::floor(t)) {
      return Err(absl::StrCat("T", t, " is not a tool number (0-65535)"));
    }
    last_t_ = static_cast<int32_t>(t);
    if (!had_m6_) {
      tool_ = static_cast<uint16_t>(last_t_);
      path_.NoteToolSelected(tool_, static_cast<int32_t>(main_line_));
    }
    used |= Bit('T');
  }
  bool m6 = false, end = false, m98 = false, m99 = false;
  for (int i = 0; i < b.nm; ++i) {
    const int32_t m = b.m[i];
    switch (m) {
      case 6: m6 = true; break;
      case 2: case 30: end = true; break;
      case 61: {
        // Set the current tool number without a change.
        if (!(b.words & Bit('Q'))) return Err("M61 needs Q (the tool number)");
        const double q = b.value['Q' - 'A'];
        if (!(q >= 0 && q <= 65535) || q != std::floor(q)) {
          return Err(absl::StrCat("M61 Q", q, " is not a tool number"));
        }
        tool_ = static_cast<uint16_t>(q);
        path_.NoteToolSelected(tool_, static_cast<int32_t>(main_line_));
        had_m6_ = true;
        used |= Bit('Q');
        break;
      }
      case 70: SaveModal(&saved_modal_); break;
      case 71: saved_modal_.valid = false; break;
      case 72:
        if (!saved_modal_.valid) return Err("M72 without a state saved by M70");
        RestoreModal(saved_modal_);
        break;
      case 73:
        if (frames_.size() == 1) return Err("M73 outside a subroutine");
        SaveModal(&frame().autorestore);
        break;
      case 98: case 99:
        if (options_.dialect != Dialect::kFanuc) {
          return Err(absl::StrCat("M", m, " (Fanuc subprogram ",
                                  m == 98 ? "call" : "return",
                                  ") needs --dialect fanuc"));
        }
        (m == 98 ? m98 : m99) = true;
        used |= Bit('P') | Bit('L');
        break;
      default:
        // Spindle, coolant, stops, I/O, machine-specific codes: no tip motion.
        if (m < kMCodeCounted) {
          ++m_ignored_[m];
        } else {
          path_.CountIgnored(absl::StrCat("M", m));
        }
    }
    if (m >= 70 && m <= 73) ++m_ignored_[m];
  }
  if (m6) {
    if (comp_side_ != 0) {
      return Err("M6 with cutter compensation on (G40 first)");
    }
    SWARF_RETURN_IF_ERROR(ToolChange());
  }
  if (length_code >= 0) SWARF_RETURN_IF_ERROR(ToolLength(b, length_code, &used));
  if (new_motion >= 0) {
    motion_ = new_motion;
    if (!IsCycle(motion_)) cycle_il_set_ = false;  // a series ends
  }

  const uint32_t axes = b.words & (kAxisWords | kPolarWords);
  if (nonmodal >= 0) {
    if (comp_side_ != 0 && (nonmodal == 280 || nonmodal == 300)) {
      return Err(absl::StrCat(GName(nonmodal),
                              " with cutter compensation on (G40 first)"));
    }
    SWARF_RETURN_IF_ERROR(NonModal(b, nonmodal, &used));
  }
  const bool axes_taken = (used & kAxisWords) != 0;
  if (axes_taken && (b.words & kPolarWords)) {
    return Err(absl::StrCat("@/^ (polar coordinates) with ",
                            GName(nonmodal >= 0 ? nonmodal : 431)));
  }
  if (axes_taken && motion_given) {
    return Err(absl::StrCat(GName(nonmodal >= 0 ? nonmodal : 431),
                            " and a motion code on one line both use the "
                            "axis words"));
  }
  const uint32_t arc_words = b.words & kArcWords & ~used;
  if (!axes_taken && (axes != 0 || (arc_words != 0 && !IsCycle(motion_)) ||
                      (motion_given && IsCycle(motion_)))) {
    if (motion_ < 0 || motion_ == 800) {
      return Err(absl::StrCat(
          "axis words with no motion mode in effect (",
          motion_ < 0 ? "no G0, G1, G2 or G3 yet" : "G80 cancelled it", ")"));
    }
    if (comp_side_ != 0 && (g53 || IsCycle(motion_))) {
      return Err(absl::StrCat(g53 ? "G53" : GName(motion_),
                              " with cutter compensation on (G40 first)"));
    }
    if (g53 && motion_ > 10) {
      return Err("G53 needs G0 or G1 (machine-coordinate straight moves)");
    }
    if (motion_ == 20 || motion_ == 30) {
      SWARF_RETURN_IF_ERROR(Arc(b));
      used |= kArcWords | Bit('P');
    } else if (IsCycle(motion_)) {
      if (axes == 0) {
        return Err(absl::StrCat(GName(motion_), " without X, Y or Z"));
      }
      SWARF_RETURN_IF_ERROR(Cycle(b, &used));
    } else {
      if (arc_words != 0) {
        const char w = static_cast<char>('A' + __builtin_ctz(arc_words));
        return Err(absl::StrCat(std::string(1, w),
                                " word without a G2/G3 arc"));
      }
      SWARF_RETURN_IF_ERROR(Linear(b, g53, motion_ == 0));
    }
  } else if (g53 && !axes_taken) {
    return Err("G53 without axis words");
  }
  for (uint32_t w = b.words & kIgnoredLetters & ~used; w != 0; w &= w - 1) {
    ++letter_ignored_[__builtin_ctz(w)];
  }
  if (m98) SWARF_RETURN_IF_ERROR(FanucCall(b));
  if (m99) SWARF_RETURN_IF_ERROR(FanucReturn());
  if (end) {
    SWARF_RETURN_IF_ERROR(CompFlush());
    ended_ = true;
  }
  return absl::OkStatus();
}

absl::Status Interpreter::ApplyGCodes(const Block& b, int* new_motion,
                                      int* nonmodal, bool* g53,
                                      int* length_code, bool* motion_given) {
  // The common case first: "G1 X.. Y.." (CAM output repeats the code).
  if (b.ng == 1 && (b.g[0] == 0 || b.g[0] == 10)) {
    *new_motion = b.g[0];
    *motion_given = true;
    return absl::OkStatus();
  }
  // Two codes of one modal group on a line contradict each other.
  enum Group {
    kMotion, kPlane, kUnits, kDistance, kArcDistance, kOffset, kLength,
    kNonModal, kRetract, kComp, kN
  };
  int32_t group_code[kN];
  std::fill(group_code, group_code + kN, -1);
  int coord = -1, plane = -1, units = -1, distance = -1, arc_distance = -1,
      retract = -1;
  bool g80 = false;
  int comp_code = -1;
  for (int i = 0; i < b.ng; ++i) {
    const int32_t c = b.g[i];
    Group group = kN;
    // clang-format off
    switch (c) {
      case 800:
        // Cancels a cycle; beside another motion code (as in "G0 G80",
        // common in post headers) that code wins.
        g80 = true;
        ++g_ignored_[c];
        break;
      case 760:
        // LinuxCNC: lathe threading; Fanuc mills: fine boring.
        if (options_.dialect != Dialect::kFanuc) return Err(UnsupportedG(c));
        group = kMotion;
        *new_motion = c;
        *motion_given = true;
        break;
      case 0: case 10: case 20: case 30:
      case 730: case 740: case 810: case 820: case 830: case 840: case 850:
      case 860: case 870: case 880: case 890:
        group = kMotion;
        *new_motion = c;
        *motion_given = true;
        break;
      case 170: case 180: case 190:
        group = kPlane;
        plane = c / 10;
        ++g_ignored_[c];
        break;
      case 200: case 210:
        group = kUnits;
        units = c;
        break;
      case 900: case 910:
        group = kDistance;
        distance = c;
        break;
      case 901: case 911:
        group = kArcDistance;
        arc_distance = c;
        break;
      case 540: case 550: case 560: case 570: case 580: case 590:
      case 591: case 592: case 593:
        group = kOffset;
        coord = c;
        ++g_ignored_[c];
        break;
      case 430: case 431: case 432: case 490:
        group = kLength;
        *length_code = c;
        ++g_ignored_[c];
        break;
      case 40: case 100: case 280: case 281: case 300: case 301: case 520:
      case 920: case 921: case 922: case 923:
        group = kNonModal;
        *nonmodal = c;
        if (c == 40) ++g_ignored_[c];  // dwell: no motion
        break;
      case 530:
        *g53 = true;
        ++g_ignored_[c];
        break;
      case 980: case 990:
        group = kRetract;
        retract = c;
        ++g_ignored_[c];
        break;
      case 400:
        group = kComp;
        comp_code = c;
        break;
      case 410: case 420: case 411: case 421:
        group = kComp;
        comp_code = c;
        break;
      // State that doesn't move the tip.
      case 80:   // lathe radius mode
      case 150:  // polar coordinates off
      case 500: case 501:  // scaling / mirroring off
      case 610: case 611: case 640:  // exact stop / blending
      case 690:  // rotation off
      case 930: case 940: case 950:  // feed modes
      case 960: case 970:  // spindle speed modes
        ++g_ignored_[c];
        break;
      default:
        return Err(UnsupportedG(c));
    }
    // clang-format on
    if (group != kN) {
      if (group_code[group] >= 0) {
        return Err(absl::StrCat(GName(group_code[group]), " and ", GName(c),
                                " on one line contradict each other"));
      }
      group_code[group] = c;
    }
  }
  if (g80 && *new_motion < 0) *new_motion = 800;
  if (comp_code == 400) {
    SWARF_RETURN_IF_ERROR(CompFlush());
    if (comp_side_ != 0) comp_exit_ = emitted_, comp_exit_block_ = blocks_;
    comp_side_ = 0;
    ++g_ignored_[400];
  } else if (comp_code >= 0) {
    SWARF_RETURN_IF_ERROR(CompStart(b, comp_code));
  }
  if (plane >= 0 && plane != plane_ && comp_side_ != 0) {
    return Err(absl::StrCat("G", plane,
                            " with cutter compensation on (G40 first)"));
  }
  if (plane >= 0) plane_ = plane;
  if (units >= 0) {
    inches_ = units == 200;
    units_declared_ = true;
  }
  if (coord >= 0) {
    const int cs = coord <= 590 ? coord / 10 - 53 : 6 + coord % 10;
    if (cs != static_cast<int>(params_[kCoordSystem])) {
      bool set = false;
      for (int a = 0; a < 3; ++a) set |= params_[kCoordBase + 20 * cs + a] != 0;
      if (!set && !offset_noted_) {
        offset_noted_ = true;
        path_.AddNote(absl::StrCat(
            GName(coord), " on line ", cur_.line,
            " selects a work offset the program never set: taken as zero "
            "(outputs are machine coordinates with all offsets zero unless "
            "the program sets them with G10)"));
      }
    }
    params_[kCoordSystem] = cs;
    offsets_dirty_ = true;
  }
  if (distance >= 0) incremental_ = distance == 910;
  if (arc_distance >= 0) arc_absolute_ = arc_distance == 901;
  if (retract >= 0) retract_r_ = retract == 990;
  if (*motion_given && IsCycle(*new_motion) && !IsCycle(motion_)) {
    // A new cycle sequence: its Z, R and Q must be given again.
    cycle_r_ = cycle_z_ = cycle_q_ = std::nan("");
  }
  return absl::OkStatus();
}

// The tip stays the controlled point under G43 (the tool table is unknown:
// the program's positions are taken as the tip, as everywhere); G43.1 Z
// offsets it by the given length and G43.2 Z adds to that; G49 cancels.
absl::Status Interpreter::ToolLength(const Block& b, int code,
                                     uint32_t* used) {
  offsets_dirty_ = true;
  if (code == 430 || code == 490) {
    params_[kToolLength] = 0;
    return absl::OkStatus();
  }
  if (b.words & (Bit('X') | Bit('Y'))) {
    return Err(absl::StrCat(GName(code),
                            " with X or Y: only a Z length offset is "
                            "supported"));
  }
  *used |= kAxisWords | Bit('H');
  double z = 0;
  if (b.words & Bit('Z')) z = b.value['Z' - 'A'] * scale();
  if (!(std::fabs(z) <= kMaxCoordinateMm)) return Err("tool length out of range");
  params_[kToolLength] = code == 431 ? z : params_[kToolLength] + z;
  return absl::OkStatus();
}

absl::Status Interpreter::NonModal(const Block& b, int code, uint32_t* used) {
  offsets_dirty_ = true;
  const double s = scale();
  const auto given = [&](int a) { return (b.words & Bit(kAxisName[a])) != 0; };
  const auto value = [&](int a) { return b.value[kAxisName[a] - 'A'] * s; };
  const auto in_range = [&](int a) -> absl::Status {
    if (given(a) && !(std::fabs(value(a)) <= kMaxCoordinateMm)) {
      return Err(absl::StrCat(std::string(1, kAxisName[a]), " value ",
                              b.value[kAxisName[a] - 'A'], " is out of range"));
    }
    return absl::OkStatus();
  };
  for (int a = 0; a < 3; ++a) SWARF_RETURN_IF_ERROR(in_range(a));
  const auto need_known = [&](int a, const char* what) -> absl::Status {
    if (!(known_ & (1u << a))) {
      return Err(absl::StrCat(what, " ", std::string(1, kAxisName[a]),
                              " while ", std::string(1, kAxisName[a]),
                              " is unknown"));
    }
    return absl::OkStatus();
  };
  switch (code) {
    case 40:  // dwell: its P is counted as ignored
      if (sink_ != nullptr) {
        sink_->Dwell(static_cast<int32_t>(main_line_),
                     (b.words & Bit('P')) ? b.value['P' - 'A'] : 0);
      }
      return absl::OkStatus();
    case 100: {
      *used |= kAxisWords | Bit('L') | Bit('P') | Bit('R');
      if (!(b.words & Bit('L'))) return Err("G10 needs L");
      const double l = b.value['L' - 'A'];
      if (l == 1 || l == 10 || l == 11) {
        // Tool table entries: lengths don't move the tip (see G43).
        ++letter_ignored_['L' - 'A'];
        return absl::OkStatus();
      }
      if (l != 2 && l != 20) {
        return Err(absl::StrCat("G10 L", l, " is not supported (L1, L2, L10, "
                                "L11, L20 are)"));
      }
      if ((b.words & Bit('R')) && b.value['R' - 'A'] != 0) {
        return Err("G10 R (coordinate system rotation) is not supported");
      }
      const double pv = (b.words & Bit('P')) ? b.value['P' - 'A'] : -1;
      if (!(pv >= 0 && pv <= 9) || pv != std::floor(pv)) {
        return Err("G10 L2/L20 needs P0..P9 (P0: the current system, P1: "
                   "G54 ... P9: G59.3)");
      }
      const int cs = pv == 0 ? static_cast<int>(params_[kCoordSystem])
                             : static_cast<int>(pv);
      for (int a = 0; a < 3; ++a) {
        if (!given(a)) continue;
        double o = value(a);
        if (l == 20) {
          // The current position gets the given coordinate in system cs.
          SWARF_RETURN_IF_ERROR(need_known(a, "G10 L20"));
          double other = params_[kG92On] != 0 ? params_[kG92 + a] : 0;
          if (a == 2) other += params_[kToolLength];
          o = pos_[a] - other - value(a);
        }
        params_[kCoordBase + 20 * cs + a] = o;
      }
      return absl::OkStatus();
    }
    case 280: case 300: {
      *used |= kAxisWords;
      const uint32_t axes = b.words & kAxisWords;
      // First the intermediate point (program coordinates).
      if (axes != 0) SWARF_RETURN_IF_ERROR(Linear(b, false, true));
      const int k = code == 280 ? 0 : 1;
      const int base = k == 0 ? kG28Home : kG30Home;
      const unsigned move = axes == 0 ? 7u : axes >> ('X' - 'A');
      if (!home_known_[k]) {
        // Like a tool change: the machine goes where we can't follow.
        known_ &= ~move;
        in_run_ = false;
        start_pending_ = false;
        if (!home_noted_) {
          home_noted_ = true;
          path_.AddNote(absl::StrCat(
              GName(code), " on line ", cur_.line,
              ": the home position is unknown (give --home X,Y,Z or set it "
              "with G28.1/G30.1); the axes it moves are unknown until given "
              "again"));
        }
        return absl::OkStatus();
      }
      const unsigned before = known_;
      for (int a = 0; a < 3; ++a) {
        if (move & (1u << a)) pos_[a] = params_[base + a];
      }
      known_ |= move;
      if (known_ != 7) return absl::OkStatus();
      if (before != 7) in_run_ = false, start_pending_ = false;
      return Emit(pos_[0], pos_[1], pos_[2], true);
    }
    case 281: case 301: {
      const int k = code == 281 ? 0 : 1;
      for (int a = 0; a < 3; ++a) {
        SWARF_RETURN_IF_ERROR(need_known(a, GName(code).c_str()));
      }
      for (int a = 0; a < 3; ++a) {
        params_[(k == 0 ? kG28Home : kG30Home) + a] = pos_[a];
      }
      home_known_[k] = true;
      return absl::OkStatus();
    }
    case 520: case 920: {
      *used |= kAxisWords;
      if ((b.words & kAxisWords) == 0) {
        return Err(absl::StrCat(GName(code), " without axis words"));
      }
      if (params_[kG92On] == 0) {
        for (int a = 0; a < 3; ++a) params_[kG92 + a] = 0;
      }
      for (int a = 0; a < 3; ++a) {
        if (!given(a)) continue;
        if (code == 520) {
          params_[kG92 + a] = value(a);  // a local offset of the origin
          continue;
        }
        SWARF_RETURN_IF_ERROR(need_known(a, "G92"));
        // The current position gets the given coordinate.
        double other = params_[kCoordBase +
                               20 * static_cast<int>(params_[kCoordSystem]) + a];
        if (a == 2) other += params_[kToolLength];
        params_[kG92 + a] = pos_[a] - other - value(a);
      }
      params_[kG92On] = 1;
      return absl::OkStatus();
    }
    case 921:
      for (int a = 0; a < 3; ++a) params_[kG92 + a] = 0;
      params_[kG92On] = 0;
      return absl::OkStatus();
    case 922:
      params_[kG92On] = 0;
      return absl::OkStatus();
    case 923:
      params_[kG92On] = 1;
      return absl::OkStatus();
    default:
      return Err(UnsupportedG(code));
  }
}

// M6: as LinuxCNC, the position stays (a rapid to the tool-change position
// first when one is given); with m6_forgets_position every axis becomes
// unknown and the next known position starts a new run.
absl::Status Interpreter::ToolChange() {
  if (options_.tool_change_position_known) {
    const double* t = options_.tool_change_position;
    SWARF_RETURN_IF_ERROR(MoveTo(t[0], t[1], t[2], true));  // the old tool
  }
  if (last_t_ >= 0) {
    tool_ = static_cast<uint16_t>(last_t_);
    path_.NoteToolSelected(tool_, static_cast<int32_t>(main_line_));
  }
  had_m6_ = true;
  if (options_.m6_forgets_position) {
    known_ = 0;
    in_run_ = false;
    start_pending_ = false;
  }
  if (sink_ != nullptr) sink_->ToolChange(static_cast<int32_t>(main_line_), tool_);
  return absl::OkStatus();
}

// The programmed end of a move: axis words in the current units, distance
// mode and offsets (machine coordinates under G53); absent axes unchanged.
absl::Status Interpreter::EndPoint(const Block& b, bool machine,
                                   double end[3]) {
  if (!units_declared_) {
    units_declared_ = true;  // note once
    path_.AddNote("no G20/G21 before the first move: millimetres assumed");
  }
  const double s = scale();
  for (int a = 0; a < 3; ++a) {
    end[a] = pos_[a];
    const char name = kAxisName[a];
    if (!(b.words & Bit(name))) continue;
    double v = b.value[name - 'A'] * s;
    if (machine) {
      if (incremental_) return Err("G53 in incremental mode (G91)");
    } else if (incremental_) {
      if (!(known_ & (1u << a))) {
        return Err(absl::StrCat("incremental (G91) ", std::string(1, name),
                                " move while ", std::string(1, name),
                                " is unknown"));
      }
      v += pos_[a];
    } else {
      v += Offset(a);
    }
    if (!(std::fabs(v) <= kMaxCoordinateMm)) {
      return Err(absl::StrCat(std::string(1, name), " position ", v,
                              " mm is out of range"));
    }
    end[a] = v;
  }
  if (b.words & kPolarWords) return Polar(b, end);
  return absl::OkStatus();
}

// '@' (radius) and '^' (angle, degrees) give X and Y, as LinuxCNC: in G90
// about the origin of the program coordinates (a missing one from the
// current position), in G91 added to the current position's radius and
// angle. G17 only.
absl::Status Interpreter::Polar(const Block& b, double end[3]) {
  if (b.words & (Bit('X') | Bit('Y'))) {
    return Err("X or Y with polar coordinates (@, ^)");
  }
  if (plane_ != 17) {
    return Err("polar coordinates (@, ^) only in the XY plane (G17)");
  }
  const bool has_r = b.words & (uint32_t{1} << kRadiusWord);
  const bool has_a = b.words & (uint32_t{1} << kAngleWord);
  const bool need_here = incremental_ || !has_r || !has_a;
  if (need_here && (known_ & 3) != 3) {
    return Err("polar coordinates (@, ^) relative to an unknown X or Y");
  }
  const double px = need_here ? ProgramPosition(0) : 0;
  const double py = need_here ? ProgramPosition(1) : 0;
  if (incremental_ && px == 0 && py == 0) {
    return Err("incremental polar coordinates (@, ^) at the origin: the "
               "angle is undefined");
  }
  double radius = need_here ? std::hypot(py, px) : 0;
  double angle = need_here ? std::atan2(py, px) : 0;
  const double rv = b.value[kRadiusWord], av = b.value[kAngleWord] * kPi / 180;
  if (incremental_) {
    if (has_r) radius += rv;
    if (has_a) angle += av;
  } else {
    if (has_r) radius = rv;
    if (has_a) angle = av;
  }
  const double xy[2] = {radius * std::cos(angle), radius * std::sin(angle)};
  for (int a = 0; a < 2; ++a) {
    const double v = xy[a] * scale() + Offset(a);
    if (!(std::fabs(v) <= kMaxCoordinateMm)) {
      return Err(absl::StrCat(std::string(1, kAxisName[a]), " position ", v,
                              " mm is out of range"));
    }
    end[a] = v;
  }
  return absl::OkStatus();
}

// Rapids from an unknown position only position the machine (a program's
// first moves, the first after M6); a feed whose start or end is unknown
// cuts somewhere we can't know: it is dropped and counted.
absl::Status Interpreter::Linear(const Block& b, bool machine, bool rapid) {
  double end[3];
  SWARF_RETURN_IF_ERROR(EndPoint(b, machine, end));
  if (comp_side_ != 0) {
    CompSeg seg;
    seg.rapid = rapid;
    seg.line = main_line_;
    for (int a = 0; a < 3; ++a) {
      seg.s[a] = pos_[comp_axes_[a]];
      seg.e[a] = end[comp_axes_[a]];
    }
    for (int a = 0; a < 3; ++a) pos_[a] = end[a];
    return CompAdd(seg);
  }
  if (comp_exit_) {
    const int u = comp_axes_[0], v = comp_axes_[1], w = comp_axes_[2];
    const uint32_t in_plane = Bit(kAxisName[u]) | Bit(kAxisName[v]) |
                              (u + v == 1 ? kPolarWords : 0);
    if (!(b.words & in_plane) && known_ == 7 && blocks_ != comp_exit_block_) {
      pos_[w] = end[w];
      return EmitPlane(last_[u], last_[v], end[w], rapid);
    }
    comp_exit_ = false;
  }
  const unsigned before = known_;
  if (b.words & kPolarWords) known_ |= 3;
  for (int a = 0; a < 3; ++a) {
    if (b.words & Bit(kAxisName[a])) known_ |= 1u << a;
    pos_[a] = end[a];
  }
  if (known_ != 7 || before != 7) {
    if (!rapid) {
      path_.AddDropped(static_cast<int32_t>(main_line_),
                       known_ != 7 ? (~known_ & 7) : (~before & 7));
    }
    if (known_ != 7) return absl::OkStatus();
  }
  return Emit(end[0], end[1], end[2], rapid);
}

absl::Status Interpreter::MoveTo(double x, double y, double z, bool rapid) {
  pos_[0] = x;
  pos_[1] = y;
  pos_[2] = z;
  known_ = 7;
  return Emit(x, y, z, rapid);
}

// A known start (GcodeOptions::start) begins the first run: the first
// move starts there.
absl::Status Interpreter::BeginRun() {
  start_pending_ = false;
  if (in_run_) return absl::OkStatus();
  const double* s = options_.start;
  return Emit(s[0], s[1], s[2], true);
}

absl::Status Interpreter::Emit(double x, double y, double z, bool rapid) {
  if (start_pending_) SWARF_RETURN_IF_ERROR(BeginRun());
  CanonStraight m;
  m.end = {x, y, z};
  m.line = static_cast<int32_t>(emit_line_ >= 0 ? emit_line_ : main_line_);
  m.tool = tool_;
  m.rapid = rapid;
  m.starts_run = !in_run_;
  in_run_ = true;
  last_[0] = x, last_[1] = y, last_[2] = z;
  emitted_ = true;
  absl::Status st =
      sink_ == nullptr ? builder_.Straight(m) : sink_->Straight(m);
  if (!st.ok()) return Err(std::string(st.message()));
  return st;
}

absl::Status Interpreter::Arc(const Block& b) {
  comp_exit_ = false;
  const bool cw = motion_ == 20;
  const char* gname = cw ? "G2" : "G3";
  // The plane's axes (first, second, linear) and centre words; the first
  // to the second is counterclockwise seen from the normal's positive side.
  int p0 = 0, p1 = 1, p2 = 2;
  char w0 = 'I', w1 = 'J', bad = 'K';
  if (plane_ == 18) {
    p0 = 2, p1 = 0, p2 = 1, w0 = 'K', w1 = 'I', bad = 'J';
  } else if (plane_ == 19) {
    p0 = 1, p1 = 2, p2 = 0, w0 = 'J', w1 = 'K', bad = 'I';
  }
  const std::string plane_name = plane_ == 17   ? "XY-plane (G17)"
                                 : plane_ == 18 ? "XZ-plane (G18)"
                                                : "YZ-plane (G19)";
  if (b.words & Bit(bad)) {
    return Err(absl::StrCat(std::string(1, bad), " word in an ", plane_name,
                            " ", gname, " arc"));
  }
  if ((!in_run_ && !start_pending_) || known_ != 7) {
    return Err(absl::StrCat(gname,
                            " arc before the start position is known (X, Y "
                            "and Z must all be given first)"));
  }
  const bool has_ij = b.words & (Bit(w0) | Bit(w1));
  const bool has_r = b.words & Bit('R');
  if (has_ij && has_r) {
    return Err(absl::StrCat(gname, " arc with both ", std::string(1, w0), "/",
                            std::string(1, w1), " and R"));
  }
  if (!has_ij && !has_r) {
    return Err(absl::StrCat(gname, " arc without ", std::string(1, w0), "/",
                            std::string(1, w1), " or R"));
  }
  int64_t turns = 1;
  if (b.words & Bit('P')) {
    const double pv = b.value['P' - 'A'];
    if (!(pv >= 1 && pv <= 10000) || pv != std::floor(pv)) {
      return Err(absl::StrCat("P", pv, " in a ", gname,
                              " arc is not a turn count (1, 2, ...)"));
    }
    turns = static_cast<int64_t>(pv);
  }
  double end[3];
  SWARF_RETURN_IF_ERROR(EndPoint(b, false, end));
  const double s = scale();
  for (const char w : {w0, w1, 'R'}) {
    if ((b.words & Bit(w)) &&
        !(std::fabs(b.value[w - 'A'] * s) <= kMaxCoordinateMm)) {
      return Err(absl::StrCat(std::string(1, w), " value ", b.value[w - 'A'],
                              " is out of range"));
    }
  }
  const double x0 = pos_[p0], y0 = pos_[p1], z0 = pos_[p2];
  const double x1 = end[p0], y1 = end[p1], z1 = end[p2];

  double cx, cy;
  if (has_r) {
    const double r = b.value['R' - 'A'] * s;
    if (x1 == x0 && y1 == y0) {
      return Err(absl::StrCat(gname,
                              " full circle with R: the centre is undefined "
                              "(use ",
                              std::string(1, w0), "/", std::string(1, w1),
                              ")"));
    }
    const double dx = x1 - x0, dy = y1 - y0;
    const double d = std::hypot(dx, dy);
    const double half = d / 2, ar = std::fabs(r);
    if (half - ar > kRadiusTolerance) {
      return Err(absl::StrCat("R", b.value['R' - 'A'], " in ", gname,
                              " is too small to reach the end point (half "
                              "the chord is ",
                              half, " mm)"));
    }
    const double h = half >= ar ? 0.0 : std::sqrt(ar * ar - half * half);
    // The centre is on the chord's bisector, left of the chord's direction
    // for a G3 short arc (R > 0) or a G2 long arc (R < 0), right otherwise.
    const double side = (!cw) == (r > 0) ? 1.0 : -1.0;
    cx = (x0 + x1) / 2 - side * h * dy / d;
    cy = (y0 + y1) / 2 + side * h * dx / d;
  } else {
    const double i = (b.words & Bit(w0)) ? b.value[w0 - 'A'] * s : 0.0;
    const double j = (b.words & Bit(w1)) ? b.value[w1 - 'A'] * s : 0.0;
    cx = arc_absolute_ ? i + Offset(p0) : x0 + i;
    cy = arc_absolute_ ? j + Offset(p1) : y0 + j;
  }
  const double r0 = std::hypot(x0 - cx, y0 - cy);
  const double r1 = std::hypot(x1 - cx, y1 - cy);
  if (!(r0 >= kRadiusTolerance && r1 >= kRadiusTolerance)) {
    return Err(absl::StrCat(gname, " arc has a zero radius (", r0,
                            " mm at the start, ", r1, " mm at the end)"));
  }
  const double err = std::fabs(r1 - r0);
  if (err > kSpiralAbsMax ||
      (err > kSpiralAbsFloor && err > kSpiralRel * std::max(r0, r1))) {
    return Err(absl::StrCat(gname, " arc: the radius to the end (", r1,
                            " mm) differs from the radius to the start (", r0,
                            " mm) by ", err, " mm"));
  }
  const double a0 = std::atan2(y0 - cy, x0 - cx);
  const double a1 = std::atan2(y1 - cy, x1 - cx);
  // Signed sweep: G2 clockwise (negative), G3 counterclockwise; equal
  // angles (start == end) make a full circle; P adds whole turns.
  double sweep = a1 - a0;
  if (cw) {
    if (sweep >= 0) sweep -= 2 * kPi;
    sweep -= 2 * kPi * static_cast<double>(turns - 1);
  } else {
    if (sweep <= 0) sweep += 2 * kPi;
    sweep += 2 * kPi * static_cast<double>(turns - 1);
  }
  if (comp_side_ != 0) {
    CompSeg seg;
    seg.arc = true;
    seg.line = main_line_;
    seg.s[0] = x0, seg.s[1] = y0, seg.s[2] = z0;
    seg.e[0] = x1, seg.e[1] = y1, seg.e[2] = z1;
    seg.c[0] = cx, seg.c[1] = cy;
    seg.radius = r0;
    seg.sweep = sweep;
    SWARF_RETURN_IF_ERROR(CompAdd(seg));
  } else {
    SWARF_RETURN_IF_ERROR(ChordArc(p0, p1, p2, cx, cy, r0, r1, a0, sweep, z0,
                                   end, false));
  }
  for (int a = 0; a < 3; ++a) pos_[a] = end[a];
  return absl::OkStatus();
}

// Emits an arc in the plane of axes (p0, p1) from angle a0 through `sweep`
// (radius r0 to r1, linear: a spiral when they differ; the third axis
// linear from z0), ending exactly at `end` (x, y, z): a CanonArc.
absl::Status Interpreter::ChordArc(int p0, int p1, int p2, double cx,
                                   double cy, double r0, double r1, double a0,
                                   double sweep, double z0, const double end[3],
                                   bool rapid) {
  if (start_pending_) SWARF_RETURN_IF_ERROR(BeginRun());
  CanonArc arc;
  arc.end = {end[0], end[1], end[2]};
  arc.p0 = p0, arc.p1 = p1, arc.p2 = p2;
  arc.cx = cx, arc.cy = cy;
  arc.r0 = r0, arc.r1 = r1;
  arc.a0 = a0, arc.sweep = sweep;
  arc.z0 = z0;
  arc.line = static_cast<int32_t>(emit_line_ >= 0 ? emit_line_ : main_line_);
  arc.tool = tool_;
  arc.rapid = rapid;
  in_run_ = true;
  last_[0] = end[0], last_[1] = end[1], last_[2] = end[2];
  emitted_ = true;
  absl::Status st =
      sink_ == nullptr ? builder_.ArcFeed(arc) : sink_->ArcFeed(arc);
  if (!st.ok()) return Err(std::string(st.message()));
  return st;
}

// Canned cycles, after LinuxCNC (XY plane). A series of cycles (until G80
// or another motion mode) keeps its initial level: the height before its
// first cycle, raised to R when below it. Each hole: over to it (the
// series' first at the current height, the others at the clearance
// height: a straight rapid, diagonal when the height changes), down to R,
// the cycle's own moves, then back to the clearance height: R under G99,
// the initial level under G98. Under G91, R is relative to the initial
// level, Z to R, and X/Y (or @/^) step from hole to hole for L repeats.
absl::Status Interpreter::Cycle(const Block& b, uint32_t* used) {
  comp_exit_ = false;
  const std::string g = GName(motion_);
  *used |= Bit('R') | Bit('Q') | Bit('P') | Bit('L');
  const bool fanuc = options_.dialect == Dialect::kFanuc;
  if (motion_ == 870) {
    if (fanuc) {
      return Err("G87 in the Fanuc form (back boring with a Q shift) is not "
                 "supported");
    }
    *used |= Bit('I') | Bit('J') | Bit('K');
  }
  if (fanuc) *used |= Bit('K');
  if (plane_ != 17) {
    return Err(absl::StrCat(g, " in the ", plane_ == 18 ? "G18" : "G19",
                            " plane is not supported (canned cycles: G17 "
                            "only)"));
  }
  if (b.words & Bit('R')) cycle_r_ = b.value['R' - 'A'];
  if (b.words & Bit('Z')) cycle_z_ = b.value['Z' - 'A'];
  if (b.words & Bit('Q')) cycle_q_ = b.value['Q' - 'A'];
  if (std::isnan(cycle_r_)) return Err(g + " needs R (the retract height)");
  if (std::isnan(cycle_z_)) return Err(g + " needs Z (the hole bottom)");
  if (!(known_ & 4)) {
    return Err(g + " while Z is unknown (the cycle starts from the current "
                   "height)");
  }
  int64_t repeats = 1;
  if (b.words & Bit('L')) {
    const double l = b.value['L' - 'A'];
    if (!(l >= 1 && l <= 1e6) || l != std::floor(l)) {
      return Err(absl::StrCat(g, " L", l, " is not a repeat count"));
    }
    repeats = static_cast<int64_t>(l);
  }
  if (fanuc && (b.words & Bit('K'))) {
    // Fanuc's repeat count.
    const double k = b.value['K' - 'A'];
    if (!(k >= 1 && k <= 1e6) || k != std::floor(k)) {
      return Err(absl::StrCat(g, " K", k, " is not a repeat count"));
    }
    repeats = static_cast<int64_t>(k);
  }
  const double s = scale();
  double peck = 0;
  if (motion_ == 730 || motion_ == 830) {
    peck = cycle_q_ * s;
    if (!(peck > 0)) return Err(g + " needs Q > 0 (the peck depth)");
  }
  // The series' initial level: the height before its first cycle.
  if (!cycle_il_set_) {
    cycle_il_set_ = true;
    cycle_il_ = pos_[2];
  }
  double old_z = cycle_il_;
  double r, bottom;
  if (incremental_) {
    r = old_z + cycle_r_ * s;
    bottom = r + cycle_z_ * s;
  } else {
    r = cycle_r_ * s + Offset(2);
    bottom = cycle_z_ * s + Offset(2);
  }
  for (const double v : {r, bottom}) {
    if (!(std::fabs(v) <= kMaxCoordinateMm)) return Err(g + ": out of range");
  }
  if (bottom > r) {
    return Err(absl::StrCat(g, ": the hole bottom Z is above the retract "
                               "height R"));
  }
  // Below R at the initial level: straight up (or down) to R first.
  double current = pos_[2];
  if (old_z < r) {
    if ((known_ & 3) == 3) {
      SWARF_RETURN_IF_ERROR(MoveTo(pos_[0], pos_[1], r, true));
    } else {
      pos_[2] = r;
    }
    old_z = current = r;
  }
  const double clear = retract_r_ ? r : old_z;
  double middle = 0, off[2] = {0, 0};
  if (motion_ == 870) {
    if ((b.words & (Bit('I') | Bit('J') | Bit('K'))) !=
        (Bit('I') | Bit('J') | Bit('K'))) {
      return Err("G87 (back boring) needs I, J and K");
    }
    off[0] = b.value['I' - 'A'] * s;
    off[1] = b.value['J' - 'A'] * s;
    middle = b.value['K' - 'A'] * s + (incremental_ ? bottom : Offset(2));
    if (!(middle >= bottom && middle <= r)) {
      return Err("G87: K must lie between the hole bottom Z and R");
    }
  }
  const int64_t pecks =
      peck > 0 ? static_cast<int64_t>(std::min(
                     std::ceil((r - bottom) / peck), 1e15))
               : 0;
  if (pecks * repeats > options_.max_points) {
    return Err(absl::StrCat(g, " needs ", pecks, " pecks: more than "
                            "max_points"));
  }
  const auto feed = [&](double x, double y, double z) {
    return MoveTo(x, y, z, false);
  };
  const auto rapid = [&](double x, double y, double z) {
    return MoveTo(x, y, z, true);
  };
  for (int64_t k = 0; k < repeats; ++k) {
    double x = 0, y = 0;
    if (b.words & kPolarWords) {
      double e[3] = {pos_[0], pos_[1], pos_[2]};
      SWARF_RETURN_IF_ERROR(Polar(b, e));
      x = e[0], y = e[1];
    }
    for (int a = 0; a < 2 && !(b.words & kPolarWords); ++a) {
      const char name = kAxisName[a];
      const bool given = b.words & Bit(name);
      double v = pos_[a];
      if (given && !incremental_) {
        v = b.value[name - 'A'] * s + Offset(a);
      } else if (!(known_ & (1u << a))) {
        return Err(absl::StrCat(g, " while ", std::string(1, name),
                                " is unknown"));
      } else if (given) {
        v += b.value[name - 'A'] * s;
      }
      if (!(std::fabs(v) <= kMaxCoordinateMm)) return Err(g + ": out of range");
      (a == 0 ? x : y) = v;
    }
    // Over to the hole (the first at the current height, the others at the
    // clearance height) and down to R.
    const double over = k == 0 && current > r ? current : clear;
    SWARF_RETURN_IF_ERROR(rapid(x, y, over));
    SWARF_RETURN_IF_ERROR(rapid(x, y, r));
    switch (motion_) {
      case 730:  // chip-breaking pecks: a short retract after each
      case 830:  // deep-hole pecks: out to R after each
        for (int64_t i = 1; i < pecks; ++i) {
          const double depth = r - static_cast<double>(i) * peck;
          if (!(depth > bottom)) break;
          SWARF_RETURN_IF_ERROR(feed(x, y, depth));
          if (motion_ == 830) SWARF_RETURN_IF_ERROR(rapid(x, y, r));
          SWARF_RETURN_IF_ERROR(
              rapid(x, y, std::min(r, depth + kPeckClearanceMm)));
        }
        SWARF_RETURN_IF_ERROR(feed(x, y, bottom));
        break;
      case 760:
        // Fanuc fine boring: the Q shift away from the wall before the
        // rapid out touches no new material, so it is not simulated.
      case 810: case 820: case 860: case 880:
        // Drill (G81), with a dwell (G82); boring with a spindle stop and a
        // rapid out (G86) or a manual retract, taken as straight up (G88).
        SWARF_RETURN_IF_ERROR(feed(x, y, bottom));
        break;
      case 740: case 840: case 850: case 890:
        // Tapping (out at the feed, spindle reversed) and boring with a
        // feed out (G85, G89 with a dwell).
        SWARF_RETURN_IF_ERROR(feed(x, y, bottom));
        SWARF_RETURN_IF_ERROR(feed(x, y, r));
        break;
      case 870:
        // Back boring: past the hole offset by I/J, down to Z, centred, up
        // to K at the feed and back down, offset again and out.
        SWARF_RETURN_IF_ERROR(rapid(x + off[0], y + off[1], r));
        SWARF_RETURN_IF_ERROR(rapid(x + off[0], y + off[1], bottom));
        SWARF_RETURN_IF_ERROR(rapid(x, y, bottom));
        SWARF_RETURN_IF_ERROR(feed(x, y, middle));
        SWARF_RETURN_IF_ERROR(feed(x, y, bottom));
        SWARF_RETURN_IF_ERROR(rapid(x + off[0], y + off[1], bottom));
        SWARF_RETURN_IF_ERROR(rapid(x + off[0], y + off[1], clear));
        break;
      default:
        return Err(UnsupportedG(motion_));
    }
    SWARF_RETURN_IF_ERROR(rapid(x, y, clear));
  }
  return absl::OkStatus();
}

// ------------------------------------------------------------ compensation
//
// As LinuxCNC: the tool runs at its radius left (G41) or right (G42) of the
// programmed path in the XY plane. The first move after G41/G42 (the entry,
// a straight line) ends at its programmed end offset perpendicular to it;
// the move after G40 (the exit) starts from the last offset point. At a
// convex corner the tool goes around the corner on an arc of its radius; at
// a concave corner both offset moves end where they meet, and a corner the
// tool cannot reach (a move shorter than the radius needs) is an error
// naming its line. Z follows each move linearly. Each move waits for the
// next to know its corner.

absl::Status Interpreter::CompStart(const Block& b, int code) {
  if (comp_side_ != 0) {
    return Err(absl::StrCat(GName(code),
                            " with cutter compensation already on (G40 "
                            "first)"));
  }
  // The plane's axes, as Arc() orders them (first to second counterclockwise
  // seen from the third's positive side).
  comp_axes_[0] = plane_ == 17 ? 0 : plane_ == 18 ? 2 : 1;
  comp_axes_[1] = plane_ == 17 ? 1 : plane_ == 18 ? 0 : 2;
  comp_axes_[2] = plane_ == 17 ? 2 : plane_ == 18 ? 1 : 0;
  if (known_ != 7) {
    return Err(absl::StrCat(GName(code),
                            " before the position is known (X, Y and Z)"));
  }
  double r;
  if (code == 411 || code == 421) {
    if (!(b.words & Bit('D'))) return Err(GName(code) + " needs D (diameter)");
    r = b.value['D' - 'A'] * scale() / 2;
  } else {
    int tool = tool_;
    if (b.words & Bit('D')) {
      const double d = b.value['D' - 'A'];
      if (!(d >= 0 && d <= 65535) || d != std::floor(d)) {
        return Err(absl::StrCat(GName(code), " D", d,
                                " is not a tool number"));
      }
      tool = static_cast<int>(d);
    }
    std::optional<double> known;
    if (tool == 0) {
      known = 0.0;  // D0: no compensation, as LinuxCNC
    } else if (options_.tool_radius) {
      known = options_.tool_radius(tool);
    }
    if (!known.has_value()) {
      return Err(absl::StrCat(GName(code), ": the radius of tool ", tool,
                              " is unknown (give --tool ", tool, "=...)"));
    }
    r = *known;
  }
  if (!(r >= 0 && r <= 1e4)) {
    return Err(absl::StrCat(GName(code), ": tool radius ", r,
                            " mm is out of range"));
  }
  ++letter_ignored_['D' - 'A'];  // counted: the word has no move of its own
  comp_side_ = code == 410 || code == 411 ? 1 : -1;
  comp_r_ = r;
  comp_entry_ = true;
  comp_pending_ = false;
  ++g_ignored_[code];
  return absl::OkStatus();
}

// An arc as the entry move, as LinuxCNC: it ends offset along the
// programmed arc's radius at its end, on an arc from where the tool is
// whose centre lies on that radius (so the tool leaves it along the
// programmed arc's end direction); a spiral-free arc, so its centre moves.
absl::Status Interpreter::CompArcEntry(CompSeg seg) {
  if (!(seg.tr >= kRadiusTolerance)) {
    return Err(absl::StrCat("arc of radius ", seg.radius,
                            " mm is too small for the compensated tool "
                            "radius ",
                            comp_r_, " mm on its inside"));
  }
  const double sign = seg.sweep > 0 ? 1 : -1;
  const double a1 = std::atan2(seg.e[1] - seg.c[1], seg.e[0] - seg.c[0]);
  seg.te[0] = seg.c[0] + seg.tr * std::cos(a1);
  seg.te[1] = seg.c[1] + seg.tr * std::sin(a1);
  // The new centre: te + t u, u towards the programmed centre, as far from
  // the start as from te.
  const double ux = -std::cos(a1), uy = -std::sin(a1);
  const double dx = seg.te[0] - seg.s[0], dy = seg.te[1] - seg.s[1];
  const double den = 2 * (ux * dx + uy * dy);
  if (!(std::fabs(den) > 1e-9)) {
    return Err("cutter compensation: the entry arc cannot start where the "
               "tool is (it is on the arc's end tangent)");
  }
  const double t = -(dx * dx + dy * dy) / den;
  seg.c[0] = seg.te[0] + t * ux;
  seg.c[1] = seg.te[1] + t * uy;
  seg.tr = std::fabs(t);
  seg.ts[0] = seg.s[0];
  seg.ts[1] = seg.s[1];
  seg.ta = std::atan2(seg.s[1] - seg.c[1], seg.s[0] - seg.c[0]);
  double sweep = std::atan2(seg.te[1] - seg.c[1], seg.te[0] - seg.c[0]) - seg.ta;
  const double whole =
      std::floor((std::fabs(seg.sweep) - 1e-9) / (2 * kPi)) * 2 * kPi;
  // The centre beyond te from the programmed one turns the other way.
  const double rot = t > 0 ? sign : -sign;
  if (rot > 0) {
    while (sweep <= 0) sweep += 2 * kPi;
    sweep += whole;
  } else {
    while (sweep >= 0) sweep -= 2 * kPi;
    sweep -= whole;
  }
  seg.tsweep = sweep;
  seg.dir_s[0] = -std::sin(seg.ta) * rot;
  seg.dir_s[1] = std::cos(seg.ta) * rot;
  // The end tangent is the programmed arc's (the centre is on its radius).
  seg.dir_e[0] = -std::sin(a1) * sign;
  seg.dir_e[1] = std::cos(a1) * sign;
  comp_entry_ = false;
  comp_seg_ = seg;
  comp_pending_ = true;
  return absl::OkStatus();
}

absl::Status Interpreter::CompAdd(CompSeg seg) {
  const double dx = seg.e[0] - seg.s[0], dy = seg.e[1] - seg.s[1];
  const double r = comp_r_ * comp_side_;  // signed: + left
  if (!seg.arc) {
    const double len = std::hypot(dx, dy);
    if (len < 1e-12) {
      // A move along Z only: the tool stays where it is in XY.
      SWARF_RETURN_IF_ERROR(CompFlush());
      double here[2] = {seg.s[0], seg.s[1]};
      if (emitted_) {
        here[0] = last_[comp_axes_[0]];
        here[1] = last_[comp_axes_[1]];
      }
      return EmitPlane(here[0], here[1], seg.e[2], seg.rapid);
    }
    seg.dir_s[0] = seg.dir_e[0] = dx / len;
    seg.dir_s[1] = seg.dir_e[1] = dy / len;
    const double nx = -dy / len * r, ny = dx / len * r;
    seg.ts[0] = seg.s[0] + nx;
    seg.ts[1] = seg.s[1] + ny;
    seg.te[0] = seg.e[0] + nx;
    seg.te[1] = seg.e[1] + ny;
    if (comp_entry_) {
      // The entry: from where the tool is to the offset end.
      seg.entry = true;
      seg.os[0] = seg.ts[0];
      seg.os[1] = seg.ts[1];
      seg.ts[0] = seg.s[0];
      seg.ts[1] = seg.s[1];
    }
  } else {
    const double sign = seg.sweep > 0 ? 1 : -1;
    seg.tr = seg.radius - r * sign;
    if (comp_entry_) return CompArcEntry(seg);
    if (std::fabs(seg.tr) < kRadiusTolerance) {
      // A tool as large as the arc, on its inside: its centre stays on the
      // arc's (LinuxCNC's arc of radius zero; a helix plunges).
      SWARF_RETURN_IF_ERROR(CompFlush());
      comp_entry_ = false;
      return EmitPlane(seg.c[0], seg.c[1], seg.e[2], seg.rapid);
    }
    if (!(seg.tr >= kRadiusTolerance)) {
      return Err(absl::StrCat("arc of radius ", seg.radius,
                              " mm is too small for the compensated tool "
                              "radius ",
                              comp_r_, " mm on its inside"));
    }
    seg.ta = std::atan2(seg.s[1] - seg.c[1], seg.s[0] - seg.c[0]);
    seg.tsweep = seg.sweep;
    const double a1 = seg.ta + seg.sweep;
    seg.ts[0] = seg.c[0] + seg.tr * std::cos(seg.ta);
    seg.ts[1] = seg.c[1] + seg.tr * std::sin(seg.ta);
    seg.te[0] = seg.c[0] + seg.tr * std::cos(a1);
    seg.te[1] = seg.c[1] + seg.tr * std::sin(a1);
    seg.dir_s[0] = -std::sin(seg.ta) * sign;
    seg.dir_s[1] = std::cos(seg.ta) * sign;
    seg.dir_e[0] = -std::sin(a1) * sign;
    seg.dir_e[1] = std::cos(a1) * sign;
  }
  comp_entry_ = false;
  if (comp_pending_) {
    SWARF_RETURN_IF_ERROR(CompJoin(&comp_seg_, &seg));
  }
  comp_seg_ = seg;
  comp_pending_ = true;
  return absl::OkStatus();
}

// Intersections of the tool paths of a and b near the corner: lines as
// infinite lines, arcs as circles.
int Intersect(const CompSeg& a, const CompSeg& b, double out[2][2]) {
  if (!a.arc && !b.arc) {
    const double* as = a.LineStart();
    const double ux = a.te[0] - as[0], uy = a.te[1] - as[1];
    const double vx = b.te[0] - b.ts[0], vy = b.te[1] - b.ts[1];
    const double den = ux * vy - uy * vx;
    if (std::fabs(den) < 1e-300) return 0;
    const double t =
        ((b.ts[0] - as[0]) * vy - (b.ts[1] - as[1]) * vx) / den;
    out[0][0] = as[0] + t * ux;
    out[0][1] = as[1] + t * uy;
    return 1;
  }
  // A circle (c, r) against a line (p, d) or a circle.
  const CompSeg& circ = a.arc ? a : b;
  const CompSeg& other = a.arc ? b : a;
  if (!other.arc) {
    const double* os = other.LineStart();
    const double dx = other.te[0] - os[0], dy = other.te[1] - os[1];
    const double len = std::hypot(dx, dy);
    const double ux = dx / len, uy = dy / len;
    const double fx = os[0] - circ.c[0], fy = os[1] - circ.c[1];
    const double bq = fx * ux + fy * uy;
    const double cq = fx * fx + fy * fy - circ.tr * circ.tr;
    const double disc = bq * bq - cq;
    if (disc < 0) return 0;
    const double sq = std::sqrt(disc);
    for (int k = 0; k < 2; ++k) {
      const double t = -bq + (k == 0 ? -sq : sq);
      out[k][0] = os[0] + t * ux;
      out[k][1] = os[1] + t * uy;
    }
    return 2;
  }
  const double dx = b.c[0] - a.c[0], dy = b.c[1] - a.c[1];
  const double d = std::hypot(dx, dy);
  if (d < 1e-12 || d > a.tr + b.tr || d < std::fabs(a.tr - b.tr)) return 0;
  const double l = (a.tr * a.tr - b.tr * b.tr + d * d) / (2 * d);
  const double h = std::sqrt(std::max(0.0, a.tr * a.tr - l * l));
  const double mx = a.c[0] + l * dx / d, my = a.c[1] + l * dy / d;
  out[0][0] = mx - h * dy / d;
  out[0][1] = my + h * dx / d;
  out[1][0] = mx + h * dy / d;
  out[1][1] = my - h * dx / d;
  return 2;
}

// Where p lies along a segment's tool path: 0 at its start, 1 at its end
// (lines: the parameter; arcs: the fraction of the sweep). On an entry
// line, `offset_line` measures along its offset line instead.
double Along(const CompSeg& s, const double p[2], bool offset_line = false) {
  if (!s.arc) {
    const double* st = offset_line ? s.LineStart() : s.ts;
    const double ux = s.te[0] - st[0], uy = s.te[1] - st[1];
    const double len2 = ux * ux + uy * uy;
    return len2 > 0 ? ((p[0] - st[0]) * ux + (p[1] - st[1]) * uy) / len2
                    : 0;
  }
  double a = std::atan2(p[1] - s.c[1], p[0] - s.c[0]) - s.ta;
  // Into the sweep's direction, [0, 2 pi).
  if (s.tsweep > 0) {
    a = std::fmod(a, 2 * kPi);
    if (a < 0) a += 2 * kPi;
  } else {
    a = std::fmod(-a, 2 * kPi);
    if (a < 0) a += 2 * kPi;
  }
  return a / std::fabs(s.tsweep);
}

absl::Status Interpreter::CompJoin(CompSeg* a, CompSeg* b) {
  const double cross = a->dir_e[0] * b->dir_s[1] - a->dir_e[1] * b->dir_s[0];
  const double dot = a->dir_e[0] * b->dir_s[0] + a->dir_e[1] * b->dir_s[1];
  const double gap = std::hypot(b->ts[0] - a->te[0], b->ts[1] - a->te[1]);
  if (gap < 1e-9 || (std::fabs(cross) < 1e-9 && dot > 0)) {
    return CompEmit(*a);  // tangent
  }
  if (comp_side_ * cross < 0 || (std::fabs(cross) < 1e-9 && dot < 0)) {
    // Convex: around the corner on an arc of the tool's radius.
    SWARF_RETURN_IF_ERROR(CompEmit(*a));
    const double px = a->e[0], py = a->e[1];
    const double a0 = std::atan2(a->te[1] - py, a->te[0] - px);
    const double a1 = std::atan2(b->ts[1] - py, b->ts[0] - px);
    double sweep = a1 - a0;
    if (comp_side_ > 0) {
      while (sweep > 0) sweep -= 2 * kPi;
    } else {
      while (sweep < 0) sweep += 2 * kPi;
    }
    const double end[3] = {b->ts[0], b->ts[1], a->e[2]};
    emit_line_ = b->line;  // the corner belongs to the move after it
    absl::Status st = ChordPlaneArc(px, py, comp_r_, a0, sweep, a->e[2], end,
                                    b->rapid);
    emit_line_ = -1;
    return st;
  }
  // Concave: both end where they meet, nearest the corner.
  double x[2][2];
  const int n = Intersect(*a, *b, x);
  int best = -1;
  double best_d = INFINITY;
  for (int k = 0; k < n; ++k) {
    const double ta = Along(*a, x[k], true), tb = Along(*b, x[k]);
    if (!(ta >= -1e-9 && ta <= 1 + 1e-9 && tb >= -1e-9 && tb <= 1 + 1e-9)) {
      continue;
    }
    const double d = std::hypot(x[k][0] - a->e[0], x[k][1] - a->e[1]);
    if (d < best_d) {
      best_d = d;
      best = k;
    }
  }
  if (best < 0 && dot > 0 && std::fabs(cross) < kNearlyTangent) {
    // Tangent but for rounding (a line into an arc with coordinates of
    // a few decimals): no corner to cut, as LinuxCNC.
    return CompEmit(*a);
  }
  if (best < 0) {
    return LineError(b->line,
                     absl::StrCat("cutter compensation: the tool (radius ",
                                  comp_r_,
                                  " mm) cannot reach the concave corner "
                                  "between line ",
                                  a->line, " and this one"));
  }
  const double* p = x[best];
  const double fa = std::clamp(Along(*a, p), 0.0, 1.0);
  const double fb = std::clamp(Along(*b, p), 0.0, 1.0);
  a->te[0] = p[0];
  a->te[1] = p[1];
  a->e[2] = a->s[2] + (a->e[2] - a->s[2]) * fa;
  if (a->arc) a->tsweep *= fa;
  b->ts[0] = p[0];
  b->ts[1] = p[1];
  if (b->arc) {
    b->ta += b->tsweep * fb;
    b->tsweep *= 1 - fb;
  }
  return CompEmit(*a);
}

// Emits a move's tool path; its points carry the move's line (it is
// emitted when the next move, on a later line, is known).
absl::Status Interpreter::CompEmit(const CompSeg& seg) {
  emit_line_ = seg.line;
  absl::Status st;
  if (!seg.arc) {
    st = EmitPlane(seg.te[0], seg.te[1], seg.e[2], seg.rapid);
  } else {
    const double end[3] = {seg.te[0], seg.te[1], seg.e[2]};
    const double z0 = emitted_ ? last_[comp_axes_[2]] : seg.s[2];
    st = ChordPlaneArc(seg.c[0], seg.c[1], seg.tr, seg.ta, seg.tsweep, z0,
                       end, seg.rapid);
  }
  emit_line_ = -1;
  return st;
}

absl::Status Interpreter::CompFlush() {
  if (!comp_pending_) return absl::OkStatus();
  comp_pending_ = false;
  return CompEmit(comp_seg_);
}

}  // namespace

absl::StatusOr<Toolpath> ParseGcode(std::string_view text,
                                    const GcodeOptions& options,
                                    CanonSink* sink) {
  Interpreter interpreter(options, sink);
  return interpreter.Run(text);
}

}  // namespace swarf::gcode
