#include "proto/api/scene_format.h"

#include "absl/strings/str_cat.h"
#include "solver/util/file_io.h"

namespace radiosity::service {

absl::StatusOr<v1::SceneFormat> ResolveFormat(v1::SceneFormat format,
                                              const std::string& main_file) {
  absl::StatusOr<SceneFormat> by_extension = SceneFormatOf(main_file);
  if (!by_extension.ok()) return by_extension.status();
  const v1::SceneFormat wire = *by_extension == SceneFormat::kObj    ? v1::SCENE_FORMAT_OBJ
                               : *by_extension == SceneFormat::kJson ? v1::SCENE_FORMAT_JSON
                                                                     : v1::SCENE_FORMAT_BINARY;
  if (format != v1::SCENE_FORMAT_UNSPECIFIED && format != wire) {
    return absl::InvalidArgumentError(
        absl::StrCat(main_file, ": the format ", v1::SceneFormat_Name(format),
                     " does not match the extension '", Extension(main_file), "'"));
  }
  return wire;
}

}  // namespace radiosity::service
