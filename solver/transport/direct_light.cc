#include "solver/transport/direct_light.h"

#include <algorithm>
#include <cmath>

#include "solver/transport/sampling.h"

namespace radiosity {

DirectLight::DirectLight(const Scene& scene, const Mesh& mesh, const Visibility& visibility)
    : scene_(scene), mesh_(mesh), visibility_(visibility) {
  const auto& elements = mesh.elements();
  for (int e = 0; e < static_cast<int>(elements.size()); ++e) {
    for (int side : {kFront, kBack}) {
      const SideRule& rule = mesh.sides().at(e, side);
      const double p = rule.exitance.Sum() * elements[e].area;
      if (!(p > 0)) continue;
      emitters_.push_back({e, side, rule.exitance, p});
      total_power_ += p;
      cumulative_.push_back(total_power_);
    }
  }
}

Rgb DirectLight::EmissionSeen(int face, float u, float v, const Vec3& dir, double* cos_y) const {
  const MeshFace& f = mesh_.faces()[face];
  const double c = Dot(dir, f.normal[f.Half(u, v)]) / Length(dir);
  *cos_y = std::fabs(c);
  // Arriving against the front normal: the front side is seen.
  return mesh_.sides().OfSurface(f.surface, c < 0 ? kFront : kBack).exitance;
}

Rgb DirectLight::Sample(const Vec3& x, const Vec3& n, int receiver_face, double t, double r1,
                        double r2, double r3, double r4, double r5) const {
  if (emitters_.empty()) return Rgb();
  const Vec3 origin = x + n * visibility_.epsilon();
  Rgb sum;
  // Emitter sampling.
  {
    const size_t i = std::min<size_t>(
        emitters_.size() - 1,
        std::upper_bound(cumulative_.begin(), cumulative_.end(), t * total_power_) -
            cumulative_.begin());
    const Emitter& em = emitters_[i];
    const Element& el = mesh_.elements()[em.element];
    int half;
    const Vec3 y = mesh_.SampleElement(em.element, r1, r2, r3, &half);
    Vec3 ny = mesh_.faces()[el.face].normal[half];
    if (em.side == 1) ny = -ny;
    const Vec3 d = y - x;
    const double r_2 = Dot(d, d);
    const double r = std::sqrt(r_2);
    const double cos_x = r > 0 ? Dot(n, d) / r : 0;
    const double cos_y = r > 0 ? -Dot(ny, d) / r : 0;
    if (cos_x > 0 && cos_y > 0) {
      const int ignore = receiver_face >= 0 ? receiver_face : el.face;
      if (!visibility_.Occluded(origin, y - origin, 0, 1 - 1e-6, ignore)) {
        const double p_l = em.exitance.Sum() / total_power_ * r_2 / cos_y;
        const double p_c = cos_x / kPi;
        sum += em.exitance * (cos_x / kPi / (p_l + p_c));
      }
    }
  }
  // Cosine sampling.
  {
    const Vec3 dir = CosineDirection(n, r4, r5);
    const Hit hit = visibility_.Intersect(origin, dir, 0, 1e30, receiver_face);
    if (hit.valid()) {
      double cos_y;
      const Rgb m = EmissionSeen(hit.face, hit.u, hit.v, dir, &cos_y);
      const double cos_x = Dot(n, dir) / Length(dir);
      if (!m.IsZero() && cos_y > 0 && cos_x > 0) {
        const double r = hit.t * Length(dir);
        const double p_l = m.Sum() / total_power_ * r * r / cos_y;
        const double p_c = cos_x / kPi;
        sum += m * (cos_x / kPi / (p_l + p_c));
      }
    }
  }
  return sum;
}

}  // namespace radiosity
