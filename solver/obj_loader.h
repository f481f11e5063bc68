// Wavefront OBJ + MTL reader (README "Scene input").
//
// Each `o` or `g` group is a named surface; a surface whose faces use several materials is split
// into one surface per material, named "group/material". MTL: `Kd` diffuse reflectance, `Ke`
// emitted radiant exitance (W/m^2 per channel), `Tf` diffuse transmittance, and the extension
// `two_sided 1` (or `two_sided on`). Polygons keep all their vertices. Every error names the file
// and line.
#ifndef RADIOSITY_SOLVER_OBJ_LOADER_H_
#define RADIOSITY_SOLVER_OBJ_LOADER_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/scene.h"

namespace radiosity {

// Reads an OBJ file and the MTL files it names (relative to its directory). Validates the result
// with ValidateScene and drops zero-area faces, appending a warning for each to `warnings`.
absl::StatusOr<Scene> LoadObj(const std::string& path, std::vector<std::string>* warnings);

// Parses OBJ text already in memory; `name` is used in messages, `mtl_dir` to resolve mtllib.
absl::StatusOr<Scene> ParseObj(const std::string& text, const std::string& name,
                               const std::string& mtl_dir, std::vector<std::string>* warnings);

// Returns an error naming `name` if `bytes` look binary (a NUL byte or invalid UTF-8 in the
// first 64 KiB), else OK.
absl::Status CheckText(const std::string& bytes, const std::string& name);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_OBJ_LOADER_H_
