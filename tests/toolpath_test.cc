// The toolpath parsers: G-code constructs with exact expected points, arcs
// (direction, chord error, exact ends), errors with line numbers, the
// corpus programs (../shared/corpus, read in place: skipped where absent,
// see tests/shared_files.h), the repository's generated examples, and XYZ
// input.
#include "gcode/toolpath.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numbers>
#include <random>
#include <string>
#include <system_error>
#include <thread>
#include <vector>

#include "absl/status/status.h"
#include "gcode/text.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/shared_files.h"

#ifndef SWARF_CORPUS_DIR
#error "SWARF_CORPUS_DIR must point at ../shared/corpus"
#endif
#ifndef SWARF_SOURCE_DIR
#error "SWARF_SOURCE_DIR must point at the repository"
#endif

namespace swarf::gcode {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::StartsWith;

constexpr double kPi = std::numbers::pi;

Toolpath Parse(const std::string& text, const GcodeOptions& options = {}) {
  absl::StatusOr<Toolpath> tp = ParseGcode(text, options);
  EXPECT_TRUE(tp.ok()) << tp.status() << "\nprogram:\n" << text;
  return tp.ok() ? *std::move(tp) : Toolpath();
}

std::vector<Vec3> Positions(const Toolpath& tp) {
  std::vector<Vec3> out;
  for (const ToolpathPoint& p : tp.points()) out.push_back(p.position);
  return out;
}

// A position equal to (x, y, z) bit for bit (up to the sign of zero).
auto At(double x, double y, double z) {
  return ::testing::AllOf(::testing::Field("x", &Vec3::x, x),
                          ::testing::Field("y", &Vec3::y, y),
                          ::testing::Field("z", &Vec3::z, z));
}

void ExpectPoint(const ToolpathPoint& p, double x, double y, double z, int line,
                 bool rapid) {
  EXPECT_EQ(p.position.x, x);
  EXPECT_EQ(p.position.y, y);
  EXPECT_EQ(p.position.z, z);
  EXPECT_EQ(p.line, line);
  EXPECT_EQ(p.rapid, rapid);
}

void ExpectError(const std::string& text, int line, const std::string& what) {
  const absl::StatusOr<Toolpath> tp = ParseGcode(text);
  ASSERT_FALSE(tp.ok()) << "program:\n" << text;
  EXPECT_EQ(tp.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(tp.status().message()),
              StartsWith("line " + std::to_string(line) + ": "))
      << text;
  EXPECT_THAT(std::string(tp.status().message()), HasSubstr(what)) << text;
}

double Dist(const Vec3& a, const Vec3& b) {
  return std::hypot(a.x - b.x, a.y - b.y, a.z - b.z);
}

double DistToSegment(const Vec3& p, const Vec3& a, const Vec3& b) {
  const double dx = b.x - a.x, dy = b.y - a.y, dz = b.z - a.z;
  const double len2 = dx * dx + dy * dy + dz * dz;
  double t =
      len2 > 0 ? ((p.x - a.x) * dx + (p.y - a.y) * dy + (p.z - a.z) * dz) / len2
               : 0;
  t = std::clamp(t, 0.0, 1.0);
  return Dist(p, {a.x + t * dx, a.y + t * dy, a.z + t * dz});
}

// A helical arc: centre (cx, cy), radius r, angle a0 + sweep t, z linear.
struct TrueArc {
  double cx, cy, r, a0, sweep, z0, z1;
  Vec3 At(double t) const {
    const double a = a0 + sweep * t;
    return {cx + r * std::cos(a), cy + r * std::sin(a), z0 + (z1 - z0) * t};
  }
};

// Largest distance from the true arc (densely sampled) to the polyline.
double MaxDeviation(const TrueArc& arc, const std::vector<Vec3>& poly) {
  double worst = 0;
  const int samples = 20000;
  for (int s = 0; s <= samples; ++s) {
    const Vec3 p = arc.At(static_cast<double>(s) / samples);
    double best = INFINITY;
    for (size_t i = 0; i + 1 < poly.size(); ++i) {
      best = std::min(best, DistToSegment(p, poly[i], poly[i + 1]));
    }
    worst = std::max(worst, best);
  }
  return worst;
}

// Signed swept angle of the polyline around (cx, cy): sum of the angles
// between consecutive points (each chord spans less than a half turn).
double SweptAngle(const std::vector<Vec3>& poly, double cx, double cy) {
  double total = 0;
  for (size_t i = 0; i + 1 < poly.size(); ++i) {
    const double ux = poly[i].x - cx, uy = poly[i].y - cy;
    const double vx = poly[i + 1].x - cx, vy = poly[i + 1].y - cy;
    total += std::atan2(ux * vy - uy * vx, ux * vx + uy * vy);
  }
  return total;
}

// ------------------------------------------------------------ linear moves

TEST(GcodeTest, StartsWhereXYZAreAllKnown) {
  const Toolpath tp = Parse("G21 G90\nG0 Z5\nG0 X1 Y2\nG1 Z-1\nX3\n");
  ASSERT_EQ(tp.point_count(), 3);
  ExpectPoint(tp.points()[0], 1, 2, 5, 3, true);
  EXPECT_TRUE(tp.points()[0].starts_run);
  ExpectPoint(tp.points()[1], 1, 2, -1, 4, false);
  EXPECT_FALSE(tp.points()[1].starts_run);
  ExpectPoint(tp.points()[2], 3, 2, -1, 5, false);
  EXPECT_EQ(tp.move_count(), 2);
  EXPECT_EQ(tp.run_count(), 1);
  EXPECT_TRUE(tp.notes().empty());
}

TEST(GcodeTest, WordsWithoutSpacesAndModalAxisWords) {
  const Toolpath tp = Parse(
      "T1M6\nG21\nG17\nG0Z20.000\nG0X0.000Y0.000S15000M3\n"
      "G1Z-17.368F6000.0\nG1X0.161\nX79.999\nY0.126\nX1.5Z-2\n");
  EXPECT_THAT(Positions(tp),
              ElementsAre(At(0.0, 0.0, 20.0), At(0.0, 0.0, -17.368),
                          At(0.161, 0.0, -17.368), At(79.999, 0.0, -17.368),
                          At(79.999, 0.126, -17.368), At(1.5, 0.126, -2.0)));
  EXPECT_TRUE(tp.points()[0].rapid);
  EXPECT_FALSE(tp.points()[3].rapid);  // modal G1
  EXPECT_EQ(tp.points()[3].line, 8);
  for (const ToolpathPoint& p : tp.points()) EXPECT_EQ(p.tool, 1);
  EXPECT_EQ(tp.ignored().at("S"), 1);
  EXPECT_EQ(tp.ignored().at("M3"), 1);
  EXPECT_EQ(tp.ignored().at("F"), 1);
  EXPECT_EQ(tp.ignored().at("G17"), 1);
}

TEST(GcodeTest, NumberFormsCaseAndBlanks) {
  const Toolpath tp = Parse(
      "g21 g0 x.5 y5. z-.25\n"
      "G1 X+2 Y -3 Z 0\n"
      "g1x-0.5y+.75z1.\n"
      "G01 X0010.0100\n");
  EXPECT_THAT(Positions(tp),
              ElementsAre(At(0.5, 5.0, -0.25), At(2.0, -3.0, 0.0),
                          At(-0.5, 0.75, 1.0), At(10.01, 0.75, 1.0)));
}

TEST(GcodeTest, CommentsLineNumbersPercentBlankLines) {
  const Toolpath tp = Parse(
      "%\n"
      "(a program) ; with comments\n"
      "\n"
      "N10 G21 (mm) G0 X1 (mid-line; with a semicolon) Y2 Z3 ; tail X9\n"
      "   \t\r\n"
      "N20 G1 X4 (MSG, hello)\n"
      "; X99\n"
      "(X98)\n"
      "%\n"
      "G0 X50\n");  // after the closing '%': not read
  EXPECT_THAT(Positions(tp), ElementsAre(At(1.0, 2.0, 3.0), At(4.0, 2.0, 3.0)));
  EXPECT_EQ(tp.points()[0].line, 4);
  EXPECT_EQ(tp.points()[1].line, 6);
  EXPECT_EQ(tp.source_lines(), 9);
  ASSERT_EQ(tp.notes().size(), 1u);
  EXPECT_THAT(tp.notes()[0], HasSubstr("ends on line 9; 1 lines"));
}

TEST(GcodeTest, CrLfLineEndings) {
  const Toolpath tp = Parse("G21\r\nG0 X1 Y2 Z3\r\nG1 X4\r\n");
  EXPECT_THAT(Positions(tp), ElementsAre(At(1.0, 2.0, 3.0), At(4.0, 2.0, 3.0)));
  EXPECT_EQ(tp.points()[1].line, 3);
}

TEST(GcodeTest, ZeroLengthMovesAddNoPoint) {
  const Toolpath tp =
      Parse("G21 G0 X0 Y0 Z20\nG0 Z20\nG0 X0 Y0 Z20\nG1 Z0\nG1 Z0\n");
  EXPECT_THAT(Positions(tp),
              ElementsAre(At(0.0, 0.0, 20.0), At(0.0, 0.0, 0.0)));
  EXPECT_EQ(tp.points()[1].line, 4);
}

TEST(GcodeTest, Inches) {
  const Toolpath tp =
      Parse("G20 G0 X1 Y2 Z3\nG1 X1.5\nG21 X10\nG20 G91 Y-0.1\n");
  EXPECT_THAT(Positions(tp),
              ElementsAre(At(1 * 25.4, 2 * 25.4, 3 * 25.4),
                          At(1.5 * 25.4, 2 * 25.4, 3 * 25.4),
                          At(10.0, 2 * 25.4, 3 * 25.4),
                          At(10.0, 2 * 25.4 + -0.1 * 25.4, 3 * 25.4)));
}

TEST(GcodeTest, IncrementalMode) {
  const Toolpath tp = Parse(
      "G21 G90 G0 X1 Y1 Z1\nG91 G1 X1 Y-2\nZ0.5\nG90 X0\nG91 X0.25 Y0.25\n");
  EXPECT_THAT(Positions(tp), ElementsAre(At(1.0, 1.0, 1.0), At(2.0, -1.0, 1.0),
                                         At(2.0, -1.0, 1.5), At(0.0, -1.0, 1.5),
                                         At(0.25, -0.75, 1.5)));
}

TEST(GcodeTest, IncrementalMoveOfAKnownAxisBeforeTheStart) {
  const Toolpath tp = Parse("G21 G0 Z10\nG91 Z-5\nG90 X1 Y2\n");
  EXPECT_THAT(Positions(tp), ElementsAre(At(1.0, 2.0, 5.0)));
}

TEST(GcodeTest, ModalMotionAndMotionWithoutAxes) {
  const Toolpath tp =
      Parse("G21 G0 X0 Y0 Z5\nG1\nZ0\nG0\nZ5\nG1 F100\nX1 F200\n");
  ASSERT_EQ(tp.point_count(), 4);
  EXPECT_FALSE(tp.points()[1].rapid);
  EXPECT_TRUE(tp.points()[2].rapid);
  EXPECT_FALSE(tp.points()[3].rapid);
  EXPECT_EQ(tp.ignored().at("F"), 2);
}

TEST(GcodeTest, DefaultUnitsAreMillimetresWithANote) {
  const Toolpath tp = Parse("G0 X1 Y2 Z3\nX2\n");
  EXPECT_THAT(Positions(tp), ElementsAre(At(1.0, 2.0, 3.0), At(2.0, 2.0, 3.0)));
  ASSERT_EQ(tp.notes().size(), 1u);
  EXPECT_THAT(tp.notes()[0], HasSubstr("millimetres assumed"));
}

TEST(GcodeTest, ProgramEndStopsReading) {
  const Toolpath tp = Parse("G21 G0 X0 Y0 Z0\nG1 X1 M30\nG0 X5\n%\n");
  EXPECT_THAT(Positions(tp), ElementsAre(At(0.0, 0.0, 0.0), At(1.0, 0.0, 0.0)));
  ASSERT_EQ(tp.notes().size(), 1u);
  EXPECT_THAT(tp.notes()[0], HasSubstr("ends on line 2; 1 lines"));
  // M2 too; a '%' that doesn't open the program is skipped.
  const Toolpath m2 = Parse("G21 G0 X0 Y0 Z0\n%\nX1\nM2\nX5\n");
  EXPECT_THAT(Positions(m2), ElementsAre(At(0.0, 0.0, 0.0), At(1.0, 0.0, 0.0)));
}

TEST(GcodeTest, BlockDeleteAndProgramNumber) {
  const Toolpath tp = Parse(
      "%\nO1234 (PART)\nG21 G0 X0 Y0 Z0\n/G1 X1\n/ (only a comment)\n%\n");
  EXPECT_THAT(Positions(tp), ElementsAre(At(0.0, 0.0, 0.0), At(1.0, 0.0, 0.0)));
  EXPECT_EQ(tp.ignored().at("O"), 1);
  EXPECT_EQ(tp.ignored().at("/"), 2);
}

TEST(GcodeTest, IgnoredWordsAreCountedAndSummarized) {
  const Toolpath tp = Parse(
      "G17 G40 G49 G80 G94 G54 G21 G90\n"
      "T1 M6\n"
      "S1000 M03 M8\n"
      "G43 H1 G0 X0 Y0 Z0 F100\n"
      "G4 P1\n"
      "G64 P0.01\n"
      "G61 G90.1\nG91.1\n"
      "M5 M9\n"
      "M30\n");
  EXPECT_EQ(tp.ignored().at("M3"), 1);
  EXPECT_EQ(tp.ignored().at("P"), 2);
  EXPECT_EQ(tp.ignored().count("G21"), 0u);  // handled, not ignored
  EXPECT_EQ(tp.ignored().count("M6"), 0u);
  EXPECT_EQ(tp.ignored().count("T"), 0u);
  EXPECT_EQ(tp.ignored_total(), 19);
  EXPECT_EQ(tp.IgnoredSummary(),
            "ignored 19 words that don't move the tool: G4 x1, G17 x1, "
            "G40 x1, G43 x1, G49 x1, G54 x1, G61 x1, G64 x1, G80 x1, G94 x1, "
            "M3 x1, M5 x1, M8 x1, M9 x1, F x1, H x1, P x2, S x1");
  EXPECT_EQ(Parse("G21 G0 X0 Y0 Z0\n").IgnoredSummary(), "");
}

// ------------------------------------------------------------------ tools

TEST(GcodeTest, ToolNumbers) {
  // T alone selects before any M6; after an M6 a T only pre-selects.
  const Toolpath tp =
      Parse("G21\nT3\nG0 X0 Y0 Z10\nT4 M6\nT5\nG0 X1 Y0 Z10\nG1 Z0\n");
  ASSERT_EQ(tp.point_count(), 3);
  EXPECT_EQ(tp.points()[0].tool, 3);
  EXPECT_EQ(tp.points()[1].tool, 4);
  EXPECT_EQ(tp.points()[2].tool, 4);
  EXPECT_THAT(tp.Tools(), ElementsAre(3, 4));
  EXPECT_THAT(Parse("G21 G0 X0 Y0 Z0\n").Tools(), ElementsAre(0));
}

TEST(GcodeTest, ToolChangeStartsANewRun) {
  // With m6_forgets_position (swarf before issue 27; the default keeps the
  // position, as LinuxCNC: GcodeTest.M6KeepsThePosition).
  GcodeOptions forget;
  forget.m6_forgets_position = true;
  const Toolpath tp = Parse(
      "G21 T1 M6\nG0 X0 Y0 Z10\nG1 Z0\nG0 Z10\n"
      "T2 M6\nG0 X5 Y5\nG43 H2 Z10\nG1 Z0\n", forget);
  EXPECT_THAT(Positions(tp), ElementsAre(At(0.0, 0.0, 10.0), At(0.0, 0.0, 0.0),
                                         At(0.0, 0.0, 10.0), At(5.0, 5.0, 10.0),
                                         At(5.0, 5.0, 0.0)));
  EXPECT_TRUE(tp.points()[3].starts_run);
  EXPECT_EQ(tp.points()[3].line, 7);
  EXPECT_EQ(tp.points()[3].tool, 2);
  EXPECT_EQ(tp.points()[2].tool, 1);
  EXPECT_EQ(tp.run_count(), 2);
  EXPECT_EQ(tp.move_count(), 3);
  EXPECT_THAT(tp.Tools(), ElementsAre(1, 2));
  // After a change the position is unknown again.
  EXPECT_THAT(
      std::string(ParseGcode("G21 G0 X0 Y0 Z0\nT2 M6\nG91 G0 Z5\n", forget)
                      .status()
                      .message()),
      StartsWith("line 3: incremental (G91) Z move while Z is unknown"));
  EXPECT_THAT(
      std::string(ParseGcode("G21 G0 X0 Y0 Z0\nM6\nG2 X1 Y0 I0.5\n", forget)
                      .status()
                      .message()),
      HasSubstr("before the start position is known"));
}

// ------------------------------------------------------------------- arcs

TEST(GcodeArcTest, G2IsClockwiseG3Counterclockwise) {
  const std::string start = "G21 G0 X10 Y0 Z0\n";
  const Toolpath cw = Parse(start + "G2 X0 Y-10 I-10 J0\n");
  const Toolpath ccw = Parse(start + "G3 X0 Y-10 I-10 J0\n");
  const std::vector<Vec3> a = Positions(cw), b = Positions(ccw);
  // Endpoints exact; every chord turns the programmed way.
  EXPECT_THAT(a.back(), At(0.0, -10.0, 0.0));
  EXPECT_THAT(b.back(), At(0.0, -10.0, 0.0));
  EXPECT_NEAR(SweptAngle(a, 0, 0), -kPi / 2, 1e-12);
  EXPECT_NEAR(SweptAngle(b, 0, 0), 3 * kPi / 2, 1e-12);
  for (size_t i = 1; i + 1 < a.size(); ++i) {
    EXPECT_NEAR(std::hypot(a[i].x, a[i].y), 10, 1e-12);
    EXPECT_LT(a[i].x * a[i + 1].y - a[i].y * a[i + 1].x, 0);  // clockwise
    EXPECT_EQ(a[i].z, 0);
  }
  for (size_t i = 1; i + 1 < b.size(); ++i) {
    EXPECT_NEAR(std::hypot(b[i].x, b[i].y), 10, 1e-12);
    EXPECT_GT(b[i].x * b[i + 1].y - b[i].y * b[i + 1].x, 0);
  }
  // G3 goes through (0, 10), the long way round.
  EXPECT_NEAR(std::max_element(b.begin(), b.end(),
                               [](auto& p, auto& q) { return p.y < q.y; })
                  ->y,
              10, 1e-3);
  EXPECT_NEAR(b.size() - 1.0, 3 * (a.size() - 1.0), 1.0);
  for (size_t i = 1; i < a.size(); ++i) {
    EXPECT_EQ(cw.points()[i].line, 2);
    EXPECT_FALSE(cw.points()[i].rapid);
  }
}

TEST(GcodeArcTest, ChordErrorWithinTolerance) {
  for (double tol : {0.0005, 0.001, 0.01, 0.1}) {
    for (double r : {0.5, 10.0, 300.0}) {
      GcodeOptions options;
      options.arc_tolerance = tol;
      const std::string prog = "G21 G0 X" + std::to_string(r) +
                               " Y0 Z0\nG3 X0 Y" + std::to_string(r) + " I-" +
                               std::to_string(r) + " J0\n";
      const std::vector<Vec3> pts = Positions(Parse(prog, options));
      if (r * (1 - std::cos(kPi / 4)) < tol * 0.9) continue;  // one chord
      const double dev = MaxDeviation({0, 0, r, 0, kPi / 2, 0, 0}, pts);
      EXPECT_LE(dev, tol * (1 + 1e-9)) << "tol " << tol << " r " << r;
      // Not over-segmented: one chord fewer would exceed the tolerance.
      const double n = pts.size() - 1.0;
      if (n < 2) continue;
      EXPECT_GT(r * (1 - std::cos(kPi / 2 / (n - 1) / 2)), tol)
          << "tol " << tol << " r " << r << " n " << n;
    }
  }
}

TEST(GcodeArcTest, FullCircles) {
  // I/J with start == end: 360 degrees; Fanuc-style without X/Y too.
  for (const std::string arc : {"G2 X0 Y0 I5 J0\n", "G2 I5\n"}) {
    const Toolpath tp = Parse("G21 G0 X0 Y0 Z0\n" + arc);
    const std::vector<Vec3> pts = Positions(tp);
    EXPECT_THAT(pts.back(), At(0.0, 0.0, 0.0));
    EXPECT_NEAR(SweptAngle(pts, 5, 0), -2 * kPi, 1e-12);
    EXPECT_LE(MaxDeviation({5, 0, 5, kPi, -2 * kPi, 0, 0}, pts),
              0.001 * (1 + 1e-9));
  }
}

TEST(GcodeArcTest, CentreAbsoluteOrIncremental) {
  // The same semicircle about (0, 0) from (1, 0) to (-1, 0) through (0, 1).
  const Toolpath inc = Parse("G21 G0 X1 Y0 Z0\nG3 X-1 Y0 I-1 J0\n");
  const Toolpath abs = Parse("G21 G0 X1 Y0 Z0\nG90.1 G3 X-1 Y0 I0 J0\n");
  EXPECT_EQ(inc.point_count(), abs.point_count());
  for (int64_t i = 0; i < inc.point_count(); ++i) {
    EXPECT_NEAR(Dist(inc.points()[i].position, abs.points()[i].position), 0,
                1e-15);
  }
  EXPECT_NEAR(SweptAngle(Positions(abs), 0, 0), kPi, 1e-12);
  // G91.1 restores incremental; absolute I/J in inches are scaled.
  const Toolpath back =
      Parse("G21 G0 X1 Y0 Z0\nG90.1\nG91.1 G3 X-1 Y0 I-1 J0\n");
  EXPECT_EQ(back.point_count(), inc.point_count());
  const Toolpath inch = Parse("G20 G0 X1 Y0 Z0\nG90.1 G3 X-1 Y0 I0 J0\n");
  EXPECT_THAT(Positions(inch).back(), At(-25.4, 0.0, 0.0));
  EXPECT_NEAR(SweptAngle(Positions(inch), 0, 0), kPi, 1e-12);
  // Absolute I/J taken as incremental would put the centre at the start.
  ExpectError("G21 G0 X1 Y0 Z0\nG3 X-1 Y0 I0 J0\n", 2, "zero radius");
}

TEST(GcodeArcTest, RadiusFormatBothSigns) {
  const std::string start = "G21 G0 X0 Y0 Z0\n";
  const auto max_y = [](const std::vector<Vec3>& p) {
    double m = -INFINITY;
    for (const Vec3& v : p) m = std::max(m, v.y);
    return m;
  };
  const auto min_y = [](const std::vector<Vec3>& p) {
    double m = INFINITY;
    for (const Vec3& v : p) m = std::min(m, v.y);
    return m;
  };
  const double h = std::sqrt(75.0);  // centre offset for R10 over a chord 10
  // Semicircle: G2 over the top.
  const std::vector<Vec3> semi = Positions(Parse(start + "G2 X10 Y0 R5\n"));
  EXPECT_THAT(semi.back(), At(10.0, 0.0, 0.0));
  EXPECT_NEAR(SweptAngle(semi, 5, 0), -kPi, 1e-9);
  EXPECT_NEAR(max_y(semi), 5, 1e-3);
  // R > 0: the short arc. G2 bulges up (centre below), G3 down.
  const std::vector<Vec3> g2s = Positions(Parse(start + "G2 X10 Y0 R10\n"));
  EXPECT_NEAR(SweptAngle(g2s, 5, -h), -kPi / 3, 1e-9);
  EXPECT_NEAR(max_y(g2s), 10 - h, 1e-3);
  const std::vector<Vec3> g3s = Positions(Parse(start + "G3 X10 Y0 R10\n"));
  EXPECT_NEAR(SweptAngle(g3s, 5, h), kPi / 3, 1e-9);
  EXPECT_NEAR(min_y(g3s), h - 10, 1e-3);
  // R < 0: the long arc (300 degrees).
  const std::vector<Vec3> g2l = Positions(Parse(start + "G2 X10 Y0 R-10\n"));
  EXPECT_THAT(g2l.back(), At(10.0, 0.0, 0.0));
  EXPECT_NEAR(SweptAngle(g2l, 5, h), -5 * kPi / 3, 1e-9);
  EXPECT_NEAR(max_y(g2l), h + 10, 1e-3);
  const std::vector<Vec3> g3l = Positions(Parse(start + "G3 X10 Y0 R-10\n"));
  EXPECT_NEAR(SweptAngle(g3l, 5, -h), 5 * kPi / 3, 1e-9);
  EXPECT_NEAR(min_y(g3l), -h - 10, 1e-3);
  EXPECT_LE(
      MaxDeviation({5, h, 10, std::atan2(-h, -5), -5 * kPi / 3, 0, 0}, g2l),
      0.001 * (1 + 1e-9));
  // Inches: R scaled.
  const std::vector<Vec3> in =
      Positions(Parse("G20 G0 X0 Y0 Z0\nG2 X1 Y0 R0.5\n"));
  EXPECT_THAT(in.back(), At(25.4, 0.0, 0.0));
  EXPECT_NEAR(max_y(in), 12.7, 1e-3);
}

TEST(GcodeArcTest, HelicalZIsLinearInAngle) {
  const Toolpath tp = Parse("G21 G0 X10 Y0 Z0\nG3 X0 Y10 Z-5 I-10 J0\n");
  const std::vector<Vec3> pts = Positions(tp);
  ASSERT_GT(pts.size(), 10u);
  EXPECT_THAT(pts.back(), At(0.0, 10.0, -5.0));
  for (const Vec3& p : pts) {
    const double angle = std::atan2(p.y, p.x);
    EXPECT_NEAR(p.z, -5 * angle / (kPi / 2), 1e-12);
  }
  EXPECT_LE(MaxDeviation({0, 0, 10, 0, kPi / 2, 0, -5}, pts),
            0.001 * (1 + 1e-9));
}

TEST(GcodeArcTest, HelixWithTurns) {
  // P2: two full turns down 4 mm, as a helical entry.
  const Toolpath tp = Parse("G21 G0 X10 Y0 Z0\nG3 X10 Y0 Z-4 I-10 J0 P2\n");
  const std::vector<Vec3> pts = Positions(tp);
  EXPECT_THAT(pts.back(), At(10.0, 0.0, -4.0));
  EXPECT_NEAR(SweptAngle(pts, 0, 0), 4 * kPi, 1e-9);
  EXPECT_LE(MaxDeviation({0, 0, 10, 0, 4 * kPi, 0, -4}, pts),
            0.001 * (1 + 1e-9));
  EXPECT_EQ(tp.ignored().count("P"), 0u);
}

TEST(GcodeArcTest, EndpointsExactBitForBit) {
  const Toolpath tp = Parse(
      "G21 G0 X1.234567 Y-7.654321 Z0.1\n"
      "G2 X3.3 Y2.2 Z-0.3 R7.7\n"
      "G3 X-1.1 Y0.7 R-4.3\n"
      "G20 G91 G2 X0.1 Y0.3 Z0.01 R0.7\n");
  const std::vector<Vec3> pts = Positions(tp);
  auto line_end = [&](int line) {
    Vec3 v;
    for (const ToolpathPoint& p : tp.points()) {
      if (p.line == line) v = p.position;
    }
    return v;
  };
  EXPECT_THAT(line_end(2), At(3.3, 2.2, -0.3));
  EXPECT_THAT(line_end(3), At(-1.1, 0.7, -0.3));
  EXPECT_THAT(line_end(4),
              At(-1.1 + 0.1 * 25.4, 0.7 + 0.3 * 25.4, -0.3 + 0.01 * 25.4));
}

TEST(GcodeArcTest, SmallRadiusMismatchIsASpiral) {
  // 0.002 mm (rounding of 3-decimal output): accepted and followed.
  const Toolpath tp = Parse("G21 G0 X10 Y0 Z0\nG3 X0 Y10.002 I-10 J0\n");
  const std::vector<Vec3> pts = Positions(tp);
  EXPECT_THAT(pts.back(), At(0.0, 10.002, 0.0));
  for (size_t i = 0; i < pts.size(); ++i) {
    const double r = std::hypot(pts[i].x, pts[i].y);
    EXPECT_GE(r, 10 - 1e-12);
    EXPECT_LE(r, 10.002 + 1e-12);
  }
  ExpectError("G21 G0 X10 Y0 Z0\nG3 X0 Y10.5 I-10 J0\n", 2,
              "radius to the end");
}

TEST(GcodeArcTest, ToleranceOption) {
  GcodeOptions coarse;
  coarse.arc_tolerance = 0.1;
  const std::string prog = "G21 G0 X10 Y0 Z0\nG3 X-10 Y0 I-10 J0\n";
  EXPECT_LT(Parse(prog, coarse).point_count(), Parse(prog).point_count());
  for (double bad : {0.0, -1.0, 1e-9, 100.0, std::nan("")}) {
    GcodeOptions o;
    o.arc_tolerance = bad;
    EXPECT_EQ(ParseGcode(prog, o).status().code(),
              absl::StatusCode::kInvalidArgument);
  }
}

TEST(GcodeTest, MaxPoints) {
  GcodeOptions o;
  o.max_points = 3;
  const absl::StatusOr<Toolpath> lines =
      ParseGcode("G21 G0 X0 Y0 Z0\nX1\nX2\nX3\n", o);
  ASSERT_FALSE(lines.ok());
  EXPECT_THAT(std::string(lines.status().message()), StartsWith("line 4: "));
  const absl::StatusOr<Toolpath> arc =
      ParseGcode("G21 G0 X0 Y0 Z0\nG2 I5\n", o);
  ASSERT_FALSE(arc.ok());
  EXPECT_THAT(std::string(arc.status().message()), StartsWith("line 2: "));
}

// ----------------------------------------------------------------- errors

TEST(GcodeErrorTest, UnsupportedThingsNameTheLine) {
  const std::string s = "G21 G0 X0 Y0 Z0\n";  // line 1
  ExpectError(s + "G41 D1\n", 2, "G41: the radius of tool 1 is unknown");
  ExpectError(s + "G42.1\n", 2, "G42.1 needs D");
  ExpectError(s + "G76 X0 Z-1 P1\n", 2, "G76 (threading cycle) is a lathe");
  ExpectError(s + "G5.2 X1 Y1\n", 2, "G5.2 (spline)");
  ExpectError(s + "G38.2 Z-10\n", 2, "G38.2 (probing)");
  ExpectError(s + "G68 X0 Y0 R45\n", 2, "G68 (coordinate rotation)");
  ExpectError(s + "G123\n", 2, "unsupported G-code G123");
  ExpectError(s + "G1.5 X1\n", 2, "unsupported G-code G1.5");
  ExpectError(s + "G0 A10\n", 2, "A axis words are not supported");
  ExpectError(s + "G0 X1\nG1 W1\n", 3, "W axis words");
  ExpectError(s + "G1 X1 E0.5\n", 2, "E words");
  ExpectError(s + "M98 P100\n", 2, "M98 (Fanuc subprogram call) needs "
              "--dialect fanuc");
  ExpectError(s + "M99\n", 2, "M99 (Fanuc subprogram return)");
  ExpectError(s + "$H\n", 2, "use --dialect grbl");
  ExpectError(s + "G10 L2 P1 R30\n", 2, "rotation");
  ExpectError(s + "G18 G81 X0 Z-1 R1\n", 2, "G17 only");
}

TEST(GcodeErrorTest, MalformedInputNamesTheLine) {
  const std::string s = "G21 G0 X0 Y0 Z0\n";
  ExpectError(s + "G0 X1 (unclosed\n", 2, "comment '(' is not closed");
  ExpectError(s + "G0 X1.2.3\n", 2, "malformed number");
  ExpectError(s + "G0 X\n", 2, "X word has no number");
  ExpectError(s + "G0 X Y1\n", 2, "X word has no number");
  ExpectError(s + "G0 X- \n", 2, "value is missing after the sign");
  ExpectError(s + "G0 X1 X2\n", 2, "two X words");
  ExpectError(s + "G0 G1 X1\n", 2, "G0 and G1 on one line");
  ExpectError(s + "G90 G91\n", 2, "G90 and G91");
  ExpectError(s + "G20 G21\n", 2, "G20 and G21");
  ExpectError(s + "X1 !\n", 2, "unexpected '!'");
  ExpectError(s + "G0 X1 % \n", 2, "'%' must be alone");
  ExpectError(s + "%%\n", 2, "'%' must be alone");
  ExpectError(s + "G0 X1 0\n", 2, "unexpected '0'");
  ExpectError(s + "G-1\n", 2, "is not a G-code");
  ExpectError(s + "M3.5\n", 2, "is not an M-code");
  ExpectError(s + "T1.5\n", 2, "not a tool number");
  ExpectError(s + "T70000\n", 2, "not a tool number");
  ExpectError(s + "G0 X2000000000\n", 2, "out of range");
  ExpectError("G21\nX1 Y1 Z1\n", 2, "no motion mode");
  ExpectError("G21 G91 G0 X1\n", 1,
              "incremental (G91) X move while X is unknown");
}

TEST(GcodeErrorTest, BadArcsNameTheLine) {
  const std::string s = "G21 G0 X0 Y0 Z0\n";
  ExpectError(s + "G1 X1 I1\n", 2, "I word without a G2/G3 arc");
  ExpectError(s + "G0 X1 R1\n", 2, "R word without a G2/G3 arc");
  ExpectError(s + "G2 X1 Y1\n", 2, "G2 arc without I/J or R");
  ExpectError(s + "G2 X1 Y0 I0.5 R0.5\n", 2, "both I/J and R");
  ExpectError(s + "G2 X0 Y0 R5\n", 2, "full circle with R");
  ExpectError(s + "G3 X10 Y0 R4\n", 2, "R4 in G3 is too small");
  ExpectError(s + "G2 X1 Y0 I0 J0\n", 2, "zero radius");
  ExpectError(s + "G3 X1 Y0 I0.5 K1\n", 2, "K word in an XY-plane (G17) G3");
  ExpectError(s + "G2 X1 Y0 I0.5 P0\n", 2, "not a turn count");
  ExpectError(s + "G2 X1 Y0 I0.5 P1.5\n", 2, "not a turn count");
  ExpectError("G21 G0 X0 Y0\nG2 X10 Y0 I5\n", 2,
              "G2 arc before the start position is known");
  ExpectError(s + "G2 X10 Y0 I4 J0\n", 2, "radius to the end");
}

TEST(GcodeErrorTest, HugeArcValuesAreRefused) {
  const std::string s = "G21 G0 X0 Y0 Z0\n";
  ExpectError(s + "G2 X1 Y0 I1e300\n", 2, "E words");
  ExpectError(s + "G2 X0 Y0 I" + std::string(320, '9') + "\n", 2, "I value");
  ExpectError(s + "G1 X" + std::string(320, '9') + "\n", 2,
              "X position inf mm is out of range");
  // Underflow is zero.
  const Toolpath tiny = Parse(s + "G1 X0." + std::string(400, '0') + "1\n");
  EXPECT_THAT(Positions(tiny), ElementsAre(At(0.0, 0.0, 0.0)));
}

// Random byte edits of a valid program: never a crash; an error always
// names its line.
TEST(GcodeErrorTest, MutatedProgramsFailCleanly) {
  const std::string base =
      "%\nO1 (X)\nG21 G17 G90 G40 G49\nT1 M6\nS9000 M3\nG0 X0 Y0 Z5\n"
      "G1 Z-1 F300\nG2 X10 Y0 R5\nG3 X0 Y0 I-5 J0 Z-2\nG91 G1 X1 Y1\n"
      "G90.1 G2 X0 Y0 I0.5 J0.5\n; end\nM30\n%\n";
  std::mt19937 rng(12345);
  const char alphabet[] = "GXYZIJKRPMTNFS0123456789.-+ ()%;#[/\n\r\t@e";
  int ok = 0, failed = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    std::string text = base;
    const int edits = 1 + static_cast<int>(rng() % 3);
    for (int e = 0; e < edits; ++e) {
      const size_t at = rng() % text.size();
      const char c = alphabet[rng() % (sizeof alphabet - 1)];
      switch (rng() % 3) {
        case 0:
          text[at] = c;
          break;
        case 1:
          text.insert(text.begin() + at, c);
          break;
        default:
          text.erase(at, 1);
          break;
      }
    }
    GcodeOptions options;
    options.max_points = 100000;
    const absl::StatusOr<Toolpath> tp = ParseGcode(text, options);
    if (tp.ok()) {
      ++ok;
      for (const ToolpathPoint& p : tp->points()) {
        ASSERT_TRUE(IsFinite(p.position)) << text;
      }
    } else {
      ++failed;
      ASSERT_THAT(std::string(tp.status().message()), StartsWith("line "))
          << text;
    }
  }
  EXPECT_GT(ok, 100);
  EXPECT_GT(failed, 100);
}

