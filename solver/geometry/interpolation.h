// Reading a piecewise-constant solution as a smooth function on the surfaces, for interpolated
// shading (images, PLY) and for resampling onto another mesh.
#ifndef RADIOSITY_SOLVER_GEOMETRY_INTERPOLATION_H_
#define RADIOSITY_SOLVER_GEOMETRY_INTERPOLATION_H_

#include <array>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/solution.h"
#include "solver/geometry/vec.h"

namespace radiosity {

// Bilinear interpolation of corner values {c00, c10, c01, c11} at local coordinates (s, t) in
// [0,1]^2: (1-s)(1-t) c00 + s(1-t) c10 + (1-s)t c01 + st c11.
inline Rgb Bilinear(const std::array<Rgb, 4>& c, double s, double t) {
  return c[0] * ((1 - s) * (1 - t)) + c[1] * (s * (1 - t)) + c[2] * ((1 - s) * t) + c[3] * (s * t);
}

// Element-local coordinates of face parameter point (u, v), clamped to the element's rectangle.
void LocalCoords(const Element& e, double u, double v, double* s, double* t);

// The radiosity of an element side, or zero when the solution has no such slot.
inline Rgb SideRadiosity(const Solution& solution, int element, int side) {
  const size_t slot = static_cast<size_t>(Slot(element, side));
  return slot < solution.radiosity.size() ? solution.radiosity[slot] : Rgb{};
}

// Smoothed radiosity at the corners of every element side, for interpolated shading: for each face
// the values on the lattice of element corners are the area-weighted means of the element sides
// touching them. Indexed like the mesh's elements: corners[Slot(e, side)] = {c00, c10, c01, c11}
// at (u0,v0), (u1,v0), (u0,v1), (u1,v1). T-vertices of a refined mesh take the value
// interpolated along the larger neighbour's edge, so shading has no cracks.
//
// Where elements cover whole faces (an agglomerated element's faces, or a face that is one
// element), the vector goes on after the 2n element sides with one corner set per face side
// (FaceCornerSlot), so that shading is smooth over the input triangles rather than flat per
// triangle or per agglomerated element: {c00, c10, c01, c11} at the face's (u, v) corners
// (0,0), (1,0), (0,1), (1,1) (p0, p1, p3, p2).
//
// Across faces: at every point where corners of different faces coincide (a shared vertex, or
// element corners meeting on a shared edge), a face's corners take the area-weighted mean over the
// element sides there of the faces on the same surface whose normals lie within
// max(Mesh::agglomerate_degrees, 1 degree) of its own; creases sharper than that stay sharp.
// So the two triangles of a quad split along its diagonal shade as one quad. Faces whose element
// lattices cross a shared edge at different points agree at the points they share only.
// On a triangle, c11 = c10 + c01 - c00 (which makes Bilinear linear) for the whole face and for
// an element whose corner c11 lies beyond the diagonal while c10 and c01 do not.
std::vector<std::array<Rgb, 4>> CornerRadiosity(const Mesh& mesh, const Solution& solution);

// Whether an element covers whole faces: agglomerated, or a face's one element.
inline bool CoversWholeFaces(const Element& e) {
  return e.num_members > 0 || (e.u0 == 0 && e.v0 == 0 && e.u1 == 1 && e.v1 == 1);
}

// Where CornerRadiosity keeps the corner set of side `side` of face `face` (CoversWholeFaces).
inline size_t FaceCornerSlot(const Mesh& mesh, int face, int side) {
  return 2 * (mesh.elements().size() + static_cast<size_t>(face)) + static_cast<size_t>(side);
}

// The interpolated radiosity of element side (element, side) at parameter point (u, v) of `face`
// (the element's face, or one of its members when agglomerated), from CornerRadiosity's corners.
inline Rgb InterpolatedRadiosity(const Mesh& mesh, const std::vector<std::array<Rgb, 4>>& corners,
                                 int element, int side, int face, double u, double v) {
  const Element& e = mesh.elements()[element];
  if (CoversWholeFaces(e) && FaceCornerSlot(mesh, face, side) < corners.size()) {
    return Bilinear(corners[FaceCornerSlot(mesh, face, side)], u, v);
  }
  double s, t;
  LocalCoords(e, u, v, &s, &t);
  return Bilinear(corners[Slot(element, side)], s, t);
}

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_INTERPOLATION_H_
