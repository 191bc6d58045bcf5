// Session journals: restore by replay is bit-identical; a damaged or
// truncated journal restores up to its last whole batch and says so; a
// deleted session leaves no files.
#include "server/journal.h"

#include <atomic>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "absl/synchronization/notification.h"
#include "gtest/gtest.h"
#include "server/convert.h"
#include "server/registry.h"

namespace swarf::server {
namespace {

namespace fs = std::filesystem;

constexpr int kBatches = 12;
constexpr int kPoints = 50;

// Batch k's points; each x is distinct so that a batch can be found in the
// file by its bytes.
std::vector<double> Points(int k) {
  std::vector<double> xyz;
  for (int p = 0; p < kPoints; ++p) {
    const double x = 1 + 8.0 * p / kPoints + 1e-7 * k;
    xyz.insert(xyz.end(), {x, 1 + 0.6 * k, -0.3 - 0.01 * p});
  }
  return xyz;
}

SessionSpec Spec(const std::string& id) {
  SessionSpec s;
  s.id = id;
  s.stock = {0, 0, 10, 10, 0, 100, 100};
  s.scheme = SchemeKind::kTaylor;
  s.tools = {{1, Cutter::Ball(0.5), {}}};
  return s;
}

// The heights, owners and derivatives of every node, the versions, and the
// exact surface (which needs every move) along a line.
struct NodeState {
  std::vector<double> w;
  std::vector<int32_t> owner;
  std::vector<float> d;
  std::vector<uint64_t> versions;
  std::vector<double> exact;
  bool operator==(const NodeState&) const = default;
};

NodeState Take(const Session& s) {
  return s.Read([](const Workpiece& wp) {
    NodeState snap;
    snap.versions.push_back(wp.version());
    snap.versions.push_back(static_cast<uint64_t>(wp.move_count()));
    for (int32_t t = 0; t < wp.tile_count(); ++t) {
      snap.versions.push_back(wp.TileVersion(t));
    }
    for (int k = 0; k <= 400; ++k) {
      snap.exact.push_back(wp.ExactHeight(0.025 * k, 1 + 0.0213 * k));
    }
    for (int32_t t = 0; t < wp.tile_count(); ++t) {
      const Workpiece::TileExtent e = wp.Extent(t);
      const size_t n = e.nx * e.ny, at = snap.w.size();
      snap.w.resize(at + n);
      snap.owner.resize(at + n);
      snap.d.resize(5 * (at + n));
      std::vector<float> d(5 * n);
      float* dp[5];
      for (int c = 0; c < 5; ++c) dp[c] = d.data() + c * n;
      wp.ReadTile(t, snap.w.data() + at, dp, snap.owner.data() + at);
      std::copy(d.begin(), d.end(), snap.d.begin() + 5 * at);
    }
    return snap;
  });
}

// A session of the first `batches` batches, kept in memory only.
NodeState Reference(int batches) {
  Registry r(Limits{});
  auto s = *r.Create(Spec("ref"));
  for (int k = 1; k <= batches; ++k) {
    EXPECT_TRUE(s->ApplyBatch(k, 1, Points(k), 1000).ok());
  }
  return Take(*s);
}

class JournalTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("swarf-journal-" + std::to_string(::getpid()) + "-" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  Persistence Durable() const { return {dir_.string(), JournalSync::kOff}; }

  // Writes a journaled session of kBatches batches, then closes it.
  void WriteJob(const std::string& id) {
    Registry r(Limits{}, Durable());
    ASSERT_TRUE(r.RestoreAll().ok());
    auto s = r.Create(Spec(id));
    ASSERT_TRUE(s.ok()) << s.status();
    for (int k = 1; k <= kBatches; ++k) {
      ASSERT_TRUE((*s)->ApplyBatch(k, 1, Points(k), 1000).ok());
    }
  }

  std::string File(const std::string& id) const {
    return (dir_ / (id + ".db")).string();
  }
  std::string SnapshotFile(const std::string& id) const {
    return (dir_ / (id + ".snap")).string();
  }

  // Flips one byte of batch k's points in the journal file.
  void DamageBatch(const std::string& id, int k) {
    std::fstream f(File(id), std::ios::in | std::ios::out | std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(f)),
                      std::istreambuf_iterator<char>());
    const std::vector<double> points = Points(k);
    const std::string needle(reinterpret_cast<const char*>(&points[30]), 24);
    const size_t at = bytes.find(needle);
    ASSERT_NE(at, std::string::npos) << "batch " << k << " not in the file";
    f.seekp(static_cast<std::streamoff>(at + 3));
    f.put(static_cast<char>(bytes[at + 3] ^ 0x5A));
  }

