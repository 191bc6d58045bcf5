// The swarf.v1.Swarf gRPC service (callback API). All simulation work runs
// on the executor, never inside a gRPC callback; streams keep one write in
// flight and bound their queues, so a slow reader slows the writer and a
// slow server slows the client (flow control).
#ifndef SWARF_SERVER_SERVICE_H_
#define SWARF_SERVER_SERVICE_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <string>

#include "absl/status/status.h"
#include "absl/synchronization/mutex.h"
#include "server/auth.h"
#include "server/client_id.h"
#include "server/executor.h"
#include "server/registry.h"
#include "swarf/v1/swarf.grpc.pb.h"

namespace swarf::server {

// GetDeviation's answer, also a Simulate stream's DeviationRequest: the
// session's machined surface against its design, read band by band under
// the session's shared lock (a batch applied meanwhile restarts the pass).
// FailedPrecondition without a design; InvalidArgument for bad options;
// ResourceExhausted when the answer would exceed max_message_bytes.
// Thread-safe.
absl::StatusOr<::swarf::v1::Deviation> ComputeDeviation(
    const Session& session, const ::swarf::v1::DeviationRequest& req,
    int64_t max_message_bytes);

// Metadata naming the session on every session call (for load balancers).
inline constexpr char kSessionMetadata[] = "x-swarf-session";
// Response metadata naming the replica that served the call.
inline constexpr char kReplicaMetadata[] = "x-swarf-replica";

// The generated callback service, but Simulate takes raw bytes: the typed
// callback API reports a message that does not parse to the reactor like
// the end of the stream, so the server could not tell the client.
using SwarfCallbackBase = ::swarf::v1::Swarf::WithCallbackMethod_CreateSession<
    ::swarf::v1::Swarf::WithCallbackMethod_GetSession<
        ::swarf::v1::Swarf::WithCallbackMethod_ListSessions<
            ::swarf::v1::Swarf::WithCallbackMethod_DeleteSession<
                ::swarf::v1::Swarf::WithRawCallbackMethod_Simulate<
                    ::swarf::v1::Swarf::WithCallbackMethod_GetTiles<
                        ::swarf::v1::Swarf::WithCallbackMethod_GetErrorStats<
                            ::swarf::v1::Swarf::WithCallbackMethod_GetCuttingMarks<
                                ::swarf::v1::Swarf::WithCallbackMethod_Probe<
                                    ::swarf::v1::Swarf::WithCallbackMethod_SetDesign<
                                        ::swarf::v1::Swarf::WithCallbackMethod_GetDeviation<
                                            ::swarf::v1::Swarf::Service>>>>>>>>>>>;

// What GetCuttingMarks' flow control did, over the service's calls (for
// tests and the log). Thread-safe.
struct MarksStreamCounters {
  // The most bytes of polylines one call held queued at once.
  std::atomic<int64_t> peak_queued_bytes{0};
  // Times a search waited for its client (the queue was full).
  std::atomic<int64_t> waits{0};
  // Searches running now (each on a thread of its own).
  std::atomic<int32_t> searches{0};
};

class SwarfService final : public SwarfCallbackBase {
 public:
  // registry, executor and tokens are not owned and must outlive the
  // service. Streams are counted per client (client_id.h), believing
  // x-real-ip from `trust`'s proxies.
  SwarfService(Registry* registry, Executor* executor, TokenStore* tokens,
               std::string replica, ProxyTrust trust = {})
      : registry_(registry),
        executor_(executor),
        tokens_(tokens),
        replica_(std::move(replica)),
        trust_(std::move(trust)) {}

  grpc::ServerUnaryReactor* CreateSession(
      grpc::CallbackServerContext* ctx,
      const ::swarf::v1::CreateSessionRequest* req,
      ::swarf::v1::Session* resp) override;
  grpc::ServerUnaryReactor* GetSession(
      grpc::CallbackServerContext* ctx,
      const ::swarf::v1::GetSessionRequest* req,
      ::swarf::v1::Session* resp) override;
  grpc::ServerUnaryReactor* ListSessions(
      grpc::CallbackServerContext* ctx,
      const ::swarf::v1::ListSessionsRequest* req,
      ::swarf::v1::ListSessionsResponse* resp) override;
  grpc::ServerUnaryReactor* DeleteSession(
      grpc::CallbackServerContext* ctx,
      const ::swarf::v1::DeleteSessionRequest* req,
      ::swarf::v1::DeleteSessionResponse* resp) override;
  // Serialized SimulateRequests in, SimulateResponses out.
  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Simulate(
      grpc::CallbackServerContext* ctx) override;
  grpc::ServerWriteReactor<::swarf::v1::Tile>* GetTiles(
      grpc::CallbackServerContext* ctx,
      const ::swarf::v1::GetTilesRequest* req) override;
  grpc::ServerUnaryReactor* GetErrorStats(
      grpc::CallbackServerContext* ctx,
      const ::swarf::v1::GetErrorStatsRequest* req,
      ::swarf::v1::ErrorStats* resp) override;
  grpc::ServerWriteReactor<::swarf::v1::Polyline>* GetCuttingMarks(
      grpc::CallbackServerContext* ctx,
      const ::swarf::v1::GetCuttingMarksRequest* req) override;
  grpc::ServerUnaryReactor* Probe(grpc::CallbackServerContext* ctx,
                                  const ::swarf::v1::ProbeRequest* req,
                                  ::swarf::v1::ProbeResponse* resp) override;
  grpc::ServerUnaryReactor* SetDesign(
      grpc::CallbackServerContext* ctx,
      const ::swarf::v1::SetDesignRequest* req,
      ::swarf::v1::DesignInfo* resp) override;
  grpc::ServerUnaryReactor* GetDeviation(
      grpc::CallbackServerContext* ctx,
      const ::swarf::v1::GetDeviationRequest* req,
      ::swarf::v1::Deviation* resp) override;

  const MarksStreamCounters& marks_counters() const { return marks_; }

 private:
  // Open Simulate streams per client key. Thread-safe.
 public:
  class StreamCounter {
   public:
    bool Acquire(const std::string& key, int32_t limit);
    void Release(const std::string& key);

   private:
    absl::Mutex mu_;
    std::map<std::string, int32_t> open_ ABSL_GUARDED_BY(mu_);
  };

 private:
  // Runs `work` on the executor and finishes the call with its status;
  // `method` names the call in the log when it was slow.
  grpc::ServerUnaryReactor* Unary(grpc::CallbackServerContext* ctx,
                                  const char* method,
                                  std::function<absl::Status()> work);

  Registry* const registry_;
  Executor* const executor_;
  TokenStore* const tokens_;
  const std::string replica_;
  const ProxyTrust trust_;
  StreamCounter streams_;
  MarksStreamCounters marks_;
};

}  // namespace swarf::server

#endif  // SWARF_SERVER_SERVICE_H_
