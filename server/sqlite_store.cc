#include "server/sqlite_store.h"

#include <fcntl.h>
#include <sqlite3.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/time/clock.h"
#include "server/store_rows.h"

namespace radiosity::service {
namespace {

// The database's last error: RESOURCE_EXHAUSTED when the disk is full, else INTERNAL.
absl::Status DatabaseError(sqlite3* db) {
  std::string message = absl::StrCat("database: ", sqlite3_errmsg(db));
  const int code = sqlite3_errcode(db) & 0xff;
  if (code == SQLITE_FULL) return absl::ResourceExhaustedError(message);
  return absl::InternalError(message);
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

}  // namespace

// The schema's migrations, oldest first; migration k takes a database from version k to k + 1
// (PRAGMA user_version). Each can run on a database of before user_version was kept (version 0,
// whatever its tables), so they check what is there.
//   1: the scenes and jobs tables;
//   2: their tenant and bytes columns (rows of before tenants belong to no tenant, "", and their
//      bytes are read from the stored messages);
//   3: indexes by tenant and request id, and the meta table with the page tokens' key;
//   4: job leases (owner, lease_until in milliseconds since 1970, cancel_requested).
constexpr int kMigrations = 4;

int SqliteStore::LatestSchema() { return kMigrations; }

absl::StatusOr<std::unique_ptr<SqliteStore>> SqliteStore::Open(const std::string& path) {
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
  std::unique_ptr<SqliteStore> store(new SqliteStore(db, path));
  absl::Status st = store->Exec("PRAGMA journal_mode=WAL; PRAGMA synchronous=NORMAL;");
  if (st.ok()) st = store->Migrate();
  if (st.ok()) st = store->LoadPageKey();
  if (!st.ok()) return absl::Status(st.code(), absl::StrCat(path, ": ", st.message()));
  return store;
}

absl::Status SqliteStore::Migrate() {
  {
    Statement s(db_, "PRAGMA user_version");
    if (!s.status().ok()) return s.status();
    if (s.Step() != SQLITE_ROW) return s.Error();
    schema_ = static_cast<int>(s.Int(0));
  }
  if (schema_ > kMigrations) {
    return absl::FailedPreconditionError(absl::StrCat("the database is at schema version ", schema_,
                                                      ", written by a newer radiosity-server; "
                                                      "this one knows versions up to ",
                                                      kMigrations,
                                                      " (run the newer server, or restore a "
                                                      "backup)"));
  }
  while (schema_ < kMigrations) {
    const int next = schema_ + 1;
    absl::Status st = WriteTransactionLocked([&] {
      absl::Status applied = Apply(next);
      return applied.ok() ? Exec(absl::StrCat("PRAGMA user_version = ", next, ";")) : applied;
    });
    if (!st.ok()) {
      return absl::Status(st.code(), absl::StrCat("schema migration ", next, ": ", st.message()));
    }
    schema_ = next;
  }
  return absl::OkStatus();
}

absl::Status SqliteStore::Apply(int version) {
  switch (version) {
    case 1:
      return Exec(
          "CREATE TABLE IF NOT EXISTS scenes("
          "  seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT UNIQUE NOT NULL,"
          "  request_id TEXT NOT NULL, info BLOB NOT NULL);"
          "CREATE TABLE IF NOT EXISTS jobs("
          "  seq INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT UNIQUE NOT NULL, scene TEXT NOT NULL,"
          "  request_id TEXT NOT NULL, state INTEGER NOT NULL, info BLOB NOT NULL);"
          "CREATE INDEX IF NOT EXISTS jobs_state ON jobs(state);");
    case 2: {
      absl::StatusOr<bool> has = HasColumn("scenes", "tenant");
      if (!has.ok()) return has.status();
      if (*has) return absl::OkStatus();
      if (absl::Status st = Exec("ALTER TABLE scenes ADD COLUMN tenant TEXT NOT NULL DEFAULT '';"
                                 "ALTER TABLE scenes ADD COLUMN bytes INTEGER NOT NULL DEFAULT 0;"
                                 "ALTER TABLE jobs ADD COLUMN tenant TEXT NOT NULL DEFAULT '';"
                                 "ALTER TABLE jobs ADD COLUMN bytes INTEGER NOT NULL DEFAULT 0;");
          !st.ok()) {
        return st;
      }
      return FillBytes();
    }
    case 3:
      return Exec(
          "DROP INDEX IF EXISTS scenes_request;"
          "DROP INDEX IF EXISTS jobs_request;"
          "CREATE INDEX IF NOT EXISTS scenes_tenant ON scenes(tenant, request_id);"
          "CREATE INDEX IF NOT EXISTS jobs_tenant ON jobs(tenant, request_id);"
          "CREATE TABLE IF NOT EXISTS meta(key TEXT PRIMARY KEY, value BLOB);");
    case 4: {
      absl::StatusOr<bool> has = HasColumn("jobs", "owner");
      if (!has.ok()) return has.status();
      if (*has) return absl::OkStatus();
      return Exec(
          "ALTER TABLE jobs ADD COLUMN owner TEXT NOT NULL DEFAULT '';"
          "ALTER TABLE jobs ADD COLUMN lease_until INTEGER;"
          "ALTER TABLE jobs ADD COLUMN cancel_requested INTEGER NOT NULL DEFAULT 0;"
          "CREATE INDEX IF NOT EXISTS jobs_claimable ON jobs(seq) WHERE state IN (1, 2);");
    }
  }
  return absl::InternalError(absl::StrCat("no schema migration ", version));
}

// The page tokens' key: 16 random bytes made once, kept in the meta table.
absl::Status SqliteStore::LoadPageKey() {
  std::string key;
  {
    Statement s(db_, "SELECT value FROM meta WHERE key = 'page_key'");
    if (!s.status().ok()) return s.status();
    if (s.Step() == SQLITE_ROW) key = s.Blob(0);
  }
  if (key.size() != 16) {
    absl::StatusOr<std::string> made = PageTokens::NewKey();
    if (!made.ok()) return made.status();
    Statement s(db_, "INSERT OR REPLACE INTO meta(key, value) VALUES('page_key', ?)");
    if (!s.status().ok()) return s.status();
    s.BindBlob(1, *made);
    if (s.Step() != SQLITE_DONE) return s.Error();
    key = *made;
  }
  tokens_ = PageTokens(key);
  return absl::OkStatus();
}

absl::StatusOr<bool> SqliteStore::HasColumn(const char* table, const char* column) {
  Statement s(db_, absl::StrCat("PRAGMA table_info(", table, ")"));
  if (!s.status().ok()) return s.status();
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    if (s.Text(1) == column) return true;
  }
  if (rc != SQLITE_DONE) return s.Error();
  return false;
}

absl::Status SqliteStore::FillBytes() {
  std::vector<std::pair<std::string, int64_t>> scenes, jobs;
  {
    Statement s(db_, "SELECT id, info FROM scenes");
    if (!s.status().ok()) return s.status();
    int rc;
    while ((rc = s.Step()) == SQLITE_ROW) {
      absl::StatusOr<v1::SceneInfo> info = ParseRow<v1::SceneInfo>(s.Blob(1));
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
      absl::StatusOr<v1::Job> job = ParseRow<v1::Job>(s.Blob(1));
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

SqliteStore::~SqliteStore() {
  sqlite3_close(db_);
  if (claim_fd_ >= 0) close(claim_fd_);
}

bool SqliteStore::ServesReplicas() const { return false; }

absl::Status SqliteStore::ClaimExclusive() {
  std::lock_guard<std::mutex> lock(mu_);
  if (claim_fd_ >= 0) return absl::OkStatus();
  const std::string lock_path = path_ + ".lock";
  const int fd = open(lock_path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
  if (fd < 0) {
    return absl::InternalError(absl::StrCat(lock_path, ": cannot open: ", std::strerror(errno)));
  }
  if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
    close(fd);
    return absl::FailedPreconditionError(
        absl::StrCat(ToString(),
                     ": another radiosity-server uses this store (one server per store: this "
                     "version's workers do not share a queue)"));
  }
  claim_fd_ = fd;
  return absl::OkStatus();
}

absl::Status SqliteStore::Exec(const std::string& sql) {
  char* error = nullptr;
  const int rc = sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &error);
  if (rc == SQLITE_OK) return absl::OkStatus();
  const std::string message = absl::StrCat("database: ", error ? error : "unknown error");
  sqlite3_free(error);
  if ((rc & 0xff) == SQLITE_FULL) return absl::ResourceExhaustedError(message);
  return absl::InternalError(message);
}

template <typename Message>
absl::StatusOr<std::optional<Message>> SqliteStore::FindByRequestLocked(
    const char* table, const std::string& tenant, const std::string& request_id) {
  Statement s(db_, absl::StrCat("SELECT info FROM ", table,
                                " WHERE tenant = ? AND request_id = ? AND request_id <> ''"
                                " ORDER BY seq LIMIT 1"));
  if (!s.status().ok()) return s.status();
  s.Bind(1, tenant);
  s.Bind(2, request_id);
  int rc = s.Step();
  if (rc == SQLITE_DONE) return std::optional<Message>();
  if (rc != SQLITE_ROW) return s.Error();
  absl::StatusOr<Message> message = ParseRow<Message>(s.Blob(0));
  if (!message.ok()) return message.status();
  return std::optional<Message>(*std::move(message));
}

template <typename Message>
absl::StatusOr<std::optional<Message>> SqliteStore::InsertOnceLocked(
    const char* table, const Message& message, absl::FunctionRef<absl::Status()> insert) {
  if (message.request_id().empty()) {
    if (absl::Status st = insert(); !st.ok()) return st;
    return std::optional<Message>();
  }
  // The write lock taken first: the lookup and the insert see no other connection's insert
  // between them.
  absl::StatusOr<std::optional<Message>> found = std::optional<Message>();
  absl::Status st = WriteTransactionLocked([&] {
    found = FindByRequestLocked<Message>(table, message.tenant(), message.request_id());
    if (!found.ok()) return found.status();
    return found->has_value() ? absl::OkStatus() : insert();
  });
  if (!st.ok()) return st;
  return found;
}

absl::Status SqliteStore::WriteTransactionLocked(absl::FunctionRef<absl::Status()> body) {
  if (absl::Status st = Exec("BEGIN IMMEDIATE;"); !st.ok()) return st;
  absl::Status st = body();
  if (st.ok()) st = Exec("COMMIT;");
  // A failed body or COMMIT (a full disk) rolls back, so that the connection's next writes are
  // not made inside a transaction that never commits.
  if (!st.ok() && sqlite3_get_autocommit(db_) == 0) Exec("ROLLBACK;").IgnoreError();
  return st;
}

absl::StatusOr<std::optional<v1::SceneInfo>> SqliteStore::InsertScene(const std::string& id,
                                                                      const v1::SceneInfo& scene) {
  std::lock_guard<std::mutex> lock(mu_);
  return InsertOnceLocked<v1::SceneInfo>("scenes", scene, [&] {
    Statement s(db_,
                "INSERT INTO scenes(id, tenant, request_id, bytes, info) VALUES(?, ?, ?, ?, ?)");
    if (!s.status().ok()) return s.status();
    s.Bind(1, id);
    s.Bind(2, scene.tenant());
    s.Bind(3, scene.request_id());
    s.Bind(4, scene.total_size());
    s.BindBlob(5, scene.SerializeAsString());
    return s.Step() == SQLITE_DONE ? absl::OkStatus() : s.Error();
  });
}

absl::StatusOr<v1::SceneInfo> SqliteStore::GetScene(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "SELECT info FROM scenes WHERE id = ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  int rc = s.Step();
  if (rc == SQLITE_DONE) return absl::NotFoundError(absl::StrCat("scenes/", id, " does not exist"));
  if (rc != SQLITE_ROW) return s.Error();
  return ParseRow<v1::SceneInfo>(s.Blob(0));
}

absl::StatusOr<std::optional<v1::SceneInfo>> SqliteStore::FindSceneByRequest(
    const std::string& tenant, const std::string& request_id) {
  std::lock_guard<std::mutex> lock(mu_);
  return FindByRequestLocked<v1::SceneInfo>("scenes", tenant, request_id);
}

absl::StatusOr<v1::ListScenesResponse> SqliteStore::ListScenes(const std::string& tenant,
                                                               int page_size,
                                                               const std::string& page_token) {
  absl::StatusOr<int64_t> before = tokens_.Parse(tenant, page_token);
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
      response.set_next_page_token(tokens_.Make(tenant, last));
      break;
    }
    absl::StatusOr<v1::SceneInfo> info = ParseRow<v1::SceneInfo>(s.Blob(1));
    if (!info.ok()) return info.status();
    *response.add_scenes() = *std::move(info);
    last = s.Int(0);
  }
  if (rc != SQLITE_ROW && rc != SQLITE_DONE) return s.Error();
  return response;
}

absl::Status SqliteStore::DeleteScene(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "DELETE FROM scenes WHERE id = ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  if (s.Step() != SQLITE_DONE) return s.Error();
  return absl::OkStatus();
}

absl::StatusOr<std::optional<v1::Job>> SqliteStore::InsertJob(const std::string& id,
                                                              const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  return InsertOnceLocked<v1::Job>("jobs", job, [&] {
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
    return s.Step() == SQLITE_DONE ? absl::OkStatus() : s.Error();
  });
}

absl::Status SqliteStore::UpdateJob(const std::string& id, const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  // An ended job has no lease (a holder still running it finds it lost at its next renewal).
  Statement s(db_,
              "UPDATE jobs SET state = ?1, bytes = ?2, info = ?3,"
              " owner = CASE WHEN ?1 IN (1, 2) THEN owner ELSE '' END,"
              " lease_until = CASE WHEN ?1 IN (1, 2) THEN lease_until END WHERE id = ?4");
  if (!s.status().ok()) return s.status();
  s.Bind(1, static_cast<int64_t>(job.state()));
  s.Bind(2, ResultBytes(job));
  s.BindBlob(3, job.SerializeAsString());
  s.Bind(4, id);
  if (s.Step() != SQLITE_DONE) return s.Error();
  return absl::OkStatus();
}

absl::StatusOr<v1::Job> SqliteStore::GetJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "SELECT info FROM jobs WHERE id = ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  int rc = s.Step();
  if (rc == SQLITE_DONE) return absl::NotFoundError(absl::StrCat("jobs/", id, " does not exist"));
  if (rc != SQLITE_ROW) return s.Error();
  return ParseRow<v1::Job>(s.Blob(0));
}

