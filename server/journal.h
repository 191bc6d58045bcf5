// A session's journal: its definition and every applied move batch, in an
// SQLite database (WAL mode) of its own, so that a restarted server can
// rebuild the session by replaying the batches (the same simulation, hence
// bit-identical results).
//
// Every batch row carries a CRC32C of its contents; reading stops at the
// first row that is damaged or out of sequence, so a corrupt or truncated
// journal restores up to its last whole batch.
//
// Not thread-safe: the owning Session serialises access.
#ifndef SWARF_SERVER_JOURNAL_H_
#define SWARF_SERVER_JOURNAL_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

struct sqlite3;
struct sqlite3_stmt;

namespace swarf::server {

enum class JournalSync {
  kFull,    // fsync at every batch: durable when acknowledged (default)
  kNormal,  // survives a crash of swarfd, not of the machine
  kOff,     // no syncing (tests, benchmarks)
};

// CRC32C (Castagnoli) of `data`, continuing from `crc`.
uint32_t Crc32c(const void* data, size_t size, uint32_t crc = 0);
// The same by table lookup, without the CPU's instruction (for tests).
uint32_t Crc32cPortable(const void* data, size_t size, uint32_t crc = 0);

// A digest of a batch's contents (tool, reposition flag, points), to tell a
// resent batch from a different one under the same seq.
uint32_t BatchDigest(int32_t tool_id, bool reposition,
                     std::span<const double> xyz);

class Journal {
 public:
  struct Batch {
    uint64_t seq = 0;
    int32_t tool_id = 0;
    bool reposition = false;
    std::vector<double> xyz;
  };

  // Creates a new journal at `path` holding `definition` (opaque bytes).
  // ALREADY_EXISTS if the file exists.
  // `owner` is kept beside it (the session's principal).
  static absl::StatusOr<std::unique_ptr<Journal>> Create(
      const std::string& path, const std::string& definition,
      const std::string& owner, JournalSync sync);
  // Opens an existing journal; `definition` and `owner` receive what Create
  // stored.
  static absl::StatusOr<std::unique_ptr<Journal>> Open(
      const std::string& path, JournalSync sync, std::string* definition,
      std::string* owner);
  ~Journal();

  // Appends a batch durably (per the sync mode) before it is applied.
  absl::Status Append(uint64_t seq, int32_t tool_id, bool reposition,
                      std::span<const double> xyz);
  // Removes the batch `seq` again (its application failed).
  absl::Status Remove(uint64_t seq);
  // Removes every batch after `seq`.
  absl::Status Truncate(uint64_t seq);

  // Calls fn for every whole batch in seq order, from 1, stopping at the
  // first damaged or missing one. Returns a description of the problem if
  // reading stopped early (empty when the journal is whole).
  absl::StatusOr<std::string> Replay(
      const std::function<absl::Status(const Batch&)>& fn);

  // A named blob beside the definition (the session's design), replaced
  // durably in one transaction with its CRC32C. GetBlob: nullopt when
  // absent, DataLoss when its CRC does not match.
  absl::Status PutBlob(const std::string& key, const std::string& value);
  absl::StatusOr<std::optional<std::string>> GetBlob(const std::string& key);

  // Deletes the journal's files (the object is unusable afterwards).
  static void DeleteFiles(const std::string& path);

 private:
  Journal(sqlite3* db, std::string path) : db_(db), path_(std::move(path)) {}
  absl::Status Prepare();

  sqlite3* db_;
  std::string path_;
  sqlite3_stmt* insert_ = nullptr;
  sqlite3_stmt* remove_ = nullptr;
};

}  // namespace swarf::server

#endif  // SWARF_SERVER_JOURNAL_H_
