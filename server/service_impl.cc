#include "server/service_impl.h"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <thread>

#include "absl/cleanup/cleanup.h"
#include "absl/strings/str_cat.h"
#include "proto/api/names.h"
#include "proto/api/scene_format.h"
#include "proto/api/sha256.h"
#include "proto/api/spec.h"
#include "proto/api/status.h"
#include "server/logging.h"
#include "server/snapshots.h"
#include "solver/input/photometry_file.h"
#include "solver/util/file_io.h"

namespace radiosity::service {
namespace {

namespace fs = std::filesystem;

// Runs `fn` (returning absl::Status) so that no exception escapes a handler.
template <typename Fn>
absl::Status Guarded(const char* method, Fn&& fn) noexcept {
  try {
    return fn();
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat(method, ": unexpected error: ", e.what()));
  } catch (...) {
    return absl::InternalError(absl::StrCat(method, ": unexpected error"));
  }
}

// Longest UploadSceneHeader.display_name (a client's path of the main file).
constexpr size_t kMaxDisplayName = 1024;
// Loader warnings kept in a SceneInfo; the rest are counted.
constexpr size_t kMaxWarnings = 200;

bool IsHex64(const std::string& s) {
  if (s.size() != 64) return false;
  for (char c : s) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  }
  return true;
}

// A client's string for quoting in a message: long ones are cut (the message must stay short).
std::string Abbreviate(const std::string& s) {
  if (s.size() <= 80) return s;
  return absl::StrCat(s.substr(0, 64), "... (", s.size(), " bytes)");
}

absl::StatusOr<std::string> RequireId(const std::string& name, const char* collection) {
  std::string id = IdFromName(name, collection);
  if (id.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat("name: '", Abbreviate(name), "' is not a ", collection, "/{id} name"));
  }
  return id;
}

// A streaming call that failed before it started: finishes with the error at once.
template <typename T>
class FailedWriteReactor : public grpc::ServerWriteReactor<T> {
 public:
  explicit FailedWriteReactor(const grpc::Status& status) { this->Finish(status); }
  void OnDone() override { delete this; }
};

// A unary call whose body `fn` (returning absl::Status) runs on the executor, which then
// finishes the call.
template <typename Fn>
grpc::ServerUnaryReactor* FinishOnExecutor(RadiosityServiceImpl* service,
                                           grpc::CallbackServerContext* context, const char* method,
                                           Fn fn) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  service->executor().Run([service, reactor, method, fn = std::move(fn)]() mutable {
    absl::Status status = Guarded(method, fn);
    service->Record(method, status);
    reactor->Finish(ToGrpcStatus(status));
  });
  return reactor;
}

// ---------------------------------------------------------------------------------------------
// UploadScene: a header, then chunks; the files are written to a private directory under
// DIR/uploads as they arrive (checksummed on the way) and become a scene only when complete and
// valid.

class UploadReactor : public grpc::ServerReadReactor<v1::UploadSceneRequest> {
 public:
  UploadReactor(RadiosityServiceImpl* service, grpc::CallbackServerContext* context,
                v1::SceneInfo* response)
      : service_(service), context_(context), response_(response) {
    // Each open upload holds a temporary directory and a file descriptor: past --max-uploads
    // the call ends at once.
    if (absl::Status admitted = service_->limits().AdmitUpload(&place_, context_); !admitted.ok()) {
      service_->Record("UploadScene", admitted);
      Finish(ToGrpcStatus(admitted));
      return;
    }
    admitted_ = true;
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    bool done = false;
    bool received = false;
    place_.Touch();
    absl::Status status = Guarded("UploadScene", [&]() -> absl::Status {
      if (!ok) {
        if (place_.TimedOut()) {
          return absl::DeadlineExceededError(
              "the upload sent nothing for --upload-idle-seconds; cancelled");
        }
        if (context_->IsCancelled()) return absl::CancelledError("the upload was cancelled");
        received = true;
        return CheckReceived();
      }
      if (!have_header_) return Header(&done);
      return Chunk();
    });
    if (status.ok() && received) {
      // Validation parses the whole scene (up to --max-upload-mb): on the executor, which
      // finishes the call. Nothing else touches this reactor meanwhile (no read is pending).
      place_.SetBusy(true);
      service_->executor().Run([this] {
        absl::Status commit = Guarded("UploadScene", [&] { return Commit(); });
        service_->Record("UploadScene", commit);
        Finish(ToGrpcStatus(commit));
      });
      return;
    }
    if (!status.ok() || done) {
      // A probe's NOT_FOUND (only_if_stored) is an answer, not a failed call.
      service_->Record("UploadScene", probe_miss_ ? absl::OkStatus() : status);
      Finish(ToGrpcStatus(status));
      return;
    }
    StartRead(&request_);
  }

  // The client gave up: a validation running on the executor stops at its next check.
  void OnCancel() override { cancelled_ = true; }

  void OnDone() override {
    if (admitted_) service_->limits().ReleaseUpload(&place_);
    out_.close();
    if (!tmp_dir_.empty()) {
      files_.clear();
      std::error_code ec;
      fs::remove_all(tmp_dir_, ec);
    }
    delete this;
  }

 private:
  struct Incoming {
    v1::FileInfo info;
    std::string path;  // Where it is written, in the upload's temporary directory.
    int64_t received = 0;
    std::unique_ptr<Sha256> sha;
  };

  bool probe_miss_ = false;  // An only_if_stored header for a request id not stored.

  // Closes the file being written, if any.
  absl::Status CloseOpen() {
    if (!open_) return absl::OkStatus();
    out_.close();
    const std::string name = open_->info.name();
    open_ = nullptr;
    if (!out_) return WriteErrnoStatus(errno, absl::StrCat(name, ": cannot write: "));
    out_.clear();
    return absl::OkStatus();
  }

