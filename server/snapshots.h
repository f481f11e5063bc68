// Snapshots of a running solve and their fan-out to watchers (WatchJob streams).
//
// A JobChannel holds only the newest snapshot of its job; each watcher registers a SnapshotSink
// and is handed every new snapshot as it is published. A sink keeps at most one snapshot waiting
// (the newest replaces an older one still waiting: latest wins), so a slow reader costs a bounded
// amount of memory however fast the solver publishes. Snapshots are immutable and shared.
#ifndef RADIOSITY_SERVER_SNAPSHOTS_H_
#define RADIOSITY_SERVER_SNAPSHOTS_H_

#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include "absl/status/status.h"
#include "radiosity/v1/service.pb.h"
#include "solver/solution.h"

namespace radiosity::service {

// Packed radiosity, (2 e + side) x 3 + channel, counted in SnapshotBytesLive() while alive.
class FloatBlock {
 public:
  explicit FloatBlock(std::vector<float> data);
  ~FloatBlock();
  FloatBlock(const FloatBlock&) = delete;
  FloatBlock& operator=(const FloatBlock&) = delete;
  const std::vector<float>& data() const { return data_; }

 private:
  std::vector<float> data_;
};

// The radiosity of a solution as packed floats.
std::shared_ptr<const FloatBlock> PackRadiosity(const Solution& solution);

struct Snapshot {
  int64_t sequence = 0;
  v1::JobState state = v1::JOB_STATE_UNSPECIFIED;
  v1::JobProgress progress;
  bool final = false;
  v1::JobError error;
  int64_t elements = 0;
  std::shared_ptr<const FloatBlock> radiosity;  // Null when there is none.
};
using SnapshotPtr = std::shared_ptr<const Snapshot>;

class SnapshotSink {
 public:
  virtual ~SnapshotSink() = default;
  // A new snapshot (called under the channel's lock: must not block or call back into it).
  virtual void OnSnapshot(const SnapshotPtr& snapshot) = 0;
  // The channel closed without a final snapshot (the server is shutting down).
  virtual void OnClose(const absl::Status& status) = 0;
};

class JobChannel {
 public:
  // Makes `snapshot` the newest and hands it to every sink.
  void Publish(SnapshotPtr snapshot);
  // Ends the channel without a final snapshot; sinks (present and future) get OnClose(status).
  void Close(const absl::Status& status);
  // Registers a sink and hands it the newest snapshot, if any (or OnClose if closed).
  void Subscribe(SnapshotSink* sink);
  // After this returns, the sink is never called again.
  void Unsubscribe(SnapshotSink* sink);
  SnapshotPtr latest() const;

 private:
  mutable std::mutex mu_;
  SnapshotPtr latest_;
  std::vector<SnapshotSink*> sinks_;
  bool closed_ = false;
  absl::Status close_status_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_SNAPSHOTS_H_
