// The cutting marks served with bounded memory (issue 28): GetCuttingMarks
// writes the polylines as the search finds them, the search waiting for a
// slow client and stopping for a gone one, on a thread of its own; a
// Simulate MarksRequest stops its search once the answer passes the message
// limit. The real server on a loopback port against the core run directly.

#include <algorithm>
#include <bit>
#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "core/cutting_marks.h"
#include "core/workpiece.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "server/server.h"
#include "server/service.h"
#include "spdlog/spdlog.h"
#include "swarf/v1/swarf.grpc.pb.h"
#include "tests/server_test_util.h"
#include "tests/sim_stream.h"

namespace swarf::server {
namespace {

namespace pb = ::swarf::v1;
using ::swarf::testing::ForSession;
using ::swarf::testing::MovesRequest;
using ::swarf::testing::SetStock;
using ::swarf::testing::SimStream;
using ::swarf::testing::UnlimitedChannel;
using ::swarf::testing::ValueOrDie;

constexpr int32_t kTool = 1;
constexpr double kRadius = 1;

// A raster of 150 passes 0.25 mm apart, at depth 0.3, over a 40 x 40 mm
// stock of 400 x 400 elements, as one polyline of tips: a crease between
// every two passes, about 150 polylines and 1.9 MB of messages.
constexpr StockSpec kStock{0, 0, 40, 40, 0, 400, 400};

std::vector<double> RasterTips() {
  std::vector<double> xyz;
  for (int pass = 0; pass < 150; ++pass) {
    const double y = 1 + 0.25 * pass;
    xyz.insert(xyz.end(), {pass % 2 ? 39.0 : 1.0, y, -0.3});
    xyz.insert(xyz.end(), {pass % 2 ? 1.0 : 39.0, y, -0.3});
  }
  return xyz;
}

// The marks of the raster found by the core itself, as the session cuts it
// (one batch: each tip continues the polyline from the one before).
std::vector<MarkPolyline> CoreMarks() {
  const std::vector<double> xyz = RasterTips();
  std::vector<Move> moves;
  for (size_t k = 3; k + 2 < xyz.size(); k += 3) {
    moves.emplace_back(Vec3{xyz[k - 3], xyz[k - 2], xyz[k - 1]},
                       Vec3{xyz[k], xyz[k + 1], xyz[k + 2]}, kRadius);
  }
  auto wp = ValueOrDie(Workpiece::Create(kStock, SchemeKind::kTaylor));
  EXPECT_TRUE(wp->Apply(moves).ok());
  return ValueOrDie(FindCuttingMarks(*wp, {}));
}

uint64_t Bits(double v) { return std::bit_cast<uint64_t>(v); }

// A streamed polyline is the core's, bit for bit.
::testing::AssertionResult SameMark(const pb::Polyline& got,
                                    const MarkPolyline& want) {
  if (got.closed() != want.closed || got.owners_size() != 2 ||
      got.owners(0) != want.owners[0] || got.owners(1) != want.owners[1]) {
    return ::testing::AssertionFailure() << "closed or owners differ";
  }
  if (got.xyz_size() != 3 * static_cast<int>(want.vertices.size()) ||
      got.angle_deg_size() != static_cast<int>(want.angle_deg.size())) {
    return ::testing::AssertionFailure()
           << got.xyz_size() / 3 << " vertices, not " << want.vertices.size();
  }
  for (size_t i = 0; i < want.vertices.size(); ++i) {
    const Vec3& v = want.vertices[i];
    if (Bits(got.xyz(3 * i)) != Bits(v.x) ||
        Bits(got.xyz(3 * i + 1)) != Bits(v.y) ||
        Bits(got.xyz(3 * i + 2)) != Bits(v.z) ||
        Bits(got.angle_deg(i)) != Bits(want.angle_deg[i])) {
      return ::testing::AssertionFailure() << "vertex " << i << " differs";
    }
  }
  return ::testing::AssertionSuccess();
}

class MarksStreamTest : public ::testing::Test {
 protected:
  void SetUp() override { spdlog::set_level(spdlog::level::warn); }
  void TearDown() override { StopServer(); }

