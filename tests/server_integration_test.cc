// In-process integration test of the swarf gRPC service: the real server on
// a loopback TCP port, the generated stub, and as the reference for every
// result the core engine run directly on exactly the moves the server sees.
//
// A MoveBatch's points continue the session's polyline, so the paper
// instances (separate moves) are streamed as one polyline through all their
// moves, with connecting moves lifted to kSafeZ where they cut nothing; the
// core reference applies that same polyline, batch by batch.

#include <algorithm>
#include <atomic>
#include <bit>
#include <cmath>
#include <cstdint>
#include <functional>
#include <future>
#include <latch>
#include <limits>
#include <map>
#include <memory>
#include <ostream>
#include <set>
#include <string>
#include <string_view>
#include <thread>
#include <tuple>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "core/instances.h"
#include "core/valuation.h"
#include "core/workpiece.h"
#include "grpcpp/generic/generic_stub.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "server/server.h"
#include "server/service.h"
#include "server/session.h"
#include "spdlog/spdlog.h"
#include "swarf/v1/swarf.grpc.pb.h"
#include "tests/server_test_util.h"
#include "tests/sim_stream.h"
#include "tests/tile_copy.h"

namespace swarf::server {
namespace {

namespace pb = ::swarf::v1;
using ::swarf::testing::CollectTiles;
using ::swarf::testing::ForSession;
using ::swarf::testing::MovesRequest;
using ::swarf::testing::SetDeadline;
using ::swarf::testing::SetStock;
using ::swarf::testing::SimStream;
using ::swarf::testing::ValueOrDie;

constexpr char kReplica[] = "it-replica";
constexpr int32_t kToolId = 7;
// A decoy tool listed before kToolId: a server picking the wrong tool cuts
// differently.
constexpr int32_t kDecoyToolId = 3;
constexpr double kDecoyRadius = 2.5;
// Connecting moves run at this tip height, above every stock top here.
constexpr double kSafeZ = 50;

uint64_t Bits(double v) { return std::bit_cast<uint64_t>(v); }
uint32_t Bits(float v) { return std::bit_cast<uint32_t>(v); }

bool Has(const std::string& s, std::string_view sub) {
  return s.find(sub) != std::string::npos;
}

// ------------------------------------------------------------- toolpaths

// A tip polyline and its split into batches: batch k (1-based) holds points
// [begin[k - 1], begin[k]).
struct Toolpath {
  StockSpec stock;
  double radius = 0;
  std::vector<Vec3> points;
  std::vector<size_t> begin;

  int batches() const { return static_cast<int>(begin.size()) - 1; }

  // Batch k's moves as the session makes them: every point continues the
  // polyline; the very first point is only the start position.
  std::vector<Move> Moves(int k) const {
    std::vector<Move> out;
    for (size_t p = std::max<size_t>(begin[k - 1], 1); p < begin[k]; ++p) {
      out.push_back({points[p - 1], points[p], radius});
    }
    return out;
  }
  // Moves in batches 1..k.
  int64_t MovesThrough(int k) const {
    return k == 0 ? 0 : static_cast<int64_t>(begin[k]) - 1;
  }
  pb::SimulateRequest Batch(int k) const {
    pb::SimulateRequest r;
    pb::MoveBatch* b = r.mutable_moves();
    b->set_seq(k);
    b->set_tool_id(kToolId);
    for (size_t p = begin[k - 1]; p < begin[k]; ++p) {
      b->add_xyz(points[p].x);
      b->add_xyz(points[p].y);
      b->add_xyz(points[p].z);
    }
    return r;
  }
};

void SplitIntoBatches(Toolpath* tp, int batches) {
  const size_t n = tp->points.size();
  tp->begin.clear();
  for (int k = 0; k <= batches; ++k) tp->begin.push_back(n * k / batches);
}

// A paper instance as one polyline: each move is cut in `segments` pieces,
// approached from and left to kSafeZ.
Toolpath FromInstance(std::string_view name, int mesh, int segments,
                      int batches) {
  const Instance inst = ValueOrDie(PaperInstance(name, mesh));
  Toolpath tp;
  tp.stock = inst.stock;
  tp.radius = inst.moves.front().cutter.radius;
  auto add = [&](const Vec3& p) {
    if (!tp.points.empty() && tp.points.back().x == p.x &&
        tp.points.back().y == p.y && tp.points.back().z == p.z) {
      return;
    }
    tp.points.push_back(p);
  };
  for (const Move& m : inst.moves) {
    EXPECT_EQ(m.cutter.radius, tp.radius);  // one tool per instance
    add({m.from.x, m.from.y, kSafeZ});
    add(m.from);
    for (int s = 1; s < segments; ++s) {
      const double f = static_cast<double>(s) / segments;
      add({m.from.x + (m.to.x - m.from.x) * f,
           m.from.y + (m.to.y - m.from.y) * f,
           m.from.z + (m.to.z - m.from.z) * f});
    }
    add(m.to);
    add({m.to.x, m.to.y, kSafeZ});
  }
  SplitIntoBatches(&tp, batches);
  return tp;
}

// A zig-zag raster at depth 1 with a 3 mm ball, one line per batch: many
// small moves, as a CAM post-processor writes them.
Toolpath Raster(int lines, int points_per_line) {
  Toolpath tp;
  tp.stock = {0, 0, 100, 100, 0, 100, 100};
  tp.radius = 3;
  for (int l = 0; l < lines; ++l) {
    const double y = 2 + 96.0 * l / (lines - 1);
    for (int p = 0; p < points_per_line; ++p) {
      double f = static_cast<double>(p) / (points_per_line - 1);
      if (l % 2 == 1) f = 1 - f;
      tp.points.push_back({2 + 96 * f, y, -1});
    }
  }
  SplitIntoBatches(&tp, lines);
  return tp;
}

// ------------------------------------------------------------ reference

// One tile of a core workpiece, as Workpiece::ReadTile gives it.
struct CoreTile : TileCopy {
  int32_t t = 0;
  uint64_t version = 0;
};

CoreTile ReadCore(const Workpiece& wp, int32_t t) {
  CoreTile c;
  static_cast<TileCopy&>(c) = CopyTile(wp, t);
  c.t = t;
  c.version = wp.TileVersion(t);
  return c;
}

// The core run directly on a toolpath's batches, one Apply per batch like
// the session. Optionally keeps each changed tile's contents at every
// version, to check pushed tiles against the state they claim.
class Reference {
 public:
  Reference(const Toolpath& tp, SchemeKind scheme, bool snapshots = false)
      : tp_(tp),
        wp_(ValueOrDie(Workpiece::Create(tp.stock, scheme))),
        snapshots_(snapshots) {}

  void ApplyThrough(int k) {
    while (applied() < k) {
      const ApplyResult r = ValueOrDie(wp_->Apply(tp_.Moves(applied() + 1)));
      if (snapshots_) {
        for (int32_t t : r.changed_tiles) {
          snaps_[{t, r.version}] = ReadCore(*wp_, t);
        }
      }
      results_.push_back(r);
    }
  }

  const Workpiece& wp() const { return *wp_; }
  int applied() const { return static_cast<int>(results_.size()); }
  const ApplyResult& result(int k) const { return results_[k - 1]; }
  const CoreTile* Snapshot(int32_t t, uint64_t version) const {
    auto it = snaps_.find({t, version});
    return it == snaps_.end() ? nullptr : &it->second;
  }

