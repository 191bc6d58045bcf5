#include "core/cutter/ball_sweep.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/cutter/hypot.h"
#include "core/target_clones.h"
#include "core/value_minmax.h"

namespace swarf {
namespace {

// Moves whose horizontal travel is below this fraction of their length are
// treated as vertical: their cylinder part would be a sliver narrower than
// 1e-12 of the move, and its derivatives would not be representable.
constexpr double kVerticalFraction = 1e-12;

}  // namespace

double SphereHeight(const Vec3& c, double r, double x, double y) {
  const double dx = x - c.x, dy = y - c.y;
  const double d2 = r * r - (dx * dx + dy * dy);
  if (!(d2 >= 0)) return kInf;
  return c.z - std::sqrt(d2);
}

double BallHeightLowerBound(const Vec3& tip_from, const Vec3& tip_to, double r,
                            double x, double y) {
  const double ux = tip_to.x - tip_from.x, uy = tip_to.y - tip_from.y;
  const double uz = tip_to.z - tip_from.z;
  const double l2 = ux * ux + uy * uy;
  const double len2 = l2 + uz * uz;
  if (400 * l2 < len2) return -kInf;  // g < 1/20, and vertical moves
  const double r2 = r * r;
  // sqrt(r^2 - d2), widened: d2 is off by a few ulps of r^2, which moves
  // the root most (by about 1e-8 r) where it vanishes. +inf beyond r.
  auto root = [r2](double d2) {
    return d2 > r2 * (1 + 1e-9) ? kInf
                                : std::sqrt(std::max(0.0, r2 - d2) + 1e-9 * r2);
  };
  const double px = x - tip_from.x, py = y - tip_from.y;
  if (len2 == 0) {
    return tip_from.z + r - root(px * px + py * py) - 2e-6 * (1 + r);
  }
  // Eq. (10)-(14) by another road: over the line's balls the height at
  // (x, y) is convex in t, least at t* (the cylinder's contact), where it
  // is the least over the whole line: at most the move's. Beyond the move
  // it is the nearer end's sphere; t* is taken as within the move up to a
  // margin for its rounding and the widened root (there the line's least
  // is still a bound, the sphere would not be).
  const double inv_g = std::sqrt(len2 / l2);
  const double tu = (px * ux + py * uy) / l2;
  const double nx = px - tu * ux, ny = py - tu * uy;
  const double rho = root(nx * nx + ny * ny);
  if (rho == kInf) return kInf;
  const double ts = tu - uz * rho / (l2 * inv_g);
  const double margin = 1e-4 * r / std::sqrt(l2) + 1e-9;
  double h;
  if (ts >= -margin && ts <= 1 + margin) {
    h = tip_from.z + r + uz * tu - rho * inv_g;
  } else {
    const Vec3& e = ts < 0 ? tip_from : tip_to;
    const double ex = x - e.x, ey = y - e.y;
    h = e.z + r - root(ex * ex + ey * ey);
  }
  // As SupportingPlane's slack: the sweep's heights are off by up to about
  // sqrt(ulp) sqrt(r (r + len)) / g near a rim; 60 times that, for them
  // and for this bound's own roots.
  return h - 2e-6 * (1 + r + 0.1 * std::sqrt(len2)) * inv_g;
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
  const double dxy = Hypot(dx, dy);
  len_ = Hypot(dxy, dz);
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

std::optional<BallSweep::SupportPlane> BallSweep::SupportingPlane(
    double x, double y) const {
  // Rounding: a computed height's root sqrt(r^2 - d^2) is off by at most
  // sqrt(ulp) * r where the root vanishes (about 2e-8 r; where the cylinder
  // is taken, with n from coordinates up to r + len, 3e-8 sqrt(r (r +
  // len))), divided by g on the cylinder. The slack is that 30 times over,
  // for the heights and the plane's own height; its slopes are taken away
  // from the rim (depth >= 5% of r), where they are accurate to about
  // 1e-13 of their size.
  constexpr double kMinDepth = 0.05;
  constexpr double kMaxInvG = 20;
  const SweepPoint p = Locate(x, y);
  if (p.piece == SweepPoint::kNone || !(p.depth >= kMinDepth * r_)) {
    return std::nullopt;
  }
  const double inv_g = kind_ == kGeneral ? inv_g_ : 1;
  if (!(inv_g <= kMaxInvG)) return std::nullopt;
  SupportPlane plane;
  plane.w = p.w;
  plane.slack = 1e-6 * (1 + r_ + 0.1 * len_) * inv_g;
  if (p.piece == SweepPoint::kCylinder) {
    // The cylinder's gradient (as CylinderJet).
    const double n = h1_ * p.py - h2_ * p.px;
    const double along = k3_ * inv_g_;
    const double across = n / p.depth * inv_g_;
    plane.wx = along * h1_ - across * h2_;
    plane.wy = along * h2_ + across * h1_;
  } else {
    // The sphere's (eq. 8).
    plane.wx = p.px / p.depth;
    plane.wy = p.py / p.depth;
  }
  return plane;
}

SWARF_TARGET_CLONES
void BallSweep::FootprintRadii(const double* __restrict caps, int32_t n,
                               double* __restrict out) const {
  const double z_min = std::min(a_.z, b_.z), r = r_, r2 = r2_;
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    // FootprintRadiusAt as selects.
    const double h = z_min - caps[q];
    const double below = std::sqrt(MaxOf(0.0, r2 - h * h));
    const double rho = z_min > caps[q] ? below : r;
    out[q] = rho * (1 + 1e-12) + kFootprintMargin;
  }
}

std::optional<BallSweep::Shadow> BallSweep::ShadowAfter(
    const BallSweep& prev) const {
  if (kind_ != kGeneral || prev.kind_ != kGeneral || !SameBits(r_, prev.r_) ||
      !SameBits(a_, prev.b_)) {
    return std::nullopt;
  }
  // As BallHeightLowerBound: no steeper than about 87 degrees.
  constexpr double kMinG = 0.05;
  if (g_ < kMinG || prev.g_ < kMinG) return std::nullopt;
  const double r = r_;
  // Both heights' rounding, generously: a sphere's height near its rim is
  // off by up to about sqrt(ulp) r (the root of a rounded r^2 - d^2), and
  // elsewhere each height is within some thousands of ulps of what it is
  // computed from (the coordinates, offsets along a move up to its length
  // and 2r over g).
  const double scale = 1 + std::fabs(a_.x) + std::fabs(a_.y) + std::fabs(a_.z) +
                       std::fabs(prev.a_.x) + std::fabs(prev.a_.y) +
                       std::fabs(prev.a_.z) + r + (len_ + 2 * r) / g_ +
                       (prev.len_ + 2 * r) / prev.g_;
  const double err = 1e-6 * (1 + r) + 1e-10 * scale;
  // prev's gap g'^2 delta^2 / 2r is 4 err; prev must be longer than delta
  // (else its contact may be its start's, closer than delta to its end).
  const double delta = std::sqrt(8 * r * err) / prev.g_;
  if (!(prev.len_ > 2 * delta)) return std::nullopt;
  // With q from the shared centre and root = sqrt(r^2 - n^2) in [0, r]
  // (n the distance to a move's axis): this sweep's contact lies at
  // (q . h - k3 root) / g from its start, prev's at (q . h' - k3' root') /
  // g' from its end (eq. 12-13 solved for the contact). Each bound holds
  // for every root (a move that climbs needs none: its k3 root only
  // helps), with err to spare against the rounding of the contacts. Where
  // |q| > r this sweep's height is +inf (its start ball misses, and its
  // contact is before its start); elsewhere prev's line meets its
  // cylinder at a root of at least g' delta.
  Shadow s;
  s.cx = a_.x;
  s.cy = a_.y;
  s.h1 = h1_;
  s.h2 = h2_;
  s.c_this = -std::max(0.0, -k3_) * r - err;
  s.p1 = prev.h1_;
  s.p2 = prev.h2_;
  s.c_prev = -std::max(0.0, -prev.k3_) * r - delta * prev.g_ - err;
  return s;
}

SWARF_TARGET_CLONES
void BallSweep::ShadowRows(const Shadow& s, double y0, double dy, int32_t j0,
                           int32_t n, double x0, double inv_dx, int32_t i_max,
                           int32_t* __restrict out_lo,
                           int32_t* __restrict out_hi) {
  const double cx = s.cx, cy = s.cy;
  const double h2 = s.h2, c_this = s.c_this, p2 = s.p2, c_prev = s.c_prev;
  // Each half-plane bounds qx from above or below, or (a1 = 0) holds on a
  // whole row or on none: decided once, so that the loop is selects only.
  const bool h_up = s.h1 > 0, h_down = s.h1 < 0, h_flat = s.h1 == 0;
  const bool p_up = s.p1 > 0, p_down = s.p1 < 0, p_flat = s.p1 == 0;
  const double h_inv = h_flat ? 0 : 1 / s.h1, p_inv = p_flat ? 0 : 1 / s.p1;
  const double top = i_max + 1.0;
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    const double qy = (y0 + (j0 + q) * dy) - cy;
    double lo = -kInf, hi = kInf;
    const double rh = c_this - qy * h2, rp = c_prev - qy * p2;
    hi = h_up ? MinOf(hi, rh * h_inv) : hi;
    lo = h_down ? MaxOf(lo, rh * h_inv) : lo;
    hi = p_up ? MinOf(hi, rp * p_inv) : hi;
    lo = p_down ? MaxOf(lo, rp * p_inv) : lo;
    const bool crossed = !(lo < hi);
    const bool none = (h_flat & (rh < 0)) | (p_flat & (rp < 0)) | crossed;
    // A node inside each end, on [0, i_max], as doubles (selects on
    // doubles' comparisons).
    const double fa = MinOf(MaxOf((cx + lo - x0) * inv_dx, -2.0), top + 1);
    const double fb = MinOf(MaxOf((cx + hi - x0) * inv_dx, -2.0), top + 1);
    const double i_lo = MaxOf(std::ceil(fa) + 1, 0.0);
    const double i_hi = MinOf(std::floor(fb) - 1, top - 1);
    const bool empty = none | (i_lo > i_hi);
    out_lo[q] = static_cast<int32_t>(empty ? 1.0 : i_lo);
    out_hi[q] = static_cast<int32_t>(empty ? 0.0 : i_hi);
  }
}

