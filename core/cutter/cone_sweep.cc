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
  if (tip_radius > 0) {
    p.piece[p.pieces].kind = ProfilePiece::kFlat;
    p.piece[p.pieces].rho0 = 0;
    p.piece[p.pieces].rho1 = tip_radius;
    ++p.pieces;
  }
  ProfilePiece& flank = p.piece[p.pieces++];
  flank.kind = ProfilePiece::kLine;
  flank.rho0 = tip_radius;
  flank.rho1 = radius;
  flank.h0 = 0;
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
