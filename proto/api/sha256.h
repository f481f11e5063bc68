// SHA-256 of uploads and downloads (FIPS 180-4, through OpenSSL's EVP interface): clients and
// the server checksum every file they send each other.
#ifndef RADIOSITY_PROTO_API_SHA256_H_
#define RADIOSITY_PROTO_API_SHA256_H_

#include <cstdint>
#include <memory>
#include <string>
#include <utility>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"

namespace radiosity::service {

// Incremental SHA-256.
class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;
  void Update(absl::string_view data);
  // Lowercase hex digest; the object cannot be updated afterwards.
  std::string HexDigest();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

std::string Sha256Hex(absl::string_view data);

// SHA-256 and size of a file.
absl::StatusOr<std::pair<std::string, int64_t>> Sha256File(const std::string& path);

}  // namespace radiosity::service

#endif  // RADIOSITY_PROTO_API_SHA256_H_
