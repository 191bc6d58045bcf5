#include "core/scheme.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <string>

#include "absl/strings/str_cat.h"
#include "core/stock.h"
#include "core/target_clones.h"

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

namespace {

// The squared distance from (x, y) to a capsule's segment, clamped to its
// ends: what CornerReach::Capsule::Contains compares with the radius.
[[gnu::always_inline]] inline double CapsuleDistance2(
    const CornerReach::Capsule& c, double x, double y) {
  const double ux = c.bx - c.ax, uy = c.by - c.ay;
  const double px = x - c.ax, py = y - c.ay;
  const double len2 = ux * ux + uy * uy;
  const double t =
      len2 > 0 ? std::clamp((px * ux + py * uy) / len2, 0.0, 1.0) : 0.0;
  const double dx = px - t * ux, dy = py - t * uy;
  return dx * dx + dy * dy;
}

}  // namespace

bool CornerReach::Capsule::Contains(double x, double y) const {
  return CapsuleDistance2(*this, x, y) <= radius * radius;
}

bool CornerReach::Contains(double x, double y) const {
  if (!bounded) return true;
  return !empty && capsule.Contains(x, y);
}

namespace {

// The gradient at (x, y) of the bilinear interpolation over the element of
// the values v[k] at its corners (in the order of ElementCorners::c).
void BilinearGradientOf(const ElementCorners& e, const double v[4], double x,
                        double y, double* gx, double* gy) {
  const double lx = e.x1 - e.x0, ly = e.y1 - e.y0;
  const double s = (x - e.x0) / lx, t = (y - e.y0) / ly;
  *gx = ((1 - t) * (v[1] - v[0]) + t * (v[2] - v[3])) / lx;
  *gy = ((1 - s) * (v[3] - v[0]) + s * (v[2] - v[1])) / ly;
}

// Eq. (16)'s gradient: of the corner heights.
void BilinearGradient(const ElementCorners& e, double x, double y, double* gx,
                      double* gy) {
  const double w[4] = {e.c[0].w, e.c[1].w, e.c[2].w, e.c[3].w};
  BilinearGradientOf(e, w, x, y, gx, gy);
}

// The lowest of the stock top and the element's candidates' exact surfaces
// at (x, y), and the candidate that gives it (-1: the top).
struct Lowest {
  double w;
  int32_t id;
};
Lowest LowestCandidate(const ElementCorners& e, double x, double y) {
  Lowest l{e.z_top, -1};
  for (const int32_t id : e.candidates) {
    const double h = e.surfaces->Height(id, x, y);
    if (h < l.w) l = {h, id};
  }
  return l;
}

// Corner coordinates, in the order of ElementCorners::c.
struct CornerXY {
  double x[4], y[4];
};
CornerXY CornersOf(const ElementCorners& e) {
  return {{e.x0, e.x1, e.x1, e.x0}, {e.y0, e.y0, e.y1, e.y1}};
}

// What gives the guarded height: corner `corner`'s lifted patch, or the
// exact surface of move `move`, or (neither) the top; kBilinear: eq. (16).
constexpr int kBilinear = -2;
struct GuardedValue {
  double w = 0;
  int corner = -1;
  int32_t move = -1;
};

// Corner k's patch lifted by the bilinear interpolation of its shortfalls
// (Guard::lift_uv): one quadric, evaluated as the patch is, for the cost of
// the patch alone (the lerps of the shortfalls a point took more than the
// patch). Corner k's own height is kept exactly (u = v = 0 there); an
// unlifted corner's jet is e.c[k] itself.
SurfaceJet LiftedJet(const ElementCorners& e, int k) {
  SurfaceJet j = e.c[k];
  const double* l = e.guard.lift_uv[k];
  j.wx += l[0];
  j.wy += l[1];
  j.wxy += l[2];
  return j;
}

// The true surface at (x, y) where it is below v: a cut between the nodes.
void TakeLowest(const ElementCorners& e, double x, double y, GuardedValue* v) {
  int32_t id = -1;
  const double w = e.surfaces->LowestAt(e.ei, e.ej, x, y, v->w, &id);
  if (w < v->w) {
    v->w = w;
    v->corner = -1;
    v->move = id;
  }
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

// Points per call of SmoothChunk (a multiple of 8).
constexpr int32_t kGuardedChunk = 64;

// SmoothChunk's arrays for one corner's pass.
struct CornerPoints {
  const double *x, *y, *inside;
  double *any, *w;
};

// A patch's value raw held at or above its owner's lowest tip z_low:
// std::max(raw, z_low), by value.
[[gnu::always_inline]] inline double HeldAtTip(double raw, double z_low) {
  return raw < z_low ? z_low : raw;
}

// A running minimum w lowered by a patch's value raw held at its owner's
// lowest tip: std::min(w, HeldAtTip(raw, z_low)), by value.
[[gnu::always_inline]] inline double LowerByPatch(double w, double raw,
                                                  double z_low) {
  const double p = HeldAtTip(raw, z_low);
  return p < w ? p : w;
}

// Whether corner k's reach surely holds every point of the element: it
// holds the element's corners (a capsule is convex), or it is unbounded.
[[gnu::always_inline]] inline bool ReachHoldsAll(const ElementCorners& e,
                                                 int k) {
  return e.guard.inside[k] || !e.reach[k].bounded;
}

// A corner's lifted patch (LiftedJet) over SmoothChunk's points, and the
// running minimum where the corner holds them (kAll: it holds them all,
// `inside` is not read). One loop for both, vectorized in its caller's
// clone.
template <bool kAll>
[[gnu::always_inline]] inline void LowerByCorner(const SurfaceJet& j, double xk,
                                                 double yk, double z_low,
                                                 const CornerPoints& pts,
                                                 int32_t n) {
  const double* __restrict x = pts.x;
  const double* __restrict y = pts.y;
  const double* __restrict inside = pts.inside;
  double* __restrict any = pts.any;
  double* __restrict w = pts.w;
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    const double raw = EvaluatePatch(j, xk, yk, x[q], y[q]);
    if constexpr (kAll) {
      any[q] = 1.0;
      w[q] = LowerByPatch(w[q], raw, z_low);
    } else {
      const double p = HeldAtTip(raw, z_low);
      const bool holds = inside[q] != 0;
      any[q] = holds ? 1.0 : any[q];
      w[q] = (holds & (p < w[q])) ? p : w[q];
    }
  }
}

// A chunk's worth of ones and of zeros: the reach flags of a corner that
// holds every point or none.
constexpr std::array<double, kGuardedChunk> Filled(double v) {
  std::array<double, kGuardedChunk> a{};
  for (double& x : a) x = v;
  return a;
}
alignas(64) constexpr std::array<double, kGuardedChunk> kAllInside =
    Filled(1.0);
alignas(64) constexpr std::array<double, kGuardedChunk> kNoneInside =
    Filled(0.0);

// Guarded() at 1 <= n_in <= kGuardedChunk points of a smooth element with
// surfaces, corner by corner in vectorized loops: each point sees the same
// operations in the same order (its reach test, each lifted patch and the
// running minimum, the hidden test). A capsule that holds all the points or
// none is decided once (CapsuleBoxSide). Points where a corner is hidden
// take the true surface one by one (TakeLowest), as Guarded does.
SWARF_TARGET_CLONES
void SmoothChunk(const ElementCorners& e, const double* __restrict x_in,
                 const double* __restrict y_in, int32_t n_in, bool padded,
                 double* __restrict out) {
  // The points padded to a multiple of 8 with copies of the last: the
  // vector loops then have no scalar remainder (the valuation gives 21
  // points an element: each loop ended with one point alone). A copy's
  // values are the last point's and are not written out; it does not widen
  // the points' box. `padded`: the caller's arrays are so padded (and out
  // has room for them): read in place.
  double x_copy[kGuardedChunk], y_copy[kGuardedChunk];
  const int32_t n = (n_in + 7) & ~7;
  if (!padded) {
#pragma omp simd
    for (int32_t q = 0; q < n_in; ++q) {
      x_copy[q] = x_in[q];
      y_copy[q] = y_in[q];
    }
    for (int32_t q = n_in; q < n; ++q) {
      x_copy[q] = x_in[n_in - 1];
      y_copy[q] = y_in[n_in - 1];
    }
  }
  const double* __restrict x = padded ? x_in : x_copy;
  const double* __restrict y = padded ? y_in : y_copy;
  // Every corner's reach holding every point (the usual smooth interior):
  // the four lifted patches' running minimum in registers, the same
  // operations in the same order as the corner passes below, and no point
  // hidden (every corner holds it), so no flags and no hidden test.
  if (ReachHoldsAll(e, 0) && ReachHoldsAll(e, 1) && ReachHoldsAll(e, 2) &&
      ReachHoldsAll(e, 3)) {
    const CornerXY c = CornersOf(e);
    const SurfaceJet j0 = LiftedJet(e, 0), j1 = LiftedJet(e, 1),
                     j2 = LiftedJet(e, 2), j3 = LiftedJet(e, 3);
    const double z0 = e.reach[0].z_low, z1 = e.reach[1].z_low,
                 z2 = e.reach[2].z_low, z3 = e.reach[3].z_low;
    const double top = e.z_top;
    double w_copy[kGuardedChunk];
    // Padded, out has room for the copies' values too.
    double* const w = padded ? out : w_copy;
#pragma omp simd
    for (int32_t q = 0; q < n; ++q) {
      double v = top;
      v = LowerByPatch(v, EvaluatePatch(j0, c.x[0], c.y[0], x[q], y[q]), z0);
      v = LowerByPatch(v, EvaluatePatch(j1, c.x[1], c.y[1], x[q], y[q]), z1);
      v = LowerByPatch(v, EvaluatePatch(j2, c.x[2], c.y[2], x[q], y[q]), z2);
      v = LowerByPatch(v, EvaluatePatch(j3, c.x[3], c.y[3], x[q], y[q]), z3);
      w[q] = v;
    }
    if (!padded) {
#pragma omp simd
      for (int32_t q = 0; q < n_in; ++q) out[q] = w[q];
    }
    return;
  }
  // Flags as doubles (0 or 1) beside the doubles, and loop-invariant tests
  // outside the loops, so that every loop is selects the vectorizer takes.
  double in_store[4][kGuardedChunk];
  const double* in[4];  // corner k's flags: in_store[k], or all 1 or all 0
  double w[kGuardedChunk], any[kGuardedChunk];
#pragma omp simd
  for (int32_t q = 0; q < n; ++q) {
    w[q] = e.z_top;
    any[q] = 0;
  }
  // The points' box, for a capsule that may hold some of them, taken on
  // first use (most corners hold all or none), and only when every point is
  // finite: then the order of the comparisons does not matter.
  double box_x0, box_x1, box_y0, box_y1;
  int box = -1;  // -1: not yet; 0: not finite; 1: taken
  auto take_box = [&] {
    box_x0 = box_x1 = x[0];
    box_y0 = box_y1 = y[0];
    bool finite = true;
    for (int32_t q = 0; q < n_in; ++q) {
      finite &= static_cast<int>(std::isfinite(x[q])) &
                static_cast<int>(std::isfinite(y[q]));
      box_x0 = std::min(box_x0, x[q]);
      box_x1 = std::max(box_x1, x[q]);
      box_y0 = std::min(box_y0, y[q]);
      box_y1 = std::max(box_y1, y[q]);
    }
    box = finite ? 1 : 0;
  };
  const CornerXY c = CornersOf(e);
  for (int k = 0; k < 4; ++k) {
    const CornerReach& r = e.reach[k];
    // in[k][q]: e.guard.inside[k] || r.Contains(x[q], y[q]); decided for
    // all the points at once where it can be (no flags to fill).
    const bool all = ReachHoldsAll(e, k);
    const bool none = !all && r.empty;
    BoxSide side = all ? BoxSide::kInside : none ? BoxSide::kOutside
                                                  : BoxSide::kMixed;
    if (side == BoxSide::kMixed && box < 0) take_box();
    if (side == BoxSide::kMixed && box == 1) {
      side = CapsuleBoxSide(r.capsule, box_x0, box_y0, box_x1, box_y1);
    }
    in[k] = side == BoxSide::kInside    ? kAllInside.data()
            : side == BoxSide::kOutside ? kNoneInside.data()
                                        : in_store[k];
    // A corner that holds no point lowers none.
    if (side == BoxSide::kOutside) continue;
    if (side == BoxSide::kMixed) {
      double* __restrict inside = in_store[k];
      const CornerReach::Capsule& cs = r.capsule;
      const double ax = cs.ax, ay = cs.ay;
      const double ux = cs.bx - ax, uy = cs.by - ay;
      const double len2 = ux * ux + uy * uy;
      const double r2 = cs.radius * cs.radius;
      if (len2 > 0) {
#pragma omp simd
        for (int32_t q = 0; q < n; ++q) {
          const double px = x[q] - ax, py = y[q] - ay;
          // std::clamp(v, 0, 1) by value: min(max(v, 0), 1).
          const double v = (px * ux + py * uy) / len2;
          const double v0 = v < 0.0 ? 0.0 : v;
          const double tc = 1.0 < v0 ? 1.0 : v0;
          const double dx = px - tc * ux, dy = py - tc * uy;
          inside[q] = dx * dx + dy * dy <= r2 ? 1.0 : 0.0;
        }
      } else {
#pragma omp simd
        for (int32_t q = 0; q < n; ++q) {
          const double px = x[q] - ax, py = y[q] - ay;
          const double tc = 0.0;
          const double dx = px - tc * ux, dy = py - tc * uy;
          inside[q] = dx * dx + dy * dy <= r2 ? 1.0 : 0.0;
        }
      }
    }
    const SurfaceJet j = LiftedJet(e, k);
    const double xk = c.x[k], yk = c.y[k], z_low = r.z_low;
    const CornerPoints pts{x, y, in[k], any, w};
    if (side == BoxSide::kInside) {
      LowerByCorner<true>(j, xk, yk, z_low, pts, n);
    } else {
      LowerByCorner<false>(j, xk, yk, z_low, pts, n);
    }
  }
  // Hidden points (no corner holds them, or a corner out of its reach is
  // below them) as flags in one vectorized loop; then those take the true
  // surface.
  double hidden[kGuardedChunk];
  double hidden_count = 0;  // exact: a sum of at most 64 ones
  const double c0 = e.c[0].w, c1 = e.c[1].w, c2 = e.c[2].w, c3 = e.c[3].w;
#pragma omp simd reduction(+ : hidden_count)
  for (int32_t q = 0; q < n; ++q) {
    const bool h = (any[q] == 0) | ((in[0][q] == 0) & (c0 < w[q])) |
                   ((in[1][q] == 0) & (c1 < w[q])) |
                   ((in[2][q] == 0) & (c2 < w[q])) |
                   ((in[3][q] == 0) & (c3 < w[q]));
    hidden[q] = h ? 1.0 : 0.0;
    hidden_count += hidden[q];
  }
#pragma omp simd
  for (int32_t q = 0; q < n_in; ++q) out[q] = w[q];
  if (hidden_count == 0) return;
  for (int32_t q = 0; q < n_in; ++q) {
    if (hidden[q] == 0) continue;
    GuardedValue v;
    v.w = w[q];
    TakeLowest(e, x[q], y[q], &v);
    out[q] = v.w;
  }
}

GuardedValue Guarded(const ElementCorners& e, double x, double y) {
  const CornerXY c = CornersOf(e);
  GuardedValue v;
  v.w = e.z_top;
  if (!GuardedIsExact(e)) {
    bool any = false;
    bool in[4];
    for (int k = 0; k < 4; ++k) {
      in[k] = e.guard.inside[k] || e.reach[k].Contains(x, y);
      if (!in[k]) continue;
      any = true;
      const double p =
          std::max(EvaluatePatch(LiftedJet(e, k), c.x[k], c.y[k], x, y),
                   e.reach[k].z_low);
      if (p < v.w) {
        v.w = p;
        v.corner = k;
      }
    }
    if (e.surfaces == nullptr) {
      if (!any) {
        v.w = BilinearHeight(e, x, y);
        v.corner = kBilinear;
      }
      return v;
    }
    bool hidden = !any;
    for (int k = 0; k < 4; ++k) hidden |= !in[k] && e.c[k].w < v.w;
    if (hidden) TakeLowest(e, x, y, &v);
    return v;
  }
  // The exact surface: the element's candidates (PrepareGuarded) hold
  // every move that can be the lowest in it.
  const Lowest l = LowestCandidate(e, x, y);
  v.w = l.w;
  v.move = l.id;
  return v;
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

PatchTrustRegion TrustRegion(const SurfaceJet& j) {
  PatchTrustRegion r;
  r.delta = RimDistance(j);
  if (r.delta == kInfinity) return r;
  r.everywhere = false;
  // The same along the direction of the larger principal curvature (a
  // ramp's cylinder: its cross-section, where the gradient mixes in the
  // flat slope along the axis).
  const Principal p = PrincipalCurvatures(j);
  const double k1 = p.m + p.q;
  r.ex = p.ex;
  r.ey = p.ey;
  r.se = j.wx * r.ex + j.wy * r.ey;
  r.de = k1 > 0 ? CircleRimDistance(r.se * r.se, k1) : kInfinity;
  r.reach = kPatchReach * std::min(r.delta, r.de);
  r.gx = j.wx;
  r.gy = j.wy;
  r.s = std::hypot(j.wx, j.wy);
  return r;
}

namespace {

// Trust, inlined where an element's twelve corner pairs are tested.
[[gnu::always_inline]] inline PatchTrust TrustAt(const PatchTrustRegion& r,
                                                 double dx, double dy) {
  if (r.everywhere) return PatchTrust::kFull;
  if (dx * dx + dy * dy > r.reach * r.reach) return PatchTrust::kNone;
  if (r.s > 0 && (dx * r.gx + dy * r.gy) / r.s > kPatchUphill * r.delta) {
    return PatchTrust::kLowerBound;  // uphill, towards the rim
  }
  const double along = (dx * r.ex + dy * r.ey) * (r.se < 0 ? -1 : 1);
  if (r.se != 0 && along > kPatchUphill * r.de) return PatchTrust::kLowerBound;
  return PatchTrust::kFull;
}

// Whether TrustAt(r, dx, dy) is surely kFull at the element's other three
// corners, dx in {0, +-hx} and dy in {0, +-hy} (hx, hy >= 0): each of
// TrustAt's sums there is at most the sum here of the terms' magnitudes
// (|dx gx| <= hx |gx|; sums, products and the division by s > 0 round
// monotonically), and the slack covers a sum contracted into a fused
// multiply-add on one side and not the other. So passing here passes there,
// as TrustAt decides, bit for bit; false only says that the corners must be
// tested one by one. One test for three.
[[gnu::always_inline]] inline bool SurelyTrustedAt(const PatchTrustRegion& r,
                                                   double hx, double hy) {
  constexpr double kSlack = 1 + 1e-9;
  if (r.everywhere) return true;
  if ((hx * hx + hy * hy) * kSlack > r.reach * r.reach) return false;
  if (r.s > 0 && (hx * std::abs(r.gx) + hy * std::abs(r.gy)) * kSlack / r.s >
                     kPatchUphill * r.delta) {
    return false;
  }
  return !(r.se != 0 && (hx * std::abs(r.ex) + hy * std::abs(r.ey)) * kSlack >
                            kPatchUphill * r.de);
}

}  // namespace

PatchTrust Trust(const PatchTrustRegion& r, double dx, double dy) {
  return TrustAt(r, dx, dy);
}

bool SurelyTrusted(const PatchTrustRegion& r, double hx, double hy) {
  return SurelyTrustedAt(r, hx, hy);
}

PatchTrust TrustPatch(const SurfaceJet& j, double dx, double dy) {
  return Trust(TrustRegion(j), dx, dy);
}

double GuardedHeight(const ElementCorners& e, double x, double y) {
  return Guarded(e, x, y).w;
}

namespace {

// out[q] = r.Contains(c.x[q], c.y[q]) as 1 or 0, inlined: the segment's
// terms are the same for the four points. Returns whether it holds all
// four.
bool ReachHolds(const CornerReach& r, const CornerXY& c, double out[4]) {
  if (!r.bounded || r.empty) {
    for (int q = 0; q < 4; ++q) out[q] = r.bounded ? 0.0 : 1.0;
    return !r.bounded;
  }
  const double r2 = r.capsule.radius * r.capsule.radius;
  bool all = true;
  for (int q = 0; q < 4; ++q) {
    const bool in = CapsuleDistance2(r.capsule, c.x[q], c.y[q]) <= r2;
    out[q] = in ? 1.0 : 0.0;
    all &= in;
  }
  return all;
}

// Whether a.Contains and b.Contains are one function.
bool SameReach(const CornerReach& a, const CornerReach& b) {
  return a.bounded == b.bounded && a.empty == b.empty &&
         a.capsule.ax == b.capsule.ax && a.capsule.ay == b.capsule.ay &&
         a.capsule.bx == b.capsule.bx && a.capsule.by == b.capsule.by &&
         a.capsule.radius == b.capsule.radius;
}

// r[k][q] = e.c[q].w - EvaluatePatch(e.c[k], corner k, corner q): each
// corner's patch's shortfall at every corner (r[k][k] unused), the same
// operations four corners at a time.
SWARF_TARGET_CLONES
void CornerResiduals(const ElementCorners& e, const CornerXY& c,
                     double r[4][4]) {
  const double w[4] = {e.c[0].w, e.c[1].w, e.c[2].w, e.c[3].w};
  for (int k = 0; k < 4; ++k) {
    const SurfaceJet j = e.c[k];
    const double xk = c.x[k], yk = c.y[k];
    double* __restrict rk = r[k];
#pragma omp simd
    for (int q = 0; q < 4; ++q) {
      rk[q] = w[q] - EvaluatePatch(j, xk, yk, c.x[q], c.y[q]);
    }
  }
}

// lift[k][q] = shortfall[k][q] where corner q (q != k) is in corner k's
// reach (holds[k][q] != 0) and the patch passes below it, else 0; returns
// whether such a shortfall passes tau. The sixteen pairs in one vectorized
// pass: an element's pairs took a branch each.
SWARF_TARGET_CLONES
bool CornerLifts(const double (&shortfall)[4][4], const double (&holds)[4][4],
                 double tau, double (&lift)[4][4]) {
  static constexpr double kOffDiagonal[16] = {0, 1, 1, 1, 1, 0, 1, 1,
                                              1, 1, 0, 1, 1, 1, 1, 0};
  const double* __restrict r = &shortfall[0][0];
  const double* __restrict h = &holds[0][0];
  double* __restrict l = &lift[0][0];
  double over = 0;
#pragma omp simd reduction(max : over)
  for (int i = 0; i < 16; ++i) {
    // Non-short-circuit: with && GCC loads r[i] under a mask, branching.
    const double ri = r[i];
    const bool seen = (h[i] != 0) & (kOffDiagonal[i] != 0);
    l[i] = (seen & (ri > 0)) ? ri : 0.0;
    over = std::max(over, (seen & (ri > tau)) ? 1.0 : 0.0);
  }
  return over != 0;
}

// Guard::lift_uv[k] from lift[k] (d) for each corner k: the lift is the
// bilinear
//   L(s, t) = (1 - s)(1 - t) d0 + s (1 - t) d1 + s t d2 + (1 - s) t d3
// over the element's fractions s and t, 0 at corner k (d[k] = 0). About that
// corner it is a u + b v + c u v: a and b its slopes along s and t there
// over the element's width and height, c its twist over their product. The
// four corners' twelve divisions in vector lanes, three a corner, without a
// test for a corner without lifts: its d are +0 (lifts are +0 or above), and
// the differences and quotients of +0 are the +0 terms it needs.
SWARF_TARGET_CLONES
void LiftTerms(ElementCorners* e) {
  const double (&d)[4][4] = e->guard.lift;
  const double lx = e->x1 - e->x0, ly = e->y1 - e->y0;
  const double lxy = lx * ly;
  // Corner k's neighbours along s and t: right = k is 1 or 2, top = k >= 2.
  const double a[4] = {d[0][1] - d[0][0], d[1][1] - d[1][0], d[2][2] - d[2][3],
                       d[3][2] - d[3][3]};
  const double b[4] = {d[0][3] - d[0][0], d[1][2] - d[1][1], d[2][2] - d[2][1],
                       d[3][3] - d[3][0]};
  double c[4];
  for (int k = 0; k < 4; ++k) c[k] = d[k][0] - d[k][1] + d[k][2] - d[k][3];
  double qa[4], qb[4], qc[4];
#pragma omp simd
  for (int k = 0; k < 4; ++k) {
    qa[k] = a[k] / lx;
    qb[k] = b[k] / ly;
    qc[k] = c[k] / lxy;
  }
  for (int k = 0; k < 4; ++k) {
    double* l = e->guard.lift_uv[k];
    l[0] = qa[k];
    l[1] = qb[k];
    l[2] = qc[k];
  }
}

}  // namespace

void ClassifyGuarded(ElementCorners* e, const PatchTrustRegion* const trust[4],
                     const bool* sure) {
  const CornerXY c = CornersOf(*e);
  ElementCorners::Guard& g = e->guard;
  const double hx = e->x1 - e->x0, hy = e->y1 - e->y0;
  const double tau = kGuardConsistency * std::max(hx, hy);
  // Whether corner k's reach holds corner q: for the lifts and for the
  // whole element, tested once, and once for corners with one reach
  // (neighbouring nodes mostly share an owner, and with it the reach: one
  // owner is one reach without comparing the capsules, a tenth of this).
  double holds[4][4];
  for (int k = 0; k < 4; ++k) {
    int same = k;
    for (int p = 0; p < k && same == k; ++p) {
      if (e->owner[p] == e->owner[k] ||
          SameReach(e->reach[p], e->reach[k])) {
        same = p;
      }
    }
    // A capsule is convex: holding the element's corners, it holds it all.
    if (same != k) {
      for (int q = 0; q < 4; ++q) holds[k][q] = holds[same][q];
      g.inside[k] = g.inside[same];
    } else {
      g.inside[k] = ReachHolds(e->reach[k], c, holds[k]);
    }
  }
  double shortfall[4][4];
  CornerResiduals(*e, c, shortfall);
  // Every lift and the consistency test at once (a node outside the
  // owner's reach says nothing of its surface): whether the element is
  // smooth does not depend on the order of its tests, so the trust regions
  // are read only where the rest holds.
  const bool disagrees = CornerLifts(shortfall, holds, tau, g.lift);
  bool smooth = !disagrees && e->owner[0] >= 0 && e->owner[1] >= 0 &&
                e->owner[2] >= 0 && e->owner[3] >= 0;
  LiftTerms(e);
  // The trust region is convex: trusted at the other corners, the patch is
  // trusted over the whole element. Read in place (not copied), and
  // computed only where not given. Most regions hold the whole element:
  // one test for the three corners (a test the caller may have taken for
  // the node).
  PatchTrustRegion computed;
  for (int k = 0; k < 4 && smooth; ++k) {
    const PatchTrustRegion* region;
    if (trust != nullptr) {
      region = trust[k];
    } else {
      computed = TrustRegion(e->c[k]);
      region = &computed;
    }
    if (trust != nullptr && sure != nullptr
            ? sure[k]
            : SurelyTrustedAt(*region, hx, hy)) {
      continue;
    }
    for (int q = 0; q < 4; ++q) {
      if (q == k) continue;
      const double dx = c.x[q] - c.x[k], dy = c.y[q] - c.y[k];
      if (TrustAt(*region, dx, dy) != PatchTrust::kFull) smooth = false;
    }
  }
  g.smooth = smooth;
}

void PrepareGuarded(ElementCorners* e, const PatchTrustRegion* const trust[4],
                    const bool* sure) {
  ClassifyGuarded(e, trust, sure);
  // Elsewhere the exact surface: every move that can be the lowest in the
  // element (an uncut one too: a cut may pass between its nodes).
  if (GuardedIsExact(*e)) e->surfaces->FillCandidates(e);
}

void SetElementFrame(const GridGeometry& grid, double z_top, int32_t ei,
                     int32_t ej, ElementCorners* e) {
  e->ei = ei;
  e->ej = ej;
  e->x0 = grid.NodeX(ei);
  e->x1 = grid.NodeX(ei + 1);
  e->y0 = grid.NodeY(ej);
  e->y1 = grid.NodeY(ej + 1);
  e->z_top = z_top;
}

double MinOfPatches(const ElementCorners& e, double x, double y) {
  const CornerXY c = CornersOf(e);
  double w = e.z_top;
  for (int k = 0; k < 4; ++k) {
    w = std::min(w, EvaluatePatch(e.c[k], c.x[k], c.y[k], x, y));
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
    const CornerXY c = CornersOf(e);
    double w = e.z_top;
    *gx = *gy = 0;  // the stock top
    for (int k = 0; k < 4; ++k) {
      const double wk = EvaluatePatch(e.c[k], c.x[k], c.y[k], x, y);
      if (wk < w) {
        w = wk;
        PatchGradient(e.c[k], c.x[k], c.y[k], x, y, gx, gy);
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
  void Prepare(ElementCorners* e) const override { PrepareGuarded(e); }
  double Reconstruct(const ElementCorners& e, double x,
                     double y) const override {
    return GuardedHeight(e, x, y);
  }
  void ReconstructMany(const ElementCorners& e, const double* x,
                       const double* y, int32_t n,
                       double* out) const override {
    Many(e, x, y, n, /*padded=*/false, out);
  }
  void ReconstructManyPadded(const ElementCorners& e, const double* x,
                             const double* y, int32_t n,
                             double* out) const override {
    Many(e, x, y, n, /*padded=*/true, out);
  }
  void Gradient(const ElementCorners& e, double x, double y, double* gx,
                double* gy) const override {
    HeightAndGradient(e, x, y, gx, gy);
  }
  double HeightAndGradient(const ElementCorners& e, double x, double y,
                           double* gx, double* gy) const override {
    const GuardedValue v = Guarded(e, x, y);
    *gx = *gy = 0;  // the top, or a patch held at its owner's lowest point
    if (v.corner == kBilinear) {
      BilinearGradient(e, x, y, gx, gy);
    } else if (v.move >= 0) {
      const SurfaceJet j = e.surfaces->Jet(v.move, x, y);
      *gx = j.wx;
      *gy = j.wy;
    } else if (v.corner >= 0 && v.w > e.reach[v.corner].z_low) {
      const CornerXY c = CornersOf(e);
      const int k = v.corner;
      PatchGradient(LiftedJet(e, k), c.x[k], c.y[k], x, y, gx, gy);
    }
    return v.w;
  }

 private:
  // Both ReconstructMany forms: a smooth element's points a chunk at a
  // time (every chunk but the last a multiple of 8 points: a padded
  // array's padding is the last chunk's).
  static void Many(const ElementCorners& e, const double* x, const double* y,
                   int32_t n, bool padded, double* out) {
    if (!e.guard.smooth || e.surfaces == nullptr) {
      for (int32_t q = 0; q < n; ++q) out[q] = GuardedHeight(e, x[q], y[q]);
      return;
    }
    for (int32_t q0 = 0; q0 < n; q0 += kGuardedChunk) {
      SmoothChunk(e, x + q0, y + q0, std::min(kGuardedChunk, n - q0), padded,
                  out + q0);
    }
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
    const int32_t lowest = LowestCandidate(e, x, y).id;
    if (lowest < 0) return;
    const SurfaceJet j = e.surfaces->Jet(lowest, x, y);
    *gx = j.wx;
    *gy = j.wy;
  }
};

}  // namespace

double ExactCandidatesHeight(const ElementCorners& e, double x, double y) {
  if (e.surfaces == nullptr) return MinOfPatches(e, x, y);
  return LowestCandidate(e, x, y).w;
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
