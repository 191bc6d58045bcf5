// Sessions written by an older swarfd restore unchanged in this one.
// tests/data/v1_sessions holds what a real swarfd of commit 5d6008b wrote
// (README.md and make_fixture.py there): three sessions (taylor with two
// tools and a reposition, guarded, zmap; ball tools), each journaled and
// snapshotted mid-job in the version-1 state format ("SWARFWP1", which
// stored five derivatives per node), with journal batches after the
// snapshot, and what the old server reported just before it was killed
// (expected.txt: counters and a digest of every tile).
//
// Against the recipe's moves cut batch by batch by the current core:
// - the fixture itself: each journal holds the recipe's batches bit for
//   bit, and each snapshot's payload is the current core's state after the
//   snapshot's batches in the version-1 format, byte for byte (heights,
//   owners, versions and the stored derivatives);
// - a new swarfd on a copy restores every session from its snapshot plus
//   the journal's tail (snapshot_seq, the log): counters, and every tile's
//   heights, owners, derivatives and versions bit-identical to the core's
//   and to what the old server served; resent batches are recognised, one
//   more batch streams on; SIGTERM rewrites the snapshots in the current
//   format, and a second restart loads them to the same state;
// - without the snapshots the whole journal is replayed, to the same state.
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "core/cutter/cutter.h"
#include "core/workpiece.h"
#include "grpcpp/grpcpp.h"
#include "gtest/gtest.h"
#include "server/journal.h"
#include "server/snapshot.h"
#include "swarf/v1/swarf.grpc.pb.h"
#include "tests/server_test_util.h"
#include "tests/sim_stream.h"
#include "tests/state_v1.h"
#include "tests/swarfd_process.h"

namespace swarf {
namespace {

namespace pb = ::swarf::v1;
namespace fs = std::filesystem;
using ::swarf::testing::CollectTiles;
using ::swarf::testing::ForSession;
using ::swarf::testing::MovesRequest;
using ::swarf::testing::ReadFileText;
using ::swarf::testing::SimStream;
using ::swarf::testing::SwarfdProcess;
using ::swarf::testing::UnlimitedChannel;
using ::swarf::testing::ValueOrDie;

const fs::path kFixture = SWARF_V1_SESSIONS_DIR;

struct Batch {
  int32_t tool = 0;
  bool reposition = false;
  std::vector<double> xyz;
};

// A session of make_fixture.py's SESSIONS, and its batches' points.
struct Recipe {
  std::string id;
  SchemeKind scheme;
  pb::Scheme proto_scheme;
  StockSpec stock;
  std::vector<std::pair<int32_t, double>> tools;  // id, ball radius
  // The raster: points per row, steps along x and between rows.
  int per_row;
  double sx, sy;
  struct Part {
    int32_t tool;
    bool reposition;
    int points;
  };
  std::vector<Part> batches;

