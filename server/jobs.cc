#include "server/jobs.h"

#include <google/protobuf/util/message_differencer.h>
#include <malloc.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>

#include "absl/cleanup/cleanup.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "proto/api/names.h"
#include "proto/api/sha256.h"
#include "proto/api/spec.h"
#include "proto/api/status.h"
#include "server/live_share.h"
#include "server/logging.h"
#include "solver/geometry/mesh.h"
#include "solver/methods/viewfactor.h"
#include "solver/pipeline/job.h"
#include "solver/results/exchange_csv.h"
#include "solver/results/viewfactor_csv.h"
#include "solver/util/file_io.h"

namespace radiosity::service {
namespace {

namespace fs = std::filesystem;
using google::protobuf::util::MessageDifferencer;

// How often a running job's progress is written to the store.
constexpr double kPersistSeconds = 1.0;
// Replicas: how often an idle worker asks the store for a job (a CreateJob on its own replica
// wakes it at once).
constexpr std::chrono::milliseconds kClaimPoll(500);
// Replicas: the share of the lease after the start of its last renewal beyond which a worker
// stops its job without waiting to hear that it lost it.
constexpr double kLeaseSafety = 0.8;
// Replicas: how often the row of a job watched here but running on another replica is read.
constexpr std::chrono::milliseconds kFollowPoll(250);

// Removes temporary files a killed checkpoint write left in the job's directory and, unless
// `keep_checkpoint`, the checkpoint itself (whatever it is: a directory put there is removed too).
void RemoveCheckpointFiles(const DataDir& dir, const std::string& id, bool keep_checkpoint) {
  std::error_code ec;
  const std::string name = fs::path(dir.Checkpoint(id)).filename().string();
  for (const auto& entry : fs::directory_iterator(dir.Job(id), ec)) {
    const std::string file = entry.path().filename().string();
    if ((file == name && !keep_checkpoint) || file.rfind(name + ".tmp-", 0) == 0) {
      fs::remove_all(entry.path(), ec);
    }
  }
}

bool IsEnded(v1::JobState s) {
  return s == v1::JOB_STATE_SUCCEEDED || s == v1::JOB_STATE_FAILED || s == v1::JOB_STATE_CANCELLED;
}

void SetProgress(const Progress& p, v1::JobProgress* out) {
  out->set_step(p.step);
  out->set_shots(p.shots);
  out->set_rays(p.rays);
  out->set_unshot_fraction(p.unshot_fraction);
  out->set_elapsed_seconds(p.seconds);
  out->set_rays_per_second(p.seconds > 0 ? p.rays / p.seconds : 0);
  out->set_phase(v1::JOB_PHASE_SOLVING);
  out->set_phase_fraction(0);
  out->clear_phase_item();
}

absl::Status WriteFloats(const std::string& path, const std::vector<float>& data) {
  return WriteFileAtomically(
      path, absl::string_view(reinterpret_cast<const char*>(data.data()), data.size() * 4));
}

// Checks the element count of a solve against the server's limit before anything is allocated.
// solve.mesh.max_elements against the server's --max-elements.
absl::Status CheckMaxElements(const JobSpec& spec, int64_t limit) {
  if (spec.mesh.max_elements <= limit) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrCat(
      "solve.mesh.max_elements: max elements ", spec.mesh.max_elements,
      " is above this server's limit of ", limit, " elements (the server's --max-elements)"));
}

absl::Status CheckElementCount(const Scene& scene, const JobSpec& spec, int64_t limit,
                               int64_t* elements) {
  if (spec.mesh.element_size <= 0) {
    if (absl::Status st = CheckMaxElements(spec, limit); !st.ok()) return st;
    *elements = spec.mesh.max_elements;
    return absl::OkStatus();
  }
  // Cheap bounds first: the bounding box's diagonal bounds every edge, and area / size^2 bounds
  // the count from below; only then count exactly (Mesh::CountElements, no allocation per
  // element).
  Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  double area = 0;
  for (const Face& f : scene.faces) {
    for (int v : f.vertices) {
      lo = Min(lo, scene.vertices[v]);
      hi = Max(hi, scene.vertices[v]);
    }
    area += PolygonArea(scene, f);
  }
  const double size = spec.mesh.element_size;
  const double diagonal = Length(hi - lo);
  if (diagonal / size > kMaxEdgeRatio || area / (size * size) > static_cast<double>(limit)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "solve.mesh.element_size: element size %g is too small for this scene (%.3g square "
        "units, %g across): the mesh would have over %d elements, this server's limit (its "
        "--max-elements); use a larger element size",
        size, area, diagonal, limit));
  }
  int64_t count = Mesh::CountElements(scene, size, spec.mesh.patch_depth);
  if (count > limit) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "solve.mesh.element_size: the mesh would have %d elements, above this server's limit "
        "of %d; use a larger element size",
        count, limit));
  }
  *elements = count;
  return absl::OkStatus();
}

// This process's name as the holder of job leases: host, pid and a random part (a pid is reused
// across restarts and containers).
std::string WorkerName() {
  char host[256] = {};
  if (gethostname(host, sizeof(host) - 1) != 0) host[0] = 0;
  return absl::StrCat(host, ":", getpid(), ":", NewId().substr(0, 8));
}

}  // namespace

int64_t EstimateSolveBytes(int64_t elements, int64_t pixels) {
  // Per element: the element and its quadtree nodes (~100 B), Embree's quads and BVH (~150 B per
  // face, faces <= elements), two sides of radiosity and unshot power in double (~100 B), packed
  // snapshots (24 B each, a few alive), the announced mesh geometry (~100 B, one or two versions
  // alive), corner radiosity for output (~200 B), margin. Per pixel:
  // the float image, the sample buffer and the 8-bit copy.
  return elements * 1024 + pixels * 64 + (int64_t{64} << 20);
}

JobManager::JobManager(const ServiceOptions& options, const DataDir& dir, Store* store,
                       Metrics* metrics)
    : options_(options),
      dir_(dir),
      store_(store),
      metrics_(metrics),
      shared_(dir.shared()),
      owner_(WorkerName()),
      quotas_(options.quotas, store) {}

JobManager::~JobManager() {
  BeginShutdown();
  Join();
}

int JobManager::ThreadsFor(int requested) const {
  int cap = options_.threads_per_job > 0
                ? options_.threads_per_job
                : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  if (requested <= 0) return options_.threads_per_job > 0 ? cap : 0;
  return std::min(requested, cap);
}

absl::Status JobManager::Start() {
  // Leftovers of a previous run: uploads that never completed, results half written.
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir_.Uploads(), ec)) {
    fs::remove_all(entry.path(), ec);
  }
  if (shared_) {
    // Replicas: the store's queue is everyone's; a job another replica lost is claimed when its
    // lease runs out (ClaimNext), not recovered here.
    LogLine("replica_started")
        .Str("worker", owner_)
        .Str("blob_dir", dir_.blob_root())
        .Num("lease_seconds", options_.lease_seconds)
        .Info();
    StartThreads();
    return absl::OkStatus();
  }
  absl::StatusOr<std::vector<v1::Job>> jobs =
      store_->JobsInStates({v1::JOB_STATE_QUEUED, v1::JOB_STATE_RUNNING});
  if (!jobs.ok()) return jobs.status();
  // Each recovered job is written back before it is queued (no lock: the workers and the RPCs
  // have not started).
  std::vector<std::shared_ptr<Active>> queued;
  for (v1::Job& job : *jobs) {
    std::string id = IdFromName(job.name(), "jobs");
    auto active = std::make_shared<Active>();
    active->id = id;
    Recover(&job, active.get());
    if (absl::Status st = store_->UpdateJob(id, job); !st.ok()) return st;
    active->job = std::move(job);
    active->last_persist = std::chrono::steady_clock::now();
    if (active->job.state() == v1::JOB_STATE_QUEUED) queued.push_back(std::move(active));
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    for (const auto& active : queued) {
      active_[active->id] = active;
      queue_.push_back(active->id);
    }
  }
  LogLine("jobs_recovered").Int("queued", static_cast<int64_t>(queued.size())).Info();
  StartThreads();
  return absl::OkStatus();
}

void JobManager::StartThreads() {
  const int workers = std::max(1, options_.workers);
  for (int i = 0; i < workers; ++i) workers_.emplace_back([this] { WorkerLoop(); });
  retry_thread_ = std::thread([this] { RetryLoop(); });
  if (options_.max_memory_mb > 0) memory_thread_ = std::thread([this] { MemoryLoop(); });
  if (shared_) {
    lease_thread_ = std::thread([this] { LeaseLoop(); });
    watchdog_thread_ = std::thread([this] { LeaseWatchdog(); });
    follow_thread_ = std::thread([this] { FollowLoop(); });
  }
}

