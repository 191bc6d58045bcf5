// BallSweep against analytic truths (spheres, horizontal grooves), a
// brute-force minimum over the balls along the move, and finite differences.
#include "core/cutter/ball_sweep.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "core/cutter/sweep.h"
#include "gtest/gtest.h"
#include "tests/sweep_reference.h"

namespace swarf {
namespace {

using ::swarf::testing::BruteForceHeight;
using ::swarf::testing::DistanceToPath;
using ::swarf::testing::HeightRoundoff;
using ::swarf::testing::kDoubleEps;
using ::swarf::testing::LD;
using ::swarf::testing::ReferencePoint;

// The analytic formulas below are a handful of flops on well-conditioned
// points (depth >= 0.14 r, so r^2 / depth^2 <= 50 amplifies rounding by at
// most 50): 1e-12 relative leaves a wide margin over the ~1e-14 expected and
// still catches any formula error.
constexpr double kAnalyticRel = 1e-12;

struct Jet6 {
  LD w, wx, wy, wxx, wxy, wyy;
};

// Lower hemisphere z = zc - sqrt(r^2 - d^2) of the ball whose tip is at
// `tip`, with its derivatives (paper eq. 7-8), in long double.
Jet6 SphereTruth(const Vec3& tip, double r, double x, double y) {
  const LD zc = LD{tip.z} + r;
  const LD dx = LD{x} - tip.x, dy = LD{y} - tip.y;
  const LD depth = std::sqrt(LD{r} * r - dx * dx - dy * dy);
  Jet6 j;
  j.w = zc - depth;
  j.wx = dx / depth;
  j.wy = dy / depth;
  j.wxx = (1 + j.wx * j.wx) / depth;
  j.wxy = j.wx * j.wy / depth;
  j.wyy = (1 + j.wy * j.wy) / depth;
  return j;
}

// Compares a jet with the truth: the height relative to the size of the
// numbers involved, first and second derivatives relative to the size of
// their group (a zero entry is then held to the same absolute standard).
void ExpectJetNear(const SurfaceJet& got, const Jet6& want, double scale,
                   double rel, const std::string& where) {
  SCOPED_TRACE(where);
  const double s1 = 1 + std::fabs(static_cast<double>(want.wx)) +
                    std::fabs(static_cast<double>(want.wy));
  const double s2 = std::fabs(static_cast<double>(want.wxx)) +
                    std::fabs(static_cast<double>(want.wxy)) +
                    std::fabs(static_cast<double>(want.wyy));
  EXPECT_NEAR(got.w, static_cast<double>(want.w), rel * scale);
  EXPECT_NEAR(got.wx, static_cast<double>(want.wx), rel * s1);
  EXPECT_NEAR(got.wy, static_cast<double>(want.wy), rel * s1);
  EXPECT_NEAR(got.wxx, static_cast<double>(want.wxx), rel * s2);
  EXPECT_NEAR(got.wxy, static_cast<double>(want.wxy), rel * s2);
  EXPECT_NEAR(got.wyy, static_cast<double>(want.wyy), rel * s2);
}

std::string Where(double x, double y) {
  return "at (" + std::to_string(x) + ", " + std::to_string(y) + ")";
}

// Offsets (as fractions of r) from a ball's axis, all with d <= 0.99 r.
constexpr double kSphereOffsets[][2] = {
    {0, 0},      {0.3, -0.2},  {-0.7, 0.5}, {0.99, 0},  {0, -0.99},
    {0.6, 0.75}, {-0.45, -0.8}, {0.1, 0.05}, {-0.9, 0.3}, {0.69, -0.69}};

void CheckSphere(const BallSweep& sweep, const Vec3& lowest_tip, double r,
                 SweepPoint::Piece piece) {
  const double scale = std::fabs(lowest_tip.z) + r;
  for (const auto& o : kSphereOffsets) {
    const double x = lowest_tip.x + o[0] * r, y = lowest_tip.y + o[1] * r;
    const SweepPoint p = sweep.Locate(x, y);
    EXPECT_EQ(p.piece, piece) << Where(x, y);
    const Jet6 want = SphereTruth(lowest_tip, r, x, y);
    EXPECT_NEAR(sweep.Height(x, y), static_cast<double>(want.w),
                kAnalyticRel * scale)
        << Where(x, y);
    ExpectJetNear(sweep.Jet(p), want, scale, kAnalyticRel, Where(x, y));
  }
}

TEST(BallSweepSphereTest, ZeroLengthMoveIsTheBall) {
  for (double r : {0.5, 3.0, 12.5}) {
    const Vec3 tip{12.3, -7.1, 4.2};
    const BallSweep sweep(tip, tip, r);
    EXPECT_EQ(sweep.radius(), r);
    EXPECT_EQ(sweep.centre_from().z, tip.z + r);  // centre = tip + r on z
    // (tip.z + r) - r may differ from tip.z by rounding: 1e-15 relative.
    EXPECT_NEAR(sweep.lowest(), tip.z, 1e-15 * (tip.z + r));
    // Directly below the centre the surface is the tool tip.
    EXPECT_NEAR(sweep.Height(tip.x, tip.y), tip.z, 1e-15 * (tip.z + r));
    CheckSphere(sweep, tip, r, SweepPoint::kStartSphere);
  }
}

TEST(BallSweepSphereTest, VerticalPlungeIsItsLowerEndSphere) {
  for (double r : {0.5, 3.0, 12.5}) {
    const Vec3 top{-3.75, 8.5, 6.0}, bottom{-3.75, 8.5, -2.25};
    const BallSweep sweep(top, bottom, r);
    EXPECT_NEAR(sweep.lowest(), bottom.z, 1e-15 * (top.z + r));
    CheckSphere(sweep, bottom, r, SweepPoint::kEndSphere);
  }
}

TEST(BallSweepSphereTest, RetractIsItsLowerStartSphere) {
  for (double r : {0.5, 3.0, 12.5}) {
    const Vec3 bottom{4.1, 0.3, -1.7}, top{4.1, 0.3, 9.9};
    const BallSweep sweep(bottom, top, r);
    EXPECT_NEAR(sweep.lowest(), bottom.z, 1e-15 * (top.z + r));
    CheckSphere(sweep, bottom, r, SweepPoint::kStartSphere);
  }
}

// A horizontal groove of length `len` from `tip` in direction `deg` degrees.
void CheckGroove(const Vec3& tip, double deg, double len, double r) {
  SCOPED_TRACE("groove at " + std::to_string(deg) + " degrees, r " +
               std::to_string(r));
  const double a = deg * M_PI / 180;
  const Vec3 end{tip.x + len * std::cos(a), tip.y + len * std::sin(a), tip.z};
  const BallSweep sweep(tip, end, r);
  // Unit direction and normal from the doubles actually passed.
  const LD ex = LD{end.x} - tip.x, ey = LD{end.y} - tip.y;
  const LD el = std::hypot(ex, ey);
  const LD ux = ex / el, uy = ey / el;
  const LD zc = LD{tip.z} + r;
  const double scale = std::fabs(tip.z) + r + std::fabs(tip.x) +
                       std::fabs(tip.y) + len;
  int cylinder_points = 0;
  for (double fu : {0.01, 0.2, 0.5, 0.77, 0.99}) {
    for (double fn : {-0.97, -0.6, -0.2, 0.0, 0.3, 0.8, 0.95}) {
      const double x = static_cast<double>(tip.x + fu * len * ux - fn * r * uy);
      const double y = static_cast<double>(tip.y + fu * len * uy + fn * r * ux);
      // Across (n) and along (u) coordinates of the rounded point.
      const LD n = -(LD{x} - tip.x) * uy + (LD{y} - tip.y) * ux;
      const LD depth = std::sqrt(LD{r} * r - n * n);
      const LD slope = n / depth;                 // across the groove
      const LD curv = LD{r} * r / (depth * depth * depth);  // r^2/(r^2-n^2)^1.5
      const Jet6 want{zc - depth,       -slope * uy,    slope * ux,
                      curv * uy * uy, -curv * ux * uy, curv * ux * ux};
      const SweepPoint p = sweep.Locate(x, y);
      EXPECT_EQ(p.piece, SweepPoint::kCylinder) << Where(x, y);
      ExpectJetNear(sweep.Jet(p), want, scale, kAnalyticRel, Where(x, y));
      // Along the groove the surface is flat: zero slope and curvature.
      const SurfaceJet j = sweep.Jet(p);
      const double along_slope = j.wx * ux + j.wy * uy;
      const double along_curv =
          j.wxx * ux * ux + 2 * j.wxy * ux * uy + j.wyy * uy * uy;
      EXPECT_NEAR(along_slope, 0, kAnalyticRel * (1 + std::fabs(j.wx) +
                                                  std::fabs(j.wy)));
      EXPECT_NEAR(along_curv, 0,
                  kAnalyticRel * (std::fabs(j.wxx) + std::fabs(j.wxy) +
                                  std::fabs(j.wyy)));
      ++cylinder_points;
    }
  }
  EXPECT_EQ(cylinder_points, 35);
  // Beyond the ends the surface is the end balls.
  for (double fu : {-0.8, -0.4, -0.05}) {
    for (double fn : {-0.5, 0.0, 0.35}) {
      const double x = static_cast<double>(tip.x + fu * r * ux - fn * r * uy);
      const double y = static_cast<double>(tip.y + fu * r * uy + fn * r * ux);
      const SweepPoint p = sweep.Locate(x, y);
      EXPECT_EQ(p.piece, SweepPoint::kStartSphere) << Where(x, y);
      ExpectJetNear(sweep.Jet(p), SphereTruth(tip, r, x, y), scale,
                    kAnalyticRel, Where(x, y));
    }
  }
  for (double fu : {0.05, 0.4, 0.8}) {
    for (double fn : {-0.5, 0.0, 0.35}) {
      const double x =
          static_cast<double>(end.x + fu * r * ux - fn * r * uy);
      const double y =
          static_cast<double>(end.y + fu * r * uy + fn * r * ux);
      const SweepPoint p = sweep.Locate(x, y);
      EXPECT_EQ(p.piece, SweepPoint::kEndSphere) << Where(x, y);
      ExpectJetNear(sweep.Jet(p), SphereTruth(end, r, x, y), scale,
                    kAnalyticRel, Where(x, y));
    }
  }
}

TEST(BallSweepGrooveTest, AlongX) { CheckGroove({-5, 2, -1.5}, 0, 20, 3); }

TEST(BallSweepGrooveTest, AlongThirtyDegrees) {
  CheckGroove({1.25, -3.5, 0.75}, 30, 14, 2.5);
}

TEST(BallSweepGrooveTest, AlongNegativeY) {
  CheckGroove({7, 7, -4}, 270, 9, 1);
}

TEST(BallSweepGrooveTest, ReversedDirection) {
  CheckGroove({10, 4, 2}, 210, 11, 4);
}

// Moves used against the brute force and finite differences.
struct MoveCase {
  std::string name;
  Vec3 from, to;
  double radius;
};

std::vector<MoveCase> RandomMoves(uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> pos(-20, 20), z(-8, 8),
      rad(0.5, 10);
  std::vector<MoveCase> out;
  for (int k = 0; k < 8; ++k) {
    out.push_back({"sloped " + std::to_string(k),
                   {pos(rng), pos(rng), z(rng)},
                   {pos(rng), pos(rng), z(rng)},
                   rad(rng)});
  }
  // Near-vertical: horizontal travel 1e-6 of the length, down and up.
  out.push_back({"near-vertical down", {3, -2, 9}, {3 + 12e-6 * 0.6, -2 + 12e-6 * 0.8, -3}, 4});
  out.push_back({"near-vertical up", {-1, 5, -6}, {-1 - 9e-6, 5, 3}, 2.5});
  // Steep but clearly general (87 degrees).
  out.push_back({"steep", {0, 0, 6}, {0.5, 0.2, -4}, 3});
  // 45 degrees up and down, on a diagonal.
  out.push_back({"45 down", {-4, -4, 5}, {2, 2, 5 - 6 * std::sqrt(2.0)}, 3});
  out.push_back({"45 up", {2, -3, -6}, {2, 7, 4}, 1.5});
  // Shallow: vertical travel 1e-6 of the length.
  out.push_back({"shallow", {-10, 3, 1}, {10, -3, 1 - 2e-5}, 5});
  return out;
}

// Swept height against the brute-force minimum over the balls along the
// move, at random points and at points just inside the rims (where the
// crescent of a near-vertical move's cylinder lies).
TEST(BallSweepBruteForceTest, HeightMatchesMinimumOverBalls) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(0, 1);
  double worst_ratio = 0;
  int compared = 0, cylinder = 0;
  for (const MoveCase& mc : RandomMoves(42)) {
    SCOPED_TRACE(mc.name);
    const BallSweep sweep(mc.from, mc.to, mc.radius);
    const double r = mc.radius;
    const double scale = std::max({std::fabs(mc.from.x), std::fabs(mc.from.y),
                                   std::fabs(mc.from.z), std::fabs(mc.to.x),
                                   std::fabs(mc.to.y), std::fabs(mc.to.z)}) +
                         r;
    const double bx0 = std::min(mc.from.x, mc.to.x) - 1.1 * r;
    const double bx1 = std::max(mc.from.x, mc.to.x) + 1.1 * r;
    const double by0 = std::min(mc.from.y, mc.to.y) - 1.1 * r;
    const double by1 = std::max(mc.from.y, mc.to.y) + 1.1 * r;
    for (int k = 0; k < 260; ++k) {
      double x, y;
      if (k < 180) {
        x = bx0 + (bx1 - bx0) * unit(rng);
        y = by0 + (by1 - by0) * unit(rng);
      } else {
        // Just inside the rim of some ball along the move.
        const double t = unit(rng), phi = 2 * M_PI * unit(rng);
        const double rho = r * (1 - std::pow(10.0, -13 + 12 * unit(rng)));
        x = mc.from.x + t * (mc.to.x - mc.from.x) + rho * std::cos(phi);
        y = mc.from.y + t * (mc.to.y - mc.from.y) + rho * std::sin(phi);
      }
      const ReferencePoint ref =
          BruteForceHeight(mc.from, mc.to, r, x, y);
      const SweepPoint p = sweep.Locate(x, y);
      const double got = p.w;
      const LD dist = DistanceToPath(mc.from, mc.to, x, y);
      // Within rounding of the outer rim either side may call it a miss.
      const bool at_rim = std::fabs(static_cast<double>(dist) - r) <= 1e-12 * scale;
      if (std::isinf(static_cast<double>(ref.w)) || std::isinf(got)) {
        if (!at_rim) {
          EXPECT_EQ(got, static_cast<double>(ref.w)) << Where(x, y);
          EXPECT_EQ(std::isinf(got), p.piece == SweepPoint::kNone);
        }
        continue;
      }
      // 1e-9 mm, plus the conditioning of the height where it is steep.
      const double slope = static_cast<double>(ref.slope);
      const double err = std::fabs(got - static_cast<double>(ref.w));
      const double tol = 1e-9 + HeightRoundoff(scale, slope);
      EXPECT_LE(err, tol) << Where(x, y) << " ref " << static_cast<double>(ref.w)
                          << " slope " << slope << " piece " << int(p.piece);
      worst_ratio = std::max(worst_ratio,
                             err / (kDoubleEps * scale * (1 + slope)));
      ++compared;
      cylinder += p.piece == SweepPoint::kCylinder;
    }
  }
  // Enough points really tested, on the cylinder too.
  EXPECT_GT(compared, 2000);
  EXPECT_GT(cylinder, 800);
  RecordProperty("worst_error_over_eps_scale_slope", std::to_string(worst_ratio));
}

// No ball along a move reaches below the swept surface (the other half of
// "lowest point of the union", next to the brute-force minimum above), here
// with balls at arbitrary positions along the move.
TEST(BallSweepBruteForceTest, NoBallReachesBelowTheSurface) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0, 1);
  for (const MoveCase& mc : RandomMoves(43)) {
    SCOPED_TRACE(mc.name);
    const BallSweep sweep(mc.from, mc.to, mc.radius);
    const double r = mc.radius;
    for (int k = 0; k < 2000; ++k) {
      const double t = unit(rng), phi = 2 * M_PI * unit(rng);
      const double rho = 0.999 * r * std::sqrt(unit(rng));  // off the rim
      const double x = mc.from.x + t * (mc.to.x - mc.from.x) + rho * std::cos(phi);
      const double y = mc.from.y + t * (mc.to.y - mc.from.y) + rho * std::sin(phi);
      const Vec3 c{mc.from.x + t * (mc.to.x - mc.from.x),
                   mc.from.y + t * (mc.to.y - mc.from.y),
                   mc.from.z + t * (mc.to.z - mc.from.z) + r};
      const double ball = SphereHeight(c, r, x, y);
      const double w = sweep.Height(x, y);
      ASSERT_TRUE(std::isfinite(w)) << Where(x, y);
      // The ball's own height is rounded like any other (its slope there is
      // d / depth).
      const double d = std::hypot(x - c.x, y - c.y);
      const double ball_slope = d / std::sqrt(std::max(r * r - d * d, 1e-300));
      EXPECT_LE(w, ball + 1e-9 + HeightRoundoff(30, ball_slope))
          << Where(x, y);
    }
  }
}

