// The server's sessions, with admission limits. Thread-safe.
#ifndef SWARF_SERVER_REGISTRY_H_
#define SWARF_SERVER_REGISTRY_H_

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "server/session.h"

namespace swarf::server {

struct Limits {
  int32_t max_sessions = 256;
  // Limits in bytes of a session's worst-case memory, every tile of its
  // grid cut (Session::EstimateMemoryBytes: the scheme's bytes per node,
  // 12 for every scheme now, plus a tile's bookkeeping). There is no node
  // cap: a grid of any size is admitted when its bytes fit.
  // One session at most (0: only the total applies).
  int64_t max_session_memory_bytes = 0;
  // All sessions together.
  int64_t max_total_memory_bytes = int64_t{8} << 30;
  int64_t max_batch_points = int64_t{1} << 20;
  // Open Simulate streams per client (per token, or per address without
  // authentication).
  int32_t max_streams_per_client = 16;
  // Journaled sessions idle this long leave memory until used (0: never).
  double idle_evict_seconds = 600;
  int32_t max_message_bytes = 64 << 20;
  // Polylines one GetCuttingMarks call holds queued for its client (their
  // serialized bytes, the one being written included); one polyline when a
  // single one is larger. The search waits while the queue is full.
  int64_t marks_queue_bytes = int64_t{4} << 20;
  // Largest design upload per session (SetDesign).
  int64_t max_design_bytes = int64_t{256} << 20;
};

// Where sessions are kept: in memory only (empty data_dir), or journaled
// to one SQLite file per session under data_dir.
struct Persistence {
  std::string data_dir;
  JournalSync sync = JournalSync::kFull;
  // A session's snapshot is rewritten after this many moves (0: only when
  // it is evicted or the server stops), bounding what a restart replays.
  int64_t snapshot_every_moves = 1'000'000;
};

class Registry {
 public:
  explicit Registry(const Limits& limits, Persistence persistence = {})
      : limits_(limits), persistence_(std::move(persistence)) {}

  // Restores every session journaled under data_dir (at start-up). Sessions
  // whose journal cannot be read at all are logged and left on disk.
  // Returns how many were restored.
  absl::StatusOr<int> RestoreAll();

  // Validates the id (1-64 of [A-Za-z0-9_-]; generated when empty) and the
  // limits, then creates. ALREADY_EXISTS, RESOURCE_EXHAUSTED (over
  // max_sessions, max_session_memory_bytes or max_total_memory_bytes, the
  // message naming the bytes needed and allowed), INVALID_ARGUMENT. A
  // session needing exactly the bytes left is admitted.
  absl::StatusOr<std::shared_ptr<Session>> Create(SessionSpec spec);
  // NOT_FOUND when absent, or when it belongs to another principal (so
  // that its existence is not revealed).
  absl::StatusOr<std::shared_ptr<Session>> Get(
      const std::string& id, const std::string& principal = "") const;
  // Deletes the session and its files, once its readers are done (a long
  // measurement); other sessions are served meanwhile. NOT_FOUND as Get.
  // The id is gone for Get at once, and free for Create when this returns.
  absl::Status Delete(const std::string& id, const std::string& principal = "");
  // Evicts journaled sessions unused for `idle_seconds` that no stream
  // holds. Returns how many were evicted.
  int EvictIdle(double idle_seconds);

  // Writes a snapshot of every journaled session that changed since its
  // last one (at shutdown, so that the next start replays nothing).
  // Returns how many were written.
  int SnapshotAll();

  // The sessions of `principal`.
  std::vector<std::shared_ptr<Session>> List(
      const std::string& principal = "") const;

  const Limits& limits() const { return limits_; }

  // INVALID_ARGUMENT unless id is 1-64 characters of [A-Za-z0-9_-].
  static absl::Status ValidateId(const std::string& id);

 private:
  std::string JournalPath(const std::string& id) const;
  SnapshotPolicy Snapshots(const std::string& id) const;
  // Removes a session's journal and snapshot files.
  void DeleteFiles(const std::string& id) const;
  // RESOURCE_EXHAUSTED unless `bytes` fit what the sessions have left of
  // max_total_memory_bytes, naming both and the grid of `stock`.
  absl::Status FitsTotalLocked(int64_t bytes, const StockSpec& stock) const
      ABSL_SHARED_LOCKS_REQUIRED(mu_);
  // Admission of a session of `bytes` (its grid: `stock`) under mu_;
  // reserves them.
  absl::Status AdmitLocked(const std::string& id, int64_t bytes,
                           const StockSpec& stock)
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const Limits limits_;
  const Persistence persistence_;
  mutable absl::Mutex mu_;
  std::map<std::string, std::shared_ptr<Session>> sessions_
      ABSL_GUARDED_BY(mu_);
  int64_t reserved_bytes_ ABSL_GUARDED_BY(mu_) = 0;
};

}  // namespace swarf::server

#endif  // SWARF_SERVER_REGISTRY_H_
