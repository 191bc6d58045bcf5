// Cutting marks (issue 3) against analytic creases.
#include "core/cutting_marks.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <ostream>
#include <random>
#include <string>
#include <vector>

#include "core/instances.h"
#include "core/thread_pool.h"
#include "core/workpiece.h"
#include "gtest/gtest.h"

namespace swarf {
namespace {

std::unique_ptr<Workpiece> Cut(const StockSpec& stock,
                               const std::vector<Move>& moves,
                               SchemeKind scheme = SchemeKind::kTaylor,
                               ThreadPool* pool = nullptr) {
  auto wp = Workpiece::Create(stock, scheme, pool);
  EXPECT_TRUE(wp.ok()) << wp.status();
  auto applied = (*wp)->Apply(moves);
  EXPECT_TRUE(applied.ok()) << applied.status();
  return *std::move(wp);
}

std::vector<MarkPolyline> Marks(const Workpiece& wp,
                                const MarkOptions& options = {}) {
  auto marks = FindCuttingMarks(wp, options);
  EXPECT_TRUE(marks.ok()) << marks.status();
  return marks.ok() ? *std::move(marks) : std::vector<MarkPolyline>{};
}

double Spacing(const Workpiece& wp) {
  return std::fmin(wp.grid().dx(), wp.grid().dy());
}

// Well-formed polylines: consistent sizes, distinct consecutive vertices,
// and (for smooth creases) no turn back by more than 90 degrees.
void ExpectClean(const std::vector<MarkPolyline>& marks, bool smooth) {
  for (size_t k = 0; k < marks.size(); ++k) {
    const MarkPolyline& p = marks[k];
    const size_t n = p.vertices.size();
    ASSERT_EQ(p.angle_deg.size(), n);
    ASSERT_EQ(p.vertex_owners.size(), n);
    ASSERT_GE(n, p.closed ? 3u : 2u);
    EXPECT_EQ(p.owners, p.vertex_owners[0]);
    const size_t segs = p.closed ? n : n - 1;
    for (size_t i = 0; i < segs; ++i) {
      const Vec3& a = p.vertices[i];
      const Vec3& b = p.vertices[(i + 1) % n];
      EXPECT_GT(std::hypot(b.x - a.x, b.y - a.y), 0)
          << "polyline " << k << " repeats vertex " << i;
      if (smooth && (p.closed || i + 1 < segs)) {
        const Vec3& c = p.vertices[(i + 2) % n];
        const double dot = (b.x - a.x) * (c.x - b.x) + (b.y - a.y) * (c.y - b.y);
        EXPECT_GT(dot, 0) << "polyline " << k << " folds back at vertex "
                          << (i + 1) % n;
      }
    }
  }
}

bool HasTop(const std::array<int32_t, 2>& o) {
  return o[0] == kStockTopOwner || o[1] == kStockTopOwner;
}

// ---------------------------------------------------------------------------

// Two equal ball plunges at equal depth: the crease is the perpendicular
// bisector of their centres, between the points where it meets the top.
void CheckTwoBalls(double ax, double ay, double bx, double by) {
  const double r = 10, depth = 5;
  const StockSpec stock{0, 0, 40, 32, 0, 200, 160};
  auto wp = Cut(stock, {{{ax, ay, 5}, {ax, ay, -depth}, r},
                        {{bx, by, 5}, {bx, by, -depth}, r}});
  const double h = Spacing(*wp);
  const auto marks = Marks(*wp);
  ExpectClean(marks, /*smooth=*/true);
  // Midpoint, unit direction between the centres, and along the bisector.
  const double mx = 0.5 * (ax + bx), my = 0.5 * (ay + by);
  const double d = std::hypot(bx - ax, by - ay);
  const double ux = (bx - ax) / d, uy = (by - ay) / d;
  const double rim = std::sqrt(r * r - (r - depth) * (r - depth));
  const double half = std::sqrt(rim * rim - 0.25 * d * d);

  int creases = 0, rims = 0;
  for (const MarkPolyline& p : marks) {
    if (p.owners == std::array<int32_t, 2>{0, 1}) {
      ++creases;
      EXPECT_FALSE(p.closed);
      double lo = kInf, hi = -kInf;
      for (size_t k = 0; k < p.vertices.size(); ++k) {
        const Vec3& v = p.vertices[k];
        EXPECT_EQ(p.vertex_owners[k], (std::array<int32_t, 2>{0, 1}));
        EXPECT_LE(std::fabs((v.x - mx) * ux + (v.y - my) * uy), h / 50)
            << "vertex " << k << " at (" << v.x << ", " << v.y << ")";
        const double along = (v.x - mx) * -uy + (v.y - my) * ux;
        lo = std::fmin(lo, along);
        hi = std::fmax(hi, along);
      }
      EXPECT_GE(hi - lo, 0.98 * 2 * half);
      EXPECT_LE(hi - lo, 2 * half + h / 50);
    } else {
      ++rims;
      EXPECT_FALSE(p.closed);  // each rim ends where the crease meets the top
      for (const auto& o : p.vertex_owners) EXPECT_TRUE(HasTop(o));
    }
  }
  EXPECT_EQ(creases, 1);
  EXPECT_EQ(rims, 2);
}

TEST(CuttingMarksTest, TwoBallPlungesMeetOnTheBisector) {
  CheckTwoBalls(14.3, 13.1, 24.1, 17.9);
}

TEST(CuttingMarksTest, TwoBallPlungesMeetOnTheBisectorAlongAGridLine) {
  // The crease is the grid line x = 20: nodes lie exactly on it and take
  // either owner by rounding.
  CheckTwoBalls(15, 15.7, 25, 15.7);
}

TEST(CuttingMarksTest, TwoBallPlungesMeetOnTheBisectorAlongAGridDiagonal) {
  // The crease x + y = 35 runs through the nodes along element diagonals.
  CheckTwoBalls(14, 13, 21, 20);
}

// ---------------------------------------------------------------------------

struct RasterCase {
  double s, r;       // stepover and ball radius (mm)
  int32_t nx, ny;    // mesh over [0, 9.7 s] x [0, 10.3 s]
  double piece;      // length of the moves making a pass (0: one move)
};

void PrintTo(const RasterCase& c, std::ostream* os) {
  *os << "s=" << c.s << " r=" << c.r << " mesh " << c.nx << "x" << c.ny
      << " moves of " << c.piece;
}

class RasterTest : public ::testing::TestWithParam<RasterCase> {};

// Parallel horizontal passes at depth 0.5 on a flat stock: the marks are the
// mid-lines between passes, at the scallop height.
TEST_P(RasterTest, ScallopsLieOnTheMidLines) {
  const RasterCase c = GetParam();
  const double s = c.s, r = c.r, bottom = -0.5;
  const double wx = 9.7 * s, wy = 10.3 * s;
  const StockSpec stock{0, 0, wx, wy, 0, c.nx, c.ny};
  // Pass k at y = (k + 0.037) s, off the grid; passes cover the stock in y
  // and run past it in x, so there are no rims and no pass ends.
  std::vector<Move> moves;
  std::vector<double> mids;
  const int k0 = -static_cast<int>(std::ceil(r / s)) - 1;
  const int k1 = static_cast<int>(std::ceil((wy + r) / s)) + 1;
  const double xa = -r - 1, xb = wx + r + 1;
  for (int k = k0; k <= k1; ++k) {
    const double y = (k + 0.037) * s;
    if (c.piece > 0) {
      for (double x = xa; x < xb; x += c.piece) {
        moves.push_back({{x, y, bottom}, {std::fmin(x + c.piece, xb), y, bottom}, r});
      }
    } else {
      moves.push_back({{xa, y, bottom}, {xb, y, bottom}, r});
    }
    const double mid = y + 0.5 * s;
    if (mid > 0 && mid < wy) mids.push_back(mid);
  }
  auto wp = Cut(stock, moves);
  const double h = Spacing(*wp);
  const double scallop = bottom + r - std::sqrt(r * r - 0.25 * s * s);
  const auto marks = Marks(*wp);
  ExpectClean(marks, /*smooth=*/true);
  ASSERT_EQ(marks.size(), mids.size());
  std::vector<int> seen(mids.size(), 0);
  double max_angle_error = 0;
  for (const MarkPolyline& p : marks) {
    EXPECT_FALSE(p.closed);
    // The mid-line of the first vertex; every vertex must stay on it.
    size_t m = 0;
    for (size_t k = 1; k < mids.size(); ++k) {
      if (std::fabs(p.vertices[0].y - mids[k]) <
          std::fabs(p.vertices[0].y - mids[m])) {
        m = k;
      }
    }
    ++seen[m];
    for (size_t k = 0; k < p.vertices.size(); ++k) {
      const Vec3& v = p.vertices[k];
      EXPECT_LE(std::fabs(v.y - mids[m]), h / 50)
          << "vertex " << k << " at (" << v.x << ", " << v.y << ")";
      EXPECT_LE(std::fabs(v.z - scallop), 1e-4)
          << "vertex " << k << " at (" << v.x << ", " << v.y << ")";
      EXPECT_NE(p.vertex_owners[k][0], kStockTopOwner);
      max_angle_error = std::fmax(
          max_angle_error,
          std::fabs(p.angle_deg[k] -
                    2 * std::asin(0.5 * s / r) * 180 / std::numbers::pi));
    }
    // From one side of the stock to the other.
    const double x_first = p.vertices.front().x, x_last = p.vertices.back().x;
    EXPECT_NEAR(std::fmin(x_first, x_last), 0, 1e-9);
    EXPECT_NEAR(std::fmax(x_first, x_last), wx, 1e-9);
  }
  for (size_t k = 0; k < mids.size(); ++k) {
    EXPECT_EQ(seen[k], 1) << "mid-line y = " << mids[k];
  }
  // The patches' gradients carry their own O(h^2) error.
  EXPECT_LE(max_angle_error,
            0.005 * 2 * std::asin(0.5 * s / r) * 180 / std::numbers::pi);
}

INSTANTIATE_TEST_SUITE_P(
    Stepovers, RasterTest,
    ::testing::Values(RasterCase{0.5, 2, 97, 93, 0},
                      RasterCase{1.0, 3, 97, 93, 0},
                      RasterCase{0.3, 1, 97, 93, 0},
                      // A 60-degree scallop: strongly curved, so a finer grid for 1e-4 mm.
                      RasterCase{1.0, 1, 194, 186, 0},
                      // The smallest realistic scallop: 1.91 degrees.
                      RasterCase{0.1, 3, 97, 93, 0},
                      // Passes made of many short collinear moves: the owners
                      // on each side change along every mark.
                      RasterCase{0.5, 2, 97, 93, 0.137},
                      RasterCase{0.1, 3, 97, 93, 0.0291}),
    [](const ::testing::TestParamInfo<RasterCase>& info) {
      const RasterCase& c = info.param;
      std::string name = "s" + std::to_string(static_cast<int>(c.s * 1000)) +
                         "um_r" + std::to_string(static_cast<int>(c.r)) +
                         "mm_mesh" + std::to_string(c.nx);
      if (c.piece > 0) name += "_short_moves";
      return name;
    });

// ---------------------------------------------------------------------------

TEST(CuttingMarksTest, PlungeRimIsOneClosedCircle) {
  const double cx = 9.7, cy = 10.3, r = 6, depth = 2;
  auto wp = Cut({0, 0, 20, 20, 0, 200, 200},
                {{{cx, cy, 1}, {cx, cy, -depth}, r}});
  const double h = Spacing(*wp);
  const double rim = std::sqrt(r * r - (r - depth) * (r - depth));
  const auto marks = Marks(*wp);
  ExpectClean(marks, /*smooth=*/true);
  ASSERT_EQ(marks.size(), 1u);
  const MarkPolyline& p = marks[0];
  EXPECT_TRUE(p.closed);
  EXPECT_EQ(p.owners, (std::array<int32_t, 2>{kStockTopOwner, 0}));
  for (size_t k = 0; k < p.vertices.size(); ++k) {
    const Vec3& v = p.vertices[k];
    EXPECT_LE(std::fabs(std::hypot(v.x - cx, v.y - cy) - rim), h / 50)
        << "vertex " << k << " at (" << v.x << ", " << v.y << ")";
    EXPECT_EQ(v.z, 0);
  }
  EXPECT_NEAR(PolylineLength(p), 2 * std::numbers::pi * rim,
              1e-3 * 2 * std::numbers::pi * rim);
}

// Tiles never cut are skipped (their nodes are the stock top): a rim that
// crosses into one between nodes needs that tile's nodes all the same.
// Nodes every 0.1 mm, tiles of 64: tile column 1 starts at x = 6.4. The
// rim's west end, x = 6.35, lies between the last node of tile column 0
// and the first of column 1, and its south end likewise between rows.
TEST(CuttingMarksTest, RimIntoUntouchedTilesIsWhole) {
  const double r = 6, depth = 2;
  const double rim = std::sqrt(r * r - (r - depth) * (r - depth));
  const double cx = 6.35 + rim, cy = 6.35 + rim;
  // A top other than 0: an unread node (a default jet, flat at 0) would
  // not pass for the stock top.
  const double top = 2.5;
  auto wp = Cut({0, 0, 40, 40, top, 400, 400},
                {{{cx, cy, top + 1}, {cx, cy, top - depth}, r}});
  ASSERT_EQ(wp->tiles_x(), 7);
  EXPECT_FALSE(wp->TileAllocated(0 * 7 + 1));  // west of the rim
  EXPECT_FALSE(wp->TileAllocated(1 * 7 + 0));  // south of it
  EXPECT_TRUE(wp->TileAllocated(1 * 7 + 1));
  EXPECT_LT(wp->allocated_tiles(), 7 * 7 / 2);
  const double h = Spacing(*wp);
  const auto marks = Marks(*wp);
  ExpectClean(marks, /*smooth=*/true);
  ASSERT_EQ(marks.size(), 1u);
  const MarkPolyline& p = marks[0];
  EXPECT_TRUE(p.closed);
  double west = cx, south = cy;
  for (size_t k = 0; k < p.vertices.size(); ++k) {
    const Vec3& v = p.vertices[k];
    EXPECT_LE(std::fabs(std::hypot(v.x - cx, v.y - cy) - rim), h / 50)
        << "vertex " << k << " at (" << v.x << ", " << v.y << ")";
    west = std::min(west, v.x);
    south = std::min(south, v.y);
  }
  EXPECT_LT(west, 6.4);
  EXPECT_LT(south, 6.4);
  EXPECT_NEAR(PolylineLength(p), 2 * std::numbers::pi * rim,
              1e-3 * 2 * std::numbers::pi * rim);
}

// Only rims: one closed polyline whose every vertex has the top on one side.
void ExpectOnlyOneRim(const std::vector<MarkPolyline>& marks) {
  ExpectClean(marks, /*smooth=*/true);
  ASSERT_EQ(marks.size(), 1u);
  EXPECT_TRUE(marks[0].closed);
  for (const auto& o : marks[0].vertex_owners) {
    EXPECT_TRUE(HasTop(o)) << o[0] << " | " << o[1];
  }
}

TEST(CuttingMarksTest, LongSlopedMoveHasOnlyItsRim) {
  auto wp = Cut({0, 0, 40, 25, 0, 160, 100},
                {{{3, 10, 1}, {37, 14, -2.5}, 2.5}});
  ExpectOnlyOneRim(Marks(*wp));
}

// A groove along an arc of radius 20 mm made of 0.5 mm chords. Consecutive
// chords turn by 1.43 degrees; on the inner side their cylinders meet at a
// real but smooth-looking crease that eq. (5) must reject with the default t2.
std::vector<Move> ArcGroove() {
  std::vector<Move> moves;
  const double R = 20, step = 2 * std::asin(0.25 / R);
  Vec3 prev{20 + R * std::cos(0.5), 1 + R * std::sin(0.5), -1};
  for (double a = 0.5 + step; a <= 2.6; a += step) {
    const Vec3 next{20 + R * std::cos(a), 1 + R * std::sin(a), -1};
    moves.push_back({prev, next, 3});
    prev = next;
  }
  return moves;
}

TEST(CuttingMarksTest, ArcOfShortMovesHasOnlyItsRim) {
  auto wp = Cut({0, 0, 40, 25, 0, 200, 125}, ArcGroove());
  ExpectOnlyOneRim(Marks(*wp));
}

TEST(CuttingMarksTest, ArcFacetCreasesAppearBelowTheirAngle) {
  // The same arc with t2 below the facets' 1.43 degrees: the creases between
  // consecutive moves become marks, so the test above does exercise eq. (5).
  auto wp = Cut({0, 0, 40, 25, 0, 200, 125}, ArcGroove());
  MarkOptions o;
  o.t2_deg = 0.5;
  const auto marks = Marks(*wp, o);
  int facet_vertices = 0;
  for (const auto& p : marks) {
    for (const auto& ow : p.vertex_owners) facet_vertices += !HasTop(ow);
  }
  EXPECT_GT(facet_vertices, 100);
}

TEST(CuttingMarksTest, HumpArcOfShortMovesHasOnlyItsRim) {
  // The tool goes over a hump: an arc of radius 20 mm in the xz plane made
  // of 0.5 mm chords. Below the path's inner side consecutive cylinders meet
  // at 1.43 degrees.
  std::vector<Move> moves;
  const double R = 20, step = 2 * std::asin(0.25 / R);
  auto at = [&](double a) {
    return Vec3{20 + R * std::sin(a), 12, -21 + R * std::cos(a)};
  };
  for (double a = -0.41; a + step <= 0.41; a += step) {
    moves.push_back({at(a), at(a + step), 3});
  }
  auto wp = Cut({0, 0, 40, 25, 0, 200, 125}, moves);
  ExpectOnlyOneRim(Marks(*wp));
}

// ---------------------------------------------------------------------------

TEST(CuttingMarksTest, ThreeBallsMeetAtOneJunction) {
  // Three equal plunges around (20, 15): three creases from the circumcentre,
  // plus three rim arcs.
  const double cx = 20.03, cy = 15.07, rho = 6, r = 10;
  std::vector<Move> moves;
  for (int k = 0; k < 3; ++k) {
    const double a = 0.3 + k * 2 * std::numbers::pi / 3;
    const double x = cx + rho * std::cos(a), y = cy + rho * std::sin(a);
    moves.push_back({{x, y, 5}, {x, y, -5}, r});
  }
  auto wp = Cut({0, 0, 40, 30, 0, 200, 150}, moves);
  const double h = Spacing(*wp);
  const auto marks = Marks(*wp);
  ExpectClean(marks, /*smooth=*/true);
  int creases = 0;
  for (const MarkPolyline& p : marks) {
    if (HasTop(p.owners)) continue;
    ++creases;
    // One end at the junction, exactly shared by the three creases.
    const Vec3& a = p.vertices.front();
    const Vec3& b = p.vertices.back();
    const double da = std::hypot(a.x - cx, a.y - cy);
    const double db = std::hypot(b.x - cx, b.y - cy);
    EXPECT_LE(std::fmin(da, db), h / 50);
    for (size_t k = 0; k < p.vertices.size(); ++k) {
      EXPECT_LE(ExactCreaseDistance(*wp, p.vertex_owners[k][0],
                                    p.vertex_owners[k][1], p.vertices[k].x,
                                    p.vertices[k].y),
                h / 50);
    }
  }
  EXPECT_EQ(creases, 3);
  EXPECT_EQ(marks.size(), 6u);
}

// ProjectOntoExactCreases, which the marks finish runs of a crease's
// vertices with (their junction tests taken together for each move bin),
// moves every vertex as ProjectOntoExactCrease alone does, bit for bit:
// the patches' vertices of junctions (three and five creases meeting),
// creases of cylinders, and random plunges and slots, in runs of a whole
// polyline, of seven vertices and of one.
TEST(CuttingMarksTest, CreaseRunsProjectAsEachVertexAlone) {
  struct Scene {
    StockSpec stock;
    std::vector<Move> moves;
  };
  std::vector<Scene> scenes;
  for (const char* name : {"five-balls", "five-cylinders"}) {
    auto inst = PaperInstance(name, 100);
    ASSERT_TRUE(inst.ok());
    scenes.push_back({inst->stock, inst->moves});
  }
  {
    std::vector<Move> moves;
    for (int k = 0; k < 3; ++k) {
      const double a = 0.3 + k * 2 * std::numbers::pi / 3;
      const double x = 20.03 + 6 * std::cos(a), y = 15.07 + 6 * std::sin(a);
      moves.push_back({{x, y, 5}, {x, y, -5}, 10});
    }
    scenes.push_back({{0, 0, 40, 30, 0, 200, 150}, moves});
  }
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0, 1);
  for (int scene = 0; scene < 6; ++scene) {
    std::vector<Move> moves;
    for (int k = 0; k < 10; ++k) {
      const Vec3 a{30 * u(rng), 20 * u(rng), -3 * u(rng)};
      const Vec3 b = k % 2 ? Vec3{30 * u(rng), 20 * u(rng), -3 * u(rng)}
                           : Vec3{a.x, a.y, a.z + 3};
      moves.push_back({a, b, 1 + 4 * u(rng)});
    }
    scenes.push_back({{0, 0, 30, 20, 0, 90, 60}, moves});
  }
  const double t1 = MarkOptions{}.t1;
  int64_t moved = 0, vertices = 0;
  for (size_t q = 0; q < scenes.size(); ++q) {
    SCOPED_TRACE(q);
    // The patches' vertices (the taylor scheme's marks are not projected).
    auto wp = Cut(scenes[q].stock, scenes[q].moves);
    const double h = Spacing(*wp);
    for (const MarkPolyline& patches : Marks(*wp)) {
      MarkPolyline alone = patches;
      for (size_t k = 0; k < alone.vertices.size(); ++k) {
        ProjectOntoExactCrease(*wp, alone.vertex_owners[k], h, t1,
                               &alone.vertices[k], &alone.angle_deg[k]);
        moved += alone.vertices[k].x != patches.vertices[k].x;
      }
      vertices += static_cast<int64_t>(alone.vertices.size());
      const uint32_t n = static_cast<uint32_t>(patches.vertices.size());
      for (const uint32_t run : {n, 7u, 1u}) {
        MarkPolyline runs = patches;
        for (uint32_t k = 0; k < n; k += run) {
          ProjectOntoExactCreases(*wp, &runs, k, std::min(n, k + run), h, t1);
        }
        for (uint32_t k = 0; k < n; ++k) {
          ASSERT_EQ(runs.vertices[k].x, alone.vertices[k].x) << k;
          ASSERT_EQ(runs.vertices[k].y, alone.vertices[k].y) << k;
          ASSERT_EQ(runs.vertices[k].z, alone.vertices[k].z) << k;
          ASSERT_EQ(runs.angle_deg[k], alone.angle_deg[k]) << k;
        }
      }
    }
  }
  // The projection moves most vertices.
  EXPECT_GT(moved, vertices / 2);
}

// The centre of the circle through three points.
void Circumcentre(const double p[2], const double q[2], const double r[2],
                  double* x, double* y) {
  const double d = 2 * (p[0] * (q[1] - r[1]) + q[0] * (r[1] - p[1]) +
                        r[0] * (p[1] - q[1]));
  const double p2 = p[0] * p[0] + p[1] * p[1];
  const double q2 = q[0] * q[0] + q[1] * q[1];
  const double r2 = r[0] * r[0] + r[1] * r[1];
  *x = (p2 * (q[1] - r[1]) + q2 * (r[1] - p[1]) + r2 * (p[1] - q[1])) / d;
  *y = (p2 * (r[0] - q[0]) + q2 * (p[0] - r[0]) + r2 * (q[0] - p[0])) / d;
}

TEST(CuttingMarksTest, FourBallsMeetAtTwoJunctionsInOneElement) {
  // Four plunges at the corners of a slightly distorted square: two triple
  // junctions 0.01 mm apart, joined by a crease between balls 1 and 3, all
  // inside one element (paper Fig. 3).
  const double c[4][2] = {{17, 12}, {23.3, 12}, {23, 18.3}, {17, 18}};
  std::vector<Move> moves;
  for (const auto& p : c) moves.push_back({{p[0], p[1], 5}, {p[0], p[1], -5}, 10});
  auto wp = Cut({0, 0, 40, 30, 0, 200, 150}, moves);
  const double h = Spacing(*wp);
  const auto marks = Marks(*wp);
  ExpectClean(marks, /*smooth=*/true);
  double jx[2], jy[2];
  Circumcentre(c[0], c[1], c[3], &jx[0], &jy[0]);
  Circumcentre(c[1], c[2], c[3], &jx[1], &jy[1]);
  int creases = 0, short_ones = 0;
  for (const MarkPolyline& p : marks) {
    for (size_t k = 0; k < p.vertices.size(); ++k) {
      EXPECT_LE(ExactCreaseDistance(*wp, p.vertex_owners[k][0],
                                    p.vertex_owners[k][1], p.vertices[k].x,
                                    p.vertices[k].y),
                h / 50);
    }
    if (HasTop(p.owners)) continue;
    ++creases;
    if (p.owners == std::array<int32_t, 2>{1, 3}) {
      ++short_ones;
      // From one junction to the other.
      const Vec3& a = p.vertices.front();
      const Vec3& b = p.vertices.back();
      const bool fwd = std::hypot(a.x - jx[0], a.y - jy[0]) <
                       std::hypot(a.x - jx[1], a.y - jy[1]);
      EXPECT_LE(std::hypot(a.x - jx[fwd ? 0 : 1], a.y - jy[fwd ? 0 : 1]),
                h / 50);
      EXPECT_LE(std::hypot(b.x - jx[fwd ? 1 : 0], b.y - jy[fwd ? 1 : 0]),
                h / 50);
    }
  }
  EXPECT_EQ(short_ones, 1);
  EXPECT_EQ(creases, 5);
}

TEST(CuttingMarksTest, SeveralMarksPerElement) {
  // Diagonal raster with stepover 1.3 grid spacings: elements hold two
  // parallel marks (paper Fig. 3).
  const double s = 0.5, r = 3, bottom = -0.5;
  const double ang = 0.5236;  // ~30 degrees
  const double ux = std::cos(ang), uy = std::sin(ang);
  const double nxv = -uy, nyv = ux;  // pass normal
  const int32_t mesh = 26;           // h = 10 / 26 = 0.385 = s / 1.3
  std::vector<Move> moves;
  std::vector<double> mids;          // offsets along the normal
  for (int k = -40; k <= 40; ++k) {
    const double off = (k + 0.21) * s;
    const double px = 5 + off * nxv, py = 5 + off * nyv;
    moves.push_back({{px - 20 * ux, py - 20 * uy, bottom},
                     {px + 20 * ux, py + 20 * uy, bottom}, r});
    mids.push_back(off + 0.5 * s);
  }
  auto wp = Cut({0, 0, 10, 10, 0, mesh, mesh}, moves);
  const double h = Spacing(*wp);
  const auto marks = Marks(*wp);
  ExpectClean(marks, /*smooth=*/true);
  ASSERT_FALSE(marks.empty());
  // Every vertex on a mid-line; the elements around each vertex (two for an
  // edge point) collect the polylines passing through them.
  std::vector<std::vector<int>> through(mesh * mesh);
  for (size_t q = 0; q < marks.size(); ++q) {
    for (const Vec3& v : marks[q].vertices) {
      const double off = (v.x - 5) * nxv + (v.y - 5) * nyv;
      double best = kInf;
      for (double m : mids) best = std::fmin(best, std::fabs(off - m));
      EXPECT_LE(best, h / 50) << "(" << v.x << ", " << v.y << ")";
      const double fx = v.x / h, fy = v.y / h;
      for (int ej = static_cast<int>(std::ceil(fy - 1 - 1e-9));
           ej <= static_cast<int>(std::floor(fy + 1e-9)); ++ej) {
        for (int ei = static_cast<int>(std::ceil(fx - 1 - 1e-9));
             ei <= static_cast<int>(std::floor(fx + 1e-9)); ++ei) {
          if (ei < 0 || ej < 0 || ei >= mesh || ej >= mesh) continue;
          auto& t = through[ej * mesh + ei];
          if (std::find(t.begin(), t.end(), q) == t.end()) t.push_back(q);
        }
      }
    }
  }
  int two = 0;
  for (const auto& t : through) two += t.size() >= 2;
  EXPECT_GT(two, 10);
  // One polyline per mid-line crossing the stock.
  size_t inside = 0;
  for (double m : mids) inside += std::fabs(m) < 5 * (std::fabs(nxv) + std::fabs(nyv));
  EXPECT_EQ(marks.size(), inside);
}

// ---------------------------------------------------------------------------

TEST(CuttingMarksTest, FiveBallsGiveFourCreasesAndTheRims) {
  auto inst = PaperInstance("five-balls", 100);
  ASSERT_TRUE(inst.ok());
  auto wp = Cut(inst->stock, inst->moves);
  const double h = Spacing(*wp);
  const auto marks = Marks(*wp);
  ExpectClean(marks, /*smooth=*/true);
  int creases[5] = {0, 0, 0, 0, 0};
  int rims = 0;
  for (const MarkPolyline& p : marks) {
    if (HasTop(p.owners)) {
      ++rims;
      for (const auto& o : p.vertex_owners) EXPECT_TRUE(HasTop(o));
      continue;
    }
    // Centre ball (move 0) against a corner ball k: the bisector of their
    // centres, 20 mm long (the rims are 17.32 mm from each centre).
    ASSERT_EQ(p.owners[0], 0);
    const int k = p.owners[1];
    ASSERT_GE(k, 1);
    ASSERT_LE(k, 4);
    ++creases[k];
    const Move& m = inst->moves[k];
    const double mx = 0.5 * (50 + m.from.x), my = 0.5 * (50 + m.from.y);
    const double ux = (m.from.x - 50) / std::sqrt(800.0);
    const double uy = (m.from.y - 50) / std::sqrt(800.0);
    double lo = kInf, hi = -kInf;
    for (const Vec3& v : p.vertices) {
      EXPECT_LE(std::fabs((v.x - mx) * ux + (v.y - my) * uy), h / 50);
      const double along = -(v.x - mx) * uy + (v.y - my) * ux;
      lo = std::fmin(lo, along);
      hi = std::fmax(hi, along);
    }
    EXPECT_GE(hi - lo, 0.98 * 20);
  }
  for (int k = 1; k <= 4; ++k) EXPECT_EQ(creases[k], 1) << "ball " << k;
  // The rim of the union of the five discs, split at the 8 junctions.
  EXPECT_EQ(rims, 8);
  EXPECT_EQ(marks.size(), 12u);
}

TEST(CuttingMarksTest, VerticesAreCloseToTheExactCreases) {
  for (const char* name : {"five-balls", "five-cylinders"}) {
    auto inst = PaperInstance(name, 400);
    ASSERT_TRUE(inst.ok());
    auto wp = Cut(inst->stock, inst->moves);
    const auto marks = Marks(*wp);
    ExpectClean(marks, /*smooth=*/false);
    const MarkAccuracy acc = MeasureMarkAccuracy(*wp, marks);
    EXPECT_LE(acc.max_distance, Spacing(*wp) / 50)
        << name << " at (" << acc.max_x << ", " << acc.max_y << ")";
  }
}

// The exact and guarded schemes' marks lie on the exact creases: every
// vertex where the two owners' exact swept surfaces meet (to first order,
// 1e-9 of an element instead of the patches' 1/50; issue 12's target: 0.001
// mm at mesh 100, the centre where the five grooves meet included), at
// their exact height; the same marks as the paper scheme's otherwise (count
// and owners).
TEST(CuttingMarksTest, ExactAndGuardedVerticesAreOnTheExactCreases) {
  for (const auto& [name, scheme] :
       {std::pair{"five-balls", SchemeKind::kExact},
        std::pair{"five-cylinders", SchemeKind::kExact},
        std::pair{"five-balls", SchemeKind::kGuarded},
        std::pair{"five-cylinders", SchemeKind::kGuarded}}) {
    SCOPED_TRACE(GetScheme(scheme).name());
    auto inst = PaperInstance(name, 100);
    ASSERT_TRUE(inst.ok());
    auto taylor = Cut(inst->stock, inst->moves);
    auto exact = Cut(inst->stock, inst->moves, scheme);
    const auto tm = Marks(*taylor);
    const auto em = Marks(*exact);
    ASSERT_EQ(em.size(), tm.size()) << name;
    for (size_t k = 0; k < em.size(); ++k) {
      EXPECT_EQ(em[k].owners, tm[k].owners) << name;
    }
    const MarkAccuracy t_acc = MeasureMarkAccuracy(*taylor, tm);
    const MarkAccuracy e_acc = MeasureMarkAccuracy(*exact, em);
    EXPECT_GT(t_acc.max_distance, 1e-4) << name;
    EXPECT_LE(e_acc.max_distance, 1e-9 * Spacing(*exact))
        << name << " at (" << e_acc.max_x << ", " << e_acc.max_y << ")";
    for (const MarkPolyline& p : em) {
      for (const Vec3& v : p.vertices) {
        EXPECT_NEAR(v.z, exact->ExactHeight(v.x, v.y), 1e-8) << name;
      }
    }
  }
}

// ---------------------------------------------------------------------------

// Random cuts on coarse grids: whatever the geometry, polylines are well
// formed, inside the stock and the same on every run.
TEST(CuttingMarksTest, RandomScenesGiveWellFormedPolylines) {
  ThreadPool one(1), four(4);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  for (int scene = 0; scene < 40; ++scene) {
    const int32_t n = 20 + 10 * (scene % 5);
    const StockSpec stock{0, 0, 30, 20, 0, n * 3 / 2 + scene % 7, n};
    std::vector<Move> moves;
    const int count = 1 + scene % 12;
    for (int k = 0; k < count; ++k) {
      const double r = 1 + 4 * u(rng);
      Vec3 a{30 * u(rng), 20 * u(rng), 0.5 - 3 * u(rng)};
      Vec3 b = a;
      switch (k % 3) {
        case 0:
          a.z += 3;  // plunge
          break;
        case 1:
          b = {30 * u(rng), 20 * u(rng), -3 * u(rng)};
          break;
        default: {
          const double t = 6.28 * u(rng);
          b = {a.x + 8 * std::cos(t), a.y + 8 * std::sin(t),
               a.z - 1 + 2 * u(rng)};
        }
      }
      moves.push_back({a, b, r});
    }
    auto wa = Cut(stock, moves, SchemeKind::kTaylor, &one);
    auto wb = Cut(stock, moves, SchemeKind::kTaylor, &four);
    const auto ma = Marks(*wa), mb = Marks(*wb);
    ExpectClean(ma, /*smooth=*/false);
    ASSERT_EQ(ma.size(), mb.size()) << "scene " << scene;
    for (size_t q = 0; q < ma.size(); ++q) {
      ASSERT_EQ(ma[q].vertices.size(), mb[q].vertices.size());
      for (size_t k = 0; k < ma[q].vertices.size(); ++k) {
        const Vec3& v = ma[q].vertices[k];
        EXPECT_EQ(v.x, mb[q].vertices[k].x);
        EXPECT_EQ(v.y, mb[q].vertices[k].y);
        EXPECT_TRUE(std::isfinite(v.z));
        EXPECT_TRUE(v.x >= 0 && v.x <= 30 && v.y >= 0 && v.y <= 20)
            << "scene " << scene << " (" << v.x << ", " << v.y << ")";
        EXPECT_LE(v.z, 0);
        EXPECT_GE(ma[q].angle_deg[k], 0);
        EXPECT_LE(ma[q].angle_deg[k], 180);
      }
    }
  }
}

double ClippedLength(const std::vector<MarkPolyline>& marks, const Rect& r) {
  double len = 0;
  for (const MarkPolyline& p : marks) {
    const size_t n = p.vertices.size();
    const size_t segs = p.closed ? n : n - 1;
    for (size_t k = 0; k < segs; ++k) {
      const Vec3& a = p.vertices[k];
      const Vec3& b = p.vertices[(k + 1) % n];
      // Liang-Barsky in XY; the length in 3D.
      double t0 = 0, t1 = 1;
      const double dx = b.x - a.x, dy = b.y - a.y;
      const double pp[4] = {-dx, dx, -dy, dy};
      const double qq[4] = {a.x - r.x0, r.x1 - a.x, a.y - r.y0, r.y1 - a.y};
      bool out = false;
      for (int i = 0; i < 4; ++i) {
        if (pp[i] == 0) {
          out |= qq[i] < 0;
        } else if (pp[i] < 0) {
          t0 = std::fmax(t0, qq[i] / pp[i]);
        } else {
          t1 = std::fmin(t1, qq[i] / pp[i]);
        }
      }
      if (out || t0 >= t1) continue;
      len += (t1 - t0) * std::sqrt(dx * dx + dy * dy +
                                   (b.z - a.z) * (b.z - a.z));
    }
  }
  return len;
}

TEST(CuttingMarksTest, RegionGivesTheMarksInsideIt) {
  auto inst = PaperInstance("five-balls", 100);
  ASSERT_TRUE(inst.ok());
  auto wp = Cut(inst->stock, inst->moves);
  const auto all = Marks(*wp);
  for (const Rect r : {Rect{35.5, 28.25, 45.2, 61.9}, Rect{0, 0, 100, 100},
                       Rect{60, 60, 140, 75}}) {
    MarkOptions o;
    o.region = r;
    const auto part = Marks(*wp, o);
    ExpectClean(part, /*smooth=*/true);
    ASSERT_FALSE(part.empty());
    for (const MarkPolyline& p : part) {
      for (const Vec3& v : p.vertices) {
        EXPECT_TRUE(r.Contains(v.x, v.y)) << "(" << v.x << ", " << v.y << ")";
      }
    }
    const double want = ClippedLength(all, r);
    EXPECT_NEAR(Summarize(part).total_length, want, 1e-9 * want);
  }
}

TEST(CuttingMarksTest, SameResultWhateverTheThreads) {
  auto inst = PaperInstance("five-cylinders", 300);
  ASSERT_TRUE(inst.ok());
  ThreadPool one(1), four(4);
  auto a = Cut(inst->stock, inst->moves, SchemeKind::kTaylor, &one);
  auto b = Cut(inst->stock, inst->moves, SchemeKind::kTaylor, &four);
  const auto ma = Marks(*a), mb = Marks(*b), mb2 = Marks(*b);
  for (const auto* m : {&mb, &mb2}) {
    ASSERT_EQ(ma.size(), m->size());
    for (size_t k = 0; k < ma.size(); ++k) {
      const MarkPolyline& p = ma[k];
      const MarkPolyline& q = (*m)[k];
      EXPECT_EQ(p.closed, q.closed);
      EXPECT_EQ(p.owners, q.owners);
      ASSERT_EQ(p.vertices.size(), q.vertices.size());
      for (size_t i = 0; i < p.vertices.size(); ++i) {
        EXPECT_EQ(p.vertices[i].x, q.vertices[i].x);
        EXPECT_EQ(p.vertices[i].y, q.vertices[i].y);
        EXPECT_EQ(p.vertices[i].z, q.vertices[i].z);
        EXPECT_EQ(p.angle_deg[i], q.angle_deg[i]);
      }
    }
  }
}

// Bit for bit.
void ExpectSamePolyline(const MarkPolyline& p, const MarkPolyline& q) {
  EXPECT_EQ(p.closed, q.closed);
  EXPECT_EQ(p.owners, q.owners);
  ASSERT_EQ(p.vertices.size(), q.vertices.size());
  ASSERT_EQ(p.angle_deg.size(), q.angle_deg.size());
  EXPECT_EQ(p.vertex_owners, q.vertex_owners);
  for (size_t i = 0; i < p.vertices.size(); ++i) {
    EXPECT_EQ(p.vertices[i].x, q.vertices[i].x);
    EXPECT_EQ(p.vertices[i].y, q.vertices[i].y);
    EXPECT_EQ(p.vertices[i].z, q.vertices[i].z);
    EXPECT_EQ(p.angle_deg[i], q.angle_deg[i]);
  }
}

// Raster passes along x, 0.5 mm apart, over 500 element rows: a mark
// between every two passes, completed band by band, over several windows of
// bands (8 bands of 16 rows with one thread).
std::unique_ptr<Workpiece> LongRaster(ThreadPool* pool) {
  std::vector<Move> moves;
  for (int k = -5; k <= 105; ++k) {
    const double y = (k + 0.037) * 0.5;
    moves.push_back({{-3, y, -0.5}, {13, y, -0.5}, 2});
  }
  return Cut({0, 0, 10, 50, 0, 100, 500}, moves, SchemeKind::kTaylor, pool);
}

TEST(CuttingMarksTest, EmitStopsTheSearchAfterTheFirstPolylines) {
  ThreadPool one(1);
  auto wp = LongRaster(&one);
  const std::vector<MarkPolyline> all = Marks(*wp);
  ASSERT_GE(all.size(), 90u);
  for (size_t k : {size_t{0}, size_t{1}, size_t{7}, all.size() / 2,
                   all.size() - 1, all.size()}) {
    SCOPED_TRACE(k);
    std::vector<MarkPolyline> got;
    int calls = 0, polls = 0;
    const absl::Status st = FindCuttingMarks(
        *wp, {},
        [&](MarkPolyline p) {
          ++calls;
          if (got.size() == k) return absl::CancelledError("enough marks");
          got.push_back(std::move(p));
          return absl::OkStatus();
        },
        [&] {
          ++polls;
          return absl::OkStatus();
        });
    if (k < all.size()) {
      EXPECT_EQ(st, absl::CancelledError("enough marks"));
      EXPECT_EQ(calls, static_cast<int>(k) + 1);  // none after the stop
    } else {
      EXPECT_TRUE(st.ok()) << st;
      EXPECT_EQ(calls, static_cast<int>(k));
    }
    EXPECT_GE(polls, 1);
    ASSERT_EQ(got.size(), k);
    for (size_t i = 0; i < k; ++i) ExpectSamePolyline(got[i], all[i]);
  }
}

// Many threads search bands of fewer rows (8 on 8 threads, 4 on 16, so
// that the bands searched at once lie in two tile rows): the same marks, bit
// for bit, as one thread's bands of 16, in windows of the default size and
// of one band a thread.
TEST(CuttingMarksTest, ManyThreadsShorterBandsGiveTheSameMarks) {
  ThreadPool one(1);
  auto wp = LongRaster(&one);
  const std::vector<MarkPolyline> want = Marks(*wp);
  ASSERT_GE(want.size(), 90u);
  for (int threads : {8, 16}) {
    SCOPED_TRACE(threads);
    ThreadPool pool(threads);
    auto many = LongRaster(&pool);
    for (int64_t bytes : {MarkOptions().window_segment_bytes, int64_t{1}}) {
      SCOPED_TRACE(bytes);
      MarkOptions o;
      o.window_segment_bytes = bytes;
      const absl::StatusOr<std::vector<MarkPolyline>> got =
          FindCuttingMarks(*many, o);
      ASSERT_TRUE(got.ok()) << got.status();
      ASSERT_EQ(got->size(), want.size());
      for (size_t i = 0; i < want.size(); ++i) {
        ExpectSamePolyline((*got)[i], want[i]);
      }
    }
  }
}

// Windows as small as the thread count (one band each) where the segments
// would pass window_segment_bytes: the same marks, bit for bit, as windows
// of 8 bands; the budget is validated.
TEST(CuttingMarksTest, SmallerWindowsGiveTheSameMarks) {
  for (int threads : {1, 3}) {
    SCOPED_TRACE(threads);
    ThreadPool pool(threads);
    auto wp = LongRaster(&pool);
    const std::vector<MarkPolyline> all = Marks(*wp);
    ASSERT_GE(all.size(), 90u);
    MarkOptions o;
    o.window_segment_bytes = 1;
    int polls = 0, default_polls = 0;
    std::vector<MarkPolyline> got;
    ASSERT_TRUE(FindCuttingMarks(
                    *wp, o,
                    [&](MarkPolyline p) {
                      got.push_back(std::move(p));
                      return absl::OkStatus();
                    },
                    [&] {
                      ++polls;
                      return absl::OkStatus();
                    })
                    .ok());
    ASSERT_TRUE(FindCuttingMarks(
                    *wp, {}, [](MarkPolyline) { return absl::OkStatus(); },
                    [&] {
                      ++default_polls;
                      return absl::OkStatus();
                    })
                    .ok());
    // A poll a window: more windows, of one band a thread after the first.
    EXPECT_GT(polls, default_polls);
    ASSERT_EQ(got.size(), all.size());
    for (size_t k = 0; k < all.size(); ++k) ExpectSamePolyline(got[k], all[k]);
  }
  ThreadPool one(1);
  auto wp = LongRaster(&one);
  MarkOptions bad;
  bad.window_segment_bytes = 0;
  EXPECT_EQ(FindCuttingMarks(*wp, bad).status().code(),
            absl::StatusCode::kInvalidArgument);
}

// The streamed marks into *got until the poll after window `stop_at`
// stops the search with DeadlineExceeded("stop"); its status.
absl::Status MarksUntilPoll(const Workpiece& wp, int stop_at,
                            std::vector<MarkPolyline>* got) {
  int polls = 0;
  return FindCuttingMarks(
      wp, {},
      [&](MarkPolyline p) {
        got->push_back(std::move(p));
        return absl::OkStatus();
      },
      [&] {
        return ++polls == stop_at ? absl::DeadlineExceededError("stop")
                                  : absl::OkStatus();
      });
}

TEST(CuttingMarksTest, PollStopsTheSearchBetweenWindows) {
  ThreadPool one(1);
  auto wp = LongRaster(&one);
  const std::vector<MarkPolyline> all = Marks(*wp);
  // 500 rows: 32 bands, 4 windows. A chain is complete once a window has
  // passed without touching it, and handed on while the next window is
  // searched: the poll after the second window stops the search before any
  // is, the one after the third once the first window's marks are.
  std::vector<MarkPolyline> got;
  EXPECT_EQ(MarksUntilPoll(*wp, 2, &got), absl::DeadlineExceededError("stop"));
  EXPECT_TRUE(got.empty());
  EXPECT_EQ(MarksUntilPoll(*wp, 3, &got), absl::DeadlineExceededError("stop"));
  // The marks of the first window's passes, and none of the rest.
  EXPECT_GT(got.size(), 0u);
  EXPECT_LT(got.size(), all.size() / 2);
  for (size_t i = 0; i < got.size(); ++i) ExpectSamePolyline(got[i], all[i]);
  // Without a stop, a poll after every window.
  int polls = 0;
  size_t n = 0;
  ASSERT_TRUE(FindCuttingMarks(
                  *wp, {},
                  [&](MarkPolyline) {
                    ++n;
                    return absl::OkStatus();
                  },
                  [&] {
                    ++polls;
                    return absl::OkStatus();
                  })
                  .ok());
  EXPECT_EQ(n, all.size());
  EXPECT_EQ(polls, 4);
}

// A window of tens of thousands of crease segments is chained with its
// incidences sorted in buckets of keys on every thread (under 16 Ki
// segments, on one): the same marks as one thread's plain sort. Raster
// passes 0.3 mm apart across 1000 elements, and cross passes beside them
// for junctions.
TEST(CuttingMarksTest, ManySegmentsChainAsOnOneThread) {
  ThreadPool one(1), four(4);
  std::vector<Move> moves;
  for (int k = -3; k <= 200; ++k) {
    const double y = (k + 0.037) * 0.3;
    moves.push_back({{-3, y, -0.4}, {103, y, -0.4}, 1.5});
  }
  for (int k = 0; k < 12; ++k) {
    const double x = 4.1 + 8.3 * k;
    moves.push_back({{x, -3, -0.6}, {x, 63, -0.6}, 1.5});
  }
  const StockSpec stock{0, 0, 100, 60, 0, 1000, 600};
  auto wa = Cut(stock, moves, SchemeKind::kTaylor, &one);
  auto wb = Cut(stock, moves, SchemeKind::kTaylor, &four);
  const std::vector<MarkPolyline> a = Marks(*wa), b = Marks(*wb);
  // Every pass but the first few meets its neighbours: about 200 creases
  // across the stock, cut by the cross passes.
  size_t vertices = 0;
  for (const MarkPolyline& p : a) vertices += p.vertices.size();
  EXPECT_GT(vertices, 100000u);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) ExpectSamePolyline(a[i], b[i]);
}