// Finite-difference check of the five derivatives (paper eq. 8-9, 14).
//
// Truncation: each piece is a circle profile z = c - sqrt(rho^2 - u^2) / g
// along some direction (g = 1 for the spheres; g = horizontal fraction of the
// axis for the cylinder, whose vertical sections are ellipses), so with
// delta the smallest depth sqrt(r^2 - d^2) over the stencil,
// |w'''| <= 3 r^3 / (g delta^5) and |w''''| <= 15 r^4 / (g delta^7).
// Central differences then err by h^2 |w'''| / 6 (first), h^2 |w''''| / 12
// (second, 3-point) and h^2 (|w_xxxy| + |w_xyyy|) / 6 <= h^2 |w''''| / 3
// (mixed, 4-point), plus the round-off of Height (HeightRoundoff, verified by
// the brute-force test) divided by h resp. h^2.
struct FdStats {
  int tested = 0;
  int cylinder = 0;
};

FdStats CheckDerivativesByFiniteDifferences(const MoveCase& mc, int points,
                                            uint64_t seed) {
  SCOPED_TRACE(mc.name);
  FdStats stats;
  const BallSweep sweep(mc.from, mc.to, mc.radius);
  const double r = mc.radius;
  const double hx = mc.to.x - mc.from.x, hy = mc.to.y - mc.from.y,
               hz = mc.to.z - mc.from.z;
  const double len = std::sqrt(hx * hx + hy * hy + hz * hz);
  const double g_move = len > 0 ? std::hypot(hx, hy) / len : 1;
  const double scale =
      std::max({std::fabs(mc.from.x), std::fabs(mc.from.y),
                std::fabs(mc.from.z), std::fabs(mc.to.x), std::fabs(mc.to.y),
                std::fabs(mc.to.z)}) + r;
  const double h1 = 1e-5;  // first derivatives
  const double h2 = 1e-4;  // second derivatives
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1);
  for (int k = 0; k < points; ++k) {
    const double t = unit(rng), phi = 2 * M_PI * unit(rng);
    const double rho = 0.97 * r * std::sqrt(unit(rng));
    const double x = mc.from.x + t * hx + rho * std::cos(phi);
    const double y = mc.from.y + t * hy + rho * std::sin(phi);
    const SweepPoint p = sweep.Locate(x, y);
    if (p.piece == SweepPoint::kNone) continue;
    // Skip points within a few steps of a piece boundary or near the rim:
    // the whole 5 x 5 neighbourhood (+-2 h2) must be on p's piece, at depth
    // >= r / 4 where the bounds above stay moderate.
    double delta = kInf;
    bool ok = true;
    for (int a = -2; a <= 2 && ok; ++a) {
      for (int b = -2; b <= 2 && ok; ++b) {
        const SweepPoint q = sweep.Locate(x + a * h2, y + b * h2);
        ok = q.piece == p.piece;
        delta = std::min(delta, q.depth);
      }
    }
    if (!ok || delta < 0.25 * r) continue;
    const double g = p.piece == SweepPoint::kCylinder ? g_move : 1;
    const double m3 = 3 * std::pow(r, 3) / (g * std::pow(delta, 5));
    const double m4 = 15 * std::pow(r, 4) / (g * std::pow(delta, 7));
    const SurfaceJet j = sweep.Jet(p);
    const double slope = std::hypot(j.wx, j.wy);
    const double eh = HeightRoundoff(scale, slope);
    auto f = [&](double dx, double dy) { return sweep.Height(x + dx, y + dy); };

    const double fx = (f(h1, 0) - f(-h1, 0)) / (2 * h1);
    const double fy = (f(0, h1) - f(0, -h1)) / (2 * h1);
    const double tol1 = h1 * h1 * m3 / 6 + eh / h1;
    const double f0 = f(0, 0);
    const double fxx = (f(h2, 0) - 2 * f0 + f(-h2, 0)) / (h2 * h2);
    const double fyy = (f(0, h2) - 2 * f0 + f(0, -h2)) / (h2 * h2);
    const double fxy =
        (f(h2, h2) - f(h2, -h2) - f(-h2, h2) + f(-h2, -h2)) / (4 * h2 * h2);
    const double tol2 = h2 * h2 * m4 / 12 + 4 * eh / (h2 * h2);
    const double tolxy = h2 * h2 * m4 / 3 + eh / (h2 * h2);
    const std::string where = Where(x, y) + " piece " + std::to_string(p.piece);
    EXPECT_EQ(j.w, f0) << where;
    EXPECT_NEAR(j.wx, fx, tol1) << where;
    EXPECT_NEAR(j.wy, fy, tol1) << where;
    EXPECT_NEAR(j.wxx, fxx, tol2) << where;
    EXPECT_NEAR(j.wyy, fyy, tol2) << where;
    EXPECT_NEAR(j.wxy, fxy, tolxy) << where;
    // The tolerances must stay far below the values they check, or the
    // comparison would say nothing.
    EXPECT_LT(tol1, 1e-3 * (1 + slope)) << where;
    EXPECT_LT(std::max(tol2, tolxy),
              1e-2 * (std::fabs(j.wxx) + std::fabs(j.wyy))) << where;
    ++stats.tested;
    stats.cylinder += p.piece == SweepPoint::kCylinder;
  }
  return stats;
}

