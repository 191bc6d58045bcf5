#include "client/cli/connection.h"

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <cstdio>
#include <optional>
#include <thread>

#include "absl/strings/str_cat.h"
#include "client/cli/args.h"

namespace swarf::cli {

absl::Status FromGrpc(const grpc::Status& s) {
  if (s.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()),
                      s.error_message());
}

namespace {

absl::StatusOr<std::string> ReadFile(const std::string& flag,
                                     const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", flag, ": cannot read ", path));
  }
  return std::string((std::istreambuf_iterator<char>(in)),
                     std::istreambuf_iterator<char>());
}

}  // namespace

absl::StatusOr<ConnectionOptions> ConnectionOptionsFrom(const Args& args) {
  ConnectionOptions o;
  if (auto t = args.Get("token")) {
    o.token = *t;
  } else if (const char* env = std::getenv("SWARF_TOKEN")) {
    o.token = env;
  }
  const std::pair<const char*, std::string*> files[] = {
      {"tls-ca", &o.tls_ca}, {"tls-cert", &o.tls_cert}, {"tls-key", &o.tls_key}};
  for (const auto& [flag, out] : files) {
    if (auto path = args.Get(flag)) {
      auto text = ReadFile(flag, *path);
      if (!text.ok()) return text.status();
      *out = *std::move(text);
    }
  }
  if (o.tls_cert.empty() != o.tls_key.empty()) {
    return absl::InvalidArgumentError("--tls-cert and --tls-key go together");
  }
  return o;
}

absl::StatusOr<std::unique_ptr<Connection>> Connection::Open(
    const std::string& server, const ConnectionOptions& options) {
  auto c = std::unique_ptr<Connection>(new Connection);
  c->token_ = options.token;
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  args.SetMaxSendMessageSize(64 << 20);
  if (server.empty()) {
    server::ServerOptions opt;
    opt.listen = "";  // in-process only
    opt.replica = "embedded";
    if (options.embedded_limits.has_value()) {
      opt.limits = *options.embedded_limits;
    }
    auto srv = server::SwarfServer::Start(opt);
    if (!srv.ok()) return srv.status();
    c->embedded_ = *std::move(srv);
    c->channel_ = c->embedded_->InProcessChannel();
    c->target_ = "embedded server";
  } else {
    std::shared_ptr<grpc::ChannelCredentials> creds =
        grpc::InsecureChannelCredentials();
    if (!options.tls_ca.empty() || !options.tls_cert.empty()) {
      grpc::SslCredentialsOptions ssl;
      ssl.pem_root_certs = options.tls_ca;
      ssl.pem_private_key = options.tls_key;
      ssl.pem_cert_chain = options.tls_cert;
      creds = grpc::SslCredentials(ssl);
    }
    c->channel_ = grpc::CreateCustomChannel(server, creds, args);
    c->target_ = server;
  }
  c->stub_ = pb::Swarf::NewStub(c->channel_);
  return c;
}

std::unique_ptr<grpc::ClientContext> Connection::Context(
    const std::string& session_id, double timeout_s) const {
  auto ctx = std::make_unique<grpc::ClientContext>();
  if (!session_id.empty()) ctx->AddMetadata("x-swarf-session", session_id);
  if (!token_.empty()) ctx->AddMetadata("authorization", "Bearer " + token_);
  ctx->set_deadline(std::chrono::system_clock::now() +
                    std::chrono::milliseconds(
                        static_cast<int64_t>(timeout_s * 1000)));
  return ctx;
}

std::vector<Move> RunMoves(const std::vector<PathRun>& runs,
                           const std::map<int32_t, Cutter>& cutter_by_tool) {
  std::vector<Move> moves;
  std::optional<Vec3> pos;
  for (const PathRun& run : runs) {
    if (run.reposition) pos.reset();
    const Cutter& c = cutter_by_tool.at(run.tool_id);
    for (const Vec3& p : run.points) {
      if (pos.has_value()) moves.push_back({*pos, p, c});
      pos = p;
    }
  }
  return moves;
}

absl::StatusOr<std::optional<pb::Session>> AfterBrokenStream(
    Connection& conn, const std::string& session_id, const grpc::Status& st,
    std::chrono::steady_clock::time_point deadline, int attempt) {
  const bool transient = st.error_code() == grpc::StatusCode::UNAVAILABLE ||
                         st.error_code() == grpc::StatusCode::ABORTED ||
                         st.error_code() == grpc::StatusCode::CANCELLED ||
                         st.ok();
  if (!transient || std::chrono::steady_clock::now() > deadline) {
    return FromGrpc(st.ok() ? grpc::Status(grpc::StatusCode::DATA_LOSS,
                                           "the stream ended early")
                            : st);
  }
  std::this_thread::sleep_for(
      std::chrono::milliseconds(std::min(2000, 100 << std::min(attempt, 4))));
  auto gctx = conn.Context(session_id, 5);
  pb::GetSessionRequest get;
  get.set_session_id(session_id);
  pb::Session session;
  grpc::Status gs = conn.stub().GetSession(gctx.get(), get, &session);
  if (gs.ok()) return session;
  // NOT_FOUND: gone for good. Else not back yet: the caller's resume window
  // bounds the retries.
  if (gs.error_code() == grpc::StatusCode::NOT_FOUND) return FromGrpc(gs);
  return std::nullopt;
}

