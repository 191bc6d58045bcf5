// The sweep of a flat end mill (FlatEnd{radius}): a flat disk bottom at the
// tip and a cylindrical side. Exact heights and analytic derivatives by the
// profile engine (core/cutter/profile_sweep.h): on a horizontal move the
// floor is flat (all derivatives 0) out to the wall at `radius` from the
// path; on a ramp of slope m the floor is the disk's leading rim,
// w = z0 + m (a - sqrt(R^2 - n^2)) (a along the move, n across it), which
// turns vertical at |n| = R. Vertical walls: derivatives clamped as the
// ball's rim (kRimDepthFraction of R on the rim's half chord), then
// bounded with ClampedJet; heights never clamped.
//
// Immutable value; thread-safe.
#ifndef SWARF_CORE_CUTTER_FLAT_SWEEP_H_
#define SWARF_CORE_CUTTER_FLAT_SWEEP_H_

#include "core/cutter/profile_sweep.h"

namespace swarf {

class FlatSweep : public ProfileSweep {
 public:
  // Tool tips (finite, mm); radius as ValidateCutter admits.
  FlatSweep(const Vec3& tip_from, const Vec3& tip_to, double radius);

  // f(rho) = 0 on [0, R].
  static Profile MakeProfile(double radius);
};

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_FLAT_SWEEP_H_
