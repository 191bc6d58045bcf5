#include "core/cutter/ball_sweep.h"

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

}  // namespace

double SphereHeight(const Vec3& c, double r, double x, double y) {
  const double dx = x - c.x, dy = y - c.y;
  const double d2 = r * r - (dx * dx + dy * dy);
  if (!(d2 >= 0)) return kInf;
  return c.z - std::sqrt(d2);
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

// Clones for wider vectors, picked at load time; the same IEEE operations in
// every clone (no FMA: -ffp-contract=off), so the same bits.
// SWARF_NO_TARGET_CLONES keeps only the default: clang 14 names the ifunc
// "<name>.ifunc", so callers in other files don't link (fuzz builds).
#ifdef SWARF_NO_TARGET_CLONES
#define SWARF_TARGET_CLONES
#else
#define SWARF_TARGET_CLONES \
  __attribute__((target_clones("default", "avx2", "arch=x86-64-v4")))
#endif
SWARF_TARGET_CLONES
void BallSweep::Heights(const double* x, const double* y, int32_t n,
                        double* out) const {
  if (kind_ == kGeneral) {
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) out[q] = LocateGeneral(x[q], y[q]).w;
    return;
  }
  const Vec3 c = LowestCentre();
  const SweepPoint::Piece piece = LowestPiece();
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) out[q] = LocateSphere(c, piece, x[q], y[q]).w;
}

SWARF_TARGET_CLONES
void BallSweep::Locate(const double* x, const double* y, int32_t n,
                       Points* out) const {
  double* __restrict ow = out->w;
  double* __restrict opx = out->px;
  double* __restrict opy = out->py;
  double* __restrict odepth = out->depth;
  int32_t* __restrict opiece = out->piece;
  if (kind_ == kGeneral) {
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) {
      const SweepPoint p = LocateGeneral(x[q], y[q]);
      ow[q] = p.w;
      opx[q] = p.px;
      opy[q] = p.py;
      odepth[q] = p.depth;
      opiece[q] = p.piece;
    }
    return;
  }
  const Vec3 c = LowestCentre();
  const SweepPoint::Piece piece = LowestPiece();
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    const SweepPoint p = LocateSphere(c, piece, x[q], y[q]);
    ow[q] = p.w;
    opx[q] = p.px;
    opy[q] = p.py;
    odepth[q] = p.depth;
    opiece[q] = p.piece;
  }
}

SWARF_TARGET_CLONES
void BallSweep::Jets(const Points& pts, int32_t n, float* const d[5]) const {
  const double* __restrict w = pts.w;
  const double* __restrict px = pts.px;
  const double* __restrict py = pts.py;
  const double* __restrict depth = pts.depth;
  const int32_t* __restrict piece = pts.piece;
  float* __restrict d0 = d[0];
  float* __restrict d1 = d[1];
  float* __restrict d2 = d[2];
  float* __restrict d3 = d[3];
  float* __restrict d4 = d[4];
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    SweepPoint p;
    p.piece = static_cast<SweepPoint::Piece>(piece[q]);
    p.w = w[q];
    p.px = px[q];
    p.py = py[q];
    p.depth = depth[q];
    const SurfaceJet j = Jet(p);
    d0[q] = static_cast<float>(j.wx);
    d1[q] = static_cast<float>(j.wy);
    d2[q] = static_cast<float>(j.wxx);
    d3[q] = static_cast<float>(j.wxy);
    d4[q] = static_cast<float>(j.wyy);
  }
}

SurfaceJet BallSweep::CylinderJetEq14(const SweepPoint& p) const {
  // Eq. (14). At the lower root of eq. (12), C1 = A s - k3 (k1 px + k2 py)
  // simplifies to -g sqrt(r^2 - n^2); that form avoids its cancellation for
  // near-vertical moves.
  const double s = p.w - a_.z;
  const double px = p.px, py = p.py;
  const double k1 = k1_, k2 = k2_, k3 = k3_;
  const double A = g_ * g_;
  const double c1 = -g_ * std::max(p.depth, kRimDepthFraction * r_);
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
  return ClampedJet(j);
}

BallSweep::Capsule BallSweep::FootprintEnds(const Vec3& a, const Vec3& b,
                                             double r, double r2,
                                             double cap) {
  Capsule c;
  // Only centres below cap + r can put the ball below cap.
  const double z_lim = cap + r + kFootprintMargin;
  double t0 = 0, t1 = 1;
  if (a.z >= z_lim && b.z >= z_lim) return c;
  if (a.z >= z_lim || b.z >= z_lim) {
    const double t = (z_lim - a.z) / (b.z - a.z);
    if (a.z < z_lim) {
      t1 = std::min(1.0, t + 1e-12);
    } else {
      t0 = std::max(0.0, t - 1e-12);
    }
  }
  // Over the kept part, a ball at height zc reaches below cap within a
  // horizontal radius sqrt(r^2 - (zc - cap)^2), largest at the lowest centre.
  const double z_min = std::min(a.z, b.z);
  double rho = r;
  if (z_min > cap) {
    const double h = z_min - cap;
    rho = std::sqrt(std::max(0.0, r2 - h * h));
  }
  c.empty = false;
  c.x0 = a.x + t0 * (b.x - a.x);
  c.y0 = a.y + t0 * (b.y - a.y);
  c.x1 = a.x + t1 * (b.x - a.x);
  c.y1 = a.y + t1 * (b.y - a.y);
  c.radius = rho * (1 + 1e-12) + kFootprintMargin;
  return c;
}

std::optional<Rect> BallSweep::FootprintBounds(const Vec3& tip_from,
                                               const Vec3& tip_to,
                                               double radius, double cap) {
  // The centres as the constructor places them.
  const Vec3 a{tip_from.x, tip_from.y, tip_from.z + radius};
  const Vec3 b{tip_to.x, tip_to.y, tip_to.z + radius};
  const Capsule c = FootprintEnds(a, b, radius, radius * radius, cap);
  if (c.empty) return std::nullopt;
  return c.Bounds();
}

BallSweep::Capsule BallSweep::FootprintOf(const Vec3& tip_from,
                                           const Vec3& tip_to, double radius,
                                           double cap) {
  const Vec3 a{tip_from.x, tip_from.y, tip_from.z + radius};
  const Vec3 b{tip_to.x, tip_to.y, tip_to.z + radius};
  Capsule c = FootprintEnds(a, b, radius, radius * radius, cap);
  if (c.empty) return c;
  FillDirection(&c);
  return c;
}

BallSweep::Capsule BallSweep::Footprint(double cap) const {
  Capsule c = FootprintEnds(a_, b_, r_, r2_, cap);
  if (c.empty) return c;
  FillDirection(&c);
  return c;
}

}  // namespace swarf
