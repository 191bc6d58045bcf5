// A workpiece session: the core workpiece plus what the stream protocol
// needs (tools, the last applied seq and tip position).
//
// Thread-safe: batches take the session's lock exclusively, reads share it.
#ifndef SWARF_SERVER_SESSION_H_
#define SWARF_SERVER_SESSION_H_

#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "core/cutter/cutter.h"
#include "core/geometry.h"
#include "core/safety.h"
#include "core/scheme.h"
#include "core/stock.h"
#include "core/unfilled_vector.h"
#include "core/workpiece.h"
#include "design/placed_design.h"
#include "server/journal.h"
#include "server/snapshot.h"

namespace swarf::server {

inline constexpr double kDefaultArcTolerance = 0.001;
inline constexpr double kMinArcTolerance = 1e-6;
inline constexpr double kMaxArcTolerance = 10;

// An arc of a batch (the proto's Arc): the move ending at point end_index
// (>= 1) is an arc from point end_index - 1 about the centre's in-plane
// coordinates.
struct ArcSpec {
  int64_t end_index = 0;
  Vec3 centre;
  int plane = 17;  // 17 XY, 18 XZ, 19 YZ
  bool clockwise = false;
  int64_t turns = 1;
};

struct ToolSpec {
  int32_t id = 0;
  Cutter cutter;  // valid per ValidateTool (server/convert.h)
  ToolAssembly assembly;  // the non-cutting parts, for the safety checks
};

struct SessionSpec {
  std::string id;
  // The principal (see auth.h) that created the session; "" without auth.
  std::string owner;
  StockSpec stock;
  SchemeKind scheme = SchemeKind::kGuarded;
  std::vector<ToolSpec> tools;
  // Chord tolerance of the batches' arcs (mm), in [kMinArcTolerance,
  // kMaxArcTolerance]; `swarf run`'s default.
  double arc_tolerance = kDefaultArcTolerance;
};

// What a batch's move did that can crash or break the tool (Ack.safety).
struct SafetyFinding {
  enum Kind { kRapidCut = 1, kShankContact = 2, kHolderContact = 3, kPlunge = 4 };
  Kind kind = kRapidCut;
  int64_t move_index = 0;  // in the batch
  int64_t move_id = 0;     // in the session
  double x = 0, y = 0, z = 0, depth = 0, volume_mm3 = 0;
};

// How a batch is applied beyond its moves (not journaled: the cuts are the
// same either way).
struct BatchOptions {
  bool reposition = false;  // the first point only places the tool
  bool rapid = false;       // rapids: any material removed is reported
  bool report_cuts = false;  // BatchResult::removed_mm3
  // Arcs of the batch, chorded within the session's arc tolerance before
  // anything else (ChordBatch): the batch is then its chorded polyline.
  std::span<const ArcSpec> arcs;
};

// The batch's polyline with its arcs chorded (gcode::CentreArc and
// gcode::ChordArc, as `swarf run` chords a program's arcs): xyz with the
// chords of each arc inserted before its end point. InvalidArgument naming
// "moves.arcs[k]" and the field for a bad arc, or more than max_points
// points after chording.
absl::StatusOr<std::vector<double>> ChordBatch(std::span<const double> xyz,
                                               std::span<const ArcSpec> arcs,
                                               double arc_tolerance,
                                               int64_t max_points);

// What a batch did, for its Ack.
struct BatchResult {
  uint64_t seq = 0;
  int64_t moves_applied = 0;  // in the session, in total
  int64_t node_lowerings = 0;  // by this batch
  uint64_t version = 0;       // after the batch
  std::vector<std::pair<int32_t, uint64_t>> changed_tiles;  // tile, version
  bool duplicate = false;  // seq already applied: nothing done
  // With BatchOptions::report_cuts: each move's removed volume (mm^3).
  std::vector<double> removed_mm3;
  std::vector<SafetyFinding> safety;  // in move order
};

// A snapshot of the session's counters.
struct SessionState {
  uint64_t last_seq = 0;
  int64_t moves_applied = 0;
  uint64_t version = 0;
  int64_t allocated_tiles = 0;
  int64_t memory_bytes = 0;
  std::optional<Vec3> last_position;
  uint64_t snapshot_seq = 0;  // batches the snapshot on disk holds (0: none)
};

// One chunk of a design upload (the proto's SetDesignRequest).
struct DesignChunk {
  uint64_t offset = 0;  // bytes of the upload before `data`; 0: a new one
  std::string_view data;
  bool last = false;    // read and place the upload
  double scale = 1;     // with the last chunk: file units to mm
  Vec3 translation;     // mm
  std::string name = "design";
  int64_t max_bytes = int64_t{256} << 20;  // the upload's limit
};

// Where a design upload stands.
struct DesignUploadState {
  uint64_t received = 0;
  // Set when the last chunk placed a design.
  std::shared_ptr<const design::PlacedDesign> placed;
};

// Snapshots of a journaled session's workpiece (see snapshot.h).
struct SnapshotPolicy {
  std::string path;  // empty: no snapshots
  // A snapshot is written after a batch once this many moves were applied
  // since the last one (0: only when evicted or saved explicitly).
  int64_t every_moves = 0;
};

class Session {
 public:
  // InvalidArgument naming the field for a bad stock or tools.
  static absl::Status ValidateSpec(const SessionSpec& spec);
  // Validates, then creates. With a journal (not null), every batch is
  // written to it before it is applied.
  static absl::StatusOr<std::shared_ptr<Session>> Create(
      SessionSpec spec, std::unique_ptr<Journal> journal = nullptr,
      SnapshotPolicy snapshots = {});
  // Rebuilds a session from its journal, up to the last whole batch:
  // from the snapshot when there is a usable one (its batches' moves are
  // recorded, the later batches replayed), otherwise by replaying every
  // batch; recovery() then says what was wrong with the journal, if
  // anything. Bit-identical either way.
  static absl::StatusOr<std::shared_ptr<Session>> Restore(
      const std::string& path, JournalSync sync, SnapshotPolicy snapshots = {});

