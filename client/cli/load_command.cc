// swarf load: many sessions streaming at once against a server, to measure
// throughput, acknowledgement latency and the server's memory.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_format.h"
#include "client/cli/args.h"
#include "client/cli/commands.h"
#include "client/cli/connection.h"
#include "client/cli/tool_table.h"
#include "server/convert.h"

namespace swarf::cli {
namespace {

using Clock = std::chrono::steady_clock;

constexpr char kUsage[] =
    "usage: swarf load [--server HOST:PORT] [--sessions N] [--moves N]\n"
    "                  [--batch N] [--mesh N] [--tool SHAPE:KEYS] [--token T]\n"
    "                  [--tls-ca F ...]\n"
    "Streams a finishing raster (0.1 mm moves; --tool as for swarf run,\n"
    "default ball:d=1) into N sessions\n"
    "at once (default 32 sessions of 100000 moves, batches of 2000, grids of\n"
    "300 x 300) and reports the throughput (the batches are made before the\n"
    "clock starts), the p50/p99 time from sending a batch to its\n"
    "acknowledgement, the errors and the server's peak memory.\n"
    "The throughput and latencies count only the sessions that succeeded;\n"
    "any that failed are counted and named, and the exit code is 1.\n"
    "Without --server it loads an embedded server, which admits N streams\n"
    "and N sessions from this one client.\n";

struct Result {
  int64_t moves = 0;
  std::vector<double> latencies;  // seconds
  std::string error;
};

// One session's batches: a zig-zag raster, rows of 0.1 mm moves across a
// mesh x mesh grid of 0.1 mm, `moves` moves in batches of `batch`.
std::vector<pb::SimulateRequest> RasterBatches(int64_t moves, int64_t batch,
                                               int32_t mesh) {
  const double side = mesh * 0.1;
  const int64_t per_row = std::max<int64_t>(2, mesh - 10);
  std::vector<pb::SimulateRequest> reqs;
  for (int64_t k = 0, seq = 1; k <= moves; ++seq) {
    pb::MoveBatch* b = reqs.emplace_back().mutable_moves();
    b->set_seq(seq);
    b->set_tool_id(1);
    // A batch past protobuf's int sizes is the server's to refuse.
    b->mutable_xyz()->Reserve(static_cast<int>(std::min<int64_t>(
        3 * std::min(batch, moves + 1 - k), std::numeric_limits<int>::max())));
    for (int64_t n = 0; n < batch && k <= moves; ++n, ++k) {
      const int64_t row = k / per_row, col = k % per_row;
      const double x = 0.5 + 0.1 * (row % 2 == 0 ? col : per_row - 1 - col);
      const double y = 0.5 + std::fmod(0.05 * row, side - 1);
      b->add_xyz(x);
      b->add_xyz(y);
      b->add_xyz(-0.5 + 0.2 * std::sin(0.5 * x + 0.3 * y));
    }
  }
  return reqs;
}

// One session's job: create, stream `reqs` (RasterBatches), delete.
void RunSession(Connection& conn, const std::string& id, const Cutter& cutter,
                const std::vector<pb::SimulateRequest>& reqs, int32_t mesh,
                Result* out) {
  pb::CreateSessionRequest create;
  create.set_session_id(id);
  const double side = mesh * 0.1;
  create.mutable_stock()->set_x1(side);
  create.mutable_stock()->set_y1(side);
  create.set_nx(mesh);
  create.set_ny(mesh);
  server::ToolToProto({1, cutter, {}}, create.add_tools());  // no assembly
  {
    pb::Session s;
    auto ctx = conn.Context(id, 60);
    grpc::Status st = conn.stub().CreateSession(ctx.get(), create, &s);
    if (!st.ok()) {
      out->error = "create: " + st.error_message();
      return;
    }
  }
  std::vector<Clock::time_point> sent(reqs.size());
  std::mutex mu;
  auto ctx = conn.Context(id, 3600);
  auto stream = conn.stub().Simulate(ctx.get());
  std::thread writer([&] {
    for (size_t k = 0; k < reqs.size(); ++k) {
      {
        std::lock_guard<std::mutex> l(mu);
        sent[k] = Clock::now();
      }
      if (!stream->Write(reqs[k])) break;
    }
    stream->WritesDone();
  });
  pb::SimulateResponse resp;
  uint64_t acked = 0;
  int64_t applied = 0;
  while (stream->Read(&resp)) {
    if (resp.has_ack()) {
      const auto now = Clock::now();
      acked = resp.ack().seq();
      applied = resp.ack().moves_applied();
      std::lock_guard<std::mutex> l(mu);
      out->latencies.push_back(
          std::chrono::duration<double>(now - sent[acked - 1]).count());
    } else if (resp.has_error()) {
      out->error = "batch: " + resp.error().message();
    }
  }
  writer.join();
  grpc::Status st = stream->Finish();
  if (!st.ok() && out->error.empty()) out->error = "stream: " + st.error_message();
  if (acked != reqs.size() && out->error.empty()) out->error = "not all acked";
  out->moves = applied;
  pb::DeleteSessionRequest del;
  del.set_session_id(id);
  pb::DeleteSessionResponse dresp;
  auto dctx = conn.Context(id, 60);
  conn.stub().DeleteSession(dctx.get(), del, &dresp);
}

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * v.size()))];
}

}  // namespace

