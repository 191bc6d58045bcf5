// The live viewer in a real headless Chromium (tests/viewer_browser.py,
// selenium + chromium-driver): `swarf view` attached to a swarfd session
// while another client streams a 1000 x 1000 job into it, and `swarf run
// --view` after its job. Checks: the page loads without console errors,
// draws its mesh, gets tiles while the job streams (only changed ones), a
// height read under the pointer equals the API's Probe bit for bit, and the
// screenshot is neither blank nor uniform. Skipped when chromium,
// chromium-driver or python3-selenium is not installed.
#include <png.h>
#include <signal.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "gtest/gtest.h"
#include "grpcpp/grpcpp.h"
#include "server/server.h"
#include "swarf/v1/swarf.grpc.pb.h"

extern char** environ;

namespace {

namespace pb = ::swarf::v1;

// A child process in its own process group (with whatever it starts:
// chromedriver, chromium), its stdout piped; killed with the test.
class Child {
 public:
  explicit Child(const std::vector<std::string>& argv,
                 bool with_stderr = false) {
    int out[2];
    EXPECT_EQ(pipe(out), 0);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    pid_ = fork();
    if (pid_ == 0) {
      prctl(PR_SET_PDEATHSIG, SIGKILL);  // the test died: so does this
      setpgid(0, 0);
      dup2(out[1], STDOUT_FILENO);
      if (with_stderr) dup2(out[1], STDERR_FILENO);
      close(out[0]);
      close(out[1]);
      execve(args[0], args.data(), environ);
      _exit(127);
    }
    EXPECT_GT(pid_, 0) << argv[0];
    close(out[1]);
    fd_ = out[0];
  }
  ~Child() {
    if (pid_ > 0) kill(-pid_, SIGKILL);  // the group: nothing left behind
    if (pid_ > 0 && !waited_) Wait();
    if (fd_ >= 0) close(fd_);
  }
  // The next line of its stdout without the newline; false at EOF or when
  // none comes within `timeout_s`.
  bool ReadLine(std::string* line, double timeout_s = 180) {
    const auto deadline = std::chrono::steady_clock::now() +
                          std::chrono::milliseconds(int64_t(timeout_s * 1000));
    for (;;) {
      const size_t nl = buf_.find('\n');
      if (nl != std::string::npos) {
        line->assign(buf_, 0, nl);
        buf_.erase(0, nl + 1);
        return true;
      }
      const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now());
      pollfd p{fd_, POLLIN, 0};
      if (left.count() <= 0 || poll(&p, 1, static_cast<int>(left.count())) <= 0) {
        ADD_FAILURE() << "no line from the child within " << timeout_s << " s";
        return false;
      }
      char chunk[4096];
      const ssize_t n = read(fd_, chunk, sizeof chunk);
      if (n <= 0) return false;
      buf_.append(chunk, n);
    }
  }
  void Signal(int sig) { kill(pid_, sig); }
  // Exit status (-1 if killed by a signal).
  int Wait() {
    int st = 0;
    waitpid(pid_, &st, 0);
    waited_ = true;
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  }

 private:
  pid_t pid_ = -1;
  bool waited_ = false;
  int fd_ = -1;
  std::string buf_;
};

bool Installed() {
  return std::filesystem::exists("/usr/bin/chromium") &&
         std::filesystem::exists("/usr/bin/chromedriver") &&
         std::system("/usr/bin/python3 -c 'import selenium' 2>/dev/null") == 0;
}

#define SKIP_WITHOUT_CHROMIUM()                                              \
  if (!Installed()) {                                                        \
    GTEST_SKIP() << "chromium, chromium-driver or python3-selenium is not "  \
                    "installed (scripts/install-deps installs them): the "   \
                    "viewer's browser test is skipped";                      \
  }

// What the browser script reported.
struct Report {
  std::vector<std::array<double, 3>> probes;  // x, y, z under the pointer
  std::string verdict;                        // "OK" or "FAIL ..."
};

// Reads the script's lines after READY until its verdict.
Report ReadReport(Child& script) {
  Report r;
  std::string line;
  while (script.ReadLine(&line)) {
    std::fprintf(stderr, "viewer_browser.py: %s\n", line.c_str());
    if (line.rfind("PROBE ", 0) == 0) {
      std::array<double, 3> p;
      char* s = line.data() + 6;
      for (double& v : p) v = std::strtod(s, &s);
      r.probes.push_back(p);
    } else if (line == "OK" || line.rfind("FAIL", 0) == 0) {
      r.verdict = line;
    }
  }
  return r;
}

