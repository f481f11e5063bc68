#include "server/tenants.h"

#include <sys/stat.h>

#include <cerrno>
#include <utility>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"
#include "proto/api/sha256.h"
#include "server/logging.h"
#include "solver/util/file_io.h"

namespace radiosity::service {
namespace {

constexpr size_t kMinTokenLength = 16;
constexpr size_t kMaxTokenLength = 4096;
constexpr size_t kMaxTenantLength = 64;

bool IsTokenChar(char c) {
  return absl::ascii_isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '~' ||
         c == '+' || c == '/' || c == '=' || c == '-';
}

bool IsTenantChar(char c) {
  return absl::ascii_isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-';
}

bool AllOf(absl::string_view s, bool (*ok)(char)) {
  for (char c : s) {
    if (!ok(c)) return false;
  }
  return true;
}

// What tells that `path` changed: modification and change times (ns), size and inode (a file
// replaced by a rename, or rewritten with its mtime restored, still changes one of them).
absl::StatusOr<std::array<int64_t, 4>> Stamp(const std::string& path) {
  struct stat st = {};
  if (stat(path.c_str(), &st) != 0) return WriteErrnoStatus(errno, path + ": ");
  auto ns = [](const struct timespec& t) {
    return static_cast<int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
  };
  return std::array<int64_t, 4>{ns(st.st_mtim), ns(st.st_ctim), static_cast<int64_t>(st.st_size),
                                static_cast<int64_t>(st.st_ino)};
}

// The token of an "authorization" value ("Bearer TOKEN", the scheme in any case), or empty.
std::string BearerToken(absl::string_view value) {
  constexpr absl::string_view kBearer = "Bearer ";
  if (!absl::StartsWithIgnoreCase(value, kBearer)) return std::string();
  return std::string(value.substr(kBearer.size()));
}

// `who` stores `stored` bytes and `more` (0: a job's results to come) would pass `limit`.
absl::Status StoredBytesError(const char* who, int64_t stored, int64_t more, int64_t limit,
                              const char* flag) {
  const std::string what =
      more == 0 ? std::string(", at or past") : absl::StrCat("; ", more, " more would pass");
  return absl::ResourceExhaustedError(
      absl::StrCat(who, " stores ", stored, " bytes of scenes and results", what, " its limit of ",
                   limit, " bytes (", flag, "); delete scenes or jobs to make room"));
}

}  // namespace

absl::StatusOr<std::map<std::string, std::string>> TokenTable::Parse(const std::string& path,
                                                                     const std::string& text) {
  std::map<std::string, std::string> tenants;
  int line_number = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_number;
    if (size_t hash = line.find('#'); hash != absl::string_view::npos) line = line.substr(0, hash);
    std::vector<absl::string_view> fields =
        absl::StrSplit(line, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (fields.empty()) continue;
    const std::string where = absl::StrCat(path, ":", line_number, ": ");
    if (fields.size() != 2) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "expected 'TOKEN TENANT', found ", fields.size(), " fields"));
    }
    const absl::string_view token = fields[0], tenant = fields[1];
    if (token.size() < kMinTokenLength || token.size() > kMaxTokenLength ||
        !AllOf(token, IsTokenChar)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "a token must be ", kMinTokenLength, " to ", kMaxTokenLength,
                       " characters of A-Z a-z 0-9 . _ ~ + / = - (e.g. `openssl rand -hex 32`)"));
    }
    if (tenant.size() > kMaxTenantLength || !AllOf(tenant, IsTenantChar)) {
      return absl::InvalidArgumentError(absl::StrCat(where, "tenant '", tenant, "': 1 to ",
                                                     kMaxTenantLength,
                                                     " characters of A-Z a-z 0-9 . _ -"));
    }
    auto [it, inserted] = tenants.emplace(Sha256Hex(token), std::string(tenant));
    if (!inserted && it->second != tenant) {
      return absl::InvalidArgumentError(absl::StrCat(where, "this token is given to two tenants ('",
                                                     it->second, "' and '", tenant, "')"));
    }
  }
  return tenants;
}

absl::StatusOr<std::unique_ptr<TokenTable>> TokenTable::Open(const std::string& path) {
  std::unique_ptr<TokenTable> table(new TokenTable(path));
  absl::StatusOr<std::array<int64_t, 4>> stamp = Stamp(path);
  if (!stamp.ok()) return absl::InvalidArgumentError(stamp.status().message());
  absl::StatusOr<std::string> text = ReadWholeFile(path);
  if (!text.ok()) return absl::InvalidArgumentError(text.status().message());
  absl::StatusOr<std::map<std::string, std::string>> tenants = Parse(path, *text);
  if (!tenants.ok()) return tenants.status();
  if (tenants->empty()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": no tokens (lines 'TOKEN TENANT')"));
  }
  table->tenants_ = *std::move(tenants);
  table->stamp_ = *stamp;
  table->checked_ = std::chrono::steady_clock::now();
  return table;
}

void TokenTable::ReloadIfChanged() {
  const auto now = std::chrono::steady_clock::now();
  if (now - checked_ < std::chrono::seconds(1)) return;
  checked_ = now;
  absl::StatusOr<std::array<int64_t, 4>> stamp = Stamp(path_);
  if (!stamp.ok()) {
    LogLine("tokens_reload_failed").Str("error", stamp.status().message()).Error();
    return;
  }
  if (*stamp == stamp_) return;
  absl::StatusOr<std::string> text = ReadWholeFile(path_);
  absl::StatusOr<std::map<std::string, std::string>> tenants =
      text.ok() ? Parse(path_, *text) : text.status();
  if (!tenants.ok()) {
    // Retried at the next change of the file; until then the tokens read last stay.
    stamp_ = *stamp;
    LogLine("tokens_reload_failed")
        .Str("error", tenants.status().message())
        .Str("detail", "the tokens read before stay in use")
        .Error();
    return;
  }
  tenants_ = *std::move(tenants);
  stamp_ = *stamp;
  LogLine("tokens_reloaded").Int("tokens", static_cast<int64_t>(tenants_.size())).Info();
}

