#include "server/service.h"

#include <algorithm>
#include <atomic>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <span>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/synchronization/mutex.h"
#include "absl/time/clock.h"
#include "absl/time/time.h"
#include "client/outputs/deviation.h"
#include "client/outputs/grid_bands.h"
#include "client/outputs/surface_grid.h"
#include "core/valuation.h"
#include "google/protobuf/io/coded_stream.h"
#include "server/convert.h"
#include "server/program.h"
#include "server/status_util.h"
#include "spdlog/spdlog.h"

namespace swarf::server {
namespace {

namespace pb = ::swarf::v1;
using ::google::protobuf::io::CodedOutputStream;

// The call's metadata value under `key` ("" when absent).
std::string MetadataOf(grpc::CallbackServerContext* ctx, const char* key) {
  const auto& md = ctx->client_metadata();
  auto it = md.find(key);
  return it == md.end() ? std::string()
                        : std::string(it->second.data(), it->second.size());
}

// The session id of a call: the request's field and/or the
// x-swarf-session metadata, which must agree when both are given.
absl::StatusOr<std::string> SessionIdOf(grpc::CallbackServerContext* ctx,
                                        const std::string& field) {
  const std::string meta = MetadataOf(ctx, kSessionMetadata);
  if (!field.empty() && !meta.empty() && field != meta) {
    return absl::InvalidArgumentError(
        absl::StrCat("session_id \"", field, "\" differs from the ",
                     kSessionMetadata, " metadata \"", meta, "\""));
  }
  std::string id = field.empty() ? meta : field;
  if (id.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(
        "session_id is required (field or ", kSessionMetadata, " metadata)"));
  }
  return id;
}

// The caller's principal, from its `authorization` metadata; "" when
// authentication is off; UNAUTHENTICATED when the token is missing or wrong.
absl::StatusOr<std::string> PrincipalOf(TokenStore* tokens,
                                        grpc::CallbackServerContext* ctx) {
  if (!tokens->enabled()) return std::string();
  return tokens->Check(MetadataOf(ctx, "authorization"));
}

// The caller's session, NOT_FOUND when it is another principal's.
absl::StatusOr<std::shared_ptr<Session>> SessionOf(
    Registry* registry, TokenStore* tokens, grpc::CallbackServerContext* ctx,
    const std::string& field) {
  auto principal = PrincipalOf(tokens, ctx);
  if (!principal.ok()) return principal.status();
  auto id = SessionIdOf(ctx, field);
  if (!id.ok()) return id.status();
  return registry->Get(*id, *principal);
}

// Peak resident memory of this process (VmHWM), 0 where /proc is absent.
int64_t PeakMemoryBytes() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) {
      return std::strtoll(line.c_str() + 6, nullptr, 10) * 1024;
    }
  }
  return 0;
}

// RESOURCE_EXHAUSTED unless an answer of `bytes` fits the server's message
// limit: the caller answers with this status instead of a message the
// transport would refuse (which would end a stream).
absl::Status FitsMessage(size_t bytes, int64_t limit, absl::string_view what) {
  if (static_cast<int64_t>(bytes) <= limit) return absl::OkStatus();
  return absl::ResourceExhaustedError(absl::StrCat(
      what, " would be a message of ", bytes,
      " bytes, over the server's limit of ", limit,
      " (--max_message_mb): ask for a smaller region or map"));
}

// FitsMessage's error for a MarksRequest's answer, found a polyline at a
// time and stopped once its first `bytes` were over the limit.
absl::Status MarksAnswerOverLimit(size_t bytes, int64_t limit) {
  return absl::ResourceExhaustedError(absl::StrCat(
      "the answer to this request would be a message of more than ", bytes,
      " bytes, over the server's limit of ", limit,
      " (--max_message_mb): ask for a smaller region, or for GetCuttingMarks "
      "(a message per polyline)"));
}

// The error map's size is known before it is computed: refuse early.
absl::Status MapFits(int32_t cols, int32_t rows, int64_t limit) {
  if (cols <= 0 || rows <= 0 || int64_t{cols} * rows > kMaxMapCells) {
    return absl::OkStatus();  // bad input: ComputeStats names the fields
  }
  // 4 bytes a cell, plus the statistics and framing.
  return FitsMessage(4 * static_cast<size_t>(cols) * rows + 256, limit,
                     absl::StrCat("an error map of ", cols, " x ", rows,
                                  " cells"));
}

}  // namespace

absl::StatusOr<pb::Deviation> ComputeDeviation(const Session& session,
                                               const pb::DeviationRequest& req,
                                               int64_t max_message_bytes) {
  const std::shared_ptr<const design::PlacedDesign> design = session.design();
  if (design == nullptr) {
    return absl::FailedPreconditionError(
        "the session has no design: SetDesign first");
  }
  cli::DeviationOptions o;
  o.allowance = req.allowance();
  if (req.has_tolerance()) o.tolerance = req.tolerance().value();
  if (req.has_samples_per_edge()) {
    const int32_t n = req.samples_per_edge().value();
    if (n < 0 || n > 64) {
      return absl::InvalidArgumentError("samples_per_edge must be in [0, 64]");
    }
    o.samples_per_edge = n;
  }
  if (req.max_moves() < 0) {
    return absl::InvalidArgumentError("max_moves must be >= 0");
  }
  if (req.max_moves() > 0) o.max_lines = req.max_moves();
  // The session's grid band by band (tile rows of about 1 M nodes,
  // cli::TileRowBands), never a whole-grid copy: the banded measure gives
  // the whole grid's figures bit for bit. Each band is read under the
  // session's shared lock, let go between bands so that batches can apply
  // meanwhile; a band that finds another state than the pass began with (a
  // batch applied, the session reloaded) stops the pass, which starts over;
  // the last try holds the lock for its whole pass.
  struct State {
    const Workpiece* wp = nullptr;
    uint64_t version = 0;
    int64_t moves = 0;
    bool operator==(const State&) const = default;
  };
  auto state_of = [](const Workpiece& wp) {
    return State{&wp, wp.version(), wp.move_count()};
  };
  struct Start {
    State state;
    StockSpec spec;
    SchemeKind scheme;
    std::shared_ptr<const MoveSource> moves;
  };
  auto start_of = [&](const Workpiece& wp) {
    // The moves copied compactly (28 bytes each): the session's list grows
    // while the pass lets the lock go.
    auto moves = std::make_shared<MoveList>();
    for (int64_t id = 0; id < wp.move_count(); ++id) moves->Append(wp.move(id));
    return Start{state_of(wp), wp.spec(), wp.scheme().kind(),
                 std::move(moves)};
  };
  auto measure = [&](Start start, cli::TileRowBands::Fill fill)
      -> absl::StatusOr<cli::DeviationReport> {
    // The moves themselves are the "lines": the client maps them.
    std::vector<cli::SourceLine> lines(start.moves->size());
    for (size_t k = 0; k < lines.size(); ++k) {
      lines[k] = {0, static_cast<int32_t>(k)};
    }
    cli::TileRowBands bands(start.spec, start.scheme, std::move(fill),
                            std::move(start.moves));
    bands.SetFillWritesEveryNode();  // SetTileRows
    return cli::MeasureDeviation(bands, design->envelope(), design->index(),
                                 lines, o,
                                 [](int32_t, int32_t, const float*) {});
  };
  constexpr int kTries = 3;
  absl::StatusOr<cli::DeviationReport> r;
  bool changed = true;
  for (int attempt = 1; attempt < kTries && changed; ++attempt) {
    Start start = session.Read(start_of);
    const State seen = start.state;
    changed = false;
    r = measure(std::move(start), [&](cli::SurfaceGrid* band, int32_t t0,
                                      int32_t t1, bool heights_only) {
      return session.Read([&](const Workpiece& wp) -> absl::Status {
        if (!(state_of(wp) == seen)) {
          changed = true;
          return absl::AbortedError("the session changed during the pass");
        }
        return band->SetTileRows(wp, t0, t1, heights_only);
      });
    });
  }
  if (changed) {
    r = session.Read([&](const Workpiece& wp) {
      return measure(start_of(wp), [&](cli::SurfaceGrid* band, int32_t t0,
                                       int32_t t1, bool heights_only) {
        return band->SetTileRows(wp, t0, t1, heights_only);
      });
    });
  }
  if (!r.ok()) return r.status();
  pb::Deviation out;
  out.set_triangles(static_cast<int64_t>(design->mesh().triangles.size()));
  out.set_nodes(r->nodes);
  out.set_samples(r->samples);
  out.set_gouge_max(r->gouge_max);
  out.set_gouge_x(r->gouge_x);
  out.set_gouge_y(r->gouge_y);
  out.set_gouge_move(r->gouge_move);
  out.set_gouge_volume_mm3(r->gouge_volume);
  out.set_excess_max(r->excess_max);
  out.set_excess_x(r->excess_x);
  out.set_excess_y(r->excess_y);
  out.set_excess_mean(r->excess_mean);
  out.set_excess_volume_mm3(r->excess_volume);
  out.set_normal_gouge_max(r->normal_gouge_max);
  out.set_normal_excess_max(r->normal_excess_max);
  out.set_allowance(r->allowance);
  out.set_tolerance(r->tolerance);
  out.set_out_of_tolerance_area_mm2(r->out_area_mm2);
  out.set_ok(r->ok);
  auto add = [](const cli::LineDeviation& l, pb::DeviationMove* m) {
    m->set_move(l.line);
    m->set_depth(l.depth);
    m->set_x(l.x);
    m->set_y(l.y);
    m->set_area_mm2(l.area_mm2);
  };
  for (const auto& l : r->gouge_lines) add(l, out.add_gouge_moves());
  for (const auto& l : r->excess_lines) add(l, out.add_excess_moves());
  if (absl::Status fits =
          FitsMessage(out.ByteSizeLong(), max_message_bytes, "the deviation");
      !fits.ok()) {
    return fits;
  }
  return out;
}