 private:
  const Toolpath& tp_;
  std::unique_ptr<Workpiece> wp_;
  const bool snapshots_;
  std::vector<ApplyResult> results_;
  std::map<std::pair<int32_t, uint64_t>, CoreTile> snaps_;
};

// ---------------------------------------------------------- comparisons

::testing::AssertionResult SameTile(const pb::Tile& got, const CoreTile& want,
                                    int32_t tiles_x, bool doubles,
                                    bool derivatives, bool owners) {
  auto fail = [&]() {
    return ::testing::AssertionFailure()
           << "tile (" << got.tx() << ", " << got.ty() << ") v" << got.version()
           << " vs core tile " << want.t << " v" << want.version << ": ";
  };
  if (got.tx() != want.t % tiles_x || got.ty() != want.t / tiles_x) {
    return fail() << "wrong index";
  }
  if (got.version() != want.version) return fail() << "version differs";
  const Workpiece::TileExtent& e = want.extent;
  if (got.i0() != e.i0 || got.j0() != e.j0 || got.nx() != e.nx ||
      got.ny() != e.ny) {
    return fail() << "extent differs: (" << got.i0() << ", " << got.j0() << ", "
                  << got.nx() << ", " << got.ny() << ")";
  }
  const int n = static_cast<int>(want.w.size());
  if (doubles) {
    if (got.heights_d_size() != n || got.heights_f_size() != 0) {
      return fail() << "heights_d has " << got.heights_d_size()
                    << " values, heights_f " << got.heights_f_size();
    }
    for (int k = 0; k < n; ++k) {
      if (Bits(got.heights_d(k)) != Bits(want.w[k])) {
        return fail() << "heights_d[" << k << "] = " << got.heights_d(k)
                      << ", core " << want.w[k];
      }
    }
  } else {
    if (got.heights_f_size() != n || got.heights_d_size() != 0) {
      return fail() << "heights_f has " << got.heights_f_size()
                    << " values, heights_d " << got.heights_d_size();
    }
    for (int k = 0; k < n; ++k) {
      if (Bits(got.heights_f(k)) != Bits(static_cast<float>(want.w[k]))) {
        return fail() << "heights_f[" << k << "] = " << got.heights_f(k)
                      << ", core " << want.w[k];
      }
    }
  }
  const google::protobuf::RepeatedField<float>* d[5] = {
      &got.wx(), &got.wy(), &got.wxx(), &got.wxy(), &got.wyy()};
  for (int c = 0; c < 5; ++c) {
    if (d[c]->size() != (derivatives ? n : 0)) {
      return fail() << "derivative " << c << " has " << d[c]->size()
                    << " values";
    }
    for (int k = 0; derivatives && k < n; ++k) {
      if (Bits(d[c]->Get(k)) != Bits(want.d[c * n + k])) {
        return fail() << "derivative " << c << " [" << k
                      << "] = " << d[c]->Get(k) << ", core "
                      << want.d[c * n + k];
      }
    }
  }
  if (got.owners_size() != (owners ? n : 0)) {
    return fail() << "owners has " << got.owners_size() << " values";
  }
  for (int k = 0; owners && k < n; ++k) {
    if (got.owners(k) != want.owner[k]) {
      return fail() << "owners[" << k << "] = " << got.owners(k) << ", core "
                    << want.owner[k];
    }
  }
  return ::testing::AssertionSuccess();
}

::testing::AssertionResult SameStats(const pb::ErrorStats& got,
                                     const ErrorStats& want) {
  if (Bits(got.max_error()) != Bits(want.max_error) ||
      Bits(got.mean_error()) != Bits(want.mean_error) ||
      Bits(got.rms_error()) != Bits(want.rms_error) ||
      Bits(got.max_x()) != Bits(want.max_x) ||
      Bits(got.max_y()) != Bits(want.max_y) || got.samples() != want.samples ||
      got.map_cols() != want.map_cols || got.map_rows() != want.map_rows ||
      got.map_max_error_size() != static_cast<int>(want.map.size())) {
    return ::testing::AssertionFailure()
           << "server max " << got.max_error() << " mean " << got.mean_error()
           << " rms " << got.rms_error() << " at (" << got.max_x() << ", "
           << got.max_y() << ") n " << got.samples() << "; core max "
           << want.max_error << " mean " << want.mean_error << " rms "
           << want.rms_error << " at (" << want.max_x << ", " << want.max_y
           << ") n " << want.samples << "; maps " << got.map_cols() << "x"
           << got.map_rows() << " (" << got.map_max_error_size()
           << " cells) vs " << want.map_cols << "x" << want.map_rows << " ("
           << want.map.size() << ")";
  }
  for (size_t k = 0; k < want.map.size(); ++k) {
    if (Bits(got.map_max_error(k)) != Bits(want.map[k])) {
      return ::testing::AssertionFailure()
             << "map_max_error[" << k << "] = " << got.map_max_error(k)
             << ", core " << want.map[k];
    }
  }
  return ::testing::AssertionSuccess();
}

using TileVersions = std::vector<std::tuple<int32_t, int32_t, uint64_t>>;

TileVersions ChangedTiles(const pb::Ack& a) {
  TileVersions out;
  for (const pb::TileVersion& tv : a.changed_tiles()) {
    out.emplace_back(tv.tx(), tv.ty(), tv.version());
  }
  return out;
}

TileVersions ChangedTiles(const ApplyResult& r, int32_t tiles_x) {
  TileVersions out;
  for (int32_t t : r.changed_tiles) {
    out.emplace_back(t % tiles_x, t / tiles_x, r.version);
  }
  return out;
}

// An applied (not duplicate) ack against the core's result for batch k.
void ExpectAck(const pb::Ack& a, int k, const Toolpath& tp,
               const Reference& ref) {
  SCOPED_TRACE(absl::StrCat("ack of batch ", k));
  EXPECT_EQ(a.seq(), static_cast<uint64_t>(k));
  EXPECT_FALSE(a.duplicate());
  EXPECT_EQ(a.moves_applied(), tp.MovesThrough(k));
  EXPECT_EQ(a.node_lowerings(), ref.result(k).node_lowerings);
  EXPECT_EQ(a.version(), ref.result(k).version);
  EXPECT_EQ(ChangedTiles(a), ChangedTiles(ref.result(k), ref.wp().tiles_x()));
}

std::vector<pb::Ack> AcksOf(const std::vector<pb::SimulateResponse>& rs) {
  std::vector<pb::Ack> out;
  for (const auto& r : rs) {
    if (r.has_ack()) out.push_back(r.ack());
  }
  return out;
}

size_t CountAcks(const std::vector<pb::SimulateResponse>& rs) {
  return std::count_if(rs.begin(), rs.end(),
                       [](const auto& r) { return r.has_ack(); });
}

// --------------------------------------------------------------- client

pb::SimulateRequest SubscribeRequest(uint64_t id, pb::Precision precision,
                                     bool derivatives, bool owners) {
  pb::SimulateRequest r;
  pb::Subscribe* s = r.mutable_subscribe();
  s->set_request_id(id);
  s->set_precision(precision);
  s->set_include_derivatives(derivatives);
  s->set_include_owners(owners);
  return r;
}

pb::SimulateRequest StatsRequest(uint64_t id, int32_t map_cols = 0,
                                 int32_t map_rows = 0) {
  pb::SimulateRequest r;
  r.mutable_stats()->set_request_id(id);
  r.mutable_stats()->set_map_cols(map_cols);
  r.mutable_stats()->set_map_rows(map_rows);
  return r;
}

pb::SimulateRequest TileRequest(uint64_t id, uint64_t since,
                                pb::Precision precision, bool derivatives,
                                bool owners) {
  pb::SimulateRequest r;
  pb::TileRequest* t = r.mutable_tiles();
  t->set_request_id(id);
  t->set_since_version(since);
  t->set_precision(precision);
  t->set_include_derivatives(derivatives);
  t->set_include_owners(owners);
  return r;
}

pb::CreateSessionRequest CreateRequest(const std::string& id,
                                       const Toolpath& tp, pb::Scheme scheme) {
  pb::CreateSessionRequest r;
  r.set_session_id(id);
  SetStock(tp.stock, &r);
  r.set_scheme(scheme);
  pb::Tool* decoy = r.add_tools();
  decoy->set_id(kDecoyToolId);
  decoy->mutable_ball()->set_radius(kDecoyRadius);
  pb::Tool* tool = r.add_tools();
  tool->set_id(kToolId);
  tool->mutable_ball()->set_radius(tp.radius);
  return r;
}

// A small valid session: 10 x 10 mm, 10 x 10 elements (one tile).
pb::CreateSessionRequest SmallRequest(const std::string& id) {
  Toolpath tp;
  tp.stock = {0, 0, 10, 10, 0, 10, 10};
  tp.radius = 1;
  return CreateRequest(id, tp, pb::SCHEME_TAYLOR);
}

std::string ReplicaOf(const grpc::ClientContext& ctx) {
  const auto& md = ctx.GetServerInitialMetadata();
  auto it = md.find(kReplicaMetadata);
  return it == md.end() ? "<absent>"
                        : std::string(it->second.data(), it->second.size());
}

// -------------------------------------------------------------- fixture

class ServerTest : public ::testing::Test {
 protected:
  void SetUp() override { spdlog::set_level(spdlog::level::warn); }
  void TearDown() override { StopServer(); }

  void StartServer(const Limits& limits = Limits()) {
    StopServer();
    ServerOptions o;
    o.listen = "127.0.0.1:0";
    o.worker_threads = 2;
    o.limits = limits;
    o.replica = kReplica;
    auto s = SwarfServer::Start(o);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
    ASSERT_GT(server_->port(), 0);
    channel_ = grpc::CreateChannel(absl::StrCat("127.0.0.1:", server_->port()),
                                   grpc::InsecureChannelCredentials());
    stub_ = pb::Swarf::NewStub(channel_);
  }
  void StopServer() {
    stub_.reset();
    channel_.reset();
    if (server_ != nullptr) server_->Shutdown(absl::Seconds(5));
    server_.reset();
  }

  grpc::Status Create(const pb::CreateSessionRequest& req,
                      pb::Session* out = nullptr) {
    grpc::ClientContext ctx;
    ForSession(&ctx, req.session_id());
    pb::Session s;
    grpc::Status st = stub_->CreateSession(&ctx, req, &s);
    if (out != nullptr) *out = s;
    return st;
  }
  grpc::Status GetSession(const std::string& id, pb::Session* out,
                          std::string* replica = nullptr) {
    grpc::ClientContext ctx;
    ForSession(&ctx, id);
    pb::GetSessionRequest req;
    req.set_session_id(id);
    grpc::Status st = stub_->GetSession(&ctx, req, out);
    if (replica != nullptr) *replica = ReplicaOf(ctx);
    return st;
  }
  grpc::Status Delete(const std::string& id) {
    grpc::ClientContext ctx;
    ForSession(&ctx, id);
    pb::DeleteSessionRequest req;
    req.set_session_id(id);
    pb::DeleteSessionResponse resp;
    return stub_->DeleteSession(&ctx, req, &resp);
  }
  grpc::Status ReadTiles(const std::string& id, pb::GetTilesRequest req,
                         std::vector<pb::Tile>* out,
                         std::string* replica = nullptr) {
    grpc::ClientContext ctx;
    grpc::Status st = CollectTiles(stub_.get(), &ctx, id, std::move(req), out);
    if (replica != nullptr) *replica = ReplicaOf(ctx);
    return st;
  }
  grpc::Status AllTiles(const std::string& id, bool derivatives,
                        std::vector<pb::Tile>* out) {
    pb::GetTilesRequest req;
    req.set_precision(pb::PRECISION_DOUBLE);
    req.set_include_derivatives(derivatives);
    req.set_include_owners(true);
    return ReadTiles(id, req, out);
  }

