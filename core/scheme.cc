#include "core/scheme.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"

namespace swarf {

namespace {
constexpr double kInfinity = std::numeric_limits<double>::infinity();
}  // namespace

double BilinearHeight(const ElementCorners& e, double x, double y) {
  // Eq. (16). With s = (1 + xi) / 2 and t = (1 + eta) / 2 in [0, 1] its four
  // shape functions are the nested linear interpolation below: the same
  // polynomial, but std::lerp is exact at s, t = 0 and 1 and for equal ends,
  // so corners and flat (untouched) elements reconstruct exactly.
  const double s = (x - e.x0) / (e.x1 - e.x0);
  const double t = (y - e.y0) / (e.y1 - e.y0);
  return std::lerp(std::lerp(e.c[0].w, e.c[1].w, s),
                   std::lerp(e.c[3].w, e.c[2].w, s), t);
}

bool CornerReach::Capsule::Contains(double x, double y) const {
  // Distance from the segment, clamped to its ends.
  const double ux = bx - ax, uy = by - ay;
  const double px = x - ax, py = y - ay;
  const double len2 = ux * ux + uy * uy;
  const double t =
      len2 > 0 ? std::clamp((px * ux + py * uy) / len2, 0.0, 1.0) : 0.0;
  const double dx = px - t * ux, dy = py - t * uy;
  return dx * dx + dy * dy <= radius * radius;
}

bool CornerReach::Contains(double x, double y) const {
  if (!bounded) return true;
  for (int k = 0; k < count; ++k) {
    if (capsule[k].Contains(x, y)) return true;
  }
  return false;
}

namespace {

void BilinearGradient(const ElementCorners& e, double x, double y, double* gx,
                      double* gy) {
  const double lx = e.x1 - e.x0, ly = e.y1 - e.y0;
  const double s = (x - e.x0) / lx, t = (y - e.y0) / ly;
  const double w0 = e.c[0].w, w1 = e.c[1].w, w2 = e.c[2].w, w3 = e.c[3].w;
  *gx = ((1 - t) * (w1 - w0) + t * (w2 - w3)) / lx;
  *gy = ((1 - s) * (w3 - w0) + s * (w2 - w1)) / ly;
}

// Corner k's term of the guarded minimum at (x, y), for (x, y) in its
// footprint: its patch (held at its owner's lowest point) within its trust
// radius, the bilinear `b` beyond. Sets *patch when the patch is used.
double GuardedTerm(const ElementCorners& e, int k, double x, double y,
                   double b, bool* patch) {
  const double xs[4] = {e.x0, e.x1, e.x1, e.x0};
  const double ys[4] = {e.y0, e.y0, e.y1, e.y1};
  const double dx = x - xs[k], dy = y - ys[k];
  const PatchTrust trust =
      e.has_trust ? TrustPatch(e.trust[k], dx, dy) : TrustPatch(e.c[k], dx, dy);
  *patch = trust != PatchTrust::kNone;
  if (!*patch) return b;
  const double p = std::max(EvaluatePatch(e.c[k], xs[k], ys[k], x, y),
                            e.reach[k].z_low);
  if (trust == PatchTrust::kLowerBound && b > p) {
    *patch = false;
    return b;
  }
  return p;
}

// The guarded minimum: the index of the corner that gives it (-1: the top),
// or -2 when it is the bilinear.
int GuardedMin(const ElementCorners& e, double x, double y, double* w) {
  const double b = BilinearHeight(e, x, y);
  *w = e.z_top;
  int best = -1;
  bool any = false;
  for (int k = 0; k < 4; ++k) {
    if (!e.reach[k].Contains(x, y)) continue;
    any = true;
    bool patch;
    const double v = GuardedTerm(e, k, x, y, b, &patch);
    if (v < *w) {
      *w = v;
      best = patch ? k : -2;
    }
  }
  if (!any) {
    *w = b;
    return -2;
  }
  return best;
}

}  // namespace

namespace {

// Where a circle of curvature k met at slope^2 s2 turns vertical (see
// RimDistance); infinite for k = 0.
double CircleRimDistance(double s2, double k) {
  const double denom = std::abs(k) * (std::sqrt(1 + s2) + std::sqrt(s2));
  if (!(denom > 0)) return kInfinity;
  return (1 + s2) / denom;
}

// The patch's principal curvatures m +- q, and the direction (ex, ey) of
// m + q.
struct Principal {
  double m, q, ex, ey;
};
Principal PrincipalCurvatures(const SurfaceJet& j) {
  Principal p;
  p.m = 0.5 * (j.wxx + j.wyy);
  p.q = std::hypot(0.5 * (j.wxx - j.wyy), j.wxy);
  const double th = 0.5 * std::atan2(2 * j.wxy, j.wxx - j.wyy);
  p.ex = std::cos(th);
  p.ey = std::sin(th);
  return p;
}

}  // namespace

double RimDistance(const SurfaceJet& j) {
  const double s2 = j.wx * j.wx + j.wy * j.wy;
  // Curvature along the gradient direction (at a flat node, the larger
  // principal curvature).
  double k;
  if (s2 > 0) {
    k = (j.wx * j.wx * j.wxx + 2 * j.wx * j.wy * j.wxy + j.wy * j.wy * j.wyy) /
        s2;
  } else {
    const Principal p = PrincipalCurvatures(j);
    k = std::max(std::abs(p.m + p.q), std::abs(p.m - p.q));
  }
  return CircleRimDistance(s2, k);
}

PatchTrustFrame TrustFrameOf(const SurfaceJet& j) {
  PatchTrustFrame f;
  const double delta = RimDistance(j);
  if (delta == kInfinity) return f;
  f.unbounded = false;
  // The same along the direction of the larger principal curvature (a
  // ramp's cylinder: its cross-section, where the gradient mixes in the
  // flat slope along the axis).
  const Principal p = PrincipalCurvatures(j);
  const double k1 = p.m + p.q;
  f.wx = j.wx;
  f.wy = j.wy;
  f.ex = p.ex;
  f.ey = p.ey;
  f.se = j.wx * f.ex + j.wy * f.ey;
  const double de = k1 > 0 ? CircleRimDistance(f.se * f.se, k1) : kInfinity;
  const double reach = kPatchReach * std::min(delta, de);
  f.reach2 = reach * reach;
  f.s = std::hypot(j.wx, j.wy);
  f.uphill = kPatchUphill * delta;
  f.uphill_e = kPatchUphill * de;
  return f;
}

PatchTrust TrustPatch(const PatchTrustFrame& f, double dx, double dy) {
  if (f.unbounded) return PatchTrust::kFull;
  if (dx * dx + dy * dy > f.reach2) return PatchTrust::kNone;
  if (f.s > 0 && (dx * f.wx + dy * f.wy) / f.s > f.uphill) {
    return PatchTrust::kLowerBound;  // uphill, towards the rim
  }
  const double along = (dx * f.ex + dy * f.ey) * (f.se < 0 ? -1 : 1);
  if (f.se != 0 && along > f.uphill_e) return PatchTrust::kLowerBound;
  return PatchTrust::kFull;
}

void FillTrust(ElementCorners* e) {
  for (int k = 0; k < 4; ++k) e->trust[k] = TrustFrameOf(e->c[k]);
  e->has_trust = true;
}

PatchTrust TrustPatch(const SurfaceJet& j, double dx, double dy) {
  return TrustPatch(TrustFrameOf(j), dx, dy);
}

double GuardedHeight(const ElementCorners& e, double x, double y) {
  double w;
  GuardedMin(e, x, y, &w);
  return w;
}

namespace {

// Clones for wider vectors, picked at load time; the same IEEE operations in
// every clone (no FMA: -ffp-contract=off), so the same bits (as the sweeps'
// kernels, core/cutter/ball_sweep.cc).
#ifdef SWARF_NO_TARGET_CLONES
#define SWARF_TARGET_CLONES
#else
#define SWARF_TARGET_CLONES \
  __attribute__((target_clones("default", "avx2", "arch=x86-64-v4")))
#endif

// The squared distance from (x, y) to a capsule's segment exactly as
// CornerReach::Capsule::Contains computes it.
double CapsuleDistance2(const CornerReach::Capsule& c, double x, double y) {
  const double ux = c.bx - c.ax, uy = c.by - c.ay;
  const double px = x - c.ax, py = y - c.ay;
  const double len2 = ux * ux + uy * uy;
  const double t =
      len2 > 0 ? std::clamp((px * ux + py * uy) / len2, 0.0, 1.0) : 0.0;
  const double dx = px - t * ux, dy = py - t * uy;
  return dx * dx + dy * dy;
}

// Whether Contains, as computed, holds at every point of the finite box
// [x0, x1] x [y0, y1] (kInside), at none (kOutside), or either is possible
// (kMixed). The distance to a segment is 1-Lipschitz, so over the box it is
// at most its value at the centre plus the half diagonal, and it is at
// least the gap between the box and the segment's bounding box. The
// computed distance is within a few ulps of the coordinates of the true
// one (the point on the segment it measures to is off by as little); tol,
// a thousand times that, separates the cases.
enum class BoxSide { kInside, kOutside, kMixed };
BoxSide CapsuleBoxSide(const CornerReach::Capsule& c, double x0, double y0,
                       double x1, double y1) {
  const double scale = 1 + std::fabs(c.ax) + std::fabs(c.ay) +
                       std::fabs(c.bx) + std::fabs(c.by) + std::fabs(x0) +
                       std::fabs(x1) + std::fabs(y0) + std::fabs(y1) +
                       std::fabs(c.radius);
  const double tol = 1e-12 * scale;
  const double centre = std::sqrt(
      CapsuleDistance2(c, 0.5 * (x0 + x1), 0.5 * (y0 + y1)));
  const double half_diagonal =
      0.5 * std::sqrt((x1 - x0) * (x1 - x0) + (y1 - y0) * (y1 - y0));
  if (centre + half_diagonal + 4 * tol <= c.radius * (1 - 1e-12)) {
    return BoxSide::kInside;
  }
  const double gap_x = std::max(x0 - std::max(c.ax, c.bx),
                                std::min(c.ax, c.bx) - x1);
  const double gap_y = std::max(y0 - std::max(c.ay, c.by),
                                std::min(c.ay, c.by) - y1);
  if (std::max(gap_x, gap_y) - 4 * tol >= c.radius * (1 + 1e-12)) {
    return BoxSide::kOutside;
  }
  return BoxSide::kMixed;
}

// std::lerp(a, b, t) (libstdc++'s, which BilinearHeight uses) as selects,
// for vectorized loops: the same operations on every path.
inline double LerpSelect(double a, double b, double t) {
  const bool opposite = ((a <= 0) & (b >= 0)) | ((a >= 0) & (b <= 0));
  const double r1 = t * b + (1 - t) * a;
  const double x = a + t * (b - a);
  const double r2 =
      (t > 1) == (b > a) ? (b < x ? x : b) : (b > x ? x : b);
  return opposite ? r1 : (t == 1 ? b : r2);
}

// out[q] = std::lerp(a, b, t[q]) for loop-invariant a and b: their tests
// decided once (the vectorizer takes no select on a scalar condition).
// Inlined into its callers' clones.
inline void LerpInvariant(double a, double b, const double* __restrict t, int32_t n,
                   double* __restrict out) {
  if ((a <= 0 && b >= 0) || (a >= 0 && b <= 0)) {
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) out[q] = t[q] * b + (1 - t[q]) * a;
  } else if (b > a) {
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) {
      const double x = a + t[q] * (b - a);
      out[q] = t[q] == 1 ? b : t[q] > 1 ? (b < x ? x : b) : (b > x ? x : b);
    }
  } else {
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) {
      const double x = a + t[q] * (b - a);
      out[q] = t[q] == 1 ? b : t[q] > 1 ? (b > x ? x : b) : (b < x ? x : b);
    }
  }
}