// ----------------------------------------------------------------- corpus

std::string ReadCorpus(const std::string& name) {
  const std::string path = std::string(SWARF_CORPUS_DIR) + "/" + name;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  EXPECT_NE(f, nullptr) << path;
  std::string data;
  if (f == nullptr) return data;
  char buf[1 << 16];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) data.append(buf, n);
  std::fclose(f);
  return data;
}

struct CorpusCase {
  const char* file;
  double x0, y0, z0, x1, y1, z1;  // stock (README)
  double retract;                 // highest Z in the program
  int start_line;
  Vec3 start;
  int64_t points;  // lines with a move, less the first position's setup
                   // and zero-length moves (counted by hand)
};

TEST(CorpusTest, ProgramsParseUnmodifiedInsideTheirStock) {
  SWARF_SKIP_UNLESS_SHARED_FILE(std::string(SWARF_CORPUS_DIR) + "/bear.nc");
  SWARF_SKIP_UNLESS_SHARED_FILE(std::string(SWARF_CORPUS_DIR) + "/cameo.nc");
  const CorpusCase cases[] = {
      // bear: 15163 lines, 4 without motion (T1M6 G21 G17 M30), G0Z20
      // before XY is known, two repeats of (0, 0, 20) at the end.
      {"bear.nc", 0, 0, -20, 80, 80, 0, 20, 5, {0, 0, 20}, 15156},
      // cameo: N4 (first known position) to N35284, every one a move.
      {"cameo.nc",
       -83.6,
       -104.153,
       -7,
       83.6,
       103.747,
       0,
       2,
       5,
       {-75, -93.703, 2},
       35281},
  };
  for (const CorpusCase& c : cases) {
    SCOPED_TRACE(c.file);
    const std::string text = ReadCorpus(c.file);
    ASSERT_FALSE(text.empty());
    const absl::StatusOr<Toolpath> tp = ParseGcode(text);
    ASSERT_TRUE(tp.ok()) << tp.status();
    EXPECT_EQ(tp->point_count(), c.points);
    EXPECT_EQ(tp->move_count(), c.points - 1);
    EXPECT_EQ(tp->run_count(), 1);
    EXPECT_THAT(tp->Tools(), ElementsAre(1));
    EXPECT_TRUE(tp->notes().empty());
    EXPECT_THAT(tp->points()[0].position, At(c.start.x, c.start.y, c.start.z));
    EXPECT_EQ(tp->points()[0].line, c.start_line);
    EXPECT_TRUE(tp->points()[0].rapid);
    EXPECT_GE(tp->x_bounds().lo, c.x0);
    EXPECT_LE(tp->x_bounds().hi, c.x1);
    EXPECT_GE(tp->y_bounds().lo, c.y0);
    EXPECT_LE(tp->y_bounds().hi, c.y1);
    EXPECT_GE(tp->z_bounds().lo, c.z0);
    EXPECT_EQ(tp->z_bounds().hi, c.retract);
    // No rapid goes below the stock top.
    for (const ToolpathPoint& p : tp->points()) {
      if (p.position.z < c.z1) {
        EXPECT_FALSE(p.rapid) << "line " << p.line;
      }
    }
    EXPECT_FALSE(tp->IgnoredSummary().empty());
    EXPECT_GT(tp->ignored().at("F"), 0);
  }
}

