// swarf run end to end, in process, on the repository's generated jobs
// (examples/, scripts/make-example: every checkout has them) and on the
// real corpus programs (../shared/corpus, read in place; skipped where
// absent, failed instead with SWARF_REQUIRE_SHARED: tests/shared_files.h):
// they run unmodified, the machined heights stay within the stock, and the
// pictures and the mesh read back valid (the STL watertight).
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

#include "client/cli/commands.h"
#include "client/cli/run_report.h"
#include "client/outputs/png_image.h"
#include "gcode/toolpath.h"
#include "google/protobuf/struct.pb.h"
#include "google/protobuf/util/json_util.h"
#include "google/protobuf/util/message_differencer.h"
#include "gtest/gtest.h"
#include "server/server.h"
#include "tests/shared_files.h"

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

// A job: its program, where it lies, and its tools and stock as options.
struct Job {
  const char* name;
  bool corpus;                    // in ../shared/corpus, else in examples/
  std::vector<std::string> args;  // --tool ..., --stock ...
  bool marks = true;              // has cutting marks (a flat-end pocket
                                  // has none: floors and vertical walls)
  const char* spacing = "0.25";   // quick; the code path is 0.1 mm's (the
                                  // pictures are a pixel per node, >= 300)
  std::string File() const {
    return std::string(corpus ? SWARF_CORPUS_DIR : SWARF_EXAMPLES_DIR) + "/" +
           name;
  }
};

void PrintTo(const Job& job, std::ostream* os) { *os << job.File(); }

const Job kPocket{"pocket.nc",
                  false,
                  {"--tool", "T1=flat:d=6", "--tool", "T2=flat:d=3", "--tool",
                   "T3=flat:d=1", "--stock", "0,0,100,80,0"},
                  false};
const Job kVcarve{"vcarve.nc",
                  false,
                  {"--tool", "vbit:d=6,angle=60", "--stock", "0,0,80,80,0"}};
const Job kRelief{"relief.nc",
                  false,
                  {"--tool", "ball:d=2", "--stock", "0,0,60,60,0"},
                  true,
                  "0.2"};

std::string JobTestName(const ::testing::TestParamInfo<Job>& info) {
  std::string n = info.param.name;
  return n.substr(0, n.find('.'));
}

class RunE2eTest : public ::testing::TestWithParam<Job> {};

