#include "server/store.h"

#include <openssl/evp.h>
#include <openssl/rand.h>
#include <sqlite3.h>

#include <algorithm>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/escaping.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "proto/api/sha256.h"

namespace radiosity::service {
namespace {

constexpr int kDefaultPageSize = 50;
constexpr int kMaxPageSize = 1000;

// The database's last error: RESOURCE_EXHAUSTED when the disk is full, else INTERNAL.
absl::Status DatabaseError(sqlite3* db) {
  std::string message = absl::StrCat("database: ", sqlite3_errmsg(db));
  const int code = sqlite3_errcode(db) & 0xff;
  if (code == SQLITE_FULL) return absl::ResourceExhaustedError(message);
  return absl::InternalError(message);
}

int PageSize(int requested) {
  if (requested <= 0) return kDefaultPageSize;
  return requested > kMaxPageSize ? kMaxPageSize : requested;
}

// A prepared statement, finalized on destruction.
class Statement {
 public:
  Statement(sqlite3* db, const std::string& sql) : db_(db) {
    rc_ = sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt_, nullptr);
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  absl::Status status() const {
    if (rc_ == SQLITE_OK) return absl::OkStatus();
    return DatabaseError(db_);
  }
  void Bind(int i, const std::string& text) {
    sqlite3_bind_text(stmt_, i, text.data(), static_cast<int>(text.size()), SQLITE_TRANSIENT);
  }
  void BindBlob(int i, const std::string& blob) {
    sqlite3_bind_blob(stmt_, i, blob.data(), static_cast<int>(blob.size()), SQLITE_TRANSIENT);
  }
  void Bind(int i, int64_t value) { sqlite3_bind_int64(stmt_, i, value); }
  // SQLITE_ROW, SQLITE_DONE or an error code.
  int Step() { return sqlite3_step(stmt_); }
  std::string Blob(int column) const {
    const void* data = sqlite3_column_blob(stmt_, column);
    int size = sqlite3_column_bytes(stmt_, column);
    return data ? std::string(static_cast<const char*>(data), static_cast<size_t>(size)) : "";
  }
  std::string Text(int column) const { return Blob(column); }
  int64_t Int(int column) const { return sqlite3_column_int64(stmt_, column); }
  absl::Status Error() const { return DatabaseError(db_); }

