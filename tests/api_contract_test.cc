// The API contract as an independent frontend meets it (issue 13): the real
// server on a loopback port, memory-only and journaled alike.
//
// - an empty MoveBatch: INVALID_ARGUMENT naming moves.xyz on both kinds of
//   server, no storage text, the seq not consumed;
// - a resent seq with other moves ends the stream with ALREADY_EXISTS and
//   nothing after it applies, also after a restart (from the snapshot or
//   from the journal alone);
// - RequestError.kind tells a tile request's id from a batch's seq;
// - two Simulate streams on one session at once (a reconnect while the old
//   stream is half-open);
// - every documented maximum: a request at exactly the maximum is answered
//   or gets that one request's error with the stream alive, one past it is
//   that request's error, and no answer ever exceeds the message limit;
// - every binary's --help lists its flags.

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "server/server.h"
#include "server/session.h"
#include "spdlog/spdlog.h"
#include "swarf/v1/swarf.grpc.pb.h"
#include "tests/server_test_util.h"
#include "tests/sim_stream.h"

namespace swarf::server {
namespace {

namespace fs = std::filesystem;
namespace pb = ::swarf::v1;
using ::swarf::testing::ForSession;
using ::swarf::testing::MovesRequest;
using ::swarf::testing::SetStock;
using ::swarf::testing::SimStream;

constexpr int32_t kTool = 1;

bool Has(absl::string_view s, absl::string_view sub) {
  return absl::StrContains(s, sub);
}

// A 10 x 10 mm taylor session of 20 x 20 elements, ball r = 1 (id 1) and
// r = 0.5 (id 2).
pb::CreateSessionRequest SmallRequest(const std::string& id) {
  pb::CreateSessionRequest r;
  r.set_session_id(id);
  SetStock({0, 0, 10, 10, 0, 20, 20}, &r);
  r.set_scheme(pb::SCHEME_TAYLOR);
  for (auto [tool, radius] : {std::pair{1, 1.0}, std::pair{2, 0.5}}) {
    pb::Tool* t = r.add_tools();
    t->set_id(tool);
    t->mutable_ball()->set_radius(radius);
  }
  return r;
}

// `points` tips from (1, y) to (9, y) at depth z.
std::vector<double> Line(int points, double y, double z) {
  std::vector<double> xyz;
  for (int p = 0; p < points; ++p) {
    xyz.insert(xyz.end(),
               {1 + 8.0 * p / std::max(1, points - 1), y, z});
  }
  return xyz;
}

pb::SimulateRequest TilesRequest(uint64_t id) {
  pb::SimulateRequest r;
  r.mutable_tiles()->set_request_id(id);
  r.mutable_tiles()->set_precision(pb::PRECISION_DOUBLE);
  return r;
}

pb::SimulateRequest StatsRequest(uint64_t id, int32_t samples, int32_t cols,
                                 int32_t rows) {
  pb::SimulateRequest r;
  r.mutable_stats()->set_request_id(id);
  r.mutable_stats()->set_samples_per_edge(samples);
  r.mutable_stats()->set_map_cols(cols);
  r.mutable_stats()->set_map_rows(rows);
  return r;
}

pb::Rect Region(double x0, double y0, double x1, double y1) {
  pb::Rect r;
  r.set_x0(x0);
  r.set_y0(y0);
  r.set_x1(x1);
  r.set_y1(y1);
  return r;
}

class ApiTest : public ::testing::TestWithParam<bool> {
 protected:
  void SetUp() override {
    spdlog::set_level(spdlog::level::off);
    dir_ = fs::temp_directory_path() /
           absl::StrCat("swarf-api-", ::getpid(), "-",
                        ::testing::UnitTest::GetInstance()->random_seed(), "-",
                        reinterpret_cast<uintptr_t>(this));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    StopServer();
    fs::remove_all(dir_);
  }
  bool journaled() const { return GetParam(); }