// Guarded marks are projected onto the exact creases a window later, while
// the next window is chained: they are handed on after the window that
// follows the one that completed them, still before the search stops.
TEST(CuttingMarksTest, PollStopsGuardedMarksAWindowLater) {
  ThreadPool one(1), four(4);
  std::vector<MarkPolyline> reference;
  for (ThreadPool* pool : {&one, &four}) {
    std::vector<Move> moves;
    for (int k = -5; k <= 105; ++k) {
      const double y = (k + 0.037) * 0.5;
      moves.push_back({{-3, y, -0.5}, {13, y, -0.5}, 2});
    }
    auto wp =
        Cut({0, 0, 10, 50, 0, 100, 500}, moves, SchemeKind::kGuarded, pool);
    const std::vector<MarkPolyline> all = Marks(*wp);
    ASSERT_GE(all.size(), 90u);
    // One thread: 500 rows are 32 bands in 4 windows of 8. After the
    // second window, the first's chains are complete but not projected;
    // projected during the third, they are handed on during the fourth.
    for (int stop_at : {3, 4}) {
      if (pool == &four) break;
      std::vector<MarkPolyline> got;
      EXPECT_EQ(MarksUntilPoll(*wp, stop_at, &got),
                absl::DeadlineExceededError("stop"));
      if (stop_at == 3) {
        EXPECT_EQ(got.size(), 0u);
      } else {
        EXPECT_GT(got.size(), 0u);
        EXPECT_LT(got.size(), all.size() / 2);
      }
      for (size_t i = 0; i < got.size(); ++i) {
        ExpectSamePolyline(got[i], all[i]);
      }
    }
    // Four threads (other windows, finished beside other chaining): the
    // same marks in the same order as one thread's.
    if (pool == &one) {
      reference = all;
    } else {
      ASSERT_EQ(all.size(), reference.size());
      for (size_t i = 0; i < all.size(); ++i) {
        ExpectSamePolyline(all[i], reference[i]);
      }
    }
  }
}

