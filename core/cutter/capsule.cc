#include "core/cutter/capsule.h"

#include <algorithm>
#include <cmath>

#include "core/target_clones.h"
#include "core/value_minmax.h"

namespace swarf {
namespace {

// As the ball sweep's: keeps the footprint conservative under rounding, so
// that results do not depend on batching.
constexpr double kFootprintMargin = 1e-9;

// Interval::Hull of [lo, hi] with [o_lo, o_hi] where `take`, as selects,
// with the empty interval as [+inf, -inf] (Interval's is [1, 0]): the
// first hull is then the minimum and maximum with infinities, the same
// bits as taking the other interval (the vectorizer did not take the test
// for an empty one).
[[gnu::always_inline]] inline void HullWhere(bool take, double o_lo,
                                             double o_hi, double& lo,
                                             double& hi) {
  const bool apply = take & (o_lo <= o_hi);  // o is not empty
  lo = apply ? MinOf(lo, o_lo) : lo;
  hi = apply ? MaxOf(hi, o_hi) : hi;
}

// The band's clips of Capsule::RowSpan, by which of them are degenerate
// (a direction component 0: a test instead of a clip): decided per capsule
// outside the loop, so that the loop is selects only.
enum Strip { kNoStrip, kBothClips, kUxZero, kUyZero };

// RowNodeRanges for one kind of band: rows j0 + q of c, or (kRadii) rows
// j0 + rows[q] of c with radius radii[q].
template <Strip kStrip, bool kRadii>
[[gnu::always_inline]] inline void RowNodeRangesOf(
    const Capsule& c, const double* __restrict radii,
    const int32_t* __restrict rows, double y0, double dy, int32_t j0, int32_t n,
    double x0, double inv_dx, int32_t i_max, int32_t* __restrict out_lo,
    int32_t* __restrict out_hi) {
  const double ax = c.x0, ay = c.y0, bx = c.x1, by = c.y1;
  const double ux = c.ux, uy = c.uy, length = c.length;
  // ClipLinear's bounds, swapped where its slope is negative.
  const double inv_a1 = c.inv_ux, inv_a2 = -c.inv_uy;
  const double c1_lo = ux < 0 ? length : 0, c1_hi = ux < 0 ? 0 : length;
  const bool swap2 = -uy < 0;
  const double top = i_max + 1.0;
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    const double radius = kRadii ? radii[q] : c.radius;
    const double r2 = radius * radius;
    const double c2_lo = swap2 ? radius : -radius;
    const double c2_hi = swap2 ? -radius : radius;
    const double y = y0 + (j0 + (kRadii ? rows[q] : q)) * dy;
    const double dy0 = y - ay, dy1 = y - by;
    const double q0 = r2 - dy0 * dy0, q1 = r2 - dy1 * dy1;
    double lo = kInf, hi = -kInf;                         // empty (HullWhere)
    const double w0 = std::sqrt(q0), w1 = std::sqrt(q1);  // NaN: not taken
    HullWhere(q0 >= 0, ax - w0, ax + w0, lo, hi);
    HullWhere(q1 >= 0, bx - w1, bx + w1, lo, hi);
    if constexpr (kStrip != kNoStrip) {
      double s_lo = -kInf, s_hi = kInf;
      bool none = false;
      const double b1 = dy0 * uy - ax * ux;
      if constexpr (kStrip == kUxZero) {
        none = none | (b1 < 0) | (b1 > length);
      } else {
        s_lo = MaxOf(s_lo, (c1_lo - b1) * inv_a1);
        s_hi = MinOf(s_hi, (c1_hi - b1) * inv_a1);
      }
      const double b2 = ax * uy + dy0 * ux;
      if constexpr (kStrip == kUyZero) {
        none = none | (b2 < -radius) | (b2 > radius);
      } else {
        s_lo = MaxOf(s_lo, (c2_lo - b2) * inv_a2);
        s_hi = MinOf(s_hi, (c2_hi - b2) * inv_a2);
      }
      HullWhere(!none, s_lo, s_hi, lo, hi);
    }
    // NodeRange(lo, hi, x0, inv_dx, i_max), none where the span is empty.
    const double fa = MinOf(MaxOf((lo - x0) * inv_dx, -1.0), top);
    const double fb = MinOf(MaxOf((hi - x0) * inv_dx, -1.0), top);
    // NodeRange's truncations and steps are ceil(fa) and floor(fb) on
    // [-1, i_max + 1]; as doubles, so that every select is on a double's
    // comparison (its integer conversions were branches).
    const bool nan = !(fa == fa) | !(fb == fb);
    const double c = std::ceil(fa), f = std::floor(fb);
    const double i_lo = c < 0 ? 0.0 : c;
    const double i_hi = top - 1 < f ? top - 1 : f;
    const bool empty = !(lo <= hi) | nan | (i_lo > i_hi);
    out_lo[q] = static_cast<int32_t>(empty ? 1.0 : i_lo);
    out_hi[q] = static_cast<int32_t>(empty ? 0.0 : i_hi);
  }
}

// RowNodeRangesOf for c's kind of band, decided once for its rows.
template <bool kRadii>
[[gnu::always_inline]] inline void RowNodeRangesBy(
    const Capsule& c, const double* radii, const int32_t* rows, double y0,
    double dy, int32_t j0, int32_t n, double x0, double inv_dx, int32_t i_max,
    int32_t* lo, int32_t* hi) {
  if (!(c.length > 0)) {
    RowNodeRangesOf<kNoStrip, kRadii>(c, radii, rows, y0, dy, j0, n, x0, inv_dx,
                                      i_max, lo, hi);
  } else if (c.ux == 0) {
    RowNodeRangesOf<kUxZero, kRadii>(c, radii, rows, y0, dy, j0, n, x0, inv_dx,
                                     i_max, lo, hi);
  } else if (c.uy == 0) {
    RowNodeRangesOf<kUyZero, kRadii>(c, radii, rows, y0, dy, j0, n, x0, inv_dx,
                                     i_max, lo, hi);
  } else {
    RowNodeRangesOf<kBothClips, kRadii>(c, radii, rows, y0, dy, j0, n, x0,
                                        inv_dx, i_max, lo, hi);
  }
}

}  // namespace

