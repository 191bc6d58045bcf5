#include "server/registry.h"

#include <algorithm>
#include <filesystem>
#include <random>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "spdlog/spdlog.h"

namespace swarf::server {
namespace {

std::string NewId() {
  static constexpr char kChars[] = "0123456789abcdefghijklmnopqrstuvwxyz";
  thread_local std::mt19937_64 rng(std::random_device{}());
  std::string id = "s-";
  for (int k = 0; k < 16; ++k) id += kChars[rng() % 36];
  return id;
}

// Bytes as MiB with one decimal, for messages.
std::string MiB(int64_t bytes) {
  return absl::StrFormat("%.1f", static_cast<double>(bytes) / (1 << 20));
}

}  // namespace

absl::Status Registry::ValidateId(const std::string& id) {
  if (id.empty() || id.size() > 64) {
    return absl::InvalidArgumentError(
        absl::StrCat("session_id must be 1-64 characters, got ", id.size()));
  }
  for (char c : id) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                    (c >= '0' && c <= '9') || c == '_' || c == '-';
    if (!ok) {
      return absl::InvalidArgumentError(
          "session_id may only contain A-Z, a-z, 0-9, '_' and '-'");
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::shared_ptr<Session>> Registry::Create(SessionSpec spec) {
  if (spec.id.empty()) {
    spec.id = NewId();
  } else if (absl::Status s = ValidateId(spec.id); !s.ok()) {
    return s;
  }
  // Bad input is reported as such even on a full server. A grid over the
  // byte limits is RESOURCE_EXHAUSTED even where it is also over the core's
  // node limit (which ValidateSpec calls bad input): the rest is validated
  // first, with each element count that is valid on its own taken as 1.
  SessionSpec shape = spec;
  for (int32_t* n : {&shape.stock.nx, &shape.stock.ny}) {
    if (*n >= 1 && *n <= kMaxElementsPerAxis) *n = 1;
  }
  if (absl::Status s = Session::ValidateSpec(shape); !s.ok()) return s;
  // Both counts are within kMaxElementsPerAxis here: no overflow.
  const int64_t bytes = Session::EstimateMemoryBytes(spec.stock, spec.scheme);
  if (limits_.max_session_memory_bytes > 0 &&
      bytes > limits_.max_session_memory_bytes) {
    return absl::ResourceExhaustedError(
        absl::StrCat("the session needs ", bytes, " bytes (", MiB(bytes),
                     " MiB for ", spec.stock.nx, " x ", spec.stock.ny,
                     " elements, every tile cut); this server allows ",
                     limits_.max_session_memory_bytes, " bytes (",
                     MiB(limits_.max_session_memory_bytes),
                     " MiB) per session (--max_session_memory_mb)"));
  }
  if (bytes > limits_.max_total_memory_bytes) {
    // Never fits: named as such even past the core's node limit.
    absl::MutexLock l(&mu_);
    return FitsTotalLocked(bytes, spec.stock);
  }
  if (absl::Status s = Session::ValidateSpec(spec); !s.ok()) return s;
  {
    absl::MutexLock l(&mu_);
    if (absl::Status s = AdmitLocked(spec.id, bytes, spec.stock); !s.ok())
      return s;
  }
  const std::string id = spec.id;
  // The journal first: a session that cannot be made durable is refused.
  absl::StatusOr<std::unique_ptr<Journal>> journal = std::unique_ptr<Journal>();
  if (!persistence_.data_dir.empty()) {
    journal = Journal::Create(JournalPath(id), Session::Definition(spec),
                              spec.owner, persistence_.sync);
  }
  absl::StatusOr<std::shared_ptr<Session>> session =
      journal.ok()
          ? Session::Create(std::move(spec), *std::move(journal), Snapshots(id))
          : absl::UnavailableError(journal.status().message());
  absl::MutexLock l(&mu_);
  if (!session.ok()) {
    sessions_.erase(id);
    reserved_bytes_ -= bytes;
    DeleteFiles(id);
    return session.status();
  }
  sessions_[id] = *session;
  return *session;
}

absl::Status Registry::AdmitLocked(const std::string& id, int64_t bytes,
                                   const StockSpec& stock) {
  if (auto it = sessions_.find(id); it != sessions_.end()) {
    return absl::AlreadyExistsError(
        it->second != nullptr
            ? absl::StrCat("session ", id, " already exists")
            : absl::StrCat("session ", id, " is being created or deleted"));
  }
  if (static_cast<int64_t>(sessions_.size()) >= limits_.max_sessions) {
    return absl::ResourceExhaustedError(absl::StrCat(
        "this server holds its limit of ", limits_.max_sessions, " sessions"));
  }
  if (absl::Status s = FitsTotalLocked(bytes, stock); !s.ok()) return s;
  reserved_bytes_ += bytes;
  // The id is taken while the session is created.
  sessions_[id] = nullptr;
  return absl::OkStatus();
}

absl::Status Registry::FitsTotalLocked(int64_t bytes,
                                       const StockSpec& stock) const {
  const int64_t left = limits_.max_total_memory_bytes - reserved_bytes_;
  if (bytes <= left) return absl::OkStatus();
  return absl::ResourceExhaustedError(absl::StrCat(
      "the session needs ", bytes, " bytes (", MiB(bytes), " MiB for ",
      stock.nx, " x ", stock.ny, " elements, every tile cut); this server has ",
      left, " bytes (", MiB(left), " MiB) left of the ",
      limits_.max_total_memory_bytes, " bytes (",
      MiB(limits_.max_total_memory_bytes),
      " MiB) all its sessions may take (--max_total_memory_mb)"));
}

std::string Registry::JournalPath(const std::string& id) const {
  return (std::filesystem::path(persistence_.data_dir) / (id + ".db")).string();
}

SnapshotPolicy Registry::Snapshots(const std::string& id) const {
  return {SnapshotPath(JournalPath(id)), persistence_.snapshot_every_moves};
}

void Registry::DeleteFiles(const std::string& id) const {
  if (persistence_.data_dir.empty()) return;
  Journal::DeleteFiles(JournalPath(id));
  DeleteSnapshot(SnapshotPath(JournalPath(id)));
}

int Registry::SnapshotAll() {
  std::vector<std::shared_ptr<Session>> all;
  {
    absl::MutexLock l(&mu_);
    for (const auto& [id, s] : sessions_) {
      if (s != nullptr) all.push_back(s);
    }
  }
  int written = 0;
  for (const auto& s : all) {
    const absl::StatusOr<bool> saved = s->SaveSnapshot();  // logged inside
    if (saved.ok() && *saved) ++written;
  }
  return written;
}

absl::StatusOr<int> Registry::RestoreAll() {
  if (persistence_.data_dir.empty()) return 0;
  std::error_code ec;
  std::filesystem::create_directories(persistence_.data_dir, ec);
  if (ec) {
    return absl::FailedPreconditionError(
        absl::StrCat("cannot create --data_dir ", persistence_.data_dir, ": ",
                     ec.message()));
  }
  std::vector<std::filesystem::path> files;
  for (const auto& e :
       std::filesystem::directory_iterator(persistence_.data_dir, ec)) {
    if (e.path().extension() == ".db") files.push_back(e.path());
  }
  std::sort(files.begin(), files.end());
  int restored = 0;
  for (const auto& f : files) {
    const std::string id = f.stem().string();
    if (!ValidateId(id).ok()) continue;
    auto session =
        Session::Restore(f.string(), persistence_.sync, Snapshots(id));
    if (!session.ok()) {
      spdlog::error("session {}: not restored: {}", id,
                    std::string(session.status().message()));
      continue;
    }
    const SessionSpec& spec = (*session)->spec();
    absl::MutexLock l(&mu_);
    absl::Status admitted = AdmitLocked(
        id, Session::EstimateMemoryBytes(spec.stock, spec.scheme), spec.stock);
    if (!admitted.ok()) {
      spdlog::error("session {}: not restored: {}", id,
                    std::string(admitted.message()));
      continue;
    }
    sessions_[id] = *session;
    ++restored;
    const SessionState st = (*session)->State();
    if ((*session)->recovery().empty()) {
      spdlog::info("session {}: restored ({} batches, {} moves)", id,
                   st.last_seq, st.moves_applied);
    } else {
      spdlog::warn("session {}: restored up to batch {}: {}", id, st.last_seq,
                   (*session)->recovery());
    }
  }
  return restored;
}

absl::StatusOr<std::shared_ptr<Session>> Registry::Get(
    const std::string& id, const std::string& principal) const {
  absl::MutexLock l(&mu_);
  auto it = sessions_.find(id);
  if (it == sessions_.end() || it->second == nullptr ||
      it->second->spec().owner != principal) {
    return absl::NotFoundError(absl::StrCat("no session ", id));
  }
  return it->second;
}

absl::Status Registry::Delete(const std::string& id,
                              const std::string& principal) {
  std::shared_ptr<Session> session;
  {
    absl::MutexLock l(&mu_);
    auto it = sessions_.find(id);
    if (it == sessions_.end() || it->second == nullptr ||
        it->second->spec().owner != principal) {
      return absl::NotFoundError(absl::StrCat("no session ", id));
    }
    // Gone for every call from here on, but the id stays taken (null, as
    // while a session is created) until its files are deleted: a new
    // session under the same id would lose its journal to DeleteFiles.
    session = std::move(it->second);
  }
  // Not under mu_: MarkDeleted waits for the session's readers (a long
  // error measurement, say), and every other session's calls need mu_.
  session->MarkDeleted();  // closes its journal
  DeleteFiles(id);
  absl::MutexLock l(&mu_);
  reserved_bytes_ -= Session::EstimateMemoryBytes(session->spec().stock,
                                                  session->spec().scheme);
  sessions_.erase(id);
  return absl::OkStatus();
}

int Registry::EvictIdle(double idle_seconds) {
  std::vector<std::shared_ptr<Session>> idle;
  {
    absl::MutexLock l(&mu_);
    for (const auto& [id, s] : sessions_) {
      // use_count 1: only the registry holds it, so no stream is open.
      if (s != nullptr && s.use_count() == 1 &&
          s->IdleSeconds() >= idle_seconds) {
        idle.push_back(s);
      }
    }
  }
  int evicted = 0;
  for (const auto& s : idle) {
    if (s->Evict()) {
      ++evicted;
      spdlog::info("session {}: evicted after {:.0f} s idle", s->id(),
                   s->IdleSeconds());
    }
  }
  return evicted;
}

std::vector<std::shared_ptr<Session>> Registry::List(
    const std::string& principal) const {
  absl::MutexLock l(&mu_);
  std::vector<std::shared_ptr<Session>> out;
  for (const auto& [id, s] : sessions_) {
    if (s != nullptr && s->spec().owner == principal) out.push_back(s);
  }
  return out;
}

}  // namespace swarf::server