absl::Status StreamPath(
    Connection& conn, const std::string& session_id,
    const std::vector<PathRun>& runs, int64_t batch_points,
    const std::function<void(const StreamProgress&)>& progress,
    const std::function<void(const pb::Ack&, int64_t first_move_id)>& on_ack) {
  // Batches in order, and how many moves each one makes.
  std::vector<pb::SimulateRequest> reqs;
  std::vector<int64_t> moves_of;
  std::vector<int64_t> first_of;  // each batch's first move id
  StreamProgress p;
  uint64_t seq = 0;
  bool started = false;
  for (const PathRun& run : runs) {
    for (size_t k = 0; k < run.points.size(); k += batch_points) {
      const size_t end = std::min(run.points.size(), k + batch_points);
      pb::MoveBatch* b = reqs.emplace_back().mutable_moves();
      b->set_seq(++seq);
      b->set_tool_id(run.tool_id);
      b->set_rapid(run.rapid);
      const bool places = run.reposition && k == 0;
      b->set_reposition(places);
      b->set_report_cuts(on_ack != nullptr);
      b->mutable_xyz()->Reserve(3 * (end - k));
      for (size_t i = k; i < end; ++i) {
        b->add_xyz(run.points[i].x);
        b->add_xyz(run.points[i].y);
        b->add_xyz(run.points[i].z);
      }
      // The very first point, and a repositioning one, only place the tool.
      const int64_t moves =
          static_cast<int64_t>(end - k) - (started && !places ? 0 : 1);
      started = true;
      moves_of.push_back(moves);
      first_of.push_back(p.moves_total);
      p.moves_total += moves;
    }
  }
  // Stream from batch `from` (1-based); acks before it are counted already.
  // A stream that breaks (the server restarted, the network dropped) is
  // resumed: the server says which batch it has last, and the rest is sent
  // again. A batch the server rejects ends the run.
  constexpr auto kResumeWindow = std::chrono::seconds(120);
  uint64_t from = 1;
  uint64_t acked = 0;
  auto deadline = std::chrono::steady_clock::now() + kResumeWindow;
  for (int attempt = 0;; ++attempt) {
    auto ctx = conn.Context(session_id, 24 * 3600);
    auto stream = conn.stub().Simulate(ctx.get());
    std::thread writer([&] {
      for (uint64_t k = from; k <= reqs.size(); ++k) {
        if (!stream->Write(reqs[k - 1])) break;  // Finish says why
      }
      stream->WritesDone();
    });
    pb::SimulateResponse resp;
    absl::Status batch_error;
    while (stream->Read(&resp)) {
      if (resp.has_ack()) {
        const pb::Ack& a = resp.ack();
        if (a.seq() > acked) {
          for (uint64_t k = acked + 1; k <= a.seq(); ++k) {
            p.moves_done += moves_of[k - 1];
          }
          if (on_ack && a.seq() == acked + 1 && !a.duplicate()) {
            on_ack(a, first_of[a.seq() - 1]);
          }
          acked = a.seq();
          p.node_lowerings += a.node_lowerings();
          if (progress) progress(p);
        }
      } else if (resp.has_error() && batch_error.ok()) {
        batch_error = absl::Status(
            static_cast<absl::StatusCode>(resp.error().code()),
            absl::StrCat("batch ", resp.error().request_id(), ": ",
                         resp.error().message()));
        ctx->TryCancel();
      }
    }
    writer.join();
    grpc::Status st = stream->Finish();
    if (!batch_error.ok()) return batch_error;
    if (st.ok() && acked == reqs.size()) return absl::OkStatus();
    // Ask where the server is; it may still be restarting.
    absl::StatusOr<std::optional<pb::Session>> back =
        AfterBrokenStream(conn, session_id, st, deadline, attempt);
    if (!back.ok()) return back.status();
    if (!back->has_value()) continue;
    const pb::Session& session = **back;
    from = session.last_seq() + 1;
    if (session.last_seq() > acked) {
      // Applied but the ack was lost with the connection.
      for (uint64_t k = acked + 1; k <= session.last_seq(); ++k) {
        p.moves_done += moves_of[k - 1];
      }
      acked = session.last_seq();
    }
    std::fprintf(stderr,
                 "\nswarf: the stream to the server broke (%s); resuming at "
                 "batch %llu of %zu\n",
                 st.ok() ? "ended early" : st.error_message().c_str(),
                 static_cast<unsigned long long>(from), reqs.size());
    deadline = std::chrono::steady_clock::now() + kResumeWindow;
    if (from > reqs.size()) return absl::OkStatus();
  }
}

}  // namespace swarf::cli
