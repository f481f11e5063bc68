// The client side of the radiosity service (proto/radiosity/v1/service.proto): uploads with
// checksums and content-derived idempotency keys, job calls, watching with reassembly of chunked
// snapshots and resumption after a dropped stream, and downloads with checksum verification.
// Every call has a deadline; only UNAVAILABLE is retried, and only for calls safe to repeat (reads,
// cancel, and creates that carry a request id).
#ifndef RADIOSITY_CLIENT_CLIENT_H_
#define RADIOSITY_CLIENT_CLIENT_H_

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "radiosity/v1/service.grpc.pb.h"

namespace radiosity::client {

struct ClientOptions {
  // Deadline of unary calls, and the base of streaming calls' deadlines, seconds.
  double timeout_seconds = 30;
  // Deadline of one WatchJob stream; when it passes the client reconnects and resumes.
  double watch_stream_seconds = 600;
  // Deadline of a download, seconds.
  double download_seconds = 600;
  // Reconnections in a row after UNAVAILABLE before giving up (backoff 0.1 s doubling to 2 s).
  int max_retries = 12;
};

// The element geometry of one mesh version, reassembled from a WatchJob mesh announcement
// (v1::MeshGeometry; the arrays are those of the proto, concatenated over its messages).
struct MeshGeometry {
  int64_t version = 0;
  int64_t faces = 0;
  double origin[3] = {0, 0, 0};  // Positions are float offsets from this point.
  std::vector<std::string> surface_names;
  std::vector<int32_t> surface, face;   // Per element.
  std::vector<float> uv;                // 4 per element: u0, v0, u1, v1.
  std::vector<float> corners;           // 12 per element.
  std::vector<float> normal, centroid;  // 3 per element.
  std::vector<float> area;              // Per element.
  // Per element: faces held when agglomerated (0: a leaf of `face`); their faces, in order.
  std::vector<int32_t> member_count, member_faces;
  // 12 per member face: its corners (MeshGeometry.member_corners); NaN where a message had none.
  std::vector<float> member_corners;
  int64_t elements() const { return static_cast<int64_t>(surface.size()); }
};

// One complete snapshot (all chunks of a sequence number).
struct Snapshot {
  int64_t sequence = 0;
  v1::JobState state = v1::JOB_STATE_UNSPECIFIED;
  v1::JobProgress progress;
  bool resync = false;
  bool final = false;
  v1::JobError error;
  int64_t elements = 0;
  int32_t attempts = 0;          // The job's attempts when the snapshot was taken.
  std::vector<float> radiosity;  // (2 e + side) x 3 + channel; empty when progress_only.
  // Version of the mesh the radiosity refers to (0: unknown), and, when watching with
  // include_mesh, its geometry as announced on the stream (null if none was).
  int64_t mesh_version = 0;
  std::shared_ptr<const MeshGeometry> mesh;
};

// The files of a scene on disk as an upload sends them: the main file, then (for OBJ) the MTL
// files its mtllib lines name that exist, relative to its directory.
struct SceneFiles {
  v1::UploadSceneHeader header;
  std::vector<std::string> paths;  // Local paths, parallel to header.files.
};
// NOT_FOUND / INVALID_ARGUMENT with "PATH: problem" when the main file cannot be read or has an
// unknown extension. `request_id` empty: derived from the display name and the files' checksums,
// so uploading the same files again returns the stored scene without sending them.
// `read`: how the service is to read the scene (UploadSceneHeader.strict, .vertex_colors; part of
// the derived request_id).
struct SceneReadOptions {
  bool strict = false;
  bool vertex_colors = false;
  // Local files sent with the scene besides those it references (photometric files for
  // luminaires), each named by its base name.
  std::vector<std::string> extra_files;
};
absl::StatusOr<SceneFiles> CollectSceneFiles(const std::string& path,
                                             const std::string& request_id = "",
                                             const SceneReadOptions& read = {});

class Client {
 public:
  explicit Client(std::shared_ptr<grpc::Channel> channel, ClientOptions options = {});

