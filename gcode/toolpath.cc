#include "gcode/toolpath.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numbers>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/status_macros.h"

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

constexpr uint32_t Bit(char letter) { return uint32_t{1} << (letter - 'A'); }
constexpr uint32_t kAxisWords = Bit('X') | Bit('Y') | Bit('Z');
constexpr uint32_t kArcWords = Bit('I') | Bit('J') | Bit('K') | Bit('R');
// Words that never move the tool: feed, speed, length and radius offset
// numbers, cycle parameters, repeat counts.
constexpr uint32_t kIgnoredLetters =
    Bit('F') | Bit('S') | Bit('H') | Bit('D') | Bit('Q') | Bit('L');
constexpr char kAxisName[3] = {'X', 'Y', 'Z'};

// G-codes are kept as integers x10 (G90.1 -> 901).
constexpr int32_t kGCodeLimit = 10000;
constexpr int32_t kMCodeCounted = 1000;  // larger M codes: counted in a map
constexpr int kMaxCodesPerLine = 32;

inline bool IsBlank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v';
}
inline bool IsDigit(char c) { return c >= '0' && c <= '9'; }

const char* SkipBlanks(const char* p, const char* end) {
  while (p < end && IsBlank(*p)) ++p;
  return p;
}

const char* SkipBom(const char* p, const char* end) {
  if (end - p >= 3 && std::memcmp(p, "\xEF\xBB\xBF", 3) == 0) return p + 3;
  return p;
}

absl::Status LineError(int64_t line, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat("line ", line, ": ", what));
}

std::string CharName(char c) {
  const auto u = static_cast<unsigned char>(c);
  if (u >= 0x21 && u < 0x7F) return std::string("'") + c + "'";
  char buf[16];
  std::snprintf(buf, sizeof buf, "byte 0x%02X", u);
  return buf;
}

std::string GName(int32_t code10) {
  return code10 % 10 == 0 ? absl::StrCat("G", code10 / 10)
                          : absl::StrCat("G", code10 / 10, ".", code10 % 10);
}

// A G-code number: [+-] digits [. digits] with at least one digit; blanks
// may separate it from its letter. No exponent: E is a word in G-code.
// Returns the end of the number, or null when there is none.
const char* ScanNumber(const char* p, const char* end, double* out) {
  while (p < end && (*p == ' ' || *p == '\t')) ++p;
  bool negative = false;
  if (p < end && (*p == '+' || *p == '-')) {
    negative = *p == '-';
    ++p;
  }
  const char* first = p;
  while (p < end && IsDigit(*p)) ++p;
  bool digits = p != first;
  if (p < end && *p == '.') {
    const char* frac = ++p;
    while (p < end && IsDigit(*p)) ++p;
    digits = digits || p != frac;
  }
  if (!digits) return nullptr;
  // from_chars: no locale, no allocation, correctly rounded (fast_float in
  // libstdc++ 12); it rejects a leading '+', hence the sign is ours.
  const auto r = std::from_chars(first, p, *out, std::chars_format::fixed);
  if (r.ec == std::errc::result_out_of_range) {
    // Too large for a double when the integer part isn't zero (every user
    // of a value range-checks it, so an infinity makes the right error);
    // else too small: zero.
    bool large = false;
    for (const char* d = first; d < p && *d != '.'; ++d) large |= *d != '0';
    *out = large ? std::numeric_limits<double>::infinity() : 0.0;
    if (negative) *out = -*out;
    return p;
  }
  if (r.ec != std::errc() || r.ptr != p) return nullptr;
  if (negative) *out = -*out;
  return p;
}

// True when [p, end) holds only blanks and comments.
bool OnlyComments(const char* p, const char* end) {
  for (p = SkipBlanks(p, end); p < end; p = SkipBlanks(p, end)) {
    if (*p == ';') return true;
    if (*p != '(') return false;
    const void* close = std::memchr(p, ')', end - p);
    if (close == nullptr) return false;
    p = static_cast<const char*>(close) + 1;
  }
  return true;
}

// The words of one line.
struct Block {
  uint32_t words = 0;  // Bit(letter) of each word other than G, M, N, O
  double value[26];
  int ng = 0;
  int32_t g[kMaxCodesPerLine];  // x10
  int nm = 0;
  int32_t m[kMaxCodesPerLine];
  bool block_delete = false;
  bool program_number = false;

  bool empty() const {
    return words == 0 && ng == 0 && nm == 0 && !program_number;
  }
};

