// The one place where absl::Status becomes a gRPC status (server edge), and back (client edge).
#ifndef RADIOSITY_PROTO_API_STATUS_H_
#define RADIOSITY_PROTO_API_STATUS_H_

#include <grpcpp/support/status.h>

#include "absl/status/status.h"

namespace radiosity::service {

// Longest message sent in a gRPC status (bytes); longer ones are cut, saying how much was dropped.
inline constexpr size_t kMaxStatusMessage = 4096;

// Same code (the numeric values of absl::StatusCode and grpc::StatusCode are both google.rpc.Code),
// same message (up to kMaxStatusMessage). Codes outside google.rpc.Code become INTERNAL.
grpc::Status ToGrpcStatus(const absl::Status& status);

absl::Status FromGrpcStatus(const grpc::Status& status);

}  // namespace radiosity::service

#endif  // RADIOSITY_PROTO_API_STATUS_H_
