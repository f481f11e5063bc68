#include "proto/api/scene_format.h"

#include "absl/strings/str_cat.h"
#include "solver/util/file_io.h"

namespace radiosity::service {

absl::StatusOr<v1::SceneFormat> ResolveFormat(v1::SceneFormat format,
                                              const std::string& main_file) {
  absl::StatusOr<SceneFormat> by_extension = SceneFormatOf(main_file);
  if (!by_extension.ok()) return by_extension.status();
  v1::SceneFormat wire = v1::SCENE_FORMAT_UNSPECIFIED;
  switch (*by_extension) {
    case SceneFormat::kObj:
      wire = v1::SCENE_FORMAT_OBJ;
      break;
    case SceneFormat::kJson:
      wire = v1::SCENE_FORMAT_JSON;
      break;
    case SceneFormat::kBinary:
      wire = v1::SCENE_FORMAT_BINARY;
      break;
    case SceneFormat::kModel:
      wire = v1::SCENE_FORMAT_MODEL;
      break;
  }
  if (format != v1::SCENE_FORMAT_UNSPECIFIED && format != wire) {
    return absl::InvalidArgumentError(
        absl::StrCat(main_file, ": the format ", v1::SceneFormat_Name(format),
                     " does not match the extension '", Extension(main_file), "'"));
  }
  return wire;
}

}  // namespace radiosity::service
