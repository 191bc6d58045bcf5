// The RS274/NGC interpreter (gcode/interpreter.cc): parameters and
// expressions, O-word control flow, arcs in every plane, offsets, homes,
// canned cycles, dialects, and the moves it must not drop silently; each
// against tool-tip positions computed by hand.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include <unistd.h>

#include "absl/status/status.h"
#include "gcode/toolpath.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace swarf::gcode {
namespace {

using ::testing::AllOf;
using ::testing::HasSubstr;
using ::testing::StartsWith;

Toolpath MustRun(const std::string& text, const GcodeOptions& options = {}) {
  absl::StatusOr<Toolpath> tp = ParseGcode(text, options);
  EXPECT_TRUE(tp.ok()) << tp.status() << "\nprogram:\n" << text;
  return tp.ok() ? *std::move(tp) : Toolpath();
}

// (x, y, z) of every point.
std::vector<std::vector<double>> Xyz(const Toolpath& tp) {
  std::vector<std::vector<double>> out;
  for (const ToolpathPoint& p : tp.points()) {
    out.push_back({p.position.x, p.position.y, p.position.z});
  }
  return out;
}

using V = std::vector<std::vector<double>>;

void ExpectNear(const V& got, const V& want, double tol = 1e-9) {
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < got.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      EXPECT_NEAR(got[i][a], want[i][a], tol) << "point " << i << " axis " << a;
    }
  }
}

// The value of an expression: the X of a rapid to it.
double Eval(const std::string& expr) {
  const Toolpath tp = MustRun("G21 G0 X" + expr + " Y0 Z0\n");
  return tp.point_count() == 1 ? tp.points()[0].position.x : NAN;
}

std::string ErrorOf(const std::string& text, const GcodeOptions& options = {}) {
  absl::StatusOr<Toolpath> tp = ParseGcode(text, options);
  EXPECT_FALSE(tp.ok()) << "program:\n" << text;
  if (!tp.ok()) {
    EXPECT_EQ(tp.status().code(), absl::StatusCode::kInvalidArgument);
  }
  return tp.ok() ? "" : std::string(tp.status().message());
}

// ------------------------------------------------------------ expressions

TEST(ExpressionTest, EveryBinaryOperatorAndPrecedence) {
  EXPECT_EQ(Eval("[1 + 2 * 3]"), 7);
  EXPECT_EQ(Eval("[1 - 2 - 3]"), -4);      // left to right
  EXPECT_EQ(Eval("[10 / 4]"), 2.5);
  EXPECT_EQ(Eval("[2 ** 3 ** 2]"), 64);    // (2 ** 3) ** 2
  EXPECT_EQ(Eval("[2 * 3 ** 2]"), 18);     // ** binds tighter
  EXPECT_EQ(Eval("[7 MOD 3]"), 1);
  EXPECT_EQ(Eval("[-7 mod 3]"), 2);        // as LinuxCNC: not negative
  EXPECT_EQ(Eval("[3 EQ 3]"), 1);
  EXPECT_EQ(Eval("[3 EQ 3.00001]"), 1);    // within 1e-4
  EXPECT_EQ(Eval("[3 NE 3]"), 0);
  EXPECT_EQ(Eval("[2 GT 1]"), 1);
  EXPECT_EQ(Eval("[1 GT 1]"), 0);
  EXPECT_EQ(Eval("[1 GE 1]"), 1);
  EXPECT_EQ(Eval("[1 LT 1]"), 0);
  EXPECT_EQ(Eval("[0 LT 1]"), 1);
  EXPECT_EQ(Eval("[1 LE 1]"), 1);
  EXPECT_EQ(Eval("[1 AND 0]"), 0);
  EXPECT_EQ(Eval("[2 AND 3]"), 1);
  EXPECT_EQ(Eval("[0 OR 0]"), 0);
  EXPECT_EQ(Eval("[1 OR 0]"), 1);
  EXPECT_EQ(Eval("[1 XOR 1]"), 0);
  EXPECT_EQ(Eval("[1 XOR 0]"), 1);
  EXPECT_EQ(Eval("[1 + 2 EQ 3]"), 1);      // + before EQ
  EXPECT_EQ(Eval("[1 LT 2 AND 3 LT 2]"), 0);  // relations before AND
  EXPECT_EQ(Eval("[[1 + 2] * 3]"), 9);
  EXPECT_EQ(Eval("-[1 + 2]"), -3);
  EXPECT_EQ(Eval("[-[2] * -3]"), 6);
}

TEST(ExpressionTest, EveryFunction) {
  EXPECT_NEAR(Eval("sin[30]"), 0.5, 1e-15);
  EXPECT_NEAR(Eval("COS[60]"), 0.5, 1e-15);
  EXPECT_NEAR(Eval("tan[45]"), 1, 1e-15);
  EXPECT_NEAR(Eval("asin[0.5]"), 30, 1e-12);
  EXPECT_NEAR(Eval("acos[0.5]"), 60, 1e-12);
  EXPECT_NEAR(Eval("atan[1]/[1]"), 45, 1e-12);
  EXPECT_NEAR(Eval("atan[1]/[-1]"), 135, 1e-12);  // quadrant from both
  EXPECT_NEAR(Eval("atan[-1]/[-1]"), -135, 1e-12);
  EXPECT_EQ(Eval("sqrt[16]"), 4);
  EXPECT_EQ(Eval("abs[-3.5]"), 3.5);
  EXPECT_EQ(Eval("exp[0]"), 1);
  EXPECT_NEAR(Eval("ln[exp[2]]"), 2, 1e-15);
  EXPECT_EQ(Eval("fix[-1.5]"), -2);
  EXPECT_EQ(Eval("fup[-1.5]"), -1);
  EXPECT_EQ(Eval("fix[1.5]"), 1);
  EXPECT_EQ(Eval("fup[1.2]"), 2);
  EXPECT_EQ(Eval("round[2.5]"), 3);
  EXPECT_EQ(Eval("round[-2.4]"), -2);
  const Toolpath tp = MustRun(
      "#<_g> = 1\n#<l> = 2\n"
      "G21 G0 X[exists[#<_g>] * 100 + exists[#<l>] * 10 + exists[#<no>]] "
      "Y0 Z0\n");
  EXPECT_EQ(tp.points()[0].position.x, 110);
}

TEST(ExpressionTest, BadExpressionsNameTheLine) {
  const std::string s = "G21 G0 X0 Y0 Z0\n";
  EXPECT_THAT(ErrorOf(s + "X[1/0]\n"), StartsWith("line 2: division by zero"));
  EXPECT_THAT(ErrorOf(s + "X[1 MOD 0]\n"), HasSubstr("MOD by zero"));
  EXPECT_THAT(ErrorOf(s + "X sqrt[-1]\n"), HasSubstr("SQRT of -1"));
  EXPECT_THAT(ErrorOf(s + "X ln[0]\n"), HasSubstr("LN of 0"));
  EXPECT_THAT(ErrorOf(s + "X acos[2]\n"), HasSubstr("ACOS of 2"));
  EXPECT_THAT(ErrorOf(s + "X asin[-1.5]\n"), HasSubstr("ASIN of -1.5"));
  EXPECT_THAT(ErrorOf(s + "X[-8 ** 0.5]\n"), HasSubstr("non-integer power"));
  EXPECT_THAT(ErrorOf(s + "X[exp[1000]]\n"), HasSubstr("not finite"));
  EXPECT_THAT(ErrorOf(s + "X foo[1]\n"), HasSubstr("unknown function 'foo'"));
  EXPECT_THAT(ErrorOf(s + "X[1 + 2\n"), HasSubstr("']' missing"));
  EXPECT_THAT(ErrorOf(s + "X[1 2]\n"), HasSubstr("expected an operator"));
  EXPECT_THAT(ErrorOf(s + "X atan[1]\n"), HasSubstr("ATAN needs [y]/[x]"));
  EXPECT_THAT(ErrorOf(s + "X" + std::string(100, '[') + "1" +
                      std::string(100, ']') + "\n"),
              HasSubstr("nested deeper than 64"));
  EXPECT_THAT(ErrorOf(s + "X#<nothing>\n"),
              StartsWith("line 2: parameter #<nothing> is not set"));
  EXPECT_THAT(ErrorOf(s + "#0 = 1\n"), HasSubstr("not a parameter"));
  EXPECT_THAT(ErrorOf(s + "#5603 = 1\n"), HasSubstr("not a parameter"));
  EXPECT_THAT(ErrorOf(s + "#<_x> = 1\n"), HasSubstr("read-only"));
  EXPECT_THAT(ErrorOf(s + "#5420 = 1\n"), HasSubstr("read-only"));
}