TEST_P(RunE2eTest, JobRunsAndItsOutputsAreValid) {
  const Job& job = GetParam();
  const std::string name = job.name;
  const std::string file = job.File();
  if (job.corpus) SWARF_SKIP_UNLESS_SHARED_FILE(file);
  const std::string out =
      (std::filesystem::temp_directory_path() /
       ("swarf-e2e-" + std::string(name) + "-" + std::to_string(::getpid())))
          .string();
  std::filesystem::remove_all(out);
  std::vector<std::string> argv = {file,    "--spacing", job.spacing,
                                   "--out", out,         "--quiet"};
  argv.insert(argv.end(), job.args.begin(), job.args.end());
  ASSERT_EQ(RunCommand(argv), 0);

  // The stats document: every move simulated, finite errors, marks found.
  const auto path = ReadToolpathFile(file);
  ASSERT_TRUE(path.ok()) << path.status();
  const google::protobuf::Struct stats = ReadJson(out + "/stats.json");
  const auto& f = stats.fields();
  EXPECT_EQ(f.at("moves").number_value(), path->move_count());
  const auto& err = f.at("error").struct_value().fields();
  EXPECT_TRUE(std::isfinite(err.at("max").number_value()));
  EXPECT_GT(err.at("samples").number_value(), 0);
  EXPECT_EQ(f.at("dropped_moves").number_value(), 0);
  EXPECT_EQ(f.count("outside_stock"), 0u);
  // The marks shown are a part of those found; the adaptive mesh is within
  // its tolerance with fewer triangles than the lattice; every step timed.
  const auto& marks = f.at("marks").struct_value().fields();
  const auto& shown = marks.at("shown").struct_value().fields();
  EXPECT_LE(shown.at("vertices").number_value(),
            marks.at("vertices").number_value());
  if (job.marks) {
    EXPECT_GT(marks.at("polylines").number_value(), 0);
    EXPECT_GT(shown.at("polylines").number_value(), 0);
  }
  const auto& mesh = f.at("mesh").struct_value().fields();
  EXPECT_EQ(mesh.at("tolerance").number_value(), 0.005);
  EXPECT_LE(mesh.at("max_deviation").number_value(), 0.005);
  EXPECT_LT(mesh.at("triangles").number_value(),
            mesh.at("full_triangles").number_value());
  const auto& steps = f.at("seconds")
                          .struct_value()
                          .fields()
                          .at("output_steps")
                          .struct_value()
                          .fields();
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

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// swarf run asks a server for the marks as one message, and one per
// polyline when they pass the server's message limit; the embedded run
// finds them on its session's workpiece: the same marks every way. A server
// with 1 MiB messages (the marks of bear.nc and vcarve.nc at 0.25 mm are
// over 1 MiB), one with the default 64 MiB (one message) and the embedded
// one. The other files are the same too, though the embedded run's outputs
// read the session's own moves and index (pinned) and the remote runs'
// their program's points, indexed again.
class RunE2eMarksTest : public ::testing::TestWithParam<Job> {};

// swarf run asks for the marks streamed at once past 16 Mi nodes (4 bytes
// a node against the 64 MiB message): cameo.nc at 0.05 mm (11.7 M nodes,
// whose 1.5 M vertices fit one message) asks for one message first, the
// 300 mm plate at 0.05 mm (36 M nodes, over the limit after 29 of its 47
// windows) streamed.
TEST(RunMarksRequestTest, LargeGridsAskForTheMarksStreamed) {
  auto stock = [](int32_t nx, int32_t ny) {
    return StockSpec{0, 0, 1, 1, 0, nx, ny};
  };
  EXPECT_TRUE(cli::MarksFitOneMessage(stock(3064, 3804)));
  EXPECT_FALSE(cli::MarksFitOneMessage(stock(6000, 6000)));
  EXPECT_FALSE(cli::MarksFitOneMessage(stock(20000, 20000)));
  EXPECT_TRUE(cli::MarksFitOneMessage(stock(4095, 4095)));   // 16 Mi nodes
  EXPECT_FALSE(cli::MarksFitOneMessage(stock(4095, 4096)));  // a row more
}

TEST_P(RunE2eMarksTest, OneMessageOnePerPolylineAndEmbeddedGiveTheSameMarks) {
  const Job& job = GetParam();
  const std::string file = job.File();
  if (job.corpus) SWARF_SKIP_UNLESS_SHARED_FILE(file);
  server::ServerOptions o;
  o.listen = "127.0.0.1:0";
  o.limits.max_message_bytes = 1 << 20;
  o.limits.max_batch_points = 20000;
  auto srv = server::SwarfServer::Start(o);
  ASSERT_TRUE(srv.ok()) << srv.status();
  server::ServerOptions o_one;
  o_one.listen = "127.0.0.1:0";
  auto srv_one = server::SwarfServer::Start(o_one);
  ASSERT_TRUE(srv_one.ok()) << srv_one.status();
  ASSERT_EQ(o_one.limits.max_message_bytes, 64 << 20);
  const std::filesystem::path base =
      std::filesystem::temp_directory_path() /
      ("swarf-e2e-marks-" + std::to_string(::getpid()));
  const std::string remote = (base / "remote").string();
  const std::string one = (base / "one").string();
  const std::string embedded = (base / "embedded").string();
  std::filesystem::remove_all(base);
  std::vector<std::string> args = {file, "--spacing", "0.25", "--quiet"};
  args.insert(args.end(), job.args.begin(), job.args.end());
  std::vector<std::string> a = args;
  a.insert(a.end(), {"--out", remote, "--server",
                     "127.0.0.1:" + std::to_string((*srv)->port())});
  ASSERT_EQ(RunCommand(a), 0);
  a = args;
  a.insert(a.end(), {"--out", one, "--server",
                     "127.0.0.1:" + std::to_string((*srv_one)->port())});
  ASSERT_EQ(RunCommand(a), 0);
  a = args;
  a.insert(a.end(), {"--out", embedded});
  ASSERT_EQ(RunCommand(a), 0);
  // Each server took its way: one per polyline (GetCuttingMarks queues
  // them), one message (nothing queued).
  EXPECT_GT((*srv)->marks_counters().peak_queued_bytes.load(), 0);
  EXPECT_EQ((*srv_one)->marks_counters().peak_queued_bytes.load(), 0);
  const google::protobuf::Struct remote_stats =
      ReadJson(remote + "/stats.json");
  const google::protobuf::Struct embedded_stats =
      ReadJson(embedded + "/stats.json");
  const auto& m = remote_stats.fields().at("marks").struct_value().fields();
  const auto& e = embedded_stats.fields().at("marks").struct_value().fields();
  EXPECT_GT(m.at("vertices").number_value() * 32, 1 << 20);  // x, y, z, angle
  for (const char* k : {"polylines", "vertices", "total_length"}) {
    EXPECT_EQ(m.at(k).number_value(), e.at(k).number_value()) << k;
  }
  for (const char* f :
       {"marks.json", "marks.svg", "marks.png", "relief.png", "error.png",
        "surface.stl", "surface.wrl", "load.png"}) {
    const std::string r = ReadFile(remote + "/" + f);
    EXPECT_FALSE(r.empty()) << f;
    EXPECT_TRUE(r == ReadFile(one + "/" + f)) << f;
    EXPECT_TRUE(r == ReadFile(embedded + "/" + f)) << f;
  }
  std::filesystem::remove_all(base);
}

INSTANTIATE_TEST_SUITE_P(
    Jobs, RunE2eMarksTest,
    ::testing::Values(Job{"bear.nc", true, {"--tool", "ball:d=3.175"}},
                      kVcarve),
    JobTestName);

// The machined surface of the generated jobs where their programs say what
// it must be, read off the STL (within its 0.005 mm tolerance): the pocket
// floors at their programmed depths, the engraving's grooves, the stock
// left alone elsewhere; the V-carve's grooves as deep and as wide as the
// 60-degree V-bit cuts at the programmed depth.
class Surface {
 public:
  explicit Surface(const Stl& stl) : stl_(stl) {}
  // The highest triangle over (x, y): the machined top (the STL also has
  // the bottom plane and the vertical sides).
  double At(double x, double y) const {
    double best = -1e30;
    for (const auto& t : stl_.triangles) {
      const double ax = t[0], ay = t[1], bx = t[3], by = t[4], cx = t[6],
                   cy = t[7];
      const double d = (by - cy) * (ax - cx) + (cx - bx) * (ay - cy);
      if (std::abs(d) < 1e-12) continue;  // vertical
      const double l1 = ((by - cy) * (x - cx) + (cx - bx) * (y - cy)) / d;
      const double l2 = ((cy - ay) * (x - cx) + (ax - cx) * (y - cy)) / d;
      const double l3 = 1 - l1 - l2;
      const double e = -1e-9;
      if (l1 < e || l2 < e || l3 < e) continue;
      best = std::max(best, l1 * t[2] + l2 * t[5] + l3 * t[8]);
    }
    return best;
  }

 private:
  const Stl& stl_;
};

Stl RunToStl(const Job& job, const std::string& tag) {
  const std::string out =
      (std::filesystem::temp_directory_path() /
       ("swarf-e2e-" + tag + "-" + std::to_string(::getpid())))
          .string();
  std::filesystem::remove_all(out);
  std::vector<std::string> argv = {job.File(), "--spacing", "0.25",
                                   "--out",    out,         "--quiet"};
  argv.insert(argv.end(), job.args.begin(), job.args.end());
  EXPECT_EQ(RunCommand(argv), 0);
  Stl stl = ReadStl(out + "/surface.stl");
  std::filesystem::remove_all(out);
  return stl;
}

TEST(GeneratedJobsTest, PocketFloorsAtTheirProgrammedDepths) {
  const Stl stl = RunToStl(kPocket, "pocket-floors");
  ASSERT_GT(stl.triangles.size(), 1000u);
  const Surface s(stl);
  const double tol = 0.006;  // the mesh's 0.005 mm, and float coordinates
  // T1's round pocket (r 22 at (30, 40)): z = -6 to its wall.
  for (auto [x, y] : {std::pair{30.0, 40.0},
                      {45.0, 40.0},
                      {30.0, 22.0},
                      {51.0, 40.0},
                      {20.0, 55.0}}) {
    EXPECT_NEAR(s.At(x, y), -6, tol) << x << ", " << y;
  }
  // T2's rounded rectangle (x 60..92, y 10..70, corners r 4): z = -4, in a
  // corner too; just outside the corner's arc the top.
  for (auto [x, y] : {std::pair{76.0, 40.0},
                      {61.0, 40.0},
                      {90.5, 68.5},
                      {61.5, 11.5},
                      {90.0, 12.0}}) {
    EXPECT_NEAR(s.At(x, y), -4, tol) << x << ", " << y;
  }
  EXPECT_NEAR(s.At(60.5, 10.5), 0, tol);
  // T3's 1 mm grooves at z = -0.5: the ring (r 25 round the pocket) and
  // the wave (y = 75 at x = 50).
  EXPECT_NEAR(s.At(55, 40), -0.5, tol);
  EXPECT_NEAR(s.At(30, 15), -0.5, tol);
  EXPECT_NEAR(s.At(50, 75), -0.5, tol);
  // Untouched stock.
  for (auto [x, y] :
       {std::pair{2.0, 2.0}, {95.0, 5.0}, {57.5, 40.0}, {30.0, 10.0}}) {
    EXPECT_NEAR(s.At(x, y), 0, tol) << x << ", " << y;
  }
}

google::protobuf::Struct RunJson(const std::vector<std::string>& argv);

// examples/pocket.camotics (its three tools, its workpiece) runs the
// program as the flags do: the same moves, tools and stock.
TEST(GeneratedJobsTest, PocketProjectIsTheJobWithItsTools) {
  std::vector<std::string> flags = {kPocket.File(), "--spacing", "0.5",
                                    "--json", "--quiet"};
  flags.insert(flags.end(), kPocket.args.begin(), kPocket.args.end());
  const google::protobuf::Struct a = RunJson(flags);
  const google::protobuf::Struct b = RunJson(
      {"--project", std::string(SWARF_EXAMPLES_DIR) + "/pocket.camotics",
       "--spacing", "0.5", "--json", "--quiet"});
  for (const char* k : {"moves", "tools", "stock", "error"}) {
    EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(
        a.fields().at(k), b.fields().at(k)))
        << k << ": " << a.fields().at(k).DebugString() << " vs "
        << b.fields().at(k).DebugString();
  }
}

