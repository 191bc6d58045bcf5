// An embeddable swarf server: the gRPC service with health checking and
// reflection, listening on a TCP address and reachable in-process.
#ifndef SWARF_SERVER_SERVER_H_
#define SWARF_SERVER_SERVER_H_

#include <memory>
#include <string>
#include <thread>

#include "absl/status/statusor.h"
#include "absl/synchronization/mutex.h"
#include "absl/time/time.h"
#include "grpcpp/channel.h"
#include "grpcpp/server.h"
#include "server/executor.h"
#include "server/registry.h"
#include "server/service.h"

namespace swarf::server {

struct ServerOptions {
  // host:port; port 0 picks a free one. Empty: in-process only.
  std::string listen = "127.0.0.1:50051";
  int worker_threads = 0;  // 0: one per available core (AvailableCores)
  Limits limits;
  std::string replica = "swarfd";  // reported in x-swarf-replica
  // Journal sessions under data_dir and restore them at start; empty: in
  // memory only (tests, the CLI's embedded server).
  Persistence persistence;
  // Bearer tokens, one per line (see auth.h); empty: no authentication.
  std::string auth_tokens_file;
  // TLS: PEM files of the server's certificate chain and key; with
  // tls_client_ca, clients must present a certificate it signed.
  std::string tls_cert, tls_key, tls_client_ca;
  // Without tokens the server only listens on loopback unless this is set.
  bool insecure_public = false;
  // Balancers whose x-real-ip names the client (client_id.h): addresses or
  // CIDR prefixes, comma-separated; empty: none.
  std::string trusted_proxies;
};

// The largest serialized SimulateRequest of a batch of `points` points
// (bytes, an upper bound); Start refuses limits where it exceeds
// max_message_bytes.
int64_t FullBatchMessageBytes(int64_t points);

// Whether a listen address (host:port) is on the loopback interface.
bool IsLoopback(const std::string& listen);

// Thread-safe.
class SwarfServer {
 public:
  static absl::StatusOr<std::unique_ptr<SwarfServer>> Start(
      const ServerOptions& options);
  ~SwarfServer();  // Shutdown(1 s) if not done

  // The bound TCP port (0 when not listening on TCP).
  int port() const { return port_; }
  // A channel to this server that bypasses the network.
  std::shared_ptr<grpc::Channel> InProcessChannel();
  // Stops accepting calls, lets in-flight ones finish until `deadline`,
  // cancels the rest.
  void Shutdown(absl::Duration deadline);
  // Blocks until Shutdown.
  void Wait();
  // Session `id`'s workpiece pinned for reading in this process (Session::
  // Pin): the embedded server's client reads its moves and their index
  // instead of building its own. NotFound as Registry::Get (principal "").
  absl::StatusOr<std::shared_ptr<const Workpiece>> PinSession(
      const std::string& id);
  // The service's GetCuttingMarks counters (for tests); valid until the
  // server is destroyed.
  const MarksStreamCounters& marks_counters() const {
    return service_->marks_counters();
  }

 private:
  SwarfServer() = default;
  ServerOptions options_;
  std::unique_ptr<TokenStore> tokens_;
  std::unique_ptr<Registry> registry_;
  std::unique_ptr<Executor> executor_;
  std::unique_ptr<SwarfService> service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  bool shut_down_ = false;
  // Evicts idle journaled sessions now and then.
  std::thread evictor_;
  absl::Mutex evictor_mu_;
  bool stopping_ ABSL_GUARDED_BY(evictor_mu_) = false;
};

}  // namespace swarf::server

#endif  // SWARF_SERVER_SERVER_H_
