// The design model and the deviation: analytic cases (a ball's scallop on a
// flat floor, one raster line run deeper, a pocket wall left or cut by e, an
// overhang), the readers' bad input, STEP against STL of the same part, and
// `swarf run --design` end to end (stats.json, deviation.png, exit status 3).
#include "client/outputs/deviation.h"

#include <unistd.h>

#include <BRepMesh_IncrementalMesh.hxx>
#include <BRepPrimAPI_MakeBox.hxx>
#include <STEPControl_Writer.hxx>
#include <StlAPI_Writer.hxx>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "client/cli/commands.h"
#include "client/outputs/png_image.h"
#include "client/outputs/surface_grid.h"
#include "core/workpiece.h"
#include "design/closest_point.h"
#include "design/design_mesh.h"
#include "design/top_envelope.h"
#include "gtest/gtest.h"

namespace swarf {
namespace {

using cli::DeviationOptions;
using cli::DeviationReport;
using cli::SourceLine;
using cli::SurfaceGrid;
using design::DesignMesh;

// Quads (4 corners, counter-clockwise from above) as a triangle soup.
void AddQuad(std::vector<double>& soup, Vec3 a, Vec3 b, Vec3 c, Vec3 d) {
  for (const Vec3& p : {a, b, c, a, c, d}) {
    soup.insert(soup.end(), {p.x, p.y, p.z});
  }
}

DesignMesh Mesh(const std::vector<double>& soup) {
  auto m = design::MeshFromSoup(soup, "test");
  EXPECT_TRUE(m.ok()) << m.status();
  return *std::move(m);
}

DesignMesh Plane(double x0, double y0, double x1, double y1, double z) {
  std::vector<double> soup;
  AddQuad(soup, {x0, y0, z}, {x1, y0, z}, {x1, y1, z}, {x0, y1, z});
  return Mesh(soup);
}

// A step: the part's top z=0 for x < xw, a vertical wall at xw down to a
// floor at z=-depth for x > xw (an open surface, as CAM exports a top).
DesignMesh Step(double xw, double depth, double size) {
  std::vector<double> soup;
  AddQuad(soup, {-1, -1, 0}, {xw, -1, 0}, {xw, size + 1, 0}, {-1, size + 1, 0});
  AddQuad(soup, {xw, -1, 0}, {xw, -1, -depth}, {xw, size + 1, -depth},
          {xw, size + 1, 0});
  AddQuad(soup, {xw, -1, -depth}, {size + 1, -1, -depth},
          {size + 1, size + 1, -depth}, {xw, size + 1, -depth});
  return Mesh(soup);
}

StockSpec Stock(double size, double spacing) {
  const int32_t n = static_cast<int32_t>(std::lround(size / spacing));
  return {0, 0, size, size, 0, n, n};
}

struct Cut {
  SurfaceGrid grid;
  std::vector<SourceLine> lines;  // move id -> line
};

// Applies `moves`; move k comes from line 100 + k.
Cut Simulate(const StockSpec& spec, const std::vector<Move>& moves) {
  auto wp = Workpiece::Create(spec, SchemeKind::kGuarded);
  EXPECT_TRUE(wp.ok()) << wp.status();
  auto applied = (*wp)->Apply(moves);
  EXPECT_TRUE(applied.ok()) << applied.status();
  auto g = SurfaceGrid::FromWorkpiece(**wp);
  EXPECT_TRUE(g.ok()) << g.status();
  Cut c{*std::move(g), {}};
  c.grid.SetMoves(moves);
  for (size_t k = 0; k < moves.size(); ++k) {
    c.lines.push_back({0, static_cast<int32_t>(100 + k)});
  }
  return c;
}

DeviationReport Measure(const Cut& cut, const DesignMesh& mesh,
                        const DeviationOptions& o = {}) {
  auto env = design::TopEnvelope::Build(mesh, cut.grid.geometry());
  EXPECT_TRUE(env.ok()) << env.status();
  auto index = design::ClosestPointIndex::Build(mesh);
  EXPECT_TRUE(index.ok()) << index.status();
  auto r = cli::MeasureDeviation(cut.grid, *env, **index, cut.lines, o);
  EXPECT_TRUE(r.ok()) << r.status();
  return *std::move(r);
}

// Raster passes along x at y = k * s (k = -1 .. n), tip at z; one move a
// pass (the passes' links lie outside the stock, above it).
std::vector<Move> Raster(double size, double s, double z, double r,
                         int deep_pass = -100, double deep_z = 0) {
  std::vector<Move> moves;
  const Cutter ball = Cutter::Ball(r);
  for (int k = -1; k * s <= size + s; ++k) {
    const double y = k * s;
    const double zz = k == deep_pass ? deep_z : z;
    moves.emplace_back(Vec3{-r - 1, y, zz}, Vec3{size + r + 1, y, zz}, ball);
  }
  return moves;
}

TEST(DeviationTest, BallScallopsOnAFloorAreTheirAnalyticHeight) {
  const double R = 2, s = 1, floor = -1;
  const Cut cut = Simulate(Stock(20, 0.05), Raster(20, s, floor, R));
  const double h = R - std::sqrt(R * R - s * s / 4);  // 0.0635083
  DeviationOptions o;
  o.tolerance = 0.07;
  const DeviationReport r = Measure(cut, Plane(-5, -5, 25, 25, floor), o);
  // Nodes lie on the cusps (y = k + 0.5); samples between nodes come
  // through the scheme, which never rises above the highest swept surface.
  EXPECT_NEAR(r.excess_max, h, 1e-9);
  EXPECT_NEAR(std::fmod(r.excess_y, s), 0.5, 1e-9);
  EXPECT_LE(r.gouge_max, 1e-9);
  EXPECT_NEAR(r.normal_excess_max, h, 1e-9);  // the floor is level
  EXPECT_TRUE(r.ok);
  EXPECT_EQ(r.nodes, 401 * 401);
  EXPECT_EQ(r.samples, int64_t{400} * 400 * 21);
  // Tighter than the scallop: out, but nothing gouges.
  o.tolerance = 0.05;
  const DeviationReport tight = Measure(cut, Plane(-5, -5, 25, 25, floor), o);
  EXPECT_FALSE(tight.ok);
  EXPECT_TRUE(tight.gouge_lines.empty());
  EXPECT_GT(tight.out_area_mm2, 0);
  // An allowance of 0.02 takes the same scallops back in.
  o.allowance = 0.02;
  EXPECT_TRUE(Measure(cut, Plane(-5, -5, 25, 25, floor), o).ok);
}

TEST(DeviationTest, ADeeperLineGougesByItsDepthAndIsNamed) {
  const double R = 2, s = 1, floor = -1, d = 0.3;
  const int deep = 10;  // the pass at y = 10: move 11, line 111
  const Cut cut =
      Simulate(Stock(20, 0.05), Raster(20, s, floor, R, deep, floor - d));
  DeviationOptions o;
  o.tolerance = 0.01;
  o.allowance = 0.06;  // the scallops (0.0635) are within A + T
  const DeviationReport r = Measure(cut, Plane(-5, -5, 25, 25, floor), o);
  EXPECT_NEAR(r.gouge_max, d, 1e-9);
  EXPECT_NEAR(r.gouge_y, 10, 1e-9);
  EXPECT_EQ(r.gouge_move, deep + 1);
  EXPECT_NEAR(r.normal_gouge_max, d, 1e-9);
  EXPECT_FALSE(r.ok);
  ASSERT_EQ(r.gouge_lines.size(), 1u);
  EXPECT_EQ(r.gouge_lines[0].line, 100 + deep + 1);
  EXPECT_NEAR(r.gouge_lines[0].depth, d, 1e-9);
  // The groove deeper than the tolerance: |y - 10| < sqrt(R^2 - (R-d+T)^2)
  // over the stock's 20 mm; node cells are off by at most one row a side.
  const double half = std::sqrt(R * R - std::pow(R - d + o.tolerance, 2));
  EXPECT_NEAR(r.gouge_lines[0].area_mm2, 20 * 2 * half, 2 * 20 * 0.05);
  EXPECT_NEAR(r.out_area_mm2, r.gouge_lines[0].area_mm2, 1e-9);
  // The groove's volume below the floor: its cross-section (a circular
  // segment of height d) along 20 mm, to the node quadrature.
  const double seg = R * R * std::acos((R - d) / R) -
                     (R - d) * std::sqrt(2 * R * d - d * d);
  EXPECT_NEAR(r.gouge_volume, 20 * seg, 0.01 * 20 * seg);
}

TEST(DeviationTest, AWallLeftByEShowsENormallyAndItsDepthVertically) {
  const double e = 0.3, depth = 5, wall = 10, r = 1, sp = 0.05;
  std::vector<Move> moves;
  const Cutter flat = Cutter::Flat(r);
  // The floor cut from x = wall + e on (the tool's side on the wall line).
  for (double xc = wall + e + r; xc < 22 + r; xc += 1.5) {
    moves.emplace_back(Vec3{xc, -2, -depth}, Vec3{xc, 22, -depth}, flat);
  }
  const Cut cut = Simulate(Stock(20, sp), moves);
  DeviationOptions o;
  o.tolerance = 0.1;
  const DeviationReport d = Measure(cut, Step(wall, depth, 20), o);
  EXPECT_NEAR(d.excess_max, depth, 1e-9);  // the uncut strip's top
  EXPECT_LE(d.normal_excess_max, e + 1e-9);
  EXPECT_GE(d.normal_excess_max, e - sp - 1e-9);
  EXPECT_LE(d.gouge_max, 1e-9);
  EXPECT_FALSE(d.ok);  // e > the tolerance
  o.tolerance = 0.35;  // e within it: in, though dz is 5 mm there
  EXPECT_TRUE(Measure(cut, Step(wall, depth, 20), o).ok);
}

TEST(DeviationTest, AWallCutByEGougesENormally) {
  const double e = 0.3, depth = 5, wall = 10, r = 1, sp = 0.05;
  std::vector<Move> moves;
  const Cutter flat = Cutter::Flat(r);
  for (double xc = wall - e + r; xc < 22 + r; xc += 1.5) {
    moves.emplace_back(Vec3{xc, -2, -depth}, Vec3{xc, 22, -depth}, flat);
  }
  const Cut cut = Simulate(Stock(20, sp), moves);
  DeviationOptions o;
  o.tolerance = 0.1;
  const DeviationReport d = Measure(cut, Step(wall, depth, 20), o);
  EXPECT_NEAR(d.gouge_max, depth, 1e-9);
  EXPECT_LE(d.normal_gouge_max, e + 1e-9);
  EXPECT_GE(d.normal_gouge_max, e - sp - 1e-9);
  EXPECT_FALSE(d.ok);
  ASSERT_FALSE(d.gouge_lines.empty());
  EXPECT_EQ(d.gouge_lines[0].line, 100);  // the first pass, along the wall
}

TEST(TopEnvelopeTest, AnOverhangKeepsItsTop) {
  std::vector<double> soup;
  AddQuad(soup, {0, 0, -5}, {20, 0, -5}, {20, 20, -5}, {0, 20, -5});  // floor
  // A shelf over x in [5, 15] at z = 0, its underside at z = -1.
  AddQuad(soup, {5, 0, 0}, {15, 0, 0}, {15, 20, 0}, {5, 20, 0});
  AddQuad(soup, {5, 0, -1}, {5, 20, -1}, {15, 20, -1}, {15, 0, -1});
  const DesignMesh m = Mesh(soup);
  const GridGeometry g(Stock(20, 0.5));
  auto env = design::TopEnvelope::Build(m, g);
  ASSERT_TRUE(env.ok()) << env.status();
  EXPECT_EQ(env->AtNode(20, 10), 0.0f);   // x = 10, under the shelf's top
  EXPECT_EQ(env->AtNode(4, 10), -5.0f);   // x = 2, the floor
  EXPECT_DOUBLE_EQ(env->At(10.25, 3.3), 0.0);
  EXPECT_DOUBLE_EQ(env->At(2.25, 3.3), -5.0);
  EXPECT_EQ(env->covered_nodes(), 41 * 41);
  // A point beyond the design: nothing to keep.
  const DesignMesh corner = Plane(0, 0, 5, 5, 0);  // outlives its envelope
  auto small = design::TopEnvelope::Build(corner, g);
  ASSERT_TRUE(small.ok());
  EXPECT_TRUE(std::isnan(small->AtNode(40, 40)));
  EXPECT_TRUE(std::isnan(small->At(7, 7)));
  EXPECT_EQ(small->covered_nodes(), 11 * 11);
}

TEST(TopEnvelopeTest, ANearVerticalSliverNeverReachesBeyondItsHeights) {
  // A wall 1e-9 mm out of vertical, 10 mm high: inside its XY projection
  // rounding may not extrapolate the plane beyond the wall's heights.
  std::vector<double> soup = {0, 0, 0, 0, 10, 0, 1e-9, 5, 10};
  const DesignMesh m = Mesh(soup);
  const GridGeometry g(Stock(10, 0.5));
  auto env = design::TopEnvelope::Build(m, g);
  ASSERT_TRUE(env.ok());
  for (double y = 0; y <= 10; y += 0.125) {
    for (double x : {0.0, 1e-10, 5e-10}) {
      const double z = env->At(x, y);
      if (!std::isnan(z)) {
        EXPECT_GE(z, 0);
        EXPECT_LE(z, 10);
      }
    }
  }
}

TEST(TopEnvelopeTest, ASlopeIsInterpolatedExactly) {
  std::vector<double> soup;
  // z = 0.25 x - 0.5 y - 3 over [0, 8]^2.
  auto z = [](double x, double y) { return 0.25 * x - 0.5 * y - 3; };
  AddQuad(soup, {0, 0, z(0, 0)}, {8, 0, z(8, 0)}, {8, 8, z(8, 8)},
          {0, 8, z(0, 8)});
  const DesignMesh m = Mesh(soup);
  const GridGeometry g(Stock(8, 0.25));
  auto env = design::TopEnvelope::Build(m, g);
  ASSERT_TRUE(env.ok());
  for (int32_t j = 0; j <= 32; j += 3) {
    for (int32_t i = 0; i <= 32; i += 5) {
      EXPECT_FLOAT_EQ(env->AtNode(i, j), z(g.NodeX(i), g.NodeY(j)));
    }
  }
  EXPECT_NEAR(env->At(3.1, 4.7), z(3.1, 4.7), 1e-12);
}

// A pyramid whose faces are fans of long thin triangles from its apex, over
// a fan of its underside (as CAD exports planar faces): each small
// rectangle's candidates are the few slivers that can hold its points,
// and the envelope from them (and At's) is every triangle's, bit for bit,
// at every point of the rectangle (its corners and edges too), as are the
// nodes'.
TEST(TopEnvelopeTest, AFansCandidatesAreTheSliversOverTheRectangle) {
  std::vector<double> soup;
  const Vec3 apex{10, 10, 1}, under{10, 10, -5};
  constexpr int kPerSide = 40;
  std::vector<Vec3> rim;
  for (int k = 0; k < 4 * kPerSide; ++k) {
    const double f = 20.0 * (k % kPerSide) / kPerSide;
    const int side = k / kPerSide;
    const double x = side == 0 ? f : side == 1 ? 20 : side == 2 ? 20 - f : 0;
    const double y = side == 0 ? 0 : side == 1 ? f : side == 2 ? 20 : 20 - f;
    rim.push_back({x, y, 0});
  }
  for (size_t k = 0; k < rim.size(); ++k) {
    const Vec3& a = rim[k];
    const Vec3& b = rim[(k + 1) % rim.size()];
    for (const Vec3& p : {apex, a, b, under, b, a}) {
      soup.insert(soup.end(), {p.x, p.y, p.z});
    }
  }
  const DesignMesh m = Mesh(soup);
  const GridGeometry g(Stock(20, 0.1));
  auto env = design::TopEnvelope::Build(m, g);
  ASSERT_TRUE(env.ok()) << env.status();
  // Every triangle, as the envelope's own test sees it.
  std::vector<int32_t> every(m.triangles.size());
  std::iota(every.begin(), every.end(), 0);
  std::vector<int32_t> candidates;
  size_t most_away = 0;  // away from the apex
  int compared = 0;
  for (double y0 = 0; y0 < 20; y0 += 0.7) {
    for (double x0 = 0; x0 < 20; x0 += 0.3) {
      const Rect r{x0, y0, x0 + 0.1, y0 + 0.1};
      env->Candidates(r, &candidates);
      if (std::hypot(x0 - 10, y0 - 10) > 3) {
        most_away = std::max(most_away, candidates.size());
      }
      std::vector<double> xs, ys;
      for (int t = 0; t <= 4; ++t) {
        for (int s = 0; s <= 4; ++s) {
          xs.push_back(s == 4 ? r.x1 : r.x0 + s * 0.1 / 4);
          ys.push_back(t == 4 ? r.y1 : r.y0 + t * 0.1 / 4);
        }
      }
      std::vector<double> zs(xs.size());
      env->AtManyAmong(candidates, xs.data(), ys.data(),
                       static_cast<int32_t>(xs.size()), zs.data());
      for (size_t q = 0; q < xs.size(); ++q) {
        const double want = env->AtAmong(every, xs[q], ys[q]);
        ASSERT_FALSE(std::isnan(want)) << xs[q] << " " << ys[q];
        ASSERT_EQ(zs[q], want) << xs[q] << " " << ys[q];
        ASSERT_EQ(env->At(xs[q], ys[q]), want) << xs[q] << " " << ys[q];
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 29 * 67 * 25);
  // The nodes, rasterized run by run: every triangle's too.
  for (int32_t j = 0; j < g.nodes_y(); ++j) {
    for (int32_t i = 0; i < g.nodes_x(); ++i) {
      const double want = env->AtAmong(every, g.NodeX(i), g.NodeY(j));
      ASSERT_EQ(env->AtNode(i, j), static_cast<float>(want)) << i << " " << j;
    }
  }
  // Two or three slivers of each fan; by their XY bounds alone, dozens.
  EXPECT_LE(most_away, 8u);
}

TEST(ClosestPointTest, DistancesToABoxAndItsUndersideIsIgnored) {
  // A closed box [0,10]x[0,10]x[-2,0], outward winding.
  std::vector<double> soup;
  AddQuad(soup, {0, 0, 0}, {10, 0, 0}, {10, 10, 0}, {0, 10, 0});      // top
  AddQuad(soup, {0, 0, -2}, {0, 10, -2}, {10, 10, -2}, {10, 0, -2});  // bottom
  AddQuad(soup, {0, 0, -2}, {10, 0, -2}, {10, 0, 0}, {0, 0, 0});      // y=0
  AddQuad(soup, {10, 10, -2}, {0, 10, -2}, {0, 10, 0}, {10, 10, 0});  // y=10
  AddQuad(soup, {0, 10, -2}, {0, 0, -2}, {0, 0, 0}, {0, 10, 0});      // x=0
  AddQuad(soup, {10, 0, -2}, {10, 10, -2}, {10, 10, 0}, {10, 0, 0});  // x=10
  const DesignMesh m = Mesh(soup);
  EXPECT_TRUE(m.closed);
  EXPECT_TRUE(m.outward);
  auto index = design::ClosestPointIndex::Build(m);
  ASSERT_TRUE(index.ok()) << index.status();
  Vec3 q;
  EXPECT_NEAR((*index)->Distance({5, 5, 0.5}, 10, &q), 0.5, 1e-12);
  EXPECT_NEAR(q.z, 0, 1e-12);
  EXPECT_NEAR((*index)->Distance({12, 5, -1}, 10), 2, 1e-12);  // the side
  // 1.8 deep inside a 2 mm plate: the top is 1.8 away; the underside (0.2
  // away) faces down, out of reach from above.
  EXPECT_NEAR((*index)->Distance({5, 5, -1.8}, 10), 1.8, 1e-12);
  // Nothing within the radius: the radius comes back.
  EXPECT_EQ((*index)->Distance({5, 5, 30}, 3), 3);
}

TEST(DesignMeshTest, BinaryAndAsciiStlReadTheSame) {
  const DesignMesh plane = Plane(0, 0, 4, 2, -1.5);
  const std::string bin = design::ToBinaryStl(plane);
  auto b = design::ParseStl(bin, "plane.stl");
  ASSERT_TRUE(b.ok()) << b.status();
  const std::string ascii =
      "solid p\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 -1.5\n"
      "   vertex 4 0 -1.5\n   vertex 4 2 -1.5\n  endloop\n endfacet\n"
      " facet normal 0 0 1\n  outer loop\n   vertex 0 0 -1.5\n"
      "   vertex 4 2 -1.5\n   vertex 0 2 -1.5\n  endloop\n endfacet\n"
      "endsolid p\n";
  auto a = design::ParseStl(ascii, "plane.stl");
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->triangles, b->triangles);
  ASSERT_EQ(a->vertices.size(), 4u);
  for (size_t k = 0; k < 4; ++k) {
    EXPECT_EQ(a->vertices[k].x, b->vertices[k].x);
    EXPECT_EQ(a->vertices[k].z, -1.5);
  }
  // Inches and an offset.
  design::DesignReadOptions o;
  o.scale = 25.4;
  o.offset = {1, 2, 3};
  auto in = design::ParseStl(ascii, "plane.stl", o);
  ASSERT_TRUE(in.ok());
  EXPECT_DOUBLE_EQ(in->x.hi, 4 * 25.4 + 1);
  EXPECT_DOUBLE_EQ(in->z.lo, -1.5 * 25.4 + 3);
}

TEST(DesignMeshTest, BadInputIsNamed) {
  auto code = [](const absl::StatusOr<DesignMesh>& m) {
    return m.status().code();
  };
  auto msg = [](const absl::StatusOr<DesignMesh>& m) {
    return std::string(m.status().message());
  };
  // Not STL at all.
  auto g = design::ParseStl("G0 X0 Y0\nG1 Z-1\n", "prog.nc");
  EXPECT_EQ(code(g), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(msg(g).find("prog.nc: not an STL file"), std::string::npos) << msg(g);
  // NaN, on its line.
  auto n = design::ParseStl(
      "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
      "vertex nan 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid\n",
      "nan.stl");
  EXPECT_EQ(code(n), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(msg(n).find("nan.stl: line 5"), std::string::npos) << msg(n);
  // Empty, and only degenerate triangles.
  EXPECT_NE(msg(design::ParseStl("solid e\nendsolid e\n", "e.stl"))
                .find("no triangles"),
            std::string::npos);
  std::vector<double> degenerate = {0, 0, 0, 1, 1, 1, 2, 2, 2};
  EXPECT_EQ(code(design::MeshFromSoup(degenerate, "d")),
            absl::StatusCode::kInvalidArgument);
  // Binary with a NaN.
  DesignMesh plane = Plane(0, 0, 1, 1, 0);
  std::string bin = design::ToBinaryStl(plane);
  const float nan = std::nanf("");
  std::memcpy(&bin[84 + 12], &nan, 4);
  auto bn = design::ParseStl(bin, "b.stl");
  EXPECT_EQ(code(bn), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(msg(bn).find("triangle 1"), std::string::npos) << msg(bn);
  // Non-manifold: three triangles on one edge.
  std::vector<double> fin;
  for (double z : {1.0, -1.0}) {
    fin.insert(fin.end(), {0, 0, 0, 1, 0, 0, 0.5, 1, z});
  }
  fin.insert(fin.end(), {0, 0, 0, 1, 0, 0, 0.5, -1, 0});
  auto nm = design::MeshFromSoup(fin, "fin.stl");
  EXPECT_EQ(code(nm), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(msg(nm).find("non-manifold"), std::string::npos) << msg(nm);
  EXPECT_NE(msg(nm).find("(0, 0, 0) - (1, 0, 0)"), std::string::npos) << msg(nm);
  // A coordinate the envelope's floats cannot hold.
  std::vector<double> far_z = {0, 0, 0, 1, 0, 0, 0, 1, 5e12};
  auto huge = design::MeshFromSoup(far_z, "huge.stl");
  EXPECT_EQ(code(huge), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(msg(huge).find("beyond"), std::string::npos) << msg(huge);
  // Over the limit.
  auto big = design::MeshFromSoup(fin, "fin.stl", 2);
  EXPECT_EQ(code(big), absl::StatusCode::kResourceExhausted);
  // Outside the stock.
  const DesignMesh far = Plane(100, 100, 110, 110, 0);
  auto out = design::TopEnvelope::Build(far, GridGeometry(Stock(20, 0.5)));
  EXPECT_EQ(out.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(out.status().message()).find("outside the stock"),
            std::string::npos);
  // A missing file.
  EXPECT_EQ(code(design::ReadDesignFile("/nonexistent/part.stl")),
            absl::StatusCode::kNotFound);
}

// A fresh directory, removed at the end.
class TempDir {
 public:
  TempDir() {
    std::string t = (std::filesystem::temp_directory_path() /
                     "swarf_deviation_XXXXXX").string();
    path_ = mkdtemp(t.data());
  }
  ~TempDir() { std::filesystem::remove_all(path_); }
  std::string operator/(const std::string& name) const {
    return (std::filesystem::path(path_) / name).string();
  }

 private:
  std::string path_;
};

TEST(DesignMeshTest, StepAndStlOfTheSamePartGiveTheSameVerdict) {
  TempDir dir;
  // A 20 x 20 x 3 block with its top at z = -1 (OpenCASCADE writes both).
  const TopoDS_Shape box =
      BRepPrimAPI_MakeBox(gp_Pnt(0, 0, -4), gp_Pnt(20, 20, -1)).Shape();
  STEPControl_Writer step;
  ASSERT_EQ(step.Transfer(box, STEPControl_AsIs), IFSelect_RetDone);
  ASSERT_EQ(step.Write((dir / "block.step").c_str()), IFSelect_RetDone);
  BRepMesh_IncrementalMesh mesh(box, 0.01);
  StlAPI_Writer stl;
  stl.ASCIIMode() = false;
  ASSERT_TRUE(stl.Write(box, (dir / "block.stl").c_str()));
  auto from_step = design::ReadDesignFile(dir / "block.step");
  ASSERT_TRUE(from_step.ok()) << from_step.status();
  auto from_stl = design::ReadDesignFile(dir / "block.stl");
  ASSERT_TRUE(from_stl.ok()) << from_stl.status();
  EXPECT_TRUE(from_step->closed);
  EXPECT_TRUE(from_stl->closed);
  const Cut cut = Simulate(Stock(20, 0.1), Raster(20, 1, -1, 2, 7, -1.2));
  DeviationOptions o;
  o.tolerance = 0.05;
  const DeviationReport a = Measure(cut, *from_step, o);
  const DeviationReport b = Measure(cut, *from_stl, o);
  EXPECT_FALSE(a.ok);
  EXPECT_EQ(a.ok, b.ok);
  EXPECT_NEAR(a.gouge_max, 0.2, 1e-9);
  EXPECT_NEAR(b.gouge_max, 0.2, 1e-9);
  EXPECT_NEAR(a.excess_max, b.excess_max, 1e-9);
  EXPECT_NEAR(a.normal_gouge_max, b.normal_gouge_max, 1e-9);
  EXPECT_NEAR(a.out_area_mm2, b.out_area_mm2, 1e-9);
  ASSERT_EQ(a.gouge_lines.size(), 1u);
  ASSERT_EQ(b.gouge_lines.size(), 1u);
  EXPECT_EQ(a.gouge_lines[0].line, b.gouge_lines[0].line);
}

// swarf run --design end to end: a G-code raster with one line too deep.
TEST(RunDesignTest, StatsJsonNamesTheGougingLineAndTheExitStatusIsThree) {
  TempDir dir;
  std::ofstream prog(dir / "raster.nc");
  int line = 0, gouge_line = 0;
  auto put = [&](const std::string& text) {
    prog << text << "\n";
    ++line;
  };
  put("G21 G90 G17");
  put("G0 Z5");
  for (int k = 0; k <= 20; ++k) {
    put(absl::StrFormat("G0 X-2 Y%d", k));
    put(absl::StrFormat("G1 Z%g F600", k == 9 ? -1.25 : -1.0));
    put("G1 X22");
    if (k == 9) gouge_line = line;
    put("G0 Z5");
  }
  prog << "M2\n";
  prog.close();
  {
    std::ofstream stl(dir / "floor.stl", std::ios::binary);
    stl << design::ToBinaryStl(Plane(-5, -5, 25, 25, -1));
  }
  const std::vector<std::string> base = {
      dir / "raster.nc", "--tool",  "ball:d=4", "--stock", "0,0,20,20,0",
      "--spacing",       "0.1",     "--design", dir / "floor.stl", "--quiet",
      "--out",           dir / "out"};
  std::vector<std::string> gated = base;
  gated.insert(gated.end(), {"--tolerance", "0.05"});
  EXPECT_EQ(cli::RunCommand(gated), 3);
  std::ifstream in(dir / "out/stats.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  const auto& d = j.at("deviation");
  EXPECT_EQ(d.at("ok"), false);
  EXPECT_EQ(d.at("triangles"), 2);
  EXPECT_NEAR(d.at("gouge").at("max").get<double>(), 0.25, 1e-9);
  EXPECT_EQ(d.at("gouge").at("line"), gouge_line);
  EXPECT_EQ(d.at("gouge").at("file"), dir / "raster.nc");
  const auto& lines = d.at("out_of_tolerance").at("lines");
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].at("line"), gouge_line);
  EXPECT_NEAR(lines[0].at("gouge_max").get<double>(), 0.25, 1e-9);
  EXPECT_NEAR(d.at("excess").at("max").get<double>(),
              2 - std::sqrt(4 - 0.25), 1e-6);
  EXPECT_EQ(d.at("tolerance"), 0.05);
  auto png = cli::ReadPng(dir / "out/deviation.png");
  ASSERT_TRUE(png.ok()) << png.status();
  EXPECT_GT(png->width(), 201);
  // Without --tolerance the verdict is reported but the run succeeds.
  EXPECT_EQ(cli::RunCommand(base), 0);
  // Bad design input: a clear error, exit 2, before anything is cut.
  std::vector<std::string> bad = base;
  bad[8] = dir / "raster.nc";
  EXPECT_EQ(cli::RunCommand(bad), 2);
  std::vector<std::string> units = base;
  units.insert(units.end(), {"--design-units", "furlong"});
  EXPECT_EQ(cli::RunCommand(units), 2);
  std::vector<std::string> offset = base;
  offset.insert(offset.end(), {"--design-offset", "500,0,0"});
  EXPECT_EQ(cli::RunCommand(offset), 2);  // outside the stock
}

}  // namespace
}  // namespace swarf
