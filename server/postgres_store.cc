#include "server/postgres_store.h"

#include <libpq-fe.h>

#include <chrono>
#include <thread>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "server/store_rows.h"
#include "spdlog/spdlog.h"

namespace radiosity::service {

// A query's result, in binary: bigint columns as 8 big-endian bytes, bytea and text as bytes.
class PostgresStore::Rows {
 public:
  explicit Rows(PGresult* result) : result_(result, &PQclear) {}
  int size() const { return PQntuples(result_.get()); }
  std::string Bytes(int row, int column) const {
    return std::string(PQgetvalue(result_.get(), row, column),
                       static_cast<size_t>(PQgetlength(result_.get(), row, column)));
  }
  int64_t Int(int row, int column) const {
    const auto* p = reinterpret_cast<const unsigned char*>(PQgetvalue(result_.get(), row, column));
    const int n = PQgetlength(result_.get(), row, column);
    uint64_t v = 0;
    for (int i = 0; i < n; ++i) v = v << 8 | p[i];
    if (n == 4) return static_cast<int32_t>(static_cast<uint32_t>(v));
    return static_cast<int64_t>(v);
  }
  bool IsNull(int row, int column) const { return PQgetisnull(result_.get(), row, column) != 0; }

 private:
  std::unique_ptr<PGresult, void (*)(PGresult*)> result_;
};

namespace {

// The schema's migrations, oldest first: kMigrations[k] takes the database from version k to
// k + 1 (the versions applied are rows of schema_migrations).
const char* const kMigrations[] = {
    // 1: scenes and jobs, each row its resource's message; request ids unique per tenant.
    "CREATE TABLE scenes("
    "  seq bigserial PRIMARY KEY, id text UNIQUE NOT NULL, tenant text NOT NULL,"
    "  request_id text NOT NULL, bytes bigint NOT NULL, info bytea NOT NULL);"
    "CREATE UNIQUE INDEX scenes_request ON scenes(tenant, request_id) WHERE request_id <> '';"
    "CREATE INDEX scenes_tenant ON scenes(tenant, seq);"
    "CREATE TABLE jobs("
    "  seq bigserial PRIMARY KEY, id text UNIQUE NOT NULL, scene text NOT NULL,"
    "  tenant text NOT NULL, request_id text NOT NULL, state integer NOT NULL,"
    "  bytes bigint NOT NULL, info bytea NOT NULL);"
    "CREATE UNIQUE INDEX jobs_request ON jobs(tenant, request_id) WHERE request_id <> '';"
    "CREATE INDEX jobs_tenant ON jobs(tenant, seq);"
    "CREATE INDEX jobs_state ON jobs(state);"
    "CREATE INDEX jobs_scene ON jobs(scene);"
    "CREATE TABLE meta(key text PRIMARY KEY, value bytea NOT NULL);",
    // 2: job leases (the owner, until when, and a cancel for the owner to hear of).
    "ALTER TABLE jobs ADD COLUMN owner text NOT NULL DEFAULT '',"
    "  ADD COLUMN lease_until timestamptz, ADD COLUMN cancel_requested integer NOT NULL DEFAULT 0;"
    "CREATE INDEX jobs_claimable ON jobs(seq) WHERE state IN (1, 2);",
};
constexpr int kLatest = static_cast<int>(std::size(kMigrations));

// The migrations' advisory lock: replicas that start together migrate one at a time.
constexpr int64_t kMigrationLock = 0x7261646f73747931;  // "radosty1"

// The advisory lock of ClaimExclusive.
constexpr int64_t kServerLock = 0x7261646f73727631;  // "radosrv1"

// A failed command's status: RESOURCE_EXHAUSTED on a full disk or out of memory (SQLSTATE class
// 53), UNAVAILABLE when the connection is gone (class 08, or no result), INTERNAL otherwise.
absl::Status QueryError(PGconn* conn, const PGresult* result) {
  std::string message(absl::StripTrailingAsciiWhitespace(
      result != nullptr ? PQresultErrorMessage(result) : PQerrorMessage(conn)));
  const char* state = result != nullptr ? PQresultErrorField(result, PG_DIAG_SQLSTATE) : nullptr;
  const std::string sqlstate = state != nullptr ? state : "";
  message = absl::StrCat("database: ", message);
  if (sqlstate.rfind("53", 0) == 0) return absl::ResourceExhaustedError(message);
  if (sqlstate.rfind("08", 0) == 0 || result == nullptr || PQstatus(conn) == CONNECTION_BAD) {
    return absl::UnavailableError(message);
  }
  return absl::InternalError(message);
}

std::string Int(int64_t v) { return absl::StrCat(v); }

}  // namespace

int PostgresStore::LatestSchema() { return kLatest; }

absl::StatusOr<std::unique_ptr<PostgresStore>> PostgresStore::Open(const std::string& uri) {
  std::unique_ptr<PostgresStore> store(new PostgresStore(uri));
  // Defaults a user would want from a service, before the URI's own parameters (which win): a
  // host that does not answer fails in seconds instead of never, and a peer that vanished
  // mid-query is noticed by TCP keepalives instead of hanging every request behind it.
  const char* const keywords[] = {"connect_timeout",
                                  "keepalives_idle",
                                  "keepalives_interval",
                                  "keepalives_count",
                                  "application_name",
                                  "dbname",
                                  nullptr};
  const char* const values[] = {"10", "15", "5", "3", "radiosity-server", uri.c_str(), nullptr};
  store->conn_ = PQconnectdbParams(keywords, values, /*expand_dbname=*/1);
  if (store->conn_ != nullptr) {
    // The server's notices ("relation ... already exists, skipping") are not errors: kept out of
    // the log unless it is verbose.
    PQsetNoticeProcessor(
        store->conn_,
        [](void*, const char* message) {
          spdlog::debug("postgresql: {}", std::string(absl::StripTrailingAsciiWhitespace(message)));
        },
        nullptr);
  }
  if (store->conn_ == nullptr || PQstatus(store->conn_) != CONNECTION_OK) {
    std::string message =
        store->conn_ != nullptr
            ? std::string(absl::StripTrailingAsciiWhitespace(PQerrorMessage(store->conn_)))
            : "out of memory";
    return absl::UnavailableError(
        absl::StrCat(HidePassword(uri), ": cannot connect to PostgreSQL: ", message));
  }
  absl::Status st = store->Migrate();
  if (st.ok()) st = store->LoadPageKey();
  if (!st.ok()) return absl::Status(st.code(), absl::StrCat(HidePassword(uri), ": ", st.message()));
  return store;
}

PostgresStore::~PostgresStore() {
  if (conn_ != nullptr) PQfinish(conn_);
}

absl::StatusOr<PostgresStore::Rows> PostgresStore::Query(const std::string& sql,
                                                         const std::vector<Param>& params) {
  std::vector<const char*> values;
  std::vector<int> lengths, formats;
  for (const Param& p : params) {
    values.push_back(p.value.c_str());
    lengths.push_back(static_cast<int>(p.value.size()));
    formats.push_back(p.binary ? 1 : 0);
  }
  for (int attempt = 0;; ++attempt) {
    // A connection lost since the last query (a PostgreSQL restart) is made again, once; its
    // claim went with it, and no query runs until the claim is held again (the old session may
    // hold it until PostgreSQL notices that its peer is gone).
    if (PQstatus(conn_) == CONNECTION_BAD) {
      PQreset(conn_);
      claim_held_ = false;
    }
    if (exclusive_ && !claim_held_ && PQstatus(conn_) == CONNECTION_OK) {
      if (absl::Status st = TakeServerLock(); !st.ok()) {
        return absl::UnavailableError(
            absl::StrCat("the connection to the store was made again but its claim is not back "
                         "yet: ",
                         st.message()));
      }
      claim_held_ = true;
    }
    PGresult* result =
        PQexecParams(conn_, sql.c_str(), static_cast<int>(params.size()), nullptr, values.data(),
                     lengths.data(), formats.data(), /*resultFormat=*/1);
    const ExecStatusType status = result != nullptr ? PQresultStatus(result) : PGRES_FATAL_ERROR;
    if (status == PGRES_TUPLES_OK || status == PGRES_COMMAND_OK) return Rows(result);
    absl::Status error = QueryError(conn_, result);
    PQclear(result);
    if (attempt == 0 && PQstatus(conn_) == CONNECTION_BAD) continue;
    return error;
  }
}

bool PostgresStore::ServesReplicas() const { return true; }

absl::Status PostgresStore::ClaimExclusive() {
  std::lock_guard<std::mutex> lock(mu_);
  // A server that just stopped (or was killed) frees the lock when PostgreSQL's backend for its
  // connection has exited, which may be a moment after the connection closed: a restart waits a
  // few seconds for it before refusing.
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  absl::Status st = TakeServerLock();
  while (absl::IsFailedPrecondition(st) && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    st = TakeServerLock();
  }
  if (!st.ok()) return st;
  exclusive_ = true;
  claim_held_ = true;
  return absl::OkStatus();
}

absl::Status PostgresStore::TakeServerLock() {
  PGresult* result =
      PQexec(conn_, absl::StrCat("SELECT pg_try_advisory_lock(", kServerLock, ")::text").c_str());
  absl::Status st;
  if (PQresultStatus(result) != PGRES_TUPLES_OK) {
    st = QueryError(conn_, result);
  } else if (std::string(PQgetvalue(result, 0, 0)) != "true") {
    st = absl::FailedPreconditionError(
        absl::StrCat(ToString(),
                     ": another radiosity-server uses this store (one server per store: this "
                     "version's workers do not share a queue)"));
  }
  PQclear(result);
  return st;
}

absl::Status PostgresStore::Migrate() {
  // Simple statements (several commands each) go through PQexec, in one transaction with the
  // lock; the lock is released at its end.
  auto exec = [&](const std::string& sql) -> absl::Status {
    PGresult* result = PQexec(conn_, sql.c_str());
    absl::Status st =
        PQresultStatus(result) == PGRES_COMMAND_OK || PQresultStatus(result) == PGRES_TUPLES_OK
            ? absl::OkStatus()
            : QueryError(conn_, result);
    PQclear(result);
    return st;
  };
  if (absl::Status st = exec(absl::StrCat(
          "BEGIN; SELECT pg_advisory_xact_lock(", kMigrationLock,
          ");"
          "CREATE TABLE IF NOT EXISTS schema_migrations("
          "  version integer PRIMARY KEY, applied_at timestamptz NOT NULL DEFAULT now());"));
      !st.ok()) {
    exec("ROLLBACK;").IgnoreError();
    return st;
  }
  absl::Status st;
  absl::StatusOr<Rows> version =
      Query("SELECT COALESCE(MAX(version), 0)::bigint FROM schema_migrations");
  if (!version.ok()) {
    st = version.status();
  } else {
    schema_ = static_cast<int>(version->Int(0, 0));
    if (schema_ > kLatest) {
      st = absl::FailedPreconditionError(
          absl::StrCat("the database is at schema version ", schema_,
                       ", written by a newer radiosity-server; this one knows versions up to ",
                       kLatest, " (run the newer server, or restore a backup)"));
    }
  }
  while (st.ok() && schema_ < kLatest) {
    const int next = schema_ + 1;
    st = exec(kMigrations[schema_]);
    if (st.ok())
      st = exec(absl::StrCat("INSERT INTO schema_migrations(version) VALUES(", next, ");"));
    if (!st.ok()) {
      st = absl::Status(st.code(), absl::StrCat("schema migration ", next, ": ", st.message()));
    } else {
      schema_ = next;
    }
  }
  if (absl::Status end = exec(st.ok() ? "COMMIT;" : "ROLLBACK;"); st.ok()) st = end;
  return st;
}

// The page tokens' key: made by whichever replica comes first, kept in the meta table, the same
// for all (a token from one replica pages on another).
absl::Status PostgresStore::LoadPageKey() {
  absl::StatusOr<std::string> made = PageTokens::NewKey();
  if (!made.ok()) return made.status();
  absl::StatusOr<Rows> inserted =
      Query("INSERT INTO meta(key, value) VALUES('page_key', $1) ON CONFLICT (key) DO NOTHING",
            {{*made, true}});
  if (!inserted.ok()) return inserted.status();
  absl::StatusOr<Rows> key = Query("SELECT value FROM meta WHERE key = 'page_key'");
  if (!key.ok()) return key.status();
  if (key->size() != 1 || key->Bytes(0, 0).size() != 16) {
    return absl::InternalError("database: the page-token key in table meta is not 16 bytes");
  }
  tokens_ = PageTokens(key->Bytes(0, 0));
  return absl::OkStatus();
}

template <typename Message>
absl::StatusOr<std::optional<Message>> PostgresStore::FindByRequest(const char* table,
                                                                    const std::string& tenant,
                                                                    const std::string& request_id) {
  if (request_id.empty()) return std::optional<Message>();
  absl::StatusOr<Rows> rows =
      Query(absl::StrCat("SELECT info FROM ", table, " WHERE tenant = $1 AND request_id = $2"),
            {{tenant}, {request_id}});
  if (!rows.ok()) return rows.status();
  if (rows->size() == 0) return std::optional<Message>();
  absl::StatusOr<Message> message = ParseRow<Message>(rows->Bytes(0, 0));
  if (!message.ok()) return message.status();
  return std::optional<Message>(*std::move(message));
}

template <typename Message>
absl::StatusOr<Message> PostgresStore::GetRow(const char* table, const std::string& id) {
  absl::StatusOr<Rows> rows =
      Query(absl::StrCat("SELECT info FROM ", table, " WHERE id = $1"), {{id}});
  if (!rows.ok()) return rows.status();
  if (rows->size() == 0) {
    return absl::NotFoundError(absl::StrCat(table, "/", id, " does not exist"));
  }
  return ParseRow<Message>(rows->Bytes(0, 0));
}

absl::StatusOr<std::optional<v1::SceneInfo>> PostgresStore::InsertScene(
    const std::string& id, const v1::SceneInfo& scene) {
  std::lock_guard<std::mutex> lock(mu_);
  // The partial unique index on (tenant, request_id) makes the check and the insert one step
  // for every replica: a second insert of the request inserts nothing, and finds the first.
  absl::StatusOr<Rows> rows = Query(
      "INSERT INTO scenes(id, tenant, request_id, bytes, info) VALUES($1, $2, $3, $4, $5)"
      " ON CONFLICT (tenant, request_id) WHERE request_id <> '' DO NOTHING RETURNING seq",
      {{id},
       {scene.tenant()},
       {scene.request_id()},
       {Int(scene.total_size())},
       {scene.SerializeAsString(), true}});
  if (!rows.ok()) return rows.status();
  if (rows->size() == 1) return std::optional<v1::SceneInfo>();
  return FindByRequest<v1::SceneInfo>("scenes", scene.tenant(), scene.request_id());
}

absl::StatusOr<v1::SceneInfo> PostgresStore::GetScene(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  return GetRow<v1::SceneInfo>("scenes", id);
}

absl::StatusOr<std::optional<v1::SceneInfo>> PostgresStore::FindSceneByRequest(
    const std::string& tenant, const std::string& request_id) {
  std::lock_guard<std::mutex> lock(mu_);
  return FindByRequest<v1::SceneInfo>("scenes", tenant, request_id);
}

absl::StatusOr<v1::ListScenesResponse> PostgresStore::ListScenes(const std::string& tenant,
                                                                 int page_size,
                                                                 const std::string& page_token) {
  absl::StatusOr<int64_t> before = tokens_.Parse(tenant, page_token);
  if (!before.ok()) return before.status();
  const int limit = PageSize(page_size);
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(
      "SELECT seq, info FROM scenes WHERE tenant = $1 AND seq < $2 ORDER BY seq DESC LIMIT $3",
      {{tenant}, {Int(*before)}, {Int(limit + 1)}});
  if (!rows.ok()) return rows.status();
  v1::ListScenesResponse response;
  for (int r = 0; r < rows->size() && r < limit; ++r) {
    absl::StatusOr<v1::SceneInfo> info = ParseRow<v1::SceneInfo>(rows->Bytes(r, 1));
    if (!info.ok()) return info.status();
    *response.add_scenes() = *std::move(info);
  }
  if (rows->size() > limit)
    response.set_next_page_token(tokens_.Make(tenant, rows->Int(limit - 1, 0)));
  return response;
}

absl::Status PostgresStore::DeleteScene(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  return Query("DELETE FROM scenes WHERE id = $1", {{id}}).status();
}

absl::StatusOr<std::optional<v1::Job>> PostgresStore::InsertJob(const std::string& id,
                                                                const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(
      "INSERT INTO jobs(id, scene, tenant, request_id, state, bytes, info)"
      " VALUES($1, $2, $3, $4, $5, $6, $7)"
      " ON CONFLICT (tenant, request_id) WHERE request_id <> '' DO NOTHING RETURNING seq",
      {{id},
       {job.scene()},
       {job.tenant()},
       {job.request_id()},
       {Int(job.state())},
       {Int(ResultBytes(job))},
       {job.SerializeAsString(), true}});
  if (!rows.ok()) return rows.status();
  if (rows->size() == 1) return std::optional<v1::Job>();
  return FindByRequest<v1::Job>("jobs", job.tenant(), job.request_id());
}

absl::Status PostgresStore::UpdateJob(const std::string& id, const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  // An ended job has no lease (a holder still running it finds it lost at its next renewal).
  return Query(
             "UPDATE jobs SET state = $1, bytes = $2, info = $3,"
             " owner = CASE WHEN $1 IN (1, 2) THEN owner ELSE '' END,"
             " lease_until = CASE WHEN $1 IN (1, 2) THEN lease_until END WHERE id = $4",
             {{Int(job.state())}, {Int(ResultBytes(job))}, {job.SerializeAsString(), true}, {id}})
      .status();
}

absl::StatusOr<v1::Job> PostgresStore::GetJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  return GetRow<v1::Job>("jobs", id);
}

