#include "server/journal.h"

#include <sqlite3.h>

#if defined(__x86_64__)
#include <nmmintrin.h>
#endif

#include <array>
#include <cstring>
#include <filesystem>

#include "absl/strings/str_cat.h"

namespace swarf::server {
namespace {

constexpr int kFormatVersion = 1;

std::array<uint32_t, 256> MakeCrcTable() {
  std::array<uint32_t, 256> t{};
  for (uint32_t i = 0; i < 256; ++i) {
    uint32_t c = i;
    for (int k = 0; k < 8; ++k) c = (c & 1) ? 0x82F63B78u ^ (c >> 1) : c >> 1;
    t[i] = c;
  }
  return t;
}

absl::Status SqlError(sqlite3* db, const std::string& what) {
  return absl::InternalError(
      absl::StrCat("journal: ", what, ": ", sqlite3_errmsg(db)));
}

absl::Status Exec(sqlite3* db, const char* sql) {
  char* err = nullptr;
  if (sqlite3_exec(db, sql, nullptr, nullptr, &err) != SQLITE_OK) {
    std::string msg = err != nullptr ? err : "unknown error";
    sqlite3_free(err);
    return absl::InternalError(absl::StrCat("journal: ", sql, ": ", msg));
  }
  return absl::OkStatus();
}

const char* SyncPragma(JournalSync sync) {
  switch (sync) {
    case JournalSync::kFull:
      return "PRAGMA synchronous=FULL;";
    case JournalSync::kNormal:
      return "PRAGMA synchronous=NORMAL;";
    case JournalSync::kOff:
      break;
  }
  return "PRAGMA synchronous=OFF;";
}

// The checksum of a batch row: its fields, then its points.
uint32_t BatchCrc(uint64_t seq, int32_t tool_id, bool reposition,
                  const void* xyz, size_t bytes) {
  uint8_t head[13];
  std::memcpy(head, &seq, 8);
  std::memcpy(head + 8, &tool_id, 4);
  head[12] = reposition ? 1 : 0;
  return Crc32c(xyz, bytes, Crc32c(head, sizeof head));
}

absl::StatusOr<sqlite3*> OpenDb(const std::string& path, int flags) {
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db, flags, nullptr) != SQLITE_OK) {
    absl::Status s = absl::UnavailableError(absl::StrCat(
        "journal: cannot open ", path, ": ",
        db != nullptr ? sqlite3_errmsg(db) : "out of memory"));
    sqlite3_close(db);
    return s;
  }
  sqlite3_busy_timeout(db, 5000);
  return db;
}

}  // namespace

