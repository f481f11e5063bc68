// Page tokens of the stores' list calls ("seq < N" paging, server/store.h). A token seals the last
// row's sequence number and the tenant's tag in one AES-128 block under a key kept in the
// database: row numbers are global, so a plain number would tell a tenant how many rows others
// created between its pages; sealed, a token says nothing, works across restarts (and replicas
// sharing the key), and is refused for another tenant.
#ifndef RADIOSITY_SERVER_PAGE_TOKEN_H_
#define RADIOSITY_SERVER_PAGE_TOKEN_H_

#include <cstdint>
#include <string>

#include "absl/status/statusor.h"

namespace radiosity::service {

class PageTokens {
 public:
  // 16 random bytes for a new database's key; INTERNAL when the system has no randomness.
  static absl::StatusOr<std::string> NewKey();
  // `key`: 16 bytes (NewKey's, as kept in the database).
  explicit PageTokens(std::string key = "") : key_(std::move(key)) {}
  bool valid() const { return key_.size() == 16; }

  std::string Make(const std::string& tenant, int64_t seq) const;
  // The sequence number before which the next page starts: INT64_MAX for "" (the first page);
  // INVALID_ARGUMENT naming page_token for anything not made by Make for this tenant.
  absl::StatusOr<int64_t> Parse(const std::string& tenant, const std::string& token) const;

 private:
  std::string key_;
};

// The page size a list call uses for the one requested (<= 0: the default, 50; at most 1000).
int PageSize(int requested);

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_PAGE_TOKEN_H_
