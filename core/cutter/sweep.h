// The seam between the simulation and the cutter shapes: the sweep of one
// straight move of any cutter, and the one place that picks the shape.
//
// Every shape's sweep class (BallSweep, FlatSweep, ...: one file per shape
// in core/cutter/) is an immutable value, thread-safe, built from the two
// tool-tip positions of the move and a Cutter validated by ValidateCutter,
// and provides:
//   double lowest() const;               // lowest height the tool reaches
//   Capsule Footprint(double cap) const; // conservative XY region where the
//                                        // swept surface is below cap
//   double Height(double x, double y) const;  // exact lowest height of the
//                                        // swept solid at (x, y); +inf where
//                                        // the tool never passes over it
//   void Heights(const double* x, const double* y, int32_t n,
//                double* out) const;     // bit-identical to Height, n <= 256
//   SurfaceJet JetAt(double x, double y) const;  // w bit-identical to
//                                        // Height; analytic derivatives of
//                                        // the swept surface that sets the
//                                        // height, bounded with ClampedJet;
//                                        // zeros where the height is +inf
// The tile kernel is a template over these classes, chosen once per move
// (Sweep::Visit), so that each shape's row loops stay vectorized.
#ifndef SWARF_CORE_CUTTER_SWEEP_H_
#define SWARF_CORE_CUTTER_SWEEP_H_

#include <algorithm>
#include <cstdint>
#include <optional>
#include <utility>
#include <variant>

#include "core/cutter/ball_sweep.h"
#include "core/cutter/bull_nose_sweep.h"
#include "core/cutter/capsule.h"
#include "core/cutter/cone_sweep.h"
#include "core/cutter/cutter.h"
#include "core/cutter/flat_sweep.h"
#include "core/cutter/tapered_ball_sweep.h"
#include "core/geometry.h"
#include "core/surface_jet.h"

namespace swarf {

// The cutter whose sweep Sweep builds for `cutter`: itself, but for the
// degenerate bull-noses, swept as the ball (corner = radius) and as the flat
// end (corner 0).
inline Cutter SweptCutter(const Cutter& cutter) {
  if (cutter.kind == CutterKind::kBullNose) {
    if (cutter.corner_radius == cutter.radius) {
      return Cutter::Ball(cutter.radius);
    }
    if (cutter.corner_radius == 0) return Cutter::Flat(cutter.radius);
  }
  return cutter;
}

// Whether Sweep holds a BallSweep(tip_from, tip_to, cutter.radius) for
// `cutter`: the ball, and the bull-nose whose corner is its radius.
inline bool SweptAsBall(const Cutter& cutter) {
  return SweptCutter(cutter).kind == CutterKind::kBall;
}

// The sweep of one straight move of any cutter. Immutable, thread-safe.
class Sweep {
 public:
  using Variant = std::variant<BallSweep, FlatSweep, BullNoseSweep,
                               ConeSweep, TaperedBallSweep>;

  // tip_from/tip_to finite; `cutter` valid (ValidateCutter). Exact for
  // every CutterKind. A bull-nose whose corner is its radius is swept as the
  // ball (BallSweep: the same bits), one whose corner is 0 as the flat end.
  Sweep(const Vec3& tip_from, const Vec3& tip_to, const Cutter& cutter);

  double lowest() const {
    return std::visit([](const auto& s) { return s.lowest(); }, v_);
  }
  Capsule Footprint(double cap) const {
    return std::visit([&](const auto& s) { return s.Footprint(cap); }, v_);
  }
  double Height(double x, double y) const {
    return std::visit([&](const auto& s) { return s.Height(x, y); }, v_);
  }
  void Heights(const double* x, const double* y, int32_t n,
               double* out) const {
    std::visit([&](const auto& s) { s.Heights(x, y, n, out); }, v_);
  }
  // Height and derivatives of the swept surface at (x, y), as the tile
  // kernel stores them (before float rounding).
  SurfaceJet JetAt(double x, double y) const {
    return std::visit([&](const auto& s) { return s.JetAt(x, y); }, v_);
  }
  // The ball's sweep, or null for the other shapes.
  const BallSweep* ball() const { return std::get_if<BallSweep>(&v_); }
  // Calls f(const ShapeSweep&) with the shape's own class.
  template <class F>
  decltype(auto) Visit(F&& f) const {
    return std::visit(std::forward<F>(f), v_);
  }

