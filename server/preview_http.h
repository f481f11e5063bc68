// The browser preview (docs/service/preview.md): an HTTP server (`--http-port`) that
// serves a page listing the caller's jobs and showing one converging (server/web/), and the two
// JSON/event endpoints the page reads:
//
//   GET /api/jobs                 ListJobs as JSON ({"jobs": [...], "next_page_token": ...}).
//   GET /api/jobs/{id}/events     WatchJob (include_mesh, include_errors) as Server-Sent Events:
//                                 `mesh` and `snapshot` events, one per WatchJobResponse message,
//                                 each a JSON object whose float arrays are base64 of
//                                 little-endian float32; then `end` with the call's status.
//                                 `id:` is the snapshot's sequence, and a reconnect's
//                                 Last-Event-ID (or ?after_sequence=N) resumes after it.
//
// It is a gateway, not a second service: each request is a call of the RadiosityService over the
// server's in-process channel, carrying the request's "Authorization: Bearer TOKEN" header as
// its metadata, so tenants, tokens, limits, ended jobs and latest-wins are exactly WatchJob's and
// ListJobs'. gRPC errors become HTTP statuses (401, 404, 429, ...) with a JSON body
// {"error": {"code": "NOT_FOUND", "message": ...}} before a stream starts, and the `end` event
// after. With TLS on the gRPC port, the preview serves HTTPS with the same certificate (and
// requires the same client certificates).
//
// Every event stream waits on its call with a timeout, so that a disconnected browser is noticed
// (a keep-alive comment fails to write) and Stop() ends every stream within a fraction of a
// second.
#ifndef RADIOSITY_SERVER_PREVIEW_HTTP_H_
#define RADIOSITY_SERVER_PREVIEW_HTTP_H_

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <memory>
#include <string>
#include <thread>

#include "absl/status/statusor.h"

namespace httplib {
class Server;
struct Request;
struct Response;
}  // namespace httplib

namespace radiosity::service {

struct PreviewHttpOptions {
  std::string host = "127.0.0.1";
  int port = 0;  // 0 picks a free one.
  // HTTPS with this PEM certificate chain and key; with client_ca, clients must present a
  // certificate it signed. All empty: plain HTTP.
  std::string tls_cert_file;
  std::string tls_key_file;
  std::string tls_client_ca_file;
  // Event streams open at once; more are refused with 503.
  int max_streams = 16;
};

class PreviewHttpServer {
 public:
  // Binds at once and serves on its own threads; every request is a call on `channel`.
  static absl::StatusOr<std::unique_ptr<PreviewHttpServer>> Start(
      const PreviewHttpOptions& options, std::shared_ptr<grpc::Channel> channel);
  ~PreviewHttpServer();
  PreviewHttpServer(const PreviewHttpServer&) = delete;
  PreviewHttpServer& operator=(const PreviewHttpServer&) = delete;

  int port() const { return port_; }
  bool tls() const { return tls_; }
  // Ends the event streams, stops listening and joins its threads. Idempotent.
  void Stop();

 private:
  PreviewHttpServer() = default;
  void Route();
  // GET /api/jobs/{id}/events.
  void Events(const httplib::Request& req, httplib::Response& res);

  PreviewHttpOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<httplib::Server> http_;
  std::thread thread_;
  int port_ = 0;
  bool tls_ = false;
  std::atomic<bool> stopping_{false};
  std::atomic<int> streams_{0};
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_PREVIEW_HTTP_H_
