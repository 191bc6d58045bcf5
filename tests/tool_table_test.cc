// Tools as users give them (client/cli/tool_table.h): the --tool syntax,
// LinuxCNC tool tables, CAMotics projects and the choice of a tool per T
// number; every error names the option and key, the file and line, or the
// tool.
#include "client/cli/tool_table.h"

#include <cmath>
#include <numbers>
#include <string>

#include "absl/strings/match.h"
#include "gtest/gtest.h"

namespace swarf::cli {
namespace {

constexpr double kDeg = 180 / std::numbers::pi;

// The status is InvalidArgument and its message holds every `part`.
::testing::AssertionResult Names(const absl::Status& s,
                                 std::initializer_list<std::string> parts) {
  if (s.code() != absl::StatusCode::kInvalidArgument) {
    return ::testing::AssertionFailure() << "status " << s;
  }
  for (const std::string& p : parts) {
    if (!absl::StrContains(s.message(), p)) {
      return ::testing::AssertionFailure()
             << "\"" << s.message() << "\" does not name \"" << p << "\"";
    }
  }
  return ::testing::AssertionSuccess();
}

Cutter Tool(const std::string& spec) {
  auto o = ParseToolOption(spec);
  EXPECT_TRUE(o.ok()) << spec << ": " << o.status();
  return o.ok() ? o->cutter : Cutter{};
}

// ------------------------------------------------------------- --tool

TEST(ToolOptionTest, EveryShapeInTheUsersTerms) {
  EXPECT_EQ(Tool("ball:d=6"), Cutter::Ball(3));
  EXPECT_EQ(Tool("ball:r=1.5"), Cutter::Ball(1.5));
  EXPECT_EQ(Tool("ball:d=3.175"), Cutter::Ball(3.175 / 2));
  EXPECT_EQ(Tool("flat:d=6"), Cutter::Flat(3));
  EXPECT_EQ(Tool("bull:d=6,r=1"), Cutter::BullNose(3, 1));
  EXPECT_EQ(Tool("bull:d=6,r=0"), Cutter::BullNose(3, 0));
  EXPECT_EQ(Tool("bull:d=6,r=3"), Cutter::BullNose(3, 3));
  // Included angles as V-bits are sold: a 90 degree V-bit has 45.
  EXPECT_EQ(Tool("vbit:d=6,angle=90"), Cutter::Cone(3, 45, 0));
  EXPECT_EQ(Tool("vbit:d=6,angle=60,tip=0.2"), Cutter::Cone(3, 30, 0.1));
  EXPECT_EQ(Tool("cone:d=6,angle=90"), Cutter::Cone(3, 45, 0));  // alias
  EXPECT_EQ(Tool("taper:d=6,tip=1,angle=10"), Cutter::TaperedBall(3, 0.5, 5));
  EXPECT_EQ(Tool("Flat: d = 6 "), Cutter::Flat(3));  // case, blanks
}

TEST(ToolOptionTest, ToolNumbers) {
  for (const char* spec : {"T2=flat:d=6", "2=flat:d=6", "t2=flat:d=6"}) {
    auto o = ParseToolOption(spec);
    ASSERT_TRUE(o.ok()) << spec << ": " << o.status();
    EXPECT_EQ(o->number, 2) << spec;
    EXPECT_EQ(o->cutter, Cutter::Flat(3)) << spec;
  }
  EXPECT_FALSE(ParseToolOption("ball:d=6")->number.has_value());
  EXPECT_TRUE(Names(ParseToolOption("T-1=ball:d=1").status(),
                    {"--tool \"T-1=ball:d=1\"", "bad tool number"}));
  EXPECT_TRUE(Names(ParseToolOption("T70000=ball:d=1").status(),
                    {"bad tool number"}));
}

TEST(ToolOptionTest, ErrorsNameTheOptionAndTheKey) {
  struct Case {
    std::string spec;
    std::initializer_list<std::string> names;
  };
  const Case cases[] = {
      {"vbit:d=6,angle=190", {"--tool \"vbit:d=6,angle=190\"", "angle must be in (0, 180)"}},
      {"vbit:d=6,angle=0", {"angle must be in (0, 180)", "got 0"}},
      {"vbit:d=6,angle=180", {"angle must be in (0, 180)"}},
      {"vbit:d=6", {"missing angle="}},
      {"vbit:d=6,angle=90,tip=7", {"tip must be in [0, 6]"}},
      {"vbit:d=6,angle=90,tip=-1", {"tip must be"}},
      {"bull:d=6,r=4", {"--tool \"bull:d=6,r=4\"", "r must be in [0, 3]"}},
      {"bull:d=6", {"missing r="}},
      {"bull:d=6,r=-0.5", {"r must be"}},
      {"flat:d=6,x=1", {"unknown key \"x\"", "flat:d=DIAMETER"}},
      {"flat:r=3", {"unknown key \"r\""}},
      {"flat:d=abc", {"d must be a number", "\"abc\""}},
      {"flat:d=nan", {"d must be a number"}},
      {"flat:d=inf", {"d must be a number"}},
      {"flat:d=0", {"d must be in"}},
      {"flat:d=-6", {"d must be in"}},
      {"flat:d=1e9", {"d must be in"}},
      {"flat:d=6,d=7", {"d is given twice"}},
      {"flat", {"expected SHAPE:KEY=VALUE"}},
      {"flat:6", {"\"6\" is not KEY=VALUE"}},
      {"drill:d=3", {"unknown shape \"drill\""}},
      {"ball:d=2,r=1", {"give one of d= and r="}},
      {"ball:", {"give one of d= and r="}},
      {"taper:d=6,tip=0,angle=10", {"tip must be in (0, 6]"}},
      {"taper:d=6,tip=1", {"missing angle="}},
      {"taper:d=6,angle=10,tip=1,r=2", {"unknown key \"r\""}},
  };
  for (const Case& c : cases) {
    EXPECT_TRUE(Names(ParseToolOption(c.spec).status(), c.names)) << c.spec;
  }
}

TEST(ToolOptionTest, SummaryIsInTheUsersTerms) {
  EXPECT_EQ(CutterSummary(Tool("ball:d=3.175")), "ball d=3.175");
  EXPECT_EQ(CutterSummary(Tool("flat:d=6")), "flat d=6");
  EXPECT_EQ(CutterSummary(Tool("bull:d=6,r=1")), "bull d=6 r=1");
  EXPECT_EQ(CutterSummary(Tool("vbit:d=6,angle=90")), "vbit d=6 angle=90");
  EXPECT_EQ(CutterSummary(Tool("vbit:d=6,angle=90,tip=0.2")),
            "vbit d=6 angle=90 tip=0.2");
  EXPECT_EQ(CutterSummary(Tool("taper:d=6,tip=1,angle=10")),
            "taper d=6 tip=1 angle=10");
}

// ------------------------------------------------------- LinuxCNC .tbl

constexpr char kTable[] =
    "T1 P1 D6.0 ;ball\n"
    "T2 P2 Z+0.511 D6 ;1/4 flat end mill\n"
    "T3 P3 D6 ;bull r=1\n"
    "t4 p4 d6.35 ; VBit 90\n"
    "T5 P5 D6 ;vbit 60deg tip=0.2\n"
    "T6 P6 D6 ;tapered tip=1 angle=10\n"
    "T7 P7 X0 Y0 Z1 D3 ;carbide 2 flute\n"
    "T8 P8 ;no diameter given\n"
    "; a comment line\n"
    "\n"
    "T9 P9 D6 ;engraving vbit\n"
    "T10 P10 D6\r\n";

TEST(LinuxCncTableTest, ShapesFromTheCommentFlatOtherwise) {
  auto t = ParseLinuxCncToolTable(kTable, "tools.tbl");
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_EQ(t->file, "tools.tbl");
  ASSERT_EQ(t->tools.size(), 10u);
  auto cutter = [&](int n) { return *t->tools.at(n).cutter; };
  EXPECT_EQ(cutter(1), Cutter::Ball(3));
  EXPECT_EQ(cutter(2), Cutter::Flat(3));
  EXPECT_EQ(cutter(3), Cutter::BullNose(3, 1));
  EXPECT_EQ(cutter(4), Cutter::Cone(3.175, 45, 0));
  EXPECT_EQ(cutter(5), Cutter::Cone(3, 30, 0.1));
  EXPECT_EQ(cutter(6), Cutter::TaperedBall(3, 0.5, 5));
  EXPECT_EQ(cutter(7), Cutter::Flat(1.5));  // no shape named: a flat end mill
  EXPECT_EQ(cutter(10), Cutter::Flat(3));
  EXPECT_EQ(t->tools.at(2).source, "tools.tbl line 2");
  // A tool that can't be simulated is an error only when used, naming it.
  EXPECT_TRUE(Names(t->tools.at(8).cutter.status(),
                    {"tools.tbl line 8", "T8", "no diameter (D)"}));
  EXPECT_TRUE(Names(t->tools.at(9).cutter.status(),
                    {"tools.tbl line 11", "T9", "missing angle="}));
}

TEST(LinuxCncTableTest, InchTable) {
  auto t = ParseLinuxCncToolTable("T1 P1 D0.125 ;ball\nT2 P2 D0.25\n", "in.tbl",
                                  25.4);
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_EQ(*t->tools.at(1).cutter, Cutter::Ball(0.125 * 25.4 / 2));
  EXPECT_EQ(*t->tools.at(2).cutter, Cutter::Flat(0.25 * 25.4 / 2));
}

TEST(LinuxCncTableTest, MalformedLinesAreErrorsNamingTheLine) {
  EXPECT_TRUE(Names(ParseLinuxCncToolTable("T1 D6\nT2 D6 X\n", "a.tbl").status(),
                    {"a.tbl line 2", "\"X\" is not a tool table word"}));
  EXPECT_TRUE(Names(ParseLinuxCncToolTable("T1 D6\nT1 D3\n", "a.tbl").status(),
                    {"a.tbl line 2", "T1 is given twice", "a.tbl line 1"}));
  EXPECT_TRUE(Names(ParseLinuxCncToolTable("\n\nP1 D6\n", "a.tbl").status(),
                    {"a.tbl line 3", "no tool number (T)"}));
  EXPECT_TRUE(Names(ParseLinuxCncToolTable("T1.5 D6\n", "a.tbl").status(),
                    {"a.tbl line 1", "T must be a tool number"}));
  EXPECT_TRUE(Names(ParseLinuxCncToolTable("T1 D6 D7\n", "a.tbl").status(),
                    {"a.tbl line 1", "D is given twice"}));
  EXPECT_TRUE(Names(ParseLinuxCncToolTable("T1 Dx\n", "a.tbl").status(),
                    {"a.tbl line 1", "\"Dx\""}));
}

// ------------------------------------------------------------ CAMotics

constexpr char kProject[] = R"({
  "units": "metric",
  "tools": {
    "1": {"units": "imperial", "shape": "ballnose", "length": 1,
          "diameter": 0.125},
    "2": {"units": "metric", "shape": "cylindrical", "length": 10,
          "diameter": 1},
    "3": {"shape": "conical", "length": 2, "diameter": 2},
    "4": {"shape": "snubnose", "length": 4, "diameter": 6,
          "snub_diameter": 2},
    "5": {"shape": "spheroid", "length": 4, "diameter": 6},
    "6": {"shape": "snubnose", "length": 4, "diameter": 6,
          "snub_diameter": 6},
    "7": {}
  },
  "workpiece": {"automatic": false, "margin": 5,
                "bounds": {"min": [-1, -2, -20], "max": [80, 81, 0.5]}},
  "files": ["a.nc", "sub/b.ngc", "/abs/c.nc"]
})";