// ------------------------------------------------------------ parameters

TEST(ParameterTest, NumberedIndirectAndSameLineSettings) {
  // "#1=2 #2=#1": settings take effect after the line, so #2 gets the old
  // #1 (0 by default); ## and #[] are indirect.
  const Toolpath tp = MustRun(
      "#1 = 2 #2 = #1\n"
      "#3 = 7\n#[1 + 3] = ##1\n"  // #4 = #[#1] = #2 = 0
      "#10 = 3\n#11 = ##10\n"     // #11 = #[#10] = #3 = 7
      "G21 G0 X#2 Y#11 Z#4\n");
  ExpectNear(Xyz(tp), {{0, 7, 0}});
}

TEST(ParameterTest, NamedLocalsAreScopedGlobalsAreNot) {
  const Toolpath tp = MustRun(
      "#<depth> = 5 #<_g> = 1\n"
      "o<s> sub\n"
      "  #<depth> = 9\n"  // local to the call
      "  #<_g> = [#<_g> + #<depth>]\n"
      "o<s> endsub\n"
      "o<s> call\n"
      "G21 G0 X#<depth> Y#<_g> Z0\n");
  ExpectNear(Xyz(tp), {{5, 10, 0}});
  EXPECT_THAT(ErrorOf("#<a> = 1\no1 sub\nG0 X#<a>\no1 endsub\no1 call\n"),
              StartsWith("line 3: parameter #<a> is not set"));
}

TEST(ParameterTest, PositionParametersReadTheProgramPosition) {
  // #<_x> and #5420.. are the position in the current coordinate system and
  // units; #<_abs_x> the machine position.
  const Toolpath tp = MustRun(
      "G21 G10 L2 P1 X10\n"
      "G0 X1 Y2 Z3\n"
      "G0 X[#<_x> + 1] Y[#5421 * 2] Z#<_abs_x>\n"
      "#<_m> = #<_metric>\n"
      "G20\n#<_i> = [#<_imperial> + #<_metric>]\n"
      "G21 G0 X#<_m> Y#<_i> Z#<_line>\n");
  ExpectNear(Xyz(tp), {{11, 2, 3}, {12, 4, 11}, {11, 1, 7}});
}

// ------------------------------------------------------------ O-words

TEST(OWordTest, SubroutineArgumentsAndReturnValue) {
  const Toolpath tp = MustRun(
      "G21 G90\n"
      "o<hole> sub\n"
      "  G0 X#1 Y#2 Z1\n"
      "  G1 Z[-#3]\n"
      "  G0 Z1\n"
      "o<hole> endsub [#1 + #2]\n"
      "#1 = 99\n"
      "o<hole> call [1] [2] [0.5]\n"
      "G0 X#<_value> Y#1 Z#<_value_returned>\n"  // #1 restored after the call
      "M2\n");
  ExpectNear(Xyz(tp), {{1, 2, 1}, {1, 2, -0.5}, {1, 2, 1}, {3, 99, 1}});
  // The lines are the subroutine's lines.
  EXPECT_EQ(tp.points()[0].line, 3);
  EXPECT_EQ(tp.points()[1].line, 4);
  EXPECT_EQ(tp.points()[3].line, 9);
}

TEST(OWordTest, RecursionComputesAFactorial) {
  const Toolpath tp = MustRun(
      "o100 sub\n"
      "  o101 if [#1 LE 1]\n"
      "    o100 return [1]\n"
      "  o101 endif\n"
      "  o100 call [#1 - 1]\n"
      "o100 endsub [#1 * #<_value>]\n"
      "o100 call [5]\n"
      "G21 G0 X#<_value> Y0 Z0\n");
  ExpectNear(Xyz(tp), {{120, 0, 0}});
}

TEST(OWordTest, DeepRecursionAndEndlessLoopsStopWithAClearError) {
  EXPECT_THAT(ErrorOf("o1 sub\no1 call\no1 endsub\no1 call\n"),
              AllOf(StartsWith("line 2: "), HasSubstr("nested deeper than 100")));
  GcodeOptions o;
  o.max_blocks = 1000;
  EXPECT_THAT(ErrorOf("o1 while [1]\nG0 X0\no1 endwhile\n", o),
              HasSubstr("more than 1000 blocks executed"));
  o.max_blocks = 200'000'000;
  o.max_call_depth = 3;
  EXPECT_THAT(ErrorOf("o1 sub\no1 call\no1 endsub\no1 call\n", o),
              HasSubstr("nested deeper than 3"));
}

TEST(OWordTest, IfElseifElse) {
  std::string prog =
      "G21 G0 X0 Y0 Z0\n"
      "o1 if [#1 EQ 1]\n  G0 X1\n"
      "o1 elseif [#1 EQ 2]\n  G0 X2\n"
      "o1 elseif [#1 EQ 3]\n  G0 X3\n"
      "o1 else\n  G0 X4\n"
      "o1 endif\nG0 Y1\n";
  for (int v = 1; v <= 5; ++v) {
    const Toolpath tp = MustRun("#1=" + std::to_string(v) + "\n" + prog);
    ExpectNear(Xyz(tp), {{0, 0, 0}, {std::min(v, 4) * 1.0, 0, 0},
                         {std::min(v, 4) * 1.0, 1, 0}});
  }
}

TEST(OWordTest, WhileDoRepeatBreakContinue) {
  // while with continue (skips 2) and break (at 4); do-while runs once
  // even when false; repeat 3 steps of G91 X1; repeat [0] runs nothing.
  const Toolpath ok = MustRun(
      "G21 G0 X0 Y0 Z0\n"
      "#1 = 0\n"
      "o1 while [#1 LT 10]\n"
      "  #1 = [#1 + 1]\n"
      "  o2 if [#1 EQ 2]\n    o1 continue\n  o2 endif\n"
      "  o3 if [#1 EQ 4]\n    o1 break\n  o3 endif\n"
      "  G0 X#1\n"
      "o1 endwhile\n"
      "o4 do\n  G0 Y5\no4 while [0]\n"
      "o5 repeat [3]\n  G91 G0 X1\no5 endrepeat\n"
      "G90\no6 repeat [0]\n  G0 Z9\no6 endrepeat\n");
  ExpectNear(Xyz(ok), {{0, 0, 0}, {1, 0, 0}, {3, 0, 0}, {3, 5, 0},
                       {4, 5, 0}, {5, 5, 0}, {6, 5, 0}});
}

