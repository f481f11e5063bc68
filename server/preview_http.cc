#include "server/preview_http.h"

#include <httplib.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <optional>
#include <string_view>
#include <utility>

#include "absl/strings/escaping.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "nlohmann/json.hpp"
#include "proto/api/spec.h"
#include "radiosity/v1/service.grpc.pb.h"
#include "server/logging.h"
#include "server/web_assets.h"

namespace radiosity::service {
namespace {

using Json = nlohmann::json;

// How long an event stream waits for its call before checking the stop flag, and how long it may
// stay silent before it writes a keep-alive comment (which is how a closed browser is noticed).
constexpr auto kPoll = std::chrono::milliseconds(200);
constexpr auto kKeepAlive = std::chrono::seconds(5);
// How long a request waits for its call's first answer before starting the stream anyway (a
// queued job has nothing to say for a while; errors arrive at once).
constexpr auto kFirstAnswer = std::chrono::seconds(2);

std::string Dump(const Json& json) {
  // Names and messages come from users' files: replace what is not UTF-8 rather than throw.
  return json.dump(-1, ' ', false, Json::error_handler_t::replace);
}

template <typename T>
std::string Base64(const google::protobuf::RepeatedField<T>& values) {
  return absl::Base64Escape(
      absl::string_view(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T)));
}

int HttpStatus(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK:
      return 200;
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::OUT_OF_RANGE:
    case grpc::StatusCode::FAILED_PRECONDITION:
      return 400;
    case grpc::StatusCode::UNAUTHENTICATED:
      return 401;
    case grpc::StatusCode::PERMISSION_DENIED:
      return 403;
    case grpc::StatusCode::NOT_FOUND:
      return 404;
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return 429;
    case grpc::StatusCode::UNAVAILABLE:
      return 503;
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return 504;
    default:
      return 500;
  }
}

const char* CodeName(grpc::StatusCode code) {
  static constexpr const char* kNames[] = {"OK",
                                           "CANCELLED",
                                           "UNKNOWN",
                                           "INVALID_ARGUMENT",
                                           "DEADLINE_EXCEEDED",
                                           "NOT_FOUND",
                                           "ALREADY_EXISTS",
                                           "PERMISSION_DENIED",
                                           "RESOURCE_EXHAUSTED",
                                           "FAILED_PRECONDITION",
                                           "ABORTED",
                                           "OUT_OF_RANGE",
                                           "UNIMPLEMENTED",
                                           "INTERNAL",
                                           "UNAVAILABLE",
                                           "DATA_LOSS",
                                           "UNAUTHENTICATED"};
  const int i = static_cast<int>(code);
  return i >= 0 && i < 17 ? kNames[i] : "UNKNOWN";
}

Json StatusJson(const grpc::Status& status) {
  return Json{{"code", CodeName(status.error_code())}, {"message", status.error_message()}};
}

void SendError(httplib::Response& res, int http_status, const std::string& code,
               const std::string& message) {
  res.status = http_status;
  res.set_header("Cache-Control", "no-store");
  res.set_content(Dump(Json{{"error", {{"code", code}, {"message", message}}}}) + "\n",
                  "application/json");
}

void SendError(httplib::Response& res, const grpc::Status& status) {
  SendError(res, HttpStatus(status.error_code()), CodeName(status.error_code()),
            status.error_message());
}

Json ProgressJson(const v1::JobProgress& p) {
  return Json{{"step", p.step()},
              {"shots", p.shots()},
              {"rays", p.rays()},
              {"unshot_fraction", p.unshot_fraction()},
              {"elapsed_seconds", p.elapsed_seconds()},
              {"rays_per_second", p.rays_per_second()},
              {"phase", PhaseName(p.phase())},
              {"phase_fraction", p.phase_fraction()},
              {"phase_item", p.phase_item()}};
}

Json JobJson(const v1::Job& job) {
  Json j{{"name", job.name()},
         {"id", job.name().substr(job.name().find('/') + 1)},
         {"scene", job.scene()},
         {"kind", job.has_view_factor() ? "view_factor" : "solve"},
         {"state", StateName(job.state())},
         {"method", job.method()},
         {"create_time", job.create_time().seconds()},
         {"elements", job.mesh().elements()},
         {"stop_reason", job.stop_reason()},
         {"progress", ProgressJson(job.progress())}};
  if (job.has_error() && job.error().code() != 0) {
    j["error"] = Json{{"code", job.error().code()}, {"message", job.error().message()}};
  }
  return j;
}

