#include "server/data_dir.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <map>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "proto/api/sha256.h"
#include "solver/input/model_loader.h"
#include "solver/input/photometry_file.h"
#include "solver/input/scene_files.h"
#include "solver/util/file_io.h"

namespace radiosity::service {

absl::Status DataDir::Create() const {
  std::error_code ec;
  for (const std::string& dir :
       {root_, blob_root_, blob_root_ + "/scenes", blob_root_ + "/jobs", Uploads()}) {
    std::filesystem::create_directories(dir, ec);
    if (ec) return absl::InternalError(absl::StrCat(dir, ": cannot create: ", ec.message()));
  }
  return absl::OkStatus();
}

absl::Status DataDir::Redact(const absl::Status& status) const {
  if (status.ok() || root_.empty()) return status;
  if (shared()) return DataDir(blob_root_).Redact(DataDir(root_).Redact(status));
  std::string message(status.message());
  const std::string prefix = root_.back() == '/' ? root_ : root_ + "/";
  bool changed = false;
  for (size_t at = message.find(prefix); at != std::string::npos; at = message.find(prefix, at)) {
    size_t end = at;
    while (end < message.size() && message[end] != ':' && message[end] != ' ' &&
           message[end] != '\'' && message[end] != ')' && message[end] != ',') {
      ++end;
    }
    const size_t slash = message.rfind('/', end - 1);
    message.erase(at, slash + 1 - at);
    changed = true;
    ++at;
  }
  return changed ? absl::Status(status.code(), message) : status;
}

absl::StatusOr<int> DataDir::Lock() const {
  const std::string path = root_ + "/lock";
  int fd = open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) {
    return absl::InternalError(absl::StrCat(path, ": cannot open: ", std::strerror(errno)));
  }
  if (flock(fd, LOCK_EX | LOCK_NB) != 0) {
    close(fd);
    return absl::FailedPreconditionError(
        absl::StrCat(root_, " is in use by another radiosity server (", path, " is locked)"));
  }
  return fd;
}

absl::Status MoveDirectory(const std::string& from, const std::string& to) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::rename(from, to, ec);
  if (!ec) return absl::OkStatus();
  if (ec != std::errc::cross_device_link) {
    return absl::InternalError(absl::StrCat(to, ": ", ec.message()));
  }
  const std::string copy = absl::StrCat(to, ".tmp-", getpid());
  fs::remove_all(copy, ec);
  fs::copy(from, copy, fs::copy_options::recursive, ec);
  if (!ec) fs::rename(copy, to, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove_all(copy, ignored);
    return absl::InternalError(absl::StrCat(to, ": ", ec.message()));
  }
  fs::remove_all(from, ec);
  return absl::OkStatus();
}

absl::Status VerifyStoredScene(const std::string& dir, const v1::SceneInfo& info) {
  for (const v1::FileInfo& f : info.files()) {
    absl::StatusOr<std::pair<std::string, int64_t>> sum = Sha256File(dir + "/" + f.name());
    if (!sum.ok()) {
      return absl::DataLossError(
          absl::StrCat(info.name(), ": '", f.name(), "' cannot be read: ", sum.status().message()));
    }
    if (sum->second != f.size() || (!f.sha256().empty() && sum->first != f.sha256())) {
      return absl::DataLossError(
          absl::StrCat(info.name(), ": '", f.name(), "' is not the file uploaded (", sum->second,
                       " bytes, sha256 ", sum->first, "; uploaded: ", f.size(), " bytes, sha256 ",
                       f.sha256(), ")"));
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<Scene> LoadStoredScene(const std::string& dir, const v1::SceneInfo& info,
                                      std::vector<std::string>* warnings, const StopToken* stop) {
  if (info.files().empty()) return absl::InvalidArgumentError("the scene has no files");
  const std::string& main = info.files(0).name();
  const std::string display = info.display_name().empty() ? main : info.display_name();
  // The client's directory of the main file: what replaces `dir` in messages.
  std::string prefix;
  if (display.size() > main.size() && absl::EndsWith(display, "/" + main)) {
    prefix = display.substr(0, display.size() - main.size());
  }
  auto rewrite = [&](absl::string_view text) {
    return absl::StrReplaceAll(text, {{dir + "/", prefix}});
  };
  const std::string path = dir + "/" + main;
  std::vector<std::string> local;
  SceneLoadOptions options;
  options.confine_to_directory = true;
  options.strict = info.strict();
  options.vertex_colors = info.vertex_colors();
  // Models are read in a child process (radiosity-import beside this executable), where there is
  // one: an importer crash or hang on a hostile upload then costs an error, not the service.
  options.model_importer = ModelImporter();
  options.stop = stop;
  absl::StatusOr<Scene> scene = LoadSceneFile(path, &local, options);
  for (const std::string& w : local) {
    if (warnings) warnings->push_back(rewrite(w));
  }
  if (!scene.ok()) {
    return absl::Status(scene.status().code(), rewrite(scene.status().message()));
  }
  scene->source = display;
  return scene;
}

absl::Status LoadStoredLuminaires(const std::string& dir, const v1::SceneInfo& info,
                                  SolveOptions* solve) {
  if (solve->luminaires.empty()) return absl::OkStatus();
  const std::string main = info.files().empty() ? "" : info.files(0).name();
  const std::string& display = info.display_name();
  std::string shown;
  if (display.size() > main.size() && absl::EndsWith(display, "/" + main)) {
    shown = display.substr(0, display.size() - main.size() - 1);
  }
  // Each file read once, its distribution shared by every luminaire that names it.
  std::map<std::string, std::shared_ptr<const Photometry>> read;
  for (size_t i = 0; i < solve->luminaires.size(); ++i) {
    Luminaire& l = solve->luminaires[i];
    std::shared_ptr<const Photometry>& shared = read[l.file];
    if (!shared) {
      absl::StatusOr<Photometry> p = LoadScenePhotometry(dir, l.file, shown);
      if (!p.ok()) {
        return absl::Status(p.status().code(), absl::StrCat("solve.luminaires[", i, "] (", l.file,
                                                            "): ", p.status().message()));
      }
      shared = std::make_shared<const Photometry>(*std::move(p));
    }
    l.photometry = shared;
  }
  return absl::OkStatus();
}

}  // namespace radiosity::service
