// Jobs: a bounded queue, a pool of workers that run solves (RunJob) and view-factor jobs, their
// persistence in the Store, and the snapshot channel of every job that has not ended.
//
// Durability: every state change is written to the Store before it is visible. On start-up,
// queued jobs are queued again in creation order and jobs that were running are re-run from the
// start (their results were never published), so a restart loses nothing. On shutdown, running
// solves are stopped and put back in the queue, not cancelled.
//
// Ordering, and which lock is held where (no lock that a reader takes is ever held across a
// database write):
//  - A job is inserted in the Store (QUEUED) before it enters the queue and the set of active
//    jobs, so whatever can see it can also read it back after a restart. CreateJob's check of the
//    queue's room and its entry are two short steps under mu_ with the insert between them, done
//    without a lock (a slot is reserved meanwhile, so concurrent creations never overfill it).
//  - Each active job has two locks. `write_mu` serializes the changes of that job: a change takes
//    it, copies the job, edits the copy, writes the copy to the Store and only then installs it
//    under `mu`, the lock of the copy that readers (Get, List, metrics) see. So a reader never
//    waits for the database, and the changes of one job reach the Store in the order they become
//    visible: the stored row is never older than a state a reader has seen, except as below.
//  - Progress and the last snapshot sequence are visible at once and written at most
//    kPersistSeconds later, with the next write of the job; a re-run after a crash numbers its
//    snapshots kSequenceGap ahead so that numbers never repeat.
//  - Ending a job writes its final row, installs it, then drops the job from the active set
//    (Get reads the Store from then on: the same row) and only then publishes the final snapshot.
//  - A write that fails is logged and the change is made all the same, so a job can always end.
//  - Lock order: write_mu, then mu_, then mu. The Store's own lock is taken only inside it.
//  - A retried CreateJob (same request_id) answers with Get of the job it created, on every path:
//    the live copy while the job is active, the stored row once it has ended, and these are the
//    same representation (the row is the copy that was last installed).
//
// Replicas (ServiceOptions::blob_dir set, a PostgreSQL store shared by several servers): there
// is no queue in memory. CreateJob inserts the job QUEUED in the store; idle workers claim the
// oldest claimable job (Store::ClaimJob) and hold it under a lease that LeaseLoop renews. Only
// the lease's holder writes the job (Store::UpdateLeasedJob): a worker that loses its lease (it
// could not renew in time, or another claimed the job) stops the solve and writes nothing more.
// A job whose holder died is claimed again once its lease runs out and resumes from its
// checkpoint (in the shared blob directory) as after a restart. Cancel of a job held elsewhere is
// stored (Store::RequestCancel) and reaches its holder at its next renewal; a queued one is
// claimed and ended at once. Shutdown gives running jobs back to the queue.
//
// Scene deletion: Create loads the scene from its files; the caller keeps it from being deleted
// meanwhile (RadiosityServiceImpl holds a SceneRefs reference). Once inserted, the job is counted
// by Store::CountJobs, which DeleteScene consults.
#ifndef RADIOSITY_SERVER_JOBS_H_
#define RADIOSITY_SERVER_JOBS_H_

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "absl/time/time.h"
#include "proto/api/names.h"
#include "radiosity/v1/service.pb.h"
#include "server/call_limits.h"
#include "server/data_dir.h"
#include "server/metrics.h"
#include "server/snapshots.h"
#include "server/store.h"
#include "server/tenants.h"