void JobManager::Recover(v1::Job* job_ptr, Active* active) {
  v1::Job& job = *job_ptr;
  const std::string& id = active->id;
  std::error_code ec;
  fs::remove_all(WorkDir(id), ec);
  const bool was_running = job.state() == v1::JOB_STATE_RUNNING;
  // Every snapshot's number is persisted before it is published: numbering continues.
  active->next_sequence = job.last_sequence() + 1;
  if (was_running) {
    // The previous process ended while the job ran: a lost attempt.
    job.set_lost_attempts(job.lost_attempts() + 1);
    if (job.lost_attempts() >= options_.max_attempts && !job.cancel_requested()) {
      job.set_state(v1::JOB_STATE_FAILED);
      *job.mutable_end_time() = Now();
      job.clear_results();
      job.mutable_error()->set_code(static_cast<int>(absl::StatusCode::kInternal));
      job.mutable_error()->set_message(absl::StrCat(
          "the server process ended while this job ran, ", job.lost_attempts(),
          " times (a crash, the memory killer, kill -9, or a shutdown past its grace); it is "
          "not run again (the server's --max-attempts is ",
          options_.max_attempts, ")"));
      LogLine("job_failed")
          .Str("job", id)
          .Str("code", "INTERNAL")
          .Int("lost_attempts", job.lost_attempts())
          .Str("error", job.error().message())
          .Warn();
    } else {
      job.set_state(v1::JOB_STATE_QUEUED);
      LogLine("job_requeued")
          .Str("job", id)
          .Int("attempts", job.attempts())
          .Int("lost_attempts", job.lost_attempts())
          .Info();
    }
  }
  if (job.cancel_requested()) {
    // Cancelled while it ran, and the server stopped before it could end: end it now.
    job.set_state(v1::JOB_STATE_CANCELLED);
    *job.mutable_end_time() = Now();
  }
  // Ended now: the end is a snapshot of its own (WatchJob serves it as the final one).
  if (IsEnded(job.state())) job.set_last_sequence(active->next_sequence);
  RemoveCheckpointFiles(dir_, id, /*keep_checkpoint=*/!IsEnded(job.state()));
}

absl::StatusOr<v1::Job> JobManager::Create(const v1::CreateJobRequest& wire,
                                           const std::string& tenant) {
  // Each named choice in both its forms (enum and deprecated string), for the idempotency check
  // and for what Job.solve returns.
  v1::CreateJobRequest request = wire;
  if (request.has_solve()) {
    if (absl::Status st = NormalizeSpec(request.mutable_solve()); !st.ok()) return st;
  } else if (request.has_view_factor()) {
    if (absl::Status st = NormalizeSpec(request.mutable_view_factor()); !st.ok()) return st;
  }
  const std::string scene_id = IdFromName(request.scene(), "scenes");
  if (scene_id.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("scene: '", request.scene(), "' is not a scene name (scenes/{id})"));
  }
  if (request.spec_case() == v1::CreateJobRequest::SPEC_NOT_SET) {
    return absl::InvalidArgumentError("one of solve or view_factor is required");
  }
  if (request.request_id().size() > 256) {
    return absl::InvalidArgumentError("request_id: longer than 256 bytes");
  }
  if (!request.request_id().empty()) {
    absl::StatusOr<std::optional<v1::Job>> existing =
        store_->FindJobByRequest(tenant, request.request_id());
    if (!existing.ok()) return existing.status();
    if (existing->has_value()) {
      // A retry must ask for the same thing: a key reused for another request is refused rather
      // than answered with a job that is not what was asked for.
      // Jobs stored before the enums hold only the strings: compared normalized too.
      v1::Job stored = **existing;
      if (stored.has_solve()) {
        (void)NormalizeSpec(stored.mutable_solve());
      } else if (stored.has_view_factor()) {
        (void)NormalizeSpec(stored.mutable_view_factor());
      }
      const bool same =
          stored.scene() == "scenes/" + scene_id && stored.has_solve() == request.has_solve() &&
          (request.has_solve()
               ? MessageDifferencer::Equals(stored.solve(), request.solve())
               : MessageDifferencer::Equals(stored.view_factor(), request.view_factor()));
      if (!same) {
        return absl::AlreadyExistsError(absl::StrCat("request_id '", request.request_id(),
                                                     "' was used for a different request (",
                                                     stored.name(), ")"));
      }
      return Get(IdFromName(stored.name(), "jobs"));
    }
  }
  absl::StatusOr<v1::SceneInfo> info = store_->GetScene(scene_id);
  if (!info.ok()) return info.status();
  if (info->tenant() != tenant) {
    return absl::NotFoundError(absl::StrCat("scenes/", scene_id, " does not exist"));
  }

  // Everything that can be checked is checked now, before the job takes a place in the queue.
  if (request.has_solve()) {
    absl::StatusOr<JobSpec> spec = ToJobSpec(request.solve());
    if (!spec.ok()) return spec.status();
    if (shared_) {
      if (absl::Status st = VerifyStoredScene(dir_.Scene(scene_id), *info); !st.ok()) return st;
    }
    const StopToken stop(&stopping_, 0);
    absl::StatusOr<Scene> scene = LoadStoredScene(dir_.Scene(scene_id), *info, nullptr, &stop);
    if (!scene.ok() && scene.status().code() == absl::StatusCode::kCancelled) {
      return absl::UnavailableError("the server is shutting down");
    }
    if (!scene.ok()) {
      return absl::InternalError(absl::StrCat("stored scene ", info->name(),
                                              " no longer loads: ", scene.status().message()));
    }
    if (absl::Status st = ApplyEmitOverrides(spec->emit, &*scene); !st.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("solve.", st.message()));
    }
    if (absl::Status st = LoadStoredLuminaires(dir_.Scene(scene_id), *info, &spec->solve);
        !st.ok()) {
      return st;
    }
    if (!(EmittedPower(*scene).Sum() > 0) && !spec->solve.sky.enabled() &&
        spec->solve.luminaires.empty()) {
      return absl::FailedPreconditionError(absl::StrCat(scene->source, ": ", kNoEmitterMessage));
    }
    int64_t elements = 0;
    if (absl::Status st = CheckElementCount(*scene, *spec, options_.max_elements, &elements);
        !st.ok()) {
      return st;
    }
    if (spec->refine.tolerance > 0) {
      // Refinement spends mesh.max_elements, whatever the first mesh.
      if (absl::Status st = CheckMaxElements(*spec, options_.max_elements); !st.ok()) return st;
      elements = std::max(elements, spec->mesh.max_elements);
    }
    const int64_t bytes =
        EstimateSolveBytes(elements, static_cast<int64_t>(spec->width) * spec->height);
    if (options_.max_memory_mb > 0 && bytes > (options_.max_memory_mb << 20)) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "the solve would need about %d MiB for %d elements, above this server's limit of %d "
          "MiB per job (--max-memory-mb)",
          bytes >> 20, elements, options_.max_memory_mb));
    }
  } else {
    absl::StatusOr<ViewFactorOptions> options = ToViewFactorOptions(request.view_factor());
    if (!options.ok()) return options.status();
  }

  auto active = std::make_shared<Active>();
  active->id = NewId();
  v1::Job& job = active->job;
  job.set_name("jobs/" + active->id);
  job.set_scene("scenes/" + scene_id);
  if (request.has_solve()) {
    *job.mutable_solve() = request.solve();
  } else {
    *job.mutable_view_factor() = request.view_factor();
  }
  job.set_state(v1::JOB_STATE_QUEUED);
  *job.mutable_create_time() = Now();
  job.set_request_id(request.request_id());
  job.set_tenant(tenant);
  // The answer is the job as created (QUEUED): once queued, a worker may start it at once, and
  // `job` is then the worker's to change under active->mu.
  const v1::Job created = job;

  // The tenant's quotas, held until the row is in (or not): then the row counts.
  absl::StatusOr<QuotaKeeper::Reservation> quota = quotas_.ReserveJob(tenant);
  if (!quota.ok()) {
    ++metrics_->jobs_rejected;
    return quota.status();
  }
  if (shared_) return CreateShared(active->id, job, tenant);
  // Reserve a place in the queue, insert the row without a lock, then take the place.
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (shutting_down_) return absl::UnavailableError("the server is shutting down");
    if (static_cast<int64_t>(queue_.size()) + creating_ >= options_.max_queued) {
      ++metrics_->jobs_rejected;
      return absl::ResourceExhaustedError(absl::StrCat("the job queue is full (", queue_.size(),
                                                       " jobs waiting, --max-queued ",
                                                       options_.max_queued, "); retry later"));
    }
    ++creating_;
  }
  bool queued = false;
  int64_t depth = 0;
  absl::StatusOr<std::optional<v1::Job>> existing;
  {
    absl::Cleanup take_place = [&] {
      std::lock_guard<std::mutex> lock(mu_);
      --creating_;
      // After a shutdown began, the stored row is queued again by the next start.
      if (existing.ok() && !existing->has_value() && !shutting_down_) {
        active_[active->id] = active;
        queue_.push_back(active->id);
        cv_.notify_one();
        queued = true;
      }
      depth = static_cast<int64_t>(queue_.size());
    };
    active->last_persist = std::chrono::steady_clock::now();
    existing = store_->InsertJob(active->id, job);
  }
  if (!existing.ok()) return existing.status();
  // A concurrent retry inserted first: the same answer as any retry.
  if (existing->has_value()) return Get(IdFromName((*existing)->name(), "jobs"));
  ++metrics_->jobs_created;
  LogLine("job_created")
      .Str("job", active->id)
      .Str("scene", scene_id)
      .Str("kind", request.has_solve() ? "solve" : "view_factor")
      .Str("tenant", tenant)
      .Str("request", request.request_id())
      .Int("queue_depth", depth)
      .Str("queued", queued ? "now" : "after a restart")
      .Info();
  return created;
}