absl::StatusOr<std::optional<v1::Job>> PostgresStore::FindJobByRequest(
    const std::string& tenant, const std::string& request_id) {
  std::lock_guard<std::mutex> lock(mu_);
  return FindByRequest<v1::Job>("jobs", tenant, request_id);
}

absl::StatusOr<v1::ListJobsResponse> PostgresStore::ListJobs(const std::string& tenant,
                                                             const v1::ListJobsRequest& request) {
  absl::StatusOr<int64_t> before = tokens_.Parse(tenant, request.page_token());
  if (!before.ok()) return before.status();
  const int limit = PageSize(request.page_size());
  std::vector<v1::JobState> states;
  for (int s : request.states()) states.push_back(static_cast<v1::JobState>(s));
  std::vector<Param> params = {{tenant}, {Int(*before)}};
  std::string sql = "SELECT seq, info FROM jobs WHERE tenant = $1 AND seq < $2";
  const std::string state_list = StateList(states);
  if (!state_list.empty()) absl::StrAppend(&sql, " AND state IN (", state_list, ")");
  if (!request.scene().empty()) {
    params.push_back({request.scene()});
    absl::StrAppend(&sql, " AND scene = $", params.size());
  }
  params.push_back({Int(limit + 1)});
  absl::StrAppend(&sql, " ORDER BY seq DESC LIMIT $", params.size());
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(sql, params);
  if (!rows.ok()) return rows.status();
  v1::ListJobsResponse response;
  for (int r = 0; r < rows->size() && r < limit; ++r) {
    absl::StatusOr<v1::Job> job = ParseRow<v1::Job>(rows->Bytes(r, 1));
    if (!job.ok()) return job.status();
    *response.add_jobs() = *std::move(job);
  }
  if (rows->size() > limit)
    response.set_next_page_token(tokens_.Make(tenant, rows->Int(limit - 1, 0)));
  return response;
}