  // Snapshots every 120 moves: batch 1 has 49 moves, the others 50, so
  // they are written after batches 3, 6, 9, 12, ...
  Persistence Snapshotting() const {
    Persistence p = Durable();
    p.snapshot_every_moves = 120;
    return p;
  }

  // Writes a journaled session of `batches` batches with snapshots.
  void WriteSnapshottedJob(const std::string& id, int batches,
                           SchemeKind scheme = SchemeKind::kTaylor) {
    Registry r(Limits{}, Snapshotting());
    ASSERT_TRUE(r.RestoreAll().ok());
    SessionSpec spec = Spec(id);
    spec.scheme = scheme;
    auto s = r.Create(spec);
    ASSERT_TRUE(s.ok()) << s.status();
    for (int k = 1; k <= batches; ++k) {
      ASSERT_TRUE((*s)->ApplyBatch(k, 1, Points(k), 1000).ok());
    }
    EXPECT_EQ((*s)->State().snapshot_seq, static_cast<uint64_t>(batches / 3 * 3));
  }

  fs::path dir_;
};

TEST_F(JournalTest, RestartReplaysToTheSameStateAndContinues) {
  ASSERT_NO_FATAL_FAILURE(WriteJob("job"));
  Registry r(Limits{}, Durable());
  auto restored = r.RestoreAll();
  ASSERT_TRUE(restored.ok()) << restored.status();
  EXPECT_EQ(*restored, 1);
  auto s = *r.Get("job");
  EXPECT_EQ(s->recovery(), "");
  EXPECT_EQ(s->State().last_seq, static_cast<uint64_t>(kBatches));
  EXPECT_TRUE(Take(*s) == Reference(kBatches));
  // The restored session goes on, journaled: a repeat is a duplicate, the
  // next batch applies, and a second restart has it too.
  EXPECT_TRUE(s->ApplyBatch(kBatches, 1, Points(kBatches), 1000)->duplicate);
  ASSERT_TRUE(s->ApplyBatch(kBatches + 1, 1, Points(kBatches + 1), 1000).ok());
  const NodeState after = Take(*s);
  s.reset();
  Registry r2(Limits{}, Durable());
  ASSERT_EQ(*r2.RestoreAll(), 1);
  EXPECT_TRUE(Take(**r2.Get("job")) == after);
}

// Journals written before cutters had kinds hold a ball as BallEnd in the
// definition: the definition of a ball session is still those bytes, and
// they restore to the same spec.
TEST_F(JournalTest, BallDefinitionIsTheBytesOfEarlierJournals) {
  const SessionSpec spec = Spec("old");
  v1::CreateSessionRequest before;  // as Definition wrote it before
  before.set_session_id("old");
  before.mutable_stock()->set_x1(10);
  before.mutable_stock()->set_y1(10);
  before.set_nx(100);
  before.set_ny(100);
  before.set_scheme(v1::SCHEME_TAYLOR);
  v1::Tool* tool = before.add_tools();
  tool->set_id(1);
  tool->mutable_ball()->set_radius(0.5);
  EXPECT_EQ(Session::Definition(spec), before.SerializeAsString());
  auto back = SpecFromRequest(before);
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->tools.size(), 1u);
  EXPECT_EQ(back->tools[0].id, 1);
  EXPECT_EQ(back->tools[0].cutter, Cutter::Ball(0.5));
}