  // make_fixture.py's Points(): the same operations in the same order on
  // IEEE doubles (the build has -ffp-contract=off), so the same bits.
  std::vector<double> Points(int first, int count) const {
    std::vector<double> xyz;
    for (int k = first; k < first + count; ++k) {
      const int row = k / per_row;
      const int col = k % per_row;
      const int u = row % 2 == 0 ? col : per_row - 1 - col;
      xyz.push_back(stock.x0 + 0.3 + u * sx);
      xyz.push_back(stock.y0 + 0.3 + row * sy);
      xyz.push_back(stock.z_top - 0.3 - 0.1 * ((row * 5 + u * 3) % 7) / 6);
    }
    return xyz;
  }
  std::vector<Batch> Batches() const {
    std::vector<Batch> out;
    int first = 0;
    for (const Part& p : batches) {
      out.push_back({p.tool, p.reposition, Points(first, p.points)});
      first += p.points;
    }
    return out;
  }
  double Radius(int32_t tool) const {
    for (const auto& [id, r] : tools) {
      if (id == tool) return r;
    }
    return 0;
  }
};

std::vector<Recipe> Recipes() {
  std::vector<Recipe::Part> taylor(8, {1, false, 40});
  taylor.push_back({2, true, 40});  // a tool change
  taylor.insert(taylor.end(), 3, {2, false, 40});
  return {
      {.id = "v1-taylor",
       .scheme = SchemeKind::kTaylor,
       .proto_scheme = pb::SCHEME_TAYLOR,
       .stock = {-2, 1, 6, 5, 10, 80, 40},
       .tools = {{1, 0.5}, {2, 0.25}},
       .per_row = 60,
       .sx = 0.12,
       .sy = 0.2,
       .batches = taylor},
      {.id = "v1-guarded",
       .scheme = SchemeKind::kGuarded,
       .proto_scheme = pb::SCHEME_GUARDED,
       .stock = {0, 0, 4, 4, 0, 40, 40},
       .tools = {{1, 0.4}},
       .per_row = 30,
       .sx = 0.12,
       .sy = 0.15,
       .batches = std::vector<Recipe::Part>(12, {1, false, 30})},
      {.id = "v1-zmap",
       .scheme = SchemeKind::kZmap,
       .proto_scheme = pb::SCHEME_ZMAP,
       .stock = {0, 0, 4, 4, 0, 40, 40},
       .tools = {{1, 0.3}},
       .per_row = 30,
       .sx = 0.12,
       .sy = 0.15,
       .batches = std::vector<Recipe::Part>(10, {1, false, 36})},
  };
}

// One more batch after the fixture's: a diagonal across the stock with
// tool 1, continuing from the last point.
Batch ExtraBatch(const Recipe& r) {
  Batch b{1, false, {}};
  const StockSpec& s = r.stock;
  for (int k = 0; k < 20; ++k) {
    b.xyz.push_back(s.x0 + 0.4 + k * (s.x1 - s.x0 - 0.8) / 19);
    b.xyz.push_back(s.y0 + 0.4 + k * (s.y1 - s.y0 - 0.8) / 19);
    b.xyz.push_back(s.z_top - 0.45);
  }
  return b;
}

// What the old server reported before it was killed (expected.txt).
struct Expected {
  uint64_t last_seq = 0, snapshot_seq = 0;
  int64_t moves = 0;
  uint64_t version = 0;
  uint64_t digest = 0;  // of its tiles, as TilesDigest below
};

std::map<std::string, Expected> ReadExpected() {
  std::map<std::string, Expected> out;
  std::istringstream in(ReadFileText((kFixture / "expected.txt").string()));
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream f(line);
    std::string id, digest;
    Expected e;
    f >> id >> e.last_seq >> e.snapshot_seq >> e.moves >> e.version >> digest;
    e.digest = std::stoull(digest, nullptr, 16);
    out[id] = e;
  }
  return out;
}

// The recipe's workpiece in the current core: batches applied one Apply
// each, as a session applies them (continuing from the last point unless
// the batch repositions).
class Reference {
 public:
  explicit Reference(const Recipe& r)
      : recipe_(r), wp_(ValueOrDie(Workpiece::Create(r.stock, r.scheme))) {}
  void Apply(const Batch& b) {
    std::vector<Move> moves;
    const Cutter cutter = Cutter::Ball(recipe_.Radius(b.tool));
    std::optional<Vec3> pos = b.reposition ? std::nullopt : last_;
    for (size_t p = 0; p + 2 < b.xyz.size(); p += 3) {
      const Vec3 next{b.xyz[p], b.xyz[p + 1], b.xyz[p + 2]};
      if (pos.has_value()) moves.push_back({*pos, next, cutter});
      pos = next;
    }
    last_ = pos;
    ValueOrDie(wp_->Apply(moves));
  }
  const Workpiece& wp() const { return *wp_; }
  const std::optional<Vec3>& last() const { return last_; }