SWARF_TARGET_CLONES
void BallSweep::Heights(const double* x, const double* y, int32_t n,
                        double* out) const {
  if (kind_ == kGeneral) {
    const Frame f = frame();
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) out[q] = LocateGeneral(f, x[q], y[q]).w;
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
    const Frame f = frame();
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) {
      const SweepPoint p = LocateGeneral(f, x[q], y[q]);
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
  const Frame f = frame();
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    SweepPoint p;
    p.piece = static_cast<SweepPoint::Piece>(piece[q]);
    p.w = w[q];
    p.px = px[q];
    p.py = py[q];
    p.depth = depth[q];
    const SurfaceJet j = JetIn(f, p);
    d0[q] = static_cast<float>(j.wx);
    d1[q] = static_cast<float>(j.wy);
    d2[q] = static_cast<float>(j.wxx);
    d3[q] = static_cast<float>(j.wxy);
    d4[q] = static_cast<float>(j.wyy);
  }
}

void BallSweep::FrameTable::Set(int32_t f, const Frame& frame) const {
  double v[kFrameValues];
  std::memcpy(v, &frame, sizeof v);
  for (int32_t k = 0; k < kFrameValues; ++k) data[k * stride + f] = v[k];
}

BallSweep::Frame BallSweep::FrameTable::Get(int32_t f) const {
  double v[kFrameValues];
  for (int32_t k = 0; k < kFrameValues; ++k) v[k] = data[k * stride + f];
  Frame frame;
  std::memcpy(&frame, v, sizeof v);
  return frame;
}

