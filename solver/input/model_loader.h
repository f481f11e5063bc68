// Models in the formats other tools export (glTF 2.0, FBX, Collada, 3DS, PLY, STL), read through
// assimp (docs/guide/scenes.md, "Models through assimp").
//
// The node hierarchy is walked with each node's transform applied (a mirroring transform reverses
// the winding so fronts stay outside); every mesh of a node becomes a surface named after the node
// (and the mesh, when it has a name of its own). Polygons are triangulated; points and lines are
// dropped with a warning. Coordinates are in metres where the format says what its unit is (glTF;
// FBX and Collada scale by their unit declarations), else in the file's own units.
//
// Materials, per channel, with every reflectance clamped to kMaxReflectance:
//  - base colour (glTF's baseColorFactor, else the diffuse colour) is the diffuse reflectance; a
//    base-colour (or diffuse) texture multiplies it, averaged over each face (sRGB texels made
//    linear). Faces are then grouped into a surface per distinct colour, rounded to
//    kTextureColorStep ("node/mesh#k", material "name#k");
//  - emissive colour x emissive strength (KHR_materials_emissive_strength) is the radiant exitance
//    in W/m^2 (as MTL's Ke);
//  - metallic-roughness (docs/guide/specular.md): the dielectric part (1 -
//    metallic) reflects the base colour diffusely, and transmission (KHR_materials_transmission)
//    t of it meets thin glass of index KHR_materials_ior (1.5 by default); the metallic part
//    reflects the base colour into a glossy lobe of Phong exponent 2 / roughness^4 - 2 (a mirror
//    above kMirrorExponent, diffusely below 1). glTF's defaults are metallic 1, roughness 1: a
//    rough metal, diffuse here;
//  - opacity d < 1 (alpha, other formats): reflects d x the above and transmits 1 - d diffusely;
//  - double-sided (glTF doubleSided, assimp's two-sided flag) is two-sided.
#ifndef RADIOSITY_SOLVER_INPUT_MODEL_LOADER_H_
#define RADIOSITY_SOLVER_INPUT_MODEL_LOADER_H_

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/scene.h"
#include "solver/util/stop.h"

namespace radiosity {

struct ModelOptions {
  // Open only files inside the model's directory (safe relative names): a model can never make
  // its reader (the service) open other files.
  bool confine_to_directory = false;
  // Use the first vertex-colour set, where a mesh has one, as the diffuse reflectance (averaged
  // over each face, taken as linear) instead of the material's base colour.
  bool vertex_colors = false;
  // Checked between the import's steps and while the nodes are walked: a stop ends the read with
  // CANCELLED. May be null.
  const StopToken* stop = nullptr;
  // Non-empty: the model is read by this program (radiosity-import, ModelImportMain) in a child
  // process with the limits below, so that an importer that crashes, hangs or exhausts memory on
  // a hostile file costs an error naming the file, not the caller's process. The service reads
  // every model this way (ModelImporter()).
  std::string importer;
  int64_t import_memory_mb = 4096;  // Address-space limit of the child.
  double import_seconds = 60;       // Wall-clock limit; the child is killed after it.
};

// The importer program beside the running executable (radiosity-import in its directory), or
// $RADIOSITY_IMPORT when set; empty when neither exists.
std::string ModelImporter();

// The importer's main: `radiosity-import MODEL OUT [--confine] [--vertex-colors]
// [--memory-mb N]`. Reads MODEL with LoadModel and writes the scene (binary radiosity.v1.Scene) to
// OUT and its warnings, one a line, to OUT.warnings; on an error writes the status code and
// message to OUT.error and returns 1; 2 for bad arguments.
int ModelImportMain(int argc, char** argv);

// Colours from textures and vertex colours are rounded to multiples of this before faces are
// grouped by colour (a coarser step is used, with a warning, if a mesh would get more than
// kMaxColorGroups groups).
inline constexpr double kTextureColorStep = 1.0 / 64;
inline constexpr int kMaxColorGroups = 1024;

// `color` in units of `step`, rounded: the key faces are grouped by.
std::array<int64_t, 3> ColorKey(const Rgb& color, double step);
// The step colours are grouped by: kTextureColorStep, doubled until `colors` give at most
// kMaxColorGroups keys (the OBJ and model loaders warn when it is coarser).
double ColorGroupingStep(const std::vector<Rgb>& colors);

// Whether `extension` (lower case, with the dot) is a format read by LoadModel.
bool IsModelExtension(const std::string& extension);
// The extensions LoadModel reads, for messages: ".gltf, .glb, ...".
std::string ModelExtensions();

// Reads the model at `path` (and the files it names: a .gltf's buffers and images, textures).
// Validates the result (ValidateScene) and drops zero-area faces with a warning. Errors and
// warnings name the file.
absl::StatusOr<Scene> LoadModel(const std::string& path, std::vector<std::string>* warnings,
                                const ModelOptions& options = {});

// The files a model reads besides itself, as relative names that exist inside its directory:
// for .gltf, the buffers and images its JSON names by relative URI (not data: URIs).
absl::StatusOr<std::vector<std::string>> ModelDependencies(const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_INPUT_MODEL_LOADER_H_
