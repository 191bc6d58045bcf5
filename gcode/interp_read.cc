// The interpreter's reading (see interpreter.h): a line into a Block (words,
// numbers in place, expressions, '@'/'^', O-word lines, parameter settings
// applied after the line is read) and the parameters (numbered, named,
// system, read-only).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "core/status_macros.h"
#include "gcode/interpreter.h"

namespace swarf::gcode::interp {

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

}  // namespace swarf::gcode::interp