TEST(CamoticsProjectTest, ToolsWorkpieceAndFiles) {
  auto p = ParseCamoticsProject(kProject, "/jobs/x/job.camotics");
  ASSERT_TRUE(p.ok()) << p.status();
  const auto& tools = p->tools.tools;
  ASSERT_EQ(tools.size(), 7u);
  EXPECT_EQ(*tools.at(1).cutter, Cutter::Ball(0.125 * 25.4 / 2));  // inches
  EXPECT_EQ(*tools.at(2).cutter, Cutter::Flat(0.5));
  // Conical: the cone spans the radius over the length; included angle
  // 180 - 2 atan(length / radius).
  const Cutter cone = *tools.at(3).cutter;
  EXPECT_EQ(cone.kind, CutterKind::kCone);
  EXPECT_EQ(cone.radius, 1);
  EXPECT_EQ(cone.tip_radius, 0);
  EXPECT_DOUBLE_EQ(cone.half_angle_deg, std::atan(1.0 / 2) * kDeg);
  EXPECT_NEAR(2 * cone.half_angle_deg, 180 - 2 * std::atan(2.0 / 1) * kDeg,
              1e-12);
  // Snubnose: from the diameter down to the snub diameter over the length.
  const Cutter snub = *tools.at(4).cutter;
  EXPECT_EQ(snub.kind, CutterKind::kCone);
  EXPECT_EQ(snub.radius, 3);
  EXPECT_EQ(snub.tip_radius, 1);
  EXPECT_DOUBLE_EQ(snub.half_angle_deg, std::atan(2.0 / 4) * kDeg);
  EXPECT_TRUE(Names(tools.at(5).cutter.status(),
                    {"job.camotics tool \"5\"", "spheroid", "can't be simulated"}));
  EXPECT_EQ(*tools.at(6).cutter, Cutter::Flat(3));  // no taper
  EXPECT_EQ(*tools.at(7).cutter, Cutter::Flat(1));  // CAMotics' defaults
  EXPECT_FALSE(p->automatic);
  EXPECT_EQ(p->margin_percent, 5);
  ASSERT_TRUE(p->has_bounds);
  EXPECT_EQ(p->min[0], -1);
  EXPECT_EQ(p->min[1], -2);
  EXPECT_EQ(p->max[0], 80);
  EXPECT_EQ(p->max[1], 81);
  EXPECT_EQ(p->max[2], 0.5);
  EXPECT_EQ(p->files, (std::vector<std::string>{
                          "/jobs/x/a.nc", "/jobs/x/sub/b.ngc", "/abs/c.nc"}));
}

