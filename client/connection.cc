#include "client/connection.h"

#include <chrono>
#include <thread>

#include "absl/strings/str_cat.h"

namespace swarf::cli {

absl::Status FromGrpc(const grpc::Status& s) {
  if (s.ok()) return absl::OkStatus();
  return absl::Status(static_cast<absl::StatusCode>(s.error_code()),
                      s.error_message());
}

absl::StatusOr<std::unique_ptr<Connection>> Connection::Open(
    const std::string& server) {
  auto c = std::unique_ptr<Connection>(new Connection);
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(64 << 20);
  args.SetMaxSendMessageSize(64 << 20);
  if (server.empty()) {
    server::ServerOptions opt;
    opt.listen = "";  // in-process only
    opt.replica = "embedded";
    auto srv = server::SwarfServer::Start(opt);
    if (!srv.ok()) return srv.status();
    c->embedded_ = *std::move(srv);
    c->channel_ = c->embedded_->InProcessChannel();
    c->target_ = "embedded server";
  } else {
    c->channel_ = grpc::CreateCustomChannel(
        server, grpc::InsecureChannelCredentials(), args);
    c->target_ = server;
  }
  c->stub_ = pb::Swarf::NewStub(c->channel_);
  return c;
}

std::unique_ptr<grpc::ClientContext> Connection::Context(
    const std::string& session_id, double timeout_s) const {
  auto ctx = std::make_unique<grpc::ClientContext>();
  if (!session_id.empty()) ctx->AddMetadata("x-swarf-session", session_id);
  ctx->set_deadline(std::chrono::system_clock::now() +
                    std::chrono::milliseconds(
                        static_cast<int64_t>(timeout_s * 1000)));
  return ctx;
}

absl::Status StreamPath(
    Connection& conn, const std::string& session_id,
    const std::vector<PathRun>& runs, int64_t batch_points,
    const std::function<void(const StreamProgress&)>& progress) {
  // Batches in order, and how many moves each one makes.
  std::vector<pb::SimulateRequest> reqs;
  std::vector<int64_t> moves_of;
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
      p.moves_total += moves;
    }
  }
  auto ctx = conn.Context(session_id, 24 * 3600);
  auto stream = conn.stub().Simulate(ctx.get());
  std::thread writer([&] {
    for (const auto& r : reqs) {
      if (!stream->Write(r)) break;  // the stream ended; Finish says why
    }
    stream->WritesDone();
  });
  pb::SimulateResponse resp;
  absl::Status batch_error;
  while (stream->Read(&resp)) {
    if (resp.has_ack()) {
      const pb::Ack& a = resp.ack();
      p.moves_done += moves_of[a.seq() - 1];
      p.nodes_lowered += a.nodes_lowered();
      if (progress) progress(p);
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
  return FromGrpc(st);
}

}  // namespace swarf::cli
