#include "server/tenants.h"

#include <sys/stat.h>

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

// mtime (ns) and size of `path`, or an error.
absl::StatusOr<std::pair<int64_t, int64_t>> Stamp(const std::string& path) {
  struct stat st = {};
  if (stat(path.c_str(), &st) != 0) return WriteErrnoStatus(errno, path);
  return std::pair<int64_t, int64_t>(
      static_cast<int64_t>(st.st_mtim.tv_sec) * 1'000'000'000 + st.st_mtim.tv_nsec, st.st_size);
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
  absl::StatusOr<std::pair<int64_t, int64_t>> stamp = Stamp(path);
  if (!stamp.ok()) return absl::InvalidArgumentError(stamp.status().message());
  absl::StatusOr<std::string> text = ReadWholeFile(path);
  if (!text.ok()) return absl::InvalidArgumentError(text.status().message());
  absl::StatusOr<std::map<std::string, std::string>> tenants = Parse(path, *text);
  if (!tenants.ok()) return tenants.status();
  if (tenants->empty()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": no tokens (lines 'TOKEN TENANT')"));
  }
  table->tenants_ = *std::move(tenants);
  table->mtime_ns_ = stamp->first;
  table->size_ = stamp->second;
  table->checked_ = std::chrono::steady_clock::now();
  return table;
}

void TokenTable::ReloadIfChanged() {
  const auto now = std::chrono::steady_clock::now();
  if (now - checked_ < std::chrono::seconds(1)) return;
  checked_ = now;
  absl::StatusOr<std::pair<int64_t, int64_t>> stamp = Stamp(path_);
  if (!stamp.ok()) {
    LogLine("tokens_reload_failed").Str("error", stamp.status().message()).Error();
    return;
  }
  if (stamp->first == mtime_ns_ && stamp->second == size_) return;
  absl::StatusOr<std::string> text = ReadWholeFile(path_);
  absl::StatusOr<std::map<std::string, std::string>> tenants =
      text.ok() ? Parse(path_, *text) : text.status();
  if (!tenants.ok()) {
    // Retried at the next change of the file; until then the tokens read last stay.
    mtime_ns_ = stamp->first;
    size_ = stamp->second;
    LogLine("tokens_reload_failed")
        .Str("error", tenants.status().message())
        .Str("detail", "the tokens read before stay in use")
        .Error();
    return;
  }
  tenants_ = *std::move(tenants);
  mtime_ns_ = stamp->first;
  size_ = stamp->second;
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
                                         grpc::AuthContext* context,
                                         OutputMetadata* consumed_auth_metadata,
                                         OutputMetadata* /*response_metadata*/) {
  auto it = auth_metadata.find("authorization");
  if (it == auth_metadata.end()) return grpc::Status::OK;
  const absl::string_view value(it->second.data(), it->second.size());
  constexpr absl::string_view kBearer = "Bearer ";
  if (!absl::StartsWithIgnoreCase(value, kBearer)) {
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED,
                        "the authorization header is not 'Bearer TOKEN'");
  }
  const std::string tenant = tokens_->Lookup(std::string(value.substr(kBearer.size())));
  if (tenant.empty()) {
    return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, "unknown bearer token");
  }
  context->AddProperty(kTenantProperty, tenant);
  // The token goes no further than this check (handlers and logs never see it).
  consumed_auth_metadata->insert(
      std::make_pair(std::string(it->first.data(), it->first.size()), std::string(value)));
  return grpc::Status::OK;
}

absl::StatusOr<std::string> TenantOf(const grpc::CallbackServerContext& context,
                                     bool tokens_required) {
  if (!tokens_required) return std::string();
  std::shared_ptr<const grpc::AuthContext> auth = context.auth_context();
  if (auth) {
    std::vector<grpc::string_ref> values = auth->FindPropertyValues(kTenantProperty);
    if (!values.empty()) return std::string(values[0].data(), values[0].size());
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
    const int64_t unfinished = usage->unfinished_jobs + reserved_[tenant];
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
    return StoredBytesError("this server", *stored, bytes, quotas_.server_max_stored_bytes,
                            "--max-stored-mb");
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