// A session with a tool of every shape, cut with each, restores from its
// journal with the same tools and the same nodes.
TEST_F(JournalTest, EveryCutterShapeRestoresWithItsTools) {
  SessionSpec spec = Spec("shapes");
  spec.tools = {{1, Cutter::Ball(0.5), {}},
                {2, Cutter::Flat(0.4), {}},
                {3, Cutter::BullNose(0.6, 0.2), {}},
                {4, Cutter::Cone(0.7, 30, 0.05), {}},
                {5, Cutter::TaperedBall(0.8, 0.25, 8), {}}};
  NodeState cut;
  {
    Registry r(Limits{}, Durable());
    ASSERT_TRUE(r.RestoreAll().ok());
    auto s = r.Create(spec);
    ASSERT_TRUE(s.ok()) << s.status();
    for (int k = 1; k <= 10; ++k) {
      ASSERT_TRUE((*s)->ApplyBatch(k, 1 + (k - 1) % 5, Points(k), 1000).ok());
    }
    cut = Take(**s);
  }
  Registry r(Limits{}, Durable());
  ASSERT_EQ(*r.RestoreAll(), 1);
  auto s = *r.Get("shapes");
  EXPECT_EQ(s->recovery(), "");
  ASSERT_EQ(s->spec().tools.size(), spec.tools.size());
  for (size_t k = 0; k < spec.tools.size(); ++k) {
    EXPECT_EQ(s->spec().tools[k].id, spec.tools[k].id);
    EXPECT_EQ(s->spec().tools[k].cutter, spec.tools[k].cutter)
        << CutterToString(s->spec().tools[k].cutter);
  }
  EXPECT_TRUE(Take(*s) == cut);
}

TEST_F(JournalTest, DamagedBatchRestoresUpToTheLastWholeOne) {
  ASSERT_NO_FATAL_FAILURE(WriteJob("job"));
  ASSERT_NO_FATAL_FAILURE(DamageBatch("job", 8));

  Registry r(Limits{}, Durable());
  ASSERT_EQ(*r.RestoreAll(), 1);
  auto s = *r.Get("job");
  EXPECT_EQ(s->State().last_seq, 7u);
  EXPECT_NE(s->recovery().find("batch 8"), std::string::npos) << s->recovery();
  EXPECT_TRUE(Take(*s) == Reference(7));
  // The client resends from 8: the journal takes it (the damaged rows were
  // dropped) and the state is whole again.
  for (int k = 8; k <= kBatches; ++k) {
    ASSERT_TRUE(s->ApplyBatch(k, 1, Points(k), 1000).ok()) << k;
  }
  EXPECT_TRUE(Take(*s) == Reference(kBatches));
}

TEST_F(JournalTest, TornLogAfterACrashRestoresUpToTheLastWholeBatch) {
  // A crash mid-write leaves a torn write-ahead log. Copy a live journal
  // (its connection open, so the log is not checkpointed into the file) and
  // cut the copy's log part-way through.
  const fs::path copy = dir_ / "copy";
  {
    Registry r(Limits{}, Durable());
    ASSERT_TRUE(r.RestoreAll().ok());
    auto s = *r.Create(Spec("job"));
    for (int k = 1; k <= kBatches; ++k) {
      ASSERT_TRUE(s->ApplyBatch(k, 1, Points(k), 1000).ok());
    }
    fs::create_directories(copy);
    fs::copy_file(File("job"), copy / "job.db");
    fs::copy_file(File("job") + "-wal", copy / "job.db-wal");
  }
  const auto wal = copy / "job.db-wal";
  fs::resize_file(wal, fs::file_size(wal) * 3 / 5);
  Registry r(Limits{}, {copy.string(), JournalSync::kOff});
  ASSERT_EQ(*r.RestoreAll(), 1);
  auto s = *r.Get("job");
  const uint64_t last = s->State().last_seq;
  EXPECT_GT(last, 0u);
  EXPECT_LT(last, static_cast<uint64_t>(kBatches));
  EXPECT_TRUE(Take(*s) == Reference(static_cast<int>(last)));
}

