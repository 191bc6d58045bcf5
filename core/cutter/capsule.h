// The XY region where a sweep may go below a height: a segment widened by a
// radius (a capsule). Plain value.
#ifndef SWARF_CORE_CUTTER_CAPSULE_H_
#define SWARF_CORE_CUTTER_CAPSULE_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#include "core/cutter/cutter.h"
#include "core/geometry.h"

namespace swarf {

inline constexpr double kInf = std::numeric_limits<double>::infinity();

// Where a sweep reaches below some height (conservatively): the points
// within `radius` of the segment (x0, y0)-(x1, y1).
struct Capsule {
  bool empty = true;
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // segment ends (XY)
  double radius = 0;
  double ux = 0, uy = 0, length = 0;  // unit XY direction and length
  double inv_ux = 0, inv_uy = 0;      // 1 / ux, 1 / uy (0 where those are)
  Rect Bounds() const {
    return {std::min(x0, x1) - radius, std::min(y0, y1) - radius,
            std::max(x0, x1) + radius, std::max(y0, y1) + radius};
  }
  // The x-interval of the capsule on the row y (empty if it misses).
  // Inline: it runs for every row of every move.
  Interval RowSpan(double y) const {
    Interval out;
    if (empty) return out;
    const double r2 = radius * radius;
    const double dy0 = y - y0, dy1 = y - y1;
    const double q0 = r2 - dy0 * dy0, q1 = r2 - dy1 * dy1;
    if (q0 >= 0) {
      const double w = std::sqrt(q0);
      out.Hull({x0 - w, x0 + w});
    }
    if (q1 >= 0) {
      const double w = std::sqrt(q1);
      out.Hull({x1 - w, x1 + w});
    }
    if (length > 0) {
      // The band between the ends: 0 <= (p - p0) . u <= length and
      // |(p - p0) . (-uy, ux)| <= radius, each linear in x on the row.
      Interval strip{-kInf, kInf};
      ClipLinear(ux, inv_ux, dy0 * uy - x0 * ux, 0, length, &strip);
      ClipLinear(-uy, -inv_uy, x0 * uy + dy0 * ux, -radius, radius, &strip);
      out.Hull(strip);
    }
    return out;
  }
  // Restricts `iv` to the x where lo <= a x + b <= hi; inv_a = 1 / a.
  static void ClipLinear(double a, double inv_a, double b, double lo,
                         double hi, Interval* iv) {
    if (a == 0) {
      if (b < lo || b > hi) *iv = Interval{};
      return;
    }
    double x_lo = (lo - b) * inv_a, x_hi = (hi - b) * inv_a;
    if (a < 0) std::swap(x_lo, x_hi);
    iv->Intersect(x_lo, x_hi);
  }
};
// Fills c's direction fields (ux, uy, length, inv_ux, inv_uy) from its
// ends.
void FillDirection(Capsule* c);

// Node index range [lo, hi] within [0, max] of the nodes origin + k * step
// that lie in [a, b] (inv_step = 1 / step; the ranges only need to be
// conservative, footprints carry a margin); lo > hi if none.
inline std::pair<int32_t, int32_t> NodeRange(double a, double b, double origin,
                                             double inv_step, int32_t max) {
  // Clamped to [-1, max + 1] first, so that the integer conversions below
  // are exact ceil/floor without libm calls.
  const double top = max + 1.0;
  const double fa = std::min(std::max((a - origin) * inv_step, -1.0), top);
  const double fb = std::min(std::max((b - origin) * inv_step, -1.0), top);
  int32_t lo = static_cast<int32_t>(fa);  // truncation: ceil for fa <= 0
  if (lo < fa) ++lo;
  int32_t hi = static_cast<int32_t>(fb);  // floor for fb >= 0
  if (hi > fb) --hi;
  lo = std::max(lo, 0);
  hi = std::min(hi, max);
  if (!(fa == fa) || !(fb == fb) || lo > hi) return {1, 0};  // NaN: none
  return {lo, hi};
}

// For the rows y = y0 + j * dy (as GridGeometry::NodeY), j0 <= j < j0 + n:
// lo[q], hi[q] (q = j - j0) = NodeRange(c.RowSpan(y)'s ends, x0, inv_dx,
// i_max), and lo > hi where RowSpan is empty: the same values as those
// calls, rows at a time (vectorized). c is not empty.
void RowNodeRanges(const Capsule& c, double y0, double dy, int32_t j0,
                   int32_t n, double x0, double inv_dx, int32_t i_max,
                   int32_t* lo, int32_t* hi);

// As RowNodeRanges, for m rows j0 + rows[k] (k < m, any order), each of its
// own capsule: c with radius radii[k] (a footprint narrowed row by row).
void RowNodeRangesAt(const Capsule& c, const double* radii, int32_t j0,
                     const int32_t* rows, int32_t m, double y0, double dy,
                     double x0, double inv_dx, int32_t i_max, int32_t* lo,
                     int32_t* hi);

// The footprint below `cap` of a straight move of cutter `c` between two
// tool tips: the part of the segment where the tip is below cap, widened by
// FootprintRadius at the lowest tip (plus a rounding margin, so that a node
// whose swept height is below the cap is always inside). Any cutter shape;
// the ball sweep has its own, tighter by construction.
Capsule TipFootprint(const Vec3& tip_from, const Vec3& tip_to,
                     const Cutter& c, double cap);
// TipFootprint's ends, radius and `empty` (the same bits) without its
// direction (ux, uy, length, inv_ux, inv_uy left 0).
Capsule TipFootprintEnds(const Vec3& tip_from, const Vec3& tip_to,
                         const Cutter& c, double cap);

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_CAPSULE_H_