 private:
  const Recipe& recipe_;
  std::unique_ptr<Workpiece> wp_;
  std::optional<Vec3> last_;
};

std::unique_ptr<Reference> CutReference(const Recipe& r, size_t batches) {
  auto ref = std::make_unique<Reference>(r);
  const std::vector<Batch> all = r.Batches();
  for (size_t k = 0; k < batches && k < all.size(); ++k) ref->Apply(all[k]);
  return ref;
}

template <typename T>
bool SameBits(const T& a, const T& b) {
  return std::memcmp(&a, &b, sizeof(T)) == 0;
}

template <typename T>
void AppendBytes(std::string* out, const T* data, size_t n) {
  out->append(reinterpret_cast<const char*>(data), n * sizeof(T));
}

// make_fixture.py's TilesDigest: FNV-1a 64 over every tile as served: tx,
// ty (i32), version (u64), heights (f64), owners (i32), wx, wy, wxx, wxy,
// wyy (f32, zeros when not served), little-endian.
uint64_t Fnv1a(uint64_t h, const std::string& bytes) {
  for (unsigned char c : bytes) h = (h ^ c) * 0x100000001b3ull;
  return h;
}

// Reads every tile of session `id` and expects each bit-identical to the
// reference (heights, owners, derivatives unless zmap, tile versions).
// Returns the digest of what was served.
uint64_t CheckTiles(pb::Swarf::Stub* stub, const std::string& id,
                    const Workpiece& ref) {
  pb::GetTilesRequest req;
  req.set_precision(pb::PRECISION_DOUBLE);
  req.set_include_owners(true);
  const bool derivs = ref.scheme().kind() != SchemeKind::kZmap;
  req.set_include_derivatives(derivs);
  std::vector<pb::Tile> tiles;
  grpc::ClientContext ctx;
  const grpc::Status st = CollectTiles(stub, &ctx, id, req, &tiles);
  EXPECT_TRUE(st.ok()) << id << ": " << st.error_code() << " "
                       << st.error_message();
  EXPECT_EQ(static_cast<int>(tiles.size()), ref.tile_count()) << id;
  uint64_t digest = 0xcbf29ce484222325ull;
  for (const pb::Tile& t : tiles) {
    const int32_t index = t.ty() * ref.tiles_x() + t.tx();
    const Workpiece::TileExtent e = ref.Extent(index);
    const int n = e.nx * e.ny;
    EXPECT_EQ(t.i0(), e.i0);
    EXPECT_EQ(t.j0(), e.j0);
    EXPECT_EQ(t.nx(), e.nx);
    EXPECT_EQ(t.ny(), e.ny);
    EXPECT_EQ(t.version(), ref.TileVersion(index)) << id << " tile " << index;
    std::vector<double> w(n);
    std::vector<int32_t> owner(n);
    std::vector<float> d(5 * n);
    float* dp[5];
    for (int c = 0; c < 5; ++c) dp[c] = d.data() + c * n;
    ref.ReadTile(index, w.data(), dp, owner.data());
    const google::protobuf::RepeatedField<float>* served[5] = {
        &t.wx(), &t.wy(), &t.wxx(), &t.wxy(), &t.wyy()};
    EXPECT_EQ(t.heights_d_size(), n);
    EXPECT_EQ(t.owners_size(), n);
    for (int c = 0; c < 5; ++c) {
      EXPECT_EQ(served[c]->size(), derivs ? n : 0) << "derivative " << c;
    }
    if (::testing::Test::HasFailure()) return 0;
    int wrong = 0;
    for (int k = 0; k < n; ++k) {
      bool same = SameBits(w[k], t.heights_d(k)) && owner[k] == t.owners(k);
      for (int c = 0; derivs && c < 5; ++c) {
        same = same && SameBits(dp[c][k], served[c]->Get(k));
      }
      if (!same && ++wrong <= 3) {
        ADD_FAILURE() << id << " tile " << index << " node " << k
                      << ": served height " << t.heights_d(k) << " owner "
                      << t.owners(k) << ", the core's " << w[k] << " owner "
                      << owner[k];
      }
    }
    EXPECT_EQ(wrong, 0) << id << " tile " << index << ": nodes that differ";
    std::string bytes;
    const int32_t txy[2] = {t.tx(), t.ty()};
    const uint64_t version = t.version();
    AppendBytes(&bytes, txy, 2);
    AppendBytes(&bytes, &version, 1);
    AppendBytes(&bytes, t.heights_d().data(), n);
    AppendBytes(&bytes, t.owners().data(), n);
    const std::vector<float> zeros(n, 0.0f);
    for (int c = 0; c < 5; ++c) {
      AppendBytes(&bytes, derivs ? served[c]->data() : zeros.data(), n);
    }
    digest = Fnv1a(digest, bytes);
  }
  return digest;
}

std::unique_ptr<pb::Swarf::Stub> Stub(int port) {
  return pb::Swarf::NewStub(UnlimitedChannel(port));
}

pb::Session GetSession(pb::Swarf::Stub* stub, const std::string& id) {
  grpc::ClientContext ctx;
  ForSession(&ctx, id);
  pb::GetSessionRequest req;
  req.set_session_id(id);
  pb::Session s;
  const grpc::Status st = stub->GetSession(&ctx, req, &s);
  EXPECT_TRUE(st.ok()) << id << ": " << st.error_code() << " "
                       << st.error_message();
  return s;
}

std::vector<std::string> ListedIds(pb::Swarf::Stub* stub) {
  grpc::ClientContext ctx;
  ForSession(&ctx, "");
  pb::ListSessionsResponse resp;
  const grpc::Status st =
      stub->ListSessions(&ctx, pb::ListSessionsRequest(), &resp);
  EXPECT_TRUE(st.ok()) << st.error_code() << " " << st.error_message();
  std::vector<std::string> ids;
  for (const pb::Session& s : resp.sessions()) ids.push_back(s.session_id());
  std::sort(ids.begin(), ids.end());
  return ids;
}

pb::SimulateRequest Request(uint64_t seq, const Batch& b) {
  pb::SimulateRequest r = MovesRequest(seq, b.tool, b.xyz);
  r.mutable_moves()->set_reposition(b.reposition);
  return r;
}

// A scratch directory per test: data/ (a copy of the fixture's files whose
// names end in one of `extensions`) and the servers' logs.
class ScratchDir {
 public:
  explicit ScratchDir(const std::vector<std::string>& extensions) {
    const ::testing::TestInfo* info =
        ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           absl::StrCat("swarf-legacy-", ::getpid(), "-", info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "data");
    for (const auto& f : fs::directory_iterator(kFixture)) {
      for (const std::string& ext : extensions) {
        if (f.path().extension() == ext) {
          fs::copy_file(f.path(), dir_ / "data" / f.path().filename());
        }
      }
    }
  }
  ~ScratchDir() {
    if (!::testing::Test::HasFailure()) fs::remove_all(dir_);  // keep logs
  }
  std::string data() const { return (dir_ / "data").string(); }
  std::string Log() { return (dir_ / absl::StrCat("log", ++logs_)).string(); }
  fs::path path(const std::string& name) const { return dir_ / name; }