TEST(GeneratedJobsTest, VcarveGroovesAsDeepAndWideAsTheAngleCuts) {
  const Stl stl = RunToStl(kVcarve, "vcarve-grooves");
  ASSERT_GT(stl.triangles.size(), 1000u);
  const Surface s(stl);
  const double tan_half = std::tan(30 * M_PI / 180);  // 60-degree V-bit
  const double tol = 0.006;
  // The frame at x = 5 (a node line), 1 mm deep: across it at y = 40 the
  // surface is the V, z = min(0, -1 + |dx| / tan 30), at every node: 1 mm
  // deep, 2 tan(30) = 1.155 mm wide at the top.
  for (int k = -6; k <= 6; ++k) {
    const double dx = 0.25 * k;
    EXPECT_NEAR(s.At(5 + dx, 40), std::min(0.0, -1 + std::abs(dx) / tan_half),
                tol)
        << "dx " << dx;
  }
  // A leaf, carved along its middle line at depth = half-width / tan 30: at
  // its widest (half-width 2, on the diagonal through (40, 40), 41 mm out)
  // the cross-section is a V 2 / tan 30 = 3.464 mm deep and 4 mm wide. On
  // the flanks the mesh is exact (linear between nodes); at the bottom the
  // nodes straddle the crease.
  const double c = 40 + 41 / std::sqrt(2.0);
  const double deep = -2 / tan_half;
  auto across = [&](double u) {
    return s.At(c + u / std::sqrt(2.0), c - u / std::sqrt(2.0));
  };
  for (double u : {-1.5, -1.0, -0.6, 0.6, 1.0, 1.5}) {
    EXPECT_NEAR(across(u), (std::abs(u) - 2) / tan_half, 0.01) << "u " << u;
  }
  for (double u : {-2.5, -2.3, 2.3, 2.5}) {
    EXPECT_NEAR(across(u), 0, tol) << "u " << u;
  }
  EXPECT_GE(across(0), deep - tol);
  EXPECT_LE(across(0), deep + 0.25);
  // The node on the middle line nearest the widest point, (69, 69), is cut
  // to the tips' depth there (s = 5.012: -3.4640).
  EXPECT_NEAR(s.At(69, 69), -3.4640, tol);
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
  // M6 forgetting the position (swarf before issue 27; by default M6 keeps
  // it, as LinuxCNC) drops the feeds until X, Y and Z are known again.
  ASSERT_EQ(RunCommand({prog, "--tool", "ball:d=1", "--stock", "0,0,4,4,0",
                        "--spacing", "0.25", "--out", out, "--quiet",
                        "--m6-forgets-position"}),
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
                                 "--quiet", "--m6-forgets-position"});
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
  EXPECT_NE(
      err.str().find("swarf run: " + bad + ": line 2: division by zero\n"),
      std::string::npos)
      << err.str();
  EXPECT_EQ(err.str().find(bad + ": " + bad), std::string::npos) << err.str();
  std::filesystem::remove_all(dir);
}