  // One executor thread unless told: a search there that waited for its
  // client would stall every other call.
  void StartServer(const Limits& limits, int workers = 1) {
    ServerOptions o;
    o.listen = "127.0.0.1:0";
    o.worker_threads = workers;
    o.limits = limits;
    server_ = ValueOrDie(SwarfServer::Start(o));
    channel_ = UnlimitedChannel(server_->port());
    stub_ = pb::Swarf::NewStub(channel_);
    // GetCuttingMarks through the in-process transport: it holds no more
    // than a message for a client that does not read, where a TCP
    // connection's buffers (the kernel's, gRPC's flow-control window) take
    // megabytes, so the server's own queue is what a slow reader fills.
    marks_stub_ = pb::Swarf::NewStub(server_->InProcessChannel());
  }
  void StopServer() {
    marks_stub_.reset();
    stub_.reset();
    channel_.reset();
    if (server_ != nullptr) server_->Shutdown(absl::Seconds(5));
    server_.reset();
  }

  // Creates session `id` and cuts the raster (or one short pass) in it.
  void CreateAndCut(const std::string& id, bool raster = true) {
    pb::CreateSessionRequest req;
    req.set_session_id(id);
    SetStock(kStock, &req);
    req.set_scheme(pb::SCHEME_TAYLOR);
    pb::Tool* t = req.add_tools();
    t->set_id(kTool);
    t->mutable_ball()->set_radius(kRadius);
    grpc::ClientContext ctx;
    ForSession(&ctx, id);
    pb::Session s;
    const grpc::Status created = stub_->CreateSession(&ctx, req, &s);
    ASSERT_TRUE(created.ok()) << created.error_message();
    ASSERT_NO_FATAL_FAILURE(Cut(
        id, 1,
        raster ? RasterTips() : std::vector<double>{1, 5, -0.3, 39, 5, -0.3}));
  }

  // Batch `seq` on session `id`, acknowledged.
  void Cut(const std::string& id, uint64_t seq,
           const std::vector<double>& xyz) {
    SimStream stream(stub_.get(), id);
    ASSERT_TRUE(stream.Write(MovesRequest(seq, kTool, xyz)));
    const grpc::Status st = stream.Finish();
    ASSERT_TRUE(st.ok()) << st.error_message();
    const auto rs = stream.responses();
    ASSERT_EQ(rs.size(), 1u);
    ASSERT_TRUE(rs[0].has_ack()) << rs[0].DebugString();
    EXPECT_EQ(rs[0].ack().seq(), seq);
  }

  // A Simulate stream's MarksRequest: its one response.
  pb::SimulateResponse SimulateMarks(const std::string& id) {
    SimStream stream(stub_.get(), id);
    pb::SimulateRequest req;
    req.mutable_marks()->set_request_id(5);
    EXPECT_TRUE(stream.Write(req));
    const grpc::Status st = stream.Finish();
    EXPECT_TRUE(st.ok()) << st.error_message();
    const auto rs = stream.responses();
    EXPECT_EQ(rs.size(), 1u);
    return rs.empty() ? pb::SimulateResponse() : rs[0];
  }