TEST(OWordTest, ExternalSubroutineFileNextToTheProgram) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() /
      ("swarf-gcode-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  {
    std::ofstream f(dir / "square.ngc");
    f << "(a square of side #1 at depth #2)\n"
         "o<square> sub\n"
         "  G1 Z#2\n  G91 X#1\n  Y#1\n  X-#1\n  Y-#1\n  G90\n"
         "  G1 Z#2 Q\n"  // line 8: an error when reached
         "o<square> endsub\n";
    std::ofstream m(dir / "main.ngc");
    m << "G21 G0 X0 Y0 Z1\no<square> call [2] [-1]\nM2\n";
  }
  GcodeOptions o;
  const absl::StatusOr<Toolpath> tp =
      ReadToolpathFile((dir / "main.ngc").string(), o);
  ASSERT_FALSE(tp.ok());
  // The error names the main file once, then the subroutine file's line.
  EXPECT_EQ(std::string(tp.status().message()),
            (dir / "main.ngc").string() + ": line 9 of " +
                (dir / "square.ngc").string() +
                " (called from line 2): Q word has no number");
  EXPECT_EQ(std::string(tp.status().message()).find(": line 9 of"),
            (dir / "main.ngc").string().size());
  {
    std::ofstream f(dir / "square.ngc");
    f << "o<square> sub\n"
         "  G1 Z#2\n  G91 X#1\n  Y#1\n  X-#1\n  Y-#1\n  G90\n"
         "o<square> endsub\n";
  }
  const absl::StatusOr<Toolpath> ok =
      ReadToolpathFile((dir / "main.ngc").string(), o);
  ASSERT_TRUE(ok.ok()) << ok.status();
  ExpectNear(Xyz(*ok),
             {{0, 0, 1}, {0, 0, -1}, {2, 0, -1}, {2, 2, -1}, {0, 2, -1},
              {0, 0, -1}});
  for (const ToolpathPoint& p : ok->points()) EXPECT_EQ(p.line, p.starts_run ? 1 : 2);
  EXPECT_THAT(ErrorOf("o<nosuch> call\n", GcodeOptions{}),
              HasSubstr("subroutine o<nosuch> is not defined"));
  std::filesystem::remove_all(dir);
}

TEST(OWordTest, MisplacedOWordsNameTheLine) {
  EXPECT_THAT(ErrorOf("o1 endif\n"), StartsWith("line 1: o1 endif without o1 if"));
  EXPECT_THAT(ErrorOf("o1 if [1]\nG0 X0\n"),
              StartsWith("line 1: o1 if is never closed"));
  EXPECT_THAT(ErrorOf("o1 if [0]\nG0 X0\n"), HasSubstr("no o1 line to end"));
  EXPECT_THAT(ErrorOf("o1 while [1]\no2 break\no1 endwhile\n"),
              StartsWith("line 2: o2 break outside an o2 loop"));
  EXPECT_THAT(ErrorOf("o1 return\n"), HasSubstr("outside a subroutine"));
  EXPECT_THAT(ErrorOf("o1 sub\n"), HasSubstr("no o1 line to end"));
  EXPECT_THAT(ErrorOf("o1 frobnicate\n"), HasSubstr("unknown O-word keyword"));
  EXPECT_THAT(ErrorOf("o1 if\no1 endif\n"), HasSubstr("needs a [condition]"));
}

// ------------------------------------------------------------ arcs

// Every point of an arc lies on its circle (within the chord tolerance at
// most between points; exactly at them up to rounding).
void ExpectOnCircle(const Toolpath& tp, int a, int b, double ca, double cb,
                    double r) {
  for (const ToolpathPoint& p : tp.points()) {
    const double v[3] = {p.position.x, p.position.y, p.position.z};
    if (p.line < 2) continue;
    EXPECT_NEAR(std::hypot(v[a] - ca, v[b] - cb), r, 1e-9);
  }
}

TEST(ArcTest, G18AndG19ArcsTurnAsLinuxCncDoes) {
  // G18: clockwise seen from +Y: X0 -> X2 about X1 passes Z = -1.
  Toolpath tp = MustRun("G21 G0 X0 Y0 Z0\nG18 G2 X2 Z0 I1 K0\n");
  ExpectOnCircle(tp, 0, 2, 1, 0, 1);
  double lo = 0, hi = 0;
  for (const ToolpathPoint& p : tp.points()) {
    lo = std::min(lo, p.position.z);
    hi = std::max(hi, p.position.z);
    EXPECT_EQ(p.position.y, 0);
  }
  EXPECT_NEAR(lo, -1, 1e-3);
  EXPECT_EQ(hi, 0);
  EXPECT_EQ(tp.points().back().position.x, 2);
  // The R form makes the same arc; G3 the other half.
  const Toolpath r = MustRun("G21 G0 X0 Y0 Z0\nG18 G2 X2 Z0 R1\n");
  ExpectNear(Xyz(r), Xyz(tp), 1e-12);
  tp = MustRun("G21 G0 X0 Y0 Z0\nG18 G3 X2 Z0 I1 K0\n");
  for (const ToolpathPoint& p : tp.points()) EXPECT_GE(p.position.z, 0);
  // G19: clockwise seen from +X: Y0 -> Y2 about Y1 passes Z = +1.
  tp = MustRun("G21 G0 X0 Y0 Z0\nG19 G2 Y2 Z0 J1 K0\n");
  ExpectOnCircle(tp, 1, 2, 1, 0, 1);
  hi = 0;
  for (const ToolpathPoint& p : tp.points()) {
    hi = std::max(hi, p.position.z);
    EXPECT_GE(p.position.z, 0);
    EXPECT_EQ(p.position.x, 0);
  }
  EXPECT_NEAR(hi, 1, 1e-3);
}

TEST(ArcTest, HelicalG18ArcMovesYLinearlyWithTurns) {
  // Two turns (P2) of a full circle in XZ while Y goes 0 -> 4.
  const Toolpath tp =
      MustRun("G21 G0 X0 Y0 Z0\nG18 G3 X0 Y4 Z0 I1 K0 P2\n");
  ExpectOnCircle(tp, 0, 2, 1, 0, 1);
  double swept = 0;
  for (size_t i = 1; i < tp.points().size(); ++i) {
    const Vec3& u = tp.points()[i - 1].position;
    const Vec3& v = tp.points()[i].position;
    // Angle in the (Z, X) plane about (Z0, X1).
    const double a0 = std::atan2(u.x - 1, u.z), a1 = std::atan2(v.x - 1, v.z);
    double d = a1 - a0;
    if (d > M_PI) d -= 2 * M_PI;
    if (d < -M_PI) d += 2 * M_PI;
    swept += d;
    // Y is linear in the angle.
    EXPECT_NEAR(v.y, 4 * std::fabs(swept) / (4 * M_PI), 1e-9);
  }
  EXPECT_NEAR(std::fabs(swept), 4 * M_PI, 1e-9);
  ExpectNear({Xyz(tp).back()}, {{0, 4, 0}});
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG18 G2 X2 Z0 I1 J0\n"),
              HasSubstr("J word in an XZ-plane (G18) G2 arc"));
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG19 G2 Y2 Z0 I1\n"),
              HasSubstr("I word in an YZ-plane (G19) G2 arc"));
}

// ------------------------------------------------------------ offsets

TEST(OffsetTest, WorkOffsetsG92G52G53AndLengthOffsetsStack) {
  const Toolpath tp = MustRun(
      "G21 G10 L2 P1 X10 Y20 Z-5\n"
      "G0 X0 Y0 Z0\n"          // (10, 20, -5)
      "G92 X1\nG0 X2\n"        // X0 is now X1: 11
      "G92.2\nG0 X2\n"         // suspended: 12
      "G92.3\nG0 X2\n"         // restored: 11
      "G92.1\nG0 X2\n"         // cleared: 12
      "G52 X5\nG0 X0\n"        // local origin +5: 15
      "G52 X0\nG0 X0\n"        // 10
      "G10 L20 P2 X0 Y0\n"     // G55 origin here: (10, 20)
      "G55 G0 X1 Y1\n"         // (11, 21, -5): G55 Z offset 0
      "G53 G0 X0 Y0 Z0\n"      // machine (0, 0, 0)
      "G43.1 Z2\nG0 Z0\n"      // the tip 2 above: (0, 0, 2)
      "G49\nG0 Z0\n"           // (0, 0, 0)
      "G54 G0 X0 Y0 Z0\n");    // (10, 20, -5) again
  ExpectNear(Xyz(tp), {{10, 20, -5}, {11, 20, -5}, {12, 20, -5},
                       {11, 20, -5}, {12, 20, -5}, {15, 20, -5},
                       {10, 20, -5}, {11, 21, -5}, {0, 0, 0}, {0, 0, 2},
                       {0, 0, 0}, {10, 20, -5}});
  EXPECT_TRUE(tp.notes().empty()) << tp.notes()[0];
  // Offsets are in the program's units; a never-set offset is noted.
  const Toolpath inch = MustRun("G20 G10 L2 P3 X1\nG56 G0 X1 Y0 Z0\nG57\n");
  ExpectNear(Xyz(inch), {{50.8, 0, 0}});
  ASSERT_EQ(inch.notes().size(), 1u);
  EXPECT_THAT(inch.notes()[0], HasSubstr("G57 on line 3 selects a work "
                                         "offset the program never set"));
  EXPECT_THAT(ErrorOf("G21 G91 G53 G0 X1\n"), HasSubstr("G53 in incremental"));
  EXPECT_THAT(ErrorOf("G21 G92 X1\n"), HasSubstr("G92 X while X is unknown"));
  EXPECT_THAT(ErrorOf("G21 G10 L2 P10 X1\n"), HasSubstr("P0..P9"));
}