SWARF_TARGET_CLONES
void BallSweep::MakeFrames(int32_t n, const Vec3* tip_from,
                           const Vec3* tip_to, const double* radius,
                           const FrameTable& table, int32_t first,
                           uint8_t* general) {
  // The constructor's steps over blocks of moves, vectorized (Hypot is
  // branch-free), written value by value.
  constexpr int32_t kBlock = 64;
  alignas(64) double gen[kBlock];  // 1: general (a double: vectorizes)
  const int32_t stride = table.stride;
  for (int32_t q0 = 0; q0 < n; q0 += kBlock) {
    const int32_t m = std::min(kBlock, n - q0);
    double* __restrict ax = table.data + 0 * stride + first + q0;
    double* __restrict ay = table.data + 1 * stride + first + q0;
    double* __restrict az = table.data + 2 * stride + first + q0;
    double* __restrict bx = table.data + 3 * stride + first + q0;
    double* __restrict by = table.data + 4 * stride + first + q0;
    double* __restrict bz = table.data + 5 * stride + first + q0;
    double* __restrict r2 = table.data + 6 * stride + first + q0;
    double* __restrict rim = table.data + 7 * stride + first + q0;
    double* __restrict h1 = table.data + 8 * stride + first + q0;
    double* __restrict h2 = table.data + 9 * stride + first + q0;
    double* __restrict k3 = table.data + 10 * stride + first + q0;
    double* __restrict g = table.data + 11 * stride + first + q0;
    double* __restrict inv_g = table.data + 12 * stride + first + q0;
    double* __restrict len = table.data + 13 * stride + first + q0;
    for (int32_t q = 0; q < m; ++q) {
      const Vec3& from = tip_from[q0 + q];
      const Vec3& to = tip_to[q0 + q];
      const double r = radius[q0 + q];
      ax[q] = from.x;
      ay[q] = from.y;
      az[q] = from.z + r;
      bx[q] = to.x;
      by[q] = to.y;
      bz[q] = to.z + r;
      r2[q] = r * r;
      rim[q] = kRimDepthFraction * r;
    }
#pragma omp simd
    for (int32_t q = 0; q < m; ++q) {
      const double dx = bx[q] - ax[q], dy = by[q] - ay[q], dz = bz[q] - az[q];
      const double dxy = Hypot(dx, dy);
      const double l = Hypot(dxy, dz);
      // A point (length 0) or a vertical move is not general; the
      // constructor leaves their h1 .. inv_g zero.
      const bool c = l != 0 && !(dxy <= kVerticalFraction * l);
      gen[q] = c ? 1.0 : 0.0;
      len[q] = l;
      k3[q] = c ? dz / l : 0;
      g[q] = c ? dxy / l : 0;
      inv_g[q] = c ? l / dxy : 0;
      h1[q] = c ? dx / dxy : 0;
      h2[q] = c ? dy / dxy : 0;
    }
    for (int32_t q = 0; q < m; ++q) general[q0 + q] = gen[q] != 0;
  }
}

