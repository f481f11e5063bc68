// The embedded store: SQLite, one file (by default DATA_DIR/radiosity.db), one server process.
// Schema migrations are numbered and recorded in the file's user_version (sqlite_store.cc).
#ifndef RADIOSITY_SERVER_SQLITE_STORE_H_
#define RADIOSITY_SERVER_SQLITE_STORE_H_

#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/functional/function_ref.h"
#include "server/page_token.h"
#include "server/store.h"

struct sqlite3;

namespace radiosity::service {

class SqliteStore : public Store {
 public:
  // Opens (creating and migrating if needed) the database file at `path`.
  static absl::StatusOr<std::unique_ptr<SqliteStore>> Open(const std::string& path);
  // The newest schema this server writes.
  static int LatestSchema();
  ~SqliteStore() override;
  SqliteStore(const SqliteStore&) = delete;
  SqliteStore& operator=(const SqliteStore&) = delete;

  std::string ToString() const override { return "sqlite:" + path_; }
  int SchemaVersion() const override { return schema_; }
  // An exclusive lock (flock) on DB.lock beside the database file, held until the store closes.
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

 private:
  // ClaimJob (`id` empty) or ClaimJobById.
  absl::StatusOr<std::optional<Claim>> ClaimOne(const std::string& owner, absl::Duration lease,
                                                const std::string& id);
  SqliteStore(sqlite3* db, std::string path) : db_(db), path_(std::move(path)) {}
  absl::Status Exec(const std::string& sql);
  absl::Status Migrate();
  absl::Status Apply(int version);
  absl::Status LoadPageKey();
  absl::Status FillBytes();
  absl::StatusOr<bool> HasColumn(const char* table, const char* column);
  template <typename Message>
  absl::StatusOr<std::optional<Message>> FindByRequestLocked(const char* table,
                                                             const std::string& tenant,
                                                             const std::string& request_id);
  // Returns the row of `message`'s tenant and request id if there is one, or else runs `insert`;
  // in one write transaction, so that no other connection to the file (a second store, a second
  // server) inserts the same request in between.
  // Runs `body` in a transaction that holds the file's write lock from its start (BEGIN
  // IMMEDIATE, waiting out the busy timeout for another writer); commits if it succeeds.
  absl::Status WriteTransactionLocked(absl::FunctionRef<absl::Status()> body);
  template <typename Message>
  absl::StatusOr<std::optional<Message>> InsertOnceLocked(const char* table, const Message& message,
                                                          absl::FunctionRef<absl::Status()> insert);

  std::mutex mu_;
  sqlite3* db_;
  std::string path_;
  int schema_ = 0;
  int claim_fd_ = -1;  // The lock file of ClaimExclusive.
  PageTokens tokens_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_SQLITE_STORE_H_