  void StartServer(const Limits& limits = Limits()) {
    StopServer();
    ServerOptions o;
    o.listen = "127.0.0.1:0";
    o.worker_threads = 2;
    o.limits = limits;
    if (journaled()) {
      o.persistence.data_dir = dir_.string();
      o.persistence.sync = JournalSync::kOff;
      o.persistence.snapshot_every_moves = 0;
    }
    auto s = SwarfServer::Start(o);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
    channel_ = ::swarf::testing::UnlimitedChannel(server_->port());
    stub_ = pb::Swarf::NewStub(channel_);
  }
  void StopServer() {
    stub_.reset();
    channel_.reset();
    if (server_ != nullptr) server_->Shutdown(absl::Seconds(5));
    server_.reset();
  }

  grpc::Status Create(const pb::CreateSessionRequest& req) {
    grpc::ClientContext ctx;
    ForSession(&ctx, req.session_id());
    pb::Session s;
    return stub_->CreateSession(&ctx, req, &s);
  }
  pb::Session Get(const std::string& id) {
    grpc::ClientContext ctx;
    ForSession(&ctx, id);
    pb::GetSessionRequest req;
    req.set_session_id(id);
    pb::Session s;
    EXPECT_TRUE(stub_->GetSession(&ctx, req, &s).ok());
    return s;
  }

  // Writes `reqs` on a new stream, half-closes and returns the responses;
  // the stream must end OK.
  SimStream::Responses Exchange(const std::string& id,
                                const std::vector<pb::SimulateRequest>& reqs) {
    SimStream sim(stub_.get(), id);
    for (const auto& r : reqs) EXPECT_TRUE(sim.Write(r));
    const grpc::Status st = sim.Finish();
    EXPECT_TRUE(st.ok()) << st.error_code() << " " << st.error_message();
    return sim.responses();
  }