 private:
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
  int rc_;
};

template <typename Message>
absl::StatusOr<Message> Parse(const std::string& blob) {
  Message m;
  if (!m.ParseFromString(blob)) return absl::InternalError("database: a stored row is corrupt");
  return m;
}

// A tenant's tag in its page tokens: the first 8 bytes of SHA-256(tenant).
uint64_t TenantTag(const std::string& tenant) {
  const std::string bytes = absl::HexStringToBytes(Sha256Hex(tenant).substr(0, 16));
  uint64_t tag = 0;
  for (unsigned char c : bytes) tag = tag << 8 | c;
  return tag;
}

// One AES-128 block (a pseudo-random permutation of 16 bytes) with the store's page key.
bool AesBlock(const std::string& key, bool encrypt, const unsigned char in[16],
              unsigned char out[16]) {
  EVP_CIPHER_CTX* ctx = EVP_CIPHER_CTX_new();
  if (ctx == nullptr) return false;
  int n = 0, m = 0;
  const auto* k = reinterpret_cast<const unsigned char*>(key.data());
  const bool ok =
      EVP_CipherInit_ex(ctx, EVP_aes_128_ecb(), nullptr, k, nullptr, encrypt ? 1 : 0) == 1 &&
      EVP_CIPHER_CTX_set_padding(ctx, 0) == 1 && EVP_CipherUpdate(ctx, out, &n, in, 16) == 1 &&
      EVP_CipherFinal_ex(ctx, out + n, &m) == 1 && n + m == 16;
  EVP_CIPHER_CTX_free(ctx);
  return ok;
}

}  // namespace

// "seq < N" paging. The token seals the last row's sequence number and the tenant's tag in one
// AES block under a key kept in the database: row numbers are global, so a plain number would
// tell a tenant how many rows others created between its pages; sealed, a token says nothing,
// works across restarts, and is refused for another tenant.
std::string Store::MakeToken(const std::string& tenant, int64_t seq) const {
  unsigned char in[16], out[16];
  const uint64_t tag = TenantTag(tenant);
  for (int i = 0; i < 8; ++i) {
    in[i] = static_cast<unsigned char>(static_cast<uint64_t>(seq) >> (8 * i));
    in[8 + i] = static_cast<unsigned char>(tag >> (8 * i));
  }
  if (!AesBlock(page_key_, true, in, out)) return absl::StrCat(seq);  // Not reached.
  return absl::BytesToHexString(absl::string_view(reinterpret_cast<const char*>(out), sizeof(out)));
}

absl::StatusOr<int64_t> Store::ParseToken(const std::string& tenant,
                                          const std::string& token) const {
  if (token.empty()) return INT64_MAX;
  const auto invalid = [&] {
    return absl::InvalidArgumentError(
        absl::StrCat("page_token '", token.substr(0, 64), token.size() > 64 ? "...' " : "' ",
                     "is not valid: pass the next_page_token of a previous list call, unchanged"));
  };
  if (token.size() != 32 || !std::all_of(token.begin(), token.end(), [](char c) {
        return absl::ascii_isdigit(c) || (c >= 'a' && c <= 'f');
      })) {
    return invalid();
  }
  const std::string bytes = absl::HexStringToBytes(token);
  unsigned char out[16];
  if (!AesBlock(page_key_, false, reinterpret_cast<const unsigned char*>(bytes.data()), out)) {
    return invalid();
  }
  uint64_t seq = 0, tag = 0;
  for (int i = 7; i >= 0; --i) {
    seq = seq << 8 | out[i];
    tag = tag << 8 | out[8 + i];
  }
  if (tag != TenantTag(tenant) || seq == 0 || seq > static_cast<uint64_t>(INT64_MAX)) {
    return invalid();
  }
  return static_cast<int64_t>(seq);
}

namespace {

std::string StateList(const std::vector<v1::JobState>& states) {
  std::vector<int> codes;
  for (v1::JobState s : states) {
    if (s != v1::JOB_STATE_UNSPECIFIED) codes.push_back(static_cast<int>(s));
  }
  return absl::StrJoin(codes, ",");
}

// Bytes a job's results take (what counts towards its tenant's stored bytes).
int64_t ResultBytes(const v1::Job& job) {
  int64_t bytes = 0;
  for (const v1::FileInfo& f : job.results()) bytes += f.size();
  return bytes;
}

}  // namespace

absl::StatusOr<std::unique_ptr<Store>> Store::Open(const std::string& path) {
  sqlite3* db = nullptr;
  int rc =
      sqlite3_open_v2(path.c_str(), &db,
                      SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX, nullptr);
  if (rc != SQLITE_OK) {
    std::string message = db ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    return absl::InternalError(absl::StrCat(path, ": cannot open the database: ", message));
  }
  sqlite3_busy_timeout(db, 5000);
  std::unique_ptr<Store> store(new Store(db));
  absl::Status st = store->Exec(
      "PRAGMA journal_mode=WAL;"
      "PRAGMA synchronous=NORMAL;"
      "CREATE TABLE IF NOT EXISTS scenes("
      "  seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT UNIQUE NOT NULL,"
      "  request_id TEXT NOT NULL, info BLOB NOT NULL);"
      "CREATE TABLE IF NOT EXISTS jobs("
      "  seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT UNIQUE NOT NULL, scene TEXT NOT NULL,"
      "  request_id TEXT NOT NULL, state INTEGER NOT NULL, info BLOB NOT NULL);"
      "CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state);");
  if (st.ok()) st = store->Migrate();
  if (st.ok()) st = store->LoadPageKey();
  if (!st.ok()) return absl::InternalError(absl::StrCat(path, ": ", st.message()));
  return store;
}

// The page tokens' key: 16 random bytes made once, kept in the meta table.
absl::Status Store::LoadPageKey() {
  if (absl::Status st = Exec("CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value BLOB);");
      !st.ok()) {
    return st;
  }
  {
    Statement s(db_, "SELECT value FROM meta WHERE key = 'page_key'");
    if (!s.status().ok()) return s.status();
    if (s.Step() == SQLITE_ROW) page_key_ = s.Blob(0);
  }
  if (page_key_.size() == 16) return absl::OkStatus();
  std::string key(16, '\0');
  if (RAND_bytes(reinterpret_cast<unsigned char*>(key.data()), 16) != 1) {
    return absl::InternalError("cannot make a page-token key: no randomness");
  }
  Statement s(db_, "INSERT OR REPLACE INTO meta(key, value) VALUES('page_key', ?)");
  if (!s.status().ok()) return s.status();
  s.BindBlob(1, key);
  if (s.Step() != SQLITE_DONE) return s.Error();
  page_key_ = key;
  return absl::OkStatus();
}

absl::StatusOr<bool> Store::HasColumn(const char* table, const char* column) {
  Statement s(db_, absl::StrCat("PRAGMA table_info(", table, ")"));
  if (!s.status().ok()) return s.status();
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    if (s.Text(1) == column) return true;
  }
  if (rc != SQLITE_DONE) return s.Error();
  return false;
}