TEST(CamoticsProjectTest, ErrorsNameTheFileAndTheTool) {
  const std::string f = "p.camotics";
  EXPECT_TRUE(Names(ParseCamoticsProject("{\"tools\": ", f).status(),
                    {f, "not a CAMotics project"}));
  EXPECT_TRUE(Names(ParseCamoticsProject(R"({"tools": {"x": {}}})", f).status(),
                    {"p.camotics tool \"x\"", "tool number"}));
  EXPECT_TRUE(Names(
      ParseCamoticsProject(R"({"tools": {"1": {"diameter": "6"}}})", f).status(),
      {"p.camotics tool \"1\"", "\"diameter\" must be a number"}));
  EXPECT_TRUE(Names(
      ParseCamoticsProject(R"({"tools": {"1": {"units": "cubits"}}})", f).status(),
      {"p.camotics tool \"1\"", "\"units\""}));
  EXPECT_TRUE(Names(ParseCamoticsProject(
                        R"({"workpiece": {"automatic": false}})", f).status(),
                    {"p.camotics workpiece", "no bounds"}));
  EXPECT_TRUE(Names(
      ParseCamoticsProject(
          R"({"workpiece": {"bounds": {"min": [0, 0], "max": [1, 1, 1]}}})", f)
          .status(),
      {"bounds.min must be [x, y, z]"}));
  // Bad dimensions are the tool's error, reported when it is used.
  auto p = ParseCamoticsProject(
      R"({"tools": {"2": {"shape": "conical", "diameter": 2, "length": 0},
                    "3": {"shape": "snubnose", "diameter": 2, "length": 1,
                          "snub_diameter": 3},
                    "4": {"shape": "ballnose", "diameter": -1}}})",
      f);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_TRUE(Names(p->tools.tools.at(2).cutter.status(),
                    {"tool \"2\"", "\"length\" must be > 0"}));
  EXPECT_TRUE(Names(p->tools.tools.at(3).cutter.status(),
                    {"tool \"3\"", "\"snub_diameter\""}));
  EXPECT_TRUE(Names(p->tools.tools.at(4).cutter.status(),
                    {"tool \"4\"", "\"diameter\" must be > 0"}));
}