TEST(BallSweepDerivativeTest, RandomMovesMatchFiniteDifferences) {
  int cylinder = 0, tested = 0;
  uint64_t seed = 100;
  for (const MoveCase& mc : RandomMoves(44)) {
    const FdStats s = CheckDerivativesByFiniteDifferences(mc, 300, ++seed);
    EXPECT_GT(s.tested, 100) << mc.name;
    cylinder += s.cylinder;
    tested += s.tested;
  }
  EXPECT_GT(cylinder, 1000);
}

TEST(BallSweepDerivativeTest, PlungesRetractsHorizontalAndPoints) {
  const std::vector<MoveCase> moves = {
      {"plunge", {1, 2, 5}, {1, 2, -3}, 2},
      {"retract", {-2, 1, -4}, {-2, 1, 3}, 5},
      {"point", {0.5, -0.25, 1}, {0.5, -0.25, 1}, 3},
      {"horizontal x", {-6, 1, -2}, {6, 1, -2}, 2.5},
      {"horizontal diagonal", {-3, -4, 0.5}, {5, 2, 0.5}, 4},
  };
  uint64_t seed = 200;
  for (const MoveCase& mc : moves) {
    const FdStats s = CheckDerivativesByFiniteDifferences(mc, 300, ++seed);
    EXPECT_GT(s.tested, 100) << mc.name;
  }
}