  absl::Status Header(bool* done) {
    if (!request_.has_header()) {
      return absl::InvalidArgumentError("the first message of an upload must be its header");
    }
    have_header_ = true;
    absl::StatusOr<std::string> tenant = service_->Tenant(*context_);
    if (!tenant.ok()) return tenant.status();
    info_.set_tenant(*tenant);
    const v1::UploadSceneHeader& h = request_.header();
    if (h.request_id().size() > 256) {
      return absl::InvalidArgumentError("header.request_id: longer than 256 bytes");
    }
    if (h.display_name().size() > kMaxDisplayName) {
      return absl::InvalidArgumentError(
          absl::StrCat("header.display_name: longer than ", kMaxDisplayName, " bytes"));
    }
    if (h.files().empty()) return absl::InvalidArgumentError("header.files: no files");
    if (h.files_size() > kMaxUploadFiles) {
      return absl::InvalidArgumentError(
          absl::StrCat("header.files: ", h.files_size(), " files, more than ", kMaxUploadFiles));
    }
    int64_t total = 0;
    for (int i = 0; i < h.files_size(); ++i) {
      const v1::FileInfo& f = h.files(i);
      std::string where = absl::StrCat("header.files[", i, "] ('", f.name(), "')");
      if (!IsSafeRelativeName(f.name())) {
        return absl::InvalidArgumentError(absl::StrCat(
            where, ": not a relative path inside the scene (no '..', no leading '/')"));
      }
      if (files_.count(f.name())) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": appears twice"));
      }
      if (f.size() < 0) return absl::InvalidArgumentError(absl::StrCat(where, ": negative size"));
      if (!IsHex64(f.sha256())) {
        return absl::InvalidArgumentError(
            absl::StrCat(where, ": sha256 must be 64 lowercase hex digits"));
      }
      total += f.size();
      if (total > service_->options().max_upload_bytes) {
        return absl::ResourceExhaustedError(
            absl::StrCat("the upload is larger than this server's limit of ",
                         service_->options().max_upload_bytes, " bytes (--max-upload-mb)"));
      }
      files_[f.name()].info = f;
    }
    // A file whose name is a directory of another's ("m" and "m/a.mtl") cannot be stored.
    for (const auto& [name, incoming] : files_) {
      for (size_t slash = name.find('/'); slash != std::string::npos;
           slash = name.find('/', slash + 1)) {
        if (files_.count(name.substr(0, slash))) {
          return absl::InvalidArgumentError(absl::StrCat("header.files: '", name.substr(0, slash),
                                                         "' is both a file and a directory (of '",
                                                         name, "')"));
        }
      }
    }
    // proto3 enums are open: an undefined number arrives as is.
    if (!v1::SceneFormat_IsValid(h.format())) {
      return absl::InvalidArgumentError(absl::StrCat(
          "header.format: ", static_cast<int>(h.format()), " is not a SceneFormat value (0 to 4)"));
    }
    absl::StatusOr<v1::SceneFormat> format = ResolveFormat(h.format(), h.files(0).name());
    if (!format.ok()) return format.status();
    if (*format == v1::SCENE_FORMAT_JSON || *format == v1::SCENE_FORMAT_BINARY) {
      // Besides photometric files for luminaires (SolveSpec.luminaires).
      for (int i = 1; i < h.files_size(); ++i) {
        if (!IsPhotometryFile(h.files(i).name())) {
          return absl::InvalidArgumentError(
              absl::StrCat("header.files[", i, "]: '", h.files(i).name(),
                           "': a native scene is a single file (with photometric .ies or .ldt "
                           "files for its luminaires)"));
        }
      }
    }
    info_.set_display_name(h.display_name().empty() ? h.files(0).name() : h.display_name());
    info_.set_strict(h.strict());
    info_.set_vertex_colors(h.vertex_colors());
    info_.set_format(*format);
    *info_.mutable_files() = h.files();
    info_.set_total_size(total);
    info_.set_request_id(h.request_id());

    // A retry of an upload already stored: answer with it at once.
    if (!h.request_id().empty()) {
      absl::StatusOr<std::optional<v1::SceneInfo>> existing =
          service_->store()->FindSceneByRequest(*tenant, h.request_id());
      if (!existing.ok()) return existing.status();
      if (existing->has_value()) {
        const v1::SceneInfo& stored = **existing;
        bool same = stored.files_size() == h.files_size();
        for (int i = 0; same && i < h.files_size(); ++i) {
          same = stored.files(i).name() == h.files(i).name() &&
                 stored.files(i).sha256() == h.files(i).sha256();
        }
        if (!same) {
          return absl::AlreadyExistsError(absl::StrCat("request_id '", h.request_id(),
                                                       "' was used for different files (",
                                                       stored.name(), ")"));
        }
        *response_ = stored;
        *done = true;
        return absl::OkStatus();
      }
    }
    if (h.only_if_stored()) {
      probe_miss_ = true;
      return absl::NotFoundError(absl::StrCat("no scene is stored for request_id '", h.request_id(),
                                              "' (send the files)"));
    }
    if (absl::Status st = service_->jobs()->quotas().CheckStore(*tenant, total); !st.ok()) {
      return st;
    }
    tmp_dir_ = absl::StrCat(service_->data_dir().Uploads(), "/", NewId());
    std::error_code ec;
    fs::create_directories(tmp_dir_, ec);
    if (ec) return absl::InternalError(absl::StrCat(tmp_dir_, ": ", ec.message()));
    for (auto& [name, incoming] : files_) {
      fs::path path = fs::path(tmp_dir_) / name;
      fs::create_directories(path.parent_path(), ec);
      if (ec) return absl::InternalError(absl::StrCat(name, ": cannot create: ", ec.message()));
      incoming.path = path.string();
      incoming.sha = std::make_unique<Sha256>();
    }
    return absl::OkStatus();
  }

  absl::Status Chunk() {
    if (!request_.has_chunk()) {
      return absl::InvalidArgumentError("after the header, an upload sends only chunks");
    }
    const v1::FileChunk& c = request_.chunk();
    auto it = files_.find(c.file());
    if (it == files_.end()) {
      return absl::InvalidArgumentError(
          absl::StrCat("chunk for '", Abbreviate(c.file()), "', which the header does not list"));
    }
    Incoming& f = it->second;
    if (static_cast<int64_t>(c.data().size()) > kMaxChunkBytes) {
      return absl::InvalidArgumentError(
          absl::StrCat("chunk of '", c.file(), "': ", c.data().size(), " bytes, above 1 MiB"));
    }
    if (c.offset() != f.received) {
      return absl::InvalidArgumentError(absl::StrCat("chunk of '", c.file(), "' at offset ",
                                                     c.offset(), "; expected ", f.received));
    }
    if (f.received + static_cast<int64_t>(c.data().size()) > f.info.size()) {
      return absl::InvalidArgumentError(
          absl::StrCat("'", c.file(), "' is longer than the ", f.info.size(), " bytes declared"));
    }
    // One file open at a time (an upload of many files holds one descriptor): chunks of one file
    // follow each other, so a file is reopened only when the client interleaves files.
    if (open_ != &f) {
      if (absl::Status st = CloseOpen(); !st.ok()) return st;
      out_.open(f.path, std::ios::binary | (f.received == 0 ? std::ios::trunc : std::ios::app));
      if (!out_) return absl::InternalError(absl::StrCat(c.file(), ": cannot create"));
      open_ = &f;
    }
    out_.write(c.data().data(), static_cast<std::streamsize>(c.data().size()));
    if (!out_) return WriteErrnoStatus(errno, absl::StrCat(c.file(), ": cannot write: "));
    f.sha->Update(c.data());
    f.received += static_cast<int64_t>(c.data().size());
    service_->metrics()->upload_bytes += static_cast<int64_t>(c.data().size());
    return absl::OkStatus();
  }

  // The stream has ended: every file must be complete and match its checksum.
  absl::Status CheckReceived() {
    if (!have_header_) return absl::InvalidArgumentError("an upload needs a header");
    if (absl::Status st = CloseOpen(); !st.ok()) return st;
    for (auto& [name, f] : files_) {
      if (f.received != f.info.size()) {
        return absl::InvalidArgumentError(
            absl::StrCat("'", name, "': received ", f.received, " of ", f.info.size(), " bytes"));
      }
      if (f.received == 0) {
        // An empty file has no chunk: create it now.
        std::ofstream(f.path, std::ios::binary | std::ios::trunc);
      }
      std::string digest = f.sha->HexDigest();
      if (digest != f.info.sha256()) {
        return absl::InvalidArgumentError(
            absl::StrCat("'", name, "': checksum mismatch (received sha256 ", digest,
                         ", header says ", f.info.sha256(), ")"));
      }
    }
    return absl::OkStatus();
  }

  absl::Status Commit() {
    absl::StatusOr<v1::SceneInfo> info = service_->CommitUpload(tmp_dir_, info_, &cancelled_);
    if (!info.ok()) return info.status();
    tmp_dir_.clear();  // Moved into the store.
    *response_ = *std::move(info);
    return absl::OkStatus();
  }

  RadiosityServiceImpl* const service_;
  grpc::CallbackServerContext* const context_;
  v1::SceneInfo* const response_;
  v1::UploadSceneRequest request_;
  bool have_header_ = false;
  v1::SceneInfo info_;
  std::map<std::string, Incoming> files_;
  CallLimits::Upload place_;  // Admitted by CallLimits (admitted_) until OnDone.
  bool admitted_ = false;
  std::atomic<bool> cancelled_{false};  // OnCancel: the client cancelled the call.
  Incoming* open_ = nullptr;            // The file out_ writes.
  std::ofstream out_;
  std::string tmp_dir_;
};