namespace radiosity::service {

struct ServiceOptions {
  std::string data_dir;
  // Where scenes and jobs are recorded (OpenStore, server/store.h): "" is SQLite in data_dir.
  std::string store;
  // Replicas (docs/service/stores.md): scenes and jobs' files in this directory, which every
  // replica of one PostgreSQL store mounts; workers then claim jobs from the store under a lease
  // instead of keeping a queue in memory. "": one server owns its store and data directory.
  std::string blob_dir;
  // How long a claim lasts without renewal; a worker renews every quarter of it, and stops a job
  // whose lease it could not renew in time (another replica may have claimed it).
  double lease_seconds = 10;
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
  // A job that ends the server process this many times (Job.lost_attempts) is failed rather than
  // run again (a poison job would otherwise loop through restarts forever).
  int max_attempts = 3;
  // Seconds of solving between checkpoints of a running job (docs/service/server.md; 0: none).
  double checkpoint_seconds = 10;
  // The server's --tokens-file: every call must carry a bearer token it maps to a tenant (null:
  // no tokens, every call is the tenant "").
  std::shared_ptr<TokenTable> tokens;
  // Per-tenant quotas, and the server's stored-bytes cap (0: none).
  TenantQuotas quotas;
  // Open uploads and watch streams.
  CallLimitOptions limits;
};

// Estimated peak memory of a solve with this many elements and image pixels (bytes).
int64_t EstimateSolveBytes(int64_t elements, int64_t pixels);

class JobManager {
 public:
  JobManager(const ServiceOptions& options, const DataDir& dir, Store* store, Metrics* metrics);
  // Raised when shutdown begins (BeginShutdown): long loads outside jobs stop on it.
  const std::atomic<bool>* stopping() const { return &stopping_; }
  ~JobManager();

  // Recovers jobs from the store and starts the workers.
  absl::Status Start();

  // Checks the request (loading the scene and counting its elements, which takes long for a large
  // scene; no lock is held meanwhile), then inserts the job and queues it. A request_id used
  // before by the tenant answers with Get of the job it created. The scene must be the tenant's;
  // the job is, and counts towards the tenant's quotas.
  absl::StatusOr<v1::Job> Create(const v1::CreateJobRequest& request, const std::string& tenant);
  // The live copy of an active job, else the stored row (whoever its tenant).
  absl::StatusOr<v1::Job> Get(const std::string& id);
  // Get, NOT_FOUND ("jobs/ID does not exist", as for a job that does not) unless it is the
  // tenant's.
  absl::StatusOr<v1::Job> GetOwned(const std::string& id, const std::string& tenant);
  // The tenant's jobs.
  absl::StatusOr<v1::ListJobsResponse> List(const std::string& tenant,
                                            const v1::ListJobsRequest& request);
  absl::StatusOr<v1::Job> Cancel(const std::string& id);
  absl::Status Delete(const std::string& id);
  // The snapshot channel of a job that has not ended; null when it has (or does not exist).
  // Replicas: a job queued in the store or running on another replica has one too, fed from its
  // row: progress snapshots without radiosity (FollowLoop).
  std::shared_ptr<JobChannel> Channel(const std::string& id);

  // Stops taking jobs, stops the running ones (they are queued again) and closes every channel
  // with UNAVAILABLE. Join() then waits for the workers.
  void BeginShutdown();
  void Join();

  int64_t QueueDepth();
  int64_t RunningJobs();
  double RaysPerSecond();

  // Whether the store takes writes: false from a failed write of a job (a full disk, say) until
  // a write succeeds and no ended job waits to be written. `on_change` (called on each change,
  // from the thread that wrote; must not block) lets the server's health follow it.
  bool StoreWritable() const { return !store_failing_; }
  void OnStoreWritableChange(std::function<void(bool writable)> on_change);

  QuotaKeeper& quotas() { return quotas_; }

 private:
  struct Active {
    std::string id;
    // Serializes the changes of `job` (above); guards next_sequence, next_mesh_version and
    // last_persist. Held across the store write, so never taken by readers.
    std::mutex write_mu;
    std::mutex mu;  // Guards `job`; held only to copy it in or out.
    v1::Job job;    // Authoritative while the job is active.
    int64_t next_sequence = 1;
    int64_t next_mesh_version = 1;
    std::chrono::steady_clock::time_point last_persist;
    std::atomic<bool> stop{false};
    std::shared_ptr<JobChannel> channel = std::make_shared<JobChannel>();
    // The process's resident bytes when the job started running (-1: not running), and whether
    // MemoryLoop stopped it for passing --max-memory-mb (then it fails RESOURCE_EXHAUSTED).
    std::atomic<int64_t> rss_at_start{-1};
    std::atomic<bool> over_memory{false};
    // Replicas: when this replica last renewed the job's lease, and whether it lost it (then the
    // job is stopped and nothing more of it is written: another replica may run it).
    std::atomic<std::chrono::steady_clock::time_point> lease_renewed{};
    std::atomic<bool> lease_lost{false};
    // A cancel learnt at a lease renewal (the store has it; the job's end records it).
    std::atomic<bool> cancel_seen{false};
  };
  // What a worker's run came to.
  struct Outcome {
    absl::Status status;                          // Not OK: FAILED with this.
    bool requeue = false;                         // Stopped by shutdown: queue again.
    bool cancelled = false;                       // Stopped by CancelJob.
    std::shared_ptr<const FloatBlock> radiosity;  // Final radiosity, if any.
    std::shared_ptr<const FloatBlock> std_error;  // Its standard errors, if estimated.
    MeshPtr mesh;                                 // The mesh it refers to, if known.
    // What a run that did not fail adds to the job (results, statistics, stop reason).
    std::function<void(v1::Job*)> finish;
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

