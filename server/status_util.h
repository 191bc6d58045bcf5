// absl::Status <-> grpc::Status: the codes are the same google.rpc.Code
// values, so the mapping is 1:1.
#ifndef SWARF_SERVER_STATUS_UTIL_H_
#define SWARF_SERVER_STATUS_UTIL_H_

#include <string>

#include "absl/status/status.h"
#include "grpcpp/support/status.h"

namespace swarf::server {

inline grpc::Status ToGrpcStatus(const absl::Status& s) {
  return grpc::Status(static_cast<grpc::StatusCode>(s.code()),
                      std::string(s.message()));
}

}  // namespace swarf::server

#endif  // SWARF_SERVER_STATUS_UTIL_H_
