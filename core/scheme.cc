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

// The bilinear interpolation of corner k's shortfalls, at the element's
// fractions (s, t).
double LiftAt(const ElementCorners& e, int k, double s, double t) {
  const double* d = e.guard.lift[k];
  return std::lerp(std::lerp(d[0], d[1], s), std::lerp(d[3], d[2], s), t);
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

GuardedValue Guarded(const ElementCorners& e, double x, double y) {
  const CornerXY c = CornersOf(e);
  GuardedValue v;
  v.w = e.z_top;
  if (e.guard.smooth || e.surfaces == nullptr) {
    const double s = (x - e.x0) / (e.x1 - e.x0);
    const double t = (y - e.y0) / (e.y1 - e.y0);
    bool any = false;
    for (int k = 0; k < 4; ++k) {
      if (!e.reach[k].Contains(x, y)) continue;
      any = true;
      const double p = std::max(
          EvaluatePatch(e.c[k], c.x[k], c.y[k], x, y) + LiftAt(e, k, s, t),
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
    for (int k = 0; k < 4; ++k) {
      hidden |= !e.reach[k].Contains(x, y) && e.c[k].w < v.w;
    }
    if (hidden) TakeLowest(e, x, y, &v);
    return v;
  }
  // The exact surfaces of the corners' owners and of the moves continuing
  // them.
  double h[4];
  for (int k = 0; k < 4; ++k) {
    h[k] = kInfinity;
    if (e.owner[k] < 0) continue;
    for (int q = 0; q < e.reach[k].count; ++q) {
      const int32_t id = e.reach[k].id[q];
      const double hk = e.surfaces->Height(id, x, y);
      h[k] = std::min(h[k], hk);
      if (hk < v.w) {
        v.w = hk;
        v.move = id;
      }
    }
  }
  // An uncut element may still hold a cut between its nodes: its
  // candidates (PrepareGuarded).
  for (const int32_t id : e.candidates) {
    const double hk = e.surfaces->Height(id, x, y);
    if (hk < v.w) {
      v.w = hk;
      v.move = id;
    }
  }
  bool hidden = false;
  for (int k = 0; k < 4; ++k) {
    hidden |= e.owner[k] >= 0 && h[k] > v.w && e.c[k].w < v.w;
  }
  if (hidden) TakeLowest(e, x, y, &v);
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

PatchTrust Trust(const PatchTrustRegion& r, double dx, double dy) {
  if (r.everywhere) return PatchTrust::kFull;
  if (dx * dx + dy * dy > r.reach * r.reach) return PatchTrust::kNone;
  if (r.s > 0 && (dx * r.gx + dy * r.gy) / r.s > kPatchUphill * r.delta) {
    return PatchTrust::kLowerBound;  // uphill, towards the rim
  }
  const double along = (dx * r.ex + dy * r.ey) * (r.se < 0 ? -1 : 1);
  if (r.se != 0 && along > kPatchUphill * r.de) return PatchTrust::kLowerBound;
  return PatchTrust::kFull;
}

PatchTrust TrustPatch(const SurfaceJet& j, double dx, double dy) {
  return Trust(TrustRegion(j), dx, dy);
}

double GuardedHeight(const ElementCorners& e, double x, double y) {
  return Guarded(e, x, y).w;
}

void PrepareGuarded(ElementCorners* e) {
  const CornerXY c = CornersOf(*e);
  e->guard = {};
  const double tau = kGuardConsistency * std::max(e->x1 - e->x0, e->y1 - e->y0);
  bool smooth = true;
  for (int k = 0; k < 4; ++k) smooth &= e->owner[k] >= 0;
  for (int k = 0; k < 4; ++k) {
    // The trust region is convex: trusted at the other corners, the patch
    // is trusted over the whole element.
    const PatchTrustRegion trust =
        smooth ? TrustRegion(e->c[k]) : PatchTrustRegion{};
    for (int q = 0; q < 4; ++q) {
      if (q == k) continue;
      const double dx = c.x[q] - c.x[k], dy = c.y[q] - c.y[k];
      if (smooth && Trust(trust, dx, dy) != PatchTrust::kFull) {
        smooth = false;
      }
      // A node outside the owner's reach says nothing of its surface.
      if (!e->reach[k].Contains(c.x[q], c.y[q])) continue;
      const double r =
          e->c[q].w - EvaluatePatch(e->c[k], c.x[k], c.y[k], c.x[q], c.y[q]);
      if (r > 0) e->guard.lift[k][q] = r;
      if (r > tau) smooth = false;
    }
  }
  e->guard.smooth = smooth;
  // An uncut element: the moves that may cut it between its nodes.
  if (e->surfaces != nullptr && e->owner[0] < 0 && e->owner[1] < 0 &&
      e->owner[2] < 0 && e->owner[3] < 0) {
    e->surfaces->FillCandidates(e);
  }
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
      PatchGradient(e.c[k], c.x[k], c.y[k], x, y, gx, gy);
      // The lift's: bilinear in (s, t).
      const double lx = e.x1 - e.x0, ly = e.y1 - e.y0;
      const double s = (x - e.x0) / lx, t = (y - e.y0) / ly;
      const double* d = e.guard.lift[k];
      *gx += ((1 - t) * (d[1] - d[0]) + t * (d[2] - d[3])) / lx;
      *gy += ((1 - s) * (d[3] - d[0]) + s * (d[2] - d[1])) / ly;
    }
    return v.w;
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