  fs::path dir_;
  std::unique_ptr<SwarfServer> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::Swarf::Stub> stub_;
};

INSTANTIATE_TEST_SUITE_P(Servers, ApiTest, ::testing::Bool(),
                         [](const auto& info) {
                           return info.param ? "Journaled" : "MemoryOnly";
                         });

// ------------------------------------------------------- empty batches

TEST_P(ApiTest, EmptyBatchIsInvalidArgumentNamingTheFieldOnEveryServer) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  ASSERT_TRUE(Create(SmallRequest("empty")).ok());
  pb::SimulateRequest empty_reposition = MovesRequest(1, kTool, {});
  empty_reposition.mutable_moves()->set_reposition(true);
  const auto rs = Exchange(
      "empty", {MovesRequest(1, kTool, {}), empty_reposition,
                MovesRequest(1, kTool, Line(5, 5, -0.3)),
                MovesRequest(2, kTool, {})});
  ASSERT_EQ(rs.size(), 4u);
  for (int k : {0, 1, 3}) {
    ASSERT_TRUE(rs[k].has_error()) << rs[k].ShortDebugString();
    const pb::RequestError& e = rs[k].error();
    EXPECT_EQ(e.code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_TRUE(Has(e.message(), "moves.xyz")) << e.message();
    EXPECT_FALSE(Has(e.message(), "NOT NULL")) << e.message();
    EXPECT_FALSE(Has(e.message(), "journal")) << e.message();
    EXPECT_EQ(e.kind(), pb::REQUEST_KIND_MOVES);
  }
  EXPECT_EQ(rs[0].error().request_id(), 1u);
  EXPECT_EQ(rs[3].error().request_id(), 2u);
  // The empty batch did not consume seq 1.
  ASSERT_TRUE(rs[2].has_ack()) << rs[2].ShortDebugString();
  EXPECT_EQ(rs[2].ack().seq(), 1u);
  EXPECT_FALSE(rs[2].ack().duplicate());
  EXPECT_EQ(rs[2].ack().moves_applied(), 4);
  EXPECT_EQ(Get("empty").last_seq(), 1u);
}

// ------------------------------------------------------- cutter shapes

// Every cutter shape is accepted (never UNIMPLEMENTED), cuts, and GetSession
// returns the tools exactly as created, also after a restart (from the
// journal's definition).
TEST_P(ApiTest, EveryCutterShapeRoundTripsThroughCreateAndGetSession) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  pb::CreateSessionRequest req;
  req.set_session_id("shapes");
  SetStock({0, 0, 10, 10, 0, 40, 40}, &req);
  req.set_scheme(pb::SCHEME_TAYLOR);
  auto add = [&](int32_t id) {
    pb::Tool* t = req.add_tools();
    t->set_id(id);
    return t;
  };
  add(1)->mutable_ball()->set_radius(0.75);
  add(2)->mutable_flat()->set_radius(0.5);
  pb::BullNose* bull = add(3)->mutable_bull_nose();
  bull->set_radius(1);
  bull->set_corner_radius(0.25);
  pb::Cone* vbit = add(4)->mutable_cone();
  vbit->set_radius(1.5);
  vbit->set_half_angle_deg(45);
  vbit->set_tip_radius(0.1);
  pb::Cone* sharp = add(5)->mutable_cone();
  sharp->set_radius(1);
  sharp->set_half_angle_deg(15);
  pb::TaperedBall* taper = add(6)->mutable_tapered_ball();
  taper->set_radius(2);
  taper->set_tip_radius(0.5);
  taper->set_half_angle_deg(5);
  const grpc::Status created = Create(req);
  ASSERT_TRUE(created.ok()) << created.error_code() << " "
                            << created.error_message();
  auto same_tools = [&](const pb::Session& s) {
    ASSERT_EQ(s.tools_size(), req.tools_size());
    for (int k = 0; k < req.tools_size(); ++k) {
      EXPECT_EQ(s.tools(k).SerializeAsString(), req.tools(k).SerializeAsString())
          << s.tools(k).ShortDebugString() << " vs "
          << req.tools(k).ShortDebugString();
    }
  };
  same_tools(Get("shapes"));
  std::vector<pb::SimulateRequest> batches;
  for (int32_t id = 1; id <= 6; ++id) {
    batches.push_back(MovesRequest(id, id, Line(5, 1.5 * id, -0.3)));
    batches.back().mutable_moves()->set_reposition(true);
  }
  const auto rs = Exchange("shapes", batches);
  ASSERT_EQ(rs.size(), 6u);
  for (const auto& r : rs) {
    ASSERT_TRUE(r.has_ack()) << r.ShortDebugString();
    EXPECT_GT(r.ack().node_lowerings(), 0) << r.ShortDebugString();
  }
  EXPECT_EQ(Get("shapes").moves_applied(), 24);
  if (journaled()) {
    ASSERT_NO_FATAL_FAILURE(StartServer());
    const pb::Session restored = Get("shapes");
    same_tools(restored);
    EXPECT_EQ(restored.last_seq(), 6u);
    EXPECT_EQ(restored.moves_applied(), 24);
  }
}

// ------------------------------------------------------- resent seqs

// Batch 2 again: the same, then altered in each part the digest covers.
std::vector<pb::SimulateRequest> Resends(const std::vector<double>& b2) {
  std::vector<double> moved = b2;
  moved.back() = std::nextafter(moved.back(), 0.0);  // one ulp
  pb::SimulateRequest reposition = MovesRequest(2, kTool, b2);
  reposition.mutable_moves()->set_reposition(true);
  return {MovesRequest(2, kTool, b2), MovesRequest(2, kTool, moved),
          MovesRequest(2, 2, b2), reposition,
          MovesRequest(2, kTool, Line(3, 2, -0.1))};
}

// The same batch 2 is a duplicate; each altered one ends its stream with
// ALREADY_EXISTS, and the valid batch `next` sent after it on that stream
// is not applied.
void ExpectResendsChecked(pb::Swarf::Stub* stub, const std::string& id,
                          const std::vector<double>& b2, uint64_t next_seq,
                          int64_t moves) {
  const auto resends = Resends(b2);
  {
    SimStream sim(stub, id);
    ASSERT_TRUE(sim.Write(resends[0]));
    ASSERT_TRUE(sim.Finish().ok());
    const auto rs = sim.responses();
    ASSERT_EQ(rs.size(), 1u);
    ASSERT_TRUE(rs[0].has_ack()) << rs[0].ShortDebugString();
    EXPECT_TRUE(rs[0].ack().duplicate());
    EXPECT_EQ(rs[0].ack().moves_applied(), moves);
  }
  for (size_t k = 1; k < resends.size(); ++k) {
    SimStream sim(stub, id);
    ASSERT_TRUE(sim.Write(resends[k]));
    sim.Write(MovesRequest(next_seq, kTool, Line(3, 9, -0.1)));
    const grpc::Status st = sim.Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::ALREADY_EXISTS) << k;
    EXPECT_TRUE(Has(st.error_message(), "moves.seq 2")) << st.error_message();
    EXPECT_TRUE(sim.responses().empty()) << k;
  }
}