// ------------------------------------------------- tools and projects

void WriteFile(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream(path) << text;
}

// RunCommand with std::cerr captured into *err.
int RunCapturing(const std::vector<std::string>& argv, std::string* err) {
  std::stringstream captured;
  std::streambuf* old = std::cerr.rdbuf(captured.rdbuf());
  const int rc = RunCommand(argv);
  std::cerr.rdbuf(old);
  *err = captured.str();
  return rc;
}

class RunProjectTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("swarf-e2e-project-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    // Two programs: a metric one with T1 (a 2 mm ball), an inch one in a
    // subdirectory with T2 (a 1/8 in flat end, given in inches).
    WriteFile(dir_ / "part1.nc",
              "G21\nT1 M6\nG0 X2 Y2 Z5\nG1 Z-1 F100\nX18\nG0 Z5\n");
    WriteFile(dir_ / "sub" / "part2.nc",
              "G20\nT2 M6\nG0 X0.1 Y0.3 Z0.2\nG1 Z-0.02\nX0.6\nG0 Z0.2\n");
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  // A project over `files` with tools 1 and 2 as above (tool 2's shape
  // `shape2`) and a 20 x 10 mm workpiece (margin 5, not automatic).
  std::string Project(const std::string& files,
                      const std::string& shape2 = "cylindrical") {
    const std::string path = (dir_ / "job.camotics").string();
    WriteFile(path, R"({
      "units": "metric",
      "tools": {
        "1": {"units": "metric", "shape": "ballnose", "length": 10,
              "diameter": 2},
        "2": {"units": "imperial", "shape": ")" +
                        shape2 + R"(", "length": 1,
              "diameter": 0.125}
      },
      "workpiece": {"automatic": false, "margin": 5,
                    "bounds": {"min": [0, 0, -5], "max": [20, 10, 0]}},
      "files": [)" + files +
                        "]}");
    return path;
  }

  std::filesystem::path dir_;
};