// out[q] = BilinearHeight(e, x[q], y[q]) for n <= kGuardedChunk points.
constexpr int32_t kGuardedChunk = 64;
SWARF_TARGET_CLONES
void BilinearHeights(const ElementCorners& e, const double* __restrict x,
                     const double* __restrict y, int32_t n,
                     double* __restrict out) {
  double s[kGuardedChunk], l0[kGuardedChunk], l1[kGuardedChunk];
  const double x0 = e.x0, lx = e.x1 - e.x0, y0 = e.y0, ly = e.y1 - e.y0;
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) s[q] = (x[q] - x0) / lx;
  LerpInvariant(e.c[0].w, e.c[1].w, s, n, l0);
  LerpInvariant(e.c[3].w, e.c[2].w, s, n, l1);
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    out[q] = LerpSelect(l0[q], l1[q], (y[q] - y0) / ly);
  }
}

// GuardedHeights on at most kGuardedChunk points. Corner by corner, each
// point sees the same operations in the same order as GuardedMin: the
// bilinear, then for k = 0..3 whether its reach holds the point
// (CornerReach::Contains), its term (GuardedTerm) and the running minimum.

SWARF_TARGET_CLONES
void GuardedChunk(const ElementCorners& e, const double* __restrict x,
                  const double* __restrict y, int32_t n,
                  double* __restrict out) {
  // Flags as doubles (0 or 1), and loop-invariant conditions folded into
  // the thresholds, so that every loop is selects the vectorizer takes.
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double b[kGuardedChunk], w[kGuardedChunk];
  double any[kGuardedChunk], in[kGuardedChunk];
  BilinearHeights(e, x, y, n, b);
  for (int32_t q = 0; q < n; ++q) {
    w[q] = e.z_top;
    any[q] = 0;
  }
  const double xs[4] = {e.x0, e.x1, e.x1, e.x0};
  const double ys[4] = {e.y0, e.y0, e.y1, e.y1};
  // The points' box, for capsules that hold all of it or none.
  double box_x0 = x[0], box_x1 = x[0], box_y0 = y[0], box_y1 = y[0];
  bool finite = true;
  for (int32_t q = 0; q < n; ++q) {
    finite &= std::isfinite(x[q]) & std::isfinite(y[q]);
    box_x0 = std::min(box_x0, x[q]);
    box_x1 = std::max(box_x1, x[q]);
    box_y0 = std::min(box_y0, y[q]);
    box_y1 = std::max(box_y1, y[q]);
  }
  for (int k = 0; k < 4; ++k) {
    const CornerReach& r = e.reach[k];
    // in[q]: r.Contains(x[q], y[q]).
    const double in_all = r.bounded ? 0.0 : 1.0;
    for (int32_t q = 0; q < n; ++q) in[q] = in_all;
    for (int c = 0; r.bounded && c < r.count; ++c) {
      const CornerReach::Capsule& cap = r.capsule[c];
      if (finite) {
        const BoxSide side =
            CapsuleBoxSide(cap, box_x0, box_y0, box_x1, box_y1);
        if (side == BoxSide::kOutside) continue;
        if (side == BoxSide::kInside) {
          for (int32_t q = 0; q < n; ++q) in[q] = 1;
          break;
        }
      }
      const double ax = cap.ax, ay = cap.ay;
      const double ux = cap.bx - ax, uy = cap.by - ay;
      const double len2 = ux * ux + uy * uy;
      const double r2 = cap.radius * cap.radius;
      if (len2 > 0) {
#pragma omp simd
        for (int32_t q = 0; q < n; ++q) {
          const double px = x[q] - ax, py = y[q] - ay;
          // std::clamp(v, 0, 1) by value: min(max(v, 0), 1).
          const double v = (px * ux + py * uy) / len2;
          const double v0 = v < 0.0 ? 0.0 : v;
          const double t = 1.0 < v0 ? 1.0 : v0;
          const double dx = px - t * ux, dy = py - t * uy;
          in[q] = dx * dx + dy * dy <= r2 ? 1.0 : in[q];
        }
      } else {
#pragma omp simd
        for (int32_t q = 0; q < n; ++q) {
          const double px = x[q] - ax, py = y[q] - ay;
          const double t = 0.0;
          const double dx = px - t * ux, dy = py - t * uy;
          in[q] = dx * dx + dy * dy <= r2 ? 1.0 : in[q];
        }
      }
    }
    // TrustPatch(f, dx, dy): kNone past reach2; kLowerBound uphill along
    // the gradient (when s > 0) or along (ex, ey) (when se != 0). A test
    // that does not apply gets an infinite threshold, which nothing passes.
    const PatchTrustFrame f =
        e.has_trust ? e.trust[k] : TrustFrameOf(e.c[k]);
    const double reach2 = f.unbounded ? kInf : f.reach2;
    const double uphill = f.unbounded || !(f.s > 0) ? kInf : f.uphill;
    const double uphill_e = f.unbounded || !(f.se != 0) ? kInf : f.uphill_e;
    const double sign = f.se < 0 ? -1 : 1;
    const double s = f.s, wx = f.wx, wy = f.wy, ex = f.ex, ey = f.ey;
    const SurfaceJet& j = e.c[k];
    const double xk = xs[k], yk = ys[k], z_low = r.z_low;
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) {
      const double dx = x[q] - xk, dy = y[q] - yk;
      const bool none = dx * dx + dy * dy > reach2;
      const bool lower = ((dx * wx + dy * wy) / s > uphill) |
                         ((dx * ex + dy * ey) * sign > uphill_e);
      // GuardedTerm: the patch held at z_low (std::max(raw, z_low)), the
      // bilinear where it is not trusted or only a lower bound below it.
      const double raw = EvaluatePatch(j, xk, yk, x[q], y[q]);
      const double p = raw < z_low ? z_low : raw;
      const double v = none | (lower & (b[q] > p)) ? b[q] : p;
      const bool inside = in[q] != 0;
      any[q] = inside ? 1.0 : any[q];
      w[q] = inside & (v < w[q]) ? v : w[q];
    }
  }
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) out[q] = any[q] != 0 ? w[q] : b[q];
}

}  // namespace

