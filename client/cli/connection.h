// The CLI's connection to a swarf server: a remote swarfd (host:port) or an
// embedded server in this process, reached over an in-process channel so
// that both take the same code path.
#ifndef SWARF_CLIENT_CONNECTION_H_
#define SWARF_CLIENT_CONNECTION_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "core/geometry.h"
#include "core/workpiece.h"
#include "gcode/toolpath.h"
#include "grpcpp/grpcpp.h"
#include "server/server.h"
#include "swarf/v1/swarf.grpc.pb.h"

namespace swarf::cli {

namespace pb = ::swarf::v1;

// absl::Status of a gRPC status, with the code kept.
absl::Status FromGrpc(const grpc::Status& s);

// How to reach a remote server securely. Empty fields are not used.
struct ConnectionOptions {
  std::string token;     // sent as "authorization: Bearer <token>"
  std::string tls_ca;    // PEM CA of the server's certificate: use TLS
  std::string tls_cert;  // PEM client certificate (with tls_key)
  std::string tls_key;
  // The embedded server's limits (no --server); its defaults when unset.
  std::optional<server::Limits> embedded_limits;
};

// The options of the CLI flags --token (or $SWARF_TOKEN), --tls-ca,
// --tls-cert, --tls-key; InvalidArgument naming a file it cannot read.
class Args;
absl::StatusOr<ConnectionOptions> ConnectionOptionsFrom(const Args& args);
// Those flags' names, for Args::Parse.
inline const char* const kConnectionFlags[] = {"token", "tls-ca", "tls-cert",
                                               "tls-key"};

class Connection {
 public:
  // `server` empty: start an embedded server.
  static absl::StatusOr<std::unique_ptr<Connection>> Open(
      const std::string& server, const ConnectionOptions& options = {});

  std::shared_ptr<grpc::Channel> channel() { return channel_; }

  pb::Swarf::Stub& stub() { return *stub_; }
  bool embedded() const { return embedded_ != nullptr; }
  const std::string& target() const { return target_; }
  // The embedded server's session `id`, its workpiece pinned for reading
  // here (server::Session::Pin: batches are refused while it is held).
  // FailedPrecondition on a remote server.
  absl::StatusOr<std::shared_ptr<const Workpiece>> PinEmbeddedSession(
      const std::string& id);

  // A context carrying the session metadata (for routing) and a deadline.
  std::unique_ptr<grpc::ClientContext> Context(const std::string& session_id,
                                               double timeout_s = 600) const;

 private:
  std::string token_;
  std::unique_ptr<server::SwarfServer> embedded_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::Swarf::Stub> stub_;
  std::string target_;
};

// After a Simulate stream of `session_id` ended with `st` before its work
// was done: the error to give up with when `st` is not one a resume
// outlives (UNAVAILABLE, ABORTED, CANCELLED, or OK: the stream ended early)
// or `deadline` has passed. Otherwise it waits (backing off with `attempt`)
// and asks the server for the session: nullopt when the server is not back
// yet (try again), else the session as the server has it.
absl::StatusOr<std::optional<pb::Session>> AfterBrokenStream(
    Connection& conn, const std::string& session_id, const grpc::Status& st,
    std::chrono::steady_clock::time_point deadline, int attempt);

// A run of tip positions cut with one tool at one kind of feed.
struct PathRun {
  int32_t tool_id = 0;
  bool rapid = false;
  // The first point only places the tool (the session's first run, or after
  // a tool change); otherwise it continues from the previous run's last.
  bool reposition = false;
  // The positions: `points`, or where `path` is set, the toolpath's points
  // [begin, end) (not owned: the toolpath must outlive the run), so that a
  // program's runs hold no copy of its points.
  std::vector<Vec3> points;
  const gcode::ToolpathPoint* path = nullptr;
  int64_t begin = 0, end = 0;

  int64_t size() const {
    return path != nullptr ? end - begin
                           : static_cast<int64_t>(points.size());
  }
  const Vec3& point(int64_t k) const {
    return path != nullptr ? path[begin + k].position : points[k];
  }
};

// The moves a session numbers from `runs`, in id order (as
// Session::BatchMoves does), with the cutter of each run's tool, read from
// the runs' points when asked: no copy of each move. Keeps a copy of the
// runs (views of a toolpath, which must outlive it). Thread-safe.
class RunMoveSource final : public MoveSource {
 public:
  // NotFound-free: every run's tool_id must be in cutter_by_tool.
  RunMoveSource(std::vector<PathRun> runs,
                const std::map<int32_t, Cutter>& cutter_by_tool);
  int64_t size() const override { return size_; }
  Move Get(int64_t id) const override;

 private:
  struct Part {
    int64_t first_move;  // id of the run's first move
    int32_t run;
    int32_t skip;  // 1: the run's first point only places the tool
    Vec3 before;   // with skip 0: where the tool was before the run
    Cutter cutter;
  };
  std::vector<PathRun> runs_;
  std::vector<Part> parts_;  // runs with at least one move, in id order
  int64_t size_ = 0;
};

struct StreamProgress {
  int64_t moves_done = 0;   // acknowledged
  int64_t moves_total = 0;
  int64_t node_lowerings = 0;
};

// Streams runs into the session as move batches of at most `batch_points`
// points, pipelined (a writer thread; acks read here), calling `progress`
// after every ack. The first point of the first run is the start position.
// With `on_ack`, every batch asks for its moves' removed volumes
// (MoveBatch.report_cuts) and its first acknowledgement is passed on with
// the session's id of the batch's first move (safety events included).
absl::Status StreamPath(
    Connection& conn, const std::string& session_id,
    const std::vector<PathRun>& runs, int64_t batch_points,
    const std::function<void(const StreamProgress&)>& progress,
    const std::function<void(const pb::Ack&, int64_t first_move_id)>& on_ack =
        nullptr);

}  // namespace swarf::cli

#endif  // SWARF_CLIENT_CONNECTION_H_
