// Conversion between the native scene message (radiosity.v1.Scene, proto/radiosity/v1/scene.proto)
// and the solver's scene model, and reading/writing scene files in every supported format.
#ifndef RADIOSITY_PROTO_SCENE_CODEC_H_
#define RADIOSITY_PROTO_SCENE_CODEC_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "radiosity/v1/scene.pb.h"
#include "solver/scene.h"

namespace radiosity {

// Converts a Scene message to the solver's model. Each surface's vertices are appended to the
// global vertex array and its face indices offset accordingly. Checks the message first, with
// errors naming `source` and the field path, e.g.
//   "scene.json: surfaces[2] ('floor').faces[5].indices[3]: vertex index 7 is out of range
//    (surface has 4 vertices)",
// then runs ValidateScene and DropDegenerateFaces (zero-area faces are dropped with a warning
// appended to `warnings`, which may be null). `source` becomes Scene::source.
absl::StatusOr<Scene> SceneFromProto(const radiosity::v1::Scene& msg, const std::string& source,
                                     std::vector<std::string>* warnings = nullptr);

// Converts the solver's model to a Scene message. Every surface gets its own vertex list: the
// vertices its faces use, in the order of their global indices (vertices shared between surfaces
// are duplicated; vertices no face uses are left out). Materials are referenced by name, so
// material and surface names must be unique and non-empty for the result to load back.
radiosity::v1::Scene SceneToProto(const Scene& scene);

// Loads a scene file, choosing the format by extension (case-insensitive):
//   .obj          Wavefront OBJ + MTL (LoadObj),
//   .json         protobuf JSON mapping of radiosity.v1.Scene,
//   .pb / .binpb  binary radiosity.v1.Scene.
// The result is validated and zero-area faces are dropped with a warning appended to `warnings`
// (may be null). Errors name the file.
absl::StatusOr<Scene> LoadSceneFile(const std::string& path, std::vector<std::string>* warnings);

// Writes `scene` (through SceneToProto) as .json (indented, snake_case field names) or .pb/.binpb
// (binary), by the extension of `path`.
absl::Status SaveSceneFile(const Scene& scene, const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_PROTO_SCENE_CODEC_H_
