// PlaneFitHat against what least squares must do: reproduce a plane exactly, average a constant,
// and shrink the variance of independent noise by the leverage of each point.
#include "solver/geometry/plane_fit.h"

#include <cmath>
#include <numeric>
#include <random>

#include "gtest/gtest.h"

namespace radiosity {
namespace {

std::vector<FitPoint> Grid(int nx, int ny) {
  std::vector<FitPoint> points;
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i)
      points.push_back({double(i), double(j), 1.0 + 0.25 * ((i + j) % 3)});
  }
  return points;
}

TEST(PlaneFitTest, ReproducesAPlaneAndRowsSumToOne) {
  for (auto [nx, ny] : {std::pair{3, 3}, {2, 3}, {3, 1}, {1, 2}, {1, 1}, {2, 2}}) {
    const std::vector<FitPoint> points = Grid(nx, ny);
    std::vector<double> hat;
    const int terms = PlaneFitHat(points, &hat);
    const int n = static_cast<int>(points.size());
    EXPECT_EQ(terms, 1 + (nx > 1) + (ny > 1)) << nx << "x" << ny;
    ASSERT_EQ(hat.size(), size_t(n * n));
    for (int i = 0; i < n; ++i) {
      double row = 0, fit = 0;
      for (int j = 0; j < n; ++j) {
        row += hat[i * n + j];
        // A plane in the directions the points span is fitted exactly.
        const double x = nx > 1 ? points[j].x : 0, y = ny > 1 ? points[j].y : 0;
        fit += hat[i * n + j] * (2 - 0.5 * x + 3 * y);
      }
      const double x = nx > 1 ? points[i].x : 0, y = ny > 1 ? points[i].y : 0;
      EXPECT_NEAR(row, 1, 1e-12);
      EXPECT_NEAR(fit, 2 - 0.5 * x + 3 * y, 1e-12) << nx << "x" << ny << " point " << i;
    }
    // Trace of the hat matrix = the number of terms (Draper & Smith).
    double trace = 0;
    for (int i = 0; i < n; ++i) trace += hat[i * n + i];
    EXPECT_NEAR(trace, terms, 1e-12);
  }
}

TEST(PlaneFitTest, CentreOfAThreeByThreeGridHasANinthOfTheVariance) {
  // Equal weights: the centre's leverage is 1/9 (x and y terms vanish there), a corner's
  // 1/9 + 1/6 + 1/6. Checked against the empirical variance of fits to noise.
  std::vector<FitPoint> points;
  for (int j = 0; j < 3; ++j) {
    for (int i = 0; i < 3; ++i) points.push_back({double(i), double(j), 1.0});
  }
  std::vector<double> hat;
  ASSERT_EQ(PlaneFitHat(points, &hat), 3);
  EXPECT_NEAR(hat[4 * 9 + 4], 1.0 / 9, 1e-12);
  EXPECT_NEAR(hat[0], 1.0 / 9 + 1.0 / 6 + 1.0 / 6, 1e-12);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> noise;
  double sum_sq = 0;
  const int trials = 20000;
  for (int t = 0; t < trials; ++t) {
    double fit = 0;
    for (int j = 0; j < 9; ++j) fit += hat[4 * 9 + j] * noise(rng);
    sum_sq += fit * fit;
  }
  EXPECT_NEAR(sum_sq / trials, 1.0 / 9, 0.005);
}

TEST(PlaneFitTest, CollinearPointsFallBackToTheirMean) {
  const std::vector<FitPoint> points = {{0, 0, 1}, {1, 1, 2}, {2, 2, 1}};
  std::vector<double> hat;
  EXPECT_EQ(PlaneFitHat(points, &hat), 1);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(hat[i * 3 + 1], 0.5, 1e-12);
    EXPECT_NEAR(hat[i * 3 + 0], 0.25, 1e-12);
  }
  EXPECT_EQ(PlaneFitHat({}, &hat), 0);
  EXPECT_TRUE(hat.empty());
}

}  // namespace
}  // namespace radiosity