// One WatchJobResponse as an SSE event: `mesh` for an announcement chunk, else `snapshot`.
std::string EventOf(const v1::WatchJobResponse& m) {
  Json j;
  std::string event;
  if (m.has_mesh()) {
    const v1::MeshGeometry& g = m.mesh();
    event = "mesh";
    j = Json{{"sequence", m.sequence()},
             {"version", g.version()},
             {"elements", g.elements()},
             {"chunk_index", g.chunk_index()},
             {"chunk_count", g.chunk_count()},
             {"first_element", g.first_element()},
             {"origin", {g.origin().x(), g.origin().y(), g.origin().z()}},
             {"surfaces", g.surfaces()},
             {"surface_names", g.surface_names()},
             {"surface_names_offset", g.surface_names_offset()},
             {"surface", Base64(g.surface())},
             {"corners", Base64(g.corners())},
             {"normal", Base64(g.normal())},
             {"area", Base64(g.area())},
             {"member_count", Base64(g.member_count())},
             {"member_corners", Base64(g.member_corners())}};
  } else {
    event = "snapshot";
    j = Json{{"sequence", m.sequence()},
             {"state", StateName(m.state())},
             {"progress", ProgressJson(m.progress())},
             {"resync", m.resync()},
             {"final", m.final()},
             {"elements", m.elements()},
             {"mesh_version", m.mesh_version()},
             {"attempts", m.attempts()},
             {"radiosity_total", m.radiosity_total()},
             {"radiosity_offset", m.radiosity_offset()},
             {"chunk_index", m.chunk_index()},
             {"chunk_count", m.chunk_count()},
             {"radiosity", Base64(m.radiosity())},
             {"std_error", Base64(m.std_error())},
             {"existing_sides_only", m.existing_sides_only()},
             {"back_ranges", m.back_ranges()}};
    if (m.has_error() && m.error().code() != 0) {
      j["error"] = Json{{"code", m.error().code()}, {"message", m.error().message()}};
    }
  }
  // The sequence as the event id only on a snapshot's last chunk: a reconnect resumes after a
  // snapshot it has whole.
  std::string id;
  if (event == "snapshot" && m.chunk_index() + 1 >= m.chunk_count()) {
    id = absl::StrCat("id: ", m.sequence(), "\n");
  }
  return absl::StrCat("event: ", event, "\n", id, "data: ", Dump(j), "\n\n");
}

// One WatchJob call read on behalf of one HTTP response: the reactor reads one message at a time,
// and the response's thread takes it (Next), which asks for the next. So a slow browser holds
// at most one message here; the service's own latest-wins drops the snapshots it cannot take.
class WatchRelay : public grpc::ClientReadReactor<v1::WatchJobResponse> {
 public:
  WatchRelay(v1::RadiosityService::Stub* stub, v1::WatchJobRequest request,
             const std::string& authorization)
      : request_(std::move(request)) {
    if (!authorization.empty()) context_.AddMetadata("authorization", authorization);
    stub->async()->WatchJob(&context_, &request_, this);
    // The hold keeps the call (and its reader) alive between a read's end and Next's StartRead:
    // without it the call can finish in that gap and StartRead would touch a reader gRPC has
    // already destroyed. It is removed once no read will follow (OnReadDone's end or ours).
    AddHold();
    StartRead(&incoming_);
    StartCall();
  }
  // Cancels the call and waits for its end (the reactor must outlive it).
  ~WatchRelay() override {
    context_.TryCancel();
    bool release = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      cancelled_ = true;
      // A message not taken means no read is pending, so no OnReadDone will release the hold.
      release = has_message_;
    }
    if (release) RemoveHold();
    std::unique_lock<std::mutex> lock(mu_);
    cv_.wait(lock, [&] { return done_; });
  }

  enum class Got { kMessage, kDone, kNothing };
  // Waits up to `timeout` for the next message (moved to *out) or the call's end (*status).
  Got Next(std::chrono::milliseconds timeout, v1::WatchJobResponse* out, grpc::Status* status) {
    {
      std::unique_lock<std::mutex> lock(mu_);
      cv_.wait_for(lock, timeout, [&] { return has_message_ || done_; });
      if (!has_message_) {
        if (!done_) return Got::kNothing;
        *status = status_;
        return Got::kDone;
      }
      out->Swap(&incoming_);
      incoming_.Clear();
      has_message_ = false;
    }
    StartRead(&incoming_);
    return Got::kMessage;
  }

  void OnReadDone(bool ok) override {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (ok && !cancelled_) {
        has_message_ = true;
        cv_.notify_all();
        return;
      }
    }
    RemoveHold();  // No read follows: OnDone comes once the call ends.
  }
  void OnDone(const grpc::Status& status) override {
    std::lock_guard<std::mutex> lock(mu_);
    status_ = status;
    done_ = true;
    cv_.notify_all();
  }

 private:
  grpc::ClientContext context_;
  v1::WatchJobRequest request_;
  std::mutex mu_;
  std::condition_variable cv_;
  v1::WatchJobResponse incoming_;
  bool has_message_ = false;
  bool cancelled_ = false;
  bool done_ = false;
  grpc::Status status_;
};