absl::StatusOr<std::optional<v1::Job>> SqliteStore::FindJobByRequest(
    const std::string& tenant, const std::string& request_id) {
  std::lock_guard<std::mutex> lock(mu_);
  return FindByRequestLocked<v1::Job>("jobs", tenant, request_id);
}

absl::StatusOr<v1::ListJobsResponse> SqliteStore::ListJobs(const std::string& tenant,
                                                           const v1::ListJobsRequest& request) {
  absl::StatusOr<int64_t> before = tokens_.Parse(tenant, request.page_token());
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
      response.set_next_page_token(tokens_.Make(tenant, last));
      break;
    }
    absl::StatusOr<v1::Job> job = ParseRow<v1::Job>(s.Blob(1));
    if (!job.ok()) return job.status();
    *response.add_jobs() = *std::move(job);
    last = s.Int(0);
  }
  if (rc != SQLITE_ROW && rc != SQLITE_DONE) return s.Error();
  return response;
}

absl::StatusOr<std::vector<v1::SceneInfo>> SqliteStore::AllScenes() {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "SELECT info FROM scenes ORDER BY seq ASC");
  if (!s.status().ok()) return s.status();
  std::vector<v1::SceneInfo> scenes;
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    absl::StatusOr<v1::SceneInfo> scene = ParseRow<v1::SceneInfo>(s.Blob(0));
    if (!scene.ok()) return scene.status();
    scenes.push_back(*std::move(scene));
  }
  if (rc != SQLITE_DONE) return s.Error();
  return scenes;
}

