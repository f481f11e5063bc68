// PEM files of TLS (certificates, keys, CAs), read for the server's and the CLI's options.
#ifndef RADIOSITY_PROTO_API_PEM_H_
#define RADIOSITY_PROTO_API_PEM_H_

#include <string>

#include "absl/status/statusor.h"

namespace radiosity {

// The text of the PEM file `path`; INVALID_ARGUMENT naming `flag` (the option that gave the path)
// when it cannot be read or holds no PEM block.
absl::StatusOr<std::string> ReadPemFile(const std::string& path, const char* flag);

}  // namespace radiosity

#endif  // RADIOSITY_PROTO_API_PEM_H_