// ------------------------------------------------------------- choosing

ToolChoices Choices(std::vector<std::string> options,
                    std::optional<ToolTable> table = std::nullopt) {
  auto c = ParseToolChoices(options, std::move(table));
  EXPECT_TRUE(c.ok()) << c.status();
  return c.ok() ? *c : ToolChoices{};
}

TEST(ChooseToolsTest, WithoutATableTheUnnumberedToolServesEveryNumber) {
  const ToolChoices c = Choices({"ball:d=2", "T2=flat:d=6"});
  auto t = ChooseTools(c, {{0, "p.nc line 1"}, {1, "p.nc line 3"},
                           {2, "p.nc line 9"}});
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_EQ(t->at(0), Cutter::Ball(1));
  EXPECT_EQ(t->at(1), Cutter::Ball(1));
  EXPECT_EQ(t->at(2), Cutter::Flat(3));
  EXPECT_EQ(KnownTool(c, 2)->radius, 3);
  EXPECT_TRUE(Names(ChooseTools(Choices({"T1=ball:d=2"}), {{4, "p.nc line 7"}})
                        .status(),
                    {"p.nc line 7", "T4", "--tool 4="}));
}

TEST(ChooseToolsTest, TableNumbersProgramsWithoutTWordsAndOverrides) {
  auto table = ParseLinuxCncToolTable(kTable, "tools.tbl");
  ASSERT_TRUE(table.ok());
  // T words pick the table's tools; a numbered --tool overrides one.
  auto t = ChooseTools(Choices({"T2=ball:d=1"}, *table),
                       {{1, "p.nc line 2"}, {2, "p.nc line 8"}, {6, "p.nc line 9"}});
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_EQ(t->at(1), Cutter::Ball(3));
  EXPECT_EQ(t->at(2), Cutter::Ball(0.5));
  EXPECT_EQ(t->at(6), Cutter::TaperedBall(3, 0.5, 5));
  // A T number the table lacks names the line, the table and what it has.
  EXPECT_TRUE(Names(ChooseTools(Choices({"ball:d=2"}, *table),
                                {{1, "p.nc line 2"}, {42, "p.nc line 30"}})
                        .status(),
                    {"p.nc line 30", "T42 is not in the tool table tools.tbl",
                     "T1, T2"}));
  // A tool the table can't describe, used: its error, naming line and tool.
  EXPECT_TRUE(Names(ChooseTools(Choices({}, *table), {{8, "p.nc line 5"}}).status(),
                    {"p.nc line 5", "tools.tbl line 8", "no diameter"}));
  // No T word: the unnumbered --tool, else an error (the table has many).
  EXPECT_EQ(ChooseTools(Choices({"flat:d=2"}, *table), {{0, "p.nc line 1"}})->at(0),
            Cutter::Flat(1));
  EXPECT_TRUE(Names(ChooseTools(Choices({}, *table), {{0, "p.nc line 1"}}).status(),
                    {"p.nc line 1", "selects no tool", "tools.tbl"}));
}