TEST_F(RunProjectTest, RunsTheFilesInOrderWithTheProjectsToolsAndWorkpiece) {
  const std::string out = (dir_ / "out").string();
  std::string err;
  ASSERT_EQ(RunCapturing({"--project", Project(R"("part1.nc", "sub/part2.nc")"),
                          "--spacing", "0.25", "--out", out, "--quiet"},
                         &err),
            0)
      << err;
  const auto p1 = ReadToolpathFile((dir_ / "part1.nc").string());
  const auto p2 = ReadToolpathFile((dir_ / "sub" / "part2.nc").string());
  ASSERT_TRUE(p1.ok() && p2.ok());
  const google::protobuf::Struct stats = ReadJson(out + "/stats.json");
  const auto& f = stats.fields();
  EXPECT_EQ(f.at("moves").number_value(), p1->move_count() + p2->move_count());
  // The workpiece as given: CAMotics ignores the margin when not automatic.
  const auto& st = f.at("stock").struct_value().fields();
  EXPECT_EQ(st.at("x0").number_value(), 0);
  EXPECT_EQ(st.at("y0").number_value(), 0);
  EXPECT_EQ(st.at("x1").number_value(), 20);
  EXPECT_EQ(st.at("y1").number_value(), 10);
  EXPECT_EQ(st.at("top").number_value(), 0);
  const auto& tools = f.at("tools").struct_value().fields();
  ASSERT_EQ(tools.size(), 2u);
  EXPECT_EQ(tools.at("1").string_value(), "ball d=2");
  EXPECT_EQ(tools.at("2").string_value(), "flat d=3.175");  // inches
  // The first file's groove reaches its tip depth on the nodes under it
  // (the top surface's lowest vertex; the mesh's bottom plane is below).
  const Stl stl = ReadStl(out + "/surface.stl");
  float bottom = 1e30f;
  for (const auto& t : stl.triangles) {
    for (int v = 0; v < 3; ++v) bottom = std::min(bottom, t[3 * v + 2]);
  }
  float lowest_top = 1e30f;
  for (const auto& t : stl.triangles) {
    for (int v = 0; v < 3; ++v) {
      if (t[3 * v + 2] > bottom + 1e-3f) {
        lowest_top = std::min(lowest_top, t[3 * v + 2]);
      }
    }
  }
  EXPECT_NEAR(lowest_top, -1, 1e-5);
}

