// Small helpers shared by the server and the client: checksums, identifiers, timestamps, file
// names and whole-file I/O.
#ifndef RADIOSITY_SERVER_UTIL_H_
#define RADIOSITY_SERVER_UTIL_H_

#include <cstdint>
#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "google/protobuf/timestamp.pb.h"

namespace radiosity::service {

// Incremental SHA-256 (FIPS 180-4, through OpenSSL's EVP interface).
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

// A fresh random identifier: 12 lowercase hex digits (48 bits).
std::string NewId();

google::protobuf::Timestamp Now();
// RFC 3339 text of a timestamp ("" when unset).
std::string TimeText(const google::protobuf::Timestamp& t);

// Whether `name` is a relative '/'-separated path with no empty, "." or ".." component, no
// backslash or NUL, at most 255 bytes: safe to join below a directory.
bool IsSafeRelativeName(absl::string_view name);

// The id of a resource name: "jobs/abc" -> "abc" for collection "jobs"; a bare id is returned as
// it is. Empty when the name belongs to another collection or the id is not [0-9a-z-]{1,64}.
std::string IdFromName(absl::string_view name, absl::string_view collection);

absl::StatusOr<std::string> ReadWholeFile(const std::string& path);
// Writes through a temporary file and a rename, so readers never see half a file.
absl::Status WriteFileAtomically(const std::string& path, absl::string_view data);

// JSON string literal (quotes included) with the escapes RFC 8259 requires.
std::string JsonQuote(absl::string_view s);

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_UTIL_H_
