// Independent reference values for the ball-sweep tests: the swept lower
// surface computed by brute force, straight from its definition (the lowest
// point of the union of all balls along the move), in long double. Shares no
// code with core/ball_sweep.cc.
#ifndef SWARF_TESTS_SWEEP_REFERENCE_H_
#define SWARF_TESTS_SWEEP_REFERENCE_H_

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/geometry.h"

namespace swarf::testing {

using LD = long double;

inline constexpr double kDoubleEps = std::numeric_limits<double>::epsilon();

// Conditioning of BallSweep::Height: its inputs (x, y, the move) are doubles
// of magnitude `scale`, and each is rounded a handful of times on the way,
// so any correct double implementation may be off by about
// eps * scale * (1 + |grad w|). This constant covers the handful of roundings
// (sqrt, the root formula, differences of coordinates); the core measured at
// most 0.85 of one such unit. ball_sweep_test
// verifies this error model against the brute force and the finite-difference
// test relies on it for its round-off term.
inline constexpr double kHeightRoundings = 16;

inline double HeightRoundoff(double scale, double slope) {
  return kHeightRoundings * kDoubleEps * scale * (1 + slope);
}

struct ReferencePoint {
  LD w = std::numeric_limits<LD>::infinity();  // lowest point of the union
  // |grad w| at (x, y): by the envelope theorem, the touching ball's slope
  // d / sqrt(r^2 - d^2) (d: horizontal distance to its centre).
  LD slope = 0;
  LD t = 0;  // parameter in [0, 1] of the touching ball's centre
};

// Lower height of the ball centred at a + t (b - a) at (x, y); +inf outside
// its shadow.
inline LD BallLow(const LD a[3], const LD e[3], LD r, LD x, LD y, LD t,
                  LD* slope = nullptr) {
  const LD cx = a[0] + t * e[0], cy = a[1] + t * e[1], cz = a[2] + t * e[2];
  const LD d2 = (x - cx) * (x - cx) + (y - cy) * (y - cy);
  const LD q = r * r - d2;
  if (q < 0) return std::numeric_limits<LD>::infinity();
  const LD depth = std::sqrt(q);
  if (slope != nullptr) {
    *slope = depth > 0 ? std::sqrt(d2) / depth
                       : std::numeric_limits<LD>::infinity();
  }
  return cz - depth;
}

// The parameters t in [0, 1] at which a tool of radius r whose axis moves
// (in XY) from (ax, ay) by (ex, ey) covers (x, y): |d0 + t e|^2 <= r^2,
// d0 = a - (x, y). False when there are none.
inline bool CoveringInterval(LD ax, LD ay, LD ex, LD ey, LD r, LD x, LD y,
                             LD* lo, LD* hi) {
  const LD d0x = ax - x, d0y = ay - y;
  const LD ee = ex * ex + ey * ey;
  const LD de = d0x * ex + d0y * ey;
  const LD dd = d0x * d0x + d0y * d0y - r * r;
  *lo = 0;
  *hi = 1;
  if (ee == 0) return dd <= 0;
  const LD disc = de * de - ee * dd;
  if (disc < 0) return false;
  const LD s = std::sqrt(disc);
  *lo = std::max(*lo, (-de - s) / ee);
  *hi = std::min(*hi, (-de + s) / ee);
  return *lo <= *hi;
}

// The t in [lo, hi] minimizing f, convex there: `samples` evenly spaced
// values pick the best one's neighbours as the bracket, golden section
// (`iterations` steps) refines it; the lowest of everything evaluated
// (bracket ends, golden points, best sample, lo and hi) wins. The samples
// only guard against a flat stretch fooling the first golden-section step.
template <class F>
LD ConvexArgMin(const F& f, LD lo, LD hi, int samples, int iterations) {
  const int n = std::max(samples, 2);
  int best_k = 0;
  LD best_f = std::numeric_limits<LD>::infinity();
  for (int k = 0; k < n; ++k) {
    const LD v = f(lo + (hi - lo) * k / (n - 1));
    if (v < best_f) {
      best_f = v;
      best_k = k;
    }
  }
  LD l = lo + (hi - lo) * std::max(best_k - 1, 0) / (n - 1);
  LD u = lo + (hi - lo) * std::min(best_k + 1, n - 1) / (n - 1);
  const LD phi = (std::sqrt(LD{5}) - 1) / 2;
  LD t1 = u - phi * (u - l), t2 = l + phi * (u - l);
  LD f1 = f(t1), f2 = f(t2);
  for (int it = 0; it < iterations && u - l > 0; ++it) {
    if (f1 <= f2) {
      u = t2;
      t2 = t1;
      f2 = f1;
      t1 = u - phi * (u - l);
      f1 = f(t1);
    } else {
      l = t1;
      t1 = t2;
      f1 = f2;
      t2 = l + phi * (u - l);
      f2 = f(t2);
    }
  }
  LD best_t = lo;
  best_f = std::numeric_limits<LD>::infinity();
  for (LD t : {lo + (hi - lo) * best_k / (n - 1), l, u, t1, t2, lo, hi}) {
    const LD v = f(t);
    if (v < best_f) {
      best_f = v;
      best_t = t;
    }
  }
  return best_t;
}

// Brute-force swept height at (x, y) of the ball of radius r whose tip moves
// from tip_from to tip_to: `samples` balls evenly spaced over the part of
// the move whose balls cover (x, y), then golden-section refinement around
// the best one (ConvexArgMin: the height of the covering balls is convex
// in t).
inline ReferencePoint BruteForceHeight(const Vec3& tip_from, const Vec3& tip_to,
                                       double radius, double x, double y,
                                       int samples = 20001) {
  const LD r = radius;
  const LD a[3] = {tip_from.x, tip_from.y, LD{tip_from.z} + r};
  const LD e[3] = {LD{tip_to.x} - tip_from.x, LD{tip_to.y} - tip_from.y,
                   LD{tip_to.z} - tip_from.z};
  LD lo, hi;
  if (!CoveringInterval(a[0], a[1], e[0], e[1], r, x, y, &lo, &hi)) return {};
  const LD t = ConvexArgMin(
      [&](LD t) { return BallLow(a, e, r, x, y, t); }, lo, hi, samples, 120);
  ReferencePoint best;
  best.t = t;
  best.w = BallLow(a, e, r, x, y, t, &best.slope);
  return best;
}

// Horizontal distance from (x, y) to the XY segment of ball centres.
inline LD DistanceToPath(const Vec3& from, const Vec3& to, double x,
                         double y) {
  const LD ex = LD{to.x} - from.x, ey = LD{to.y} - from.y;
  const LD qx = LD{x} - from.x, qy = LD{y} - from.y;
  const LD ee = ex * ex + ey * ey;
  LD t = ee > 0 ? (qx * ex + qy * ey) / ee : 0;
  t = std::clamp(t, LD{0}, LD{1});
  return std::hypot(qx - t * ex, qy - t * ey);
}

}  // namespace swarf::testing

#endif  // SWARF_TESTS_SWEEP_REFERENCE_H_
