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
#ifndef SWARF_CORE_CUTTER_BALL_SWEEP_H_
#define SWARF_CORE_CUTTER_BALL_SWEEP_H_

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <limits>
#include <utility>

#include "core/cutter/capsule.h"
#include "core/geometry.h"
#include "core/surface_jet.h"

namespace swarf {

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

// Limits every derivative of `j` to +-kMaxDerivative.
inline SurfaceJet ClampedJet(const SurfaceJet& j) {
  auto c = [](double v) {
    return std::min(std::max(v, -kMaxDerivative), kMaxDerivative);
  };
  return {j.w, c(j.wx), c(j.wy), c(j.wxx), c(j.wxy), c(j.wyy)};
}

// Eq. (8)-(9): derivatives of the lower hemisphere at offset (dx, dy) from the
// centre, where `depth` = zc - z = sqrt(r^2 - dx^2 - dy^2) (already clamped).
// Unbounded: BallSweep::Jet bounds the values it returns.
inline SurfaceJet SphereJet(double z, double dx, double dy, double depth) {
  // With z - zc = -depth: zx = dx / depth, zxx = (1 + zx^2) / depth, ...
  const double inv = 1 / depth;
  SurfaceJet j;
  j.w = z;
  j.wx = dx * inv;
  j.wy = dy * inv;
  j.wxx = (1 + j.wx * j.wx) * inv;
  j.wxy = (j.wx * j.wy) * inv;
  j.wyy = (1 + j.wy * j.wy) * inv;
  return j;
}

// A value at most BallSweep(tip_from, tip_to, r).Height(x, y) as that
// computes it (r > 0, mm), and within about 1e-5 mm of it away from the
// rims: the height from the move's data alone (the cylinder's contact or
// the nearer end's sphere), less a slack for both roundings; no sweep
// built. -inf (no bound) for moves steeper than about 87 degrees, where
// the sweep's rounding grows with the slope; +inf only off the footprint.
double BallHeightLowerBound(const Vec3& tip_from, const Vec3& tip_to, double r,
                            double x, double y);

// Where (x, y) lies on the swept surface, and the intermediate values needed
// to differentiate there.
struct SweepPoint {
  // 32-bit so that it vectorizes alongside doubles.
  enum Piece : int32_t { kNone, kStartSphere, kEndSphere, kCylinder };
  Piece piece = kNone;
  double w = kInf;  // height of the swept lower surface (mm)
  double depth = 0;  // sqrt(r^2 - d^2) for spheres, sqrt(r^2 - n^2) cylinder
  // (x, y) minus the centre of the piece (a for the cylinder).
  double px = 0, py = 0;
};

class BallSweep {
 public:
  // tip_from/tip_to: tool-tip positions (finite), radius > 0 (mm).
  BallSweep(const Vec3& tip_from, const Vec3& tip_to, double radius);

  // Height of the swept lower surface at (x, y); +inf where the tool never
  // passes over that point.
  double Height(double x, double y) const { return Locate(x, y).w; }

  // A plane below the swept surface that touches it at (x, y): for every
  // (u, v), Height(u, v) >= w + wx (u - x) + wy (v - y) - slack, Height as
  // computed. The swept solid (a capsule) is convex, so its lower surface
  // lies above each of its tangent planes (and is +inf off the footprint);
  // `slack` covers the rounding of the heights and of the plane. nullopt
  // where (x, y) is off the surface or near its rim (the depth below the
  // centre under 5% of the radius), or the move is steeper than about 87
  // degrees (no plane there to help).
  struct SupportPlane {
    double w, wx, wy, slack;
  };
  std::optional<SupportPlane> SupportingPlane(double x, double y) const;

  // Locates (x, y) on the swept surface.
  [[gnu::always_inline]] SweepPoint Locate(double x, double y) const {
    return kind_ == kGeneral ? LocateGeneral(frame(), x, y)
                             : LocateSphere(LowestCentre(), LowestPiece(),
                                            x, y);
  }