TEST(HomeTest, G28AndG30GoHomeThroughTheIntermediatePoint) {
  GcodeOptions o;
  o.home_known = true;
  o.home[0] = 0, o.home[1] = 0, o.home[2] = 50;
  Toolpath tp = MustRun(
      "G21 G0 X1 Y2 Z3\nG28 Z10\nG0 X5\nG28\n"
      "G0 X1 Y1 Z1\nG30.1\nG0 X5 Y5 Z5\nG91 G30 Z0\n",
      o);
  ExpectNear(Xyz(tp), {{1, 2, 3}, {1, 2, 10}, {1, 2, 50}, {5, 2, 50},
                       {0, 0, 50}, {1, 1, 1}, {5, 5, 5}, {5, 5, 1}});
  // G28.1 sets the home from the position.
  tp = MustRun("G21 G0 X1 Y1 Z1\nG28.1\nG0 X5 Y5 Z5\nG28\n");
  ExpectNear(Xyz(tp), {{1, 1, 1}, {5, 5, 5}, {1, 1, 1}});
  // Unknown home: the axes sent there are unknown, and a feed needing
  // them is dropped and named.
  tp = MustRun("G21 G0 X0 Y0 Z0\nG28 G91 Z0\nG90 G1 X5\n");
  EXPECT_EQ(tp.point_count(), 1);
  EXPECT_EQ(tp.dropped_moves(), 1);
  EXPECT_THAT(tp.DroppedSummary(), HasSubstr("line 3 (Z unknown)"));
  ASSERT_EQ(tp.notes().size(), 1u);
  EXPECT_THAT(tp.notes()[0], HasSubstr("the home position is unknown"));
}

// ------------------------------------------------------------ cycles

struct Pt {
  double x, y, z;
  bool rapid;
};

void ExpectPath(const Toolpath& tp, const std::vector<Pt>& want) {
  ASSERT_EQ(tp.points().size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    const ToolpathPoint& p = tp.points()[i];
    EXPECT_NEAR(p.position.x, want[i].x, 1e-12) << i;
    EXPECT_NEAR(p.position.y, want[i].y, 1e-12) << i;
    EXPECT_NEAR(p.position.z, want[i].z, 1e-12) << i;
    if (i > 0) {
      EXPECT_EQ(p.rapid, want[i].rapid) << i;
    }
  }
}

TEST(CycleTest, G81RetractsToTheOldZUnderG98AndToRUnderG99) {
  ExpectPath(MustRun("G21 G0 X0 Y0 Z10\nG98 G81 X5 Y5 Z-2 R1\nX10\nG80\n"),
             {{0, 0, 10, true}, {5, 5, 10, true}, {5, 5, 1, true},
              {5, 5, -2, false}, {5, 5, 10, true}, {10, 5, 10, true},
              {10, 5, 1, true}, {10, 5, -2, false}, {10, 5, 10, true}});
  ExpectPath(MustRun("G21 G0 X0 Y0 Z10\nG99 G81 X5 Y5 Z-2 R1\nX10\n"),
             {{0, 0, 10, true}, {5, 5, 10, true}, {5, 5, 1, true},
              {5, 5, -2, false}, {5, 5, 1, true}, {10, 5, 1, true},
              {10, 5, -2, false}, {10, 5, 1, true}});
  // Below R: up to R first.
  ExpectPath(MustRun("G21 G0 X0 Y0 Z-1\nG98 G82 X1 Y0 Z-2 R1 P1\n"),
             {{0, 0, -1, true}, {0, 0, 1, true}, {1, 0, 1, true},
              {1, 0, -2, false}, {1, 0, 1, true}});
}

TEST(CycleTest, PeckCyclesG83AndG73) {
  // R1 to Z-1 by Q0.8: pecks to 0.2 and -0.6, then the bottom; G83 goes
  // out to R after each, G73 back 0.254 mm; both come down to 0.254 above
  // the last peck.
  ExpectPath(MustRun("G21 G0 X0 Y0 Z5\nG99 G83 X0 Y0 Z-1 R1 Q0.8\n"),
             {{0, 0, 5, true}, {0, 0, 1, true}, {0, 0, 0.2, false},
              {0, 0, 1, true}, {0, 0, 0.454, true}, {0, 0, -0.6, false},
              {0, 0, 1, true}, {0, 0, -0.346, true}, {0, 0, -1, false},
              {0, 0, 1, true}});
  ExpectPath(MustRun("G21 G0 X0 Y0 Z5\nG99 G73 X0 Y0 Z-1 R1 Q0.8\n"),
             {{0, 0, 5, true}, {0, 0, 1, true}, {0, 0, 0.2, false},
              {0, 0, 0.454, true}, {0, 0, -0.6, false},
              {0, 0, -0.346, true}, {0, 0, -1, false}, {0, 0, 1, true}});
}

TEST(CycleTest, IncrementalRepeatsStepFromHoleToHole) {
  // G91: R is relative to the start height (5 - 4 = 1), Z to R (1 - 3).
  ExpectPath(MustRun("G21 G0 X0 Y0 Z5\nG91 G99 G81 X2 Y0 Z-3 R-4 L3\n"),
             {{0, 0, 5, true}, {2, 0, 5, true}, {2, 0, 1, true},
              {2, 0, -2, false}, {2, 0, 1, true}, {4, 0, 1, true},
              {4, 0, -2, false}, {4, 0, 1, true}, {6, 0, 1, true},
              {6, 0, -2, false}, {6, 0, 1, true}});
}

TEST(CycleTest, BoringTappingAndBackBoring) {
  const std::vector<Pt> feed_out = {{0, 0, 5, true}, {1, 0, 5, true},
                                    {1, 0, 1, true}, {1, 0, -1, false},
                                    {1, 0, 1, false}, {1, 0, 5, true}};
  for (const char* g : {"G84", "G74", "G85", "G89"}) {
    ExpectPath(MustRun(std::string("G21 G0 X0 Y0 Z5\nG98 ") + g +
                       " X1 Y0 Z-1 R1 P0.5\n"),
               feed_out);
  }
  for (const char* g : {"G86", "G88"}) {
    ExpectPath(MustRun(std::string("G21 G0 X0 Y0 Z5\nG98 ") + g +
                       " X1 Y0 Z-1 R1 P0.5\n"),
               {{0, 0, 5, true}, {1, 0, 5, true}, {1, 0, 1, true},
                {1, 0, -1, false}, {1, 0, 5, true}});
  }
  ExpectPath(MustRun("G21 G0 X0 Y0 Z5\nG98 G87 X1 Y0 Z-3 R1 I0.5 J0 K-1\n"),
             {{0, 0, 5, true}, {1, 0, 5, true}, {1, 0, 1, true},
              {1.5, 0, 1, true}, {1.5, 0, -3, true}, {1, 0, -3, true},
              {1, 0, -1, false}, {1, 0, -3, false}, {1.5, 0, -3, true},
              {1.5, 0, 5, true}, {1, 0, 5, true}});
}

