#include "core/cutter/bull_nose_sweep.h"

#include "core/cutter/flat_sweep.h"

namespace swarf {

Profile BullNoseSweep::MakeProfile(double radius, double corner_radius) {
  if (corner_radius == 0) return FlatSweep::MakeProfile(radius);
  Profile p;
  p.radius = radius;
  const double flat = radius - corner_radius;
  if (flat > 0) p.Add(ProfilePiece::kFlat, 0, flat);
  // corner == radius: the centre circle shrinks to the axis, a sphere.
  ProfilePiece& arc =
      flat > 0 ? p.Add(ProfilePiece::kTorus, flat, radius)
               : p.Add(ProfilePiece::kSphere, 0, radius);
  arc.rho_c = arc.rho0;
  arc.hc = corner_radius;
  arc.rc = corner_radius;
  return p;
}

BullNoseSweep::BullNoseSweep(const Vec3& tip_from, const Vec3& tip_to,
                             double radius, double corner_radius)
    : ProfileSweep(tip_from, tip_to,
                   Cutter::BullNose(radius, corner_radius),
                   MakeProfile(radius, corner_radius)) {}

}  // namespace swarf