absl::StatusOr<std::vector<v1::Job>> SqliteStore::JobsInStates(
    const std::vector<v1::JobState>& states) {
  std::string state_list = StateList(states);
  if (state_list.empty()) return std::vector<v1::Job>();
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, absl::StrCat("SELECT info FROM jobs WHERE state IN (", state_list,
                                ") ORDER BY seq ASC"));
  if (!s.status().ok()) return s.status();
  std::vector<v1::Job> jobs;
  int rc;
  while ((rc = s.Step()) == SQLITE_ROW) {
    absl::StatusOr<v1::Job> job = ParseRow<v1::Job>(s.Blob(0));
    if (!job.ok()) return job.status();
    jobs.push_back(*std::move(job));
  }
  if (rc != SQLITE_DONE) return s.Error();
  return jobs;
}

absl::StatusOr<int64_t> SqliteStore::CountJobs(const std::string& scene_name,
                                               const std::vector<v1::JobState>& states) {
  std::string state_list = StateList(states);
  std::lock_guard<std::mutex> lock(mu_);
  // "? = ''": every scene's jobs.
  std::string sql = "SELECT COUNT(*) FROM jobs WHERE (scene = ? OR ? = '')";
  if (!state_list.empty()) absl::StrAppend(&sql, " AND state IN (", state_list, ")");
  Statement s(db_, sql);
  if (!s.status().ok()) return s.status();
  s.Bind(1, scene_name);
  s.Bind(2, scene_name);
  if (s.Step() != SQLITE_ROW) return s.Error();
  return s.Int(0);
}

