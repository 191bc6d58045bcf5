// End-to-end throughput: a long finishing path streamed through a running
// server on loopback TCP, against applying the same batches in-process.
// Run: build/bin/swarf_stream_bench [--benchmark_filter=...]
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>
#include <unistd.h>
#include <thread>
#include <vector>

#include "core/workpiece.h"
#include "grpcpp/grpcpp.h"
#include "server/registry.h"
#include "server/server.h"
#include "swarf/v1/swarf.grpc.pb.h"

namespace swarf {
namespace {

namespace pb = ::swarf::v1;

constexpr double kBallRadius = 0.5;  // a 1 mm ball
const StockSpec kStock{0, 0, 100, 100, 0, 1000, 1000};

// A zig-zag finishing raster of 0.1 mm moves over a gentle wave: about
// `moves` tip positions.
std::vector<Vec3> Raster(int64_t moves) {
  const double step = 0.1, x_min = 5, x_max = 95;
  const int64_t per_row = static_cast<int64_t>((x_max - x_min) / step);
  const int64_t rows = (moves + per_row - 1) / per_row;
  const double stepover = 90.0 / rows;
  std::vector<Vec3> pts;
  pts.reserve(moves + 1);
  for (int64_t r = 0; r < rows && static_cast<int64_t>(pts.size()) <= moves;
       ++r) {
    const double y = 5 + r * stepover;
    for (int64_t k = 0; k < per_row && static_cast<int64_t>(pts.size()) <= moves;
         ++k) {
      const double s = x_min + k * step;
      const double x = r % 2 == 0 ? s : x_max - (s - x_min);
      pts.push_back({x, y, -1 + 0.3 * std::sin(x * 0.2 + y * 0.1)});
    }
  }
  return pts;
}

// In-process: the same polyline cut through Workpiece::Apply in batches.
void BM_InProcess(benchmark::State& state) {
  const int64_t moves = state.range(0), batch = state.range(1);
  const std::vector<Vec3> pts = Raster(moves);
  for (auto _ : state) {
    state.PauseTiming();
    auto wp = *Workpiece::Create(kStock, SchemeKind::kTaylor);
    std::vector<Move> buf;
    state.ResumeTiming();
    for (size_t k = 1; k < pts.size(); k += batch) {
      buf.clear();
      for (size_t p = k; p < std::min(pts.size(), k + batch); ++p) {
        buf.push_back({pts[p - 1], pts[p], kBallRadius});
      }
      benchmark::DoNotOptimize(wp->Apply(buf)->node_lowerings);
    }
    state.PauseTiming();
    wp.reset();
    state.ResumeTiming();
  }
  state.counters["moves_per_s"] = benchmark::Counter(
      static_cast<double>(pts.size() - 1),
      benchmark::Counter::kIsIterationInvariantRate);
}

// A swarfd in this process on 127.0.0.1 and a client of it.
struct Loopback {
  std::unique_ptr<server::SwarfServer> server;
  std::unique_ptr<pb::Swarf::Stub> stub;
};

Loopback StartLoopback() {
  server::ServerOptions opt;
  opt.listen = "127.0.0.1:0";
  Loopback loop;
  loop.server = *server::SwarfServer::Start(opt);
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  loop.stub = pb::Swarf::NewStub(grpc::CreateCustomChannel(
      "127.0.0.1:" + std::to_string(loop.server->port()),
      grpc::InsecureChannelCredentials(), args));
  return loop;
}

// A taylor session `id` of kStock with tool 1 (the ball); false if refused.
bool CreateBenchSession(pb::Swarf::Stub* stub, const std::string& id) {
  pb::CreateSessionRequest create;
  create.set_session_id(id);
  create.mutable_stock()->set_x1(kStock.x1);
  create.mutable_stock()->set_y1(kStock.y1);
  create.set_nx(kStock.nx);
  create.set_ny(kStock.ny);
  create.set_scheme(pb::SCHEME_TAYLOR);
  pb::Tool* tool = create.add_tools();
  tool->set_id(1);
  tool->mutable_ball()->set_radius(kBallRadius);
  grpc::ClientContext ctx;
  pb::Session session;
  return stub->CreateSession(&ctx, create, &session).ok();
}

void DeleteBenchSession(pb::Swarf::Stub* stub, const std::string& id) {
  grpc::ClientContext ctx;
  pb::DeleteSessionRequest del;
  del.set_session_id(id);
  pb::DeleteSessionResponse resp;
  stub->DeleteSession(&ctx, del, &resp);
}

// The polyline as Simulate requests of `batch` points, seq 1, 2, ...; each
// batch continues from the last point (the first point of the first batch
// is only the start).
std::vector<pb::SimulateRequest> MoveBatches(const std::vector<Vec3>& pts,
                                             size_t batch) {
  std::vector<pb::SimulateRequest> reqs;
  uint64_t seq = 0;
  for (size_t k = 0; k < pts.size(); k += batch) {
    pb::MoveBatch* b = reqs.emplace_back().mutable_moves();
    b->set_seq(++seq);
    b->set_tool_id(1);
    for (size_t p = k; p < std::min(pts.size(), k + batch); ++p) {
      b->add_xyz(pts[p].x);
      b->add_xyz(pts[p].y);
      b->add_xyz(pts[p].z);
    }
  }
  return reqs;
}

// End to end: a client streams the batches to swarfd over 127.0.0.1 (one
// thread writing, one reading acks) until the last batch is acknowledged.
void BM_EndToEnd(benchmark::State& state) {
  const int64_t moves = state.range(0), batch = state.range(1);
  const std::vector<Vec3> pts = Raster(moves);
  const Loopback loop = StartLoopback();
  pb::Swarf::Stub* const stub = loop.stub.get();
  int run = 0;
  for (auto _ : state) {
    state.PauseTiming();
    const std::string id = "bench-" + std::to_string(run++);
    if (!CreateBenchSession(stub, id)) {
      state.SkipWithError("CreateSession failed");
    }
    // Requests are built before timing: the client's own work is not the
    // server's throughput.
    const std::vector<pb::SimulateRequest> reqs = MoveBatches(pts, batch);
    const uint64_t seq = reqs.size();
    state.ResumeTiming();
    grpc::ClientContext ctx;
    ctx.AddMetadata("x-swarf-session", id);
    auto stream = stub->Simulate(&ctx);
    std::thread writer([&] {
      for (const auto& r : reqs) stream->Write(r);
      stream->WritesDone();
    });
    pb::SimulateResponse resp;
    uint64_t acked = 0;
    while (stream->Read(&resp)) {
      if (resp.has_ack()) acked = resp.ack().seq();
    }
    writer.join();
    grpc::Status st = stream->Finish();
    if (!st.ok() || acked != seq) {
      state.SkipWithError(("stream failed: " + st.error_message()).c_str());
    }
    state.PauseTiming();
    DeleteBenchSession(stub, id);
    state.ResumeTiming();
  }
  state.counters["moves_per_s"] = benchmark::Counter(
      static_cast<double>(pts.size() - 1),
      benchmark::Counter::kIsIterationInvariantRate);
}

// Tile reads as a client sees them: a session of `moves` finishing moves
// (taylor, 1000x1000) streamed in first, then every tile of the stock read
// with one GetTiles (floats; with derivatives and owners when range(1) is
// 1). Each iteration reads a freshly cut session, so no tile's derivatives
// were computed before (the first read of each tile version).
void BM_GetTiles(benchmark::State& state) {
  const int64_t moves = state.range(0);
  const bool derivatives = state.range(1) != 0;
  const std::vector<Vec3> pts = Raster(moves);
  const Loopback loop = StartLoopback();
  pb::Swarf::Stub* const stub = loop.stub.get();
  int run = 0;
  int64_t tiles = 0, bytes = 0;
  for (auto _ : state) {
    state.PauseTiming();
    const std::string id = "tiles-" + std::to_string(run++);
    if (!CreateBenchSession(stub, id)) {
      state.SkipWithError("CreateSession failed");
    }
    {
      grpc::ClientContext ctx;
      ctx.AddMetadata("x-swarf-session", id);
      auto stream = stub->Simulate(&ctx);
      for (const auto& r : MoveBatches(pts, 10000)) stream->Write(r);
      stream->WritesDone();
      pb::SimulateResponse resp;
      while (stream->Read(&resp)) {
      }
      if (!stream->Finish().ok()) state.SkipWithError("stream failed");
    }
    pb::GetTilesRequest req;
    req.set_session_id(id);
    pb::Rect* region = req.mutable_selection()->mutable_region();
    region->set_x1(kStock.x1);
    region->set_y1(kStock.y1);
    req.set_precision(pb::PRECISION_FLOAT);
    req.set_include_derivatives(derivatives);
    req.set_include_owners(derivatives);
    state.ResumeTiming();
    grpc::ClientContext ctx;
    auto reader = stub->GetTiles(&ctx, req);
    pb::Tile tile;
    tiles = 0;
    bytes = 0;
    while (reader->Read(&tile)) {
      ++tiles;
      bytes += static_cast<int64_t>(tile.ByteSizeLong());
    }
    if (!reader->Finish().ok()) state.SkipWithError("GetTiles failed");
    state.PauseTiming();
    DeleteBenchSession(stub, id);
    state.ResumeTiming();
  }
  state.counters["tiles"] = static_cast<double>(tiles);
  state.counters["MB"] = static_cast<double>(bytes) / 1e6;
}
BENCHMARK(BM_GetTiles)
    ->Args({100000, 1})
    ->Args({100000, 0})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// Restart: a journaled session of `moves` moves is restored (what swarfd
// does at start) from its journal and, with snapshots every `every` moves
// (0: none), from its last snapshot plus the batches after it. Reports the
// restore time, and the batch the snapshot held.
void BM_Restart(benchmark::State& state) {
  const int64_t moves = state.range(0), batch = state.range(1);
  server::Persistence persistence{
      "/tmp/swarf-restart-bench-" + std::to_string(::getpid()),
      server::JournalSync::kNormal, state.range(2)};
  const std::vector<Vec3> pts = Raster(moves);
  std::filesystem::remove_all(persistence.data_dir);
  {
    server::Registry r(server::Limits{}, persistence);
    (void)r.RestoreAll();
    server::SessionSpec spec;
    spec.id = "long-job";
    spec.stock = kStock;
    spec.tools = {{1, Cutter::Ball(kBallRadius), {}}};
    auto s = *r.Create(spec);
    std::vector<double> xyz;
    uint64_t seq = 0;
    for (size_t k = 0; k < pts.size(); k += batch) {
      xyz.clear();
      for (size_t p = k; p < std::min(pts.size(), k + batch); ++p) {
        xyz.insert(xyz.end(), {pts[p].x, pts[p].y, pts[p].z});
      }
      if (!s->ApplyBatch(++seq, 1, xyz, batch).ok()) {
        state.SkipWithError("batch failed");
      }
    }
  }
  uint64_t snapshot_seq = 0, last_seq = 0;
  for (auto _ : state) {
    server::Registry r(server::Limits{}, persistence);
    auto restored = r.RestoreAll();
    if (!restored.ok() || *restored != 1) state.SkipWithError("not restored");
    state.PauseTiming();
    const server::SessionState st = (*r.Get("long-job"))->State();
    snapshot_seq = st.snapshot_seq;
    last_seq = st.last_seq;
    state.ResumeTiming();
  }
  state.counters["moves"] = static_cast<double>(pts.size() - 1);
  state.counters["batches"] = static_cast<double>(last_seq);
  state.counters["snapshot_at"] = static_cast<double>(snapshot_seq);
  std::filesystem::remove_all(persistence.data_dir);
}
// Moves, moves per batch, snapshot every (0: never).
BENCHMARK(BM_Restart)
    ->Args({1000000, 10000, 0})
    ->Args({1000000, 10000, 1000000})
    ->Args({1000000, 10000, 600000})
    ->Args({5000000, 10000, 0})
    ->Args({5000000, 10000, 1000000})
    ->Args({5500000, 10000, 1000000})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3);

BENCHMARK(BM_InProcess)
    ->Args({1000000, 10000})
    ->Args({1000000, 50000})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3);
BENCHMARK(BM_EndToEnd)
    ->Args({1000000, 10000})
    ->Args({1000000, 50000})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(3);

}  // namespace
}  // namespace swarf

BENCHMARK_MAIN();
