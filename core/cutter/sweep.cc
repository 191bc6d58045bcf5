#include "core/cutter/sweep.h"

namespace swarf {
namespace {

Sweep::Variant MakeVariant(const Vec3& a, const Vec3& b, const Cutter& c) {
  // The degenerate bull-noses are those shapes, to the bit.
  const Cutter s = SweptCutter(c);
  switch (s.kind) {
    case CutterKind::kBall:
      return BallSweep(a, b, s.radius);
    case CutterKind::kFlat:
      return FlatSweep(a, b, s.radius);
    case CutterKind::kBullNose:
      return BullNoseSweep(a, b, s.radius, s.corner_radius);
    case CutterKind::kCone:
      return ConeSweep(a, b, s.radius, s.half_angle_deg, s.tip_radius);
    case CutterKind::kTaperedBall:
      return TaperedBallSweep(a, b, s.radius, s.tip_radius,
                              s.half_angle_deg);
  }
  return BallSweep(a, b, s.radius);  // unreachable: ValidateCutter
}

}  // namespace

Sweep::Sweep(const Vec3& tip_from, const Vec3& tip_to, const Cutter& cutter)
    : v_(MakeVariant(tip_from, tip_to, cutter)) {}

Capsule FootprintCapsule(const Vec3& tip_from, const Vec3& tip_to,
                         const Cutter& cutter, double cap) {
  // As BallSweep::Footprint and TipFootprint: the ends, then the
  // direction.
  Capsule c = FootprintCapsuleEnds(tip_from, tip_to, cutter, cap);
  if (!c.empty) FillDirection(&c);
  return c;
}

Capsule FootprintCapsuleEnds(const Vec3& tip_from, const Vec3& tip_to,
                             const Cutter& cutter, double cap) {
  const Cutter s = SweptCutter(cutter);
  if (s.kind == CutterKind::kBall) {
    return BallSweep::FootprintEndsOf(tip_from, tip_to, s.radius, cap);
  }
  // The profile sweeps' own (ProfileSweep::Footprint), with the cutter they
  // are built for.
  return TipFootprintEnds(tip_from, tip_to, s, cap);
}

double SweepLowest(const Vec3& tip_from, const Vec3& tip_to,
                   const Cutter& cutter) {
  const Cutter s = SweptCutter(cutter);
  if (s.kind == CutterKind::kBall) {
    // BallSweep's: its balls' lowest centre less the radius (the centres
    // are the tips raised by it, so not always the lowest tip's bits).
    return std::min(tip_from.z + s.radius, tip_to.z + s.radius) - s.radius;
  }
  return std::min(tip_from.z, tip_to.z);  // ProfileSweep's
}

std::optional<Rect> FootprintBounds(const Vec3& tip_from, const Vec3& tip_to,
                                    const Cutter& cutter, double cap) {
  if (SweptAsBall(cutter)) {
    return BallSweep::FootprintBounds(tip_from, tip_to, cutter.radius, cap);
  }
  const Capsule c = FootprintCapsuleEnds(tip_from, tip_to, cutter, cap);
  if (c.empty) return std::nullopt;
  return c.Bounds();
}

}  // namespace swarf
