#include "server/store_copy.h"

#include <unistd.h>

#include <filesystem>

#include "absl/strings/str_cat.h"
#include "proto/api/names.h"
#include "server/data_dir.h"
#include "server/logging.h"
#include "server/store.h"

namespace radiosity::service {
namespace {

namespace fs = std::filesystem;

// Copies the directory `from` to `to` (absent) under a temporary name, then renames it; leaves
// out the subdirectory `skip` (when not empty). Adds the bytes copied to `bytes`.
absl::Status CopyTree(const std::string& from, const std::string& to, const std::string& skip,
                      int64_t* bytes) {
  const std::string tmp = absl::StrCat(to, ".tmp-", getpid());
  std::error_code ec;
  fs::remove_all(tmp, ec);
  fs::create_directories(tmp, ec);
  if (ec) return absl::InternalError(absl::StrCat(tmp, ": cannot create: ", ec.message()));
  for (const fs::directory_entry& entry : fs::directory_iterator(from, ec)) {
    const std::string name = entry.path().filename().string();
    if (name == skip) continue;
    fs::copy(entry.path(), tmp + "/" + name, fs::copy_options::recursive, ec);
    if (ec) break;
  }
  if (!ec) {
    for (const fs::directory_entry& entry : fs::recursive_directory_iterator(tmp, ec)) {
      if (entry.is_regular_file()) *bytes += static_cast<int64_t>(entry.file_size());
    }
  }
  if (!ec) fs::rename(tmp, to, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove_all(tmp, ignored);
    return absl::InternalError(absl::StrCat(to, ": cannot copy from ", from, ": ", ec.message()));
  }
  return absl::OkStatus();
}

// Copies `from` to `to` unless `to` exists (a row not yet inserted after its files were).
absl::Status CopyFiles(const std::string& from, const std::string& to, const std::string& skip,
                       int64_t* bytes) {
  std::error_code ec;
  if (fs::exists(to, ec)) fs::remove_all(to, ec);  // An earlier run's files, row not in: again.
  if (ec) return absl::InternalError(absl::StrCat(to, ": cannot replace: ", ec.message()));
  return CopyTree(from, to, skip, bytes);
}

}  // namespace

std::string CopyReport::ToString() const {
  return absl::StrCat(scenes, " scenes and ", jobs, " jobs copied (", bytes, " bytes of files); ",
                      scenes_present, " scenes and ", jobs_present, " jobs were there already");
}

absl::Status CopyDataDir(const std::string& from_dir, const std::string& to_store,
                         const std::string& blob_dir, const std::atomic<bool>* stop,
                         CopyReport* report) {
  *report = CopyReport();
  const DataDir from(from_dir);
  std::error_code ec;
  if (!fs::exists(from_dir + "/radiosity.db", ec)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--copy-from ", from_dir, ": no radiosity.db there (not a data directory)"));
  }
  absl::StatusOr<int> lock = from.Lock();
  if (!lock.ok()) return lock.status();
  struct Unlock {
    int fd;
    ~Unlock() { close(fd); }
  } unlock{*lock};
  absl::StatusOr<std::unique_ptr<Store>> source = OpenStore("sqlite:" + from_dir, from_dir);
  if (!source.ok()) return source.status();
  absl::StatusOr<std::unique_ptr<Store>> target = OpenStore(to_store, "");
  if (!target.ok()) return target.status();
  if (!(*target)->ServesReplicas()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--copy-from copies into a store replicas share (PostgreSQL); --store names ",
                     (*target)->ToString()));
  }
  const DataDir blobs(blob_dir);  // Scene(id), Job(id) under blob_dir.
  if (absl::Status st = blobs.Create(); !st.ok()) return st;
  auto stopped = [&] { return stop && stop->load(); };

  absl::StatusOr<std::vector<v1::SceneInfo>> scenes = (*source)->AllScenes();
  if (!scenes.ok()) return scenes.status();
  for (const v1::SceneInfo& scene : *scenes) {
    if (stopped()) return absl::CancelledError("stopped; run the copy again to finish it");
    const std::string id = IdFromName(scene.name(), "scenes");
    absl::StatusOr<v1::SceneInfo> present = (*target)->GetScene(id);
    if (present.ok()) {
      ++report->scenes_present;
      continue;
    }
    if (!absl::IsNotFound(present.status())) return present.status();
    if (!fs::is_directory(from.Scene(id), ec)) {
      return absl::DataLossError(
          absl::StrCat(scene.name(), ": its files are missing from ", from.Scene(id)));
    }
    if (absl::Status st = CopyFiles(from.Scene(id), blobs.Scene(id), "", &report->bytes);
        !st.ok()) {
      return st;
    }
    if (absl::Status st = VerifyStoredScene(blobs.Scene(id), scene); !st.ok()) return st;
    absl::StatusOr<std::optional<v1::SceneInfo>> other = (*target)->InsertScene(id, scene);
    if (!other.ok()) return other.status();
    if (other->has_value()) {
      return absl::AlreadyExistsError(
          absl::StrCat(scene.name(), ": the target store has another scene, ", (*other)->name(),
                       ", for its tenant's request id '", scene.request_id(), "'; not copied"));
    }
    ++report->scenes;
  }

  absl::StatusOr<std::vector<v1::Job>> jobs =
      (*source)->JobsInStates({v1::JOB_STATE_QUEUED, v1::JOB_STATE_RUNNING, v1::JOB_STATE_SUCCEEDED,
                               v1::JOB_STATE_FAILED, v1::JOB_STATE_CANCELLED});
  if (!jobs.ok()) return jobs.status();
  for (const v1::Job& job : *jobs) {
    if (stopped()) return absl::CancelledError("stopped; run the copy again to finish it");
    const std::string id = IdFromName(job.name(), "jobs");
    absl::StatusOr<v1::Job> present = (*target)->GetJob(id);
    if (present.ok()) {
      ++report->jobs_present;
      continue;
    }
    if (!absl::IsNotFound(present.status())) return present.status();
    if (fs::is_directory(from.Job(id), ec)) {
      // Results and checkpoint; not the work directory of a run that never finished.
      if (absl::Status st = CopyFiles(from.Job(id), blobs.Job(id), "work", &report->bytes);
          !st.ok()) {
        return st;
      }
    }
    absl::StatusOr<std::optional<v1::Job>> other = (*target)->InsertJob(id, job);
    if (!other.ok()) return other.status();
    if (other->has_value()) {
      return absl::AlreadyExistsError(
          absl::StrCat(job.name(), ": the target store has another job, ", (*other)->name(),
                       ", for its tenant's request id '", job.request_id(), "'; not copied"));
    }
    ++report->jobs;
  }
  LogLine("data_dir_copied")
      .Str("from", from_dir)
      .Str("store", (*target)->ToString())
      .Str("blob_dir", blob_dir)
      .Int("scenes", report->scenes)
      .Int("jobs", report->jobs)
      .Int("bytes", report->bytes)
      .Int("scenes_present", report->scenes_present)
      .Int("jobs_present", report->jobs_present)
      .Info();
  return absl::OkStatus();
}

}  // namespace radiosity::service
