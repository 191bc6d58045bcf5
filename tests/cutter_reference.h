// Independent reference values for the cutter-shape tests: the lower
// surface swept by ANY cutter along a straight move, computed by brute force
// straight from its definition, in long double, and its derivatives by
// finite differences (tests only: the sweeps themselves must never use
// them). Shares no code with core/cutter/ beyond the Cutter description:
// the profiles below are written out by hand from each shape's geometry.
//
// Definition: a cutter whose tip is at T has the solid
// {(x, y, z) : rho <= R, z >= T.z + P(rho)}, rho the horizontal distance to
// its axis, P its profile (the height of its lower surface above the tip,
// nondecreasing and convex in rho). Along a move the tip is
// T(t) = from + t (to - from), t in [0, 1], so the lowest point of the swept
// solid above (x, y) is
//   w(x, y) = min { g(t) = T(t).z + P(rho(t)) : t in [0, 1], rho(t) <= R },
// +inf when no t qualifies. rho(t) is convex in t (the norm of an affine
// function) and P is convex and nondecreasing, so g is convex on the
// interval where rho(t) <= R: dense sampling picks the bracket and golden
// section refines it.
#ifndef SWARF_TESTS_CUTTER_REFERENCE_H_
#define SWARF_TESTS_CUTTER_REFERENCE_H_

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <string>

#include "core/cutter/cutter.h"
#include "core/geometry.h"
#include "core/surface_jet.h"
#include "tests/sweep_reference.h"

namespace swarf::testing {

inline constexpr LD kLdInf = std::numeric_limits<LD>::infinity();

inline LD Radians(double deg) { return LD{deg} * std::numbers::pi_v<LD> / 180; }

// A cross-section of the cutter's lower surface: height f above the tip at
// horizontal distance rho from the axis, with f' and f'' (d/d rho).
struct Section {
  LD f = 0, f1 = 0, f2 = 0;
};

// Lower quarter-circle of radius r whose centre is r above the tip and `at`
// out from the axis, at distance rho: f = r - sqrt(r^2 - u^2), u = rho - at;
// f' = u / sqrt(r^2 - u^2), f'' = r^2 / (r^2 - u^2)^(3/2).
inline Section ArcSection(LD r, LD at, LD rho) {
  const LD u = rho - at;
  const LD q = std::sqrt(std::max(LD{0}, r * r - u * u));
  return {r - q, u / q, r * r / (q * q * q)};
}

// The profile of `c` written out by hand from its geometry (0 <= rho <= R;
// clamped there). At the joins the section of the outer piece is returned.
//   ball         quarter circle of radius R centred on the axis
//   flat         0
//   bull-nose    0 up to R - rc, then the torus corner: a quarter circle of
//                radius rc centred at (R - rc, rc)
//   cone         0 up to the flat tip's radius, then the flank at the half
//                angle: (rho - tip) cot a
//   tapered ball the ball tip (radius rb, centre rb above the tip) up to
//                where its normal is perpendicular to the flank, i.e. at
//                angle a below the horizontal: (rb cos a, rb - rb sin a);
//                from there the flank tangent to it
// The angle's sine and cosine are taken once (the brute force evaluates
// the profile millions of times).
class HandProfile {
 public:
  explicit HandProfile(const Cutter& c)
      : c_(c),
        sin_(std::sin(Radians(c.half_angle_deg))),
        cos_(std::cos(Radians(c.half_angle_deg))) {}

  Section At(LD rho) const {
    const LD r = c_.radius;
    rho = std::clamp(rho, LD{0}, r);
    switch (c_.kind) {
      case CutterKind::kBall:
        return ArcSection(r, 0, rho);
      case CutterKind::kFlat:
        return {};
      case CutterKind::kBullNose: {
        const LD rc = c_.corner_radius;
        if (rho <= r - rc) return {};
        return ArcSection(rc, r - rc, rho);
      }
      case CutterKind::kCone:
        if (rho <= c_.tip_radius) return {};
        return Flank(c_.tip_radius, 0, rho);
      case CutterKind::kTaperedBall: {
        const LD rb = c_.tip_radius;
        const LD rho_t = rb * cos_;
        if (rho <= rho_t) return ArcSection(rb, 0, rho);
        return Flank(rho_t, rb - rb * sin_, rho);
      }
    }
    return {};
  }

