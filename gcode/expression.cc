#include "gcode/expression.h"

#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"
#include "core/status_macros.h"
#include "gcode/text.h"

namespace swarf::gcode {
namespace {

constexpr double kDegPerRad = 180.0 / std::numbers::pi;
// LinuxCNC's TOLERANCE_EQUAL: EQ, NE, GE and LE compare within it.
constexpr double kEqualTolerance = 1e-4;

absl::Status Bad(const std::string& what) {
  return absl::InvalidArgumentError(what);
}

enum Op {
  kNone, kPow, kMul, kDiv, kMod, kAdd, kSub,
  kEq, kNe, kGt, kGe, kLt, kLe, kAnd, kOr, kXor
};

int Precedence(Op op) {
  switch (op) {
    case kPow: return 4;
    case kMul: case kDiv: case kMod: return 3;
    case kAdd: case kSub: return 2;
    case kEq: case kNe: case kGt: case kGe: case kLt: case kLe: return 1;
    case kAnd: case kOr: case kXor: return 0;
    case kNone: break;
  }
  return -1;
}

// A run of letters at p, lower-cased (at most 8 kept).
std::string Letters(const char* p, const char* end, const char** after) {
  std::string w;
  while (p < end && ((*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z'))) {
    if (w.size() < 8) w += Lower(*p);
    ++p;
  }
  *after = p;
  return w;
}

// The binary operator at *p, or kNone (then *p is unchanged).
Op PeekOp(const char* p, const char* end, const char** after) {
  p = SkipBlanks(p, end);
  if (p >= end) return kNone;
  switch (*p) {
    case '*':
      if (p + 1 < end && p[1] == '*') {
        *after = p + 2;
        return kPow;
      }
      *after = p + 1;
      return kMul;
    case '/': *after = p + 1; return kDiv;
    case '+': *after = p + 1; return kAdd;
    case '-': *after = p + 1; return kSub;
    default: break;
  }
  const std::string w = Letters(p, end, after);
  if (w == "mod") return kMod;
  if (w == "eq") return kEq;
  if (w == "ne") return kNe;
  if (w == "gt") return kGt;
  if (w == "ge") return kGe;
  if (w == "lt") return kLt;
  if (w == "le") return kLe;
  if (w == "and") return kAnd;
  if (w == "or") return kOr;
  if (w == "xor") return kXor;
  return kNone;
}

absl::Status Finite(double v, const char* what) {
  if (!std::isfinite(v)) {
    return Bad(absl::StrCat(what, " gives a value that is not finite"));
  }
  return absl::OkStatus();
}

absl::StatusOr<double> Apply(Op op, double a, double b) {
  double r = 0;
  switch (op) {
    case kPow:
      if (a < 0 && b != std::floor(b)) {
        return Bad(absl::StrCat("negative base ", a,
                                " to a non-integer power ", b));
      }
      if (a == 0 && b < 0) return Bad("zero to a negative power");
      r = std::pow(a, b);
      break;
    case kMul: r = a * b; break;
    case kDiv:
      if (b == 0) return Bad("division by zero");
      r = a / b;
      break;
    case kMod:
      if (b == 0) return Bad("MOD by zero");
      // As LinuxCNC: the result has the divisor's magnitude sign rule.
      r = std::fmod(a, b);
      if (r < 0) r += std::fabs(b);
      break;
    case kAdd: r = a + b; break;
    case kSub: r = a - b; break;
    case kEq: r = std::fabs(a - b) < kEqualTolerance; break;
    case kNe: r = !(std::fabs(a - b) < kEqualTolerance); break;
    case kGt: r = a > b; break;
    case kGe: r = a > b || std::fabs(a - b) < kEqualTolerance; break;
    case kLt: r = a < b; break;
    case kLe: r = a < b || std::fabs(a - b) < kEqualTolerance; break;
    case kAnd: r = a != 0 && b != 0; break;
    case kOr: r = a != 0 || b != 0; break;
    case kXor: r = (a != 0) != (b != 0); break;
    case kNone: break;
  }
  SWARF_RETURN_IF_ERROR(Finite(r, "an operation"));
  return r;
}

class Parser {
 public:
  Parser(const char* end, ParameterSource& params)
      : end_(end), params_(params) {}

  absl::Status Real(const char** p, int depth, double* out);
  absl::Status Ref(const char** p, int depth, ParamRef* ref);

 private:
  absl::Status Bracket(const char** p, int depth, double* out);
  absl::Status Binary(const char** p, int depth, int min_prec, double* out);
  absl::Status Function(const char** p, int depth, const std::string& name,
                        double* out);
  absl::Status Name(const char** p, std::string* name);

  const char* const end_;
  ParameterSource& params_;
};

absl::Status Parser::Bracket(const char** p, int depth, double* out) {
  // *p at '['.
  if (depth >= kMaxExpressionDepth) {
    return Bad(absl::StrCat("expression nested deeper than ",
                            kMaxExpressionDepth));
  }
  const char* q = *p + 1;
  SWARF_RETURN_IF_ERROR(Binary(&q, depth + 1, 0, out));
  q = SkipBlanks(q, end_);
  if (q >= end_ || *q != ']') {
    return Bad(q >= end_ ? "expression: ']' missing"
                         : absl::StrCat("expression: unexpected ", CharName(*q),
                                        " (expected an operator or ']')"));
  }
  *p = q + 1;
  return absl::OkStatus();
}

absl::Status Parser::Binary(const char** p, int depth, int min_prec,
                            double* out) {
  double lhs;
  SWARF_RETURN_IF_ERROR(Real(p, depth, &lhs));
  for (;;) {
    const char* after = *p;
    const Op op = PeekOp(*p, end_, &after);
    if (op == kNone || Precedence(op) < min_prec) break;
    *p = after;
    double rhs;
    SWARF_RETURN_IF_ERROR(Binary(p, depth, Precedence(op) + 1, &rhs));
    absl::StatusOr<double> r = Apply(op, lhs, rhs);
    if (!r.ok()) return r.status();
    lhs = *r;
  }
  *out = lhs;
  return absl::OkStatus();
}

absl::Status Parser::Name(const char** p, std::string* name) {
  // *p at '<'.
  const char* q = *p + 1;
  name->clear();
  while (q < end_ && *q != '>') {
    if (*q == '\n' || *q == '<' || *q == '(' || *q == '[' || *q == '#') {
      return Bad("parameter name: '>' missing");
    }
    if (!IsBlank(*q)) name->push_back(Lower(*q));
    ++q;
    if (name->size() > 255) return Bad("parameter name longer than 255");
  }
  if (q >= end_) return Bad("parameter name: '>' missing");
  if (name->empty()) return Bad("empty parameter name #<>");
  *p = q + 1;
  return absl::OkStatus();
}

absl::Status Parser::Ref(const char** p, int depth, ParamRef* ref) {
  // *p at '#'.
  if (depth >= kMaxExpressionDepth) {
    return Bad(absl::StrCat("parameter reference nested deeper than ",
                            kMaxExpressionDepth));
  }
  const char* q = SkipBlanks(*p + 1, end_);
  if (q < end_ && *q == '<') {
    ref->named = true;
    SWARF_RETURN_IF_ERROR(Name(&q, &ref->name));
    *p = q;
    return absl::OkStatus();
  }
  // #n, ##n, #[expr]: the number is itself a real value.
  double v;
  SWARF_RETURN_IF_ERROR(Real(&q, depth + 1, &v));
  ref->named = false;
  absl::StatusOr<int> n = ParameterNumber(v);
  if (!n.ok()) return n.status();
  ref->number = *n;
  *p = q;
  return absl::OkStatus();
}

absl::Status Parser::Function(const char** p, int depth,
                              const std::string& name, double* out) {
  const char* q = SkipBlanks(*p, end_);
  if (q >= end_ || *q != '[') {
    return Bad(absl::StrCat("function ", name, " needs [argument]"));
  }
  if (name == "exists") {
    q = SkipBlanks(q + 1, end_);
    if (q >= end_ || *q != '#') return Bad("EXISTS needs [#<name>]");
    q = SkipBlanks(q + 1, end_);
    if (q >= end_ || *q != '<') return Bad("EXISTS needs [#<name>]");
    std::string n;
    SWARF_RETURN_IF_ERROR(Name(&q, &n));
    q = SkipBlanks(q, end_);
    if (q >= end_ || *q != ']') return Bad("EXISTS: ']' missing");
    *out = params_.Exists(n) ? 1 : 0;
    *p = q + 1;
    return absl::OkStatus();
  }
  double a;
  SWARF_RETURN_IF_ERROR(Bracket(&q, depth, &a));
  double r;
  if (name == "atan") {
    q = SkipBlanks(q, end_);
    if (q >= end_ || *q != '/') return Bad("ATAN needs [y]/[x]");
    q = SkipBlanks(q + 1, end_);
    if (q >= end_ || *q != '[') return Bad("ATAN needs [y]/[x]");
    double b;
    SWARF_RETURN_IF_ERROR(Bracket(&q, depth, &b));
    r = std::atan2(a, b) * kDegPerRad;
  } else if (name == "abs") {
    r = std::fabs(a);
  } else if (name == "acos" || name == "asin") {
    if (!(a >= -1 && a <= 1)) {
      return Bad(absl::StrCat(name == "acos" ? "ACOS" : "ASIN", " of ", a,
                              ": outside [-1, 1]"));
    }
    r = (name == "acos" ? std::acos(a) : std::asin(a)) * kDegPerRad;
  } else if (name == "cos") {
    r = std::cos(a / kDegPerRad);
  } else if (name == "sin") {
    r = std::sin(a / kDegPerRad);
  } else if (name == "tan") {
    r = std::tan(a / kDegPerRad);
  } else if (name == "exp") {
    r = std::exp(a);
  } else if (name == "fix") {
    r = std::floor(a);
  } else if (name == "fup") {
    r = std::ceil(a);
  } else if (name == "round") {
    r = std::round(a);
  } else if (name == "ln") {
    if (!(a > 0)) return Bad(absl::StrCat("LN of ", a, ": not positive"));
    r = std::log(a);
  } else if (name == "sqrt") {
    if (!(a >= 0)) return Bad(absl::StrCat("SQRT of ", a, ": negative"));
    r = std::sqrt(a);
  } else {
    return Bad(absl::StrCat("unknown function '", name, "'"));
  }
  SWARF_RETURN_IF_ERROR(Finite(r, name.c_str()));
  *out = r;
  *p = q;
  return absl::OkStatus();
}

absl::Status Parser::Real(const char** p, int depth, double* out) {
  const char* q = SkipBlanks(*p, end_);
  if (q >= end_) return Bad("a value is missing");
  double sign = 1;
  if ((*q == '-' || *q == '+') && q + 1 < end_ && !IsDigit(q[1]) &&
      q[1] != '.') {
    sign = *q == '-' ? -1 : 1;
    q = SkipBlanks(q + 1, end_);
    if (q >= end_) return Bad("a value is missing after the sign");
  }
  double v;
  if (*q == '[') {
    SWARF_RETURN_IF_ERROR(Bracket(&q, depth, &v));
  } else if (*q == '#') {
    ParamRef ref;
    SWARF_RETURN_IF_ERROR(Ref(&q, depth, &ref));
    absl::StatusOr<double> r =
        ref.named ? params_.Named(ref.name) : params_.Numbered(ref.number);
    if (!r.ok()) return r.status();
    v = *r;
  } else if ((*q >= 'a' && *q <= 'z') || (*q >= 'A' && *q <= 'Z')) {
    const char* after;
    const std::string name = Letters(q, end_, &after);
    q = after;
    SWARF_RETURN_IF_ERROR(Function(&q, depth + 1, name, &v));
  } else {
    const char* after = ScanNumber(q, end_, &v);
    if (after == nullptr) {
      return Bad(absl::StrCat("expected a value at ", CharName(*q)));
    }
    if (after < end_ && *after == '.') return Bad("malformed number");
    q = after;
  }
  *out = sign * v;
  *p = q;
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<int> ParameterNumber(double v) {
  const double r = std::round(v);
  if (!(std::fabs(v - r) < 1e-4) || r < 1 || r > 5602) {
    return Bad(absl::StrCat("#", v, " is not a parameter (1-5602)"));
  }
  return static_cast<int>(r);
}

absl::Status ReadParamRef(const char** p, const char* end,
                          ParameterSource& params, ParamRef* ref) {
  return Parser(end, params).Ref(p, 0, ref);
}

absl::Status ReadReal(const char** p, const char* end, ParameterSource& params,
                      double* out) {
  return Parser(end, params).Real(p, 0, out);
}

}  // namespace swarf::gcode
