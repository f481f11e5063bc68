#include "client/client.h"

#include <grpcpp/generic/generic_stub.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <future>
#include <limits>
#include <optional>
#include <thread>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "proto/api/back_ranges.h"
#include "proto/api/pem.h"
#include "proto/api/scene_format.h"
#include "proto/api/sha256.h"
#include "proto/api/status.h"
#include "solver/input/scene_files.h"
#include "solver/util/file_io.h"

namespace radiosity::client {
namespace {

// WatchJobResponse.existing_sides_only: each element's front, then its back where `ranges` (the
// response's back_ranges) has one, expanded in place to the full layout ((2 e + side) x 3 + c,
// zeros for missing backs). False when the values do not fit the ranges and element count.
bool ExpandExistingSides(const std::vector<int64_t>& ranges, int64_t elements,
                         std::vector<float>* values) {
  const int64_t backs = service::BackRangeElements(ranges, elements);
  if (backs < 0 || static_cast<int64_t>(values->size()) != 3 * (elements + backs)) return false;
  std::vector<float> full(static_cast<size_t>(6 * elements), 0.0f);
  size_t r = 0, in = 0;
  for (int64_t e = 0; e < elements; ++e) {
    while (r + 1 < ranges.size() && ranges[r + 1] <= e) r += 2;
    const bool back = r + 1 < ranges.size() && ranges[r] <= e;
    const size_t count = back ? 6 : 3;
    std::copy_n(values->begin() + static_cast<std::ptrdiff_t>(in), count, full.begin() + 6 * e);
    in += count;
  }
  *values = std::move(full);
  return true;
}

namespace fs = std::filesystem;
using service::FromGrpcStatus;

// Upload chunk payload: well under the 1 MiB a message may carry.
constexpr size_t kUploadChunk = size_t{512} << 10;

// `dir`/`name` for a name the server sent (joined below `dir` even if it starts with '/').
std::string Join(const std::string& dir, const std::string& name) {
  return dir.empty() ? name : dir + "/" + name;
}

absl::Status ReadError(const std::string& path) {
  int error = errno;
  std::string message = absl::StrCat(path, ": ", std::strerror(error));
  return error == ENOENT ? absl::NotFoundError(message) : absl::InvalidArgumentError(message);
}

// Adds one message of a mesh announcement to *m (which chunk 0 starts afresh). Sets *complete
// when it was the last message and the geometry is whole; INTERNAL when the message does not fit.
absl::Status AddMeshChunk(const v1::MeshGeometry& g, MeshGeometry* m, bool* complete) {
  *complete = false;
  if (g.chunk_index() == 0) {
    *m = MeshGeometry();
    m->version = g.version();
    m->faces = g.faces();
    m->origin[0] = g.origin().x();
    m->origin[1] = g.origin().y();
    m->origin[2] = g.origin().z();
    const size_t n = static_cast<size_t>(std::max<int64_t>(0, g.elements()));
    m->surface.reserve(n);
    m->face.reserve(n);
    m->uv.reserve(4 * n);
    m->corners.reserve(12 * n);
    m->normal.reserve(3 * n);
    m->centroid.reserve(3 * n);
    m->area.reserve(n);
  }
  const int k = g.surface_size();
  int64_t members = 0;
  for (int32_t c : g.member_count()) members += std::max(0, c);
  if ((g.member_count_size() != 0 && g.member_count_size() != k) ||
      members != g.member_faces_size() ||
      (g.member_corners_size() != 0 && g.member_corners_size() != 12 * members)) {
    return absl::InternalError(absl::StrCat("mesh announcement of version ", g.version(),
                                            ": message ", g.chunk_index(),
                                            " has member faces not as counted"));
  }
  if (g.version() != m->version || g.first_element() != m->elements() || g.face_size() != k ||
      g.uv_size() != 4 * k || g.corners_size() != 12 * k || g.normal_size() != 3 * k ||
      g.centroid_size() != 3 * k || g.area_size() != k || m->elements() + k > g.elements() ||
      (g.surface_names_size() > 0 &&
       g.surface_names_offset() != static_cast<int64_t>(m->surface_names.size()))) {
    return absl::InternalError(absl::StrCat("mesh announcement of version ", g.version(),
                                            ": message ", g.chunk_index(), " of ", g.chunk_count(),
                                            " does not follow the previous ones"));
  }
  m->surface_names.insert(m->surface_names.end(), g.surface_names().begin(),
                          g.surface_names().end());
  m->surface.insert(m->surface.end(), g.surface().begin(), g.surface().end());
  m->face.insert(m->face.end(), g.face().begin(), g.face().end());
  m->uv.insert(m->uv.end(), g.uv().begin(), g.uv().end());
  m->corners.insert(m->corners.end(), g.corners().begin(), g.corners().end());
  m->normal.insert(m->normal.end(), g.normal().begin(), g.normal().end());
  m->centroid.insert(m->centroid.end(), g.centroid().begin(), g.centroid().end());
  m->area.insert(m->area.end(), g.area().begin(), g.area().end());
  // A server from before agglomeration sends no counts: every element a leaf.
  if (g.member_count_size() == 0) {
    m->member_count.resize(m->member_count.size() + static_cast<size_t>(k), 0);
  } else {
    m->member_count.insert(m->member_count.end(), g.member_count().begin(), g.member_count().end());
  }
  m->member_faces.insert(m->member_faces.end(), g.member_faces().begin(), g.member_faces().end());
  if (g.member_corners_size() == 0) {
    m->member_corners.resize(m->member_corners.size() + 12 * static_cast<size_t>(members),
                             std::numeric_limits<float>::quiet_NaN());
  } else {
    m->member_corners.insert(m->member_corners.end(), g.member_corners().begin(),
                             g.member_corners().end());
  }
  if (g.chunk_index() + 1 < g.chunk_count()) return absl::OkStatus();
  if (m->elements() != g.elements() ||
      static_cast<int64_t>(m->surface_names.size()) != g.surfaces()) {
    return absl::InternalError(absl::StrCat(
        "mesh announcement of version ", g.version(), ": ", m->elements(), " of ", g.elements(),
        " elements and ", m->surface_names.size(), " of ", g.surfaces(), " surface names"));
  }
  *complete = true;
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<SceneFiles> CollectSceneFiles(const std::string& path, const std::string& request_id,
                                             const SceneReadOptions& read) {
  SceneFiles files;
  std::ifstream probe(path, std::ios::binary);
  if (!probe) return ReadError(path);
  std::error_code ec;
  if (fs::is_directory(path, ec)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": is a directory"));
  }
  absl::StatusOr<v1::SceneFormat> format =
      service::ResolveFormat(v1::SCENE_FORMAT_UNSPECIFIED, path);
  if (!format.ok()) return format.status();
  std::vector<std::pair<std::string, std::string>> named = {{BaseName(path), path}};
  absl::StatusOr<std::vector<std::string>> dependencies = SceneDependencies(path);
  if (!dependencies.ok()) return dependencies.status();
  for (const std::string& name : *dependencies) {
    if (name != named[0].first) named.emplace_back(name, JoinPath(DirName(path), name));
  }
  for (const std::string& extra : read.extra_files) {
    const std::string name = BaseName(extra);
    auto same =
        std::find_if(named.begin(), named.end(), [&](const auto& n) { return n.first == name; });
    if (same != named.end()) {
      std::error_code same_ec;
      if (fs::equivalent(same->second, extra, same_ec)) continue;
      return absl::InvalidArgumentError(absl::StrCat(extra, ": the scene already has a file named ",
                                                     name, " (", same->second,
                                                     "); rename one of them"));
    }
    std::ifstream readable(extra, std::ios::binary);
    if (!readable) return ReadError(extra);
    named.emplace_back(name, extra);
  }
  files.header.set_format(*format);
  files.header.set_display_name(path);
  files.header.set_strict(read.strict);
  files.header.set_vertex_colors(read.vertex_colors);
  service::Sha256 key;
  key.Update(path);
  if (read.strict) key.Update(std::string("\0strict", 7));
  if (read.vertex_colors) key.Update(std::string("\0vertex_colors", 14));
  for (const auto& [name, local] : named) {
    absl::StatusOr<std::pair<std::string, int64_t>> sum = service::Sha256File(local);
    if (!sum.ok()) return sum.status();
    v1::FileInfo* info = files.header.add_files();
    info->set_name(name);
    info->set_sha256(sum->first);
    info->set_size(sum->second);
    files.paths.push_back(local);
    key.Update(std::string(1, '\0') + name + '\0' + sum->first);
  }
  files.header.set_request_id(request_id.empty() ? "upload-" + key.HexDigest() : request_id);
  return files;
}

namespace {

grpc::ChannelArguments ChannelArgs() {
  grpc::ChannelArguments args;
  args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, 60'000);
  args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 20'000);
  args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 0);
  args.SetMaxReceiveMessageSize(4 << 20);
  return args;
}

}  // namespace