  // Every tile of the session equals the core workpiece, bit for bit.
  void ExpectTilesEqualCore(const std::string& id, const Workpiece& wp,
                            bool derivatives) {
    std::vector<pb::Tile> tiles;
    const grpc::Status st = AllTiles(id, derivatives, &tiles);
    ASSERT_TRUE(st.ok()) << st.error_message();
    ASSERT_EQ(tiles.size(), static_cast<size_t>(wp.tile_count()));
    for (int32_t t = 0; t < wp.tile_count(); ++t) {
      EXPECT_TRUE(SameTile(tiles[t], ReadCore(wp, t), wp.tiles_x(), true,
                           derivatives, true));
    }
  }

  std::unique_ptr<SwarfServer> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::Swarf::Stub> stub_;
};

// ------------------------------------------- 1. paper instances, streamed

struct InstanceCase {
  std::string name;
  int mesh;
  pb::Scheme scheme;
  int batches;
};

void PrintTo(const InstanceCase& c, std::ostream* os) {
  *os << c.name << " mesh " << c.mesh << " scheme " << c.scheme << ", "
      << c.batches << " batches";
}

class InstanceStreamTest : public ServerTest,
                           public ::testing::WithParamInterface<InstanceCase> {
};

TEST_P(InstanceStreamTest, MatchesCoreBitForBit) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  const InstanceCase& c = GetParam();
  const bool taylor = c.scheme == pb::SCHEME_TAYLOR;
  const Toolpath tp = FromInstance(c.name, c.mesh, 8, c.batches);
  const int batches = tp.batches();
  ASSERT_GE(batches, 6);
  Reference ref(tp, taylor ? SchemeKind::kTaylor : SchemeKind::kZmap,
                /*snapshots=*/true);
  const int32_t tiles_x = ref.wp().tiles_x();
  const int32_t tile_count = ref.wp().tile_count();
  const std::string id =
      absl::StrCat(c.name, "-", c.mesh, "-", static_cast<int>(c.scheme));

  pb::Session created;
  grpc::Status st = Create(CreateRequest(id, tp, c.scheme), &created);
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(created.session_id(), id);
  EXPECT_EQ(created.nx(), c.mesh);
  EXPECT_EQ(created.tile_size(), kTileSize);
  EXPECT_EQ(created.tiles_x(), tiles_x);
  EXPECT_EQ(created.tiles_y(), ref.wp().tiles_y());
  EXPECT_EQ(created.last_seq(), 0u);
  EXPECT_FALSE(created.has_last_position());

  // Request ids: the subscription, mid-stream stats (100 + batch), a
  // mid-stream since-version tile request, and the final full read.
  constexpr uint64_t kSubId = 1, kMidTilesId = 500, kFinalId = 999;
  constexpr int kMidTilesAfter = 5, kMidSinceBatch = 3;
  const std::set<int> stats_after = {2, kMidTilesAfter, batches};
  std::map<uint64_t, ErrorStats> want_stats;
  std::vector<CoreTile> want_mid;

  SimStream s(stub_.get(), id);
  ASSERT_TRUE(
      s.Write(SubscribeRequest(kSubId, pb::PRECISION_DOUBLE, taylor, true)));
  for (int k = 1; k <= batches; ++k) {
    ASSERT_TRUE(s.Write(tp.Batch(k)));
    ref.ApplyThrough(k);
    if (stats_after.count(k)) {
      // One of them with an error map.
      ValuationOptions vo;
      if (k == kMidTilesAfter) {
        vo.map_cols = 8;
        vo.map_rows = 6;
      }
      ASSERT_TRUE(s.Write(StatsRequest(100 + k, vo.map_cols, vo.map_rows)));
      want_stats[100 + k] = ValueOrDie(MeasureError(ref.wp(), vo));
      if (k == kMidTilesAfter) {
        ASSERT_EQ(want_stats[100 + k].map.size(), 48u);
      }
    }
    if (k == kMidTilesAfter) {
      const uint64_t since = ref.result(kMidSinceBatch).version;
      ASSERT_GT(since, 0u);  // 0 would mean every tile
      ASSERT_TRUE(s.Write(
          TileRequest(kMidTilesId, since, pb::PRECISION_FLOAT, false, true)));
      for (int32_t t = 0; t < tile_count; ++t) {
        if (ref.wp().TileVersion(t) > since) {
          want_mid.push_back(ReadCore(ref.wp(), t));
        }
      }
    }
  }
  ASSERT_TRUE(
      s.Write(TileRequest(kFinalId, 0, pb::PRECISION_DOUBLE, taylor, true)));
  st = s.Finish();
  ASSERT_TRUE(st.ok()) << st.error_code() << ": " << st.error_message();
  EXPECT_EQ(ReplicaOf(s.context()), kReplica);

  const std::vector<pb::SimulateResponse> rs = s.responses();
  std::vector<size_t> ack_pos;
  std::map<uint64_t, size_t> stats_pos;
  std::vector<size_t> mid_pos;
  std::vector<const pb::Tile*> pushes, mid, final_tiles;
  // Each tile request ends with a TilesDone after its last tile.
  std::map<uint64_t, std::pair<size_t, int64_t>> done;  // id -> (pos, tiles)
  std::map<uint64_t, size_t> last_tile_pos;
  for (size_t i = 0; i < rs.size(); ++i) {
    switch (rs[i].response_case()) {
      case pb::SimulateResponse::kAck:
        ack_pos.push_back(i);
        break;
      case pb::SimulateResponse::kTilesDone:
        EXPECT_TRUE(done.emplace(rs[i].tiles_done().request_id(),
                                 std::pair{i, rs[i].tiles_done().tiles()})
                        .second);
        break;
      case pb::SimulateResponse::kStats:
        EXPECT_TRUE(stats_pos.emplace(rs[i].stats().request_id(), i).second);
        break;
      case pb::SimulateResponse::kTile: {
        const pb::Tile& t = rs[i].tile();
        last_tile_pos[t.request_id()] = i;
        if (t.request_id() == kSubId) {
          pushes.push_back(&t);
        } else if (t.request_id() == kMidTilesId) {
          mid.push_back(&t);
          mid_pos.push_back(i);
        } else if (t.request_id() == kFinalId) {
          final_tiles.push_back(&t);
        } else {
          ADD_FAILURE() << "tile for unknown request " << t.request_id();
        }
        break;
      }
      default:
        ADD_FAILURE() << "unexpected response " << rs[i].ShortDebugString();
    }
  }

  // TilesDone: one per tile request (none for the subscription), after its
  // tiles, counting them.
  ASSERT_EQ(done.size(), 2u);
  ASSERT_TRUE(done.count(kMidTilesId) && done.count(kFinalId));
  EXPECT_EQ(done[kMidTilesId].second, static_cast<int64_t>(mid.size()));
  EXPECT_EQ(done[kFinalId].second, static_cast<int64_t>(final_tiles.size()));
  EXPECT_GT(done[kMidTilesId].first, last_tile_pos[kMidTilesId]);
  EXPECT_GT(done[kFinalId].first, last_tile_pos[kFinalId]);

  // Acks: one per batch, in order, equal to the core's results.
  ASSERT_EQ(ack_pos.size(), static_cast<size_t>(batches));
  for (int k = 1; k <= batches; ++k) {
    ExpectAck(rs[ack_pos[k - 1]].ack(), k, tp, ref);
  }

  // Stats: equal to the core after exactly the batches before them, and
  // answered between those batches' acks and the next.
  for (const auto& [rid, want] : want_stats) {
    SCOPED_TRACE(absl::StrCat("stats ", rid));
    auto it = stats_pos.find(rid);
    ASSERT_NE(it, stats_pos.end());
    EXPECT_TRUE(SameStats(rs[it->second].stats(), want));
    const int k = static_cast<int>(rid - 100);
    EXPECT_GT(it->second, ack_pos[k - 1]);
    if (k < batches) {
      EXPECT_LT(it->second, ack_pos[k]);
    }
  }
  EXPECT_EQ(stats_pos.size(), want_stats.size());

  // Mid-stream since-version tiles: exactly those newer than the version
  // after batch kMidSinceBatch, as they were after batch kMidTilesAfter.
  ASSERT_EQ(mid.size(), want_mid.size());
  ASSERT_FALSE(want_mid.empty());
  for (size_t k = 0; k < mid.size(); ++k) {
    EXPECT_TRUE(SameTile(*mid[k], want_mid[k], tiles_x, false, false, true));
    EXPECT_GT(mid_pos[k], ack_pos[kMidTilesAfter - 1]);
    EXPECT_LT(mid_pos[k], ack_pos[kMidTilesAfter]);
  }

  // Final read: every tile, bit-identical to the core.
  ASSERT_EQ(final_tiles.size(), static_cast<size_t>(tile_count));
  for (int32_t t = 0; t < tile_count; ++t) {
    EXPECT_TRUE(SameTile(*final_tiles[t], ReadCore(ref.wp(), t), tiles_x, true,
                         taylor, true));
  }

  // Pushes: only changed tiles, each equal to the core at the version it
  // claims, and every changed tile pushed at its final version last.
  std::set<int32_t> changed;
  for (int k = 1; k <= batches; ++k) {
    changed.insert(ref.result(k).changed_tiles.begin(),
                   ref.result(k).changed_tiles.end());
  }
  ASSERT_FALSE(changed.empty());
  std::map<int32_t, const pb::Tile*> last_push;
  for (const pb::Tile* p : pushes) {
    const int32_t t = p->ty() * tiles_x + p->tx();
    EXPECT_TRUE(changed.count(t)) << "pushed unchanged tile " << t;
    EXPECT_LE(p->version(), ref.wp().version());
    const CoreTile* snap = ref.Snapshot(t, p->version());
    if (snap == nullptr) {
      ADD_FAILURE() << "tile " << t << " pushed at version " << p->version()
                    << ", at which it did not change";
      continue;
    }
    EXPECT_TRUE(SameTile(*p, *snap, tiles_x, true, taylor, true));
    last_push[t] = p;
  }
  std::set<int32_t> pushed;
  for (const auto& [t, p] : last_push) {
    pushed.insert(t);
    EXPECT_EQ(p->version(), ref.wp().TileVersion(t)) << "tile " << t;
  }
  EXPECT_EQ(pushed, changed);