// Databases written before tenants had no `tenant` and `bytes` columns: they are added (their
// rows belong to no tenant, "") and the bytes filled in from the stored messages, in one
// transaction.
absl::Status Store::Migrate() {
  absl::StatusOr<bool> has = HasColumn("scenes", "tenant");
  if (!has.ok()) return has.status();
  if (!*has) {
    if (absl::Status st = Exec("BEGIN IMMEDIATE;"
                               "ALTER TABLE scenes ADD COLUMN tenant TEXT NOT NULL DEFAULT '';"
                               "ALTER TABLE scenes ADD COLUMN bytes INTEGER NOT NULL DEFAULT 0;"
                               "ALTER TABLE jobs ADD COLUMN tenant TEXT NOT NULL DEFAULT '';"
                               "ALTER TABLE jobs ADD COLUMN bytes INTEGER NOT NULL DEFAULT 0;");
        !st.ok()) {
      return st;
    }
    absl::Status st = FillBytes();
    if (absl::Status end = Exec(st.ok() ? "COMMIT;" : "ROLLBACK;"); st.ok()) st = end;
    if (!st.ok()) return st;
  }
  return Exec(
      "DROP INDEX IF EXISTS scenes_request;"
      "DROP INDEX IF EXISTS jobs_request;"
      "CREATE INDEX IF NOT EXISTS scenes_tenant ON scenes(tenant, request_id);"
      "CREATE INDEX IF NOT EXISTS jobs_tenant ON jobs(tenant, request_id);");
}

absl::Status Store::FillBytes() {
  std::vector<std::pair<std::string, int64_t>> scenes, jobs;
  {
    Statement s(db_, "SELECT id, info FROM scenes");
    if (!s.status().ok()) return s.status();
    int rc;
    while ((rc = s.Step()) == SQLITE_ROW) {
      absl::StatusOr<v1::SceneInfo> info = Parse<v1::SceneInfo>(s.Blob(1));
      if (!info.ok()) return info.status();
      scenes.emplace_back(s.Text(0), info->total_size());
    }
    if (rc != SQLITE_DONE) return s.Error();
  }
  {
    Statement s(db_, "SELECT id, info FROM jobs");
    if (!s.status().ok()) return s.status();
    int rc;
    while ((rc = s.Step()) == SQLITE_ROW) {
      absl::StatusOr<v1::Job> job = Parse<v1::Job>(s.Blob(1));
      if (!job.ok()) return job.status();
      jobs.emplace_back(s.Text(0), ResultBytes(*job));
    }
    if (rc != SQLITE_DONE) return s.Error();
  }
  for (const auto& [table, rows] : {std::pair{"scenes", &scenes}, std::pair{"jobs", &jobs}}) {
    for (const auto& [id, bytes] : *rows) {
      Statement s(db_, absl::StrCat("UPDATE ", table, " SET bytes = ? WHERE id = ?"));
      if (!s.status().ok()) return s.status();
      s.Bind(1, bytes);
      s.Bind(2, id);
      if (s.Step() != SQLITE_DONE) return s.Error();
    }
  }
  return absl::OkStatus();
}

Store::~Store() { sqlite3_close(db_); }

absl::Status Store::Exec(const std::string& sql) {
  char* error = nullptr;
  if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &error) != SQLITE_OK) {
    std::string message = error ? error : "unknown error";
    sqlite3_free(error);
    return absl::InternalError(absl::StrCat("database: ", message));
  }
  return absl::OkStatus();
}

template <typename Message>
absl::StatusOr<std::optional<Message>> Store::FindByRequestLocked(const char* table,
                                                                  const std::string& tenant,
                                                                  const std::string& request_id) {
  Statement s(db_, absl::StrCat("SELECT info FROM ", table,
                                " WHERE tenant = ? AND request_id = ? AND request_id <> ''"
                                " ORDER BY seq LIMIT 1"));
  if (!s.status().ok()) return s.status();
  s.Bind(1, tenant);
  s.Bind(2, request_id);
  int rc = s.Step();
  if (rc == SQLITE_DONE) return std::optional<Message>();
  if (rc != SQLITE_ROW) return s.Error();
  absl::StatusOr<Message> message = Parse<Message>(s.Blob(0));
  if (!message.ok()) return message.status();
  return std::optional<Message>(*std::move(message));
}