 private:
  // A straight flank through (rho0, h0) at the half angle from the axis:
  // it rises by cot a per mm.
  Section Flank(LD rho0, LD h0, LD rho) const {
    const LD cot = cos_ / sin_;
    return {h0 + (rho - rho0) * cot, cot, 0};
  }

  Cutter c_;
  LD sin_, cos_;
};

inline Section ReferenceSection(const Cutter& c, LD rho) {
  return HandProfile(c).At(rho);
}

inline LD ReferenceProfile(const Cutter& c, LD rho) {
  return ReferenceSection(c, rho).f;
}

// The radii where the profile changes formula (creases or curvature jumps
// of every swept surface lie where the touching point crosses them), or
// -1 where there is none.
inline LD ProfileJoin(const Cutter& c) {
  switch (c.kind) {
    case CutterKind::kBullNose:
      return LD{c.radius} - c.corner_radius;
    case CutterKind::kCone:
      return c.tip_radius;
    case CutterKind::kTaperedBall:
      return LD{c.tip_radius} * std::cos(Radians(c.half_angle_deg));
    default:
      return -1;
  }
}

struct CutterReference {
  LD w = kLdInf;  // lowest height of the swept solid at (x, y)
  LD t = 0;       // where along the move the tool touching it is
  LD rho = 0;     // the touching point's distance from that tool's axis
};

// Brute-force swept height at (x, y) of cutter `c` whose tip moves from
// tip_from to tip_to (see the definition at the top): g minimized over the
// t-interval whose tool covers (x, y) by ConvexArgMin, `samples` positions
// then 90 golden-section steps (the bracket shrinks below 1e-19 in t); the
// interval's ends are candidates too (a flat end's minimum lies there).
inline CutterReference ReferenceHeight(const Cutter& c, const Vec3& tip_from,
                                       const Vec3& tip_to, double x, double y,
                                       int samples = 32) {
  const LD r = c.radius;
  const LD ax = tip_from.x, ay = tip_from.y, az = tip_from.z;
  const LD ex = LD{tip_to.x} - ax, ey = LD{tip_to.y} - ay,
           ez = LD{tip_to.z} - az;
  LD lo, hi;
  if (!CoveringInterval(ax, ay, ex, ey, r, x, y, &lo, &hi)) return {};
  auto rho_at = [&](LD t) { return std::hypot(ax + t * ex - x, ay + t * ey - y); };
  const HandProfile profile(c);
  auto g = [&](LD t) { return az + t * ez + profile.At(rho_at(t)).f; };
  CutterReference best;
  best.t = ConvexArgMin(g, lo, hi, samples, 90);
  best.w = g(best.t);
  best.rho = std::min(rho_at(best.t), r);
  return best;
}

// Height, gradient and Hessian of the reference surface at (x, y).
struct ReferenceJet {
  LD w = kLdInf, wx = 0, wy = 0, wxx = 0, wxy = 0, wyy = 0;
  // False where the finite differences cannot be trusted: a crease, a
  // curvature jump or a wall within the stencil (two step sizes disagree,
  // or a stencil point is off the swept surface).
  bool smooth = false;
};

// Finite differences of ReferenceHeight with Richardson extrapolation
// (O(h^4)), at step h and at step h/2; the two must agree to `agree`
// relative (to |value| + unit, unit 1 for slopes and 1/R for curvatures)
// for the point to count as smooth. The stencil spans 2h each way.
// Long double heights carry ~1e-18 mm of noise, so at h = 1e-3 mm the
// second differences are good to ~1e-10 /mm.
inline ReferenceJet ReferenceDerivatives(const Cutter& c, const Vec3& from,
                                         const Vec3& to, double x, double y,
                                         double h = 1e-3,
                                         double agree = 1e-8) {
  ReferenceJet j;
  auto f = [&](double i, double k) {
    return ReferenceHeight(c, from, to, x + i * h, y + k * h).w;
  };
  const LD f0 = f(0, 0);
  j.w = f0;
  if (!std::isfinite(f0)) return j;
  // Steps a in {h/2, h, 2h}, as multiples of h.
  constexpr double kSteps[3] = {0.5, 1, 2};
  LD dx[3], dy[3], dxx[3], dyy[3], dxy[3];
  bool finite = true;
  for (int s = 0; s < 3; ++s) {
    const double m = kSteps[s];
    const LD a = LD{m} * h;
    const LD xp = f(m, 0), xm = f(-m, 0), yp = f(0, m), ym = f(0, -m);
    const LD pp = f(m, m), pm = f(m, -m), mp = f(-m, m), mm = f(-m, -m);
    for (LD v : {xp, xm, yp, ym, pp, pm, mp, mm}) finite &= std::isfinite(v);
    dx[s] = (xp - xm) / (2 * a);
    dy[s] = (yp - ym) / (2 * a);
    dxx[s] = (xp - 2 * f0 + xm) / (a * a);
    dyy[s] = (yp - 2 * f0 + ym) / (a * a);
    dxy[s] = (pp - pm - mp + mm) / (4 * a * a);
  }
  if (!finite) return j;
  // Richardson: (4 D(a) - D(2a)) / 3 cancels the a^2 term.
  auto rich = [](const LD d[3], int s) { return (4 * d[s] - d[s + 1]) / 3; };
  bool smooth = true;
  auto pick = [&](const LD d[3], LD unit) {
    const LD fine = rich(d, 0), coarse = rich(d, 1);
    smooth &= std::fabs(fine - coarse) <= agree * (std::fabs(fine) + unit);
    return fine;
  };
  const LD curvature_unit = 1 / LD{c.radius};
  j.wx = pick(dx, 1);
  j.wy = pick(dy, 1);
  j.wxx = pick(dxx, curvature_unit);
  j.wyy = pick(dyy, curvature_unit);
  j.wxy = pick(dxy, curvature_unit);
  j.smooth = smooth;
  return j;
}

// Height and derivatives of a surface of revolution w = z + f(r) about the
// vertical axis through (cx, cy) (a plunge's crater), from the section:
// grad w = f' u, Hess w = f'' u u^T + (f' / r) (I - u u^T), u = (p - c) / r.
inline ReferenceJet RevolutionJet(const Section& s, LD z, LD dx, LD dy) {
  const LD r = std::hypot(dx, dy);
  const LD ux = dx / r, uy = dy / r, k = s.f1 / r;
  ReferenceJet j;
  j.w = z + s.f;
  j.wx = s.f1 * ux;
  j.wy = s.f1 * uy;
  j.wxx = s.f2 * ux * ux + k * uy * uy;
  j.wxy = (s.f2 - k) * ux * uy;
  j.wyy = s.f2 * uy * uy + k * ux * ux;
  j.smooth = true;
  return j;
}

// Height and derivatives of a straight groove w = z + f(|d|), d the signed
// distance from the line through the path with unit normal (nx, ny):
// grad w = f' sign(d) n, Hess w = f'' n n^T.
inline ReferenceJet GrooveJet(const Section& s, LD z, LD d, LD nx, LD ny) {
  const LD sg = d < 0 ? -1 : 1;
  ReferenceJet j;
  j.w = z + s.f;
  j.wx = s.f1 * sg * nx;
  j.wy = s.f1 * sg * ny;
  j.wxx = s.f2 * nx * nx;
  j.wxy = s.f2 * nx * ny;
  j.wyy = s.f2 * ny * ny;
  j.smooth = true;
  return j;
}

// Where pieces of a swept surface meet (a move's end plane, a profile's
// join circle, a wall) a height field has no derivative. A node there may
// take the jet of any surface meeting there, but its eq. (1) patch must
// not dig into the swept surface: CheckSeamJet accepts the jet `got` at
// (x, y) when either
// - it is a one-sided limit of the jets round it: each derivative lies
//   within the range of the jets `jet_at` gives at eight points eps away
//   (those on the surface), widened by rel * (|value| + unit) (unit 1 for
//   slopes, 1/radius for curvatures) and, for slopes, by the change over
//   eps the neighbours' curvatures allow. At a wall (a neighbour steeper
//   than kWallSlope) the derivatives are clamped (core/cutter/ball_sweep.h:
//   kRimDepthFraction) and the clamped values vary along the rim, so there
//   each derivative need only have the sign the neighbours agree on; or
// - its patch digs no deeper below the surface (`height_at`), at distance
//   r = 1e-4 and 1e-3 mm in sixteen directions, than a kink allows: the
//   largest gap S between its gradient and a neighbour's, times r, plus
//   (off walls) the neighbours' largest second derivative C times r^2, plus
//   1e-6 mm. A jet that is no limit (a triple point, a piece that sets the
//   height only along a curve, a sharp cone's apex, where no finite jet
//   avoids digging) is harmless if its patch leaves the surface no faster
//   than the surfaces meeting there leave each other; a wrong sign or a
//   runaway curvature digs metres.
// The neighbours are off the axis directions, so that they do not lie on
// the same axis-aligned seam as (x, y). w is not checked (at a wall it is
// not Lipschitz; heights are checked against the reference). Returns ""
// when the jet is accepted, else why not.
inline constexpr double kWallSlope = 100;

inline std::string CheckSeamJet(
    const std::function<SurfaceJet(double, double)>& jet_at,
    const std::function<double(double, double)>& height_at, double x,
    double y, const SurfaceJet& got, double radius, double eps = 1e-9,
    double rel = 1e-6) {
  double lo[6], hi[6];
  std::fill(lo, lo + 6, std::numeric_limits<double>::infinity());
  std::fill(hi, hi + 6, -std::numeric_limits<double>::infinity());
  double max_curv = 0, max_slope = 0;
  int on_surface = 0;
  for (int k = 0; k < 8; ++k) {
    const double a = (k + 0.5) * std::numbers::pi / 4;
    const SurfaceJet n = jet_at(x + eps * std::cos(a), y + eps * std::sin(a));
    if (!std::isfinite(n.w)) continue;
    ++on_surface;
    const double v[6] = {n.w, n.wx, n.wy, n.wxx, n.wxy, n.wyy};
    for (int c = 0; c < 6; ++c) {
      lo[c] = std::min(lo[c], v[c]);
      hi[c] = std::max(hi[c], v[c]);
    }
    max_slope = std::max({max_slope, std::fabs(n.wx), std::fabs(n.wy)});
    max_curv = std::max(
        {max_curv, std::fabs(n.wxx), std::fabs(n.wxy), std::fabs(n.wyy)});
  }
  if (on_surface == 0) return "";  // on the footprint's very edge
  const double v[6] = {got.w, got.wx, got.wy, got.wxx, got.wxy, got.wyy};
  const char* names[6] = {"w", "wx", "wy", "wxx", "wxy", "wyy"};
  std::string why;
  for (int c = 1; c < 6; ++c) {
    const double unit = c < 3 ? 1 : 1 / radius;
    double slack = rel * (std::fabs(v[c]) + unit);
    if (c < 3) slack += 2 * eps * max_curv;
    const bool ok =
        max_slope > kWallSlope
            ? !(lo[c] > 0 && !(v[c] > 0)) && !(hi[c] < 0 && !(v[c] < 0))
            : v[c] >= lo[c] - slack && v[c] <= hi[c] + slack;
    if (!ok) {
      why += std::string(names[c]) + " = " + std::to_string(v[c]) +
             " outside [" + std::to_string(lo[c]) + ", " +
             std::to_string(hi[c]) + "] ";
    }
  }
  if (why.empty()) return "";
  // Not a limit: harmless only if the patch digs no faster than a kink.
  double gap = 0;  // S
  for (int k = 0; k < 8; ++k) {
    const double a = (k + 0.5) * std::numbers::pi / 4;
    const SurfaceJet n = jet_at(x + eps * std::cos(a), y + eps * std::sin(a));
    if (std::isfinite(n.w)) gap = std::max(gap, std::hypot(n.wx - got.wx, n.wy - got.wy));
  }
  const bool wall = max_slope > kWallSlope;
  double dig = 0, allowed = 0;
  for (double r : {1e-4, 1e-3}) {
    const double allow = 1e-6 + gap * r + (wall ? 0 : max_curv * r * r);
    for (int k = 0; k < 16; ++k) {
      const double a = (k + 0.5) * std::numbers::pi / 8;
      const double qx = x + r * std::cos(a), qy = y + r * std::sin(a);
      const double h = height_at(qx, qy);
      if (!std::isfinite(h)) continue;
      const double d = h - EvaluatePatch(got, x, y, qx, qy);
      if (d - allow > dig - allowed) {
        dig = d;
        allowed = allow;
      }
    }
  }
  if (dig <= allowed) return "";
  return why + "and its patch digs " + std::to_string(dig) + " mm (a kink allows " +
         std::to_string(allowed) + ")";
}

}  // namespace swarf::testing

#endif  // SWARF_TESTS_CUTTER_REFERENCE_H_