std::shared_ptr<grpc::Channel> MakeChannel(const std::string& address) {
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), ChannelArgs());
}

absl::StatusOr<std::shared_ptr<grpc::Channel>> MakeChannel(const std::string& address,
                                                           const ChannelSecurity& security) {
  const bool tls = security.tls || !security.ca_file.empty() || !security.cert_file.empty() ||
                   !security.key_file.empty();
  if (!tls) {
    if (!security.token.empty()) {
      return absl::InvalidArgumentError(
          "a bearer token (--token-file or RADIOSITY_TOKEN) is sent only over TLS: add --tls-ca "
          "FILE, or --tls for the system's CAs");
    }
    return MakeChannel(address);
  }
  if (security.cert_file.empty() != security.key_file.empty()) {
    return absl::InvalidArgumentError("--tls-cert and --tls-key go together");
  }
  grpc::SslCredentialsOptions ssl;
  if (!security.ca_file.empty()) {
    absl::StatusOr<std::string> ca = ReadPemFile(security.ca_file, "--tls-ca");
    if (!ca.ok()) return ca.status();
    ssl.pem_root_certs = *ca;
  }
  if (!security.cert_file.empty()) {
    absl::StatusOr<std::string> cert = ReadPemFile(security.cert_file, "--tls-cert");
    if (!cert.ok()) return cert.status();
    absl::StatusOr<std::string> key = ReadPemFile(security.key_file, "--tls-key");
    if (!key.ok()) return key.status();
    ssl.pem_cert_chain = *cert;
    ssl.pem_private_key = *key;
  }
  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::SslCredentials(ssl);
  if (!security.token.empty()) {
    credentials = grpc::CompositeChannelCredentials(credentials,
                                                    grpc::AccessTokenCredentials(security.token));
  }
  grpc::ChannelArguments args = ChannelArgs();
  if (!security.server_name.empty()) args.SetSslTargetNameOverride(security.server_name);
  return grpc::CreateCustomChannel(address, credentials, args);
}