std::string Authorization(const httplib::Request& req) {
  return req.get_header_value("Authorization");
}

void SecurityHeaders(httplib::Response& res) {
  res.set_header("Content-Security-Policy",
                 "default-src 'self'; img-src 'self' data:; object-src 'none'; "
                 "base-uri 'none'; frame-ancestors 'none'");
  res.set_header("X-Content-Type-Options", "nosniff");
  res.set_header("Referrer-Policy", "no-referrer");
}

}  // namespace

absl::StatusOr<std::unique_ptr<PreviewHttpServer>> PreviewHttpServer::Start(
    const PreviewHttpOptions& options, std::shared_ptr<grpc::Channel> channel) {
  std::unique_ptr<PreviewHttpServer> s(new PreviewHttpServer());
  s->options_ = options;
  s->channel_ = std::move(channel);
  s->tls_ = !options.tls_cert_file.empty();
  if (s->tls_) {
    auto ssl = std::make_unique<httplib::SSLServer>(
        options.tls_cert_file.c_str(), options.tls_key_file.c_str(),
        options.tls_client_ca_file.empty() ? nullptr : options.tls_client_ca_file.c_str());
    if (!ssl->is_valid()) {
      return absl::InvalidArgumentError(
          "--http-port: cannot serve HTTPS with --tls-cert and --tls-key (and --tls-client-ca)");
    }
    s->http_ = std::move(ssl);
  } else {
    s->http_ = std::make_unique<httplib::Server>();
  }
  // Each event stream holds a thread; the rest serve pages and lists.
  const int threads = options.max_streams + 8;
  s->http_->new_task_queue = [threads] { return new httplib::ThreadPool(threads); };
  s->http_->set_read_timeout(10);
  s->http_->set_write_timeout(10);
  s->http_->set_keep_alive_timeout(5);
  s->http_->set_payload_max_length(64 << 10);
  s->Route();
  if (options.port == 0) {
    s->port_ = s->http_->bind_to_any_port(options.host);
  } else if (s->http_->bind_to_port(options.host, options.port)) {
    s->port_ = options.port;
  }
  if (s->port_ <= 0) {
    return absl::UnavailableError(
        absl::StrCat("--http-port: cannot listen on ", options.host, ":", options.port));
  }
  s->thread_ = std::thread([http = s->http_.get()] { http->listen_after_bind(); });
  return s;
}

PreviewHttpServer::~PreviewHttpServer() { Stop(); }

void PreviewHttpServer::Stop() {
  if (stopping_.exchange(true)) return;
  // The streams see stopping_ within kPoll and end; stop() closes the listening socket, and the
  // listening thread joins the pool's threads once their requests have returned.
  if (http_) http_->stop();
  if (thread_.joinable()) thread_.join();
}

void PreviewHttpServer::Route() {
  httplib::Server& http = *http_;
  http.set_exception_handler(
      [](const httplib::Request& req, httplib::Response& res, std::exception_ptr ep) {
        std::string what = "unknown exception";
        try {
          std::rethrow_exception(ep);
        } catch (const std::exception& e) {
          what = e.what();
        } catch (...) {
        }
        LogLine("http_exception").Str("path", req.path).Str("detail", what).Error();
        SendError(res, 500, "INTERNAL", "internal error");
      });
  http.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
    if (!res.body.empty()) return;  // A handler's own error.
    SendError(res, res.status, res.status == 404 ? "NOT_FOUND" : "INVALID_ARGUMENT",
              absl::StrCat(req.method, " ", req.path, ": ",
                           res.status == 404 ? "no such page" : "not served"));
  });

  // The page and its assets (server/web/, embedded at build time).
  http.Get(R"(/|/index\.html|/preview\.js|/preview\.css)",
           [](const httplib::Request& req, httplib::Response& res) {
             const WebAsset* asset = FindWebAsset(req.path == "/" ? "/index.html" : req.path);
             if (!asset) return SendError(res, 404, "NOT_FOUND", req.path + ": no such page");
             SecurityHeaders(res);
             res.set_header("Cache-Control", "no-cache");
             res.set_content(std::string(asset->data, asset->size), asset->content_type);
           });

  http.Get("/api/jobs", [this](const httplib::Request& req, httplib::Response& res) {
    v1::ListJobsRequest request;
    request.set_page_size(1000);
    if (req.has_param("page_token")) request.set_page_token(req.get_param_value("page_token"));
    v1::ListJobsResponse response;
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    if (std::string a = Authorization(req); !a.empty()) context.AddMetadata("authorization", a);
    grpc::Status status =
        v1::RadiosityService::NewStub(channel_)->ListJobs(&context, request, &response);
    if (!status.ok()) return SendError(res, status);
    Json jobs = Json::array();
    for (const v1::Job& job : response.jobs()) jobs.push_back(JobJson(job));
    res.set_header("Cache-Control", "no-store");
    res.set_content(
        Dump(Json{{"jobs", jobs}, {"next_page_token", response.next_page_token()}}) + "\n",
        "application/json");
  });

  http.Get(R"(/api/jobs/([A-Za-z0-9_.-]{1,128})/events)",
           [this](const httplib::Request& req, httplib::Response& res) { Events(req, res); });
}

