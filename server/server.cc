#include "server/server.h"

#include <chrono>
#include <fstream>
#include <thread>

#include "absl/strings/str_cat.h"
#include "core/thread_pool.h"
#include "grpcpp/ext/proto_server_reflection_plugin.h"
#include "grpcpp/health_check_service_interface.h"
#include "grpcpp/security/server_credentials.h"
#include "grpcpp/server_builder.h"
#include "spdlog/spdlog.h"

namespace swarf::server {

absl::StatusOr<std::unique_ptr<SwarfServer>> SwarfServer::Start(
    const ServerOptions& options) {
  // A full tile with doubles, derivatives and owners is about 131 KB.
  constexpr int32_t kMinMessageBytes = 1 << 20;
  if (options.limits.max_message_bytes < kMinMessageBytes) {
    return absl::InvalidArgumentError(absl::StrCat(
        "max_message_bytes must be at least ", kMinMessageBytes,
        " (a tile with derivatives is about 131 KB)"));
  }
  // A batch at the point limit must fit in one message, or a client that
  // obeys the documented limit would have its stream ended by the transport.
  const int64_t full_batch = FullBatchMessageBytes(options.limits.max_batch_points);
  if (options.limits.max_batch_points < 1 ||
      full_batch > options.limits.max_message_bytes) {
    return absl::InvalidArgumentError(absl::StrCat(
        "max_batch_points ", options.limits.max_batch_points,
        " must be at least 1, and a batch that large (", full_batch,
        " bytes) must fit max_message_bytes ",
        options.limits.max_message_bytes));
  }
  auto tokens = TokenStore::Open(options.auth_tokens_file);
  if (!tokens.ok()) return tokens.status();
  if (!options.listen.empty() && !IsLoopback(options.listen) &&
      !(*tokens)->enabled() && !options.insecure_public) {
    return absl::FailedPreconditionError(absl::StrCat(
        "refusing to serve ", options.listen,
        " without authentication: give --auth_tokens_file, listen on "
        "127.0.0.1, or pass --insecure_public if the network is the "
        "boundary"));
  }
  std::shared_ptr<grpc::ServerCredentials> creds =
      grpc::InsecureServerCredentials();
  if (!options.tls_cert.empty() || !options.tls_key.empty()) {
    auto read = [](const std::string& path) -> absl::StatusOr<std::string> {
      std::ifstream in(path, std::ios::binary);
      if (!in) return absl::FailedPreconditionError(absl::StrCat(
          "cannot read ", path));
      return std::string((std::istreambuf_iterator<char>(in)),
                         std::istreambuf_iterator<char>());
    };
    auto cert = read(options.tls_cert);
    auto key = read(options.tls_key);
    if (!cert.ok()) return cert.status();
    if (!key.ok()) return key.status();
    grpc::SslServerCredentialsOptions ssl;
    ssl.pem_key_cert_pairs.push_back({*key, *cert});
    if (!options.tls_client_ca.empty()) {
      auto ca = read(options.tls_client_ca);
      if (!ca.ok()) return ca.status();
      ssl.pem_root_certs = *ca;
      ssl.client_certificate_request =
          GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY;
    }
    creds = grpc::SslServerCredentials(ssl);
  } else if (!options.tls_client_ca.empty()) {
    return absl::InvalidArgumentError(
        "tls_client_ca needs tls_cert and tls_key");
  }

  auto trust = ProxyTrust::Parse(options.trusted_proxies);
  if (!trust.ok()) return trust.status();

  std::unique_ptr<SwarfServer> s(new SwarfServer);
  s->options_ = options;
  s->tokens_ = *std::move(tokens);
  s->registry_ =
      std::make_unique<Registry>(options.limits, options.persistence);
  // Sessions come back before the first call is accepted.
  const auto t0 = std::chrono::steady_clock::now();
  auto restored = s->registry_->RestoreAll();
  if (!restored.ok()) return restored.status();
  if (*restored > 0) {
    spdlog::info("restored {} session(s) from {} in {:.3f} s", *restored,
                 options.persistence.data_dir,
                 std::chrono::duration<double>(
                     std::chrono::steady_clock::now() - t0)
                     .count());
  }
  const int threads = options.worker_threads > 0
                          ? options.worker_threads
                          : DefaultThreads();
  s->executor_ = std::make_unique<Executor>(threads);
  s->service_ = std::make_unique<SwarfService>(
      s->registry_.get(), s->executor_.get(), s->tokens_.get(),
      options.replica, *std::move(trust));

  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  if (!options.listen.empty()) {
    builder.AddListeningPort(options.listen, creds, &s->port_);
  }
  builder.RegisterService(s->service_.get());
  builder.SetMaxReceiveMessageSize(options.limits.max_message_bytes);
  builder.SetMaxSendMessageSize(options.limits.max_message_bytes);
  s->server_ = builder.BuildAndStart();
  if (s->server_ == nullptr || (!options.listen.empty() && s->port_ == 0)) {
    return absl::UnavailableError(
        absl::StrCat("cannot listen on ", options.listen));
  }
  // Probes may name the service (Kubernetes' grpc probe `service`) or not.
  s->server_->GetHealthCheckService()->SetServingStatus(true);
  s->server_->GetHealthCheckService()->SetServingStatus(
      ::swarf::v1::Swarf::service_full_name(), true);
  const double idle = options.limits.idle_evict_seconds;
  if (!options.persistence.data_dir.empty() && idle > 0) {
    SwarfServer* self = s.get();
    s->evictor_ = std::thread([self, idle] {
      const absl::Duration every =
          std::min(absl::Seconds(idle / 4), absl::Seconds(10));
      absl::MutexLock l(&self->evictor_mu_);
      while (!self->evictor_mu_.AwaitWithTimeout(
          absl::Condition(&self->stopping_), every)) {
        self->evictor_mu_.Unlock();
        self->registry_->EvictIdle(idle);
        self->evictor_mu_.Lock();
      }
    });
  }
  return s;
}

int64_t FullBatchMessageBytes(int64_t points) {
  // 24 bytes a point, the field's length and the batch's other fields
  // (seq, tool, flags, oneof framing): 64 bytes is ample.
  return 24 * points + 64;
}

bool IsLoopback(const std::string& listen) {
  const size_t colon = listen.rfind(':');
  std::string host = listen.substr(0, colon == std::string::npos ? listen.size()
                                                                  : colon);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
    host = host.substr(1, host.size() - 2);
  }
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0 ||
         listen.rfind("unix:", 0) == 0;
}