// ---------------------------------------------------------------------------------------------
// DownloadScene / DownloadResult: files in chunks, one write in flight.

class FileStreamReactor : public grpc::ServerWriteReactor<v1::FileChunk> {
 public:
  FileStreamReactor(std::string dir, std::vector<v1::FileInfo> files, int64_t offset)
      : dir_(std::move(dir)), files_(std::move(files)), offset_(offset) {
    NextWrite();
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(grpc::Status(grpc::StatusCode::CANCELLED, "the download stream broke"));
      return;
    }
    NextWrite();
  }

  void OnDone() override { delete this; }

 private:
  void NextWrite() {
    bool write = false;
    absl::Status status = Guarded("Download", [&]() -> absl::Status {
      if (index_ >= files_.size()) return absl::OkStatus();
      const v1::FileInfo& info = files_[index_];
      if (!in_.is_open()) {
        in_.open(dir_ + "/" + info.name(), std::ios::binary);
        if (!in_) return absl::InternalError(absl::StrCat(info.name(), ": cannot open"));
        in_.seekg(offset_);
        position_ = offset_;
      }
      chunk_.Clear();
      std::string* data = chunk_.mutable_data();
      data->resize(static_cast<size_t>(
          std::min<int64_t>(kDownloadChunkBytes, std::max<int64_t>(0, info.size() - position_))));
      in_.read(data->data(), static_cast<std::streamsize>(data->size()));
      if (in_.gcount() != static_cast<std::streamsize>(data->size())) {
        return absl::InternalError(absl::StrCat(info.name(), ": shorter than recorded"));
      }
      chunk_.set_file(info.name());
      chunk_.set_offset(position_);
      *chunk_.mutable_info() = info;
      position_ += static_cast<int64_t>(data->size());
      if (position_ >= info.size()) {
        chunk_.set_last(true);
        in_.close();
        ++index_;
        offset_ = 0;
      }
      write = true;
      return absl::OkStatus();
    });
    if (!status.ok()) {
      Finish(ToGrpcStatus(status));
    } else if (write) {
      StartWrite(&chunk_);
    } else {
      Finish(grpc::Status::OK);
    }
  }

  std::string dir_;
  std::vector<v1::FileInfo> files_;
  int64_t offset_;
  size_t index_ = 0;
  int64_t position_ = 0;
  std::ifstream in_;
  v1::FileChunk chunk_;
};

// ---------------------------------------------------------------------------------------------
// WatchJob: snapshots of one job, latest wins.

class WatchReactor : public grpc::ServerWriteReactor<v1::WatchJobResponse>, public SnapshotSink {
 public:
  // `limits` admitted this stream (as a watcher of class `admitted_progress_only`); it is released
  // when the stream is done.
  WatchReactor(Metrics* metrics, CallLimits* limits, bool admitted_progress_only,
               const v1::WatchJobRequest& request, std::shared_ptr<JobChannel> channel,
               SnapshotPtr ended)
      : metrics_(metrics),
        limits_(limits),
        admitted_progress_only_(admitted_progress_only),
        channel_(std::move(channel)),
        after_(request.after_sequence()),
        last_sent_(request.after_sequence()),
        progress_only_(request.progress_only()),
        include_mesh_(request.include_mesh() && !request.progress_only()),
        include_errors_(request.include_errors() && !request.progress_only()),
        existing_sides_only_(request.existing_sides_only()),
        floats_per_message_(include_errors_ ? kMaxFloatsPerMessage / 2 : kMaxFloatsPerMessage) {
    ++metrics_->watchers;
    if (channel_) {
      channel_->Subscribe(this);
    } else {
      OnSnapshot(ended);
    }
  }

