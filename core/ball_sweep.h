// The lower surface swept by a ball-end cutter moving along a straight line
// (paper section 4, eq. 6-14), with closed-form height and derivatives.
//
// Positions given to BallSweep are tool-tip positions (mm), as CAM posts write
// them; the ball centre is tip + r on z. The swept lower surface at (x, y) is
// the lowest point of the union of all balls along the move. Since that
// height, as a function of the position t along the move, is convex, it is
// the cylinder (mid-surface) where its contact point lies inside the move,
// and otherwise the start or end sphere on the side where the contact lies.
//
// A BallSweep is an immutable value; all methods are thread-safe.
#ifndef SWARF_CORE_BALL_SWEEP_H_
#define SWARF_CORE_BALL_SWEEP_H_

#include <cmath>
#include <cstdint>
#include <limits>

#include "core/geometry.h"
#include "core/surface_jet.h"

namespace swarf {

inline constexpr double kInf = std::numeric_limits<double>::infinity();

// At the rim of a sphere or cylinder the lower surface is vertical and its
// derivatives are infinite. Derivatives are computed with the depth below the
// centre (sqrt(r^2 - d^2)) clamped to at least kRimDepthFraction * r, which
// bounds the slope at about 1/kRimDepthFraction (89.99 degrees) and keeps the
// curvature consistent with that slope, so a rim node's patch stays the
// osculating parabola of the steepest representable sphere. The height itself
// is never clamped. Every derivative is finally limited to
// +-kMaxDerivative so that it is finite in float storage.
inline constexpr double kRimDepthFraction = 1e-4;
inline constexpr double kMaxDerivative = 1e30;

// Eq. (7): lower hemisphere of radius r centred at c; +inf outside its shadow.
double SphereHeight(const Vec3& c, double r, double x, double y);

// Eq. (8)-(9): derivatives of the lower hemisphere at offset (dx, dy) from the
// centre, where `depth` = zc - z = sqrt(r^2 - dx^2 - dy^2) (already clamped).
SurfaceJet SphereJet(double z, double dx, double dy, double depth);

// Where (x, y) lies on the swept surface, and the intermediate values needed
// to differentiate there.
struct SweepPoint {
  enum Piece : uint8_t { kNone, kStartSphere, kEndSphere, kCylinder };
  Piece piece = kNone;
  double w = kInf;  // height of the swept lower surface (mm)
  double depth = 0;  // sqrt(r^2 - d^2) for spheres, sqrt(r^2 - n^2) cylinder
  double px = 0, py = 0;  // (x, y) minus the centre used (a for the cylinder)
};

class BallSweep {
 public:
  // tip_from/tip_to: tool-tip positions (finite), radius > 0 (mm).
  BallSweep(const Vec3& tip_from, const Vec3& tip_to, double radius);

  // Height of the swept lower surface at (x, y); +inf where the tool never
  // passes over that point.
  double Height(double x, double y) const { return Locate(x, y).w; }

  // Locates (x, y) on the swept surface (inline: the hot path).
  inline SweepPoint Locate(double x, double y) const;

  // Height and derivatives at a located point (piece != kNone).
  SurfaceJet Jet(const SweepPoint& p) const;

  // Lowest height the sweep reaches anywhere.
  double lowest() const { return std::fmin(a_.z, b_.z) - r_; }
  double radius() const { return r_; }
  const Vec3& centre_from() const { return a_; }
  const Vec3& centre_to() const { return b_; }

  // The region where the swept surface is below `cap` lies inside the XY
  // capsule returned here (a segment and a radius). Empty when the sweep
  // never goes below `cap`.
  struct Capsule {
    bool empty = true;
    double x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // segment ends (ball centres, XY)
    double radius = 0;
    Rect Bounds() const {
      return {std::fmin(x0, x1) - radius, std::fmin(y0, y1) - radius,
              std::fmax(x0, x1) + radius, std::fmax(y0, y1) + radius};
    }
    // The x-interval of the capsule on the row y (empty if it misses).
    Interval RowSpan(double y) const;
  };
  Capsule Footprint(double cap) const;

 private:
  enum Kind : uint8_t { kPoint, kVertical, kGeneral };
  // Eq. (12)-(13): lower root s = z - za of the cylinder equation, in a
  // numerically stable form. `along`/`n`: horizontal coordinates of (x, y)
  // relative to a, along and across the move's XY direction.
  double CylinderRoot(double along, double root, double root2) const;
  // Eq. (14): derivatives of the cylinder (mid-surface).
  SurfaceJet CylinderJet(const SweepPoint& p) const;

  Vec3 a_, b_;  // ball centres at the start and end
  double r_, r2_;
  Kind kind_;
  double len_;             // |b - a|, L_AB
  double k1_, k2_, k3_;    // eq. (10): unit axis
  double g_, inv_g_;       // horizontal part of the axis, sqrt(k1^2 + k2^2)
  double h1_, h2_;         // unit XY direction of the move
};

inline SweepPoint BallSweep::Locate(double x, double y) const {
  SweepPoint p;
  if (kind_ != kGeneral) {
    // Vertical moves and points: the lowest ball is the whole envelope.
    const Vec3& c = (kind_ == kVertical && b_.z < a_.z) ? b_ : a_;
    p.px = x - c.x;
    p.py = y - c.y;
    const double d2 = r2_ - (p.px * p.px + p.py * p.py);
    if (!(d2 >= 0)) return p;
    p.depth = std::sqrt(d2);
    p.w = c.z - p.depth;
    p.piece = (&c == &a_) ? SweepPoint::kStartSphere : SweepPoint::kEndSphere;
    return p;
  }
  const double px = x - a_.x, py = y - a_.y;
  const double n = h1_ * py - h2_ * px;
  const double root2 = r2_ - n * n;
  if (!(root2 >= 0)) return p;  // the vertical line misses every ball
  const double along = h1_ * px + h2_ * py;
  const double root = std::sqrt(root2);
  const double s = CylinderRoot(along, root, root2);
  // Axial coordinate of the cylinder contact point, measured from a.
  const double t = g_ * along + k3_ * s;
  if (t >= 0 && t <= len_) {
    p.piece = SweepPoint::kCylinder;
    p.px = px;
    p.py = py;
    p.depth = root;
    p.w = a_.z + s;
    return p;
  }
  const Vec3& c = (t < 0) ? a_ : b_;
  p.px = x - c.x;
  p.py = y - c.y;
  const double d2 = r2_ - (p.px * p.px + p.py * p.py);
  if (!(d2 >= 0)) return p;
  p.depth = std::sqrt(d2);
  p.w = c.z - p.depth;
  p.piece = (t < 0) ? SweepPoint::kStartSphere : SweepPoint::kEndSphere;
  return p;
}

inline double BallSweep::CylinderRoot(double along, double root,
                                       double root2) const {
  // With k = (g h, k3) and n the horizontal distance to the axis' XY line,
  // eq. (12) reduces to g^2 s^2 - 2 g k3 along s + (k3^2 along^2 + n^2 - r^2)
  // = 0, whose lower root is (k3 along - root) / g. When k3 along > 0 that
  // difference cancels; the product of the roots gives the same root without
  // cancellation.
  const double q = k3_ * along;
  if (q > 0) return (q * q - root2) / (g_ * (q + root));
  return (q - root) * inv_g_;
}

}  // namespace swarf

#endif  // SWARF_CORE_BALL_SWEEP_H_
