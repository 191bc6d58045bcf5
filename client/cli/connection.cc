#include "client/cli/connection.h"

#include <algorithm>
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

absl::StatusOr<std::shared_ptr<const Workpiece>>
Connection::PinEmbeddedSession(const std::string& id) {
  if (embedded_ == nullptr) {
    return absl::FailedPreconditionError(absl::StrCat(
        "session ", id, " is on ", target_, ", not in this process"));
  }
  return embedded_->PinSession(id);
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

RunMoveSource::RunMoveSource(std::vector<PathRun> runs,
                             const std::map<int32_t, Cutter>& cutter_by_tool)
    : runs_(std::move(runs)) {
  // As Session::BatchMoves numbers them: a point makes a move from the last
  // position, which a repositioning run forgets.
  std::optional<Vec3> pos;
  for (size_t r = 0; r < runs_.size(); ++r) {
    const PathRun& run = runs_[r];
    if (run.reposition) pos.reset();
    if (run.size() == 0) continue;
    const int32_t skip = pos.has_value() ? 0 : 1;
    const int64_t moves = run.size() - skip;
    if (moves > 0) {
      parts_.push_back({size_, static_cast<int32_t>(r), skip,
                        pos.value_or(Vec3{}), cutter_by_tool.at(run.tool_id)});
      size_ += moves;
    }
    pos = run.point(run.size() - 1);
  }
}

Move RunMoveSource::Get(int64_t id) const {
  const auto it = std::upper_bound(
      parts_.begin(), parts_.end(), id,
      [](int64_t v, const Part& p) { return v < p.first_move; });
  const Part& part = *(it - 1);
  const PathRun& run = runs_[part.run];
  const int64_t k = id - part.first_move + part.skip;
  return Move(k == 0 ? part.before : run.point(k - 1), run.point(k),
              part.cutter);
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
  // Batches in order: where each one's points are, and how many moves it
  // makes. The requests are made from the runs as they are written (and
  // again after a resume), not held: a program's points are not copied.
  struct Batch {
    size_t run;
    int64_t k, end;  // its points, [k, end) of the run's
    int64_t moves, first;  // moves it makes, the id of its first
  };
  std::vector<Batch> batches;
  StreamProgress p;
  bool started = false;
  for (size_t r = 0; r < runs.size(); ++r) {
    const PathRun& run = runs[r];
    for (int64_t k = 0; k < run.size(); k += batch_points) {
      const int64_t end = std::min(run.size(), k + batch_points);
      const bool places = run.reposition && k == 0;
      // The very first point, and a repositioning one, only place the tool.
      const int64_t moves = (end - k) - (started && !places ? 0 : 1);
      started = true;
      batches.push_back({r, k, end, moves, p.moves_total});
      p.moves_total += moves;
    }
  }
  const auto request = [&](uint64_t seq, pb::SimulateRequest* req) {
    const Batch& batch = batches[seq - 1];
    const PathRun& run = runs[batch.run];
    pb::MoveBatch* b = req->mutable_moves();
    b->set_seq(seq);
    b->set_tool_id(run.tool_id);
    b->set_rapid(run.rapid);
    b->set_reposition(run.reposition && batch.k == 0);
    b->set_report_cuts(on_ack != nullptr);
    b->mutable_xyz()->Reserve(3 * (batch.end - batch.k));
    for (int64_t i = batch.k; i < batch.end; ++i) {
      const Vec3& q = run.point(i);
      b->add_xyz(q.x);
      b->add_xyz(q.y);
      b->add_xyz(q.z);
    }
  };
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
      pb::SimulateRequest req;
      for (uint64_t k = from; k <= batches.size(); ++k) {
        req.Clear();
        request(k, &req);
        if (!stream->Write(req)) break;  // Finish says why
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
            p.moves_done += batches[k - 1].moves;
          }
          if (on_ack && a.seq() == acked + 1 && !a.duplicate()) {
            on_ack(a, batches[a.seq() - 1].first);
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
    if (st.ok() && acked == batches.size()) return absl::OkStatus();
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
        p.moves_done += batches[k - 1].moves;
      }
      acked = session.last_seq();
    }
    std::fprintf(stderr,
                 "\nswarf: the stream to the server broke (%s); resuming at "
                 "batch %llu of %zu\n",
                 st.ok() ? "ended early" : st.error_message().c_str(),
                 static_cast<unsigned long long>(from), batches.size());
    deadline = std::chrono::steady_clock::now() + kResumeWindow;
    if (from > batches.size()) return absl::OkStatus();
  }
}

}  // namespace swarf::cli