absl::StatusOr<std::vector<v1::SceneInfo>> PostgresStore::AllScenes() {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query("SELECT info FROM scenes ORDER BY seq ASC");
  if (!rows.ok()) return rows.status();
  std::vector<v1::SceneInfo> scenes;
  for (int r = 0; r < rows->size(); ++r) {
    absl::StatusOr<v1::SceneInfo> scene = ParseRow<v1::SceneInfo>(rows->Bytes(r, 0));
    if (!scene.ok()) return scene.status();
    scenes.push_back(*std::move(scene));
  }
  return scenes;
}

absl::StatusOr<std::vector<v1::Job>> PostgresStore::JobsInStates(
    const std::vector<v1::JobState>& states) {
  const std::string state_list = StateList(states);
  if (state_list.empty()) return std::vector<v1::Job>();
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(
      absl::StrCat("SELECT info FROM jobs WHERE state IN (", state_list, ") ORDER BY seq ASC"));
  if (!rows.ok()) return rows.status();
  std::vector<v1::Job> jobs;
  for (int r = 0; r < rows->size(); ++r) {
    absl::StatusOr<v1::Job> job = ParseRow<v1::Job>(rows->Bytes(r, 0));
    if (!job.ok()) return job.status();
    jobs.push_back(*std::move(job));
  }
  return jobs;
}

