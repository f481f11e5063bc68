// Limits on the calls a server holds open (docs/service/server.md: --max-uploads,
// --upload-idle-seconds, --max-watchers, --max-progress-watchers): each open call costs memory or a file descriptor
// until it ends, so past a limit new ones are refused (RESOURCE_EXHAUSTED) rather than taking the
// server down, and an upload that stops sending is cancelled after its idle time.
#ifndef RADIOSITY_SERVER_CALL_LIMITS_H_
#define RADIOSITY_SERVER_CALL_LIMITS_H_

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <set>
#include <thread>

#include "absl/status/status.h"

namespace radiosity::service {

struct CallLimitOptions {
  int64_t max_uploads = 16;              // Uploads open at once (call start to stored).
  double upload_idle_seconds = 60;       // An upload that sends nothing this long is cancelled.
  int64_t max_full_watchers = 256;       // WatchJob streams with values.
  int64_t max_progress_watchers = 4096;  // WatchJob streams with progress only.
};

class CallLimits {
 public:
  explicit CallLimits(const CallLimitOptions& options);
  ~CallLimits();  // Stops the idle sweeper.
  CallLimits(const CallLimits&) = delete;
  CallLimits& operator=(const CallLimits&) = delete;

  // An open upload, as its reactor holds it.
  class Upload {
   public:
    // A message arrived: the idle clock starts again.
    void Touch();
    // While busy (validating what was received) the upload is not idle, whatever the clock.
    void SetBusy(bool busy) { busy_ = busy; }
    // The sweeper cancelled the call for idleness.
    bool TimedOut() const { return timed_out_; }

   private:
    friend class CallLimits;
    grpc::CallbackServerContext* context_ = nullptr;
    std::atomic<int64_t> last_ns_{0};
    std::atomic<bool> busy_{false};
    std::atomic<bool> timed_out_{false};
  };

  // Takes a place for `upload` (whose call is `context`) until ReleaseUpload; RESOURCE_EXHAUSTED
  // naming --max-uploads when all are taken.
  absl::Status AdmitUpload(Upload* upload, grpc::CallbackServerContext* context);
  // Gives the place back (from the reactor's OnDone, before it is deleted). Only after an admit.
  void ReleaseUpload(Upload* upload);

  // Takes a watcher's place (full or progress-only) until ReleaseWatcher; RESOURCE_EXHAUSTED
  // naming the flag when all are taken.
  absl::Status AdmitWatcher(bool progress_only);
  void ReleaseWatcher(bool progress_only);

  int64_t open_uploads() const;

 private:
  void SweepLoop();

  const CallLimitOptions options_;
  mutable std::mutex mu_;
  std::set<Upload*> uploads_;
  std::atomic<int64_t> full_watchers_{0};
  std::atomic<int64_t> progress_watchers_{0};
  std::condition_variable cv_;
  bool stopping_ = false;
  std::thread sweeper_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_CALL_LIMITS_H_
