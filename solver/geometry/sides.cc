#include "solver/geometry/sides.h"

#include "absl/strings/str_format.h"

namespace radiosity {

std::string SideRule::ToString() const {
  return absl::StrFormat("SideRule{exists=%d E=%s R=%s T=%s}", exists, exitance.ToString(),
                         reflectance.ToString(), transmittance.ToString());
}

SideRule MaterialSide(const Material& m, int side) {
  SideRule rule;
  rule.exists = side == kFront || m.HasBackSide();
  if (!rule.exists) return rule;
  const bool lit = side == kFront || m.two_sided;
  rule.exitance = lit ? m.emission : Rgb();
  rule.reflectance = lit ? m.reflectance : Rgb();
  rule.transmittance = m.transmittance;
  // As transport/specular.h's MaterialSpecular: mirror and glossy where the side reflects, glass
  // on both sides.
  rule.glass = m.glass;
  rule.mirror = lit ? m.mirror : Rgb();
  rule.specular = (lit ? m.mirror + m.glossy : Rgb()) + m.glass;
  return rule;
}

SideTable::SideTable(const Scene& scene, const std::vector<int32_t>& element_surfaces) {
  rules_.reserve(2 * scene.materials.size());
  for (const Material& m : scene.materials) {
    rules_.push_back(MaterialSide(m, kFront));
    rules_.push_back(MaterialSide(m, kBack));
  }
  surface_material_.reserve(scene.surfaces.size());
  for (const Surface& surface : scene.surfaces) surface_material_.push_back(surface.material);
  material_.reserve(element_surfaces.size());
  for (int32_t s : element_surfaces) {
    const int32_t m = scene.surfaces[static_cast<size_t>(s)].material;
    material_.push_back(m);
    any_back_ |= rules_[2 * static_cast<size_t>(m) + 1].exists;
    any_specular_ |= rules_[2 * static_cast<size_t>(m)].Specular() ||
                     rules_[2 * static_cast<size_t>(m) + 1].Specular();
  }
}

}  // namespace radiosity