TEST_P(ApiTest, ResentSeqWithOtherMovesIsAlreadyExists) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  const std::string id = "resend";
  ASSERT_TRUE(Create(SmallRequest(id)).ok());
  const std::vector<double> b1 = Line(4, 3, -0.4), b2 = Line(5, 6, -0.5),
                            b3 = Line(3, 8, -0.2);
  auto rs = Exchange(id, {MovesRequest(1, kTool, b1), MovesRequest(2, kTool, b2)});
  ASSERT_EQ(rs.size(), 2u);
  ASSERT_TRUE(rs[1].has_ack());
  const uint64_t version = rs[1].ack().version();
  ASSERT_NO_FATAL_FAILURE(ExpectResendsChecked(stub_.get(), id, b2, 3, 8));
  pb::Session s = Get(id);
  EXPECT_EQ(s.last_seq(), 2u);
  EXPECT_EQ(s.version(), version);
  EXPECT_EQ(s.moves_applied(), 8);
  // Going on from last_seq + 1 works.
  rs = Exchange(id, {MovesRequest(3, kTool, b3)});
  ASSERT_TRUE(rs.at(0).has_ack());
  EXPECT_FALSE(rs[0].ack().duplicate());
  if (!journaled()) return;
  // After a restart (from the snapshot written at shutdown), then from the
  // journal alone, the digests are the same.
  for (bool drop_snapshot : {false, true}) {
    SCOPED_TRACE(drop_snapshot ? "journal only" : "snapshot");
    StopServer();
    if (drop_snapshot) {
      ASSERT_TRUE(fs::remove(dir_ / (id + ".snap")));
    }
    ASSERT_NO_FATAL_FAILURE(StartServer());
    EXPECT_EQ(Get(id).snapshot_seq(), drop_snapshot ? 0u : 3u);
    ASSERT_NO_FATAL_FAILURE(ExpectResendsChecked(stub_.get(), id, b2, 4, 11));
    EXPECT_EQ(Get(id).last_seq(), 3u);
  }
}

// ---------------------------------------------- RequestError.kind

TEST_P(ApiTest, RequestErrorsSayWhichKindOfRequestTheyAnswer) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  ASSERT_TRUE(Create(SmallRequest("kind")).ok());
  pb::SimulateRequest bad_tiles = TilesRequest(2);
  bad_tiles.mutable_tiles()->mutable_selection()->add_tiles()->set_tx(99);
  pb::SimulateRequest bad_marks;
  bad_marks.mutable_marks()->set_request_id(2);
  bad_marks.mutable_marks()->set_min_angle_deg(95);
  pb::SimulateRequest bad_sub;
  bad_sub.mutable_subscribe()->set_request_id(2);
  bad_sub.mutable_subscribe()->mutable_selection()->add_tiles()->set_ty(-1);
  const auto rs = Exchange(
      "kind", {MovesRequest(1, kTool, Line(3, 5, -0.2)), bad_tiles,
               MovesRequest(2, 77, Line(3, 5, -0.2)), StatsRequest(2, 99, 0, 0),
               bad_marks, bad_sub, pb::SimulateRequest()});
  ASSERT_EQ(rs.size(), 7u);
  const pb::RequestKind want[] = {
      pb::REQUEST_KIND_TILES, pb::REQUEST_KIND_MOVES, pb::REQUEST_KIND_STATS,
      pb::REQUEST_KIND_MARKS, pb::REQUEST_KIND_SUBSCRIBE,
      pb::REQUEST_KIND_UNSPECIFIED};
  for (int k = 1; k < 7; ++k) {
    ASSERT_TRUE(rs[k].has_error()) << k << ": " << rs[k].ShortDebugString();
    EXPECT_EQ(rs[k].error().kind(), want[k - 1]) << k;
    EXPECT_EQ(rs[k].error().request_id(), k == 6 ? 0u : 2u) << k;
  }
}