absl::StatusOr<int64_t> PostgresStore::CountJobs(const std::string& scene_name,
                                                 const std::vector<v1::JobState>& states) {
  std::string sql = "SELECT COUNT(*)::bigint FROM jobs WHERE (scene = $1 OR $1 = '')";
  const std::string state_list = StateList(states);
  if (!state_list.empty()) absl::StrAppend(&sql, " AND state IN (", state_list, ")");
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(sql, {{scene_name}});
  if (!rows.ok()) return rows.status();
  return rows->Int(0, 0);
}

absl::Status PostgresStore::DeleteJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  return Query("DELETE FROM jobs WHERE id = $1", {{id}}).status();
}

absl::StatusOr<TenantUsage> PostgresStore::Usage(const std::string& tenant) {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(
      absl::StrCat("SELECT (SELECT COUNT(*) FROM jobs WHERE tenant = $1 AND state IN (",
                   StateList({v1::JOB_STATE_QUEUED, v1::JOB_STATE_RUNNING}),
                   "))::bigint, (COALESCE((SELECT SUM(bytes) FROM scenes WHERE tenant = $1), 0)"
                   " + COALESCE((SELECT SUM(bytes) FROM jobs WHERE tenant = $1), 0))::bigint"),
      {{tenant}});
  if (!rows.ok()) return rows.status();
  TenantUsage usage;
  usage.unfinished_jobs = rows->Int(0, 0);
  usage.stored_bytes = rows->Int(0, 1);
  return usage;
}

