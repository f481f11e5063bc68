// The service's embedded database: scenes and jobs in SQLite (one file under --data-dir), each row
// holding the resource's protobuf message, plus the columns the queries need. The files of scenes
// and results live beside it in directories (server/service_impl.h).
#ifndef RADIOSITY_SERVER_STORE_H_
#define RADIOSITY_SERVER_STORE_H_

#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "radiosity/v1/service.pb.h"

struct sqlite3;

namespace radiosity::service {

// What a tenant has in the store (for its quotas).
struct TenantUsage {
  int64_t unfinished_jobs = 0;  // QUEUED or RUNNING.
  int64_t stored_bytes = 0;     // Its scenes' files and its jobs' results.
};

// Every scene and job row carries its tenant ("" on a server without tenants): request ids are
// looked up, and lists made, within one tenant. Get* return any tenant's row; the service checks
// the owner.
class Store {
 public:
  // Opens (creating if needed) the database at `path`.
  static absl::StatusOr<std::unique_ptr<Store>> Open(const std::string& path);
  ~Store();
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;

  // Scenes. Ids are the part after "scenes/".
  // Inserts the scene unless one with its request_id (when not empty) exists, and then returns
  // that one instead (nothing when inserted): the check and the insert are one step under the
  // store's lock, so concurrent retries of one request insert once.
  absl::StatusOr<std::optional<v1::SceneInfo>> InsertScene(const std::string& id,
                                                           const v1::SceneInfo& scene);
  absl::StatusOr<v1::SceneInfo> GetScene(const std::string& id);  // NOT_FOUND if absent.
  absl::StatusOr<std::optional<v1::SceneInfo>> FindSceneByRequest(const std::string& tenant,
                                                                  const std::string& request_id);
  // The tenant's scenes, newest first; `page_token` is the previous page's next_page_token.
  absl::StatusOr<v1::ListScenesResponse> ListScenes(const std::string& tenant, int page_size,
                                                    const std::string& page_token);
  absl::Status DeleteScene(const std::string& id);

  // Jobs. Ids are the part after "jobs/"; the state column follows job.state().
  // Inserts the job unless one with its request_id (when not empty) exists, as InsertScene.
  absl::StatusOr<std::optional<v1::Job>> InsertJob(const std::string& id, const v1::Job& job);
  absl::Status UpdateJob(const std::string& id, const v1::Job& job);
  absl::StatusOr<v1::Job> GetJob(const std::string& id);  // NOT_FOUND if absent.
  absl::StatusOr<std::optional<v1::Job>> FindJobByRequest(const std::string& tenant,
                                                          const std::string& request_id);
  // The tenant's jobs, newest first.
  absl::StatusOr<v1::ListJobsResponse> ListJobs(const std::string& tenant,
                                                const v1::ListJobsRequest& request);
  // Jobs in the given states, oldest first (for recovery after a restart).
  absl::StatusOr<std::vector<v1::Job>> JobsInStates(const std::vector<v1::JobState>& states);
  // Number of jobs on a scene in the given states.
  absl::StatusOr<int64_t> CountJobs(const std::string& scene_name,
                                    const std::vector<v1::JobState>& states);
  absl::Status DeleteJob(const std::string& id);
  absl::StatusOr<TenantUsage> Usage(const std::string& tenant);
  // Bytes of every tenant's scenes and results.
  absl::StatusOr<int64_t> TotalBytes();

 private:
  explicit Store(sqlite3* db) : db_(db) {}
  absl::Status Exec(const std::string& sql);
  absl::Status Migrate();
  absl::Status LoadPageKey();
  std::string MakeToken(const std::string& tenant, int64_t seq) const;
  absl::StatusOr<int64_t> ParseToken(const std::string& tenant, const std::string& token) const;
  absl::Status FillBytes();
  absl::StatusOr<bool> HasColumn(const char* table, const char* column);
  template <typename Message>
  absl::StatusOr<std::optional<Message>> FindByRequestLocked(const char* table,
                                                             const std::string& tenant,
                                                             const std::string& request_id);

  std::mutex mu_;
  sqlite3* db_;
  std::string page_key_;  // AES-128 key of the page tokens (LoadPageKey).
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_STORE_H_