void GuardedHeights(const ElementCorners& e, const double* x, const double* y,
                    int32_t n, double* out) {
  for (int32_t q0 = 0; q0 < n; q0 += kGuardedChunk) {
    GuardedChunk(e, x + q0, y + q0, std::min(kGuardedChunk, n - q0), out + q0);
  }
}

double MinOfPatches(const ElementCorners& e, double x, double y) {
  const double xs[4] = {e.x0, e.x1, e.x1, e.x0};
  const double ys[4] = {e.y0, e.y0, e.y1, e.y1};
  double w = e.z_top;
  for (int k = 0; k < 4; ++k) {
    w = std::min(w, EvaluatePatch(e.c[k], xs[k], ys[k], x, y));
  }
  return w;
}

namespace {

class ZmapScheme final : public Scheme {
 public:
  SchemeKind kind() const override { return SchemeKind::kZmap; }
  std::string_view name() const override { return "zmap"; }
  int parameters_per_node() const override { return 1; }
  bool stores_derivatives() const override { return false; }
  int bytes_per_node() const override { return 12; }  // double w + int32 id
  double Reconstruct(const ElementCorners& e, double x,
                     double y) const override {
    return BilinearHeight(e, x, y);
  }
  void Gradient(const ElementCorners& e, double x, double y, double* gx,
                double* gy) const override {
    BilinearGradient(e, x, y, gx, gy);
  }
};

class TaylorScheme final : public Scheme {
 public:
  SchemeKind kind() const override { return SchemeKind::kTaylor; }
  std::string_view name() const override { return "taylor"; }
  int parameters_per_node() const override { return 6; }
  bool stores_derivatives() const override { return true; }
  // double w and int32 owner: the derivatives are computed from the owner.
  int bytes_per_node() const override { return 12; }
  double Reconstruct(const ElementCorners& e, double x,
                     double y) const override {
    return MinOfPatches(e, x, y);
  }
  void Gradient(const ElementCorners& e, double x, double y, double* gx,
                double* gy) const override {
    const double xs[4] = {e.x0, e.x1, e.x1, e.x0};
    const double ys[4] = {e.y0, e.y0, e.y1, e.y1};
    double w = e.z_top;
    *gx = *gy = 0;  // the stock top
    for (int k = 0; k < 4; ++k) {
      const double wk = EvaluatePatch(e.c[k], xs[k], ys[k], x, y);
      if (wk < w) {
        w = wk;
        PatchGradient(e.c[k], xs[k], ys[k], x, y, gx, gy);
      }
    }
  }
};

class GuardedScheme final : public Scheme {
 public:
  SchemeKind kind() const override { return SchemeKind::kGuarded; }
  std::string_view name() const override { return "guarded"; }
  int parameters_per_node() const override { return 6; }
  bool stores_derivatives() const override { return true; }
  int bytes_per_node() const override { return 12; }  // as taylor
  bool uses_reach() const override { return true; }
  bool uses_trust() const override { return true; }
  double Reconstruct(const ElementCorners& e, double x,
                     double y) const override {
    return GuardedHeight(e, x, y);
  }
  void ReconstructMany(const ElementCorners& e, const double* x,
                       const double* y, int32_t n,
                       double* out) const override {
    GuardedHeights(e, x, y, n, out);
  }
  void Gradient(const ElementCorners& e, double x, double y, double* gx,
                double* gy) const override {
    HeightAndGradient(e, x, y, gx, gy);
  }
  double HeightAndGradient(const ElementCorners& e, double x, double y,
                           double* gx, double* gy) const override {
    double w;
    const int k = GuardedMin(e, x, y, &w);
    if (k == -2) {
      BilinearGradient(e, x, y, gx, gy);
      return w;
    }
    *gx = *gy = 0;  // the top, or a patch held at its owner's lowest point
    if (k < 0) return w;
    const double xs[4] = {e.x0, e.x1, e.x1, e.x0};
    const double ys[4] = {e.y0, e.y0, e.y1, e.y1};
    if (EvaluatePatch(e.c[k], xs[k], ys[k], x, y) < e.reach[k].z_low) return w;
    PatchGradient(e.c[k], xs[k], ys[k], x, y, gx, gy);
    return w;
  }
};

class ExactScheme final : public Scheme {
 public:
  SchemeKind kind() const override { return SchemeKind::kExact; }
  std::string_view name() const override { return "exact"; }
  // The height; the owner names the surface the rest comes from.
  int parameters_per_node() const override { return 1; }
  bool stores_derivatives() const override { return true; }  // on demand
  int bytes_per_node() const override { return 12; }
  bool uses_candidates() const override { return true; }
  double Reconstruct(const ElementCorners& e, double x,
                     double y) const override {
    return ExactCandidatesHeight(e, x, y);
  }
  void Gradient(const ElementCorners& e, double x, double y, double* gx,
                double* gy) const override {
    *gx = *gy = 0;  // the stock top
    if (e.surfaces == nullptr) {
      GetScheme(SchemeKind::kTaylor).Gradient(e, x, y, gx, gy);
      return;
    }
    double w = e.z_top;
    int32_t lowest = -1;
    for (const int32_t id : e.candidates) {
      const double h = e.surfaces->Height(id, x, y);
      if (h < w) {
        w = h;
        lowest = id;
      }
    }
    if (lowest < 0) return;
    const SurfaceJet j = e.surfaces->Jet(lowest, x, y);
    *gx = j.wx;
    *gy = j.wy;
  }
};

}  // namespace