SWARF_TARGET_CLONES
void RowNodeRanges(const Capsule& c, double y0, double dy, int32_t j0,
                   int32_t n, double x0, double inv_dx, int32_t i_max,
                   int32_t* lo, int32_t* hi) {
  RowNodeRangesBy<false>(c, nullptr, nullptr, y0, dy, j0, n, x0, inv_dx, i_max,
                         lo, hi);
}

SWARF_TARGET_CLONES
void RowNodeRangesAt(const Capsule& c, const double* radii, int32_t j0,
                     const int32_t* rows, int32_t m, double y0, double dy,
                     double x0, double inv_dx, int32_t i_max, int32_t* lo,
                     int32_t* hi) {
  RowNodeRangesBy<true>(c, radii, rows, y0, dy, j0, m, x0, inv_dx, i_max, lo,
                        hi);
}

void FillDirection(Capsule* c) {
  c->length = std::hypot(c->x1 - c->x0, c->y1 - c->y0);
  if (c->length > 0) {
    c->ux = (c->x1 - c->x0) / c->length;
    c->uy = (c->y1 - c->y0) / c->length;
    c->inv_ux = c->ux != 0 ? 1 / c->ux : 0;
    c->inv_uy = c->uy != 0 ? 1 / c->uy : 0;
  }
}

Capsule TipFootprint(const Vec3& a, const Vec3& b, const Cutter& cutter,
                     double cap) {
  Capsule c = TipFootprintEnds(a, b, cutter, cap);
  if (!c.empty) FillDirection(&c);
  return c;
}

Capsule TipFootprintEnds(const Vec3& a, const Vec3& b, const Cutter& cutter,
                         double cap) {
  Capsule c;
  // Only tips below the cap put the tool below it.
  const double z_lim = cap + kFootprintMargin;
  double t0 = 0, t1 = 1;
  if (a.z >= z_lim && b.z >= z_lim) return c;
  if (a.z >= z_lim || b.z >= z_lim) {
    const double t = (z_lim - a.z) / (b.z - a.z);
    if (a.z < z_lim) {
      t1 = std::min(1.0, t + 1e-12);
    } else {
      t0 = std::max(0.0, t - 1e-12);
    }
  }
  // The widest reach below the cap is at the lowest tip.
  const double rho =
      FootprintRadius(cutter, std::min(a.z, b.z), cap);
  c.empty = false;
  c.x0 = a.x + t0 * (b.x - a.x);
  c.y0 = a.y + t0 * (b.y - a.y);
  c.x1 = a.x + t1 * (b.x - a.x);
  c.y1 = a.y + t1 * (b.y - a.y);
  c.radius = rho * (1 + 1e-12) + kFootprintMargin;
  return c;
}

}  // namespace swarf
