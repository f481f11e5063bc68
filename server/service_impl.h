// The RadiosityService (proto/radiosity/v1/service.proto) on gRPC's callback API: unary methods
// finish on the default reactor; each streaming method has its own reactor class, which keeps at
// most one write (or read) in flight and deletes itself only in OnDone. Every handler runs inside
// a guard that turns an escaping exception into INTERNAL; absl::Status becomes a gRPC status in
// one place (proto/api/status.h).
//
// Threads: gRPC's callback threads only start and finish calls and do short steps (one database
// statement, one chunk). Long work runs on the service's Executor, which then finishes the call:
// validating a completed upload, CreateJob (loading the scene, counting its elements),
// DeleteScene and DeleteJob (removing files), and reading an ended job's results for WatchJob.
// The executor has twice as many threads as cores (at least 4), so a few long validations do
// not hold up a CreateJob. No lock over all scenes is held meanwhile: a scene is kept from deletion
// by the references of the CreateJob calls using it (server/scene_refs.h), and concurrent retries
// of one upload or job are inserted once by the Store (its insert checks the request id).
#ifndef RADIOSITY_SERVER_SERVICE_IMPL_H_
#define RADIOSITY_SERVER_SERVICE_IMPL_H_

#include "radiosity/v1/service.grpc.pb.h"
#include "server/call_limits.h"
#include "server/data_dir.h"
#include "server/executor.h"
#include "server/jobs.h"
#include "server/metrics.h"
#include "server/scene_refs.h"
#include "server/store.h"

namespace radiosity::service {

// Largest chunk accepted in uploads and sent in downloads (payload bytes).
inline constexpr int64_t kMaxChunkBytes = int64_t{1} << 20;
inline constexpr int64_t kDownloadChunkBytes = int64_t{512} << 10;
// Most floats in one WatchJobResponse: 768 KiB of payload, well under 1 MiB with the header.
inline constexpr int64_t kMaxFloatsPerMessage = 196'608;
// Most files in one upload.
inline constexpr int kMaxUploadFiles = 64;

class RadiosityServiceImpl final : public v1::RadiosityService::CallbackService {
 public:
  RadiosityServiceImpl(const ServiceOptions& options, const DataDir& dir, Store* store,
                       JobManager* jobs, Metrics* metrics);

  grpc::ServerReadReactor<v1::UploadSceneRequest>* UploadScene(grpc::CallbackServerContext* context,
                                                               v1::SceneInfo* response) override;
  grpc::ServerUnaryReactor* GetScene(grpc::CallbackServerContext* context,
                                     const v1::GetSceneRequest* request,
                                     v1::SceneInfo* response) override;
  grpc::ServerUnaryReactor* ListScenes(grpc::CallbackServerContext* context,
                                       const v1::ListScenesRequest* request,
                                       v1::ListScenesResponse* response) override;
  grpc::ServerUnaryReactor* DeleteScene(grpc::CallbackServerContext* context,
                                        const v1::DeleteSceneRequest* request,
                                        v1::DeleteSceneResponse* response) override;
  grpc::ServerWriteReactor<v1::FileChunk>* DownloadScene(
      grpc::CallbackServerContext* context, const v1::DownloadSceneRequest* request) override;
  grpc::ServerUnaryReactor* CreateJob(grpc::CallbackServerContext* context,
                                      const v1::CreateJobRequest* request,
                                      v1::Job* response) override;
  grpc::ServerUnaryReactor* GetJob(grpc::CallbackServerContext* context,
                                   const v1::GetJobRequest* request, v1::Job* response) override;
  grpc::ServerUnaryReactor* ListJobs(grpc::CallbackServerContext* context,
                                     const v1::ListJobsRequest* request,
                                     v1::ListJobsResponse* response) override;
  grpc::ServerUnaryReactor* CancelJob(grpc::CallbackServerContext* context,
                                      const v1::CancelJobRequest* request,
                                      v1::Job* response) override;
  grpc::ServerUnaryReactor* DeleteJob(grpc::CallbackServerContext* context,
                                      const v1::DeleteJobRequest* request,
                                      v1::DeleteJobResponse* response) override;
  grpc::ServerWriteReactor<v1::WatchJobResponse>* WatchJob(
      grpc::CallbackServerContext* context, const v1::WatchJobRequest* request) override;
  grpc::ServerWriteReactor<v1::FileChunk>* DownloadResult(
      grpc::CallbackServerContext* context, const v1::DownloadResultRequest* request) override;

  // Used by the upload reactor, on the executor: validates the received files in `dir`, stores
  // the scene. Validation stops (CANCELLED) once *cancelled (the client's cancel) is raised, or
  // at shutdown (UNAVAILABLE).
  absl::StatusOr<v1::SceneInfo> CommitUpload(const std::string& dir, v1::SceneInfo info,
                                             const std::atomic<bool>* cancelled);

  const ServiceOptions& options() const { return options_; }
  Executor& executor() { return executor_; }
  CallLimits& limits() { return limits_; }
  const DataDir& data_dir() const { return dir_; }
  Store* store() { return store_; }
  JobManager* jobs() { return jobs_; }
  Metrics* metrics() { return metrics_; }
  // The calling tenant (server/tenants.h): "" without tokens, UNAUTHENTICATED without one.
  absl::StatusOr<std::string> Tenant(const grpc::CallbackServerContext& context) const;
  // The scene, NOT_FOUND (as for a scene that does not exist) unless it is the tenant's.
  absl::StatusOr<v1::SceneInfo> OwnedScene(const std::string& id, const std::string& tenant);
  // Counts a finished RPC and logs it when it failed.
  void Record(const char* method, const absl::Status& status);

 private:
  const ServiceOptions options_;
  const DataDir dir_;
  Store* const store_;
  JobManager* const jobs_;
  Metrics* const metrics_;
  SceneRefs scene_refs_;
  CallLimits limits_;
  // Last: destroyed first, so the tasks it still runs find everything else alive.
  Executor executor_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_SERVICE_IMPL_H_
