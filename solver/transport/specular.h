// Specular transport (Shirley's thesis 6.3): where light goes after it meets a surface's mirror,
// glossy or glass part. The zonal methods store only diffuse radiosity per element; a ray that
// meets a specular part continues along the reflected or refracted direction, carrying that
// fraction of its power, until it reaches a diffuse part (extended form factors: Sillion & Puech
// 1989; Rushmeier & Torrance 1990).
//
// The parts (scene.h, Material) are fractions of the arriving light, so the power a ray carries
// on is exactly S = mirror + glossy + glass of what arrives, whatever the direction:
//  - mirror: the ideal reflection;
//  - glossy: a reflection into a lobe about the mirror direction that is reciprocal and loses
//    nothing at any incidence (GlossyDirection), so a closed scene whose surfaces all have the
//    same total reflectance still has uniform radiosity;
//  - glass: Fresnel's fraction F (unpolarised, index `ior`) is reflected as by a mirror, the
//    rest passes. A thin sheet reflects 2F / (1 + F) and passes (1 - F) / (1 + F) straight on
//    (the two faces of a non-absorbing slab, summed over its internal reflections); a refracting
//    interface (air on the front, glass behind) reflects F and refracts 1 - F by Snell's law,
//    reflecting all under total internal reflection.
#ifndef RADIOSITY_SOLVER_TRANSPORT_SPECULAR_H_
#define RADIOSITY_SOLVER_TRANSPORT_SPECULAR_H_

#include <string>
#include <vector>

#include "solver/geometry/scene.h"
#include "solver/geometry/vec.h"

namespace radiosity {

// The specular parts of one side of a material.
struct SpecularRule {
  Rgb mirror;
  Rgb glossy;
  double exponent = 0;  // The glossy lobe's Phong exponent.
  Rgb glass;
  double ior = 1.5;
  bool refracts = false;
  bool front = true;  // Which side of the surface this is (a refracting interface's air side).

  // S: the fraction of arriving light that leaves specularly.
  Rgb Total() const { return mirror + glossy + glass; }
  bool Any() const { return !Total().IsZero(); }
  std::string ToString() const;
};

// The rule of `side` (kFront or kBack) of a material: mirror and glossy parts act on the sides
// that reflect (the front, and the back of a two-sided material), glass on both.
SpecularRule MaterialSpecular(const Material& m, int side);

// Per material side, for the transport.
class SpecularTable {
 public:
  SpecularTable() = default;
  explicit SpecularTable(const Scene& scene);
  // Whether no face of the scene has a specular part.
  bool empty() const { return empty_; }
  // The rule of `side` of scene surface `surface`.
  const SpecularRule& Rule(int surface, int side) const {
    return rules_[2 * static_cast<size_t>(surface_material_[static_cast<size_t>(surface)]) +
                  static_cast<size_t>(side)];
  }
  // The names of the materials with specular parts (for messages), at most `max` of them.
  std::string Names(int max = 5) const;

 private:
  bool empty_ = true;
  std::vector<SpecularRule> rules_;  // 2 per material.
  std::vector<int> surface_material_;
  std::vector<std::string> specular_names_;
};

// Where light continues: a direction and the fraction of the arriving power it carries.
struct SpecularBranch {
  Vec3 dir;
  Rgb weight;
  bool mirror_direction = false;  // The ideal reflection (mirror and glass's reflected part).
};

// The branches of light arriving along unit `dir` at a side whose unit normal (pointing out of
// the side the light arrives at) is `n`: at most 3 (the mirror direction, a glossy direction
// sampled with r1, r2 in [0, 1), the transmitted direction), with weights summing to
// rule.Total() exactly. Returns how many it wrote to `out`. With `radiance` (a walk from the
// eye or a sensor that carries radiance back, not power forward) the refracted branch's weight
// is divided by eta^2 (radiance in a medium of index n scales as n^2), so the weights sum to
// rule.Total() only without refraction.
int ScatterSpecular(const SpecularRule& rule, const Vec3& dir, const Vec3& n, double r1, double r2,
                    SpecularBranch out[3], bool radiance = false);

// Fresnel's reflectance of unpolarised light at a dielectric interface: `cos_i` the cosine of
// incidence, `eta` = n_t / n_i. 1 under total internal reflection.
double FresnelDielectric(double cos_i, double eta);

// A direction of the glossy lobe of exponent `exponent` for light arriving along `dir` at a side
// of normal `n`: the incident direction's projection on the tangent disk is mapped to the square
// by Shirley & Chiu's concentric map (area-preserving, so the square's area measure is projected
// solid angle), reflected through the centre (the mirror direction), moved by a Gaussian step of
// deviation 1 / sqrt(exponent) per axis (Phong's lobe cos^n has that angular deviation), folded
// back into the square at its edges, and mapped back. Folding makes the kernel symmetric and
// stochastic in the projected solid angle measure (the heat kernel of a square with reflecting
// edges), so the BRDF is reciprocal and reflects exactly its fraction at every incidence.
Vec3 GlossyDirection(const Vec3& dir, const Vec3& n, double exponent, double r1, double r2);

// Shirley & Chiu's concentric map from [-1, 1]^2 to the unit disk, and its inverse.
void ConcentricToDisk(double a, double b, double* x, double* y);
void DiskToConcentric(double x, double y, double* a, double* b);

// A ray's specular continuation is given up (booked as absorbed) after this many specular
// bounces, once its weight falls below kSpecularCutWeight in every channel, or once the ray has
// traced kMaxSpecularSegments branches in all (glass splits every branch in two: a stack of
// panes would otherwise make millions of paths of one ray).
inline constexpr int kMaxSpecularBounces = 64;
inline constexpr double kSpecularCutWeight = 1e-6;
inline constexpr int kMaxSpecularSegments = 256;

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_SPECULAR_H_