// "automatic": true: the stock from the toolpath (its XY bounds plus the
// tool radius, top 0), grown by the margin, percent of its size, as CAMotics
// grows its automatic workpiece.
TEST_F(RunProjectTest, AutomaticWorkpieceGrowsByTheMarginPercent) {
  std::string project = Project(R"("part1.nc")");
  std::string text;
  {
    std::ifstream in(project);
    text.assign(std::istreambuf_iterator<char>(in), {});
  }
  const std::string given = "\"automatic\": false, \"margin\": 5";
  const size_t at = text.find(given);
  ASSERT_NE(at, std::string::npos);
  text.replace(at, given.size(), "\"automatic\": true, \"margin\": 10");
  WriteFile(project, text);
  std::stringstream out;
  std::streambuf* old = std::cout.rdbuf(out.rdbuf());
  std::string err;
  const int rc = RunCapturing(
      {"--project", project, "--spacing", "0.25", "--json", "--quiet"}, &err);
  std::cout.rdbuf(old);
  ASSERT_EQ(rc, 0) << err;
  google::protobuf::Struct stats;
  ASSERT_TRUE(
      google::protobuf::util::JsonStringToMessage(out.str(), &stats).ok());
  // part1.nc: X2..18 at Y2 with a 2 mm ball: [1, 19] x [1, 3], then 10%.
  const auto& st = stats.fields().at("stock").struct_value().fields();
  EXPECT_DOUBLE_EQ(st.at("x0").number_value(), 1 - 1.8);
  EXPECT_DOUBLE_EQ(st.at("x1").number_value(), 19 + 1.8);
  EXPECT_DOUBLE_EQ(st.at("y0").number_value(), 1 - 0.2);
  EXPECT_DOUBLE_EQ(st.at("y1").number_value(), 3 + 0.2);
  EXPECT_EQ(st.at("top").number_value(), 0);
}

TEST_F(RunProjectTest, ToolErrorsNameTheLineAndTheTool) {
  WriteFile(dir_ / "t3.nc",
            "G21\n(T3 is the tool)\nT3 M6\nG0 X1 Y1 Z5\nG1 Z-1\n");
  std::string err;
  EXPECT_EQ(
      RunCapturing({"--project", Project(R"("part1.nc", "t3.nc")"), "--quiet"},
                   &err),
      2);
  EXPECT_NE(err.find("t3.nc line 3: T3 is not in the tool table " +
                     (dir_ / "job.camotics").string() + " (T1, T2)"),
            std::string::npos)
      << err;
  // A shape swarf can't simulate, used: an error naming the tool.
  EXPECT_EQ(RunCapturing({"--project", Project(R"("sub/part2.nc")", "spheroid"),
                          "--quiet"},
                         &err),
            2);
  EXPECT_NE(err.find("part2.nc line 2: T2: "), std::string::npos) << err;
  EXPECT_NE(err.find("job.camotics tool \"2\": spheroid"), std::string::npos)
      << err;
  // A program and --project at once; a project without files.
  EXPECT_EQ(RunCapturing({(dir_ / "part1.nc").string(), "--project",
                          Project(R"("part1.nc")"), "--quiet"},
                         &err),
            2);
  EXPECT_EQ(RunCapturing({"--project", Project(""), "--quiet"}, &err), 2);
  EXPECT_NE(err.find("the project lists no files"), std::string::npos) << err;
  // A bad --tool names the option and its key.
  EXPECT_EQ(RunCapturing({(dir_ / "part1.nc").string(), "--tool",
                          "vbit:d=6,angle=200", "--quiet"},
                         &err),
            2);
  EXPECT_NE(err.find("--tool \"vbit:d=6,angle=200\": angle must be"),
            std::string::npos)
      << err;
}