absl::StatusOr<std::string> ReadToken(const std::string& token_file) {
  std::string token;
  if (!token_file.empty()) {
    absl::StatusOr<std::string> text = ReadWholeFile(token_file);
    if (!text.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("--token-file: ", text.status().message()));
    }
    token = text->substr(0, text->find('\n'));
  } else if (const char* env = std::getenv("RADIOSITY_TOKEN")) {
    token = env;
  }
  token = std::string(absl::StripAsciiWhitespace(token));
  if (!token_file.empty() && token.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--token-file: ", token_file, " has no token on its first line"));
  }
  return token;
}

Client::Client(std::shared_ptr<grpc::Channel> channel, ClientOptions options)
    : channel_(std::move(channel)),
      stub_(v1::RadiosityService::NewStub(channel_)),
      options_(options) {}

void Client::SetDeadline(grpc::ClientContext* context, double seconds) const {
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000)));
}

absl::StatusOr<v1::SceneInfo> Client::UploadSceneFile(const std::string& path,
                                                      const std::string& request_id,
                                                      const SceneReadOptions& read) {
  absl::StatusOr<SceneFiles> files = CollectSceneFiles(path, request_id, read);
  if (!files.ok()) return files.status();
  return Upload(*files);
}

absl::StatusOr<v1::SceneInfo> Client::Upload(const SceneFiles& files) {
  // The request id makes a repeated upload return the first: safe to retry.
  double backoff = 0.1;
  for (int attempt = 0;; ++attempt) {
    absl::StatusOr<v1::SceneInfo> info = UploadOnce(files);
    if (info.ok() || info.status().code() != absl::StatusCode::kUnavailable ||
        files.header.request_id().empty() || attempt + 1 >= kUnaryAttempts) {
      return info;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(static_cast<int64_t>(backoff * 1000)));
    backoff *= 2;
  }
}