absl::StatusOr<int64_t> PostgresStore::TotalBytes() {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(
      "SELECT (COALESCE((SELECT SUM(bytes) FROM scenes), 0)"
      " + COALESCE((SELECT SUM(bytes) FROM jobs), 0))::bigint");
  if (!rows.ok()) return rows.status();
  return rows->Int(0, 0);
}

// QUEUED and RUNNING are 1 and 2 in the queries below (store_rows.h).
absl::StatusOr<std::optional<Store::Claim>> PostgresStore::ClaimJob(const std::string& owner,
                                                                    absl::Duration lease) {
  return ClaimOne(owner, lease, "");
}

absl::StatusOr<std::optional<Store::Claim>> PostgresStore::ClaimJobById(const std::string& id,
                                                                        const std::string& owner,
                                                                        absl::Duration lease) {
  return ClaimOne(owner, lease, id);
}

absl::StatusOr<std::optional<Store::Claim>> PostgresStore::ClaimOne(const std::string& owner,
                                                                    absl::Duration lease,
                                                                    const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  // The subquery locks the first claimable row that no other transaction holds (SKIP LOCKED:
  // concurrent claimers take different rows instead of waiting on one).
  absl::StatusOr<Rows> rows = Query(
      absl::StrCat(
          "UPDATE jobs SET owner = $1, lease_until = now() + $2::bigint * interval '1 millisecond'"
          " WHERE seq = (SELECT seq FROM jobs WHERE state IN (1, 2)"
          "   AND (owner = '' OR lease_until IS NULL OR lease_until < now())",
          id.empty() ? "" : " AND id = $3",
          "   ORDER BY seq LIMIT 1 FOR UPDATE SKIP LOCKED)"
          " RETURNING info, cancel_requested"),
      id.empty() ? std::vector<Param>{{owner}, {Int(absl::ToInt64Milliseconds(lease))}}
                 : std::vector<Param>{{owner}, {Int(absl::ToInt64Milliseconds(lease))}, {id}});
  if (!rows.ok()) return rows.status();
  if (rows->size() == 0) return std::optional<Store::Claim>();
  absl::StatusOr<v1::Job> job = ParseRow<v1::Job>(rows->Bytes(0, 0));
  if (!job.ok()) return job.status();
  return std::optional<Store::Claim>(Store::Claim{*std::move(job), rows->Int(0, 1) != 0});
}