TEST(CycleTest, BoltCircleFromASubroutineInALoop) {
  // A LinuxCNC-style program: four holes on a circle of radius 10, each a
  // G81 in a subroutine called from a while loop with the angle.
  const Toolpath tp = MustRun(
      "G21 G90 G17\n"
      "#<_r> = 10\n"
      "#<n> = 4\n"
      "o<hole> sub\n"
      "  G98 G81 X[#<_r> * cos[#1]] Y[#<_r> * sin[#1]] Z-2 R1\n"
      "o<hole> endsub\n"
      "G0 X0 Y0 Z5\n"
      "#<i> = 0\n"
      "o10 while [#<i> LT #<n>]\n"
      "  o<hole> call [#<i> * 360 / #<n>]\n"
      "  #<i> = [#<i> + 1]\n"
      "o10 endwhile\n"
      "G80\nM2\n");
  std::vector<Pt> want = {{0, 0, 5, true}};
  const double holes[4][2] = {{10, 0}, {0, 10}, {-10, 0}, {0, -10}};
  for (const auto& h : holes) {
    want.push_back({h[0], h[1], 5, true});
    want.push_back({h[0], h[1], 1, true});
    want.push_back({h[0], h[1], -2, false});
    want.push_back({h[0], h[1], 5, true});
  }
  ExpectPath(tp, want);
  for (size_t i = 1; i < tp.points().size(); ++i) {
    EXPECT_EQ(tp.points()[i].line, 5);  // the subroutine's line
  }
}

TEST(CycleTest, BadCyclesNameTheLine) {
  const std::string s = "G21 G0 X0 Y0 Z5\n";
  EXPECT_THAT(ErrorOf(s + "G81 X0 Y0 Z-1\n"),
              StartsWith("line 2: G81 needs R"));
  EXPECT_THAT(ErrorOf(s + "G81 X0 Y0 Z2 R1\n"), HasSubstr("above the retract"));
  EXPECT_THAT(ErrorOf(s + "G83 X0 Y0 Z-1 R1\n"), HasSubstr("needs Q > 0"));
  EXPECT_THAT(ErrorOf(s + "G81 X0 Y0 Z-1 R1 L0\n"), HasSubstr("repeat count"));
  EXPECT_THAT(ErrorOf(s + "G81 R1 Z-1\nG80 X1\n"), HasSubstr("G80 cancelled"));
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0\nG81 X0 Y0 Z-1 R1\n"),
              HasSubstr("while Z is unknown"));
  EXPECT_THAT(ErrorOf(s + "G87 X1 Y0 Z-3 R1 I1\n"), HasSubstr("I, J and K"));
}

// ------------------------------------------------------------ compensation

// Distance from p to the boundary of the square [0, 10]^2.
double ToSquare(double x, double y) {
  const double dx = std::max({-x, x - 10, 0.0}), dy = std::max({-y, y - 10, 0.0});
  if (dx > 0 || dy > 0) return std::hypot(dx, dy);
  return std::min({x, 10 - x, y, 10 - y});
}

TEST(CompensationTest, InsideASquareTheCornersAreCut) {
  // G41 going counterclockwise: the tool (r 1) inside; concave corners.
  const Toolpath tp = MustRun(
      "G21 G0 X-5 Y0 Z1\nG1 Z-1\nG41.1 D2\nG1 X0 Y0\nX10\nY10\nX0\nY0\n"
      "G40\nG1 X-5\n");
  ExpectNear(Xyz(tp), {{-5, 0, 1}, {-5, 0, -1}, {0, 1, -1}, {9, 1, -1},
                       {9, 9, -1}, {1, 9, -1}, {1, 0, -1}, {-5, 0, -1}});
}

TEST(CompensationTest, AroundASquareTheCornersAreArcs) {
  // G42 counterclockwise: the tool outside, around each corner on an arc of
  // its radius: every point of the contour is 1.5 from the square.
  GcodeOptions o;
  o.tool_radius = [](int t) -> std::optional<double> {
    if (t == 3) return 1.5;
    return std::nullopt;
  };
  const Toolpath tp = MustRun(
      "G21 T3 M6\nG0 X-5 Y-5 Z1\nG1 Z-1\nG42 D3\nG1 X0 Y0\nX10\nY10\nX0\n"
      "Y0\nG40\nG1 X-5 Y-5\n",
      o);
  int on_contour = 0;
  for (size_t i = 0; i < tp.points().size(); ++i) {
    const ToolpathPoint& p = tp.points()[i];
    if (p.line < 6 || p.line > 9) continue;
    EXPECT_NEAR(ToSquare(p.position.x, p.position.y), 1.5, 1e-9) << i;
    ++on_contour;
  }
  EXPECT_GT(on_contour, 20);  // the corner arcs are chorded
  // The corner at (10, 0): from (10, -1.5) round to (11.5, 0).
  bool seen = false;
  for (const ToolpathPoint& p : tp.points()) {
    seen |= std::fabs(p.position.x - 11.5) < 1e-12 && p.position.y == 0;
  }
  EXPECT_TRUE(seen);
  EXPECT_THAT(ErrorOf("G21 T3 M6\nG0 X0 Y0 Z0\nG42 D3\n"),
              HasSubstr("the radius of tool 3 is unknown"));
}

TEST(CompensationTest, InsideACircleTheToolRunsOnTheSmallerRadius) {
  const Toolpath tp = MustRun(
      "G21 G0 X0 Y0 Z1\nG1 Z-1\nG41.1 D2\nG1 X10 Y0\nG3 X10 Y0 I-10 J0\n"
      "G40 G1 X0 Y0\n");
  // The entry's offset line (y = 1) meets the circle (r 9) at (sqrt 80, 1):
  // rs274 gives STRAIGHT_FEED(8.9443, 1.0000, -1.0000).
  ASSERT_GE(tp.point_count(), 5);
  ExpectNear({Xyz(tp)[2]}, {{std::sqrt(80.0), 1, -1}}, 1e-12);
  int on_circle = 0;
  for (const ToolpathPoint& p : tp.points()) {
    if (p.line != 5) continue;
    EXPECT_NEAR(std::hypot(p.position.x, p.position.y), 9, 1e-9);
    ++on_circle;
  }
  EXPECT_GT(on_circle, 100);
  ExpectNear({Xyz(tp)[tp.points().size() - 2]}, {{9, 0, -1}}, 1e-9);
  ExpectNear({Xyz(tp).back()}, {{0, 0, -1}});
  // An arc smaller than the tool on its inside, and a corner the tool
  // can't reach, are errors naming the line.
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG41.1 D4\nG1 X1\nG3 X1 Y2 J1\n"),
              StartsWith("line 4: arc of radius 1 mm is too small"));
  EXPECT_THAT(ErrorOf("G21 G0 X-5 Y0 Z0\nG41.1 D4\nG1 X0 Y0\nX10\nY1\nX0\n"
                      "G40\n"),
              StartsWith("line 5: cutter compensation: the tool (radius 2 mm) "
                         "cannot reach the concave corner between line 4"));
  // An arc may be the entry move (LinuxCncParityTest.CompWithAnArcAs...),
  // but not one smaller than the tool on its inside.
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG41.1 D2\nG3 X2 Y0 I1\n"),
              HasSubstr("too small for the compensated tool radius"));
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG41.1 D2\nG1 X1\nM6 T2\n"),
              HasSubstr("M6 with cutter compensation on"));
}

// ------------------------------------------------------------ never silent

