// swarf health / swarf sessions: ask a running swarfd.
#include <future>
#include <optional>
#include <set>
#include <iostream>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "client/cli/args.h"
#include "client/cli/commands.h"
#include "server/convert.h"
#include "client/cli/connection.h"
#include "grpcpp/generic/generic_stub.h"

namespace swarf::cli {

namespace {
std::string SchemeLabel(int scheme) {
  auto k = server::SchemeFromProto(scheme, "scheme");
  return k.ok() ? std::string(GetScheme(*k).name()) : "?";
}
}  // namespace
namespace {

// grpc.health.v1.Health/Check through a generic stub (the health proto is
// not part of Debian's gRPC packages): the request for the whole server is
// empty, the response is field 1 (status, varint: 1 = SERVING).
absl::StatusOr<int> HealthStatus(Connection& conn, double timeout_s) {
  grpc::GenericStub stub(conn.channel());
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() +
                   std::chrono::milliseconds(static_cast<int>(timeout_s * 1e3)));
  grpc::Slice empty("", 0);  // an empty message, not "no message"
  grpc::ByteBuffer request(&empty, 1), response;
  std::promise<grpc::Status> done;
  stub.UnaryCall(&ctx, "/grpc.health.v1.Health/Check", grpc::StubOptions(),
                 &request, &response,
                 [&](grpc::Status s) { done.set_value(std::move(s)); });
  grpc::Status st = done.get_future().get();
  if (!st.ok()) return FromGrpc(st);
  std::vector<grpc::Slice> slices;
  if (!response.Dump(&slices).ok()) {
    return absl::InternalError("unreadable health response");
  }
  std::string bytes;
  for (const auto& s : slices) {
    bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  }
  int status = 0;  // UNKNOWN when absent
  if (bytes.size() >= 2 && bytes[0] == 0x08) status = bytes[1];
  return status;
}

// Parses a command that talks to a running server: --server is required.
// Returns the exit code to stop with, or nullopt to go on.
std::optional<int> ParseServerArgs(const char* name, const char* usage,
                                   const std::vector<std::string>& argv,
                                   const std::set<std::string>& valued,
                                   absl::StatusOr<Args>* args) {
  std::set<std::string> options = valued;
  options.insert("server");
  options.insert(std::begin(kConnectionFlags), std::end(kConnectionFlags));
  *args = Args::Parse(argv, options, {"help"});
  if (args->ok() && (*args)->Has("help")) {
    std::cout << usage;
    return 0;
  }
  if (!args->ok() || !(*args)->Has("server") ||
      !(*args)->positional().empty()) {
    std::cerr << "swarf " << name << ": "
              << (args->ok() ? "--server is required" : args->status().message())
              << "\n" << usage;
    return 2;
  }
  return std::nullopt;
}

}  // namespace

int HealthCommand(const std::vector<std::string>& argv) {
  constexpr char kUsage[] =
      "usage: swarf health --server HOST:PORT [--timeout SECONDS]\n"
      "                    [--token T] [--tls-ca FILE [--tls-cert F --tls-key F]]\n"
      "Exits 0 when the server answers SERVING (for health checks).\n";
  absl::StatusOr<Args> args;
  if (auto done = ParseServerArgs("health", kUsage, argv, {"timeout"}, &args)) {
    return *done;
  }
  double timeout = 5;
  if (auto t = args->Get("timeout"); t && !absl::SimpleAtod(*t, &timeout)) {
    std::cerr << "swarf health: --timeout must be a number\n";
    return 2;
  }
  auto copt = ConnectionOptionsFrom(*args);
  if (!copt.ok()) {
    std::cerr << "swarf health: " << copt.status().message() << "\n";
    return 2;
  }
  auto conn = Connection::Open(*args->Get("server"), *copt);
  if (!conn.ok()) {
    std::cerr << "swarf health: " << conn.status().message() << "\n";
    return 1;
  }
  auto status = HealthStatus(**conn, timeout);
  if (!status.ok()) {
    std::cerr << "swarf health: " << *args->Get("server") << ": "
              << status.status().message() << "\n";
    return 1;
  }
  static const char* const kNames[] = {"UNKNOWN", "SERVING", "NOT_SERVING",
                                       "SERVICE_UNKNOWN"};
  const int s = *status;
  std::cout << *args->Get("server") << ": "
            << (s >= 0 && s <= 3 ? kNames[s] : "?") << "\n";
  return s == 1 ? 0 : 1;
}

int SessionsCommand(const std::vector<std::string>& argv) {
  constexpr char kUsage[] =
      "usage: swarf sessions --server HOST:PORT [--token T]\n"
      "                      [--tls-ca FILE [--tls-cert F --tls-key F]]\n"
      "Lists the server's sessions.\n";
  absl::StatusOr<Args> args;
  if (auto done = ParseServerArgs("sessions", kUsage, argv, {}, &args)) {
    return *done;
  }
  auto copt = ConnectionOptionsFrom(*args);
  if (!copt.ok()) {
    std::cerr << "swarf sessions: " << copt.status().message() << "\n";
    return 2;
  }
  auto conn = Connection::Open(*args->Get("server"), *copt);
  if (!conn.ok()) {
    std::cerr << "swarf sessions: " << conn.status().message() << "\n";
    return 1;
  }
  auto ctx = (*conn)->Context("", 10);
  pb::ListSessionsRequest req;
  pb::ListSessionsResponse resp;
  grpc::Status st = (*conn)->stub().ListSessions(ctx.get(), req, &resp);
  if (!st.ok()) {
    std::cerr << "swarf sessions: " << *args->Get("server") << ": "
              << st.error_message() << "\n";
    return 1;
  }
  std::cout << absl::StrFormat("%-24s %-7s %11s %10s %12s %10s\n", "session",
                               "scheme", "grid", "last seq", "moves",
                               "MiB");
  for (const pb::Session& s : resp.sessions()) {
    std::cout << absl::StrFormat(
        "%-24s %-7s %5dx%-5d %10d %12d %10.1f\n", s.session_id(),
        SchemeLabel(s.scheme()), s.nx(), s.ny(),
        s.last_seq(), s.moves_applied(), s.memory_bytes() / 1048576.0);
  }
  std::cout << resp.sessions_size() << " session(s) on "
            << *args->Get("server") << "\n";
  return 0;
}

}  // namespace swarf::cli
