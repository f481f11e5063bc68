// Area-uniform points of a rectangle of a face's (u, v) parameter square by a measure-preserving
// map of the unit square, so that strata of the unit square stay strata of the surface
// (Mesh::SampleElement picks the half with a separate random number, which would undo them).
#ifndef RADIOSITY_SOLVER_GEOMETRY_RECT_SAMPLER_H_
#define RADIOSITY_SOLVER_GEOMETRY_RECT_SAMPLER_H_

#include <array>

#include "solver/geometry/mesh.h"
#include "solver/geometry/vec.h"

namespace radiosity {

class RectSampler {
 public:
  // The rectangle [u0, u1] x [v0, v1] of `face` (which must outlive the sampler). With
  // `affine_within_half`, a rectangle within one half is sampled through that half's affine map
  // (the strata stay rectangles); without, through its fan triangles like any other.
  RectSampler(const MeshFace& face, double u0, double v0, double u1, double v1,
              bool affine_within_half = true);

  // The point for (s, t) in [0, 1)^2 (mesh coordinates) and the half it lies on. On a rectangle
  // within one half, or on a parallelogram face, the face map is affine and the point is (u, v)
  // in the rectangle; otherwise s picks a fan triangle of the rectangle's pieces by area, and its
  // remainder and t place the point by the square-root map (Shirley & Chiu 1997).
  Vec3 Sample(double s, double t, int* half) const;

  // The rectangle's pieces on each half of the face's diagonal (RectPieces).
  const std::array<ElementPiece, 2>& pieces() const { return pieces_; }
  int num_pieces() const { return num_pieces_; }

 private:
  struct FanTri {
    int piece, k;
    double area;
  };
  const MeshFace* face_;
  double u0_, v0_, u1_, v1_;
  int whole_half_ = -1;         // >= 0: the whole rectangle lies on this half (the map is affine).
  bool parallelogram_ = false;  // The face's map is affine over the whole square.
  std::array<ElementPiece, 2> pieces_;
  int num_pieces_ = 0;
  std::array<FanTri, 10> tris_;
  int num_tris_ = 0;
  double total_ = 0;
};

// RectSampler of an element's rectangle, one point, through fan triangles unless the face is a
// parallelogram (the form-factor estimators' sampling); returns the face sampled in *face (of an
// agglomerated element, s first picks a member face by area and is rescaled within it).
Vec3 SampleElementArea(const Mesh& mesh, int element, double s, double t, int* half, int* face);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_RECT_SAMPLER_H_