TEST_F(RunProjectTest, LinuxCncToolTableAndNumberedTools) {
  const std::string tbl = (dir_ / "tools.tbl").string();
  WriteFile(tbl, "T1 P1 D4 ;bull r=1\nT2 P2 D0.25 ;ball\n");
  const std::string prog = (dir_ / "both.nc").string();
  WriteFile(prog,
            "G21\nT1 M6\nG0 X2 Y2 Z5\nG1 Z-1\nX18\nG0 Z5\n"
            "T2 M6\nG0 X2 Y6 Z5\nG1 Z-0.5\nX18\nG0 Z5\n");
  const std::string out = (dir_ / "out").string();
  std::string err;
  ASSERT_EQ(
      RunCapturing({prog, "--tools", tbl, "--tools-units", "inch", "--tool",
                    "T2=vbit:d=3,angle=60", "--stock", "0,0,20,10,0",
                    "--spacing", "0.25", "--out", out, "--quiet"},
                   &err),
      0)
      << err;
  const google::protobuf::Struct stats = ReadJson(out + "/stats.json");
  const auto& tools = stats.fields().at("tools").struct_value().fields();
  ASSERT_EQ(tools.size(), 2u);
  EXPECT_EQ(tools.at("1").string_value(), "bull d=101.6 r=1");   // D in inches
  EXPECT_EQ(tools.at("2").string_value(), "vbit d=3 angle=60");  // --tool wins

  // Cutter compensation takes the radius of the table's tool D names.
  const std::string comp = (dir_ / "comp.nc").string();
  WriteFile(comp,
            "G21 G17\nT1 M6\nG0 X-5 Y-5 Z1\nG1 Z-1\nG41 D1\nG1 X0 Y0\nX10\n"
            "G40\nG1 X15 Y-5\n");
  EXPECT_EQ(
      RunCapturing({comp, "--tools", tbl, "--spacing", "0.5", "--quiet"}, &err),
      0)
      << err;
  WriteFile(comp, "G21 G17\nT1 M6\nG0 X-5 Y-5 Z1\nG1 Z-1\nG41 D3\nG1 X0 Y0\n");
  EXPECT_EQ(RunCapturing({comp, "--tools", tbl, "--quiet"}, &err), 1);
  EXPECT_NE(err.find("line 5: G41: the radius of tool 3 is unknown"),
            std::string::npos)
      << err;
}

// The corpus' new projects run unmodified with the tools they name.
TEST(RunCorpusProjectTest, FlowerMoldAndVcarve) {
  SWARF_SKIP_UNLESS_SHARED_FILE(std::string(SWARF_CORPUS_DIR) +
                                "/vcarve.camotics");
  SWARF_SKIP_UNLESS_SHARED_FILE(std::string(SWARF_CORPUS_DIR) +
                                "/flower_mold.camotics");
  for (const auto& [name, program, tool] :
       {std::tuple{"vcarve", "vcarve.ngc", "vbit d=2 angle=53.1301"},
        std::tuple{"flower_mold", "flower_mold.nc", "flat d=1"}}) {
    SCOPED_TRACE(name);
    const std::string dir = std::string(SWARF_CORPUS_DIR) + "/";
    const std::string out = (std::filesystem::temp_directory_path() /
                             ("swarf-e2e-" + std::string(name) + "-project-" +
                              std::to_string(::getpid())))
                                .string();
    std::string err;
    ASSERT_EQ(RunCapturing({"--project", dir + name + ".camotics", "--spacing",
                            "0.5", "--out", out, "--quiet"},
                           &err),
              0)
        << err;
    const google::protobuf::Struct stats = ReadJson(out + "/stats.json");
    const auto& f = stats.fields();
    EXPECT_EQ(f.at("moves").number_value(),
              ReadToolpathFile(dir + program)->move_count());
    // No T word in these programs: the project's only tool.
    EXPECT_EQ(f.at("tools").struct_value().fields().at("0").string_value(),
              tool);
    EXPECT_TRUE(std::isfinite(
        f.at("error").struct_value().fields().at("max").number_value()));
    std::filesystem::remove_all(out);
  }
}

