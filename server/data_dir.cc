#include "server/data_dir.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "proto/scene_codec.h"
#include "server/util.h"

namespace radiosity::service {
namespace {

std::string Extension(const std::string& name) {
  size_t slash = name.rfind('/');
  size_t dot = name.rfind('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  return absl::AsciiStrToLower(name.substr(dot));
}

// Checks the mtllib lines of an OBJ text: each name (the whole rest of the line, or each blank-
// separated token, as the loader reads them) must be a safe relative name.
absl::Status CheckMaterialLibraries(const std::string& text, const std::string& display) {
  int line_number = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_number;
    absl::string_view rest = absl::StripLeadingAsciiWhitespace(line);
    if (!absl::ConsumePrefix(&rest, "mtllib")) continue;
    if (!rest.empty() && !absl::ascii_isspace(static_cast<unsigned char>(rest[0]))) continue;
    rest = absl::StripAsciiWhitespace(rest);
    if (size_t hash = rest.find('#'); hash != absl::string_view::npos) {
      rest = absl::StripAsciiWhitespace(rest.substr(0, hash));
    }
    std::vector<absl::string_view> names = absl::StrSplit(rest, ' ', absl::SkipWhitespace());
    names.push_back(rest);
    for (absl::string_view name : names) {
      if (name.empty()) continue;
      if (!IsSafeRelativeName(name)) {
        return absl::InvalidArgumentError(absl::StrCat(
            display, ":", line_number, ": mtllib '", name,
            "': the service only reads material libraries uploaded with the scene (a relative "
            "path inside the OBJ's directory, without '..')"));
      }
    }
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status DataDir::Create() const {
  std::error_code ec;
  for (const std::string& dir : {root_, root_ + "/scenes", root_ + "/jobs", Uploads()}) {
    std::filesystem::create_directories(dir, ec);
    if (ec) return absl::InternalError(absl::StrCat(dir, ": cannot create: ", ec.message()));
  }
  return absl::OkStatus();
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

absl::StatusOr<v1::SceneFormat> ResolveFormat(v1::SceneFormat format,
                                              const std::string& main_file) {
  const std::string ext = Extension(main_file);
  v1::SceneFormat by_extension = v1::SCENE_FORMAT_UNSPECIFIED;
  if (ext == ".obj") by_extension = v1::SCENE_FORMAT_OBJ;
  if (ext == ".json") by_extension = v1::SCENE_FORMAT_JSON;
  if (ext == ".pb" || ext == ".binpb") by_extension = v1::SCENE_FORMAT_BINARY;
  if (by_extension == v1::SCENE_FORMAT_UNSPECIFIED) {
    return absl::InvalidArgumentError(absl::StrCat(main_file, ": unknown scene format '", ext,
                                                   "' (expected .obj, .json or .pb)"));
  }
  if (format != v1::SCENE_FORMAT_UNSPECIFIED && format != by_extension) {
    return absl::InvalidArgumentError(absl::StrCat(main_file, ": the format ",
                                                   v1::SceneFormat_Name(format),
                                                   " does not match the extension '", ext, "'"));
  }
  return by_extension;
}

absl::StatusOr<Scene> LoadStoredScene(const std::string& dir, const v1::SceneInfo& info,
                                      std::vector<std::string>* warnings) {
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
  if (info.format() == v1::SCENE_FORMAT_OBJ) {
    absl::StatusOr<std::string> text = ReadWholeFile(path);
    if (!text.ok()) return absl::InternalError(rewrite(text.status().message()));
    if (absl::Status st = CheckMaterialLibraries(*text, display); !st.ok()) return st;
  }
  std::vector<std::string> local;
  absl::StatusOr<Scene> scene = LoadSceneFile(path, &local);
  for (const std::string& w : local) {
    if (warnings) warnings->push_back(rewrite(w));
  }
  if (!scene.ok()) {
    return absl::Status(scene.status().code(), rewrite(scene.status().message()));
  }
  scene->source = display;
  return scene;
}

}  // namespace radiosity::service
