// `swarf run`'s safety checks and process facts end to end (issue 30):
// programs with hand-computed crashes, named by file and line, and real
// programs that must raise none.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "client/cli/commands.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"

namespace swarf::cli {
namespace {

using Json = nlohmann::json;
constexpr double kPi = std::numbers::pi;

class SafetyRunTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("swarf-safety-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  std::string Write(const std::string& name, const std::string& text) {
    const std::string p = (dir_ / name).string();
    std::ofstream(p) << text;
    return p;
  }
  // Runs swarf run with `argv`, --json; the stats document
  // and stderr.
  // Without `json`, stats is not filled (the warnings go to stderr only
  // then).
  int Run(std::vector<std::string> argv, Json* stats, std::string* err,
          bool json = true) {
    if (json) argv.push_back("--json");
    std::stringstream out, cerr;
    std::streambuf* old_out = std::cout.rdbuf(out.rdbuf());
    std::streambuf* old_err = std::cerr.rdbuf(cerr.rdbuf());
    const int rc = RunCommand(argv);
    std::cout.rdbuf(old_out);
    std::cerr.rdbuf(old_err);
    *err = cerr.str();
    *stats = Json::parse(out.str(), nullptr, false);
    return rc;
  }
  std::filesystem::path dir_;
};

// Line numbers matter: each move is on its own line.
constexpr const char* kCrash =
    "G21 G90\n"                // 1
    "G0 X10 Y20.05 Z5\n"       // 2
    "G0 Z-2\n"                 // 3: a rapid into the top, 2 mm deep
    "G0 X40\n"                 // 4: a rapid through the block
    "G0 Z5\n"                  // 5
    "G1 X60.05 Y50.05 F500\n"  // 6: air
    "G1 Z-12\n"                // 7: plunge 12 deep, 2 below the flutes
    "G1 X80.05\n"              // 8: slot 2 mm deeper than the flutes
    "G0 Z5\n"                  // 9
    "G0 X20.05 Y80.05\n"       // 10
    "G1 Z-35\n"                // 11: the holder's face 5 mm into the top
    "G0 Z5\n"                  // 12
    "M2\n";

TEST_F(SafetyRunTest, CrashesNamedByLineWithDepthAndVolume) {
  const std::string nc = Write("crash.nc", kCrash);
  Json s;
  std::string err;
  const std::vector<std::string> args = {
      nc, "--tool", "flat:d=6,flute=10,holder=40,stickout=30,center=0",
      "--stock", "0,0,100,100,0", "--floor", "-30", "--check"};
  ASSERT_EQ(Run(args, &s, &err), 3) << err;
  const Json& sf = s["safety"];
  ASSERT_EQ(sf["rapid_cuts"].size(), 2u) << sf.dump();
  EXPECT_EQ(sf["rapid_cuts"][0]["line"], 3);
  EXPECT_EQ(sf["rapid_cuts"][0]["file"], nc);
  EXPECT_EQ(sf["rapid_cuts"][1]["line"], 4);
  EXPECT_DOUBLE_EQ(sf["rapid_cuts"][1]["depth"].get<double>(), 2);
  // Line 3 took the disc at x 10 (2 * pi 9 mm^3); line 4 the rest of the
  // 30 mm slot: 2 * 30 * 6 = 360 mm^3.
  EXPECT_NEAR(sf["rapid_cuts"][1]["volume_mm3"].get<double>(), 360, 1.8);
  EXPECT_NEAR(sf["rapid_cuts"][0]["volume_mm3"].get<double>(), 18 * kPi,
              0.01 * 18 * kPi);

  // The shank: 2 mm at lines 7 and 8, 25 mm at line 11.
  const Json& sh = sf["shank_contacts"];
  ASSERT_EQ(sh.size(), 3u) << sh.dump();
  EXPECT_EQ(sh[0]["line"], 7);
  EXPECT_EQ(sh[1]["line"], 8);
  EXPECT_EQ(sh[2]["line"], 11);
  EXPECT_DOUBLE_EQ(sh[1]["depth"].get<double>(), 2);
  EXPECT_DOUBLE_EQ(sh[2]["depth"].get<double>(), 25);
  // Line 8's slot: 20 mm long beyond the plunge's disc, 6 wide, 2 of its
  // 12 mm above the flutes.
  EXPECT_NEAR(sh[1]["volume_mm3"].get<double>(), 2 * 20 * 6, 0.01 * 240);

  // The holder (radius 20, face 30 above the tip): first at line 11, 5 mm.
  const Json& ho = sf["holder_contacts"];
  ASSERT_GE(ho.size(), 1u);
  EXPECT_EQ(ho[0]["line"], 11);
  EXPECT_DOUBLE_EQ(ho[0]["depth"].get<double>(), 5);
  EXPECT_NEAR(ho[0]["volume_mm3"].get<double>(), 5 * kPi * (400 - 9),
              0.005 * 5 * kPi * 400);

  // Plunges of a tool not cutting at its centre: lines 3, 7 and 11.
  const Json& pl = sf["center_plunges"];
  ASSERT_EQ(pl.size(), 3u);
  EXPECT_EQ(pl[0]["line"], 3);
  EXPECT_EQ(pl[1]["line"], 7);
  EXPECT_EQ(pl[2]["line"], 11);
  EXPECT_DOUBLE_EQ(pl[1]["depth"].get<double>(), 12);

  // Below --floor -30: line 11 by 5 mm.
  ASSERT_GE(sf["below_floor"].size(), 1u);
  EXPECT_EQ(sf["below_floor"][0]["line"], 11);
  EXPECT_DOUBLE_EQ(sf["below_floor"][0]["depth"].get<double>(), 5);
  EXPECT_EQ(sf["outside_limits"].size(), 0u);
  EXPECT_FALSE(sf["ok"].get<bool>());

  // Without --check: the same report, exit 0; on the terminal, warnings.
  std::vector<std::string> no_check(args.begin(), args.end() - 1);
  ASSERT_EQ(Run(no_check, &s, &err), 0) << err;
  EXPECT_EQ(s["safety"]["counts"]["rapid_cuts"], 2);
  no_check.push_back("--quiet");
  Json unused;
  ASSERT_EQ(Run(no_check, &unused, &err, /*json=*/false), 0) << err;
  EXPECT_NE(err.find("warning: rapid moves cut material (rapid_cuts): 2; the "
                     "first: " + nc + " line 3, 2 mm deep"),
            std::string::npos)
      << err;
}

TEST_F(SafetyRunTest, AirTimeAndLimitsOfAProgramThatCutsNothing) {
  // Every move above the stock top: all feed moves cut air.
  const std::string nc = Write("air.nc",
                               "G21 G90\n"
                               "G0 X0 Y0 Z5\n"
                               "G1 X30 F600\n"
                               "G1 Y40\n"
                               "G0 X0 Y0\n"
                               "G1 Z120\n"
                               "M2\n");
  Json s;
  std::string err;
  ASSERT_EQ(Run({nc, "--tool", "ball:d=2", "--stock", "-5,-5,35,45,0",
                 "--rapid-rate", "6000", "--limits", "-10,-10,-50,100,100,100",
                 "--check"},
                &s, &err),
            3)
      << err;
  const Json& p = s["process"];
  EXPECT_EQ(p["removed_mm3"].get<double>(), 0);
  EXPECT_EQ(p["cutting_moves"], 0);
  EXPECT_EQ(p["air_moves"], 3);
  EXPECT_DOUBLE_EQ(p["air_mm"].get<double>(), 30 + 40 + 115);
  EXPECT_DOUBLE_EQ(p["rapid_mm"].get<double>(), 50);  // the 30-40-50 diagonal
  EXPECT_DOUBLE_EQ(p["rapid_s"].get<double>(), 50.0 / 6000 * 60);
  // At F600: 30, 40 and 115 mm in 3, 4 and 11.5 s; the rapid 50 mm at
  // 6000 mm/min in 0.5 s.
  EXPECT_DOUBLE_EQ(p["air_s"].get<double>(), 18.5);
  EXPECT_DOUBLE_EQ(p["cutting_s"].get<double>(), 0);
  EXPECT_DOUBLE_EQ(p["cycle_time_s"].get<double>(), 19);
  EXPECT_DOUBLE_EQ(p["air_lines"][0]["time_s"].get<double>(), 11.5);
  EXPECT_EQ(p["air_lines"][0]["line"], 6);
  EXPECT_DOUBLE_EQ(p["air_lines"][0]["mm"].get<double>(), 115);
  // Only line 6 leaves the limits, by 20 mm.
  const Json& out = s["safety"]["outside_limits"];
  ASSERT_EQ(out.size(), 1u) << out.dump();
  EXPECT_EQ(out[0]["line"], 6);
  EXPECT_DOUBLE_EQ(out[0]["depth"].get<double>(), 20);
  Json unused;
  ASSERT_EQ(Run({nc, "--tool", "ball:d=2", "--stock", "-5,-5,35,45,0", "--quiet"},
                &unused, &err, /*json=*/false),
            0);
  EXPECT_NE(err.find("note: T0 has no flute length or holder: no shank or "
                     "holder check"),
            std::string::npos)
      << err;
}

TEST_F(SafetyRunTest, AFeedOfF0IsARapidAndTimesFollowTheFeeds) {
  const std::string nc = Write("f0.nc",
                               "G21 G90\n"              // 1
                               "G0 X10.05 Y20.05 Z5\n"  // 2
                               "G1 Z-1 F0\n"            // 3: F0 into the top
                               "G1 X40.05 F300\n"       // 4: a 30 mm slot
                               "G1 Z5 F0\n"             // 5
                               "M2\n");
  Json s;
  std::string err;
  const std::string out = (dir_ / "out").string();
  ASSERT_EQ(Run({nc, "--tool", "flat:d=6", "--stock", "0,0,60,40,0", "--out",
                 out, "--check"},
                &s, &err),
            3)
      << err;
  const Json& rc = s["safety"]["rapid_cuts"];
  ASSERT_EQ(rc.size(), 1u) << rc.dump();
  EXPECT_EQ(rc[0]["line"], 3);
  EXPECT_DOUBLE_EQ(rc[0]["depth"].get<double>(), 1);
  const Json& p = s["process"];
  EXPECT_EQ(p["f0_moves"], 2);
  // The slot: 30 mm at 300 mm/min, 6 s; it removed 1 * 30 * 6 mm^3 beyond
  // the plunge's disc.
  EXPECT_DOUBLE_EQ(p["cutting_s"].get<double>(), 6);
  EXPECT_NEAR(p["lines"][0]["volume_mm3"].get<double>(), 180, 0.9);
  EXPECT_EQ(p["lines"][0]["line"], 4);
  // The F0 moves (6 mm each) at the default 5000 mm/min.
  EXPECT_DOUBLE_EQ(p["rapid_s"].get<double>(), 12.0 / 5000 * 60);
  EXPECT_TRUE(std::filesystem::exists(out + "/load.png"));
}

TEST_F(SafetyRunTest, RealProgramsRaiseNothingAndVolumesAddUp) {
  Json s;
  std::string err;
  const std::string ex = SWARF_EXAMPLES_DIR;
  ASSERT_EQ(Run({ex + "/relief.nc", "--tool", "ball:d=2,flute=8,holder=20,stickout=25",
                 "--check"},
                &s, &err),
            0)
      << err << s["safety"].dump();
  double by_tool = 0;
  for (const auto& [n, t] : s["process"]["by_tool"].items()) {
    by_tool += t["volume_mm3"].get<double>();
  }
  EXPECT_NEAR(by_tool, s["process"]["removed_mm3"].get<double>(), 1e-6);
  EXPECT_GT(s["process"]["cutting_moves"].get<int64_t>(), 29000);
  ASSERT_EQ(Run({ex + "/pocket.nc", "--tool", "T1=flat:d=6,flute=12,holder=30,stickout=25",
                 "--tool", "T2=flat:d=3,flute=8", "--tool", "T3=flat:d=1,flute=3",
                 "--stock", "0,0,100,80,0", "--check"},
                &s, &err),
            0)
      << err << s["safety"].dump();
  EXPECT_EQ(s["process"]["by_tool"].size(), 3u);
}

}  // namespace
}  // namespace swarf::cli