// Rim nodes: where the surface is vertical, heights stay finite and the
// derivatives finite and representable in float storage.
void ExpectRepresentable(const BallSweep& sweep, double x, double y,
                         const std::string& what) {
  const SweepPoint p = sweep.Locate(x, y);
  ASSERT_NE(p.piece, SweepPoint::kNone) << what << Where(x, y);
  EXPECT_TRUE(std::isfinite(p.w)) << what << Where(x, y);
  const SurfaceJet j = sweep.Jet(p);
  EXPECT_EQ(j.w, p.w) << what;
  const double d[6] = {j.w, j.wx, j.wy, j.wxx, j.wxy, j.wyy};
  for (double v : d) {
    EXPECT_TRUE(std::isfinite(v)) << what << Where(x, y);
    EXPECT_LT(std::fabs(v), 3e38) << what << Where(x, y);
    EXPECT_TRUE(std::isfinite(static_cast<float>(v))) << what;
  }
}

// RandomMoves(seed), and a point, a plunge, a level move, a plate job's
// finishing pass (0.1 mm, 900 mm from the origin) and a 300 mm move.
std::vector<MoveCase> EveryKindOfMove(uint64_t seed) {
  std::vector<MoveCase> moves = RandomMoves(seed);
  moves.push_back({"point", {1, 2, 3}, {1, 2, 3}, 2});
  moves.push_back({"plunge", {1, 2, 3}, {1, 2, -3}, 2});
  moves.push_back({"horizontal", {-3, 1, -1}, {5, 4, -1}, 1.5});
  moves.push_back(
      {"plate pass", {900.1, 873.45, -2.8941}, {900.2, 873.45, -2.8902}, 2});
  moves.push_back({"long", {-150, -20, -1}, {150, 30, -4}, 3});
  return moves;
}

