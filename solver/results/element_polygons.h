// The polygons the mesh outputs draw (mesh.ply, mesh.glb): each element's pieces on the halves of
// its face, with element-local coordinates for interpolating its corner values.
#ifndef RADIOSITY_SOLVER_RESULTS_ELEMENT_POLYGONS_H_
#define RADIOSITY_SOLVER_RESULTS_ELEMENT_POLYGONS_H_

#include <array>
#include <cstdint>

#include "solver/geometry/interpolation.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/sides.h"

namespace radiosity {

// Appends to `sizes` the vertex count of each polygon piece of element `i`: its pieces on the
// halves of its face, or of every face an agglomerated element holds (Mesh::Members).
inline void ElementPieceSizes(const Mesh& mesh, int64_t i, std::vector<int>* sizes) {
  std::array<ElementPiece, 2> pieces;
  for (int m = 0; m < mesh.FaceCount(static_cast<int>(i)); ++m) {
    const int np = mesh.Pieces(static_cast<int>(i), &pieces, m);
    for (int k = 0; k < np; ++k) sizes->push_back(pieces[k].n);
  }
}

// Calls emit(position in scene coordinates, face, u, v) for each vertex of element `i`'s polygon
// pieces, in the order of ElementPieceSizes (counter-clockwise about the front normal: mesh.h's
// maps preserve the (u, v) orientation on both halves), where (u, v) is the vertex's parameter
// point on `face` (for InterpolatedRadiosity).
template <typename Emit>
void ForEachElementVertex(const Mesh& mesh, int64_t i, Emit&& emit) {
  const Vec3 origin = mesh.origin();
  std::array<ElementPiece, 2> pieces;
  for (int m = 0; m < mesh.FaceCount(static_cast<int>(i)); ++m) {
    const int face = mesh.FaceOf(static_cast<int>(i), m);
    const MeshFace& f = mesh.faces()[face];
    const int np = mesh.Pieces(static_cast<int>(i), &pieces, m);
    for (int k = 0; k < np; ++k) {
      const ElementPiece& pc = pieces[k];
      for (int j = 0; j < pc.n; ++j) {
        const double u = pc.uv[2 * j], v = pc.uv[2 * j + 1];
        emit(f.EvalOnHalf(pc.half, u, v) + origin, face, u, v);
      }
    }
  }
}

// How many sides of element `i` the outputs draw: 1, or 2 when its back exists.
inline int DrawnSides(const Mesh& mesh, int64_t i) {
  return mesh.sides().exists(Slot(static_cast<int>(i), kBack)) ? 2 : 1;
}

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_ELEMENT_POLYGONS_H_
