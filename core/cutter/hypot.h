// sqrt(x^2 + y^2) without undue overflow or underflow, the same function
// wherever swarf is built, and branch-free so that loops over it vectorize.
#ifndef SWARF_CORE_CUTTER_HYPOT_H_
#define SWARF_CORE_CUTTER_HYPOT_H_

#include <cmath>
#include <limits>

namespace swarf {

// hypot(x, y) by Borges' corrected algorithm ("An improved algorithm for
// hypot(a, b)", 2019, its fused-multiply-add-free form): the rounded square
// root, then one Newton step on the exact residual of the squares. This is
// the algorithm of glibc 2.35 and later (without FMA, as x86-64 builds
// it), and tests check that both agree bit for bit there; within 1 ulp
// elsewhere. The sweeps use it instead of std::hypot so that their bits do
// not depend on the platform's libm, and so that kernels building many
// sweeps at once (BallSweep::MakeFrames) vectorize it. Every operation is
// a separately rounded IEEE operation (build flags: -ffp-contract=off).
// Both arms of each test are computed and one selected: no branches.
[[gnu::always_inline]] inline double Hypot(double x, double y) {
  constexpr double kScale = 0x1p-600;  // scale factor for extreme inputs
  constexpr double kLarge = 0x1p+511;  // above: squares may overflow
  constexpr double kTiny = 0x1p-459;   // below: squares may underflow
  constexpr double kEps = 0x1p-54;     // ay below ax * kEps cannot matter
  const double fx = std::fabs(x), fy = std::fabs(y);
  const double ax = fx < fy ? fy : fx;
  const double ay = fx < fy ? fx : fy;
  const bool large = ax > kLarge;
  const bool tiny = !large && ay < kTiny;
  // Scaled so that squaring neither overflows nor underflows.
  const double sx = large ? ax * kScale : tiny ? ax / kScale : ax;
  const double sy = large ? ay * kScale : tiny ? ay / kScale : ay;
  double h = std::sqrt(sx * sx + sy * sy);
  // The residual h^2 - sx^2 - sy^2, in the form that is exact for the two
  // regimes (the larger input near h, or both near h / sqrt(2)).
  const bool close = h <= 2.0 * sy;
  const double delta = close ? h - sy : h - sx;
  const double t1_close = sx * (2.0 * delta - sx);
  const double t2_close = (delta - 2.0 * (sx - sy)) * delta;
  const double t1_far = 2.0 * delta * (sx - 2.0 * sy);
  const double t2_far = (4.0 * delta - sy) * sy + delta * delta;
  const double t1 = close ? t1_close : t1_far;
  const double t2 = close ? t2_close : t2_far;
  h -= (t1 + t2) / (2.0 * h);
  const double scaled = large ? h / kScale : tiny ? h * kScale : h;
  // The smaller input below an ulp of the larger one: their plain sum
  // (tiny: ax >= ay / kEps, else ay <= ax * kEps; written as one comparison
  // of selected values, which vectorizes).
  const double small = tiny ? ay / kEps : ay;
  const double big = tiny ? ax : ax * kEps;
  const double r = small <= big ? ax + ay : scaled;
  // Infinities win over NaNs; otherwise NaNs propagate.
  constexpr double kInfinity = std::numeric_limits<double>::infinity();
  const double special = fx == kInfinity || fy == kInfinity ? kInfinity
                                                            : x + y;
  const bool finite = fx <= std::numeric_limits<double>::max() &&
                      fy <= std::numeric_limits<double>::max();
  return finite ? r : special;
}

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_HYPOT_H_