double ExactCandidatesHeight(const ElementCorners& e, double x, double y) {
  if (e.surfaces == nullptr) return MinOfPatches(e, x, y);
  double w = e.z_top;
  for (const int32_t id : e.candidates) {
    w = std::min(w, e.surfaces->Height(id, x, y));
  }
  return w;
}

const Scheme& GetScheme(SchemeKind kind) {
  static const ZmapScheme* const zmap = new ZmapScheme;
  static const TaylorScheme* const taylor = new TaylorScheme;
  static const GuardedScheme* const guarded = new GuardedScheme;
  static const ExactScheme* const exact = new ExactScheme;
  switch (kind) {
    case SchemeKind::kZmap:
      return *zmap;
    case SchemeKind::kTaylor:
      return *taylor;
    case SchemeKind::kExact:
      return *exact;
    case SchemeKind::kGuarded:
      break;
  }
  return *guarded;
}

absl::StatusOr<SchemeKind> ParseScheme(std::string_view name) {
  if (name == "zmap") return SchemeKind::kZmap;
  if (name == "taylor") return SchemeKind::kTaylor;
  if (name == "guarded") return SchemeKind::kGuarded;
  if (name == "exact") return SchemeKind::kExact;
  return absl::InvalidArgumentError(
      absl::StrCat("unknown scheme \"", std::string(name),
                   "\" (expected guarded, exact, taylor or zmap)"));
}

}  // namespace swarf
