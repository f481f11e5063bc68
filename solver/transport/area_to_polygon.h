// Unoccluded form factors from a receiving area (an element, or any planar piece of a face) to a
// planar polygon, integrated by adaptive quadrature of Lambert's contour formula: the inner
// integral over the polygon is exact (formfactor.h, PointToPolygonFormFactorClipped), the outer
// one over the receiver uses a degree-5 rule with error control, so the result is accurate to a
// stated tolerance also where the kernel is singular (a receiver sharing an edge or a corner with
// the polygon, where the point-to-polygon factor has a logarithmic derivative).
#ifndef RADIOSITY_SOLVER_TRANSPORT_AREA_TO_POLYGON_H_
#define RADIOSITY_SOLVER_TRANSPORT_AREA_TO_POLYGON_H_

#include <array>
#include <cstdint>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/vec.h"

namespace radiosity {

// A planar convex polygon in mesh coordinates, with the unit normal of the side that sends (an
// emitter's emitting side, a form-factor source's side).
struct SpacePolygon {
  std::array<Vec3, 6> v;
  int n = 0;
  Vec3 normal;
  double Area() const;
};

// The pieces of `face` inside its parameter rectangle [u0,u1]x[v0,v1] (one per half of the
// diagonal that has area), as polygons in space with the normal of side `side`.
void FacePolygons(const MeshFace& face, double u0, double v0, double u1, double v1, int side,
                  std::vector<SpacePolygon>* out);

// An element's pieces (Mesh::Pieces; of every face an agglomerated element holds) as polygons
// with the normal of side `side`.
void ElementPolygons(const Mesh& mesh, int element, int side, std::vector<SpacePolygon>* out);

struct AreaFormFactor {
  // (1/A) integral over the receiver of F(dA(x) -> polygon), for the receiver's front normal n
  // and for -n (its back): only the part of the polygon in front of each side counts, and only
  // points x in front of the polygon's sending side receive anything.
  double front = 0;
  double back = 0;
  int64_t evaluations = 0;  // Point-to-polygon evaluations spent.
};

struct QuadratureOptions {
  // Refine until the error estimates (degree-5 rule against the sum of its four children) summed
  // over the receiver fall below max(relative x |coarse integral|, absolute x area); see
  // AreaToPolygon. max_depth bounds the subdivisions of any one initial triangle.
  double relative = 1e-6;
  double absolute = 1e-9;
  int max_depth = 12;
  // When > 0: a receiver whose gap to the polygon exceeds far_ratio x its own diameter takes the
  // rule once, unrefined (its error is O((diameter / gap)^6); 4 keeps it near 1e-4 of the value).
  double far_ratio = 0;
  // Cost bound: refinement stops once this many point-to-polygon evaluations are spent on one
  // receiver-polygon pair (a receiver nearly touching a polygon over its whole area would
  // otherwise refine everywhere to max_depth); the result is then the finest sum reached.
  int64_t max_evaluations = 1000000;
};

// The unoccluded form factor from the receiver (polygons of one face with front normal `n`, as
// ElementPolygons(..., side 0, ...) gives them; total area `area`) to `polygon`. Globally
// adaptive: the triangle with the largest error estimate is bisected first.
AreaFormFactor AreaToPolygon(const std::vector<SpacePolygon>& receiver, double area,
                             const SpacePolygon& polygon, const QuadratureOptions& options = {});

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_AREA_TO_POLYGON_H_
