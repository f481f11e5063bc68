// The wire's scene formats (radiosity.v1.SceneFormat) against the files' extensions.
#ifndef RADIOSITY_PROTO_API_SCENE_FORMAT_H_
#define RADIOSITY_PROTO_API_SCENE_FORMAT_H_

#include <string>

#include "absl/status/statusor.h"
#include "radiosity/v1/service.pb.h"
#include "solver/input/scene_files.h"

namespace radiosity::service {

// The format a scene's files are read as: `format`, or from the main file's extension
// (SceneFormatOf). INVALID_ARGUMENT when they disagree or the extension is unknown.
absl::StatusOr<v1::SceneFormat> ResolveFormat(v1::SceneFormat format, const std::string& main_file);

}  // namespace radiosity::service

#endif  // RADIOSITY_PROTO_API_SCENE_FORMAT_H_
