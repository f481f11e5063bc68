// An axis-aligned bounding box in space.
#ifndef RADIOSITY_SOLVER_GEOMETRY_BOX_H_
#define RADIOSITY_SOLVER_GEOMETRY_BOX_H_

#include <algorithm>
#include <cmath>
#include <limits>

#include "solver/geometry/vec.h"

namespace radiosity {

struct Box {
  Vec3 lo{std::numeric_limits<double>::max(), std::numeric_limits<double>::max(),
          std::numeric_limits<double>::max()};
  Vec3 hi{-std::numeric_limits<double>::max(), -std::numeric_limits<double>::max(),
          -std::numeric_limits<double>::max()};
  // (std::min / std::max, not Min / Max: the coordinates are finite, and fmin / fmax are calls.)
  void Add(const Vec3& p) {
    lo = {std::min(lo.x, p.x), std::min(lo.y, p.y), std::min(lo.z, p.z)};
    hi = {std::max(hi.x, p.x), std::max(hi.y, p.y), std::max(hi.z, p.z)};
  }
  void Add(const Box& b) {
    lo = {std::min(lo.x, b.lo.x), std::min(lo.y, b.lo.y), std::min(lo.z, b.lo.z)};
    hi = {std::max(hi.x, b.hi.x), std::max(hi.y, b.hi.y), std::max(hi.z, b.hi.z)};
  }
  bool empty() const { return lo.x > hi.x; }
  // The distance to another box (0 when they overlap or touch).
  double Distance(const Box& b) const {
    double s = 0;
    for (int k = 0; k < 3; ++k) {
      const double gap = std::max({0.0, lo[k] - b.hi[k], b.lo[k] - hi[k]});
      s += gap * gap;
    }
    return std::sqrt(s);
  }
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_BOX_H_
