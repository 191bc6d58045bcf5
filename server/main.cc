// swarfd: the swarf simulation server.
#include <csignal>
#include <cstdlib>
#include <string>
#include <thread>

#include "absl/flags/flag.h"
#include "absl/flags/parse.h"
#include "absl/flags/usage.h"
#include "absl/flags/usage_config.h"
#include "absl/strings/match.h"
#include "core/memory_policy.h"
#include "core/thread_pool.h"
#include "server/server.h"
#include "spdlog/spdlog.h"

ABSL_FLAG(std::string, listen, "127.0.0.1:50051",
          "host:port to listen on (port 0: any free port)");
ABSL_FLAG(int, worker_threads, 0,
          "threads running simulation work (0: $SWARF_THREADS, else one per "
          "core this process may use)");
ABSL_FLAG(int, max_sessions, 256, "sessions this server holds at most");
ABSL_FLAG(int64_t, max_session_memory_mb, 0,
          "worst-case memory of one session, every tile of its grid cut "
          "(MiB; 12 bytes a node; 0: only --max_total_memory_mb applies)");
ABSL_FLAG(int64_t, max_total_memory_mb, 8192,
          "worst-case memory of all sessions together (MiB; 12 bytes a "
          "node of each session's grid)");
// Replaced by the byte limits above: given, swarfd refuses to start.
ABSL_FLAG(int64_t, max_nodes_per_session, 0,
          "removed: use --max_session_memory_mb (12 bytes a node)");
ABSL_FLAG(int64_t, max_batch_points, int64_t{1} << 20,
          "points (moves) per move batch at most");
ABSL_FLAG(int, max_message_mb, 64, "largest gRPC message (MiB)");
ABSL_FLAG(int64_t, max_design_mb, 256,
          "largest design file a session may upload (SetDesign, MiB)");
ABSL_FLAG(int, max_streams_per_client, 16,
          "open Simulate streams per client (token, or address without auth)");
ABSL_FLAG(double, idle_evict_seconds, 600,
          "journaled sessions idle this long leave memory until used again "
          "(0: never)");
ABSL_FLAG(std::string, replica, "",
          "name reported in x-swarf-replica (default: $POD_NAME, $HOSTNAME "
          "or swarfd)");
ABSL_FLAG(double, drain_seconds, 10,
          "on SIGTERM/SIGINT, how long in-flight calls may finish");
ABSL_FLAG(std::string, log_level, "info", "trace|debug|info|warn|error");
ABSL_FLAG(std::string, data_dir, "./swarf-data",
          "where sessions are journaled (one SQLite file each) and restored "
          "from at start; empty: keep sessions in memory only");
ABSL_FLAG(std::string, auth_tokens_file, "",
          "bearer tokens, one per line (reread when the file changes); "
          "clients send 'authorization: Bearer <token>'; empty: no auth");
ABSL_FLAG(std::string, tls_cert, "", "PEM certificate chain: serve TLS");
ABSL_FLAG(std::string, tls_key, "", "PEM private key of --tls_cert");
ABSL_FLAG(std::string, tls_client_ca, "",
          "PEM CA: clients must present a certificate it signed");
ABSL_FLAG(bool, insecure_public, false,
          "allow a non-loopback --listen without --auth_tokens_file");
ABSL_FLAG(std::string, trusted_proxies, "",
          "balancers (IP addresses or CIDR prefixes, comma-separated) whose "
          "x-real-ip metadata names the client for --max_streams_per_client");
ABSL_FLAG(std::string, journal_sync, "full",
          "full: a batch is on disk (fsync) when acknowledged; normal: "
          "survives a crash of swarfd, not of the machine; off");
ABSL_FLAG(int64_t, snapshot_every_moves, 1'000'000,
          "write a session's snapshot (its tiles) after this many moves, so "
          "that a restart replays at most that many; 0: only when a session "
          "is evicted or swarfd stops");

namespace {

std::string ReplicaName() {
  std::string r = absl::GetFlag(FLAGS_replica);
  for (const char* env : {"POD_NAME", "HOSTNAME"}) {
    if (r.empty() && std::getenv(env) != nullptr) r = std::getenv(env);
  }
  return r.empty() ? "swarfd" : r;
}

}  // namespace

