#include "solver/input/scene_files.h"

#include "absl/strings/str_cat.h"
#include "solver/input/model_loader.h"
#include "solver/input/obj_loader.h"
#include "solver/input/scene_codec.h"
#include "solver/util/file_io.h"

namespace radiosity {

absl::StatusOr<SceneFormat> SceneFormatOf(const std::string& path) {
  const std::string ext = Extension(path);
  if (ext == ".obj") return SceneFormat::kObj;
  if (ext == ".json") return SceneFormat::kJson;
  if (ext == ".pb" || ext == ".binpb") return SceneFormat::kBinary;
  if (IsModelExtension(ext)) return SceneFormat::kModel;
  return absl::InvalidArgumentError(
      absl::StrCat(path, ": unknown scene format '", ext,
                   "' (expected .obj, .json, .pb or a model: ", ModelExtensions(), ")"));
}

absl::StatusOr<Scene> LoadSceneFile(const std::string& path, std::vector<std::string>* warnings,
                                    const SceneLoadOptions& options) {
  absl::StatusOr<SceneFormat> format = SceneFormatOf(path);
  if (!format.ok()) return format.status();
  if (*format == SceneFormat::kObj) {
    ObjOptions obj;
    obj.confine_to_directory = options.confine_to_directory;
    obj.strict = options.strict;
    obj.vertex_colors = options.vertex_colors;
    obj.stop = options.stop;
    return LoadObj(path, warnings, obj);
  }
  if (*format == SceneFormat::kModel) {
    ModelOptions model;
    model.confine_to_directory = options.confine_to_directory;
    model.vertex_colors = options.vertex_colors;
    model.stop = options.stop;
    model.importer = options.model_importer;
    return LoadModel(path, warnings, model);
  }
  absl::StatusOr<std::string> bytes = ReadWholeFile(path);
  if (!bytes.ok()) return bytes.status();
  return ParseNativeScene(*bytes, *format == SceneFormat::kJson, path, warnings);
}

absl::StatusOr<std::vector<std::string>> SceneDependencies(const std::string& path) {
  absl::StatusOr<SceneFormat> format = SceneFormatOf(path);
  if (!format.ok()) return format.status();
  if (*format == SceneFormat::kModel) return ModelDependencies(path);
  std::vector<std::string> files;
  if (*format != SceneFormat::kObj) return files;
  absl::StatusOr<std::string> text = ReadWholeFile(path);
  if (!text.ok()) return text.status();
  const std::string dir = DirName(path);
  for (std::string& name : ScanMaterialLibraries(*text, dir)) {
    // Missing or unsafe libraries are left for the loader to report (with the line naming them).
    if (!IsSafeRelativeName(name) || !FileExists(JoinPath(dir, name))) continue;
    bool seen = false;
    for (const std::string& f : files) seen |= f == name;
    if (!seen) files.push_back(std::move(name));
  }
  return files;
}

absl::Status SaveSceneFile(const Scene& scene, const std::string& path) {
  absl::StatusOr<SceneFormat> format = SceneFormatOf(path);
  if (!format.ok() || *format == SceneFormat::kObj || *format == SceneFormat::kModel) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": unknown scene format '",
                                                   Extension(path),
                                                   "' for writing (expected .json or .pb)"));
  }
  absl::StatusOr<std::string> bytes = EncodeNativeScene(scene, *format == SceneFormat::kJson, path);
  if (!bytes.ok()) return bytes.status();
  return WriteWholeFile(path, *bytes);
}

}  // namespace radiosity