  // The session's counters.
  pb::Session after;
  std::string replica;
  st = GetSession(id, &after, &replica);
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(replica, kReplica);
  EXPECT_EQ(after.replica(), kReplica);
  EXPECT_EQ(after.last_seq(), static_cast<uint64_t>(batches));
  EXPECT_EQ(after.moves_applied(), ref.wp().move_count());
  EXPECT_EQ(after.moves_applied(), tp.MovesThrough(batches));
  EXPECT_EQ(after.version(), ref.wp().version());
  EXPECT_EQ(after.allocated_tiles(), ref.wp().allocated_tiles());
  ASSERT_TRUE(after.has_last_position());
  EXPECT_EQ(after.last_position().x(), tp.points.back().x);
  EXPECT_EQ(after.last_position().y(), tp.points.back().y);
  EXPECT_EQ(after.last_position().z(), tp.points.back().z);

  // Probe: the scheme's reconstruction, its normal and the nearest node's
  // owner, at points inside, on nodes, and outside (clamped).
  const std::vector<std::pair<double, double>> probes = {
      {50, 50}, {30.3, 29.7}, {12.34, 87.65}, {70.1, 70.6},
      {0, 0},   {100, 100},   {-5, 50.2},     {48.77, 61.9}};
  pb::ProbeRequest preq;
  preq.set_session_id(id);
  for (const auto& [x, y] : probes) {
    preq.add_xy(x);
    preq.add_xy(y);
  }
  pb::ProbeResponse presp;
  {
    grpc::ClientContext ctx;
    ForSession(&ctx, id);
    st = stub_->Probe(&ctx, preq, &presp);
  }
  ASSERT_TRUE(st.ok()) << st.error_message();
  ASSERT_EQ(presp.heights_size(), static_cast<int>(probes.size()));
  ASSERT_EQ(presp.normals_size(), 3 * static_cast<int>(probes.size()));
  ASSERT_EQ(presp.owners_size(), static_cast<int>(probes.size()));
  const GridGeometry& g = ref.wp().grid();
  for (size_t k = 0; k < probes.size(); ++k) {
    const auto [x, y] = probes[k];
    SCOPED_TRACE(absl::StrCat("probe (", x, ", ", y, ")"));
    EXPECT_EQ(Bits(presp.heights(k)), Bits(ref.wp().Reconstruct(x, y)));
    double gx, gy;
    ref.wp().ReconstructGradient(x, y, &gx, &gy);
    const double len = std::sqrt(gx * gx + gy * gy + 1);
    EXPECT_DOUBLE_EQ(presp.normals(3 * k), -gx / len);
    EXPECT_DOUBLE_EQ(presp.normals(3 * k + 1), -gy / len);
    EXPECT_DOUBLE_EQ(presp.normals(3 * k + 2), 1 / len);
    const double cx = std::clamp(x, g.spec().x0, g.spec().x1);
    const double cy = std::clamp(y, g.spec().y0, g.spec().y1);
    const int32_t i =
        static_cast<int32_t>(std::lround((cx - g.spec().x0) / g.dx()));
    const int32_t j =
        static_cast<int32_t>(std::lround((cy - g.spec().y0) / g.dy()));
    EXPECT_EQ(presp.owners(k), ref.wp().Node(i, j).owner);
  }

  // Unary stats over a region with a non-default lattice.
  pb::GetErrorStatsRequest sreq;
  sreq.set_session_id(id);
  sreq.mutable_region()->set_x0(20);
  sreq.mutable_region()->set_y0(25);
  sreq.mutable_region()->set_x1(60);
  sreq.mutable_region()->set_y1(75);
  sreq.set_samples_per_edge(7);
  pb::ErrorStats sresp;
  {
    grpc::ClientContext ctx;
    ForSession(&ctx, id);
    st = stub_->GetErrorStats(&ctx, sreq, &sresp);
  }
  ASSERT_TRUE(st.ok()) << st.error_message();
  ValuationOptions vo;
  vo.samples_per_edge = 7;
  vo.region = Rect{20, 25, 60, 75};
  EXPECT_TRUE(SameStats(sresp, ValueOrDie(MeasureError(ref.wp(), vo))));
  EXPECT_EQ(sresp.scheme(), c.scheme);
}

INSTANTIATE_TEST_SUITE_P(
    PaperInstances, InstanceStreamTest,
    ::testing::Values(InstanceCase{"five-balls", 100, pb::SCHEME_TAYLOR, 7},
                      InstanceCase{"five-cylinders", 100, pb::SCHEME_TAYLOR, 7},
                      InstanceCase{"five-balls", 300, pb::SCHEME_TAYLOR, 9},
                      InstanceCase{"five-cylinders", 300, pb::SCHEME_TAYLOR, 9},
                      InstanceCase{"five-cylinders", 150, pb::SCHEME_ZMAP, 7}),
    [](const ::testing::TestParamInfo<InstanceCase>& info) {
      return absl::StrCat(
          absl::StrReplaceAll(info.param.name, {{"-", "_"}}), "_",
          info.param.mesh, "_",
          info.param.scheme == pb::SCHEME_ZMAP ? "zmap" : "taylor");
    });

// With MoveBatch.reposition a batch's first point only places the tool, so
// the instances' separate moves stream as they are: one batch per move cuts
// exactly the instance, no connecting moves.
TEST_F(ServerTest, RepositionBatchesCutExactlyTheInstanceMoves) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  for (const std::string_view name : kPaperInstances) {
    SCOPED_TRACE(name);
    const Instance inst = ValueOrDie(PaperInstance(name, 120));
    Toolpath tp;  // for the session request only
    tp.stock = inst.stock;
    tp.radius = inst.moves.front().cutter.radius;
    const std::string id = absl::StrCat("reposition-", std::string(name));
    ASSERT_TRUE(Create(CreateRequest(id, tp, pb::SCHEME_TAYLOR)).ok());
    auto wp = ValueOrDie(Workpiece::Create(inst.stock, SchemeKind::kTaylor));
    std::vector<ApplyResult> want;

    SimStream s(stub_.get(), id);
    for (size_t k = 0; k < inst.moves.size(); ++k) {
      const Move& m = inst.moves[k];
      pb::SimulateRequest r =
          MovesRequest(k + 1, kToolId,
                       {m.from.x, m.from.y, m.from.z, m.to.x, m.to.y, m.to.z});
      r.mutable_moves()->set_reposition(true);
      ASSERT_TRUE(s.Write(r));
      want.push_back(ValueOrDie(wp->Apply(std::span<const Move>(&m, 1))));
    }
    // Without reposition the next batch continues from the last point.
    const Vec3 last = inst.moves.back().to;
    ASSERT_TRUE(s.Write(MovesRequest(inst.moves.size() + 1, kToolId,
                                     {last.x, last.y, kSafeZ})));
    const Move lift{last, {last.x, last.y, kSafeZ}, tp.radius};
    want.push_back(ValueOrDie(wp->Apply(std::span<const Move>(&lift, 1))));
    const grpc::Status st = s.Finish();
    ASSERT_TRUE(st.ok()) << st.error_message();

    const std::vector<pb::Ack> acks = AcksOf(s.responses());
    ASSERT_EQ(acks.size(), want.size());
    for (size_t k = 0; k < acks.size(); ++k) {
      SCOPED_TRACE(absl::StrCat("batch ", k + 1));
      EXPECT_EQ(acks[k].seq(), k + 1);
      EXPECT_EQ(acks[k].moves_applied(), static_cast<int64_t>(k + 1));
      EXPECT_EQ(acks[k].node_lowerings(), want[k].node_lowerings);
      EXPECT_EQ(acks[k].version(), want[k].version);
      EXPECT_EQ(ChangedTiles(acks[k]), ChangedTiles(want[k], wp->tiles_x()));
    }
    EXPECT_GT(wp->version(), 0u);
    ExpectTilesEqualCore(id, *wp, true);
  }
}

// ---------------------------------------- 2. GetTiles since a version