absl::StatusOr<v1::SceneInfo> Client::UploadOnce(const SceneFiles& files) {
  // First the header alone: a scene stored under this request id comes back without sending its
  // files (a stream answered early can leave a writer blocked, as over the in-process channel).
  if (!files.header.request_id().empty()) {
    grpc::ClientContext probe_context;
    SetDeadline(&probe_context, options_.timeout_seconds);
    v1::SceneInfo stored;
    std::unique_ptr<grpc::ClientWriter<v1::UploadSceneRequest>> probe =
        stub_->UploadScene(&probe_context, &stored);
    v1::UploadSceneRequest header;
    *header.mutable_header() = files.header;
    header.mutable_header()->set_only_if_stored(true);
    if (probe->Write(header)) probe->WritesDone();
    const grpc::Status status = probe->Finish();
    if (status.ok()) return stored;
    if (status.error_code() != grpc::StatusCode::NOT_FOUND) return FromGrpcStatus(status);
  }
  int64_t total = 0;
  for (const v1::FileInfo& f : files.header.files()) total += f.size();
  grpc::ClientContext context;
  // The base deadline plus a second per MiB (a slow link still finishes).
  SetDeadline(&context, options_.timeout_seconds + static_cast<double>(total) / (1 << 20));
  v1::SceneInfo response;
  std::unique_ptr<grpc::ClientWriter<v1::UploadSceneRequest>> writer =
      stub_->UploadScene(&context, &response);
  v1::UploadSceneRequest request;
  *request.mutable_header() = files.header;
  bool open = writer->Write(request);
  std::string buffer(kUploadChunk, '\0');
  for (size_t i = 0; open && i < files.paths.size(); ++i) {
    std::ifstream in(files.paths[i], std::ios::binary);
    if (!in) {
      context.TryCancel();
      return ReadError(files.paths[i]);
    }
    const std::string& name = files.header.files(static_cast<int>(i)).name();
    int64_t offset = 0;
    while (open) {
      in.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
      std::streamsize n = in.gcount();
      if (n <= 0) break;
      request.Clear();
      v1::FileChunk* chunk = request.mutable_chunk();
      chunk->set_file(name);
      chunk->set_offset(offset);
      chunk->set_data(buffer.data(), static_cast<size_t>(n));
      offset += n;
      open = writer->Write(request);
    }
  }
  // A closed stream means the server has answered (a known request id, or an error): Finish
  // tells which.
  if (open) writer->WritesDone();
  grpc::Status status = writer->Finish();
  if (!status.ok()) return FromGrpcStatus(status);
  return response;
}

template <typename Request, typename Response>
absl::StatusOr<Response> Client::Unary(grpc::Status (v1::RadiosityService::Stub::*method)(
                                           grpc::ClientContext*, const Request&, Response*),
                                       const Request& request, bool idempotent) {
  double backoff = 0.1;
  for (int attempt = 0;; ++attempt) {
    grpc::ClientContext context;
    SetDeadline(&context, options_.timeout_seconds);
    Response response;
    grpc::Status status = ((*stub_).*method)(&context, request, &response);
    if (status.ok()) return response;
    // Only UNAVAILABLE is retried, and only calls that are safe to repeat.
    if (!idempotent || status.error_code() != grpc::StatusCode::UNAVAILABLE ||
        attempt + 1 >= kUnaryAttempts) {
      return FromGrpcStatus(status);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(static_cast<int64_t>(backoff * 1000)));
    backoff *= 2;
  }
}

absl::StatusOr<v1::SceneInfo> Client::GetScene(const std::string& name) {
  v1::GetSceneRequest request;
  request.set_name(name);
  return Unary(&v1::RadiosityService::Stub::GetScene, request, true);
}

absl::StatusOr<v1::ListScenesResponse> Client::ListScenes(const v1::ListScenesRequest& request) {
  return Unary(&v1::RadiosityService::Stub::ListScenes, request, true);
}