namespace {

// The kind of request a RequestError answers.
pb::RequestKind KindOf(pb::SimulateRequest::RequestCase c) {
  switch (c) {
    case pb::SimulateRequest::kMoves:
      return pb::REQUEST_KIND_MOVES;
    case pb::SimulateRequest::kTiles:
      return pb::REQUEST_KIND_TILES;
    case pb::SimulateRequest::kStats:
      return pb::REQUEST_KIND_STATS;
    case pb::SimulateRequest::kMarks:
      return pb::REQUEST_KIND_MARKS;
    case pb::SimulateRequest::kSubscribe:
      return pb::REQUEST_KIND_SUBSCRIBE;
    case pb::SimulateRequest::kDeviation:
      return pb::REQUEST_KIND_DEVIATION;
    case pb::SimulateRequest::kProgram:
      return pb::REQUEST_KIND_PROGRAM;
    case pb::SimulateRequest::REQUEST_NOT_SET:
      break;
  }
  return pb::REQUEST_KIND_UNSPECIFIED;
}

// The id and kind of the request a stream response answers (to replace it
// with a RequestError).
std::pair<uint64_t, pb::RequestKind> RequestOf(const pb::SimulateResponse& r) {
  switch (r.response_case()) {
    case pb::SimulateResponse::kAck:
      return {r.ack().seq(), pb::REQUEST_KIND_MOVES};
    case pb::SimulateResponse::kTile:
      return {r.tile().request_id(), pb::REQUEST_KIND_TILES};
    case pb::SimulateResponse::kTilesDone:
      return {r.tiles_done().request_id(), pb::REQUEST_KIND_TILES};
    case pb::SimulateResponse::kStats:
      return {r.stats().request_id(), pb::REQUEST_KIND_STATS};
    case pb::SimulateResponse::kPolylines:
      return {r.polylines().request_id(), pb::REQUEST_KIND_MARKS};
    case pb::SimulateResponse::kError:
      return {r.error().request_id(), r.error().kind()};
    case pb::SimulateResponse::kDeviation:
      return {r.deviation().request_id(), pb::REQUEST_KIND_DEVIATION};
    case pb::SimulateResponse::kProgramDone:
      return {r.program_done().request_id(), pb::REQUEST_KIND_PROGRAM};
    case pb::SimulateResponse::RESPONSE_NOT_SET:
      break;
  }
  return {0, pb::REQUEST_KIND_UNSPECIFIED};
}

// Who still needs a reactor: gRPC until OnDone, and each executor task
// scheduled for it until the task's last step (after its lock is released,
// another thread may finish the stream and gRPC call OnDone). Whoever
// releases the last reference deletes the reactor.
class ReactorRefs {
 public:
  void Add() { refs_.fetch_add(1, std::memory_order_relaxed); }
  // Whether that was the last reference.
  bool Release() { return refs_.fetch_sub(1, std::memory_order_acq_rel) == 1; }

 private:
  std::atomic<int> refs_{1};  // gRPC's
};

// What a server stream with one write in flight does next, decided under
// its lock: start writing the queue's front, end the call, or neither.
// `producing`: messages may still be added by a task now running; `more`:
// a task may be started for more. A cancelled call ends CANCELLED once no
// write is in flight and no task runs; otherwise with `status` once the
// queue is written and nothing more can come. Sets *writing and *finished
// as it decides (shared by ChunkedWriter and MarksWriter).
struct WriteTurn {
  bool write = false;
  std::optional<grpc::Status> finish;
};
WriteTurn NextWriteTurn(bool cancelled, bool producing, bool more,
                        bool queue_empty, const grpc::Status& status,
                        bool* writing, bool* finished) {
  WriteTurn turn;
  if (*finished) return turn;
  if (cancelled) {
    if (!*writing && !producing) {
      *finished = true;
      turn.finish = grpc::Status::CANCELLED;
    }
    return turn;
  }
  if (!*writing && !queue_empty) {
    *writing = true;
    turn.write = true;
  }
  if (!*writing && !producing && !more && queue_empty) {
    *finished = true;
    turn.finish = status;
  }
  return turn;
}

// A server stream whose messages are produced on the executor in chunks:
// `produce` appends the next messages and returns false once there are no
// more (or an error). One write in flight; the next chunk is produced when
// the queue runs low.
template <typename T>
class ChunkedWriter : public grpc::ServerWriteReactor<T> {
 public:
  using Producer = std::function<absl::StatusOr<bool>(std::deque<T>*)>;

  ChunkedWriter(grpc::CallbackServerContext* ctx, Executor* executor,
                const std::string& replica, Producer produce)
      : executor_(executor), produce_(std::move(produce)) {
    ctx->AddInitialMetadata(kReplicaMetadata, replica);
    this->StartSendInitialMetadata();
    {
      absl::MutexLock l(&mu_);
      producing_ = true;
    }
    refs_.Add();
    executor_->Schedule([this] { Produce(); });
  }

  void OnWriteDone(bool ok) override {
    Act act;
    {
      absl::MutexLock l(&mu_);
      writing_ = false;
      queue_.pop_front();
      if (!ok) cancelled_ = true;
      act = NextLocked();
    }
    Do(act);
  }

  void OnCancel() override {
    Act act;
    {
      absl::MutexLock l(&mu_);
      cancelled_ = true;
      act = NextLocked();
    }
    Do(act);
  }

  void OnDone() override {
    if (refs_.Release()) delete this;
  }

 private:
  static constexpr size_t kLowWater = 16;

  struct Act {
    const T* write = nullptr;
    bool produce = false;
    std::optional<grpc::Status> finish;
  };

  // Decides what to do next; the caller does it without holding mu_.
  Act NextLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    Act act;
    const WriteTurn turn = NextWriteTurn(cancelled_, producing_, more_,
                                         queue_.empty(), status_, &writing_,
                                         &finished_);
    if (turn.write) act.write = &queue_.front();
    act.finish = turn.finish;
    if (!finished_ && !cancelled_ && !producing_ && more_ &&
        queue_.size() <= kLowWater) {
      producing_ = true;
      refs_.Add();
      act.produce = true;
    }
    return act;
  }

  void Do(const Act& act) {
    if (act.produce) executor_->Schedule([this] { Produce(); });
    if (act.write != nullptr) this->StartWrite(act.write);
    if (act.finish.has_value()) this->Finish(*act.finish);
  }

