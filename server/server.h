// A running radiosity service: the gRPC server (RadiosityService, grpc.health.v1, optionally
// reflection), its job manager and store, and the optional metrics responder. Used by the
// `radiosity-server` binary, by the CLI in-process (no --server), and by the tests.
#ifndef RADIOSITY_SERVER_SERVER_H_
#define RADIOSITY_SERVER_SERVER_H_

#include <grpcpp/grpcpp.h>

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "server/jobs.h"
#include "server/metrics.h"
#include "server/preview_http.h"

namespace radiosity::service {

// The name under which the health service reports the RadiosityService.
inline constexpr char kServiceName[] = "radiosity.v1.RadiosityService";

struct ServerOptions {
  ServiceOptions service;
  // HOST:PORT to listen on (port 0 picks a free one); empty: in-process channels only.
  std::string listen;
  // TLS (docs/service/security.md): PEM certificate chain and private key of the server;
  // with `tls_client_ca`, clients must present a certificate that CA signed.
  std::string tls_cert_file;
  std::string tls_key_file;
  std::string tls_client_ca_file;
  // "TOKEN TENANT" lines (server/tenants.h): every call needs a bearer token; needs TLS.
  std::string tokens_file;
  // Listen on a non-loopback address without credentials (tokens or client certificates).
  bool insecure = false;
  // Port of the Prometheus text responder, on the host of `listen` (0 picks a free one, -1: off).
  int metrics_port = -1;
  // Port of the browser preview (server/preview_http.h), on the same host as the metrics
  // responder; HTTPS when the gRPC port has TLS (0 picks a free one, -1: off).
  int http_port = -1;
  // Serve grpc.reflection (v1alpha on Debian's gRPC). Once on, on for every server in the process.
  bool reflection = false;
  // How long Shutdown() lets calls in flight finish before cancelling them.
  double shutdown_grace_seconds = 5;
  // spdlog level of the JSON-lines log: trace, debug, info, warn, error, off.
  std::string log_level = "info";
};

class Server {
 public:
  static absl::StatusOr<std::unique_ptr<Server>> Start(const ServerOptions& options);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // The port listened on (0 when not listening).
  int port() const { return port_; }
  int metrics_port() const { return metrics_http_ ? metrics_http_->port() : 0; }
  int http_port() const { return preview_http_ ? preview_http_->port() : 0; }
  // A channel to this server inside the process (no socket).
  std::shared_ptr<grpc::Channel> InProcessChannel();
  // Graceful: health NOT_SERVING, no new jobs, running solves stopped and queued again, watch
  // streams ended with UNAVAILABLE, calls in flight given the grace period. Idempotent.
  void Shutdown();
  // Blocks until Shutdown() has completed (called from another thread).
  void Wait();

  Metrics& metrics() { return *metrics_; }
  JobManager& jobs() { return *jobs_; }

 private:
  Server() = default;
  ServerOptions options_;
  std::unique_ptr<Store> store_;
  std::unique_ptr<Metrics> metrics_;
  std::unique_ptr<JobManager> jobs_;
  std::unique_ptr<grpc::Service> service_;
  std::unique_ptr<grpc::Service> reflection_v1_;  // With options.reflection.
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<MetricsHttpServer> metrics_http_;
  std::unique_ptr<PreviewHttpServer> preview_http_;
  int port_ = 0;
  int lock_fd_ = -1;  // DataDir::Lock(), released when the server is destroyed.
  std::mutex mu_;
  bool shut_down_ = false;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_SERVER_H_