// ------------------------------------------- two streams on one session

TEST_P(ApiTest, TwoStreamsOnOneSessionShareOneSeqSequence) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  const std::string id = "two";
  ASSERT_TRUE(Create(SmallRequest(id)).ok());
  const std::vector<double> b1 = Line(4, 3, -0.4), b2 = Line(5, 6, -0.5),
                            b3 = Line(3, 8, -0.2);
  // The old stream: batches 1 and 2 sent, then it goes quiet (half-open:
  // never half-closed).
  SimStream old_stream(stub_.get(), id);
  ASSERT_TRUE(old_stream.Write(MovesRequest(1, kTool, b1)));
  ASSERT_TRUE(old_stream.Write(MovesRequest(2, kTool, b2)));
  ASSERT_TRUE(old_stream.WaitForCount(2));
  // The reconnect resends from what it last saw acknowledged (1) on.
  SimStream fresh(stub_.get(), id);
  ASSERT_TRUE(fresh.Write(MovesRequest(2, kTool, b2)));
  ASSERT_TRUE(fresh.Write(MovesRequest(3, kTool, b3)));
  ASSERT_TRUE(fresh.Write(TilesRequest(7)));
  ASSERT_TRUE(fresh.WaitFor([](const SimStream::Responses& rs) {
    return !rs.empty() && rs.back().has_tiles_done();
  }));
  // The old stream is still served, and sees batch 3 of the other one.
  ASSERT_TRUE(old_stream.Write(MovesRequest(3, kTool, b3)));
  ASSERT_TRUE(old_stream.Write(TilesRequest(8)));
  ASSERT_TRUE(old_stream.Finish().ok());
  ASSERT_TRUE(fresh.Finish().ok());

  const auto a = old_stream.responses(), b = fresh.responses();
  ASSERT_GE(a.size(), 4u);
  ASSERT_GE(b.size(), 3u);
  EXPECT_FALSE(a[0].ack().duplicate());
  EXPECT_FALSE(a[1].ack().duplicate());
  EXPECT_TRUE(b[0].ack().duplicate());
  EXPECT_EQ(b[0].ack().seq(), 2u);
  EXPECT_FALSE(b[1].ack().duplicate());
  EXPECT_EQ(b[1].ack().moves_applied(), 11);
  EXPECT_TRUE(a[2].ack().duplicate());
  EXPECT_EQ(a[2].ack().seq(), 3u);
  // Both streams' tile answers are the same grid, after batch 3.
  std::vector<pb::Tile> ta, tb;
  for (const auto& r : a) {
    if (r.has_tile()) ta.push_back(r.tile());
  }
  for (const auto& r : b) {
    if (r.has_tile()) tb.push_back(r.tile());
  }
  ASSERT_EQ(ta.size(), 1u);
  ASSERT_EQ(tb.size(), 1u);
  EXPECT_EQ(ta[0].version(), b[1].ack().version());
  EXPECT_EQ(tb[0].version(), ta[0].version());
  ASSERT_EQ(ta[0].heights_d_size(), tb[0].heights_d_size());
  for (int k = 0; k < ta[0].heights_d_size(); ++k) {
    ASSERT_EQ(ta[0].heights_d(k), tb[0].heights_d(k)) << k;
  }
  const pb::Session s = Get(id);
  EXPECT_EQ(s.last_seq(), 3u);
  EXPECT_EQ(s.moves_applied(), 11);
}

// ------------------------------------------------------------- limits

