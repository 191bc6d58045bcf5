// What a cutter is: its kind and dimensions, validated in one place, and its
// profile (the height of its lower surface above the tip as a function of the
// distance from its axis).
//
// Every cutter is a surface of revolution about a vertical axis, positioned
// by its TIP: the lowest point on its axis. Units: millimetres; angles in
// degrees. Above its profile every cutter has a cylindrical side of `radius`.
//
// A Cutter is a plain value; all functions are pure and thread-safe.
#ifndef SWARF_CORE_CUTTER_CUTTER_H_
#define SWARF_CORE_CUTTER_CUTTER_H_

#include <cstdint>
#include <string>
#include <string_view>

#include "absl/status/status.h"

namespace swarf {

enum class CutterKind : uint8_t {
  kBall,         // radius
  kFlat,         // radius: flat disk bottom
  kBullNose,     // radius, corner_radius: flat annulus + torus corner
  kCone,         // radius, half_angle_deg, tip_radius (flat tip, 0: sharp)
  kTaperedBall,  // radius, half_angle_deg, tip_radius (the ball tip's)
};

// Physical bounds on a cutter's dimensions (mm). They keep every
// intermediate value of a sweep finite. kMinRadius also bounds a corner or
// tip radius that is not 0, and kMinHalfAngleDeg a cone's or tapered ball's
// half angle (degrees): a tip of 1e-200 mm or a flank at 1e-200 degrees
// gives curvatures whose squares overflow.
inline constexpr double kMinRadius = 1e-4;
inline constexpr double kMaxRadius = 1e5;
inline constexpr double kMinHalfAngleDeg = 1e-3;

struct Cutter {
  CutterKind kind = CutterKind::kBall;
  double radius = 0;          // outer radius R (mm)
  double corner_radius = 0;   // bull-nose torus radius rc: 0 or [1e-4, R]
  double half_angle_deg = 0;  // cone / tapered ball: flank vs axis, [1e-3, 90)
  double tip_radius = 0;      // cone: flat tip; tapered ball: ball tip

  static Cutter Ball(double r) { return {CutterKind::kBall, r, 0, 0, 0}; }
  static Cutter Flat(double r) { return {CutterKind::kFlat, r, 0, 0, 0}; }
  static Cutter BullNose(double r, double corner) {
    return {CutterKind::kBullNose, r, corner, 0, 0};
  }
  static Cutter Cone(double r, double half_angle_deg, double tip_radius) {
    return {CutterKind::kCone, r, 0, half_angle_deg, tip_radius};
  }
  static Cutter TaperedBall(double r, double tip_radius,
                            double half_angle_deg) {
    return {CutterKind::kTaperedBall, r, 0, half_angle_deg, tip_radius};
  }

  friend bool operator==(const Cutter&, const Cutter&) = default;
};

// "ball", "flat", "bull_nose", "cone", "tapered_ball".
std::string_view CutterKindName(CutterKind kind);

// Human-readable, e.g. "ball r=1", "bull_nose r=3 corner=1".
std::string CutterToString(const Cutter& c);

// InvalidArgument naming `field` + the dimension (e.g. "tools[0].radius")
// for a dimension that is not finite, out of [kMinRadius, kMaxRadius] (the
// radius), negative, or inconsistent: a corner or tip radius neither 0 nor
// in [kMinRadius, radius] (a tapered ball's tip not 0 either), a half angle
// outside [kMinHalfAngleDeg, 90). The only validation of a cutter; every
// layer calls it.
absl::Status ValidateCutter(const Cutter& c, std::string_view field);

// The cutter's lower surface: its height above the tip at horizontal
// distance rho (0 <= rho <= radius) from the axis. Nondecreasing and convex
// in rho. At rho == radius it is the height where the cylindrical side
// starts (0 for a flat end).
// (Used by tests and by FootprintRadius' derivation.)
double ProfileHeight(const Cutter& c, double rho);

// The inverse: the largest horizontal distance from the axis at which the
// lower surface of the cutter with its tip at height z_tip is at or below
// height `cap` (radius when cap is at or above the side's start; 0 when
// cap <= z_tip). Exact, so that a point outside a footprint built from it
// stays outside.
double FootprintRadius(const Cutter& c, double z_tip, double cap);

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_CUTTER_H_
