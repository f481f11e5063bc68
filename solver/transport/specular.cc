#include "solver/transport/specular.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "solver/geometry/sides.h"

namespace radiosity {

namespace {

constexpr double kPiOver4 = 0.78539816339744830962;

// Folds x into [-1, 1] by reflection at the ends (a triangle wave of period 4).
double Fold(double x) {
  double y = std::fmod(x + 1, 4.0);
  if (y < 0) y += 4;
  if (y > 2) y = 4 - y;
  return y - 1;
}

Vec3 Reflect(const Vec3& dir, const Vec3& n) { return dir - n * (2 * Dot(dir, n)); }

}  // namespace

std::string SpecularRule::ToString() const {
  return absl::StrCat("SpecularRule{mirror=", mirror.ToString(), " glossy=", glossy.ToString(), "^",
                      exponent, " glass=", glass.ToString(), " ior=", ior,
                      refracts ? " refracts" : "", front ? "" : " back", "}");
}

SpecularRule MaterialSpecular(const Material& m, int side) {
  SpecularRule rule;
  rule.front = side == kFront;
  const bool reflects = side == kFront || m.two_sided;
  if (reflects) {
    rule.mirror = m.mirror;
    rule.glossy = m.glossy;
    rule.exponent = m.glossy_exponent;
  }
  rule.glass = m.glass;
  rule.ior = m.ior;
  rule.refracts = m.refracts;
  return rule;
}

SpecularTable::SpecularTable(const Scene& scene) {
  // Only materials some face uses count (a library may define a mirror nothing uses).
  std::vector<bool> used(scene.materials.size(), false);
  for (const Face& f : scene.faces) {
    if (f.surface < 0 || f.surface >= static_cast<int>(scene.surfaces.size())) continue;
    const int m = scene.surfaces[f.surface].material;
    if (m >= 0 && m < static_cast<int>(used.size())) used[m] = true;
  }
  for (size_t i = 0; i < scene.materials.size(); ++i) {
    const Material& m = scene.materials[i];
    rules_.push_back(MaterialSpecular(m, kFront));
    rules_.push_back(MaterialSpecular(m, kBack));
    if (used[i] && m.IsSpecular()) specular_names_.push_back(absl::StrCat("'", m.name, "'"));
  }
  for (const Surface& s : scene.surfaces) surface_material_.push_back(s.material);
  empty_ = specular_names_.empty();
}

std::string SpecularTable::Names(int max) const {
  const size_t shown = std::min(specular_names_.size(), static_cast<size_t>(std::max(max, 0)));
  std::string out = absl::StrJoin(specular_names_.begin(), specular_names_.begin() + shown, ", ");
  if (shown < specular_names_.size()) {
    absl::StrAppend(&out, " and ", specular_names_.size() - shown, " more");
  }
  return out;
}

double FresnelDielectric(double cos_i, double eta) {
  cos_i = std::clamp(cos_i, 0.0, 1.0);
  const double sin2_t = (1 - cos_i * cos_i) / (eta * eta);
  if (sin2_t >= 1) return 1;
  const double cos_t = std::sqrt(1 - sin2_t);
  const double rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  const double rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  return 0.5 * (rs * rs + rp * rp);
}

void ConcentricToDisk(double a, double b, double* x, double* y) {
  if (a == 0 && b == 0) {
    *x = *y = 0;
    return;
  }
  double r, phi;
  if (std::fabs(a) > std::fabs(b)) {
    r = a;
    phi = kPiOver4 * (b / a);
  } else {
    r = b;
    phi = 2 * kPiOver4 - kPiOver4 * (a / b);
  }
  *x = r * std::cos(phi);
  *y = r * std::sin(phi);
}

void DiskToConcentric(double x, double y, double* a, double* b) {
  const double r = std::hypot(x, y);
  if (r == 0) {
    *a = *b = 0;
    return;
  }
  double phi = std::atan2(y, x);             // (-pi, pi]
  if (phi < -kPiOver4) phi += 8 * kPiOver4;  // [-pi/4, 7pi/4)
  if (phi < kPiOver4) {                      // Right wedge: r = a, phi = pi/4 b / a.
    *a = r;
    *b = phi / kPiOver4 * r;
  } else if (phi < 3 * kPiOver4) {  // Top: r = b, phi = pi/2 - pi/4 a / b.
    *b = r;
    *a = (2 * kPiOver4 - phi) / kPiOver4 * r;
  } else if (phi < 5 * kPiOver4) {  // Left: r = a < 0, phi = pi + pi/4 b / a.
    *a = -r;
    *b = (phi - 4 * kPiOver4) / kPiOver4 * -r;
  } else {  // Bottom: r = b < 0, phi = 3pi/2 - pi/4 a / b.
    *b = -r;
    *a = (6 * kPiOver4 - phi) / kPiOver4 * -r;
  }
}

Vec3 GlossyDirection(const Vec3& dir, const Vec3& n, double exponent, double r1, double r2) {
  Vec3 t, b;
  OrthonormalBasis(n, &t, &b);
  // The mirror direction's projection on the tangent disk is minus the incident one's (the
  // incident direction -dir), and the concentric map is odd.
  double a, c;
  DiskToConcentric(Dot(dir, t), Dot(dir, b), &a, &c);
  // Box-Muller: two independent Gaussian steps.
  const double sigma = 1 / std::sqrt(exponent);
  const double radius = sigma * std::sqrt(-2 * std::log(std::max(1 - r1, 1e-300)));
  const double angle = 8 * kPiOver4 * r2;
  a = Fold(a + radius * std::cos(angle));
  c = Fold(c + radius * std::sin(angle));
  double x, y;
  ConcentricToDisk(a, c, &x, &y);
  const double z = std::sqrt(std::max(0.0, 1 - x * x - y * y));
  return Normalize(t * x + b * y + n * z);
}

int ScatterSpecular(const SpecularRule& rule, const Vec3& dir, const Vec3& n, double r1, double r2,
                    SpecularBranch out[3], bool radiance) {
  int count = 0;
  const double cos_i = std::clamp(-Dot(dir, n), 0.0, 1.0);
  Rgb reflect = rule.mirror;
  Rgb pass;
  Vec3 pass_dir = dir;
  if (!rule.glass.IsZero()) {
    if (rule.refracts) {
      // Air on the front: light arriving at the front enters the glass (eta = ior).
      const double eta = rule.front ? rule.ior : 1 / rule.ior;
      const double f = FresnelDielectric(cos_i, eta);
      reflect += rule.glass * f;
      if (f < 1) {
        pass = rule.glass * ((1 - f) / (radiance ? eta * eta : 1.0));
        const double sin2_t = (1 - cos_i * cos_i) / (eta * eta);
        const double cos_t = std::sqrt(std::max(0.0, 1 - sin2_t));
        pass_dir = Normalize(dir * (1 / eta) + n * (cos_i / eta - cos_t));
      }
    } else {
      const double f = FresnelDielectric(cos_i, rule.ior);
      reflect += rule.glass * (2 * f / (1 + f));
      pass = rule.glass * ((1 - f) / (1 + f));
    }
  }
  if (!reflect.IsZero()) out[count++] = {Reflect(dir, n), reflect, true};
  if (!rule.glossy.IsZero()) {
    out[count++] = {GlossyDirection(dir, n, rule.exponent, r1, r2), rule.glossy};
  }
  if (!pass.IsZero()) out[count++] = {pass_dir, pass};
  return count;
}

}  // namespace radiosity
