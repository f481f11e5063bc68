#include "proto/api/status.h"

#include <string>

namespace radiosity::service {

grpc::Status ToGrpcStatus(const absl::Status& status) {
  if (status.ok()) return grpc::Status::OK;
  int code = static_cast<int>(status.code());
  if (code <= 0 || code > static_cast<int>(grpc::StatusCode::UNAUTHENTICATED)) {
    code = static_cast<int>(grpc::StatusCode::INTERNAL);
  }
  // Messages may quote what a client sent; a long one would not fit in the trailers a client
  // accepts (8 KiB of metadata by default) and reach it as RESOURCE_EXHAUSTED instead.
  std::string message(status.message());
  if (message.size() > kMaxStatusMessage) {
    size_t cut = kMaxStatusMessage - 64;
    while (cut > 0 && (static_cast<unsigned char>(message[cut]) & 0xc0) == 0x80) --cut;
    const size_t dropped = message.size() - cut;
    message.resize(cut);
    message += "... (" + std::to_string(dropped) + " more bytes)";
  }
  return grpc::Status(static_cast<grpc::StatusCode>(code), message);
}

absl::Status FromGrpcStatus(const grpc::Status& status) {
  if (status.ok()) return absl::OkStatus();
  int code = static_cast<int>(status.error_code());
  if (code <= 0 || code > static_cast<int>(absl::StatusCode::kUnauthenticated)) {
    code = static_cast<int>(absl::StatusCode::kInternal);
  }
  return absl::Status(static_cast<absl::StatusCode>(code), status.error_message());
}

}  // namespace radiosity::service
