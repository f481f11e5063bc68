#include "server/call_limits.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "server/logging.h"

namespace radiosity::service {
namespace {

int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

}  // namespace

void CallLimits::Upload::Touch() { last_ns_ = NowNs(); }

CallLimits::CallLimits(const CallLimitOptions& options) : options_(options) {
  if (options_.upload_idle_seconds > 0) sweeper_ = std::thread([this] { SweepLoop(); });
}

CallLimits::~CallLimits() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stopping_ = true;
  }
  cv_.notify_all();
  if (sweeper_.joinable()) sweeper_.join();
}

absl::Status CallLimits::AdmitUpload(Upload* upload, grpc::CallbackServerContext* context) {
  std::lock_guard<std::mutex> lock(mu_);
  if (static_cast<int64_t>(uploads_.size()) >= options_.max_uploads) {
    return absl::ResourceExhaustedError(
        absl::StrCat(uploads_.size(), " uploads are open, this server's limit (--max-uploads ",
                     options_.max_uploads, "); retry later"));
  }
  upload->context_ = context;
  upload->Touch();
  uploads_.insert(upload);
  return absl::OkStatus();
}

void CallLimits::ReleaseUpload(Upload* upload) {
  std::lock_guard<std::mutex> lock(mu_);
  uploads_.erase(upload);
}

int64_t CallLimits::open_uploads() const {
  std::lock_guard<std::mutex> lock(mu_);
  return static_cast<int64_t>(uploads_.size());
}

absl::Status CallLimits::AdmitWatcher(bool progress_only) {
  std::atomic<int64_t>& count = progress_only ? progress_watchers_ : full_watchers_;
  const int64_t limit = progress_only ? options_.max_progress_watchers : options_.max_full_watchers;
  if (count.fetch_add(1) >= limit) {
    --count;
    return absl::ResourceExhaustedError(
        absl::StrCat(limit, progress_only ? " progress-only" : "",
                     " WatchJob streams are open, this server's "
                     "limit (",
                     progress_only ? "--max-progress-watchers " : "--max-watchers ", limit,
                     "); retry later", progress_only ? "" : ", or watch with progress_only"));
  }
  return absl::OkStatus();
}

void CallLimits::ReleaseWatcher(bool progress_only) {
  --(progress_only ? progress_watchers_ : full_watchers_);
}

void CallLimits::SweepLoop() {
  const int64_t idle_ns = static_cast<int64_t>(options_.upload_idle_seconds * 1e9);
  // Checked four times per idle period (at most once a second): an idle upload ends within
  // 1.25 idle periods.
  const auto period = std::chrono::milliseconds(
      std::clamp<int64_t>(static_cast<int64_t>(options_.upload_idle_seconds * 250), 10, 1000));
  std::unique_lock<std::mutex> lock(mu_);
  while (!stopping_) {
    cv_.wait_for(lock, period, [this] { return stopping_; });
    if (stopping_) break;
    const int64_t now = NowNs();
    for (Upload* upload : uploads_) {
      if (upload->busy_ || upload->timed_out_ || now - upload->last_ns_ < idle_ns) continue;
      // Under mu_: the reactor releases its place (under mu_) before it is deleted.
      upload->timed_out_ = true;
      upload->context_->TryCancel();
      LogLine("upload_idle")
          .Str("detail", absl::StrCat("nothing received for ", options_.upload_idle_seconds,
                                      " s (--upload-idle-seconds); cancelled"))
          .Warn();
    }
  }
}

}  // namespace radiosity::service