absl::StatusOr<v1::Job> JobManager::CreateShared(const std::string& id, const v1::Job& job,
                                                 const std::string& tenant) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (shutting_down_) return absl::UnavailableError("the server is shutting down");
  }
  // The queue is the store's: its room is every replica's waiting jobs.
  absl::StatusOr<int64_t> waiting = store_->CountJobs("", {v1::JOB_STATE_QUEUED});
  if (!waiting.ok()) return waiting.status();
  if (*waiting >= options_.max_queued) {
    ++metrics_->jobs_rejected;
    return absl::ResourceExhaustedError(
        absl::StrCat("the job queue is full (", *waiting,
                     " jobs waiting for the replicas' workers, --max-queued ", options_.max_queued,
                     "); retry later"));
  }
  absl::StatusOr<std::optional<v1::Job>> existing = store_->InsertJob(id, job);
  if (!existing.ok()) return existing.status();
  if (existing->has_value()) return Get(IdFromName((*existing)->name(), "jobs"));
  ++metrics_->jobs_created;
  {
    std::lock_guard<std::mutex> lock(mu_);
    cv_.notify_one();  // A worker of this replica that waits claims it at once.
  }
  LogLine("job_created")
      .Str("job", id)
      .Str("scene", job.scene())
      .Str("kind", job.has_solve() ? "solve" : "view_factor")
      .Str("tenant", tenant)
      .Str("request", job.request_id())
      .Int("queue_depth", *waiting + 1)
      .Str("queued", "store")
      .Info();
  return job;
}

std::shared_ptr<JobManager::Active> JobManager::FindActive(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = active_.find(id);
  return it == active_.end() ? nullptr : it->second;
}

v1::Job JobManager::Current(Active& active) {
  std::lock_guard<std::mutex> lock(active.mu);
  return active.job;
}

absl::StatusOr<v1::Job> JobManager::Get(const std::string& id) {
  if (std::shared_ptr<Active> active = FindActive(id)) return Current(*active);
  return GetInactive(id);
}

absl::StatusOr<v1::Job> JobManager::GetOwned(const std::string& id, const std::string& tenant) {
  absl::StatusOr<v1::Job> job = Get(id);
  if (job.ok() && job->tenant() != tenant) {
    return absl::NotFoundError(absl::StrCat("jobs/", id, " does not exist"));
  }
  return job;
}

absl::StatusOr<v1::ListJobsResponse> JobManager::List(const std::string& tenant,
                                                      const v1::ListJobsRequest& request) {
  v1::ListJobsRequest query = request;
  if (!request.scene().empty()) {
    std::string scene_id = IdFromName(request.scene(), "scenes");
    if (scene_id.empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat("scene: '", request.scene(), "' is not a scene name (scenes/{id})"));
    }
    query.set_scene("scenes/" + scene_id);
  }
  absl::StatusOr<v1::ListJobsResponse> response = store_->ListJobs(tenant, query);
  if (!response.ok()) return response;
  // Active jobs: the live copy (progress) rather than the last persisted one; ended ones whose
  // end is not written yet: that end.
  for (v1::Job& job : *response->mutable_jobs()) {
    if (IsEnded(job.state())) continue;
    absl::StatusOr<v1::Job> live = Get(IdFromName(job.name(), "jobs"));
    if (live.ok()) job = *std::move(live);
  }
  return response;
}

absl::StatusOr<v1::Job> JobManager::Cancel(const std::string& id) {
  std::shared_ptr<Active> active = FindActive(id);
  auto not_active = [&]() -> absl::StatusOr<v1::Job> {
    absl::StatusOr<v1::Job> job = GetInactive(id);
    if (!job.ok()) return job.status();
    if (!IsEnded(job->state())) {
      // Inserted by a CreateJob that has not queued it yet (or queued after a restart).
      return absl::UnavailableError(absl::StrCat(job->name(), " is not being tracked yet; retry"));
    }
    return absl::FailedPreconditionError(
        absl::StrCat(job->name(), " has already ended (", StateName(job->state()), ")"));
  };
  // Replicas: a job this replica no longer holds (or never did) is cancelled through the store.
  if (shared_ && (!active || active->lease_lost)) return CancelElsewhere(id);
  if (!active) return not_active();
  SnapshotPtr final_snapshot;
  v1::Job answer;
  bool lost = false;
  {
    std::lock_guard<std::mutex> write(active->write_mu);
    v1::Job next = Current(*active);
    if (IsEnded(next.state())) return not_active();  // It ended meanwhile.
    next.set_cancel_requested(true);
    if (next.state() == v1::JOB_STATE_QUEUED) {
      // It ends now, without results; a worker that took it from the queue finds it ended.
      next.set_state(v1::JOB_STATE_CANCELLED);
      LogLine("job_cancelled").Str("job", id).Str("while", "queued").Info();
      final_snapshot = EndLocked(*active, std::move(next), nullptr, nullptr);
      lost = !final_snapshot;  // Replicas: taken over before its end was written.
    } else {
      // Running: the request is stored before the solve is told to stop.
      if (!CommitLocked(*active, std::move(next)) && active->lease_lost) {
        lost = true;  // Taken over meanwhile: through the store, below.
      }
      active->stop = true;
      LogLine("job_cancel_requested").Str("job", id).Info();
    }
    answer = Current(*active);
  }
  if (final_snapshot) active->channel->Publish(std::move(final_snapshot));
  if (lost) return CancelElsewhere(id);
  return answer;
}

void JobManager::ShareLive(Active& active, const Snapshot& snapshot, LiveWrites* live) {
  const auto now = std::chrono::steady_clock::now();
  if (now < live->next || !snapshot.mesh || !LiveWatched(dir_.Job(active.id)) ||
      !LeaseHeld(active)) {
    return;
  }
  const absl::Status st = WriteLiveSnapshot(dir_.Job(active.id), snapshot);
  const auto took = std::chrono::steady_clock::now() - now;
  // At most one write in 0.5 s, and writing at most a tenth of the time.
  live->next = now + std::max<std::chrono::steady_clock::duration>(std::chrono::milliseconds(500),
                                                                   10 * took);
  if (!st.ok() && !live->failed) {
    LogLine("live_snapshot_failed").Str("job", active.id).Str("error", st.message()).Warn();
  }
  live->failed = !st.ok();
}

void JobManager::RemoveEndedJobFiles(const std::string& id) {
  RemoveCheckpointFiles(dir_, id, /*keep_checkpoint=*/false);
  if (!shared_) return;
  std::error_code ec;
  fs::remove_all(LiveDir(dir_.Job(id)), ec);
  // Work directories of claims that died or lost the job.
  const std::string prefix = fs::path(dir_.Work(id)).filename().string() + "-";
  for (const auto& entry : fs::directory_iterator(dir_.Job(id), ec)) {
    if (entry.path().filename().string().rfind(prefix, 0) == 0) fs::remove_all(entry.path(), ec);
  }
}

absl::StatusOr<v1::Job> JobManager::CancelElsewhere(const std::string& id) {
  absl::StatusOr<v1::Job> job = store_->GetJob(id);
  if (!job.ok()) return job.status();
  if (IsEnded(job->state())) {
    return absl::FailedPreconditionError(
        absl::StrCat(job->name(), " has already ended (", StateName(job->state()), ")"));
  }
  // Stored first: whichever replica holds the job, or claims it next, sees the request.
  if (absl::Status st = store_->RequestCancel(id); !st.ok()) return st;
  absl::StatusOr<std::optional<Store::Claim>> claim =
      store_->ClaimJobById(id, owner_, LeaseDuration());
  if (!claim.ok()) return claim.status();
  if (!claim->has_value()) {
    // Held by a live worker (perhaps this replica's, claimed meanwhile): it stops at its next
    // renewal, within a quarter of the lease.
    LogLine("job_cancel_requested").Str("job", id).Str("holder", "another worker").Info();
    job = store_->GetJob(id);
    if (job.ok() && !IsEnded(job->state())) job->set_cancel_requested(true);
    return job;
  }
  // Waiting (or left by a worker that died): it ends here, without results.
  v1::Job next = std::move((*claim)->job);
  next.set_cancel_requested(true);
  next.set_state(v1::JOB_STATE_CANCELLED);
  *next.mutable_end_time() = Now();
  next.set_last_sequence(next.last_sequence() + 1);  // The end is a snapshot of its own.
  if (absl::Status st = store_->UpdateLeasedJob(id, owner_, next); !st.ok()) return st;
  RemoveEndedJobFiles(id);
  ++metrics_->jobs_cancelled;
  LogLine("job_cancelled").Str("job", id).Str("while", "queued").Info();
  return next;
}