absl::Status Client::DeleteScene(const std::string& name) {
  v1::DeleteSceneRequest request;
  request.set_name(name);
  return Unary(&v1::RadiosityService::Stub::DeleteScene, request, false).status();
}

absl::StatusOr<v1::Job> Client::CreateJob(const v1::CreateJobRequest& request) {
  // With a request id a repeated create returns the first job: safe to retry.
  return Unary(&v1::RadiosityService::Stub::CreateJob, request, !request.request_id().empty());
}

absl::StatusOr<v1::Job> Client::GetJob(const std::string& name) {
  v1::GetJobRequest request;
  request.set_name(name);
  return Unary(&v1::RadiosityService::Stub::GetJob, request, true);
}

absl::StatusOr<v1::ListJobsResponse> Client::ListJobs(const v1::ListJobsRequest& request) {
  return Unary(&v1::RadiosityService::Stub::ListJobs, request, true);
}

absl::StatusOr<v1::Job> Client::CancelJob(const std::string& name) {
  v1::CancelJobRequest request;
  request.set_name(name);
  return Unary(&v1::RadiosityService::Stub::CancelJob, request, true);
}

absl::Status Client::DeleteJob(const std::string& name) {
  v1::DeleteJobRequest request;
  request.set_name(name);
  return Unary(&v1::RadiosityService::Stub::DeleteJob, request, false).status();
}

absl::StatusOr<Snapshot> Client::Watch(const std::string& job, int64_t after_sequence,
                                       bool progress_only,
                                       const std::function<bool(const Snapshot&)>& on_snapshot,
                                       const std::atomic<bool>* stop, bool include_mesh) {
  int64_t after = after_sequence;
  // The mesh most recently announced (kept across reconnections; each stream announces again).
  std::shared_ptr<const MeshGeometry> mesh;
  int failures = 0;
  double backoff = 0.1;
  bool stopped_by_callback = false;
  while (true) {
    if (stop && *stop) return absl::CancelledError("stopped watching");
    grpc::ClientContext context;
    SetDeadline(&context, options_.watch_stream_seconds);
    v1::WatchJobRequest request;
    request.set_name(job);
    request.set_after_sequence(after);
    request.set_progress_only(progress_only);
    request.set_include_mesh(include_mesh);
    // Half the floats for one-sided surfaces; expanded to the full layout below.
    request.set_existing_sides_only(true);
    std::unique_ptr<grpc::ClientReader<v1::WatchJobResponse>> reader =
        stub_->WatchJob(&context, request);
    // Cancels the stream when *stop becomes true (Read blocks otherwise).
    std::atomic<bool> done{false};
    std::thread canceller;
    if (stop) {
      canceller = std::thread([&] {
        while (!done && !*stop) std::this_thread::sleep_for(std::chrono::milliseconds(20));
        if (!done) context.TryCancel();
      });
    }
    Snapshot current;
    bool assembling = false;
    bool existing_sides = false;  // current's values are of the existing sides only.
    std::vector<int64_t> back_ranges;
    std::optional<Snapshot> final_snapshot;
    bool progressed = false;
    std::shared_ptr<MeshGeometry> announcing;  // A mesh announcement being received.
    absl::Status bad_mesh;
    v1::WatchJobResponse message;
    while (reader->Read(&message)) {
      if (message.has_mesh()) {
        if (message.mesh().chunk_index() == 0) announcing = std::make_shared<MeshGeometry>();
        if (!announcing) continue;  // Missed its start.
        bool complete = false;
        bad_mesh = AddMeshChunk(message.mesh(), announcing.get(), &complete);
        if (!bad_mesh.ok()) {
          context.TryCancel();
          break;
        }
        if (complete) mesh = std::move(announcing);
        continue;
      }
      if (message.chunk_index() == 0) {
        current = Snapshot();
        current.sequence = message.sequence();
        current.state = message.state();
        current.progress = message.progress();
        current.resync = message.resync();
        current.final = message.final();
        current.error = message.error();
        current.elements = message.elements();
        current.attempts = message.attempts();
        current.mesh_version = message.mesh_version();
        current.radiosity.assign(
            static_cast<size_t>(std::max<int64_t>(0, message.radiosity_total())), 0.0f);
        existing_sides = message.existing_sides_only();
        back_ranges.assign(message.back_ranges().begin(), message.back_ranges().end());
        assembling = true;
      }
      if (!assembling || message.sequence() != current.sequence) continue;  // Missed its start.
      const int64_t offset = message.radiosity_offset();
      if (offset >= 0 &&
          offset + message.radiosity().size() <= static_cast<int64_t>(current.radiosity.size())) {
        std::copy(message.radiosity().begin(), message.radiosity().end(),
                  current.radiosity.begin() + offset);
      }
      if (message.chunk_index() + 1 < message.chunk_count()) continue;
      assembling = false;
      if (existing_sides &&
          !ExpandExistingSides(back_ranges, current.elements, &current.radiosity)) {
        current.radiosity.clear();  // Inconsistent with its ranges: dropped, never misread.
      }
      if (mesh && mesh->version == current.mesh_version && !current.radiosity.empty() &&
          static_cast<int64_t>(current.radiosity.size()) == 6 * mesh->elements()) {
        current.mesh = mesh;
      }
      after = current.sequence;
      progressed = true;
      if (current.final) {
        final_snapshot = std::move(current);
        if (on_snapshot) on_snapshot(*final_snapshot);
        continue;  // The server ends the stream.
      }
      if (on_snapshot && !on_snapshot(current)) {
        stopped_by_callback = true;
        context.TryCancel();
        break;
      }
    }
    grpc::Status status = reader->Finish();
    done = true;
    if (canceller.joinable()) canceller.join();
    if (!bad_mesh.ok()) return bad_mesh;
    if (final_snapshot) return *std::move(final_snapshot);
    if (stopped_by_callback || (stop && *stop)) return absl::CancelledError("stopped watching");
    if (status.ok()) {
      // The stream ended with nothing newer than `after`: the job had ended before.
      absl::StatusOr<v1::Job> ended = GetJob(job);
      if (!ended.ok()) return ended.status();
      Snapshot s;
      s.sequence = ended->last_sequence();
      s.state = ended->state();
      s.progress = ended->progress();
      s.final = true;
      s.error = ended->error();
      s.elements = ended->mesh().elements();
      s.attempts = ended->attempts();
      return s;
    }
    if (status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) continue;  // Resume.
    if (status.error_code() != grpc::StatusCode::UNAVAILABLE) return FromGrpcStatus(status);
    if (progressed) {
      failures = 0;
      backoff = 0.1;
    }
    if (++failures > options_.max_retries) return FromGrpcStatus(status);
    std::this_thread::sleep_for(std::chrono::milliseconds(static_cast<int64_t>(backoff * 1000)));
    backoff = std::min(2.0, backoff * 2);
  }
}

