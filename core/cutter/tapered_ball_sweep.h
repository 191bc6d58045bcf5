// The sweep of a tapered ball mill (TaperedBall{radius, tip_radius,
// half_angle_deg}): the relief-carving tool. A ball tip of tip_radius rb
// (centre rb above the tip) tangent to a cone flank at half_angle_deg from
// the axis, where the ball's normal makes the half angle with the
// horizontal (rho_t = rb cos a, height rb (1 - sin a)), the flank up to R,
// then the cylindrical side. Exact heights and analytic derivatives by the
// profile engine (core/cutter/profile_sweep.h): the ball tip sweeps the
// ball's cylinder (paper eq. 12-14) where its contact lies within rho_t,
// the flank the wedge of eq. L; the wall at R is a kink circle. Vertical
// walls: derivatives clamped as the ball's rim (kRimDepthFraction of R on
// the wall circle's half chord), then ClampedJet; heights never clamped.
//
// Immutable value; thread-safe.
#ifndef SWARF_CORE_CUTTER_TAPERED_BALL_SWEEP_H_
#define SWARF_CORE_CUTTER_TAPERED_BALL_SWEEP_H_

#include "core/cutter/profile_sweep.h"

namespace swarf {

class TaperedBallSweep : public ProfileSweep {
 public:
  // Tool tips (finite, mm); dimensions as ValidateCutter admits.
  TaperedBallSweep(const Vec3& tip_from, const Vec3& tip_to, double radius,
                   double tip_radius, double half_angle_deg);

  // f = rb - sqrt(rb^2 - rho^2) on [0, rb cos a], then the flank
  // rb (1 - sin a) + (rho - rb cos a) cot a up to R.
  static Profile MakeProfile(double radius, double tip_radius,
                             double half_angle_deg);
};

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_TAPERED_BALL_SWEEP_H_
