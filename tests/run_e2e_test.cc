// swarf run end to end, in process, on the real corpus programs: they run
// unmodified, the machined heights stay within the stock, and the pictures
// and the mesh read back valid (the STL watertight).
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include <unistd.h>

#include "client/commands.h"
#include "client/png_image.h"
#include "gcode/toolpath.h"
#include "google/protobuf/struct.pb.h"
#include "google/protobuf/util/json_util.h"
#include "gtest/gtest.h"

namespace swarf::cli {
namespace {

using gcode::ReadToolpathFile;

struct Stl {
  std::vector<std::array<float, 9>> triangles;  // 3 vertices each
};

Stl ReadStl(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                          std::istreambuf_iterator<char>());
  Stl stl;
  if (bytes.size() < 84) return stl;
  uint32_t n;
  std::memcpy(&n, bytes.data() + 80, 4);
  EXPECT_EQ(bytes.size(), 84 + 50 * size_t{n}) << "size vs triangle count";
  for (uint32_t t = 0; t < n && 84 + 50 * (t + 1) <= bytes.size(); ++t) {
    std::array<float, 9> v;
    std::memcpy(v.data(), bytes.data() + 84 + 50 * t + 12, 36);
    stl.triangles.push_back(v);
  }
  return stl;
}

google::protobuf::Struct ReadJson(const std::string& path) {
  std::ifstream in(path);
  std::string text((std::istreambuf_iterator<char>(in)),
                   std::istreambuf_iterator<char>());
  google::protobuf::Struct s;
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(text, &s).ok())
      << text.substr(0, 200);
  return s;
}

class RunE2eTest : public ::testing::TestWithParam<std::tuple<const char*, const char*>> {};

TEST_P(RunE2eTest, CorpusJobRunsAndItsOutputsAreValid) {
  const auto [name, tool] = GetParam();
  const std::string file = std::string(SWARF_CORPUS_DIR) + "/" + name;
  const std::string out =
      (std::filesystem::temp_directory_path() /
       ("swarf-e2e-" + std::string(name) + "-" + std::to_string(::getpid())))
          .string();
  std::filesystem::remove_all(out);
  // 0.25 mm keeps the test quick; the code path is the one of 0.1 mm.
  ASSERT_EQ(RunCommand({file, "--tool", tool, "--spacing", "0.25", "--out",
                        out, "--quiet"}),
            0);

  // The stats document: every move simulated, finite errors, marks found.
  const auto path = ReadToolpathFile(file);
  ASSERT_TRUE(path.ok()) << path.status();
  const google::protobuf::Struct stats = ReadJson(out + "/stats.json");
  const auto& f = stats.fields();
  EXPECT_EQ(f.at("moves").number_value(), path->move_count());
  const auto& err = f.at("error").struct_value().fields();
  EXPECT_TRUE(std::isfinite(err.at("max").number_value()));
  EXPECT_GT(err.at("samples").number_value(), 0);
  EXPECT_GT(f.at("marks").struct_value().fields().at("polylines").number_value(),
            0);
  // The marks shown are a part of those found; the adaptive mesh is within
  // its tolerance with fewer triangles than the lattice; every step timed.
  const auto& marks = f.at("marks").struct_value().fields();
  const auto& shown = marks.at("shown").struct_value().fields();
  EXPECT_LE(shown.at("vertices").number_value(),
            marks.at("vertices").number_value());
  EXPECT_GT(shown.at("polylines").number_value(), 0);
  const auto& mesh = f.at("mesh").struct_value().fields();
  EXPECT_EQ(mesh.at("tolerance").number_value(), 0.005);
  EXPECT_LE(mesh.at("max_deviation").number_value(), 0.005);
  EXPECT_LT(mesh.at("triangles").number_value(),
            mesh.at("full_triangles").number_value());
  const auto& steps = f.at("seconds").struct_value().fields().at(
      "output_steps").struct_value().fields();
  for (const char* step : {"error_stats", "marks", "tiles", "relief.png",
                           "surface.stl", "surface.wrl"}) {
    EXPECT_GE(steps.at(step).number_value(), 0) << step;
  }
  const auto& st = f.at("stock").struct_value().fields();
  const double x0 = st.at("x0").number_value(), x1 = st.at("x1").number_value();
  const double y0 = st.at("y0").number_value(), y1 = st.at("y1").number_value();
  const double top = st.at("top").number_value();

  // Pictures decode at sensible sizes.
  for (const char* png : {"relief.png", "error.png", "marks.png"}) {
    auto img = ReadPng(out + "/" + png);
    ASSERT_TRUE(img.ok()) << png << ": " << img.status();
    EXPECT_GE(img->width(), 300) << png;
    EXPECT_GE(img->height(), 300) << png;
  }

  // The mesh: bounds are the stock; the machined top lies between the
  // lowest tool tip and the stock top (heights only go down, never below
  // where a tip went); every edge is shared by exactly two triangles.
  const Stl stl = ReadStl(out + "/surface.stl");
  ASSERT_GT(stl.triangles.size(), 1000u);
  const double lowest_tip = path->z_bounds().lo;
  float min_x = 1e30f, max_x = -1e30f, min_y = 1e30f, max_y = -1e30f;
  float min_z = 1e30f, max_z = -1e30f;
  std::map<std::array<float, 6>, int> edges;
  for (const auto& t : stl.triangles) {
    for (int v = 0; v < 3; ++v) {
      min_x = std::min(min_x, t[3 * v]);
      max_x = std::max(max_x, t[3 * v]);
      min_y = std::min(min_y, t[3 * v + 1]);
      max_y = std::max(max_y, t[3 * v + 1]);
      min_z = std::min(min_z, t[3 * v + 2]);
      max_z = std::max(max_z, t[3 * v + 2]);
      std::array<float, 3> a{t[3 * v], t[3 * v + 1], t[3 * v + 2]};
      const int w = (v + 1) % 3;
      std::array<float, 3> b{t[3 * w], t[3 * w + 1], t[3 * w + 2]};
      if (b < a) std::swap(a, b);
      ++edges[{a[0], a[1], a[2], b[0], b[1], b[2]}];
    }
  }
  const float eps = 1e-3f;  // float STL coordinates
  EXPECT_NEAR(min_x, x0, eps);
  EXPECT_NEAR(max_x, x1, eps);
  EXPECT_NEAR(min_y, y0, eps);
  EXPECT_NEAR(max_y, y1, eps);
  EXPECT_LE(max_z, top + eps);
  int open = 0;
  for (const auto& [e, n] : edges) open += n != 2;
  EXPECT_EQ(open, 0) << "edges not shared by exactly two triangles";
  // Top vertices (all but the bottom plane's) are at or above the lowest
  // tip: the bottom is the one plane below it.
  int below = 0;
  for (const auto& t : stl.triangles) {
    for (int v = 0; v < 3; ++v) {
      const float z = t[3 * v + 2];
      if (z < lowest_tip - eps && z > min_z + eps) ++below;
    }
  }
  EXPECT_EQ(below, 0) << "machined below the lowest tool tip";
  EXPECT_LT(min_z, lowest_tip);  // the bottom plane
  std::filesystem::remove_all(out);
}