  void StartThreads();
  void WorkerLoop();
  // A job read back from the store after its server or worker ended (Start, ClaimNext): a lost
  // attempt if it was running (FAILED past --max-attempts), CANCELLED if a cancel was asked,
  // else QUEUED; numbering of snapshots continues; stale work files removed.
  void Recover(v1::Job* job, Active* active);
  // Replicas (shared_): CreateJob's insert into the store's queue.
  absl::StatusOr<v1::Job> CreateShared(const std::string& id, const v1::Job& job,
                                       const std::string& tenant);
  // Replicas: claims the oldest claimable job from the store and makes it active here (null when
  // there is none, or it ended at the claim: cancelled, or past --max-attempts).
  std::shared_ptr<Active> ClaimNext();
  // Replicas: renews the leases of this replica's jobs every quarter of the lease; a cancel asked
  // on another replica, a lease lost, or no renewal for a whole lease stops the job.
  void LeaseLoop();
  void LoseLease(Active& active, absl::string_view why);
  // Replicas: stops (LoseLease) every job whose lease may have run out because no renewal
  // succeeded within kLeaseSafety of it, every 0.1 s, whatever the store does meanwhile.
  void LeaseWatchdog();
  // Whether this replica still holds the job's lease by its own clock (true without replicas);
  // LoseLease when not. Checked before changing the job's shared files.
  bool LeaseHeld(Active& active);
  // A cancel asked of the job, here or (replicas) on another replica.
  bool CancelAsked(Active& active);
  // The directory a run writes its results in (replicas: one per claim).
  std::string WorkDir(const std::string& id) const;
  // An ended job's checkpoint and (replicas) other claims' work directories.
  void RemoveEndedJobFiles(const std::string& id);
  // A cancel learnt at renewal: as Cancel of a running job.
  void CancelHeld(Active& active);
  // Replicas: Cancel of a job not active here (queued in the store, or on another replica).
  absl::StatusOr<v1::Job> CancelElsewhere(const std::string& id);
  void DropLost(Active& active);
  // Replicas: the snapshots of jobs watched here that run elsewhere, every kFollowPoll: the
  // holder's latest with radiosity (live_share.h: asked for by touching a file), else progress
  // from the row; ends each when its job ends or moves here (the watchers resume and find the
  // final snapshot or the job's own channel), or nobody watches it.
  void FollowLoop();
  // Replicas: when a running job may next share its latest snapshot, and whether the last try
  // failed (logged once).
  struct LiveWrites {
    std::chrono::steady_clock::time_point next;
    bool failed = false;
  };
  // Replicas: shares `snapshot` through the blob directory (live_share.h) when a replica's
  // watchers follow the job, at most every 0.5 s and a tenth of the time, and only while the
  // lease is held.
  void ShareLive(Active& active, const Snapshot& snapshot, LiveWrites* live);
  // A progress snapshot of a job as its row has it.
  static SnapshotPtr RowSnapshot(const v1::Job& job);
  absl::Duration LeaseDuration() const;
  // The hard memory cap: samples the process's resident memory every 50 ms while jobs run; when
  // it has grown since the earliest running job started by more than --max-memory-mb per
  // running job, stops the job that started last (over_memory).
  void MemoryLoop();
  // Retries, every second until shutdown, the store writes of jobs that ended while it failed.
  void RetryLoop();
  // Records whether a store write succeeded (StoreWritable).
  void NoteStoreWrite(bool ok);
  // The stored row of a job that is not active, or the in-memory end of one whose end could not
  // be written yet.
  absl::StatusOr<v1::Job> GetInactive(const std::string& id);
  void RunOne(const std::shared_ptr<Active>& active);
  // The outcome of a job a step of which (loading, meshing) ended with `status`.
  Outcome StoppedOrFailed(Active& active, const absl::Status& status);
  Outcome RunSolve(const std::shared_ptr<Active>& active, const v1::Job& job);
  Outcome RunViewFactor(const std::shared_ptr<Active>& active, const v1::Job& job);
  // Moves the work directory to results and lists its files (with checksums) in `results`.
  absl::Status PublishResults(Active& active, const std::vector<std::string>& files,
                              std::vector<v1::FileInfo>* results);
  std::shared_ptr<Active> FindActive(const std::string& id);
  // The job as readers see it.
  static v1::Job Current(Active& active);
  // With write_mu held: writes `next` to the store, then installs it as the job (also when the
  // write fails: memory stays the truth). Returns whether the write succeeded.
  bool CommitLocked(Active& active, v1::Job next);
  // With write_mu held: the store write of CommitLocked and PersistLocked (replicas: only while
  // this replica holds the lease; ABORTED, and the lease lost, otherwise).
  absl::Status WriteLocked(Active& active, const v1::Job& job);
  // With write_mu held: writes the job as it is (progress written late, see above).
  void PersistLocked(Active& active);
  // With write_mu held: ends the job as `next` (its state already ended): commits it with its
  // end time and final sequence, drops it from the active set and the queue (kept in
  // unpersisted_ if the store did not take the end). Returns the final
  // snapshot, for the caller to publish once it has released write_mu.
  SnapshotPtr EndLocked(Active& active, v1::Job next, std::shared_ptr<const FloatBlock> radiosity,
                        MeshPtr mesh, std::shared_ptr<const FloatBlock> std_error = nullptr);
  int ThreadsFor(int requested) const;

