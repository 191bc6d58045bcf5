// std::max and std::min by value, for vectorized loops: on references, GCC
// compiled their selects and reductions to branches the vectorizer did not
// take. Same results as std::max(a, b) and std::min(a, b).
#ifndef SWARF_CORE_VALUE_MINMAX_H_
#define SWARF_CORE_VALUE_MINMAX_H_

namespace swarf {

[[gnu::always_inline]] inline double MaxOf(double a, double b) {
  return a < b ? b : a;
}
[[gnu::always_inline]] inline double MinOf(double a, double b) {
  return b < a ? b : a;
}

}  // namespace swarf

#endif  // SWARF_CORE_VALUE_MINMAX_H_