  // out[q] = Height(x[q], y[q]) for q in [0, n), bit-identical to Height()
  // (the same operations, evaluated several points at a time).
  void Heights(const double* x, const double* y, int32_t n,
               double* out) const;
  // Located points, structure-of-arrays.
  struct Points {
    static constexpr int32_t kMax = 256;
    alignas(64) double w[kMax];
    alignas(64) double px[kMax];
    alignas(64) double py[kMax];
    alignas(64) double depth[kMax];
    alignas(64) int32_t piece[kMax];  // SweepPoint::Piece
    SweepPoint At(int32_t q) const {
      SweepPoint p;
      p.piece = static_cast<SweepPoint::Piece>(piece[q]);
      p.w = w[q];
      p.px = px[q];
      p.py = py[q];
      p.depth = depth[q];
      return p;
    }
    void Set(int32_t q, const SweepPoint& p) {
      w[q] = p.w;
      px[q] = p.px;
      py[q] = p.py;
      depth[q] = p.depth;
      piece[q] = p.piece;
    }
  };
  // out->At(q) = Locate(x[q], y[q]) for q in [0, n), n <= Points::kMax.
  // Vectorized; bit-identical to Locate.
  void Locate(const double* x, const double* y, int32_t n,
              Points* out) const;
  // d[c][q] = float(component c of Jet(pts.At(q))), components wx, wy, wxx,
  // wxy, wyy, for q in [0, n). Vectorized.
  void Jets(const Points& pts, int32_t n, float* const d[5]) const;

  // Height and derivatives at a located point; for kNone, +inf and zeros.
  // Branch-free (both forms computed, one selected) so that it vectorizes.
  [[gnu::always_inline]] SurfaceJet Jet(const SweepPoint& p) const {
    return JetIn(frame(), p);
  }

  // Jet(Locate(x, y)): the seam's entry point (core/cutter/sweep.h).
  SurfaceJet JetAt(double x, double y) const { return Jet(Locate(x, y)); }

  // The values that Locate and Jet read, for kernels that evaluate the
  // nodes of many sweeps at once (JetsOfFrames) with the same operations.
  struct Frame {
    double ax, ay, az, bx, by, bz;  // ball centres at the start and end
    double r2;                      // radius squared
    double rim_depth;               // kRimDepthFraction * radius
    double h1, h2;                  // unit XY direction of the move
    double k3, g, inv_g;            // eq. (10)
    double len;                     // |b - a|
  };
  Frame frame() const {
    return {a_.x, a_.y, a_.z, b_.x, b_.y, b_.z, r2_, kRimDepthFraction * r_,
            h1_, h2_, k3_, g_, inv_g_, len_};
  }
  // Whether Locate is the general (cylinder and end spheres) form, the one
  // JetsOfFrames evaluates: false for points and vertical moves (one
  // sphere).
  bool general() const { return kind_ == kGeneral; }
  // A frame off whose surface every point lies: JetsOfFrames gives zeros,
  // as Jet does for kNone.
  static Frame NoFrame() {
    return {0, 0, 0, 0, 0, 0, -1, 1, 1, 0, 0, 1, 1, 1};
  }
  // Frames of many sweeps value by value (structure of arrays), so that a
  // kernel loads one value of several frames at once: value v (the v-th
  // member of Frame) of frame f is data[v * stride + f]. Kernels read
  // kFramePadding entries past the last frame they are given (and do not
  // use them): stride >= frames + kFramePadding. Not owned.
  static constexpr int32_t kFrameValues = sizeof(Frame) / sizeof(double);
  static constexpr int32_t kFramePadding = 8;
  struct FrameTable {
    double* data = nullptr;
    int32_t stride = 0;
    void Set(int32_t f, const Frame& frame) const;
    Frame Get(int32_t f) const;
  };
  // For q in [0, n): frame first + q of `table` = BallSweep(tip_from[q],
  // tip_to[q], radius[q]).frame() and general[q] = its general(), bit for
  // bit (the constructor's operations, several moves at a time).
  static void MakeFrames(int32_t n, const Vec3* tip_from, const Vec3* tip_to,
                         const double* radius, const FrameTable& table,
                         int32_t first, uint8_t* general);
  // For q in [0, n): d[c][q] = float(component c of JetAt(x[q], y)) of the
  // general sweep whose frame is frame_of[q] of `table` (components wx,
  // wy, wxx, wxy, wyy), bit-identical to it. Vectorized across sweeps, so
  // that nodes of different owners share the vector units; fastest where
  // each 8 consecutive lanes span at most 8 consecutive frames (on
  // AVX-512, frame values are then permuted, not gathered). Frames of
  // general sweeps (frame()) or NoFrame() only.
  static void JetsOfFrames(const FrameTable& table, const int32_t* frame_of,
                           const double* x, double y, int32_t n,
                           float* const d[5]);