SwarfServer::~SwarfServer() { Shutdown(absl::Seconds(1)); }

std::shared_ptr<grpc::Channel> SwarfServer::InProcessChannel() {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(options_.limits.max_message_bytes);
  args.SetMaxSendMessageSize(options_.limits.max_message_bytes);
  return server_->InProcessChannel(args);
}

absl::StatusOr<std::shared_ptr<const Workpiece>> SwarfServer::PinSession(
    const std::string& id) {
  absl::StatusOr<std::shared_ptr<Session>> s = registry_->Get(id);
  if (!s.ok()) return s.status();
  return (*s)->Pin();
}

void SwarfServer::Shutdown(absl::Duration deadline) {
  if (shut_down_) return;
  shut_down_ = true;
  {
    absl::MutexLock l(&evictor_mu_);
    stopping_ = true;
  }
  if (evictor_.joinable()) evictor_.join();
  server_->GetHealthCheckService()->SetServingStatus(false);  // every name
  server_->Shutdown(std::chrono::system_clock::now() +
                    absl::ToChronoSeconds(deadline));
  server_->Wait();
  executor_.reset();  // runs what is queued, then joins
  // Nothing changes the sessions now: the next start replays nothing.
  const int snapshots = registry_->SnapshotAll();
  if (snapshots > 0) spdlog::info("wrote {} session snapshots", snapshots);
}

void SwarfServer::Wait() { server_->Wait(); }

}  // namespace swarf::server