TEST_F(JournalTest, TruncatedDatabaseFileIsLeftAsideNotCrashedOn) {
  // Cutting the database file itself (not a crash: outside damage) breaks
  // SQLite's tree: the session is logged and left on disk for inspection.
  ASSERT_NO_FATAL_FAILURE(WriteJob("job"));
  ASSERT_NO_FATAL_FAILURE(WriteJob("other"));
  fs::resize_file(File("job"), fs::file_size(File("job")) * 2 / 3);
  Registry r(Limits{}, Durable());
  auto restored = r.RestoreAll();
  ASSERT_TRUE(restored.ok()) << restored.status();
  EXPECT_EQ(*restored, 1);
  EXPECT_TRUE(r.Get("other").ok());
  EXPECT_EQ(r.Get("job").status().code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(fs::exists(File("job")));
}

TEST_F(JournalTest, DamagedDefinitionIsNotRestoredAndOthersAre) {
  ASSERT_NO_FATAL_FAILURE(WriteJob("good"));
  ASSERT_NO_FATAL_FAILURE(WriteJob("bad"));
  {
    std::ofstream f(File("bad"), std::ios::binary | std::ios::trunc);
    f << "not a journal at all";
  }
  Registry r(Limits{}, Durable());
  auto restored = r.RestoreAll();
  ASSERT_TRUE(restored.ok());
  EXPECT_EQ(*restored, 1);
  EXPECT_TRUE(r.Get("good").ok());
  EXPECT_EQ(r.Get("bad").status().code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(fs::exists(File("bad")));
}

TEST_F(JournalTest, DeletingASessionDeletesItsFiles) {
  Registry r(Limits{}, Durable());
  ASSERT_TRUE(r.RestoreAll().ok());
  auto s = *r.Create(Spec("gone"));
  ASSERT_TRUE(s->ApplyBatch(1, 1, Points(1), 1000).ok());
  ASSERT_TRUE(fs::exists(File("gone")));
  ASSERT_TRUE(r.Delete("gone").ok());
  EXPECT_FALSE(fs::exists(File("gone")));
  EXPECT_FALSE(fs::exists(File("gone") + "-wal"));
  // A stream that still holds the session cannot write into a ghost.
  EXPECT_EQ(s->ApplyBatch(2, 1, Points(2), 1000).status().code(),
            absl::StatusCode::kNotFound);
  Registry r2(Limits{}, Durable());
  EXPECT_EQ(*r2.RestoreAll(), 0);
}

// A session being read (a long measurement) holds up its own deletion,
// never the other sessions: the registry is not locked while Delete waits.
TEST_F(JournalTest, DeletionWaitingForAReaderHoldsUpNoOtherSession) {
  Registry r(Limits{}, Durable());
  ASSERT_TRUE(r.RestoreAll().ok());
  auto gone = *r.Create(Spec("gone"));
  ASSERT_TRUE(r.Create(Spec("kept")).ok());
  absl::Notification reading, release, checked;
  std::thread reader([&] {
    gone->Read([&](const Workpiece&) {
      reading.Notify();
      release.WaitForNotification();
      return 0;
    });
  });
  reading.WaitForNotification();
  std::atomic<bool> deleted{false};
  std::thread deleter([&] {
    EXPECT_TRUE(r.Delete("gone").ok());
    deleted = true;
  });
  std::thread others([&] {
    // The id leaves the registry before Delete waits for the reader.
    while (r.Get("gone").ok()) std::this_thread::yield();
    EXPECT_TRUE(r.Get("kept").ok());
    EXPECT_EQ(r.List().size(), 1u);
    EXPECT_TRUE(r.Create(Spec("other")).ok());
    const auto again = r.Create(Spec("gone"));
    EXPECT_EQ(again.status().code(), absl::StatusCode::kAlreadyExists);
    EXPECT_NE(again.status().message().find("being created or deleted"),
              std::string::npos)
        << again.status();
    EXPECT_FALSE(deleted);
    checked.Notify();
  });
  // A deadlock fails here, not at ctest's timeout.
  EXPECT_TRUE(checked.WaitForNotificationWithTimeout(absl::Seconds(60)))
      << "calls on other sessions waited for the deletion";
  release.Notify();
  reader.join();
  deleter.join();
  others.join();
  EXPECT_TRUE(deleted);
  EXPECT_FALSE(fs::exists(File("gone")));
  EXPECT_TRUE(r.Create(Spec("gone")).ok());
}

TEST_F(JournalTest, IdleSessionIsEvictedAndReloadedBitIdentical) {
  Registry r(Limits{}, Durable());
  ASSERT_TRUE(r.RestoreAll().ok());
  {
    auto s = *r.Create(Spec("idle"));
    for (int k = 1; k <= kBatches; ++k) {
      ASSERT_TRUE(s->ApplyBatch(k, 1, Points(k), 1000).ok());
    }
    // Held (as by an open stream): not evicted.
    EXPECT_EQ(r.EvictIdle(0), 0);
  }
  EXPECT_EQ(r.EvictIdle(3600), 0);  // not idle long enough
  EXPECT_EQ(r.EvictIdle(0), 1);
  auto s = *r.Get("idle");
  EXPECT_TRUE(s->evicted());
  // Evicting wrote a snapshot, which the reload loads.
  EXPECT_TRUE(fs::exists(SnapshotFile("idle")));
  EXPECT_EQ(s->State().snapshot_seq, static_cast<uint64_t>(kBatches));
  // Its counters answer without a reload.
  const SessionState st = s->State();
  EXPECT_EQ(st.last_seq, static_cast<uint64_t>(kBatches));
  EXPECT_EQ(st.moves_applied, kBatches * kPoints - 1);
  EXPECT_TRUE(s->evicted());
  // Use reloads it, exactly as it was; it goes on from there.
  EXPECT_TRUE(Take(*s) == Reference(kBatches));
  EXPECT_FALSE(s->evicted());
  ASSERT_TRUE(s->ApplyBatch(kBatches + 1, 1, Points(kBatches + 1), 1000).ok());
  EXPECT_TRUE(Take(*s) == Reference(kBatches + 1));
  // A batch may also be what wakes it.
  s.reset();
  EXPECT_EQ(r.EvictIdle(0), 1);
  s = *r.Get("idle");
  ASSERT_TRUE(s->ApplyBatch(kBatches + 2, 1, Points(kBatches + 2), 1000).ok());
  EXPECT_TRUE(Take(*s) == Reference(kBatches + 2));
}

// A pinned workpiece (Session::Pin, read outside the lock by an in-process
// client) stays as it was: batches are refused while a pin is held, the
// session is not evicted, and a deleted session's workpiece lives on until
// the pin goes. Once the pins go, batches and eviction work again.
TEST_F(JournalTest, PinnedSessionRefusesBatchesAndIsNotEvicted) {
  Registry r(Limits{}, Durable());
  ASSERT_TRUE(r.RestoreAll().ok());
  auto s = *r.Create(Spec("pinned"));
  ASSERT_TRUE(s->ApplyBatch(1, 1, Points(1), 1000).ok());
  const NodeState before = Take(*s);
  absl::StatusOr<std::shared_ptr<const Workpiece>> pin = s->Pin();
  ASSERT_TRUE(pin.ok()) << pin.status();
  auto second = s->Pin();
  ASSERT_TRUE(second.ok()) << second.status();
  EXPECT_EQ(pin->get(), second->get());
  const auto refused = s->ApplyBatch(2, 1, Points(2), 1000);
  EXPECT_EQ(refused.status().code(), absl::StatusCode::kFailedPrecondition)
      << refused.status();
  EXPECT_NE(refused.status().message().find("session pinned is being read"),
            std::string::npos)
      << refused.status();
  EXPECT_EQ(s->State().last_seq, 1u);  // nothing applied
  EXPECT_FALSE(s->Evict());
  const int64_t moves = (*pin)->move_count();
  EXPECT_EQ(moves, kPoints - 1);
  second->reset();
  // One pin is still held.
  EXPECT_EQ(s->ApplyBatch(2, 1, Points(2), 1000).status().code(),
            absl::StatusCode::kFailedPrecondition);
  pin->reset();
  ASSERT_TRUE(s->ApplyBatch(2, 1, Points(2), 1000).ok());
  EXPECT_FALSE(Take(*s) == before);
  EXPECT_TRUE(s->Evict());
  EXPECT_TRUE(s->evicted());
  // Pinning reloads an evicted session, exactly as it was.
  pin = s->Pin();
  ASSERT_TRUE(pin.ok()) << pin.status();
  EXPECT_FALSE(s->evicted());
  EXPECT_EQ((*pin)->move_count(), 2 * kPoints - 1);
  EXPECT_TRUE(Take(*s) == Reference(2));
  // Deleted while pinned: the pin's workpiece is still whole.
  s.reset();
  ASSERT_TRUE(r.Delete("pinned").ok());
  EXPECT_EQ((*pin)->move_count(), 2 * kPoints - 1);
  EXPECT_EQ((*pin)->moves().Get(0).to.x, Points(1)[3]);
  EXPECT_EQ(r.Get("pinned").status().code(), absl::StatusCode::kNotFound);
}

TEST_F(JournalTest, InMemorySessionsAreNeverEvicted) {
  Registry r(Limits{});
  auto s = *r.Create(Spec("mem"));
  ASSERT_TRUE(s->ApplyBatch(1, 1, Points(1), 1000).ok());
  s.reset();
  EXPECT_EQ(r.EvictIdle(0), 0);
  EXPECT_FALSE((*r.Get("mem"))->evicted());
}

// A restart loads the last snapshot and replays only the batches after it;
// the result is the uninterrupted run's, bit for bit, and goes on as one.
TEST_F(JournalTest, RestartFromASnapshotReplaysOnlyTheTail) {
  ASSERT_NO_FATAL_FAILURE(WriteSnapshottedJob("job", 14));
  ASSERT_TRUE(fs::exists(SnapshotFile("job")));
  EXPECT_FALSE(fs::exists(SnapshotFile("job") + ".tmp"));
  Registry r(Limits{}, Snapshotting());
  ASSERT_EQ(*r.RestoreAll(), 1);
  auto s = *r.Get("job");
  const SessionState st = s->State();
  EXPECT_EQ(s->recovery(), "");
  EXPECT_EQ(st.last_seq, 14u);
  EXPECT_EQ(st.moves_applied, 14 * kPoints - 1);
  // Restored from batch 12's snapshot (a whole replay would have written a
  // new one at 14).
  EXPECT_EQ(st.snapshot_seq, 12u);
  EXPECT_TRUE(Take(*s) == Reference(14));
  // The tool position survived: batch 15 continues from batch 14's end.
  ASSERT_TRUE(s->ApplyBatch(15, 1, Points(15), 1000).ok());
  EXPECT_EQ(s->State().snapshot_seq, 15u);
  EXPECT_TRUE(Take(*s) == Reference(15));
}

// A damaged or truncated snapshot, or one of another session, is not used:
// the whole journal is replayed instead, nothing is lost, and a good
// snapshot replaces it.
TEST_F(JournalTest, BadSnapshotFallsBackToTheWholeJournal) {
  ASSERT_NO_FATAL_FAILURE(WriteSnapshottedJob("job", 14));
  ASSERT_NO_FATAL_FAILURE(
      WriteSnapshottedJob("zmap", 14, SchemeKind::kZmap));
  const std::string good = SnapshotFile("job") + ".good";
  fs::copy_file(SnapshotFile("job"), good);
  const auto size = fs::file_size(good);
  const struct {
    std::string what;
    std::function<void()> spoil;
  } cases[] = {
      {"a flipped payload byte",
       [&] {
         std::fstream f(SnapshotFile("job"),
                        std::ios::in | std::ios::out | std::ios::binary);
         f.seekp(static_cast<std::streamoff>(size / 2));
         f.put('\x7f');
       }},
      {"a flipped header byte",
       [&] {
         std::fstream f(SnapshotFile("job"),
                        std::ios::in | std::ios::out | std::ios::binary);
         f.seekp(17);
         f.put('\x01');
       }},
      {"a truncated file",
       [&] { fs::resize_file(SnapshotFile("job"), size - 4096); }},
      {"an empty file", [&] { fs::resize_file(SnapshotFile("job"), 0); }},
      {"another session's snapshot",
       [&] {
         fs::copy_file(SnapshotFile("zmap"), SnapshotFile("job"),
                       fs::copy_options::overwrite_existing);
       }},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.what);
    fs::copy_file(good, SnapshotFile("job"),
                  fs::copy_options::overwrite_existing);
    c.spoil();
    Registry r(Limits{}, Snapshotting());
    ASSERT_EQ(*r.RestoreAll(), 2);
    auto s = *r.Get("job");
    EXPECT_EQ(s->recovery(), "");
    EXPECT_EQ(s->State().last_seq, 14u);
    EXPECT_TRUE(Take(*s) == Reference(14));
    // The long replay wrote a snapshot of the whole job.
    EXPECT_EQ(s->State().snapshot_seq, 14u);
  }
}

// A snapshot beyond the journal's last whole batch (the journal was
// damaged after it was written) cannot be used: its moves are gone.
TEST_F(JournalTest, SnapshotBeyondADamagedJournalIsDropped) {
  ASSERT_NO_FATAL_FAILURE(WriteSnapshottedJob("job", 14));
  ASSERT_NO_FATAL_FAILURE(DamageBatch("job", 8));
  Registry r(Limits{}, Snapshotting());
  ASSERT_EQ(*r.RestoreAll(), 1);
  auto s = *r.Get("job");
  EXPECT_EQ(s->State().last_seq, 7u);
  EXPECT_NE(s->recovery().find("batch 8"), std::string::npos) << s->recovery();
  EXPECT_TRUE(Take(*s) == Reference(7));
  EXPECT_EQ(s->State().snapshot_seq, 7u);  // rewritten for what is left
  for (int k = 8; k <= 14; ++k) {
    ASSERT_TRUE(s->ApplyBatch(k, 1, Points(k), 1000).ok()) << k;
  }
  EXPECT_TRUE(Take(*s) == Reference(14));
  s.reset();
  Registry r2(Limits{}, Snapshotting());
  ASSERT_EQ(*r2.RestoreAll(), 1);
  EXPECT_TRUE(Take(**r2.Get("job")) == Reference(14));
}

// At shutdown every changed session is snapshotted, so the next start
// replays nothing; deleting the session removes the snapshot too.
TEST_F(JournalTest, SnapshotAllThenRestartReplaysNothing) {
  Persistence never = Durable();
  never.snapshot_every_moves = 0;
  {
    Registry r(Limits{}, never);
    ASSERT_TRUE(r.RestoreAll().ok());
    auto a = *r.Create(Spec("a"));
    auto b = *r.Create(Spec("b"));
    (void)*r.Create(Spec("untouched"));
    for (int k = 1; k <= 5; ++k) {
      ASSERT_TRUE(a->ApplyBatch(k, 1, Points(k), 1000).ok());
      ASSERT_TRUE(b->ApplyBatch(k, 1, Points(k + 1), 1000).ok());
    }
    EXPECT_FALSE(fs::exists(SnapshotFile("a")));
    EXPECT_EQ(r.SnapshotAll(), 2);
    EXPECT_EQ(r.SnapshotAll(), 0);  // nothing changed since
    EXPECT_EQ(a->State().snapshot_seq, 5u);
    EXPECT_FALSE(fs::exists(SnapshotFile("untouched")));
  }
  Registry r(Limits{}, never);
  ASSERT_EQ(*r.RestoreAll(), 3);
  auto a = *r.Get("a");
  EXPECT_EQ(a->State().snapshot_seq, 5u);
  EXPECT_TRUE(Take(*a) == Reference(5));
  ASSERT_TRUE(r.Delete("a").ok());
  EXPECT_FALSE(fs::exists(SnapshotFile("a")));
  EXPECT_FALSE(fs::exists(File("a")));
  EXPECT_TRUE(fs::exists(SnapshotFile("b")));
}

TEST(Crc32cTest, KnownValue) {
  // The CRC32C check value of "123456789".
  EXPECT_EQ(Crc32c("123456789", 9), 0xE3069283u);
  EXPECT_EQ(Crc32cPortable("123456789", 9), 0xE3069283u);
}

// The instruction path (when the CPU has it) and the table agree for every
// length and alignment, and when continued piece by piece.
TEST(Crc32cTest, FastPathMatchesTable) {
  std::mt19937 rng(4);
  std::vector<uint8_t> data(300);
  for (uint8_t& b : data) b = static_cast<uint8_t>(rng());
  for (size_t off = 0; off < 9; ++off) {
    for (size_t len = 0; off + len <= data.size(); len += 7) {
      ASSERT_EQ(Crc32c(data.data() + off, len),
                Crc32cPortable(data.data() + off, len))
          << off << "+" << len;
    }
  }
  const uint32_t whole = Crc32c(data.data(), data.size());
  EXPECT_EQ(Crc32c(data.data() + 100, 200, Crc32c(data.data(), 100)), whole);
}

}  // namespace
}  // namespace swarf::server
