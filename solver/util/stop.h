// When long work must end: a stop flag raised by another thread (a cancel, a shutdown) or a
// deadline. Cheap enough to check inside inner loops (a relaxed atomic load and, with a deadline,
// a clock read), so that every loop whose length depends on the input can check it (Mitsuba 3's
// should_stop()).
#ifndef RADIOSITY_SOLVER_UTIL_STOP_H_
#define RADIOSITY_SOLVER_UTIL_STOP_H_

#include <atomic>
#include <chrono>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace radiosity {

class StopToken {
 public:
  // Never stops.
  StopToken() = default;
  // Stops when *flag becomes true (flag may be null) or `seconds` after now (<= 0: no deadline).
  StopToken(const std::atomic<bool>* flag, double seconds) : StopToken(flag, nullptr, seconds) {}
  // Stops when either flag (each may be null) becomes true, or at the deadline.
  StopToken(const std::atomic<bool>* flag, const std::atomic<bool>* also, double seconds)
      : flag_(flag),
        also_(also),
        has_deadline_(seconds > 0),
        deadline_(has_deadline_ ? std::chrono::steady_clock::now() +
                                      std::chrono::duration_cast<std::chrono::nanoseconds>(
                                          std::chrono::duration<double>(seconds))
                                : std::chrono::steady_clock::time_point::max()) {}

  // Once true, stays true.
  bool ShouldStop() const { return Cancelled() || Expired(); }
  bool Cancelled() const {
    return (flag_ != nullptr && flag_->load(std::memory_order_relaxed)) ||
           (also_ != nullptr && also_->load(std::memory_order_relaxed));
  }
  bool Expired() const { return has_deadline_ && std::chrono::steady_clock::now() >= deadline_; }

 private:
  const std::atomic<bool>* flag_ = nullptr;
  const std::atomic<bool>* also_ = nullptr;
  bool has_deadline_ = false;
  std::chrono::steady_clock::time_point deadline_ = std::chrono::steady_clock::time_point::max();
};

// OK while `stop` (may be null) has not stopped; else CANCELLED ("stopped while WHAT") for a
// raised flag or DEADLINE_EXCEEDED for a passed deadline: how a step that cannot return partial
// work ends early.
inline absl::Status StopStatus(const StopToken* stop, const char* what) {
  if (stop == nullptr || !stop->ShouldStop()) return absl::OkStatus();
  if (stop->Cancelled()) return absl::CancelledError(absl::StrCat("stopped while ", what));
  return absl::DeadlineExceededError(absl::StrCat("the time limit passed while ", what));
}

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_UTIL_STOP_H_