TEST(ChooseToolsTest, AProgramWithoutTWordsUsesTheOnlyTool) {
  auto p = ParseCamoticsProject(
      R"({"tools": {"1": {"shape": "conical", "diameter": 2, "length": 2}}})",
      "v.camotics");
  ASSERT_TRUE(p.ok());
  auto t = ChooseTools(Choices({}, p->tools), {{0, "v.ngc line 4"}});
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_EQ(t->at(0), *p->tools.tools.at(1).cutter);
  EXPECT_EQ(KnownTool(Choices({}, p->tools), 0), *p->tools.tools.at(1).cutter);
  EXPECT_FALSE(KnownTool(Choices({}, p->tools), 3).has_value());
}

TEST(ChooseToolsTest, ToolOptionsGivenTwiceAreErrors) {
  EXPECT_TRUE(Names(ParseToolChoices({"ball:d=1", "flat:d=1"}, {}).status(),
                    {"--tool", "without a number"}));
  EXPECT_TRUE(Names(ParseToolChoices({"T1=ball:d=1", "1=flat:d=1"}, {}).status(),
                    {"--tool", "tool 1 is given twice"}));
  EXPECT_TRUE(Names(ParseToolChoices({"flat:d=x"}, {}).status(),
                    {"--tool \"flat:d=x\"", "d must be a number"}));
}

}  // namespace
}  // namespace swarf::cli

