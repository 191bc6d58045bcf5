// The exact sweeps of the flat, bull-nose, cone and tapered-ball cutters
// (core/cutter/profile_sweep.h and the shape files): against a brute-force
// reference written here (the lowest point of the tool's lower surface over
// many positions along the move, refined by golden section on the convex
// height along the move), against analytic cross-sections, the degenerate
// shapes against the ball and the flat end, the chunked and jet paths
// against Height bit for bit, and the workpiece's nodes against the sweeps.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "core/cutter/ball_sweep.h"
#include "core/cutter/bull_nose_sweep.h"
#include "core/cutter/cone_sweep.h"
#include "core/cutter/cutter.h"
#include "core/cutter/flat_sweep.h"
#include "core/cutter/profile_sweep.h"
#include "core/cutter/sweep.h"
#include "core/cutter/tapered_ball_sweep.h"
#include "core/workpiece.h"
#include "gtest/gtest.h"
#include "tests/cutter_reference.h"

namespace swarf {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
constexpr double kDeg = 3.14159265358979323846 / 180;

struct Shape {
  const char* name;
  Cutter cutter;
};

// Every new shape, with its degenerate-ish variants (sharp and flat-tipped
// cones, a wide and a narrow bull-nose corner).
const Shape kShapes[] = {
    {"flat", Cutter::Flat(2)},
    {"bull", Cutter::BullNose(3, 1)},
    {"bull_small_corner", Cutter::BullNose(2, 0.25)},
    {"vbit90", Cutter::Cone(3, 45, 0)},
    {"vbit60_tip", Cutter::Cone(3, 30, 0.4)},
    {"taper10", Cutter::TaperedBall(3, 0.5, 10)},
    {"taper30", Cutter::TaperedBall(2, 1, 30)},
};

struct MoveCase {
  const char* name;
  Vec3 from, to;
};

const MoveCase kMoves[] = {
    {"horizontal", {1, 2, -1}, {9, 5, -1}},
    {"ramp_down", {1, 2, -1}, {9, 5, -2}},
    {"ramp_up", {9, 5, -2}, {1, 2, -0.5}},
    {"steep_ramp", {1, 2, -1}, {2, 2.6, -5}},
    {"near_vertical", {1, 2, 1}, {1.002, 2.001, -4}},
    {"plunge", {4, 4, 2}, {4, 4, -3}},
    {"retract", {4, 4, -3}, {4, 4, 2}},
    {"zero_length", {4, 4, -1}, {4, 4, -1}},
};

// ---------------------------------------------------------------------------
// The reference: min over t in [0, 1] of tip.z(t) + ProfileHeight(rho(t)),
// where rho(t) <= R. g(t) is convex: 512 samples over the feasible part of
// the move, then golden section around the best one, and the ends.

struct Reference {
  double w = kInfinity;
  double t = 0;
};

Reference ReferenceHeight(const Cutter& c, const Vec3& a, const Vec3& b,
                          double x, double y) {
  const double dx = b.x - a.x, dy = b.y - a.y, dz = b.z - a.z;
  const double qx = x - a.x, qy = y - a.y;
  const double r = c.radius;
  // Feasible t: |q - t d|^2 <= R^2.
  const double A = dx * dx + dy * dy, B = dx * qx + dy * qy;
  const double C = qx * qx + qy * qy - r * r;
  double lo = 0, hi = 1;
  if (A == 0) {
    if (C > 0) return {};
  } else {
    const double disc = B * B - A * C;
    if (disc < 0) return {};
    const double root = std::sqrt(disc);
    lo = std::max(0.0, (B - root) / A);
    hi = std::min(1.0, (B + root) / A);
    if (lo > hi) return {};
  }
  auto g = [&](double t) {
    const double ex = qx - t * dx, ey = qy - t * dy;
    return a.z + t * dz + ProfileHeight(c, std::sqrt(ex * ex + ey * ey));
  };
  Reference best{g(lo), lo};
  auto take = [&](double t) {
    const double v = g(t);
    if (v < best.w) best = {v, t};
  };
  take(hi);
  constexpr int kSamples = 512;
  int k_best = 0;
  double v_best = kInfinity;
  for (int k = 0; k <= kSamples; ++k) {
    const double t = lo + (hi - lo) * k / kSamples;
    const double v = g(t);
    if (v < v_best) {
      v_best = v;
      k_best = k;
    }
  }
  double u0 = lo + (hi - lo) * std::max(0, k_best - 1) / kSamples;
  double u1 = lo + (hi - lo) * std::min(kSamples, k_best + 1) / kSamples;
  const double phi = (std::sqrt(5.0) - 1) / 2;
  double m1 = u1 - phi * (u1 - u0), m2 = u0 + phi * (u1 - u0);
  double g1 = g(m1), g2 = g(m2);
  for (int it = 0; it < 200 && u1 - u0 > 0; ++it) {
    if (g1 <= g2) {
      u1 = m2;
      m2 = m1;
      g2 = g1;
      m1 = u1 - phi * (u1 - u0);
      g1 = g(m1);
    } else {
      u0 = m1;
      m1 = m2;
      g1 = g2;
      m2 = u0 + phi * (u1 - u0);
      g2 = g(m2);
    }
  }
  take(m1);
  take(m2);
  take(0.5 * (u0 + u1));
  return best;
}

std::unique_ptr<ProfileSweep> EngineFor(const Cutter& c, const Vec3& a,
                                        const Vec3& b) {
  switch (c.kind) {
    case CutterKind::kFlat:
      return std::make_unique<FlatSweep>(a, b, c.radius);
    case CutterKind::kBullNose:
      return std::make_unique<BullNoseSweep>(a, b, c.radius,
                                             c.corner_radius);
    case CutterKind::kCone:
      return std::make_unique<ConeSweep>(a, b, c.radius, c.half_angle_deg,
                                         c.tip_radius);
    case CutterKind::kTaperedBall:
      return std::make_unique<TaperedBallSweep>(a, b, c.radius, c.tip_radius,
                                                c.half_angle_deg);
    case CutterKind::kBall:
      break;
  }
  ADD_FAILURE() << "no profile sweep for the ball";
  return nullptr;
}

// Random points over the move's reach (and a little beyond), skipping those
// within 1e-7 mm of its edge, where rounding may decide reach.
std::vector<std::pair<double, double>> PointsNear(const Cutter& c,
                                                  const MoveCase& mc,
                                                  int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const double r = c.radius;
  std::uniform_real_distribution<double> ux(
      std::min(mc.from.x, mc.to.x) - r - 0.3,
      std::max(mc.from.x, mc.to.x) + r + 0.3);
  std::uniform_real_distribution<double> uy(
      std::min(mc.from.y, mc.to.y) - r - 0.3,
      std::max(mc.from.y, mc.to.y) + r + 0.3);
  std::vector<std::pair<double, double>> pts;
  while (static_cast<int>(pts.size()) < count) {
    const double x = ux(rng), y = uy(rng);
    // Distance to the XY segment.
    const double dx = mc.to.x - mc.from.x, dy = mc.to.y - mc.from.y;
    const double l2 = dx * dx + dy * dy;
    double t = l2 > 0 ? ((x - mc.from.x) * dx + (y - mc.from.y) * dy) / l2 : 0;
    t = std::clamp(t, 0.0, 1.0);
    const double d = std::hypot(x - mc.from.x - t * dx, y - mc.from.y - t * dy);
    if (std::fabs(d - r) < 1e-7) continue;
    pts.emplace_back(x, y);
  }
  return pts;
}

std::string CaseName(const Shape& s, const MoveCase& m) {
  return std::string(s.name) + "/" + m.name;
}

TEST(ProfileSweep, HeightMatchesBruteForce) {
  for (const Shape& shape : kShapes) {
    ASSERT_TRUE(ValidateCutter(shape.cutter, "t").ok()) << shape.name;
    for (const MoveCase& mc : kMoves) {
      SCOPED_TRACE(CaseName(shape, mc));
      const auto sweep = EngineFor(shape.cutter, mc.from, mc.to);
      int reached = 0;
      for (const auto& [x, y] : PointsNear(shape.cutter, mc, 300, 17)) {
        const double w = sweep->Height(x, y);
        const Reference ref = ReferenceHeight(shape.cutter, mc.from, mc.to,
                                              x, y);
        if (std::isinf(ref.w)) {
          EXPECT_TRUE(std::isinf(w)) << x << "," << y << " got " << w;
          continue;
        }
        ++reached;
        EXPECT_NEAR(w, ref.w, 1e-9) << x << "," << y;
        // Never below the lowest tip.
        EXPECT_GE(w, sweep->lowest());
      }
      EXPECT_GT(reached, 50);
    }
  }
}

// Random shapes and random moves (slopes from 0 to about 30, both
// directions, cones whose flank is near the ramp's slope).
TEST(ProfileSweep, RandomShapesAndMovesMatchBruteForce) {
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> unit(0, 1);
  for (int c = 0; c < 60; ++c) {
    const double r = 0.3 + 3 * unit(rng);
    Cutter cutter;
    switch (c % 4) {
      case 0:
        cutter = Cutter::Flat(r);
        break;
      case 1:
        cutter = Cutter::BullNose(r, r * (0.05 + 0.9 * unit(rng)));
        break;
      case 2:
        cutter = Cutter::Cone(r, 5 + 80 * unit(rng),
                              unit(rng) < 0.5 ? 0 : r * unit(rng));
        break;
      default:
        cutter = Cutter::TaperedBall(r, r * (0.05 + 0.9 * unit(rng)),
                                     1 + 40 * unit(rng));
        break;
    }
    ASSERT_TRUE(ValidateCutter(cutter, "t").ok()) << CutterToString(cutter);
    const double len = 5 * unit(rng) * unit(rng);
    const double dir = 6.3 * unit(rng);
    const double slope = unit(rng) < 0.3 ? 0 : std::tan(1.55 * unit(rng));
    const double dz = (unit(rng) < 0.5 ? -1 : 1) * slope * len;
    MoveCase mc{"random", {1, 2, -1}, {1 + len * std::cos(dir),
                                       2 + len * std::sin(dir), -1 + dz}};
    SCOPED_TRACE(CutterToString(cutter) + " to " + std::to_string(mc.to.x) +
                 "," + std::to_string(mc.to.y) + "," +
                 std::to_string(mc.to.z));
    const auto sweep = EngineFor(cutter, mc.from, mc.to);
    for (const auto& [x, y] : PointsNear(cutter, mc, 100, c)) {
      const double w = sweep->Height(x, y);
      const Reference ref = ReferenceHeight(cutter, mc.from, mc.to, x, y);
      if (std::isinf(ref.w)) {
        EXPECT_TRUE(std::isinf(w)) << x << "," << y;
        continue;
      }
      EXPECT_NEAR(w, ref.w, 1e-9) << x << "," << y;
    }
  }
}

// Derivatives of the reference by Richardson-extrapolated central
// differences (step h and h / 2; finite differences in tests only).
SurfaceJet ReferenceJet(const Cutter& c, const MoveCase& mc, double x,
                        double y, double h) {
  auto w = [&](double u, double v) {
    return ReferenceHeight(c, mc.from, mc.to, x + u, y + v).w;
  };
  const double w0 = w(0, 0);
  auto at = [&](double s, SurfaceJet* j) {
    const double xp = w(s, 0), xm = w(-s, 0), yp = w(0, s), ym = w(0, -s);
    j->wx = (xp - xm) / (2 * s);
    j->wy = (yp - ym) / (2 * s);
    j->wxx = (xp - 2 * w0 + xm) / (s * s);
    j->wyy = (yp - 2 * w0 + ym) / (s * s);
    j->wxy = (w(s, s) - w(s, -s) - w(-s, s) + w(-s, -s)) / (4 * s * s);
  };
  SurfaceJet a, b;
  at(h, &a);
  at(h / 2, &b);
  auto rich = [](double coarse, double fine) {
    return (4 * fine - coarse) / 3;
  };
  return {w0,
          rich(a.wx, b.wx),
          rich(a.wy, b.wy),
          rich(a.wxx, b.wxx),
          rich(a.wxy, b.wxy),
          rich(a.wyy, b.wyy)};
}

// Which smooth piece of the swept surface sets (x, y): the contact, its
// index, and for a tool contact its profile piece.
int PieceKey(const ProfileSweep& s, double x, double y) {
  const ProfilePoint p = s.Locate(x, y);
  int key = static_cast<int>(p.contact) * 100 + (p.index + 1) * 10;
  if (p.contact == ProfilePoint::kTool) {
    key += s.profile().PieceAt(std::hypot(p.p0, p.p1));
  }
  if (p.contact == ProfilePoint::kKink) key += p.p2 > 0 ? 1 : 0;
  return key;
}

double MaxAbs(const SurfaceJet& j) {
  return std::max({std::fabs(j.wx), std::fabs(j.wy), std::fabs(j.wxx),
                   std::fabs(j.wxy), std::fabs(j.wyy)});
}

TEST(ProfileSweep, DerivativesMatchFiniteDifferencesOfTheReference) {
  constexpr double kStep = 5e-4;
  for (const Shape& shape : kShapes) {
    for (const MoveCase& mc : kMoves) {
      SCOPED_TRACE(CaseName(shape, mc));
      const auto sweep = EngineFor(shape.cutter, mc.from, mc.to);
      int checked = 0;
      for (const auto& [x, y] : PointsNear(shape.cutter, mc, 150, 29)) {
        const SurfaceJet j = sweep->JetAt(x, y);
        if (std::isinf(j.w)) continue;
        // Away from creases, walls and apexes: the whole stencil on one
        // smooth piece, and moderate derivatives (no clamping near).
        const int key = PieceKey(*sweep, x, y);
        bool smooth = MaxAbs(j) < 20;
        for (double u : {-kStep, 0.0, kStep}) {
          for (double v : {-kStep, 0.0, kStep}) {
            smooth = smooth && PieceKey(*sweep, x + u, y + v) == key &&
                     MaxAbs(sweep->JetAt(x + u, y + v)) < 20;
          }
        }
        if (!smooth) continue;
        ++checked;
        const SurfaceJet fd = ReferenceJet(shape.cutter, mc, x, y, kStep);
        auto tol = [](double v) { return 1e-6 * std::max(1.0, std::fabs(v)); };
        EXPECT_NEAR(j.wx, fd.wx, tol(j.wx)) << x << "," << y;
        EXPECT_NEAR(j.wy, fd.wy, tol(j.wy)) << x << "," << y;
        EXPECT_NEAR(j.wxx, fd.wxx, tol(j.wxx)) << x << "," << y;
        EXPECT_NEAR(j.wxy, fd.wxy, tol(j.wxy)) << x << "," << y;
        EXPECT_NEAR(j.wyy, fd.wyy, tol(j.wyy)) << x << "," << y;
      }
      EXPECT_GT(checked, 10);
    }
  }
}

// ---------------------------------------------------------------------------
// Analytic cross-sections. A horizontal groove in direction (c, s) at tip
// height z0 through (2, 3): at distance n across it (inside the move), the
// height is z0 + f(|n|), its slope across f'(|n|) sign(n), its curvature
// across f''(|n|), nothing along.

struct CrossSection {
  double f, f1, f2;  // f(|n|), f'(|n|), f''(|n|)
};

void CheckGroove(const Cutter& c, CrossSection (*section)(const Cutter&,
                                                          double)) {
  for (double angle : {0.0, 37.0, 90.0, 200.0}) {
    const double cs = std::cos(angle * kDeg), sn = std::sin(angle * kDeg);
    const Vec3 a{2, 3, -1.5}, b{2 + 10 * cs, 3 + 10 * sn, -1.5};
    const auto sweep = EngineFor(c, a, b);
    for (double n = -c.radius + 1e-3; n < c.radius; n += 0.0137) {
      const double x = 2 + 5 * cs - n * sn, y = 3 + 5 * sn + n * cs;
      const CrossSection e = section(c, std::fabs(n));
      const double sg = n > 0 ? 1 : n < 0 ? -1 : 0;
      const SurfaceJet j = sweep->JetAt(x, y);
      SCOPED_TRACE(std::to_string(angle) + " n=" + std::to_string(n));
      EXPECT_NEAR(j.w, -1.5 + e.f, 1e-12);
      // Gradient sg f' (-sn, cs); Hessian f'' (-sn, cs)(-sn, cs)^T.
      const double t1 = 1e-9 * std::max(1.0, std::fabs(e.f1));
      const double t2 = 1e-9 * std::max(1.0, std::fabs(e.f2));
      EXPECT_NEAR(j.wx, -sg * e.f1 * sn, t1);
      EXPECT_NEAR(j.wy, sg * e.f1 * cs, t1);
      EXPECT_NEAR(j.wxx, e.f2 * sn * sn, t2);
      EXPECT_NEAR(j.wxy, -e.f2 * sn * cs, t2);
      EXPECT_NEAR(j.wyy, e.f2 * cs * cs, t2);
    }
  }
}

TEST(ProfileSweep, FlatGrooveFloorIsFlatToTheWall) {
  CheckGroove(Cutter::Flat(2), [](const Cutter&, double) {
    return CrossSection{0, 0, 0};
  });
  // And nothing beyond the wall at exactly R.
  const FlatSweep s({0, 0, -1}, {10, 0, -1}, 2);
  EXPECT_EQ(s.Height(5, 2), -1);
  EXPECT_TRUE(std::isinf(s.Height(5, std::nextafter(2.0, 3.0))));
}

TEST(ProfileSweep, BullNoseGrooveIsTheBandAndTheCornerCircle) {
  CheckGroove(Cutter::BullNose(3, 1), [](const Cutter& c, double n) {
    const double rc = c.corner_radius, flat = c.radius - rc;
    if (n <= flat) return CrossSection{0, 0, 0};
    const double e = n - flat, d = std::sqrt(rc * rc - e * e);
    return CrossSection{rc - d, e / d, rc * rc / (d * d * d)};
  });
}

TEST(ProfileSweep, VGrooveHasStraightFlanksAtTheHalfAngle) {
  for (const Cutter& c : {Cutter::Cone(3, 45, 0), Cutter::Cone(3, 30, 0.4)}) {
    CheckGroove(c, [](const Cutter& c, double n) {
      const double k = 1 / std::tan(c.half_angle_deg * kDeg);
      if (n <= c.tip_radius) return CrossSection{0, 0, 0};
      return CrossSection{(n - c.tip_radius) * k, k, 0};
    });
  }
}

TEST(ProfileSweep, TaperedBallGrooveIsTheBallThenTheFlank) {
  CheckGroove(Cutter::TaperedBall(3, 0.5, 10), [](const Cutter& c, double n) {
    const double rb = c.tip_radius, a = c.half_angle_deg * kDeg;
    const double rho_t = rb * std::cos(a);
    if (n <= rho_t) {
      const double d = std::sqrt(rb * rb - n * n);
      return CrossSection{rb - d, n / d, rb * rb / (d * d * d)};
    }
    const double k = 1 / std::tan(a);
    return CrossSection{rb - rb * std::sin(a) + (n - rho_t) * k, k, 0};
  });
}

// A ramp of slope m: every point set by the moving tool (not an end) has
// slope m along the move. The flat end's floor there is the disk's leading
// rim, w = z0 + m (a - sqrt(R^2 - n^2)); the sharp cone's is the wedge
// w = z0 + m a + |n| sqrt(k^2 - m^2).
TEST(ProfileSweep, RampFloors) {
  const Vec3 a{0, 0, 0}, b{8, 6, -2};  // L = 10, m = -0.2, h = (0.8, 0.6)
  const double m = -0.2, h1 = 0.8, h2 = 0.6;
  {
    const double r = 2;
    const FlatSweep s(a, b, r);
    for (double al : {3.0, 5.5, 7.25}) {
      for (double n = -1.9; n < 1.9; n += 0.1) {
        const double x = al * h1 - n * h2, y = al * h2 + n * h1;
        const double root = std::sqrt(r * r - n * n);
        // Descending: the trailing rim (a + root) is lowest, until the end.
        const double s_rim = std::min(al + root, 10.0);
        const SurfaceJet j = s.JetAt(x, y);
        EXPECT_NEAR(j.w, m * s_rim, 1e-12) << al << " " << n;
        if (al + root < 10) {
          // w_n = -m n / root, w_nn = -m R^2 / root^3 (sigma = +1).
          const double wn = -m * n / root, wnn = -m * r * r / (root * root * root);
          EXPECT_NEAR(j.wx, m * h1 - wn * h2, 1e-12);
          EXPECT_NEAR(j.wy, m * h2 + wn * h1, 1e-12);
          EXPECT_NEAR(j.wxx, wnn * h2 * h2, 1e-12);
          EXPECT_NEAR(j.wxy, -wnn * h1 * h2, 1e-12);
          EXPECT_NEAR(j.wyy, wnn * h1 * h1, 1e-12);
        }
      }
    }
  }
  {
    const ConeSweep s(a, b, 3, 45, 0);
    const double k = 1, root = std::sqrt(k * k - m * m);
    for (double al : {3.0, 5.5}) {
      for (double n = -2; n < 2; n += 0.1) {
        const double x = al * h1 - n * h2, y = al * h2 + n * h1;
        const SurfaceJet j = s.JetAt(x, y);
        const double sg = n > 0 ? 1 : n < 0 ? -1 : 0;
        EXPECT_NEAR(j.w, m * al + std::fabs(n) * root, 1e-12);
        EXPECT_NEAR(j.wx, m * h1 - sg * root * h2, 1e-12);
        EXPECT_NEAR(j.wy, m * h2 + sg * root * h1, 1e-12);
        EXPECT_EQ(j.wxx, 0);
        EXPECT_EQ(j.wxy, 0);
        EXPECT_EQ(j.wyy, 0);
      }
    }
  }
  // Every shape: slope m along the move wherever the moving tool sets w.
  for (const Shape& shape : kShapes) {
    const auto s = EngineFor(shape.cutter, a, b);
    for (double al = 2; al < 8; al += 0.37) {
      for (double n = -1.5; n < 1.5; n += 0.21) {
        const double x = al * h1 - n * h2, y = al * h2 + n * h1;
        const ProfilePoint p = s->Locate(x, y);
        if (p.contact == ProfilePoint::kTool) continue;
        const SurfaceJet j = s->Jet(p);
        if (MaxAbs(j) > 1e3) continue;  // a clamped wall
        EXPECT_NEAR(j.wx * h1 + j.wy * h2, m, 1e-12) << shape.name;
      }
    }
  }
}

// A plunge's crater is the tool at its lowest: w = z_low + f(rho).
TEST(ProfileSweep, PlungeCraterIsTheTool) {
  for (const Shape& shape : kShapes) {
    const Cutter& c = shape.cutter;
    const auto s = EngineFor(c, {1, 1, 3}, {1, 1, -2});
    for (double rho = 0; rho < c.radius; rho += 0.05) {
      const double x = 1 + rho * 0.6, y = 1 - rho * 0.8;
      EXPECT_NEAR(s->Height(x, y), -2 + ProfileHeight(c, rho), 1e-12)
          << shape.name << " rho=" << rho;
    }
    EXPECT_TRUE(std::isinf(s->Height(1 + c.radius * 1.0001, 1)));
  }
}

// ---------------------------------------------------------------------------
// Degenerate shapes.

std::vector<std::pair<double, double>> GridPoints(double x0, double y0,
                                                  double x1, double y1) {
  std::vector<std::pair<double, double>> pts;
  for (double y = y0; y <= y1; y += 0.0731) {
    for (double x = x0; x <= x1; x += 0.0917) pts.emplace_back(x, y);
  }
  return pts;
}

TEST(ProfileSweep, BullNoseWithFullCornerIsTheBall) {
  // The engine's own sphere piece against BallSweep: 1e-12 mm in height
  // (different but equivalent formulas), 1e-9 relative in derivatives away
  // from the rim. Sweep() picks BallSweep itself: bit-identical.
  for (const MoveCase& mc : kMoves) {
    SCOPED_TRACE(mc.name);
    const double r = 2;
    const BullNoseSweep bull(mc.from, mc.to, r, r);
    const BallSweep ball(mc.from, mc.to, r);
    const Sweep via_seam(mc.from, mc.to, Cutter::BullNose(r, r));
    for (const auto& [x, y] : GridPoints(-2, -1, 12, 8)) {
      const double wb = ball.Height(x, y);
      const double wn = bull.Height(x, y);
      const double ws = via_seam.Height(x, y);
      EXPECT_EQ(std::bit_cast<uint64_t>(ws), std::bit_cast<uint64_t>(wb));
      if (std::isinf(wb)) {
        EXPECT_TRUE(std::isinf(wn)) << x << "," << y;
        continue;
      }
      EXPECT_NEAR(wn, wb, 1e-12) << x << "," << y;
      const SurfaceJet jb = ball.JetAt(x, y), jn = bull.JetAt(x, y);
      if (MaxAbs(jb) > 100) continue;
      for (auto [u, v] : {std::pair{jn.wx, jb.wx}, {jn.wy, jb.wy},
                          {jn.wxx, jb.wxx}, {jn.wxy, jb.wxy},
                          {jn.wyy, jb.wyy}}) {
        EXPECT_NEAR(u, v, 1e-9 * std::max(1.0, std::fabs(v))) << x << "," << y;
      }
    }
  }
}

void ExpectBitIdentical(const Sweep& a, const Sweep& b, double x, double y) {
  const SurfaceJet ja = a.JetAt(x, y), jb = b.JetAt(x, y);
  EXPECT_EQ(std::memcmp(&ja, &jb, sizeof ja), 0) << x << "," << y;
}

TEST(ProfileSweep, BullNoseWithoutCornerIsTheFlatEnd) {
  // The same profile: bit-identical, through the engine and the seam.
  for (const MoveCase& mc : kMoves) {
    const Sweep bull(mc.from, mc.to, Cutter::BullNose(2, 0));
    const Sweep flat(mc.from, mc.to, Cutter::Flat(2));
    const BullNoseSweep engine(mc.from, mc.to, 2, 0);
    for (const auto& [x, y] : GridPoints(-2, -1, 12, 8)) {
      ExpectBitIdentical(bull, flat, x, y);
      const SurfaceJet je = engine.JetAt(x, y), jf = flat.JetAt(x, y);
      EXPECT_EQ(std::memcmp(&je, &jf, sizeof je), 0);
    }
  }
}

TEST(ProfileSweep, ConeNearNinetyDegreesIsTheFlatEnd) {
  // Half angle 90 - 1e-12 degrees: the flank rises (R - tip) cot(a) < 1e-13
  // mm over the whole tool, so heights agree with the flat end to 1e-12 and
  // slopes to 1e-12 wherever the flat end's are not a clamped wall.
  for (double tip : {0.0, 0.5}) {
    for (const MoveCase& mc : kMoves) {
      SCOPED_TRACE(std::string(mc.name) + " tip " + std::to_string(tip));
      const ConeSweep cone(mc.from, mc.to, 2, 90 - 1e-12, tip);
      const FlatSweep flat(mc.from, mc.to, 2);
      for (const auto& [x, y] : GridPoints(-2, -1, 12, 8)) {
        const double wc = cone.Height(x, y), wf = flat.Height(x, y);
        if (std::isinf(wf)) {
          EXPECT_TRUE(std::isinf(wc));
          continue;
        }
        EXPECT_NEAR(wc, wf, 1e-12) << x << "," << y;
        const SurfaceJet jf = flat.JetAt(x, y), jc = cone.JetAt(x, y);
        if (MaxAbs(jf) > 100) continue;
        EXPECT_NEAR(jc.wx, jf.wx, 1e-12 * std::max(1.0, std::fabs(jf.wx)));
        EXPECT_NEAR(jc.wy, jf.wy, 1e-12 * std::max(1.0, std::fabs(jf.wy)));
      }
    }
  }
  // At 89.9999999 degrees the difference is the flank's rise, no more.
  const ConeSweep cone({0, 0, 0}, {5, 0, -1}, 2, 89.9999999, 0);
  const FlatSweep flat({0, 0, 0}, {5, 0, -1}, 2);
  const double rise = 2 / std::tan(89.9999999 * kDeg);
  for (const auto& [x, y] : GridPoints(-2, -2, 7, 2)) {
    const double wf = flat.Height(x, y);
    if (std::isinf(wf)) continue;
    const double d = cone.Height(x, y) - wf;
    EXPECT_GE(d, -1e-12);
    EXPECT_LE(d, rise + 1e-12);
  }
}

TEST(ProfileSweep, TaperedBallWithTinyTaperIsTheBall) {
  // Tip radius = radius, half angle 1e-12 degrees: the flank is the
  // ball's rim, within 1e-12 mm.
  for (const MoveCase& mc : kMoves) {
    SCOPED_TRACE(mc.name);
    const TaperedBallSweep taper(mc.from, mc.to, 2, 2, 1e-12);
    const BallSweep ball(mc.from, mc.to, 2);
    for (const auto& [x, y] : GridPoints(-2, -1, 12, 8)) {
      const double wb = ball.Height(x, y);
      if (std::isinf(wb)) continue;
      EXPECT_NEAR(taper.Height(x, y), wb, 1e-12) << x << "," << y;
      const SurfaceJet jb = ball.JetAt(x, y), jt = taper.JetAt(x, y);
      if (MaxAbs(jb) > 100) continue;
      for (auto [u, v] : {std::pair{jt.wx, jb.wx}, {jt.wy, jb.wy},
                          {jt.wxx, jb.wxx}, {jt.wxy, jb.wxy},
                          {jt.wyy, jb.wyy}}) {
        EXPECT_NEAR(u, v, 1e-9 * std::max(1.0, std::fabs(v))) << x << "," << y;
      }
    }
  }
}

// Grid nodes exactly on a bull-nose ramp's end planes, at the edge of the
// flat band (|n| = R - rc) and at the wall (|n| = R): the bull-ramps
// instance's first move with the heights its job computes (-0.1 * 1.6 is
// -0.16000000000000003). At (90, 10) rounding put z0 + m L below to.z, so
// the wall circle's crossing at the end (half chord 0) beat the end's tool
// and, taken with the sign of the crossing the ramp climbs from, gave a
// mirrored wall (wy = 160, wyy = -3.2e9) among neighbours with wy = -1e4,
// wyy = +5e11. Written -0.16 the same move gave the end's tool. Every jet
// must be a one-sided limit of its neighbours' or a harmless patch.
TEST(ProfileSweep, BullRampEndPlaneAtTheFlatBandEdgeTakesALimit) {
  const Cutter bull = Cutter::BullNose(5, 2);
  for (const auto& [z0, z1] :
       {std::pair{-0.1 * 1.6, -0.9 * 1.6}, std::pair{-0.16, -1.44}}) {
    SCOPED_TRACE(z0);
    const Sweep s({10, 15, z0}, {90, 15, z1}, bull);
    auto jet_at = [&](double x, double y) { return s.JetAt(x, y); };
    auto height_at = [&](double x, double y) { return s.Height(x, y); };
    for (double x : {90.0, 10.0}) {
      for (double y : {12.0, 18.0, 10.0, 20.0}) {
        const SurfaceJet j = s.JetAt(x, y);
        EXPECT_EQ(std::bit_cast<uint64_t>(j.w),
                  std::bit_cast<uint64_t>(s.Height(x, y)));
        EXPECT_EQ(testing::CheckSeamJet(jet_at, height_at, x, y, j, 5), "")
            << x << "," << y << ": wy " << j.wy << " wyy " << j.wyy;
      }
    }
  }
}

// ---------------------------------------------------------------------------
// The paths the tile kernel takes: Heights and JetAt().w bit-identical to
// Height, through the seam.

TEST(ProfileSweep, HeightsAndJetsAreBitIdenticalToHeight) {
  for (const Shape& shape : kShapes) {
    for (const MoveCase& mc : kMoves) {
      SCOPED_TRACE(CaseName(shape, mc));
      const Sweep s(mc.from, mc.to, shape.cutter);
      const auto pts = PointsNear(shape.cutter, mc, 256, 5);
      std::vector<double> xs, ys, out(pts.size());
      for (const auto& [x, y] : pts) {
        xs.push_back(x);
        ys.push_back(y);
      }
      s.Heights(xs.data(), ys.data(), static_cast<int32_t>(pts.size()),
                out.data());
      for (size_t q = 0; q < pts.size(); ++q) {
        const double w = s.Height(xs[q], ys[q]);
        const double wj = s.JetAt(xs[q], ys[q]).w;
        EXPECT_EQ(std::bit_cast<uint64_t>(out[q]), std::bit_cast<uint64_t>(w));
        EXPECT_EQ(std::bit_cast<uint64_t>(wj), std::bit_cast<uint64_t>(w));
        const SurfaceJet j = s.JetAt(xs[q], ys[q]);
        for (double d : {j.wx, j.wy, j.wxx, j.wxy, j.wyy}) {
          EXPECT_TRUE(std::isfinite(d));
          EXPECT_LE(std::fabs(d), kMaxDerivative);
        }
      }
    }
  }
}

// Extreme but valid input: tiny and huge tools, near-vertical ramps (slope
// up to 1e12), far coordinates. Heights are never NaN and never below the
// lowest tip; derivatives are finite and bounded.
TEST(ProfileSweep, ExtremeMovesStayFinite) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(0, 1);
  const Cutter cutters[] = {
      Cutter::Flat(1e-4),          Cutter::BullNose(2e-4, 1e-4),
      Cutter::BullNose(1e5, 1),    Cutter::Cone(1e-4, 0.001, 0),
      Cutter::Cone(50, 89.999, 1), Cutter::TaperedBall(1e5, 1e-4, 45),
      Cutter::TaperedBall(3, 2.9, 0.01)};
  for (const Cutter& c : cutters) {
    ASSERT_TRUE(ValidateCutter(c, "t").ok()) << CutterToString(c);
    for (double base : {0.0, 1e9 - 100}) {
      for (double dxy : {0.0, 1e-9, 1e-6, 1e-3, 1.0, 100.0}) {
        const Vec3 a{base, base, 1}, b{base + dxy, base + 0.5 * dxy, -2};
        const Sweep s(a, b, c);
        for (int k = 0; k < 200; ++k) {
          const double x = base + (unit(rng) - 0.3) * (dxy + 2 * c.radius);
          const double y = base + (unit(rng) - 0.5) * (dxy + 2 * c.radius);
          const SurfaceJet j = s.JetAt(x, y);
          ASSERT_FALSE(std::isnan(j.w)) << CutterToString(c) << " " << dxy;
          if (std::isinf(j.w)) continue;
          EXPECT_GE(j.w, s.lowest());
          for (double d : {j.wx, j.wy, j.wxx, j.wxy, j.wyy}) {
            ASSERT_TRUE(std::isfinite(d)) << CutterToString(c) << " " << dxy;
            EXPECT_LE(std::fabs(d), kMaxDerivative);
          }
        }
      }
    }
  }
}

