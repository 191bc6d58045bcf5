#include "core/cutter/profile_sweep.h"

#include <algorithm>
#include <cmath>

#include "core/cutter/ball_sweep.h"  // kRimDepthFraction, ClampedJet

namespace swarf {
namespace {

// As the ball sweep: moves with less horizontal travel than this fraction of
// their length are vertical (the lowest tool is the whole envelope).
constexpr double kVerticalFraction = 1e-12;

// sqrt(a^2 - b^2) without the cancellation of a * a - b * b (a, b >= 0);
// 0 when b >= a.
double Leg(double a, double b) {
  return std::sqrt(std::max(0.0, (a - b) * (a + b)));
}

// A candidate replaces the best only when strictly lower, so on exact ties
// the earlier kind wins (envelopes, then move ends, then kink circles, of
// a circle's two crossings the one the ramp descends to).
void Take(ProfilePoint* best, ProfilePoint::Contact contact, int32_t index,
          double w, double p0, double p1, double p2) {
  if (w < best->w) {
    best->contact = contact;
    best->index = index;
    best->w = w;
    best->p0 = p0;
    best->p1 = p1;
    best->p2 = p2;
  }
}

// The torus envelope on a ramp (slope m != 0): the contact on the torus of
// centre circle rho_c and radius rc that sets the swept height at distance
// |n| across the move's line. With psi the contact's angle above the
// torus' equator (its normal makes pi/2 - psi with the vertical), the
// envelope condition g'(s) = m + f'(rho) u / rho = 0 with f' = cot(psi)
// gives u / rho = -m tan(psi) (u: along the move, from (x, y)'s foot to
// the axis), and the distance across is then
//   F(t) = (rho_c + rc cos(psi)) sqrt(1 - m^2 t^2) - |n| = 0,  t = tan(psi)
// over t in [0, 1 / |m|]: F decreases from R - |n| >= 0 to -|n| <= 0, so
// the root is unique and bracketed. Bracketed (bisection-guarded) Newton;
// returns t. No closed form: this is a quartic in cos(psi).
double TorusContact(double rho_c, double rc, double abs_m, double abs_n) {
  double lo = 0, hi = 1 / abs_m;
  if (abs_n == 0) return hi;  // contact in the move's vertical plane
  auto f = [&](double t, double* df) {
    const double c = 1 / std::sqrt(1 + t * t);  // cos(psi)
    const double mt = abs_m * t;
    const double s = std::sqrt(std::max(0.0, (1 - mt) * (1 + mt)));
    const double rho = rho_c + rc * c;
    // dF/dt: d cos(psi)/dt = -t c^3; d s/dt = -m^2 t / s.
    *df = -rc * t * c * c * c * s - (s > 0 ? rho * abs_m * mt / s : kInf);
    return rho * s - abs_n;
  };
  // Bounds on the root: rho(t) >= max(|n|, rho_c) (rho decreases in t,
  // and S <= 1) bounds t above by the horizontal move's contact, and
  // S(t) = |n| / rho(t) <= |n| / max(|n|, rho_c) bounds it below. Start
  // from the upper one (exact as m -> 0) where it is finite.
  const double e = abs_n - rho_c;
  const double rho_min = std::max(abs_n, rho_c);
  lo = std::max(lo, Leg(rho_min, abs_n) / (rho_min * abs_m));
  if (e > 0) hi = std::min(hi, Leg(rc, e) / e);
  if (!(lo < hi)) return hi;  // the bounds met: t is known to rounding
  double t = e > 0 && hi < 1 / abs_m ? hi : lo;
  for (int iter = 0; iter < 100; ++iter) {
    double df;
    const double v = f(t, &df);
    if (v == 0) break;
    if (v > 0) {
      lo = t;
    } else {
      hi = t;
    }
    double next = t - v / df;
    const bool newton = next > lo && next < hi;
    if (!newton) next = 0.5 * (lo + hi);
    // Newton converges quadratically: after a step below 1e-6 of t, t is
    // within about 1e-12 of the root (the caller evaluates g at the
    // resulting s, so the height is off by the square of that).
    if (std::fabs(next - t) <= (newton ? 1e-6 : 2.3e-16) * std::max(t, next)) {
      t = next;
      break;
    }
    t = next;
  }
  return t;
}

}  // namespace

double ProfilePiece::Height(double rho) const {
  switch (kind) {
    case kFlat:
      return h0;
    case kLine:
      return h0 + (rho - rho0) * k;
    case kSphere:
    case kTorus:
      return hc - Leg(rc, rho - rho_c);
  }
  return h0;
}

double ProfilePiece::Slope(double rho) const {
  switch (kind) {
    case kFlat:
      return 0;
    case kLine:
      return k;
    case kSphere:
    case kTorus: {
      const double e = rho - rho_c, d = Leg(rc, e);
      return d > 0 ? e / d : e > 0 ? kInf : 0;
    }
  }
  return 0;
}

ProfileSweep::ProfileSweep(const Vec3& tip_from, const Vec3& tip_to,
                           const Cutter& cutter, const Profile& profile)
    : cutter_(cutter), profile_(profile), from_(tip_from), to_(tip_to) {
  const double dx = to_.x - from_.x, dy = to_.y - from_.y;
  const double dz = to_.z - from_.z;
  const double dxy = std::hypot(dx, dy);
  const double len = std::hypot(dxy, dz);
  z_low_ = std::min(from_.z, to_.z);
  const Vec3& low = to_.z < from_.z ? to_ : from_;
  x_low_ = low.x;
  y_low_ = low.y;
  if (len == 0) {
    kind_ = kPoint;
    return;
  }
  if (dxy <= kVerticalFraction * len) {
    kind_ = kVertical;
    return;
  }
  kind_ = kGeneral;
  len_ = dxy;
  h1_ = dx / dxy;
  h2_ = dy / dxy;
  m_ = dz / dxy;
  g_ = dxy / len;
  k3_ = dz / len;
}

Capsule ProfileSweep::Footprint(double cap) const {
  return TipFootprint(from_, to_, cutter_, cap);
}

void ProfileSweep::Heights(const double* x, const double* y, int32_t n,
                           double* out) const {
  for (int32_t q = 0; q < n; ++q) out[q] = Locate(x[q], y[q]).w;
}

ProfilePoint ProfileSweep::Locate(double x, double y) const {
  const Profile& pf = profile_;
  const double r = pf.radius, r2 = r * r;
  ProfilePoint best;
  if (kind_ != kGeneral) {
    // Plunge, retract, or no move: the lowest tool is the envelope.
    const double vx = x - x_low_, vy = y - y_low_;
    const double rho2 = vx * vx + vy * vy;
    if (rho2 <= r2) {
      Take(&best, ProfilePoint::kTool, 0,
           z_low_ + pf.Height(std::sqrt(rho2)), vx, vy, 0);
    }
    return best;
  }
  const double px = x - from_.x, py = y - from_.y;
  const double a = h1_ * px + h2_ * py;  // along the move, from its start
  const double n = h1_ * py - h2_ * px;  // across it
  const double an = std::fabs(n);
  if (an > r) return best;  // the tool passes beside (x, y)
  const double z0 = from_.z, m = m_, am = std::fabs(m);
  auto inside = [&](double s) { return s >= 0 && s <= len_; };
  // One-sided slopes of g(s) = z0 + m s + f(rho(s)) at the ends, d rho/ds
  // = (s - a) / rho. An end the tool does not cover counts as falling
  // (start) or rising (end): the reach begins or ends at the vertical wall.
  auto slope_at = [&](double vx, double vy, double s_minus_a) {
    const double rho = std::sqrt(vx * vx + vy * vy);
    if (rho > r) return kInf;
    if (rho == 0) return m;  // on the axis: f'(0) = 0 for the torus' band
    return m + pf.Slope(rho) * s_minus_a / rho;
  };
  // Convexity: g rising from the start, or falling into the end, puts the
  // minimum at that end. At a piece boundary slope_at takes the inner
  // piece's f', which can only err towards not taking the shortcut (f' is
  // nondecreasing); a NaN (0 * inf at a rim) never takes it.
  const double rho_start2 = px * px + py * py;
  const double ex = x - to_.x, ey = y - to_.y;
  const double rho_end2 = ex * ex + ey * ey;
  if (rho_start2 <= r2 && slope_at(px, py, -a) >= 0) {
    Take(&best, ProfilePoint::kTool, 0, z0 + pf.Height(std::sqrt(rho_start2)),
         px, py, 0);
    return best;
  }
  if (rho_end2 <= r2 && slope_at(ex, ey, len_ - a) <= 0) {
    Take(&best, ProfilePoint::kTool, 1, to_.z + pf.Height(std::sqrt(rho_end2)),
         ex, ey, 0);
    return best;
  }
  auto falls_at = [&](double vx, double vy, double a_) {
    const double d = slope_at(vx, vy, -a_);
    return d == kInf || d < 0;
  };
  auto rises_at = [&](double x_, double y_, double a_) {
    const double d = slope_at(x_ - to_.x, y_ - to_.y, len_ - a_);
    return d == kInf || d > 0;
  };

  // 1. Stationary points of the smooth pieces (g'(s) = 0).
  for (int32_t i = 0; i < pf.pieces; ++i) {
    const ProfilePiece& pc = pf.piece[i];
    switch (pc.kind) {
      case ProfilePiece::kFlat:
        break;  // stationary only when m = 0, at its boundary's value
      case ProfilePiece::kLine: {
        // Eq. L (the wedge): g' = m + k u / rho = 0 gives
        // u = -m |n| / sqrt(k^2 - m^2), rho = k |n| / sqrt(k^2 - m^2),
        // for |m| < k (a flank steeper than the ramp).
        if (!(am < pc.k)) break;
        const double root = Leg(pc.k, am);
        const double u = -m * an / root;
        const double rho = pc.k * an / root;
        const double s = a + u;
        if (rho >= pc.rho0 && rho <= pc.rho1 && inside(s)) {
          Take(&best, ProfilePoint::kEnvelope, i,
               z0 + m * s + pc.h0 + (rho - pc.rho0) * pc.k, n, root, 0);
        }
        break;
      }
      case ProfilePiece::kSphere: {
        // The ball's cylinder (paper eq. 12-13 in the move's frame): with
        // root = sqrt(rc^2 - n^2), the contact is u = -k3 root and the
        // sphere's depth there g root.
        if (an > pc.rc) break;
        const double root = Leg(pc.rc, an);
        const double u = -k3_ * root;
        const double s = a + u;
        if (u * u + n * n <= pc.rho1 * pc.rho1 && inside(s)) {
          Take(&best, ProfilePoint::kEnvelope, i,
               z0 + m * s + pc.hc - g_ * root, n, root, 0);
        }
        break;
      }
      case ProfilePiece::kTorus: {
        if (an < pc.rho_c && m == 0) break;  // only the flat band there
        // g is convex: unless it falls at the move's start and rises at
        // its end, its minimum over the move is an end, and the solve
        // below can be skipped.
        if (m != 0 && !(falls_at(px, py, a) && rises_at(x, y, a))) break;
        double sin_psi, cos_psi, u;
        if (m == 0) {
          // Horizontal move: the contact is abeam (u = 0), on the torus'
          // circle through |n|.
          const double e = an - pc.rho_c;
          sin_psi = Leg(pc.rc, e) / pc.rc;
          cos_psi = e / pc.rc;
          u = 0;
        } else {
          const double t = TorusContact(pc.rho_c, pc.rc, am, an);
          cos_psi = 1 / std::sqrt(1 + t * t);
          sin_psi = t * cos_psi;
          u = -(pc.rho_c + pc.rc * cos_psi) * m * t;
        }
        const double s = a + u;
        if (inside(s)) {
          // g(s) itself, at the distance the contact's s really has: a
          // value of g (so never below the true minimum), within the
          // square of the solve's error of it.
          const double w =
              m == 0 ? z0 + pc.hc - pc.rc * sin_psi
                     : z0 + m * s + pc.Height(std::sqrt(u * u + n * n));
          Take(&best, ProfilePoint::kEnvelope, i, w, n, sin_psi, cos_psi);
          // On a ramp g falls at the start and rises at the end (checked
          // above), so its minimum is interior, where g' = 0: not on the
          // flat band (g' = m there) nor at the wall, so this contact is
          // the minimum and no other candidate can be lower. (A torus is
          // only ever a bull-nose's corner: a flat band inside, the wall
          // outside.)
          if (m != 0) return best;
        }
        break;
      }
    }
  }
  // 2. The tool at the move's ends.
  if (rho_start2 <= r2) {
    Take(&best, ProfilePoint::kTool, 0, z0 + pf.Height(std::sqrt(rho_start2)),
         px, py, 0);
  }
  if (rho_end2 <= r2) {
    Take(&best, ProfilePoint::kTool, 1, to_.z + pf.Height(std::sqrt(rho_end2)),
         ex, ey, 0);
  }
  // 3. Kink circles: where the distance crosses a piece boundary (the last
  // is the wall at R): s = a -+ sqrt(rho_k^2 - n^2). The crossing the ramp
  // descends to comes first: it is the lower one, so where the two meet
  // (the circle's side, half = 0, or a half lost to rounding) it wins the
  // tie and gives the jet of the surface inside, not its mirror image.
  const double first = m < 0 ? 1.0 : -1.0;
  auto kink = [&](int32_t index, double rho_k, double f_k) {
    if (an > rho_k) return;
    const double half = Leg(rho_k, an);
    for (double sigma : {first, -first}) {
      const double s = a + sigma * half;
      if (inside(s)) {
        Take(&best, ProfilePoint::kKink, index, z0 + m * s + f_k, n, half,
             sigma);
      }
    }
  };
  if (pf.piece[0].kind == ProfilePiece::kLine && pf.piece[0].rho0 == 0) {
    kink(-1, 0, pf.piece[0].h0);  // a sharp apex
  }
  for (int32_t i = 0; i < pf.pieces; ++i) {
    kink(i, pf.piece[i].rho1, pf.piece[i].Height(pf.piece[i].rho1));
  }
  // The crossing the ramp climbs from (sigma m > 0) is never the minimum: g
  // falls on from it (g' <= m < 0 just after it on a descending ramp). It
  // wins only where the other crossing lies past the move's end and the
  // end's tool, exactly no higher, was lost to rounding (rho_end^2 a hair
  // above R^2, or z0 + m L below to.z): the reach of (x, y) has shrunk to
  // that end, whose tool is the surface round it. Its height stays (the
  // same value of g to rounding); the jet is the end tool's.
  if (best.contact == ProfilePoint::kKink && best.p2 * m > 0) {
    const bool end = m < 0;
    best.contact = ProfilePoint::kTool;
    best.index = end ? 1 : 0;
    best.p0 = end ? ex : px;
    best.p1 = end ? ey : py;
    best.p2 = 0;
  }
  return best;
}

SurfaceJet ProfileSweep::ToolJet(double w, double vx, double vy) const {
  // The tool's surface of revolution z = f(rho): gradient f' v/rho, Hessian
  // f'' v v^T / rho^2 + (f' / rho) (I - v v^T / rho^2).
  const double rho = std::sqrt(vx * vx + vy * vy);
  const ProfilePiece& pc = profile_.piece[profile_.PieceAt(rho)];
  const double ux = rho > 0 ? vx / rho : 0, uy = rho > 0 ? vy / rho : 0;
  double f1 = 0, f2 = 0, f1_over_rho = 0;
  switch (pc.kind) {
    case ProfilePiece::kFlat:
      break;
    case ProfilePiece::kLine:
      // The cone's apex has no curvature: its distance clamped like a rim.
      f1 = pc.k;
      f1_over_rho =
          pc.k / std::max(rho, kRimDepthFraction * profile_.radius);
      break;
    case ProfilePiece::kSphere:
    case ProfilePiece::kTorus: {
      // Paper eq. (8)-(9) for the sphere; the torus likewise with e the
      // distance from its centre circle. Depth clamped as the ball's rim.
      const double e = rho - pc.rho_c;
      const double depth =
          std::max(Leg(pc.rc, e), kRimDepthFraction * pc.rc);
      f1 = e / depth;
      f2 = pc.rc * pc.rc / (depth * depth * depth);
      f1_over_rho = pc.rho_c == 0 ? 1 / depth : f1 / rho;
      break;
    }
  }
  SurfaceJet j;
  j.w = w;
  j.wx = f1 * ux;
  j.wy = f1 * uy;
  j.wxx = f2 * ux * ux + f1_over_rho * (1 - ux * ux);
  j.wxy = (f2 - f1_over_rho) * ux * uy;
  j.wyy = f2 * uy * uy + f1_over_rho * (1 - uy * uy);
  return ClampedJet(j);
}

SurfaceJet ProfileSweep::Jet(const ProfilePoint& p) const {
  SurfaceJet j;
  j.w = p.w;
  switch (p.contact) {
    case ProfilePoint::kNone:
      return j;
    case ProfilePoint::kTool:
      return ToolJet(p.w, p.p0, p.p1);
    case ProfilePoint::kEnvelope:
    case ProfilePoint::kKink:
      break;
  }
  // Envelopes and kink circles are translates along (h, m): w = m a + W(n),
  // so grad = m h + W' h_perp and Hessian = W'' h_perp h_perp^T.
  const double n = p.p0, m = m_, am = std::fabs(m);
  const double sign_n = n > 0 ? 1 : n < 0 ? -1 : 0;
  double w1 = 0, w2 = 0;  // W'(n), W''(n)
  if (p.contact == ProfilePoint::kKink) {
    // w = z0 + m (a + sigma S) + f(rho_k), S = sqrt(rho_k^2 - n^2):
    // W' = -m sigma n / S, W'' = -m sigma rho_k^2 / S^3. S is clamped at
    // the circle's sides, where the surface turns vertical.
    const double rho_k = p.index < 0 ? 0 : profile_.piece[p.index].rho1;
    const double half = std::max(p.p1, kRimDepthFraction * rho_k);
    if (half > 0) {
      w1 = -m * p.p2 * n / half;
      w2 = -m * p.p2 * rho_k * rho_k / (half * half * half);
    }
  } else {
    const ProfilePiece& pc = profile_.piece[p.index];
    switch (pc.kind) {
      case ProfilePiece::kFlat:
        break;
      case ProfilePiece::kLine:
        // Eq. L: W = |n| sqrt(k^2 - m^2) + const, a wedge of two planes.
        w1 = sign_n * p.p1;
        break;
      case ProfilePiece::kSphere: {
        // The ball's cylinder: W = -sqrt(rc^2 - n^2) / g, so
        // W' = n / (g root), W'' = rc^2 / (g root^3); root clamped.
        const double root = std::max(p.p1, kRimDepthFraction * pc.rc);
        w1 = n / (g_ * root);
        w2 = pc.rc * pc.rc / (g_ * root * root * root);
        break;
      }
      case ProfilePiece::kTorus: {
        // The torus envelope (TorusContact): by the envelope theorem the
        // slope across is that of the tool at the contact, projected:
        // W' = sign(n) sqrt(cot^2(psi) - m^2). Differentiating F(psi, |n|)
        // = 0 (implicit function theorem) gives
        //   W'' = cos^3 / (sin^3 [rc cos (cos^2 - m^2 sin^2) + rho m^2])
        // (psi's sin and cos, rho = rho_c + rc cos(psi)): 1 / (rc sin^3)
        // on a horizontal move. sin(psi) is clamped to kRimDepthFraction of
        // its largest value g = 1 / sqrt(1 + m^2) (the ball's rim clamp
        // when m = 0).
        double sn = p.p1, cs = p.p2;
        const double sn_min = kRimDepthFraction * g_;
        if (sn < sn_min) {
          sn = sn_min;
          cs = std::sqrt((1 - sn) * (1 + sn));
        }
        const double rho = pc.rho_c + pc.rc * cs;
        const double across = std::max(0.0, (cs - am * sn) * (cs + am * sn));
        w1 = sign_n * std::sqrt(across) / sn;
        // m = 0: cos(psi) may be 0 (the flat band's edge), where the
        // general form is 0 / 0; its limit is this one.
        w2 = m == 0 ? 1 / (pc.rc * sn * sn * sn)
                    : cs * cs * cs /
                          (sn * sn * sn * (pc.rc * cs * across + rho * m * m));
        break;
      }
    }
  }
  const double h1 = h1_, h2 = h2_;
  j.wx = m * h1 - w1 * h2;
  j.wy = m * h2 + w1 * h1;
  j.wxx = w2 * h2 * h2;
  j.wxy = -w2 * h1 * h2;
  j.wyy = w2 * h1 * h1;
  return ClampedJet(j);
}

}  // namespace swarf
