// Cluster test: the deployment's session-affine balancing with real
// processes on loopback. Three swarfd replicas on their own ports and nginx
// with the balancer config rendered by deploy/nginx/render-config for those
// ports (the same template compose and Kubernetes use). Through nginx only:
// 12 sessions with client-chosen ids, moves streamed into each; every call of
// a session must reach the same replica (x-swarf-replica) and the sessions
// must spread over all three. Then one replica is stopped and started again
// on its data directory: the other replicas' sessions are unaffected, the
// stopped replica's sessions answer UNAVAILABLE while it is down (they are
// not moved), and once it is back its sessions come back and continue
// (when swarfd journals sessions: `--data_dir` in `swarfd --helpfull`) or,
// without persistence, it serves again and the ids still route to it.
//
// Everything listens on 127.0.0.1 and is stopped by the test (RAII; children
// also die with the test: PR_SET_PDEATHSIG). nginx must be installed
// (scripts/install-deps installs it): without it the test fails. Its files
// (logs, nginx config and access log, data directories) are kept after a
// failure, or always with SWARF_CLUSTER_KEEP=1.

#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "swarf/v1/swarf.grpc.pb.h"

extern char** environ;

namespace {

namespace fs = std::filesystem;
namespace pb = ::swarf::v1;
using Clock = std::chrono::steady_clock;
using namespace std::chrono_literals;

constexpr int kReplicas = 3;
constexpr int kSessions = 12;
constexpr int kBatchesBefore = 3;  // batches streamed before the restart
constexpr int kPointsPerBatch = 120;
constexpr char kSessionKey[] = "x-swarf-session";
constexpr char kReplicaKey[] = "x-swarf-replica";
// What every stream claims as its x-real-ip, which nginx must overwrite.
constexpr char kSpoofedIp[] = "192.0.2.77";

// ---------------------------------------------------------------- processes

std::string ReadFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string Tail(const std::string& s, size_t n = 3000) {
  return s.size() <= n ? s : "..." + s.substr(s.size() - n);
}

// A child process with stdout and stderr appended to a log file. It dies with
// this thread (PR_SET_PDEATHSIG) and is stopped by the destructor.
class Process {
 public:
  Process(std::string name, std::vector<std::string> argv, fs::path log,
          int stop_signal = SIGTERM)
      : name_(std::move(name)),
        argv_(std::move(argv)),
        log_(std::move(log)),
        stop_signal_(stop_signal) {}
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;
  ~Process() { Stop(5s); }

  const std::string& name() const { return name_; }
  std::string log() const { return ReadFile(log_); }

  bool Start() {
    std::vector<char*> args;
    for (auto& a : argv_) args.push_back(a.data());
    args.push_back(nullptr);
    const std::string log = log_.string();
    const int death = stop_signal_;
    const pid_t pid = fork();
    if (pid < 0) return false;
    if (pid == 0) {
      // Only async-signal-safe calls until exec.
      prctl(PR_SET_PDEATHSIG, death);
      const int in = open("/dev/null", O_RDONLY);
      const int out = open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      if (in < 0 || out < 0) _exit(126);
      dup2(in, 0);
      dup2(out, 1);
      dup2(out, 2);
      execve(args[0], args.data(), environ);
      _exit(127);
    }
    pid_ = pid;
    exit_status_.reset();
    return true;
  }

  bool Running() {
    if (pid_ <= 0) return false;
    int status = 0;
    const pid_t r = waitpid(pid_, &status, WNOHANG);
    if (r == pid_) {
      exit_status_ = status;
      pid_ = -1;
      return false;
    }
    return r == 0;
  }

  // Sends the stop signal and waits; SIGKILL after `timeout`. True when the
  // process stopped by itself within the timeout (or was not running).
  bool Stop(std::chrono::milliseconds timeout) {
    if (!Running()) return true;
    kill(pid_, stop_signal_);
    const auto end = Clock::now() + timeout;
    while (Clock::now() < end) {
      if (!Running()) return true;
      std::this_thread::sleep_for(20ms);
    }
    kill(pid_, SIGKILL);
    int status = 0;
    waitpid(pid_, &status, 0);
    exit_status_ = status;
    pid_ = -1;
    return false;
  }

