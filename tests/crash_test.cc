// Durable sessions with real processes: swarfd is killed with SIGKILL in the
// middle of a streamed job (several times, at seeded random points),
// restarted on its data directory, and the client resumes. Nothing that was
// acknowledged is lost, and the final heights, derivatives and owners are
// bit-identical to an uninterrupted run of the same moves. Snapshots are
// written every 5 batches, so restarts load one and replay the tail (and a
// kill may land in the middle of writing one).
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "core/workpiece.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "swarf/v1/swarf.grpc.pb.h"
#include "tests/swarfd_process.h"

namespace swarf {
namespace {

namespace pb = ::swarf::v1;
namespace fs = std::filesystem;
using ::swarf::testing::SwarfdProcess;

constexpr double kRadius = 0.5;
const StockSpec kStock{0, 0, 20, 20, 0, 200, 200};
constexpr int kBatches = 240;
constexpr int kPointsPerBatch = 400;

// A zig-zag finishing raster over a wave, as tip positions.
std::vector<Vec3> Path() {
  std::vector<Vec3> pts;
  const int total = kBatches * kPointsPerBatch;
  const int per_row = 190;
  for (int k = 0; static_cast<int>(pts.size()) < total; ++k) {
    const int row = k / per_row, col = k % per_row;
    const double y = 1 + 0.05 * row;
    const double x = 1 + 0.1 * (row % 2 == 0 ? col : per_row - 1 - col);
    pts.push_back({x, std::fmod(y, 18) + 1,
                   -0.6 + 0.2 * std::sin(0.7 * x + 0.3 * y)});
  }
  return pts;
}

pb::SimulateRequest Batch(const std::vector<Vec3>& pts, int seq) {
  pb::SimulateRequest r;
  pb::MoveBatch* b = r.mutable_moves();
  b->set_seq(seq);
  b->set_tool_id(1);
  for (int k = (seq - 1) * kPointsPerBatch; k < seq * kPointsPerBatch; ++k) {
    b->add_xyz(pts[k].x);
    b->add_xyz(pts[k].y);
    b->add_xyz(pts[k].z);
  }
  return r;
}

// How the test runs swarfd: snapshots every 5 batches.
const std::vector<std::string> kFlags = {
    "--journal_sync=full", "--worker_threads=2", "--snapshot_every_moves=2000"};

std::unique_ptr<pb::Swarf::Stub> Stub(int port) {
  return pb::Swarf::NewStub(grpc::CreateChannel(
      "127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials()));
}

std::unique_ptr<grpc::ClientContext> Ctx(const std::string& id) {
  auto ctx = std::make_unique<grpc::ClientContext>();
  ctx->AddMetadata("x-swarf-session", id);
  // A round streams up to 240 batches, each fsynced (--journal_sync=full),
  // with a snapshot every 5: generous for a slow disk under a loaded
  // sanitizer run.
  ctx->set_deadline(std::chrono::system_clock::now() +
                    std::chrono::seconds(300));
  return ctx;
}

TEST(CrashTest, KilledServerLosesNothingAcknowledgedAndEndsBitIdentical) {
  const fs::path dir = fs::temp_directory_path() /
                       ("swarf-crash-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string data = (dir / "data").string();
  int starts = 0;
  auto log = [&] { return (dir / ("log" + std::to_string(++starts))).string(); };
  // A failure shows what every swarfd it started logged.
  struct PrintLogsOnFailure {
    const fs::path& dir;
    const int& starts;
    ~PrintLogsOnFailure() {
      if (!::testing::Test::HasFailure()) return;
      for (int k = 1; k <= starts; ++k) {
        const std::string name = "log" + std::to_string(k);
        std::printf(
            "---- swarfd %s ----\n%s\n", name.c_str(),
            swarf::testing::ReadFileText((dir / name).string()).c_str());
      }
    }
  } print_logs{dir, starts};
  const std::vector<Vec3> pts = Path();
  const std::string id = "crash-job";

  auto server = std::make_unique<SwarfdProcess>(data, log(), kFlags);
  ASSERT_GT(server->port(), 0) << "swarfd did not start";
  {
    pb::CreateSessionRequest req;
    req.set_session_id(id);
    req.mutable_stock()->set_x1(kStock.x1);
    req.mutable_stock()->set_y1(kStock.y1);
    req.set_nx(kStock.nx);
    req.set_ny(kStock.ny);
    req.set_scheme(pb::SCHEME_TAYLOR);
    pb::Tool* t = req.add_tools();
    t->set_id(1);
    t->mutable_ball()->set_radius(kRadius);
    pb::Session s;
    const grpc::Status st =
        Stub(server->port())->CreateSession(Ctx(id).get(), req, &s);
    ASSERT_TRUE(st.ok()) << st.error_code() << ": " << st.error_message();
  }

  std::mt19937 rng(20261121);
  int next_seq = 1;
  for (int round = 0; round < 4 && next_seq <= kBatches; ++round) {
    const bool last = round == 3;
    // Kill right after a random ack, with more batches in flight.
    const int kill_after =
        last ? kBatches + 1
             : next_seq + 10 + static_cast<int>(rng() % 40);
    auto stub = Stub(server->port());
    auto ctx = Ctx(id);
    auto stream = stub->Simulate(ctx.get());
    std::thread writer([&, from = next_seq] {
      for (int seq = from; seq <= kBatches; ++seq) {
        if (!stream->Write(Batch(pts, seq))) break;
      }
      stream->WritesDone();
    });
    int last_acked = next_seq - 1;
    pb::SimulateResponse resp;
    while (stream->Read(&resp)) {
      if (resp.has_ack()) {
        EXPECT_EQ(resp.ack().seq(), static_cast<uint64_t>(last_acked + 1));
        last_acked = static_cast<int>(resp.ack().seq());
        if (last_acked == kill_after) {
          server->Kill();  // SIGKILL: no chance to flush anything
          break;
        }
      }
    }
    ctx->TryCancel();
    writer.join();
    const grpc::Status finished = stream->Finish();
    if (last) {
      ASSERT_EQ(last_acked, kBatches)
          << "the stream ended: " << finished.error_code() << ": "
          << finished.error_message();
      break;
    }
    // Not killed: the stream failed before the ack it waited for.
    ASSERT_EQ(last_acked, kill_after)
        << "round " << round << ": the stream ended: " << finished.error_code()
        << ": " << finished.error_message();
    server = std::make_unique<SwarfdProcess>(data, log(), kFlags);
    ASSERT_GT(server->port(), 0) << "swarfd did not restart";
    pb::Session s;
    pb::GetSessionRequest get;
    get.set_session_id(id);
    const grpc::Status got =
        Stub(server->port())->GetSession(Ctx(id).get(), get, &s);
    ASSERT_TRUE(got.ok()) << got.error_code() << ": " << got.error_message();
    // Everything acknowledged survived; a batch in flight may have too.
    EXPECT_GE(s.last_seq(), static_cast<uint64_t>(last_acked)) << "round "
                                                                << round;
    EXPECT_EQ(s.recovery(), "");
    // The kill really came mid-stream: acknowledged work was at stake.
    EXPECT_GT(last_acked, next_seq);
    // The restart loaded a snapshot rather than replaying everything.
    std::ifstream in(dir / ("log" + std::to_string(starts)));
    const std::string text((std::istreambuf_iterator<char>(in)),
                           std::istreambuf_iterator<char>());
    std::smatch m;
    ASSERT_TRUE(std::regex_search(
        text, m, std::regex(R"(from the snapshot at batch (\d+), (\d+) batches replayed)")))
        << text;
    EXPECT_GE(s.snapshot_seq(), std::stoull(m[1].str()));
    EXPECT_LE(s.snapshot_seq(), s.last_seq());
    std::printf(
        "round %d: killed after ack %d, restored at batch %d from the "
        "snapshot at batch %s (%s replayed)\n",
        round, last_acked, static_cast<int>(s.last_seq()), m[1].str().c_str(),
        m[2].str().c_str());
    next_seq = static_cast<int>(s.last_seq()) + 1;
  }

  // The same moves, uninterrupted, in the core.
  auto ref = *Workpiece::Create(kStock, SchemeKind::kTaylor);
  std::vector<Move> moves;
  for (size_t k = 1; k < pts.size(); ++k) {
    moves.push_back({pts[k - 1], pts[k], kRadius});
  }
  ASSERT_TRUE(ref->Apply(moves).ok());

  pb::GetTilesRequest req;
  req.set_session_id(id);
  req.set_precision(pb::PRECISION_DOUBLE);
  req.set_include_derivatives(true);
  req.set_include_owners(true);
  auto ctx = Ctx(id);
  auto reader = Stub(server->port())->GetTiles(ctx.get(), req);
  pb::Tile t;
  int tiles = 0;
  while (reader->Read(&t)) {
    const int32_t index = t.ty() * ref->tiles_x() + t.tx();
    const Workpiece::TileExtent e = ref->Extent(index);
    const int n = e.nx * e.ny;
    std::vector<double> w(n);
    std::vector<int32_t> owner(n);
    std::vector<float> d(5 * n);
    float* dp[5];
    for (int c = 0; c < 5; ++c) dp[c] = d.data() + c * n;
    ref->ReadTile(index, w.data(), dp, owner.data());
    ASSERT_EQ(t.heights_d_size(), n);
    for (int k = 0; k < n; ++k) {
      const double got = t.heights_d(k);
      ASSERT_EQ(std::memcmp(&w[k], &got, 8), 0) << "tile " << index;
      ASSERT_EQ(owner[k], t.owners(k));
      ASSERT_EQ(dp[0][k], t.wx(k));
      ASSERT_EQ(dp[2][k], t.wxx(k));
      ASSERT_EQ(dp[4][k], t.wyy(k));
    }
    ++tiles;
  }
  const grpc::Status read = reader->Finish();
  ASSERT_TRUE(read.ok()) << read.error_code() << ": " << read.error_message();
  EXPECT_EQ(tiles, ref->tile_count());
  server->Kill();
  if (!::testing::Test::HasFailure()) fs::remove_all(dir);  // keep logs
}

}  // namespace
}  // namespace swarf