  // Writes a snapshot of the current state unless the last one holds it
  // already (or the session has no snapshot path, or is evicted). Returns
  // whether one was written.
  absl::StatusOr<bool> SaveSnapshot();

  // The journal's definition of a session (its spec as a protobuf).
  static std::string Definition(const SessionSpec& spec);

  // What restoring found wrong with the journal (empty: nothing).
  const std::string& recovery() const { return recovery_; }
  // Later batches fail with NOT_FOUND (streams may outlive a delete).
  void MarkDeleted();

  const SessionSpec& spec() const { return spec_; }
  const std::string& id() const { return spec_.id; }

  // Worst-case memory of the session's grid (every tile cut: the tile
  // arena's 2 MiB chunks, 12 bytes a node in them, and each tile's
  // bookkeeping), for admission. The moves (Workpiece::move_bytes) come on top.
  static int64_t EstimateMemoryBytes(const StockSpec& stock,
                                     SchemeKind scheme);

  // Applies batch `seq`: the tip polyline xyz (x, y, z triples) continuing
  // from the last position, cut with tool `tool_id`. seq <= last applied:
  // a duplicate, acknowledged without applying, when its tool, reposition
  // and points are those first applied under that seq (BatchDigest), else
  // AlreadyExists. seq > last + 1: FailedPrecondition. Bad values (an empty
  // batch too): InvalidArgument naming the field, and nothing applied.
  // Batches of more than max_points points: InvalidArgument. A journal
  // that cannot be written: Unavailable (details only in the log).
  // With `reposition`, the first point only places the tool.
  absl::StatusOr<BatchResult> ApplyBatch(uint64_t seq, int32_t tool_id,
                                         std::span<const double> xyz,
                                         int64_t max_points,
                                         bool reposition = false);
  // The same, with the safety checks (rapids that cut, shank and holder
  // contacts, plunges of tools not cutting at their centre) made as the
  // moves are applied, and each move's removed volume when asked.
  absl::StatusOr<BatchResult> ApplyBatch(uint64_t seq, int32_t tool_id,
                                         std::span<const double> xyz,
                                         int64_t max_points,
                                         const BatchOptions& options);

  SessionState State() const;

  // A chunk of a design upload. A chunk at an offset other than the bytes
  // held is FailedPrecondition naming the expected offset, unless it lies
  // within them (a resend: acknowledged, nothing changes). Past
  // chunk.max_bytes: ResourceExhausted, and the upload is dropped. The last
  // chunk reads the file (design::ParseDesign) and places it on the
  // session's grid; then, journaled first, it replaces the design. Any
  // error drops the upload and leaves the current design.
  absl::StatusOr<DesignUploadState> AddDesignChunk(const DesignChunk& chunk);
  // The current design (null: none). Thread-safe.
  std::shared_ptr<const design::PlacedDesign> design() const;

  // The program last run on the session (a serialized ProgramChunk holding
  // the whole text and its options), journaled beside the definition so
  // that a client can resume it after a restart without uploading it
  // again. A memory-only session keeps nothing (Unavailable when the
  // journal cannot be written). Thread-safe.
  absl::Status SaveProgram(const std::string& bytes);
  // nullopt when none was journaled; DataLoss when it is damaged.
  absl::StatusOr<std::optional<std::string>> SavedProgram() const;

  // Runs fn(const Workpiece&) under the shared lock and returns its result
  // (reloading an evicted session first).
  template <typename F>
  auto Read(F&& fn) const {
    EnsureLoaded();
    absl::ReaderMutexLock l(&mu_);
    return fn(*wp_);
  }

  // The workpiece, held for reading outside the session's lock by an
  // in-process reader that drives the session alone: swarf run's outputs
  // on its embedded server read its moves and their index (Workpiece::
  // moves, sweeps) instead of indexing every move a second time. While a
  // pin is held, batches are refused (FailedPrecondition) and the session
  // is not evicted; a deleted session's workpiece lives until its last pin
  // goes. NotFound once deleted. Thread-safe; the pin may be dropped on
  // any thread.
  absl::StatusOr<std::shared_ptr<const Workpiece>> Pin() const;

