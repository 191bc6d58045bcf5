// The client side of the calls of the tests that run the real server on a
// loopback port (server_integration_test, bad_input_test): call deadlines,
// the session metadata, a GetTiles read, and SimStream, a synchronous bidi
// Simulate stream whose responses a reader thread collects.
#ifndef SWARF_TESTS_SIM_STREAM_H_
#define SWARF_TESTS_SIM_STREAM_H_

#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "grpcpp/grpcpp.h"
#include "swarf/v1/swarf.grpc.pb.h"

namespace swarf::testing {

// Bound on every call and wait, so that a hang fails instead of blocking.
inline constexpr auto kTimeout = std::chrono::seconds(60);

// A channel to 127.0.0.1:port that sends and receives messages of any
// size (the server's limits are what a test exercises).
std::shared_ptr<grpc::Channel> UnlimitedChannel(int port);

// Sets the call's deadline to kTimeout from now.
void SetDeadline(grpc::ClientContext* ctx);

// Names session `id` in the call's metadata (none if `id` is empty) and sets
// its deadline.
void ForSession(grpc::ClientContext* ctx, const std::string& id);

// GetTiles on session `id` (req.session_id set to it), through `ctx`, which
// it sets up with ForSession: appends every tile to *out and returns the
// call's status. `ctx` stays the caller's, for the server's metadata.
grpc::Status CollectTiles(::swarf::v1::Swarf::Stub* stub,
                          grpc::ClientContext* ctx, const std::string& id,
                          ::swarf::v1::GetTilesRequest req,
                          std::vector<::swarf::v1::Tile>* out);

// GetSession of `id`; a failure is a GoogleTest failure (and an empty
// Session).
::swarf::v1::Session GetSessionOrFail(::swarf::v1::Swarf::Stub* stub,
                                      const std::string& id);

// Every tile of session `id`, heights as doubles and owners, each
// serialized, in the server's tile order: what bit-identity tests compare.
std::vector<std::string> SerializedTiles(::swarf::v1::Swarf::Stub* stub,
                                         const std::string& id);

// A Simulate stream: requests are written from the caller's thread while a
// reader thread collects every response, so that server backpressure never
// deadlocks the test.
//
// Thread safety: Write, Finish and Wait from one thread at a time (one write
// in flight, as gRPC requires); Cancel, WaitFor, WaitForCount and responses
// from any thread. Ownership: `stub` is used by the constructor only. The
// destructor of a stream not yet finished cancels the call and joins the
// reader, so a test that fails early does not hang.
class SimStream {
 public:
  using Responses = std::vector<::swarf::v1::SimulateResponse>;

  // An empty `session` sends no x-swarf-session metadata. The call's
  // deadline is kTimeout from now.
  SimStream(::swarf::v1::Swarf::Stub* stub, const std::string& session);
  ~SimStream();
  SimStream(const SimStream&) = delete;
  SimStream& operator=(const SimStream&) = delete;

  // False once the stream has ended.
  bool Write(const ::swarf::v1::SimulateRequest& r) {
    return stream_->Write(r);
  }
  void Cancel() { ctx_.TryCancel(); }

  // Half-closes, waits for the server to finish and returns its status.
  grpc::Status Finish();
  // Waits for the end of the stream (the server's status), without
  // half-closing. Call Finish or Wait once at the most.
  grpc::Status Wait();

  // Waits (bounded) until pred(responses so far) holds, or the stream ends;
  // whether it holds.
  bool WaitFor(const std::function<bool(const Responses&)>& pred,
               std::chrono::steady_clock::duration timeout = kTimeout);
  // Waits (bounded) until there are n responses.
  bool WaitForCount(size_t n,
                    std::chrono::steady_clock::duration timeout = kTimeout);

  // A copy of the responses so far, in the order received.
  Responses responses() const;
  // The call's context (the server's metadata, once it has sent it).
  grpc::ClientContext& context() { return ctx_; }

 private:
  void ReadLoop();

  grpc::ClientContext ctx_;
  std::unique_ptr<grpc::ClientReaderWriter<::swarf::v1::SimulateRequest,
                                           ::swarf::v1::SimulateResponse>>
      stream_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  Responses responses_;  // guarded by mu_
  bool done_ = false;    // guarded by mu_: the reader has seen the end
  bool finished_ = false;
  std::thread reader_;
};

}  // namespace swarf::testing

#endif  // SWARF_TESTS_SIM_STREAM_H_