  const ServiceOptions options_;
  const DataDir dir_;
  Store* const store_;
  Metrics* const metrics_;
  // Replicas (--blob-dir): jobs are claimed from the store under leases held as `owner_`.
  const bool shared_;
  const std::string owner_;
  const std::string work_suffix_ = NewId().substr(0, 8);
  std::thread watchdog_thread_;
  std::thread lease_thread_;
  std::condition_variable lease_cv_;
  std::atomic<bool> claim_failing_{false};
  struct Followed {
    std::shared_ptr<JobChannel> channel = std::make_shared<JobChannel>();
    std::chrono::steady_clock::time_point since;
    // The mesh of the latest live snapshot read (FollowLoop's only; shared by the map's copies).
    std::shared_ptr<MeshPtr> mesh = std::make_shared<MeshPtr>();
  };
  std::map<std::string, Followed> followed_;  // Guarded by mu_.
  std::condition_variable follow_cv_;
  std::thread follow_thread_;

  std::mutex mu_;  // Guards what follows; held only for in-memory steps.
  std::condition_variable cv_;
  std::deque<std::string> queue_;
  int64_t creating_ = 0;  // Creations between their check of the queue's room and their entry.
  std::map<std::string, std::shared_ptr<Active>> active_;
  bool shutting_down_ = false;
  // Raised with shutting_down_; read without the lock by loads that must not outlive a shutdown.
  std::atomic<bool> stopping_{false};
  std::vector<std::thread> workers_;
  // Ended jobs whose end the store has not taken yet (a full disk): what Get, List, Cancel,
  // Delete and WatchJob report for them, until RetryLoop writes it.
  std::map<std::string, v1::Job> unpersisted_;
  std::function<void(bool)> on_store_writable_;
  std::thread retry_thread_;
  std::thread memory_thread_;
  std::condition_variable retry_cv_;  // Wakes RetryLoop (the workers have cv_ to themselves).
  bool workers_joined_ = false;       // Join has joined the workers: RetryLoop's last round.
  std::atomic<bool> store_failing_{false};
  QuotaKeeper quotas_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_JOBS_H_