  void Produce() {
    std::deque<T> chunk;
    absl::StatusOr<bool> more = produce_(&chunk);
    Act act;
    {
      absl::MutexLock l(&mu_);
      producing_ = false;
      if (!more.ok()) {
        status_ = ToGrpcStatus(more.status());
        more_ = false;
      } else {
        more_ = *more;
        for (T& m : chunk) queue_.push_back(std::move(m));
      }
      act = NextLocked();
    }
    Do(act);
    if (refs_.Release()) delete this;
  }

  Executor* const executor_;
  const Producer produce_;
  absl::Mutex mu_;
  std::deque<T> queue_ ABSL_GUARDED_BY(mu_);  // front is in flight if writing_
  bool writing_ ABSL_GUARDED_BY(mu_) = false;
  bool producing_ ABSL_GUARDED_BY(mu_) = false;
  bool more_ ABSL_GUARDED_BY(mu_) = true;
  bool cancelled_ ABSL_GUARDED_BY(mu_) = false;
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
  grpc::Status status_ ABSL_GUARDED_BY(mu_);
  ReactorRefs refs_;  // gRPC's, and each Produce task's
};

// GetCuttingMarks: the polylines written one per message as the search
// finds them (StreamMarks), never all of them held.
//
// The search runs on a thread of its own (Executor::StartThread), not on
// the executor: it waits whenever its client reads slower than it finds
// marks, and the executor's threads (one per core) serve every session's
// calls, so a few slow readers there would stall the server. That thread
// mostly waits: the search's loops run on the workpiece's pool. It holds the
// session's shared lock while it runs, as every read does: a batch or a
// DeleteSession of that session waits for the search, so for its client,
// at most until the call's deadline; other sessions do not. One thread per
// open call: as many as there are GetCuttingMarks calls at once.
//
// Flow control: one write in flight, the next started by OnWriteDone or by
// the search when it queues one; the queue holds at most
// limits.marks_queue_bytes of polylines (serialized, the one in flight
// included), or one polyline when a single one is larger (each is at most
// the message limit). A cancelled call (the client gone, its deadline, the
// server shutting down) wakes the search, which stops at its next polyline
// or window of bands (FindCuttingMarks' poll); the call ends CANCELLED once
// the search has ended and no write is in flight.
//
// Lifetime: gRPC's reference until OnDone and the search thread's until its
// last step; whoever releases the last deletes the reactor (ReactorRefs).
class MarksWriter : public grpc::ServerWriteReactor<pb::Polyline> {
 public:
  MarksWriter(grpc::CallbackServerContext* ctx, Registry* registry,
              TokenStore* tokens, Executor* executor,
              MarksStreamCounters* counters, const std::string& replica,
              const pb::GetCuttingMarksRequest& req)
      : ctx_(ctx),
        registry_(registry),
        tokens_(tokens),
        counters_(counters),
        req_(req),
        max_queued_(registry->limits().marks_queue_bytes) {
    ctx->AddInitialMetadata(kReplicaMetadata, replica);
    this->StartSendInitialMetadata();
    {
      absl::MutexLock l(&mu_);
      searching_ = true;
    }
    refs_.Add();
    counters_->searches.fetch_add(1, std::memory_order_relaxed);
    if (!executor->StartThread([this] { Search(); })) {
      Ended(absl::ResourceExhaustedError(
          "no thread for the cutting marks' search: try again later"));
    }
  }

  void OnWriteDone(bool ok) override {
    Act act;
    {
      absl::MutexLock l(&mu_);
      writing_ = false;
      queued_bytes_ -= queue_.front().bytes;
      queue_.pop_front();
      if (!ok) cancelled_ = true;
      act = NextLocked();
    }
    Do(act);  // the search, if it waits for room, wakes when mu_ is let go
  }

  void OnCancel() override {
    Act act;
    {
      absl::MutexLock l(&mu_);
      cancelled_ = true;
      act = NextLocked();
    }
    Do(act);
  }

  void OnDone() override {
    if (refs_.Release()) delete this;
  }

 private:
  struct Queued {
    pb::Polyline message;
    int64_t bytes = 0;
  };

  struct Act {
    const pb::Polyline* write = nullptr;
    std::optional<grpc::Status> finish;
  };

  // Decides what to do next; the caller does it without holding mu_.
  Act NextLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    Act act;
    const WriteTurn turn =
        NextWriteTurn(cancelled_, searching_, /*more=*/false, queue_.empty(),
                      status_, &writing_, &finished_);
    // A deque's elements stay put.
    if (turn.write) act.write = &queue_.front().message;
    act.finish = turn.finish;
    return act;
  }

  void Do(const Act& act) {
    if (act.write != nullptr) this->StartWrite(act.write);
    if (act.finish.has_value()) this->Finish(*act.finish);
  }

  // Whether the search may queue a polyline of next_bytes_ (or must stop).
  bool CanQueueLocked() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    return cancelled_ || queued_bytes_ == 0 ||
           queued_bytes_ + next_bytes_ <= max_queued_;
  }

  // The search's emit: waits for room, then queues `p` (and writes it if
  // no write is in flight). CANCELLED stops the search.
  absl::Status Enqueue(pb::Polyline p) {
    const int64_t bytes = static_cast<int64_t>(p.ByteSizeLong());
    if (absl::Status fits = FitsMessage(
            bytes, registry_->limits().max_message_bytes, "a cutting mark");
        !fits.ok()) {
      return fits;
    }
    Act act;
    {
      absl::MutexLock l(&mu_);
      next_bytes_ = bytes;
      if (!CanQueueLocked()) {
        counters_->waits.fetch_add(1, std::memory_order_relaxed);
        mu_.Await(absl::Condition(this, &MarksWriter::CanQueueLocked));
      }
      if (cancelled_) return absl::CancelledError("the call was cancelled");
      queued_bytes_ += bytes;
      int64_t peak = counters_->peak_queued_bytes.load();
      while (queued_bytes_ > peak &&
             !counters_->peak_queued_bytes.compare_exchange_weak(
                 peak, queued_bytes_)) {
      }
      queue_.push_back({std::move(p), bytes});
      act = NextLocked();
    }
    Do(act);
    return absl::OkStatus();
  }

  // The search's poll, after every window of bands.
  absl::Status Cancelled() {
    absl::MutexLock l(&mu_);
    return cancelled_ ? absl::CancelledError("the call was cancelled")
                      : absl::OkStatus();
  }

  absl::Status Find() {
    if (absl::Status st = Cancelled(); !st.ok()) return st;
    auto session = SessionOf(registry_, tokens_, ctx_, req_.session_id());
    if (!session.ok()) return session.status();
    return (*session)->Read([&](const Workpiece& wp) {
      return StreamMarks(
          wp, req_.has_region() ? &req_.region() : nullptr,
          req_.screening_threshold(), req_.min_angle_deg(),
          [this](pb::Polyline p) { return Enqueue(std::move(p)); },
          [this] { return Cancelled(); });
    });
  }

  // The search thread's task.
  void Search() { Ended(Find()); }  // the session's lock is let go

  // The search ended with `st` (or never started): the call ends once the
  // queue is written. Releases the search's reference.
  void Ended(const absl::Status& st) {
    // Before the call can end: once a client sees the end, no search runs.
    counters_->searches.fetch_sub(1, std::memory_order_relaxed);
    Act act;
    {
      absl::MutexLock l(&mu_);
      searching_ = false;
      status_ = ToGrpcStatus(st);  // unless cancelled (NextLocked)
      act = NextLocked();
    }
    Do(act);
    if (refs_.Release()) delete this;
  }

  grpc::CallbackServerContext* const ctx_;  // valid until OnDone
  Registry* const registry_;
  TokenStore* const tokens_;
  MarksStreamCounters* const counters_;
  const pb::GetCuttingMarksRequest req_;
  const int64_t max_queued_;
  absl::Mutex mu_;
  // Its front is being written while writing_.
  std::deque<Queued> queue_ ABSL_GUARDED_BY(mu_);
  int64_t queued_bytes_ ABSL_GUARDED_BY(mu_) = 0;
  int64_t next_bytes_ ABSL_GUARDED_BY(mu_) = 0;  // the polyline to queue
  bool writing_ ABSL_GUARDED_BY(mu_) = false;
  bool searching_ ABSL_GUARDED_BY(mu_) = false;
  bool cancelled_ ABSL_GUARDED_BY(mu_) = false;
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
  grpc::Status status_ ABSL_GUARDED_BY(mu_);
  ReactorRefs refs_;  // gRPC's, and the search thread's
};

