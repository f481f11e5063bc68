// Names and times of the API: resource names ("jobs/ID"), fresh identifiers, timestamps.
#ifndef RADIOSITY_PROTO_API_NAMES_H_
#define RADIOSITY_PROTO_API_NAMES_H_

#include <string>

#include "absl/strings/string_view.h"
#include "google/protobuf/timestamp.pb.h"

namespace radiosity::service {

// A fresh random identifier: 12 lowercase hex digits (48 bits).
std::string NewId();

google::protobuf::Timestamp Now();

// RFC 3339 text of a timestamp ("" when unset).
std::string TimeText(const google::protobuf::Timestamp& t);

// The id of a resource name: "jobs/abc" -> "abc" for collection "jobs"; a bare id is returned as
// it is. Empty when the name belongs to another collection or the id is not [0-9a-z-]{1,64}.
std::string IdFromName(absl::string_view name, absl::string_view collection);

}  // namespace radiosity::service

#endif  // RADIOSITY_PROTO_API_NAMES_H_
