#include "server/server.h"

#include <arpa/inet.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <netinet/in.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <mutex>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "proto/api/pem.h"
#include "server/logging.h"
#include "server/reflection_v1.h"
#include "server/service_impl.h"
#include "server/tenants.h"
#include "solver/input/model_loader.h"

namespace radiosity::service {
namespace {

// Whether `listen` (HOST:PORT, or a unix: socket) is reachable only from this machine.
bool IsLoopback(const std::string& listen) {
  if (absl::StartsWith(listen, "unix:") || absl::StartsWith(listen, "unix-abstract:")) return true;
  size_t colon = listen.rfind(':');
  std::string host = colon == std::string::npos ? listen : listen.substr(0, colon);
  if (host.size() >= 2 && host.front() == '[') host = host.substr(1, host.size() - 2);
  if (host == "localhost") return true;
  // Addresses only (a host name that starts with "127." is not one).
  in_addr v4;
  in6_addr v6;
  if (inet_pton(AF_INET, host.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  return inet_pton(AF_INET6, host.c_str(), &v6) == 1 && IN6_IS_ADDR_LOOPBACK(&v6);
}

// The listening port's credentials: TLS (with the token check) when configured, else plaintext,
// which off loopback needs --insecure.
absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> ListenCredentials(
    const ServerOptions& options, const std::shared_ptr<TokenTable>& tokens) {
  const bool tls = !options.tls_cert_file.empty() || !options.tls_key_file.empty();
  if (tls && (options.tls_cert_file.empty() || options.tls_key_file.empty())) {
    return absl::InvalidArgumentError("--tls-cert and --tls-key go together");
  }
  if (!tls && !options.tls_client_ca_file.empty()) {
    return absl::InvalidArgumentError("--tls-client-ca needs --tls-cert and --tls-key");
  }
  if (!tls && !options.tokens_file.empty()) {
    return absl::InvalidArgumentError(
        "--tokens-file needs --tls-cert and --tls-key: bearer tokens are not sent in clear");
  }
  const bool credentials = !options.tokens_file.empty() || !options.tls_client_ca_file.empty();
  if (!IsLoopback(options.listen) && !credentials && !options.insecure) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--listen ", options.listen,
        " is reachable from other machines, and without "
        "--tokens-file (or --tls-client-ca) anyone there could read, run and delete every scene "
        "and job: give credentials, or --insecure to accept that (e.g. behind a proxy that "
        "authenticates)"));
  }
  if (!tls) return grpc::InsecureServerCredentials();
  grpc::SslServerCredentialsOptions ssl(
      options.tls_client_ca_file.empty()
          ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
          : GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  absl::StatusOr<std::string> cert = ReadPemFile(options.tls_cert_file, "--tls-cert");
  if (!cert.ok()) return cert.status();
  absl::StatusOr<std::string> key = ReadPemFile(options.tls_key_file, "--tls-key");
  if (!key.ok()) return key.status();
  ssl.pem_key_cert_pairs.push_back({*key, *cert});
  if (!options.tls_client_ca_file.empty()) {
    absl::StatusOr<std::string> ca = ReadPemFile(options.tls_client_ca_file, "--tls-client-ca");
    if (!ca.ok()) return ca.status();
    ssl.pem_root_certs = *ca;
  }
  std::shared_ptr<grpc::ServerCredentials> creds = grpc::SslServerCredentials(ssl);
  if (tokens) creds->SetAuthMetadataProcessor(std::make_shared<TokenAuthProcessor>(tokens));
  return creds;
}

}  // namespace

absl::StatusOr<std::unique_ptr<Server>> Server::Start(const ServerOptions& options) {
  if (!SetLogLevel(options.log_level)) {
    return absl::InvalidArgumentError(absl::StrCat("unknown log level '", options.log_level, "'"));
  }
  if (options.service.data_dir.empty()) return absl::InvalidArgumentError("no data directory");
  std::shared_ptr<TokenTable> tokens;
  if (!options.tokens_file.empty()) {
    absl::StatusOr<std::unique_ptr<TokenTable>> table = TokenTable::Open(options.tokens_file);
    if (!table.ok()) return table.status();
    tokens = *std::move(table);
  }
  std::shared_ptr<grpc::ServerCredentials> credentials;
  if (!options.listen.empty()) {
    absl::StatusOr<std::shared_ptr<grpc::ServerCredentials>> made =
        ListenCredentials(options, tokens);
    if (!made.ok()) return made.status();
    credentials = *std::move(made);
  } else if (!options.tokens_file.empty() || !options.tls_cert_file.empty()) {
    return absl::InvalidArgumentError("TLS and tokens need --listen");
  }
  std::unique_ptr<Server> s(new Server());
  s->options_ = options;
  s->options_.service.tokens = tokens;
  DataDir dir(options.service.data_dir, options.service.blob_dir);
  if (absl::Status st = dir.Create(); !st.ok()) return st;
  absl::StatusOr<int> lock = dir.Lock();
  if (!lock.ok()) return lock.status();
  s->lock_fd_ = *lock;
  absl::StatusOr<std::unique_ptr<Store>> store = OpenStore(options.service.store, dir.root());
  if (!store.ok()) return store.status();
  if (dir.shared() && !(*store)->ServesReplicas()) {
    return absl::InvalidArgumentError(
        absl::StrCat("--blob-dir is for replicas sharing a PostgreSQL --store; ",
                     (*store)->ToString(), " is one server's store"));
  }
  // Replicas share the store; a single server claims it.
  if (!dir.shared()) {
    if (absl::Status st = (*store)->ClaimExclusive(); !st.ok()) return st;
  }
  s->store_ = *std::move(store);
  s->metrics_ = std::make_unique<Metrics>();
  s->jobs_ =
      std::make_unique<JobManager>(s->options_.service, dir, s->store_.get(), s->metrics_.get());
  JobManager* jobs = s->jobs_.get();
  s->metrics_->queue_depth = [jobs] { return jobs->QueueDepth(); };
  s->metrics_->running_jobs = [jobs] { return jobs->RunningJobs(); };
  s->metrics_->rays_per_second = [jobs] { return jobs->RaysPerSecond(); };
  if (absl::Status st = s->jobs_->Start(); !st.ok()) return st;
  s->service_ = std::make_unique<RadiosityServiceImpl>(s->options_.service, dir, s->store_.get(),
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
    builder.AddListeningPort(options.listen, credentials, &s->port_);
  }
  builder.RegisterService(s->service_.get());
  if (options.reflection) {
    // v1 beside the plugin's v1alpha (Debian's gRPC 1.51 has only that).
    s->reflection_v1_ = std::make_unique<ReflectionV1Service>(
        std::vector<std::string>{v1::RadiosityService::service_full_name(), "grpc.health.v1.Health",
                                 grpc::reflection::v1::ServerReflection::service_full_name(),
                                 "grpc.reflection.v1alpha.ServerReflection"});
    builder.RegisterService(s->reflection_v1_.get());
  }
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
    return absl::UnavailableError(
        absl::StrCat("cannot listen on ", options.listen,
                     options.tls_cert_file.empty()
                         ? ""
                         : " (with TLS: check that --tls-key is the key of --tls-cert, and that "
                           "--tls-client-ca is a CA certificate)"));
  }
  grpc::HealthCheckServiceInterface* health = s->server_->GetHealthCheckService();
  if (health) {
    health->SetServingStatus(kServiceName, true);
    health->SetServingStatus(true);
    // NOT_SERVING while the store cannot be written (a full disk), SERVING again once it can.
    Server* server = s.get();
    s->jobs_->OnStoreWritableChange([health, server](bool writable) {
      {
        std::lock_guard<std::mutex> guard(server->mu_);
        if (server->shut_down_) return;
      }
      health->SetServingStatus(kServiceName, writable);
      health->SetServingStatus(writable);
    });
  }
  // The HTTP ports listen on the host of --listen.
  std::string host = "127.0.0.1";
  if (size_t colon = options.listen.rfind(':'); colon != std::string::npos) {
    host = options.listen.substr(0, colon);
    if (host.size() >= 2 && host.front() == '[') host = host.substr(1, host.size() - 2);
  }
  if (absl::StartsWith(options.listen, "unix")) host = "127.0.0.1";
  if (options.metrics_port >= 0) {
    // Plaintext and without tokens: off loopback only when the gRPC port is open as well.
    absl::StatusOr<std::unique_ptr<MetricsHttpServer>> http = MetricsHttpServer::Start(
        IsLoopback(options.listen) || options.insecure ? host : "127.0.0.1", options.metrics_port,
        [m = s->metrics_.get()] { return m->Prometheus(); });
    if (!http.ok()) {
      s->Shutdown();
      return http.status();
    }
    s->metrics_http_ = *std::move(http);
  }
  if (options.http_port >= 0) {
    // The same credentials as the gRPC port: its TLS, and the calls' own tokens (the preview is
    // a gateway to this server's in-process channel).
    PreviewHttpOptions preview;
    preview.host = options.listen.empty() ? "127.0.0.1" : host;
    preview.port = options.http_port;
    preview.tls_cert_file = options.tls_cert_file;
    preview.tls_key_file = options.tls_key_file;
    preview.tls_client_ca_file = options.tls_client_ca_file;
    absl::StatusOr<std::unique_ptr<PreviewHttpServer>> http =
        PreviewHttpServer::Start(preview, s->InProcessChannel());
    if (!http.ok()) {
      s->Shutdown();
      return http.status();
    }
    s->preview_http_ = *std::move(http);
  }
  LogLine("server_started")
      .Str("listen", options.listen)
      .Int("port", s->port_)
      .Int("metrics_port", s->metrics_port())
      .Int("http_port", s->http_port())
      .Str("data_dir", options.service.data_dir)
      .Str("store", s->store_->ToString())
      .Int("workers", options.service.workers)
      .Int("max_queued", options.service.max_queued)
      .Int("threads_per_job", options.service.threads_per_job)
      .Str("model_importer", ModelImporter())
      .Str("tls", options.tls_cert_file.empty()        ? "off"
                  : options.tls_client_ca_file.empty() ? "server"
                                                       : "mutual")
      .Str("tenants", options.tokens_file.empty() ? "off" : "tokens")
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
  preview_http_.reset();  // Its in-process channel goes before the server.
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
  // The preview's streams are calls of this server: ended first, so that they do not hold its
  // shutdown for the grace period.
  if (preview_http_) preview_http_->Stop();
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
