// Refined meshes: elements split in their patches' quadtrees, balanced 2:1 within each face, and
// the same refinement rebuilt from the elements' rectangles alone (what a watcher is sent).
#ifndef RADIOSITY_SOLVER_GEOMETRY_REFINE_MESH_H_
#define RADIOSITY_SOLVER_GEOMETRY_REFINE_MESH_H_

#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"

namespace radiosity {

// A copy of `mesh` with the given elements split (in u, v or both by their shape) and the
// quadtrees balanced 2:1 within each face, renumbered.
Mesh RefineMesh(const Scene& scene, const Mesh& mesh, const std::vector<int>& elements);

// An element's rectangle in its face's (u, v) parameter square: a leaf of a refined mesh.
struct ElementRect {
  int face = -1;
  float u0 = 0, v0 = 0, u1 = 0, v1 = 0;
};

// Rebuilds a refinement of `base` from nothing but the rectangles of its elements (e.g. the
// geometry a server announces after refining `base` over several passes): splits base's leaves
// until each rectangle is a leaf, and renumbers. Refinement only ever halves leaves, so the
// rectangles determine the leaves exactly (though not always the order of the splits, hence of
// the numbering): `local` receives, for each rectangle in order, its element in the returned
// mesh. INVALID_ARGUMENT when the rectangles are not such a refinement (a face out of range, a
// rectangle that halving base's leaves cannot reach, overlaps, or leaves with area left over).
absl::StatusOr<Mesh> MeshFromElementRects(const Scene& scene, const Mesh& base,
                                          const std::vector<ElementRect>& rects,
                                          std::vector<int>* local);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_REFINE_MESH_H_
