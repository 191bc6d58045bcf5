// RS274/NGC expressions and parameter references, as LinuxCNC documents
// them: [a + b], #1, ##1, #[expr], #<name>, and the unary functions ABS
// ACOS ASIN ATAN (ATAN[y]/[x]) COS EXP FIX FUP ROUND LN SIN SQRT TAN and
// EXISTS[#<name>]. Binary operators by precedence, highest first: **;
// * / MOD; + -; EQ NE GT GE LT LE; AND OR XOR (left to right within a
// level). Angles in degrees. Keywords are case-insensitive; blanks may
// separate tokens.
//
// Errors are InvalidArgument without a line prefix (the interpreter adds
// "line N: "): division by zero, a domain error, a result that isn't
// finite, nesting deeper than kMaxExpressionDepth, a malformed expression.
#ifndef SWARF_GCODE_EXPRESSION_H_
#define SWARF_GCODE_EXPRESSION_H_

#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace swarf::gcode {

inline constexpr int kMaxExpressionDepth = 64;

// Where expressions read parameter values. Not thread-safe (one per
// interpreter).
class ParameterSource {
 public:
  virtual ~ParameterSource() = default;
  // #n, n already rounded to an integer by the caller's rules.
  virtual absl::StatusOr<double> Numbered(int n) = 0;
  // #<name>: name lower-cased without blanks.
  virtual absl::StatusOr<double> Named(const std::string& name) = 0;
  virtual bool Exists(const std::string& name) = 0;
};

// A parameter reference: #n (named false) or #<name>.
struct ParamRef {
  bool named = false;
  int number = 0;
  std::string name;  // lower-cased, blanks removed
};

// The number of a parameter: a value within 1e-4 of an integer in
// [1, 5602] (LinuxCNC's range). InvalidArgument else.
absl::StatusOr<int> ParameterNumber(double v);

// Reads a parameter reference at *p (which points at the '#'); advances *p.
absl::Status ReadParamRef(const char** p, const char* end,
                          ParameterSource& params, ParamRef* ref);

// Reads a real value at *p (blanks first are skipped): a number, an
// [expression], a #parameter or a unary function, with an optional sign;
// advances *p past it.
absl::Status ReadReal(const char** p, const char* end, ParameterSource& params,
                      double* out);

}  // namespace swarf::gcode

#endif  // SWARF_GCODE_EXPRESSION_H_