  std::optional<int> exit_status() const { return exit_status_; }

 private:
  std::string name_;
  std::vector<std::string> argv_;
  fs::path log_;
  int stop_signal_;
  pid_t pid_ = -1;
  std::optional<int> exit_status_;
};

// Runs a command to completion (bounded); returns its exit code, -1 if it
// could not run or timed out. Output goes to `log`.
int RunCommand(std::vector<std::string> argv, const fs::path& log,
        std::chrono::milliseconds timeout = 20s) {
  std::string name = argv.front();
  Process p(std::move(name), std::move(argv), log, SIGKILL);
  if (!p.Start()) return -1;
  const auto end = Clock::now() + timeout;
  while (p.Running()) {
    if (Clock::now() > end) return -1;
    std::this_thread::sleep_for(10ms);
  }
  const int status = p.exit_status().value_or(-1);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::optional<std::string> FindNginx() {
  if (const char* env = std::getenv("SWARF_NGINX"); env && *env) return env;
  std::vector<std::string> dirs;
  if (const char* path = std::getenv("PATH")) {
    std::stringstream ss(path);
    for (std::string d; std::getline(ss, d, ':');) dirs.push_back(d);
  }
  for (const char* d : {"/usr/sbin", "/usr/local/sbin", "/sbin"}) {
    dirs.push_back(d);
  }
  for (const auto& d : dirs) {
    const fs::path p = fs::path(d) / "nginx";
    if (access(p.c_str(), X_OK) == 0) return p.string();
  }
  return std::nullopt;
}

// A free port on 127.0.0.1 below the usual ephemeral range (32768-60999), so
// that no outgoing connection takes it while a replica is restarted.
int PickPort(std::set<int>* taken) {
  std::mt19937 rng(std::random_device{}());
  std::uniform_int_distribution<int> dist(20000, 32000);
  for (int attempt = 0; attempt < 1000; ++attempt) {
    const int port = dist(rng);
    if (taken->count(port)) continue;
    const int fd = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(static_cast<uint16_t>(port));
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    const bool free =
        bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0;
    close(fd);
    if (free) {
      taken->insert(port);
      return port;
    }
  }
  return -1;
}

// ------------------------------------------------- nginx's consistent hash

// nginx's `hash ... consistent` (ngx_http_upstream_hash_module): 160 points
// per server at CRC32 chains seeded by "host\0port", a key goes to the first
// point at or after CRC32(key). Used only to choose session ids that spread
// evenly (4 per replica) whatever ports the replicas got; the test asserts
// what nginx really does, not this model.
class ChashModel {
 public:
  explicit ChashModel(const std::vector<std::string>& servers) {
    for (size_t s = 0; s < servers.size(); ++s) {
      const std::string& name = servers[s];
      const size_t colon = name.rfind(':');
      uint32_t base = 0xffffffffu;
      base = Update(base, name.data(), colon);
      base = Update(base, "", 1);
      base = Update(base, name.data() + colon + 1, name.size() - colon - 1);
      uint32_t prev = 0;
      for (int j = 0; j < 160; ++j) {
        const unsigned char b[4] = {
            static_cast<unsigned char>(prev), static_cast<unsigned char>(prev >> 8),
            static_cast<unsigned char>(prev >> 16),
            static_cast<unsigned char>(prev >> 24)};
        const uint32_t h = Update(base, b, 4) ^ 0xffffffffu;
        points_.emplace_back(h, static_cast<int>(s));
        prev = h;
      }
    }
    std::sort(points_.begin(), points_.end());
  }

  int ServerOf(std::string_view key) const {
    const uint32_t h = Update(0xffffffffu, key.data(), key.size()) ^ 0xffffffffu;
    auto it = std::lower_bound(
        points_.begin(), points_.end(), h,
        [](const std::pair<uint32_t, int>& p, uint32_t v) { return p.first < v; });
    if (it == points_.end()) it = points_.begin();
    return it->second;
  }

 private:
  static uint32_t Update(uint32_t crc, const void* data, size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < n; ++i) {
      crc ^= p[i];
      for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return crc;
  }

  std::vector<std::pair<uint32_t, int>> points_;
};

// ------------------------------------------------------------------ client

std::string ReplicaOf(const grpc::ClientContext& ctx) {
  const auto& md = ctx.GetServerInitialMetadata();
  auto it = md.find(kReplicaKey);
  if (it == md.end()) return "";
  return std::string(it->second.data(), it->second.size());
}

std::unique_ptr<grpc::ClientContext> Ctx(const std::string& session,
                                         std::chrono::seconds timeout = 20s) {
  auto ctx = std::make_unique<grpc::ClientContext>();
  if (!session.empty()) ctx->AddMetadata(kSessionKey, session);
  ctx->set_deadline(std::chrono::system_clock::now() + timeout);
  return ctx;
}

// A session's tool path: a zigzag over the stock at a depth of its own, in
// batches of kPointsPerBatch points (batch k is seq k).
pb::SimulateRequest Batch(int session_index, int seq) {
  pb::SimulateRequest r;
  pb::MoveBatch* b = r.mutable_moves();
  b->set_seq(seq);
  b->set_tool_id(1);
  const double depth = -0.2 - 0.05 * session_index;
  for (int k = 0; k < kPointsPerBatch; ++k) {
    const int n = (seq - 1) * kPointsPerBatch + k;
    const double y = 1.0 + 0.25 * (n / 2 % 72);
    const double x = (n % 4 == 0 || n % 4 == 3) ? 1.0 : 19.0;
    b->add_xyz(x);
    b->add_xyz(y);
    b->add_xyz(depth);
  }
  return r;
}

struct CallResult {
  grpc::StatusCode code = grpc::StatusCode::UNKNOWN;
  std::string message;
  std::vector<std::string> replicas;  // x-swarf-replica of each call
};

class Client {
 public:
  explicit Client(const std::string& target) {
    grpc::ChannelArguments args;
    args.SetMaxReceiveMessageSize(64 << 20);
    args.SetMaxSendMessageSize(64 << 20);
    channel_ = grpc::CreateCustomChannel(
        target, grpc::InsecureChannelCredentials(), args);
    stub_ = pb::Swarf::NewStub(channel_);
  }
  pb::Swarf::Stub& stub() { return *stub_; }

  grpc::Status Create(const std::string& id, pb::Session* out,
                      std::string* replica) {
    pb::CreateSessionRequest req;
    req.set_session_id(id);
    pb::Stock* s = req.mutable_stock();
    s->set_x0(0);
    s->set_y0(0);
    s->set_x1(20);
    s->set_y1(20);
    s->set_z_top(0);
    req.set_spacing(0.1);
    req.set_scheme(pb::SCHEME_TAYLOR);
    pb::Tool* t = req.add_tools();
    t->set_id(1);
    t->mutable_ball()->set_radius(1);
    auto ctx = Ctx(id);
    grpc::Status st = stub_->CreateSession(ctx.get(), req, out);
    *replica = ReplicaOf(*ctx);
    return st;
  }

  grpc::Status Get(const std::string& id, pb::Session* out,
                   std::string* replica) {
    pb::GetSessionRequest req;
    req.set_session_id(id);
    auto ctx = Ctx(id);
    grpc::Status st = stub_->GetSession(ctx.get(), req, out);
    *replica = ReplicaOf(*ctx);
    return st;
  }

  // Streams batches [first, last] on one Simulate stream; every one must be
  // acknowledged, not as a duplicate.
  grpc::Status Stream(const std::string& id, int session_index, int first,
                      int last, std::string* replica, std::string* problem) {
    auto ctx = Ctx(id, 60s);
    // A client cannot name itself: nginx replaces this with its peer.
    ctx->AddMetadata("x-real-ip", kSpoofedIp);
    auto stream = stub_->Simulate(ctx.get());
    std::thread writer([&] {
      for (int seq = first; seq <= last; ++seq) {
        if (!stream->Write(Batch(session_index, seq))) break;
      }
      stream->WritesDone();
    });
    pb::SimulateResponse resp;
    int expect = first;
    while (stream->Read(&resp)) {
      if (replica->empty()) *replica = ReplicaOf(*ctx);
      if (!resp.has_ack()) {
        *problem = "unexpected response " + resp.ShortDebugString();
        continue;
      }
      if (resp.ack().seq() != static_cast<uint64_t>(expect) ||
          resp.ack().duplicate()) {
        *problem = "ack " + resp.ack().ShortDebugString() + ", expected seq " +
                   std::to_string(expect);
      }
      ++expect;
    }
    writer.join();
    grpc::Status st = stream->Finish();
    if (replica->empty()) *replica = ReplicaOf(*ctx);
    if (st.ok() && expect != last + 1 && problem->empty()) {
      *problem = "acks up to " + std::to_string(expect - 1) + " of " +
                 std::to_string(last);
    }
    return st;
  }

  grpc::Status ProbeHeights(const std::string& id, std::vector<double>* h,
                            std::string* replica) {
    pb::ProbeRequest req;
    req.set_session_id(id);
    for (double x : {2.0, 7.5, 10.0, 18.0}) {
      for (double y : {1.5, 5.0, 12.25, 18.5}) {
        req.add_xy(x);
        req.add_xy(y);
      }
    }
    pb::ProbeResponse resp;
    auto ctx = Ctx(id);
    grpc::Status st = stub_->Probe(ctx.get(), req, &resp);
    *replica = ReplicaOf(*ctx);
    h->assign(resp.heights().begin(), resp.heights().end());
    return st;
  }

  // GetTiles (a server stream through nginx): the number of tiles.
  grpc::Status Tiles(const std::string& id, int* tiles, std::string* replica) {
    pb::GetTilesRequest req;
    req.set_session_id(id);
    req.set_since_version(0);
    auto ctx = Ctx(id);
    auto reader = stub_->GetTiles(ctx.get(), req);
    pb::Tile tile;
    *tiles = 0;
    while (reader->Read(&tile)) ++*tiles;
    grpc::Status st = reader->Finish();
    *replica = ReplicaOf(*ctx);
    return st;
  }

  grpc::Status List(std::vector<std::string>* ids) {
    pb::ListSessionsRequest req;
    pb::ListSessionsResponse resp;
    auto ctx = Ctx("");
    grpc::Status st = stub_->ListSessions(ctx.get(), req, &resp);
    ids->clear();
    for (const auto& s : resp.sessions()) ids->push_back(s.session_id());
    std::sort(ids->begin(), ids->end());
    return st;
  }

 private:
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::Swarf::Stub> stub_;
};

// ------------------------------------------------------------------ cluster

struct Replica {
  std::string name;
  int port = 0;
  fs::path data_dir;
  std::unique_ptr<Process> process;
  std::string address() const { return "127.0.0.1:" + std::to_string(port); }
};

class ClusterTest : public ::testing::Test {
 protected:
  void SetUp() override {
    char tmpl[] = "/tmp/swarf-cluster-XXXXXX";
    ASSERT_NE(mkdtemp(tmpl), nullptr);
    dir_ = tmpl;
    // nginx workers (nobody when the test runs as root) must reach the dir.
    chmod(dir_.c_str(), 0755);

    // swarfd journals sessions when it has --data_dir (the reliability
    // issue); then the restart must bring them back.
    RunCommand({SWARF_SWARFD, "--helpfull"}, dir_ / "helpfull.txt");
    const std::string help = ReadFile(dir_ / "helpfull.txt");
    ASSERT_NE(help.find("--drain_seconds"), std::string::npos)
        << "swarfd --helpfull did not list its flags:\n" << Tail(help);
    persistence_ = help.find("--data_dir") != std::string::npos;
  }

  void TearDown() override {
    if (nginx_) nginx_->Stop(5s);
    for (auto& r : replicas_) {
      if (r.process) r.process->Stop(10s);
    }
    const char* keep = std::getenv("SWARF_CLUSTER_KEEP");  // for a look
    if (HasFailure() || (keep != nullptr && *keep != '\0')) {
      for (auto& r : replicas_) {
        if (r.process) {
          std::fprintf(stderr, "---- %s log:\n%s\n", r.name.c_str(),
                       Tail(r.process->log()).c_str());
        }
      }
      std::fprintf(stderr, "---- nginx error.log:\n%s\n---- access.log:\n%s\n",
                   Tail(ReadFile(dir_ / "nginx" / "error.log")).c_str(),
                   Tail(ReadFile(dir_ / "nginx" / "access.log"), 6000).c_str());
      std::fprintf(stderr, "cluster test files kept in %s\n", dir_.c_str());
    } else {
      std::error_code ec;
      fs::remove_all(dir_, ec);
    }
  }

  std::unique_ptr<Process> NewReplicaProcess(const Replica& r) {
    std::vector<std::string> argv = {
        SWARF_SWARFD,           "--listen=" + r.address(),
        "--replica=" + r.name,  "--worker_threads=2",
        "--max_sessions=64",    "--max_total_memory_mb=1024",
        "--drain_seconds=2",    "--log_level=info",
        "--trusted_proxies=127.0.0.1"};
    if (persistence_) argv.push_back("--data_dir=" + r.data_dir.string());
    return std::make_unique<Process>(r.name, argv,
                                     dir_ / (r.name + ".log"));
  }

  // `swarf health --server ADDR` (what the Docker HEALTHCHECK runs) until it
  // exits 0; false after `timeout` or if `process` died.
  bool WaitHealthy(const std::string& address, Process* process,
                   std::chrono::seconds timeout = 20s) {
    const auto end = Clock::now() + timeout;
    while (Clock::now() < end) {
      if (process != nullptr && !process->Running()) return false;
      if (RunCommand({SWARF_CLI, "health", "--server", address, "--timeout", "1"},
              dir_ / "health.log", 5s) == 0) {
        return true;
      }
      std::this_thread::sleep_for(100ms);
    }
    return false;
  }

  void StartReplica(Replica& r) {
    r.process = NewReplicaProcess(r);
    ASSERT_TRUE(r.process->Start()) << r.name;
    ASSERT_TRUE(WaitHealthy(r.address(), r.process.get()))
        << r.name << " on " << r.address() << " did not become healthy:\n"
        << Tail(r.process->log());
  }

  void StartCluster() {
    const std::optional<std::string> nginx = FindNginx();
    ASSERT_TRUE(nginx.has_value())
        << "nginx is not installed (scripts/install-deps installs it); the "
           "cluster test needs it";
    std::set<int> ports;
    for (int i = 0; i < kReplicas; ++i) {
      Replica r;
      r.name = "replica-" + std::to_string(i);
      r.port = PickPort(&ports);
      ASSERT_GT(r.port, 0);
      r.data_dir = dir_ / ("data-" + std::to_string(i));
      fs::create_directories(r.data_dir);
      replicas_.push_back(std::move(r));
    }
    for (auto& r : replicas_) {
      ASSERT_NO_FATAL_FAILURE(StartReplica(r));
    }

    // nginx with the config rendered for these ports.
    nginx_port_ = PickPort(&ports);
    ASSERT_GT(nginx_port_, 0);
    const fs::path ndir = dir_ / "nginx";
    std::vector<std::string> render = {
        "/bin/bash", SWARF_RENDER_CONFIG, "--standalone", ndir.string(),
        "--listen", nginx_address()};
    for (const auto& r : replicas_) render.push_back(r.address());
    ASSERT_EQ(RunCommand(render, dir_ / "render.log"), 0)
        << ReadFile(dir_ / "render.log");
    ASSERT_EQ(RunCommand({*nginx, "-t", "-p", ndir.string() + "/", "-c",
                   (ndir / "nginx.conf").string(), "-e",
                   (ndir / "error.log").string()},
                  dir_ / "nginx-t.log"),
              0)
        << "nginx -t rejected the rendered config:\n"
        << ReadFile(dir_ / "nginx-t.log");
    nginx_ = std::make_unique<Process>(
        "nginx",
        std::vector<std::string>{*nginx, "-p", ndir.string() + "/", "-c",
                                 (ndir / "nginx.conf").string(), "-e",
                                 (ndir / "error.log").string()},
        dir_ / "nginx.log", SIGTERM);
    ASSERT_TRUE(nginx_->Start());
    ASSERT_TRUE(WaitHealthy(nginx_address(), nginx_.get()))
        << "nginx on " << nginx_address() << " did not pass health checks:\n"
        << nginx_->log() << ReadFile(ndir / "error.log");
  }

  std::string nginx_address() const {
    return "127.0.0.1:" + std::to_string(nginx_port_);
  }

  fs::path dir_;
  bool persistence_ = false;
  std::vector<Replica> replicas_;
  int nginx_port_ = 0;
  std::unique_ptr<Process> nginx_;
};

// What one session saw: the replica of each call, in order.
struct SessionLog {
  std::string id;
  int index = 0;
  int predicted = -1;  // replica index by the hash model
  std::vector<std::string> replicas;
  std::vector<double> heights;  // probed before the restart
  std::string replica() const { return replicas.empty() ? "" : replicas[0]; }
};

TEST_F(ClusterTest, SessionsStayOnTheirReplicaThroughNginxAndRestart) {
  const auto t0 = Clock::now();
  ASSERT_NO_FATAL_FAILURE(StartCluster());
  std::printf("cluster up in %.1f s: nginx %s, replicas", 
              std::chrono::duration<double>(Clock::now() - t0).count(),
              nginx_address().c_str());
  for (const auto& r : replicas_) std::printf(" %s", r.address().c_str());
  std::printf("; persistence (swarfd --data_dir): %s\n",
              persistence_ ? "yes" : "no");

  // Client-chosen ids, 4 per replica by nginx's hash (see ChashModel).
  std::vector<std::string> servers;
  for (const auto& r : replicas_) servers.push_back(r.address());
  const ChashModel model(servers);
  std::vector<SessionLog> sessions;
  std::array<int, kReplicas> per{};
  for (int n = 0; static_cast<int>(sessions.size()) < kSessions && n < 10000;
       ++n) {
    const std::string id = "job-" + std::to_string(n);
    const int r = model.ServerOf(id);
    if (per[r] == kSessions / kReplicas) continue;
    ++per[r];
    SessionLog s;
    s.id = id;
    s.index = static_cast<int>(sessions.size());
    s.predicted = r;
    sessions.push_back(s);
  }
  ASSERT_EQ(static_cast<int>(sessions.size()), kSessions);

  Client client(nginx_address());

  // Phase 1, all sessions concurrently: create, stream, read back.
  {
    std::vector<std::future<void>> work;
    for (SessionLog& s : sessions) {
      work.push_back(std::async(std::launch::async, [&client, &s] {
        std::string rep, problem;
        pb::Session session;
        grpc::Status st = client.Create(s.id, &session, &rep);
        ASSERT_TRUE(st.ok()) << s.id << " create: " << st.error_message();
        s.replicas.push_back(rep);
        EXPECT_EQ(session.replica(), rep) << s.id;

        rep.clear();
        st = client.Stream(s.id, s.index, 1, kBatchesBefore, &rep, &problem);
        ASSERT_TRUE(st.ok()) << s.id << " stream: " << st.error_message();
        EXPECT_EQ(problem, "") << s.id;
        s.replicas.push_back(rep);

        st = client.Get(s.id, &session, &rep);
        ASSERT_TRUE(st.ok()) << s.id << " get: " << st.error_message();
        s.replicas.push_back(rep);
        EXPECT_EQ(session.replica(), rep) << s.id;
        EXPECT_EQ(session.last_seq(), static_cast<uint64_t>(kBatchesBefore));
        EXPECT_EQ(session.moves_applied(),
                  int64_t{kBatchesBefore} * kPointsPerBatch - 1);

        int tiles = 0;
        st = client.Tiles(s.id, &tiles, &rep);
        ASSERT_TRUE(st.ok()) << s.id << " tiles: " << st.error_message();
        s.replicas.push_back(rep);
        EXPECT_EQ(tiles, session.tiles_x() * session.tiles_y()) << s.id;

        st = client.ProbeHeights(s.id, &s.heights, &rep);
        ASSERT_TRUE(st.ok()) << s.id << " probe: " << st.error_message();
        s.replicas.push_back(rep);
        EXPECT_LT(*std::min_element(s.heights.begin(), s.heights.end()), 0)
            << s.id << ": nothing was cut";
      }));
    }
    for (auto& w : work) w.get();
  }
  ASSERT_FALSE(HasFailure());

  // Every call of a session reached the same replica; all three are used.
  std::map<std::string, std::set<std::string>> by_replica;
  int model_agrees = 0;
  for (const SessionLog& s : sessions) {
    ASSERT_FALSE(s.replica().empty()) << s.id << ": no x-swarf-replica";
    for (const auto& r : s.replicas) {
      EXPECT_EQ(r, s.replica()) << s.id << " moved between replicas";
    }
    by_replica[s.replica()].insert(s.id);
    model_agrees += s.replica() == replicas_[s.predicted].name;
  }
  EXPECT_EQ(static_cast<int>(by_replica.size()), kReplicas)
      << "sessions did not spread over all replicas";
  std::printf("%d sessions over %zu replicas:", kSessions, by_replica.size());
  for (const auto& [r, ids] : by_replica) std::printf(" %s=%zu", r.c_str(), ids.size());
  std::printf(" (hash model agreed on %d of %d)\n", model_agrees, kSessions);

  // Each replica really holds exactly the sessions routed to it (asked
  // directly, not through nginx).
  for (const auto& r : replicas_) {
    Client direct(r.address());
    std::vector<std::string> ids;
    ASSERT_TRUE(direct.List(&ids).ok()) << r.name;
    const auto& want = by_replica[r.name];
    EXPECT_EQ(std::set<std::string>(ids.begin(), ids.end()), want) << r.name;
  }

  // Streams were counted per real client (swarfd trusts nginx's
  // x-real-ip, here 127.0.0.1), never per what the client claimed.
  for (const auto& r : replicas_) {
    const std::string log = r.process->log();
    if (by_replica[r.name].empty()) continue;
    EXPECT_NE(log.find("(client 127.0.0.1)"), std::string::npos) << r.name;
    EXPECT_EQ(log.find(std::string("client ") + kSpoofedIp),
              std::string::npos)
        << r.name << " believed a client's own x-real-ip";
  }

  // Phase 2: stop the replica of the first session.
  const std::string victim_name = sessions[0].replica();
  Replica* victim = nullptr;
  for (auto& r : replicas_) {
    if (r.name == victim_name) victim = &r;
  }
  ASSERT_NE(victim, nullptr);
  EXPECT_TRUE(victim->process->Stop(15s))
      << victim->name << " did not drain and stop on SIGTERM";
  std::printf("stopped %s\n", victim->name.c_str());

  // The others are unaffected: they continue where they were.
  for (const SessionLog& s : sessions) {
    if (s.replica() == victim_name) continue;
    std::string rep, problem;
    grpc::Status st = client.Stream(s.id, s.index, kBatchesBefore + 1,
                                    kBatchesBefore + 1, &rep, &problem);
    ASSERT_TRUE(st.ok()) << s.id << ": " << st.error_message();
    EXPECT_EQ(problem, "") << s.id;
    EXPECT_EQ(rep, s.replica()) << s.id;
    pb::Session session;
    ASSERT_TRUE(client.Get(s.id, &session, &rep).ok()) << s.id;
    EXPECT_EQ(rep, s.replica()) << s.id;
    EXPECT_EQ(session.last_seq(), static_cast<uint64_t>(kBatchesBefore + 1));
  }
  // The stopped replica's sessions are not moved elsewhere: UNAVAILABLE.
  for (const SessionLog& s : sessions) {
    if (s.replica() != victim_name) continue;
    std::string rep;
    pb::Session session;
    grpc::Status st = client.Get(s.id, &session, &rep);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAVAILABLE)
        << s.id << " while its replica is down: " << st.error_message()
        << " (from " << rep << ")";
    // From the balancer's error_page (a gRPC status, not an HTML page).
    EXPECT_EQ(st.error_message(), "swarf replica unavailable") << s.id;
  }
  // Calls without a session still find a replica.
  EXPECT_TRUE(WaitHealthy(nginx_address(), nginx_.get(), 5s))
      << "health through nginx with a replica down";

  // Phase 3: start it again on its port and data directory.
  ASSERT_NO_FATAL_FAILURE(StartReplica(*victim));
  std::printf("restarted %s\n", victim->name.c_str());

  for (const SessionLog& s : sessions) {
    if (s.replica() != victim_name) continue;
    std::string rep, problem;
    pb::Session session;
    grpc::Status st = client.Get(s.id, &session, &rep);
    if (persistence_) {
      // READY CHECK (persistence): the session came back where it was...
      ASSERT_TRUE(st.ok()) << s.id << " after the restart: "
                           << st.error_message();
      EXPECT_EQ(rep, victim_name) << s.id;
      EXPECT_EQ(session.last_seq(), static_cast<uint64_t>(kBatchesBefore))
          << s.id;
      // The SIGTERM drain snapshotted it: the restart replayed nothing.
      EXPECT_EQ(session.snapshot_seq(), static_cast<uint64_t>(kBatchesBefore))
          << s.id;
      EXPECT_EQ(session.moves_applied(),
                int64_t{kBatchesBefore} * kPointsPerBatch - 1)
          << s.id;
      std::vector<double> heights;
      ASSERT_TRUE(client.ProbeHeights(s.id, &heights, &rep).ok()) << s.id;
      EXPECT_EQ(heights, s.heights) << s.id << ": surface changed";
      // ...and continues.
      st = client.Stream(s.id, s.index, kBatchesBefore + 1, kBatchesBefore + 1,
                         &rep, &problem);
      ASSERT_TRUE(st.ok()) << s.id << ": " << st.error_message();
      EXPECT_EQ(problem, "") << s.id;
      EXPECT_EQ(rep, victim_name) << s.id;
    } else {
      // No persistence yet: the session is gone from the restarted replica,
      // but its id still routes there and the replica serves again.
      EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND)
          << s.id << ": " << st.error_message();
      pb::Session created;
      st = client.Create(s.id, &created, &rep);
      ASSERT_TRUE(st.ok()) << s.id << " re-create: " << st.error_message();
      EXPECT_EQ(rep, victim_name) << s.id;
      rep.clear();
      st = client.Stream(s.id, s.index, 1, kBatchesBefore + 1, &rep, &problem);
      ASSERT_TRUE(st.ok()) << s.id << ": " << st.error_message();
      EXPECT_EQ(problem, "") << s.id;
      EXPECT_EQ(rep, victim_name) << s.id;
    }
  }

  // Finally every session is where it was, at the same point.
  for (const SessionLog& s : sessions) {
    std::string rep;
    pb::Session session;
    grpc::Status st = client.Get(s.id, &session, &rep);
    ASSERT_TRUE(st.ok()) << s.id << ": " << st.error_message();
    EXPECT_EQ(rep, s.replica()) << s.id;
    EXPECT_EQ(session.last_seq(), static_cast<uint64_t>(kBatchesBefore + 1))
        << s.id;
  }
  std::printf("restart checked (%s) in %.1f s total\n",
              persistence_ ? "sessions restored and continued"
                           : "no persistence: others unaffected, replica "
                             "serves its ids again",
              std::chrono::duration<double>(Clock::now() - t0).count());
}

}  // namespace