absl::StatusOr<std::optional<v1::SceneInfo>> Store::InsertScene(const std::string& id,
                                                                const v1::SceneInfo& scene) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!scene.request_id().empty()) {
    absl::StatusOr<std::optional<v1::SceneInfo>> existing =
        FindByRequestLocked<v1::SceneInfo>("scenes", scene.tenant(), scene.request_id());
    if (!existing.ok() || existing->has_value()) return existing;
  }
  Statement s(db_, "INSERT INTO scenes(id, tenant, request_id, bytes, info) VALUES(?, ?, ?, ?, ?)");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  s.Bind(2, scene.tenant());
  s.Bind(3, scene.request_id());
  s.Bind(4, scene.total_size());
  s.BindBlob(5, scene.SerializeAsString());
  if (s.Step() != SQLITE_DONE) return s.Error();
  return std::optional<v1::SceneInfo>();
}

absl::StatusOr<v1::SceneInfo> Store::GetScene(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "SELECT info FROM scenes WHERE id = ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  int rc = s.Step();
  if (rc == SQLITE_DONE) return absl::NotFoundError(absl::StrCat("scenes/", id, " does not exist"));
  if (rc != SQLITE_ROW) return s.Error();
  return Parse<v1::SceneInfo>(s.Blob(0));
}

absl::StatusOr<std::optional<v1::SceneInfo>> Store::FindSceneByRequest(
    const std::string& tenant, const std::string& request_id) {
  std::lock_guard<std::mutex> lock(mu_);
  return FindByRequestLocked<v1::SceneInfo>("scenes", tenant, request_id);
}

absl::StatusOr<v1::ListScenesResponse> Store::ListScenes(const std::string& tenant, int page_size,
                                                         const std::string& page_token) {
  absl::StatusOr<int64_t> before = ParseToken(tenant, page_token);
  if (!before.ok()) return before.status();
  const int limit = PageSize(page_size);
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(
      db_, "SELECT seq, info FROM scenes WHERE tenant = ? AND seq < ? ORDER BY seq DESC LIMIT ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, tenant);
  s.Bind(2, *before);
  s.Bind(3, static_cast<int64_t>(limit + 1));
  v1::ListScenesResponse response;
  int64_t last = 0;
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    if (response.scenes_size() == limit) {
      response.set_next_page_token(MakeToken(tenant, last));
      break;
    }
    absl::StatusOr<v1::SceneInfo> info = Parse<v1::SceneInfo>(s.Blob(1));
    if (!info.ok()) return info.status();
    *response.add_scenes() = *std::move(info);
    last = s.Int(0);
  }
  if (rc != SQLITE_ROW && rc != SQLITE_DONE) return s.Error();
  return response;
}

absl::Status Store::DeleteScene(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "DELETE FROM scenes WHERE id = ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  if (s.Step() != SQLITE_DONE) return s.Error();
  return absl::OkStatus();
}

absl::StatusOr<std::optional<v1::Job>> Store::InsertJob(const std::string& id, const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  if (!job.request_id().empty()) {
    absl::StatusOr<std::optional<v1::Job>> existing =
        FindByRequestLocked<v1::Job>("jobs", job.tenant(), job.request_id());
    if (!existing.ok() || existing->has_value()) return existing;
  }
  Statement s(db_,
              "INSERT INTO jobs(id, scene, tenant, request_id, state, bytes, info)"
              " VALUES(?, ?, ?, ?, ?, ?, ?)");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  s.Bind(2, job.scene());
  s.Bind(3, job.tenant());
  s.Bind(4, job.request_id());
  s.Bind(5, static_cast<int64_t>(job.state()));
  s.Bind(6, ResultBytes(job));
  s.BindBlob(7, job.SerializeAsString());
  if (s.Step() != SQLITE_DONE) return s.Error();
  return std::optional<v1::Job>();
}

absl::Status Store::UpdateJob(const std::string& id, const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "UPDATE jobs SET state = ?, bytes = ?, info = ? WHERE id = ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, static_cast<int64_t>(job.state()));
  s.Bind(2, ResultBytes(job));
  s.BindBlob(3, job.SerializeAsString());
  s.Bind(4, id);
  if (s.Step() != SQLITE_DONE) return s.Error();
  return absl::OkStatus();
}

absl::StatusOr<v1::Job> Store::GetJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "SELECT info FROM jobs WHERE id = ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  int rc = s.Step();
  if (rc == SQLITE_DONE) return absl::NotFoundError(absl::StrCat("jobs/", id, " does not exist"));
  if (rc != SQLITE_ROW) return s.Error();
  return Parse<v1::Job>(s.Blob(0));
}

