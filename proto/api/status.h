// The one place where absl::Status becomes a gRPC status (server edge), and back (client edge).
#ifndef RADIOSITY_PROTO_API_STATUS_H_
#define RADIOSITY_PROTO_API_STATUS_H_

#include <grpcpp/support/status.h>

#include <string>

#include "absl/status/status.h"
#include "absl/strings/string_view.h"

namespace radiosity::service {

// Longest message sent in a gRPC status (bytes); longer ones are cut, saying how much was dropped.
inline constexpr size_t kMaxStatusMessage = 4096;

// Same code (the numeric values of absl::StatusCode and grpc::StatusCode are both google.rpc.Code),
// same message (up to kMaxStatusMessage). Codes outside google.rpc.Code become INTERNAL.
grpc::Status ToGrpcStatus(const absl::Status& status);

absl::Status FromGrpcStatus(const grpc::Status& status);

// `text` as valid UTF-8, each byte that does not begin or continue a valid sequence replaced by
// U+FFFD: what goes into a proto3 string field (a stored or sent message with invalid UTF-8 could
// never be read back).
std::string ValidUtf8(absl::string_view text);

}  // namespace radiosity::service

#endif  // RADIOSITY_PROTO_API_STATUS_H_
