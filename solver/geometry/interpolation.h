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
std::vector<std::array<Rgb, 4>> CornerRadiosity(const Mesh& mesh, const Solution& solution);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_INTERPOLATION_H_