absl::StatusOr<std::vector<std::string>> Client::DownloadResults(const std::string& job,
                                                                 const std::string& dir,
                                                                 const std::string& file) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) {
    return absl::InternalError(absl::StrCat(dir, ": cannot create directory: ", ec.message()));
  }
  grpc::ClientContext context;
  SetDeadline(&context, options_.download_seconds);
  v1::DownloadResultRequest request;
  request.set_name(job);
  request.set_file(file);
  std::unique_ptr<grpc::ClientReader<v1::FileChunk>> reader =
      stub_->DownloadResult(&context, request);
  std::vector<std::string> written;
  std::ofstream out;
  std::unique_ptr<service::Sha256> sha;
  std::string part;
  int64_t expected_offset = 0;
  absl::Status error;
  v1::FileChunk chunk;
  while (error.ok() && reader->Read(&chunk)) {
    if (!IsSafeRelativeName(chunk.file())) {
      error =
          absl::InternalError(absl::StrCat("the server sent a bad file name '", chunk.file(), "'"));
      break;
    }
    if (chunk.offset() == 0) {
      part = Join(dir, chunk.file()) + ".part";
      fs::create_directories(fs::path(part).parent_path(), ec);
      out = std::ofstream(part, std::ios::binary | std::ios::trunc);
      if (!out) {
        error = WriteErrnoStatus(errno, absl::StrCat(part, ": cannot write: "));
        break;
      }
      sha = std::make_unique<service::Sha256>();
      expected_offset = 0;
    }
    if (!sha || chunk.offset() != expected_offset) {
      error = absl::InternalError(absl::StrCat(chunk.file(), ": chunks out of order"));
      break;
    }
    out.write(chunk.data().data(), static_cast<std::streamsize>(chunk.data().size()));
    sha->Update(chunk.data());
    expected_offset += static_cast<int64_t>(chunk.data().size());
    if (!chunk.last()) continue;
    out.close();
    std::string digest = sha->HexDigest();
    sha.reset();
    if (!out || expected_offset != chunk.info().size() || digest != chunk.info().sha256()) {
      error = absl::DataLossError(
          absl::StrCat(chunk.file(), ": the download does not match its size or checksum"));
      break;
    }
    std::string target = Join(dir, chunk.file());
    fs::rename(part, target, ec);
    if (ec) {
      error = absl::InternalError(absl::StrCat(target, ": ", ec.message()));
      break;
    }
    part.clear();
    written.push_back(chunk.file());
  }
  if (!error.ok()) context.TryCancel();
  grpc::Status status = reader->Finish();
  if (!part.empty()) fs::remove(part, ec);
  if (!error.ok()) return error;
  if (!status.ok()) return FromGrpcStatus(status);
  return written;
}