uint32_t Crc32cPortable(const void* data, size_t size, uint32_t crc) {
  static const std::array<uint32_t, 256> table = MakeCrcTable();
  const auto* p = static_cast<const uint8_t*>(data);
  crc = ~crc;
  for (size_t i = 0; i < size; ++i) crc = table[(crc ^ p[i]) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

#if defined(__x86_64__)
// SSE4.2's crc32 instruction computes CRC32C: about 10x the table's speed,
// which matters for snapshots of tens of MB.
__attribute__((target("sse4.2"))) static uint32_t Crc32cSse42(
    const void* data, size_t size, uint32_t crc) {
  const auto* p = static_cast<const uint8_t*>(data);
  uint64_t c = ~crc;
  for (; size >= 8; size -= 8, p += 8) {
    uint64_t v;
    std::memcpy(&v, p, 8);
    c = _mm_crc32_u64(c, v);
  }
  uint32_t c32 = static_cast<uint32_t>(c);
  for (; size > 0; --size) c32 = _mm_crc32_u8(c32, *p++);
  return ~c32;
}
#endif

uint32_t Crc32c(const void* data, size_t size, uint32_t crc) {
#if defined(__x86_64__)
  static const bool hardware = __builtin_cpu_supports("sse4.2");
  if (hardware) return Crc32cSse42(data, size, crc);
#endif
  return Crc32cPortable(data, size, crc);
}

uint32_t BatchDigest(int32_t tool_id, bool reposition,
                     std::span<const double> xyz) {
  // The journal row's checksum without the seq (which the caller matches).
  return BatchCrc(0, tool_id, reposition, xyz.data(),
                  xyz.size() * sizeof(double));
}

absl::StatusOr<std::unique_ptr<Journal>> Journal::Create(
    const std::string& path, const std::string& definition,
    const std::string& owner, JournalSync sync) {
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) {
    return absl::AlreadyExistsError(
        absl::StrCat("journal: ", path, " already exists"));
  }
  auto db = OpenDb(path, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
  if (!db.ok()) return db.status();
  std::unique_ptr<Journal> j(new Journal(*db, path));
  for (const char* sql :
       {"PRAGMA journal_mode=WAL;", SyncPragma(sync),
        "CREATE TABLE meta (key TEXT PRIMARY KEY, value BLOB NOT NULL);",
        "CREATE TABLE batches (seq INTEGER PRIMARY KEY, tool_id INTEGER NOT "
        "NULL, reposition INTEGER NOT NULL, xyz BLOB NOT NULL, crc INTEGER "
        "NOT NULL);"}) {
    if (absl::Status s = Exec(j->db_, sql); !s.ok()) return s;
  }
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(j->db_,
                         "INSERT INTO meta (key, value) VALUES (?, ?), "
                         "('format', ?), ('definition_crc', ?), ('owner', ?);",
                         -1, &st, nullptr) != SQLITE_OK) {
    return SqlError(j->db_, "prepare meta");
  }
  sqlite3_bind_text(st, 1, "definition", -1, SQLITE_STATIC);
  sqlite3_bind_blob(st, 2, definition.data(), static_cast<int>(definition.size()),
                    SQLITE_TRANSIENT);
  sqlite3_bind_int(st, 3, kFormatVersion);
  sqlite3_bind_int64(st, 4, Crc32c(definition.data(), definition.size()));
  sqlite3_bind_text(st, 5, owner.c_str(), -1, SQLITE_TRANSIENT);
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return SqlError(j->db_, "write definition");
  if (absl::Status s = j->Prepare(); !s.ok()) return s;
  return j;
}

absl::StatusOr<std::unique_ptr<Journal>> Journal::Open(
    const std::string& path, JournalSync sync, std::string* definition,
    std::string* owner) {
  auto db = OpenDb(path, SQLITE_OPEN_READWRITE);
  if (!db.ok()) return db.status();
  std::unique_ptr<Journal> j(new Journal(*db, path));
  if (absl::Status s = Exec(j->db_, "PRAGMA journal_mode=WAL;"); !s.ok()) {
    return s;
  }
  if (absl::Status s = Exec(j->db_, SyncPragma(sync)); !s.ok()) return s;
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(j->db_, "SELECT key, value FROM meta;", -1, &st,
                         nullptr) != SQLITE_OK) {
    return absl::DataLossError(absl::StrCat(
        "journal ", path, " is unreadable: ", sqlite3_errmsg(j->db_)));
  }
  bool have_def = false, have_crc = false;
  int64_t def_crc = 0;
  int format = 0;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    const std::string key =
        reinterpret_cast<const char*>(sqlite3_column_text(st, 0));
    if (key == "definition") {
      const void* b = sqlite3_column_blob(st, 1);
      definition->assign(static_cast<const char*>(b),
                         sqlite3_column_bytes(st, 1));
      have_def = true;
    } else if (key == "definition_crc") {
      def_crc = sqlite3_column_int64(st, 1);
      have_crc = true;
    } else if (key == "format") {
      format = sqlite3_column_int(st, 1);
    } else if (key == "owner") {
      const unsigned char* t = sqlite3_column_text(st, 1);
      owner->assign(t != nullptr ? reinterpret_cast<const char*>(t) : "");
    }
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE || !have_def || !have_crc ||
      def_crc != Crc32c(definition->data(), definition->size())) {
    return absl::DataLossError(absl::StrCat(
        "journal ", path, ": the session definition is missing or damaged"));
  }
  if (format != kFormatVersion) {
    return absl::FailedPreconditionError(absl::StrCat(
        "journal ", path, " has format ", format, ", this swarfd reads ",
        kFormatVersion));
  }
  if (absl::Status s = j->Prepare(); !s.ok()) return s;
  return j;
}

