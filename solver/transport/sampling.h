// Sampling helpers shared by the Monte Carlo estimators and solvers.
#ifndef RADIOSITY_SOLVER_TRANSPORT_SAMPLING_H_
#define RADIOSITY_SOLVER_TRANSPORT_SAMPLING_H_

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "solver/geometry/vec.h"

namespace radiosity {

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

// Equal-area stratification of [0, 1)^2 into exactly k cells: floor(sqrt(k)) rows, row i holding
// c_i = floor((i + 1) k / rows) - floor(i k / rows) cells of width 1 / c_i and height c_i / k, so
// that every cell has area 1 / k whatever k is (a plain jittered grid when k is a square).
struct Stratum {
  double u0, v0, du, dv;
};

inline Stratum StratumCell(int64_t k, int64_t cell) {
  const int64_t rows =
      std::max<int64_t>(1, static_cast<int64_t>(std::sqrt(static_cast<double>(k))));
  auto start = [&](int64_t i) { return i * k / rows; };
  int64_t i = std::min(rows - 1, cell * rows / k);
  while (i + 1 < rows && start(i + 1) <= cell) ++i;
  while (i > 0 && start(i) > cell) --i;
  const int64_t first = start(i), count = start(i + 1) - first;
  Stratum s;
  s.du = 1.0 / static_cast<double>(count);
  s.u0 = static_cast<double>(cell - first) * s.du;
  s.v0 = static_cast<double>(first) / static_cast<double>(k);
  s.dv = static_cast<double>(count) / static_cast<double>(k);
  return s;
}

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_SAMPLING_H_