// Checks a screenshot: decodable, and neither blank nor of one colour (the
// part drawn shaded covers many colours).
void ExpectPicture(const std::string& path) {
  png_image img{};
  img.version = PNG_IMAGE_VERSION;
  ASSERT_TRUE(png_image_begin_read_from_file(&img, path.c_str())) << path;
  img.format = PNG_FORMAT_RGB;
  std::vector<uint8_t> px(PNG_IMAGE_SIZE(img));
  ASSERT_TRUE(png_image_finish_read(&img, nullptr, px.data(), 0, nullptr));
  ASSERT_GT(img.width * img.height, 100000u) << path;
  std::map<uint32_t, int64_t> counts;
  double sum = 0, sum2 = 0;
  const int64_t n = static_cast<int64_t>(img.width) * img.height;
  for (int64_t k = 0; k < n; ++k) {
    const uint8_t* p = &px[3 * k];
    ++counts[(p[0] << 16) | (p[1] << 8) | p[2]];
    const double l = 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2];
    sum += l;
    sum2 += l * l;
  }
  int64_t most = 0;
  for (const auto& [c, k] : counts) most = std::max(most, k);
  const double mean = sum / n, sd = std::sqrt(std::max(0.0, sum2 / n - mean * mean));
  EXPECT_GT(counts.size(), 500u) << path << ": too few colours";
  EXPECT_LT(most, n * 0.85) << path << ": one colour covers the picture";
  EXPECT_GT(sd, 10) << path << ": nearly uniform";
  EXPECT_GT(mean, 5) << path << ": black";
  EXPECT_LT(mean, 250) << path << ": white";
}

std::string ShotPrefix(const std::string& name) {
  std::filesystem::create_directories(SWARF_VIEWER_OUT);
  return std::string(SWARF_VIEWER_OUT) + "/" + name;
}

// A raster finishing job: passes along x at increasing y, a wavy depth.
std::vector<std::vector<double>> RasterPasses(int passes, int points) {
  std::vector<std::vector<double>> out;
  for (int p = 0; p < passes; ++p) {
    std::vector<double>& xyz = out.emplace_back();
    const double y = 8 + p * 84.0 / (passes - 1);
    for (int k = 0; k < points; ++k) {
      const double t = static_cast<double>(k) / (points - 1);
      const double x = (p % 2 == 0) ? 8 + 84 * t : 92 - 84 * t;
      xyz.insert(xyz.end(), {x, y, -1.5 - std::sin(x / 9) * std::cos(y / 13)});
    }
  }
  return out;
}

