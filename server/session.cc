#include "server/session.h"

#include <cmath>
#include <set>

#include "absl/strings/str_cat.h"
#include "core/tile_arena.h"
#include "gcode/toolpath.h"
#include "server/convert.h"
#include "design/design_mesh.h"
#include "server/snapshot.h"
#include "spdlog/spdlog.h"

namespace swarf::server {

absl::StatusOr<std::vector<double>> ChordBatch(std::span<const double> xyz,
                                               std::span<const ArcSpec> arcs,
                                               double arc_tolerance,
                                               int64_t max_points) {
  const int64_t points = static_cast<int64_t>(xyz.size() / 3);
  auto point = [&](int64_t p) {
    return Vec3{xyz[3 * p], xyz[3 * p + 1], xyz[3 * p + 2]};
  };
  // Checked whole before anything is chorded: the error names the first bad
  // arc, whatever the chords of the others would cost.
  for (size_t k = 0; k < arcs.size(); ++k) {
    const ArcSpec& a = arcs[k];
    const std::string field = absl::StrCat("moves.arcs[", k, "]");
    if (a.end_index < 1 || a.end_index >= points) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, ".end_index ", a.end_index, " is out of range: an arc starts "
          "at the batch's previous point, so it ends at a point in [1, ",
          points - 1, "]"));
    }
    if (k > 0 && a.end_index <= arcs[k - 1].end_index) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, ".end_index ", a.end_index, " is not after moves.arcs[",
          k - 1, "].end_index ", arcs[k - 1].end_index,
          ": arcs ascend, one per point"));
    }
    if (!(std::fabs(a.centre.x) <= kMaxCoordinate &&
          std::fabs(a.centre.y) <= kMaxCoordinate &&
          std::fabs(a.centre.z) <= kMaxCoordinate)) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, ".centre must be finite and within +-", kMaxCoordinate,
          " mm, got (", a.centre.x, ", ", a.centre.y, ", ", a.centre.z, ")"));
    }
    if (a.turns < 1 || a.turns > 10000) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, ".turns must be in [1, 10000] (1: less than a full turn), "
          "got ", a.turns));
    }
  }
  std::vector<double> out;
  out.reserve(xyz.size() + 3 * 64 * arcs.size());
  int64_t next = 0;  // the first point not copied yet
  for (size_t k = 0; k < arcs.size(); ++k) {
    const ArcSpec& a = arcs[k];
    const std::string field = absl::StrCat("moves.arcs[", k, "]");
    out.insert(out.end(), xyz.begin() + 3 * next,
               xyz.begin() + 3 * a.end_index);
    const double c[3] = {a.centre.x, a.centre.y, a.centre.z};
    const int p0 = a.plane == 18 ? 2 : a.plane == 19 ? 1 : 0;
    const int p1 = a.plane == 18 ? 0 : a.plane == 19 ? 2 : 1;
    auto arc = gcode::CentreArc(point(a.end_index - 1), point(a.end_index),
                                c[p0], c[p1], a.plane, a.clockwise, a.turns,
                                a.clockwise ? "a clockwise" : "a counterclockwise");
    if (!arc.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat(field, ".centre: ", arc.status().message()));
    }
    const int64_t room =
        max_points - static_cast<int64_t>(out.size() / 3) -
        (points - a.end_index - 1);
    auto chords = gcode::ChordArc(point(a.end_index - 1), *arc, arc_tolerance,
                                  std::max<int64_t>(room, 0));
    if (!chords.ok()) {
      // The chord count, or the arc bulging past +-1e9 mm.
      return absl::InvalidArgumentError(absl::StrCat(
          field, ": ", chords.status().message(), " (chorded within ",
          arc_tolerance, " mm, the batch may hold ", max_points,
          " points, chords included)"));
    }
    for (const Vec3& v : *chords) {
      out.push_back(v.x);
      out.push_back(v.y);
      out.push_back(v.z);
    }
    next = a.end_index + 1;
  }
  out.insert(out.end(), xyz.begin() + 3 * next, xyz.end());
  return out;
}