absl::StatusOr<std::string> Client::DownloadScene(const std::string& name, const std::string& dir) {
  grpc::ClientContext context;
  SetDeadline(&context, options_.download_seconds);
  v1::DownloadSceneRequest request;
  request.set_name(name);
  std::unique_ptr<grpc::ClientReader<v1::FileChunk>> reader =
      stub_->DownloadScene(&context, request);
  std::string main;
  std::ofstream out;
  v1::FileChunk chunk;
  absl::Status error;
  std::error_code ec;
  while (reader->Read(&chunk)) {
    if (!error.ok()) continue;
    if (!IsSafeRelativeName(chunk.file())) {
      error =
          absl::InternalError(absl::StrCat("the server sent a bad file name '", chunk.file(), "'"));
      continue;
    }
    std::string path = Join(dir, chunk.file());
    if (main.empty()) main = path;
    if (chunk.offset() == 0) {
      fs::create_directories(fs::path(path).parent_path(), ec);
      out = std::ofstream(path, std::ios::binary | std::ios::trunc);
    }
    out.write(chunk.data().data(), static_cast<std::streamsize>(chunk.data().size()));
    if (!out) error = WriteErrnoStatus(errno, absl::StrCat(path, ": cannot write: "));
    if (chunk.last()) out.close();
  }
  grpc::Status status = reader->Finish();
  if (!status.ok()) return FromGrpcStatus(status);
  if (!error.ok()) return error;
  if (main.empty()) return absl::InternalError(absl::StrCat(name, ": the scene has no files"));
  return main;
}

absl::StatusOr<bool> Client::CheckHealth(const std::string& service_name) {
  // grpc.health.v1.HealthCheckRequest { string service = 1; }, encoded by hand: the health
  // protos are not installed with Debian's gRPC.
  std::string request_bytes;
  request_bytes.push_back(0x0a);
  size_t n = service_name.size();
  do {
    unsigned char byte = n & 0x7f;
    n >>= 7;
    request_bytes.push_back(static_cast<char>(byte | (n ? 0x80 : 0)));
  } while (n);
  request_bytes += service_name;
  grpc::Slice slice(request_bytes);
  grpc::ByteBuffer request(&slice, 1);
  grpc::ByteBuffer response;
  grpc::GenericStub stub(channel_);
  grpc::ClientContext context;
  SetDeadline(&context, options_.timeout_seconds);
  std::promise<grpc::Status> done;
  stub.UnaryCall(&context, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request, &response,
                 [&](grpc::Status s) { done.set_value(std::move(s)); });
  grpc::Status status = done.get_future().get();
  if (!status.ok()) return FromGrpcStatus(status);
  std::vector<grpc::Slice> slices;
  if (!response.Dump(&slices).ok()) return absl::InternalError("bad health response");
  std::string bytes;
  for (const grpc::Slice& s : slices)
    bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  // HealthCheckResponse { ServingStatus status = 1; }: SERVING = 1; an empty message is UNKNOWN.
  return bytes.size() >= 2 && bytes[0] == 0x08 && bytes[1] == 0x01;
}

}  // namespace radiosity::client