TEST_F(ServerTest, GetTilesSinceVersionReturnsExactlyTheLaterChangedTiles) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  // Five balls at mesh 200 (4 x 4 tiles), one ball per batch: each batch
  // changes a different set of tiles.
  const Toolpath tp = FromInstance("five-balls", 200, 4, 5);
  Reference ref(tp, SchemeKind::kTaylor);
  ref.ApplyThrough(tp.batches());
  const std::string id = "since";
  ASSERT_TRUE(Create(CreateRequest(id, tp, pb::SCHEME_TAYLOR)).ok());

  SimStream s(stub_.get(), id);
  for (int k = 1; k <= tp.batches(); ++k) ASSERT_TRUE(s.Write(tp.Batch(k)));
  const grpc::Status fin = s.Finish();
  ASSERT_TRUE(fin.ok()) << fin.error_message();
  const std::vector<pb::Ack> acks = AcksOf(s.responses());
  ASSERT_EQ(acks.size(), static_cast<size_t>(tp.batches()));
  for (int k = 1; k <= tp.batches(); ++k) ExpectAck(acks[k - 1], k, tp, ref);

  const int32_t tiles_x = ref.wp().tiles_x();
  const int32_t tile_count = ref.wp().tile_count();
  std::set<uint64_t> versions = {0};
  for (const pb::Ack& a : acks) versions.insert(a.version());
  versions.insert(ref.wp().version() + 1);
  bool proper_subset_seen = false;
  for (uint64_t v : versions) {
    SCOPED_TRACE(absl::StrCat("since_version ", v));
    // Expected from the acks: tiles changed by a batch after version v,
    // at the version of their last change; every tile for v = 0.
    std::map<std::pair<int32_t, int32_t>, uint64_t> want;
    if (v == 0) {
      for (int32_t t = 0; t < tile_count; ++t) {
        want[{t % tiles_x, t / tiles_x}] = ref.wp().TileVersion(t);
      }
    }
    for (const pb::Ack& a : acks) {
      if (a.version() <= v) continue;
      for (const pb::TileVersion& tv : a.changed_tiles()) {
        uint64_t& w = want[{tv.tx(), tv.ty()}];
        w = std::max(w, tv.version());
      }
    }
    if (!want.empty() && want.size() < static_cast<size_t>(tile_count)) {
      proper_subset_seen = true;
    }
    pb::GetTilesRequest req;
    req.set_since_version(v);
    req.set_include_owners(true);  // float heights (the default precision)
    std::vector<pb::Tile> tiles;
    const grpc::Status st = ReadTiles(id, req, &tiles);
    ASSERT_TRUE(st.ok()) << st.error_message();
    std::map<std::pair<int32_t, int32_t>, uint64_t> got;
    for (const pb::Tile& t : tiles) {
      EXPECT_TRUE(got.emplace(std::pair{t.tx(), t.ty()}, t.version()).second)
          << "tile sent twice";
      EXPECT_TRUE(SameTile(t, ReadCore(ref.wp(), t.ty() * tiles_x + t.tx()),
                           tiles_x, false, false, true));
    }
    EXPECT_EQ(got, want);
  }
  // The instance must make since_version discriminate, or the test says
  // nothing.
  EXPECT_TRUE(proper_subset_seen);

  // A region narrows the selection: nodes in [0, 40]^2 at 0.5 mm are
  // columns and rows 0..80, tiles 0..1 on each axis.
  const uint64_t v = acks[1].version();
  pb::GetTilesRequest req;
  req.set_since_version(v);
  pb::Rect* r = req.mutable_selection()->mutable_region();
  r->set_x0(0);
  r->set_y0(0);
  r->set_x1(40);
  r->set_y1(40);
  std::vector<pb::Tile> tiles;
  ASSERT_TRUE(ReadTiles(id, req, &tiles).ok());
  std::set<std::pair<int32_t, int32_t>> got, want;
  for (const pb::Tile& t : tiles) got.insert({t.tx(), t.ty()});
  for (int32_t t = 0; t < tile_count; ++t) {
    if (t % tiles_x <= 1 && t / tiles_x <= 1 && ref.wp().TileVersion(t) > v) {
      want.insert({t % tiles_x, t / tiles_x});
    }
  }
  EXPECT_EQ(got, want);
}

// ------------------------------------------ 3. concurrent sessions

TEST_F(ServerTest, TileRequestThatMatchesNothingStillEnds) {
  // A client waiting for a TileRequest's answer must learn that there is
  // none: a TilesDone with zero tiles, in order with the acks.
  ASSERT_NO_FATAL_FAILURE(StartServer());
  ASSERT_TRUE(Create(SmallRequest("empty-tiles")).ok());
  SimStream s(stub_.get(), "empty-tiles");
  ASSERT_TRUE(s.Write(MovesRequest(1, kToolId, {1, 5, 1, 9, 5, -0.5})));
  // Nothing changed after the last version: no tile matches.
  ASSERT_TRUE(s.Write(TileRequest(77, 1u << 30, pb::PRECISION_FLOAT, false,
                                  false)));
  ASSERT_TRUE(s.Write(MovesRequest(2, kToolId, {9, 6, -0.5})));
  const grpc::Status st = s.Finish();
  ASSERT_TRUE(st.ok()) << st.error_message();
  const std::vector<pb::SimulateResponse> rs = s.responses();
  ASSERT_EQ(rs.size(), 3u);
  EXPECT_TRUE(rs[0].has_ack());
  ASSERT_TRUE(rs[1].has_tiles_done()) << rs[1].ShortDebugString();
  EXPECT_EQ(rs[1].tiles_done().request_id(), 77u);
  EXPECT_EQ(rs[1].tiles_done().tiles(), 0);
  EXPECT_TRUE(rs[2].has_ack());
}

TEST_F(ServerTest, ConcurrentSessionsDoNotInterfere) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  struct Job {
    std::string id;
    Toolpath tp;
    std::unique_ptr<Reference> ref;
    ErrorStats want_stats;
    grpc::Status status;
    std::vector<pb::SimulateResponse> responses;
  };
  constexpr int kStatsAfter = 4;
  Job jobs[2];
  jobs[0].id = "concurrent-balls";
  jobs[0].tp = FromInstance("five-balls", 200, 8, 8);
  jobs[1].id = "concurrent-cylinders";
  jobs[1].tp = FromInstance("five-cylinders", 200, 8, 8);
  for (Job& j : jobs) {
    j.ref = std::make_unique<Reference>(j.tp, SchemeKind::kTaylor);
    j.ref->ApplyThrough(kStatsAfter);
    j.want_stats = ValueOrDie(MeasureError(j.ref->wp()));
    j.ref->ApplyThrough(j.tp.batches());
    ASSERT_TRUE(Create(CreateRequest(j.id, j.tp, pb::SCHEME_TAYLOR)).ok());
  }

  // Both streams open first, then write at the same time.
  std::latch start(2);
  auto run = [&](Job* j) {
    SimStream s(stub_.get(), j->id);
    start.arrive_and_wait();
    for (int k = 1; k <= j->tp.batches(); ++k) {
      if (!s.Write(j->tp.Batch(k))) break;
      if (k == kStatsAfter && !s.Write(StatsRequest(1))) break;
    }
    j->status = s.Finish();
    j->responses = s.responses();
  };
  std::thread a(run, &jobs[0]), b(run, &jobs[1]);
  a.join();
  b.join();

  for (Job& j : jobs) {
    SCOPED_TRACE(j.id);
    ASSERT_TRUE(j.status.ok()) << j.status.error_message();
    const std::vector<pb::Ack> acks = AcksOf(j.responses);
    ASSERT_EQ(acks.size(), static_cast<size_t>(j.tp.batches()));
    for (int k = 1; k <= j.tp.batches(); ++k) {
      ExpectAck(acks[k - 1], k, j.tp, *j.ref);
    }
    int stats = 0;
    for (const auto& r : j.responses) {
      if (r.has_stats()) {
        ++stats;
        EXPECT_TRUE(SameStats(r.stats(), j.want_stats));
      }
      EXPECT_FALSE(r.has_error()) << r.error().message();
    }
    EXPECT_EQ(stats, 1);
    ExpectTilesEqualCore(j.id, j.ref->wp(), true);
  }
}

// -------------------------------------------------- 4. cancel mid-stream

TEST_F(ServerTest, CancelMidStreamLeavesWholeBatchesOnly) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  // 150 batches of 2000 points (48 KB each): far more than the server reads
  // ahead or flow control lets through before the cancel.
  const Toolpath tp = Raster(150, 2000);
  const int n = tp.batches();
  const std::string id = "cancel";
  ASSERT_TRUE(Create(CreateRequest(id, tp, pb::SCHEME_TAYLOR)).ok());

  SimStream s(stub_.get(), id);
  std::thread writer([&] {
    for (int k = 1; k <= n; ++k) {
      if (!s.Write(tp.Batch(k))) break;
    }
  });
  EXPECT_TRUE(s.WaitFor([](const auto& rs) { return CountAcks(rs) >= 3; }));
  s.Cancel();
  writer.join();
  const grpc::Status fin = s.Finish();
  EXPECT_EQ(fin.error_code(), grpc::StatusCode::CANCELLED)
      << fin.error_message();

  const std::vector<pb::SimulateResponse> rs = s.responses();
  const std::vector<pb::Ack> acks = AcksOf(rs);
  ASSERT_GE(acks.size(), 3u);
  EXPECT_EQ(acks.size(), rs.size()) << "only acks expected";
  for (size_t k = 0; k < acks.size(); ++k) {
    EXPECT_EQ(acks[k].seq(), k + 1);
    EXPECT_EQ(acks[k].moves_applied(), tp.MovesThrough(k + 1));
  }
  const uint64_t last_acked = acks.back().seq();

  // A batch running when the cancel arrived may still land: read the
  // counters and tiles with no batch completing in between (a batch holds
  // the session exclusively, so equal last_seq before and after the reads
  // means the tiles belong to it).
  pb::Session before, after;
  std::vector<pb::Tile> tiles;
  for (int attempt = 0; attempt < 50; ++attempt) {
    tiles.clear();
    ASSERT_TRUE(GetSession(id, &before).ok());
    ASSERT_TRUE(AllTiles(id, true, &tiles).ok());
    ASSERT_TRUE(GetSession(id, &after).ok());
    if (before.last_seq() == after.last_seq()) break;
  }
  ASSERT_EQ(before.last_seq(), after.last_seq());
  const int applied = static_cast<int>(after.last_seq());
  EXPECT_GE(after.last_seq(), last_acked);
  EXPECT_LT(applied, n) << "every batch was applied before the cancel took "
                           "effect: nothing was in flight";
  EXPECT_EQ(after.moves_applied(), tp.MovesThrough(applied));
  const Vec3& last = tp.points[tp.begin[applied] - 1];
  EXPECT_EQ(after.last_position().x(), last.x);
  EXPECT_EQ(after.last_position().y(), last.y);

  Reference ref(tp, SchemeKind::kTaylor);
  ref.ApplyThrough(applied);
  EXPECT_EQ(after.version(), ref.wp().version());
  for (size_t k = 0; k < acks.size(); ++k) {
    EXPECT_EQ(acks[k].version(), ref.result(k + 1).version);
    EXPECT_EQ(acks[k].node_lowerings(), ref.result(k + 1).node_lowerings);
  }
  ASSERT_EQ(tiles.size(), static_cast<size_t>(ref.wp().tile_count()));
  for (int32_t t = 0; t < ref.wp().tile_count(); ++t) {
    EXPECT_TRUE(SameTile(tiles[t], ReadCore(ref.wp(), t), ref.wp().tiles_x(),
                         true, true, true));
  }
}

