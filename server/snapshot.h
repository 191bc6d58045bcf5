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

// What a snapshot file's header says.
struct SnapshotHeader {
  uint64_t seq = 0;  // the last batch the state holds (>= 1)
  uint64_t payload_bytes = 0;
  uint32_t payload_crc = 0;
};

// Where the snapshot of the session journaled at `journal_path` lives.
std::string SnapshotPath(const std::string& journal_path);

// Saves wp's state, which holds batches 1..seq, to `path`.
absl::Status WriteSnapshot(const std::string& path, uint64_t seq,
                           const Workpiece& wp);
// NotFound when there is none; DataLoss naming the problem when its header
// is damaged or the file's size is not what the header says.
absl::StatusOr<SnapshotHeader> ReadSnapshotHeader(const std::string& path);
// Loads the state `header` describes into wp (Workpiece::LoadState),
// streaming it (a 1 MiB buffer, whatever the grid's size) and checking its
// CRC32C before wp takes it. DataLoss when it is damaged or is not a state
// of wp; wp is unchanged then.
absl::Status LoadSnapshot(const std::string& path,
                          const SnapshotHeader& header, Workpiece* wp);
// Removes the snapshot and any half-written one.
void DeleteSnapshot(const std::string& path);

}  // namespace swarf::server

#endif  // SWARF_SERVER_SNAPSHOT_H_
