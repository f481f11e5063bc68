// Closed intervals that option values must lie in, and how messages print them.
#ifndef RADIOSITY_SOLVER_UTIL_BOUNDS_H_
#define RADIOSITY_SOLVER_UTIL_BOUNDS_H_

#include <cmath>

namespace radiosity {

struct Bounds {
  double lo, hi;
  const char* text;  // As messages print it, e.g. "[1, 4096]".
  bool Contains(double v) const { return std::isfinite(v) && v >= lo && v <= hi; }
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_UTIL_BOUNDS_H_