  // Eq. (14) as the paper writes it (C1, C2, C3 and their derivatives), at a
  // point on the cylinder. Jet() uses the equivalent closed form of
  // CylinderJet(), which costs a third; tests check that they agree.
  SurfaceJet CylinderJetEq14(const SweepPoint& p) const;

  // Lowest height the sweep reaches anywhere.
  double lowest() const { return std::min(a_.z, b_.z) - r_; }
  double radius() const { return r_; }
  const Vec3& centre_from() const { return a_; }
  const Vec3& centre_to() const { return b_; }

  // The region where the swept surface is below `cap` lies inside the XY
  // capsule returned here (a segment and a radius). Empty when the sweep
  // never goes below `cap`.
  using Capsule = swarf::Capsule;
  // Where the sweep reaches below the height `cap` (a conservative capsule
  // around it).
  Capsule Footprint(double cap) const;
  // The footprint's bounds for the move between two tool tips, bit-identical
  // to BallSweep(tip_from, tip_to, radius).Footprint(cap).Bounds(), without
  // building the sweep; nullopt where the footprint is empty.
  static std::optional<Rect> FootprintBounds(const Vec3& tip_from,
                                             const Vec3& tip_to,
                                             double radius, double cap);
  // The footprint's ends, radius and `empty`, bit-identical to
  // BallSweep(tip_from, tip_to, radius).Footprint(cap)'s, without building
  // the sweep and without its direction (ux, uy, length, inv_ux, inv_uy
  // left 0; FillDirection adds them).
  static Capsule FootprintEndsOf(const Vec3& tip_from, const Vec3& tip_to,
                                 double radius, double cap);
  // Footprint(cap)'s radius. Footprint(c)'s segment for any c >= cap,
  // widened by this radius, also holds every point where the sweep is
  // below cap (a lower cap only shortens the segment and the radius).
  double FootprintRadius(double cap) const {
    return FootprintRadiusAt(std::min(a_.z, b_.z), r_, r2_, cap);
  }
  // out[q] = FootprintRadius(caps[q]) for q < n, the same bits, in a
  // vectorized loop.
  void FootprintRadii(const double* caps, int32_t n, double* out) const;

  // Where this sweep surely lowers nothing that `prev` was applied to:
  // `prev` is a move of the same radius whose end centre is this sweep's
  // start centre, bit for bit (a path's previous move). There this
  // sweep's height is its start ball's, which is prev's ball at its end,
  // and prev's contact lies at least `delta` before its end: prev's height
  // along its move is convex with curvature at least g^2 / r, so prev's
  // height is lower by g^2 delta^2 / 2r, four times both heights' rounding
  // or more (where this sweep's start ball misses, its height is +inf).
  // Heights only go down, so a node prev was applied to is below this
  // sweep there. With q = (x - cx, y - cy): q . (h1, h2) <= c_this and
  // q . (p1, p2) <= c_prev. nullopt where there is none: another radius or
  // start, a point or vertical move, or one steeper than about 87 degrees
  // (the rounding grows with the slope).
  struct Shadow {
    double cx, cy, h1, h2, c_this, p1, p2, c_prev;
  };
  std::optional<Shadow> ShadowAfter(const BallSweep& prev) const;
  // For the rows j0 + q (q < n) at y = y0 + (j0 + q) dy: the nodes x0 +
  // i dx (i in [lo[q], hi[q]], within [0, i_max]) inside s by a node's
  // width at each end (more than the rounding of the range); lo > hi where
  // none. Vectorized.
  static void ShadowRows(const Shadow& s, double y0, double dy, int32_t j0,
                         int32_t n, double x0, double inv_dx, int32_t i_max,
                         int32_t* lo, int32_t* hi);

 private:
  friend struct BallSweepKernels;  // the kernels over many frames
  enum Kind : uint8_t { kPoint, kVertical, kGeneral };