 private:
  Variant v_;
};

// A quick, conservative test done before FootprintBounds where many moves
// are tried against a box: SurelyMisses is true only where the footprint
// below `cap` of the move between the two tips surely misses `box`
// (FootprintCapsule(...) does not meet it, though its bounds may: at their
// corners); false where unsure. For the ball: the footprint's axis is a
// part of the move, so it lies within its radius sqrt(r^2 - h^2) (h: the
// lowest ball centre above cap; r where below) of the tips' XY box, and the
// box must lie farther than that from it by more than the footprint's
// margins (1e-9 mm and a relative 1e-12) and the rounding of its clipped
// ends: 1e-6 mm. No root and no division, where FootprintBounds takes both
// and a call. Other shapes: false. The move's parts are taken
// once (Of), for testing one move against many boxes; branch-free, so that
// loops over many moves' parts vectorize.
struct FootprintGap {
  double ball = 0;                        // 1: swept as a ball; 0: never misses
  double x0 = 0, x1 = 0, y0 = 0, y1 = 0;  // the tips' XY box
  double z_r = 0;                         // lowest tip + radius
  double r2 = 0;                          // radius^2

  static FootprintGap Of(const Vec3& tip_from, const Vec3& tip_to,
                         const Cutter& cutter) {
    return {SweptAsBall(cutter) ? 1.0 : 0.0,
            std::min(tip_from.x, tip_to.x),
            std::max(tip_from.x, tip_to.x),
            std::min(tip_from.y, tip_to.y),
            std::max(tip_from.y, tip_to.y),
            std::min(tip_from.z, tip_to.z) + cutter.radius,
            cutter.radius * cutter.radius};
  }
  // The margin a gap must clear (mm).
  static constexpr double kSlack = 1e-6;
  // The square of the footprint's radius below cap, sqrt(r^2 - h^2) with
  // h = z_r - cap where the lowest centre is above cap, else r (negative
  // where the ball lies wholly above cap). A select, for vector loops.
  static double ReachSquared(double z_r, double r2, double cap) {
    const double h = z_r - cap;
    return h > 0 ? r2 - h * h : r2;
  }
  // 1 where it surely misses, else 0, from the parts (selects only). The
  // footprint below cap lies within the reach of the centres' XY segment,
  // which lies in the tips' box: a box farther than the reach from it
  // (Euclidean: the gaps on both axes count) is missed. Each gap is less
  // the slack, so the margin is at least the slack in any direction.
  // Where the reach is negative (the ball above cap everywhere) only a box
  // off the tips' box (a gap) is counted as missed.
  static double Misses(double ball, double x0, double x1, double y0, double y1,
                       double z_r, double r2, const Rect& box, double cap) {
    // std::max by value: selects (by reference they were branches).
    auto max = [](double a, double b) { return a < b ? b : a; };
    const double gx = max(max(box.x0 - x1, x0 - box.x1) - kSlack, 0.0);
    const double gy = max(max(box.y0 - y1, y0 - box.y1) - kSlack, 0.0);
    const double rho2 = max(ReachSquared(z_r, r2, cap), 0.0);
    return gx * gx + gy * gy > rho2 ? ball : 0.0;
  }
  bool SurelyMisses(const Rect& box, double cap) const {
    return Misses(ball, x0, x1, y0, y1, z_r, r2, box, cap) != 0;
  }
};

// FootprintGap::Of(...).SurelyMisses(box, cap), for one test.
inline bool FootprintSurelyMisses(const Vec3& tip_from, const Vec3& tip_to,
                                  const Cutter& cutter, const Rect& box,
                                  double cap) {
  return FootprintGap::Of(tip_from, tip_to, cutter).SurelyMisses(box, cap);
}

// The footprint's bounds below `cap` for the move between two tool tips,
// without building the sweep where the shape allows; nullopt where the
// footprint is empty. Bit-identical to Sweep(...).Footprint(cap).Bounds().
std::optional<Rect> FootprintBounds(const Vec3& tip_from, const Vec3& tip_to,
                                    const Cutter& cutter, double cap);
// The footprint below `cap` itself, bit-identical to Sweep(tip_from, tip_to,
// cutter).Footprint(cap), without building the sweep.
Capsule FootprintCapsule(const Vec3& tip_from, const Vec3& tip_to,
                         const Cutter& cutter, double cap);
// FootprintCapsule's ends, radius and `empty` (the same bits) without its
// direction (ux, uy, length, inv_ux, inv_uy left 0), which costs a hypot
// and divisions: for callers that read only those, such as Bounds().
Capsule FootprintCapsuleEnds(const Vec3& tip_from, const Vec3& tip_to,
                             const Cutter& cutter, double cap);
// The lowest height the tool reaches on the move, bit-identical to
// Sweep(tip_from, tip_to, cutter).lowest(), without building the sweep.
double SweepLowest(const Vec3& tip_from, const Vec3& tip_to,
                   const Cutter& cutter);

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_SWEEP_H_