absl::Status JobManager::Delete(const std::string& id) {
  // A job's end is published a moment before its worker lets it go (its files tidied first): a
  // client that deletes it as soon as it sees the end waits for that, instead of being refused.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  for (std::shared_ptr<Active> active = FindActive(id);
       active != nullptr && IsEnded(Current(*active).state()) &&
       std::chrono::steady_clock::now() < deadline;
       active = FindActive(id)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  if (FindActive(id)) {
    return absl::FailedPreconditionError(
        absl::StrCat("jobs/", id, " is queued or running; cancel it first"));
  }
  absl::StatusOr<v1::Job> job = GetInactive(id);
  if (!job.ok()) return job.status();
  if (!IsEnded(job->state())) {
    // Inserted by a CreateJob that has not queued it yet.
    return absl::FailedPreconditionError(
        absl::StrCat("jobs/", id, " is queued or running; cancel it first"));
  }
  if (absl::Status st = store_->DeleteJob(id); !st.ok()) return st;
  {
    std::lock_guard<std::mutex> lock(mu_);
    unpersisted_.erase(id);
  }
  std::error_code ec;
  fs::remove_all(dir_.Job(id), ec);
  LogLine("job_deleted").Str("job", id).Info();
  return absl::OkStatus();
}

std::shared_ptr<JobChannel> JobManager::Channel(const std::string& id) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = active_.find(id);
    if (it != active_.end()) return it->second->channel;
    if (!shared_ || shutting_down_) return nullptr;
    auto followed = followed_.find(id);
    if (followed != followed_.end()) {
      followed->second.since = std::chrono::steady_clock::now();
      return followed->second.channel;
    }
  }
  // Replicas: a job queued in the store or running on another replica is followed through its
  // row (FollowLoop).
  absl::StatusOr<v1::Job> job = store_->GetJob(id);
  if (!job.ok() || IsEnded(job->state())) return nullptr;
  Followed followed;
  followed.since = std::chrono::steady_clock::now();
  if (job->last_sequence() > 0) followed.channel->Publish(RowSnapshot(*job));
  std::lock_guard<std::mutex> lock(mu_);
  if (shutting_down_) return nullptr;
  auto it = active_.find(id);  // Claimed here meanwhile.
  if (it != active_.end()) return it->second->channel;
  auto [at, inserted] = followed_.emplace(id, std::move(followed));
  follow_cv_.notify_all();
  return at->second.channel;
}

SnapshotPtr JobManager::RowSnapshot(const v1::Job& job) {
  auto snapshot = std::make_shared<Snapshot>();
  snapshot->sequence = job.last_sequence();
  snapshot->state = job.state();
  snapshot->progress = job.progress();
  snapshot->elements = job.mesh().elements();
  snapshot->attempts = job.attempts();
  return snapshot;
}

void JobManager::FollowLoop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!shutting_down_) {
    follow_cv_.wait_for(lock, kFollowPoll);
    if (shutting_down_) break;
    const std::map<std::string, Followed> followed = followed_;
    lock.unlock();
    std::vector<std::string> done, unwatched;
    for (const auto& [id, f] : followed) {
      if (!f.channel->HasSinks()) {
        // Nobody watches any more (a second's grace for the first subscriber): ended below.
        if (std::chrono::steady_clock::now() - f.since > std::chrono::seconds(1)) {
          unwatched.push_back(id);
        }
        continue;
      }
      absl::StatusOr<v1::Job> job = store_->GetJob(id);
      if (!job.ok()) continue;  // The store is failing: the watchers wait.
      if (IsEnded(job->state()) || FindActive(id)) {
        // Its final snapshot (read from its results) or its own channel here: the watchers are
        // told to resume, and find either.
        f.channel->Close(absl::UnavailableError(
            absl::StrCat(IsEnded(job->state()) ? "the job has ended" : "the job moved here",
                         "; resume watching after the last snapshot")));
        done.push_back(id);
        continue;
      }
      // Radiosity too when the holder shares it (live_share.h); else the row's progress.
      TouchLiveInterest(dir_.Job(id));
      SnapshotPtr latest = f.channel->latest();
      const int64_t after = latest ? latest->sequence : 0;
      absl::StatusOr<SnapshotPtr> live = ReadLiveSnapshot(dir_.Job(id), after, f.mesh.get());
      if (live.ok() && *live) {
        f.channel->Publish(*std::move(live));
      } else if (job->last_sequence() > after) {
        f.channel->Publish(RowSnapshot(*job));
      }
    }
    lock.lock();
    for (const std::string& id : done) followed_.erase(id);
    for (const std::string& id : unwatched) {
      auto it = followed_.find(id);
      // Channel() hands out an entry only under mu_ and refreshes `since`: one handed out since
      // the check above is kept. A watcher that subscribes after the close is told to resume.
      if (it == followed_.end() ||
          std::chrono::steady_clock::now() - it->second.since <= std::chrono::seconds(1)) {
        continue;
      }
      it->second.channel->Close(absl::UnavailableError("resume watching"));
      followed_.erase(it);
    }
  }
  // Shutting down: watchers of followed jobs resume on another replica.
  for (auto& [id, f] : followed_) {
    f.channel->Close(absl::UnavailableError("the server is shutting down; resume watching"));
  }
  followed_.clear();
}

void JobManager::BeginShutdown() {
  std::vector<std::shared_ptr<Active>> active;
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (shutting_down_) return;
    shutting_down_ = true;
    stopping_ = true;
    for (auto& [id, a] : active_) {
      a->stop = true;
      active.push_back(a);
    }
    cv_.notify_all();
    follow_cv_.notify_all();
  }
  for (auto& a : active) {
    SnapshotPtr latest = a->channel->latest();
    a->channel->Close(absl::UnavailableError(
        absl::StrCat("the server is shutting down; resume watching after sequence ",
                     latest ? latest->sequence : 0)));
  }
  LogLine("shutdown_started").Int("active_jobs", static_cast<int64_t>(active.size())).Info();
}

void JobManager::Join() {
  for (std::thread& t : workers_) {
    if (t.joinable()) t.join();
  }
  workers_.clear();
  // The retry thread makes a last attempt now that the workers are done.
  {
    std::lock_guard<std::mutex> lock(mu_);
    workers_joined_ = true;
    retry_cv_.notify_all();
    lease_cv_.notify_all();
  }
  if (retry_thread_.joinable()) retry_thread_.join();
  if (memory_thread_.joinable()) memory_thread_.join();
  if (lease_thread_.joinable()) lease_thread_.join();
  if (watchdog_thread_.joinable()) watchdog_thread_.join();
  if (follow_thread_.joinable()) follow_thread_.join();
}

namespace {

// Resident bytes of this process (/proc/self/statm), or -1.
int64_t ResidentBytes() {
  std::ifstream in("/proc/self/statm");
  int64_t size = 0, resident = 0;
  if (!(in >> size >> resident)) return -1;
  return resident * static_cast<int64_t>(sysconf(_SC_PAGESIZE));
}

}  // namespace

void JobManager::MemoryLoop() {
  const int64_t cap = options_.max_memory_mb << 20;
  while (!stopping_) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    std::vector<std::shared_ptr<Active>> running;
    {
      std::lock_guard<std::mutex> lock(mu_);
      for (auto& [id, a] : active_) {
        if (a->rss_at_start >= 0 && !a->over_memory) running.push_back(a);
      }
    }
    if (running.empty()) continue;
    const int64_t rss = ResidentBytes();
    if (rss < 0) continue;
    int64_t base = INT64_MAX;
    std::shared_ptr<Active> last;
    for (const auto& a : running) {
      base = std::min<int64_t>(base, a->rss_at_start);
      if (!last || a->rss_at_start >= last->rss_at_start) last = a;
    }
    if (rss - base <= cap * static_cast<int64_t>(running.size())) continue;
    last->over_memory = true;
    last->stop = true;
    LogLine("job_memory_exceeded")
        .Str("job", last->id)
        .Int("grown_mb", (rss - base) >> 20)
        .Int("running_jobs", static_cast<int64_t>(running.size()))
        .Int("max_memory_mb", options_.max_memory_mb)
        .Warn();
  }
}

int64_t JobManager::QueueDepth() {
  if (shared_) {
    // Replicas: the store's queue, every replica's (-1 when the store does not answer).
    absl::StatusOr<int64_t> waiting = store_->CountJobs("", {v1::JOB_STATE_QUEUED});
    return waiting.ok() ? *waiting : -1;
  }
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<int64_t>(queue_.size());
}

int64_t JobManager::RunningJobs() {
  std::lock_guard<std::mutex> lock(mu_);
  int64_t n = 0;
  for (auto& [id, a] : active_) {
    std::lock_guard<std::mutex> job_lock(a->mu);
    n += a->job.state() == v1::JOB_STATE_RUNNING;
  }
  return n;
}

double JobManager::RaysPerSecond() {
  std::lock_guard<std::mutex> lock(mu_);
  double rate = 0;
  for (auto& [id, a] : active_) {
    std::lock_guard<std::mutex> job_lock(a->mu);
    if (a->job.state() == v1::JOB_STATE_RUNNING) rate += a->job.progress().rays_per_second();
  }
  return rate;
}

absl::Status JobManager::WriteLocked(Active& active, const v1::Job& job) {
  active.last_persist = std::chrono::steady_clock::now();
  if (!shared_) {
    absl::Status st = store_->UpdateJob(active.id, job);
    if (!st.ok())
      LogLine("persist_failed").Str("job", active.id).Str("error", st.message()).Error();
    NoteStoreWrite(st.ok());
    return st;
  }
  if (active.lease_lost) {
    return absl::AbortedError(absl::StrCat("jobs/", active.id, ": this replica lost its lease"));
  }
  absl::Status st = store_->UpdateLeasedJob(active.id, owner_, job);
  if (st.code() == absl::StatusCode::kAborted) {
    LoseLease(active, st.message());
  } else if (!st.ok()) {
    LogLine("persist_failed").Str("job", active.id).Str("error", st.message()).Error();
  }
  NoteStoreWrite(st.ok() || st.code() == absl::StatusCode::kAborted);
  return st;
}

