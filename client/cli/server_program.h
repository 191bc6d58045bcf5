// `swarf run --interpret server`: the program itself sent to the session's
// server, which interprets it (ProgramChunk on the Simulate stream) and
// applies the batches `swarf run` would have streamed.
#ifndef SWARF_CLIENT_SERVER_PROGRAM_H_
#define SWARF_CLIENT_SERVER_PROGRAM_H_

#include <cstdint>
#include <functional>
#include <string>

#include "absl/status/status.h"
#include "client/cli/connection.h"
#include "gcode/toolpath.h"

namespace swarf::cli {

// The API's options for a program that `swarf run` interprets with
// `options` (dialect, start, home, tool-change position, M6, max blocks,
// arc tolerance), `strict` and batches of `batch_points`. The program's T
// numbers are the session's tool ids (as swarf run creates them).
pb::ProgramOptions ProgramOptionsFor(const gcode::GcodeOptions& options,
                                     bool strict, int64_t batch_points,
                                     const std::string& name);

// Uploads `text` in chunks (options.first_seq set by the caller: the
// session's last_seq + 1) and follows its acknowledgements: `progress`
// after each (moves_done: the session's moves), `on_ack` with each batch's
// first acknowledgement and the session id of its first move (the batches
// ask for removed volumes when on_ack is given). A stream that breaks is
// resumed as StreamPath resumes (the program the server journaled, else
// uploaded again). The server's error: its status, "FILE: line N: ..." for
// the program's. *done receives the ProgramDone.
absl::Status StreamProgram(
    Connection& conn, const std::string& session_id, const std::string& text,
    pb::ProgramOptions options, StreamProgress* progress_state,
    const std::function<void(const StreamProgress&)>& progress,
    const std::function<void(const pb::Ack&, int64_t first_move_id)>& on_ack,
    pb::ProgramDone* done);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_SERVER_PROGRAM_H_