// ---------------------------------------------------------------------------
// The workpiece with each shape: every node is the minimum of the top and
// of the moves' Sweep::Height (the lowest id on ties), and on taylor its
// stored derivatives are float(JetAt) of its owner.

std::vector<Move> RandomMoves(const Cutter& c, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> ux(-1, 21), uy(-1, 16), uz(-3, 0.5),
      unit(0, 1);
  std::vector<Move> moves;
  for (int k = 0; k < 36; ++k) {
    const Vec3 p{ux(rng), uy(rng), uz(rng)};
    Vec3 q;
    switch (k % 6) {
      case 0:  // horizontal
        q = {ux(rng), uy(rng), p.z};
        break;
      case 1:  // ramp
        q = {ux(rng), uy(rng), uz(rng)};
        break;
      case 2:  // steep ramp
        q = {p.x + unit(rng) - 0.5, p.y + unit(rng) - 0.5, p.z - 3};
        break;
      case 3:  // plunge
        q = {p.x, p.y, p.z - 2};
        break;
      case 4:  // retract
        q = {p.x, p.y, p.z + 2};
        break;
      default:  // zero length
        q = p;
        break;
    }
    moves.emplace_back(p, q, c);
  }
  return moves;
}

TEST(ProfileSweep, WorkpieceNodesAreTheSweeps) {
  const StockSpec spec{0, 0, 20, 15, 0, 100, 75};
  for (const Shape& shape : kShapes) {
    for (SchemeKind scheme : {SchemeKind::kZmap, SchemeKind::kTaylor}) {
      SCOPED_TRACE(std::string(shape.name) + " " +
                   std::string(GetScheme(scheme).name()));
      auto wp = *Workpiece::Create(spec, scheme);
      const std::vector<Move> moves = RandomMoves(shape.cutter, 99);
      // Two batches, to cross batch boundaries.
      ASSERT_TRUE(wp->Apply(std::span(moves).first(20)).ok());
      ASSERT_TRUE(wp->Apply(std::span(moves).subspan(20)).ok());
      std::vector<Sweep> sweeps;
      for (const Move& m : moves) sweeps.emplace_back(m.from, m.to, m.cutter);
      const GridGeometry& g = wp->grid();
      int cut = 0;
      for (int32_t j = 0; j <= g.ny(); ++j) {
        for (int32_t i = 0; i <= g.nx(); ++i) {
          const double x = g.NodeX(i), y = g.NodeY(j);
          std::vector<double> heights;
          for (const Sweep& s : sweeps) heights.push_back(s.Height(x, y));
          // The first of equal minima: the lowest id wins ties.
          const auto low = std::min_element(heights.begin(), heights.end());
          const bool below = *low < spec.z_top;
          const double w = below ? *low : spec.z_top;
          const int32_t owner =
              below ? static_cast<int32_t>(low - heights.begin()) : -1;
          const NodeValue nv = wp->Node(i, j);
          ASSERT_EQ(std::bit_cast<uint64_t>(nv.jet.w),
                    std::bit_cast<uint64_t>(w))
              << i << "," << j;
          ASSERT_EQ(nv.owner, owner) << i << "," << j;
          if (owner < 0 || scheme != SchemeKind::kTaylor) continue;
          ++cut;
          const SurfaceJet e = sweeps[owner].JetAt(x, y);
          EXPECT_EQ(static_cast<float>(nv.jet.wx), static_cast<float>(e.wx));
          EXPECT_EQ(static_cast<float>(nv.jet.wy), static_cast<float>(e.wy));
          EXPECT_EQ(static_cast<float>(nv.jet.wxx), static_cast<float>(e.wxx));
          EXPECT_EQ(static_cast<float>(nv.jet.wxy), static_cast<float>(e.wxy));
          EXPECT_EQ(static_cast<float>(nv.jet.wyy), static_cast<float>(e.wyy));
        }
      }
      if (scheme == SchemeKind::kTaylor) {
        EXPECT_GT(cut, 1000);
      }
    }
  }
}

}  // namespace
}  // namespace swarf