// ------------------------------------------- 5. reconnect and resume

TEST_F(ServerTest, ResumeOnANewStreamDuplicatesAndGaps) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  const Toolpath tp = FromInstance("five-cylinders", 100, 16, 10);
  const int n = tp.batches();
  Reference full(tp, SchemeKind::kTaylor);
  full.ApplyThrough(n);
  const std::string id = "resume";
  ASSERT_TRUE(Create(CreateRequest(id, tp, pb::SCHEME_TAYLOR)).ok());

  // First stream: six batches, dropped once two are acknowledged.
  uint64_t last_acked = 0;
  {
    SimStream s(stub_.get(), id);
    for (int k = 1; k <= 6; ++k) ASSERT_TRUE(s.Write(tp.Batch(k)));
    ASSERT_TRUE(s.WaitFor([](const auto& rs) { return CountAcks(rs) >= 2; }));
    s.Cancel();
    EXPECT_EQ(s.Finish().error_code(), grpc::StatusCode::CANCELLED);
    const std::vector<pb::Ack> acks = AcksOf(s.responses());
    for (size_t k = 0; k < acks.size(); ++k) {
      EXPECT_EQ(acks[k].seq(), k + 1);
    }
    last_acked = acks.back().seq();
  }
  pb::Session state;
  ASSERT_TRUE(GetSession(id, &state).ok());
  const uint64_t seen_seq = state.last_seq();
  EXPECT_GE(seen_seq, last_acked);
  EXPECT_LE(seen_seq, 6u);

  // Second stream: first re-send the last acknowledged batch, then resume
  // from there as a client does. Batches the first stream applied although
  // their acks were lost come back as duplicates (a prefix: at most the
  // first stream's in-flight batches); the rest are applied exactly once.
  SimStream s(stub_.get(), id);
  ASSERT_TRUE(s.Write(tp.Batch(static_cast<int>(last_acked))));
  for (int k = static_cast<int>(last_acked) + 1; k <= n; ++k) {
    ASSERT_TRUE(s.Write(tp.Batch(k)));
  }
  const size_t want_acks = 1 + n - last_acked;
  ASSERT_TRUE(
      s.WaitFor([&](const auto& rs) { return CountAcks(rs) >= want_acks; }));
  std::vector<pb::Ack> acks = AcksOf(s.responses());
  ASSERT_EQ(acks.size(), want_acks);
  EXPECT_EQ(acks[0].seq(), last_acked);
  EXPECT_TRUE(acks[0].duplicate());
  EXPECT_EQ(acks[0].node_lowerings(), 0);
  EXPECT_EQ(acks[0].changed_tiles_size(), 0);
  uint64_t applied_by_first = last_acked;
  for (size_t i = 1; i < acks.size() && acks[i].duplicate(); ++i) {
    applied_by_first = acks[i].seq();
  }
  EXPECT_GE(applied_by_first, seen_seq);
  EXPECT_LE(applied_by_first, 6u);
  for (size_t i = 1; i < acks.size(); ++i) {
    const int k = static_cast<int>(last_acked + i);
    SCOPED_TRACE(absl::StrCat("resumed batch ", k));
    EXPECT_EQ(acks[i].seq(), static_cast<uint64_t>(k));
    if (static_cast<uint64_t>(k) <= applied_by_first) {
      EXPECT_EQ(acks[i].node_lowerings(), 0);
      EXPECT_EQ(acks[i].changed_tiles_size(), 0);
      EXPECT_GE(acks[i].moves_applied(), tp.MovesThrough(k));
      EXPECT_LE(acks[i].moves_applied(), tp.MovesThrough(applied_by_first));
    } else {
      ExpectAck(acks[i], k, tp, full);
    }
  }
  // The session continued at last_seq + 1: resumed batches were applied.
  EXPECT_LT(applied_by_first, static_cast<uint64_t>(n));

  // Ends identical to an uninterrupted run.
  ASSERT_TRUE(GetSession(id, &state).ok());
  EXPECT_EQ(state.last_seq(), static_cast<uint64_t>(n));
  EXPECT_EQ(state.moves_applied(), tp.MovesThrough(n));
  EXPECT_EQ(state.version(), full.wp().version());
  ExpectTilesEqualCore(id, full.wp(), true);

  // Re-sending an old batch changes nothing.
  ASSERT_TRUE(s.Write(tp.Batch(1)));
  ASSERT_TRUE(s.WaitFor(
      [&](const auto& rs) { return CountAcks(rs) >= want_acks + 1; }));
  const pb::Ack dup = AcksOf(s.responses()).back();
  EXPECT_EQ(dup.seq(), 1u);
  EXPECT_TRUE(dup.duplicate());
  EXPECT_EQ(dup.moves_applied(), tp.MovesThrough(n));
  EXPECT_EQ(dup.version(), full.wp().version());
  EXPECT_EQ(dup.node_lowerings(), 0);
  pb::Session after_dup;
  ASSERT_TRUE(GetSession(id, &after_dup).ok());
  EXPECT_EQ(after_dup.last_seq(), state.last_seq());
  EXPECT_EQ(after_dup.moves_applied(), state.moves_applied());
  EXPECT_EQ(after_dup.version(), state.version());
  ExpectTilesEqualCore(id, full.wp(), true);

  // A gap (last + 2) fails the stream and is not applied.
  ASSERT_TRUE(s.Write(MovesRequest(n + 2, kToolId, {50, 50, -20})));
  const grpc::Status gap = s.Finish();
  EXPECT_EQ(gap.error_code(), grpc::StatusCode::FAILED_PRECONDITION)
      << gap.error_message();
  EXPECT_TRUE(Has(gap.error_message(), "moves.seq")) << gap.error_message();
  pb::Session after_gap;
  ASSERT_TRUE(GetSession(id, &after_gap).ok());
  EXPECT_EQ(after_gap.last_seq(), static_cast<uint64_t>(n));
  EXPECT_EQ(after_gap.moves_applied(), tp.MovesThrough(n));
  EXPECT_EQ(after_gap.version(), full.wp().version());

  // The session goes on at last + 1 on a new stream; a move at kSafeZ
  // cuts nothing.
  SimStream s3(stub_.get(), id);
  ASSERT_TRUE(s3.Write(MovesRequest(n + 1, kToolId, {50, 50, kSafeZ})));
  ASSERT_TRUE(s3.Finish().ok());
  const std::vector<pb::Ack> acks3 = AcksOf(s3.responses());
  ASSERT_EQ(acks3.size(), 1u);
  EXPECT_EQ(acks3[0].seq(), static_cast<uint64_t>(n + 1));
  EXPECT_FALSE(acks3[0].duplicate());
  EXPECT_EQ(acks3[0].moves_applied(), tp.MovesThrough(n) + 1);
  EXPECT_EQ(acks3[0].version(), full.wp().version());
}

// ------------------------------------------------- 6. status codes

struct BadCreate {
  std::string what;
  std::function<void(pb::CreateSessionRequest*)> mutate;
  grpc::StatusCode code;
  std::string names;  // the message must contain this
};