std::string TokenTable::Lookup(const std::string& token) {
  const std::string key = Sha256Hex(token);
  std::lock_guard<std::mutex> lock(mu_);
  ReloadIfChanged();
  auto it = tenants_.find(key);
  return it == tenants_.end() ? std::string() : it->second;
}

grpc::Status TokenAuthProcessor::Process(const InputMetadata& auth_metadata,
                                         grpc::AuthContext* /*context*/,
                                         OutputMetadata* /*consumed_auth_metadata*/,
                                         OutputMetadata* /*response_metadata*/) {
  // Nothing is recorded in the AuthContext: it is the connection's, shared by its calls.
  const size_t count = auth_metadata.count("authorization");
  if (count == 0) return grpc::Status::OK;
  if (count > 1) {
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, "more than one authorization header");
  }
  const grpc::string_ref value = auth_metadata.find("authorization")->second;
  const std::string token = BearerToken(absl::string_view(value.data(), value.size()));
  if (token.empty()) {
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED,
                        "the authorization header is not 'Bearer TOKEN'");
  }
  if (tokens_->Lookup(token).empty()) {
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, "unknown bearer token");
  }
  return grpc::Status::OK;
}

absl::StatusOr<std::string> TenantOf(const grpc::CallbackServerContext& context,
                                     TokenTable* tokens) {
  if (!tokens) return std::string();
  const auto& metadata = context.client_metadata();
  const size_t count = metadata.count("authorization");
  if (count > 1) return absl::UnauthenticatedError("more than one authorization header");
  if (count == 1) {
    const grpc::string_ref value = metadata.find("authorization")->second;
    const std::string token = BearerToken(absl::string_view(value.data(), value.size()));
    // Looked up again: the token may have been revoked since the processor saw it.
    std::string tenant = token.empty() ? std::string() : tokens->Lookup(token);
    if (!tenant.empty()) return tenant;
    return absl::UnauthenticatedError("unknown bearer token");
  }
  return absl::UnauthenticatedError(
      "this server requires a bearer token (metadata 'authorization: Bearer TOKEN'; the CLI's "
      "--token-file or RADIOSITY_TOKEN)");
}

QuotaKeeper::Reservation::~Reservation() {
  if (!keeper_) return;
  std::lock_guard<std::mutex> lock(keeper_->mu_);
  if (--keeper_->reserved_[tenant_] <= 0) keeper_->reserved_.erase(tenant_);
}

absl::StatusOr<QuotaKeeper::Reservation> QuotaKeeper::ReserveJob(const std::string& tenant) {
  std::lock_guard<std::mutex> lock(mu_);
  if (absl::Status st = CheckServerLocked(0); !st.ok()) return st;
  if (quotas_.max_unfinished_jobs > 0 || quotas_.max_stored_bytes > 0) {
    absl::StatusOr<TenantUsage> usage = store_->Usage(tenant);
    if (!usage.ok()) return usage.status();
    auto reserved = reserved_.find(tenant);
    const int64_t unfinished =
        usage->unfinished_jobs + (reserved == reserved_.end() ? 0 : reserved->second);
    if (quotas_.max_unfinished_jobs > 0 && unfinished >= quotas_.max_unfinished_jobs) {
      return absl::ResourceExhaustedError(absl::StrCat("this tenant has ", unfinished,
                                                       " jobs queued or running, its quota "
                                                       "(--tenant-max-jobs ",
                                                       quotas_.max_unfinished_jobs,
                                                       "); retry when one has ended"));
    }
    if (quotas_.max_stored_bytes > 0 && usage->stored_bytes >= quotas_.max_stored_bytes) {
      return StoredBytesError("this tenant", usage->stored_bytes, 0, quotas_.max_stored_bytes,
                              "--tenant-max-stored-mb");
    }
  }
  ++reserved_[tenant];
  return Reservation(this, tenant);
}

absl::Status QuotaKeeper::CheckServerLocked(int64_t bytes) {
  if (quotas_.server_max_stored_bytes <= 0) return absl::OkStatus();
  absl::StatusOr<int64_t> stored = store_->TotalBytes();
  if (!stored.ok()) return stored.status();
  // A job adds results: refused once the server is full; an upload: if it would pass the cap.
  if (bytes == 0 ? *stored >= quotas_.server_max_stored_bytes
                 : *stored + bytes > quotas_.server_max_stored_bytes) {
    // No figures: they would tell one tenant what the others store.
    return absl::ResourceExhaustedError(
        "this server has no room for more scenes and results (--max-stored-mb); delete scenes or "
        "jobs, or ask the operator for room");
  }
  return absl::OkStatus();
}

absl::Status QuotaKeeper::CheckStore(const std::string& tenant, int64_t bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  if (absl::Status st = CheckServerLocked(bytes); !st.ok()) return st;
  if (quotas_.max_stored_bytes <= 0) return absl::OkStatus();
  absl::StatusOr<TenantUsage> usage = store_->Usage(tenant);
  if (!usage.ok()) return usage.status();
  if (usage->stored_bytes + bytes > quotas_.max_stored_bytes) {
    return StoredBytesError("this tenant", usage->stored_bytes, bytes, quotas_.max_stored_bytes,
                            "--tenant-max-stored-mb");
  }
  return absl::OkStatus();
}

}  // namespace radiosity::service
