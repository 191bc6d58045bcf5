// A G-code program interpreted by the server (the API's ProgramChunk): its
// options read from the API (errors name the field), the program run
// through gcode/ exactly as `swarf run` runs a file, and its points split
// into the batches `swarf run` streams (gcode::SplitRuns, then every
// batch_points points), so that the session's result is the CLI's bit for
// bit.
//
// Pure functions of their arguments (the interpreter is deterministic): a
// program interpreted again after a restart makes the same batches.
// Thread-safe; no gRPC, only the messages.
#ifndef SWARF_SERVER_PROGRAM_H_
#define SWARF_SERVER_PROGRAM_H_

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "gcode/toolpath.h"
#include "server/session.h"
#include "swarf/v1/swarf.pb.h"

namespace swarf::server {

// Programs of more points than this (32 bytes each, held while they are
// applied) are refused: a 50 MB CAM program makes a few million.
inline constexpr int64_t kMaxProgramPoints = 50'000'000;
// The upload's limit (bytes).
inline constexpr int64_t kMaxProgramBytes = int64_t{256} << 20;
// `swarf run`'s --batch default.
inline constexpr int64_t kDefaultProgramBatchPoints = 20000;

// One batch: points [begin, end) of the toolpath as one MoveBatch.
struct ProgramBatch {
  int64_t begin = 0, end = 0;
  int32_t tool_id = 0;  // the session's tool
  bool rapid = false;
  bool reposition = false;
  int64_t moves = 0;  // the moves it makes (its points, less a placing one)
};

struct InterpretedProgram {
  std::string name;  // for messages
  gcode::Toolpath path;
  std::vector<ProgramBatch> batches;
  int64_t moves = 0;
  // What `swarf run` prints before simulating, each prefixed with the name:
  // notes, ignored words, dropped moves, a cut leaving the stock.
  std::vector<std::string> warnings;
};

// Interprets `text` with `options` for a session of `spec`, batches of at
// most max_batch_points (the server's limit). InvalidArgument: a bad option
// naming "program.options.<field>", an interpreter error "NAME: line N:
// ..." (as `swarf run` prints it), a T number without a session tool
// naming it and the line that selects it, dropped moves under strict.
// More than max_points points is InvalidArgument (the fuzz target bounds
// its work with a smaller one).
absl::StatusOr<InterpretedProgram> InterpretProgram(
    std::string_view text, const ::swarf::v1::ProgramOptions& options,
    const SessionSpec& spec, int64_t max_batch_points,
    int64_t max_points = kMaxProgramPoints);

}  // namespace swarf::server

#endif  // SWARF_SERVER_PROGRAM_H_
