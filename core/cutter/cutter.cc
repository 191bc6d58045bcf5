#include "core/cutter/cutter.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "absl/strings/str_cat.h"

namespace swarf {
namespace {

constexpr double kDegree = std::numbers::pi / 180;

absl::Status Bad(std::string_view field, std::string_view name,
                 std::string_view why, double v) {
  return absl::InvalidArgumentError(
      absl::StrCat(std::string(field), ".", std::string(name), " ",
                   std::string(why), ", got ", v));
}

// Height above the tip of a cone flank that leaves the axis at distance
// rho0 and height h0, at half angle a (from the axis), at distance rho.
double Flank(double rho0, double h0, double half_angle_deg, double rho) {
  return h0 + (rho - rho0) / std::tan(half_angle_deg * kDegree);
}

// A corner or tip radius: 0 where `zero_ok` (a flat end, a sharp cone),
// else in [kMinRadius, c.radius].
absl::Status ValidateInnerRadius(const Cutter& c, std::string_view field,
                                 std::string_view name, double v,
                                 bool zero_ok) {
  if (!std::isfinite(v) || v < 0) {
    return Bad(field, name, "must be finite and >= 0", v);
  }
  if (v > c.radius) {
    return Bad(field, name, absl::StrCat("must be at most the radius ", c.radius),
               v);
  }
  if (v == 0 && zero_ok) return absl::OkStatus();
  if (!(v >= kMinRadius)) {
    return Bad(field, name,
               absl::StrCat(zero_ok ? "must be 0 or at least " : "must be at least ",
                            kMinRadius, " mm"),
               v);
  }
  return absl::OkStatus();
}

}  // namespace

std::string_view CutterKindName(CutterKind kind) {
  switch (kind) {
    case CutterKind::kBall:
      return "ball";
    case CutterKind::kFlat:
      return "flat";
    case CutterKind::kBullNose:
      return "bull_nose";
    case CutterKind::kCone:
      return "cone";
    case CutterKind::kTaperedBall:
      return "tapered_ball";
  }
  return "unknown";
}

std::string CutterToString(const Cutter& c) {
  std::string s = absl::StrCat(std::string(CutterKindName(c.kind)), " r=", c.radius);
  switch (c.kind) {
    case CutterKind::kBullNose:
      absl::StrAppend(&s, " corner=", c.corner_radius);
      break;
    case CutterKind::kCone:
    case CutterKind::kTaperedBall:
      absl::StrAppend(&s, " half_angle=", c.half_angle_deg,
                      " tip=", c.tip_radius);
      break;
    default:
      break;
  }
  return s;
}

absl::Status ValidateCutter(const Cutter& c, std::string_view field) {
  if (!std::isfinite(c.radius)) return Bad(field, "radius", "must be finite", c.radius);
  if (!(c.radius >= kMinRadius && c.radius <= kMaxRadius)) {
    return Bad(field, "radius",
               absl::StrCat("must be in [", kMinRadius, ", ", kMaxRadius,
                            "] mm"),
               c.radius);
  }
  switch (c.kind) {
    case CutterKind::kBall:
    case CutterKind::kFlat:
      return absl::OkStatus();
    case CutterKind::kBullNose:
      return ValidateInnerRadius(c, field, "corner_radius", c.corner_radius,
                                 /*zero_ok=*/true);
    case CutterKind::kCone:
    case CutterKind::kTaperedBall:
      if (!std::isfinite(c.half_angle_deg) ||
          !(c.half_angle_deg >= kMinHalfAngleDeg) ||
          !(c.half_angle_deg < 90)) {
        return Bad(field, "half_angle_deg",
                   absl::StrCat("must be in [", kMinHalfAngleDeg,
                                ", 90) degrees"),
                   c.half_angle_deg);
      }
      return ValidateInnerRadius(c, field, "tip_radius", c.tip_radius,
                                 /*zero_ok=*/c.kind == CutterKind::kCone);
  }
  return absl::InvalidArgumentError(absl::StrCat(std::string(field), ": unknown shape"));
}

double ProfileHeight(const Cutter& c, double rho) {
  const double r = c.radius;
  rho = std::clamp(rho, 0.0, r);
  switch (c.kind) {
    case CutterKind::kBall:
      return r - std::sqrt(std::max(0.0, r * r - rho * rho));
    case CutterKind::kFlat:
      return 0;
    case CutterKind::kBullNose: {
      const double rc = c.corner_radius, flat = r - rc;
      if (rho <= flat) return 0;
      const double u = rho - flat;
      return rc - std::sqrt(std::max(0.0, rc * rc - u * u));
    }
    case CutterKind::kCone:
      if (rho <= c.tip_radius) return 0;
      return Flank(c.tip_radius, 0, c.half_angle_deg, rho);
    case CutterKind::kTaperedBall: {
      // The ball (centre tip_radius above the tip) meets the flank where
      // its normal makes half_angle with the horizontal.
      const double rb = c.tip_radius;
      const double a = c.half_angle_deg * kDegree;
      const double rho_t = rb * std::cos(a);
      if (rho <= rho_t) return rb - std::sqrt(std::max(0.0, rb * rb - rho * rho));
      return Flank(rho_t, rb - rb * std::sin(a), c.half_angle_deg, rho);
    }
  }
  return 0;
}

double FootprintRadius(const Cutter& c, double z_tip, double cap) {
  const double r = c.radius;
  if (c.kind != CutterKind::kBall && cap < z_tip) return 0;
  switch (c.kind) {
    case CutterKind::kBall: {
      // As the ball sweep computes it: h below the centre.
      const double h = z_tip + r - cap;
      return h > 0 ? std::sqrt(std::max(0.0, r * r - h * h)) : r;
    }
    case CutterKind::kFlat:
      return r;
    case CutterKind::kBullNose: {
      const double rc = c.corner_radius;
      const double h = z_tip + rc - cap;  // below the torus' centre circle
      return h > 0 ? (r - rc) + std::sqrt(std::max(0.0, rc * rc - h * h)) : r;
    }
    case CutterKind::kCone: {
      const double rho =
          c.tip_radius + (cap - z_tip) * std::tan(c.half_angle_deg * kDegree);
      return std::min(rho, r);
    }
    case CutterKind::kTaperedBall: {
      const double rb = c.tip_radius;
      const double a = c.half_angle_deg * kDegree;
      const double h = cap - z_tip;
      const double h_t = rb - rb * std::sin(a);
      if (h <= h_t) {
        const double d = rb - h;
        return std::min(std::sqrt(std::max(0.0, rb * rb - d * d)), r);
      }
      return std::min(rb * std::cos(a) + (h - h_t) * std::tan(a), r);
    }
  }
  return r;
}

}  // namespace swarf
