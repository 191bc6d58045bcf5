#include "tests/sim_stream.h"

#include <string>
#include <utility>

#include "gtest/gtest.h"
#include "server/service.h"

namespace swarf::testing {

namespace pb = ::swarf::v1;

std::shared_ptr<grpc::Channel> UnlimitedChannel(int port) {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(-1);
  args.SetMaxSendMessageSize(-1);
  return grpc::CreateCustomChannel("127.0.0.1:" + std::to_string(port),
                                   grpc::InsecureChannelCredentials(), args);
}

void SetDeadline(grpc::ClientContext* ctx) {
  ctx->set_deadline(std::chrono::system_clock::now() + kTimeout);
}

void ForSession(grpc::ClientContext* ctx, const std::string& id) {
  if (!id.empty()) ctx->AddMetadata(server::kSessionMetadata, id);
  SetDeadline(ctx);
}

grpc::Status CollectTiles(pb::Swarf::Stub* stub, grpc::ClientContext* ctx,
                          const std::string& id, pb::GetTilesRequest req,
                          std::vector<pb::Tile>* out) {
  ForSession(ctx, id);
  req.set_session_id(id);
  auto reader = stub->GetTiles(ctx, req);
  pb::Tile t;
  while (reader->Read(&t)) out->push_back(t);
  return reader->Finish();
}

pb::Session GetSessionOrFail(pb::Swarf::Stub* stub, const std::string& id) {
  pb::GetSessionRequest req;
  req.set_session_id(id);
  pb::Session s;
  grpc::ClientContext ctx;
  SetDeadline(&ctx);
  const grpc::Status st = stub->GetSession(&ctx, req, &s);
  EXPECT_TRUE(st.ok()) << st.error_message();
  return s;
}

std::vector<std::string> SerializedTiles(pb::Swarf::Stub* stub,
                                         const std::string& id) {
  pb::GetTilesRequest req;
  req.set_precision(pb::PRECISION_DOUBLE);
  req.set_include_owners(true);
  std::vector<pb::Tile> tiles;
  grpc::ClientContext ctx;
  const grpc::Status st = CollectTiles(stub, &ctx, id, req, &tiles);
  EXPECT_TRUE(st.ok()) << st.error_message();
  std::vector<std::string> out;
  for (const pb::Tile& t : tiles) out.push_back(t.SerializeAsString());
  return out;
}

SimStream::SimStream(pb::Swarf::Stub* stub, const std::string& session) {
  ForSession(&ctx_, session);
  stream_ = stub->Simulate(&ctx_);
  reader_ = std::thread([this] { ReadLoop(); });
}

SimStream::~SimStream() {
  if (!finished_) {
    ctx_.TryCancel();
    reader_.join();
    stream_->Finish();
  }
}

grpc::Status SimStream::Finish() {
  stream_->WritesDone();
  return Wait();
}

grpc::Status SimStream::Wait() {
  reader_.join();
  finished_ = true;
  return stream_->Finish();
}

bool SimStream::WaitFor(const std::function<bool(const Responses&)>& pred,
                        std::chrono::steady_clock::duration timeout) {
  std::unique_lock<std::mutex> l(mu_);
  cv_.wait_for(l, timeout, [&] { return done_ || pred(responses_); });
  return pred(responses_);
}

bool SimStream::WaitForCount(size_t n,
                             std::chrono::steady_clock::duration timeout) {
  return WaitFor([n](const Responses& rs) { return rs.size() >= n; }, timeout);
}

SimStream::Responses SimStream::responses() const {
  std::lock_guard<std::mutex> l(mu_);
  return responses_;
}

void SimStream::ReadLoop() {
  pb::SimulateResponse r;
  while (stream_->Read(&r)) {
    {
      std::lock_guard<std::mutex> l(mu_);
      responses_.push_back(std::move(r));
    }
    cv_.notify_all();
    r.Clear();
  }
  {
    std::lock_guard<std::mutex> l(mu_);
    done_ = true;
  }
  cv_.notify_all();
}

}  // namespace swarf::testing