// The Simulate stream of one session.
//
// Requests are read into `in_` and processed in order by one task at a time
// on the executor; responses queue in `out_` and are written one at a time.
// Reading pauses while either queue is full, which is the backpressure both
// ways. A large tile request becomes a job that produces tiles as room frees
// up; subscribed tiles that change are pushed coalesced (one pending push per
// tile, materialised at its latest version when it is its turn).
class SimulateReactor
    : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  SimulateReactor(grpc::CallbackServerContext* ctx, Registry* registry,
                  Executor* executor, TokenStore* tokens,
                  SwarfService::StreamCounter* streams, const ProxyTrust& trust,
                  const std::string& replica)
      : registry_(registry), executor_(executor) {
    ctx->AddInitialMetadata(kReplicaMetadata, replica);
    auto session = SessionOf(registry, tokens, ctx, "");
    if (!session.ok()) {
      finished_ = true;
      Finish(ToGrpcStatus(session.status()));
      return;
    }
    // A client is its token, or its address without authentication.
    auto principal = PrincipalOf(tokens, ctx);
    const std::string real_ip = MetadataOf(ctx, kRealIpMetadata);
    std::string client =
        ClientKey(principal.ok() ? *principal : "", ctx->peer(),
                  real_ip.empty() ? nullptr : &real_ip, trust);
    const int32_t limit = registry->limits().max_streams_per_client;
    if (!streams->Acquire(client, limit)) {
      finished_ = true;
      Finish(grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                          absl::StrCat("this client has ", limit,
                                       " streams open, the server's limit")));
      return;
    }
    streams_ = streams;
    client_ = std::move(client);
    session_ = *session;
    StartSendInitialMetadata();
    spdlog::info("session {}: stream opened by {} (client {})",
                 session_->id(), ctx->peer(), client_);
    {
      absl::MutexLock l(&mu_);
      read_pending_ = true;
    }
    StartRead(&req_);  // never under mu_: a reaction may run inline
  }

  void OnReadDone(bool ok) override {
    // Parsed here (raw method): a message that is not a SimulateRequest
    // ends the reading, and the stream once what came before is answered.
    pb::SimulateRequest req;
    const bool parsed =
        ok && grpc::SerializationTraits<pb::SimulateRequest>::Deserialize(
                  &req_, &req)
                  .ok();
    Act act;
    {
      absl::MutexLock l(&mu_);
      read_pending_ = false;
      if (!ok) {
        reads_done_ = true;
      } else if (!parsed) {
        reads_done_ = true;
        read_error_ = grpc::Status(
            grpc::StatusCode::INVALID_ARGUMENT,
            absl::StrCat("message ", reads_ + 1,
                         " of the stream is not a SimulateRequest"));
      } else {
        ++reads_;
        in_.push_back(std::move(req));
      }
      act = NextLocked();
    }
    Do(act);
  }

  void OnWriteDone(bool ok) override {
    Act act;
    {
      absl::MutexLock l(&mu_);
      writing_ = false;
      out_.pop_front();
      if (!ok) cancelled_ = true;
      act = NextLocked();
    }
    Do(act);
  }

  void OnCancel() override {
    Act act;
    {
      absl::MutexLock l(&mu_);
      cancelled_ = true;
      act = NextLocked();
    }
    Do(act);
  }

  void OnDone() override {
    if (session_ != nullptr) {
      spdlog::info("session {}: stream closed", session_->id());
    }
    if (streams_ != nullptr) streams_->Release(client_);
    if (refs_.Release()) delete this;
  }

 private:
  static constexpr size_t kMaxIn = 4;    // requests read ahead
  static constexpr size_t kMaxOut = 64;  // responses queued

  struct Act {
    bool read = false;
    const pb::SimulateResponse* write = nullptr;
    bool process = false;
    std::optional<grpc::Status> finish;
  };

  struct TileJob {
    std::vector<int32_t> tiles;  // still to send, in order
    size_t next = 0;
    TileOptions options;
  };

  struct Subscription {
    uint64_t request_id = 0;
    std::set<int32_t> tiles;  // selected
    TileOptions options;
  };

  // A program being applied: one batch per processing turn, each answered
  // by its Ack, then a ProgramDone.
  struct ProgramJob {
    uint64_t request_id = 0;
    std::shared_ptr<const InterpretedProgram> program;
    uint64_t first_seq = 0;
    bool report_cuts = false;
    size_t next = 0;  // the next batch
  };

  bool HasWorkLocked() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    return !in_.empty() || job_.has_value() || program_.has_value() ||
           !pending_push_.empty();
  }
  // Whether a processing turn would make progress: a tile job or pushes
  // need room in out_ (a request is handled regardless: it yields at most
  // one response, or becomes a job).
  bool CanProcessLocked() const ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    const bool room = out_.size() < kMaxOut;
    if (job_.has_value() || program_.has_value()) return room;
    if (!in_.empty()) return true;
    return !pending_push_.empty() && room;
  }

  Act NextLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_) {
    Act act;
    if (finished_) return act;
    if (cancelled_) {
      if (!writing_ && !processing_ && !read_starting_) {
        finished_ = true;
        act.finish = grpc::Status::CANCELLED;
      }
      return act;
    }
    if (!writing_ && !out_.empty()) {
      writing_ = true;
      act.write = &out_.front();
    }
    const bool failing = fatal_.has_value();
    if (!processing_ && !failing && CanProcessLocked()) {
      processing_ = true;
      refs_.Add();
      act.process = true;
    }
    if (!read_pending_ && !reads_done_ && !failing && in_.size() < kMaxIn &&
        out_.size() < kMaxOut) {
      read_pending_ = true;
      read_starting_ = true;
      act.read = true;
    }
    const bool drained =
        !writing_ && !processing_ && !read_starting_ && out_.empty();
    if (drained && failing) {
      finished_ = true;
      act.finish = *fatal_;
    } else if (drained && reads_done_ && !HasWorkLocked()) {
      finished_ = true;
      act.finish = read_error_.value_or(grpc::Status::OK);
    }
    return act;
  }

  // Carries out what NextLocked decided. A read, a write or a Process it
  // decided keeps every other thread from finishing the stream (read_starting_,
  // writing_, processing_) until this thread has started it: gRPC's call
  // must not end under a read or write not yet started. Once the read has
  // started, what NextLocked decides next is done here too (the stream may
  // be able to finish now).
  void Do(Act act) {
    for (;;) {
      if (act.read) StartRead(&req_);
      if (act.write != nullptr) {
        // One write in flight: the previous one is done with the buffer.
        write_buf_.Clear();
        bool own = false;
        grpc::SerializationTraits<pb::SimulateResponse>::Serialize(
            *act.write, &write_buf_, &own);
        StartWrite(&write_buf_);
      }
      if (act.finish.has_value()) Finish(*act.finish);
      if (act.process) executor_->Schedule([this] { Process(); });
      if (!act.read) return;
      absl::MutexLock l(&mu_);
      read_starting_ = false;
      act = NextLocked();
    }
  }

  // One processing turn on the executor: a slice of the tile job, one
  // request, or pending pushes, then decides what comes next.
  void Process() {
    std::vector<pb::SimulateResponse> responses;
    std::optional<pb::SimulateRequest> req;
    std::vector<int32_t> job_tiles;
    std::optional<uint64_t> job_done;  // the job's last slice: its request
    int64_t job_count = 0;
    std::vector<int32_t> push_tiles;
    TileOptions job_options, push_options;
    std::optional<ProgramJob> program_step;  // the batch `next` of it
    {
      absl::MutexLock l(&mu_);
      const size_t room = out_.size() < kMaxOut ? kMaxOut - out_.size() : 0;
      // While a program runs, its batches and the pushes they cause take
      // turns (as streamed batches and pushes would).
      const bool push_now = program_.has_value() && push_turn_ &&
                            !pending_push_.empty() && sub_.has_value();
      if (program_.has_value() && !push_now) {
        // Its batches come before anything after it on the stream.
        program_step = *program_;
        push_turn_ = true;
        if (++program_->next == program_->program->batches.size()) {
          program_.reset();
        }
      } else if (job_.has_value()) {
        // Tiles of a request come before anything after it.
        const size_t n = std::min(room, job_->tiles.size() - job_->next);
        job_tiles.assign(job_->tiles.begin() + job_->next,
                         job_->tiles.begin() + job_->next + n);
        job_->next += n;
        job_options = job_->options;
        if (job_->next == job_->tiles.size()) {
          job_done = job_->options.request_id;
          job_count = static_cast<int64_t>(job_->tiles.size());
          job_.reset();
        }
      } else if (!push_now && !in_.empty()) {
        req = std::move(in_.front());
        in_.pop_front();
      } else if (!pending_push_.empty() && sub_.has_value()) {
        push_turn_ = false;
        for (auto it = pending_push_.begin();
             it != pending_push_.end() && push_tiles.size() < room;) {
          push_tiles.push_back(*it);
          it = pending_push_.erase(it);
        }
        push_options = sub_->options;
      } else {
        pending_push_.clear();
      }
    }
    if (!job_tiles.empty() || !push_tiles.empty()) {
      session_->Read([&](const Workpiece& wp) {
        // The messages first, then pointers into them (the vector moves).
        const size_t first = responses.size();
        responses.resize(first + job_tiles.size() + push_tiles.size());
        std::vector<pb::Tile*> job_out, push_out;
        for (size_t k = 0; k < job_tiles.size(); ++k) {
          job_out.push_back(responses[first + k].mutable_tile());
        }
        for (size_t k = 0; k < push_tiles.size(); ++k) {
          push_out.push_back(
              responses[first + job_tiles.size() + k].mutable_tile());
        }
        FillTiles(wp, job_tiles, job_options, job_out);
        FillTiles(wp, push_tiles, push_options, push_out);
        return 0;
      });
    }
    if (job_done.has_value()) {
      pb::TilesDone* done = responses.emplace_back().mutable_tiles_done();
      done->set_request_id(*job_done);
      done->set_tiles(job_count);
    }
    if (req.has_value()) Handle(*req, &responses);
    if (program_step.has_value()) ProgramStep(*program_step, &responses);
    // Never a message over the limit: the transport would end the stream.
    const int64_t limit = registry_->limits().max_message_bytes;
    for (pb::SimulateResponse& r : responses) {
      absl::Status fits =
          FitsMessage(r.ByteSizeLong(), limit, "the answer to this request");
      if (!fits.ok()) {
        const auto [id, kind] = RequestOf(r);
        r.Clear();
        pb::RequestError* e = r.mutable_error();
        e->set_request_id(id);
        e->set_kind(kind);
        e->set_code(static_cast<int32_t>(fits.code()));
        e->set_message(std::string(fits.message()));
      }
    }
    Act act;
    {
      absl::MutexLock l(&mu_);
      for (size_t k = 0; k < responses.size(); ++k) {
        out_.push_back(std::move(responses[k]));
      }
      processing_ = false;
      act = NextLocked();
    }
    Do(act);
    if (refs_.Release()) delete this;
  }

  static void Error(uint64_t id, const absl::Status& s,
                    std::vector<pb::SimulateResponse>* out) {
    pb::RequestError* e = out->emplace_back().mutable_error();
    e->set_request_id(id);
    e->set_code(static_cast<int32_t>(s.code()));
    e->set_message(std::string(s.message()));
  }

  // Answers one request; its errors say what kind of request it was.
  void Handle(const pb::SimulateRequest& req,
              std::vector<pb::SimulateResponse>* out) {
    const size_t first = out->size();
    Dispatch(req, out);
    for (size_t k = first; k < out->size(); ++k) {
      if ((*out)[k].has_error()) {
        (*out)[k].mutable_error()->set_kind(KindOf(req.request_case()));
      }
    }
  }

  void Dispatch(const pb::SimulateRequest& req,
                std::vector<pb::SimulateResponse>* out) {
    switch (req.request_case()) {
      case pb::SimulateRequest::kMoves:
        return HandleMoves(req.moves(), out);
      case pb::SimulateRequest::kTiles:
        return HandleTiles(req.tiles(), out);
      case pb::SimulateRequest::kStats: {
        const pb::StatsRequest& r = req.stats();
        if (absl::Status fits =
                MapFits(r.map_cols(), r.map_rows(),
                        registry_->limits().max_message_bytes);
            !fits.ok()) {
          return Error(r.request_id(), fits, out);
        }
        auto stats = session_->Read([&](const Workpiece& wp) {
          return ComputeStats(wp, r.has_region() ? &r.region() : nullptr,
                              r.samples_per_edge(), r.map_cols(),
                              r.map_rows());
        });
        if (!stats.ok()) return Error(r.request_id(), stats.status(), out);
        stats->set_request_id(r.request_id());
        *out->emplace_back().mutable_stats() = *std::move(stats);
        return;
      }
      case pb::SimulateRequest::kMarks: {
        // One message holds them all: the search stops once they are more
        // than the message limit (Process would refuse the answer), rather
        // than finding and holding the rest. So a MarksRequest holds at most
        // about one message of marks; GetCuttingMarks serves any number.
        const pb::MarksRequest& r = req.marks();
        const int64_t limit = registry_->limits().max_message_bytes;
        pb::Polylines answer;
        answer.set_request_id(r.request_id());
        // The answer's size so far (Polylines.polylines entries: a tag byte,
        // the length, the polyline): less than the whole SimulateResponse.
        size_t bytes = 0;
        absl::Status st = session_->Read([&](const Workpiece& wp) {
          return StreamMarks(
              wp, r.has_region() ? &r.region() : nullptr,
              r.screening_threshold(), r.min_angle_deg(),
              [&](pb::Polyline line) {
                line.set_request_id(r.request_id());
                const size_t n = line.ByteSizeLong();
                bytes += 1 + CodedOutputStream::VarintSize64(n) + n;
                if (static_cast<int64_t>(bytes) > limit) {
                  return MarksAnswerOverLimit(bytes, limit);
                }
                *answer.add_polylines() = std::move(line);
                return absl::OkStatus();
              },
              [] { return absl::OkStatus(); });
        });
        if (!st.ok()) return Error(r.request_id(), st, out);
        *out->emplace_back().mutable_polylines() = std::move(answer);
        return;
      }
      case pb::SimulateRequest::kSubscribe:
        return HandleSubscribe(req.subscribe(), out);
      case pb::SimulateRequest::kProgram:
        return HandleProgram(req.program(), out);
      case pb::SimulateRequest::kDeviation: {
        const pb::DeviationRequest& r = req.deviation();
        auto d = ComputeDeviation(*session_, r,
                                  registry_->limits().max_message_bytes);
        if (!d.ok()) return Error(r.request_id(), d.status(), out);
        d->set_request_id(r.request_id());
        *out->emplace_back().mutable_deviation() = *std::move(d);
        return;
      }
      case pb::SimulateRequest::REQUEST_NOT_SET:
        break;
    }
    Error(0, absl::InvalidArgumentError("empty SimulateRequest"), out);
  }

  void HandleMoves(const pb::MoveBatch& b,
                   std::vector<pb::SimulateResponse>* out) {
    BatchOptions options;
    options.reposition = b.reposition();
    options.rapid = b.rapid();
    options.report_cuts = b.report_cuts();
    auto arcs = ArcsFromProto(b);
    if (!arcs.ok()) return Error(b.seq(), arcs.status(), out);
    options.arcs = *arcs;
    auto r = session_->ApplyBatch(
        b.seq(), b.tool_id(), std::span<const double>(b.xyz().data(), b.xyz_size()),
        registry_->limits().max_batch_points, options);
    if (!r.ok()) {
      // A gap, or another batch under an acknowledged seq: what follows on
      // this stream continues a history the session does not have.
      if (r.status().code() == absl::StatusCode::kFailedPrecondition ||
          r.status().code() == absl::StatusCode::kAlreadyExists) {
        spdlog::warn("session {}: {}", session_->id(),
                     std::string(r.status().message()));
        absl::MutexLock l(&mu_);
        fatal_ = ToGrpcStatus(r.status());
        return;
      }
      return Error(b.seq(), r.status(), out);
    }
    pb::Ack* ack = out->emplace_back().mutable_ack();
    ack->set_seq(r->seq);
    ack->set_moves_applied(r->moves_applied);
    ack->set_node_lowerings(r->node_lowerings);
    ack->set_version(r->version);
    ack->set_duplicate(r->duplicate);
    ack->mutable_removed_mm3()->Assign(r->removed_mm3.begin(),
                                       r->removed_mm3.end());
    for (const SafetyFinding& f : r->safety) {
      pb::SafetyEvent* e = ack->add_safety();
      e->set_kind(static_cast<pb::SafetyEvent::Kind>(f.kind));
      e->set_move_index(f.move_index);
      e->set_move_id(f.move_id);
      e->set_x(f.x);
      e->set_y(f.y);
      e->set_z(f.z);
      e->set_depth(f.depth);
      e->set_volume_mm3(f.volume_mm3);
    }
    const int32_t tiles_x = session_->spec().stock.nx / kTileSize + 1;
    for (const auto& [t, v] : r->changed_tiles) {
      pb::TileVersion* tv = ack->add_changed_tiles();
      tv->set_tx(t % tiles_x);
      tv->set_ty(t / tiles_x);
      tv->set_version(v);
    }
    absl::MutexLock l(&mu_);
    if (sub_.has_value()) {
      for (const auto& [t, v] : r->changed_tiles) {
        if (sub_->tiles.count(t)) pending_push_.insert(t);
      }
    }
  }

  // A chunk of a program: held until the last, which is interpreted (here,
  // on the executor) and becomes the stream's ProgramJob.
  void HandleProgram(const pb::ProgramChunk& c,
                     std::vector<pb::SimulateResponse>* out) {
    pb::ProgramChunk whole;
    if (c.resume()) {
      auto saved = session_->SavedProgram();
      if (!saved.ok()) return Error(c.request_id(), saved.status(), out);
      if (!saved->has_value() || !whole.ParseFromString(**saved)) {
        return Error(c.request_id(),
                     absl::FailedPreconditionError(
                         "program.resume: the session has no journaled "
                         "program (a memory-only server keeps none): send "
                         "the program again"),
                     out);
      }
      // Not an older program journaled before the one meant was.
      const uint64_t want = c.options().first_seq();
      if (want != 0 && want != whole.options().first_seq()) {
        return Error(c.request_id(),
                     absl::FailedPreconditionError(absl::StrCat(
                         "program.resume: the journaled program starts at seq ",
                         whole.options().first_seq(), ", not ", want,
                         ": send the program again")),
                     out);
      }
    } else {
      if (c.offset() == 0) upload_.clear();
      if (c.offset() != upload_.size()) {
        return Error(c.request_id(),
                     absl::FailedPreconditionError(absl::StrCat(
                         "program upload: a chunk at offset ", c.offset(),
                         "; this stream holds ", upload_.size(),
                         " bytes of the upload (send from there, or from 0 "
                         "to start again)")),
                     out);
      }
      if (upload_.size() + c.data().size() >
          static_cast<uint64_t>(kMaxProgramBytes)) {
        upload_.clear();
        upload_.shrink_to_fit();
        return Error(c.request_id(),
                     absl::ResourceExhaustedError(absl::StrCat(
                         "program upload: more than ", kMaxProgramBytes,
                         " bytes; the upload is dropped")),
                     out);
      }
      upload_.append(c.data());
      if (!c.last()) return;  // answered by the last chunk
      whole.set_data(std::move(upload_));
      upload_ = std::string();
      *whole.mutable_options() = c.options();
    }
    const absl::Time start = absl::Now();
    auto program = InterpretProgram(whole.data(), whole.options(),
                                    session_->spec(),
                                    registry_->limits().max_batch_points);
    if (!program.ok()) return Error(c.request_id(), program.status(), out);
    uint64_t first_seq = whole.options().first_seq();
    if (first_seq == 0) first_seq = session_->State().last_seq + 1;
    spdlog::info("session {}: program {} ({} bytes, {} moves in {} batches "
                 "from seq {}) interpreted in {:.3f} s",
                 session_->id(), program->name, whole.data().size(),
                 program->moves, program->batches.size(), first_seq,
                 absl::ToDoubleSeconds(absl::Now() - start));
    if (!c.resume()) {
      // Durable before its first batch: a restart can resume it.
      whole.set_last(true);
      whole.mutable_options()->set_first_seq(first_seq);
      if (absl::Status s = session_->SaveProgram(whole.SerializeAsString());
          !s.ok()) {
        return Error(c.request_id(), s, out);
      }
    }
    ProgramJob job;
    job.request_id = c.request_id();
    job.program =
        std::make_shared<const InterpretedProgram>(*std::move(program));
    job.first_seq = first_seq;
    job.report_cuts = whole.options().report_cuts();
    if (job.program->batches.empty()) return ProgramFinished(job, out);
    absl::MutexLock l(&mu_);
    program_ = std::move(job);
  }

  // Applies batch job.next of a program as a MoveBatch would be.
  void ProgramStep(const ProgramJob& job,
                   std::vector<pb::SimulateResponse>* out) {
    const InterpretedProgram& p = *job.program;
    const ProgramBatch& b = p.batches[job.next];
    pb::MoveBatch batch;
    batch.set_seq(job.first_seq + job.next);
    batch.set_tool_id(b.tool_id);
    batch.set_rapid(b.rapid);
    batch.set_reposition(b.reposition);
    batch.set_report_cuts(job.report_cuts);
    batch.mutable_xyz()->Reserve(3 * (b.end - b.begin));
    for (int64_t k = b.begin; k < b.end; ++k) {
      const Vec3& v = p.path.points()[k].position;
      batch.add_xyz(v.x);
      batch.add_xyz(v.y);
      batch.add_xyz(v.z);
    }
    const size_t first = out->size();
    HandleMoves(batch, out);
    bool failed = false;
    for (size_t k = first; k < out->size(); ++k) {
      if (!(*out)[k].has_error()) continue;
      // The program's error: the rest of it is not applied.
      pb::RequestError* e = (*out)[k].mutable_error();
      e->set_message(absl::StrCat(p.name, ": batch ", batch.seq(), ": ",
                                  e->message()));
      e->set_request_id(job.request_id);
      e->set_kind(pb::REQUEST_KIND_PROGRAM);
      failed = true;
    }
    bool fatal;
    {
      absl::MutexLock l(&mu_);
      fatal = fatal_.has_value();
      if (failed || fatal) program_.reset();
    }
    if (!failed && !fatal && job.next + 1 == p.batches.size()) {
      ProgramFinished(job, out);
    }
  }

  static void ProgramFinished(const ProgramJob& job,
                              std::vector<pb::SimulateResponse>* out) {
    const InterpretedProgram& p = *job.program;
    pb::ProgramDone* d = out->emplace_back().mutable_program_done();
    d->set_request_id(job.request_id);
    d->set_first_seq(job.first_seq);
    d->set_last_seq(job.first_seq + p.batches.size() - 1);
    d->set_moves(p.moves);
    d->set_points(p.path.point_count());
    d->set_source_lines(p.path.source_lines());
    d->set_blocks_executed(p.path.blocks_executed());
    for (const std::string& w : p.warnings) d->add_warnings(w);
  }

  void HandleTiles(const pb::TileRequest& r,
                   std::vector<pb::SimulateResponse>* out) {
    auto job = session_->Read([&](const Workpiece& wp) -> absl::StatusOr<TileJob> {
      auto options = TileOptionsFrom(wp, r.request_id(), r.precision(),
                                     r.include_derivatives(),
                                     r.include_owners());
      if (!options.ok()) return options.status();
      auto tiles = SelectTiles(wp, r.has_selection() ? &r.selection() : nullptr);
      if (!tiles.ok()) return tiles.status();
      TileJob job;
      job.options = *options;
      for (int32_t t : *tiles) {
        if (wp.TileVersion(t) > r.since_version() || r.since_version() == 0) {
          job.tiles.push_back(t);
        }
      }
      return job;
    });
    if (!job.ok()) return Error(r.request_id(), job.status(), out);
    if (job->tiles.empty()) {
      out->emplace_back().mutable_tiles_done()->set_request_id(r.request_id());
      return;
    }
    absl::MutexLock l(&mu_);
    job_ = *std::move(job);
  }

  void HandleSubscribe(const pb::Subscribe& r,
                       std::vector<pb::SimulateResponse>* out) {
    if (r.cancel()) {
      absl::MutexLock l(&mu_);
      sub_.reset();
      pending_push_.clear();
      return;
    }
    auto sub = session_->Read(
        [&](const Workpiece& wp) -> absl::StatusOr<Subscription> {
          auto options = TileOptionsFrom(wp, r.request_id(), r.precision(),
                                         r.include_derivatives(),
                                         r.include_owners());
          if (!options.ok()) return options.status();
          auto tiles =
              SelectTiles(wp, r.has_selection() ? &r.selection() : nullptr);
          if (!tiles.ok()) return tiles.status();
          Subscription s;
          s.request_id = r.request_id();
          s.options = *options;
          s.tiles.insert(tiles->begin(), tiles->end());
          return s;
        });
    if (!sub.ok()) return Error(r.request_id(), sub.status(), out);
    absl::MutexLock l(&mu_);
    sub_ = *std::move(sub);
    pending_push_.clear();
  }

  Registry* const registry_;
  Executor* const executor_;
  std::shared_ptr<Session> session_;
  SwarfService::StreamCounter* streams_ = nullptr;  // counted while open
  std::string client_;

  absl::Mutex mu_;
  grpc::ByteBuffer req_;        // target of the read in flight
  grpc::ByteBuffer write_buf_;  // the write in flight, serialized
  std::deque<pb::SimulateRequest> in_ ABSL_GUARDED_BY(mu_);
  std::deque<pb::SimulateResponse> out_ ABSL_GUARDED_BY(mu_);
  std::optional<TileJob> job_ ABSL_GUARDED_BY(mu_);
  std::optional<ProgramJob> program_ ABSL_GUARDED_BY(mu_);
  bool push_turn_ ABSL_GUARDED_BY(mu_) = false;  // see Process
  // A program upload in progress: only touched by the processing turn
  // (processing_: one at a time), so not under mu_.
  std::string upload_;
  std::optional<Subscription> sub_ ABSL_GUARDED_BY(mu_);
  // Subscribed tiles changed since last pushed: one entry per tile, read at
  // its latest version when pushed (coalescing).
  std::set<int32_t> pending_push_ ABSL_GUARDED_BY(mu_);
  std::optional<grpc::Status> fatal_ ABSL_GUARDED_BY(mu_);
  // Requests read, and why reading stopped early (a message that did not
  // parse): the stream's status once the requests before are answered.
  uint64_t reads_ ABSL_GUARDED_BY(mu_) = 0;
  std::optional<grpc::Status> read_error_ ABSL_GUARDED_BY(mu_);
  bool read_pending_ ABSL_GUARDED_BY(mu_) = false;
  // A read NextLocked decided on, not started yet (Do).
  bool read_starting_ ABSL_GUARDED_BY(mu_) = false;
  bool reads_done_ ABSL_GUARDED_BY(mu_) = false;
  bool writing_ ABSL_GUARDED_BY(mu_) = false;
  bool processing_ ABSL_GUARDED_BY(mu_) = false;
  bool cancelled_ ABSL_GUARDED_BY(mu_) = false;
  bool finished_ ABSL_GUARDED_BY(mu_) = false;
  ReactorRefs refs_;  // gRPC's, and each Process task's
};

}  // namespace