// The supporting plane at a point of the surface touches it there and lies
// below it everywhere (the capsule is convex), less its slack for rounding:
// near the touching point (where the two differ by less than the rounding),
// across the footprint and off it. Moves of every kind, from 0.1 mm at 900
// mm from the origin (a plate job's finishing pass) to 300 mm long.
TEST(BallSweepSupportingPlaneTest, TouchesAndLiesBelowTheSurface) {
  std::vector<MoveCase> moves = EveryKindOfMove(43);
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> unit(0, 1);
  for (const MoveCase& mc : moves) {
    SCOPED_TRACE(mc.name);
    const BallSweep sweep(mc.from, mc.to, mc.radius);
    const double r = mc.radius;
    int planes = 0;
    for (int k = 0; k < 300; ++k) {
      const double t = unit(rng), phi = 2 * M_PI * unit(rng);
      const double rho = 1.05 * r * std::sqrt(unit(rng));  // some off it
      const double x =
          mc.from.x + t * (mc.to.x - mc.from.x) + rho * std::cos(phi);
      const double y =
          mc.from.y + t * (mc.to.y - mc.from.y) + rho * std::sin(phi);
      const std::optional<BallSweep::SupportPlane> plane =
          sweep.SupportingPlane(x, y);
      const SweepPoint at = sweep.Locate(x, y);
      if (at.piece == SweepPoint::kNone || at.depth < 0.05 * r) {
        EXPECT_FALSE(plane.has_value()) << Where(x, y);
      }
      if (!plane.has_value()) continue;
      ++planes;
      EXPECT_EQ(plane->w, sweep.Height(x, y)) << Where(x, y);
      EXPECT_GT(plane->slack, 0);
      EXPECT_LT(plane->slack, 1e-4);
      auto check = [&](double u, double v) {
        const double below =
            plane->w + plane->wx * (u - x) + plane->wy * (v - y) - plane->slack;
        EXPECT_GE(sweep.Height(u, v), below)
            << Where(x, y) << " to " << Where(u, v);
      };
      for (int m = 0; m < 60; ++m) {
        // Scales from 1e-9 mm to twice the radius, in every direction.
        const double s = 2 * r * std::pow(10.0, -9 * unit(rng));
        const double psi = 2 * M_PI * unit(rng);
        check(x + s * std::cos(psi), y + s * std::sin(psi));
      }
      // Along the move, past its ends.
      for (double f : {-0.3, 0.0, 0.5, 1.0, 1.3}) {
        check(mc.from.x + f * (mc.to.x - mc.from.x),
              mc.from.y + f * (mc.to.y - mc.from.y));
      }
    }
    // The near-vertical moves are steeper than the plane allows.
    if (mc.name.rfind("near-vertical", 0) == 0) {
      EXPECT_EQ(planes, 0);
    } else {
      EXPECT_GT(planes, 150);
    }
  }
}

// The bound is at or below the height as computed everywhere (random
// points, points within 1e-12 of a rim, points along the move and past its
// ends), +inf only where the height is, and close to the height on a
// finishing pass (else it would filter nothing).
TEST(BallHeightLowerBoundTest, AtOrBelowTheHeight) {
  std::vector<MoveCase> moves = EveryKindOfMove(44);
  moves.push_back({"short steep", {4, 4, 0}, {4.0001, 4, -0.01}, 1});
  std::mt19937_64 rng(19);
  std::uniform_real_distribution<double> unit(0, 1);
  for (const MoveCase& mc : moves) {
    SCOPED_TRACE(mc.name);
    const BallSweep sweep(mc.from, mc.to, mc.radius);
    const double r = mc.radius;
    int bounded = 0;
    const double len = std::hypot(mc.to.x - mc.from.x, mc.to.y - mc.from.y,
                                  mc.to.z - mc.from.z);
    const double inv_g =
        len > 0 ? len / std::hypot(mc.to.x - mc.from.x, mc.to.y - mc.from.y)
                : 1;
    auto check = [&](double x, double y) {
      const double h = sweep.Height(x, y);
      const double b = BallHeightLowerBound(mc.from, mc.to, r, x, y);
      EXPECT_LE(b, h) << Where(x, y);
      if (b == kInf) {
        EXPECT_EQ(h, kInf) << Where(x, y);
      }
      if (!std::isfinite(b)) return;
      ++bounded;
      // Close to it away from the rims: within its slack.
      if (sweep.Locate(x, y).depth >= 0.05 * r) {
        EXPECT_GE(b, h - 5e-6 * (1 + r + 0.1 * len) * inv_g) << Where(x, y);
      }
    };
    const double ux = mc.to.x - mc.from.x, uy = mc.to.y - mc.from.y;
    const double l = std::hypot(ux, uy);
    for (int k = 0; k < 2000; ++k) {
      const double t = -0.2 + 1.4 * unit(rng), phi = 2 * M_PI * unit(rng);
      const double rho = 1.05 * r * std::sqrt(unit(rng));
      check(mc.from.x + t * ux + rho * std::cos(phi),
            mc.from.y + t * uy + rho * std::sin(phi));
      // Within 1e-12 of the rim: across the segment, and round an end.
      const double rim = r * (1 - 1e-12 * unit(rng));
      if (l > 0) {
        const double s = std::clamp(t, 0.0, 1.0);
        check(mc.from.x + s * ux - rim * uy / l,
              mc.from.y + s * uy + rim * ux / l);
      }
      const Vec3& end = unit(rng) < 0.5 ? mc.from : mc.to;
      check(end.x + rim * std::cos(phi), end.y + rim * std::sin(phi));
    }
    for (double f : {-0.3, 0.0, 0.5, 1.0, 1.3}) {
      check(mc.from.x + f * ux, mc.from.y + f * uy);
    }
    const bool steep = mc.name.rfind("near-vertical", 0) == 0 ||
                       mc.name == "plunge" || mc.name == "short steep";
    if (steep) {
      EXPECT_EQ(bounded, 0);
    } else {
      EXPECT_GT(bounded, 2000);
    }
  }
  // Analytic: a level pass of a 2 mm ball 0.3 mm to the side (the
  // cylinder: 2 - sqrt(4 - 0.09) above the tip) and past its end (the end
  // sphere); a 30-degree ramp (the cylinder's lowest line is r / cos(30)
  // below the axis: 2 - 2 / cos(30) above the tip's line).
  const Vec3 a{0, 0, -1}, b{10, 0, -1};
  const double side = -1 + 2 - std::sqrt(4 - 0.09);
  EXPECT_NEAR(BallHeightLowerBound(a, b, 2, 5, 0.3), side, 1e-4);
  EXPECT_LT(BallHeightLowerBound(a, b, 2, 5, 0.3), side);
  EXPECT_NEAR(BallHeightLowerBound(a, b, 2, 11, 0.3),
              -1 + 2 - std::sqrt(4 - 1.09), 1e-4);
  const Vec3 c{0, 0, 0}, d{10, 0, 10 * std::tan(M_PI / 6)};
  EXPECT_NEAR(BallHeightLowerBound(c, d, 2, 5, 0),
              5 * std::tan(M_PI / 6) + 2 - 2 / std::cos(M_PI / 6), 1e-4);
}

// The nodes ShadowRows gives for `next` after `prev`, on a grid of
// spacing d about the shared centre (offset by a fraction of d), each
// checked: `next` there is +inf or above `prev` (code values, strictly),
// so it lowers no node prev was applied to. Returns how many are finite.
int64_t CheckShadowNodes(const BallSweep& prev, const BallSweep& next, double d,
                         double offset) {
  const std::optional<BallSweep::Shadow> s = next.ShadowAfter(prev);
  if (!s.has_value()) return 0;
  const double r = next.radius();
  const double x0 = s->cx - 1.2 * r + offset * d;
  const double y0 = s->cy - 1.2 * r + 0.7 * offset * d;
  const int32_t n = static_cast<int32_t>(2.4 * r / d) + 1;
  std::vector<int32_t> lo(n), hi(n);
  BallSweep::ShadowRows(*s, y0, d, 0, n, x0, 1 / d, n - 1, lo.data(),
                        hi.data());
  int64_t nodes = 0;
  for (int32_t j = 0; j < n; ++j) {
    const double y = y0 + j * d;
    for (int32_t i = lo[j]; i <= hi[j]; ++i) {
      const double x = x0 + i * d;
      const double above = next.Height(x, y), below = prev.Height(x, y);
      if (above == kInf) continue;
      EXPECT_GT(above, below) << Where(x, y);
      ++nodes;
    }
  }
  return nodes;
}