  absl::StatusOr<v1::SceneInfo> UploadSceneFile(const std::string& path,
                                                const std::string& request_id = "",
                                                const SceneReadOptions& read = {});
  absl::StatusOr<v1::SceneInfo> Upload(const SceneFiles& files);
  absl::StatusOr<v1::SceneInfo> GetScene(const std::string& name);
  absl::StatusOr<v1::ListScenesResponse> ListScenes(const v1::ListScenesRequest& request);
  absl::Status DeleteScene(const std::string& name);
  // Writes the scene's files into `dir`; returns the local path of the main file.
  absl::StatusOr<std::string> DownloadScene(const std::string& name, const std::string& dir);

  absl::StatusOr<v1::Job> CreateJob(const v1::CreateJobRequest& request);
  absl::StatusOr<v1::Job> GetJob(const std::string& name);
  absl::StatusOr<v1::ListJobsResponse> ListJobs(const v1::ListJobsRequest& request);
  absl::StatusOr<v1::Job> CancelJob(const std::string& name);
  absl::Status DeleteJob(const std::string& name);

  // Watches a job until its final snapshot, which it returns. `on_snapshot` (may be empty) sees
  // every complete snapshot; returning false stops watching (CANCELLED), as does *stop becoming
  // true. A dropped stream (UNAVAILABLE) or an expired stream deadline reconnects and resumes
  // after the last complete snapshot. With `include_mesh`, the server announces the geometry of
  // each mesh before the values that refer to it, and every snapshot with radiosity carries it
  // (Snapshot::mesh; the same object while the mesh does not change).
  absl::StatusOr<Snapshot> Watch(const std::string& job, int64_t after_sequence, bool progress_only,
                                 const std::function<bool(const Snapshot&)>& on_snapshot,
                                 const std::atomic<bool>* stop = nullptr,
                                 bool include_mesh = false);

  // Downloads result files (all, or one) into `dir`, checking sizes and checksums; returns the
  // names written, in the job's order.
  absl::StatusOr<std::vector<std::string>> DownloadResults(const std::string& job,
                                                           const std::string& dir,
                                                           const std::string& file = "");

  // grpc.health.v1.Health/Check: true when `service` ("" for the server) is SERVING.
  absl::StatusOr<bool> CheckHealth(const std::string& service);

  v1::RadiosityService::Stub& stub() { return *stub_; }
  const ClientOptions& options() const { return options_; }

 private:
  // Attempts of a unary call (or an upload) that fails with UNAVAILABLE.
  static constexpr int kUnaryAttempts = 3;
  template <typename Request, typename Response>
  absl::StatusOr<Response> Unary(grpc::Status (v1::RadiosityService::Stub::*method)(
                                     grpc::ClientContext*, const Request&, Response*),
                                 const Request& request, bool idempotent);
  absl::StatusOr<v1::SceneInfo> UploadOnce(const SceneFiles& files);
  void SetDeadline(grpc::ClientContext* context, double seconds) const;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::RadiosityService::Stub> stub_;
  ClientOptions options_;
};

// Channel to a remote server with the client's keepalive settings (plaintext).
std::shared_ptr<grpc::Channel> MakeChannel(const std::string& address);

// How to reach a server that serves TLS and checks bearer tokens (docs/service/security.md).
struct ChannelSecurity {
  bool tls = false;         // TLS, verified against the system's CAs unless ca_file is set.
  std::string ca_file;      // PEM CA(s) that signed the server's certificate (implies tls).
  std::string cert_file;    // PEM client certificate (mutual TLS; with key_file).
  std::string key_file;     // Its private key.
  std::string server_name;  // Name to verify in the server's certificate (default: the host).
  std::string token;        // Bearer token sent with every call (needs TLS).
};

// A channel with `security`; INVALID_ARGUMENT naming the option when a file cannot be read or the
// options do not go together.
absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(const std::string& address,
                                                           const ChannelSecurity& security);

// The token of a CLI: the first line of `token_file` when given, else $RADIOSITY_TOKEN, else "".
absl::StatusOr<std::string> ReadToken(const std::string& token_file);

}  // namespace radiosity::client

#endif  // RADIOSITY_CLIENT_CLIENT_H_