TEST(CorpusTest, CameoIgnoresWhatItShould) {
  SWARF_SKIP_UNLESS_SHARED_FILE(std::string(SWARF_CORPUS_DIR) + "/cameo.nc");
  const absl::StatusOr<Toolpath> tp = ParseGcode(ReadCorpus("cameo.nc"));
  ASSERT_TRUE(tp.ok()) << tp.status();
  EXPECT_EQ(tp->IgnoredSummary(),
            "ignored 10 words that don't move the tool: G17 x1, G40 x1, "
            "G43 x1, G49 x1, G80 x1, M3 x1, M5 x1, M8 x1, F x1, H x1");
}

// Files of the repository itself (a fresh clone has them).
TEST(ReadToolpathFileTest, ByExtensionAndContent) {
  const std::string src = SWARF_SOURCE_DIR;
  const absl::StatusOr<Toolpath> tp =
      ReadToolpathFile(src + "/examples/relief.nc");
  ASSERT_TRUE(tp.ok()) << tp.status();
  EXPECT_GT(tp->point_count(), 10000);
  const absl::StatusOr<Toolpath> missing =
      ReadToolpathFile(src + "/examples/missing.nc");
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  const absl::StatusOr<Toolpath> unknown = ReadToolpathFile(src + "/README.md");
  EXPECT_EQ(unknown.status().code(), absl::StatusCode::kInvalidArgument);
  // By content: README.md's prose is no G-code.
  EXPECT_THAT(std::string(unknown.status().message()),
              StartsWith(src + "/README.md: line "));
}