TEST(ViewerBrowserTest, AttachedViewerFollowsAStreamedJob) {
  SKIP_WITHOUT_CHROMIUM();
  swarf::server::ServerOptions opt;
  opt.listen = "127.0.0.1:0";
  auto server = swarf::server::SwarfServer::Start(opt);
  ASSERT_TRUE(server.ok()) << server.status();
  const std::string target = "127.0.0.1:" + std::to_string((*server)->port());
  auto channel = grpc::CreateChannel(target, grpc::InsecureChannelCredentials());
  auto stub = pb::Swarf::NewStub(channel);
  const std::string id = "viewer-test";
  auto ctx = [&] {
    auto c = std::make_unique<grpc::ClientContext>();
    c->AddMetadata("x-swarf-session", id);
    return c;
  };
  {
    pb::CreateSessionRequest req;
    req.set_session_id(id);
    auto* st = req.mutable_stock();
    st->set_x0(0);
    st->set_y0(0);
    st->set_x1(100);
    st->set_y1(100);
    st->set_z_top(0);
    req.set_nx(1000);
    req.set_ny(1000);
    req.set_scheme(pb::SCHEME_TAYLOR);
    auto* tool = req.add_tools();
    tool->set_id(1);
    tool->mutable_ball()->set_radius(2.5);
    pb::Session s;
    ASSERT_TRUE(stub->CreateSession(ctx().get(), req, &s).ok());
  }
  const auto passes = RasterPasses(29, 300);
  int64_t total = 0;
  for (const auto& p : passes) total += p.size() / 3;
  total -= 1;  // the first point only places the tool

  Child view({SWARF_CLI, "view", "--server", target, "--session", id,
              "--view-port", "0"});
  std::string line;
  ASSERT_TRUE(view.ReadLine(&line));
  const size_t at = line.find("http://");
  ASSERT_NE(at, std::string::npos) << line;
  const std::string url = line.substr(at, line.find(' ', at) - at);

  const std::string shot = ShotPrefix("viewer-stream");
  Child script({"/usr/bin/python3", SWARF_VIEWER_SCRIPT, url,
                std::to_string(total), shot, "stream"});
  ASSERT_TRUE(script.ReadLine(&line));
  ASSERT_EQ(line, "READY");

  // Another client streams the job, one pass per batch. It pauses after a
  // third and after two thirds of the passes until the page says it fetched
  // tiles of a part-cut state (SEEN): paced on time alone (300 ms a batch),
  // a page slowed by a busy machine saw the job's states in bursts seconds
  // apart, and fetched tiles once or not at all while the job streamed.
  {
    auto c = ctx();
    auto stream = stub->Simulate(c.get());
    uint64_t seq = 0;
    int64_t sent = 0;
    const size_t pause_at[2] = {passes.size() / 3, 2 * passes.size() / 3};
    int64_t last_seen = 0;
    for (const auto& xyz : passes) {
      pb::SimulateRequest req;
      auto* b = req.mutable_moves();
      b->set_seq(++seq);
      b->set_tool_id(1);
      b->mutable_xyz()->Assign(xyz.begin(), xyz.end());
      ASSERT_TRUE(stream->Write(req));
      pb::SimulateResponse resp;
      ASSERT_TRUE(stream->Read(&resp));
      ASSERT_TRUE(resp.has_ack()) << resp.DebugString();
      sent += static_cast<int64_t>(xyz.size() / 3) - (seq == 1 ? 1 : 0);
      if (seq == pause_at[0] || seq == pause_at[1]) {
        ASSERT_TRUE(script.ReadLine(&line)) << "no SEEN after " << sent;
        std::fprintf(stderr, "viewer_browser.py: %s\n", line.c_str());
        ASSERT_EQ(line.rfind("SEEN ", 0), 0u) << line;
        const int64_t seen = std::stoll(line.substr(5));
        // A state the page saw is one the job was in: part-cut, and not
        // ahead of what was sent.
        EXPECT_GT(seen, last_seen);
        EXPECT_LE(seen, sent);
        last_seen = seen;
      } else {
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
      }
    }
    stream->WritesDone();
    ASSERT_TRUE(stream->Finish().ok());
  }
  const Report report = ReadReport(script);
  EXPECT_EQ(script.Wait(), 0);
  EXPECT_EQ(report.verdict, "OK");
  ASSERT_EQ(report.probes.size(), 3u);
  int on_cut = 0;
  for (const auto& [x, y, z] : report.probes) {
    pb::ProbeRequest req;
    req.set_session_id(id);
    req.add_xy(x);
    req.add_xy(y);
    pb::ProbeResponse resp;
    ASSERT_TRUE(stub->Probe(ctx().get(), req, &resp).ok());
    ASSERT_EQ(resp.heights_size(), 1);
    EXPECT_EQ(z, resp.heights(0)) << "at " << x << ", " << y;
    on_cut += z < 0;
  }
  EXPECT_GE(on_cut, 1) << "no probe landed on the machined surface";
  ExpectPicture(shot + ".png");
  ExpectPicture(shot + "-error-marks.png");

  view.Signal(SIGINT);
  EXPECT_EQ(view.Wait(), 0);
}

// swarf run --view-wait on its embedded server: the same page (its URL on
// stderr; the run cuts once the page is open), with the program's toolpath,
// until Ctrl-C.
TEST(ViewerBrowserTest, RunViewShowsTheFinishedJob) {
  SKIP_WITHOUT_CHROMIUM();
  std::filesystem::create_directories(SWARF_VIEWER_OUT);
  const std::string file = std::string(SWARF_VIEWER_OUT) + "/run-job.xyz";
  int64_t total = -1;  // the first point only places the tool
  {
    std::ofstream out(file);
    for (const auto& pass : RasterPasses(9, 60)) {
      for (size_t k = 0; k < pass.size(); k += 3) {
        out << pass[k] << "," << pass[k + 1] << "," << pass[k + 2] << "\n";
        ++total;
      }
    }
  }
  Child run({SWARF_CLI, "run", file, "--tool", "ball:d=6", "--stock",
             "0,0,100,100,0", "--mesh", "300", "--view-wait", "--view-port", "0",
             "--quiet"},
            /*with_stderr=*/true);
  std::string line, url;
  while (url.empty() && run.ReadLine(&line)) {
    const size_t at = line.find("viewer at http://");
    if (at != std::string::npos) url = line.substr(at + 10);
  }
  ASSERT_FALSE(url.empty());
  const std::string shot = ShotPrefix("viewer-run");
  Child script({"/usr/bin/python3", SWARF_VIEWER_SCRIPT, url,
                std::to_string(total), shot, "done"});
  ASSERT_TRUE(script.ReadLine(&line));
  ASSERT_EQ(line, "READY");
  const Report report = ReadReport(script);
  EXPECT_EQ(script.Wait(), 0);
  EXPECT_EQ(report.verdict, "OK");
  EXPECT_EQ(report.probes.size(), 3u);
  ExpectPicture(shot + ".png");
  run.Signal(SIGINT);
  bool summary = false;
  while (run.ReadLine(&line)) {
    summary |= line.find(std::to_string(total) + " moves simulated") !=
               std::string::npos;
  }
  EXPECT_EQ(run.Wait(), 0);
  EXPECT_TRUE(summary) << "no run summary";
}

}  // namespace
