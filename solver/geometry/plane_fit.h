// Weighted least-squares planes through scattered values, as linear smoothers: the fitted value at
// each point is a fixed combination of the values (the "hat" matrix of regression), so the
// variance of a smoothed value follows from the variances of the values it combines.
#ifndef RADIOSITY_SOLVER_GEOMETRY_PLANE_FIT_H_
#define RADIOSITY_SOLVER_GEOMETRY_PLANE_FIT_H_

#include <string>
#include <vector>

namespace radiosity {

// A point of the fit: its position and its weight (> 0) in the least-squares sum.
struct FitPoint {
  double x = 0, y = 0;
  double weight = 1;
};

// The hat matrix of the weighted least-squares fit of a + b x + c y to values at `points`
// (Draper & Smith, Applied Regression Analysis, ch. 8: H = X (X^T W X)^-1 X^T W): the fitted value
// at point i is sum_j hat[i * n + j] * value_j. Terms the points cannot determine are left out
// (points on one vertical line fit a + c y; a single position, a constant). Returns the number of
// terms fitted (1 to 3); `hat` is empty when there are no points.
int PlaneFitHat(const std::vector<FitPoint>& points, std::vector<double>* hat);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_PLANE_FIT_H_