// A regular file is read at its size, a pipe a buffer at a time: the same
// bytes either way (NULs and all, past one 64 KiB buffer).
TEST(ReadWholeFileTest, RegularFilesAndPipesWhole) {
  std::string bytes;
  for (int k = 0; k < 200000; ++k) bytes.push_back(static_cast<char>(k * 7));
  char dir_template[] = "/tmp/swarf_read_XXXXXX";
  ASSERT_NE(mkdtemp(dir_template), nullptr);
  const std::string dir = dir_template;
  const std::string file = dir + "/whole.nc", fifo = dir + "/pipe.nc";
  {
    std::FILE* f = std::fopen(file.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    ASSERT_EQ(std::fwrite(bytes.data(), 1, bytes.size(), f), bytes.size());
    std::fclose(f);
  }
  absl::StatusOr<std::string> read = gcode::ReadWholeFile(file);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_TRUE(*read == bytes);
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  std::thread writer([&] {
    std::FILE* f = std::fopen(fifo.c_str(), "wb");
    if (f == nullptr) return;
    std::fwrite(bytes.data(), 1, bytes.size(), f);
    std::fclose(f);
  });
  read = gcode::ReadWholeFile(fifo);
  writer.join();
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_TRUE(*read == bytes);
  {
    std::FILE* f = std::fopen(file.c_str(), "wb");  // empty
    ASSERT_NE(f, nullptr);
    std::fclose(f);
  }
  read = gcode::ReadWholeFile(file);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ(*read, "");
  EXPECT_EQ(gcode::ReadWholeFile(dir + "/missing.nc").status().code(),
            absl::StatusCode::kNotFound);
  std::remove(file.c_str());
  std::remove(fifo.c_str());
  rmdir(dir.c_str());
}

// ScanNumber as it was before its fast path: the sign ours, the digits
// through from_chars (correctly rounded), out of range as ScanNumber says.
const char* ScanNumberByFromChars(const char* p, const char* end, double* out) {
  while (p < end && (*p == ' ' || *p == '\t')) ++p;
  bool negative = false;
  if (p < end && (*p == '+' || *p == '-')) negative = *p++ == '-';
  const char* first = p;
  while (p < end && gcode::IsDigit(*p)) ++p;
  bool digits = p != first;
  if (p < end && *p == '.') {
    const char* frac = ++p;
    while (p < end && gcode::IsDigit(*p)) ++p;
    digits = digits || p != frac;
  }
  if (!digits) return nullptr;
  const auto r = std::from_chars(first, p, *out, std::chars_format::fixed);
  if (r.ec == std::errc::result_out_of_range) {
    bool large = false;
    for (const char* d = first; d < p && *d != '.'; ++d) large |= *d != '0';
    *out = large ? std::numeric_limits<double>::infinity() : 0.0;
  } else if (r.ec != std::errc() || r.ptr != p) {
    return nullptr;
  }
  if (negative) *out = -*out;
  return p;
}

// The fast path (an exact mantissa over an exact power of ten) gives
// from_chars' double bit for bit, and the same end, on numbers of every
// shape: CAM-post decimals, long mantissas past 2^53 and 19 digits, long
// fractions past 10^22, leading and trailing zeros, signs, blanks, and
// what is no number.
TEST(ScanNumberTest, BitForBitFromChars) {
  std::mt19937_64 rng(28);
  const auto digits = [&](int n) {
    std::string d;
    for (int k = 0; k < n; ++k)
      d.push_back(static_cast<char>('0' + rng() % 10));
    return d;
  };
  std::vector<std::string> cases = {"0",
                                    "-0",
                                    "+0",
                                    ".5",
                                    "5.",
                                    ".",
                                    "-",
                                    "+.",
                                    "",
                                    " \t 12.5",
                                    "x1",
                                    "9007199254740992",
                                    "9007199254740993",
                                    "9007199254740993.0",
                                    "18446744073709551615",
                                    "18446744073709551616.5",
                                    "1234567890123456789",
                                    "12345678901234567890",
                                    "0.0000000000000000000001",
                                    "0.00000000000000000000001",
                                    "1.0000000000000000000000",
                                    "123.4567890123456789012345",
                                    "0.1",
                                    "0.2",
                                    "0.3",
                                    "1e5",
                                    "2.5X3",
                                    std::string(400, '9') + ".5",
                                    "0." + std::string(400, '0') + "1"};
  for (int k = 0; k < 400000; ++k) {
    std::string s;
    if (rng() % 4 == 0) s += " ";
    if (const int sign = static_cast<int>(rng() % 3); sign > 0) {
      s += sign == 1 ? "-" : "+";
    }
    s += std::string(rng() % 3 == 0 ? rng() % 4 : 0, '0');
    s += digits(static_cast<int>(rng() % (k % 2 == 0 ? 7 : 21)));
    if (rng() % 5 != 0) {
      s += ".";
      s += digits(static_cast<int>(rng() % (k % 3 == 0 ? 26 : 7)));
    }
    if (rng() % 4 == 0) s += "Y";
    cases.push_back(s);
  }
  int64_t numbers = 0;
  for (const std::string& c : cases) {
    const char* end = c.data() + c.size();
    double fast = -1, reference = -2;
    const char* a = gcode::ScanNumber(c.data(), end, &fast);
    const char* b = ScanNumberByFromChars(c.data(), end, &reference);
    ASSERT_EQ(a, b) << "'" << c << "'";
    if (a == nullptr) continue;
    ++numbers;
    ASSERT_EQ(std::memcmp(&fast, &reference, sizeof fast), 0)
        << "'" << c << "': " << fast << " against " << reference;
  }
  EXPECT_GT(numbers, 350000);
}

// ---------------------------------------------- the generated examples

// examples/*.nc (scripts/make-example; the ctest make_example_check keeps
// them what it writes): realistic sizes, every move inside its stock, each
// tool no deeper than its feature's floor, no rapid into the stock.
struct ExampleCase {
  const char* file;
  double x1, y1;                // stock [0, x1] x [0, y1], top 0
  std::vector<int> tools;
  std::vector<double> floors;   // per tool: its programmed lowest tip
};

TEST(ExamplesTest, GeneratedJobsParseInsideTheirStock) {
  const double vcarve_floor = -2 / std::tan(kPi / 6);  // the leaves' middle
  const ExampleCase cases[] = {
      {"relief.nc", 60, 60, {1}, {-8.0}},
      {"pocket.nc", 100, 80, {1, 2, 3}, {-6, -4, -0.5}},
      {"vcarve.nc", 80, 80, {1}, {vcarve_floor}},
  };
  for (const ExampleCase& c : cases) {
    SCOPED_TRACE(c.file);
    const absl::StatusOr<Toolpath> tp =
        ReadToolpathFile(std::string(SWARF_SOURCE_DIR) + "/examples/" + c.file);
    ASSERT_TRUE(tp.ok()) << tp.status();
    EXPECT_GE(tp->move_count(), 10000);
    EXPECT_LE(tp->move_count(), 100000);
    EXPECT_EQ(tp->Tools(), c.tools);
    EXPECT_EQ(tp->dropped_moves(), 0);
    EXPECT_GE(tp->x_bounds().lo, 0);
    EXPECT_LE(tp->x_bounds().hi, c.x1);
    EXPECT_GE(tp->y_bounds().lo, 0);
    EXPECT_LE(tp->y_bounds().hi, c.y1);
    std::vector<double> lowest(c.tools.size(), 1e30);
    for (const ToolpathPoint& p : tp->points()) {
      if (p.rapid) {
        // Rapids stay above the stock top but where a level's cut is
        // entered, half a millimetre above what is already cut.
        EXPECT_GE(p.position.z, -5.5) << "line " << p.line;
      }
      const auto at = std::find(c.tools.begin(), c.tools.end(), p.tool);
      ASSERT_NE(at, c.tools.end()) << "line " << p.line;
      double& low = lowest[at - c.tools.begin()];
      low = std::min(low, p.position.z);
    }
    for (size_t t = 0; t < c.tools.size(); ++t) {
      if (std::string(c.file) == "relief.nc") {
        EXPECT_GT(lowest[t], c.floors[t]);  // a drop-cutter surface
      } else {
        EXPECT_NEAR(lowest[t], c.floors[t], 1e-4) << "T" << c.tools[t];
      }
    }
  }
}

// -------------------------------------------------------------- XYZ input

TEST(XyzTest, SeparatorsCommentsAndHeader) {
  const absl::StatusOr<Toolpath> tp = ParseXyz(
      "# exported tip positions\n"
      "x,y,z\n"
      "1,2,3\n"
      "4 5 6\n"
      "7\t8\t9 # trailing comment\n"
      "\n"
      " 1.5e1 , -2 ,+3\r\n"
      "1, 2, 3,\n");
  ASSERT_TRUE(tp.ok()) << tp.status();
  EXPECT_THAT(
      Positions(*tp),
      ElementsAre(At(1.0, 2.0, 3.0), At(4.0, 5.0, 6.0), At(7.0, 8.0, 9.0),
                  At(15.0, -2.0, 3.0), At(1.0, 2.0, 3.0)));
  EXPECT_EQ(tp->points()[0].line, 3);
  EXPECT_EQ(tp->points()[3].line, 7);
  EXPECT_EQ(tp->run_count(), 1);
  EXPECT_EQ(tp->move_count(), 4);
  for (const ToolpathPoint& p : tp->points()) {
    EXPECT_FALSE(p.rapid);
    EXPECT_EQ(p.tool, 0);
  }
  EXPECT_EQ(tp->x_bounds().lo, 1);
  EXPECT_EQ(tp->x_bounds().hi, 15);
  EXPECT_TRUE(tp->IgnoredSummary().empty());
}

TEST(XyzTest, BadLinesNameTheLine) {
  const struct {
    const char* text;
    int line;
    const char* what;
  } cases[] = {
      {"1,2\n", 1, "expected 3 values (x y z), got 2"},
      {"1 2 # c\n", 1, "got 2"},
      {"1,2,3\nfoo,2,3\n", 2, "x is not a number"},
      {"x y z\nX Y Z\n", 2, "x is not a number"},
      {"1,2,3\n4,5,6,7\n", 2, "unexpected '7'"},
      {"1,,3\n", 1, "y is not a number"},
      {"1 2 nan\n", 1, "z = nan is out of range"},
      {"1 2 1e999\n", 1, "z is out of range"},
      {"1 2 3mm\n", 1, "unexpected 'm'"},
      {"1;2;3\n", 1, "got 1"},
  };
  for (const auto& c : cases) {
    const absl::StatusOr<Toolpath> tp = ParseXyz(c.text);
    ASSERT_FALSE(tp.ok()) << c.text;
    EXPECT_EQ(tp.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(tp.status().message()),
                StartsWith("line " + std::to_string(c.line) + ": "))
        << c.text;
    EXPECT_THAT(std::string(tp.status().message()), HasSubstr(c.what))
        << c.text;
  }
}

TEST(FormatTest, ByExtension) {
  for (const char* g : {"a.nc", "dir.x/b.NGC", "c.gcode", "d.tap", "e.Cnc"}) {
    EXPECT_EQ(*ToolpathFormatForPath(g), ToolpathFormat::kGcode) << g;
  }
  for (const char* x : {"a.csv", "b.XYZ", "c.txt"}) {
    EXPECT_EQ(*ToolpathFormatForPath(x), ToolpathFormat::kXyz) << x;
  }
  for (const char* bad : {"a.stl", "noext", "dir.nc/file"}) {
    EXPECT_FALSE(ToolpathFormatForPath(bad).ok()) << bad;
  }
  const absl::StatusOr<Toolpath> tp =
      ParseToolpath("1 2 3\n4 5 6\n", ToolpathFormat::kXyz);
  ASSERT_TRUE(tp.ok());
  EXPECT_EQ(tp->point_count(), 2);
}

}  // namespace
}  // namespace swarf::gcode