absl::Status Journal::Prepare() {
  if (sqlite3_prepare_v2(db_,
                         "INSERT INTO batches (seq, tool_id, reposition, xyz, "
                         "crc) VALUES (?, ?, ?, ?, ?);",
                         -1, &insert_, nullptr) != SQLITE_OK) {
    return SqlError(db_, "prepare insert");
  }
  if (sqlite3_prepare_v2(db_, "DELETE FROM batches WHERE seq = ?;", -1,
                         &remove_, nullptr) != SQLITE_OK) {
    return SqlError(db_, "prepare delete");
  }
  return absl::OkStatus();
}

Journal::~Journal() {
  sqlite3_finalize(insert_);
  sqlite3_finalize(remove_);
  sqlite3_close(db_);
}

absl::Status Journal::Append(uint64_t seq, int32_t tool_id, bool reposition,
                             std::span<const double> xyz) {
  const size_t bytes = xyz.size() * sizeof(double);
  sqlite3_reset(insert_);
  sqlite3_bind_int64(insert_, 1, static_cast<sqlite3_int64>(seq));
  sqlite3_bind_int(insert_, 2, tool_id);
  sqlite3_bind_int(insert_, 3, reposition ? 1 : 0);
  if (bytes == 0) {
    // A null pointer would bind NULL, which the NOT NULL column refuses.
    sqlite3_bind_zeroblob(insert_, 4, 0);
  } else {
    sqlite3_bind_blob(insert_, 4, xyz.data(), static_cast<int>(bytes),
                      SQLITE_STATIC);
  }
  sqlite3_bind_int64(insert_, 5,
                     BatchCrc(seq, tool_id, reposition, xyz.data(), bytes));
  const int rc = sqlite3_step(insert_);
  sqlite3_reset(insert_);
  if (rc != SQLITE_DONE) return SqlError(db_, "append batch");
  return absl::OkStatus();
}

absl::Status Journal::Remove(uint64_t seq) {
  sqlite3_reset(remove_);
  sqlite3_bind_int64(remove_, 1, static_cast<sqlite3_int64>(seq));
  const int rc = sqlite3_step(remove_);
  sqlite3_reset(remove_);
  if (rc != SQLITE_DONE) return SqlError(db_, "remove batch");
  return absl::OkStatus();
}

absl::Status Journal::PutBlob(const std::string& key,
                              const std::string& value) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_,
                         "INSERT OR REPLACE INTO meta (key, value) VALUES "
                         "(?, ?), (?, ?);",
                         -1, &st, nullptr) != SQLITE_OK) {
    return SqlError(db_, "prepare blob");
  }
  const std::string crc_key = key + "_crc";
  sqlite3_bind_text(st, 1, key.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_blob64(st, 2, value.data(), value.size(), SQLITE_TRANSIENT);
  sqlite3_bind_text(st, 3, crc_key.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_int64(st, 4, Crc32c(value.data(), value.size()));
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return SqlError(db_, absl::StrCat("write ", key));
  return absl::OkStatus();
}

absl::StatusOr<std::optional<std::string>> Journal::GetBlob(
    const std::string& key) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "SELECT key, value FROM meta WHERE key IN (?, ?);",
                         -1, &st, nullptr) != SQLITE_OK) {
    return SqlError(db_, "prepare blob read");
  }
  const std::string crc_key = key + "_crc";
  sqlite3_bind_text(st, 1, key.c_str(), -1, SQLITE_TRANSIENT);
  sqlite3_bind_text(st, 2, crc_key.c_str(), -1, SQLITE_TRANSIENT);
  std::optional<std::string> value;
  std::optional<int64_t> crc;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    const std::string k =
        reinterpret_cast<const char*>(sqlite3_column_text(st, 0));
    if (k == key) {
      const void* b = sqlite3_column_blob(st, 1);
      value.emplace(static_cast<const char*>(b), sqlite3_column_bytes(st, 1));
    } else {
      crc = sqlite3_column_int64(st, 1);
    }
  }
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return SqlError(db_, absl::StrCat("read ", key));
  if (!value.has_value()) return std::optional<std::string>();
  if (!crc.has_value() ||
      *crc != static_cast<int64_t>(Crc32c(value->data(), value->size()))) {
    return absl::DataLossError(
        absl::StrCat("journal ", path_, ": the ", key, " is damaged"));
  }
  return value;
}

