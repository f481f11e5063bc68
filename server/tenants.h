// Tenants: who a call is, and what each tenant may still store (docs/service/security.md).
//
// A server started with --tokens-file refuses calls with an unknown bearer token
// ("authorization: Bearer TOKEN") in TokenAuthProcessor, before any handler runs; handlers map
// the call's own token to its tenant with TenantOf() (per call: gRPC's AuthContext belongs to the
// connection, which may carry the calls of several tenants). Every scene and job carries the
// tenant that created it, and to any other tenant it does not exist.
// Without --tokens-file every call is the tenant "" (the open, single-user service).
#ifndef RADIOSITY_SERVER_TENANTS_H_
#define RADIOSITY_SERVER_TENANTS_H_

#include <grpcpp/grpcpp.h>
#include <grpcpp/security/auth_metadata_processor.h>

#include <array>
#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "server/store.h"

namespace radiosity::service {

// A tokens file: one "TOKEN TENANT" pair per line; '#' starts a comment; blank lines are skipped.
// Tokens are at least 16 characters of [A-Za-z0-9._~+/=-]; tenants 1 to 64 characters of
// [A-Za-z0-9._-]. Several tokens may map to one tenant (rotation). The file is read again when its
// modification time or size changes (checked at most once a second), so tokens are added and
// revoked without a restart; a file that no longer parses keeps the previous tokens (logged).
class TokenTable {
 public:
  // Reads `path`; INVALID_ARGUMENT naming the file and line when it does not parse.
  static absl::StatusOr<std::unique_ptr<TokenTable>> Open(const std::string& path);
  // Parses a tokens file's text (`path` names it in errors). Keys are SHA-256 of the tokens.
  static absl::StatusOr<std::map<std::string, std::string>> Parse(const std::string& path,
                                                                  const std::string& text);

  // The tenant of `token`, or empty when no line has it.
  std::string Lookup(const std::string& token);

 private:
  explicit TokenTable(std::string path) : path_(std::move(path)) {}
  void ReloadIfChanged();

  const std::string path_;
  std::mutex mu_;
  std::map<std::string, std::string> tenants_;  // SHA-256 hex of the token -> tenant.
  std::chrono::steady_clock::time_point checked_;
  // What the file was when read: modification and change times, size and inode.
  std::array<int64_t, 4> stamp_ = {-1, -1, -1, -1};
};

// Checks each call's bearer token against a TokenTable: an unknown or malformed token, or more
// than one, fails the call (UNAUTHENTICATED) before any handler runs. A call without a token
// passes, so that health checks and reflection work; the radiosity service refuses it
// (TenantOf).
class TokenAuthProcessor : public grpc::AuthMetadataProcessor {
 public:
  explicit TokenAuthProcessor(std::shared_ptr<TokenTable> tokens) : tokens_(std::move(tokens)) {}
  bool IsBlocking() const override { return false; }
  grpc::Status Process(const InputMetadata& auth_metadata, grpc::AuthContext* context,
                       OutputMetadata* consumed_auth_metadata,
                       OutputMetadata* response_metadata) override;

 private:
  std::shared_ptr<TokenTable> tokens_;
};

// The calling tenant, from this call's bearer token: "" when the server has no tokens (null);
// UNAUTHENTICATED when it has and the call carried none, several, or one it does not know (now).
absl::StatusOr<std::string> TenantOf(const grpc::CallbackServerContext& context,
                                     TokenTable* tokens);

// Per-tenant quotas (0: none): jobs not yet ended, and bytes stored (scenes and results); and
// the bytes the whole server stores.
struct TenantQuotas {
  int64_t max_unfinished_jobs = 0;
  int64_t max_stored_bytes = 0;
  int64_t server_max_stored_bytes = 0;
};

// Checks quotas against the store. A job's check and its insertion are one step for the tenant
// (Reservation), so concurrent CreateJob calls cannot pass the quota together.
class QuotaKeeper {
 public:
  QuotaKeeper(TenantQuotas quotas, Store* store) : quotas_(quotas), store_(store) {}

  // Held from the check until the job's row is in the store (or the creation failed).
  class Reservation {
   public:
    Reservation(QuotaKeeper* keeper, std::string tenant)
        : keeper_(keeper), tenant_(std::move(tenant)) {}
    Reservation(Reservation&& other) noexcept
        : keeper_(other.keeper_), tenant_(std::move(other.tenant_)) {
      other.keeper_ = nullptr;
    }
    Reservation(const Reservation&) = delete;
    Reservation& operator=(const Reservation&) = delete;
    ~Reservation();

   private:
    QuotaKeeper* keeper_;
    std::string tenant_;
  };

  // RESOURCE_EXHAUSTED when the tenant has as many unfinished jobs as its quota, or stores its
  // quota of bytes or more.
  absl::StatusOr<Reservation> ReserveJob(const std::string& tenant);
  // RESOURCE_EXHAUSTED when `bytes` more would take the tenant past its stored-bytes quota, or
  // the server past its cap.
  absl::Status CheckStore(const std::string& tenant, int64_t bytes);

 private:
  // The server's cap: `bytes` more (0: a job, refused once the server stores its cap).
  absl::Status CheckServerLocked(int64_t bytes);

  const TenantQuotas quotas_;
  Store* const store_;
  std::mutex mu_;
  std::map<std::string, int64_t> reserved_;  // Jobs being created, per tenant.
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_TENANTS_H_
