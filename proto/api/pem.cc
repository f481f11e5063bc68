#include "proto/api/pem.h"

#include "absl/strings/str_cat.h"
#include "solver/util/file_io.h"

namespace radiosity {

absl::StatusOr<std::string> ReadPemFile(const std::string& path, const char* flag) {
  absl::StatusOr<std::string> pem = ReadWholeFile(path);
  if (!pem.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(flag, ": ", pem.status().message()));
  }
  if (pem->find("-----BEGIN ") == std::string::npos) {
    return absl::InvalidArgumentError(absl::StrCat(flag, ": ", path, " is not a PEM file"));
  }
  return pem;
}

}  // namespace radiosity