absl::Status Journal::Truncate(uint64_t seq) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_, "DELETE FROM batches WHERE seq > ?;", -1, &st,
                         nullptr) != SQLITE_OK) {
    return SqlError(db_, "prepare truncate");
  }
  sqlite3_bind_int64(st, 1, static_cast<sqlite3_int64>(seq));
  const int rc = sqlite3_step(st);
  sqlite3_finalize(st);
  if (rc != SQLITE_DONE) return SqlError(db_, "truncate");
  return absl::OkStatus();
}

absl::StatusOr<std::string> Journal::Replay(
    const std::function<absl::Status(const Batch&)>& fn) {
  sqlite3_stmt* st = nullptr;
  if (sqlite3_prepare_v2(db_,
                         "SELECT seq, tool_id, reposition, xyz, crc FROM "
                         "batches ORDER BY seq;",
                         -1, &st, nullptr) != SQLITE_OK) {
    return absl::StrCat("the batches are unreadable: ", sqlite3_errmsg(db_));
  }
  std::string problem;
  Batch b;
  uint64_t expect = 1;
  int rc;
  while ((rc = sqlite3_step(st)) == SQLITE_ROW) {
    b.seq = static_cast<uint64_t>(sqlite3_column_int64(st, 0));
    b.tool_id = sqlite3_column_int(st, 1);
    b.reposition = sqlite3_column_int(st, 2) != 0;
    const void* blob = sqlite3_column_blob(st, 3);
    const size_t bytes = sqlite3_column_bytes(st, 3);
    const uint32_t crc = static_cast<uint32_t>(sqlite3_column_int64(st, 4));
    if (b.seq != expect) {
      problem = absl::StrCat("batch ", expect, " is missing (next is ", b.seq,
                             ")");
      break;
    }
    if (bytes % (3 * sizeof(double)) != 0 ||
        crc != BatchCrc(b.seq, b.tool_id, b.reposition, blob, bytes)) {
      problem = absl::StrCat("batch ", b.seq, " is damaged (checksum)");
      break;
    }
    b.xyz.resize(bytes / sizeof(double));
    if (bytes > 0) std::memcpy(b.xyz.data(), blob, bytes);
    if (absl::Status s = fn(b); !s.ok()) {
      problem = absl::StrCat("batch ", b.seq, " does not apply: ", s.message());
      break;
    }
    ++expect;
  }
  if (problem.empty() && rc != SQLITE_DONE && rc != SQLITE_ROW) {
    problem = absl::StrCat("reading stopped after batch ", expect - 1, ": ",
                           sqlite3_errmsg(db_));
  }
  sqlite3_finalize(st);
  return problem;
}

void Journal::DeleteFiles(const std::string& path) {
  std::error_code ec;
  for (const char* suffix : {"", "-wal", "-shm"}) {
    std::filesystem::remove(path + suffix, ec);
  }
}

}  // namespace swarf::server
