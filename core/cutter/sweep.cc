#include "core/cutter/sweep.h"

namespace swarf {
namespace {

Sweep::Variant MakeVariant(const Vec3& a, const Vec3& b, const Cutter& c) {
  // The degenerate bull-noses are those shapes, to the bit.
  if (SweptAsBall(c)) return BallSweep(a, b, c.radius);
  switch (c.kind) {
    case CutterKind::kBall:
      return BallSweep(a, b, c.radius);
    case CutterKind::kFlat:
      return FlatSweep(a, b, c.radius);
    case CutterKind::kBullNose:
      if (c.corner_radius == 0) return FlatSweep(a, b, c.radius);
      return BullNoseSweep(a, b, c.radius, c.corner_radius);
    case CutterKind::kCone:
      return ConeSweep(a, b, c.radius, c.half_angle_deg, c.tip_radius);
    case CutterKind::kTaperedBall:
      return TaperedBallSweep(a, b, c.radius, c.tip_radius,
                              c.half_angle_deg);
  }
  return BallSweep(a, b, c.radius);  // unreachable: ValidateCutter
}

}  // namespace

Sweep::Sweep(const Vec3& tip_from, const Vec3& tip_to, const Cutter& cutter)
    : v_(MakeVariant(tip_from, tip_to, cutter)) {}

Capsule FootprintCapsule(const Vec3& tip_from, const Vec3& tip_to,
                         const Cutter& cutter, double cap) {
  if (SweptAsBall(cutter)) {
    return BallSweep::FootprintOf(tip_from, tip_to, cutter.radius, cap);
  }
  // The profile sweeps' own (ProfileSweep::Footprint), with the cutter they
  // are built for: a bull-nose without a corner is the flat end.
  const bool flat = cutter.kind == CutterKind::kBullNose &&
                    cutter.corner_radius == 0;
  return TipFootprint(tip_from, tip_to,
                      flat ? Cutter::Flat(cutter.radius) : cutter, cap);
}

std::optional<Rect> FootprintBounds(const Vec3& tip_from, const Vec3& tip_to,
                                    const Cutter& cutter, double cap) {
  if (SweptAsBall(cutter)) {
    return BallSweep::FootprintBounds(tip_from, tip_to, cutter.radius, cap);
  }
  const Capsule c = FootprintCapsule(tip_from, tip_to, cutter, cap);
  if (c.empty) return std::nullopt;
  return c.Bounds();
}

}  // namespace swarf
