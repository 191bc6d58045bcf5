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

// Brute-force swept height at (x, y) of the ball of radius r whose tip moves
// from tip_from to tip_to: `samples` balls evenly spaced over the part of
// the move whose balls cover (x, y), then golden-section refinement around
// the best one. The height of the covering balls is convex in t, so the
// minimum lies between the best sample's neighbours and golden section
// converges to it.
inline ReferencePoint BruteForceHeight(const Vec3& tip_from, const Vec3& tip_to,
                                       double radius, double x, double y,
                                       int samples = 20001) {
  const LD r = radius;
  const LD a[3] = {tip_from.x, tip_from.y, LD{tip_from.z} + r};
  const LD e[3] = {LD{tip_to.x} - tip_from.x, LD{tip_to.y} - tip_from.y,
                   LD{tip_to.z} - tip_from.z};
  const LD px = x, py = y;
  // Parameters t in [0, 1] whose ball covers (x, y): |d0 + t e|^2 <= r^2.
  const LD d0x = a[0] - px, d0y = a[1] - py;
  const LD ee = e[0] * e[0] + e[1] * e[1];
  const LD de = d0x * e[0] + d0y * e[1];
  const LD dd = d0x * d0x + d0y * d0y - r * r;
  LD lo = 0, hi = 1;
  if (ee == 0) {
    if (dd > 0) return {};
  } else {
    const LD disc = de * de - ee * dd;
    if (disc < 0) return {};
    const LD s = std::sqrt(disc);
    lo = std::max(lo, (-de - s) / ee);
    hi = std::min(hi, (-de + s) / ee);
    if (lo > hi) return {};
  }
  ReferencePoint best;
  // Sampling only picks the bracket; double precision is plenty for that.
  int best_k = 0;
  double best_w = std::numeric_limits<double>::infinity();
  const int n = std::max(samples, 2);
  for (int k = 0; k < n; ++k) {
    const LD t = lo + (hi - lo) * k / (n - 1);
    const double w = static_cast<double>(BallLow(a, e, r, px, py, t));
    if (w < best_w) {
      best_w = w;
      best_k = k;
    }
  }
  LD l = lo + (hi - lo) * std::max(best_k - 1, 0) / (n - 1);
  LD u = lo + (hi - lo) * std::min(best_k + 1, n - 1) / (n - 1);
  const LD phi = (std::sqrt(LD{5}) - 1) / 2;
  LD t1 = u - phi * (u - l), t2 = l + phi * (u - l);
  LD f1 = BallLow(a, e, r, px, py, t1), f2 = BallLow(a, e, r, px, py, t2);
  for (int it = 0; it < 120 && u - l > 0; ++it) {
    if (f1 <= f2) {
      u = t2;
      t2 = t1;
      f2 = f1;
      t1 = u - phi * (u - l);
      f1 = BallLow(a, e, r, px, py, t1);
    } else {
      l = t1;
      t1 = t2;
      f1 = f2;
      t2 = l + phi * (u - l);
      f2 = BallLow(a, e, r, px, py, t2);
    }
  }
  // The minimum over everything evaluated, with its slope.
  const LD candidates[] = {l, u, t1, t2,
                           lo + (hi - lo) * best_k / (n - 1), lo, hi};
  for (LD t : candidates) {
    LD slope = 0;
    const LD w = BallLow(a, e, r, px, py, t, &slope);
    if (w < best.w) {
      best.w = w;
      best.slope = slope;
      best.t = t;
    }
  }
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