  // Vertical moves and points: the lowest ball is the whole envelope.
  const Vec3& LowestCentre() const {
    return (kind_ == kVertical && b_.z < a_.z) ? b_ : a_;
  }
  // Eq. (7) at the ball centred at c (a copy of a_ or b_; `piece` says
  // which).
  [[gnu::always_inline]] SweepPoint LocateSphere(Vec3 c,
                                                 SweepPoint::Piece piece,
                                                 double x, double y) const;
  SweepPoint::Piece LowestPiece() const {
    return (kind_ == kVertical && b_.z < a_.z) ? SweepPoint::kEndSphere
                                               : SweepPoint::kStartSphere;
  }
  // The general move: cylinder where its contact lies inside the move, else
  // the sphere on the contact's side. Branch-free, so that it vectorizes.
  // Static over the frame, so that JetsOfFrames runs the same operations.
  [[gnu::always_inline]] static SweepPoint LocateGeneral(const Frame& f,
                                                         double x, double y);
  // Jet() for the sweep of frame f (any kind: a point's or vertical move's
  // frame has h1 = h2 = k3 = inv_g = 0, and its cylinder form is never
  // selected).
  [[gnu::always_inline]] static SurfaceJet JetIn(const Frame& f,
                                                 const SweepPoint& p);
  // Eq. (14) in the move's own frame, at offset (px, py) from a with the
  // clamped root `depth` = sqrt(r^2 - n^2).
  [[gnu::always_inline]] static SurfaceJet CylinderJet(const Frame& f,
                                                       double w, double px,
                                                       double py,
                                                       double depth);

  // The footprint's ends and radius (not its direction), for ball centres
  // a and b of radius r (r2 = r * r).
  static Capsule FootprintEnds(const Vec3& a, const Vec3& b, double r,
                               double r2, double cap);
  // The footprint's radius below cap for a lowest centre at z_min: over
  // the kept part, a ball at height zc reaches below cap within a
  // horizontal radius sqrt(r^2 - (zc - cap)^2), largest at the lowest
  // centre; widened against rounding.
  static double FootprintRadiusAt(double z_min, double r, double r2,
                                  double cap) {
    double rho = r;
    if (z_min > cap) {
      const double h = z_min - cap;
      rho = std::sqrt(std::max(0.0, r2 - h * h));
    }
    return rho * (1 + 1e-12) + kFootprintMargin;
  }
  // The footprint is widened by this much (mm) so that it stays
  // conservative under rounding: a node whose swept height is below the
  // cap is always evaluated, whatever the cap, which keeps results
  // independent of batching.
  static constexpr double kFootprintMargin = 1e-9;