  // Drops the grid from memory (a journaled session only; it is rebuilt
  // from the journal on next use). False when not evictable, or pinned.
  bool Evict();
  bool evicted() const;
  // Seconds since the session was last used.
  double IdleSeconds() const;

 private:
  Session(SessionSpec spec, std::unique_ptr<Workpiece> wp)
      : spec_(std::move(spec)), wp_(std::move(wp)) {}
  // ApplyBatch after validation, under mu_; `journal` false when replaying.
  absl::StatusOr<BatchResult> ApplyLocked(uint64_t seq, const ToolSpec& tool,
                                          std::span<const double> xyz,
                                          bool reposition, bool journal,
                                          const BatchOptions* checks = nullptr)
      const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  // The safety checks of an applied batch (ApplyResult with cuts) into r.
  void Check(const BatchOptions& checks, const ToolSpec& tool,
             std::span<const Move> moves, const ApplyResult& applied,
             BatchResult* r) const ABSL_SHARED_LOCKS_REQUIRED(mu_);

  // Rebuilds an evicted session's grid from its snapshot and journal.
  void EnsureLoaded() const;
  absl::Status ReloadLocked() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // Rebuilds wp_, last_seq_ and last_position_ from the snapshot (when
  // usable) and the journal. Returns what stopped the replay early ("" if
  // nothing did).
  absl::StatusOr<std::string> RebuildLocked() const
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // One pass of RebuildLocked, from `snapshot` if not null; sets
  // *snapshot_unusable when the snapshot does not fit the journal.
  absl::StatusOr<std::string> ReplayLocked(const SnapshotHeader* snapshot,
                                           bool* snapshot_unusable) const
      ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);
  // The moves of a batch continuing from last_position_ (from its first
  // point with `reposition`); *end receives the tool's position after it.
  UnfilledVector<Move> BatchMoves(const ToolSpec& tool,
                                  std::span<const double> xyz, bool reposition,
                                  std::optional<Vec3>* end) const
      ABSL_SHARED_LOCKS_REQUIRED(mu_);
  const ToolSpec* FindTool(int32_t id) const;
  absl::StatusOr<bool> SaveSnapshotLocked() const
      ABSL_SHARED_LOCKS_REQUIRED(mu_);
  // Whether every_moves moves were applied since the last snapshot.
  bool SnapshotDueLocked() const ABSL_SHARED_LOCKS_REQUIRED(mu_);
  void Touch() const;

  // Reads and places a journaled design (SetDesignRequest bytes).
  absl::StatusOr<std::shared_ptr<const design::PlacedDesign>> PlaceDesign(
      const std::string& request_bytes) const;

  const SessionSpec spec_;
  std::string recovery_;  // set once, before the session is shared
  // The design and an upload in progress.
  mutable absl::Mutex design_mu_ ABSL_ACQUIRED_AFTER(mu_);
  std::shared_ptr<const design::PlacedDesign> design_ ABSL_GUARDED_BY(design_mu_);
  std::string upload_ ABSL_GUARDED_BY(design_mu_);
  mutable std::atomic<int64_t> last_used_ms_{0};
  mutable absl::Mutex mu_;
  // Null while evicted; rebuilt (mutable) on use. Shared with pins (Pin).
  mutable std::shared_ptr<Workpiece> wp_ ABSL_GUARDED_BY(mu_);
  // Pins held (Pin); shared with them, as they may outlive the session.
  const std::shared_ptr<std::atomic<int>> pins_ =
      std::make_shared<std::atomic<int>>(0);
  // Counters kept while evicted.
  mutable SessionState evicted_state_ ABSL_GUARDED_BY(mu_);
  mutable std::unique_ptr<Journal> journal_ ABSL_GUARDED_BY(mu_);
  bool deleted_ ABSL_GUARDED_BY(mu_) = false;
  mutable uint64_t last_seq_ ABSL_GUARDED_BY(mu_) = 0;
  mutable std::optional<Vec3> last_position_ ABSL_GUARDED_BY(mu_);
  // BatchDigest of every applied batch, [seq - 1]: a resent seq must carry
  // the same moves (4 bytes a batch; rebuilt from the journal on restore).
  mutable std::vector<uint32_t> digests_ ABSL_GUARDED_BY(mu_);
  SnapshotPolicy snapshots_;  // set once, before the session is shared
  // Serialises snapshot writers (which hold mu_ shared only).
  mutable absl::Mutex snapshot_mu_ ABSL_ACQUIRED_AFTER(mu_);
  // Batches the snapshot on disk holds (0: none).
  mutable uint64_t snapshot_seq_ ABSL_GUARDED_BY(snapshot_mu_) = 0;
  // Moves applied when it was written (or when this process restored).
  mutable std::atomic<int64_t> snapshot_moves_{0};
};

}  // namespace swarf::server

#endif  // SWARF_SERVER_SESSION_H_
