// Moving a solution from one mesh of a scene to another, so that solutions on different meshes
// (uniform, adaptively refined, hierarchical) can be compared against one reference
// (bench/REPORT.md, "Adaptive and hierarchical against uniform meshes").
//
// Every mesh of a scene has the same faces (Mesh::faces() depends on the scene only; element size
// and refinement change the quadtrees inside each face), so a point is (face, u, v) on both.
// Each element of the target mesh gets the area average, over the element, of the source
// solution read as a function on the surfaces:
//   B'_j = (1 / A_j) integral over element j of B(x) dA,
// the L2 projection onto the target's piecewise-constant space, by the midpoint rule on a k x k
// grid of the element's (u, v) rectangle, weighted by the area element |dP/du x dP/dv| of the
// half each point lies on (zero beyond a triangle's diagonal). Where the source mesh nests in the
// target element (the source is coarser and its element edges do not cross the target's), the
// average of the piecewise-constant reading is exact.
//
// B(x) is read in one of two ways:
//  - piecewise constant: the source element containing x (the solution as the method defines it);
//  - interpolated: the bilinear interpolation of CornerRadiosity (what rendered images show).
#ifndef RADIOSITY_SOLVER_GEOMETRY_RESAMPLE_H_
#define RADIOSITY_SOLVER_GEOMETRY_RESAMPLE_H_

#include <array>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/solution.h"
#include "solver/geometry/vec.h"

namespace radiosity {

enum class Reading { kConstant, kInterpolated };

// Radiosity of every element side of `to` (indexed by Slot(element, side)) from `solution` on
// `from`. Both meshes must come from the same scene. `corners` (CornerRadiosity(from, solution))
// is needed for Reading::kInterpolated only. `samples` is k, the midpoint grid per axis (>= 1).
std::vector<Rgb> ResampleRadiosity(const Mesh& from, const Solution& solution,
                                   const std::vector<std::array<Rgb, 4>>& corners, Reading reading,
                                   const Mesh& to, int samples = 4);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_RESAMPLE_H_