  bool WantsExistingSides() const override { return existing_sides_only_ && !progress_only_; }

  void OnSnapshot(const SnapshotPtr& snapshot) override {
    std::lock_guard<std::mutex> lock(mu_);
    if (finished_ || !snapshot || snapshot->sequence <= newest_) return;
    // Meshing's progress before the first values (JobProgress.phase) is for progress-only
    // watchers: a stream of values starts with values.
    if (!progress_only_ && !snapshot->final && !snapshot->radiosity &&
        snapshot->progress.phase() == v1::JOB_PHASE_MESHING) {
      return;
    }
    newest_ = snapshot->sequence;
    if (snapshot->sequence <= after_) {
      // The client has it already; if it was the last one, there is nothing more to send.
      if (snapshot->final && !writing_) FinishLocked(grpc::Status::OK);
      if (snapshot->final) final_seen_ = true;
      return;
    }
    if (pending_) ++metrics_->snapshots_skipped;
    pending_ = snapshot;
    if (!writing_) WriteNextLocked();
  }

  void OnClose(const absl::Status& status) override {
    std::lock_guard<std::mutex> lock(mu_);
    close_status_ = ToGrpcStatus(status);
    if (!writing_) FinishLocked(*close_status_);
  }

  void OnWriteDone(bool ok) override {
    std::lock_guard<std::mutex> lock(mu_);
    writing_ = false;
    if (!ok) {
      FinishLocked(grpc::Status(grpc::StatusCode::CANCELLED, "the watch stream broke"));
      return;
    }
    WriteNextLocked();
  }

  void OnCancel() override {
    std::lock_guard<std::mutex> lock(mu_);
    cancelled_ = true;
    if (!writing_) FinishLocked(grpc::Status(grpc::StatusCode::CANCELLED, "watch cancelled"));
  }

  void OnDone() override {
    if (channel_) channel_->Unsubscribe(this);
    --metrics_->watchers;
    limits_->ReleaseWatcher(admitted_progress_only_);
    delete this;
  }

 private:
  void FinishLocked(const grpc::Status& status) {
    if (finished_) return;
    finished_ = true;
    Finish(status);
  }

  void WriteNextLocked() {
    if (finished_) return;
    if (announcing_) {
      // A mesh announcement, then the snapshot that refers to it.
      if (mesh_next_chunk_ < announcing_->chunks().size()) {
        WriteMeshChunkLocked();
        return;
      }
      announced_version_ = announcing_->version();
      announcing_ = nullptr;
      WriteChunkLocked();
      return;
    }
    if (current_ && next_chunk_ < chunk_count_) {
      WriteChunkLocked();
      return;
    }
    if (current_ && current_->final) {
      FinishLocked(grpc::Status::OK);
      return;
    }
    current_ = nullptr;
    if (cancelled_) {
      FinishLocked(grpc::Status(grpc::StatusCode::CANCELLED, "watch cancelled"));
      return;
    }
    if (close_status_) {
      FinishLocked(*close_status_);
      return;
    }
    if (final_seen_) {
      FinishLocked(grpc::Status::OK);
      return;
    }
    if (!pending_) return;
    current_ = std::move(pending_);
    pending_ = nullptr;
    resync_ = last_sent_ > 0 && current_->sequence != last_sent_ + 1;
    last_sent_ = current_->sequence;
    next_chunk_ = 0;
    // The layout asked for where this snapshot has it, else the full one.
    existing_ = existing_sides_only_ && current_->existing_radiosity != nullptr;
    values_ = existing_ ? current_->existing_radiosity.get() : current_->radiosity.get();
    errors_ = existing_ ? current_->existing_std_error.get() : current_->std_error.get();
    floats_ = (!progress_only_ && values_) ? static_cast<int64_t>(values_->data().size()) : 0;
    chunk_count_ = std::max<int64_t>(1, (floats_ + floats_per_message_ - 1) / floats_per_message_);
    ++metrics_->snapshots_sent;
    // Values refer to the mesh most recently announced on this stream: announce this one first
    // unless it is that one (every stream announces before its first values).
    if (include_mesh_ && floats_ > 0 && current_->mesh &&
        current_->mesh->version() != announced_version_) {
      announcing_ = current_->mesh;
      mesh_next_chunk_ = 0;
      WriteMeshChunkLocked();
      return;
    }
    WriteChunkLocked();
  }

  void WriteMeshChunkLocked() {
    response_.Clear();
    response_.set_sequence(current_->sequence);
    response_.set_mesh_version(announcing_->version());
    *response_.mutable_mesh() = announcing_->chunks()[mesh_next_chunk_];
    ++mesh_next_chunk_;
    writing_ = true;
    StartWrite(&response_);
  }

  void WriteChunkLocked() {
    const Snapshot& s = *current_;
    response_.Clear();
    response_.set_sequence(s.sequence);
    response_.set_state(s.state);
    *response_.mutable_progress() = s.progress;
    response_.set_resync(resync_);
    response_.set_final(s.final);
    if (s.error.code() != 0) *response_.mutable_error() = s.error;
    response_.set_elements(s.elements);
    response_.set_attempts(s.attempts);
    response_.set_radiosity_total(floats_);
    const int64_t begin = next_chunk_ * floats_per_message_;
    const int64_t end = std::min(floats_, begin + floats_per_message_);
    response_.set_radiosity_offset(begin);
    if (end > begin) {
      const float* data = values_->data().data();
      response_.mutable_radiosity()->Add(data + begin, data + end);
      if (include_errors_ && errors_) {
        const float* se = errors_->data().data();
        response_.mutable_std_error()->Add(se + begin, se + end);
      }
    }
    if (existing_ && floats_ > 0) {
      response_.set_existing_sides_only(true);
      if (next_chunk_ == 0) {
        const std::vector<int64_t>& ranges = *s.back_ranges;
        response_.mutable_back_ranges()->Add(ranges.begin(), ranges.end());
      }
    }
    response_.set_chunk_index(static_cast<int32_t>(next_chunk_));
    response_.set_chunk_count(static_cast<int32_t>(chunk_count_));
    if (floats_ > 0) response_.set_mesh_version(s.mesh ? s.mesh->version() : s.mesh_version);
    ++next_chunk_;
    writing_ = true;
    StartWrite(&response_);
  }