TEST_F(ServerTest, CreateSessionRejectsBadRequestsNamingTheField) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const std::vector<BadCreate> cases = {
      {"radius 0",
       [](auto* r) { r->mutable_tools(1)->mutable_ball()->set_radius(0); },
       grpc::StatusCode::INVALID_ARGUMENT, "tools[1].ball.radius"},
      {"radius < 0",
       [](auto* r) { r->mutable_tools(0)->mutable_ball()->set_radius(-1); },
       grpc::StatusCode::INVALID_ARGUMENT, "tools[0].ball.radius"},
      {"radius NaN",
       [=](auto* r) { r->mutable_tools(0)->mutable_ball()->set_radius(nan); },
       grpc::StatusCode::INVALID_ARGUMENT, "tools[0].ball.radius"},
      {"x1 == x0", [](auto* r) { r->mutable_stock()->set_x1(0); },
       grpc::StatusCode::INVALID_ARGUMENT, "stock.x1"},
      {"x1 < x0 with spacing",
       [](auto* r) {
         r->mutable_stock()->set_x1(-5);
         r->set_nx(0);
         r->set_ny(0);
         r->set_spacing(1);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "stock.x1"},
      {"y1 < y0", [](auto* r) { r->mutable_stock()->set_y1(-1); },
       grpc::StatusCode::INVALID_ARGUMENT, "stock.y1"},
      {"z_top Inf",
       [](auto* r) {
         r->mutable_stock()->set_z_top(std::numeric_limits<double>::infinity());
       },
       grpc::StatusCode::INVALID_ARGUMENT, "stock.z_top"},
      {"no stock", [](auto* r) { r->clear_stock(); },
       grpc::StatusCode::INVALID_ARGUMENT, "stock"},
      {"zero elements",
       [](auto* r) {
         r->set_nx(0);
         r->set_ny(0);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "nx"},
      {"nx 0", [](auto* r) { r->set_nx(0); },
       grpc::StatusCode::INVALID_ARGUMENT, "stock.nx"},
      {"ny < 0", [](auto* r) { r->set_ny(-3); },
       grpc::StatusCode::INVALID_ARGUMENT, "stock.ny"},
      {"counts and spacing", [](auto* r) { r->set_spacing(1); },
       grpc::StatusCode::INVALID_ARGUMENT, "spacing"},
      {"no tools", [](auto* r) { r->clear_tools(); },
       grpc::StatusCode::INVALID_ARGUMENT, "tools"},
      {"tool id twice",
       [](auto* r) { r->mutable_tools(1)->set_id(kDecoyToolId); },
       grpc::StatusCode::INVALID_ARGUMENT, "tools[1].id"},
      {"tool without shape", [](auto* r) { r->mutable_tools(1)->clear_ball(); },
       grpc::StatusCode::INVALID_ARGUMENT, "tools[1]"},
      {"bad id characters", [](auto* r) { r->set_session_id("bad id!"); },
       grpc::StatusCode::INVALID_ARGUMENT, "session_id"},
      {"id too long", [](auto* r) { r->set_session_id(std::string(65, 'a')); },
       grpc::StatusCode::INVALID_ARGUMENT, "session_id"},
      {"flat tool of zero radius",
       [](auto* r) { r->mutable_tools(1)->mutable_flat()->set_radius(0); },
       grpc::StatusCode::INVALID_ARGUMENT, "tools[1].flat.radius"},
      {"bull-nose corner above the radius",
       [](auto* r) {
         r->mutable_tools(0)->mutable_bull_nose()->set_radius(3);
         r->mutable_tools(0)->mutable_bull_nose()->set_corner_radius(4);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "tools[0].bull_nose.corner_radius"},
  };
  for (const BadCreate& c : cases) {
    SCOPED_TRACE(c.what);
    pb::CreateSessionRequest req = SmallRequest("bad-create");
    c.mutate(&req);
    // The metadata carries the (possibly bad) id like the field.
    const grpc::Status st = Create(req);
    EXPECT_EQ(st.error_code(), c.code) << st.error_message();
    EXPECT_TRUE(Has(st.error_message(), c.names)) << st.error_message();
  }
  // The field and the metadata must agree.
  {
    grpc::ClientContext ctx;
    ForSession(&ctx, "other-id");
    pb::Session s;
    const grpc::Status st =
        stub_->CreateSession(&ctx, SmallRequest("bad-create"), &s);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_TRUE(Has(st.error_message(), "session_id")) << st.error_message();
  }
  // Nothing was created by the rejected requests.
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  pb::ListSessionsResponse list;
  ASSERT_TRUE(stub_->ListSessions(&ctx, {}, &list).ok());
  EXPECT_EQ(list.sessions_size(), 0);
}

TEST_F(ServerTest, NotFoundAndAlreadyExists) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  pb::Session s;
  grpc::Status st = GetSession("nope", &s);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(Has(st.error_message(), "nope")) << st.error_message();
  {
    SimStream sim(stub_.get(), "nope");
    st = sim.Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND);
  }
  {
    // Simulate names its session only by metadata.
    SimStream sim(stub_.get(), "");
    st = sim.Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_TRUE(Has(st.error_message(), kSessionMetadata))
        << st.error_message();
  }
  std::vector<pb::Tile> tiles;
  EXPECT_EQ(ReadTiles("nope", {}, &tiles).error_code(),
            grpc::StatusCode::NOT_FOUND);

  ASSERT_TRUE(Create(SmallRequest("twice")).ok());
  st = Create(SmallRequest("twice"));
  EXPECT_EQ(st.error_code(), grpc::StatusCode::ALREADY_EXISTS);
  EXPECT_TRUE(Has(st.error_message(), "twice")) << st.error_message();

  ASSERT_TRUE(Delete("twice").ok());
  EXPECT_EQ(GetSession("twice", &s).error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(Delete("twice").error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_TRUE(Create(SmallRequest("twice")).ok());
}

TEST_F(ServerTest, PerRequestErrorsKeepTheStreamGoing) {
  Limits limits;
  limits.max_batch_points = 100;
  ASSERT_NO_FATAL_FAILURE(StartServer(limits));
  const std::string id = "errors";
  ASSERT_TRUE(Create(SmallRequest(id)).ok());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  // A valid polyline of `points` points at depth 0.5 inside the stock.
  auto line = [](int points, double y) {
    std::vector<double> xyz;
    for (int p = 0; p < points; ++p) {
      xyz.insert(xyz.end(), {1 + 8.0 * p / (points - 1), y, -0.5});
    }
    return xyz;
  };
  std::vector<double> with_nan = line(10, 5), with_inf = line(10, 5);
  with_nan[4] = nan;
  with_inf[2] = -inf;
  std::vector<double> ragged = line(10, 5);
  ragged.pop_back();

  SimStream s(stub_.get(), id);
  struct Expected {
    int code;  // 0: an ack
    uint64_t id;
    std::string names;
  };
  std::vector<Expected> want;
  auto send = [&](const pb::SimulateRequest& r, Expected e) {
    ASSERT_TRUE(s.Write(r));
    want.push_back(e);
  };
  send(MovesRequest(1, kToolId, with_nan), {3, 1, "xyz[4]"});
  send(MovesRequest(1, kToolId, with_inf), {3, 1, "xyz[2]"});
  send(MovesRequest(1, 99, line(10, 5)), {3, 1, "tool_id"});
  send(MovesRequest(1, kToolId, line(101, 5)), {3, 1, "xyz"});
  send(MovesRequest(1, kToolId, ragged), {3, 1, "xyz"});
  send(MovesRequest(0, kToolId, line(10, 5)), {3, 0, "seq"});
  // None of the rejected batches consumed seq 1; the batch limit is
  // inclusive.
  send(MovesRequest(1, kToolId, line(100, 5)), {0, 1, ""});
  {
    pb::SimulateRequest r =
        TileRequest(7, 0, pb::PRECISION_FLOAT, false, false);
    pb::TileIndex* t = r.mutable_tiles()->mutable_selection()->add_tiles();
    t->set_tx(5);
    t->set_ty(0);
    send(r, {3, 7, "selection.tiles[0]"});
  }
  {
    pb::SimulateRequest r = StatsRequest(8);
    r.mutable_stats()->set_samples_per_edge(1);
    send(r, {3, 8, "samples_per_edge"});
  }
  {
    pb::SimulateRequest r = StatsRequest(9);
    r.mutable_stats()->mutable_region()->set_x0(nan);
    send(r, {3, 9, "region"});
  }
  send(MovesRequest(2, kToolId, line(10, 7)), {0, 2, ""});
  const grpc::Status st = s.Finish();
  ASSERT_TRUE(st.ok()) << st.error_message();
  const std::vector<pb::SimulateResponse> rs = s.responses();
  ASSERT_EQ(rs.size(), want.size());
  for (size_t k = 0; k < rs.size(); ++k) {
    SCOPED_TRACE(absl::StrCat("response ", k, ": ", rs[k].ShortDebugString()));
    if (want[k].code == 0) {
      ASSERT_TRUE(rs[k].has_ack());
      EXPECT_EQ(rs[k].ack().seq(), want[k].id);
      EXPECT_FALSE(rs[k].ack().duplicate());
    } else {
      ASSERT_TRUE(rs[k].has_error());
      EXPECT_EQ(rs[k].error().code(), want[k].code);
      EXPECT_EQ(rs[k].error().request_id(), want[k].id);
      EXPECT_TRUE(Has(rs[k].error().message(), want[k].names));
    }
  }
  pb::Session state;
  ASSERT_TRUE(GetSession(id, &state).ok());
  EXPECT_EQ(state.last_seq(), 2u);
  EXPECT_EQ(state.moves_applied(), 99 + 10);
}

TEST_F(ServerTest, FailedPreconditionDerivativesOfZmapAndSeqGap) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  const std::string id = "zmap";
  pb::CreateSessionRequest req = SmallRequest(id);
  req.set_scheme(pb::SCHEME_ZMAP);
  ASSERT_TRUE(Create(req).ok());

  SimStream s(stub_.get(), id);
  ASSERT_TRUE(s.Write(
      TileRequest(1, 0, pb::PRECISION_DOUBLE, /*derivatives=*/true, false)));
  ASSERT_TRUE(s.Write(SubscribeRequest(2, pb::PRECISION_DOUBLE, true, false)));
  ASSERT_TRUE(s.Write(MovesRequest(1, kToolId, {5, 5, 5, 5, 5, -1})));
  // A gap: seq 3 after 1.
  ASSERT_TRUE(s.Write(MovesRequest(3, kToolId, {6, 6, -1})));
  const grpc::Status st = s.Finish();
  EXPECT_EQ(st.error_code(), grpc::StatusCode::FAILED_PRECONDITION)
      << st.error_message();
  EXPECT_TRUE(Has(st.error_message(), "moves.seq")) << st.error_message();
  const std::vector<pb::SimulateResponse> rs = s.responses();
  ASSERT_EQ(rs.size(), 3u);
  for (int k = 0; k < 2; ++k) {
    ASSERT_TRUE(rs[k].has_error());
    EXPECT_EQ(rs[k].error().code(), grpc::StatusCode::FAILED_PRECONDITION);
    EXPECT_EQ(rs[k].error().request_id(), static_cast<uint64_t>(k + 1));
    EXPECT_TRUE(Has(rs[k].error().message(), "include_derivatives"))
        << rs[k].error().message();
  }
  ASSERT_TRUE(rs[2].has_ack());
  EXPECT_EQ(rs[2].ack().seq(), 1u);

  pb::GetTilesRequest treq;
  treq.set_include_derivatives(true);
  std::vector<pb::Tile> tiles;
  const grpc::Status tst = ReadTiles(id, treq, &tiles);
  EXPECT_EQ(tst.error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_TRUE(Has(tst.error_message(), "include_derivatives"))
      << tst.error_message();
  pb::Session state;
  ASSERT_TRUE(GetSession(id, &state).ok());
  EXPECT_EQ(state.last_seq(), 1u);
}

TEST_F(ServerTest, ResourceExhaustedAtEachLimit) {
  // Sessions.
  {
    Limits limits;
    limits.max_sessions = 2;
    ASSERT_NO_FATAL_FAILURE(StartServer(limits));
    ASSERT_TRUE(Create(SmallRequest("a")).ok());
    ASSERT_TRUE(Create(SmallRequest("b")).ok());
    const grpc::Status st = Create(SmallRequest("c"));
    EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    EXPECT_TRUE(Has(st.error_message(), "sessions")) << st.error_message();
    ASSERT_TRUE(Delete("a").ok());
    EXPECT_TRUE(Create(SmallRequest("c")).ok());
  }
  // Bytes, not nodes (issue 28): a taylor tile is 64 x 64 nodes of 12 bytes
  // in the tile arena's 2 MiB chunks (42 tiles each), plus 80 bytes of
  // bookkeeping: one tile takes a chunk.
  const StockSpec small{0, 0, 10, 10, 0, 10, 10};
  const int64_t one = Session::EstimateMemoryBytes(small, SchemeKind::kTaylor);
  ASSERT_EQ(one, (2 << 20) + 80);
  // Bytes per session: a session of exactly the limit is admitted, one
  // element more (a second tile) is refused, naming both.
  {
    Limits limits;
    limits.max_session_memory_bytes = one;
    ASSERT_NO_FATAL_FAILURE(StartServer(limits));
    pb::CreateSessionRequest req = SmallRequest("fits");
    req.set_nx(63);
    req.set_ny(63);
    EXPECT_TRUE(Create(req).ok());
    req.set_session_id("too-big");
    req.set_nx(64);
    const grpc::Status st = Create(req);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    EXPECT_EQ(st.error_message(),
              "the session needs 2097312 bytes (2.0 MiB for 64 x 63 elements, "
              "every tile cut); this server allows 2097232 bytes (2.0 MiB) "
              "per session (--max_session_memory_mb)");
  }
  // Total memory: room for exactly two one-tile taylor sessions.
  {
    Limits limits;
    limits.max_total_memory_bytes = 2 * one;
    ASSERT_NO_FATAL_FAILURE(StartServer(limits));
    ASSERT_TRUE(Create(SmallRequest("m1")).ok());
    ASSERT_TRUE(Create(SmallRequest("m2")).ok());  // right at the limit
    const grpc::Status st = Create(SmallRequest("m3"));
    EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    EXPECT_EQ(st.error_message(),
              "the session needs 2097232 bytes (2.0 MiB for 10 x 10 elements, "
              "every tile cut); "
              "this server has 0 bytes (0.0 MiB) left of the 4194464 bytes "
              "(4.0 MiB) all its sessions may take (--max_total_memory_mb)");
    // Deleting returns the reservation.
    ASSERT_TRUE(Delete("m1").ok());
    EXPECT_TRUE(Create(SmallRequest("m3")).ok());
  }
  // No node cap: with the default limits, a grid past the old cap of 64 Mi
  // nodes (8193 x 8193 nodes, 129 x 129 tiles: 834 MB) is admitted (its
  // tiles are allocated only when cut), and one whose bytes exceed the
  // total is RESOURCE_EXHAUSTED, even past the core's node limit (which
  // alone would be INVALID_ARGUMENT).
  {
    ASSERT_NO_FATAL_FAILURE(StartServer(Limits{}));
    pb::CreateSessionRequest req = SmallRequest("past-old-cap");
    req.set_nx(8192);
    req.set_ny(8192);
    EXPECT_TRUE(Create(req).ok());
    pb::Session state;
    ASSERT_TRUE(GetSession("past-old-cap", &state).ok());
    // Only the move index's empty bins: one vector (24 bytes) per 16 x 16
    // elements, 512 x 512 of them.
    EXPECT_EQ(state.memory_bytes(), 512 * 512 * 24);
    req.set_session_id("huge");
    req.set_nx(kMaxElementsPerAxis);
    req.set_ny(kMaxElementsPerAxis);
    const grpc::Status st = Create(req);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
    const int64_t side = (int64_t{kMaxElementsPerAxis} + 64) / 64;
    const int64_t tiles = side * side;
    const int64_t chunks = (tiles + 41) / 42;
    EXPECT_TRUE(Has(st.error_message(),
                    absl::StrCat("the session needs ",
                                 chunks * (2 << 20) + tiles * 80, " bytes")))
        << st.error_message();
    EXPECT_TRUE(Has(st.error_message(), "left of the 8589934592 bytes"))
        << st.error_message();
  }
  // gRPC message size: a batch message over max_message_bytes fails the
  // stream before it reaches the session.
  {
    Limits limits;
    limits.max_message_bytes = 1 << 20;  // the server's floor
    limits.max_batch_points = 40000;      // a full batch still fits
    ASSERT_NO_FATAL_FAILURE(StartServer(limits));
    ASSERT_TRUE(Create(SmallRequest("big")).ok());
    std::vector<double> xyz;
    for (int p = 0; p < 60000; ++p) {  // 1.44 MB of doubles
      xyz.insert(xyz.end(), {1 + 8.0 * p / 59999, 5, -0.5});
    }
    SimStream s(stub_.get(), "big");
    // The write may or may not report the failure.
    s.Write(MovesRequest(1, kToolId, xyz));
    const grpc::Status st = s.Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED)
        << st.error_message();
    EXPECT_EQ(CountAcks(s.responses()), 0u);
    pb::Session state;
    ASSERT_TRUE(GetSession("big", &state).ok());
    EXPECT_EQ(state.last_seq(), 0u);
    EXPECT_EQ(state.moves_applied(), 0);
  }
}

// ------------------------------------------ health and replica metadata

std::string Flatten(const grpc::ByteBuffer& b) {
  std::vector<grpc::Slice> slices;
  std::string out;
  if (!b.Dump(&slices).ok()) return out;
  for (const grpc::Slice& s : slices) {
    out.append(reinterpret_cast<const char*>(s.begin()), s.size());
  }
  return out;
}

// grpc.health.v1.Health/Check through the generic stub: no health proto
// headers ship with the Debian packages, and the messages are tiny.
grpc::Status HealthCheck(const std::shared_ptr<grpc::Channel>& channel,
                         const std::string& service, std::string* response) {
  std::string request;
  if (!service.empty()) {  // field 1 (string), length-delimited
    request.push_back(0x0a);
    request.push_back(static_cast<char>(service.size()));
    request += service;
  }
  grpc::Slice slice(request);
  grpc::ByteBuffer req(&slice, 1), resp;
  grpc::GenericStub stub(channel);
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  std::promise<grpc::Status> done;
  stub.UnaryCall(&ctx, "/grpc.health.v1.Health/Check", grpc::StubOptions(),
                 &req, &resp, [&](grpc::Status s) { done.set_value(s); });
  grpc::Status st = done.get_future().get();
  *response = Flatten(resp);
  return st;
}

TEST_F(ServerTest, HealthServingAndReplicaMetadata) {
  ASSERT_NO_FATAL_FAILURE(StartServer());
  std::string resp;
  grpc::Status st = HealthCheck(channel_, "", &resp);
  ASSERT_TRUE(st.ok()) << st.error_message();
  // HealthCheckResponse{status: SERVING (1)}.
  EXPECT_EQ(resp, std::string("\x08\x01", 2));
  // Probes that name the service (Kubernetes' grpc probe `service`).
  resp.clear();
  st = HealthCheck(channel_, "swarf.v1.Swarf", &resp);
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(resp, std::string("\x08\x01", 2));
  st = HealthCheck(channel_, "no.such.Service", &resp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND);

  // Every kind of call names the replica in its response metadata.
  const std::string id = "meta";
  {
    grpc::ClientContext ctx;
    ForSession(&ctx, id);
    pb::Session s;
    ASSERT_TRUE(stub_->CreateSession(&ctx, SmallRequest(id), &s).ok());
    EXPECT_EQ(ReplicaOf(ctx), kReplica);
    EXPECT_EQ(s.replica(), kReplica);
  }
  pb::Session s;
  std::string replica;
  ASSERT_TRUE(GetSession(id, &s, &replica).ok());
  EXPECT_EQ(replica, kReplica);
  std::vector<pb::Tile> tiles;
  ASSERT_TRUE(ReadTiles(id, {}, &tiles, &replica).ok());
  EXPECT_EQ(replica, kReplica);
  EXPECT_EQ(tiles.size(), 1u);
  SimStream sim(stub_.get(), id);
  ASSERT_TRUE(sim.Write(StatsRequest(1)));
  ASSERT_TRUE(sim.Finish().ok());
  EXPECT_EQ(ReplicaOf(sim.context()), kReplica);
  // Also on an error.
  EXPECT_EQ(GetSession("absent", &s, &replica).error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(replica, kReplica);
}

}  // namespace
}  // namespace swarf::server