int LoadCommand(const std::vector<std::string>& argv) {
  std::set<std::string> valued = {"server", "sessions", "moves", "batch",
                                  "mesh", "tool"};
  valued.insert(std::begin(kConnectionFlags), std::end(kConnectionFlags));
  auto args = Args::Parse(argv, valued, {"help"});
  if (!args.ok()) {
    std::cerr << "swarf load: " << args.status().message() << "\n" << kUsage;
    return 2;
  }
  if (args->Has("help")) {
    std::cout << kUsage;
    return 0;
  }
  auto sessions = args->GetInt("sessions");
  auto moves = args->GetInt("moves");
  auto batch = args->GetInt("batch");
  auto mesh = args->GetInt("mesh");
  for (const auto* v : {&sessions, &moves, &batch, &mesh}) {
    if (!v->ok()) {
      std::cerr << "swarf load: " << v->status().message() << "\n";
      return 2;
    }
    if (v->value().has_value() && **v <= 0) {
      std::cerr << "swarf load: counts must be positive\n";
      return 2;
    }
  }
  auto tool = ParseToolOption(args->Get("tool").value_or("ball:d=1"));
  if (!tool.ok()) {
    std::cerr << "swarf load: " << tool.status().message() << "\n";
    return 2;
  }
  const int n = sessions->value_or(32);
  const int64_t m = moves->value_or(100000);
  const int64_t b = batch->value_or(2000);
  const int32_t g = mesh->value_or(300);
  auto copt = ConnectionOptionsFrom(*args);
  if (!copt.ok()) {
    std::cerr << "swarf load: " << copt.status().message() << "\n";
    return 2;
  }
  // One connection per session, as independent clients would have.
  std::vector<std::unique_ptr<Connection>> conns;
  std::unique_ptr<Connection> embedded;
  if (!args->Has("server")) {
    // Every session comes over one in-process channel, so the embedded
    // server sees one client: it must admit N streams (its default, for a
    // shared swarfd, is 16 a client) and N sessions.
    server::Limits limits;
    limits.max_streams_per_client =
        std::max(limits.max_streams_per_client, n);
    limits.max_sessions = std::max(limits.max_sessions, n);
    copt->embedded_limits = limits;
    auto c = Connection::Open("", *copt);
    if (!c.ok()) {
      std::cerr << "swarf load: " << c.status().message() << "\n";
      return 1;
    }
    embedded = *std::move(c);
  } else {
    for (int k = 0; k < n; ++k) {
      auto c = Connection::Open(*args->Get("server"), *copt);
      if (!c.ok()) {
        std::cerr << "swarf load: " << c.status().message() << "\n";
        return 1;
      }
      conns.push_back(*std::move(c));
    }
  }
  std::vector<Result> results(n);
  std::mt19937_64 rng(std::random_device{}());
  const std::string tag = absl::StrFormat("%08x", rng() & 0xffffffff);
  // Each session's batches are made before the clock starts, a session a
  // thread: the throughput is the streaming's, not the making of the
  // raster's points. A copy each: one message written by several streams
  // at once would share its cached sizes.
  std::vector<std::vector<pb::SimulateRequest>> reqs(n);
  {
    std::vector<std::thread> makers;
    for (int k = 0; k < n; ++k) {
      makers.emplace_back([&, k] { reqs[k] = RasterBatches(m, b, g); });
    }
    for (auto& t : makers) t.join();
  }
  const auto t0 = Clock::now();
  std::vector<std::thread> threads;
  for (int k = 0; k < n; ++k) {
    Connection& c = embedded ? *embedded : *conns[k];
    threads.emplace_back([&, k, &c = c] {
      RunSession(c, absl::StrFormat("load-%s-%d", tag, k), tool->cutter,
                 reqs[k], g, &results[k]);
    });
  }
  for (auto& t : threads) t.join();
  const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();

  // Only the sessions that succeeded count: a failed one's moves were not
  // all applied (or not at all), and its latencies are of a broken stream.
  int64_t total = 0;
  int errors = 0;
  std::vector<double> lat;
  for (const Result& r : results) {
    if (!r.error.empty()) {
      ++errors;
      std::cerr << "swarf load: " << r.error << "\n";
      continue;
    }
    total += r.moves;
    lat.insert(lat.end(), r.latencies.begin(), r.latencies.end());
  }
  Connection& c = embedded ? *embedded : *conns[0];
  pb::ListSessionsResponse list;
  auto ctx = c.Context("", 10);
  c.stub().ListSessions(ctx.get(), {}, &list);
  std::cout << absl::StrFormat(
      "%d sessions x %d moves (batches of %d, %dx%d grids, %s) on the %s\n"
      "  throughput  %.2fM moves/s (%d moves of the %d sessions that "
      "succeeded, in %.2f s)\n"
      "  ack latency p50 %.1f ms, p99 %.1f ms (%d batches)\n"
      "  errors      %d of %d sessions failed\n"
      "  server peak memory %.0f MiB\n",
      n, m, b, g, g, CutterSummary(tool->cutter), c.target(),
      total / seconds / 1e6, total, n - errors, seconds,
      1e3 * Percentile(lat, 0.5), 1e3 * Percentile(lat, 0.99), lat.size(),
      errors, n, list.server_peak_memory_bytes() / 1048576.0);
  return errors == 0 ? 0 : 1;
}

}  // namespace swarf::cli