  Metrics* const metrics_;
  CallLimits* const limits_;
  const bool admitted_progress_only_;
  const std::shared_ptr<JobChannel> channel_;
  const int64_t after_;
  int64_t last_sent_;
  const bool progress_only_;
  const bool include_mesh_;
  const bool include_errors_;
  const bool existing_sides_only_;
  // Values per message: half as many when errors come along, so a message stays below 1 MiB.
  const int64_t floats_per_message_;

  std::mutex mu_;
  bool writing_ = false;
  bool finished_ = false;
  bool cancelled_ = false;
  bool final_seen_ = false;
  std::optional<grpc::Status> close_status_;
  int64_t newest_ = 0;
  SnapshotPtr pending_;  // The newest snapshot not yet started (latest wins).
  SnapshotPtr current_;  // The snapshot being written.
  int64_t next_chunk_ = 0, chunk_count_ = 0, floats_ = 0;
  // current_'s values and errors in the layout sent (existing_: existing sides only).
  const FloatBlock* values_ = nullptr;
  const FloatBlock* errors_ = nullptr;
  bool existing_ = false;
  MeshPtr announcing_;             // The mesh being announced before current_, if any.
  size_t mesh_next_chunk_ = 0;     // Its next message.
  int64_t announced_version_ = 0;  // The mesh last announced on this stream (0: none).
  bool resync_ = false;
  v1::WatchJobResponse response_;
};

bool IsEnded(v1::JobState s) {
  return s == v1::JOB_STATE_SUCCEEDED || s == v1::JOB_STATE_FAILED || s == v1::JOB_STATE_CANCELLED;
}

// The final radiosity of an ended job (and with `include_mesh` the geometry it refers to) into
// `snapshot`, from its results directory. What the files lack is left out: jobs that ended
// before geometry was stored have no file, and their values go without an announcement.
void ReadEndedResults(const DataDir& dir, const std::string& id, int64_t mesh_version,
                      bool include_mesh, bool existing_sides, Snapshot* snapshot) {
  absl::StatusOr<std::string> bytes = ReadWholeFile(dir.Results(id) + "/" + kRadiosityFile);
  if (!bytes.ok() || bytes->size() % sizeof(float) != 0) return;
  std::vector<float> data(bytes->size() / sizeof(float));
  std::memcpy(data.data(), bytes->data(), bytes->size());
  snapshot->radiosity = std::make_shared<const FloatBlock>(std::move(data));
  snapshot->mesh_version = mesh_version;
  absl::StatusOr<std::string> errors = ReadWholeFile(dir.Results(id) + "/" + kStdErrorFile);
  if (errors.ok() && errors->size() == bytes->size()) {
    std::vector<float> se(errors->size() / sizeof(float));
    std::memcpy(se.data(), errors->data(), errors->size());
    snapshot->std_error = std::make_shared<const FloatBlock>(std::move(se));
  }
  absl::StatusOr<std::string> ranges = existing_sides
                                           ? ReadWholeFile(dir.Results(id) + "/" + kBackRangesFile)
                                           : absl::NotFoundError("not asked for");
  if (ranges.ok()) {
    snapshot->back_ranges =
        ParseBackRanges(*ranges, static_cast<int64_t>(snapshot->radiosity->data().size() / 6));
  }
  if (!include_mesh) {
    AddExistingSides(snapshot);
    return;
  }
  bytes = ReadWholeFile(dir.Results(id) + "/" + kMeshGeometryFile);
  absl::StatusOr<MeshPtr> mesh = bytes.ok() ? ParseMesh(*bytes) : bytes.status();
  if (mesh.ok() &&
      6 * (*mesh)->elements() == static_cast<int64_t>(snapshot->radiosity->data().size())) {
    snapshot->mesh = *std::move(mesh);
    snapshot->mesh_version = snapshot->mesh->version();
  }
  AddExistingSides(snapshot);
}

}  // namespace

absl::StatusOr<std::string> RadiosityServiceImpl::Tenant(
    const grpc::CallbackServerContext& context) const {
  return TenantOf(context, options_.tokens.get());
}

absl::StatusOr<v1::SceneInfo> RadiosityServiceImpl::OwnedScene(const std::string& id,
                                                               const std::string& tenant) {
  absl::StatusOr<v1::SceneInfo> info = store_->GetScene(id);
  if (info.ok() && info->tenant() != tenant) {
    return absl::NotFoundError(absl::StrCat("scenes/", id, " does not exist"));
  }
  return info;
}

RadiosityServiceImpl::RadiosityServiceImpl(const ServiceOptions& options, const DataDir& dir,
                                           Store* store, JobManager* jobs, Metrics* metrics)
    : options_(options),
      dir_(dir),
      store_(store),
      jobs_(jobs),
      metrics_(metrics),
      limits_(options.limits),
      executor_(std::max(4, 2 * static_cast<int>(std::thread::hardware_concurrency()))) {}

void RadiosityServiceImpl::Record(const char* method, const absl::Status& status) {
  ++metrics_->requests;
  if (status.ok()) return;
  ++metrics_->request_errors;
  LogLine line("rpc_error");
  line.Str("method", method)
      .Str("code", absl::StatusCodeToString(status.code()))
      .Str("error", status.message());
  if (status.code() == absl::StatusCode::kInternal) {
    line.Error();
  } else {
    line.Debug();
  }
}

