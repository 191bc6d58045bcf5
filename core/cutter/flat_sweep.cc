#include "core/cutter/flat_sweep.h"

namespace swarf {

Profile FlatSweep::MakeProfile(double radius) {
  Profile p;
  p.radius = radius;
  p.Add(ProfilePiece::kFlat, 0, radius);
  return p;
}

FlatSweep::FlatSweep(const Vec3& tip_from, const Vec3& tip_to, double radius)
    : ProfileSweep(tip_from, tip_to, Cutter::Flat(radius),
                   MakeProfile(radius)) {}

}  // namespace swarf
