// The sweep of a cone cutter (Cone{radius, half_angle_deg, tip_radius}):
// V-bits, chamfer mills and engravers. A flat tip of tip_radius (0: sharp),
// a flank at half_angle_deg from the axis (slope k = cot(half angle)) up to
// R, then the cylindrical side. Exact heights and analytic derivatives by
// the profile engine (core/cutter/profile_sweep.h): the flank's envelope on
// any move with |slope| < k is the wedge w = z0 + m a + |n| sqrt(k^2 - m^2)
// + const (eq. L there: planes, zero second derivatives); the flat tip's
// rim and the wall at R are kink circles. Vertical walls and the sharp apex:
// derivatives clamped as the ball's rim (kRimDepthFraction of the circle's
// radius on its half chord, of R on the apex distance), then ClampedJet;
// heights never clamped.
//
// Immutable value; thread-safe.
#ifndef SWARF_CORE_CUTTER_CONE_SWEEP_H_
#define SWARF_CORE_CUTTER_CONE_SWEEP_H_

#include "core/cutter/profile_sweep.h"

namespace swarf {

class ConeSweep : public ProfileSweep {
 public:
  // Tool tips (finite, mm); dimensions as ValidateCutter admits.
  ConeSweep(const Vec3& tip_from, const Vec3& tip_to, double radius,
            double half_angle_deg, double tip_radius);

  // f = 0 on [0, tip_radius], (rho - tip_radius) cot(half angle) to R.
  static Profile MakeProfile(double radius, double half_angle_deg,
                             double tip_radius);
};

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_CONE_SWEEP_H_
