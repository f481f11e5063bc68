// mesh.glb: the solved mesh as binary glTF 2.0, for Blender, three.js and game engines (baked
// light).
#ifndef RADIOSITY_SOLVER_RESULTS_GLTF_H_
#define RADIOSITY_SOLVER_RESULTS_GLTF_H_

#include <array>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/solution.h"

namespace radiosity {

// Writes one triangle mesh of every existing element side (the polygons of mesh.ply, fanned into
// triangles; back sides with their winding reversed), in scene coordinates, with per vertex:
//  - COLOR_0: linear RGB, the interpolated radiosity (`corners`, CornerRadiosity) times the
//    exposure of image.png, clamped to [0, 1] (what viewers show);
//  - _RADIOSITY: the linear radiosity itself, W/m^2 per channel (an application-specific
//    attribute, glTF 2.0 section 3.7.2.1);
// and an unlit material (KHR_materials_unlit), so the baked light is shown as it is. The exposure
// is in asset.extras.radiosity_exposure.
absl::Status WriteGlb(const Mesh& mesh, const std::vector<std::array<Rgb, 4>>& corners,
                      const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_GLTF_H_