  // Waits (up to the tests' kTimeout) until pred() holds; whether it does.
  template <typename Pred>
  static bool Eventually(Pred pred) {
    const auto end =
        std::chrono::steady_clock::now() + ::swarf::testing::kTimeout;
    while (!pred()) {
      if (std::chrono::steady_clock::now() > end) return false;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return true;
  }

  std::unique_ptr<SwarfServer> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::Swarf::Stub> stub_;
  std::unique_ptr<pb::Swarf::Stub> marks_stub_;
};

// The three ways to the marks give the same polylines in the same order:
// streamed (here through a queue far smaller than the marks, so the search
// waits for the client over and over), in one Simulate answer, and the core.
TEST_F(MarksStreamTest, StreamedMarksAreTheSimulateAnswerAndTheCores) {
  Limits limits;
  limits.marks_queue_bytes = 64 << 10;
  ASSERT_NO_FATAL_FAILURE(StartServer(limits));
  ASSERT_NO_FATAL_FAILURE(CreateAndCut("raster"));
  const std::vector<MarkPolyline> core = CoreMarks();
  ASSERT_GE(core.size(), 140u);

  grpc::ClientContext ctx;
  ForSession(&ctx, "raster");
  auto reader = stub_->GetCuttingMarks(&ctx, pb::GetCuttingMarksRequest());
  std::vector<pb::Polyline> streamed;
  size_t bytes = 0;
  for (pb::Polyline p; reader->Read(&p);) {
    bytes += p.ByteSizeLong();
    streamed.push_back(p);
  }
  const grpc::Status st = reader->Finish();
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_GT(bytes, size_t{1} << 20);
  ASSERT_EQ(streamed.size(), core.size());
  for (size_t k = 0; k < core.size(); ++k) {
    EXPECT_TRUE(SameMark(streamed[k], core[k])) << "polyline " << k;
  }

  const pb::SimulateResponse answer = SimulateMarks("raster");
  ASSERT_TRUE(answer.has_polylines()) << answer.DebugString().substr(0, 300);
  EXPECT_EQ(answer.polylines().request_id(), 5u);
  ASSERT_EQ(answer.polylines().polylines_size(),
            static_cast<int>(streamed.size()));
  for (size_t k = 0; k < streamed.size(); ++k) {
    pb::Polyline p = answer.polylines().polylines(static_cast<int>(k));
    EXPECT_EQ(p.request_id(), 5u);
    p.clear_request_id();
    EXPECT_EQ(p.SerializeAsString(), streamed[k].SerializeAsString())
        << "polyline " << k;
  }
  const MarksStreamCounters& c = server_->marks_counters();
  EXPECT_LE(c.peak_queued_bytes.load(), limits.marks_queue_bytes);
}

// A client that stops reading: the search fills the bounded queue and waits
// (holding only the queue), the single executor thread still serves other
// sessions meanwhile, and once the client reads on it gets every mark.
TEST_F(MarksStreamTest, SlowReaderHoldsABoundedQueueAndOthersAreServed) {
  Limits limits;
  limits.marks_queue_bytes = 32 << 10;
  ASSERT_NO_FATAL_FAILURE(StartServer(limits, /*workers=*/1));
  ASSERT_NO_FATAL_FAILURE(CreateAndCut("slow"));
  const std::vector<MarkPolyline> core = CoreMarks();
  size_t largest = 0;

  grpc::ClientContext ctx;
  ForSession(&ctx, "slow");
  auto reader =
      marks_stub_->GetCuttingMarks(&ctx, pb::GetCuttingMarksRequest());
  std::vector<pb::Polyline> got(1);
  ASSERT_TRUE(reader->Read(&got[0]));
  const MarksStreamCounters& c = server_->marks_counters();
  // The search waits for room (what gRPC buffers is written already).
  ASSERT_TRUE(Eventually([&] { return c.waits.load() > 0; }));
  EXPECT_EQ(c.searches.load(), 1);

  // Meanwhile another session is created, cut and read.
  ASSERT_NO_FATAL_FAILURE(CreateAndCut("other", /*raster=*/false));
  const pb::SimulateResponse other = SimulateMarks("other");
  EXPECT_TRUE(other.has_polylines());
  EXPECT_EQ(c.searches.load(), 1);  // still waiting for its client

  for (pb::Polyline p; reader->Read(&p);) got.push_back(p);
  const grpc::Status st = reader->Finish();
  ASSERT_TRUE(st.ok()) << st.error_message();
  ASSERT_EQ(got.size(), core.size());
  for (size_t k = 0; k < core.size(); ++k) {
    EXPECT_TRUE(SameMark(got[k], core[k])) << "polyline " << k;
    largest = std::max(largest, got[k].ByteSizeLong());
  }
  // Each polyline is smaller than the queue: never more than the bound.
  ASSERT_LT(largest, static_cast<size_t>(limits.marks_queue_bytes));
  EXPECT_LE(c.peak_queued_bytes.load(), limits.marks_queue_bytes);
  EXPECT_GT(c.peak_queued_bytes.load(), 0);
}

// A client that reads a few marks and cancels: the call ends CANCELLED,
// the search stops and lets the session go (a batch on it is applied), the
// server serves another session, and shuts down without waiting.
TEST_F(MarksStreamTest, CancelledCallStopsTheSearch) {
  Limits limits;
  limits.marks_queue_bytes = 32 << 10;
  ASSERT_NO_FATAL_FAILURE(StartServer(limits, /*workers=*/1));
  ASSERT_NO_FATAL_FAILURE(CreateAndCut("gone"));
  const MarksStreamCounters& c = server_->marks_counters();
  {
    grpc::ClientContext ctx;
    ForSession(&ctx, "gone");
    auto reader =
        marks_stub_->GetCuttingMarks(&ctx, pb::GetCuttingMarksRequest());
    pb::Polyline p;
    for (int k = 0; k < 3; ++k) ASSERT_TRUE(reader->Read(&p));
    ASSERT_TRUE(Eventually([&] { return c.waits.load() > 0; }));
    ASSERT_EQ(c.searches.load(), 1);  // it is waiting, not done
    ctx.TryCancel();
    while (reader->Read(&p)) {
    }
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  // The batch needs the session's exclusive lock, which the search held.
  ASSERT_NO_FATAL_FAILURE(Cut("gone", 2, {1, 20.1, -0.2, 39, 20.1, -0.2}));
  EXPECT_TRUE(Eventually([&] { return c.searches.load() == 0; }));
  ASSERT_NO_FATAL_FAILURE(CreateAndCut("next", /*raster=*/false));
  EXPECT_TRUE(SimulateMarks("next").has_polylines());
  // The session's marks are served again, all of them.
  grpc::ClientContext ctx;
  ForSession(&ctx, "gone");
  auto reader =
      marks_stub_->GetCuttingMarks(&ctx, pb::GetCuttingMarksRequest());
  size_t n = 0;
  for (pb::Polyline p; reader->Read(&p);) ++n;
  EXPECT_TRUE(reader->Finish().ok());
  EXPECT_GE(n, 140u);
  server_->Shutdown(absl::Seconds(5));  // joins the search threads
  EXPECT_EQ(c.searches.load(), 0);
}

// A call whose deadline passes while the search waits for its client ends
// DEADLINE_EXCEEDED for the client, and the search stops.
TEST_F(MarksStreamTest, DeadlineStopsAWaitingSearch) {
  Limits limits;
  limits.marks_queue_bytes = 32 << 10;
  ASSERT_NO_FATAL_FAILURE(StartServer(limits, /*workers=*/1));
  ASSERT_NO_FATAL_FAILURE(CreateAndCut("late"));
  const MarksStreamCounters& c = server_->marks_counters();
  grpc::ClientContext ctx;
  ForSession(&ctx, "late");
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(2));
  auto reader =
      marks_stub_->GetCuttingMarks(&ctx, pb::GetCuttingMarksRequest());
  pb::Polyline p;
  // One polyline, then no more reads: the deadline passes with the search
  // waiting for room (or, on a very slow machine, still searching).
  const bool read = reader->Read(&p);
  EXPECT_TRUE(Eventually([&] { return c.searches.load() == 0; }));
  while (read && reader->Read(&p)) {
  }
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  ASSERT_NO_FATAL_FAILURE(Cut("late", 2, {1, 20.1, -0.2, 39, 20.1, -0.2}));
}

// A MarksRequest whose answer would pass the message limit stops its
// search at the first polyline past it: RESOURCE_EXHAUSTED naming the
// limit, and the bytes counted are at most the limit and one polyline.
TEST_F(MarksStreamTest, SimulateMarksStopAtTheMessageLimit) {
  Limits limits;
  limits.max_message_bytes = 1 << 20;
  limits.max_batch_points = 40000;
  ASSERT_NO_FATAL_FAILURE(StartServer(limits, /*workers=*/2));
  ASSERT_NO_FATAL_FAILURE(CreateAndCut("big"));
  const pb::SimulateResponse r = SimulateMarks("big");
  ASSERT_TRUE(r.has_error()) << r.ByteSizeLong();
  EXPECT_EQ(r.error().code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(r.error().kind(), pb::REQUEST_KIND_MARKS);
  EXPECT_EQ(r.error().request_id(), 5u);
  const std::string& m = r.error().message();
  EXPECT_NE(m.find("over the server's limit of 1048576 (--max_message_mb)"),
            std::string::npos)
      << m;
  // "... a message of more than N bytes, ..."
  const std::string lead = "a message of more than ";
  const size_t at = m.find(lead);
  ASSERT_NE(at, std::string::npos) << m;
  const size_t end = m.find(' ', at + lead.size());
  int64_t counted = 0;
  ASSERT_TRUE(absl::SimpleAtoi(
      m.substr(at + lead.size(), end - at - lead.size()), &counted))
      << m;
  size_t largest = 0;
  for (const MarkPolyline& p : CoreMarks()) {
    largest = std::max(largest, 32 * p.vertices.size() + 64);
  }
  EXPECT_GT(counted, 1 << 20);
  EXPECT_LE(counted, (1 << 20) + static_cast<int64_t>(largest));
  // GetCuttingMarks serves them all, a message each.
  grpc::ClientContext ctx;
  ForSession(&ctx, "big");
  auto reader =
      marks_stub_->GetCuttingMarks(&ctx, pb::GetCuttingMarksRequest());
  size_t bytes = 0;
  for (pb::Polyline p; reader->Read(&p);) bytes += p.ByteSizeLong();
  EXPECT_TRUE(reader->Finish().ok());
  EXPECT_GT(bytes, size_t{1} << 20);
}

}  // namespace
}  // namespace swarf::server
