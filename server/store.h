// The service's database: scenes and jobs, each row holding the resource's protobuf message plus
// the columns the queries need. Two backends behind one interface: SQLite (server/sqlite_store.h,
// one file, the embedded default) and PostgreSQL (server/postgres_store.h, shared by replicas).
// The files of scenes and results live elsewhere (server/data_dir.h).
//
// Every scene and job row carries its tenant ("" on a server without tenants): request ids are
// looked up, and lists made, within one tenant. Get* return any tenant's row; the service checks
// the owner.
#ifndef RADIOSITY_SERVER_STORE_H_
#define RADIOSITY_SERVER_STORE_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/time/time.h"
#include "radiosity/v1/service.pb.h"

namespace radiosity::service {

// What a tenant has in the store (for its quotas).
struct TenantUsage {
  int64_t unfinished_jobs = 0;  // QUEUED or RUNNING.
  int64_t stored_bytes = 0;     // Its scenes' files and its jobs' results.
};

class Store {
 public:
  virtual ~Store() = default;

  // "sqlite:/path/radiosity.db" or a PostgreSQL URI with its password hidden: for logs.
  virtual std::string ToString() const = 0;
  // The schema version the database is at after Open (the migrations applied, in order).
  virtual int SchemaVersion() const = 0;
  // Makes this process the store's only server until it closes the store: FAILED_PRECONDITION
  // when another holds it. This version's workers keep their queue in memory, so a server claims
  // its store; a store opened without the claim (tests, tools) may be shared. SQLite: a lock file
  // beside the database; PostgreSQL: a session advisory lock.
  virtual absl::Status ClaimExclusive() = 0;
  // Whether processes on several machines may share it (replicas, --blob-dir): PostgreSQL.
  virtual bool ServesReplicas() const = 0;

  // Scenes. Ids are the part after "scenes/".
  // Inserts the scene unless one with its tenant and request_id (when not empty) exists, and then
  // returns that one instead (nothing when inserted): concurrent retries of one request, from one
  // process or several sharing the database, insert once.
  virtual absl::StatusOr<std::optional<v1::SceneInfo>> InsertScene(const std::string& id,
                                                                   const v1::SceneInfo& scene) = 0;
  virtual absl::StatusOr<v1::SceneInfo> GetScene(
      const std::string& id) = 0;  // NOT_FOUND if absent.
  virtual absl::StatusOr<std::optional<v1::SceneInfo>> FindSceneByRequest(
      const std::string& tenant, const std::string& request_id) = 0;
  // The tenant's scenes, newest first; `page_token` is the previous page's next_page_token.
  virtual absl::StatusOr<v1::ListScenesResponse> ListScenes(const std::string& tenant,
                                                            int page_size,
                                                            const std::string& page_token) = 0;
  virtual absl::Status DeleteScene(const std::string& id) = 0;
  // Every tenant's scenes, oldest first (copying a store: radiosity-server --copy-from).
  virtual absl::StatusOr<std::vector<v1::SceneInfo>> AllScenes() = 0;

  // Jobs. Ids are the part after "jobs/"; the state column follows job.state().
  // Inserts the job unless one with its request_id (when not empty) exists, as InsertScene.
  virtual absl::StatusOr<std::optional<v1::Job>> InsertJob(const std::string& id,
                                                           const v1::Job& job) = 0;
  virtual absl::Status UpdateJob(const std::string& id, const v1::Job& job) = 0;
  virtual absl::StatusOr<v1::Job> GetJob(const std::string& id) = 0;  // NOT_FOUND if absent.
  virtual absl::StatusOr<std::optional<v1::Job>> FindJobByRequest(
      const std::string& tenant, const std::string& request_id) = 0;
  // The tenant's jobs, newest first.
  virtual absl::StatusOr<v1::ListJobsResponse> ListJobs(const std::string& tenant,
                                                        const v1::ListJobsRequest& request) = 0;
  // Jobs in the given states, oldest first (for recovery after a restart).
  virtual absl::StatusOr<std::vector<v1::Job>> JobsInStates(
      const std::vector<v1::JobState>& states) = 0;
  // Number of jobs on a scene (every scene's when `scene_name` is empty) in the given states (all
  // states when empty).
  virtual absl::StatusOr<int64_t> CountJobs(const std::string& scene_name,
                                            const std::vector<v1::JobState>& states) = 0;
  virtual absl::Status DeleteJob(const std::string& id) = 0;
  virtual absl::StatusOr<TenantUsage> Usage(const std::string& tenant) = 0;

  // Job leases: how workers of several replicas share one queue. A worker claims a job for a
  // while (its lease), renews the lease as it works, and writes the job only while it holds it.
  // A job whose lease ran out (its worker was killed, or lost the store) can be claimed again.
  // Lease times are the database's clock (PostgreSQL's now(); SQLite's: this machine's).
  struct Claim {
    v1::Job job;                    // As stored: QUEUED, or RUNNING when its last lease expired.
    bool cancel_requested = false;  // RequestCancel came before the claim.
  };
  // Claims the oldest job that is QUEUED or RUNNING, and has no owner or an expired lease, for
  // `owner` until now + `lease`; nothing when there is none. One claimer gets each job, however
  // many processes claim at once (PostgreSQL: SELECT ... FOR UPDATE SKIP LOCKED).
  virtual absl::StatusOr<std::optional<Claim>> ClaimJob(const std::string& owner,
                                                        absl::Duration lease) = 0;
  // ClaimJob of the job `id` only (a cancel ends a queued job at once this way); nothing when it
  // has ended or another holds an unexpired lease on it.
  virtual absl::StatusOr<std::optional<Claim>> ClaimJobById(const std::string& id,
                                                            const std::string& owner,
                                                            absl::Duration lease) = 0;
  // Extends `owner`'s lease to now + `lease`, and says whether a cancel was requested. ABORTED
  // ("lease lost") when the job is no longer `owner`'s: another claimed it, or it ended.
  virtual absl::StatusOr<bool> RenewLease(const std::string& id, const std::string& owner,
                                          absl::Duration lease) = 0;
  // UpdateJob for the lease's holder only (ABORTED otherwise, nothing written). A state other
  // than RUNNING ends the lease: QUEUED gives the job back to the queue, an ended state ends it.
  virtual absl::Status UpdateLeasedJob(const std::string& id, const std::string& owner,
                                       const v1::Job& job) = 0;
  // Asks the job's holder to cancel it; it learns at its next RenewLease (or its claim).
  virtual absl::Status RequestCancel(const std::string& id) = 0;
  // Jobs whose lease has not expired.
  virtual absl::StatusOr<int64_t> CountLeased() = 0;
  // Bytes of every tenant's scenes and results.
  virtual absl::StatusOr<int64_t> TotalBytes() = 0;
};

// Opens (creating and migrating if needed) the store `spec` names:
//   ""                          SQLite at DATA_DIR/radiosity.db (the default);
//   "sqlite:DIR"                SQLite at DIR/radiosity.db;
//   "postgresql://..." or "postgres://..."   PostgreSQL (a libpq connection URI);
//   "file:PATH"                 the first line of PATH is the spec (a connection string kept out
//                               of the command line and the process list, as a mounted secret).
// Errors name the spec as given (a URI's password hidden) and what is wrong.
absl::StatusOr<std::unique_ptr<Store>> OpenStore(const std::string& spec,
                                                 const std::string& data_dir);

// `uri` with the password of a PostgreSQL URI (user:PASSWORD@ or password=...) replaced by "***".
std::string HidePassword(const std::string& uri);

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_STORE_H_
