#include "solver/geometry/plane_fit.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace radiosity {

namespace {

// Solves the k x k symmetric positive definite system m x = b in place by Cholesky's method;
// false when m is (numerically) singular.
bool SolveSpd(int k, std::array<double, 9> m, std::array<double, 3>* b) {
  std::array<double, 9> l{};
  for (int i = 0; i < k; ++i) {
    for (int j = 0; j <= i; ++j) {
      double s = m[i * 3 + j];
      for (int p = 0; p < j; ++p) s -= l[i * 3 + p] * l[j * 3 + p];
      if (i == j) {
        if (!(s > 1e-12 * std::max(1.0, std::fabs(m[i * 3 + i])))) return false;
        l[i * 3 + i] = std::sqrt(s);
      } else {
        l[i * 3 + j] = s / l[j * 3 + j];
      }
    }
  }
  for (int i = 0; i < k; ++i) {  // L y = b
    double s = (*b)[i];
    for (int p = 0; p < i; ++p) s -= l[i * 3 + p] * (*b)[p];
    (*b)[i] = s / l[i * 3 + i];
  }
  for (int i = k - 1; i >= 0; --i) {  // L^T x = y
    double s = (*b)[i];
    for (int p = i + 1; p < k; ++p) s -= l[p * 3 + i] * (*b)[p];
    (*b)[i] = s / l[i * 3 + i];
  }
  return true;
}

}  // namespace

int PlaneFitHat(const std::vector<FitPoint>& points, std::vector<double>* hat) {
  const int n = static_cast<int>(points.size());
  hat->clear();
  if (n == 0) return 0;
  // Centred on the weighted mean, scaled by the spread, so the normal equations are well
  // conditioned whatever the coordinates.
  double w_sum = 0, mx = 0, my = 0;
  for (const FitPoint& p : points) {
    w_sum += p.weight;
    mx += p.weight * p.x;
    my += p.weight * p.y;
  }
  mx /= w_sum;
  my /= w_sum;
  double sx = 0, sy = 0;
  for (const FitPoint& p : points) {
    sx = std::max(sx, std::fabs(p.x - mx));
    sy = std::max(sy, std::fabs(p.y - my));
  }
  const double scale = std::max(sx, sy);
  // The terms the points determine: a direction with no spread (relative to the other) is left
  // out.
  const bool use_x = scale > 0 && sx > 1e-9 * scale, use_y = scale > 0 && sy > 1e-9 * scale;
  auto basis = [&](const FitPoint& p, std::array<double, 3>* f) {
    int k = 0;
    (*f)[k++] = 1;
    if (use_x) (*f)[k++] = (p.x - mx) / scale;
    if (use_y) (*f)[k++] = (p.y - my) / scale;
    return k;
  };
  std::array<double, 3> f{};
  int k = basis(points[0], &f);
  std::array<double, 9> m{};
  for (const FitPoint& p : points) {
    basis(p, &f);
    for (int i = 0; i < k; ++i) {
      for (int j = 0; j < k; ++j) m[i * 3 + j] += p.weight * f[i] * f[j];
    }
  }
  // Rows of (X^T W X)^-1 X^T evaluated at each point: solve for each point's basis vector.
  // Collinear points (a singular system with both directions spread) fall back to fewer terms.
  std::vector<std::array<double, 3>> solved(static_cast<size_t>(n));
  bool ok = true;
  for (int i = 0; i < n && ok; ++i) {
    basis(points[i], &f);
    solved[i] = f;
    ok = SolveSpd(k, m, &solved[i]);
  }
  if (!ok) {
    k = 1;
    for (int i = 0; i < n; ++i) solved[i] = {1 / w_sum, 0, 0};
  }
  hat->assign(static_cast<size_t>(n) * n, 0.0);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      std::array<double, 3> fj{};
      if (k == 1) {
        fj[0] = 1;
      } else {
        basis(points[j], &fj);
      }
      double h = 0;
      for (int t = 0; t < k; ++t) h += solved[i][t] * fj[t];
      (*hat)[static_cast<size_t>(i) * n + j] = h * points[j].weight;
    }
  }
  return k;
}

}  // namespace radiosity
