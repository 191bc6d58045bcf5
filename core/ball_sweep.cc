#include "core/ball_sweep.h"

#include <algorithm>
#include <cmath>

namespace swarf {
namespace {

// Moves whose horizontal travel is below this fraction of their length are
// treated as vertical: their cylinder part would be a sliver narrower than
// 1e-12 of the move, and its derivatives would not be representable.
constexpr double kVerticalFraction = 1e-12;

// The footprint is widened by this much (mm) so that it stays conservative
// under rounding: a node whose swept height is below the cap is always
// evaluated, whatever the cap, which keeps results independent of batching.
constexpr double kFootprintMargin = 1e-9;

double ClampDerivative(double v) {
  return std::clamp(v, -kMaxDerivative, kMaxDerivative);
}

SurfaceJet Clamped(const SurfaceJet& j) {
  return {j.w,
          ClampDerivative(j.wx),
          ClampDerivative(j.wy),
          ClampDerivative(j.wxx),
          ClampDerivative(j.wxy),
          ClampDerivative(j.wyy)};
}

// Restricts `iv` to the x where lo <= a x + b <= hi.
void ClipLinear(double a, double b, double lo, double hi, Interval* iv) {
  if (a == 0) {
    if (b < lo || b > hi) *iv = Interval{};
    return;
  }
  double x_lo = (lo - b) / a, x_hi = (hi - b) / a;
  if (a < 0) std::swap(x_lo, x_hi);
  iv->Intersect(x_lo, x_hi);
}

}  // namespace

double SphereHeight(const Vec3& c, double r, double x, double y) {
  const double dx = x - c.x, dy = y - c.y;
  const double d2 = r * r - (dx * dx + dy * dy);
  if (!(d2 >= 0)) return kInf;
  return c.z - std::sqrt(d2);
}

SurfaceJet SphereJet(double z, double dx, double dy, double depth) {
  // Eq. (8)/(9) with z - zc = -depth.
  SurfaceJet j;
  j.w = z;
  j.wx = dx / depth;
  j.wy = dy / depth;
  j.wxx = (1 + j.wx * j.wx) / depth;
  j.wxy = (j.wx * j.wy) / depth;
  j.wyy = (1 + j.wy * j.wy) / depth;
  return Clamped(j);
}

BallSweep::BallSweep(const Vec3& tip_from, const Vec3& tip_to, double radius)
    : a_{tip_from.x, tip_from.y, tip_from.z + radius},
      b_{tip_to.x, tip_to.y, tip_to.z + radius},
      r_(radius),
      r2_(radius * radius),
      kind_(kGeneral),
      len_(0),
      k1_(0), k2_(0), k3_(0), g_(0), inv_g_(0), h1_(0), h2_(0) {
  const double dx = b_.x - a_.x, dy = b_.y - a_.y, dz = b_.z - a_.z;
  const double dxy = std::hypot(dx, dy);
  len_ = std::hypot(dxy, dz);
  if (len_ == 0) {
    kind_ = kPoint;
    return;
  }
  if (dxy <= kVerticalFraction * len_) {
    kind_ = kVertical;
    return;
  }
  // Eq. (10).
  k1_ = dx / len_;
  k2_ = dy / len_;
  k3_ = dz / len_;
  g_ = dxy / len_;
  inv_g_ = len_ / dxy;
  h1_ = dx / dxy;
  h2_ = dy / dxy;
}

SurfaceJet BallSweep::CylinderJet(const SweepPoint& p) const {
  // Eq. (14). At the lower root of eq. (12), C1 = A s - k3 (k1 px + k2 py)
  // simplifies to -g sqrt(r^2 - n^2); using that form avoids its
  // cancellation for near-vertical moves, and clamping the root bounds the
  // slope at the rim like the spheres'.
  const double s = p.w - a_.z;
  const double px = p.px, py = p.py;
  const double k1 = k1_, k2 = k2_, k3 = k3_;
  const double A = g_ * g_;
  const double c1 = -g_ * std::fmax(p.depth, kRimDepthFraction * r_);
  const double c2 = -k1 * k3 * s + (k2 * k2 + k3 * k3) * px - k1 * k2 * py;
  const double c3 = -k2 * k3 * s + (k1 * k1 + k3 * k3) * py - k1 * k2 * px;
  SurfaceJet j;
  j.w = p.w;
  j.wx = -c2 / c1;
  j.wy = -c3 / c1;
  const double c1x = A * j.wx - k1 * k3;
  const double c1y = A * j.wy - k2 * k3;
  const double c2x = -k1 * k3 * j.wx + k2 * k2 + k3 * k3;
  const double c2y = -k1 * k3 * j.wy - k1 * k2;
  const double c3y = -k2 * k3 * j.wy + k1 * k1 + k3 * k3;
  j.wxx = -(c2x + j.wx * c1x) / c1;
  j.wxy = -(c2y + j.wx * c1y) / c1;
  j.wyy = -(c3y + j.wy * c1y) / c1;
  return Clamped(j);
}

SurfaceJet BallSweep::Jet(const SweepPoint& p) const {
  switch (p.piece) {
    case SweepPoint::kCylinder:
      return CylinderJet(p);
    case SweepPoint::kStartSphere:
    case SweepPoint::kEndSphere:
      return SphereJet(p.w, p.px, p.py,
                       std::fmax(p.depth, kRimDepthFraction * r_));
    case SweepPoint::kNone:
      break;
  }
  return SurfaceJet{kInf, 0, 0, 0, 0, 0};
}

BallSweep::Capsule BallSweep::Footprint(double cap) const {
  Capsule c;
  // Only centres below cap + r can put the ball below cap.
  const double z_lim = cap + r_ + kFootprintMargin;
  double t0 = 0, t1 = 1;
  if (a_.z >= z_lim && b_.z >= z_lim) return c;
  if (a_.z >= z_lim || b_.z >= z_lim) {
    const double t = (z_lim - a_.z) / (b_.z - a_.z);
    if (a_.z < z_lim) {
      t1 = std::fmin(1.0, t + 1e-12);
    } else {
      t0 = std::fmax(0.0, t - 1e-12);
    }
  }
  // Over the kept part, a ball at height zc reaches below cap within a
  // horizontal radius sqrt(r^2 - (zc - cap)^2), largest at the lowest centre.
  const double z_min = std::fmin(a_.z, b_.z);
  double rho = r_;
  if (z_min > cap) {
    const double h = z_min - cap;
    rho = std::sqrt(std::fmax(0.0, r2_ - h * h));
  }
  c.empty = false;
  c.x0 = a_.x + t0 * (b_.x - a_.x);
  c.y0 = a_.y + t0 * (b_.y - a_.y);
  c.x1 = a_.x + t1 * (b_.x - a_.x);
  c.y1 = a_.y + t1 * (b_.y - a_.y);
  c.radius = rho * (1 + 1e-12) + kFootprintMargin;
  return c;
}

Interval BallSweep::Capsule::RowSpan(double y) const {
  Interval out;
  if (empty) return out;
  const double r2 = radius * radius;
  for (const auto& [cx, cy] : {std::pair{x0, y0}, std::pair{x1, y1}}) {
    const double dy = y - cy;
    const double q = r2 - dy * dy;
    if (q >= 0) {
      const double w = std::sqrt(q);
      out.Hull({cx - w, cx + w});
    }
  }
  const double ex = x1 - x0, ey = y1 - y0;
  const double l = std::hypot(ex, ey);
  if (l > 0) {
    const double ux = ex / l, uy = ey / l;
    Interval strip{-kInf, kInf};
    // 0 <= (p - p0) . u <= l  and  |(p - p0) . (-uy, ux)| <= radius.
    ClipLinear(ux, (y - y0) * uy - x0 * ux, 0, l, &strip);
    ClipLinear(-uy, x0 * uy + (y - y0) * ux, -radius, radius, &strip);
    out.Hull(strip);
  }
  return out;
}

}  // namespace swarf