// Splits [p, end) (one line, without its '\n') into words.
absl::Status ScanLine(const char* p, const char* end, int64_t line, Block* b) {
  b->words = 0;
  b->ng = b->nm = 0;
  b->block_delete = false;
  b->program_number = false;
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
      if (close == nullptr) return LineError(line, "comment '(' is not closed");
      p = static_cast<const char*>(close) + 1;
      continue;
    }
    if (c == ';') break;
    const char letter = static_cast<char>(c & ~0x20);  // upper case
    if (letter < 'A' || letter > 'Z') {
      switch (c) {
        case '#':
          return LineError(line, "parameters ('#') are not supported");
        case '[':
          return LineError(line, "expressions ('[') are not supported");
        case '%':
          return LineError(line, "'%' must be alone on its line");
        default:
          return LineError(line, absl::StrCat("unexpected ", CharName(c),
                                              " (expected a word letter)"));
      }
    }
    ++p;
    if (letter == 'O') {
      // A Fanuc program number ("O1234 (NAME)") is ignored; O-word control
      // flow (LinuxCNC "o100 sub", "o101 if [...]") is not supported.
      double v;
      const char* q = ScanNumber(p, end, &v);
      if (q == nullptr || !OnlyComments(q, end)) {
        return LineError(line,
                         "O-word control flow (subroutines, loops, "
                         "conditions) is not supported");
      }
      b->program_number = true;
      break;
    }
    double v;
    const char* q = ScanNumber(p, end, &v);
    if (q == nullptr) {
      const char* next = SkipBlanks(p, end);
      if (next < end && *next == '[') {
        return LineError(line, "expressions ('[') are not supported");
      }
      if (next < end && *next == '#') {
        return LineError(line, "parameters ('#') are not supported");
      }
      return LineError(
          line, absl::StrCat(std::string(1, letter), " word has no number"));
    }
    if (q < end && *q == '.') {
      return LineError(line, absl::StrCat("malformed number in ",
                                          std::string(1, letter), " word"));
    }
    p = q;
    switch (letter) {
      case 'G': {
        const double t = v * 10;
        const double r = std::round(t);
        if (!(v >= 0 && r < kGCodeLimit) || std::fabs(t - r) > 1e-6) {
          return LineError(line, absl::StrCat("G", v, " is not a G-code"));
        }
        if (b->ng == kMaxCodesPerLine) {
          return LineError(line, "too many G-codes on one line");
        }
        b->g[b->ng++] = static_cast<int32_t>(r);
        break;
      }
      case 'M':
        if (!(v >= 0 && v < 1e6) || v != std::floor(v)) {
          return LineError(line, absl::StrCat("M", v, " is not an M-code"));
        }
        if (b->nm == kMaxCodesPerLine) {
          return LineError(line, "too many M-codes on one line");
        }
        b->m[b->nm++] = static_cast<int32_t>(v);
        break;
      case 'N':  // line label
        break;
      case 'A':
      case 'B':
      case 'C':
      case 'U':
      case 'V':
      case 'W':
        return LineError(line, absl::StrCat(std::string(1, letter),
                                            " axis words are not supported "
                                            "(3-axis: X, Y, Z only)"));
      case 'E':
        return LineError(line, "E words are not supported");
      default: {
        const uint32_t bit = Bit(letter);
        if (b->words & bit) {
          return LineError(line, absl::StrCat("two ", std::string(1, letter),
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

// Why a G-code we don't simulate is refused.
std::string UnsupportedG(int32_t c) {
  const std::string g = GName(c);
  // clang-format off
  switch (c) {
    case 280: case 281: case 300: case 301:
      return g + " (move to a home position) is not supported: the home "
                 "position is unknown";
    case 410: case 411: case 420: case 421:
      return g + " (cutter radius compensation) is not supported: the path "
                 "would depend on the tool radius";
    case 730: case 740: case 760: case 810: case 820: case 830: case 840:
    case 850: case 860: case 870: case 880: case 890:
      return g + " (canned cycle) is not supported";
    case 520: case 920: case 923:
      return g + " (coordinate offset) is not supported: it would shift the "
                 "path";
    case 530:
      return g + " (machine coordinates) is not supported: the work offset "
                 "is unknown";
    case 100:
      return g + " (setting offsets or tool data) is not supported";
    case 50: case 51: case 52: case 53:
      return g + " (spline) is not supported";
    case 330: case 331:
      return g + " (threading) is not supported";
    case 382: case 383: case 384: case 385:
      return g + " (probing) is not supported";
    case 431: case 432:
      return g + " (dynamic tool length offset) is not supported";
    case 510: case 511:
      return g + " (scaling or mirroring) is not supported";
    case 680:
      return g + " (coordinate rotation) is not supported";
    case 160:
      return g + " (polar coordinates) is not supported";
    case 70:
      return g + " (lathe diameter mode) is not supported";
    case 171: case 181: case 191:
      return g + " (UVW plane) is not supported";
    case 650: case 660:
      return g + " (macro call) is not supported";
    default:
      return "unsupported G-code " + g;
  }
  // clang-format on
}

class GcodeParser {
 public:
  explicit GcodeParser(const GcodeOptions& options)
      : options_(options), g_ignored_(kGCodeLimit), m_ignored_(kMCodeCounted) {}

  absl::StatusOr<Toolpath> Parse(std::string_view text);

 private:
  absl::Status Execute(const Block& b, int64_t line);
  absl::Status ApplyGCodes(const Block& b, int64_t line, int* new_motion);
  absl::Status SelectWorkOffset(int32_t code, int64_t line);
  void ToolChange();
  absl::Status EndPoint(const Block& b, int64_t line, double end[3]);
  absl::Status Linear(const Block& b, int64_t line);
  absl::Status Arc(const Block& b, int64_t line);
  absl::Status Emit(double x, double y, double z, bool rapid, int64_t line);
  double scale() const { return inches_ ? kMmPerInch : 1.0; }
  void FinishCounts();

  const GcodeOptions options_;
  Toolpath path_;

  // Modal state.
  double pos_[3] = {0, 0, 0};  // mm; meaningful where known_ has the bit
  unsigned known_ = 0;         // bit a: axis a known
  bool in_run_ = false;        // a point of the current run was emitted
  int motion_ = -1;            // 0..3 for G0..G3; -1: none yet
  bool inches_ = false;
  bool units_declared_ = false;
  bool incremental_ = false;   // G91
  bool arc_absolute_ = false;  // G90.1
  int plane_ = 17;
  int32_t work_offset_ = 0;  // first G54..G59.3 selected (x10); 0: none
  bool moved_ = false;       // an axis word has been executed
  int32_t last_t_ = -1;
  bool had_m6_ = false;
  uint16_t tool_ = 0;
  bool ended_ = false;  // M2 / M30

  // Ignored words, counted in flat arrays (a map lookup per word would
  // dominate the parse) and moved into the Toolpath at the end.
  std::vector<int64_t> g_ignored_;
  std::vector<int64_t> m_ignored_;
  int64_t letter_ignored_[26] = {};
  int64_t block_deletes_ = 0;
  int64_t program_numbers_ = 0;
};

absl::StatusOr<Toolpath> GcodeParser::Parse(std::string_view text) {
  if (!(options_.arc_tolerance >= 1e-6 && options_.arc_tolerance <= 10)) {
    return absl::InvalidArgumentError(
        absl::StrCat("arc tolerance must be in [1e-6, 10] mm, got ",
                     options_.arc_tolerance));
  }
  if (options_.max_points < 1) {
    return absl::InvalidArgumentError(
        absl::StrCat("max_points must be positive, got ", options_.max_points));
  }
  const char* p = SkipBom(text.data(), text.data() + text.size());
  const char* const end = text.data() + text.size();
  // A guess at the point count (~16 bytes per line); the vector grows past.
  path_.Reserve(std::min<int64_t>(text.size() / 16, options_.max_points));

  Block block;
  int64_t line = 0;
  bool seen_content = false;   // a non-blank line was read
  bool percent_start = false;  // the program starts with '%'
  int64_t end_line = 0;        // where reading stopped early (M2/M30, '%')
  while (p < end) {
    ++line;
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
    if (eol == nullptr) eol = end;
    const char* q = SkipBlanks(p, eol);
    p = eol < end ? eol + 1 : end;
    if (q == eol) continue;
    if (*q == '%') {
      if (!OnlyComments(q + 1, eol)) {
        return LineError(line, "'%' must be alone on its line");
      }
      // As LinuxCNC: a program that starts with '%' ends at the next one.
      if (!seen_content) {
        percent_start = true;
      } else if (percent_start) {
        end_line = line;
        break;
      }
      seen_content = true;
      continue;
    }
    seen_content = true;
    SWARF_RETURN_IF_ERROR(ScanLine(q, eol, line, &block));
    if (block.empty()) {
      if (block.block_delete) ++block_deletes_;
      continue;
    }
    if (line > std::numeric_limits<int32_t>::max()) {
      return LineError(line, "too many lines");
    }
    SWARF_RETURN_IF_ERROR(Execute(block, line));
    if (ended_) {
      end_line = line;
      break;
    }
  }
  path_.set_source_lines(line);
  if (end_line > 0) {
    // Say so when something that looks like program text was not read.
    int64_t unread = 0;
    for (; p < end;) {
      const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
      if (eol == nullptr) eol = end;
      const char* q = SkipBlanks(p, eol);
      if (q < eol && *q != '%' && !OnlyComments(q, eol)) ++unread;
      p = eol < end ? eol + 1 : end;
    }
    if (unread > 0) {
      path_.AddNote(absl::StrCat("the program ends on line ", end_line, "; ",
                                 unread, " lines after it were not read"));
    }
  }
  FinishCounts();
  path_.Trim();  // the reserve above was a guess
  return std::move(path_);
}

void GcodeParser::FinishCounts() {
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
}

// In LinuxCNC's order of execution within a line: feeds, speeds, tool
// select, tool change, plane, units, ..., distance mode, motion, stop.
absl::Status GcodeParser::Execute(const Block& b, int64_t line) {
  if (b.program_number) {
    if (moved_) {
      return LineError(line,
                       "O-word after motion (a subprogram) is not supported");
    }
    ++program_numbers_;
  }
  if (b.block_delete) ++block_deletes_;
  for (uint32_t w = b.words & kIgnoredLetters; w != 0; w &= w - 1) {
    ++letter_ignored_[__builtin_ctz(w)];
  }

  int new_motion = -1;
  if (b.ng > 0) SWARF_RETURN_IF_ERROR(ApplyGCodes(b, line, &new_motion));

  if (b.words & Bit('T')) {
    const double t = b.value['T' - 'A'];
    if (!(t >= 0 && t <= 65535) || t != std::floor(t)) {
      return LineError(line,
                       absl::StrCat("T", t, " is not a tool number (0-65535)"));
    }
    last_t_ = static_cast<int32_t>(t);
    if (!had_m6_) tool_ = static_cast<uint16_t>(last_t_);
  }
  bool m6 = false;
  for (int i = 0; i < b.nm; ++i) {
    const int32_t m = b.m[i];
    switch (m) {
      case 6:
        m6 = true;
        break;
      case 2:
      case 30:
        ended_ = true;
        break;
      case 98:
      case 99:
        return LineError(line, absl::StrCat("M", m,
                                            " (subprogram call or return) "
                                            "is not supported"));
      default:
        // Spindle, coolant, stops, I/O, machine-specific codes: no tip motion.
        if (m < kMCodeCounted) {
          ++m_ignored_[m];
        } else {
          path_.CountIgnored(absl::StrCat("M", m));
        }
    }
  }
  if (m6) ToolChange();
  if (new_motion >= 0) motion_ = new_motion;

  const uint32_t axes = b.words & kAxisWords;
  const uint32_t arc_words = b.words & kArcWords;
  bool p_used = false;
  if (axes != 0 || arc_words != 0) {
    if (motion_ < 0) {
      return LineError(line,
                       "axis words with no motion mode (G0, G1, G2, G3) in "
                       "effect");
    }
    if (motion_ >= 2) {
      SWARF_RETURN_IF_ERROR(Arc(b, line));
      p_used = true;
    } else {
      if (arc_words != 0) {
        const char w = static_cast<char>('A' + __builtin_ctz(arc_words));
        return LineError(
            line, absl::StrCat(std::string(1, w), " word without a G2/G3 arc"));
      }
      SWARF_RETURN_IF_ERROR(Linear(b, line));
    }
    if (axes != 0) moved_ = true;
  }
  if (!p_used && (b.words & Bit('P'))) ++letter_ignored_['P' - 'A'];
  return absl::OkStatus();
}

absl::Status GcodeParser::ApplyGCodes(const Block& b, int64_t line,
                                      int* new_motion) {
  // Two codes of one modal group on a line contradict each other.
  enum Group { kMotion, kPlane, kUnits, kDistance, kArcDistance, kOffset, kN };
  int32_t group_code[kN] = {-1, -1, -1, -1, -1, -1};
  for (int i = 0; i < b.ng; ++i) {
    const int32_t c = b.g[i];
    Group group = kN;
    // clang-format off
    switch (c) {
      case 0: case 10: case 20: case 30:
        group = kMotion;
        *new_motion = c / 10;
        break;
      case 170: case 180: case 190:
        // State only: a G18/G19 arc is refused when it comes.
        group = kPlane;
        plane_ = c / 10;
        ++g_ignored_[c];
        break;
      case 200: case 210:
        group = kUnits;
        inches_ = c == 200;
        units_declared_ = true;
        break;
      case 900: case 910:
        group = kDistance;
        incremental_ = c == 910;
        break;
      case 901: case 911:
        group = kArcDistance;
        arc_absolute_ = c == 901;
        break;
      case 540: case 550: case 560: case 570: case 580: case 590:
      case 591: case 592: case 593:
        group = kOffset;
        SWARF_RETURN_IF_ERROR(SelectWorkOffset(c, line));
        ++g_ignored_[c];
        break;
      // State that doesn't move the tip. G43/G49: positions are the tool
      // tip by this project's convention, so tool length offsets change
      // nothing. G40, G50, G50.1, G69, G15, G92.1/2: cancel features we
      // refuse anyway.
      case 40:   // dwell
      case 80:   // lathe radius mode
      case 150:  // polar coordinates off
      case 400:  // cutter compensation off
      case 430:  // tool length offset
      case 490:  // tool length offset off
      case 500: case 501:  // scaling / mirroring off
      case 610: case 611: case 640:  // exact stop / blending
      case 690:  // rotation off
      case 800:  // canned cycle off
      case 921: case 922:  // G92 offsets off
      case 930: case 940: case 950:  // feed modes
      case 960: case 970:  // spindle speed modes
      case 980: case 990:  // canned cycle retract modes
        ++g_ignored_[c];
        break;
      default:
        return LineError(line, UnsupportedG(c));
    }
    // clang-format on
    if (group != kN) {
      if (group_code[group] >= 0) {
        return LineError(
            line, absl::StrCat(GName(group_code[group]), " and ", GName(c),
                               " on one line contradict each "
                               "other"));
      }
      group_code[group] = c;
    }
  }
  return absl::OkStatus();
}

// All work offsets are unknown, so only one may be used: positions are
// relative to it. Moves before any selection are in the default G54.
absl::Status GcodeParser::SelectWorkOffset(int32_t code, int64_t line) {
  const int32_t current = work_offset_ != 0 ? work_offset_ : moved_ ? 540 : 0;
  if (current != 0 && code != current) {
    return LineError(
        line, absl::StrCat(GName(code), " switches the work offset from ",
                           GName(current),
                           ": offsets are unknown, so the path "
                           "would shift by an unknown amount"));
  }
  work_offset_ = code;
  return absl::OkStatus();
}

// The machine may travel to a tool-change position: every axis becomes
// unknown and the next known position starts a new run.
void GcodeParser::ToolChange() {
  if (last_t_ >= 0) tool_ = static_cast<uint16_t>(last_t_);
  had_m6_ = true;
  known_ = 0;
  in_run_ = false;
}

// The programmed end of a move: axis words in the current units and
// distance mode, absent axes unchanged.
absl::Status GcodeParser::EndPoint(const Block& b, int64_t line,
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
    if (incremental_) {
      if (!(known_ & (1u << a))) {
        return LineError(
            line,
            absl::StrCat("incremental (G91) ", std::string(1, name),
                         " move while ", std::string(1, name), " is unknown"));
      }
      v += pos_[a];
    }
    if (!(std::fabs(v) <= kMaxCoordinateMm)) {
      return LineError(line, absl::StrCat(std::string(1, name), " position ", v,
                                          " mm is out of range"));
    }
    end[a] = v;
  }
  return absl::OkStatus();
}

absl::Status GcodeParser::Linear(const Block& b, int64_t line) {
  double end[3];
  SWARF_RETURN_IF_ERROR(EndPoint(b, line, end));
  for (int a = 0; a < 3; ++a) {
    if (b.words & Bit(kAxisName[a])) known_ |= 1u << a;
    pos_[a] = end[a];
  }
  // Until X, Y and Z are all known a move only sets the known axes.
  if (known_ != 7) return absl::OkStatus();
  return Emit(end[0], end[1], end[2], motion_ == 0, line);
}

absl::Status GcodeParser::Emit(double x, double y, double z, bool rapid,
                               int64_t line) {
  if (path_.point_count() >= options_.max_points) {
    return LineError(line, absl::StrCat("more than ", options_.max_points,
                                        " points (max_points)"));
  }
  ToolpathPoint p;
  p.position = {x, y, z};
  p.line = static_cast<int32_t>(line);
  p.tool = tool_;
  p.rapid = rapid;
  p.starts_run = !in_run_;
  in_run_ = true;
  path_.Append(p);
  return absl::OkStatus();
}

absl::Status GcodeParser::Arc(const Block& b, int64_t line) {
  const char* gname = motion_ == 2 ? "G2" : "G3";
  const bool cw = motion_ == 2;
  if (plane_ != 17) {
    return LineError(line, absl::StrCat(gname, " arc in the ",
                                        plane_ == 18 ? "XZ (G18)" : "YZ (G19)",
                                        " plane is not supported: only XY "
                                        "(G17) arcs"));
  }
  if (b.words & Bit('K')) {
    return LineError(
        line, absl::StrCat("K word in an XY-plane (G17) ", gname, " arc"));
  }
  if (!in_run_) {
    return LineError(line, absl::StrCat(gname,
                                        " arc before the start position is "
                                        "known (X, Y and Z must all be given "
                                        "first)"));
  }
  const bool has_ij = b.words & (Bit('I') | Bit('J'));
  const bool has_r = b.words & Bit('R');
  if (has_ij && has_r) {
    return LineError(line, absl::StrCat(gname, " arc with both I/J and R"));
  }
  if (!has_ij && !has_r) {
    return LineError(line, absl::StrCat(gname, " arc without I/J or R"));
  }
  int64_t turns = 1;
  if (b.words & Bit('P')) {
    const double pv = b.value['P' - 'A'];
    if (!(pv >= 1 && pv <= 10000) || pv != std::floor(pv)) {
      return LineError(line, absl::StrCat("P", pv, " in a ", gname,
                                          " arc is not a turn count (1, 2, "
                                          "...)"));
    }
    turns = static_cast<int64_t>(pv);
  }
  double end[3];
  SWARF_RETURN_IF_ERROR(EndPoint(b, line, end));
  const double s = scale();
  for (const char w : {'I', 'J', 'R'}) {
    if ((b.words & Bit(w)) &&
        !(std::fabs(b.value[w - 'A'] * s) <= kMaxCoordinateMm)) {
      return LineError(
          line, absl::StrCat(std::string(1, w), " value ", b.value[w - 'A'],
                             " is out of range"));
    }
  }
  const double x0 = pos_[0], y0 = pos_[1], z0 = pos_[2];
  const double x1 = end[0], y1 = end[1], z1 = end[2];

  double cx, cy;
  if (has_r) {
    const double r = b.value['R' - 'A'] * s;
    if (x1 == x0 && y1 == y0) {
      return LineError(line, absl::StrCat(gname,
                                          " full circle with R: the centre "
                                          "is undefined (use I/J)"));
    }
    const double dx = x1 - x0, dy = y1 - y0;
    const double d = std::hypot(dx, dy);
    const double half = d / 2, ar = std::fabs(r);
    if (half - ar > kRadiusTolerance) {
      return LineError(line,
                       absl::StrCat("R", b.value['R' - 'A'], " in ", gname,
                                    " is too small to reach the end "
                                    "point (half the chord is ",
                                    half, " mm)"));
    }
    const double h = half >= ar ? 0.0 : std::sqrt(ar * ar - half * half);
    // The centre is on the chord's bisector, left of the chord's direction
    // for a G3 short arc (R > 0) or a G2 long arc (R < 0), right otherwise.
    const double side = (!cw) == (r > 0) ? 1.0 : -1.0;
    cx = (x0 + x1) / 2 - side * h * dy / d;
    cy = (y0 + y1) / 2 + side * h * dx / d;
  } else {
    const double i = (b.words & Bit('I')) ? b.value['I' - 'A'] * s : 0.0;
    const double j = (b.words & Bit('J')) ? b.value['J' - 'A'] * s : 0.0;
    cx = arc_absolute_ ? i : x0 + i;
    cy = arc_absolute_ ? j : y0 + j;
  }
  const double r0 = std::hypot(x0 - cx, y0 - cy);
  const double r1 = std::hypot(x1 - cx, y1 - cy);
  if (!(r0 >= kRadiusTolerance && r1 >= kRadiusTolerance)) {
    return LineError(line,
                     absl::StrCat(gname, " arc has a zero radius (", r0,
                                  " mm at the start, ", r1, " mm at the end)"));
  }
  const double err = std::fabs(r1 - r0);
  if (err > kSpiralAbsMax ||
      (err > kSpiralAbsFloor && err > kSpiralRel * std::max(r0, r1))) {
    return LineError(line,
                     absl::StrCat(gname, " arc: the radius to the end (", r1,
                                  " mm) differs from the radius to the "
                                  "start (",
                                  r0, " mm) by ", err, " mm"));
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
  // Chords of angle `step` deviate from the arc by the sagitta
  // r (1 - cos(step / 2)) = 2 r sin^2(step / 4) <= tolerance; asin form for
  // accuracy when tolerance << r. At most a quarter turn per chord.
  const double q = options_.arc_tolerance / (2 * std::max(r0, r1));
  const double step =
      q >= 0.5 ? kPi / 2 : std::min(kPi / 2, 4 * std::asin(std::sqrt(q)));
  const double segments = std::ceil(std::fabs(sweep) / step);
  if (!(segments <=
        static_cast<double>(options_.max_points - path_.point_count()))) {
    return LineError(line, absl::StrCat(gname, " arc needs ", segments,
                                        " points: more than max_points (",
                                        options_.max_points, ")"));
  }
  const int64_t n = std::max<int64_t>(1, static_cast<int64_t>(segments));
  for (int64_t k = 1; k < n; ++k) {
    const double t = static_cast<double>(k) / static_cast<double>(n);
    const double a = a0 + sweep * t;
    const double r = r0 + (r1 - r0) * t;  // spiral when r1 != r0
    const double x = cx + r * std::cos(a), y = cy + r * std::sin(a);
    // The arc may bulge past the bound its end points keep.
    if (!(std::fabs(x) <= kMaxCoordinateMm &&
          std::fabs(y) <= kMaxCoordinateMm)) {
      return LineError(line, absl::StrCat(gname, " arc leaves the range of +-",
                                          kMaxCoordinateMm, " mm at (", x,
                                          ", ", y, ")"));
    }
    SWARF_RETURN_IF_ERROR(Emit(x, y, z0 + (z1 - z0) * t, false, line));
  }
  // The programmed end, exactly.
  SWARF_RETURN_IF_ERROR(Emit(x1, y1, z1, false, line));
  pos_[0] = x1;
  pos_[1] = y1;
  pos_[2] = z1;
  return absl::OkStatus();
}

// The rank of an ignored word in the summary: G-codes, M-codes (by number),
// other letters, then the rest.
struct WordKey {
  int rank;
  double number;
  const std::string* word;
};

WordKey KeyOf(const std::string& w) {
  const char c = w.empty() ? 0 : w[0];
  int rank = c == 'G' ? 0 : c == 'M' ? 1 : (c >= 'A' && c <= 'Z') ? 2 : 3;
  double number = 0;
  if (rank < 2 && w.size() > 1) {
    std::from_chars(w.data() + 1, w.data() + w.size(), number);
  }
  return {rank, number, &w};
}

}  // namespace

void Toolpath::Append(const ToolpathPoint& p) {
  ToolpathPoint pt = p;
  if (points_.empty()) {
    pt.starts_run = true;
    x_bounds_ = {pt.position.x, pt.position.x};
    y_bounds_ = {pt.position.y, pt.position.y};
    z_bounds_ = {pt.position.z, pt.position.z};
  } else {
    const Vec3& last = points_.back().position;
    if (!pt.starts_run && last.x == pt.position.x && last.y == pt.position.y &&
        last.z == pt.position.z) {
      return;
    }
    x_bounds_.lo = std::min(x_bounds_.lo, pt.position.x);
    x_bounds_.hi = std::max(x_bounds_.hi, pt.position.x);
    y_bounds_.lo = std::min(y_bounds_.lo, pt.position.y);
    y_bounds_.hi = std::max(y_bounds_.hi, pt.position.y);
    z_bounds_.lo = std::min(z_bounds_.lo, pt.position.z);
    z_bounds_.hi = std::max(z_bounds_.hi, pt.position.z);
  }
  if (pt.starts_run) ++runs_;
  points_.push_back(pt);
}

void Toolpath::CountIgnored(const std::string& word, int64_t n) {
  ignored_[word] += n;
}

int64_t Toolpath::ignored_total() const {
  int64_t total = 0;
  for (const auto& [word, n] : ignored_) total += n;
  return total;
}

std::vector<int> Toolpath::Tools() const {
  std::vector<int> tools;
  int last = -1;
  for (const ToolpathPoint& p : points_) {
    if (p.tool == last) continue;
    last = p.tool;
    if (std::find(tools.begin(), tools.end(), last) == tools.end()) {
      tools.push_back(last);
    }
  }
  return tools;
}

std::string Toolpath::IgnoredSummary() const {
  if (ignored_.empty()) return "";
  std::vector<WordKey> keys;
  for (const auto& [word, n] : ignored_) keys.push_back(KeyOf(word));
  std::sort(keys.begin(), keys.end(), [](const WordKey& a, const WordKey& b) {
    if (a.rank != b.rank) return a.rank < b.rank;
    if (a.number != b.number) return a.number < b.number;
    return *a.word < *b.word;
  });
  const int64_t total = ignored_total();
  std::string out =
      absl::StrCat("ignored ", total, total == 1 ? " word" : " words",
                   " that don't move the tool:");
  for (size_t i = 0; i < keys.size(); ++i) {
    absl::StrAppend(&out, i == 0 ? " " : ", ", *keys[i].word, " x",
                    ignored_.at(*keys[i].word));
  }
  return out;
}

absl::StatusOr<Toolpath> ParseGcode(std::string_view text,
                                    const GcodeOptions& options) {
  GcodeParser parser(options);
  return parser.Parse(text);
}

absl::StatusOr<Toolpath> ParseXyz(std::string_view text, int64_t max_points) {
  static constexpr char kAxis[3] = {'x', 'y', 'z'};
  Toolpath path;
  const char* p = SkipBom(text.data(), text.data() + text.size());
  const char* const end = text.data() + text.size();
  int64_t line = 0;
  bool first_content = true;  // the line that may be a header
  while (p < end) {
    ++line;
    const char* eol = static_cast<const char*>(std::memchr(p, '\n', end - p));
    if (eol == nullptr) eol = end;
    const char* s = SkipBlanks(p, eol);
    p = eol < end ? eol + 1 : end;
    if (s == eol || *s == '#') continue;
    if (line > std::numeric_limits<int32_t>::max()) {
      return LineError(line, "too many lines");
    }
    double v[3];
    bool header = false;
    for (int k = 0; k < 3; ++k) {
      if (k > 0) {
        // Blanks and/or one comma between values.
        const char* before = s;
        s = SkipBlanks(s, eol);
        if (s < eol && *s == ',') s = SkipBlanks(s + 1, eol);
        if (s == before || s == eol || *s == '#') {
          return LineError(line, absl::StrCat("expected 3 values (x y z), "
                                              "got ",
                                              k));
        }
      }
      const char* t = s < eol && *s == '+' && s + 1 < eol && s[1] != '-'
                          ? s + 1
                          : s;  // from_chars rejects a leading '+'
      const auto r = std::from_chars(t, eol, v[k]);
      if (r.ec == std::errc::result_out_of_range) {
        return LineError(
            line, absl::StrCat(std::string(1, kAxis[k]), " is out of range"));
      }
      if (r.ec != std::errc()) {
        if (k == 0 && first_content) {
          header = true;
          break;
        }
        return LineError(
            line, absl::StrCat(std::string(1, kAxis[k]), " is not a number at ",
                               CharName(*s)));
      }
      if (!(std::fabs(v[k]) <= kMaxCoordinateMm)) {
        return LineError(line, absl::StrCat(std::string(1, kAxis[k]), " = ",
                                            v[k], " is out of range"));
      }
      s = r.ptr;
    }
    first_content = false;
    if (header) continue;
    s = SkipBlanks(s, eol);
    if (s < eol && *s == ',') s = SkipBlanks(s + 1, eol);
    if (s < eol && *s != '#') {
      return LineError(line, absl::StrCat("unexpected ", CharName(*s),
                                          " after x y z (3 values per "
                                          "line)"));
    }
    if (path.point_count() >= max_points) {
      return LineError(
          line, absl::StrCat("more than ", max_points, " points (max_points)"));
    }
    ToolpathPoint pt;
    pt.position = {v[0], v[1], v[2]};
    pt.line = static_cast<int32_t>(line);
    path.Append(pt);
  }
  path.set_source_lines(line);
  path.Trim();
  return path;
}

absl::StatusOr<ToolpathFormat> ToolpathFormatForPath(std::string_view path) {
  const size_t slash = path.find_last_of("/\\");
  const std::string_view name =
      slash == std::string_view::npos ? path : path.substr(slash + 1);
  const size_t dot = name.rfind('.');
  std::string ext;
  if (dot != std::string_view::npos) {
    for (char c : name.substr(dot + 1)) {
      ext += static_cast<char>(c >= 'A' && c <= 'Z' ? c + ('a' - 'A') : c);
    }
  }
  for (const char* g : {"nc", "ngc", "gcode", "tap", "cnc"}) {
    if (ext == g) return ToolpathFormat::kGcode;
  }
  for (const char* x : {"csv", "xyz", "txt"}) {
    if (ext == x) return ToolpathFormat::kXyz;
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "unknown toolpath file extension '", ext,
      "': G-code is .nc .ngc .gcode .tap .cnc; tip positions are .csv .xyz "
      ".txt"));
}

absl::StatusOr<Toolpath> ParseToolpath(std::string_view text,
                                       ToolpathFormat format,
                                       const GcodeOptions& options) {
  if (format == ToolpathFormat::kXyz) return ParseXyz(text, options.max_points);
  return ParseGcode(text, options);
}

absl::StatusOr<Toolpath> ReadToolpathFile(const std::string& path,
                                          const GcodeOptions& options) {
  const auto prefixed = [&path](const absl::Status& st) {
    return absl::Status(st.code(), absl::StrCat(path, ": ", st.message()));
  };
  const absl::StatusOr<ToolpathFormat> format = ToolpathFormatForPath(path);
  if (!format.ok()) return prefixed(format.status());
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) {
    const int e = errno;
    return absl::NotFoundError(
        absl::StrCat(path, ": cannot open: ", std::strerror(e)));
  }
  std::string data;
  char buf[1 << 16];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) data.append(buf, n);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) {
    return absl::DataLossError(absl::StrCat(path, ": read error"));
  }
  absl::StatusOr<Toolpath> tp = ParseToolpath(data, *format, options);
  if (!tp.ok()) return prefixed(tp.status());
  return tp;
}

}  // namespace swarf::gcode