// The kernels over many frames (friends of BallSweep: they run its private
// LocateGeneral and JetIn).
struct BallSweepKernels {
  // JetsOfFrames over chunks of lanes: each lane's frame values are first
  // copied to arrays of the chunk, then the chunk is evaluated with plain
  // vector loads. kPermute (AVX-512 only): 8 lanes spanning at most 8
  // consecutive frames load each value of those frames at once and permute
  // it into place, instead of 8 scalar loads.
  template <bool kPermute>
  [[gnu::always_inline]] static void JetsOfFrames(
      const BallSweep::FrameTable& table, const int32_t* frame_of,
      const double* x, double y, int32_t n, float* const d[5]) {
    using Frame = BallSweep::Frame;
    constexpr int32_t kValues = BallSweep::kFrameValues;
    constexpr int32_t kChunk = 64;
    alignas(64) double lane[kValues][kChunk];
    const double* const data = table.data;
    const int32_t stride = table.stride;
    for (int32_t q0 = 0; q0 < n; q0 += kChunk) {
      const int32_t m = std::min(kChunk, n - q0);
      const int32_t* f = frame_of + q0;
      int32_t q = 0;
#if defined(__GNUC__) && !defined(__clang__)  // __builtin_shuffle: GCC only
      if constexpr (kPermute) {
        using V8 = double __attribute__((vector_size(64)));
        using I8 = int64_t __attribute__((vector_size(64)));
        for (; q + 8 <= m; q += 8) {
          int32_t lo = f[q], hi = f[q];
          for (int32_t l = 1; l < 8; ++l) {
            lo = std::min(lo, f[q + l]);
            hi = std::max(hi, f[q + l]);
          }
          if (hi - lo >= 8) {
            for (int32_t l = 0; l < 8; ++l) {
              for (int32_t v = 0; v < kValues; ++v) {
                lane[v][q + l] = data[v * stride + f[q + l]];
              }
            }
            continue;
          }
          const I8 index = {f[q] - lo,     f[q + 1] - lo, f[q + 2] - lo,
                            f[q + 3] - lo, f[q + 4] - lo, f[q + 5] - lo,
                            f[q + 6] - lo, f[q + 7] - lo};
          for (int32_t v = 0; v < kValues; ++v) {
            V8 values;
            std::memcpy(&values, data + v * stride + lo, sizeof values);
            const V8 placed = __builtin_shuffle(values, index);
            std::memcpy(&lane[v][q], &placed, sizeof placed);
          }
        }
      }
#endif
      for (; q < m; ++q) {
        for (int32_t v = 0; v < kValues; ++v) {
          lane[v][q] = data[v * stride + f[q]];
        }
      }
      const double* const xs = x + q0;
      float* __restrict d0 = d[0] + q0;
      float* __restrict d1 = d[1] + q0;
      float* __restrict d2 = d[2] + q0;
      float* __restrict d3 = d[3] + q0;
      float* __restrict d4 = d[4] + q0;
#pragma omp simd
      for (int32_t q = 0; q < m; ++q) {
        const Frame fr{lane[0][q],  lane[1][q],  lane[2][q],  lane[3][q],
                       lane[4][q],  lane[5][q],  lane[6][q],  lane[7][q],
                       lane[8][q],  lane[9][q],  lane[10][q], lane[11][q],
                       lane[12][q], lane[13][q]};
        const SurfaceJet j =
            BallSweep::JetIn(fr, BallSweep::LocateGeneral(fr, xs[q], y));
        d0[q] = static_cast<float>(j.wx);
        d1[q] = static_cast<float>(j.wy);
        d2[q] = static_cast<float>(j.wxx);
        d3[q] = static_cast<float>(j.wxy);
        d4[q] = static_cast<float>(j.wyy);
      }
    }
  }
};