bool SwarfService::StreamCounter::Acquire(const std::string& key,
                                         int32_t limit) {
  absl::MutexLock l(&mu_);
  int32_t& n = open_[key];
  if (n >= limit) return false;
  ++n;
  return true;
}

void SwarfService::StreamCounter::Release(const std::string& key) {
  absl::MutexLock l(&mu_);
  if (--open_[key] <= 0) open_.erase(key);
}

// A unary call that waited or ran this long is logged (seconds).
constexpr double kSlowCallSeconds = 2.0;

grpc::ServerUnaryReactor* SwarfService::Unary(
    grpc::CallbackServerContext* ctx, const char* method,
    std::function<absl::Status()> work) {
  ctx->AddInitialMetadata(kReplicaMetadata, replica_);
  grpc::ServerUnaryReactor* reactor = ctx->DefaultReactor();
  const absl::Time queued = absl::Now();
  executor_->Schedule([reactor, ctx, method, queued, work = std::move(work)] {
    if (ctx->IsCancelled()) {
      spdlog::warn("{}: cancelled after {:.3f} s in the queue", method,
                   absl::ToDoubleSeconds(absl::Now() - queued));
      reactor->Finish(grpc::Status::CANCELLED);
      return;
    }
    const absl::Time started = absl::Now();
    const absl::Status status = work();
    const double wait = absl::ToDoubleSeconds(started - queued);
    const double run = absl::ToDoubleSeconds(absl::Now() - started);
    // What a client that hit its deadline needs from the log: whether the
    // call waited for a worker or ran long (a lock, a large request).
    if (wait + run >= kSlowCallSeconds) {
      spdlog::info("{}: slow call, {:.3f} s queued and {:.3f} s running: {}",
                   method, wait, run, status.ToString());
    }
    reactor->Finish(ToGrpcStatus(status));
  });
  return reactor;
}

