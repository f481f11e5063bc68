// The shared store: PostgreSQL through libpq, for replicas of the server behind one address
// (`--store postgresql://...`). Schema migrations are numbered, recorded in the table
// schema_migrations, and applied at open under an advisory lock, so replicas starting together
// migrate once. Request ids are unique per tenant by a partial unique index, so retries of one
// request sent to different replicas insert once.
#ifndef RADIOSITY_SERVER_POSTGRES_STORE_H_
#define RADIOSITY_SERVER_POSTGRES_STORE_H_

#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "server/page_token.h"
#include "server/store.h"

struct pg_conn;

namespace radiosity::service {

class PostgresStore : public Store {
 public:
  // Connects to `uri` (a libpq connection URI) and migrates the schema. Errors name the URI with
  // its password hidden.
  static absl::StatusOr<std::unique_ptr<PostgresStore>> Open(const std::string& uri);
  // The newest schema this server writes.
  static int LatestSchema();
  ~PostgresStore() override;
  PostgresStore(const PostgresStore&) = delete;
  PostgresStore& operator=(const PostgresStore&) = delete;

  std::string ToString() const override { return HidePassword(uri_); }
  int SchemaVersion() const override { return schema_; }
  // A session advisory lock, taken again after a reconnect (until it is, queries fail
  // UNAVAILABLE).
  absl::Status ClaimExclusive() override;
  bool ServesReplicas() const override;
  absl::StatusOr<std::optional<v1::SceneInfo>> InsertScene(const std::string& id,
                                                           const v1::SceneInfo& scene) override;
  absl::StatusOr<v1::SceneInfo> GetScene(const std::string& id) override;
  absl::StatusOr<std::optional<v1::SceneInfo>> FindSceneByRequest(
      const std::string& tenant, const std::string& request_id) override;
  absl::StatusOr<v1::ListScenesResponse> ListScenes(const std::string& tenant, int page_size,
                                                    const std::string& page_token) override;
  absl::Status DeleteScene(const std::string& id) override;
  absl::StatusOr<std::vector<v1::SceneInfo>> AllScenes() override;
  absl::StatusOr<std::optional<v1::Job>> InsertJob(const std::string& id,
                                                   const v1::Job& job) override;
  absl::Status UpdateJob(const std::string& id, const v1::Job& job) override;
  absl::StatusOr<v1::Job> GetJob(const std::string& id) override;
  absl::StatusOr<std::optional<v1::Job>> FindJobByRequest(const std::string& tenant,
                                                          const std::string& request_id) override;
  absl::StatusOr<v1::ListJobsResponse> ListJobs(const std::string& tenant,
                                                const v1::ListJobsRequest& request) override;
  absl::StatusOr<std::vector<v1::Job>> JobsInStates(
      const std::vector<v1::JobState>& states) override;
  absl::StatusOr<int64_t> CountJobs(const std::string& scene_name,
                                    const std::vector<v1::JobState>& states) override;
  absl::Status DeleteJob(const std::string& id) override;
  absl::StatusOr<TenantUsage> Usage(const std::string& tenant) override;
  absl::StatusOr<int64_t> TotalBytes() override;
  absl::StatusOr<std::optional<Claim>> ClaimJob(const std::string& owner,
                                                absl::Duration lease) override;
  absl::StatusOr<std::optional<Claim>> ClaimJobById(const std::string& id, const std::string& owner,
                                                    absl::Duration lease) override;
  absl::StatusOr<bool> RenewLease(const std::string& id, const std::string& owner,
                                  absl::Duration lease) override;
  absl::Status UpdateLeasedJob(const std::string& id, const std::string& owner,
                               const v1::Job& job) override;
  absl::Status RequestCancel(const std::string& id) override;
  absl::StatusOr<int64_t> CountLeased() override;

  // One parameter of a query: text, or bytes (bytea).
  struct Param {
    std::string value;
    bool binary = false;
  };
  class Rows;

 private:
  // ClaimJob (`id` empty) or ClaimJobById.
  absl::StatusOr<std::optional<Claim>> ClaimOne(const std::string& owner, absl::Duration lease,
                                                const std::string& id);
  explicit PostgresStore(std::string uri) : uri_(std::move(uri)) {}
  // Runs `sql` with $1... bound to `params`; rows in binary (bigint, bytea and text columns
  // only). Reconnects once when the connection was lost.
  absl::StatusOr<Rows> Query(const std::string& sql, const std::vector<Param>& params = {});
  absl::Status Migrate();
  absl::Status TakeServerLock();
  absl::Status LoadPageKey();
  template <typename Message>
  absl::StatusOr<std::optional<Message>> FindByRequest(const char* table, const std::string& tenant,
                                                       const std::string& request_id);
  template <typename Message>
  absl::StatusOr<Message> GetRow(const char* table, const std::string& id);

  std::mutex mu_;  // One connection, one query at a time.
  pg_conn* conn_ = nullptr;
  std::string uri_;
  int schema_ = 0;
  bool exclusive_ = false;   // ClaimExclusive succeeded: the claim must be held to query.
  bool claim_held_ = false;  // This connection's session holds the claim.
  PageTokens tokens_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_POSTGRES_STORE_H_