namespace {

SWARF_TARGET_CLONES
void JetsOfFramesAnyCpu(const BallSweep::FrameTable& table,
                        const int32_t* frame_of, const double* x, double y,
                        int32_t n, float* const d[5]) {
  BallSweepKernels::JetsOfFrames<false>(table, frame_of, x, y, n, d);
}

// GCC's vector extensions (variable shuffles) on x86-64: the permuting
// kernel for AVX-512 CPUs.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && \
    !defined(SWARF_NO_TARGET_CLONES) && !defined(SWARF_NO_AVX512_CLONES)
#define SWARF_PERMUTED_FRAMES 1
__attribute__((target("arch=x86-64-v4"))) void JetsOfFramesAvx512(
    const BallSweep::FrameTable& table, const int32_t* frame_of,
    const double* x, double y, int32_t n, float* const d[5]) {
  BallSweepKernels::JetsOfFrames<true>(table, frame_of, x, y, n, d);
}
#endif

}  // namespace

void BallSweep::JetsOfFrames(const FrameTable& table, const int32_t* frame_of,
                             const double* x, double y, int32_t n,
                             float* const d[5]) {
#ifdef SWARF_PERMUTED_FRAMES
  static const bool avx512 = __builtin_cpu_supports("x86-64-v4");
  if (avx512) {
    JetsOfFramesAvx512(table, frame_of, x, y, n, d);
    return;
  }
#endif
  JetsOfFramesAnyCpu(table, frame_of, x, y, n, d);
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
  c.empty = false;
  c.x0 = a.x + t0 * (b.x - a.x);
  c.y0 = a.y + t0 * (b.y - a.y);
  c.x1 = a.x + t1 * (b.x - a.x);
  c.y1 = a.y + t1 * (b.y - a.y);
  c.radius = FootprintRadiusAt(std::min(a.z, b.z), r, r2, cap);
  return c;
}

std::optional<Rect> BallSweep::FootprintBounds(const Vec3& tip_from,
                                               const Vec3& tip_to,
                                               double radius, double cap) {
  const Capsule c = FootprintEndsOf(tip_from, tip_to, radius, cap);
  if (c.empty) return std::nullopt;
  return c.Bounds();
}

BallSweep::Capsule BallSweep::FootprintEndsOf(const Vec3& tip_from,
                                              const Vec3& tip_to, double radius,
                                              double cap) {
  // The centres as the constructor places them.
  const Vec3 a{tip_from.x, tip_from.y, tip_from.z + radius};
  const Vec3 b{tip_to.x, tip_to.y, tip_to.z + radius};
  return FootprintEnds(a, b, radius, radius * radius, cap);
}

BallSweep::Capsule BallSweep::Footprint(double cap) const {
  Capsule c = FootprintEnds(a_, b_, r_, r2_, cap);
  if (c.empty) return c;
  FillDirection(&c);
  return c;
}

}  // namespace swarf
