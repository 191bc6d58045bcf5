#include "core/cutter/tapered_ball_sweep.h"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace swarf {

Profile TaperedBallSweep::MakeProfile(double radius, double tip_radius,
                                      double half_angle_deg) {
  // As ProfileHeight (core/cutter/cutter.cc): the tangency where the ball's
  // normal makes the half angle with the horizontal.
  const double a = half_angle_deg * (std::numbers::pi / 180);
  const double rb = tip_radius;
  const double rho_t = std::min(rb * std::cos(a), radius);
  Profile p;
  p.radius = radius;
  ProfilePiece& ball = p.Add(ProfilePiece::kSphere, 0, rho_t);
  ball.hc = rb;
  ball.rc = rb;
  ProfilePiece& flank = p.Add(ProfilePiece::kLine, rho_t, radius);
  flank.h0 = rb - rb * std::sin(a);
  flank.k = 1 / std::tan(a);
  return p;
}

TaperedBallSweep::TaperedBallSweep(const Vec3& tip_from, const Vec3& tip_to,
                                   double radius, double tip_radius,
                                   double half_angle_deg)
    : ProfileSweep(tip_from, tip_to,
                   Cutter::TaperedBall(radius, tip_radius, half_angle_deg),
                   MakeProfile(radius, tip_radius, half_angle_deg)) {}

}  // namespace swarf
