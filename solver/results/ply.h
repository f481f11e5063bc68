// mesh.ply: the meshed scene coloured by its solution, for any mesh viewer.
#ifndef RADIOSITY_SOLVER_RESULTS_PLY_H_
#define RADIOSITY_SOLVER_RESULTS_PLY_H_

#include <array>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/solution.h"

namespace radiosity {

// mesh.ply (ASCII): one polygon per existing element side with per-vertex colours (interpolated
// radiosity `corners`, CornerRadiosity, tone-mapped to 8 bits) and float properties r, g, b
// holding the linear radiosity itself.
absl::Status WritePly(const Mesh& mesh, const Solution& solution,
                      const std::vector<std::array<Rgb, 4>>& corners, const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_PLY_H_