absl::StatusOr<TenantUsage> SqliteStore::Usage(const std::string& tenant) {
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

absl::StatusOr<int64_t> SqliteStore::TotalBytes() {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "SELECT (SELECT TOTAL(bytes) FROM scenes) + (SELECT TOTAL(bytes) FROM jobs)");
  if (!s.status().ok()) return s.status();
  if (s.Step() != SQLITE_ROW) return s.Error();
  return s.Int(0);
}

absl::Status SqliteStore::DeleteJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "DELETE FROM jobs WHERE id = ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  if (s.Step() != SQLITE_DONE) return s.Error();
  return absl::OkStatus();
}

namespace {

// The lease clock: milliseconds since 1970 on this machine (one machine shares an SQLite file).
int64_t NowMs() { return absl::ToUnixMillis(absl::Now()); }

}  // namespace

absl::StatusOr<std::optional<Store::Claim>> SqliteStore::ClaimJob(const std::string& owner,
                                                                  absl::Duration lease) {
  return ClaimOne(owner, lease, "");
}

absl::StatusOr<std::optional<Store::Claim>> SqliteStore::ClaimJobById(const std::string& id,
                                                                      const std::string& owner,
                                                                      absl::Duration lease) {
  return ClaimOne(owner, lease, id);
}

absl::StatusOr<std::optional<Store::Claim>> SqliteStore::ClaimOne(const std::string& owner,
                                                                  absl::Duration lease,
                                                                  const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  std::optional<Store::Claim> claim;
  absl::Status st = WriteTransactionLocked([&]() -> absl::Status {
    const int64_t now = NowMs();
    int64_t seq = 0;
    {
      Statement s(db_, absl::StrCat("SELECT seq, info, cancel_requested FROM jobs WHERE state IN "
                                    "(1, 2) AND (owner = '' OR lease_until IS NULL OR "
                                    "lease_until < ?)",
                                    id.empty() ? "" : " AND id = ?", " ORDER BY seq LIMIT 1"));
      if (!s.status().ok()) return s.status();
      s.Bind(1, now);
      if (!id.empty()) s.Bind(2, id);
      const int rc = s.Step();
      if (rc == SQLITE_DONE) return absl::OkStatus();
      if (rc != SQLITE_ROW) return s.Error();
      absl::StatusOr<v1::Job> job = ParseRow<v1::Job>(s.Blob(1));
      if (!job.ok()) return job.status();
      seq = s.Int(0);
      claim = Store::Claim{*std::move(job), s.Int(2) != 0};
    }
    Statement s(db_, "UPDATE jobs SET owner = ?, lease_until = ? WHERE seq = ?");
    if (!s.status().ok()) return s.status();
    s.Bind(1, owner);
    s.Bind(2, now + absl::ToInt64Milliseconds(lease));
    s.Bind(3, seq);
    return s.Step() == SQLITE_DONE ? absl::OkStatus() : s.Error();
  });
  if (!st.ok()) return st;
  return claim;
}