 private:
  fs::path dir_;
  int logs_ = 0;
};

const std::vector<std::string> kFlags = {"--journal_sync=full",
                                         "--worker_threads=2"};

// The fixture is what its README says: the journals hold the recipe, and
// each snapshot is the current core's state after its batches, written in
// the version-1 format byte for byte (so old and new cut the same nodes,
// owners and versions, and the derivatives the old server stored are the
// ones now computed on demand).
TEST(LegacyRestoreTest, FixtureHoldsTheRecipeAndTheCoresStateInVersionOne) {
  const std::map<std::string, Expected> expected = ReadExpected();
  ASSERT_EQ(expected.size(), 3u);
  ScratchDir scratch({".db"});  // Journal::Open may write: a copy
  for (const Recipe& r : Recipes()) {
    SCOPED_TRACE(r.id);
    const Expected& e = expected.at(r.id);
    std::string definition, owner;
    auto journal = server::Journal::Open(
        (fs::path(scratch.data()) / (r.id + ".db")).string(),
        server::JournalSync::kOff, &definition, &owner);
    ASSERT_TRUE(journal.ok()) << journal.status();
    EXPECT_EQ(owner, "");
    pb::CreateSessionRequest def;
    ASSERT_TRUE(def.ParseFromString(definition));
    EXPECT_EQ(def.session_id(), r.id);
    EXPECT_EQ(def.scheme(), r.proto_scheme);
    EXPECT_EQ(def.nx(), r.stock.nx);
    EXPECT_EQ(def.ny(), r.stock.ny);
    EXPECT_EQ(def.stock().x0(), r.stock.x0);
    EXPECT_EQ(def.stock().y0(), r.stock.y0);
    EXPECT_EQ(def.stock().x1(), r.stock.x1);
    EXPECT_EQ(def.stock().y1(), r.stock.y1);
    EXPECT_EQ(def.stock().z_top(), r.stock.z_top);
    ASSERT_EQ(def.tools_size(), static_cast<int>(r.tools.size()));
    for (size_t k = 0; k < r.tools.size(); ++k) {
      EXPECT_EQ(def.tools(k).id(), r.tools[k].first);
      EXPECT_EQ(def.tools(k).ball().radius(), r.tools[k].second);
    }
    const std::vector<Batch> batches = r.Batches();
    size_t read = 0;
    auto problem = (*journal)->Replay([&](const server::Journal::Batch& b) {
      EXPECT_EQ(b.seq, read + 1);
      if (read < batches.size()) {
        const Batch& want = batches[read];
        EXPECT_EQ(b.tool_id, want.tool) << "batch " << b.seq;
        EXPECT_EQ(b.reposition, want.reposition) << "batch " << b.seq;
        EXPECT_TRUE(b.xyz.size() == want.xyz.size() &&
                    std::memcmp(b.xyz.data(), want.xyz.data(),
                                b.xyz.size() * sizeof(double)) == 0)
            << "batch " << b.seq << ": not the recipe's points";
      }
      ++read;
      return absl::OkStatus();
    });
    ASSERT_TRUE(problem.ok()) << problem.status();
    EXPECT_EQ(*problem, "");
    EXPECT_EQ(read, batches.size());
    EXPECT_EQ(read, e.last_seq);

    const std::string snap = (kFixture / (r.id + ".snap")).string();
    auto header = server::ReadSnapshotHeader(snap);
    ASSERT_TRUE(header.ok()) << header.status();
    EXPECT_EQ(header->seq, e.snapshot_seq);
    const std::string file = ReadFileText(snap);
    ASSERT_GE(file.size(), header->payload_bytes);
    const std::string payload =
        file.substr(file.size() - header->payload_bytes);
    EXPECT_EQ(payload.substr(0, 8), "SWARFWP1");
    const auto ref = CutReference(r, e.snapshot_seq);
    const std::string v1 = StateV1(ref->wp());
    ASSERT_EQ(payload.size(), v1.size());
    size_t first_diff = 0;
    while (first_diff < v1.size() && payload[first_diff] == v1[first_diff]) {
      ++first_diff;
    }
    EXPECT_EQ(first_diff, v1.size()) << "the old snapshot and the core's "
                                        "state differ from byte "
                                     << first_diff;
  }
}

// Restores from the old snapshot plus the journal's tail, serves what the
// old server served, takes more batches, and rewrites the snapshot in the
// current format on SIGTERM, which a second restart loads.
TEST(LegacyRestoreTest, RestoresFromTheOldSnapshotAndJournalTail) {
  const std::map<std::string, Expected> expected = ReadExpected();
  ScratchDir scratch({".db", ".snap"});
  const std::vector<Recipe> recipes = Recipes();
  std::map<std::string, std::unique_ptr<Reference>> refs;
  {
    SwarfdProcess server(scratch.data(), scratch.Log(), kFlags);
    ASSERT_GT(server.port(), 0) << "swarfd did not start";
    auto stub = Stub(server.port());
    EXPECT_EQ(ListedIds(stub.get()),
              (std::vector<std::string>{"v1-guarded", "v1-taylor", "v1-zmap"}));
    const std::string log = server.Log();
    for (const Recipe& r : recipes) {
      SCOPED_TRACE(r.id);
      const Expected& e = expected.at(r.id);
      const pb::Session s = GetSession(stub.get(), r.id);
      EXPECT_EQ(s.scheme(), r.proto_scheme);
      EXPECT_EQ(s.last_seq(), e.last_seq);
      EXPECT_EQ(s.snapshot_seq(), e.snapshot_seq);  // the old one, loaded
      EXPECT_EQ(s.moves_applied(), e.moves);
      EXPECT_EQ(s.version(), e.version);
      EXPECT_EQ(s.recovery(), "");
      EXPECT_NE(
          log.find(absl::StrCat(
              "session ", r.id, ": from the snapshot at batch ", e.snapshot_seq,
              ", ", e.last_seq - e.snapshot_seq, " batches replayed")),
          std::string::npos)
          << log;
      auto& ref = refs[r.id] = CutReference(r, e.last_seq);
      EXPECT_EQ(ref->wp().move_count(), e.moves);
      EXPECT_EQ(ref->wp().version(), e.version);
      ASSERT_TRUE(s.has_last_position());
      EXPECT_EQ(s.last_position().x(), ref->last()->x);
      EXPECT_EQ(s.last_position().y(), ref->last()->y);
      EXPECT_EQ(s.last_position().z(), ref->last()->z);
      // What the old server served, bit for bit.
      EXPECT_EQ(CheckTiles(stub.get(), r.id, ref->wp()), e.digest);

      // A batch the snapshot holds and one of the tail, resent: duplicates
      // (their digests come back from the journal); then one more batch.
      const std::vector<Batch> batches = r.Batches();
      const Batch extra = ExtraBatch(r);
      {
        SimStream stream(stub.get(), r.id);
        ASSERT_TRUE(stream.Write(
            Request(e.snapshot_seq - 1, batches[e.snapshot_seq - 2])));
        ASSERT_TRUE(stream.Write(Request(e.last_seq, batches.back())));
        ASSERT_TRUE(stream.Write(Request(e.last_seq + 1, extra)));
        const grpc::Status st = stream.Finish();
        EXPECT_TRUE(st.ok()) << st.error_code() << " " << st.error_message();
        const SimStream::Responses acks = stream.responses();
        ASSERT_EQ(acks.size(), 3u);
        EXPECT_EQ(acks[0].ack().seq(), e.snapshot_seq - 1);
        EXPECT_TRUE(acks[0].ack().duplicate());
        EXPECT_EQ(acks[1].ack().seq(), e.last_seq);
        EXPECT_TRUE(acks[1].ack().duplicate());
        EXPECT_EQ(acks[2].ack().seq(), e.last_seq + 1);
        EXPECT_FALSE(acks[2].ack().duplicate());
        EXPECT_EQ(acks[2].ack().moves_applied(), e.moves + 20);
        EXPECT_EQ(acks[2].ack().version(), e.version + 1);
      }
      ref->Apply(extra);
      CheckTiles(stub.get(), r.id, ref->wp());
      // An acknowledged batch of the snapshot's resent with other points.
      {
        Batch changed = batches[1];
        changed.xyz[4] += 0.01;
        SimStream stream(stub.get(), r.id);
        ASSERT_TRUE(stream.Write(Request(2, changed)));
        const grpc::Status st = stream.Finish();
        EXPECT_EQ(st.error_code(), grpc::StatusCode::ALREADY_EXISTS)
            << st.error_message();
      }
      EXPECT_EQ(GetSession(stub.get(), r.id).last_seq(), e.last_seq + 1);
    }
    // SIGTERM: every session changed since its snapshot, so each gets a
    // new one, in the current format.
    EXPECT_TRUE(server.Stop());
  }
  for (const Recipe& r : recipes) {
    const std::string snap =
        (fs::path(scratch.data()) / (r.id + ".snap")).string();
    auto header = server::ReadSnapshotHeader(snap);
    ASSERT_TRUE(header.ok()) << header.status();
    EXPECT_EQ(header->seq, expected.at(r.id).last_seq + 1) << r.id;
    const std::string file = ReadFileText(snap);
    EXPECT_EQ(file.substr(file.size() - header->payload_bytes, 8), "SWARFWP2")
        << r.id;
  }
  SwarfdProcess server(scratch.data(), scratch.Log(), kFlags);
  ASSERT_GT(server.port(), 0) << "swarfd did not restart";
  auto stub = Stub(server.port());
  for (const Recipe& r : recipes) {
    SCOPED_TRACE(r.id);
    const Expected& e = expected.at(r.id);
    const pb::Session s = GetSession(stub.get(), r.id);
    EXPECT_EQ(s.last_seq(), e.last_seq + 1);
    EXPECT_EQ(s.snapshot_seq(), e.last_seq + 1);
    EXPECT_EQ(s.moves_applied(), e.moves + 20);
    EXPECT_EQ(s.version(), e.version + 1);
    EXPECT_EQ(s.recovery(), "");
    CheckTiles(stub.get(), r.id, refs.at(r.id)->wp());
  }
  server.Kill();
}

// Without the snapshots, the whole journal is replayed, to the same state.
TEST(LegacyRestoreTest, WithoutTheSnapshotsTheJournalsReplayToTheSameState) {
  const std::map<std::string, Expected> expected = ReadExpected();
  ScratchDir scratch({".db"});
  SwarfdProcess server(scratch.data(), scratch.Log(), kFlags);
  ASSERT_GT(server.port(), 0) << "swarfd did not start";
  auto stub = Stub(server.port());
  EXPECT_EQ(ListedIds(stub.get()),
            (std::vector<std::string>{"v1-guarded", "v1-taylor", "v1-zmap"}));
  EXPECT_EQ(server.Log().find("from the snapshot"), std::string::npos);
  for (const Recipe& r : Recipes()) {
    SCOPED_TRACE(r.id);
    const Expected& e = expected.at(r.id);
    const pb::Session s = GetSession(stub.get(), r.id);
    EXPECT_EQ(s.last_seq(), e.last_seq);
    EXPECT_EQ(s.snapshot_seq(), 0u);
    EXPECT_EQ(s.moves_applied(), e.moves);
    EXPECT_EQ(s.version(), e.version);
    EXPECT_EQ(s.recovery(), "");
    const auto ref = CutReference(r, e.last_seq);
    EXPECT_EQ(CheckTiles(stub.get(), r.id, ref->wp()), e.digest);
  }
  server.Kill();
}

}  // namespace
}  // namespace swarf
