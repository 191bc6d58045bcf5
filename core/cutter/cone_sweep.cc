#include "core/cutter/cone_sweep.h"

#include <cmath>
#include <numbers>

#include "core/cutter/flat_sweep.h"

namespace swarf {

Profile ConeSweep::MakeProfile(double radius, double half_angle_deg,
                               double tip_radius) {
  if (tip_radius >= radius) return FlatSweep::MakeProfile(radius);
  Profile p;
  p.radius = radius;
  if (tip_radius > 0) p.Add(ProfilePiece::kFlat, 0, tip_radius);
  ProfilePiece& flank = p.Add(ProfilePiece::kLine, tip_radius, radius);
  // As ProfileHeight (core/cutter/cutter.cc) computes the flank.
  flank.k = 1 / std::tan(half_angle_deg * (std::numbers::pi / 180));
  return p;
}

ConeSweep::ConeSweep(const Vec3& tip_from, const Vec3& tip_to, double radius,
                     double half_angle_deg, double tip_radius)
    : ProfileSweep(tip_from, tip_to,
                   Cutter::Cone(radius, half_angle_deg, tip_radius),
                   MakeProfile(radius, half_angle_deg, tip_radius)) {}

}  // namespace swarf