TEST(DroppedTest, MovesAfterM6AndWithoutZAreCountedAndNamed) {
  GcodeOptions forget;  // swarf's M6 before issue 27
  forget.m6_forgets_position = true;
  const Toolpath tp = MustRun(
      "G21\nT1 M6\nG0 X0 Y0 Z5\nG1 Z-1\nX5\nT2 M6\nG1 X20\nG0 Z5\n"
      "G1 X10 Y10 Z-1\nX11\n", forget);
  EXPECT_EQ(tp.dropped_moves(), 2);
  ASSERT_EQ(tp.first_dropped().size(), 2u);
  EXPECT_EQ(tp.first_dropped()[0].line, 7);
  EXPECT_STREQ(tp.first_dropped()[0].missing, "YZ");
  EXPECT_EQ(tp.first_dropped()[1].line, 9);
  EXPECT_STREQ(tp.first_dropped()[1].missing, "Y");
  EXPECT_EQ(tp.DroppedSummary(),
            "dropped 2 feed moves with an unknown start or end (not "
            "simulated): line 7 (YZ unknown), line 9 (Y unknown)");
  // Tools and rapids per point.
  ASSERT_EQ(tp.point_count(), 5);
  const int tools[] = {1, 1, 1, 2, 2};
  for (int i = 0; i < 5; ++i) EXPECT_EQ(tp.points()[i].tool, tools[i]) << i;
  EXPECT_TRUE(tp.points()[3].starts_run);
  // A program that never sets Z: every feed dropped, named.
  const Toolpath noz = MustRun("G21 G0 X0 Y0\n" + std::string(12, ' ') +
                               "\nG1 X1\nX2\nX3\nX4\nX5\nX6\nX7\nX8\nX9\nX10\n"
                               "X11\nX12\n");
  EXPECT_EQ(noz.point_count(), 0);
  EXPECT_EQ(noz.dropped_moves(), 12);
  EXPECT_EQ(noz.first_dropped().size(), Toolpath::kFirstDropped);
  EXPECT_THAT(noz.DroppedSummary(),
              AllOf(StartsWith("dropped 12 feed moves"),
                    HasSubstr("line 3 (Z unknown)"), testing::EndsWith(", ...")));
}

// Where each tool is first selected (for errors naming the T word's line):
// a T word alone before any M6, then M6 and M61; programs appended keep
// their first lines and start a run each.
TEST(ToolSelectionTest, TheLineOfTheFirstSelectionOfEachTool) {
  Toolpath tp = MustRun(
      "G21\nT4\nG0 X0 Y0 Z5\nG1 Z-1\nT1 M6\nG0 X0 Y0 Z5\nG1 Z-1\nT2\n"
      "G1 X1\nM6\nG0 X0 Y0 Z5\nG1 Z-1\nM61 Q7\nG1 X3\nT1 M6\nG0 X0 Y0 Z5\n");
  EXPECT_EQ(tp.ToolSelectedAt(4), 2);
  EXPECT_EQ(tp.ToolSelectedAt(1), 5);  // not 15
  EXPECT_EQ(tp.ToolSelectedAt(2), 10);  // the M6, not the T word on line 8
  EXPECT_EQ(tp.ToolSelectedAt(7), 13);
  EXPECT_FALSE(tp.ToolSelectedAt(0).has_value());
  EXPECT_FALSE(MustRun("G21 G0 X0 Y0 Z1\nG1 Z-1\n").ToolSelectedAt(0).has_value());
  const Toolpath next = MustRun("G21\nT9 M6\nG0 X0 Y0 Z5\nG1 Z-1\nX4\n");
  const int64_t points = tp.point_count(), runs = tp.run_count();
  tp.AppendProgram(next);
  EXPECT_EQ(tp.ToolSelectedAt(9), 2);
  EXPECT_EQ(tp.ToolSelectedAt(1), 5);
  EXPECT_EQ(tp.point_count(), points + next.point_count());
  EXPECT_EQ(tp.run_count(), runs + next.run_count());
  EXPECT_TRUE(tp.points()[points].starts_run);
  EXPECT_EQ(tp.move_count(), tp.point_count() - tp.run_count());
}

TEST(DroppedTest, TheCutOutsideTheStockIsFound) {
  const Toolpath tp = MustRun(
      "G21 G0 X-5 Y0 Z5\nG1 Z-1\nX3\nX12 Y4\nG0 Z5\nG0 X30\nG1 X31 Z1\n");
  // The plunge at X-5 is 5 mm out, X12 2 mm; rapids and feeds above the
  // top (Z1 > 0) don't count.
  const Excursion e = FarthestOutside(tp, 0, 0, 10, 10, 0);
  ASSERT_EQ(e.index, 1);
  EXPECT_EQ(e.distance, 5);
  EXPECT_EQ(FarthestOutside(tp, -6, 0, 12, 10, 0).index, -1);
}

// ------------------------------------------------------------ formats, dialects

TEST(FormatTest, DetectedByContent) {
  EXPECT_EQ(DetectToolpathFormat("1,2,3\n"), ToolpathFormat::kXyz);
  EXPECT_EQ(DetectToolpathFormat("\n  x, y, z\n1 2 3\n"), ToolpathFormat::kXyz);
  EXPECT_EQ(DetectToolpathFormat("# tips\n-1 2 3\n"), ToolpathFormat::kXyz);
  EXPECT_EQ(DetectToolpathFormat(".5 2 3\n"), ToolpathFormat::kXyz);
  EXPECT_EQ(DetectToolpathFormat("#1 = 2\nG0 X#1\n"), ToolpathFormat::kGcode);
  EXPECT_EQ(DetectToolpathFormat("#<a> = 2\n"), ToolpathFormat::kGcode);
  EXPECT_EQ(DetectToolpathFormat("(job)\n; x\nG0 X1\n"), ToolpathFormat::kGcode);
  EXPECT_EQ(DetectToolpathFormat("%\nO100\n"), ToolpathFormat::kGcode);
  EXPECT_EQ(DetectToolpathFormat("N10 G0 X1\n"), ToolpathFormat::kGcode);
  EXPECT_EQ(DetectToolpathFormat("X1 Y2 Z3\n"), ToolpathFormat::kGcode);
  EXPECT_EQ(DetectToolpathFormat(""), ToolpathFormat::kGcode);
}

TEST(DialectTest, GrblSettingsLinesAreIgnoredWithANote) {
  GcodeOptions o;
  o.dialect = Dialect::kGrbl;
  const Toolpath tp = MustRun("$H\n$X\nG21 G0 X0 Y0 Z0\nG1 X1\n", o);
  EXPECT_EQ(tp.point_count(), 2);
  EXPECT_EQ(tp.ignored().at("$"), 2);
  ASSERT_EQ(tp.notes().size(), 1u);
  EXPECT_THAT(tp.notes()[0], HasSubstr("Grbl '$' lines"));
}

TEST(DialectTest, FanucSubprogramsWithRepeats) {
  GcodeOptions o;
  o.dialect = Dialect::kFanuc;
  const Toolpath tp = MustRun(
      "G21 G0 X0 Y0 Z0\nM98 P1000 L2\nG0 Y1\nM30\n"
      "O1000 (STEP)\nG91 G1 X1\nG90\nM99\n",
      o);
  ExpectNear(Xyz(tp), {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {2, 1, 0}});
  EXPECT_EQ(tp.points()[1].line, 6);
}

TEST(DialectTest, FanucCycleFormsRepeatWithKAndG76Bores) {
  GcodeOptions o;
  o.dialect = Dialect::kFanuc;
  ExpectPath(MustRun("G21 G0 X0 Y0 Z5\nG91 G99 G81 X2 Y0 Z-3 R-4 K2\n", o),
             {{0, 0, 5, true}, {2, 0, 5, true}, {2, 0, 1, true},
              {2, 0, -2, false}, {2, 0, 1, true}, {4, 0, 1, true},
              {4, 0, -2, false}, {4, 0, 1, true}});
  ExpectPath(MustRun("G21 G0 X0 Y0 Z5\nG98 G76 X1 Y0 Z-1 R1 Q0.1\n", o),
             {{0, 0, 5, true}, {1, 0, 5, true}, {1, 0, 1, true},
              {1, 0, -1, false}, {1, 0, 5, true}});
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z5\nG98 G76 X1 Y0 Z-1 R1 Q0.1\n"),
              HasSubstr("lathe"));
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z5\nG87 X1 Y0 Z-1 R1 Q1\n", o),
              HasSubstr("Fanuc form"));
}

TEST(ModalStateTest, M70SavesAndM72RestoresUnitsAndDistanceMode) {
  const Toolpath tp =
      MustRun("G21 G0 X0 Y0 Z0\nM70\nG20 G91\nG0 X1\nM72\nG0 X1\n");
  ExpectNear(Xyz(tp), {{0, 0, 0}, {25.4, 0, 0}, {1, 0, 0}});
}


// ------------------------------------------------- parity with LinuxCNC (27)
//
// Each program was run by LinuxCNC 2.9's rs274 (scripts/linuxcnc-diff); the
// positions it printed (4 decimals) are in the comments, the expected values
// are worked out by hand.

