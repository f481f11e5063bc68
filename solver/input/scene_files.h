// Scene files in every supported format, chosen by extension: the one place that dispatches on
// the format (the CLI, the service and the bench all load through here). Add a format here.
#ifndef RADIOSITY_SOLVER_INPUT_SCENE_FILES_H_
#define RADIOSITY_SOLVER_INPUT_SCENE_FILES_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/geometry/scene.h"
#include "solver/util/stop.h"

namespace radiosity {

enum class SceneFormat {
  kObj,     // .obj: Wavefront OBJ + MTL (obj_loader.h).
  kJson,    // .json: protobuf JSON mapping of radiosity.v1.Scene (scene_codec.h).
  kBinary,  // .pb / .binpb: binary radiosity.v1.Scene.
  kModel,   // .gltf .glb .fbx .dae .3ds .ply .stl: through assimp (model_loader.h).
};

// The format of a file by its extension (case-insensitive). INVALID_ARGUMENT naming the path and
// the extension otherwise.
absl::StatusOr<SceneFormat> SceneFormatOf(const std::string& path);

struct SceneLoadOptions {
  // OBJ and models: read only files inside the scene's directory (ObjOptions, ModelOptions).
  bool confine_to_directory = false;
  // OBJ: ObjOptions::strict.
  bool strict = false;
  // OBJ and models: ObjOptions::vertex_colors, ModelOptions::vertex_colors.
  bool vertex_colors = false;
  // OBJ and models: ObjOptions::stop, ModelOptions::stop. May be null.
  const StopToken* stop = nullptr;
  // Models: ModelOptions::importer (empty: read in this process).
  std::string model_importer;
};

// Loads a scene file in the format of its extension. The result is validated and zero-area faces
// are dropped with a warning appended to `warnings` (may be null). Errors name the file.
absl::StatusOr<Scene> LoadSceneFile(const std::string& path, std::vector<std::string>* warnings,
                                    const SceneLoadOptions& options = {});

// The files a scene reads besides `path` itself: for OBJ, the material libraries it names
// (relative to its directory, as the loader resolves them) that exist and are safe relative names;
// for .gltf, its buffers and images (ModelDependencies).
absl::StatusOr<std::vector<std::string>> SceneDependencies(const std::string& path);

// Writes `scene` as .json (indented, snake_case field names) or .pb/.binpb (binary), by the
// extension of `path`.
absl::Status SaveSceneFile(const Scene& scene, const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_INPUT_SCENE_FILES_H_
