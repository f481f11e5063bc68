#include "server/snapshots.h"

#include <algorithm>

#include "server/metrics.h"

namespace radiosity::service {

FloatBlock::FloatBlock(std::vector<float> data) : data_(std::move(data)) {
  SnapshotBytesLive() += static_cast<int64_t>(data_.size() * sizeof(float));
}

FloatBlock::~FloatBlock() {
  SnapshotBytesLive() -= static_cast<int64_t>(data_.size() * sizeof(float));
}

std::shared_ptr<const FloatBlock> PackRadiosity(const Solution& solution) {
  std::vector<float> data(solution.radiosity.size() * 3);
  for (size_t i = 0; i < solution.radiosity.size(); ++i) {
    const Rgb& b = solution.radiosity[i];
    data[3 * i] = static_cast<float>(b.r);
    data[3 * i + 1] = static_cast<float>(b.g);
    data[3 * i + 2] = static_cast<float>(b.b);
  }
  return std::make_shared<const FloatBlock>(std::move(data));
}

void JobChannel::Publish(SnapshotPtr snapshot) {
  std::lock_guard<std::mutex> lock(mu_);
  if (closed_) return;
  latest_ = std::move(snapshot);
  for (SnapshotSink* sink : sinks_) sink->OnSnapshot(latest_);
}

void JobChannel::Close(const absl::Status& status) {
  std::lock_guard<std::mutex> lock(mu_);
  if (closed_) return;
  closed_ = true;
  close_status_ = status;
  for (SnapshotSink* sink : sinks_) sink->OnClose(status);
}

void JobChannel::Subscribe(SnapshotSink* sink) {
  std::lock_guard<std::mutex> lock(mu_);
  sinks_.push_back(sink);
  if (closed_) {
    sink->OnClose(close_status_);
  } else if (latest_) {
    sink->OnSnapshot(latest_);
  }
}

void JobChannel::Unsubscribe(SnapshotSink* sink) {
  std::lock_guard<std::mutex> lock(mu_);
  sinks_.erase(std::remove(sinks_.begin(), sinks_.end(), sink), sinks_.end());
}

SnapshotPtr JobChannel::latest() const {
  std::lock_guard<std::mutex> lock(mu_);
  return latest_;
}

}  // namespace radiosity::service