int main(int argc, char** argv) {
  swarf::ReturnLargeBuffersOnFree();
  swarf::KeepFreedArenaTops();
  absl::SetProgramUsageMessage("swarfd [flags]: the swarf simulation server");
  // absl lists only the flags of a file named like the program (swarfd.cc);
  // ours are here, so --help and --helpshort must be told.
  absl::FlagsUsageConfig usage;
  usage.contains_help_flags = [](absl::string_view file) {
    return absl::EndsWith(file, "server/main.cc");
  };
  usage.contains_helpshort_flags = usage.contains_help_flags;
  absl::SetFlagsUsageConfig(usage);
  absl::ParseCommandLine(argc, argv);
  spdlog::set_level(spdlog::level::from_str(absl::GetFlag(FLAGS_log_level)));
  if (auto threads = swarf::ThreadsFromEnvironment(); !threads.ok()) {
    spdlog::error("{}", std::string(threads.status().message()));
    return 2;
  }

  // Signals are taken by a thread of ours, never by an arbitrary one.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  swarf::server::ServerOptions options;
  options.listen = absl::GetFlag(FLAGS_listen);
  options.worker_threads = absl::GetFlag(FLAGS_worker_threads);
  options.limits.max_sessions = absl::GetFlag(FLAGS_max_sessions);
  // The node cap is gone; a deployment still passing it is told what to use
  // rather than silently getting another limit.
  if (const int64_t nodes = absl::GetFlag(FLAGS_max_nodes_per_session);
      nodes != 0) {
    spdlog::error(
        "--max_nodes_per_session was removed: limits are in bytes now; use "
        "--max_session_memory_mb (12 bytes a node: {} nodes is about {} "
        "MiB) and --max_total_memory_mb",
        nodes, (nodes * 12 + (1 << 20) - 1) >> 20);
    return 2;
  }
  const int64_t session_mb = absl::GetFlag(FLAGS_max_session_memory_mb);
  const int64_t total_mb = absl::GetFlag(FLAGS_max_total_memory_mb);
  // Past 2^43 MiB the bytes overflow int64.
  constexpr int64_t kMaxMb = int64_t{1} << 43;
  if (session_mb < 0 || session_mb > kMaxMb) {
    spdlog::error("--max_session_memory_mb must be in [0, {}], got {}",
                  kMaxMb, session_mb);
    return 2;
  }
  if (total_mb < 1 || total_mb > kMaxMb) {
    spdlog::error("--max_total_memory_mb must be in [1, {}], got {}", kMaxMb,
                  total_mb);
    return 2;
  }
  options.limits.max_session_memory_bytes = session_mb << 20;
  options.limits.max_total_memory_bytes = total_mb << 20;
  options.limits.max_batch_points = absl::GetFlag(FLAGS_max_batch_points);
  options.limits.max_message_bytes = absl::GetFlag(FLAGS_max_message_mb) << 20;
  options.limits.max_design_bytes = absl::GetFlag(FLAGS_max_design_mb) << 20;
  options.limits.max_streams_per_client =
      absl::GetFlag(FLAGS_max_streams_per_client);
  options.limits.idle_evict_seconds = absl::GetFlag(FLAGS_idle_evict_seconds);
  options.replica = ReplicaName();
  options.persistence.data_dir = absl::GetFlag(FLAGS_data_dir);
  options.auth_tokens_file = absl::GetFlag(FLAGS_auth_tokens_file);
  options.tls_cert = absl::GetFlag(FLAGS_tls_cert);
  options.tls_key = absl::GetFlag(FLAGS_tls_key);
  options.tls_client_ca = absl::GetFlag(FLAGS_tls_client_ca);
  options.insecure_public = absl::GetFlag(FLAGS_insecure_public);
  options.trusted_proxies = absl::GetFlag(FLAGS_trusted_proxies);
  options.persistence.snapshot_every_moves =
      absl::GetFlag(FLAGS_snapshot_every_moves);
  if (options.persistence.snapshot_every_moves < 0) {
    spdlog::error("--snapshot_every_moves must be >= 0, got {}",
                  options.persistence.snapshot_every_moves);
    return 2;
  }
  const std::string sync = absl::GetFlag(FLAGS_journal_sync);
  if (sync == "full") {
    options.persistence.sync = swarf::server::JournalSync::kFull;
  } else if (sync == "normal") {
    options.persistence.sync = swarf::server::JournalSync::kNormal;
  } else if (sync == "off") {
    options.persistence.sync = swarf::server::JournalSync::kOff;
  } else {
    spdlog::error("--journal_sync must be full, normal or off, got \"{}\"",
                  sync);
    return 2;
  }
  auto server = swarf::server::SwarfServer::Start(options);
  if (!server.ok()) {
    spdlog::error("{}", std::string(server.status().message()));
    return 1;
  }
  spdlog::info("swarfd {} listening on {} (port {})", options.replica,
               options.listen, (*server)->port());

  std::thread waiter([&] {
    int sig = 0;
    sigwait(&signals, &sig);
    spdlog::info("signal {}: draining for {} s", sig,
                 absl::GetFlag(FLAGS_drain_seconds));
    (*server)->Shutdown(absl::Seconds(absl::GetFlag(FLAGS_drain_seconds)));
  });
  (*server)->Wait();
  waiter.join();
  spdlog::info("swarfd stopped");
  return 0;
}