absl::StatusOr<bool> PostgresStore::RenewLease(const std::string& id, const std::string& owner,
                                               absl::Duration lease) {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(
      "UPDATE jobs SET lease_until = now() + $1::bigint * interval '1 millisecond'"
      " WHERE id = $2 AND owner = $3 AND state IN (1, 2) RETURNING cancel_requested",
      {{Int(absl::ToInt64Milliseconds(lease))}, {id}, {owner}});
  if (!rows.ok()) return rows.status();
  if (rows->size() == 0) return LeaseLost(id, owner);
  return rows->Int(0, 0) != 0;
}

absl::Status PostgresStore::UpdateLeasedJob(const std::string& id, const std::string& owner,
                                            const v1::Job& job) {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(
      "UPDATE jobs SET state = $1, bytes = $2, info = $3,"
      " owner = CASE WHEN $1 = 2 THEN owner ELSE '' END,"
      " lease_until = CASE WHEN $1 = 2 THEN lease_until END"
      " WHERE id = $4 AND owner = $5 AND state IN (1, 2) RETURNING seq",
      {{Int(job.state())},
       {Int(ResultBytes(job))},
       {job.SerializeAsString(), true},
       {id},
       {owner}});
  if (!rows.ok()) return rows.status();
  if (rows->size() == 0) return LeaseLost(id, owner);
  return absl::OkStatus();
}

absl::Status PostgresStore::RequestCancel(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows =
      Query("UPDATE jobs SET cancel_requested = 1 WHERE id = $1 RETURNING seq", {{id}});
  if (!rows.ok()) return rows.status();
  if (rows->size() == 0) return absl::NotFoundError(absl::StrCat("jobs/", id, " does not exist"));
  return absl::OkStatus();
}

absl::StatusOr<int64_t> PostgresStore::CountLeased() {
  std::lock_guard<std::mutex> lock(mu_);
  absl::StatusOr<Rows> rows = Query(
      "SELECT count(*) FROM jobs WHERE state IN (1, 2) AND owner <> ''"
      " AND lease_until >= now()");
  if (!rows.ok()) return rows.status();
  return rows->Int(0, 0);
}

}  // namespace radiosity::service
