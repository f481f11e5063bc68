#include "solver/geometry/rect_sampler.h"

#include <algorithm>
#include <cmath>

namespace radiosity {

RectSampler::RectSampler(const MeshFace& face, double u0, double v0, double u1, double v1,
                         bool affine_within_half)
    : face_(&face), u0_(u0), v0_(v0), u1_(u1), v1_(v1) {
  num_pieces_ = RectPieces(u0, v0, u1, v1, face, &pieces_);
  if (affine_within_half && num_pieces_ == 1 && pieces_[0].n == 4 &&
      (u1 + v1 <= 1.0 || u0 + v0 >= 1.0)) {
    whole_half_ = pieces_[0].half;
    return;
  }
  // A parallelogram's two halves are one affine map over the whole square.
  const double size = face.len_u + face.len_v;
  parallelogram_ =
      !face.triangle && Length(face.p[0] + face.p[2] - face.p[1] - face.p[3]) <= 1e-12 * size;
  if (parallelogram_) return;
  for (int p = 0; p < num_pieces_; ++p) {
    const ElementPiece& pc = pieces_[p];
    for (int k = 1; k + 1 < pc.n; ++k) {
      const double a = 0.5 * face.jacobian[pc.half] *
                       std::fabs((pc.uv[2 * k] - pc.uv[0]) * (pc.uv[2 * k + 3] - pc.uv[1]) -
                                 (pc.uv[2 * k + 2] - pc.uv[0]) * (pc.uv[2 * k + 1] - pc.uv[1]));
      if (a <= 0 || num_tris_ == static_cast<int>(tris_.size())) continue;
      tris_[num_tris_++] = {p, k, a};
      total_ += a;
    }
  }
}

Vec3 RectSampler::Sample(double s, double t, int* half) const {
  if (whole_half_ >= 0) {
    *half = whole_half_;
    return face_->EvalOnHalf(whole_half_, u0_ + s * (u1_ - u0_), v0_ + t * (v1_ - v0_));
  }
  if (parallelogram_) {
    const double u = u0_ + s * (u1_ - u0_), v = v0_ + t * (v1_ - v0_);
    *half = face_->Half(u, v);
    return face_->EvalOnHalf(0, u, v);  // Both halves' formulas agree on a parallelogram.
  }
  if (num_tris_ == 0) {
    *half = 0;
    return face_->Eval(0.5 * (u0_ + u1_), 0.5 * (v0_ + v1_));
  }
  double x = s * total_;
  int i = 0;
  while (i + 1 < num_tris_ && x >= tris_[i].area) x -= tris_[i++].area;
  const double r = std::clamp(x / tris_[i].area, 0.0, 1.0);
  const ElementPiece& pc = pieces_[tris_[i].piece];
  const int k = tris_[i].k;
  const double sr = std::sqrt(r);
  const double ba = 1 - sr, bb = sr * (1 - t), bc = sr * t;
  const double u = ba * pc.uv[0] + bb * pc.uv[2 * k] + bc * pc.uv[2 * k + 2];
  const double v = ba * pc.uv[1] + bb * pc.uv[2 * k + 1] + bc * pc.uv[2 * k + 3];
  *half = pc.half;
  return face_->EvalOnHalf(pc.half, u, v);
}

Vec3 SampleElementArea(const Mesh& mesh, int element, double s, double t, int* half, int* face) {
  const Element& e = mesh.elements()[element];
  *face = e.face;
  if (const ElementMembers m = mesh.Members(element); m.count > 0) {
    // A member face by its share of the area; s rescaled within it keeps the strata.
    const int k = std::min<int>(
        m.count - 1,
        static_cast<int>(std::upper_bound(m.cumulative_area, m.cumulative_area + m.count, s) -
                         m.cumulative_area));
    const double lo = k > 0 ? m.cumulative_area[k - 1] : 0.0;
    const double width = m.cumulative_area[k] - lo;
    s = width > 0 ? std::clamp((s - lo) / width, 0.0, std::nextafter(1.0, 0.0)) : 0.0;
    *face = m.faces[k];
    const MeshFace& f = mesh.faces()[*face];
    if (f.triangle) {
      // A whole triangle: the square-root map (Shirley & Chiu 1997), as RectSampler's one fan
      // triangle, without building the sampler per point.
      const double r = std::sqrt(s);
      *half = 0;
      return f.EvalOnHalf(0, r * (1 - t), r * t);
    }
  }
  return RectSampler(mesh.faces()[*face], e.u0, e.v0, e.u1, e.v1, /*affine_within_half=*/false)
      .Sample(s, t, half);
}

}  // namespace radiosity
