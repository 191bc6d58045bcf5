// Snapshots of a session's workpiece: its nodal state after batch `seq`, in
// a file beside the journal, so that a restart replays the cuts of the
// later batches only. The journal still holds every batch and stays the
// record; a snapshot is a shortcut that may be missing or damaged without
// losing anything (restoring then replays the whole journal).
//
// File: a header (magic "SWARFSNP", format, seq, payload size and CRC32C,
// the header's own CRC32C), then the payload of Workpiece::SaveState.
// Written to "<path>.tmp" and renamed over `path`, so a crash leaves the
// old snapshot or the new one; not synced (a torn file fails its checksum).
//
// Functions only; callers serialise writes to one path.
#ifndef SWARF_SERVER_SNAPSHOT_H_
#define SWARF_SERVER_SNAPSHOT_H_

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "core/workpiece.h"

namespace swarf::server {

struct Snapshot {
  uint64_t seq = 0;   // the last batch the state holds (>= 1)
  std::string state;  // Workpiece::SaveState bytes
};

// Where the snapshot of the session journaled at `journal_path` lives.
std::string SnapshotPath(const std::string& journal_path);

// Saves wp's state, which holds batches 1..seq, to `path`.
absl::Status WriteSnapshot(const std::string& path, uint64_t seq,
                           const Workpiece& wp);
// NotFound when there is none; DataLoss naming the problem when it is not
// a whole snapshot.
absl::StatusOr<Snapshot> ReadSnapshot(const std::string& path);
// Removes the snapshot and any half-written one.
void DeleteSnapshot(const std::string& path);

}  // namespace swarf::server

#endif  // SWARF_SERVER_SNAPSHOT_H_
