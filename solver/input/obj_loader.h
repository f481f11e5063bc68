// Wavefront OBJ + MTL reader (docs/guide/scenes.md).
//
// Each `o` or `g` group is a named surface; a surface whose faces use several materials is split
// into one surface per material, named "group/material". MTL: `Kd` diffuse reflectance, `Ke`
// emitted radiant exitance (W/m^2 per channel), `d`/`Tr`/`Tf` diffuse transmission (below), and the
// extension `two_sided 1` (or `two_sided on`). Polygons keep all their vertices. Every error names
// the file and line.
//
// As exporters write it: transmission is `d` (dissolve, 1 = opaque) or `Tr` (1 - d), filtered by
// `Tf` (a colour, default white), so a material reflects d x Kd and transmits (1 - d) x Tf
// diffusely; `Ks`, `Ns` and `illum` are kept (Material::specular). Faces without a usable
// material get kDefaultMaterialName with one warning per cause naming the lines (ObjOptions::strict
// refuses them instead). Files in UTF-16 (with a byte-order mark) are read as such.
#ifndef RADIOSITY_SOLVER_INPUT_OBJ_LOADER_H_
#define RADIOSITY_SOLVER_INPUT_OBJ_LOADER_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "absl/strings/string_view.h"
#include "solver/geometry/scene.h"
#include "solver/util/stop.h"

namespace radiosity {

struct ObjOptions {
  // Material libraries must be safe relative names (IsSafeRelativeName): no absolute path and no
  // '..', so a scene can never make its reader (the service) open other files.
  bool confine_to_directory = false;
  // Refuse what exporters commonly write and the loader otherwise mends with a warning: faces
  // without a material, an unknown material or a missing material library (else the default
  // material, kDefaultMaterialName), and Kd at or above 1 (else clamped to kMaxReflectance).
  bool strict = false;
  // Take the vertex colours of `v x y z r g b` (an extension MeshLab, ZBrush and scanners write),
  // averaged over each face whose vertices all have one, in Kd's place (as given, in [0, 1];
  // times d where the material transmits): the faces of a surface are grouped by colour rounded to
  // kTextureColorStep into surfaces "SURFACE#k" with materials "MATERIAL@SURFACE#k" (the
  // material's other properties kept), as models' vertex colours are (model_loader.h).
  bool vertex_colors = false;
  // Checked every 65536 lines: a stop ends the read with StopStatus (CANCELLED). May be null.
  const StopToken* stop = nullptr;
};

// kDefaultMaterialName, kDefaultReflectance and kMaxReflectance: solver/geometry/scene.h.

// Reads an OBJ file and the MTL files it names (relative to its directory). Validates the result
// with ValidateScene and drops zero-area faces, appending a warning for each to `warnings`.
absl::StatusOr<Scene> LoadObj(const std::string& path, std::vector<std::string>* warnings,
                              const ObjOptions& options = {});

// Parses OBJ text already in memory; `name` is used in messages, `mtl_dir` to resolve mtllib.
absl::StatusOr<Scene> ParseObj(const std::string& text, const std::string& name,
                               const std::string& mtl_dir, std::vector<std::string>* warnings,
                               const ObjOptions& options = {});

// The material library files that the arguments `rest` of an mtllib line name, as the loader reads
// them: the whole of `rest` as one name when a file of that name exists in `dir` (names with
// blanks), else each blank-separated name up to a comment.
std::vector<std::string> MaterialLibraryNames(absl::string_view rest, const std::string& dir);

// The names of every mtllib line of an OBJ text, in order (what the loader would read; the client
// uploads them with the scene).
std::vector<std::string> ScanMaterialLibraries(const std::string& text, const std::string& dir);

// Returns an error naming `name` if `bytes` look binary (a NUL byte or invalid UTF-8 in the
// first 64 KiB), else OK.
absl::Status CheckText(const std::string& bytes, const std::string& name);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_INPUT_OBJ_LOADER_H_