// ------------------------------------------------- tool assemblies (issue 30)

namespace swarf::cli {
namespace {

TEST(ToolAssemblyTest, ToolOptionKeys) {
  auto o = ParseToolOption("T2=flat:d=6,flute=15,shank=6,holder=40,stickout=30");
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->cutter, Cutter::Flat(3));
  EXPECT_EQ(o->assembly.flute_length, 15);
  EXPECT_EQ(o->assembly.shank_diameter, 6);
  EXPECT_EQ(o->assembly.holder_diameter, 40);
  EXPECT_EQ(o->assembly.stickout, 30);
  EXPECT_TRUE(o->assembly.center_cutting);
  EXPECT_EQ(AssemblySummary(o->assembly),
            "flute=15 shank=6 holder=40 stickout=30");
  auto plain = ParseToolOption("ball:d=3");
  ASSERT_TRUE(plain.ok());
  EXPECT_FALSE(plain->assembly.known());
  auto nc = ParseToolOption("flat:d=6,center=0");
  ASSERT_TRUE(nc.ok());
  EXPECT_FALSE(nc->assembly.center_cutting);
  EXPECT_TRUE(nc->assembly.known());
}

TEST(ToolAssemblyTest, ErrorsNameTheOptionAndTheKey) {
  auto bad = ParseToolOption("flat:d=6,flute=-1");
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.status().message(),
            "--tool \"flat:d=6,flute=-1\": flute must be a length in (0, 200000] "
            "mm, got \"-1\"");
  auto lone = ParseToolOption("flat:d=6,holder=40");
  EXPECT_TRUE(absl::StrContains(lone.status().message(),
                                "holder= and stickout= go together"))
      << lone.status();
  auto center = ParseToolOption("flat:d=6,center=2");
  EXPECT_TRUE(absl::StrContains(center.status().message(),
                                "center must be 0 or 1"))
      << center.status();
}

TEST(ToolAssemblyTest, LinuxCncCommentKeysAndCamoticsLength) {
  auto t = ParseLinuxCncToolTable(
      "T1 P1 D6 ;flat flute=15 holder=40 stickout=30\n"
      "T2 P2 D3 ;1/8 2 flute flute=12 center=0\n"
      "T3 P3 D2 ;ball\n",
      "tools.tbl");
  ASSERT_TRUE(t.ok()) << t.status();
  EXPECT_EQ(*t->tools.at(1).cutter, Cutter::Flat(3));
  EXPECT_EQ(t->tools.at(1).assembly.flute_length, 15);
  EXPECT_EQ(t->tools.at(1).assembly.holder_diameter, 40);
  EXPECT_EQ(t->tools.at(1).assembly.stickout, 30);
  EXPECT_EQ(*t->tools.at(2).cutter, Cutter::Flat(1.5));
  EXPECT_EQ(t->tools.at(2).assembly.flute_length, 12);
  EXPECT_FALSE(t->tools.at(2).assembly.center_cutting);
  EXPECT_FALSE(t->tools.at(3).assembly.known());

  auto p = ParseCamoticsProject(
      R"({"tools": {"1": {"shape": "cylindrical", "diameter": 6, "length": 20},
                    "2": {"shape": "ballnose", "diameter": 2}}})",
      "job.camotics");
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_EQ(p->tools.tools.at(1).assembly.flute_length, 20);
  EXPECT_EQ(p->tools.tools.at(2).assembly.flute_length, 0);  // not given

  ToolChoices choices;
  choices.table = *t;
  EXPECT_EQ(KnownAssembly(choices, 1).stickout, 30);
  EXPECT_FALSE(KnownAssembly(choices, 7).known());
  choices.options.push_back(*ParseToolOption("1=flat:d=6,flute=9"));
  EXPECT_EQ(KnownAssembly(choices, 1).flute_length, 9);
}

}  // namespace
}  // namespace swarf::cli
