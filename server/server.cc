#include "server/server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "server/logging.h"
#include "server/service_impl.h"
#include "solver/input/model_loader.h"

namespace radiosity::service {

absl::StatusOr<std::unique_ptr<Server>> Server::Start(const ServerOptions& options) {
  if (!SetLogLevel(options.log_level)) {
    return absl::InvalidArgumentError(absl::StrCat("unknown log level '", options.log_level, "'"));
  }
  if (options.service.data_dir.empty()) return absl::InvalidArgumentError("no data directory");
  std::unique_ptr<Server> s(new Server());
  s->options_ = options;
  DataDir dir(options.service.data_dir);
  if (absl::Status st = dir.Create(); !st.ok()) return st;
  absl::StatusOr<int> lock = dir.Lock();
  if (!lock.ok()) return lock.status();
  s->lock_fd_ = *lock;
  absl::StatusOr<std::unique_ptr<Store>> store = Store::Open(dir.Database());
  if (!store.ok()) return store.status();
  s->store_ = *std::move(store);
  s->metrics_ = std::make_unique<Metrics>();
  s->jobs_ = std::make_unique<JobManager>(options.service, dir, s->store_.get(), s->metrics_.get());
  JobManager* jobs = s->jobs_.get();
  s->metrics_->queue_depth = [jobs] { return jobs->QueueDepth(); };
  s->metrics_->running_jobs = [jobs] { return jobs->RunningJobs(); };
  s->metrics_->rays_per_second = [jobs] { return jobs->RaysPerSecond(); };
  if (absl::Status st = s->jobs_->Start(); !st.ok()) return st;
  s->service_ = std::make_unique<RadiosityServiceImpl>(options.service, dir, s->store_.get(),
                                                       s->jobs_.get(), s->metrics_.get());

  static std::once_flag health_once;
  std::call_once(health_once, [] { grpc::EnableDefaultHealthCheckService(true); });
  if (options.reflection) {
    static std::once_flag reflection_once;
    std::call_once(reflection_once,
                   [] { grpc::reflection::InitProtoReflectionServerBuilderPlugin(); });
  }
  grpc::ServerBuilder builder;
  if (!options.listen.empty()) {
    builder.AddListeningPort(options.listen, grpc::InsecureServerCredentials(), &s->port_);
  }
  builder.RegisterService(s->service_.get());
  builder.SetMaxReceiveMessageSize(4 << 20);
  builder.SetMaxSendMessageSize(4 << 20);
  // Keepalive: ping idle connections every 60 s, drop them after 20 s without an answer; accept
  // clients' pings every 10 s or more, also between calls.
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, 60'000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 20'000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MAX_PINGS_WITHOUT_DATA, 0);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 10'000);
  s->server_ = builder.BuildAndStart();
  if (!s->server_ || (!options.listen.empty() && s->port_ == 0)) {
    s->jobs_->BeginShutdown();
    s->jobs_->Join();
    return absl::UnavailableError(absl::StrCat("cannot listen on ", options.listen));
  }
  grpc::HealthCheckServiceInterface* health = s->server_->GetHealthCheckService();
  if (health) {
    health->SetServingStatus(kServiceName, true);
    health->SetServingStatus(true);
    // NOT_SERVING while the store cannot be written (a full disk), SERVING again once it can.
    Server* server = s.get();
    s->jobs_->OnStoreWritableChange([health, server](bool writable) {
      {
        std::lock_guard<std::mutex> lock(server->mu_);
        if (server->shut_down_) return;
      }
      health->SetServingStatus(kServiceName, writable);
      health->SetServingStatus(writable);
    });
  }
  if (options.metrics_port >= 0) {
    std::string host = "127.0.0.1";
    if (size_t colon = options.listen.rfind(':'); colon != std::string::npos) {
      host = options.listen.substr(0, colon);
      if (host.size() >= 2 && host.front() == '[') host = host.substr(1, host.size() - 2);
    }
    absl::StatusOr<std::unique_ptr<MetricsHttpServer>> http = MetricsHttpServer::Start(
        host, options.metrics_port, [m = s->metrics_.get()] { return m->Prometheus(); });
    if (!http.ok()) {
      s->Shutdown();
      return http.status();
    }
    s->metrics_http_ = *std::move(http);
  }
  LogLine("server_started")
      .Str("listen", options.listen)
      .Int("port", s->port_)
      .Int("metrics_port", s->metrics_port())
      .Str("data_dir", options.service.data_dir)
      .Int("workers", options.service.workers)
      .Int("max_queued", options.service.max_queued)
      .Int("threads_per_job", options.service.threads_per_job)
      .Str("model_importer", ModelImporter())
      .Info();
  if (ModelImporter().empty()) {
    LogLine("model_importer_missing")
        .Str("detail",
             "radiosity-import is not beside this executable and RADIOSITY_IMPORT is unset: "
             "models are read inside the server, where a hostile file can crash or hang it")
        .Warn();
  }
  return s;
}

Server::~Server() {
  Shutdown();
  server_.reset();
  service_.reset();
  jobs_.reset();
  store_.reset();
  if (lock_fd_ >= 0) close(lock_fd_);
}

std::shared_ptr<grpc::Channel> Server::InProcessChannel() {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(4 << 20);
  return server_->InProcessChannel(args);
}

void Server::Shutdown() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (shut_down_ || !server_) return;
    shut_down_ = true;
  }
  LogLine("server_stopping").Info();
  if (grpc::HealthCheckServiceInterface* health = server_->GetHealthCheckService()) {
    health->SetServingStatus(kServiceName, false);
    health->SetServingStatus(false);
  }
  jobs_->BeginShutdown();
  // Calls in flight get the grace period less the time the workers' joins may need after them
  // (radiosity-server exits when the grace period ends, finished or not).
  const double calls_grace = std::max(0.0, options_.shutdown_grace_seconds - 0.5);
  auto deadline = std::chrono::system_clock::now() +
                  std::chrono::milliseconds(static_cast<int64_t>(calls_grace * 1000));
  server_->Shutdown(deadline);
  jobs_->Join();
  metrics_http_.reset();
  LogLine("server_stopped").Info();
}

void Server::Wait() {
  if (server_) server_->Wait();
}

}  // namespace radiosity::service
