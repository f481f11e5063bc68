// Sampling helpers shared by the Monte Carlo estimators and solvers.
#ifndef RADIOSITY_SOLVER_SAMPLING_H_
#define RADIOSITY_SOLVER_SAMPLING_H_

#include <cmath>

#include "solver/vec.h"

namespace radiosity {

inline constexpr double kPi = 3.14159265358979323846;

// Cosine-distributed direction about the unit normal n, pdf cos(theta) / pi (Malley's method: a
// uniform point on the unit disk, (r1, r2) -> (phi = 2 pi r1, sin(theta) = sqrt(r2)), lifted to the
// hemisphere). Rays are traced in float, so the angle's sine and cosine need only float precision.
inline Vec3 CosineDirection(const Vec3& n, double r1, double r2) {
  Vec3 t, b;
  OrthonormalBasis(n, &t, &b);
  float sin_phi, cos_phi;
  ::sincosf(static_cast<float>(2 * kPi * r1), &sin_phi, &cos_phi);
  const double sin_theta = std::sqrt(r2);
  const double cos_theta = std::sqrt(std::fmax(0.0, 1 - r2));
  return t * (sin_theta * cos_phi) + b * (sin_theta * sin_phi) + n * cos_theta;
}

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_SAMPLING_H_