bool JobManager::CancelAsked(Active& active) {
  return active.cancel_seen || Current(active).cancel_requested();
}

std::string JobManager::WorkDir(const std::string& id) const {
  // Replicas: each claim writes its own, so that a replica that lost the job cannot write into
  // the directory of the one that took it over.
  return shared_ ? absl::StrCat(dir_.Work(id), "-", work_suffix_) : dir_.Work(id);
}

bool JobManager::LeaseHeld(Active& active) {
  if (!shared_) return true;
  if (active.lease_lost) return false;
  // The lease runs out lease_seconds after the start of the last renewal that succeeded; the
  // margin covers the clocks' drift and the time the next write takes.
  const auto held = std::chrono::steady_clock::now() - active.lease_renewed.load();
  if (held > std::chrono::duration<double>(options_.lease_seconds * kLeaseSafety)) {
    LoseLease(active, "no renewal in time (the store is slow or out of reach)");
    return false;
  }
  return true;
}

bool JobManager::CommitLocked(Active& active, v1::Job next) {
  const bool written = WriteLocked(active, next).ok();
  std::lock_guard<std::mutex> lock(active.mu);
  active.job = std::move(next);
  return written;
}

void JobManager::PersistLocked(Active& active) { (void)WriteLocked(active, Current(active)); }

absl::Duration JobManager::LeaseDuration() const { return absl::Seconds(options_.lease_seconds); }

void JobManager::LoseLease(Active& active, absl::string_view why) {
  if (active.lease_lost.exchange(true)) return;
  active.stop = true;
  LogLine("job_lease_lost").Str("job", active.id).Str("worker", owner_).Str("why", why).Warn();
}

std::shared_ptr<JobManager::Active> JobManager::ClaimNext() {
  const auto claim_started = std::chrono::steady_clock::now();
  absl::StatusOr<std::optional<Store::Claim>> claim = store_->ClaimJob(owner_, LeaseDuration());
  if (!claim.ok()) {
    if (!claim_failing_.exchange(true)) {
      LogLine("claim_failed").Str("worker", owner_).Str("error", claim.status().message()).Error();
    }
    return nullptr;
  }
  if (claim_failing_.exchange(false)) LogLine("claim_works").Str("worker", owner_).Info();
  if (!claim->has_value()) return nullptr;
  v1::Job job = std::move((*claim)->job);
  if ((*claim)->cancel_requested) job.set_cancel_requested(true);
  auto active = std::make_shared<Active>();
  active->id = IdFromName(job.name(), "jobs");
  active->lease_renewed = claim_started;
  // A job claimed RUNNING was left by a worker that died or lost the store: a lost attempt.
  Recover(&job, active.get());
  LogLine("job_claimed")
      .Str("job", active->id)
      .Str("worker", owner_)
      .Str("state", StateName(job.state()))
      .Int("lost_attempts", job.lost_attempts())
      .Info();
  {
    std::lock_guard<std::mutex> write(active->write_mu);
    if (IsEnded(job.state())) {
      // Cancelled, or past --max-attempts: its end is written, and the lease with it.
      if (absl::Status st = WriteLocked(*active, job); st.ok()) {
        ++(job.state() == v1::JOB_STATE_CANCELLED ? metrics_->jobs_cancelled
                                                  : metrics_->jobs_failed);
      }
      return nullptr;
    }
    std::lock_guard<std::mutex> job_lock(active->mu);
    active->job = std::move(job);
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!shutting_down_) {
      active_[active->id] = active;
      return active;
    }
  }
  // Shutting down: given back at once (QUEUED ends the lease) for another replica to take.
  std::lock_guard<std::mutex> write(active->write_mu);
  (void)WriteLocked(*active, Current(*active));
  return nullptr;
}

void JobManager::LeaseLoop() {
  const auto period = std::chrono::duration<double>(options_.lease_seconds / 4);
  std::unique_lock<std::mutex> lock(mu_);
  while (!workers_joined_) {
    lease_cv_.wait_for(lock, period);
    if (workers_joined_) return;
    std::vector<std::shared_ptr<Active>> held;
    for (auto& [id, a] : active_) {
      if (!a->lease_lost) held.push_back(a);
    }
    // Ended jobs whose end the store has not taken yet are still this replica's: their leases
    // are kept, or another replica would run them again.
    std::vector<std::string> ended;
    for (const auto& [id, job] : unpersisted_) ended.push_back(id);
    lock.unlock();
    for (const auto& a : held) {
      const auto started = std::chrono::steady_clock::now();
      absl::StatusOr<bool> cancel = store_->RenewLease(a->id, owner_, LeaseDuration());
      if (cancel.ok()) {
        a->lease_renewed = started;
        if (*cancel) CancelHeld(*a);
      } else if (cancel.status().code() == absl::StatusCode::kAborted) {
        LoseLease(*a, cancel.status().message());
      } else {
        // Tried again in a quarter of the lease; the watchdog stops the job if none succeeds.
        LogLine("lease_renew_failed")
            .Str("job", a->id)
            .Str("error", cancel.status().message())
            .Warn();
      }
    }
    for (const std::string& id : ended) (void)store_->RenewLease(id, owner_, LeaseDuration());
    lock.lock();
  }
}

void JobManager::LeaseWatchdog() {
  std::unique_lock<std::mutex> lock(mu_);
  while (!workers_joined_) {
    lease_cv_.wait_for(lock, std::chrono::milliseconds(100));
    std::vector<std::shared_ptr<Active>> held;
    for (auto& [id, a] : active_) held.push_back(a);
    lock.unlock();
    for (const auto& a : held) (void)LeaseHeld(*a);  // Stops a job whose lease may have run out.
    lock.lock();
  }
}

void JobManager::CancelHeld(Active& active) {
  // The request is in the store already: the job is only told (no write here, where a slow write
  // would hold up the other leases' renewals; its end records it).
  if (active.cancel_seen.exchange(true)) return;
  active.stop = true;
  LogLine("job_cancel_requested").Str("job", active.id).Str("holder", owner_).Info();
}

// Ends the local life of a job whose lease this replica lost: another replica runs it (or will);
// watchers here are told to watch again, which finds it wherever it runs.
void JobManager::DropLost(Active& active) {
  std::error_code ec;
  fs::remove_all(WorkDir(active.id), ec);
  {
    std::lock_guard<std::mutex> lock(mu_);
    active_.erase(active.id);
  }
  SnapshotPtr latest = active.channel->latest();
  active.channel->Close(absl::UnavailableError(
      absl::StrCat("this replica lost the job's lease (another runs it); resume watching after "
                   "sequence ",
                   latest ? latest->sequence : 0)));
  LogLine("job_dropped").Str("job", active.id).Str("worker", owner_).Warn();
}

void JobManager::OnStoreWritableChange(std::function<void(bool)> on_change) {
  std::lock_guard<std::mutex> lock(mu_);
  on_store_writable_ = std::move(on_change);
}

void JobManager::NoteStoreWrite(bool ok) {
  bool writable = ok;
  std::function<void(bool)> notify;
  {
    std::lock_guard<std::mutex> lock(mu_);
    // Writable again only once no ended job waits for its write.
    if (ok && !unpersisted_.empty()) writable = false;
    if (store_failing_.exchange(!writable) == !writable) return;  // No change.
    notify = on_store_writable_;
  }
  LogLine(writable ? "store_writable" : "store_failing").Info();
  if (notify) notify(writable);
}

void JobManager::RetryLoop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    retry_cv_.wait_for(lock, std::chrono::seconds(1));
    const bool last = workers_joined_;
    std::map<std::string, v1::Job> pending = unpersisted_;
    lock.unlock();
    bool all_written = true;
    for (const auto& [id, job] : pending) {
      absl::Status st =
          shared_ ? store_->UpdateLeasedJob(id, owner_, job) : store_->UpdateJob(id, job);
      if (st.code() == absl::StatusCode::kAborted) {
        // Replicas: the lease ran out while the store failed, and another replica claimed the
        // job; its end is that replica's to write.
        LogLine("job_dropped").Str("job", id).Str("worker", owner_).Str("why", st.message()).Warn();
        std::lock_guard<std::mutex> relock(mu_);
        unpersisted_.erase(id);
        continue;
      }
      if (!st.ok()) {
        all_written = false;
        break;  // Still failing: try again in a second.
      }
      LogLine("persist_retried").Str("job", id).Info();
      RemoveEndedJobFiles(id);
      std::lock_guard<std::mutex> relock(mu_);
      auto it = unpersisted_.find(id);
      if (it != unpersisted_.end() && it->second.SerializeAsString() == job.SerializeAsString()) {
        unpersisted_.erase(it);
      }
    }
    if (!pending.empty()) NoteStoreWrite(all_written);
    if (last) return;
    lock.lock();
  }
}