// Never silent: moves the interpreter drops and a cut leaving the stock are
// reported in stats.json; --strict turns dropped moves into an error; an
// error names the file once.
TEST(RunE2eNeverSilentTest, DroppedMovesCutsOutsideAndErrors) {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() /
      ("swarf-e2e-silent-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string prog = (dir / "m6.txt").string();  // G-code by content
  {
    std::ofstream f(prog);
    f << "G21\nT1 M6\nG0 X0 Y0 Z5\nG1 Z-1\nX5\nT2 M6\nG1 X20\nG0 Z5\n"
         "G1 X3 Y3 Z-1\nX4\n";
  }
  const std::string out = (dir / "out").string();
  ASSERT_EQ(RunCommand({prog, "--tool", "ball:d=1", "--stock", "0,0,4,4,0",
                        "--spacing", "0.25", "--out", out, "--quiet"}),
            0);
  const google::protobuf::Struct stats = ReadJson(out + "/stats.json");
  const auto& f = stats.fields();
  EXPECT_EQ(f.at("dropped_moves").number_value(), 2);
  EXPECT_EQ(f.at("dropped").string_value(),
            "dropped 2 feed moves with an unknown start or end (not "
            "simulated): line 7 (YZ unknown), line 9 (Y unknown)");
  const auto& outside = f.at("outside_stock").struct_value().fields();
  EXPECT_EQ(outside.at("mm").number_value(), 1);  // X5 on a stock to X4
  EXPECT_EQ(outside.at("line").number_value(), 5);

  std::stringstream err;
  std::streambuf* old = std::cerr.rdbuf(err.rdbuf());
  const int strict = RunCommand({prog, "--tool", "ball:d=1", "--strict",
                                 "--quiet"});
  const std::string bad = (dir / "bad.nc").string();
  {
    std::ofstream b(bad);
    b << "G21 G0 X0 Y0 Z0\nG1 X1 Y[1/0]\n";
  }
  const int broken = RunCommand({bad, "--tool", "ball:d=1", "--quiet"});
  std::cerr.rdbuf(old);
  EXPECT_EQ(strict, 1);
  EXPECT_EQ(broken, 1);
  EXPECT_NE(err.str().find("swarf run: " + prog + ": dropped 2 feed moves"),
            std::string::npos)
      << err.str();
  EXPECT_NE(err.str().find("swarf run: " + bad + ": line 2: division by zero\n"),
            std::string::npos)
      << err.str();
  EXPECT_EQ(err.str().find(bad + ": " + bad), std::string::npos) << err.str();
  std::filesystem::remove_all(dir);
}

INSTANTIATE_TEST_SUITE_P(
    Corpus, RunE2eTest,
    ::testing::Values(std::tuple{"bear.nc", "ball:d=3.175"},
                      std::tuple{"cameo.nc", "ball:d=2"}),
    [](const auto& info) {
      std::string n = std::get<0>(info.param);
      return n.substr(0, n.find('.'));
    });

}  // namespace
}  // namespace swarf::cli
