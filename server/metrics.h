// Counters a person can read: Prometheus text exposition format (version 0.0.4), served by a tiny
// HTTP responder on an optional port (`--metrics-port`), e.g.
//   radiosity_jobs_created_total 12
//   radiosity_queue_depth 3
//   radiosity_rays_per_second 4.2e+06
#ifndef RADIOSITY_SERVER_METRICS_H_
#define RADIOSITY_SERVER_METRICS_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "absl/status/statusor.h"

namespace radiosity::service {

struct Metrics {
  std::atomic<int64_t> jobs_created{0};
  std::atomic<int64_t> jobs_succeeded{0};
  std::atomic<int64_t> jobs_failed{0};
  std::atomic<int64_t> jobs_cancelled{0};
  std::atomic<int64_t> jobs_rejected{0};  // CreateJob refused with RESOURCE_EXHAUSTED.
  std::atomic<int64_t> rays{0};  // Rays traced by finished solves and running ones' last step.
  std::atomic<int64_t> uploads{0};
  std::atomic<int64_t> upload_bytes{0};
  std::atomic<int64_t> watchers{0};             // Open WatchJob streams.
  std::atomic<int64_t> uploads_validating{0};   // Uploads received whole, being validated.
  std::atomic<int64_t> creates_in_progress{0};  // CreateJob calls checking their request.
  std::atomic<int64_t> snapshots{0};            // Snapshots published by solves.
  std::atomic<int64_t> snapshots_sent{0};       // Snapshots written to watchers (all chunks).
  std::atomic<int64_t> snapshots_skipped{0};    // Snapshots a slow watcher never got (latest wins).
  std::atomic<int64_t> requests{0};
  std::atomic<int64_t> request_errors{0};

  // Gauges computed when scraped.
  std::function<int64_t()> queue_depth;
  std::function<int64_t()> running_jobs;
  std::function<double()> rays_per_second;  // Summed over running jobs.

  std::string Prometheus() const;
};

// Bytes of snapshot radiosity arrays alive in this process (published, queued for watchers or
// being written): the quantity a slow reader must not make grow.
std::atomic<int64_t>& SnapshotBytesLive();
// Bytes of announced mesh geometry alive in this process (MeshAnnouncement): one or two versions
// per running job, plus the ones being written to watchers.
std::atomic<int64_t>& MeshBytesLive();

// A minimal HTTP/1.0 responder: answers every request on `host:port` with the text of `body()`.
class MetricsHttpServer {
 public:
  // Binds at once (port 0 picks a free one); serves on its own thread until destroyed.
  static absl::StatusOr<std::unique_ptr<MetricsHttpServer>> Start(
      const std::string& host, int port, std::function<std::string()> body);
  ~MetricsHttpServer();
  int port() const { return port_; }

 private:
  MetricsHttpServer() = default;
  void Serve();
  int fd_ = -1;
  int port_ = 0;
  std::function<std::string()> body_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_METRICS_H_