// A level pass along x continued by the next move: the shadow is the
// half-plane behind the shared centre (the previous move's cylinder is
// lower there; beyond the ball the next move is +inf), all but margins
// well under a node.
TEST(BallSweepShadowTest, ALevelPassShadowsTheHalfPlaneBehind) {
  const double r = 2, d = 0.05;
  const BallSweep prev({10, 20, -1}, {10.1, 20, -1}, r);
  const BallSweep next({10.1, 20, -1}, {10.2, 20, -1}, r);
  const std::optional<BallSweep::Shadow> s = next.ShadowAfter(prev);
  ASSERT_TRUE(s.has_value());
  // The nodes at least a node's width inside the half-plane.
  const double x0 = 10.1 - 2.4 + 0.013, y0 = 20 - 2.4 + 0.007;
  const int32_t n = static_cast<int32_t>(4.8 / d) + 1;
  int64_t want = 0;
  for (int32_t i = 0; i < n; ++i) want += n * (x0 + i * d - 10.1 < -d);
  std::vector<int32_t> lo(n), hi(n);
  BallSweep::ShadowRows(*s, y0, d, 0, n, x0, 1 / d, n - 1, lo.data(),
                        hi.data());
  int64_t got = 0;
  for (int32_t j = 0; j < n; ++j) {
    for (int32_t i = lo[j]; i <= hi[j]; ++i) {
      const double qx = x0 + i * d - 10.1, qy = y0 + j * d - 20;
      EXPECT_LT(qx, 0) << qy;
      ++got;
    }
  }
  EXPECT_GE(got, want);
  EXPECT_GT(want, 4400);  // about half of (4.8 / 0.05)^2 = 9,216
  // Inside the ball's disc (about half of pi r^2 / d^2 = 5,027).
  EXPECT_GT(CheckShadowNodes(prev, next, d, 0.3), 2400);
}

// Random turns between two moves (on, across and back along the path),
// slopes up to the limit, radii from 0.1 to 5 mm, lengths from 0.01 to
// 300 mm, 900 mm from the origin, on grids of 1/100 to 1/10 of the radius:
// at every shadowed node the next move is above the previous one.
TEST(BallSweepShadowTest, TheNextMoveIsAboveThePreviousInItsShadow) {
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> unit(0, 1);
  int64_t nodes = 0;
  int shadows = 0;
  for (int k = 0; k < 300; ++k) {
    const double r = 0.1 + 4.9 * unit(rng);
    const double base = k % 3 == 0 ? 900 : 0;
    auto step = [&](const Vec3& from, double heading) {
      const double len = std::pow(10.0, -2 + 4.5 * unit(rng));
      const double slope = k % 5 == 0 ? 19 * unit(rng) : 0.3 * unit(rng);
      const double dz = (unit(rng) < 0.5 ? -1 : 1) * slope * len;
      return Vec3{from.x + len * std::cos(heading),
                  from.y + len * std::sin(heading), from.z + dz};
    };
    const double heading = 2 * M_PI * unit(rng);
    const double turn = k % 4 == 0 ? 0 : (2 * unit(rng) - 1) * M_PI;
    const Vec3 a{base + 3 * unit(rng), base - 2 * unit(rng), -unit(rng)};
    const Vec3 b = step(a, heading);
    const Vec3 c = step(b, heading + turn);
    const BallSweep prev(a, b, r), next(b, c, r);
    const double d = r / (10 + 90 * unit(rng));
    const int64_t here = CheckShadowNodes(prev, next, d, unit(rng));
    shadows += here > 0;
    nodes += here;
  }
  EXPECT_GT(shadows, 150);
  EXPECT_GT(nodes, 100000);
}

// No shadow where the premise fails: another radius, a start one ulp off
// the previous end, a vertical or zero-length move, a move steeper than
// the limit.
TEST(BallSweepShadowTest, NoneWithoutASharedBallOrOnSteepMoves) {
  const Vec3 a{0, 0, 0}, b{1, 0, -0.1}, c{2, 0.5, -0.2};
  EXPECT_TRUE(BallSweep(b, c, 1).ShadowAfter(BallSweep(a, b, 1)).has_value());
  EXPECT_FALSE(
      BallSweep(b, c, 1.5).ShadowAfter(BallSweep(a, b, 1)).has_value());
  const Vec3 b_off{std::nextafter(1.0, 2.0), 0, -0.1};
  EXPECT_FALSE(
      BallSweep(b_off, c, 1).ShadowAfter(BallSweep(a, b, 1)).has_value());
  const Vec3 below{1, 0, -3};
  EXPECT_FALSE(
      BallSweep(b, c, 1).ShadowAfter(BallSweep({1, 0, 2}, b, 1)).has_value());
  EXPECT_FALSE(
      BallSweep(b, below, 1).ShadowAfter(BallSweep(a, b, 1)).has_value());
  EXPECT_FALSE(BallSweep(b, b, 1).ShadowAfter(BallSweep(a, b, 1)).has_value());
  const Vec3 steep{1.01, 0, 1};  // about 89 degrees
  EXPECT_FALSE(
      BallSweep(b, steep, 1).ShadowAfter(BallSweep(a, b, 1)).has_value());
}

TEST(BallSweepRimTest, SphereRimIsFinite) {
  for (double r : {1e-3, 1.0, 5.0, 1e3}) {
    // At the origin so that tip +- r and the offsets below are exact.
    const Vec3 tip{0, 0, 0.5};
    const BallSweep point(tip, tip, r);
    const BallSweep plunge({tip.x, tip.y, tip.z + 7}, tip, r);
    for (const BallSweep* s : {&point, &plunge}) {
      // Exactly on the rim: axis-aligned offsets and a 3-4-5 triangle.
      ExpectRepresentable(*s, tip.x + r, tip.y, "rim +x");
      ExpectRepresentable(*s, tip.x, tip.y - r, "rim -y");
      if (r == 5.0) ExpectRepresentable(*s, tip.x + 3, tip.y + 4, "rim 3-4-5");
      EXPECT_EQ(s->Height(tip.x + r, tip.y), tip.z + r);  // depth 0: centre
      // Within 1e-15 (relative) inside the rim, all round.
      for (int k = 0; k < 64; ++k) {
        const double phi = 2 * M_PI * k / 64;
        const double rho = r * (1 - 4e-15);
        ExpectRepresentable(*s, tip.x + rho * std::cos(phi),
                            tip.y + rho * std::sin(phi), "near rim");
      }
    }
  }
}