absl::StatusOr<v1::Job> JobManager::GetInactive(const std::string& id) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = unpersisted_.find(id);
    if (it != unpersisted_.end()) return it->second;
  }
  return store_->GetJob(id);
}

void JobManager::WorkerLoop() {
  bool idle = false;
  while (true) {
    std::shared_ptr<Active> active;
    if (shared_) {
      {
        // Idle: wait for a CreateJob here or the next poll of the store for others' jobs.
        std::unique_lock<std::mutex> lock(mu_);
        if (idle) cv_.wait_for(lock, kClaimPoll);
        if (shutting_down_) return;
      }
      active = ClaimNext();
      idle = !active;
      if (!active) continue;
    } else {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait(lock, [&] { return shutting_down_ || !queue_.empty(); });
      if (shutting_down_) return;
      std::string id = queue_.front();
      queue_.pop_front();
      auto it = active_.find(id);
      if (it == active_.end()) continue;
      active = it->second;
    }
    try {
      RunOne(active);
    } catch (...) {
      // RunOne catches what the job throws; this is only for the bookkeeping around it.
      LogLine("worker_error").Str("job", active->id).Error();
    }
  }
}

void JobManager::RunOne(const std::shared_ptr<Active>& active) {
  v1::Job job;
  {
    std::lock_guard<std::mutex> write(active->write_mu);
    job = Current(*active);
    if (job.state() != v1::JOB_STATE_QUEUED) return;  // Cancelled meanwhile.
    job.set_state(v1::JOB_STATE_RUNNING);
    job.set_attempts(job.attempts() + 1);
    *job.mutable_start_time() = Now();
    job.clear_progress();
    // Mesh versions keep growing over re-runs, so a version never names two meshes.
    active->next_mesh_version = std::max(active->next_mesh_version, job.mesh().mesh_version() + 1);
    job.clear_mesh();
    job.clear_error();
    CommitLocked(*active, job);
  }
  LogLine("job_started")
      .Str("job", active->id)
      .Str("scene", job.scene())
      .Int("attempt", job.attempts())
      .Info();
  Outcome outcome;
  active->rss_at_start = ResidentBytes();
  try {
    outcome = job.has_solve() ? RunSolve(active, job) : RunViewFactor(active, job);
  } catch (const std::exception& e) {
    outcome = Failed(absl::InternalError(absl::StrCat("unexpected error: ", e.what())));
  } catch (...) {
    outcome = Failed(absl::InternalError("unexpected error"));
  }
  active->rss_at_start = -1;
  if (active->over_memory) {
    // Stopped by MemoryLoop: a job that would pass the cap again must not be re-queued.
    outcome = Failed(absl::ResourceExhaustedError(
        absl::StrCat("the job used more memory than this server allows a job (--max-memory-mb ",
                     options_.max_memory_mb,
                     "); ask for fewer elements or a smaller image, or simplify the "
                     "scene")));
  }
  // Give the freed memory back to the system, so that the next job's growth is its own.
  malloc_trim(0);
  if (active->lease_lost) {
    // Stopped because another replica may run it now: nothing of this run is written.
    DropLost(*active);
    return;
  }
  std::error_code ec;
  if (outcome.requeue) {
    // Shutdown: back to the queue (persisted), to run again after the restart.
    fs::remove_all(WorkDir(active->id), ec);
    std::lock_guard<std::mutex> write(active->write_mu);
    v1::Job next = Current(*active);
    next.set_state(v1::JOB_STATE_QUEUED);
    CommitLocked(*active, std::move(next));
    LogLine("job_requeued").Str("job", active->id).Str("why", "shutdown").Info();
    if (shared_) {
      // Given back: its lease ended with the write, and any replica may take it.
      std::lock_guard<std::mutex> lock(mu_);
      active_.erase(active->id);
    }
    return;
  }
  if (!outcome.status.ok()) fs::remove_all(WorkDir(active->id), ec);
  SnapshotPtr final_snapshot;
  {
    std::lock_guard<std::mutex> write(active->write_mu);
    v1::Job next = Current(*active);
    if (!outcome.status.ok()) {
      // Clients are told the OS's reason, not where the server keeps its files.
      outcome.status = dir_.Redact(outcome.status);
      next.set_state(v1::JOB_STATE_FAILED);
      next.mutable_error()->set_code(static_cast<int>(outcome.status.code()));
      next.mutable_error()->set_message(ValidUtf8(outcome.status.message()));
      next.clear_results();
      LogLine("job_failed")
          .Str("job", active->id)
          .Str("code", absl::StatusCodeToString(outcome.status.code()))
          .Str("error", outcome.status.message())
          .Warn();
      final_snapshot = EndLocked(*active, std::move(next), nullptr, nullptr);
    } else {
      if (outcome.finish) outcome.finish(&next);
      next.set_state(outcome.cancelled ? v1::JOB_STATE_CANCELLED : v1::JOB_STATE_SUCCEEDED);
      const std::string stop_reason = next.stop_reason();
      const int64_t rays = next.progress().rays();
      const double seconds = next.progress().elapsed_seconds();
      final_snapshot = EndLocked(*active, std::move(next), std::move(outcome.radiosity),
                                 std::move(outcome.mesh), std::move(outcome.std_error));
      // Logged once ended (replicas: not when another replica took the job meanwhile).
      if (final_snapshot) {
        LogLine(outcome.cancelled ? "job_cancelled" : "job_succeeded")
            .Str("job", active->id)
            .Str("stop_reason", stop_reason)
            .Int("rays", rays)
            .Num("seconds", seconds)
            .Info();
      }
    }
  }
  if (final_snapshot) active->channel->Publish(std::move(final_snapshot));
}

JobManager::Outcome JobManager::StoppedOrFailed(Active& active, const absl::Status& status) {
  // A step (a model's import, meshing) stopped by the job's stop flag: a shutdown queues the job
  // again, a cancel cancels it; anything else fails it.
  if (status.code() != absl::StatusCode::kCancelled || !active.stop) return Failed(status);
  bool shutting_down;
  {
    std::lock_guard<std::mutex> lock(mu_);
    shutting_down = shutting_down_;
  }
  if (shutting_down && !CancelAsked(active)) return Requeue();
  Outcome o;
  o.cancelled = true;
  o.finish = [](v1::Job* job) { job->set_stop_reason("cancelled"); };
  return o;
}

