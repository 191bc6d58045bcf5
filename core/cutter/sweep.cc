#include "core/cutter/sweep.h"

namespace swarf {
namespace {

Sweep::Variant MakeVariant(const Vec3& a, const Vec3& b, const Cutter& c) {
  switch (c.kind) {
    case CutterKind::kBall:
      return BallSweep(a, b, c.radius);
    default:
      break;
  }
  // Shapes without their own sweep yet: unreachable once every kind has
  // one (ValidateCutter admits only those).
  return BallSweep(a, b, c.radius);
}

}  // namespace

Sweep::Sweep(const Vec3& tip_from, const Vec3& tip_to, const Cutter& cutter)
    : v_(MakeVariant(tip_from, tip_to, cutter)) {}

std::optional<Rect> FootprintBounds(const Vec3& tip_from, const Vec3& tip_to,
                                    const Cutter& cutter, double cap) {
  if (cutter.kind == CutterKind::kBall) {
    return BallSweep::FootprintBounds(tip_from, tip_to, cutter.radius, cap);
  }
  const Capsule c = Sweep(tip_from, tip_to, cutter).Footprint(cap);
  if (c.empty) return std::nullopt;
  return c.Bounds();
}

}  // namespace swarf