absl::Status Session::ValidateSpec(const SessionSpec& spec) {
  if (absl::Status s = ValidateStock(spec.stock); !s.ok()) return s;
  if (!(spec.arc_tolerance >= kMinArcTolerance &&
        spec.arc_tolerance <= kMaxArcTolerance)) {
    return absl::InvalidArgumentError(absl::StrCat(
        "arc_tolerance must be in [", kMinArcTolerance, ", ",
        kMaxArcTolerance, "] mm, got ", spec.arc_tolerance));
  }
  if (spec.tools.empty()) {
    return absl::InvalidArgumentError("tools: at least one tool is needed");
  }
  std::set<int32_t> ids;
  for (size_t k = 0; k < spec.tools.size(); ++k) {
    const ToolSpec& t = spec.tools[k];
    if (!ids.insert(t.id).second) {
      return absl::InvalidArgumentError(
          absl::StrCat("tools[", k, "].id ", t.id, " is used twice"));
    }
    if (absl::Status s = ValidateTool(t, static_cast<int>(k)); !s.ok()) {
      return s;
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::shared_ptr<Session>> Session::Create(
    SessionSpec spec, std::unique_ptr<Journal> journal,
    SnapshotPolicy snapshots) {
  if (absl::Status s = ValidateSpec(spec); !s.ok()) return s;
  auto wp = Workpiece::Create(spec.stock, spec.scheme);
  if (!wp.ok()) return wp.status();
  auto session =
      std::shared_ptr<Session>(new Session(std::move(spec), *std::move(wp)));
  session->journal_ = std::move(journal);
  if (session->journal_ != nullptr) session->snapshots_ = std::move(snapshots);
  session->Touch();
  return session;
}

std::string Session::Definition(const SessionSpec& spec) {
  pb::CreateSessionRequest r;
  r.set_session_id(spec.id);
  pb::Stock* st = r.mutable_stock();
  st->set_x0(spec.stock.x0);
  st->set_y0(spec.stock.y0);
  st->set_x1(spec.stock.x1);
  st->set_y1(spec.stock.y1);
  st->set_z_top(spec.stock.z_top);
  r.set_nx(spec.stock.nx);
  r.set_ny(spec.stock.ny);
  r.set_scheme(SchemeToProto(spec.scheme));
  for (const ToolSpec& t : spec.tools) ToolToProto(t, r.add_tools());
  // Only when not the default: older servers' definitions stay as they were.
  if (spec.arc_tolerance != kDefaultArcTolerance) {
    r.mutable_arc_tolerance()->set_value(spec.arc_tolerance);
  }
  return r.SerializeAsString();
}

absl::StatusOr<std::shared_ptr<Session>> Session::Restore(
    const std::string& path, JournalSync sync, SnapshotPolicy snapshots) {
  const absl::Time start = absl::Now();
  std::string definition, owner;
  auto journal = Journal::Open(path, sync, &definition, &owner);
  if (!journal.ok()) return journal.status();
  pb::CreateSessionRequest req;
  if (!req.ParseFromString(definition)) {
    return absl::DataLossError(
        absl::StrCat("journal ", path, ": the session definition is damaged"));
  }
  auto spec = SpecFromRequest(req);
  if (!spec.ok()) return spec.status();
  spec->owner = owner;
  auto session =
      Create(*std::move(spec), *std::move(journal), std::move(snapshots));
  if (!session.ok()) return session.status();
  Session& s = **session;
  absl::MutexLock l(&s.mu_);
  auto problem = s.RebuildLocked();
  if (!problem.ok()) return problem.status();
  s.recovery_ = *problem;
  if (!problem->empty()) {
    // Batches after the damage cannot be trusted: drop them, so that the
    // client resends from last_seq + 1 into a consistent journal.
    if (absl::Status t = s.journal_->Truncate(s.last_seq_); !t.ok()) return t;
  }
  // The design, if one was set: a damaged one is dropped with a warning
  // (the client sets it again); the moves stay.
  if (s.journal_ != nullptr) {
    auto blob = s.journal_->GetBlob("design");
    absl::StatusOr<std::shared_ptr<const design::PlacedDesign>> placed =
        blob.ok() ? (blob->has_value() ? s.PlaceDesign(**blob)
                                       : absl::StatusOr<std::shared_ptr<
                                             const design::PlacedDesign>>(
                                             nullptr))
                  : absl::StatusOr<std::shared_ptr<const design::PlacedDesign>>(
                        blob.status());
    if (placed.ok()) {
      absl::MutexLock dl(&s.design_mu_);
      s.design_ = *std::move(placed);
    } else {
      spdlog::warn("session {}: the design is not restored: {}", s.spec_.id,
                   std::string(placed.status().message()));
      s.recovery_ += absl::StrCat(s.recovery_.empty() ? "" : "; ",
                                  "the design was not restored: ",
                                  placed.status().message());
    }
  }
  spdlog::info("session {}: rebuilt in {:.3f} s", s.spec_.id,
               absl::ToDoubleSeconds(absl::Now() - start));
  // A long replay is not repeated at the next start.
  if (s.SnapshotDueLocked()) s.SaveSnapshotLocked().IgnoreError();  // logged
  return *session;
}

absl::StatusOr<std::string> Session::RebuildLocked() const {
  std::optional<SnapshotHeader> snapshot;
  if (!snapshots_.path.empty()) {
    auto read = ReadSnapshotHeader(snapshots_.path);
    if (read.ok()) {
      snapshot = *std::move(read);
    } else if (!absl::IsNotFound(read.status())) {
      spdlog::warn("session {}: {}; replaying the whole journal", spec_.id,
                   std::string(read.status().message()));
      DeleteSnapshot(snapshots_.path);
    }
  }
  {
    absl::MutexLock l(&snapshot_mu_);
    snapshot_seq_ = 0;
  }
  bool unusable = false;
  auto problem = ReplayLocked(snapshot ? &*snapshot : nullptr, &unusable);
  if (unusable) {
    // Not the state of this journal: rebuild from the batches alone.
    DeleteSnapshot(snapshots_.path);
    problem = ReplayLocked(nullptr, &unusable);
  } else if (snapshot.has_value()) {
    absl::MutexLock l(&snapshot_mu_);
    snapshot_seq_ = snapshot->seq;
  }
  return problem;
}

absl::StatusOr<std::string> Session::ReplayLocked(
    const SnapshotHeader* snapshot, bool* unusable) const {
  auto wp = Workpiece::Create(spec_.stock, spec_.scheme);
  if (!wp.ok()) return wp.status();
  wp_ = *std::move(wp);
  last_seq_ = 0;
  last_position_.reset();
  digests_.clear();
  snapshot_moves_ = 0;
  *unusable = false;
  int64_t replayed = 0;
  auto problem = journal_->Replay([&](const Journal::Batch& b) {
    const ToolSpec* tool = FindTool(b.tool_id);
    if (tool == nullptr) {
      return absl::DataLossError(absl::StrCat("unknown tool ", b.tool_id));
    }
    if (snapshot == nullptr || b.seq > snapshot->seq) {
      ++replayed;
      return ApplyLocked(b.seq, *tool, b.xyz, b.reposition, false).status();
    }
    // Held by the snapshot: the moves are recorded, not cut again.
    std::optional<Vec3> end;
    const UnfilledVector<Move> moves =
        BatchMoves(*tool, b.xyz, b.reposition, &end);
    if (absl::Status s = wp_->Record(moves); !s.ok()) return s;
    last_seq_ = b.seq;
    last_position_ = end;
    digests_.push_back(BatchDigest(b.tool_id, b.reposition, b.xyz));
    if (b.seq == snapshot->seq) {
      if (absl::Status s = LoadSnapshot(snapshots_.path, *snapshot, wp_.get());
          !s.ok()) {
        spdlog::warn("session {}: {}; replaying the whole journal", spec_.id,
                     std::string(s.message()));
        *unusable = true;
        return s;
      }
      snapshot_moves_ = wp_->move_count();
    }
    return absl::OkStatus();
  });
  if (snapshot != nullptr && problem.ok() && !*unusable &&
      last_seq_ < snapshot->seq) {
    spdlog::warn("session {}: snapshot at batch {} is beyond the journal's "
                 "last whole batch {}", spec_.id, snapshot->seq, last_seq_);
    *unusable = true;
  }
  if (snapshot != nullptr && !*unusable) {
    spdlog::info("session {}: from the snapshot at batch {}, {} batches "
                 "replayed", spec_.id, snapshot->seq, replayed);
  }
  return problem;
}

bool Session::SnapshotDueLocked() const {
  return snapshots_.every_moves > 0 &&
         wp_->move_count() - snapshot_moves_ >= snapshots_.every_moves;
}

absl::StatusOr<bool> Session::SaveSnapshot() {
  absl::ReaderMutexLock l(&mu_);
  if (wp_ == nullptr || deleted_) return false;
  return SaveSnapshotLocked();
}

absl::StatusOr<bool> Session::SaveSnapshotLocked() const {
  if (snapshots_.path.empty()) return false;
  absl::MutexLock l(&snapshot_mu_);
  if (last_seq_ == 0 || snapshot_seq_ == last_seq_) return false;
  const absl::Time start = absl::Now();
  absl::Status s = WriteSnapshot(snapshots_.path, last_seq_, *wp_);
  if (!s.ok()) {
    // The journal still has everything: only the next restart is slower.
    spdlog::warn("session {}: {}", spec_.id, std::string(s.message()));
    return s;
  }
  snapshot_seq_ = last_seq_;
  snapshot_moves_ = wp_->move_count();
  spdlog::info("session {}: snapshot at batch {} ({} moves) in {:.3f} s",
               spec_.id, last_seq_, wp_->move_count(),
               absl::ToDoubleSeconds(absl::Now() - start));
  return true;
}

const ToolSpec* Session::FindTool(int32_t id) const {
  for (const ToolSpec& t : spec_.tools) {
    if (t.id == id) return &t;
  }
  return nullptr;
}

UnfilledVector<Move> Session::BatchMoves(const ToolSpec& tool,
                                         std::span<const double> xyz,
                                         bool reposition,
                                         std::optional<Vec3>* end) const {
  const int64_t points = static_cast<int64_t>(xyz.size() / 3);
  const std::optional<Vec3> start = reposition ? std::nullopt : last_position_;
  auto point = [&](int64_t p) {
    return Vec3{xyz[3 * p], xyz[3 * p + 1], xyz[3 * p + 2]};
  };
  // Without a position to start from, the first point only places the tool.
  const int64_t skip = start.has_value() ? 0 : 1;
  UnfilledVector<Move> moves;
  moves.resize(static_cast<size_t>(std::max<int64_t>(0, points - skip)));
  // Built on every thread: a batch's moves (88 bytes each) were written
  // and faulted in on one. Pieces of 512: a batch of 20,000 points makes
  // 40, enough for 16 threads (pieces of 4,096 made 5: SWARF_LOOP_PROFILE
  // modelled the loop at 3.7 times its even share on 16).
  constexpr int64_t kPiece = 512;
  const int64_t n = static_cast<int64_t>(moves.size());
  wp_->pool().ParallelFor((n + kPiece - 1) / kPiece, [&](int64_t c) {
    for (int64_t k = c * kPiece; k < std::min(n, (c + 1) * kPiece); ++k) {
      const int64_t p = k + skip;
      moves[k] = Move(p == 0 ? *start : point(p - 1), point(p), tool.cutter);
    }
  });
  *end = points > 0 ? std::optional<Vec3>(point(points - 1)) : start;
  return moves;
}

absl::StatusOr<std::shared_ptr<const design::PlacedDesign>>
Session::PlaceDesign(const std::string& request_bytes) const {
  pb::SetDesignRequest req;
  if (!req.ParseFromString(request_bytes)) {
    return absl::DataLossError("the journaled design does not parse");
  }
  design::DesignReadOptions o;
  o.scale = req.scale() > 0 ? req.scale() : 1.0;
  o.offset = {req.translation().x(), req.translation().y(),
              req.translation().z()};
  const std::string name = req.name().empty() ? "design" : req.name();
  auto mesh = design::ParseDesign(
      absl::string_view(req.data().data(), req.data().size()), name, o);
  if (!mesh.ok()) return mesh.status();
  return design::PlacedDesign::Place(*std::move(mesh), GridGeometry(spec_.stock),
                                     name);
}

absl::StatusOr<DesignUploadState> Session::AddDesignChunk(
    const DesignChunk& c) {
  Touch();
  pb::SetDesignRequest whole;
  {
    absl::MutexLock l(&design_mu_);
    if (c.offset == 0) upload_.clear();
    if (c.offset < upload_.size()) {
      // A resend of bytes held (the client lost the answer): nothing new.
      if (c.offset + c.data.size() <= upload_.size() && !c.last) {
        return DesignUploadState{upload_.size(), nullptr};
      }
    }
    if (c.offset != upload_.size()) {
      return absl::FailedPreconditionError(absl::StrCat(
          "design upload: a chunk at offset ", c.offset, "; the server holds ",
          upload_.size(), " bytes of this upload (send from there, or from 0 "
          "to start again)"));
    }
    if (upload_.size() + c.data.size() > static_cast<uint64_t>(c.max_bytes)) {
      upload_.clear();
      upload_.shrink_to_fit();
      return absl::ResourceExhaustedError(absl::StrCat(
          "design upload: more than ", c.max_bytes, " bytes (the server's "
          "--max_design_mb); the upload is dropped"));
    }
    upload_.append(c.data.data(), c.data.size());
    if (!c.last) return DesignUploadState{upload_.size(), nullptr};
    whole.set_data(std::move(upload_));
    upload_ = std::string();
  }
  if (!(c.scale > 0) || !std::isfinite(c.scale) ||
      !std::isfinite(c.translation.x) || !std::isfinite(c.translation.y) ||
      !std::isfinite(c.translation.z)) {
    return absl::InvalidArgumentError(
        "design upload: scale must be > 0 and the translation finite");
  }
  whole.set_scale(c.scale);
  whole.mutable_translation()->set_x(c.translation.x);
  whole.mutable_translation()->set_y(c.translation.y);
  whole.mutable_translation()->set_z(c.translation.z);
  whole.set_name(c.name);
  const uint64_t received = whole.data().size();
  const std::string bytes = whole.SerializeAsString();
  // Read and placed outside the locks: other calls go on meanwhile.
  auto placed = PlaceDesign(bytes);
  if (!placed.ok()) return placed.status();
  {
    absl::MutexLock l(&mu_);
    if (deleted_) return absl::NotFoundError("the session was deleted");
    if (journal_ != nullptr) {
      if (absl::Status s = journal_->PutBlob("design", bytes); !s.ok()) {
        spdlog::error("session {}: cannot journal the design: {}", spec_.id,
                      std::string(s.message()));
        return absl::UnavailableError(
            "the design could not be journaled; try again");
      }
    }
    absl::MutexLock dl(&design_mu_);
    design_ = *placed;
  }
  spdlog::info("session {}: design {} placed ({} triangles)", spec_.id,
               (*placed)->name(), (*placed)->mesh().triangles.size());
  return DesignUploadState{received, *std::move(placed)};
}

absl::Status Session::SaveProgram(const std::string& bytes) {
  absl::MutexLock l(&mu_);
  if (deleted_) return absl::NotFoundError("the session was deleted");
  if (journal_ == nullptr) return absl::OkStatus();
  if (absl::Status s = journal_->PutBlob("program", bytes); !s.ok()) {
    spdlog::error("session {}: cannot journal the program: {}", spec_.id,
                  std::string(s.message()));
    return absl::UnavailableError(
        "the program could not be journaled (a storage error, logged on the "
        "server); nothing was applied");
  }
  return absl::OkStatus();
}

absl::StatusOr<std::optional<std::string>> Session::SavedProgram() const {
  absl::MutexLock l(&mu_);
  if (journal_ == nullptr) return std::optional<std::string>();
  return journal_->GetBlob("program");
}

std::shared_ptr<const design::PlacedDesign> Session::design() const {
  absl::MutexLock l(&design_mu_);
  return design_;
}

void Session::MarkDeleted() {
  absl::MutexLock l(&mu_);
  deleted_ = true;
  journal_.reset();
}

int64_t Session::EstimateMemoryBytes(const StockSpec& stock,
                                     SchemeKind scheme) {
  const int64_t tiles_x = (int64_t{stock.nx} + kTileSize) / kTileSize;
  const int64_t tiles_y = (int64_t{stock.ny} + kTileSize) / kTileSize;
  const int64_t tiles = tiles_x * tiles_y;
  // A cut tile's nodes are a block of the workpiece's TileArena, carved
  // from 2 MiB chunks that hold a whole number of blocks: what the process
  // takes is the chunks (measured: tests/session_memory_test.cc).
  const int64_t block =
      int64_t{kTileNodes} * GetScheme(scheme).bytes_per_node();
  const int64_t per_chunk =
      static_cast<int64_t>(TileArena::kChunkBytes) / block;
  const int64_t chunks = (tiles + per_chunk - 1) / per_chunk;
  // Per tile of the grid its pointer, version and derivative cache slot
  // (32 bytes), and per cut tile its Tile (48 bytes with malloc's header).
  constexpr int64_t kTileBookkeepingBytes = 32 + 48;
  return chunks * static_cast<int64_t>(TileArena::kChunkBytes) +
         tiles * kTileBookkeepingBytes;
}

absl::StatusOr<BatchResult> Session::ApplyBatch(uint64_t seq, int32_t tool_id,
                                                std::span<const double> xyz,
                                                int64_t max_points,
                                                bool reposition) {
  BatchOptions options;
  options.reposition = reposition;
  return ApplyBatch(seq, tool_id, xyz, max_points, options);
}

absl::StatusOr<BatchResult> Session::ApplyBatch(uint64_t seq, int32_t tool_id,
                                                std::span<const double> xyz,
                                                int64_t max_points,
                                                const BatchOptions& options) {
  const bool reposition = options.reposition;
  if (seq == 0) {
    return absl::InvalidArgumentError("moves.seq must start at 1");
  }
  if (xyz.empty()) {
    // Journaled or not: an empty batch moves nothing and would consume a
    // seq, so it is refused the same way everywhere.
    return absl::InvalidArgumentError(
        "moves.xyz is empty: a batch needs at least one (x, y, z) point");
  }
  if (xyz.size() % 3 != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("moves.xyz has ", xyz.size(),
                     " values, not a whole number of (x, y, z) points"));
  }
  const int64_t points = static_cast<int64_t>(xyz.size() / 3);
  if (points > max_points) {
    return absl::InvalidArgumentError(
        absl::StrCat("moves.xyz has ", points, " points, more than the limit ",
                     max_points, " per batch"));
  }
  const ToolSpec* tool = FindTool(tool_id);
  if (tool == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat(
        "moves.tool_id ", tool_id, " is not a tool of session ", spec_.id));
  }
  static constexpr const char* kAxis[3] = {"x", "y", "z"};
  for (size_t k = 0; k < xyz.size(); ++k) {
    if (!std::isfinite(xyz[k]) || std::fabs(xyz[k]) > kMaxCoordinate) {
      return absl::InvalidArgumentError(absl::StrCat(
          "moves.xyz[", k, "] (point ", k / 3, " ", kAxis[k % 3],
          ") must be finite and within +-", kMaxCoordinate, " mm, got ",
          xyz[k]));
    }
  }
  // Arcs become their chords here, outside the lock: from then on the batch
  // is a polyline like any other (journal, digest, replay).
  std::vector<double> chorded;
  if (!options.arcs.empty()) {
    auto c = ChordBatch(xyz, options.arcs, spec_.arc_tolerance, max_points);
    if (!c.ok()) return c.status();
    chorded = *std::move(c);
    xyz = chorded;
  }

  Touch();
  absl::MutexLock l(&mu_);
  if (deleted_) {
    return absl::NotFoundError(
        absl::StrCat("session ", spec_.id, " was deleted"));
  }
  if (pins_->load() > 0) {
    // A reader holds the workpiece outside the lock (Pin).
    return absl::FailedPreconditionError(absl::StrCat(
        "session ", spec_.id,
        " is being read by an in-process client; batches are refused "
        "until it is done"));
  }
  if (wp_ == nullptr) {
    if (absl::Status s = ReloadLocked(); !s.ok()) return s;
  }
  auto result = ApplyLocked(seq, *tool, xyz, reposition, true, &options);
  if (result.ok() && SnapshotDueLocked()) {
    SaveSnapshotLocked().IgnoreError();  // logged inside
  }
  return result;
}

void Session::Touch() const {
  last_used_ms_.store(absl::ToUnixMillis(absl::Now()),
                      std::memory_order_relaxed);
}

double Session::IdleSeconds() const {
  return (absl::ToUnixMillis(absl::Now()) -
          last_used_ms_.load(std::memory_order_relaxed)) /
         1000.0;
}

absl::StatusOr<std::shared_ptr<const Workpiece>> Session::Pin() const {
  EnsureLoaded();
  absl::MutexLock l(&mu_);
  if (deleted_) {
    return absl::NotFoundError(
        absl::StrCat("session ", spec_.id, " was deleted"));
  }
  if (wp_ == nullptr) {
    return absl::UnavailableError(
        absl::StrCat("session ", spec_.id, " could not be reloaded"));
  }
  // Counted under mu_, as ApplyBatch and Evict check it: a batch either
  // ends before the pin or is refused.
  struct Holder {
    Holder(std::shared_ptr<const Workpiece> w,
           std::shared_ptr<std::atomic<int>> p)
        : wp(std::move(w)), pins(std::move(p)) {
      pins->fetch_add(1);
    }
    ~Holder() { pins->fetch_sub(1); }
    Holder(const Holder&) = delete;
    Holder& operator=(const Holder&) = delete;
    std::shared_ptr<const Workpiece> wp;
    std::shared_ptr<std::atomic<int>> pins;
  };
  auto holder = std::make_shared<Holder>(wp_, pins_);
  const Workpiece* wp = holder->wp.get();
  return std::shared_ptr<const Workpiece>(std::move(holder), wp);
}

bool Session::Evict() {
  absl::MutexLock l(&mu_);
  if (journal_ == nullptr || wp_ == nullptr || deleted_) return false;
  if (pins_->load() > 0) return false;
  // So that the reload loads the state instead of redoing every cut.
  SaveSnapshotLocked().IgnoreError();  // logged inside
  evicted_state_.last_seq = last_seq_;
  evicted_state_.moves_applied = wp_->move_count();
  evicted_state_.version = wp_->version();
  evicted_state_.allocated_tiles = 0;
  evicted_state_.memory_bytes = 0;
  evicted_state_.last_position = last_position_;
  wp_.reset();
  return true;
}

bool Session::evicted() const {
  absl::ReaderMutexLock l(&mu_);
  return wp_ == nullptr;
}

void Session::EnsureLoaded() const {
  Touch();
  {
    absl::ReaderMutexLock l(&mu_);
    if (wp_ != nullptr) return;
  }
  absl::MutexLock l(&mu_);
  if (wp_ == nullptr) ReloadLocked().IgnoreError();  // logged inside
}

absl::Status Session::ReloadLocked() const {
  // The same rebuild as a restart: bit-identical to the evicted grid.
  auto problem = RebuildLocked();
  if (!problem.ok() || !problem->empty()) {
    const std::string what =
        problem.ok() ? *problem : std::string(problem.status().message());
    spdlog::error("session {}: reloaded up to batch {}: {}", spec_.id,
                  last_seq_, what);
    return absl::DataLossError(absl::StrCat("session ", spec_.id,
                                            " reloaded up to batch ",
                                            last_seq_, ": ", what));
  }
  spdlog::info("session {}: reloaded ({} batches)", spec_.id, last_seq_);
  return absl::OkStatus();
}

absl::StatusOr<BatchResult> Session::ApplyLocked(uint64_t seq,
                                                 const ToolSpec& tool,
                                                 std::span<const double> xyz,
                                                 bool reposition,
                                                 bool journal,
                                                 const BatchOptions* checks) const {
  BatchResult r;
  r.seq = seq;
  const uint32_t digest = BatchDigest(tool.id, reposition, xyz);
  if (seq <= last_seq_) {
    if (seq <= digests_.size() && digests_[seq - 1] != digest) {
      // Resending is only safe with the same moves: a differing batch under
      // an acknowledged seq is a client bug or a second writer.
      return absl::AlreadyExistsError(absl::StrCat(
          "moves.seq ", seq, " was already acknowledged with other moves "
          "(tool, reposition or xyz differ): a second writer, or a client "
          "that lost track; the session is at seq ", last_seq_));
    }
    r.duplicate = true;
    r.moves_applied = wp_->move_count();
    r.version = wp_->version();
    return r;
  }
  if (seq != last_seq_ + 1) {
    return absl::FailedPreconditionError(
        absl::StrCat("moves.seq ", seq, " after ", last_seq_, ": batches ",
                     last_seq_ + 1, "..", seq - 1, " are missing"));
  }
  std::optional<Vec3> pos;
  const UnfilledVector<Move> moves = BatchMoves(tool, xyz, reposition, &pos);
  // Durable before applied, applied before acknowledged.
  if (journal && journal_ != nullptr) {
    if (absl::Status s = journal_->Append(seq, tool.id, reposition, xyz);
        !s.ok()) {
      // The storage's own words stay in the log: clients get what happened.
      spdlog::error("session {}: batch {}: {}", spec_.id, seq,
                    std::string(s.message()));
      return absl::UnavailableError(absl::StrCat(
          "session ", spec_.id, ": batch ", seq,
          " could not be written to the server's journal (a storage error, "
          "logged on the server); nothing was applied"));
    }
  }
  // The checks need what each move cut: asked of the kernel only when some
  // check can fire or the client wants the volumes.
  const ToolAssembly& as = tool.assembly;
  const bool check = checks != nullptr &&
                     (checks->rapid || checks->report_cuts || as.known());
  std::vector<double> flutes;
  ApplyOptions apply_options;
  if (check) {
    apply_options.cuts = true;
    if (as.flute_length > 0) {
      flutes.assign(moves.size(), as.flute_length);
      apply_options.drop_limit = flutes;
    }
  }
  auto applied = wp_->Apply(moves, apply_options);
  if (!applied.ok()) {
    if (journal && journal_ != nullptr) journal_->Remove(seq).IgnoreError();
    return applied.status();
  }
  last_seq_ = seq;
  last_position_ = pos;
  digests_.push_back(digest);
  r.moves_applied = wp_->move_count();
  r.node_lowerings = applied->node_lowerings;
  r.version = applied->version;
  for (int32_t t : applied->changed_tiles) {
    r.changed_tiles.emplace_back(t, wp_->TileVersion(t));
  }
  if (check) Check(*checks, tool, moves, *applied, &r);
  return r;
}

void Session::Check(const BatchOptions& checks, const ToolSpec& tool,
                    std::span<const Move> moves, const ApplyResult& applied,
                    BatchResult* r) const {
  const ToolAssembly& as = tool.assembly;
  const GridGeometry& g = wp_->grid();
  const double shank_r = as.shank_diameter / 2;
  if (checks.report_cuts) r->removed_mm3.resize(moves.size());
  for (size_t k = 0; k < moves.size(); ++k) {
    const MoveCut& c = applied.cuts[k];
    if (checks.report_cuts) r->removed_mm3[k] = c.removed_mm3;
    auto add = [&](SafetyFinding::Kind kind, double x, double y, double z,
                   double depth, double volume) {
      SafetyFinding f;
      f.kind = kind;
      f.move_index = static_cast<int64_t>(k);
      f.move_id = applied.first_move_id + static_cast<int64_t>(k);
      f.x = x;
      f.y = y;
      f.z = z;
      f.depth = depth;
      f.volume_mm3 = volume;
      r->safety.push_back(f);
    };
    const Move& m = moves[k];
    // Two sweeps that meet at a node (a retract from a cut's end) can set
    // it a few ulps apart: lowerings under a nanometre are that rounding,
    // not material (still counted in removed_mm3, which stays exact).
    constexpr double kCutNoiseMm = 1e-9;
    if (c.max_drop > kCutNoiseMm) {
      const double x = g.NodeX(c.i), y = g.NodeY(c.j);
      if (checks.rapid) {
        add(SafetyFinding::kRapidCut, x, y, c.z, c.max_drop, c.removed_mm3);
      }
      if (as.flute_length > 0 && c.max_drop > as.flute_length) {
        add(SafetyFinding::kShankContact, x, y, c.z + c.max_drop,
            c.max_drop - as.flute_length, c.over_limit_mm3);
      }
      if (!as.center_cutting && m.from.x == m.to.x && m.from.y == m.to.y &&
          m.to.z < m.from.z) {
        add(SafetyFinding::kPlunge, x, y, c.z, c.max_drop, c.removed_mm3);
      }
    }
    // A shank wider than the cutter meets material beside the cut.
    if (as.flute_length > 0 && shank_r > m.cutter.radius) {
      const Contact s = CylinderContact(*wp_, m.from, m.to, shank_r,
                                        as.flute_length);
      if (s.hit) {
        add(SafetyFinding::kShankContact, s.x, s.y, s.z, s.depth, s.volume_mm3);
      }
    }
    if (as.holder_diameter > 0) {
      const Contact h = CylinderContact(*wp_, m.from, m.to,
                                        as.holder_diameter / 2, as.stickout);
      if (h.hit) {
        add(SafetyFinding::kHolderContact, h.x, h.y, h.z, h.depth,
            h.volume_mm3);
      }
    }
  }
}

SessionState Session::State() const {
  absl::ReaderMutexLock l(&mu_);
  SessionState s;
  if (wp_ == nullptr) {
    s = evicted_state_;  // no reload just to report
  } else {
    s.last_seq = last_seq_;
    s.moves_applied = wp_->move_count();
    s.version = wp_->version();
    s.allocated_tiles = wp_->allocated_tiles();
    s.memory_bytes = wp_->allocated_node_bytes() + wp_->move_bytes();
    s.last_position = last_position_;
  }
  absl::MutexLock l2(&snapshot_mu_);
  s.snapshot_seq = snapshot_seq_;
  return s;
}

}  // namespace swarf::server