JobManager::Outcome JobManager::RunSolve(const std::shared_ptr<Active>& active,
                                         const v1::Job& job) {
  const std::string& id = active->id;
  absl::StatusOr<v1::SceneInfo> info = store_->GetScene(IdFromName(job.scene(), "scenes"));
  if (!info.ok()) {
    return Failed(absl::FailedPreconditionError(
        absl::StrCat("the scene ", job.scene(), " was deleted before the job ran")));
  }
  if (shared_) {
    // Written by another replica, read through a shared file system: checked before use.
    if (absl::Status st = VerifyStoredScene(dir_.Scene(IdFromName(job.scene(), "scenes")), *info);
        !st.ok()) {
      return Failed(st);
    }
  }
  const StopToken stop(&active->stop, 0);
  absl::StatusOr<Scene> scene =
      LoadStoredScene(dir_.Scene(IdFromName(job.scene(), "scenes")), *info, nullptr, &stop);
  if (!scene.ok()) return StoppedOrFailed(*active, scene.status());
  absl::StatusOr<JobSpec> spec = ToJobSpec(job.solve());
  if (!spec.ok()) return Failed(spec.status());
  if (absl::Status st =
          LoadStoredLuminaires(dir_.Scene(IdFromName(job.scene(), "scenes")), *info, &spec->solve);
      !st.ok()) {
    return Failed(st);
  }
  spec->mesh.element_limit = options_.max_elements;
  spec->solve.threads = ThreadsFor(spec->solve.threads);
  if (options_.max_memory_mb > 0) {
    spec->solve.max_matrix_mb =
        std::min(spec->solve.max_matrix_mb, static_cast<double>(options_.max_memory_mb));
  }

  std::shared_ptr<const FloatBlock> last_radiosity;
  std::shared_ptr<const FloatBlock> last_std_error;  // Its standard errors, if any.
  MeshPtr last_mesh;                                 // The mesh of last_radiosity.
  // The newest mesh, which snapshots refer to: the only version this job keeps (a previous one
  // lives on only while a published snapshot or a watcher's write still refers to it).
  MeshPtr current_mesh;
  int64_t elements = 0;
  int64_t rays_counted = 0;
  JobObserver observer;
  observer.on_mesh = [&](const Mesh& mesh) {
    elements = static_cast<int64_t>(mesh.elements().size());
    int64_t version;
    {
      std::lock_guard<std::mutex> write(active->write_mu);
      version = active->next_mesh_version++;
    }
    // Packed outside the lock: O(elements), about 100 bytes each.
    current_mesh = PackMesh(*scene, mesh, version);
    std::lock_guard<std::mutex> write(active->write_mu);
    v1::Job next = Current(*active);
    v1::MeshStats* stats = next.mutable_mesh();
    stats->set_mesh_version(version);
    stats->set_elements(elements);
    stats->set_patches(static_cast<int64_t>(mesh.patches().size()));
    stats->set_faces(static_cast<int64_t>(mesh.faces().size()));
    stats->set_element_size(mesh.element_size());
    CommitLocked(*active, std::move(next));
    LogLine("job_meshed")
        .Str("job", id)
        .Int("elements", elements)
        .Int("mesh_version", version)
        .Info();
  };
  observer.on_method = [&](const MethodChoice& choice) {
    std::lock_guard<std::mutex> write(active->write_mu);
    v1::Job next = Current(*active);
    next.set_method(choice.method);
    next.set_solve_method(SolveMethodOf(choice.method));
    next.set_method_reason(choice.reason);
    CommitLocked(*active, std::move(next));
    LogLine("job_method")
        .Str("job", id)
        .Str("method", choice.method)
        .Str("reason", choice.reason)
        .Info();
  };
  observer.on_warnings = [&](const std::vector<std::string>& warnings) {
    std::lock_guard<std::mutex> write(active->write_mu);
    v1::Job next = Current(*active);
    next.clear_warnings();  // A re-run after a restart says them again.
    for (const std::string& w : warnings) next.add_warnings(ValidUtf8(w));
    CommitLocked(*active, std::move(next));
  };
  observer.on_progress = [&](const Progress& p) {
    // Progress.rays counts every pass's rays (RunJob): it never goes back.
    metrics_->rays += p.rays >= rays_counted ? p.rays - rays_counted : 0;
    rays_counted = p.rays;
    std::lock_guard<std::mutex> write(active->write_mu);
    {
      std::lock_guard<std::mutex> lock(active->mu);
      SetProgress(p, active->job.mutable_progress());
    }
    double since =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - active->last_persist)
            .count();
    if (since >= kPersistSeconds) PersistLocked(*active);
  };
  // The newest snapshot published, which phase updates repeat with their progress.
  std::shared_ptr<const Snapshot> last_published;
  // Meshing and writing: a snapshot (the newest radiosity again, or none before the first)
  // when a phase or its file changes, at its end, and at most four a second otherwise.
  std::chrono::steady_clock::time_point last_phase_publish;
  observer.on_phase = [&](const PhaseProgress& ph) {
    const v1::JobPhase phase =
        ph.phase == PhaseProgress::Phase::kMeshing ? v1::JOB_PHASE_MESHING : v1::JOB_PHASE_WRITING;
    auto snapshot =
        last_published ? std::make_shared<Snapshot>(*last_published) : std::make_shared<Snapshot>();
    const auto now = std::chrono::steady_clock::now();
    {
      std::lock_guard<std::mutex> write(active->write_mu);
      {
        std::lock_guard<std::mutex> lock(active->mu);
        v1::JobProgress* progress = active->job.mutable_progress();
        // Nothing shot yet: all of the power is unshot (the fraction only falls from here).
        if (progress->step() == 0 && progress->rays() == 0) progress->set_unshot_fraction(1);
        const bool changed = progress->phase() != phase || progress->phase_item() != ph.item;
        progress->set_phase(phase);
        progress->set_phase_fraction(ph.fraction);
        progress->set_phase_item(ph.item);
        if (!changed && ph.fraction < 1 &&
            std::chrono::duration<double>(now - last_phase_publish).count() < 0.25) {
          return;
        }
        last_phase_publish = now;
        snapshot->progress = *progress;
        snapshot->sequence = active->next_sequence++;
        active->job.set_last_sequence(snapshot->sequence);
      }
      PersistLocked(*active);
    }
    snapshot->attempts = job.attempts();
    snapshot->state = v1::JOB_STATE_RUNNING;
    snapshot->final = false;
    if (!last_published) snapshot->elements = elements;
    active->channel->Publish(std::move(snapshot));
  };
  observer.snapshot_interval = SnapshotInterval(job.solve());
  LiveWrites live;
  observer.on_snapshot = [&](const Progress& p, const Solution& solution) {
    auto snapshot = std::make_shared<Snapshot>();
    snapshot->attempts = job.attempts();
    snapshot->radiosity = PackRadiosity(solution);
    snapshot->std_error = PackStdError(solution);
    // Snapshots are taken on the mesh of the latest on_mesh (RunJob calls it before solving).
    if (current_mesh &&
        static_cast<int64_t>(snapshot->radiosity->data().size()) == 6 * current_mesh->elements()) {
      snapshot->mesh = current_mesh;
      snapshot->mesh_version = current_mesh->version();
      if (active->channel->WantsExistingSides()) AddExistingSides(snapshot.get());
    }
    last_radiosity = snapshot->radiosity;
    last_std_error = snapshot->std_error;
    last_mesh = snapshot->mesh;
    snapshot->state = v1::JOB_STATE_RUNNING;
    snapshot->elements = elements;
    SetProgress(p, &snapshot->progress);
    {
      std::lock_guard<std::mutex> write(active->write_mu);
      snapshot->sequence = active->next_sequence++;
      {
        std::lock_guard<std::mutex> lock(active->mu);
        active->job.set_last_sequence(snapshot->sequence);
        SetProgress(p, active->job.mutable_progress());
      }
      // Persisted before it is published, so that a restart never numbers another snapshot
      // the same (a resumed job's numbers continue from the last one).
      PersistLocked(*active);
    }
    ++metrics_->snapshots;
    last_published = snapshot;
    active->channel->Publish(snapshot);
    if (shared_) ShareLive(*active, *snapshot, &live);
  };

  if (options_.checkpoint_seconds > 0) {
    spec->checkpoint_path = dir_.Checkpoint(id);
    spec->checkpoint_seconds = options_.checkpoint_seconds;
  }
  observer.on_checkpoint = [&](const CheckpointEvent& e) {
    using Kind = CheckpointEvent::Kind;
    LogLine line(e.kind == Kind::kWritten       ? "job_checkpoint"
                 : e.kind == Kind::kResumed     ? "job_resumed"
                 : e.kind == Kind::kDiscarded   ? "job_checkpoint_discarded"
                 : e.kind == Kind::kWriteFailed ? "job_checkpoint_failed"
                                                : "job_checkpoint_unsupported");
    line.Str("job", id).Int("step", e.progress.step).Int("rays", e.progress.rays);
    if (e.bytes > 0) line.Int("bytes", e.bytes);
    if (e.kind == Kind::kWritten) {
      line.Num("pause_seconds", e.pause_seconds).Num("write_seconds", e.write_seconds);
    }
    if (!e.status.ok()) line.Str("error", e.status.message());
    if (e.kind == Kind::kWritten) {
      line.Debug();
    } else if (e.kind == Kind::kResumed || e.kind == Kind::kUnsupported) {
      line.Info();
    } else {
      line.Warn();
    }
  };

  std::error_code ec;
  fs::remove_all(WorkDir(id), ec);
  fs::create_directories(dir_.Job(id), ec);
  absl::StatusOr<JobResult> result = RunJob(*scene, *spec, WorkDir(id), &active->stop, observer);
  const bool cancel_requested = CancelAsked(*active);
  bool shutting_down;
  {
    std::lock_guard<std::mutex> lock(mu_);
    shutting_down = shutting_down_;
  }
  if (active->stop && shutting_down && !cancel_requested) return Requeue();
  if (!result.ok()) return StoppedOrFailed(*active, result.status());

  Outcome outcome;
  outcome.cancelled = result->reason == StopReason::kCancelled;
  outcome.radiosity = last_radiosity ? last_radiosity : PackRadiosity(result->solution);
  outcome.std_error = last_radiosity ? last_std_error : PackStdError(result->solution);
  outcome.mesh = last_radiosity ? last_mesh : current_mesh;
  if (outcome.mesh &&
      static_cast<int64_t>(outcome.radiosity->data().size()) != 6 * outcome.mesh->elements()) {
    outcome.mesh = nullptr;
  }
  absl::Status st = WriteFloats(WorkDir(id) + "/" + kRadiosityFile, outcome.radiosity->data());
  if (st.ok() && outcome.std_error) {
    st = WriteFloats(WorkDir(id) + "/" + kStdErrorFile, outcome.std_error->data());
  }
  if (st.ok() && outcome.mesh) {
    st = WriteFileAtomically(WorkDir(id) + "/" + kMeshGeometryFile, SerializeMesh(*outcome.mesh));
  }
  if (st.ok() && outcome.mesh && outcome.mesh->back_ranges()) {
    st = WriteFileAtomically(WorkDir(id) + "/" + kBackRangesFile,
                             SerializeBackRanges(*outcome.mesh->back_ranges()));
  }
  std::vector<v1::FileInfo> results;
  if (st.ok()) st = PublishResults(*active, result->files, &results);
  if (!st.ok()) return Failed(st);
  metrics_->rays += std::max<int64_t>(0, result->solution.rays - rays_counted);
  const Solution& sol = result->solution;
  outcome.finish = [results = std::move(results), shots = sol.shots, rays = sol.rays,
                    unshot = sol.unshot_fraction, seconds = sol.seconds,
                    elements = result->elements, patches = result->patches, faces = result->faces,
                    mesh_seconds = result->mesh_seconds, reason = result->reason](v1::Job* stored) {
    stored->mutable_results()->Assign(results.begin(), results.end());
    v1::JobProgress* progress = stored->mutable_progress();
    progress->set_shots(shots);
    progress->set_rays(rays);
    progress->set_unshot_fraction(unshot);
    progress->set_elapsed_seconds(seconds);
    progress->set_rays_per_second(seconds > 0 ? rays / seconds : 0);
    stored->mutable_mesh()->set_elements(elements);
    stored->mutable_mesh()->set_patches(patches);
    stored->mutable_mesh()->set_faces(faces);
    stored->mutable_mesh()->set_mesh_seconds(mesh_seconds);
    stored->set_stop_reason(StopReasonName(reason));
  };
  return outcome;
}