TEST(BallSweepRimTest, CylinderRimIsFinite) {
  // Moves along x so that the across coordinate is exactly y - y0 and the
  // rim n = +-r is hit exactly; from horizontal to nearly vertical (the
  // vertical threshold lies at a horizontal fraction of 1e-12).
  for (double r : {1e-3, 1.0, 5.0, 1e3}) {
    for (double frac : {1.0, 0.5, 1e-3, 1e-6, 1e-9, 1e-11, 2e-12}) {
      const double len = 10 * r;
      const double dxy = len * frac;
      const double dz = -len * std::sqrt(1 - frac * frac);
      // From the origin along x: the across coordinate n is exactly y.
      const Vec3 from{0, 0, 2}, to{dxy, 0, 2 + dz};
      const BallSweep sweep(from, to, r);
      const std::string what =
          "r " + std::to_string(r) + " frac " + std::to_string(frac) + " ";
      for (double fu : {0.0, 0.25, 0.5, 1.0}) {
        const double x = from.x + fu * dxy;
        ExpectRepresentable(sweep, x, from.y + r, what + "n=+r");
        ExpectRepresentable(sweep, x, from.y - r, what + "n=-r");
        ExpectRepresentable(sweep, x, from.y + r * (1 - 1e-15), what + "n<r");
        ExpectRepresentable(sweep, x, from.y - r * (1 - 1e-15), what + "n>-r");
      }
      // Random points within a few 1e-15 of the rims of all the balls.
      // Rounding the point may move it just outside (then it is uncut, which
      // is fine); every point found cut must be representable.
      std::mt19937_64 rng(static_cast<uint64_t>(r * 1000 + 1 / frac));
      std::uniform_real_distribution<double> unit(0, 1);
      int cut = 0;
      for (int k = 0; k < 200; ++k) {
        const double t = unit(rng), phi = 2 * M_PI * unit(rng);
        const double rho = r * (1 - 1e-15 * (1 + 3 * unit(rng)));
        const double x = from.x + t * dxy + rho * std::cos(phi);
        const double y = from.y + rho * std::sin(phi);
        if (sweep.Locate(x, y).piece == SweepPoint::kNone) continue;
        ++cut;
        ExpectRepresentable(sweep, x, y, what + "random rim");
      }
      EXPECT_GT(cut, 100) << what;
    }
  }
}

TEST(BallSweepRimTest, FarPointsAreUncut) {
  const BallSweep sweeps[] = {
      BallSweep({0, 0, 0}, {0, 0, 0}, 2),
      BallSweep({0, 0, 5}, {0, 0, -5}, 2),
      BallSweep({-3, 1, 0}, {4, 2, -1}, 2),
      BallSweep({-3, 1, 0}, {4, 2, 0}, 2),
  };
  const double far[][2] = {{100, 0},   {0, -50},      {-1e6, 1e6},
                           {1e200, 0}, {-1e300, 1e300}, {7, 7},
                           {-5.01, 1}, {0, 4.5}};
  for (const BallSweep& s : sweeps) {
    for (const auto& q : far) {
      EXPECT_EQ(s.Height(q[0], q[1]), kInf) << Where(q[0], q[1]);
      EXPECT_EQ(s.Locate(q[0], q[1]).piece, SweepPoint::kNone);
    }
  }
}

// Footprint: every point below the cap lies in the capsule's row span.
TEST(BallSweepFootprintTest, ContainsEveryPointBelowTheCap) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> pos(-10, 10), z(-4, 4),
      rad(0.3, 5), unit(0, 1);
  std::vector<MoveCase> moves;
  for (int k = 0; k < 24; ++k) {
    moves.push_back({"random", {pos(rng), pos(rng), z(rng)},
                     {pos(rng), pos(rng), z(rng)}, rad(rng)});
  }
  moves.push_back({"plunge", {1, 1, 5}, {1, 1, -2}, 3});
  moves.push_back({"point", {-2, 3, 0}, {-2, 3, 0}, 2});
  moves.push_back({"horizontal", {-5, -5, 0}, {5, 1, 0}, 2});
  moves.push_back({"near-vertical", {0, 0, 4}, {4e-6, 3e-6, -1}, 2});
  moves.push_back({"along y", {3, -6, -1}, {3, 6, 1}, 1.5});
  int inside = 0;
  for (const MoveCase& mc : moves) {
    SCOPED_TRACE(mc.name);
    const BallSweep sweep(mc.from, mc.to, mc.radius);
    const double r = mc.radius;
    const double low = sweep.lowest();
    // Caps below, at, and at several levels above the lowest point.
    for (double cap : {low - 1, low, low + 0.01 * r, low + 0.5 * r,
                       low + 1.5 * r, low + 20 * unit(rng)}) {
      const BallSweep::Capsule c = sweep.Footprint(cap);
      const double x0 = std::min(mc.from.x, mc.to.x) - r,
                   x1 = std::max(mc.from.x, mc.to.x) + r;
      const double y0 = std::min(mc.from.y, mc.to.y) - r,
                   y1 = std::max(mc.from.y, mc.to.y) + r;
      const int n = 300;
      for (int jy = 0; jy <= n; ++jy) {
        const double y = y0 + (y1 - y0) * jy / n;
        const Interval span = c.RowSpan(y);
        for (int ix = 0; ix <= n; ++ix) {
          const double x = x0 + (x1 - x0) * ix / n;
          if (!(sweep.Height(x, y) < cap)) continue;
          ++inside;
          ASSERT_FALSE(c.empty) << "cap " << cap << Where(x, y);
          ASSERT_FALSE(span.empty()) << "cap " << cap << Where(x, y);
          ASSERT_TRUE(x >= span.lo && x <= span.hi)
              << "cap " << cap << Where(x, y) << " span [" << span.lo << ", "
              << span.hi << "]";
          ASSERT_TRUE(c.Bounds().Contains(x, y)) << Where(x, y);
        }
      }
    }
    // Nothing reaches below the lowest point.
    EXPECT_TRUE(sweep.Footprint(low - 1).empty);
  }
  EXPECT_GT(inside, 100000);  // the check really ran
}

// The footprint is not wildly conservative: a cap at the lowest point plus
// a little gives a capsule no wider than the ball's cross-section there.
TEST(BallSweepFootprintTest, RadiusIsTheCrossSectionAtTheCap) {
  const BallSweep sweep({0, 0, 0}, {10, 0, 0}, 2);
  const BallSweep::Capsule c = sweep.Footprint(1.0);  // 1 above the tip
  ASSERT_FALSE(c.empty);
  EXPECT_NEAR(c.radius, std::sqrt(3.0), 1e-6);  // sqrt(r^2 - (r - 1)^2)
  const Interval span = c.RowSpan(0);
  EXPECT_NEAR(span.lo, -std::sqrt(3.0), 1e-6);
  EXPECT_NEAR(span.hi, 10 + std::sqrt(3.0), 1e-6);
  EXPECT_TRUE(c.RowSpan(1.8).empty());
}