absl::StatusOr<bool> SqliteStore::RenewLease(const std::string& id, const std::string& owner,
                                             absl::Duration lease) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_,
              "UPDATE jobs SET lease_until = ? WHERE id = ? AND owner = ? AND state IN (1, 2)"
              " RETURNING cancel_requested");
  if (!s.status().ok()) return s.status();
  s.Bind(1, NowMs() + absl::ToInt64Milliseconds(lease));
  s.Bind(2, id);
  s.Bind(3, owner);
  const int rc = s.Step();
  if (rc == SQLITE_DONE) return LeaseLost(id, owner);
  if (rc != SQLITE_ROW) return s.Error();
  return s.Int(0) != 0;
}

absl::Status SqliteStore::UpdateLeasedJob(const std::string& id, const std::string& owner,
                                          const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_,
              "UPDATE jobs SET state = ?1, bytes = ?2, info = ?3,"
              " owner = CASE WHEN ?1 = 2 THEN owner ELSE '' END,"
              " lease_until = CASE WHEN ?1 = 2 THEN lease_until END"
              " WHERE id = ?4 AND owner = ?5 AND state IN (1, 2) RETURNING seq");
  if (!s.status().ok()) return s.status();
  s.Bind(1, static_cast<int64_t>(job.state()));
  s.Bind(2, ResultBytes(job));
  s.BindBlob(3, job.SerializeAsString());
  s.Bind(4, id);
  s.Bind(5, owner);
  const int rc = s.Step();
  if (rc == SQLITE_DONE) return LeaseLost(id, owner);
  if (rc != SQLITE_ROW) return s.Error();
  return absl::OkStatus();
}

absl::Status SqliteStore::RequestCancel(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_, "UPDATE jobs SET cancel_requested = 1 WHERE id = ? RETURNING seq");
  if (!s.status().ok()) return s.status();
  s.Bind(1, id);
  const int rc = s.Step();
  if (rc == SQLITE_DONE) return absl::NotFoundError(absl::StrCat("jobs/", id, " does not exist"));
  if (rc != SQLITE_ROW) return s.Error();
  return absl::OkStatus();
}

absl::StatusOr<int64_t> SqliteStore::CountLeased() {
  std::lock_guard<std::mutex> lock(mu_);
  Statement s(db_,
              "SELECT COUNT(*) FROM jobs WHERE state IN (1, 2) AND owner <> ''"
              " AND lease_until >= ?");
  if (!s.status().ok()) return s.status();
  s.Bind(1, NowMs());
  if (s.Step() != SQLITE_ROW) return s.Error();
  return s.Int(0);
}

}  // namespace radiosity::service