absl::StatusOr<v1::SceneInfo> RadiosityServiceImpl::CommitUpload(
    const std::string& dir, v1::SceneInfo info, const std::atomic<bool>* cancelled) {
  if (!info.request_id().empty()) {
    // A concurrent retry of the same upload finished first: answer with its scene.
    absl::StatusOr<std::optional<v1::SceneInfo>> existing =
        store_->FindSceneByRequest(info.tenant(), info.request_id());
    if (!existing.ok()) return existing.status();
    if (existing->has_value()) return **existing;
  }
  // No lock is held while the scene is parsed and checked: the files are this upload's own.
  std::vector<std::string> warnings;
  ++metrics_->uploads_validating;
  absl::StatusOr<Scene> scene = [&] {
    absl::Cleanup done = [&] { --metrics_->uploads_validating; };
    const StopToken stop(jobs_->stopping(), cancelled, 0);
    return LoadStoredScene(dir, info, &warnings, &stop);
  }();
  if (!scene.ok() && scene.status().code() == absl::StatusCode::kCancelled) {
    if (cancelled != nullptr && cancelled->load()) {
      return absl::CancelledError("the upload was cancelled while it was validated");
    }
    return absl::UnavailableError("the server is shutting down; upload again");
  }
  if (!scene.ok()) {
    // Whatever the loader said (missing material library, parse error, validation rule), the
    // upload is what is wrong.
    return absl::InvalidArgumentError(scene.status().message());
  }
  info.set_materials(static_cast<int64_t>(scene->materials.size()));
  info.set_surfaces(static_cast<int64_t>(scene->surfaces.size()));
  info.set_faces(static_cast<int64_t>(scene->faces.size()));
  info.set_has_emitter(EmittedPower(*scene).Sum() > 0);
  double area = 0;
  for (const Face& f : scene->faces) area += PolygonArea(*scene, f);
  info.set_area(area);
  // Bounded: a scene of a million degenerate faces must not make a SceneInfo above gRPC's
  // message limit (it could never be read back).
  for (size_t i = 0; i < warnings.size() && i < kMaxWarnings; ++i) {
    info.add_warnings(ValidUtf8(warnings[i]));
  }
  if (warnings.size() > kMaxWarnings) {
    info.add_warnings(absl::StrCat("(", warnings.size() - kMaxWarnings, " more warnings)"));
  }
  // Checked again: other uploads of the tenant may have been stored since the header.
  if (absl::Status st = jobs_->quotas().CheckStore(info.tenant(), info.total_size()); !st.ok()) {
    return st;
  }
  std::string id = NewId();
  info.set_name("scenes/" + id);
  *info.mutable_create_time() = Now();
  std::error_code ec;
  if (absl::Status st = MoveDirectory(dir, dir_.Scene(id)); !st.ok()) return st;
  // The files are in place before the row names them; a retry that committed meanwhile wins.
  absl::StatusOr<std::optional<v1::SceneInfo>> existing = store_->InsertScene(id, info);
  if (!existing.ok() || existing->has_value()) fs::remove_all(dir_.Scene(id), ec);
  if (!existing.ok()) return existing.status();
  if (existing->has_value()) return **existing;
  ++metrics_->uploads;
  LogLine("scene_uploaded")
      .Str("scene", id)
      .Str("tenant", info.tenant())
      .Str("request", info.request_id())
      .Str("display_name", info.display_name())
      .Int("bytes", info.total_size())
      .Int("faces", info.faces())
      .Info();
  return info;
}

grpc::ServerReadReactor<v1::UploadSceneRequest>* RadiosityServiceImpl::UploadScene(
    grpc::CallbackServerContext* context, v1::SceneInfo* response) {
  return new UploadReactor(this, context, response);
}

#define RADIOSITY_UNARY(method, body)                                \
  absl::Status status = Guarded(method, [&]() -> absl::Status body); \
  Record(method, status);                                            \
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();     \
  reactor->Finish(ToGrpcStatus(dir_.Redact(status)));                \
  return reactor;

grpc::ServerUnaryReactor* RadiosityServiceImpl::GetScene(grpc::CallbackServerContext* context,
                                                         const v1::GetSceneRequest* request,
                                                         v1::SceneInfo* response){
    RADIOSITY_UNARY("GetScene",
                    {
                      absl::StatusOr<std::string> id = RequireId(request->name(), "scenes");
                      if (!id.ok()) return id.status();
                      absl::StatusOr<std::string> tenant = Tenant(*context);
                      if (!tenant.ok()) return tenant.status();
                      absl::StatusOr<v1::SceneInfo> info = OwnedScene(*id, *tenant);
                      if (!info.ok()) return info.status();
                      *response = *std::move(info);
                      return absl::OkStatus();
                    })}

grpc::ServerUnaryReactor* RadiosityServiceImpl::ListScenes(grpc::CallbackServerContext* context,
                                                           const v1::ListScenesRequest* request,
                                                           v1::ListScenesResponse* response){
    RADIOSITY_UNARY("ListScenes",
                    {
                      if (request->page_size() < 0) {
                        return absl::InvalidArgumentError(
                            absl::StrCat("page_size: ", request->page_size(), " is negative"));
                      }
                      absl::StatusOr<std::string> tenant = Tenant(*context);
                      if (!tenant.ok()) return tenant.status();
                      absl::StatusOr<v1::ListScenesResponse> list =
                          store_->ListScenes(*tenant, request->page_size(), request->page_token());
                      if (!list.ok()) return list.status();
                      *response = *std::move(list);
                      return absl::OkStatus();
                    })}

grpc::ServerUnaryReactor* RadiosityServiceImpl::DeleteScene(grpc::CallbackServerContext* context,
                                                            const v1::DeleteSceneRequest* request,
                                                            v1::DeleteSceneResponse* response) {
  absl::StatusOr<std::string> tenant = Tenant(*context);
  return FinishOnExecutor(this, context, "DeleteScene", [this, request, tenant]() -> absl::Status {
    if (!tenant.ok()) return tenant.status();
    absl::StatusOr<std::string> id = RequireId(request->name(), "scenes");
    if (!id.ok()) return id.status();
    // Refused while a CreateJob uses the scene; CreateJob calls wait while this one decides.
    int64_t references = 0;
    std::optional<SceneRefs::Deletion> deletion = scene_refs_.BeginDelete(*id, &references);
    absl::StatusOr<v1::SceneInfo> info = OwnedScene(*id, *tenant);
    if (!info.ok()) return info.status();
    if (!deletion) {
      return absl::FailedPreconditionError(
          absl::StrCat(info->name(), " is used by ", references,
                       " jobs being created (to be queued or running); retry"));
    }
    absl::StatusOr<int64_t> busy =
        store_->CountJobs(info->name(), {v1::JOB_STATE_QUEUED, v1::JOB_STATE_RUNNING});
    if (!busy.ok()) return busy.status();
    if (*busy > 0) {
      return absl::FailedPreconditionError(
          absl::StrCat(info->name(), " is used by ", *busy, " queued or running jobs"));
    }
    if (absl::Status st = store_->DeleteScene(*id); !st.ok()) return st;
    // Once the row is gone no job can be created on the scene: its files go after the deletion
    // has let waiting CreateJob calls go on (to NOT_FOUND).
    deletion.reset();
    std::error_code ec;
    fs::remove_all(dir_.Scene(*id), ec);
    LogLine("scene_deleted").Str("scene", *id).Info();
    return absl::OkStatus();
  });
}