TEST_P(ApiTest, RequestsAtEveryDocumentedMaximum) {
  // 1 MiB messages: small enough to reach every answer limit quickly.
  Limits limits;
  limits.max_message_bytes = 1 << 20;
  limits.max_batch_points = 40000;
  // Exactly one tile of a taylor grid (SmallRequest's 20 x 20 elements).
  limits.max_session_memory_bytes =
      Session::EstimateMemoryBytes({0, 0, 10, 10, 0, 20, 20}, SchemeKind::kTaylor);
  limits.max_streams_per_client = 3;
  // Refused: a full batch would not fit the message limit.
  {
    Limits bad = limits;
    bad.max_batch_points = 50000;
    ServerOptions o;
    o.listen = "127.0.0.1:0";
    o.limits = bad;
    auto s = SwarfServer::Start(o);
    EXPECT_EQ(s.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_TRUE(Has(s.status().message(), "max_batch_points"));
  }
  ASSERT_NO_FATAL_FAILURE(StartServer(limits));
  // Session ids of exactly 64 characters; grids of exactly the byte limit
  // (a tile's nodes: 64 x 64), and one element more (a second tile).
  const std::string id(64, 'a');
  ASSERT_TRUE(Create(SmallRequest(id)).ok());
  EXPECT_EQ(Create(SmallRequest(std::string(65, 'b'))).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  pb::CreateSessionRequest big = SmallRequest("big");
  big.set_nx(63);
  big.set_ny(63);
  ASSERT_TRUE(Create(big).ok());
  big.set_session_id("bigger");
  big.set_nx(64);
  EXPECT_EQ(Create(big).error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);

  SimStream sim(stub_.get(), id);
  std::vector<pb::SimulateRequest> sent;
  auto send = [&](const pb::SimulateRequest& r) {
    ASSERT_TRUE(sim.Write(r));
    sent.push_back(r);
  };
  // A batch of exactly max_batch_points, then one past it.
  std::vector<double> full;
  for (int p = 0; p < 40000; ++p) {
    full.insert(full.end(), {1 + 8.0 * p / 39999, 5 + std::sin(p * 1e-3), -0.3});
  }
  ASSERT_LE(MovesRequest(1, kTool, full).ByteSizeLong(),
            static_cast<size_t>(FullBatchMessageBytes(40000)));
  send(MovesRequest(1, kTool, full));
  full.insert(full.end(), {5, 5, -0.3});
  send(MovesRequest(2, kTool, full));
  // samples_per_edge: 64 answered, 65 refused (over a few elements).
  pb::SimulateRequest most_samples = StatsRequest(3, 64, 0, 0);
  *most_samples.mutable_stats()->mutable_region() = Region(4, 4, 5, 5);
  send(most_samples);
  send(StatsRequest(4, 65, 0, 0));
  // Maps: the documented 16 Mi cells cannot fit 1 MiB: that request's
  // RESOURCE_EXHAUSTED; the largest map that fits is answered.
  send(StatsRequest(5, 0, 4096, 4096));
  const int32_t rows = ((1 << 20) - 256) / 4 / 512;
  send(StatsRequest(6, 0, 512, rows));
  send(StatsRequest(7, 0, 512, rows + 1));
  send(StatsRequest(8, 0, 4097, 4096));  // over 16 Mi: bad input
  // Then the stream still works.
  send(MovesRequest(2, kTool, Line(3, 2, -0.2)));
  ASSERT_TRUE(sim.WaitForCount(sent.size()));
  ASSERT_TRUE(sim.Finish().ok());
  const auto rs = sim.responses();
  ASSERT_EQ(rs.size(), sent.size());
  auto error_of = [&](size_t k) {
    EXPECT_TRUE(rs[k].has_error()) << k << ": " << rs[k].ShortDebugString();
    return rs[k].error();
  };
  ASSERT_TRUE(rs[0].has_ack()) << rs[0].ShortDebugString();
  EXPECT_EQ(rs[0].ack().moves_applied(), 39999);
  EXPECT_EQ(error_of(1).code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_TRUE(Has(error_of(1).message(), "moves.xyz has 40001 points"));
  ASSERT_TRUE(rs[2].has_stats());
  EXPECT_EQ(error_of(3).code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(error_of(4).code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_TRUE(Has(error_of(4).message(), "4096 x 4096")) << error_of(4).message();
  EXPECT_EQ(error_of(4).kind(), pb::REQUEST_KIND_STATS);
  ASSERT_TRUE(rs[5].has_stats()) << rs[5].error().message();
  EXPECT_EQ(rs[5].stats().map_max_error_size(), 512 * rows);
  EXPECT_LE(rs[5].ByteSizeLong(), size_t{1} << 20);
  EXPECT_EQ(error_of(6).code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(error_of(7).code(), grpc::StatusCode::INVALID_ARGUMENT);
  ASSERT_TRUE(rs[8].has_ack());
  EXPECT_EQ(rs[8].ack().seq(), 2u);
  for (const auto& r : rs) EXPECT_LE(r.ByteSizeLong(), size_t{1} << 20);

  // Unary calls: the same map limit, and probes whose answer would not fit.
  {
    grpc::ClientContext ctx;
    ForSession(&ctx, id);
    pb::GetErrorStatsRequest req;
    req.set_map_cols(4096);
    req.set_map_rows(4096);
    pb::ErrorStats out;
    const grpc::Status st = stub_->GetErrorStats(&ctx, req, &out);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    EXPECT_TRUE(Has(st.error_message(), "map")) << st.error_message();
  }
  for (int points : {20000, 40000}) {
    grpc::ClientContext ctx;
    ForSession(&ctx, id);
    pb::ProbeRequest req;
    for (int p = 0; p < points; ++p) {
      req.add_xy(1 + 8.0 * p / points);
      req.add_xy(5);
    }
    pb::ProbeResponse out;
    const grpc::Status st = stub_->Probe(&ctx, req, &out);
    if (points == 20000) {
      EXPECT_TRUE(st.ok()) << st.error_message();
      EXPECT_EQ(out.heights_size(), points);
    } else {
      EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
      EXPECT_TRUE(Has(st.error_message(), "40000 points")) << st.error_message();
    }
  }
}

// Marks are computed before their size is known: an answer over the limit
// becomes that request's error, and GetCuttingMarks (a message per mark)
// still serves them.
TEST_P(ApiTest, MarksOverTheMessageLimitAreThatRequestsError) {
  Limits limits;
  limits.max_message_bytes = 1 << 20;
  limits.max_batch_points = 40000;
  ASSERT_NO_FATAL_FAILURE(StartServer(limits));
  pb::CreateSessionRequest req = SmallRequest("marks");
  SetStock({0, 0, 40, 40, 0, 400, 400}, &req);
  ASSERT_TRUE(Create(req).ok());
  // A raster of 150 passes 0.25 mm apart: a crease between every two.
  std::vector<double> xyz;
  for (int pass = 0; pass < 150; ++pass) {
    const double y = 1 + 0.25 * pass;
    xyz.insert(xyz.end(), {pass % 2 ? 39.0 : 1.0, y, -0.3});
    xyz.insert(xyz.end(), {pass % 2 ? 1.0 : 39.0, y, -0.3});
  }
  pb::SimulateRequest marks;
  marks.mutable_marks()->set_request_id(9);
  const auto rs = Exchange("marks", {MovesRequest(1, kTool, xyz), marks,
                                     MovesRequest(2, kTool, Line(2, 39, -0.1))});
  ASSERT_EQ(rs.size(), 3u);
  ASSERT_TRUE(rs[1].has_error()) << rs[1].ByteSizeLong();
  EXPECT_EQ(rs[1].error().code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_EQ(rs[1].error().kind(), pb::REQUEST_KIND_MARKS);
  EXPECT_EQ(rs[1].error().request_id(), 9u);
  EXPECT_TRUE(rs[2].has_ack());
  grpc::ClientContext ctx;
  ForSession(&ctx, "marks");
  pb::GetCuttingMarksRequest mr;
  auto reader = stub_->GetCuttingMarks(&ctx, mr);
  size_t bytes = 0, lines = 0;
  for (pb::Polyline p; reader->Read(&p); ++lines) bytes += p.ByteSizeLong();
  EXPECT_TRUE(reader->Finish().ok());
  EXPECT_GT(bytes, size_t{1} << 20);  // all of them: more than one message
  EXPECT_GT(lines, 100u);
}

TEST_P(ApiTest, StreamsAtTheLimitOpenAndOnePastIsRefused) {
  Limits limits;
  limits.max_streams_per_client = 2;
  ASSERT_NO_FATAL_FAILURE(StartServer(limits));
  ASSERT_TRUE(Create(SmallRequest("streams")).ok());
  SimStream a(stub_.get(), "streams"), b(stub_.get(), "streams");
  for (SimStream* s : {&a, &b}) {
    ASSERT_TRUE(s->Write(TilesRequest(1)));
    ASSERT_TRUE(s->WaitForCount(2));  // a tile and TilesDone
  }
  SimStream c(stub_.get(), "streams");
  const grpc::Status st = c.Wait();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_TRUE(a.Finish().ok());
  EXPECT_TRUE(b.Finish().ok());
}

// A batch of exactly the default limit (1 Mi points) on the default server.
TEST_P(ApiTest, DefaultBatchLimitIsAnswered) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  ASSERT_EQ(Limits().max_batch_points, 1 << 20);
  ASSERT_TRUE(Create(SmallRequest("full")).ok());
  std::vector<double> xyz;
  xyz.reserve(3 << 20);
  for (int p = 0; p < (1 << 20); ++p) {
    // Above the stock: nothing is cut, so this stays fast.
    xyz.insert(xyz.end(), {1 + 8.0 * (p % 1000) / 999, 5, 3});
  }
  const auto rs = Exchange("full", {MovesRequest(1, kTool, xyz)});
  ASSERT_EQ(rs.size(), 1u);
  ASSERT_TRUE(rs[0].has_ack()) << rs[0].ShortDebugString();
  EXPECT_EQ(rs[0].ack().moves_applied(), (1 << 20) - 1);
}

// ------------------------------------------------------------- --help

std::string RunCommand(const std::string& command) {
  std::string out;
  FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  if (p == nullptr) return out;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) {
    out.append(buf.data(), n);
  }
  ::pclose(p);
  return out;
}

TEST(HelpTest, SwarfdHelpListsEveryFlag) {
  // The flags are whatever server/main.cc defines.
  std::ifstream in(std::string(SWARF_SOURCE_DIR) + "/server/main.cc");
  std::stringstream src;
  src << in.rdbuf();
  const std::string text = src.str();
  const std::regex flag(R"(ABSL_FLAG\(\s*[\w:]+\s*,\s*(\w+)\s*,)");
  std::set<std::string> flags;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), flag);
       it != std::sregex_iterator(); ++it) {
    flags.insert((*it)[1]);
  }
  ASSERT_GE(flags.size(), 20u);
  for (const char* help : {"--help", "--helpshort"}) {
    const std::string out = RunCommand(absl::StrCat(SWARFD_PATH, " ", help));
    EXPECT_FALSE(Has(out, "No flags matched")) << out;
    for (const std::string& f : flags) {
      EXPECT_TRUE(Has(out, absl::StrCat("--", f, " "))) << help << ": " << f;
    }
  }
}

TEST(HelpTest, EverySwarfCommandHasHelp) {
  EXPECT_TRUE(Has(RunCommand(absl::StrCat(SWARF_CLI, " --help")), "commands:"));
  for (const char* cmd : {"run", "table", "marks", "health", "sessions",
                          "load"}) {
    const std::string out = RunCommand(absl::StrCat(SWARF_CLI, " ", cmd, " --help"));
    EXPECT_TRUE(Has(out, absl::StrCat("swarf ", cmd))) << cmd << ": " << out;
    EXPECT_TRUE(Has(out, "--")) << cmd << ": " << out;
  }
}

}  // namespace
}  // namespace swarf::server