void PreviewHttpServer::Events(const httplib::Request& req, httplib::Response& res) {
  v1::WatchJobRequest request;
  request.set_name(absl::StrCat("jobs/", req.matches[1].str()));
  request.set_include_mesh(true);
  request.set_include_errors(true);
  request.set_existing_sides_only(true);
  const std::string after = req.has_header("Last-Event-ID") ? req.get_header_value("Last-Event-ID")
                                                            : req.get_param_value("after_sequence");
  if (!after.empty()) {
    int64_t sequence = 0;
    if (!absl::SimpleAtoi(after, &sequence) || sequence < 0) {
      return SendError(res, 400, "INVALID_ARGUMENT",
                       "after_sequence (or Last-Event-ID): not a sequence number: " + after);
    }
    request.set_after_sequence(sequence);
  }
  if (streams_.fetch_add(1) >= options_.max_streams) {
    streams_.fetch_sub(1);
    return SendError(res, 503, "RESOURCE_EXHAUSTED",
                     absl::StrCat("this server serves at most ", options_.max_streams,
                                  " preview streams at once; close one and retry"));
  }
  auto stub = v1::RadiosityService::NewStub(channel_);
  auto relay = std::make_shared<WatchRelay>(stub.get(), request, Authorization(req));
  // Errors (unknown job, token) arrive at once: answered with their HTTP status.
  auto first = std::make_shared<v1::WatchJobResponse>();
  grpc::Status status;
  WatchRelay::Got got = WatchRelay::Got::kNothing;
  for (auto waited = std::chrono::milliseconds(0);
       waited < kFirstAnswer && got == WatchRelay::Got::kNothing && !stopping_; waited += kPoll) {
    got = relay->Next(kPoll, first.get(), &status);
  }
  if (got == WatchRelay::Got::kDone && !status.ok()) {
    relay.reset();
    streams_.fetch_sub(1);
    return SendError(res, status);
  }
  res.set_header("Cache-Control", "no-store");
  res.set_header("X-Accel-Buffering", "no");
  struct Stream {
    std::shared_ptr<WatchRelay> relay;
    std::optional<v1::WatchJobResponse> pending;  // Taken before the headers were sent.
    bool ended = false;
    grpc::Status end;
    std::chrono::steady_clock::time_point last_write = std::chrono::steady_clock::now();
  };
  auto stream = std::make_shared<Stream>();
  stream->relay = std::move(relay);
  if (got == WatchRelay::Got::kMessage) stream->pending = std::move(*first);
  if (got == WatchRelay::Got::kDone) {
    stream->ended = true;
    stream->end = status;
  }
  res.set_chunked_content_provider(
      "text/event-stream",
      [this, stream](size_t, httplib::DataSink& sink) -> bool {
        auto write = [&](const std::string& text) {
          stream->last_write = std::chrono::steady_clock::now();
          return sink.write(text.data(), text.size());
        };
        if (stream->pending) {
          const bool ok = write(EventOf(*stream->pending));
          stream->pending.reset();
          return ok;
        }
        if (!stream->ended) {
          v1::WatchJobResponse message;
          switch (stream->relay->Next(kPoll, &message, &stream->end)) {
            case WatchRelay::Got::kMessage:
              return write(EventOf(message));
            case WatchRelay::Got::kDone:
              stream->ended = true;
              break;
            case WatchRelay::Got::kNothing:
              if (stopping_) return false;
              if (std::chrono::steady_clock::now() - stream->last_write >= kKeepAlive) {
                return write(": keep-alive\n\n");
              }
              return true;
          }
        }
        // The call ended: say how (OK after the final snapshot), then end the response.
        const bool ok =
            write(absl::StrCat("event: end\ndata: ", Dump(StatusJson(stream->end)), "\n\n"));
        sink.done();
        return ok;
      },
      [this, stream](bool) {
        stream->relay.reset();  // Cancels the call if it still runs, and waits for its end.
        streams_.fetch_sub(1);
      });
}

}  // namespace radiosity::service