TEST(LinuxCncParityTest, G98InASeriesRetractsToTheSeriesInitialLevel) {
  // rs274: ... (0,0,2) then STRAIGHT_TRAVERSE(5, 0, 10) (diagonal, at the
  // initial level), (5,0,2), feed (5,0,-1), back to (5,0,10).
  const Toolpath tp = MustRun(
      "G21 G0 X0 Y0 Z10\nG99 G81 X0 Y0 Z-1 R2\nG98 X5\nG80\n");
  ExpectNear(Xyz(tp), {{0, 0, 10}, {0, 0, 2}, {0, 0, -1}, {0, 0, 2},
                       {5, 0, 10}, {5, 0, 2}, {5, 0, -1}, {5, 0, 10}});
  // G91: R from the initial level (not the height after a G99 hole), L
  // repeats at the clearance height; a G0 ends the series.
  const Toolpath inc = MustRun(
      "G21 G0 X0 Y0 Z1\nG99 G81 X15 Z-1 R2\nG91 G98 G81 X5 R-1 Z-2 L2\n"
      "G90 G0 Z5\nG98 G81 X40 Z-1 R2\n");
  // rs274: (15,0,2) hole, then (20,0,2) (20,0,0) feed (20,0,-2) up to 1,
  // (25,0,1) (25,0,0) (25,0,-2) (25,0,1); the new series: (40,0,5) ...
  ExpectNear(Xyz(inc), {{0, 0, 1},   {0, 0, 2},   {15, 0, 2},  {15, 0, -1},
                        {15, 0, 2},  {20, 0, 2},  {20, 0, 0},  {20, 0, -2},
                        {20, 0, 1},  {25, 0, 1},  {25, 0, 0},  {25, 0, -2},
                        {25, 0, 1},  {25, 0, 5},  {40, 0, 5},  {40, 0, 2},
                        {40, 0, -1}, {40, 0, 5}});
}

TEST(LinuxCncParityTest, CompEntryIntoAConcaveCornerEndsOnTheOffsetLine) {
  // Radius 1.5: the entry's offset line y = -x/2 + 37.5/sqrt(500) meets the
  // next move's offset x = 18.5 at y = -9.25 + 37.5/sqrt(500) = -7.572949;
  // rs274: STRAIGHT_FEED(18.5000, -7.5729), (18.5, 0), exit (30, 10).
  const Toolpath tp = MustRun(
      "G21 G0 X0 Y0 Z0\nG41.1 D3\nG1 X20 Y-10\nG1 X20 Y0\nG40 G1 X30 Y10\n");
  ExpectNear(Xyz(tp), {{0, 0, 0},
                       {18.5, -9.25 + 37.5 / std::sqrt(500.0), 0},
                       {18.5, 0, 0},
                       {30, 10, 0}});
}

TEST(LinuxCncParityTest, TangentLineIntoArcUnderCompWithManyDecimals) {
  // useful-subroutines.ngc's slot (o200) written out with 15 decimals: the
  // line is tangent to the arc but for rounding. It was refused ("cannot
  // reach the concave corner"); rs274 runs it, as it runs 13 decimals.
  const auto slot = [](int decimals) {
    const double bx = -0.111803398874989, by = -0.055901699437495;
    const double sx = 0.055901699437495, sy = -0.111803398874989;
    char buf[1024];
    const int d = decimals;
    std::snprintf(
        buf, sizeof buf,
        "G20 G0 Z0.1\nG0 X%.*f Y%.*f\nG41.1 D0.0625 G0 X%.*f Y%.*f\n"
        "G1 X%.*f Y%.*f Z-0.1\nG3 X%.*f Y%.*f R0.125\nG1 X%.*f Y%.*f\n"
        "G3 X%.*f Y%.*f R0.125\nG1 X%.*f Y%.*f\nG0 Z0.1\nG40\n",
        d, bx + sx, d, by + sy, d, sx, d, sy, d, 1 + sx, d, 0.5 + sy, d,
        1 - sx, d, 0.5 - sy, d, -sx, d, -sy, d, sx, d, sy, d, 1 + sx, d,
        0.5 + sy);
    return std::string(buf);
  };
  for (const int d : {7, 8, 10, 12, 13, 14, 15}) {
    const absl::StatusOr<Toolpath> tp = ParseGcode(slot(d));
    ASSERT_TRUE(tp.ok()) << d << " decimals: " << tp.status();
  }
  // The same path whatever the decimals.
  const Toolpath a = MustRun(slot(13)), b = MustRun(slot(15));
  ASSERT_EQ(a.point_count(), b.point_count());
  for (int64_t i = 0; i < a.point_count(); ++i) {
    EXPECT_NEAR(a.points()[i].position.x, b.points()[i].position.x, 1e-6);
    EXPECT_NEAR(a.points()[i].position.y, b.points()[i].position.y, 1e-6);
  }
}

TEST(LinuxCncParityTest, ReturnLabelledWithAnEnclosingIf) {
  // retval.ngc's form; rs274: STRAIGHT_FEED(246, 0, 0), (246, 4712, 0).
  const Toolpath tp = MustRun(
      "o1000 sub\n  o1010 if [#1 GT 0]\n    o1010 return [123*#1]\n"
      "  o1010 endif\no1000 endsub [4712]\nG21 G0 X0 Y0 Z0\n"
      "o1000 call [2]\nG1 X#<_value>\no1000 call [0]\nG1 Y#<_value>\n");
  ExpectNear(Xyz(tp), {{0, 0, 0}, {246, 0, 0}, {246, 4712, 0}});
  // A label that encloses nothing is still an error.
  EXPECT_THAT(ErrorOf("o1 sub\no2 return\no1 endsub\nG21\no1 call\n"),
              HasSubstr("o2 return inside subroutine o1"));
}

TEST(LinuxCncParityTest, PolarCoordinates) {
  // rs274: (8.6603, 5), (0, 10), (-3.5355, 3.5355); after G92 X0 Y0 there
  // (program origin moved), @2 ^180 is (-2, 0) in program coordinates; the
  // G91 G81 @1 ^90 L3 holes step radius and angle: program (0,-3), (4,0),
  // (0,5).
  const Toolpath tp = MustRun(
      "G21 G0 X0 Y0 Z0\nG1 @10 ^30\nG1 ^90\nG91 G1 @-5 ^45\n"
      "G90 G92 X0 Y0\nG1 @2 ^180\nG91 G81 @1 ^90 R1 Z-2 L3\nG80 G90\n");
  const double h = 5 / std::sqrt(2.0);
  const double ox = -h, oy = h;  // the G92 origin
  ExpectNear(Xyz(tp),
             {{0, 0, 0},           {5 * std::sqrt(3.0), 5, 0},
              {0, 10, 0},          {-h, h, 0},
              {ox - 2, oy, 0},     {ox - 2, oy, 1},
              {ox, oy - 3, 1},     {ox, oy - 3, -1},
              {ox, oy - 3, 1},     {ox + 4, oy, 1},
              {ox + 4, oy, -1},    {ox + 4, oy, 1},
              {ox, oy + 5, 1},     {ox, oy + 5, -1},
              {ox, oy + 5, 1}},
             1e-9);
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG1 X1 @2\n"),
              HasSubstr("X or Y with polar coordinates"));
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG91 G1 @2\n"),
              HasSubstr("at the origin"));
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG18 G1 @2 ^0\n"),
              HasSubstr("only in the XY plane"));
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG1 @1 @2\n"), HasSubstr("two @"));
}

