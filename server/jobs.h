// Jobs: a bounded queue, a pool of workers that run solves (RunJob) and view-factor jobs, their
// persistence in the Store, and the snapshot channel of every job that has not ended.
//
// Durability: every state change is written to the Store before it is visible. On start-up,
// queued jobs are queued again in creation order and jobs that were running are re-run from the
// start (their results were never published), so a restart loses nothing. On shutdown, running
// solves are stopped and put back in the queue, not cancelled.
#ifndef RADIOSITY_SERVER_JOBS_H_
#define RADIOSITY_SERVER_JOBS_H_

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "radiosity/v1/service.pb.h"
#include "server/data_dir.h"
#include "server/metrics.h"
#include "server/snapshots.h"
#include "server/store.h"

namespace radiosity::service {

struct ServiceOptions {
  std::string data_dir;
  // Jobs solved at the same time.
  int workers = 1;
  // Jobs waiting for a worker; CreateJob beyond it is RESOURCE_EXHAUSTED.
  int max_queued = 64;
  // Solver threads per job (0: all cores); a job asking for more gets this many.
  int threads_per_job = 0;
  // Largest upload (sum of its files).
  int64_t max_upload_bytes = int64_t{256} << 20;
  // Largest mesh, checked with Mesh::CountElements before meshing.
  int64_t max_elements = 20'000'000;
  // Memory one job may use (estimated before it is queued; 0: no limit). Also caps the matrix
  // of the matrix methods.
  int64_t max_memory_mb = 16384;
};

// Estimated peak memory of a solve with this many elements and image pixels (bytes).
int64_t EstimateSolveBytes(int64_t elements, int64_t pixels);

class JobManager {
 public:
  JobManager(const ServiceOptions& options, const DataDir& dir, Store* store, Metrics* metrics);
  ~JobManager();

  // Recovers jobs from the store and starts the workers.
  absl::Status Start();

  absl::StatusOr<v1::Job> Create(const v1::CreateJobRequest& request);
  absl::StatusOr<v1::Job> Get(const std::string& id);
  absl::StatusOr<v1::ListJobsResponse> List(const v1::ListJobsRequest& request);
  absl::StatusOr<v1::Job> Cancel(const std::string& id);
  absl::Status Delete(const std::string& id);
  // The snapshot channel of a job that has not ended; null when it has (or does not exist).
  std::shared_ptr<JobChannel> Channel(const std::string& id);

  // Stops taking jobs, stops the running ones (they are queued again) and closes every channel
  // with UNAVAILABLE. Join() then waits for the workers.
  void BeginShutdown();
  void Join();

  int64_t QueueDepth();
  int64_t RunningJobs();
  double RaysPerSecond();

 private:
  struct Active {
    std::string id;
    std::mutex mu;  // Guards job, next_sequence, next_mesh_version, last_persist.
    v1::Job job;    // Authoritative while the job is active.
    int64_t next_sequence = 1;
    int64_t next_mesh_version = 1;
    std::chrono::steady_clock::time_point last_persist;
    std::atomic<bool> stop{false};
    std::shared_ptr<JobChannel> channel = std::make_shared<JobChannel>();
  };
  // What a worker's run came to.
  struct Outcome {
    absl::Status status;                          // Not OK: FAILED with this.
    bool requeue = false;                         // Stopped by shutdown: queue again.
    bool cancelled = false;                       // Stopped by CancelJob.
    std::shared_ptr<const FloatBlock> radiosity;  // Final radiosity, if any.
    MeshPtr mesh;                                 // The mesh it refers to, if known.
  };
  static Outcome Failed(absl::Status status) {
    Outcome o;
    o.status = std::move(status);
    return o;
  }
  static Outcome Requeue() {
    Outcome o;
    o.requeue = true;
    return o;
  }

  void WorkerLoop();
  void RunOne(const std::shared_ptr<Active>& active);
  Outcome RunSolve(const std::shared_ptr<Active>& active, const v1::Job& job);
  Outcome RunViewFactor(const std::shared_ptr<Active>& active, const v1::Job& job);
  // Moves the work directory to results and lists its files into `job`.
  absl::Status PublishResults(const std::string& id, const std::vector<std::string>& files,
                              v1::Job* job);
  // Ends an active job: persists it, drops it from the active set, publishes the final snapshot.
  void End(const std::shared_ptr<Active>& active, std::shared_ptr<const FloatBlock> radiosity,
           MeshPtr mesh);
  void PersistLocked(Active& active);
  int ThreadsFor(int requested) const;

  const ServiceOptions options_;
  const DataDir dir_;
  Store* const store_;
  Metrics* const metrics_;

  std::mutex mu_;
  std::condition_variable cv_;
  std::deque<std::string> queue_;
  std::map<std::string, std::shared_ptr<Active>> active_;
  bool shutting_down_ = false;
  std::vector<std::thread> workers_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_JOBS_H_