// Issue 15: on every corpus job, as its project gives it (tools, stock), the
// default scheme's max and RMS errors against the exact surface are each at
// most the z-map's and its mean far below, at the default 0.1 mm and on a
// grid twice as coarse (elements 40% of flower_mold's 0.5 mm radius). The
// generated jobs likewise (GeneratedPrecisionTest).
class CorpusPrecisionTest
    : public ::testing::TestWithParam<std::tuple<const char*, const char*>> {};

google::protobuf::Struct RunJson(const std::vector<std::string>& argv) {
  std::stringstream out;
  std::streambuf* old = std::cout.rdbuf(out.rdbuf());
  std::string err;
  const int rc = RunCapturing(argv, &err);
  std::cout.rdbuf(old);
  EXPECT_EQ(rc, 0) << err;
  google::protobuf::Struct s;
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(out.str(), &s).ok())
      << out.str().substr(0, 200);
  return s;
}

// `swarf run argv` with the z-map and with the default scheme: the
// default's max, mean and RMS errors at most the z-map's, its mean a tenth.
void ExpectDefaultNeverWorseThanZmap(const std::vector<std::string>& argv) {
  auto error = [&](const char* scheme) {
    std::vector<std::string> a = argv;
    if (scheme != nullptr) a.insert(a.end(), {"--scheme", scheme});
    const google::protobuf::Struct stats = RunJson(a);
    const auto& e = stats.fields().at("error").struct_value().fields();
    return std::tuple{e.at("max").number_value(), e.at("mean").number_value(),
                      e.at("rms").number_value()};
  };
  const auto [zmax, zmean, zrms] = error("zmap");
  const auto [gmax, gmean, grms] = error(nullptr);  // the default
  EXPECT_GT(zmean, 0);
  EXPECT_LE(gmax, zmax);
  EXPECT_LE(grms, zrms);
  EXPECT_LE(gmean, zmean / 10) << "default " << gmean << " zmap " << zmean;
}

TEST_P(CorpusPrecisionTest, DefaultSchemeNeverWorseThanTheZmap) {
  const auto [name, spacing] = GetParam();
  const std::string project =
      std::string(SWARF_CORPUS_DIR) + "/" + name + ".camotics";
  SWARF_SKIP_UNLESS_SHARED_FILE(project);
  ExpectDefaultNeverWorseThanZmap(
      {"--project", project, "--spacing", spacing, "--json", "--quiet"});
}

INSTANTIATE_TEST_SUITE_P(Corpus, CorpusPrecisionTest,
                         ::testing::Combine(::testing::Values("bear", "cameo",
                                                              "flower_mold",
                                                              "vcarve"),
                                            ::testing::Values("0.1", "0.2")),
                         [](const auto& info) {
                           std::string s = std::get<1>(info.param);
                           s.replace(s.find('.'), 1, "_");
                           return std::string(std::get<0>(info.param)) + "_" +
                                  s;
                         });

// The generated jobs with their tools and stock: the default scheme's max,
// mean and RMS errors at most the z-map's (the pocket's flat floors and
// vertical walls: the default scheme's error is 0 there).
class GeneratedPrecisionTest
    : public ::testing::TestWithParam<std::tuple<Job, const char*>> {};

TEST_P(GeneratedPrecisionTest, DefaultSchemeNeverWorseThanTheZmap) {
  const auto& [job, spacing] = GetParam();
  std::vector<std::string> argv = {job.File(), "--spacing", spacing, "--json",
                                   "--quiet"};
  argv.insert(argv.end(), job.args.begin(), job.args.end());
  ExpectDefaultNeverWorseThanZmap(argv);
}

INSTANTIATE_TEST_SUITE_P(Generated, GeneratedPrecisionTest,
                         ::testing::Combine(::testing::Values(kRelief, kPocket,
                                                              kVcarve),
                                            ::testing::Values("0.1", "0.2")),
                         [](const auto& info) {
                           std::string n = std::get<0>(info.param).name;
                           std::string s = std::get<1>(info.param);
                           s.replace(s.find('.'), 1, "_");
                           return n.substr(0, n.find('.')) + "_" + s;
                         });

INSTANTIATE_TEST_SUITE_P(
    Jobs, RunE2eTest,
    ::testing::Values(kRelief, kPocket, kVcarve,
                      Job{"bear.nc", true, {"--tool", "ball:d=3.175"}},
                      Job{"cameo.nc", true, {"--tool", "ball:d=2"}}),
    JobTestName);

}  // namespace
}  // namespace swarf::cli