grpc::ServerUnaryReactor* SwarfService::CreateSession(
    grpc::CallbackServerContext* ctx, const pb::CreateSessionRequest* req,
    pb::Session* resp) {
  return Unary(ctx, "CreateSession", [=, this]() -> absl::Status {
    auto principal = PrincipalOf(tokens_, ctx);
    if (!principal.ok()) return principal.status();
    pb::CreateSessionRequest r = *req;
    if (r.session_id().empty()) {
      // A client that chose its id for routing may send it only as metadata.
      auto id = SessionIdOf(ctx, "");
      if (id.ok()) r.set_session_id(*id);
    } else if (auto id = SessionIdOf(ctx, r.session_id()); !id.ok()) {
      return id.status();
    }
    auto spec = SpecFromRequest(r);
    if (!spec.ok()) return spec.status();
    spec->owner = *principal;
    auto session = registry_->Create(*std::move(spec));
    if (!session.ok()) return session.status();
    FillSession(**session, replica_, resp);
    spdlog::info("session {}: created ({}x{} elements, {})", (*session)->id(),
                 resp->nx(), resp->ny(),
                 pb::Scheme_Name(resp->scheme()));
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* SwarfService::GetSession(
    grpc::CallbackServerContext* ctx, const pb::GetSessionRequest* req,
    pb::Session* resp) {
  return Unary(ctx, "GetSession", [=, this]() -> absl::Status {
    auto session = SessionOf(registry_, tokens_, ctx, req->session_id());
    if (!session.ok()) return session.status();
    FillSession(**session, replica_, resp);
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* SwarfService::ListSessions(
    grpc::CallbackServerContext* ctx, const pb::ListSessionsRequest*,
    pb::ListSessionsResponse* resp) {
  return Unary(ctx, "ListSessions", [=, this]() -> absl::Status {
    auto principal = PrincipalOf(tokens_, ctx);
    if (!principal.ok()) return principal.status();
    for (const auto& s : registry_->List(*principal)) {
      FillSession(*s, replica_, resp->add_sessions());
    }
    resp->set_server_peak_memory_bytes(PeakMemoryBytes());
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* SwarfService::DeleteSession(
    grpc::CallbackServerContext* ctx, const pb::DeleteSessionRequest* req,
    pb::DeleteSessionResponse*) {
  return Unary(ctx, "DeleteSession", [=, this]() -> absl::Status {
    auto principal = PrincipalOf(tokens_, ctx);
    if (!principal.ok()) return principal.status();
    auto id = SessionIdOf(ctx, req->session_id());
    if (!id.ok()) return id.status();
    absl::Status s = registry_->Delete(*id, *principal);
    if (s.ok()) spdlog::info("session {}: deleted", *id);
    return s;
  });
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>*
SwarfService::Simulate(grpc::CallbackServerContext* ctx) {
  return new SimulateReactor(ctx, registry_, executor_, tokens_, &streams_,
                             trust_, replica_);
}

namespace {

// Tile.deviation: each node's height less the design's envelope there.
void AddDeviation(const design::TopEnvelope& env, pb::Tile* t) {
  const int64_t n = int64_t{t->nx()} * t->ny();
  t->mutable_deviation()->Resize(static_cast<int>(n), 0.0f);
  for (int32_t j = 0; j < t->ny(); ++j) {
    for (int32_t i = 0; i < t->nx(); ++i) {
      const int64_t k = int64_t{j} * t->nx() + i;
      const double z = t->heights_d_size() == n ? t->heights_d(k)
                                                : double(t->heights_f(k));
      t->set_deviation(k, static_cast<float>(
                              z - env.AtNode(t->i0() + i, t->j0() + j)));
    }
  }
}

}  // namespace

grpc::ServerWriteReactor<pb::Tile>* SwarfService::GetTiles(
    grpc::CallbackServerContext* ctx, const pb::GetTilesRequest* req) {
  struct State {
    std::shared_ptr<Session> session;
    std::vector<int32_t> tiles;
    size_t next = 0;
    TileOptions options;
    bool started = false;
    std::shared_ptr<const design::PlacedDesign> design;  // include_deviation
  };
  auto state = std::make_shared<State>();
  Registry* registry = registry_;
  TokenStore* tokens = tokens_;
  return new ChunkedWriter<pb::Tile>(
      ctx, executor_, replica_,
      [=](std::deque<pb::Tile>* out) -> absl::StatusOr<bool> {
        if (!state->started) {
          state->started = true;
          auto session = SessionOf(registry, tokens, ctx, req->session_id());
          if (!session.ok()) return session.status();
          state->session = *session;
          if (req->include_deviation()) {
            state->design = state->session->design();
            if (state->design == nullptr) {
              return absl::FailedPreconditionError(
                  "include_deviation: the session has no design (SetDesign "
                  "first)");
            }
          }
          absl::Status st = state->session->Read([&](const Workpiece& wp) {
            auto options = TileOptionsFrom(wp, 0, req->precision(),
                                           req->include_derivatives(),
                                           req->include_owners());
            if (!options.ok()) return options.status();
            state->options = *options;
            auto tiles = SelectTiles(
                wp, req->has_selection() ? &req->selection() : nullptr);
            if (!tiles.ok()) return tiles.status();
            for (int32_t t : *tiles) {
              if (req->since_version() == 0 ||
                  wp.TileVersion(t) > req->since_version()) {
                state->tiles.push_back(t);
              }
            }
            return absl::OkStatus();
          });
          if (!st.ok()) return st;
        }
        constexpr size_t kChunk = 16;
        const size_t end = std::min(state->tiles.size(), state->next + kChunk);
        state->session->Read([&](const Workpiece& wp) {
          std::vector<pb::Tile*> chunk;  // a deque's elements stay put
          for (size_t k = state->next; k < end; ++k) {
            chunk.push_back(&out->emplace_back());
          }
          FillTiles(wp,
                    std::span<const int32_t>(state->tiles.data() + state->next,
                                             chunk.size()),
                    state->options, chunk);
          if (state->design != nullptr) {
            for (pb::Tile* t : chunk) AddDeviation(state->design->envelope(), t);
          }
          state->next = end;
          return 0;
        });
        return state->next < state->tiles.size();
      });
}

grpc::ServerUnaryReactor* SwarfService::GetErrorStats(
    grpc::CallbackServerContext* ctx, const pb::GetErrorStatsRequest* req,
    pb::ErrorStats* resp) {
  return Unary(ctx, "GetErrorStats", [=, this]() -> absl::Status {
    auto session = SessionOf(registry_, tokens_, ctx, req->session_id());
    if (!session.ok()) return session.status();
    const int64_t limit = registry_->limits().max_message_bytes;
    if (absl::Status fits = MapFits(req->map_cols(), req->map_rows(), limit);
        !fits.ok()) {
      return fits;
    }
    auto stats = (*session)->Read([&](const Workpiece& wp) {
      return ComputeStats(wp, req->has_region() ? &req->region() : nullptr,
                          req->samples_per_edge(), req->map_cols(),
                          req->map_rows());
    });
    if (!stats.ok()) return stats.status();
    if (absl::Status fits = FitsMessage(stats->ByteSizeLong(), limit,
                                        "the error statistics");
        !fits.ok()) {
      return fits;
    }
    *resp = *std::move(stats);
    return absl::OkStatus();
  });
}

grpc::ServerWriteReactor<pb::Polyline>* SwarfService::GetCuttingMarks(
    grpc::CallbackServerContext* ctx, const pb::GetCuttingMarksRequest* req) {
  return new MarksWriter(ctx, registry_, tokens_, executor_, &marks_, replica_,
                         *req);
}

grpc::ServerUnaryReactor* SwarfService::Probe(
    grpc::CallbackServerContext* ctx, const pb::ProbeRequest* req,
    pb::ProbeResponse* resp) {
  return Unary(ctx, "Probe", [=, this]() -> absl::Status {
    auto session = SessionOf(registry_, tokens_, ctx, req->session_id());
    if (!session.ok()) return session.status();
    auto probe = (*session)->Read(
        [&](const Workpiece& wp) { return ComputeProbe(wp, *req); });
    if (!probe.ok()) return probe.status();
    if (absl::Status fits =
            FitsMessage(probe->ByteSizeLong(),
                        registry_->limits().max_message_bytes,
                        absl::StrCat("the answer for ", req->xy_size() / 2,
                                     " points"));
        !fits.ok()) {
      return fits;
    }
    *resp = *std::move(probe);
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* SwarfService::SetDesign(
    grpc::CallbackServerContext* ctx, const pb::SetDesignRequest* req,
    pb::DesignInfo* resp) {
  return Unary(ctx, "SetDesign", [=, this]() -> absl::Status {
    auto session = SessionOf(registry_, tokens_, ctx, req->session_id());
    if (!session.ok()) return session.status();
    DesignChunk c;
    c.offset = req->offset();
    c.data = std::string_view(req->data().data(), req->data().size());
    c.last = req->last();
    c.scale = req->scale() == 0 ? 1.0 : req->scale();
    c.translation = {req->translation().x(), req->translation().y(),
                     req->translation().z()};
    if (!req->name().empty()) c.name = req->name();
    c.max_bytes = registry_->limits().max_design_bytes;
    auto state = (*session)->AddDesignChunk(c);
    if (!state.ok()) return state.status();
    resp->set_received(state->received);
    if (state->placed != nullptr) {
      const design::PlacedDesign& d = *state->placed;
      resp->set_placed(true);
      resp->set_triangles(static_cast<int64_t>(d.mesh().triangles.size()));
      resp->set_covered_nodes(d.envelope().covered_nodes());
      resp->mutable_min()->set_x(d.mesh().x.lo);
      resp->mutable_min()->set_y(d.mesh().y.lo);
      resp->mutable_min()->set_z(d.mesh().z.lo);
      resp->mutable_max()->set_x(d.mesh().x.hi);
      resp->mutable_max()->set_y(d.mesh().y.hi);
      resp->mutable_max()->set_z(d.mesh().z.hi);
      resp->set_name(d.name());
    }
    return absl::OkStatus();
  });
}

grpc::ServerUnaryReactor* SwarfService::GetDeviation(
    grpc::CallbackServerContext* ctx, const pb::GetDeviationRequest* req,
    pb::Deviation* resp) {
  return Unary(ctx, "GetDeviation", [=, this]() -> absl::Status {
    auto session = SessionOf(registry_, tokens_, ctx, req->session_id());
    if (!session.ok()) return session.status();
    auto d = ComputeDeviation(**session, req->options(),
                              registry_->limits().max_message_bytes);
    if (!d.ok()) return d.status();
    *resp = *std::move(d);
    return absl::OkStatus();
  });
}

}  // namespace swarf::server