absl::StatusOr<std::optional<v1::Job>> Store::FindJobByRequest(const std::string& tenant,
                                                               const std::string& request_id) {
  std::lock_guard<std::mutex> lock(mu_);
  return FindByRequestLocked<v1::Job>("jobs", tenant, request_id);
}

absl::StatusOr<v1::ListJobsResponse> Store::ListJobs(const std::string& tenant,
                                                     const v1::ListJobsRequest& request) {
  absl::StatusOr<int64_t> before = ParseToken(tenant, request.page_token());
  if (!before.ok()) return before.status();
  const int limit = PageSize(request.page_size());
  std::vector<v1::JobState> states;
  for (int s : request.states()) states.push_back(static_cast<v1::JobState>(s));
  std::string sql = "SELECT seq, info FROM jobs WHERE tenant = ? AND seq < ?";
  std::string state_list = StateList(states);
  if (!state_list.empty()) absl::StrAppend(&sql, " AND state IN (", state_list, ")");
  if (!request.scene().empty()) sql += " AND scene = ?";
  sql += " ORDER BY seq DESC LIMIT ?";
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, sql);
  if (!s.status().ok()) return s.status();
  int i = 1;
  s.Bind(i++, tenant);
  s.Bind(i++, *before);
  if (!request.scene().empty()) s.Bind(i++, request.scene());
  s.Bind(i++, static_cast<int64_t>(limit + 1));
  v1::ListJobsResponse response;
  int64_t last = 0;
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    if (response.jobs_size() == limit) {
      response.set_next_page_token(MakeToken(tenant, last));
      break;
    }
    absl::StatusOr<v1::Job> job = Parse<v1::Job>(s.Blob(1));
    if (!job.ok()) return job.status();
    *response.add_jobs() = *std::move(job);
    last = s.Int(0);
  }
  if (rc != SQLITE_ROW && rc != SQLITE_DONE) return s.Error();
  return response;
}

absl::StatusOr<std::vector<v1::Job>> Store::JobsInStates(const std::vector<v1::JobState>& states) {
  std::string state_list = StateList(states);
  if (state_list.empty()) return std::vector<v1::Job>();
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, absl::StrCat("SELECT info FROM jobs WHERE state IN (", state_list,
                                ") ORDER BY seq ASC"));
  if (!s.status().ok()) return s.status();
  std::vector<v1::Job> jobs;
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    absl::StatusOr<v1::Job> job = Parse<v1::Job>(s.Blob(0));
    if (!job.ok()) return job.status();
    jobs.push_back(*std::move(job));
  }
  if (rc != SQLITE_DONE) return s.Error();
  return jobs;
}

absl::StatusOr<int64_t> Store::CountJobs(const std::string& scene_name,
                                         const std::vector<v1::JobState>& states) {
  std::string state_list = StateList(states);
  std::lock_guard<std::mutex> lock(mu_);
  std::string sql = "SELECT COUNT(*) FROM jobs WHERE scene = ?";
  if (!state_list.empty()) absl::StrAppend(&sql, " AND state IN (", state_list, ")");
  Statement s(db_, sql);
  if (!s.status().ok()) return s.status();
  s.Bind(1, scene_name);
  if (s.Step() != SQLITE_ROW) return s.Error();
  return s.Int(0);
}

absl::StatusOr<TenantUsage> Store::Usage(const std::string& tenant) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_,
              absl::StrCat("SELECT (SELECT COUNT(*) FROM jobs WHERE tenant = ?1 AND state IN (",
                           StateList({v1::JOB_STATE_QUEUED, v1::JOB_STATE_RUNNING}),
                           ")), (SELECT TOTAL(bytes) FROM scenes WHERE tenant = ?1)"
                           " + (SELECT TOTAL(bytes) FROM jobs WHERE tenant = ?1)"));
  if (!s.status().ok()) return s.status();
  s.Bind(1, tenant);
  if (s.Step() != SQLITE_ROW) return s.Error();
  TenantUsage usage;
  usage.unfinished_jobs = s.Int(0);
  usage.stored_bytes = s.Int(1);
  return usage;
}

absl::StatusOr<int64_t> Store::TotalBytes() {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "SELECT (SELECT TOTAL(bytes) FROM scenes) + (SELECT TOTAL(bytes) FROM jobs)");
  if (!s.status().ok()) return s.status();
  if (s.Step() != SQLITE_ROW) return s.Error();
  return s.Int(0);
}

absl::Status Store::DeleteJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "DELETE FROM jobs WHERE id = ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  if (s.Step() != SQLITE_DONE) return s.Error();
  return absl::OkStatus();
}

}  // namespace radiosity::service
