// Every cutter shape (issue 16 part 4) through the public seam only
// (core/cutter/cutter.h, core/cutter/sweep.h):
// - analytic truths: a flat pocket's floor and walls, a ramp's floor, grooves
//   whose cross-section is the tool's profile (bull-nose band + corner, V
//   flanks at the half angle, tapered ball), plunge craters; every
//   derivative against the derivative of the analytic surface;
// - random points of every shape and move type against the brute-force
//   reference of tests/cutter_reference.h (heights to 1e-9 mm, derivatives
//   to 1e-6 relative away from creases and walls);
// - the Sweep contract (batch heights, jet heights, lowest(), footprint);
// - points on the seams (end planes, join circles, walls, the axis), where
//   random points never fall: jets that are one-sided limits or harmless;
// - degenerate shapes against the shapes they degenerate to (1e-12);
// - ValidateCutter's messages, ProfileHeight and FootprintRadius.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/cutter/cutter.h"
#include "core/cutter/sweep.h"
#include "core/move_list.h"
#include "core/stock.h"
#include "core/workpiece.h"
#include "gtest/gtest.h"
#include "tests/cutter_reference.h"
#include "tests/tile_copy.h"

namespace swarf {
namespace {

using ::swarf::testing::ArcSection;
using ::swarf::testing::CheckSeamJet;
using ::swarf::testing::DistanceToPath;
using ::swarf::testing::GrooveJet;
using ::swarf::testing::HeightRoundoff;
using ::swarf::testing::LD;
using ::swarf::testing::ProfileJoin;
using ::swarf::testing::Radians;
using ::swarf::testing::ReferenceDerivatives;
using ::swarf::testing::ReferenceHeight;
using ::swarf::testing::ReferenceJet;
using ::swarf::testing::ReferenceProfile;
using ::swarf::testing::ReferenceSection;
using ::swarf::testing::RevolutionJet;
using ::swarf::testing::Section;

constexpr double kInfinity = std::numeric_limits<double>::infinity();

// The shapes under test, all 6 mm in diameter as a CAM user would pick
// them. The ball is here too: it has its own exact sweep on main, so its
// rows check the reference itself.
struct Shape {
  const char* name;
  Cutter cutter;
};
const Shape kShapes[] = {
    {"ball", Cutter::Ball(3)},
    {"flat", Cutter::Flat(3)},
    {"bull", Cutter::BullNose(3, 1)},
    {"vbit", Cutter::Cone(3, 45, 0)},          // 90-degree V-bit, sharp
    {"chamfer", Cutter::Cone(3, 30, 0.4)},     // 60 degrees, 0.8 mm flat tip
    {"taper", Cutter::TaperedBall(3, 0.5, 10)},  // 1 mm ball, 20-degree taper
    {"bull_flat", Cutter::BullNose(3, 0)},   // swept as the flat end
    {"bull_ball", Cutter::BullNose(3, 3)},   // swept as the ball
};

// Straight moves of every kind (tool tips; coordinates off any symmetry).
struct MoveCase {
  const char* name;
  Vec3 from, to;
};
const MoveCase kMoves[] = {
    {"horizontal", {1.3, 2.1, -1}, {8.2, 6.4, -1}},
    {"ramp", {1.3, 2.1, 0}, {9.1, -0.7, -1.2}},
    {"ramp_up", {9.1, -0.7, -1.2}, {1.3, 2.1, 0}},
    {"steep_ramp", {1.3, 2.1, 0}, {2.2, 2.6, -4}},
    {"plunge", {1.3, 2.1, 3}, {1.3, 2.1, -2}},
    {"retract", {1.3, 2.1, -2}, {1.3, 2.1, 3}},
    {"zero_length", {1.3, 2.1, -2}, {1.3, 2.1, -2}},
};

std::string At(double x, double y) {
  return "at (" + std::to_string(x) + ", " + std::to_string(y) + ")";
}

double D(LD v) { return static_cast<double>(v); }

// A jet against the truth: w to `w_tol` mm, each derivative to
// rel * (|truth| + unit), unit 1 for slopes and 1/R for curvatures (so an
// entry that is zero is held to rel on the tool's own scale).
void ExpectJetNear(const SurfaceJet& got, const ReferenceJet& want,
                   double w_tol, double rel, double radius,
                   const std::string& where) {
  SCOPED_TRACE(where);
  auto tol = [&](LD v, double unit) { return rel * (std::fabs(D(v)) + unit); };
  EXPECT_NEAR(got.w, D(want.w), w_tol);
  EXPECT_NEAR(got.wx, D(want.wx), tol(want.wx, 1));
  EXPECT_NEAR(got.wy, D(want.wy), tol(want.wy, 1));
  EXPECT_NEAR(got.wxx, D(want.wxx), tol(want.wxx, 1 / radius));
  EXPECT_NEAR(got.wxy, D(want.wxy), tol(want.wxy, 1 / radius));
  EXPECT_NEAR(got.wyy, D(want.wyy), tol(want.wyy, 1 / radius));
}

// A straight move along unit direction (cos phi, sin phi) in XY.
struct Path {
  Vec3 a;
  double phi_deg, length, drop;  // drop: z(a) - z(b)
  double ex() const { return std::cos(phi_deg * std::numbers::pi / 180); }
  double ey() const { return std::sin(phi_deg * std::numbers::pi / 180); }
  Vec3 b() const { return {a.x + length * ex(), a.y + length * ey(), a.z - drop}; }
  // The point `along` mm along the path and `d` mm to its left.
  void Point(double along, double d, double* x, double* y) const {
    *x = a.x + along * ex() - d * ey();
    *y = a.y + along * ey() + d * ex();
  }
};

// ---------------------------------------------------------------------------
// Analytic truths.

// What the analytic truths examine: the sweep under test, or the
// brute-force reference of tests/cutter_reference.h (so that the reference
// and the truths written out by hand check each other, today already).
struct Surface {
  std::function<double(double, double)> height;
  std::function<SurfaceJet(double, double)> jet;
  double w_tol;   // mm
  double rel;     // derivatives, relative (see ExpectJetNear)
  double margin;  // mm kept from the profile's joins and the pieces' seams
};

// The sweep's formulas are a handful of operations on well-conditioned
// points (kept 1% inside the rims): 1e-10 relative is far above their
// rounding and far below any formula error; heights to 1e-12 of the
// coordinates' size.
constexpr double kAnalyticRel = 1e-10;

Surface OfSweep(const Vec3& from, const Vec3& to, const Cutter& c) {
  auto sweep = std::make_shared<const Sweep>(from, to, c);
  return {[sweep](double x, double y) { return sweep->Height(x, y); },
          [sweep](double x, double y) { return sweep->JetAt(x, y); },
          3e-11, kAnalyticRel, 1e-6};
}

// The reference's derivatives are finite differences over +-2 um: kept
// 5 um from the seams, to 1e-6 relative.
Surface OfReference(const Vec3& from, const Vec3& to, const Cutter& c) {
  return {[=](double x, double y) {
            return D(ReferenceHeight(c, from, to, x, y).w);
          },
          [=](double x, double y) {
            const ReferenceJet j = ReferenceDerivatives(c, from, to, x, y);
            return SurfaceJet{D(j.w),   D(j.wx),  D(j.wy),
                              D(j.wxx), D(j.wxy), D(j.wyy)};
          },
          1e-12, 1e-6, 5e-3};
}

using SurfaceOf = Surface (*)(const Vec3&, const Vec3&, const Cutter&);

// A flat end mill pocketing at z = -2: the floor is at exactly -2 with zero
// derivatives everywhere within `radius` of the path, and the wall stands at
// exactly `radius` from it: finite 1e-9 mm inside, +inf 1e-9 mm outside,
// along the sides and round the end caps.
TEST(FlatEndTest, PocketFloorAtTheDepthWallAtTheRadius) {
  const double r = 3;
  const Cutter flat = Cutter::Flat(r);
  const Path path{{10.3, 9.7, -2}, 30, 20, 0};
  const Sweep sweep(path.a, path.b(), flat);
  int floor_points = 0;
  for (int i = 0; i <= 40; ++i) {
    for (int k = 0; k <= 40; ++k) {
      const double along = -r + (path.length + 2 * r) * i / 40.0;
      const double d = -r + 2 * r * k / 40.0;
      double x, y;
      path.Point(along, d, &x, &y);
      if (D(DistanceToPath(path.a, path.b(), x, y)) > 0.999 * r) continue;
      ++floor_points;
      EXPECT_EQ(sweep.Height(x, y), -2) << At(x, y);
      const SurfaceJet j = sweep.JetAt(x, y);
      EXPECT_EQ(j.w, -2) << At(x, y);
      for (double v : {j.wx, j.wy, j.wxx, j.wxy, j.wyy}) {
        EXPECT_NEAR(v, 0, 1e-12) << At(x, y);
      }
    }
  }
  EXPECT_GT(floor_points, 1000);
  // The wall: round the whole capsule, 1e-9 mm either side.
  const double eps = 1e-9;
  for (int k = 0; k < 72; ++k) {
    const double th = (k + 0.5) * std::numbers::pi / 36;
    for (double along : {-1.0, 0.0, 7.3, 20.0, 21.0}) {
      // On the sides (0 <= along <= L) the wall is at d = +-r; beyond the
      // ends it is the circle of radius r round the end tip.
      double x_in, y_in, x_out, y_out;
      if (along >= 0 && along <= path.length) {
        const double side = std::cos(th) > 0 ? 1 : -1;
        path.Point(along, side * (r - eps), &x_in, &y_in);
        path.Point(along, side * (r + eps), &x_out, &y_out);
      } else {
        const double base = along < 0 ? 0 : path.length;
        // Directions pointing away from the path only.
        const double c = std::cos(th), s = std::sin(th);
        if ((along < 0) != (c < 0)) continue;
        path.Point(base + (r - eps) * c, (r - eps) * s, &x_in, &y_in);
        path.Point(base + (r + eps) * c, (r + eps) * s, &x_out, &y_out);
      }
      EXPECT_EQ(sweep.Height(x_in, y_in), -2) << At(x_in, y_in);
      EXPECT_EQ(sweep.Height(x_out, y_out), kInfinity) << At(x_out, y_out);
    }
  }
}

// A flat end plunging 5.5 mm: a flat-bottomed hole, floor at the final tip,
// wall at the radius.
TEST(FlatEndTest, PlungeDrillsAFlatBottomedHole) {
  const double r = 3;
  const Sweep sweep({20.1, 30.2, 2}, {20.1, 30.2, -3.5}, Cutter::Flat(r));
  EXPECT_EQ(sweep.lowest(), -3.5);
  for (int k = 0; k < 36; ++k) {
    const double th = k * std::numbers::pi / 18;
    for (double rho : {0.0, 0.7, 1.9, 2.9, r - 1e-9}) {
      const double x = 20.1 + rho * std::cos(th), y = 30.2 + rho * std::sin(th);
      EXPECT_EQ(sweep.Height(x, y), -3.5) << At(x, y);
    }
    const double x = 20.1 + (r + 1e-9) * std::cos(th);
    const double y = 30.2 + (r + 1e-9) * std::sin(th);
    EXPECT_EQ(sweep.Height(x, y), kInfinity) << At(x, y);
  }
}

// The analytic truths, each run on the sweep and on the reference.
class TruthTest : public ::testing::TestWithParam<std::tuple<int, bool>> {
 protected:
  const Cutter& cutter() const { return kShapes[std::get<0>(GetParam())].cutter; }
  double radius() const { return cutter().radius; }
  Surface Of(const Vec3& from, const Vec3& to) const {
    return std::get<1>(GetParam()) ? OfReference(from, to, cutter())
                                   : OfSweep(from, to, cutter());
  }
};

// Whether rho lies within `margin` of a radius where the profile changes
// formula (its derivatives jump there: a crease or a curvature step), or
// of the axis.
bool NearJoin(const Cutter& c, double rho, double margin) {
  return std::fabs(rho - D(ProfileJoin(c))) < margin || rho < margin;
}

// A flat end ramping down at slope s (dz per mm along the path): the floor
// is set by the leading rim of the disk, so at `along` mm along the path
// and d mm across it w = z(a) + s (along + sqrt(R^2 - d^2)): it falls at
// exactly s along the path and curves up towards the sides.
// In the (along, d) frame: w_a = s, w_d = -s d / q, w_dd = -s R^2 / q^3,
// q = sqrt(R^2 - d^2), w_aa = w_ad = 0.
void CheckFlatRamp(SurfaceOf of) {
  const double r = 3;
  const Path path{{5.2, 4.9, -0.5}, 20, 20, 2};  // s = -0.1
  const double s = -path.drop / path.length;
  const Surface surf = of(path.a, path.b(), Cutter::Flat(r));
  const LD ex = path.ex(), ey = path.ey(), nx = -ey, ny = ex;
  int n = 0;
  for (double along = 1; along <= path.length - r - 1; along += 0.83) {
    for (double d = -0.99 * r; d <= 0.99 * r; d += 0.99 * r / 10) {
      double x, y;
      path.Point(along, d, &x, &y);
      const LD q = std::sqrt(LD{r} * r - LD{d} * d);
      const LD wa = s, wd = -s * d / q, wdd = -s * LD{r} * r / (q * q * q);
      ReferenceJet want;
      want.w = LD{path.a.z} + s * (along + q);
      want.wx = wa * ex + wd * nx;
      want.wy = wa * ey + wd * ny;
      want.wxx = wdd * nx * nx;
      want.wxy = wdd * nx * ny;
      want.wyy = wdd * ny * ny;
      ExpectJetNear(surf.jet(x, y), want, surf.w_tol, surf.rel, r, At(x, y));
      EXPECT_NEAR(surf.height(x, y), D(want.w), surf.w_tol) << At(x, y);
      ++n;
    }
  }
  EXPECT_GT(n, 300);
}
TEST(FlatEndTest, RampFloorIsTheLeadingRim) { CheckFlatRamp(OfSweep); }
TEST(ReferenceSelfTest, FlatRampFloorIsTheLeadingRim) {
  CheckFlatRamp(OfReference);
}

// A horizontal groove at z0 along a diagonal: across it, the surface IS the
// tool's profile (written out by hand in ReferenceSection): a flat band of
// R - rc then the torus corner's circle for the bull-nose, straight flanks
// at the half angle for a V-bit, the ball then its tangent flanks for a
// tapered ball. Along it nothing changes: w_along = 0, and the Hessian is
// f'' n n^T. Beyond the ends: the end tool's surface of revolution.
TEST_P(TruthTest, HorizontalGrooveCrossSectionIsTheProfile) {
  const double r = radius();
  const Path path{{10.3, 9.7, -1.5}, 30, 20, 0};
  const Surface surf = Of(path.a, path.b());
  const LD nx = -path.ey(), ny = path.ex();
  int n = 0;
  // Not at the ends themselves: there the groove meets the end tools'
  // surfaces of revolution (same slope, another curvature).
  for (double along : {0.4, 5.1, 10.0, 14.9, 19.6}) {
    for (int k = -40; k <= 40; ++k) {
      const double d = 0.99 * r * (k + 0.31) / 40.5;
      if (NearJoin(cutter(), std::fabs(d), surf.margin)) continue;
      double x, y;
      path.Point(along, d, &x, &y);
      const Section sec = ReferenceSection(cutter(), std::fabs(LD{d}));
      const ReferenceJet want = GrooveJet(sec, path.a.z, d, nx, ny);
      ExpectJetNear(surf.jet(x, y), want, surf.w_tol, surf.rel, r,
                    At(x, y) + " d=" + std::to_string(d));
      EXPECT_NEAR(surf.height(x, y), D(want.w), surf.w_tol) << At(x, y);
      ++n;
    }
  }
  // Round the end caps.
  for (int k = 0; k < 24; ++k) {
    const double th = (k + 0.5) * std::numbers::pi / 24 - std::numbers::pi / 2;
    for (double rho : {0.13 * r, 0.42 * r, 0.71 * r, 0.96 * r}) {
      if (NearJoin(cutter(), rho, surf.margin)) continue;
      for (int end = 0; end < 2; ++end) {
        const double sign = end == 0 ? -1 : 1;
        const double base = end == 0 ? 0 : path.length;
        double x, y;
        path.Point(base + sign * rho * std::cos(th), rho * std::sin(th), &x, &y);
        const Vec3 c = end == 0 ? path.a : path.b();
        const ReferenceJet want =
            RevolutionJet(ReferenceSection(cutter(), rho), c.z, LD{x} - c.x,
                          LD{y} - c.y);
        ExpectJetNear(surf.jet(x, y), want, surf.w_tol, surf.rel, r,
                      At(x, y) + " end cap");
        ++n;
      }
    }
  }
  EXPECT_GT(n, 500);
}

// A plunge, a retract and a move of zero length all leave the crater of the
// lowest tool: w = z_low + f(r), a surface of revolution of the profile.
TEST_P(TruthTest, PlungeRetractAndDwellLeaveTheToolsCrater) {
  const double r = radius();
  const Vec3 c{20.1, 30.2, -2.5};
  const Vec3 above{c.x, c.y, 4};
  for (const Surface& surf : {Of(above, c), Of(c, above), Of(c, c)}) {
    for (int k = 0; k < 16; ++k) {
      const double th = (k + 0.2) * std::numbers::pi / 8;
      for (double rho : {0.05, 0.31, 0.47, 0.9, 1.6, 2.05, 2.5, 2.97}) {
        if (NearJoin(cutter(), rho, surf.margin)) continue;
        const double x = c.x + rho * std::cos(th), y = c.y + rho * std::sin(th);
        const ReferenceJet want = RevolutionJet(
            ReferenceSection(cutter(), rho), c.z, LD{x} - c.x, LD{y} - c.y);
        ExpectJetNear(surf.jet(x, y), want, surf.w_tol, surf.rel, r, At(x, y));
        EXPECT_NEAR(surf.height(x, y), D(want.w), surf.w_tol) << At(x, y);
      }
      const double x = c.x + 1.001 * r * std::cos(th);
      const double y = c.y + 1.001 * r * std::sin(th);
      EXPECT_EQ(surf.height(x, y), kInfinity) << At(x, y);
    }
  }
}

// A ramp's floor falls at exactly the ramp's slope along the path, for
// every shape: away from the ends, moving the point by delta along the path
// moves the covering part of the move by delta, so
// w(p + delta e) = w(p) + s delta, hence w_e = s, w_ee = 0, w_en = 0
// (e along the path, n across it). A gentle and a steep ramp.
TEST_P(TruthTest, RampFloorFallsAtTheRampSlope) {
  const double r = radius();
  for (double drop : {2.0, 12.0}) {
    const Path path{{5.2, 4.9, -0.5}, 20, 20, drop};
    const double s = -drop / path.length;
    const Surface surf = Of(path.a, path.b());
    const double ex = path.ex(), ey = path.ey(), nx = -ey, ny = ex;
    int n = 0;
    for (double along = r + 1; along <= path.length - r - 1.5; along += 1.1) {
      for (double d = -0.9 * r; d <= 0.9 * r; d += 0.9 * r / 7.3) {
        double x, y, x2, y2;
        path.Point(along, d, &x, &y);
        path.Point(along + 0.5, d, &x2, &y2);
        const std::string where = At(x, y) + " drop " + std::to_string(drop);
        EXPECT_NEAR(surf.height(x2, y2) - surf.height(x, y), s * 0.5,
                    3 * surf.w_tol)
            << where;
        const SurfaceJet j = surf.jet(x, y);
        const double slope = std::hypot(j.wx, j.wy);
        if (slope > 100) continue;  // a wall: clamped derivatives
        const double we = j.wx * ex + j.wy * ey;
        const double wee = j.wxx * ex * ex + 2 * j.wxy * ex * ey + j.wyy * ey * ey;
        const double wen = j.wxx * ex * nx + j.wxy * (ex * ny + ey * nx) +
                           j.wyy * ey * ny;
        const double curv = std::fabs(j.wxx) + std::fabs(j.wxy) + std::fabs(j.wyy);
        EXPECT_NEAR(we, s, surf.rel * (1 + slope)) << where;
        EXPECT_NEAR(wee, 0, surf.rel * (curv + 1 / r)) << where;
        EXPECT_NEAR(wen, 0, surf.rel * (curv + 1 / r)) << where;
        ++n;
      }
    }
    EXPECT_GT(n, 100);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, TruthTest,
    ::testing::Combine(::testing::Range(0, static_cast<int>(std::size(kShapes))),
                       ::testing::Bool()),
    [](const ::testing::TestParamInfo<std::tuple<int, bool>>& info) {
      return std::string(kShapes[std::get<0>(info.param)].name) +
             (std::get<1>(info.param) ? "_reference" : "_sweep");
    });

class ShapeTest : public ::testing::TestWithParam<int> {
 protected:
  const Cutter& cutter() const { return kShapes[GetParam()].cutter; }
};

// The V-groove's flanks are straight at the half angle from the axis,
// measured from heights alone: atan(delta d / delta w) = half angle.
TEST(ConeTest, VGrooveFlanksStandAtTheHalfAngle) {
  for (const Cutter& c : {Cutter::Cone(3, 45, 0), Cutter::Cone(3, 30, 0.4),
                          Cutter::Cone(4, 10, 1)}) {
    SCOPED_TRACE(CutterToString(c));
    const Path path{{10.3, 9.7, -1.5}, 30, 20, 0};
    const Sweep sweep(path.a, path.b(), c);
    for (double side : {-1.0, 1.0}) {
      double x1, y1, x2, y2;
      const double d1 = c.tip_radius + 0.1, d2 = 0.98 * c.radius;
      path.Point(7.7, side * d1, &x1, &y1);
      path.Point(7.7, side * d2, &x2, &y2);
      const double dw = sweep.Height(x2, y2) - sweep.Height(x1, y1);
      EXPECT_NEAR(std::atan((d2 - d1) / dw) * 180 / std::numbers::pi,
                  c.half_angle_deg, 1e-9);
      // Inside the flat tip: the tip's depth.
      double x0, y0;
      path.Point(7.7, side * 0.5 * c.tip_radius, &x0, &y0);
      EXPECT_NEAR(sweep.Height(x0, y0), -1.5, 1e-12);
    }
  }
}

// The tapered ball's groove: the ball tip's circle, then flanks tangent to
// it (equal slopes cot a on both sides of the join) at the taper angle.
TEST(TaperedBallTest, GrooveIsTheBallThenTangentFlanks) {
  const Cutter c = Cutter::TaperedBall(3, 0.5, 10);
  const Path path{{10.3, 9.7, -1.5}, 30, 20, 0};
  const Sweep sweep(path.a, path.b(), c);
  const LD a = Radians(c.half_angle_deg);
  const LD join = LD{c.tip_radius} * std::cos(a);
  const LD cot = std::cos(a) / std::sin(a);
  const LD nx = -path.ey(), ny = path.ex();
  for (double side : {-1.0, 1.0}) {
    for (double d : {0.0, 0.2, 0.4, D(join) - 1e-4, D(join) + 1e-4, 1.0, 2.0,
                     2.95}) {
      double x, y;
      path.Point(11.1, side * d, &x, &y);
      // Ball: 0.5 - sqrt(0.25 - d^2); flank: from the tangent point
      // (rb cos a, rb (1 - sin a)) at cot a.
      const LD rb = c.tip_radius;
      const Section sec =
          d <= join ? ArcSection(rb, 0, d)
                    : Section{rb * (1 - std::sin(a)) + (d - join) * cot, cot, 0};
      ExpectJetNear(sweep.JetAt(x, y), GrooveJet(sec, -1.5, side * d, nx, ny),
                    1e-12 * 30, 1e-9, c.radius, At(x, y));
    }
  }
  // Tangency: delta inside the join the ball's slope is below cot a by
  // at most its curvature there, rb^2 / (rb sin a)^3, times delta; delta
  // outside the flank's is cot a.
  const double delta = 1e-7;
  const double curvature = D(LD{c.tip_radius} * c.tip_radius /
                             std::pow(LD{c.tip_radius} * std::sin(a), 3));
  double xi, yi, xo, yo;
  path.Point(11.1, D(join) - delta, &xi, &yi);
  path.Point(11.1, D(join) + delta, &xo, &yo);
  const SurfaceJet ji = sweep.JetAt(xi, yi), jo = sweep.JetAt(xo, yo);
  EXPECT_NEAR(std::hypot(ji.wx, ji.wy), D(cot), 1.01 * curvature * delta);
  EXPECT_NEAR(std::hypot(jo.wx, jo.wy), D(cot), 1e-12 * D(cot));
}

// ---------------------------------------------------------------------------
// Every shape and move type against the brute-force reference.

class ReferenceTest
    : public ::testing::TestWithParam<std::tuple<int, int>> {
 protected:
  const Cutter& cutter() const { return kShapes[std::get<0>(GetParam())].cutter; }
  const MoveCase& move() const { return kMoves[std::get<1>(GetParam())]; }
  Sweep MakeSweep() const { return Sweep(move().from, move().to, cutter()); }
  // Random points over the footprint's box, 10% beyond.
  std::vector<std::pair<double, double>> Points(int n, uint64_t seed) const {
    const double r = 1.1 * cutter().radius;
    const Vec3& a = move().from;
    const Vec3& b = move().to;
    std::mt19937_64 rng(seed + 1000 * std::get<0>(GetParam()) +
                        std::get<1>(GetParam()));
    std::uniform_real_distribution<double> ux(std::min(a.x, b.x) - r,
                                              std::max(a.x, b.x) + r);
    std::uniform_real_distribution<double> uy(std::min(a.y, b.y) - r,
                                              std::max(a.y, b.y) + r);
    std::vector<std::pair<double, double>> pts(n);
    for (auto& p : pts) p = {ux(rng), uy(rng)};
    return pts;
  }
  // |grad w| of the reference at (x, y), from one-sided differences at
  // 1e-6 mm; +inf next to a wall (a neighbour is off the surface).
  double ReferenceSlope(double x, double y, LD w) const {
    const double h = 1e-6;
    double slope = 0;
    for (auto [dx, dy] : {std::pair{h, 0.0}, {-h, 0.0}, {0.0, h}, {0.0, -h}}) {
      const LD v = ReferenceHeight(cutter(), move().from, move().to, x + dx, y + dy).w;
      slope = std::max(slope, D(std::fabs(v - w)) / h);
    }
    return slope;
  }
};

// Heights to 1e-9 mm wherever the surface is not a wall (where a height is
// only as exact as the point's coordinates: there the bound grows with the
// slope, see HeightRoundoff); +inf exactly where the reference is, but for
// points within 1e-9 mm of the footprint's edge.
TEST_P(ReferenceTest, HeightsMatchTheBruteForce) {
  const Sweep sweep = MakeSweep();
  const double r = cutter().radius;
  int compared = 0;
  for (auto [x, y] : Points(400, 1)) {
    const LD want = ReferenceHeight(cutter(), move().from, move().to, x, y).w;
    const double got = sweep.Height(x, y);
    if (std::isinf(want) || std::isinf(got)) {
      if (std::isinf(want) != std::isinf(got)) {
        EXPECT_NEAR(D(DistanceToPath(move().from, move().to, x, y)), r, 1e-9)
            << At(x, y) << " got " << got << " want " << D(want);
      }
      continue;
    }
    const double slope = ReferenceSlope(x, y, want);
    if (std::isinf(slope)) continue;  // on a wall
    EXPECT_NEAR(got, D(want), 1e-9 + HeightRoundoff(20, slope))
        << At(x, y) << " slope " << slope;
    ++compared;
  }
  EXPECT_GT(compared, 150);
}

// Derivatives to 1e-6 relative (to |value| + unit, see ExpectJetNear) at
// random points of the surface that are at least 2 um from any crease,
// curvature jump or wall (where the reference's finite differences at two
// step sizes agree) and not steeper than 100 (the rim clamp's domain).
TEST_P(ReferenceTest, DerivativesMatchFiniteDifferences) {
  const Sweep sweep = MakeSweep();
  int compared = 0, skipped = 0;
  for (auto [x, y] : Points(120, 2)) {
    if (std::isinf(ReferenceHeight(cutter(), move().from, move().to, x, y).w)) {
      continue;
    }
    const ReferenceJet want =
        ReferenceDerivatives(cutter(), move().from, move().to, x, y);
    if (!want.smooth || std::hypot(D(want.wx), D(want.wy)) > 100) {
      ++skipped;
      continue;
    }
    ExpectJetNear(sweep.JetAt(x, y), want, 1e-9, 1e-6, cutter().radius,
                  At(x, y));
    ++compared;
  }
  RecordProperty("skipped", skipped);
  EXPECT_GT(compared, 30) << skipped << " skipped";
}

// The Sweep contract (core/cutter/sweep.h): Heights bit-identical to
// Height, JetAt's w bit-identical to Height (zeros off the surface),
// lowest() the lowest tip, and the footprint below a cap covering every
// point whose height is below the cap.
TEST_P(ReferenceTest, SweepContract) {
  const Sweep sweep = MakeSweep();
  EXPECT_EQ(sweep.lowest(), std::min(move().from.z, move().to.z));
  const auto pts = Points(256, 3);
  std::vector<double> xs, ys, batch(pts.size());
  for (auto [x, y] : pts) {
    xs.push_back(x);
    ys.push_back(y);
  }
  sweep.Heights(xs.data(), ys.data(), static_cast<int32_t>(pts.size()),
                batch.data());
  for (size_t k = 0; k < pts.size(); ++k) {
    const double h = sweep.Height(xs[k], ys[k]);
    const SurfaceJet j = sweep.JetAt(xs[k], ys[k]);
    EXPECT_EQ(batch[k], h) << At(xs[k], ys[k]);
    if (std::isinf(h)) {
      EXPECT_EQ(j.w, h);
      continue;
    }
    EXPECT_EQ(j.w, h) << At(xs[k], ys[k]);
    EXPECT_GE(h, sweep.lowest());
    for (double cap : {h + 1e-6, h + 0.5}) {
      const Capsule c = sweep.Footprint(cap);
      ASSERT_FALSE(c.empty) << At(xs[k], ys[k]) << " cap " << cap;
      const Interval span = c.RowSpan(ys[k]);
      EXPECT_TRUE(!span.empty() && span.lo <= xs[k] && xs[k] <= span.hi)
          << At(xs[k], ys[k]) << " height " << h << " outside the footprint "
          << "below " << cap;
    }
  }
}

// FootprintCapsule and FootprintBounds, which do not build the sweep, give
// the sweep's own footprint bit for bit, at every cap (above the move, at
// its tips, through it, below it), and FootprintCapsuleEnds its ends and
// radius (its direction left 0); SweepLowest its lowest height.
TEST_P(ReferenceTest, FootprintWithoutTheSweep) {
  const Sweep sweep = MakeSweep();
  const MoveCase& m = move();
  EXPECT_EQ(SweepLowest(m.from, m.to, cutter()), sweep.lowest());
  const double lo = std::min(m.from.z, m.to.z);
  const double hi = std::max(m.from.z, m.to.z);
  for (double cap : {lo - 1, lo, 0.5 * (lo + hi), hi, hi + 0.1, hi + 50}) {
    const Capsule a = sweep.Footprint(cap);
    const Capsule b = FootprintCapsule(m.from, m.to, cutter(), cap);
    const Capsule e = FootprintCapsuleEnds(m.from, m.to, cutter(), cap);
    ASSERT_EQ(a.empty, b.empty) << "cap " << cap;
    ASSERT_EQ(a.empty, e.empty) << "cap " << cap;
    const std::optional<Rect> r = FootprintBounds(m.from, m.to, cutter(), cap);
    ASSERT_EQ(r.has_value(), !a.empty) << "cap " << cap;
    if (a.empty) continue;
    EXPECT_EQ(a.x0, b.x0);
    EXPECT_EQ(a.y0, b.y0);
    EXPECT_EQ(a.x1, b.x1);
    EXPECT_EQ(a.y1, b.y1);
    EXPECT_EQ(a.radius, b.radius);
    EXPECT_EQ(a.ux, b.ux);
    EXPECT_EQ(a.uy, b.uy);
    EXPECT_EQ(a.length, b.length);
    EXPECT_EQ(a.inv_ux, b.inv_ux);
    EXPECT_EQ(a.inv_uy, b.inv_uy);
    EXPECT_EQ(a.x0, e.x0);
    EXPECT_EQ(a.y0, e.y0);
    EXPECT_EQ(a.x1, e.x1);
    EXPECT_EQ(a.y1, e.y1);
    EXPECT_EQ(a.radius, e.radius);
    EXPECT_EQ(e.ux, 0.0);
    EXPECT_EQ(e.uy, 0.0);
    EXPECT_EQ(e.length, 0.0);
    const Rect ab = a.Bounds();
    EXPECT_EQ(r->x0, ab.x0);
    EXPECT_EQ(r->y0, ab.y0);
    EXPECT_EQ(r->x1, ab.x1);
    EXPECT_EQ(r->y1, ab.y1);
  }
}

// Points ON the seams, where random points never fall but grid nodes with
// round coordinates do: the ends' planes, the profile's join circles, the
// walls, the axis. There the jet must be a one-sided limit of the jets
// around, or at least harmless (CheckSeamJet): a patch built from anything
// else (a wrong sign at a wall, a degenerate solve at a join) digs far
// below the surface.
TEST_P(ReferenceTest, SeamPointsTakeHarmlessJets) {
  const Sweep sweep = MakeSweep();
  const Cutter& c = cutter();
  const Vec3& a = move().from;
  const Vec3& b = move().to;
  const double len = std::hypot(b.x - a.x, b.y - a.y);
  const double ex = len > 0 ? (b.x - a.x) / len : 1;
  const double ey = len > 0 ? (b.y - a.y) / len : 0;
  std::vector<double> radii = {c.radius, 0.5 * c.radius};
  if (ProfileJoin(c) > 0) radii.push_back(D(ProfileJoin(c)));
  std::vector<std::pair<double, double>> pts = {{a.x, a.y}, {b.x, b.y}};
  for (double rho : radii) {
    for (const Vec3& t : {a, b}) {
      for (int k = 0; k < 16; ++k) {
        const double th = k * std::numbers::pi / 8;
        pts.push_back({t.x + rho * std::cos(th), t.y + rho * std::sin(th)});
      }
      // On the end's plane, across the path.
      pts.push_back({t.x - rho * ey, t.y + rho * ex});
      pts.push_back({t.x + rho * ey, t.y - rho * ex});
    }
    for (double f : {1 / 3.0, 0.5}) {
      const double px = a.x + f * (b.x - a.x), py = a.y + f * (b.y - a.y);
      pts.push_back({px - rho * ey, py + rho * ex});
      pts.push_back({px + rho * ey, py - rho * ex});
      pts.push_back({px, py});
    }
  }
  auto jet_at = [&](double x, double y) { return sweep.JetAt(x, y); };
  auto height_at = [&](double x, double y) { return sweep.Height(x, y); };
  int checked = 0;
  for (auto [x, y] : pts) {
    const SurfaceJet j = sweep.JetAt(x, y);
    EXPECT_EQ(j.w, sweep.Height(x, y)) << At(x, y);
    if (std::isinf(j.w)) continue;
    for (double v : {j.wx, j.wy, j.wxx, j.wxy, j.wyy}) {
      EXPECT_TRUE(std::isfinite(v)) << At(x, y);
    }
    EXPECT_EQ(CheckSeamJet(jet_at, height_at, x, y, j, c.radius), "")
        << At(x, y);
    ++checked;
  }
  EXPECT_GT(checked, 20);
}

// ---------------------------------------------------------------------------
// Degenerate shapes give the numbers of the shapes they degenerate to.

void ExpectSameSurface(const Cutter& a, const Cutter& b) {
  SCOPED_TRACE(CutterToString(a) + " vs " + CutterToString(b));
  std::mt19937_64 rng(7);
  for (const MoveCase& m : kMoves) {
    SCOPED_TRACE(m.name);
    const Sweep sa(m.from, m.to, a), sb(m.from, m.to, b);
    const double r = 1.1 * a.radius;
    std::uniform_real_distribution<double> ux(std::min(m.from.x, m.to.x) - r,
                                              std::max(m.from.x, m.to.x) + r);
    std::uniform_real_distribution<double> uy(std::min(m.from.y, m.to.y) - r,
                                              std::max(m.from.y, m.to.y) + r);
    for (int k = 0; k < 300; ++k) {
      const double x = ux(rng), y = uy(rng);
      const SurfaceJet ja = sa.JetAt(x, y), jb = sb.JetAt(x, y);
      if (std::isinf(jb.w)) {
        EXPECT_EQ(ja.w, jb.w) << At(x, y);
        continue;
      }
      auto near = [](double u, double v) {
        return std::fabs(u - v) <= 1e-12 * (1 + std::fabs(v));
      };
      EXPECT_TRUE(near(ja.w, jb.w) && near(ja.wx, jb.wx) &&
                  near(ja.wy, jb.wy) && near(ja.wxx, jb.wxx) &&
                  near(ja.wxy, jb.wxy) && near(ja.wyy, jb.wyy))
          << At(x, y) << ": w " << ja.w << " vs " << jb.w << ", wx " << ja.wx
          << " vs " << jb.wx << ", wy " << ja.wy << " vs " << jb.wy
          << ", wxx " << ja.wxx << " vs " << jb.wxx << ", wxy " << ja.wxy
          << " vs " << jb.wxy << ", wyy " << ja.wyy << " vs " << jb.wyy;
      EXPECT_EQ(sa.Footprint(jb.w + 0.1).empty, sb.Footprint(jb.w + 0.1).empty);
    }
  }
}

TEST(DegenerateShapeTest, BullNoseWithCornerEqualToRadiusIsTheBall) {
  ExpectSameSurface(Cutter::BullNose(3, 3), Cutter::Ball(3));
}
TEST(DegenerateShapeTest, BullNoseWithoutCornerIsTheFlatEnd) {
  ExpectSameSurface(Cutter::BullNose(3, 0), Cutter::Flat(3));
}
// A cone whose flank tends to the horizontal: tan(1e-12 deg) = 1.7e-14
// rise per mm, 5e-14 mm over the radius.
TEST(DegenerateShapeTest, ConeWithHalfAngleToNinetyIsTheFlatEnd) {
  ExpectSameSurface(Cutter::Cone(3, 90 - 1e-12, 0), Cutter::Flat(3));
}
// A flat tip as wide as the tool leaves no flank at all.
TEST(DegenerateShapeTest, ConeWithTipAsWideAsTheToolIsTheFlatEnd) {
  ExpectSameSurface(Cutter::Cone(3, 30, 3), Cutter::Flat(3));
}
// A tapered ball whose taper tends to zero, with its ball as wide as the
// tool: the flank only spans R (1 - cos a) ~ 5e-22 mm. (The sweep's
// arithmetic; ValidateCutter refuses angles below kMinHalfAngleDeg.)
TEST(DegenerateShapeTest, TaperedBallWithHalfAngleToZeroIsTheBall) {
  ExpectSameSurface(Cutter::TaperedBall(3, 3, 1e-9), Cutter::Ball(3));
}

// ---------------------------------------------------------------------------
// The cutter description itself (exists on main since the seam).

std::string Message(const Cutter& c) {
  return std::string(ValidateCutter(c, "tools[2]").message());
}

// Every refusal is InvalidArgument and names the field and the value.
TEST(ValidateCutterTest, NamesTheField) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(ValidateCutter(Cutter::Flat(nan), "t").code(),
            absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(Message(Cutter::Flat(nan)), "tools[2].radius must be finite, got nan");
  EXPECT_EQ(Message(Cutter::Ball(kInfinity)),
            "tools[2].radius must be finite, got inf");
  EXPECT_EQ(Message(Cutter::Flat(-3)),
            "tools[2].radius must be in [0.0001, 100000] mm, got -3");
  EXPECT_EQ(Message(Cutter::BullNose(3, -1)),
            "tools[2].corner_radius must be finite and >= 0, got -1");
  EXPECT_EQ(Message(Cutter::BullNose(3, nan)),
            "tools[2].corner_radius must be finite and >= 0, got nan");
  EXPECT_EQ(Message(Cutter::BullNose(3, 3.5)),
            "tools[2].corner_radius must be at most the radius 3, got 3.5");
  for (double angle : {0.0, 90.0, -10.0, 120.0, nan, 1e-200,
                       0.999 * kMinHalfAngleDeg}) {
    for (const Cutter& c : {Cutter::Cone(3, angle, 0),
                            Cutter::TaperedBall(3, 0.5, angle)}) {
      EXPECT_EQ(Message(c), "tools[2].half_angle_deg must be in [0.001, 90) "
                            "degrees, got " + (std::isnan(angle) ? std::string("nan")
                                               : absl::StrCat(angle)))
          << CutterToString(c);
    }
  }
  EXPECT_EQ(Message(Cutter::Cone(3, 45, 3.5)),
            "tools[2].tip_radius must be at most the radius 3, got 3.5");
  EXPECT_EQ(Message(Cutter::Cone(3, 45, -0.5)),
            "tools[2].tip_radius must be finite and >= 0, got -0.5");
  EXPECT_EQ(Message(Cutter::TaperedBall(3, 4, 10)),
            "tools[2].tip_radius must be at most the radius 3, got 4");
  EXPECT_EQ(Message(Cutter::TaperedBall(3, 0, 10)),
            "tools[2].tip_radius must be at least 0.0001 mm, got 0");
  // A corner or tip radius that is not 0 is at least kMinRadius: one of
  // 1e-200 mm made non-finite derivatives (the request fuzzer found it).
  EXPECT_EQ(Message(Cutter::TaperedBall(3, 1e-200, 10)),
            "tools[2].tip_radius must be at least 0.0001 mm, got 1e-200");
  EXPECT_EQ(Message(Cutter::Cone(3, 45, 5.9e-303)),
            "tools[2].tip_radius must be 0 or at least 0.0001 mm, got 5.9e-303");
  EXPECT_EQ(Message(Cutter::BullNose(3, 0.5 * kMinRadius)),
            "tools[2].corner_radius must be 0 or at least 0.0001 mm, got 5e-05");
  // The limits themselves are valid.
  for (const Cutter& c :
       {Cutter::Ball(kMinRadius), Cutter::Flat(kMaxRadius),
        Cutter::BullNose(3, 0), Cutter::BullNose(3, 3), Cutter::Cone(3, 45, 0),
        Cutter::Cone(3, 45, 3), Cutter::TaperedBall(3, 3, 10),
        Cutter::Cone(3, kMinHalfAngleDeg, 0), Cutter::Cone(3, 90 - 1e-9, 0),
        Cutter::Cone(3, 45, kMinRadius), Cutter::BullNose(3, kMinRadius),
        Cutter::TaperedBall(3, kMinRadius, kMinHalfAngleDeg)}) {
    EXPECT_TRUE(ValidateCutter(c, "t").ok()) << CutterToString(c);
  }
}

// The cutters at the limits cut nodes whose heights and (float) derivatives
// are all finite: a plunge then a diagonal over a coarse stock, as the
// request fuzzer cuts, on grids whose nodes fall on and off the path.
TEST(ValidateCutterTest, CuttersAtTheLimitsCutFiniteNodes) {
  for (const Cutter& c :
       {Cutter::Cone(1, 45, kMinRadius), Cutter::Cone(1, kMinHalfAngleDeg, 0),
        Cutter::Cone(1, kMinHalfAngleDeg, kMinRadius),
        Cutter::BullNose(1, kMinRadius),
        Cutter::TaperedBall(1, kMinRadius, 10),
        Cutter::TaperedBall(1, kMinRadius, kMinHalfAngleDeg),
        Cutter::Ball(kMinRadius)}) {
    ASSERT_TRUE(ValidateCutter(c, "t").ok()) << CutterToString(c);
    for (int32_t n : {11, 12, 19, 20}) {
      SCOPED_TRACE(CutterToString(c) + ", " + std::to_string(n) + " elements");
      const StockSpec stock{0, 0, 50, 30, 0, n, n};
      auto wp = Workpiece::Create(stock, SchemeKind::kTaylor);
      ASSERT_TRUE(wp.ok());
      const double z = -0.5 * c.radius;
      const std::vector<Move> moves = {Move({0, 0, 1}, {0, 0, z}, c),
                                       Move({0, 0, z}, {50, 30, z}, c)};
      ASSERT_TRUE((*wp)->Apply(moves).ok());
      const TileCopy tile = CopyTile(**wp, 0);
      int cut = 0;
      for (size_t k = 0; k < tile.w.size(); ++k) {
        ASSERT_TRUE(std::isfinite(tile.w[k])) << "node " << k;
        cut += tile.owner[k] >= 0;
      }
      for (size_t k = 0; k < tile.d.size(); ++k) {
        ASSERT_TRUE(std::isfinite(tile.d[k])) << "derivative " << k;
      }
      EXPECT_GT(cut, n / 2);
    }
  }
}

// ProfileHeight against the profiles written out by hand: zero at the tip,
// nondecreasing and convex, clamped at the radius.
TEST_P(ShapeTest, ProfileHeightIsTheShapesProfile) {
  const Cutter& c = cutter();
  const double r = c.radius;
  EXPECT_EQ(ProfileHeight(c, 0), 0);
  double prev = 0, prev_slope = 0;
  const int n = 3000;
  for (int k = 1; k <= n; ++k) {
    const double rho = r * k / n;
    const double p = ProfileHeight(c, rho);
    EXPECT_NEAR(p, D(ReferenceProfile(c, rho)), 1e-12 * r) << "rho " << rho;
    EXPECT_GE(p, prev) << "rho " << rho;
    const double slope = (p - prev) / (r / n);
    EXPECT_GE(slope, prev_slope - 1e-9) << "rho " << rho;
    prev = p;
    prev_slope = slope;
  }
  EXPECT_EQ(ProfileHeight(c, 2 * r), ProfileHeight(c, r));
}

// FootprintRadius inverts the profile: the radius where the tool with its
// tip at z_tip crosses `cap`; 0 below the tip, the full radius at or above
// where the side starts.
TEST_P(ShapeTest, FootprintRadiusInvertsTheProfile) {
  const Cutter& c = cutter();
  const double r = c.radius, z = -1.7;
  const double side = D(ReferenceProfile(c, r));
  EXPECT_EQ(FootprintRadius(c, z, z - 0.1), 0);
  EXPECT_EQ(FootprintRadius(c, z, z + side + 0.1), r);
  for (int k = 1; k < 200; ++k) {
    const double rho = r * (k + 0.5) / 200;
    const Section s = ReferenceSection(c, rho);
    if (s.f1 < 0.05) {
      // A flat part of the profile: everything out to it is below any cap
      // above the tip.
      EXPECT_GE(FootprintRadius(c, z, z + s.f + 1e-9), rho);
      continue;
    }
    // Where the profile rises at f', rounding the cap moves the radius by
    // about eps |cap| / f'.
    EXPECT_NEAR(FootprintRadius(c, z, z + D(s.f)), rho, 1e-10) << "rho " << rho;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Shapes, ShapeTest, ::testing::Range(0, static_cast<int>(std::size(kShapes))),
    [](const ::testing::TestParamInfo<int>& info) {
      return std::string(kShapes[info.param].name);
    });

INSTANTIATE_TEST_SUITE_P(
    ShapesAndMoves, ReferenceTest,
    ::testing::Combine(
        ::testing::Range(0, static_cast<int>(std::size(kShapes))),
        ::testing::Range(0, static_cast<int>(std::size(kMoves)))),
    [](const ::testing::TestParamInfo<std::tuple<int, int>>& info) {
      return std::string(kShapes[std::get<0>(info.param)].name) + "_" +
             kMoves[std::get<1>(info.param)].name;
    });

}  // namespace
}  // namespace swarf