  Vec3 a_, b_;  // ball centres at the start and end
  double r_, r2_;
  Kind kind_;
  double len_;             // |b - a|, L_AB
  double k1_, k2_, k3_;    // eq. (10): unit axis
  double g_, inv_g_;       // horizontal part of the axis, sqrt(k1^2 + k2^2)
  double h1_, h2_;         // unit XY direction of the move
};

inline SurfaceJet BallSweep::CylinderJet(const Frame& f, double w,
                                         double px, double py, double depth) {
  // In the move's frame the cylinder is z = za + (k3 along - R) / g with
  // R = sqrt(r^2 - n^2): its slope along the move is k3 / g, across it
  // dz/dn = n / (g R) and d2z/dn2 = r^2 / (g R^3). With d along =
  // h . d(x, y) and dn = (-h2, h1) . d(x, y) that gives the gradient and
  // Hessian below: the same values as eq. (14), for a third of the work.
  const double h1 = f.h1, h2 = f.h2;
  const double n = h1 * py - h2 * px;
  const double inv_r = 1 / depth;
  const double slope_along = f.k3 * f.inv_g;
  const double slope_across = n * inv_r * f.inv_g;
  const double kappa = f.r2 * inv_r * inv_r * inv_r * f.inv_g;
  SurfaceJet j;
  j.w = w;
  j.wx = slope_along * h1 - slope_across * h2;
  j.wy = slope_along * h2 + slope_across * h1;
  j.wxx = kappa * h2 * h2;
  j.wxy = -kappa * h1 * h2;
  j.wyy = kappa * h1 * h1;
  return j;  // unbounded, like SphereJet
}

inline SurfaceJet BallSweep::JetIn(const Frame& f, const SweepPoint& p) {
  const double depth = std::max(p.depth, f.rim_depth);
  const SurfaceJet cyl = CylinderJet(f, p.w, p.px, p.py, depth);
  const SurfaceJet sph = SphereJet(p.w, p.px, p.py, depth);
  const bool c = p.piece == SweepPoint::kCylinder;
  const bool none = p.piece == SweepPoint::kNone;
  SurfaceJet j;
  j.w = p.w;
  j.wx = none ? 0 : c ? cyl.wx : sph.wx;
  j.wy = none ? 0 : c ? cyl.wy : sph.wy;
  j.wxx = none ? 0 : c ? cyl.wxx : sph.wxx;
  j.wxy = none ? 0 : c ? cyl.wxy : sph.wxy;
  j.wyy = none ? 0 : c ? cyl.wyy : sph.wyy;
  return ClampedJet(j);
}

inline SweepPoint BallSweep::LocateSphere(Vec3 c, SweepPoint::Piece piece,
                                          double x, double y) const {
  SweepPoint p;
  p.px = x - c.x;
  p.py = y - c.y;
  const double d2 = r2_ - (p.px * p.px + p.py * p.py);
  const bool hit = d2 >= 0;
  p.depth = std::sqrt(std::max(d2, 0.0));
  const double w = c.z - p.depth;
  p.w = hit ? w : kInf;
  p.piece = hit ? piece : SweepPoint::kNone;
  return p;
}

inline SweepPoint BallSweep::LocateGeneral(const Frame& f, double x,
                                           double y) {
  // Horizontal coordinates of (x, y) relative to a: `along` the move's XY
  // direction and `n` across it (the horizontal distance to the axis line,
  // which is also the distance from the vertical line at (x, y) to it).
  // Both centres in locals: selecting values (not addresses) below keeps
  // the loop free of gathers.
  const double ax = f.ax, ay = f.ay, az = f.az;
  const double bx = f.bx, by = f.by, bz = f.bz;
  const double h1 = f.h1, h2 = f.h2, k3 = f.k3, g = f.g;
  const double px = x - ax, py = y - ay;
  const double n = h1 * py - h2 * px;
  const double along = h1 * px + h2 * py;
  const double root2 = f.r2 - n * n;
  const double root = std::sqrt(std::max(root2, 0.0));
  // Eq. (12)-(13). With k = (g h, k3), eq. (12) reduces to
  // g^2 s^2 - 2 g k3 along s + (k3^2 along^2 + n^2 - r^2) = 0 (s = z - za),
  // whose lower root is (k3 along - root) / g. When k3 along > 0 that
  // difference cancels; the product of the roots then gives the same root
  // without cancellation.
  const double q = k3 * along;
  const double s_stable = (q * q - root2) / (g * (q + root));
  const double s_plain = (q - root) * f.inv_g;
  const double s = q > 0 ? s_stable : s_plain;
  // Axial coordinate of the cylinder's contact point, measured from a. The
  // height along the move is convex, so outside [0, L] the lowest point is
  // the end sphere on that side.
  const double t = g * along + k3 * s;
  const bool before = t < 0, after = t > f.len;
  const bool cylinder = !before && !after;
  const double cx = before ? ax : bx;
  const double cy = before ? ay : by;
  const double cz = before ? az : bz;
  const double qx = x - cx, qy = y - cy;
  const double d2 = f.r2 - (qx * qx + qy * qy);
  const double depth = std::sqrt(std::max(d2, 0.0));
  const bool hit = root2 >= 0;  // else the vertical line misses every ball
  const bool sphere_hit = d2 >= 0;
  // Both candidates are computed and then selected: no branch, so that
  // rows of nodes vectorize.
  const double w_cylinder = az + s;
  const double w_sphere = cz - depth;
  SweepPoint p;
  p.w = !hit ? kInf : cylinder ? w_cylinder : sphere_hit ? w_sphere : kInf;
  p.piece = !hit          ? SweepPoint::kNone
            : cylinder    ? SweepPoint::kCylinder
            : !sphere_hit ? SweepPoint::kNone
            : before      ? SweepPoint::kStartSphere
                          : SweepPoint::kEndSphere;
  p.depth = cylinder ? root : depth;
  p.px = cylinder ? px : qx;
  p.py = cylinder ? py : qy;
  return p;
}

}  // namespace swarf

#endif  // SWARF_CORE_CUTTER_BALL_SWEEP_H_
