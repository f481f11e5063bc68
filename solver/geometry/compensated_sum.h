// Compensated (Kahan-Babuska-Neumaier) summation of RGB power, for the energy books that receive
// one contribution per ray: a solve of 10^9 rays adds 10^9 terms to the absorbed total.
//
// Plain double summation of n terms has a worst-case relative error of about n * 2^-53 (1e-7 at
// n = 1e9, Higham, "Accuracy and Stability of Numerical Algorithms", 2nd ed., section 4.2);
// Neumaier's variant (Neumaier 1974, "Rundungsfehleranalyse einiger Verfahren zur Summation
// endlicher Summen") carries the rounding error of every addition in a second accumulator, so
// the error is about 2^-53 of the sum of magnitudes whatever n, also when a term is larger than
// the running sum. The project builds without -ffast-math, which would remove the compensation.
#ifndef RADIOSITY_SOLVER_GEOMETRY_COMPENSATED_SUM_H_
#define RADIOSITY_SOLVER_GEOMETRY_COMPENSATED_SUM_H_

#include <cmath>

#include "solver/geometry/vec.h"

namespace radiosity {

// One channel: Total() is the compensated total of every Add().
class CompensatedSum {
 public:
  void Add(double x) {
    const double t = sum_ + x;
    // The low-order bits lost by t: of x when |sum| >= |x|, of sum otherwise (Neumaier).
    if (std::fabs(sum_) >= std::fabs(x)) {
      compensation_ += (sum_ - t) + x;
    } else {
      compensation_ += (x - t) + sum_;
    }
    sum_ = t;
  }
  double Total() const { return sum_ + compensation_; }

 private:
  double sum_ = 0;
  double compensation_ = 0;
};

// Three channels, as Rgb: `books += power` accumulates, `books.Total()` reads the total.
class CompensatedRgb {
 public:
  CompensatedRgb& operator+=(const Rgb& c) {
    r_.Add(c.r);
    g_.Add(c.g);
    b_.Add(c.b);
    return *this;
  }
  Rgb Total() const { return {r_.Total(), g_.Total(), b_.Total()}; }

 private:
  CompensatedSum r_, g_, b_;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_COMPENSATED_SUM_H_