JobManager::Outcome JobManager::RunViewFactor(const std::shared_ptr<Active>& active,
                                              const v1::Job& job) {
  const std::string& id = active->id;
  absl::StatusOr<v1::SceneInfo> info = store_->GetScene(IdFromName(job.scene(), "scenes"));
  if (!info.ok()) {
    return Failed(absl::FailedPreconditionError(
        absl::StrCat("the scene ", job.scene(), " was deleted before the job ran")));
  }
  if (shared_) {
    // Written by another replica, read through a shared file system: checked before use.
    if (absl::Status st = VerifyStoredScene(dir_.Scene(IdFromName(job.scene(), "scenes")), *info);
        !st.ok()) {
      return Failed(st);
    }
  }
  const StopToken stop(&active->stop, 0);
  absl::StatusOr<Scene> scene =
      LoadStoredScene(dir_.Scene(IdFromName(job.scene(), "scenes")), *info, nullptr, &stop);
  if (!scene.ok()) return StoppedOrFailed(*active, scene.status());
  absl::StatusOr<ViewFactorOptions> options = ToViewFactorOptions(job.view_factor());
  if (!options.ok()) return Failed(options.status());
  options->threads = ThreadsFor(options->threads);
  if (!options->thermal.empty()) {
    // Thermal data that does not fit the scene fails now, not after the view factors.
    std::vector<std::string> names;
    for (const Surface& s : scene->surfaces) names.push_back(s.name);
    absl::StatusOr<std::vector<SurfaceThermal>> thermal = ResolveThermal(names, options->thermal);
    if (!thermal.ok()) return Failed(thermal.status());
  }
  absl::StatusOr<ViewFactorMatrix> matrix = ComputeViewFactors(*scene, *options, &active->stop);
  std::optional<absl::StatusOr<RadiantExchange>> exchange;
  if (matrix.ok() && !options->thermal.empty()) {
    exchange = ComputeExchange(*matrix, options->thermal, &active->stop, options->threads);
  }
  const bool cancel_requested = CancelAsked(*active);
  bool shutting_down;
  {
    std::lock_guard<std::mutex> lock(mu_);
    shutting_down = shutting_down_;
  }
  if (active->stop && shutting_down && !cancel_requested) return Requeue();
  if (active->stop && cancel_requested) {
    Outcome outcome;
    outcome.cancelled = true;
    outcome.finish = [](v1::Job* live) { live->set_stop_reason("cancelled"); };
    return outcome;
  }
  if (!matrix.ok()) return Failed(matrix.status());
  if (exchange && !exchange->ok()) return Failed(exchange->status());
  std::error_code ec;
  fs::remove_all(WorkDir(id), ec);
  fs::create_directories(WorkDir(id), ec);
  std::vector<std::string> files = {"viewfactors.csv", "viewfactors.mtx"};
  absl::Status st = WriteViewFactorCsv(*matrix, WorkDir(id) + "/viewfactors.csv");
  if (st.ok()) st = WriteViewFactorMatrixMarket(*matrix, WorkDir(id) + "/viewfactors.mtx");
  if (st.ok() && exchange) {
    st = WriteExchangeCsv(**exchange, WorkDir(id) + "/exchange.csv");
    if (st.ok()) st = WriteGebhartCsv(**exchange, WorkDir(id) + "/gebhart.csv");
    files.insert(files.end(), {"exchange.csv", "gebhart.csv"});
  }
  if (!st.ok()) return Failed(st);
  metrics_->rays += matrix->rays;
  std::vector<v1::FileInfo> results;
  st = PublishResults(*active, files, &results);
  if (!st.ok()) return Failed(st);
  v1::ViewFactorResult r;
  ViewFactorCheck check = CheckViewFactors(*matrix);
  for (const std::string& s : matrix->surfaces) r.add_surfaces(s);
  r.set_max_reciprocity_error(check.max_reciprocity_error);
  r.set_max_closure_error(check.max_closure_error);
  for (double s : check.row_sums) r.add_row_sums(s);
  r.set_rays(matrix->rays);
  r.set_seconds(matrix->seconds);
  for (double a : matrix->area) r.add_areas(a);
  r.set_enforced(matrix->enforced);
  r.set_max_reciprocity_error_before(matrix->max_reciprocity_error_before);
  r.set_max_closure_error_before(matrix->max_closure_error_before);
  r.set_smallest_entry(matrix->smallest_entry);
  r.set_near_pairs(matrix->near_pairs);
  r.set_ray_row_error(matrix->ray_row_error);
  if (exchange) {
    const RadiantExchange& x = **exchange;
    for (int i = 0; i < x.size(); ++i) {
      v1::SurfaceExchange* e = r.add_exchange();
      e->set_surface(x.surfaces[i]);
      e->set_emissivity(x.emissivity[i]);
      e->set_temperature(x.temperature[i]);
      e->set_emitted(x.emitted[i]);
      e->set_absorbed(x.absorbed[i]);
      e->set_net(x.net[i]);
      e->set_to_environment(x.to_environment[i]);
    }
    r.set_gebhart_max_reciprocity_error(x.max_reciprocity_error);
    r.set_gebhart_max_closure_error(x.max_closure_error);
    r.set_seconds(r.seconds() + x.seconds);
  }
  Outcome outcome;
  outcome.finish = [results = std::move(results), r = std::move(r)](v1::Job* live) {
    live->mutable_results()->Assign(results.begin(), results.end());
    *live->mutable_view_factor_result() = r;
    live->mutable_progress()->set_rays(r.rays());
    live->mutable_progress()->set_elapsed_seconds(r.seconds());
    live->mutable_progress()->set_unshot_fraction(0);
    live->set_stop_reason("converged");
  };
  return outcome;
}

absl::Status JobManager::PublishResults(Active& active, const std::vector<std::string>& files,
                                        std::vector<v1::FileInfo>* results) {
  const std::string& id = active.id;
  // Replicas: the results directory is shared; only the job's holder may replace it.
  if (!LeaseHeld(active)) {
    return absl::AbortedError(absl::StrCat("jobs/", id, ": this replica lost the job's lease"));
  }
  results->clear();
  for (const std::string& name : files) {
    absl::StatusOr<std::pair<std::string, int64_t>> sum = Sha256File(WorkDir(id) + "/" + name);
    if (!sum.ok()) return absl::InternalError(sum.status().message());
    v1::FileInfo& f = results->emplace_back();
    f.set_name(name);
    f.set_sha256(sum->first);
    f.set_size(sum->second);
  }
  std::error_code ec;
  fs::remove_all(dir_.Results(id), ec);
  fs::rename(WorkDir(id), dir_.Results(id), ec);
  if (ec) return absl::InternalError(absl::StrCat(dir_.Results(id), ": ", ec.message()));
  return absl::OkStatus();
}

SnapshotPtr JobManager::EndLocked(Active& active, v1::Job next,
                                  std::shared_ptr<const FloatBlock> radiosity, MeshPtr mesh,
                                  std::shared_ptr<const FloatBlock> std_error) {
  auto snapshot = std::make_shared<Snapshot>();
  *next.mutable_end_time() = Now();
  snapshot->sequence = active.next_sequence++;
  next.set_last_sequence(snapshot->sequence);
  snapshot->state = next.state();
  snapshot->progress = next.progress();
  snapshot->final = true;
  snapshot->error = next.error();
  snapshot->elements = next.mesh().elements();
  snapshot->attempts = next.attempts();
  if (radiosity && mesh) {
    snapshot->mesh_version = mesh->version();
    snapshot->mesh = std::move(mesh);
  }
  snapshot->radiosity = std::move(radiosity);
  if (snapshot->radiosity && std_error &&
      std_error->data().size() == snapshot->radiosity->data().size()) {
    snapshot->std_error = std::move(std_error);
  }
  if (active.channel->WantsExistingSides()) AddExistingSides(snapshot.get());
  const v1::JobState state = next.state();
  const bool written = CommitLocked(active, std::move(next));
  if (active.lease_lost) {
    // The end was not this replica's to write: another replica claimed the job meanwhile.
    DropLost(active);
    return nullptr;
  }
  switch (state) {
    case v1::JOB_STATE_SUCCEEDED:
      ++metrics_->jobs_succeeded;
      break;
    case v1::JOB_STATE_CANCELLED:
      ++metrics_->jobs_cancelled;
      break;
    default:
      ++metrics_->jobs_failed;
  }
  // Ended: nothing will resume it (an end not written yet keeps its checkpoint until RetryLoop
  // writes it: a restart meanwhile resumes the job rather than starting it again).
  if (written) RemoveEndedJobFiles(active.id);
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!written) unpersisted_[active.id] = Current(active);
    active_.erase(active.id);
    queue_.erase(std::remove(queue_.begin(), queue_.end(), active.id), queue_.end());
  }
  return snapshot;
}

}  // namespace radiosity::service