// The bounds computed without building the sweep (what indexing moves
// uses) are the footprint's, bit for bit, and empty exactly when it is.
// Case k of the random footprint tests: a move between tips a and b of a
// ball of radius r, and a cap; plunges, level moves and points as well as
// general ones.
struct FootprintCase {
  Vec3 a, b;
  double r, cap;
};
FootprintCase RandomFootprintCase(std::mt19937_64& rng, int k) {
  std::uniform_real_distribution<double> u(-20, 20), rad(1e-3, 5);
  FootprintCase c;
  c.a = {u(rng), u(rng), u(rng) / 4};
  c.b = {u(rng), u(rng), u(rng) / 4};
  if (k % 5 == 1) c.b = {c.a.x, c.a.y, c.b.z};
  if (k % 5 == 2) c.b.z = c.a.z;
  if (k % 5 == 3) c.b = c.a;
  c.r = rad(rng);
  c.cap = u(rng) / 8;
  return c;
}

TEST(BallSweepFootprintTest, BoundsWithoutTheSweepAreBitIdentical) {
  std::mt19937_64 rng(17);
  int empty = 0;
  for (int k = 0; k < 20000; ++k) {
    const auto [a, b, r, cap] = RandomFootprintCase(rng, k);
    const BallSweep::Capsule c = BallSweep(a, b, r).Footprint(cap);
    const std::optional<Rect> bounds = BallSweep::FootprintBounds(a, b, r, cap);
    ASSERT_EQ(bounds.has_value(), !c.empty) << k;
    if (c.empty) {
      ++empty;
      continue;
    }
    const Rect want = c.Bounds();
    ASSERT_EQ(std::memcmp(&want, &*bounds, sizeof(Rect)), 0) << k;
  }
  EXPECT_GT(empty, 1000);  // both cases were exercised
  EXPECT_LT(empty, 19000);
}

// The distance from the segment (ax, ay)-(bx, by) to `box` (0 where they
// meet), exactly enough for the test below: two convex sets apart are
// nearest at a vertex of one of them, and the segment meets the box where
// its clip to the box (Liang-Barsky) is not empty.
double SegmentToBox(double ax, double ay, double bx, double by,
                    const Rect& box) {
  double t0 = 0, t1 = 1;
  const double dx = bx - ax, dy = by - ay;
  bool meets = true;
  for (const auto [p, q] :
       {std::pair{-dx, ax - box.x0}, std::pair{dx, box.x1 - ax},
        std::pair{-dy, ay - box.y0}, std::pair{dy, box.y1 - ay}}) {
    if (p == 0) {
      if (q < 0) meets = false;
      continue;
    }
    const double t = q / p;
    if (p < 0) t0 = std::max(t0, t);
    if (p > 0) t1 = std::min(t1, t);
  }
  if (meets && t0 <= t1) return 0;
  auto to_box = [&](double x, double y) {
    return std::hypot(std::max({box.x0 - x, x - box.x1, 0.0}),
                      std::max({box.y0 - y, y - box.y1, 0.0}));
  };
  auto to_segment = [&](double x, double y) {
    return static_cast<double>(DistanceToPath({ax, ay, 0}, {bx, by, 0}, x, y));
  };
  return std::min({to_box(ax, ay), to_box(bx, by), to_segment(box.x0, box.y0),
                   to_segment(box.x1, box.y0), to_segment(box.x1, box.y1),
                   to_segment(box.x0, box.y1)});
}

// The quick test skips only what the footprint itself misses: boxes and
// points placed all around it (beside its ends, its sides and the corners
// of its bounds), from half a millimetre inside it to a micrometre and
// more outside. It skips boxes at the corners of the bounds, which those
// meet and the footprint does not.
TEST(BallSweepFootprintTest, SurelyMissesOnlyWhatTheFootprintMisses) {
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> unit(0, 1);
  int skipped = 0, close = 0, in_bounds = 0;
  for (int k = 0; k < 50000; ++k) {
    const auto [a, b, r, cap] = RandomFootprintCase(rng, k);
    const Cutter ball = Cutter::Ball(r);
    const Capsule c = FootprintCapsule(a, b, ball, cap);
    const std::optional<Rect> f = FootprintBounds(a, b, ball, cap);
    // The segment and radius to place around: the footprint's, or the
    // tips' and the ball's where it is empty.
    const double ax = c.empty ? a.x : c.x0, ay = c.empty ? a.y : c.y0;
    const double bx = c.empty ? b.x : c.x1, by = c.empty ? b.y : c.y1;
    const double rho = c.empty ? r : c.radius;
    // A point at rho + gap from the segment's end or middle, in a random
    // direction (gap 10^-e mm, e in [0, 6], or -0.5: inside); every other
    // case a box from there away from the segment.
    const double gap = unit(rng) < 0.2 ? -0.5 : std::pow(10.0, -6 * unit(rng));
    const double size = k % 2 == 0 ? 0 : unit(rng);
    const double t = k % 3 == 0 ? 0 : (k % 3 == 1 ? 1 : 0.5);
    const double theta = 2 * M_PI * unit(rng);
    const double ux = std::cos(theta), uy = std::sin(theta);
    const double px = ax + t * (bx - ax) + (rho + gap) * ux;
    const double py = ay + t * (by - ay) + (rho + gap) * uy;
    const Rect box{ux < 0 ? px - size : px, uy < 0 ? py - size : py,
                   ux < 0 ? px : px + size, uy < 0 ? py : py + size};
    if (!FootprintSurelyMisses(a, b, ball, box, cap)) continue;
    ++skipped;
    if (gap < 1e-4) ++close;
    if (f.has_value() && f->Intersects(box)) ++in_bounds;
    if (c.empty) continue;  // nothing below cap to meet
    ASSERT_GT(SegmentToBox(c.x0, c.y0, c.x1, c.y1, box), c.radius)
        << k << ": skipped a box the footprint meets";
  }
  EXPECT_GT(skipped, 10000);  // it does skip, some within 0.1 um
  EXPECT_GT(close, 100);
  EXPECT_GT(in_bounds, 1000);  // and at the corners of the bounds
  // Other shapes: never sure.
  EXPECT_FALSE(FootprintSurelyMisses({0, 0, 0}, {1, 0, 0}, Cutter::Flat(1),
                                     {50, 50, 60, 60}, 0));
}

}  // namespace
}  // namespace swarf