grpc::ServerWriteReactor<v1::FileChunk>* RadiosityServiceImpl::DownloadScene(
    grpc::CallbackServerContext* context, const v1::DownloadSceneRequest* request) {
  std::vector<v1::FileInfo> files;
  std::string id;
  absl::Status status = Guarded("DownloadScene", [&]() -> absl::Status {
    absl::StatusOr<std::string> parsed = RequireId(request->name(), "scenes");
    if (!parsed.ok()) return parsed.status();
    id = *parsed;
    absl::StatusOr<std::string> tenant = Tenant(*context);
    if (!tenant.ok()) return tenant.status();
    absl::StatusOr<v1::SceneInfo> info = OwnedScene(id, *tenant);
    if (!info.ok()) return info.status();
    files.assign(info->files().begin(), info->files().end());
    return absl::OkStatus();
  });
  Record("DownloadScene", status);
  if (!status.ok()) return new FailedWriteReactor<v1::FileChunk>(ToGrpcStatus(status));
  return new FileStreamReactor(dir_.Scene(id), std::move(files), 0);
}

grpc::ServerUnaryReactor* RadiosityServiceImpl::CreateJob(grpc::CallbackServerContext* context,
                                                          const v1::CreateJobRequest* request,
                                                          v1::Job* response) {
  absl::StatusOr<std::string> tenant = Tenant(*context);
  return FinishOnExecutor(
      this, context, "CreateJob", [this, request, response, tenant]() -> absl::Status {
        if (!tenant.ok()) return tenant.status();
        // The scene cannot be deleted while the job is checked and inserted (a DeleteScene after
        // that counts the job).
        std::optional<SceneRefs::Ref> scene;
        if (std::string id = IdFromName(request->scene(), "scenes"); !id.empty()) {
          scene.emplace(scene_refs_.Acquire(id));
        }
        ++metrics_->creates_in_progress;
        absl::Cleanup done = [this] { --metrics_->creates_in_progress; };
        absl::StatusOr<v1::Job> job = jobs_->Create(*request, *tenant);
        if (!job.ok()) return job.status();
        *response = *std::move(job);
        return absl::OkStatus();
      });
}

grpc::ServerUnaryReactor* RadiosityServiceImpl::GetJob(grpc::CallbackServerContext* context,
                                                       const v1::GetJobRequest* request,
                                                       v1::Job* response){
    RADIOSITY_UNARY("GetJob",
                    {
                      absl::StatusOr<std::string> id = RequireId(request->name(), "jobs");
                      if (!id.ok()) return id.status();
                      absl::StatusOr<std::string> tenant = Tenant(*context);
                      if (!tenant.ok()) return tenant.status();
                      absl::StatusOr<v1::Job> job = jobs_->GetOwned(*id, *tenant);
                      if (!job.ok()) return job.status();
                      *response = *std::move(job);
                      return absl::OkStatus();
                    })}

grpc::ServerUnaryReactor* RadiosityServiceImpl::ListJobs(grpc::CallbackServerContext* context,
                                                         const v1::ListJobsRequest* request,
                                                         v1::ListJobsResponse* response){
    RADIOSITY_UNARY("ListJobs",
                    {
                      if (request->page_size() < 0) {
                        return absl::InvalidArgumentError(
                            absl::StrCat("page_size: ", request->page_size(), " is negative"));
                      }
                      // proto3 enums are open: an undefined number arrives as is.
                      for (int i = 0; i < request->states_size(); ++i) {
                        if (!v1::JobState_IsValid(request->states(i))) {
                          return absl::InvalidArgumentError(
                              absl::StrCat("states[", i, "]: ", request->states(i),
                                           " is not a JobState value (0 to 5)"));
                        }
                      }
                      absl::StatusOr<std::string> tenant = Tenant(*context);
                      if (!tenant.ok()) return tenant.status();
                      absl::StatusOr<v1::ListJobsResponse> list = jobs_->List(*tenant, *request);
                      if (!list.ok()) return list.status();
                      *response = *std::move(list);
                      return absl::OkStatus();
                    })}

grpc::ServerUnaryReactor* RadiosityServiceImpl::CancelJob(grpc::CallbackServerContext* context,
                                                          const v1::CancelJobRequest* request,
                                                          v1::Job* response){
    RADIOSITY_UNARY("CancelJob",
                    {
                      absl::StatusOr<std::string> id = RequireId(request->name(), "jobs");
                      if (!id.ok()) return id.status();
                      absl::StatusOr<std::string> tenant = Tenant(*context);
                      if (!tenant.ok()) return tenant.status();
                      if (absl::StatusOr<v1::Job> owned = jobs_->GetOwned(*id, *tenant);
                          !owned.ok()) {
                        return owned.status();
                      }
                      absl::StatusOr<v1::Job> job = jobs_->Cancel(*id);
                      if (!job.ok()) return job.status();
                      *response = *std::move(job);
                      return absl::OkStatus();
                    })}

grpc::ServerUnaryReactor* RadiosityServiceImpl::DeleteJob(grpc::CallbackServerContext* context,
                                                          const v1::DeleteJobRequest* request,
                                                          v1::DeleteJobResponse* response) {
  absl::StatusOr<std::string> tenant = Tenant(*context);
  return FinishOnExecutor(this, context, "DeleteJob", [this, request, tenant]() -> absl::Status {
    if (!tenant.ok()) return tenant.status();
    absl::StatusOr<std::string> id = RequireId(request->name(), "jobs");
    if (!id.ok()) return id.status();
    if (absl::StatusOr<v1::Job> owned = jobs_->GetOwned(*id, *tenant); !owned.ok()) {
      return owned.status();
    }
    return jobs_->Delete(*id);
  });
}
#undef RADIOSITY_UNARY

