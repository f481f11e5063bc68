#include "server/metrics.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace radiosity::service {

std::atomic<int64_t>& SnapshotBytesLive() {
  static std::atomic<int64_t> bytes{0};
  return bytes;
}

std::atomic<int64_t>& MeshBytesLive() {
  static std::atomic<int64_t> bytes{0};
  return bytes;
}

std::string Metrics::Prometheus() const {
  std::string out;
  auto counter = [&](const char* name, const char* help, int64_t value) {
    absl::StrAppend(&out, "# HELP ", name, " ", help, "\n# TYPE ", name, " counter\n", name, " ",
                    value, "\n");
  };
  auto gauge = [&](const char* name, const char* help, double value) {
    absl::StrAppend(&out, "# HELP ", name, " ", help, "\n# TYPE ", name, " gauge\n", name, " ",
                    absl::StrFormat("%.6g", value), "\n");
  };
  counter("radiosity_jobs_created_total", "Jobs accepted by CreateJob.", jobs_created.load());
  counter("radiosity_jobs_succeeded_total", "Jobs that ended SUCCEEDED.", jobs_succeeded.load());
  counter("radiosity_jobs_failed_total", "Jobs that ended FAILED.", jobs_failed.load());
  counter("radiosity_jobs_cancelled_total", "Jobs that ended CANCELLED.", jobs_cancelled.load());
  counter("radiosity_jobs_rejected_total", "CreateJob calls refused because the queue was full.",
          jobs_rejected.load());
  counter("radiosity_rays_total", "Rays traced by solves.", rays.load());
  counter("radiosity_uploads_total", "Scenes uploaded.", uploads.load());
  counter("radiosity_upload_bytes_total", "Bytes of scene files received.", upload_bytes.load());
  counter("radiosity_snapshots_total", "Snapshots published by running solves.", snapshots.load());
  counter("radiosity_snapshots_sent_total", "Snapshots written to WatchJob streams.",
          snapshots_sent.load());
  counter("radiosity_snapshots_skipped_total",
          "Snapshots a slow watcher did not get because a newer one replaced them.",
          snapshots_skipped.load());
  counter("radiosity_requests_total", "RPCs handled.", requests.load());
  counter("radiosity_request_errors_total", "RPCs that ended with an error status.",
          request_errors.load());
  gauge("radiosity_queue_depth", "Jobs waiting for a worker.",
        queue_depth ? static_cast<double>(queue_depth()) : 0);
  gauge("radiosity_running_jobs", "Jobs being solved.",
        running_jobs ? static_cast<double>(running_jobs()) : 0);
  gauge("radiosity_rays_per_second", "Ray throughput of the running solves.",
        rays_per_second ? rays_per_second() : 0);
  gauge("radiosity_watchers", "Open WatchJob streams.", static_cast<double>(watchers.load()));
  gauge("radiosity_uploads_validating", "Uploads received whole and being validated.",
        static_cast<double>(uploads_validating.load()));
  gauge("radiosity_creates_in_progress",
        "CreateJob calls checking their request (loading the scene, counting elements).",
        static_cast<double>(creates_in_progress.load()));
  gauge("radiosity_snapshot_bytes", "Bytes of snapshot arrays held in memory.",
        static_cast<double>(SnapshotBytesLive().load()));
  gauge("radiosity_mesh_geometry_bytes", "Bytes of announced mesh geometry held in memory.",
        static_cast<double>(MeshBytesLive().load()));
  return out;
}

absl::StatusOr<std::unique_ptr<MetricsHttpServer>> MetricsHttpServer::Start(
    const std::string& host, int port, std::function<std::string()> body) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* result = nullptr;
  std::string service = absl::StrCat(port);
  int rc = getaddrinfo(host.empty() ? nullptr : host.c_str(), service.c_str(), &hints, &result);
  if (rc != 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("metrics address ", host, ":", port, ": ", gai_strerror(rc)));
  }
  int fd = socket(result->ai_family, result->ai_socktype | SOCK_CLOEXEC, result->ai_protocol);
  int one = 1;
  if (fd >= 0) setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  if (fd < 0 || bind(fd, result->ai_addr, result->ai_addrlen) != 0 || listen(fd, 16) != 0) {
    std::string error = std::strerror(errno);
    if (fd >= 0) close(fd);
    freeaddrinfo(result);
    return absl::UnavailableError(
        absl::StrCat("metrics address ", host, ":", port, ": cannot listen: ", error));
  }
  freeaddrinfo(result);
  sockaddr_storage addr{};
  socklen_t len = sizeof(addr);
  getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  std::unique_ptr<MetricsHttpServer> server(new MetricsHttpServer());
  server->fd_ = fd;
  server->port_ =
      ntohs(addr.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&addr)->sin6_port
                                       : reinterpret_cast<sockaddr_in*>(&addr)->sin_port);
  server->body_ = std::move(body);
  server->thread_ = std::thread([s = server.get()] { s->Serve(); });
  return server;
}

MetricsHttpServer::~MetricsHttpServer() {
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  if (fd_ >= 0) close(fd_);
}

void MetricsHttpServer::Serve() {
  while (!stop_) {
    pollfd p{fd_, POLLIN, 0};
    if (poll(&p, 1, 100) <= 0) continue;
    int client = accept4(fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (client < 0) continue;
    // Read the request head (bounded: 8 KiB or 1 s), then answer whatever it asked.
    char buffer[8192];
    size_t got = 0;
    for (int i = 0; i < 10 && got < sizeof(buffer); ++i) {
      pollfd c{client, POLLIN, 0};
      if (poll(&c, 1, 100) <= 0) continue;
      ssize_t n = recv(client, buffer + got, sizeof(buffer) - got, 0);
      if (n <= 0) break;
      got += static_cast<size_t>(n);
      if (std::string_view(buffer, got).find("\r\n\r\n") != std::string_view::npos) break;
    }
    std::string text = body_();
    std::string response = absl::StrCat(
        "HTTP/1.0 200 OK\r\nContent-Type: text/plain; version=0.0.4\r\nContent-Length: ",
        text.size(), "\r\nConnection: close\r\n\r\n", text);
    size_t sent = 0;
    while (sent < response.size()) {
      ssize_t n = send(client, response.data() + sent, response.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) break;
      sent += static_cast<size_t>(n);
    }
    close(client);
  }
}

}  // namespace radiosity::service
