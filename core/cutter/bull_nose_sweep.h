// The sweep of a bull-nose (torus) cutter (BullNose{radius, corner_radius}):
// a flat annulus out to R - rc, then a torus corner of radius rc whose
// centre circle lies at R - rc from the axis, rc above the tip, then the
// cylindrical side. Exact heights and analytic derivatives by the profile
// engine (core/cutter/profile_sweep.h). On a horizontal move the groove's
// cross-section is the flat band plus the corner's circle (closed form);
// on a ramp the torus envelope has no closed form: a bracketed Newton solve
// of the one-parameter envelope condition (TorusContact), derivatives by
// the envelope and implicit function theorems. corner_radius == radius is
// the ball (an on-axis sphere piece, the ball's cylinder), 0 the flat end
// (the flat end's profile exactly). Vertical walls (the torus' equator at
// R): derivatives clamped as the ball's rim (kRimDepthFraction of rc on the
// depth, or of the contact angle's range on a ramp), then ClampedJet;
// heights never clamped.
//
// Immutable value; thread-safe.
#ifndef SWARF_CORE_CUTTER_BULL_NOSE_SWEEP_H_
#define SWARF_CORE_CUTTER_BULL_NOSE_SWEEP_H_

#include "core/cutter/profile_sweep.h"

namespace swarf {

class BullNoseSweep : public ProfileSweep {
 public:
  // Tool tips (finite, mm); dimensions as ValidateCutter admits.
  BullNoseSweep(const Vec3& tip_from, const Vec3& tip_to, double radius,
                double corner_radius);

  // f = 0 on [0, R - rc], rc - sqrt(rc^2 - (rho - R + rc)^2) on [R - rc, R].
  static Profile MakeProfile(double radius, double corner_radius);
};

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_BULL_NOSE_SWEEP_H_