TEST(LinuxCncParityTest, M6KeepsThePositionOrGoesToTheToolChangePosition) {
  // rs274: (10,10,5) then feed (10,10,-1) with T2: the position stays.
  const std::string prog = "G21 G0 X10 Y10 Z5\nT2 M6\nG1 Z-1\nX20\n";
  const Toolpath tp = MustRun(prog);
  ExpectNear(Xyz(tp), {{10, 10, 5}, {10, 10, -1}, {20, 10, -1}});
  EXPECT_EQ(tp.run_count(), 1);
  EXPECT_EQ(tp.points()[0].tool, 0);
  EXPECT_EQ(tp.points()[1].tool, 2);
  EXPECT_EQ(tp.dropped_moves(), 0);
  // A tool-change position: a rapid there with the old tool first; the
  // machine stays there (LinuxCNC resynchronises to it).
  GcodeOptions tc;
  tc.tool_change_position_known = true;
  tc.tool_change_position[0] = 0;
  tc.tool_change_position[1] = 0;
  tc.tool_change_position[2] = 50;
  const Toolpath at = MustRun("G21 T1 M6\n" + prog, tc);
  ExpectNear(Xyz(at), {{0, 0, 50}, {10, 10, 5}, {0, 0, 50}, {0, 0, -1},
                       {20, 0, -1}});
  EXPECT_TRUE(at.points()[2].rapid);
  EXPECT_EQ(at.points()[2].tool, 1);
  EXPECT_EQ(at.points()[3].tool, 2);
  // The old behaviour: the position is lost, the feeds dropped.
  GcodeOptions forget;
  forget.m6_forgets_position = true;
  const Toolpath lost = MustRun(prog, forget);
  EXPECT_EQ(lost.point_count(), 1);
  EXPECT_EQ(lost.dropped_moves(), 2);
}

TEST(LinuxCncParityTest, AKnownStartAllowsIncrementalFirstMoves) {
  const std::string prog = "G21 G91\nG0 X5 Y5\nG1 Z-2\nX10\n";
  EXPECT_THAT(ErrorOf(prog), HasSubstr("incremental (G91) X move while X is "
                                       "unknown"));
  // rs274 (from the machine origin): (5,5,0), feed (5,5,-2), (15,5,-2).
  GcodeOptions start;
  start.start_known = true;
  const Toolpath tp = MustRun(prog, start);
  ExpectNear(Xyz(tp), {{0, 0, 0}, {5, 5, 0}, {5, 5, -2}, {15, 5, -2}});
  EXPECT_TRUE(tp.points()[0].starts_run);
  EXPECT_FALSE(tp.points()[1].starts_run);
  EXPECT_TRUE(tp.points()[1].rapid);
  // An arc may be the first move.
  const Toolpath arc = MustRun("G21 G3 X2 Y0 I1 J0\n", start);
  EXPECT_GT(arc.point_count(), 3);
  ExpectNear({Xyz(arc).back()}, {{2, 0, 0}});
}

TEST(LinuxCncParityTest, CompWithAnArcAsTheEntryMove) {
  // comp311_2.ngc's entry, radius 0.25: the arc ends at (2, 3.25) (offset
  // along the programmed radius) on a circle through the start (1, 4)
  // centred on that radius: (2, 3.25 + 1.5625 / 1.5); rs274:
  // ARC_FEED(2.0000, 3.2500, 2.0000, 4.2917, 1), then (3.25, 2) about
  // (2, 2), (3.25, -1), exit (5, -1).
  const Toolpath tp = MustRun(
      "G21 G0 X1 Y4 Z0\nG41.1 D0.5\nG3 X2 Y3 I1\nG2 X3 Y2 J-1\nG1 Y-1\n"
      "G40 G1 X5\n");
  const double cy = 3.25 + 1.5625 / 1.5, r = 1.5625 / 1.5;
  bool reached = false;
  for (const ToolpathPoint& p : tp.points()) {
    if (p.line != 3) continue;
    EXPECT_NEAR(std::hypot(p.position.x - 2, p.position.y - cy), r, 1e-9);
    reached |= p.position.x == 2 && std::fabs(p.position.y - 3.25) < 1e-12;
  }
  EXPECT_TRUE(reached);
  ExpectNear({Xyz(tp)[tp.points().size() - 2], Xyz(tp).back()},
             {{3.25, -1, 0}, {5, -1, 0}});
}

TEST(LinuxCncParityTest, AfterG40MovesWithoutXYKeepTheOffsetPoint) {
  // rs274: ... (10, 1, 0), Z up at (10, 1), then the exit to (20, 0, 5).
  const Toolpath tp = MustRun(
      "G21 G0 X0 Y0 Z0\nG41.1 D2\nG1 X10\nG40\nG0 Z5\nG0 X20\n");
  ExpectNear(Xyz(tp), {{0, 0, 0}, {10, 1, 0}, {10, 1, 5}, {20, 0, 5}});
}

TEST(LinuxCncParityTest, CompInTheXZPlane) {
  // G18: (Z, X) is the plane (Z first, as its arcs); G42 puts the tool
  // right of the path there. The entry's offset line x = z - sqrt 2 meets
  // x = -1 at z = sqrt 2 - 1; rs274: STRAIGHT_FEED(-1, 0, 0.4142), (-1, 0,
  // 10), ARC_FEED to z 14, x -5 about (10, -5), (-10, 0, 14), exit.
  const Toolpath tp = MustRun(
      "G21 G18\nG0 X-5 Z-5 Y0\nG42.1 D2\nG1 X0 Z0\nG1 Z10\n"
      "G2 R5 X-5 Z15\nG1 X-10\nG40 G0 X-15 Z20\n");
  ASSERT_GE(tp.point_count(), 6);
  ExpectNear({Xyz(tp)[1], Xyz(tp)[2]},
             {{-1, 0, std::sqrt(2.0) - 1}, {-1, 0, 10}});
  for (const ToolpathPoint& p : tp.points()) {
    if (p.line != 6) continue;
    EXPECT_NEAR(std::hypot(p.position.z - 10, p.position.x + 5), 4, 1e-9);
  }
  ExpectNear({Xyz(tp)[tp.points().size() - 2], Xyz(tp).back()},
             {{-10, 0, 14}, {-15, 0, 20}});
  EXPECT_THAT(ErrorOf("G21 G0 X0 Y0 Z0\nG41.1 D2\nG1 X5\nG18 G1 Z5\n"),
              HasSubstr("G18 with cutter compensation on"));
}

// The canonical-command seam: a sink sees arcs as arcs.
class Recorder final : public CanonSink {
 public:
  absl::Status Straight(const CanonStraight& m) override {
    kinds += m.starts_run ? 's' : m.rapid ? 'r' : 'f';
    return absl::OkStatus();
  }
  absl::Status ArcFeed(const CanonArc& a) override {
    kinds += 'a';
    arcs.push_back(a);
    return absl::OkStatus();
  }
  void ToolChange(int32_t, int tool) override { tools.push_back(tool); }
  std::string kinds;
  std::vector<CanonArc> arcs;
  std::vector<int> tools;
};

TEST(CanonSinkTest, ArcsComeWithCentreAxisAndTurns) {
  Recorder rec;
  const absl::StatusOr<Toolpath> tp = ParseGcode(
      "G21 G0 X10 Y0 Z0\nG1 Z-1\nG2 X0 Y-10 I-10 J0\nT3 M6\n"
      "G18 G3 X0 Z-1 I0 K1 P2\n",
      {}, &rec);
  ASSERT_TRUE(tp.ok()) << tp.status();
  EXPECT_EQ(tp->point_count(), 0);  // the commands went to the sink
  EXPECT_EQ(rec.kinds, "sfaa");
  ASSERT_EQ(rec.arcs.size(), 2u);
  EXPECT_EQ(rec.arcs[0].Turns(), -1);
  EXPECT_EQ(rec.arcs[0].p2, 2);
  EXPECT_NEAR(rec.arcs[0].Centre().x, 0, 1e-12);
  EXPECT_NEAR(rec.arcs[0].Centre().y, 0, 1e-12);
  EXPECT_NEAR(rec.arcs[0].sweep, -std::acos(-1.0) / 2, 1e-12);
  EXPECT_EQ(rec.arcs[1].p2, 1);  // about Y
  EXPECT_EQ(rec.arcs[1].Turns(), 2);
  EXPECT_EQ(rec.arcs[1].tool, 3);
  EXPECT_EQ(rec.tools, std::vector<int>{3});
}

}  // namespace
}  // namespace swarf::gcode
