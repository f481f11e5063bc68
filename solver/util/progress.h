// Progress of a long phase (meshing, building the ray-tracing structure, writing results),
// reported from the same loops that check the stop flag (stop.h): Mitsuba 3's ProgressReporter,
// reduced to a callback.
#ifndef RADIOSITY_SOLVER_UTIL_PROGRESS_H_
#define RADIOSITY_SOLVER_UTIL_PROGRESS_H_

#include <functional>

namespace radiosity {

// Called with the fraction of the work done, from 0 to 1, non-decreasing; possibly from worker
// threads (Embree's build), one call at a time. Empty: nothing is reported.
using ProgressCallback = std::function<void(double fraction)>;

// Passes on to a callback the fractions that moved by at least `step` since the last one passed
// on, and 1 once, so that a loop may report at every iteration. Not thread-safe.
class StepReporter {
 public:
  // `callback` (may be empty) must outlive the reporter.
  explicit StepReporter(const ProgressCallback& callback, double step = 0.01)
      : callback_(&callback), step_(step) {}
  void Report(double fraction) {
    if (!*callback_ || last_ >= 1) return;
    if (fraction >= 1 || fraction >= last_ + step_) {
      last_ = fraction >= 1 ? 1 : fraction;
      (*callback_)(last_);
    }
  }

 private:
  const ProgressCallback* callback_;
  double step_;
  double last_ = -1;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_UTIL_PROGRESS_H_
