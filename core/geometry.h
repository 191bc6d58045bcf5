// Small value types shared by the simulation. Units: millimetres.
#ifndef SWARF_CORE_GEOMETRY_H_
#define SWARF_CORE_GEOMETRY_H_

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

namespace swarf {

struct Vec3 {
  double x = 0, y = 0, z = 0;
};

// Whether a and b are the same bits (0 and -0 differ; a NaN equals its own
// bits): for values one computation must have carried over unchanged.
inline bool SameBits(double a, double b) {
  return std::bit_cast<uint64_t>(a) == std::bit_cast<uint64_t>(b);
}
inline bool SameBits(const Vec3& a, const Vec3& b) {
  return SameBits(a.x, b.x) && SameBits(a.y, b.y) && SameBits(a.z, b.z);
}

// Axis-aligned rectangle in the XY plane, [x0,x1] x [y0,y1].
struct Rect {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;

  bool Contains(double x, double y) const {
    return x >= x0 && x <= x1 && y >= y0 && y <= y1;
  }
  bool Intersects(const Rect& o) const {
    return x0 <= o.x1 && o.x0 <= x1 && y0 <= o.y1 && o.y0 <= y1;
  }
};

// A closed interval [lo, hi]; empty when lo > hi.
struct Interval {
  double lo = 1, hi = 0;
  bool empty() const { return !(lo <= hi); }
  void Hull(const Interval& o) {
    if (o.empty()) return;
    if (empty()) {
      *this = o;
    } else {
      lo = std::min(lo, o.lo);
      hi = std::max(hi, o.hi);
    }
  }
  void Intersect(double a, double b) {
    lo = std::max(lo, a);
    hi = std::min(hi, b);
  }
};

inline bool IsFinite(const Vec3& v) {
  return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

}  // namespace swarf

#endif  // SWARF_CORE_GEOMETRY_H_