grpc::ServerWriteReactor<v1::WatchJobResponse>* RadiosityServiceImpl::WatchJob(
    grpc::CallbackServerContext* context, const v1::WatchJobRequest* request) {
  std::shared_ptr<JobChannel> channel;
  std::shared_ptr<Snapshot> ended;
  bool read_results = false;
  int64_t mesh_version = 0;
  std::string id;
  absl::Status status = Guarded("WatchJob", [&]() -> absl::Status {
    absl::StatusOr<std::string> parsed = RequireId(request->name(), "jobs");
    if (!parsed.ok()) return parsed.status();
    id = *parsed;
    if (request->after_sequence() < 0) {
      return absl::InvalidArgumentError("after_sequence: negative");
    }
    absl::StatusOr<std::string> tenant = Tenant(*context);
    if (!tenant.ok()) return tenant.status();
    absl::StatusOr<v1::Job> job = jobs_->GetOwned(id, *tenant);
    if (!job.ok()) return job.status();
    channel = jobs_->Channel(id);
    if (channel) return absl::OkStatus();
    // Not active: the job has ended; its final snapshot comes from disk.
    job = jobs_->Get(id);
    if (!job.ok()) return job.status();
    if (!IsEnded(job->state())) {
      channel = jobs_->Channel(id);  // Created meanwhile (a restart's recovery).
      if (channel) return absl::OkStatus();
      return absl::UnavailableError("the job is not being tracked yet; retry");
    }
    ended = std::make_shared<Snapshot>();
    ended->sequence = job->last_sequence();
    ended->state = job->state();
    ended->progress = job->progress();
    ended->final = true;
    ended->error = job->error();
    ended->elements = job->mesh().elements();
    ended->attempts = job->attempts();
    mesh_version = job->mesh().mesh_version();
    read_results = !request->progress_only() && job->results_size() > 0 &&
                   job->last_sequence() > request->after_sequence();
    return absl::OkStatus();
  });
  if (status.ok()) status = limits_.AdmitWatcher(request->progress_only());
  Record("WatchJob", status);
  if (!status.ok()) return new FailedWriteReactor<v1::WatchJobResponse>(ToGrpcStatus(status));
  if (!channel && ended->sequence <= 0) {
    limits_.ReleaseWatcher(request->progress_only());
    return new FailedWriteReactor<v1::WatchJobResponse>(grpc::Status::OK);
  }
  if (!channel && ended->sequence <= request->after_sequence()) {
    // Resumed past the end of an ended job: its final state once more (progress only), so that
    // the client learns how it ended rather than reading an empty stream.
    v1::WatchJobRequest again = *request;
    again.set_after_sequence(ended->sequence - 1);
    again.set_progress_only(true);
    again.set_include_mesh(false);
    return new WatchReactor(metrics_, &limits_, request->progress_only(), again, nullptr,
                            std::move(ended));
  }
  if (channel || !read_results) {
    return new WatchReactor(metrics_, &limits_, request->progress_only(), *request,
                            std::move(channel), std::move(ended));
  }
  // The final radiosity (and mesh) can be hundreds of MB: read on the executor, which hands the
  // snapshot to the stream through a channel of its own (the channel's lock orders the hand-over
  // against the stream's end).
  auto loading = std::make_shared<JobChannel>();
  auto* reactor =
      new WatchReactor(metrics_, &limits_, request->progress_only(), *request, loading, nullptr);
  const bool include_mesh = request->include_mesh();
  const bool existing_sides = request->existing_sides_only();
  executor_.Run([this, loading, ended, id, mesh_version, include_mesh, existing_sides] {
    absl::Status read = Guarded("WatchJob", [&]() -> absl::Status {
      ReadEndedResults(dir_, id, mesh_version, include_mesh, existing_sides, ended.get());
      return absl::OkStatus();
    });
    if (read.ok()) {
      loading->Publish(ended);
    } else {
      loading->Close(read);
    }
  });
  return reactor;
}

grpc::ServerWriteReactor<v1::FileChunk>* RadiosityServiceImpl::DownloadResult(
    grpc::CallbackServerContext* context, const v1::DownloadResultRequest* request) {
  std::vector<v1::FileInfo> files;
  std::string id;
  absl::Status status = Guarded("DownloadResult", [&]() -> absl::Status {
    absl::StatusOr<std::string> parsed = RequireId(request->name(), "jobs");
    if (!parsed.ok()) return parsed.status();
    id = *parsed;
    absl::StatusOr<std::string> tenant = Tenant(*context);
    if (!tenant.ok()) return tenant.status();
    absl::StatusOr<v1::Job> job = jobs_->GetOwned(id, *tenant);
    if (!job.ok()) return job.status();
    if (!IsEnded(job->state())) {
      return absl::FailedPreconditionError(absl::StrCat(
          job->name(), " is ", StateName(job->state()), "; results exist once it has ended"));
    }
    if (job->results().empty()) {
      return absl::FailedPreconditionError(
          absl::StrCat(job->name(), " ended ", StateName(job->state()), " without results"));
    }
    if (request->file().empty()) {
      if (request->offset() != 0) {
        return absl::InvalidArgumentError("offset: only with a single file");
      }
      files.assign(job->results().begin(), job->results().end());
      return absl::OkStatus();
    }
    for (const v1::FileInfo& f : job->results()) {
      if (f.name() == request->file()) files.push_back(f);
    }
    if (files.empty()) {
      return absl::NotFoundError(
          absl::StrCat(job->name(), " has no result file '", request->file(), "'"));
    }
    if (request->offset() < 0 || request->offset() > files[0].size()) {
      return absl::OutOfRangeError(
          absl::StrCat("offset ", request->offset(), " is outside [0, ", files[0].size(), "]"));
    }
    return absl::OkStatus();
  });
  Record("DownloadResult", status);
  if (!status.ok()) return new FailedWriteReactor<v1::FileChunk>(ToGrpcStatus(status));
  return new FileStreamReactor(dir_.Results(id), std::move(files), request->offset());
}

}  // namespace radiosity::service