TEST(CuttingMarksTest, UntouchedStockHasNoMarks) {
  auto wp = Cut({0, 0, 10, 10, 0, 50, 50}, {});
  EXPECT_TRUE(Marks(*wp).empty());
}

TEST(CuttingMarksTest, ZmapIsAFailedPrecondition) {
  auto wp = Cut({0, 0, 10, 10, 0, 50, 50}, {{{5, 5, 1}, {5, 5, -1}, 2}},
                SchemeKind::kZmap);
  auto marks = FindCuttingMarks(*wp);
  EXPECT_EQ(marks.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(marks.status().message().find("taylor"), std::string::npos);
}

TEST(CuttingMarksTest, BadOptionsNameTheField) {
  auto wp = Cut({0, 0, 10, 10, 0, 50, 50}, {{{5, 5, 1}, {5, 5, -1}, 2}});
  const double nan = std::nan("");
  struct Case {
    MarkOptions o;
    const char* field;
  };
  std::vector<Case> cases;
  auto add = [&](auto edit, const char* field) {
    MarkOptions o;
    edit(o);
    cases.push_back({o, field});
  };
  add([](MarkOptions& o) { o.t2_deg = 0; }, "t2_deg");
  add([](MarkOptions& o) { o.t2_deg = 90; }, "t2_deg");
  add([&](MarkOptions& o) { o.t2_deg = nan; }, "t2_deg");
  add([](MarkOptions& o) { o.t1 = 0; }, "t1");
  add([](MarkOptions& o) { o.screening_threshold = -1; },
      "screening_threshold");
  add([&](MarkOptions& o) { o.screening_threshold = nan; },
      "screening_threshold");
  add([&](MarkOptions& o) { o.region = Rect{nan, 0, 1, 1}; }, "region.x0");
  add([&](MarkOptions& o) { o.region = Rect{0, 0, 1, kInf}; }, "region.y1");
  add([](MarkOptions& o) { o.region = Rect{5, 0, 4, 1}; }, "region.x1");
  add([](MarkOptions& o) { o.region = Rect{0, 5, 1, 4}; }, "region.y1");
  add([](MarkOptions& o) { o.region = Rect{20, 20, 30, 30}; }, "region");
  for (const Case& c : cases) {
    auto marks = FindCuttingMarks(*wp, c.o);
    EXPECT_EQ(marks.status().code(), absl::StatusCode::kInvalidArgument)
        << c.field;
    EXPECT_NE(marks.status().message().find(c.field), std::string::npos)
        << marks.status().message();
  }
}

TEST(CuttingMarksTest, EquationHelpers) {
  // Eq. (3): a node's own patch agrees with itself; the top and a plane of
  // slope 0.1 through one node miss by the slope times h at the other.
  SurfaceJet plane{1, 0.1, 0, 0, 0, 0};
  EXPECT_EQ(ScreeningMismatch(plane, 0, 0, {1.05, 0.1, 0, 0, 0, 0}, 0.5, 0),
            0);
  EXPECT_NEAR(ScreeningMismatch(SurfaceJet{1, 0, 0, 0, 0, 0}, 0.5, 0, plane,
                                0, 0),
              0.05 + 0, 1e-15);
  EXPECT_NEAR(DefaultScreeningThreshold(0.5, 0.04), 0.005, 1e-15);
  // Eq. (4)-(5).
  EXPECT_EQ(PatchGap(1, 3), 2);
  EXPECT_EQ(SlopeDifference(1, -1, 0, 1), 3);
  // Normals of slopes +-tan(30 deg) in x differ by 60 degrees.
  const double t = std::tan(std::numbers::pi / 6);
  EXPECT_NEAR(NormalAngle(t, 0, -t, 0), std::numbers::pi / 3, 1e-14);
  EXPECT_NEAR(NormalAngle(0, 0, 0, 1e-9), 1e-9, 1e-22);
  for (double a : {0.01, 0.3, 2.0, 50.0}) {
    EXPECT_LE(NormalAngle(a, 0.3 * a, -0.2, 0.1),
              SlopeDifference(a, 0.3 * a, -0.2, 0.1));
  }
}

}  // namespace
}  // namespace swarf
