// The radiosity command-line tool (docs/guide/cli.md, docs/service/api.md). Every command speaks
// the service's API (proto/radiosity/v1/service.proto): to a remote radiosity-server with
// `--server HOST:PORT` (before or after the command), otherwise to the same service started
// inside this process on a temporary data directory.
//
//   radiosity solve SCENE --out DIR [options]   upload, solve, watch, download the results
//   radiosity upload SCENE                      upload a scene, print its name
//   radiosity watch JOB [--preview-dir D]       follow a job's snapshots
//   radiosity jobs [--state S]                  list jobs
//   radiosity cancel JOB                        cancel a job
//   radiosity get JOB --out DIR                 download a job's results
//   radiosity viewfactor SCENE [--method M] [--out FILE.csv] [--check]
//   radiosity report JOB --out DIR             an HTML report of a finished solve
//   radiosity render JOB --out FILE.png         render a finished solve from another camera
//                  [--false-color MIN:MAX|auto] (in false colour, with a legend)
//   radiosity scenes | health
//
// `--json` makes every command print JSON lines on stdout. Exit codes are in solver/exit_codes.h.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "CLI/CLI.hpp"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "client/client.h"
#include "client/completion.h"
#include "client/preview.h"
#include "client/report.h"
#include "google/protobuf/stubs/common.h"
#include "google/protobuf/util/json_util.h"
#include "grpcpp/grpcpp.h"
#include "proto/api/exit_codes.h"
#include "proto/api/names.h"
#include "proto/api/spec.h"
#include "server/server.h"
#include "solver/input/photometry_file.h"
#include "solver/input/sensors_file.h"
#include "solver/input/thermal_file.h"
#include "solver/methods/registry.h"
#include "solver/methods/viewfactor.h"
#include "solver/pipeline/job.h"
#include "solver/results/image.h"
#include "solver/results/text_writer.h"
#include "solver/results/viewfactor_csv.h"
#include "solver/util/file_io.h"
#include "solver/util/json.h"

namespace radiosity {
namespace {

namespace fs = std::filesystem;
using client::Client;
using client::Snapshot;

std::atomic<int> g_interrupts{0};
std::atomic<bool> g_stop{false};

void OnSignal(int) {
  g_stop.store(true);
  if (g_interrupts.fetch_add(1) >= 1) _exit(kExitCancelled);  // A second Ctrl-C: leave now.
}

// Options every command takes.
struct Global {
  std::string server;    // HOST:PORT; empty: in-process service.
  std::string data_dir;  // In-process service: keep its data here instead of a temporary dir.
  bool json = false;
  double timeout = 30;
  std::string log_level = "off";
  client::SceneReadOptions read;     // Uploads: UploadSceneHeader.strict, .vertex_colors.
  client::ChannelSecurity security;  // --tls, --tls-ca, --tls-cert, --tls-key, --tls-server-name.
  std::string token_file;            // --token-file (else $RADIOSITY_TOKEN).
};

std::string ToJson(const google::protobuf::Message& m) {
  std::string out;
  google::protobuf::util::JsonPrintOptions options;
  options.preserve_proto_field_names = true;
  (void)google::protobuf::util::MessageToJsonString(m, &out, options);
  return out;
}

void PrintJsonLine(const std::string& line) {
  std::fprintf(stdout, "%s\n", line.c_str());
  std::fflush(stdout);
}

int Fail(const Global& g, int code, const absl::Status& status) {
  std::fprintf(stderr, "radiosity: error: %s\n", std::string(status.message()).c_str());
  if (g.json) {
    PrintJsonLine(
        absl::StrCat("{\"error\":{\"code\":", JsonQuote(absl::StatusCodeToString(status.code())),
                     ",\"message\":", JsonQuote(status.message()), "},\"exit_code\":", code, "}"));
  }
  return code;
}

// Exit codes for failures of calls to the service, by where they happened.
int CallExit(const absl::Status& st) {
  switch (st.code()) {
    case absl::StatusCode::kDeadlineExceeded:
    case absl::StatusCode::kCancelled:
      return kExitCancelled;
    default:
      return kExitServer;
  }
}
int UploadExit(const absl::Status& st) {
  switch (st.code()) {
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kNotFound:
    case absl::StatusCode::kFailedPrecondition:
    case absl::StatusCode::kPermissionDenied:
      return kExitInput;
    default:
      return CallExit(st);
  }
}
int CreateExit(const absl::Status& st) {
  switch (st.code()) {
    case absl::StatusCode::kInvalidArgument:
      return kExitUsage;
    case absl::StatusCode::kFailedPrecondition:
      return kExitInput;
    default:
      return CallExit(st);
  }
}
// A job that ended FAILED, as the local solve would have exited.
int JobErrorExit(const v1::JobError& e) {
  switch (static_cast<absl::StatusCode>(e.code())) {
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kResourceExhausted:
      return kExitUsage;
    case absl::StatusCode::kFailedPrecondition:
    case absl::StatusCode::kNotFound:
      return kExitInput;
    default:
      return kExitInternal;
  }
}
// Connection::Open failed: options that do not go together are a usage error.
int FailToConnect(const Global& g, const absl::Status& status) {
  return Fail(g, status.code() == absl::StatusCode::kInvalidArgument ? kExitUsage : kExitServer,
              status);
}

absl::Status JobErrorStatus(const v1::JobError& e) {
  return absl::Status(static_cast<absl::StatusCode>(e.code()), e.message());
}

// The service the commands talk to: remote, or started here on a temporary data directory.
class Connection {
 public:
  static absl::StatusOr<std::unique_ptr<Connection>> Open(const Global& g) {
    std::unique_ptr<Connection> c(new Connection());
    client::ClientOptions options;
    options.timeout_seconds = g.timeout;
    if (!g.server.empty()) {
      client::ChannelSecurity security = g.security;
      absl::StatusOr<std::string> token = client::ReadToken(g.token_file);
      if (!token.ok()) return token.status();
      // $RADIOSITY_TOKEN is for TLS servers; a plaintext one is reached without it (a token
      // named by --token-file over plaintext is an error, from MakeChannel).
      const bool tls = security.tls || !security.ca_file.empty() || !security.cert_file.empty();
      if (tls || !g.token_file.empty()) security.token = *token;
      absl::StatusOr<std::shared_ptr<grpc::Channel>> channel =
          client::MakeChannel(g.server, security);
      if (!channel.ok()) return channel.status();
      c->client_ = std::make_unique<Client>(*std::move(channel), options);
      c->where_ = g.server;
      return c;
    }
    if (g.security.tls || !g.security.ca_file.empty() || !g.security.cert_file.empty() ||
        !g.token_file.empty()) {
      return absl::InvalidArgumentError(
          "--tls, --tls-ca, --tls-cert, --tls-key and --token-file are for a remote --server");
    }
    std::string dir = g.data_dir;
    if (dir.empty()) {
      const char* tmp = std::getenv("TMPDIR");
      std::string pattern = absl::StrCat(tmp && *tmp ? tmp : "/tmp", "/radiosity-XXXXXX");
      if (!mkdtemp(pattern.data())) {
        return absl::InternalError(
            absl::StrCat(pattern, ": cannot create: ", std::strerror(errno)));
      }
      dir = pattern;
      c->temp_dir_ = dir;
    }
    service::ServerOptions server;
    server.service.data_dir = dir;
    server.service.workers = 1;
    server.service.max_queued = 1 << 20;
    server.service.threads_per_job = 0;
    server.service.max_memory_mb = 0;  // As a local solve: no limit but the element limit.
    server.service.max_upload_bytes = int64_t{1} << 40;
    server.log_level = g.log_level;
    server.shutdown_grace_seconds = 1;
    absl::StatusOr<std::unique_ptr<service::Server>> started = service::Server::Start(server);
    if (!started.ok()) return started.status();
    c->server_ = *std::move(started);
    c->client_ = std::make_unique<Client>(c->server_->InProcessChannel(), options);
    c->where_ = "the in-process service";
    return c;
  }

  ~Connection() {
    client_.reset();
    server_.reset();
    if (!temp_dir_.empty()) {
      std::error_code ec;
      fs::remove_all(temp_dir_, ec);
    }
  }

  Client& client() { return *client_; }
  const std::string& where() const { return where_; }

 private:
  Connection() = default;
  std::unique_ptr<service::Server> server_;
  std::unique_ptr<Client> client_;
  std::string temp_dir_;
  std::string where_;
};

// Says where a failed call went, for failures of the connection itself.
absl::Status Explain(const Connection& c, const absl::Status& st) {
  if (st.code() == absl::StatusCode::kUnavailable ||
      st.code() == absl::StatusCode::kDeadlineExceeded) {
    return absl::Status(st.code(), absl::StrCat(c.where(), ": ", st.message()));
  }
  return st;
}

std::string JobName(const std::string& arg) {
  return arg.rfind("jobs/", 0) == 0 ? arg : "jobs/" + arg;
}

// Prints progress on stderr, a bar per phase (meshing, solving, writing): one updating line on a
// terminal, ended when the phase ends; otherwise a plain line when a phase or its file changes
// and at most once a second.
class ProgressPrinter {
 public:
  ProgressPrinter(double tolerance, bool quiet)
      : tty_(isatty(STDERR_FILENO)), tolerance_(tolerance), quiet_(quiet) {}

  void Update(const v1::JobProgress& p, bool final = false) {
    if (quiet_) return;
    if (final && phase_ == v1::JOB_PHASE_WRITING) {
      // The bars of this job's phases were shown, the writing one last: it has ended.
      Break();
      return;
    }
    const bool changed =
        p.phase() != phase_ || p.phase_item() != item_ || (!Solving(p) && p.phase_fraction() >= 1);
    const auto now = std::chrono::steady_clock::now();
    const double since = std::chrono::duration<double>(now - last_).count();
    if (!final && !changed && since < (tty_ ? 0.1 : 1.0)) {
      skipped_ = p;  // Shown if the phase ends before the next line.
      return;
    }
    if (p.phase() != phase_) Break();
    skipped_.reset();
    Print(p, final);
  }
  // Ends the current line, before other output or the next phase's bar, with the phase's last
  // state if that was not shown (so that its line ends where the phase did).
  void Break() {
    if (skipped_) Print(*std::exchange(skipped_, std::nullopt), false);
    if (!open_) return;
    std::fprintf(stderr, "\n");
    std::fflush(stderr);
    open_ = false;
  }
  bool printed() const { return printed_; }

 private:
  void Print(const v1::JobProgress& p, bool final) {
    // A job watched after it ended shows its solve's line, whatever phase it ended in.
    const bool solving = final || Solving(p);
    phase_ = p.phase();
    item_ = p.phase_item();
    last_ = std::chrono::steady_clock::now();
    std::string line;
    if (solving) {
      // Fraction done on a log scale: unshot falls from 1 to the tolerance.
      double done = std::clamp(
          std::log(std::max(p.unshot_fraction(), 1e-300)) / std::log(tolerance_), 0.0, 1.0);
      if (!(done > 0)) done = 0;  // log(1) / log(tolerance) is -0: printed "-0%".
      double rate = p.elapsed_seconds() > 0 ? p.rays() / p.elapsed_seconds() : 0;
      line = absl::StrFormat(
          "solve [%s] %3.0f%%  unshot %.3g%% (target %.3g%%)  rays %s  %.1f s  %.1f Mrays/s",
          Bar(done), 100 * done, 100 * p.unshot_fraction(), 100 * tolerance_, HumanCount(p.rays()),
          p.elapsed_seconds(), rate / 1e6);
    } else {
      const double done = std::clamp(p.phase_fraction(), 0.0, 1.0);
      const bool meshing = p.phase() == v1::JOB_PHASE_MESHING;
      line = absl::StrFormat("%s [%s] %3.0f%%%s", meshing ? "mesh " : "write", Bar(done),
                             100 * done, p.phase_item().empty() ? "" : "  " + p.phase_item());
    }
    if (tty_) {
      std::fprintf(stderr, "\r%s\033[K", line.c_str());
      open_ = true;
      if (final) Break();
    } else {
      std::fprintf(stderr, "%s\n", line.c_str());
    }
    std::fflush(stderr);
    printed_ = true;
  }
  static std::string HumanCount(int64_t n) {
    if (n >= 1'000'000'000) return absl::StrFormat("%.2fG", n / 1e9);
    if (n >= 1'000'000) return absl::StrFormat("%.2fM", n / 1e6);
    if (n >= 1'000) return absl::StrFormat("%.1fk", n / 1e3);
    return absl::StrCat(n);
  }
  // Solving, or a server before phases (which says none).
  static bool Solving(const v1::JobProgress& p) {
    return p.phase() == v1::JOB_PHASE_SOLVING || p.phase() == v1::JOB_PHASE_UNSPECIFIED;
  }
  static std::string Bar(double done) {
    const int filled = static_cast<int>(done * 20 + 0.5);
    return std::string(filled, '#') + std::string(20 - filled, '.');
  }
  bool tty_;
  double tolerance_;
  bool quiet_;
  bool printed_ = false;
  bool open_ = false;  // A terminal line not yet ended.
  v1::JobPhase phase_ = v1::JOB_PHASE_UNSPECIFIED;
  std::string item_;
  std::optional<v1::JobProgress> skipped_;  // An update not shown (too soon after the last).
  std::chrono::steady_clock::time_point last_;
};

std::string SnapshotJson(const std::string& job, const Snapshot& s) {
  return absl::StrCat(
      "{\"event\":\"snapshot\",\"job\":", JsonQuote(job), ",\"sequence\":", s.sequence,
      ",\"state\":", JsonQuote(service::StateName(s.state)), ",\"rays\":", s.progress.rays(),
      ",\"unshot_fraction\":", absl::StrFormat("%.6g", s.progress.unshot_fraction()),
      ",\"elapsed_seconds\":", absl::StrFormat("%.6g", s.progress.elapsed_seconds()),
      ",\"resync\":", s.resync ? "true" : "false", ",\"final\":", s.final ? "true" : "false",
      ",\"elements\":", s.elements, ",\"mesh_version\":", s.mesh_version,
      ",\"phase\":", JsonQuote(service::PhaseName(s.progress.phase())),
      ",\"phase_fraction\":", absl::StrFormat("%.6g", s.progress.phase_fraction()),
      ",\"phase_item\":", JsonQuote(s.progress.phase_item()), "}");
}

// Uploads a scene file, printing the loader's warnings.
absl::StatusOr<v1::SceneInfo> Upload(Connection& c, const std::string& path,
                                     const client::SceneReadOptions& read) {
  absl::StatusOr<v1::SceneInfo> info = c.client().UploadSceneFile(path, "", read);
  if (!info.ok()) return Explain(c, info.status());
  for (const std::string& w : info->warnings()) {
    std::fprintf(stderr, "radiosity: warning: %s\n", w.c_str());
  }
  return info;
}

// ---------------------------------------------------------------------------------------------
// solve

struct SolveArgs {
  std::string scene;
  std::string out;
  JobSpec spec;
  std::string sensors;
  std::string shooting = "weighted";
  std::vector<std::string> luminaires;  // --luminaire texts.
  double snapshot_interval = 0;
  bool quiet = false;
  bool detach = false;
  bool ambient = false;           // --ambient: accepted, always on (a warning says so).
  std::vector<std::string> emit;  // --emit NAME=R,G,B
  std::string sky;                // --sky MODEL=E
  std::string sky_up;             // --sky-up X,Y,Z
};

// "NAME=R,G,B" or "NAME=V" (grey) as an EmitOverride; the name is what precedes the last '='.
absl::StatusOr<EmitOverride> ParseEmit(const std::string& text) {
  const size_t eq = text.rfind('=');
  auto bad = [&](absl::string_view why) {
    return absl::InvalidArgumentError(
        absl::StrCat("--emit '", text, "': ", why, " (expected NAME=R,G,B or NAME=V, W/m^2)"));
  };
  if (eq == std::string::npos || eq == 0) return bad("no NAME=");
  std::vector<std::string> parts = absl::StrSplit(text.substr(eq + 1), ',');
  if (parts.size() != 1 && parts.size() != 3) return bad("give 1 or 3 values");
  double v[3];
  for (size_t i = 0; i < parts.size(); ++i) {
    if (!absl::SimpleAtod(parts[i], &v[i]) || !std::isfinite(v[i]) || v[i] < 0) {
      return bad(absl::StrCat("'", parts[i], "' is not a number >= 0"));
    }
  }
  if (parts.size() == 1) v[1] = v[2] = v[0];
  return EmitOverride{text.substr(0, eq), Rgb(v[0], v[1], v[2])};
}

// "MODEL=E" or "MODEL=R,G,B" (--sky): the sky model and its horizontal irradiance.
absl::Status ParseSky(const std::string& text, SkyOptions* sky) {
  absl::StatusOr<EmitOverride> parsed = ParseEmit(text);
  if (!parsed.ok() || (parsed->name != "uniform" && parsed->name != "overcast")) {
    return absl::InvalidArgumentError(
        absl::StrCat("--sky '", text,
                     "': expected uniform=E or overcast=E (or =R,G,B), E the horizontal "
                     "irradiance under the open sky in W/m^2"));
  }
  sky->model = parsed->name;
  sky->irradiance = parsed->exitance;
  return absl::OkStatus();
}

// "X,Y,Z" (--sky-up).
absl::Status ParseDirection(const std::string& flag, const std::string& text, Vec3* out) {
  std::vector<std::string> parts = absl::StrSplit(text, ',');
  double v[3];
  if (parts.size() != 3 || !absl::SimpleAtod(parts[0], &v[0]) ||
      !absl::SimpleAtod(parts[1], &v[1]) || !absl::SimpleAtod(parts[2], &v[2])) {
    return absl::InvalidArgumentError(
        absl::StrCat(flag, " '", text, "': expected X,Y,Z (three numbers)"));
  }
  *out = Vec3(v[0], v[1], v[2]);
  return absl::OkStatus();
}

// "FILE at=X,Y,Z [aim=X,Y,Z] [c0=X,Y,Z] [multiplier=K] [color=R,G,B]" (--luminaire): a luminaire
// whose photometric file is the local FILE (uploaded with the scene, named by its base name).
absl::Status ParseLuminaire(const std::string& text, Luminaire* out, std::string* local) {
  auto bad = [&](const std::string& why) {
    return absl::InvalidArgumentError(absl::StrCat(
        "--luminaire '", text, "': ", why,
        " (expected 'FILE.ies at=X,Y,Z [aim=X,Y,Z] [c0=X,Y,Z] [multiplier=K] [color=R,G,B]')"));
  };
  std::vector<std::string> words = absl::StrSplit(text, ' ', absl::SkipWhitespace());
  if (words.empty() || words[0].find('=') != std::string::npos) return bad("no file first");
  *local = words[0];
  out->file = BaseName(words[0]);
  bool placed = false;
  for (size_t i = 1; i < words.size(); ++i) {
    const size_t eq = words[i].find('=');
    if (eq == std::string::npos) return bad(absl::StrCat("'", words[i], "' is not KEY=VALUE"));
    const std::string key = words[i].substr(0, eq), value = words[i].substr(eq + 1);
    const std::string flag = absl::StrCat("--luminaire ", key);
    if (key == "at" || key == "aim" || key == "c0") {
      Vec3 v;
      if (absl::Status st = ParseDirection(flag, value, &v); !st.ok()) return st;
      (key == "at" ? out->position : key == "aim" ? out->aim : out->c0) = v;
      placed = placed || key == "at";
    } else if (key == "multiplier") {
      if (!absl::SimpleAtod(value, &out->multiplier)) {
        return bad(absl::StrCat("multiplier '", value, "' is not a number"));
      }
    } else if (key == "color" || key == "colour") {
      absl::StatusOr<EmitOverride> c = ParseEmit("color=" + value);
      if (!c.ok()) return bad(absl::StrCat("color '", value, "' is not R,G,B (each >= 0)"));
      out->color = c->exitance;
    } else {
      return bad(absl::StrCat("unknown key '", key, "'"));
    }
  }
  if (!placed) return bad("no position at=X,Y,Z");
  return absl::OkStatus();
}

// "hierarchical (auto: mean albedo 0.95 >= 0.9 and 6 faces <= 200)", or the requested method.
std::string MethodText(const v1::Job& job, const std::string& requested) {
  if (job.method().empty()) return requested;
  if (job.method_reason().empty() || job.method_reason() == "requested") return job.method();
  return absl::StrCat(job.method(), " (auto: ", job.method_reason(), ")");
}

// Creates the job of `request` on `scene` with a fresh request id, Ctrl-C and SIGTERM caught from
// now on (they cancel it); on failure, nullopt and *code the exit code.
std::optional<v1::Job> Submit(const Global& g, Connection& c, const v1::SceneInfo& scene,
                              v1::CreateJobRequest request, int* code) {
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  request.set_scene(scene.name());
  request.set_request_id("cli-" + service::NewId() + service::NewId());
  absl::StatusOr<v1::Job> job = c.client().CreateJob(request);
  if (!job.ok()) {
    *code = Fail(g, CreateExit(job.status()), Explain(c, job.status()));
    return std::nullopt;
  }
  return *std::move(job);
}

// --method's help: the registry's methods, and what auto does.
std::string MethodHelp() {
  std::vector<std::string> names;
  for (const MethodInfo& m : Methods()) names.push_back(m.name);
  return absl::StrCat(
      "auto (default: hierarchical on bright scenes of few polygons, else "
      "progressive), ",
      absl::StrJoin(names, ", "), " (docs/guide/methods.md)");
}

std::string EstimatorHelp() {
  std::vector<std::string> names;
  for (const EstimatorInfo& e : FormFactorEstimators()) names.push_back(e.name);
  return absl::StrCat("Form-factor estimator: ", absl::StrJoin(names, ", "),
                      " (default montecarlo)");
}

int RunSolve(const Global& g, SolveArgs& args) {
  if (args.out.empty() && !args.detach) {
    return Fail(g, kExitUsage, absl::InvalidArgumentError("solve: --out is required"));
  }
  args.spec.solve.weighted_shooting = args.shooting == "weighted";
  if (args.ambient) {
    std::fprintf(stderr,
                 "radiosity: warning: --ambient is always on: a solution before convergence "
                 "includes the estimate of the light not yet propagated\n");
  }
  for (const std::string& text : args.emit) {
    absl::StatusOr<EmitOverride> e = ParseEmit(text);
    if (!e.ok()) return Fail(g, kExitUsage, e.status());
    args.spec.emit.push_back(*e);
  }
  if (!args.sky.empty()) {
    if (absl::Status st = ParseSky(args.sky, &args.spec.solve.sky); !st.ok()) {
      return Fail(g, kExitUsage, st);
    }
  }
  if (!args.sky_up.empty()) {
    if (absl::Status st = ParseDirection("--sky-up", args.sky_up, &args.spec.solve.sky.up);
        !st.ok()) {
      return Fail(g, kExitUsage, st);
    }
  }
  client::SceneReadOptions read = g.read;
  for (const std::string& text : args.luminaires) {
    Luminaire l;
    std::string local;
    if (absl::Status st = ParseLuminaire(text, &l, &local); !st.ok()) {
      return Fail(g, kExitUsage, st);
    }
    // Read here (once a file), so a bad file is named with its line before anything is uploaded.
    if (std::find(read.extra_files.begin(), read.extra_files.end(), local) ==
        read.extra_files.end()) {
      if (absl::StatusOr<Photometry> p = LoadPhotometry(local); !p.ok()) {
        return Fail(g, kExitInput, p.status());
      }
      read.extra_files.push_back(local);
    }
    args.spec.solve.luminaires.push_back(l);
  }
  if (absl::Status st = ValidateJobSpec(args.spec, FieldNaming::kFlag); !st.ok()) {
    return Fail(g, kExitUsage, st);
  }
  // Options the method ignores, said before anything runs; "auto" decides on the mesh, so its
  // warnings come with the job (printed with the mesh line below).
  std::vector<std::string> warned;
  auto warn = [&](const std::vector<std::string>& warnings) {
    for (const std::string& w : warnings) {
      if (std::find(warned.begin(), warned.end(), w) != warned.end()) continue;
      warned.push_back(w);
      std::fprintf(stderr, "radiosity: warning: %s\n", w.c_str());
    }
  };
  if (args.spec.solve.method != "auto") {
    warn(IgnoredOptions(args.spec.solve.method, args.spec.solve, FieldNaming::kFlag));
  }
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;

  absl::StatusOr<v1::SceneInfo> scene = Upload(c, args.scene, read);
  if (!scene.ok()) return Fail(g, UploadExit(scene.status()), scene.status());
  if (!args.sensors.empty()) {
    absl::StatusOr<std::vector<SensorPoint>> sensors = LoadSensors(args.sensors);
    if (!sensors.ok()) return Fail(g, UploadExit(sensors.status()), sensors.status());
    args.spec.sensors = *std::move(sensors);
  }
  v1::CreateJobRequest request;
  *request.mutable_solve() = service::ToSolveSpec(args.spec, args.snapshot_interval);
  int code = kExitOk;
  std::optional<v1::Job> job = Submit(g, c, *scene, std::move(request), &code);
  if (!job) return code;
  if (g.json) PrintJsonLine(absl::StrCat("{\"event\":\"job\",\"job\":", ToJson(*job), "}"));
  if (args.detach) {
    if (!g.json) std::fprintf(stdout, "%s\n", job->name().c_str());
    return kExitOk;
  }

  ProgressPrinter printer(args.spec.solve.tolerance, args.quiet || g.json);
  bool mesh_printed = false;
  auto print_mesh = [&](const Snapshot& s) {
    if (mesh_printed || args.quiet || g.json || s.elements == 0) return;
    mesh_printed = true;
    printer.Break();
    absl::StatusOr<v1::Job> now = c.client().GetJob(job->name());
    if (!now.ok()) return;
    warn({now->warnings().begin(), now->warnings().end()});
    std::fprintf(stderr,
                 "radiosity: %s: %lld surfaces, %lld faces, %lld patches, %lld elements "
                 "(element size %.4g), method %s\n",
                 args.scene.c_str(), static_cast<long long>(scene->surfaces()),
                 static_cast<long long>(now->mesh().faces()),
                 static_cast<long long>(now->mesh().patches()),
                 static_cast<long long>(now->mesh().elements()), now->mesh().element_size(),
                 MethodText(*now, args.spec.solve.method).c_str());
  };
  auto on_snapshot = [&](const Snapshot& s) {
    print_mesh(s);
    if (g.json) PrintJsonLine(SnapshotJson(job->name(), s));
    // Meshing has no elements yet; a solve's bar waits for the mesh line.
    if (s.elements > 0 || s.progress.phase() == v1::JOB_PHASE_MESHING) {
      printer.Update(s.progress, s.final);
    }
    return true;
  };
  absl::StatusOr<Snapshot> last = c.client().Watch(job->name(), 0, true, on_snapshot, &g_stop);
  if (!last.ok() && g_stop) {
    // Ctrl-C: cancel the job and wait for it to end with the results so far.
    absl::StatusOr<v1::Job> cancelled = c.client().CancelJob(job->name());
    if (cancelled.ok() || cancelled.status().code() == absl::StatusCode::kFailedPrecondition) {
      last = c.client().Watch(job->name(), 0, true, on_snapshot, nullptr);
    }
  }
  if (!last.ok()) return Fail(g, CallExit(last.status()), Explain(c, last.status()));
  if (last->state == v1::JOB_STATE_FAILED) {
    return Fail(g, JobErrorExit(last->error), JobErrorStatus(last->error));
  }
  absl::StatusOr<std::vector<std::string>> files =
      c.client().DownloadResults(job->name(), args.out);
  if (!files.ok()) {
    if (last->state == v1::JOB_STATE_CANCELLED &&
        files.status().code() == absl::StatusCode::kFailedPrecondition) {
      return Fail(g, kExitCancelled, absl::CancelledError("cancelled before solving began"));
    }
    return Fail(g, CallExit(files.status()), Explain(c, files.status()));
  }
  absl::StatusOr<v1::Job> ended = c.client().GetJob(job->name());
  std::string reason = ended.ok() ? ended->stop_reason() : service::StateName(last->state);
  if (g.json) {
    PrintJsonLine(
        absl::StrCat("{\"event\":\"result\",\"job\":", ended.ok() ? ToJson(*ended) : "null",
                     ",\"out\":", JsonQuote(args.out), "}"));
  } else if (!args.quiet) {
    std::fprintf(stderr, "radiosity: %s after %.2f s; wrote %s/{%s}\n", reason.c_str(),
                 last->progress.elapsed_seconds(), args.out.c_str(),
                 absl::StrJoin(*files, ",").c_str());
  }
  return last->state == v1::JOB_STATE_CANCELLED ? kExitCancelled : kExitOk;
}

// ---------------------------------------------------------------------------------------------
// upload, jobs, scenes, cancel, get, watch, health

int RunUpload(const Global& g, const std::string& path) {
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  absl::StatusOr<v1::SceneInfo> scene = Upload(**connection, path, g.read);
  if (!scene.ok()) return Fail(g, UploadExit(scene.status()), scene.status());
  if (g.json) {
    PrintJsonLine(ToJson(*scene));
  } else {
    std::fprintf(stdout, "%s\n", scene->name().c_str());
    std::fprintf(stderr, "radiosity: %s: %lld surfaces, %lld faces, %lld materials%s\n",
                 path.c_str(), static_cast<long long>(scene->surfaces()),
                 static_cast<long long>(scene->faces()), static_cast<long long>(scene->materials()),
                 scene->has_emitter() ? "" : " (no emitter)");
  }
  return kExitOk;
}

std::string JobLine(const v1::Job& j) {
  std::string kind = j.has_solve() ? "solve" : "viewfactor";
  std::string state = service::StateName(j.state());
  if (j.state() == v1::JOB_STATE_RUNNING && j.cancel_requested()) state += "*";
  return absl::StrFormat(
      "%-18s %-10s %-10s %10.3g %12lld %8.1f  %-18s %s", j.name(), state, kind,
      j.progress().unshot_fraction(), static_cast<long long>(j.progress().rays()),
      j.progress().elapsed_seconds(), j.scene(), service::TimeText(j.create_time()));
}

int RunJobs(const Global& g, const std::vector<std::string>& states, const std::string& scene,
            int limit) {
  v1::ListJobsRequest request;
  for (const std::string& s : states) {
    v1::JobState state;
    if (!service::ParseStateName(s, &state)) {
      return Fail(
          g, kExitUsage,
          absl::InvalidArgumentError(absl::StrCat(
              "--state ", s, ": not one of QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED")));
    }
    request.add_states(state);
  }
  if (!scene.empty()) request.set_scene(scene.rfind("scenes/", 0) == 0 ? scene : "scenes/" + scene);
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;
  if (!g.json) {
    std::fprintf(stdout, "%-18s %-10s %-10s %10s %12s %8s  %-18s %s\n", "JOB", "STATE", "KIND",
                 "UNSHOT", "RAYS", "SECONDS", "SCENE", "CREATED");
  }
  int shown = 0;
  for (int page = 0; page < 10000 && shown < limit; ++page) {
    request.set_page_size(std::min(1000, limit - shown));
    absl::StatusOr<v1::ListJobsResponse> list = c.client().ListJobs(request);
    if (!list.ok()) return Fail(g, CallExit(list.status()), Explain(c, list.status()));
    for (const v1::Job& j : list->jobs()) {
      if (g.json) {
        PrintJsonLine(ToJson(j));
      } else {
        std::fprintf(stdout, "%s\n", JobLine(j).c_str());
      }
      ++shown;
    }
    if (list->next_page_token().empty()) break;
    request.set_page_token(list->next_page_token());
  }
  return kExitOk;
}

int RunScenes(const Global& g) {
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;
  v1::ListScenesRequest request;
  request.set_page_size(1000);
  for (int page = 0; page < 10000; ++page) {
    absl::StatusOr<v1::ListScenesResponse> list = c.client().ListScenes(request);
    if (!list.ok()) return Fail(g, CallExit(list.status()), Explain(c, list.status()));
    for (const v1::SceneInfo& s : list->scenes()) {
      if (g.json) {
        PrintJsonLine(ToJson(s));
      } else {
        std::fprintf(stdout, "%-20s %8lld faces %10lld bytes  %s  %s\n", s.name().c_str(),
                     static_cast<long long>(s.faces()), static_cast<long long>(s.total_size()),
                     service::TimeText(s.create_time()).c_str(), s.display_name().c_str());
      }
    }
    if (list->next_page_token().empty()) break;
    request.set_page_token(list->next_page_token());
  }
  return kExitOk;
}

int RunCancel(const Global& g, const std::string& job) {
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;
  absl::StatusOr<v1::Job> j = c.client().CancelJob(JobName(job));
  if (!j.ok()) return Fail(g, CallExit(j.status()), Explain(c, j.status()));
  if (g.json) {
    PrintJsonLine(ToJson(*j));
  } else {
    std::fprintf(stdout, "%s %s%s\n", j->name().c_str(), service::StateName(j->state()).c_str(),
                 j->state() == v1::JOB_STATE_RUNNING ? " (cancel requested)" : "");
  }
  return kExitOk;
}

int RunGet(const Global& g, const std::string& job_arg, const std::string& out, bool wait) {
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;
  const std::string job = JobName(job_arg);
  if (wait) {
    std::signal(SIGINT, OnSignal);
    absl::StatusOr<Snapshot> last = c.client().Watch(job, 0, true, nullptr, &g_stop);
    if (!last.ok()) return Fail(g, CallExit(last.status()), Explain(c, last.status()));
  }
  absl::StatusOr<v1::Job> j = c.client().GetJob(job);
  if (!j.ok()) return Fail(g, CallExit(j.status()), Explain(c, j.status()));
  if (j->state() == v1::JOB_STATE_FAILED) {
    return Fail(g, JobErrorExit(j->error()), JobErrorStatus(j->error()));
  }
  absl::StatusOr<std::vector<std::string>> files = c.client().DownloadResults(job, out);
  if (!files.ok()) return Fail(g, CallExit(files.status()), Explain(c, files.status()));
  if (g.json) {
    std::vector<std::string> quoted;
    for (const std::string& f : *files) quoted.push_back(JsonQuote(f));
    PrintJsonLine(absl::StrCat("{\"job\":", JsonQuote(job), ",\"out\":", JsonQuote(out),
                               ",\"files\":[", absl::StrJoin(quoted, ","), "]}"));
  } else {
    std::fprintf(stderr, "radiosity: wrote %s/{%s}\n", out.c_str(),
                 absl::StrJoin(*files, ",").c_str());
  }
  return j->state() == v1::JOB_STATE_CANCELLED ? kExitCancelled : kExitOk;
}

// The solve job `job` once it has results (SUCCEEDED or CANCELLED), for the commands that read
// them; otherwise the exit code of the failure, already reported (`needs` ends its message).
std::variant<v1::Job, int> EndedSolve(const Global& g, Connection& c, const std::string& job,
                                      const std::string& needs) {
  absl::StatusOr<v1::Job> j = c.client().GetJob(job);
  if (!j.ok()) return Fail(g, CallExit(j.status()), Explain(c, j.status()));
  if (!j->has_solve()) {
    return Fail(g, kExitUsage, absl::InvalidArgumentError(absl::StrCat(job, " is not a solve")));
  }
  if (j->state() != v1::JOB_STATE_SUCCEEDED && j->state() != v1::JOB_STATE_CANCELLED) {
    return Fail(g, kExitServer,
                absl::FailedPreconditionError(
                    absl::StrCat(job, " is ", service::StateName(j->state()), "; ", needs)));
  }
  return *std::move(j);
}

int RunReport(const Global& g, const std::string& job_arg, const std::string& out) {
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;
  const std::string job = JobName(job_arg);
  std::variant<v1::Job, int> ended = EndedSolve(g, c, job, "a report needs its results");
  if (const int* code = std::get_if<int>(&ended)) return *code;
  const v1::Job* j = &std::get<v1::Job>(ended);
  std::error_code ec;
  fs::create_directories(out, ec);
  // What the report shows, of the files the job has.
  std::vector<std::string> written;
  for (const char* file : {"summary.json", "image.png", "sensors.csv"}) {
    for (const v1::FileInfo& f : j->results()) {
      if (f.name() == file) written.push_back(file);
    }
  }
  auto has = [&](const char* file) {
    return std::find(written.begin(), written.end(), file) != written.end();
  };
  const bool has_image = has("image.png"), has_sensors = has("sensors.csv");
  if (!has("summary.json")) {
    return Fail(
        g, kExitServer,
        absl::FailedPreconditionError(absl::StrCat(job, " has no summary.json to report on")));
  }
  for (const std::string& file : written) {
    absl::StatusOr<std::vector<std::string>> got = c.client().DownloadResults(job, out, file);
    if (!got.ok()) return Fail(g, CallExit(got.status()), Explain(c, got.status()));
  }
  absl::StatusOr<std::string> summary = ReadWholeFile(JoinPath(out, "summary.json"));
  if (!summary.ok()) return Fail(g, kExitInternal, summary.status());
  std::vector<client::SensorGridStats> grids;
  if (has_sensors) {
    absl::StatusOr<std::string> csv = ReadWholeFile(JoinPath(out, "sensors.csv"));
    absl::StatusOr<std::vector<client::SensorGridStats>> stats =
        csv.ok() ? client::SensorStatsFromCsv(*csv) : csv.status();
    if (!stats.ok()) return Fail(g, kExitInternal, stats.status());
    grids = *std::move(stats);
  }
  absl::StatusOr<std::string> html =
      client::ReportHtml(job, *summary, has_image ? "image.png" : "", grids);
  if (!html.ok()) return Fail(g, kExitInternal, html.status());
  if (absl::Status st = WriteWholeFile(JoinPath(out, "report.html"), *html); !st.ok()) {
    return Fail(g, kExitInternal, st);
  }
  written.push_back("report.html");
  if (g.json) {
    std::vector<std::string> quoted;
    for (const std::string& f : written) quoted.push_back(JsonQuote(f));
    std::vector<std::string> grid_json;
    for (const client::SensorGridStats& s : grids) {
      grid_json.push_back(absl::StrCat(
          "{\"grid\":", JsonQuote(s.name), ",\"points\":", s.points, ",\"min\":", JsonNumber(s.min),
          ",\"mean\":", JsonNumber(s.mean), ",\"max\":", JsonNumber(s.max),
          ",\"u0\":", JsonNumber(s.u0), ",\"min_max\":", JsonNumber(s.min_max), "}"));
    }
    PrintJsonLine(absl::StrCat("{\"job\":", JsonQuote(job), ",\"out\":", JsonQuote(out),
                               ",\"files\":[", absl::StrJoin(quoted, ","), "],\"sensor_grids\":[",
                               absl::StrJoin(grid_json, ","), "]}"));
  } else {
    for (const client::SensorGridStats& s : grids) {
      std::fprintf(stdout, "%s\n", s.ToString().c_str());
    }
    std::fprintf(stderr, "radiosity: wrote %s/{%s}\n", out.c_str(),
                 absl::StrJoin(written, ",").c_str());
  }
  return kExitOk;
}

int StateExit(const Global& g, const Snapshot& last) {
  switch (last.state) {
    case v1::JOB_STATE_SUCCEEDED:
      return kExitOk;
    case v1::JOB_STATE_CANCELLED:
      return kExitCancelled;
    case v1::JOB_STATE_FAILED:
      return Fail(g, JobErrorExit(last.error), JobErrorStatus(last.error));
    default:
      return kExitInternal;
  }
}

int RunWatch(const Global& g, const std::string& job_arg, int64_t after,
             const std::string& preview_dir, int width, int height, bool quiet) {
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;
  const std::string job = JobName(job_arg);
  absl::StatusOr<v1::Job> j = c.client().GetJob(job);
  if (!j.ok()) return Fail(g, CallExit(j.status()), Explain(c, j.status()));
  std::unique_ptr<client::Previewer> previewer;
  std::string scene_dir;
  if (!preview_dir.empty()) {
    std::error_code ec;
    fs::create_directories(preview_dir, ec);
    scene_dir = preview_dir + "/.scene";
    absl::StatusOr<std::unique_ptr<client::Previewer>> p =
        client::Previewer::Create(c.client(), *j, scene_dir);
    if (!p.ok()) return Fail(g, CallExit(p.status()), p.status());
    previewer = *std::move(p);
  }
  std::signal(SIGINT, OnSignal);
  double tolerance = j->has_solve() && j->solve().tolerance() > 0 ? j->solve().tolerance() : 1e-3;
  ProgressPrinter printer(tolerance, quiet || g.json);
  absl::Status preview_error;
  bool skipped_note = false;
  auto on_snapshot = [&](const Snapshot& s) {
    if (g.json) PrintJsonLine(SnapshotJson(job, s));
    printer.Update(s.progress, s.final);
    if (previewer && !s.radiosity.empty() && preview_error.ok()) {
      // The server announced the mesh these values refer to: a refinement pass made a new one.
      if (s.mesh && s.mesh->version != previewer->mesh_version()) {
        preview_error = previewer->UseMesh(*s.mesh);
        if (!preview_error.ok()) return false;
      }
      if (s.elements != previewer->elements()) {
        // No announcement to rebuild the mesh from (a server that does not send geometry).
        if (!skipped_note) {
          std::fprintf(stderr,
                       "radiosity: note: snapshots of the refined mesh (%lld elements) have no "
                       "preview\n",
                       static_cast<long long>(s.elements));
        }
        skipped_note = true;
      } else {
        std::string png = absl::StrFormat("%s/snapshot-%06d.png", preview_dir, s.sequence);
        preview_error =
            previewer->Render(s.radiosity, service::CameraOf(j->solve()), width, height, "", png);
      }
    }
    return preview_error.ok();
  };
  absl::StatusOr<Snapshot> last =
      c.client().Watch(job, after, !previewer, on_snapshot, &g_stop, /*include_mesh=*/!!previewer);
  if (!scene_dir.empty()) {
    std::error_code ec;
    fs::remove_all(scene_dir, ec);
  }
  if (!preview_error.ok()) return Fail(g, kExitInternal, preview_error);
  if (!last.ok()) return Fail(g, CallExit(last.status()), Explain(c, last.status()));
  if (!g.json) {
    std::fprintf(stdout, "%s %s after %.2f s, %lld rays, unshot %.3g\n", job.c_str(),
                 service::StateName(last->state).c_str(), last->progress.elapsed_seconds(),
                 static_cast<long long>(last->progress.rays()), last->progress.unshot_fraction());
  }
  return StateExit(g, *last);
}

int RunHealth(const Global& g) {
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;
  absl::StatusOr<bool> serving = c.client().CheckHealth(service::kServiceName);
  if (!serving.ok()) return Fail(g, CallExit(serving.status()), Explain(c, serving.status()));
  if (g.json) {
    PrintJsonLine(absl::StrCat("{\"service\":", JsonQuote(service::kServiceName),
                               ",\"serving\":", *serving ? "true" : "false", "}"));
  } else {
    std::fprintf(stdout, "%s %s\n", service::kServiceName, *serving ? "SERVING" : "NOT_SERVING");
  }
  return *serving ? kExitOk : kExitServer;
}

// ---------------------------------------------------------------------------------------------
// viewfactor, render

// Which rows of a view-factor job's result it computed, given its --from names (all if none).
std::vector<bool> ComputedRows(const v1::ViewFactorResult& r,
                               const std::vector<std::string>& from) {
  const std::set<std::string> names(from.begin(), from.end());
  std::vector<bool> computed(r.surfaces_size(), from.empty());
  for (int i = 0; i < r.surfaces_size() && !from.empty(); ++i) {
    computed[i] = names.count(r.surfaces(i)) > 0;
  }
  return computed;
}

// Writes the CSV "surface,area,row_sum" of a view-factor job's result (the rows it computed).
absl::Status WriteRowSums(const v1::ViewFactorResult& r, const std::vector<bool>& computed,
                          const std::string& path) {
  OutputFile file(path, "view-factor row sums CSV");
  if (absl::Status st = file.Open(); !st.ok()) return st;
  std::string text = "surface,area,row_sum\n";
  for (int i = 0; i < r.surfaces_size(); ++i) {
    if (!computed[i]) continue;
    absl::StrAppend(&text, CsvField(r.surfaces(i)), ",",
                    absl::StrFormat("%.12g", i < r.areas_size() ? r.areas(i) : 0.0), ",",
                    absl::StrFormat("%.12g", i < r.row_sums_size() ? r.row_sums(i) : 0.0), "\n");
  }
  if (absl::Status st = file.Write(text); !st.ok()) return st;
  return file.Close();
}

// `radiosity viewfactor`'s files besides --out.
struct ViewFactorFiles {
  std::string row_sums;  // --row-sums
  std::string thermal;   // --thermal (input)
  std::string exchange;  // --exchange
  std::string gebhart;   // --gebhart
};

int RunViewFactor(const Global& g, const std::string& scene_path, ViewFactorOptions options,
                  const std::string& out, bool check, const ViewFactorFiles& files_out) {
  const std::string& row_sums = files_out.row_sums;
  if (files_out.thermal.empty() && (!files_out.exchange.empty() || !files_out.gebhart.empty())) {
    return Fail(g, kExitUsage,
                absl::InvalidArgumentError("--exchange and --gebhart need --thermal FILE.csv"));
  }
  if (!files_out.thermal.empty()) {
    absl::StatusOr<std::vector<SurfaceThermal>> thermal = LoadThermal(files_out.thermal);
    if (!thermal.ok()) return Fail(g, kExitUsage, thermal.status());
    options.thermal.surfaces = std::move(*thermal);
  }
  if (absl::Status st = Validate(options, FieldNaming::kFlag); !st.ok()) {
    return Fail(g, kExitUsage, st);
  }
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;
  absl::StatusOr<v1::SceneInfo> scene = Upload(c, scene_path, g.read);
  if (!scene.ok()) return Fail(g, UploadExit(scene.status()), scene.status());
  v1::CreateJobRequest request;
  *request.mutable_view_factor() = service::ToViewFactorSpec(options);
  int code = kExitOk;
  std::optional<v1::Job> job = Submit(g, c, *scene, std::move(request), &code);
  if (!job) return code;
  absl::StatusOr<Snapshot> last = c.client().Watch(job->name(), 0, true, nullptr, &g_stop);
  if (!last.ok() && g_stop) {
    (void)c.client().CancelJob(job->name());
    return Fail(g, kExitCancelled, absl::CancelledError("cancelled"));
  }
  if (!last.ok()) return Fail(g, CallExit(last.status()), Explain(c, last.status()));
  if (last->state != v1::JOB_STATE_SUCCEEDED) return StateExit(g, *last);
  absl::StatusOr<v1::Job> ended = c.client().GetJob(job->name());
  if (!ended.ok()) return Fail(g, CallExit(ended.status()), Explain(c, ended.status()));
  // The CSV goes to --out, or to stdout.
  std::string target_dir = out.empty() ? "" : fs::path(out).parent_path().string();
  char tmp_pattern[] = "/tmp/radiosity-vf-XXXXXX";
  std::string tmp = mkdtemp(tmp_pattern) ? tmp_pattern : "";
  if (tmp.empty()) return Fail(g, kExitInternal, absl::InternalError("cannot create a temp dir"));
  // --out FILE.mtx: the Matrix Market file; otherwise the CSV.
  const std::string result_file =
      fs::path(out).extension() == ".mtx" ? "viewfactors.mtx" : "viewfactors.csv";
  absl::StatusOr<std::vector<std::string>> files =
      c.client().DownloadResults(job->name(), tmp, result_file);
  std::string csv = tmp + "/" + result_file;
  if (!files.ok()) {
    code = Fail(g, CallExit(files.status()), Explain(c, files.status()));
  } else if (!out.empty()) {
    std::error_code ec;
    if (!target_dir.empty()) fs::create_directories(target_dir, ec);
    fs::copy_file(csv, out, fs::copy_options::overwrite_existing, ec);
    if (ec)
      code = Fail(g, kExitInternal, absl::InternalError(absl::StrCat(out, ": ", ec.message())));
  } else if (!g.json) {
    absl::StatusOr<std::string> text = ReadWholeFile(csv);
    if (text.ok()) std::fwrite(text->data(), 1, text->size(), stdout);
  }
  const v1::ViewFactorResult& r = ended->view_factor_result();
  const std::vector<bool> computed = ComputedRows(r, options.from);
  if (code == kExitOk && !row_sums.empty()) {
    if (absl::Status st = WriteRowSums(r, computed, row_sums); !st.ok())
      code = Fail(g, kExitInternal, st);
  }
  // --exchange and --gebhart: the job's exchange.csv and gebhart.csv.
  for (const auto& [name, path] :
       {std::pair<std::string, std::string>{"exchange.csv", files_out.exchange},
        {"gebhart.csv", files_out.gebhart}}) {
    if (code != kExitOk || path.empty()) continue;
    absl::StatusOr<std::vector<std::string>> got =
        c.client().DownloadResults(job->name(), tmp, name);
    if (!got.ok()) {
      code = Fail(g, CallExit(got.status()), Explain(c, got.status()));
      break;
    }
    std::error_code ec;
    if (fs::path(path).has_parent_path()) fs::create_directories(fs::path(path).parent_path(), ec);
    fs::copy_file(tmp + "/" + name, path, fs::copy_options::overwrite_existing, ec);
    if (ec) {
      code = Fail(g, kExitInternal, absl::InternalError(absl::StrCat(path, ": ", ec.message())));
    }
  }
  if (code == kExitOk && g.json) {
    std::string line = absl::StrCat("{\"job\":", JsonQuote(job->name()), ",\"result\":", ToJson(r));
    if (!out.empty()) absl::StrAppend(&line, ",\"out\":", JsonQuote(out));
    if (out.empty()) {
      absl::StatusOr<std::string> text = ReadWholeFile(csv);
      absl::StrAppend(&line, ",\"csv\":", JsonQuote(text.ok() ? *text : ""));
    }
    PrintJsonLine(line + "}");
  } else if (code == kExitOk && (check || r.enforced() != "none")) {
    if (r.enforced() != "none" && !r.enforced().empty()) {
      std::fprintf(stderr,
                   "radiosity: before --enforce %s: max reciprocity error %.3g, max closure error "
                   "%.3g; after it (below) the smallest factor is %.3g\n",
                   r.enforced().c_str(), r.max_reciprocity_error_before(),
                   r.max_closure_error_before(), r.smallest_entry());
    }
    std::fprintf(stderr,
                 "radiosity: %d surfaces, method %s: max reciprocity error %.3g, max closure "
                 "error %.3g (closure holds only in closed enclosures)\n",
                 r.surfaces_size(), options.method.c_str(), r.max_reciprocity_error(),
                 r.max_closure_error());
    if (options.method == "montecarlo" && options.near > 0) {
      std::fprintf(stderr,
                   "radiosity: %lld pairs integrated exactly (--near); the largest standard error "
                   "of a row's ray-estimated part is %.3g\n",
                   static_cast<long long>(r.near_pairs()), r.ray_row_error());
    }
    for (int i = 0; i < r.surfaces_size() && i < r.row_sums_size(); ++i) {
      if (!computed[i]) continue;
      std::fprintf(stderr, "radiosity:   %s: sum of F = %.6f\n", r.surfaces(i).c_str(),
                   r.row_sums(i));
    }
  }
  if (code == kExitOk && !g.json && r.exchange_size() > 0) {
    std::fprintf(stderr,
                 "radiosity: radiative exchange (Gebhart factors: max reciprocity error %.3g, "
                 "max part leaving the scene %.3g); net = emitted - absorbed, W:\n",
                 r.gebhart_max_reciprocity_error(), r.gebhart_max_closure_error());
    if (r.enforced().empty() || r.enforced() == "none") {
      std::fprintf(stderr,
                   "radiosity: note: the factors were not enforced; the exchange obeys Kirchhoff's "
                   "law only as exactly as they are reciprocal and close (--enforce closure for a "
                   "closed enclosure, reciprocity otherwise)\n");
    }
    for (const v1::SurfaceExchange& e : r.exchange()) {
      std::fprintf(
          stderr, "radiosity:   %s: eps %.4g, T %.6g K: emitted %.6g, absorbed %.6g, net %.6g\n",
          e.surface().c_str(), e.emissivity(), e.temperature(), e.emitted(), e.absorbed(), e.net());
    }
  }
  std::error_code ec;
  fs::remove_all(tmp, ec);
  return code;
}

int RunRender(const Global& g, const std::string& job_arg, const std::string& out,
              const std::string& camera, int width, int height, bool wireframe,
              const std::string& false_color_text, int samples_per_pixel, int final_gather) {
  std::optional<FalseColorRange> false_color;
  if (!false_color_text.empty()) {
    absl::StatusOr<FalseColorRange> range = ParseFalseColorRange(false_color_text, "--false-color");
    if (!range.ok()) return Fail(g, kExitUsage, range.status());
    if (fs::path(out).extension() != ".png") {
      return Fail(g, kExitUsage,
                  absl::InvalidArgumentError(
                      absl::StrCat("--false-color writes a PNG; --out ", out, " is not .png")));
    }
    false_color = *range;
  }
  absl::StatusOr<std::unique_ptr<Connection>> connection = Connection::Open(g);
  if (!connection.ok()) return FailToConnect(g, connection.status());
  Connection& c = **connection;
  const std::string job = JobName(job_arg);
  std::variant<v1::Job, int> ended = EndedSolve(g, c, job, "render needs a result");
  if (const int* code = std::get_if<int>(&ended)) return *code;
  const v1::Job* j = &std::get<v1::Job>(ended);
  char tmp_pattern[] = "/tmp/radiosity-render-XXXXXX";
  std::string tmp = mkdtemp(tmp_pattern) ? tmp_pattern : "";
  if (tmp.empty()) return Fail(g, kExitInternal, absl::InternalError("cannot create a temp dir"));
  int code = kExitOk;
  absl::StatusOr<std::unique_ptr<client::Previewer>> p =
      client::Previewer::Create(c.client(), *j, tmp);
  absl::StatusOr<Snapshot> final_snapshot =
      p.ok() ? c.client().Watch(job, 0, false, nullptr, nullptr, /*include_mesh=*/true)
             : p.status();
  absl::Status mesh_status;
  if (final_snapshot.ok() && final_snapshot->mesh &&
      final_snapshot->mesh->version != (*p)->mesh_version()) {
    // The mesh the result refers to (refined, for an adaptive job), as the server announced it.
    mesh_status = (*p)->UseMesh(*final_snapshot->mesh);
  }
  if (!final_snapshot.ok()) {
    code = Fail(g, CallExit(final_snapshot.status()), Explain(c, final_snapshot.status()));
  } else if (!mesh_status.ok()) {
    code = Fail(g, kExitInternal, mesh_status);
  } else if (final_snapshot->elements != (*p)->elements()) {
    code = Fail(g, kExitServer,
                absl::FailedPreconditionError(absl::StrCat(
                    job, " was solved on an adaptively refined mesh (", final_snapshot->elements,
                    " elements) whose geometry the server did not announce (it ended before "
                    "servers kept it); use its image.png or mesh.ply")));
  } else if (final_snapshot->radiosity.empty()) {
    code =
        Fail(g, kExitServer, absl::FailedPreconditionError(absl::StrCat(job, " has no radiosity")));
  } else {
    std::string ext = fs::path(out).extension().string();
    const std::string& view = camera.empty() ? service::CameraOf(j->solve()) : camera;
    int w = width > 0 ? width : (j->solve().width() > 0 ? j->solve().width() : 512);
    int h = height > 0 ? height : (j->solve().height() > 0 ? j->solve().height() : 512);
    const FalseColorRange* scale = false_color ? &*false_color : nullptr;
    // The final gather sees the job's sky and luminaires as its solve did.
    std::optional<GatherOptions> gather;
    absl::Status st;
    if (final_gather > 0) {
      absl::StatusOr<JobSpec> spec = service::ToJobSpec(j->solve());
      gather.emplace();
      gather->samples = final_gather;
      gather->shadow_rays = 16;
      gather->max_shadow_rays = 256;
      if (spec.ok()) {
        gather->seed = spec->solve.seed;
        gather->sky = spec->solve.sky;
        gather->luminaires = spec->solve.luminaires;
        gather->luminaire_samples = spec->solve.luminaire_samples;
      } else {
        st = spec.status();
      }
    }
    const GatherOptions* gathering = gather ? &*gather : nullptr;
    std::atomic<int> shown{-1};
    auto progress = [&](double f) {
      const int tenth = static_cast<int>(10 * f);
      int before = shown.load();
      if (g.json || gathering == nullptr || tenth <= before ||
          !shown.compare_exchange_strong(before, tenth)) {
        return;
      }
      std::fprintf(stderr, "render: %d%%\n", 10 * tenth);
    };
    if (st.ok()) {
      st = ext == ".exr" ? (*p)->Render(final_snapshot->radiosity, view, w, h, out, "", wireframe,
                                        nullptr, samples_per_pixel, gathering, progress)
                         : (*p)->Render(final_snapshot->radiosity, view, w, h, "", out, wireframe,
                                        scale, samples_per_pixel, gathering, progress);
    }
    if (!st.ok()) {
      code =
          Fail(g, st.code() == absl::StatusCode::kInvalidArgument ? kExitUsage : kExitInternal, st);
    } else if (g.json) {
      PrintJsonLine(absl::StrCat("{\"job\":", JsonQuote(job), ",\"out\":", JsonQuote(out), "}"));
    } else {
      std::fprintf(stderr, "radiosity: wrote %s\n", out.c_str());
    }
  }
  std::error_code ec;
  fs::remove_all(tmp, ec);
  return code;
}

// ---------------------------------------------------------------------------------------------

int Main(int argc, char** argv) {
  // A closed stdout (`radiosity --json watch JOB | head`) must not kill the process before it
  // has cleaned up its in-process service: writes fail instead.
  std::signal(SIGPIPE, SIG_IGN);
  CLI::App app{"radiosity: diffuse global illumination by zonal (radiosity) methods", "radiosity"};
  app.require_subcommand(1);
  // --help shows every option's default: the value its variable holds before parsing.
  app.option_defaults()->always_capture_default();
  app.fallthrough();  // Global options are accepted after the command name too.
  app.set_version_flag(
      "--version",
      absl::StrCat("radiosity ", RADIOSITY_VERSION, " (gRPC ", grpc::Version(), ", protobuf ",
                   google::protobuf::internal::VersionString(GOOGLE_PROTOBUF_VERSION), ")"));
  Global g;
  app.add_option("--server", g.server,
                 "HOST:PORT of a radiosity-server (default: a service inside this process)");
  app.add_option("--data-dir", g.data_dir,
                 "Without --server: keep the in-process service's data here (default: a "
                 "temporary directory)");
  app.add_flag("--tls", g.security.tls,
               "Connect to --server over TLS, verifying it against the system's CAs");
  app.add_option("--tls-ca", g.security.ca_file,
                 "Connect over TLS, verifying the server against this PEM CA")
      ->check(CLI::ExistingFile);
  app.add_option("--tls-cert", g.security.cert_file,
                 "Client certificate (PEM) for a server that requires one (with --tls-key)")
      ->check(CLI::ExistingFile);
  app.add_option("--tls-key", g.security.key_file, "Private key (PEM) of --tls-cert")
      ->check(CLI::ExistingFile);
  app.add_option("--tls-server-name", g.security.server_name,
                 "Name to verify in the server's certificate (default: the host of --server)");
  app.add_option("--token-file", g.token_file,
                 "File whose first line is the bearer token of a server with tenants (default: "
                 "$RADIOSITY_TOKEN; needs TLS)")
      ->check(CLI::ExistingFile);
  app.add_flag("--json", g.json, "Print JSON lines on stdout");
  app.add_option("--timeout", g.timeout, "Deadline of each call, seconds")
      ->check(CLI::Range(0.1, 1e6));
  app.add_option("--log-level", g.log_level, "Log level of the in-process service (default off)");
  app.add_flag("--strict", g.read.strict,
               "OBJ: refuse faces without a material, unknown materials, missing material "
               "libraries and Kd >= 1 instead of mending them with a warning");
  app.add_flag("--vertex-colors", g.read.vertex_colors,
               "OBJ (v x y z r g b) and models: take vertex colours, where there are any, as "
               "the diffuse reflectance");

  // solve: the flags of the local solver, unchanged.
  SolveArgs solve;
  JobSpec& spec = solve.spec;
  CLI::App* cmd = app.add_subcommand("solve", "Solve a scene and write results to --out DIR");
  cmd->add_option("scene", solve.scene,
                  "Scene file (.obj, .json, .pb, or a model: .gltf .glb .fbx .dae .3ds .ply .stl)")
      ->required();
  cmd->add_option("--out", solve.out, "Output directory (required unless --detach)");
  auto* size_opt = cmd->add_option("--element-size", spec.mesh.element_size,
                                   "Target element edge length (scene units)");
  cmd->add_option("--max-elements", spec.mesh.max_elements,
                  "Largest element count (used when --element-size is not given)")
      ->excludes(size_opt);
  cmd->add_option("--patch-depth", spec.mesh.patch_depth,
                  "Elements per patch edge = 2^depth (patches shoot, elements receive)");
  cmd->add_option("--agglomerate", spec.mesh.agglomerate_degrees,
                  "Gather faces smaller than an element, of one surface and with normals within "
                  "this many degrees, into elements (0: off; progressive and reflection only)")
      ->capture_default_str();
  cmd->add_option("--method", spec.solve.method, MethodHelp());
  cmd->add_option("--formfactor", spec.solve.formfactor.method, EstimatorHelp());
  cmd->add_option("--sampling", spec.solve.formfactor.sampling,
                  "Monte Carlo sampling: sobol (Owen-scrambled), random, stratified or halton");
  cmd->add_option("--direct", spec.solve.direct,
                  "progressive: direct light computed (exact factors x visible fraction) or shot");
  cmd->add_option("--direct-shadow-rays", spec.solve.direct_shadow_rays,
                  "computed direct light: shadow rays per element and emitting face");
  cmd->add_option("--indirect", spec.solve.indirect,
                  "progressive: light from reflectors received per patch (interpolated) or "
                  "per element");
  cmd->add_option("--hemicube-resolution", spec.solve.formfactor.hemicube_resolution,
                  "Hemicube cells along the top face's edge");
  cmd->add_option("--shadow-rays", spec.solve.formfactor.shadow_rays,
                  "analytic: shadow rays per receiver sample point");
  cmd->add_flag("--ambient", solve.ambient,
                "Accepted and ignored: a solution before convergence always includes the "
                "estimate of the light not yet propagated (Cohen's ambient term)");
  cmd->add_option("--overshoot", spec.solve.overshoot,
                  "progressive: overshooting factor (1 = none)");
  cmd->add_option("--max-matrix-mb", spec.solve.max_matrix_mb,
                  "jacobi/gauss-seidel: refuse matrices larger than this (MiB)");
  cmd->add_option("--tolerance", spec.solve.tolerance,
                  "Stop when unshot power (or the residual) < this fraction of emitted power");
  cmd->add_option("--max-rays", spec.solve.max_rays, "Stop after this many rays (0: no limit)");
  cmd->add_option("--max-seconds", spec.solve.max_seconds,
                  "Stop after this many seconds of meshing and solving (0: no limit)");
  cmd->add_option("--seed", spec.solve.seed, "Random seed (results are identical for a seed)");
  cmd->add_option("--threads", spec.solve.threads, "Worker threads (0: all cores)");
  cmd->add_option("--rays-per-element", spec.solve.rays_per_element,
                  "Ray density: each ray carries emitted power / (this x elements)");
  cmd->add_option("--shooting", solve.shooting,
                  "Origins of a patch's rays: weighted (by element unshot power) or uniform")
      ->check(CLI::IsMember({"weighted", "uniform"}));
  cmd->add_option("--sensors", solve.sensors,
                  "Points \"x y z nx ny nz\" a line; writes sensors.csv (irradiance)");
  cmd->add_option("--sensor-samples", spec.sensor_samples,
                  "Sensors: rays per point gathering indirect light");
  cmd->add_option("--emit", solve.emit,
                  "NAME=R,G,B: make material NAME (or else surface NAME) emit this radiant "
                  "exitance, W/m^2 (repeatable; for models without lights)");
  cmd->add_option("--sky", solve.sky,
                  "uniform=E or overcast=E (or =R,G,B): daylight from outside, E the horizontal "
                  "irradiance under the open sky, W/m^2 (CIE overcast: zenith 3x the horizon)");
  cmd->add_option("--sky-up", solve.sky_up, "X,Y,Z: the sky's zenith direction (default 0,1,0)");
  cmd->add_option("--sky-samples", spec.solve.sky.samples,
                  "Sky: rays per element side (default 256)");
  cmd->add_option("--luminaire", solve.luminaires,
                  "'FILE.ies at=X,Y,Z [aim=X,Y,Z] [c0=X,Y,Z] [multiplier=K] [color=R,G,B]': a "
                  "luminaire from an IES LM-63 or EULUMDAT (.ldt) file, uploaded with the scene; "
                  "candela in, lux out for a scene in metres (repeatable; aim defaults to 0,-1,0)");
  cmd->add_option("--luminaire-samples", spec.solve.luminaire_samples,
                  "Luminaires: points per element side and area luminaire (default 64)");
  cmd->add_option("--camera", spec.camera,
                  "View for the image: \"eye=x,y,z look=x,y,z up=x,y,z fov=deg\"");
  cmd->add_option("--width", spec.width, "Image width in pixels");
  cmd->add_option("--height", spec.height, "Image height in pixels");
  cmd->add_option("--refine", spec.refine.tolerance,
                  "Adaptive refinement: split elements whose luminance differs from a "
                  "neighbour's by more than this fraction (0: off); --max-elements is the budget");
  cmd->add_option("--min-element-size", spec.refine.min_element_size,
                  "Refinement: never split elements smaller than this (0: initial size / 64)");
  cmd->add_option("--refine-passes", spec.refine.max_passes, "Refinement passes at most");
  cmd->add_option("--refine-light-samples", spec.refine.light_samples,
                  "Refinement: emitter points tested for shadow boundaries per element");
  cmd->add_flag("--refine-resolve", spec.refine.resolve,
                "Refinement: solve again from scratch after each split (indirect gradients too) "
                "instead of re-gathering the new elements' direct light");
  cmd->add_option("--refine-direct-samples", spec.refine.direct_samples,
                  "Refinement: shadow rays per new element side when re-gathering");
  cmd->add_option("--snapshot-interval", solve.snapshot_interval,
                  "Seconds between progress snapshots (0: the server's default, 0.5)");
  cmd->add_flag("--detach", solve.detach, "Submit the job, print its name and return");
  cmd->add_flag("--quiet,-q", solve.quiet, "No progress output");

  std::string upload_scene;
  CLI::App* upload = app.add_subcommand("upload", "Upload a scene and print its name");
  upload
      ->add_option("scene", upload_scene,
                   "Scene file (.obj, .json, .pb, or a model: .gltf .glb .fbx .dae .3ds .ply .stl)")
      ->required();

  std::string job_arg, out, preview_dir;
  int64_t after = 0;
  int preview_width = 256, preview_height = 256;
  bool watch_quiet = false;
  CLI::App* watch = app.add_subcommand("watch", "Follow a job's progress until it ends");
  watch->add_option("job", job_arg, "Job name (jobs/ID or ID)")->required();
  watch->add_option("--after", after, "Resume after this snapshot sequence number")
      ->check(CLI::NonNegativeNumber);
  watch->add_option("--preview-dir", preview_dir, "Write a PNG of every snapshot into this dir");
  watch->add_option("--preview-width", preview_width, "Preview width")->check(CLI::Range(1, 4096));
  watch->add_option("--preview-height", preview_height, "Preview height")
      ->check(CLI::Range(1, 4096));
  watch->add_flag("--quiet,-q", watch_quiet, "No progress bar");

  std::vector<std::string> states;
  std::string jobs_scene;
  int limit = 100;
  CLI::App* jobs = app.add_subcommand("jobs", "List jobs, newest first");
  jobs->add_option("--state", states, "Only jobs in this state (repeatable)");
  jobs->add_option("--scene", jobs_scene, "Only jobs on this scene");
  jobs->add_option("--limit", limit, "Most jobs to list")->check(CLI::Range(1, 1'000'000));

  CLI::App* scenes = app.add_subcommand("scenes", "List uploaded scenes");

  CLI::App* cancel = app.add_subcommand("cancel", "Cancel a job");
  cancel->add_option("job", job_arg, "Job name")->required();

  bool wait = false;
  CLI::App* get = app.add_subcommand("get", "Download a job's results into --out DIR");
  get->add_option("job", job_arg, "Job name")->required();
  get->add_option("--out", out, "Output directory")->required();
  get->add_flag("--wait", wait, "Wait for the job to end first");

  std::string vf_scene;
  ViewFactorOptions vf;
  bool vf_check = false;
  ViewFactorFiles vf_files;
  CLI::App* viewfactor =
      app.add_subcommand("viewfactor", "Surface-to-surface view factors (CSV from,to,F)");
  viewfactor
      ->add_option("scene", vf_scene,
                   "Scene file (.obj, .json, .pb, or a model: .gltf .glb .fbx .dae .3ds .ply .stl)")
      ->required();
  viewfactor->add_option("--method", vf.method, "analytic, montecarlo or hemicube");
  viewfactor->add_option("--out", out,
                         "CSV file to write (default: stdout); FILE.mtx: Matrix Market instead");
  viewfactor->add_flag("--check", vf_check, "Report reciprocity and closure errors");
  viewfactor->add_option("--enforce", vf.enforce,
                         "none, reciprocity, or closure (closed enclosures: rows sum to 1 too)");
  viewfactor->add_option("--row-sums", vf_files.row_sums, "CSV file of surface,area,row_sum");
  viewfactor->add_option("--thermal", vf_files.thermal,
                         "CSV surface,emissivity,temperature (K; surface * for the rest): compute "
                         "Gebhart factors and the net radiative exchange");
  viewfactor->add_option("--ambient-temperature", vf.thermal.ambient_temperature,
                         "--thermal: kelvin of the black environment open scenes radiate to "
                         "(default 0)");
  viewfactor->add_option("--exchange", vf_files.exchange,
                         "--thermal: CSV of each surface's emitted, absorbed and net power (W)");
  viewfactor->add_option("--gebhart", vf_files.gebhart,
                         "--thermal: CSV from,to,gebhart,net_W of the Gebhart factors");
  viewfactor->add_option("--tolerance", vf.tolerance,
                         "analytic: absolute accuracy (estimated) of each factor and each row sum");
  viewfactor->add_option("--occlusion", vf.occlusion,
                         "analytic: exact (obstructions clipped away) or sampled (shadow rays)");
  viewfactor->add_option("--shadow-rays", vf.shadow_rays,
                         "analytic, --occlusion sampled: shadow rays per point");
  viewfactor->add_option("--rays-per-surface", vf.rays_per_surface, "montecarlo: rays per surface");
  viewfactor->add_option("--near", vf.near,
                         "montecarlo: pairs closer than this x the larger surface's diagonal are "
                         "integrated exactly, the rest by rays (0: all by rays)");
  viewfactor
      ->add_option("--from", vf.from,
                   "Only the rows of these surfaces (comma-separated names): their factors to "
                   "every surface, at the cost of those rows alone")
      ->delimiter(',');
  viewfactor->add_option("--sampling", vf.sampling,
                         "montecarlo: stratified, sobol, random or halton");
  viewfactor->add_option("--hemicube-resolution", vf.hemicube_resolution, "hemicube: resolution");
  viewfactor->add_option("--hemicube-points", vf.hemicube_points,
                         "hemicube: hemicubes per surface");
  viewfactor->add_option("--seed", vf.seed, "Random seed");
  viewfactor->add_option("--threads", vf.threads, "Threads (0: all cores)");

  std::string render_camera;
  int render_width = 0, render_height = 0;
  CLI::App* render =
      app.add_subcommand("render", "Render a finished solve (PNG, or EXR by extension)");
  render->add_option("job", job_arg, "Job name")->required();
  render->add_option("--out", out, "Image file (.png or .exr)")->required();
  render->add_option("--camera", render_camera, "\"eye=x,y,z look=x,y,z up=x,y,z fov=deg\"");
  render->add_option("--width", render_width, "Width (default: the job's)")
      ->check(CLI::Range(1, 16384));
  render->add_option("--height", render_height, "Height (default: the job's)")
      ->check(CLI::Range(1, 16384));
  std::string render_false_color;
  render->add_option("--false-color", render_false_color,
                     "MIN:MAX or auto: radiosity (W per square scene unit, luminance-weighted) in "
                     "false colour on this scale (auto: from the lowest value in view to the 99th "
                     "percentile), with a legend and its unit (PNG)");
  bool render_wireframe = false;
  render->add_flag("--wireframe", render_wireframe,
                   "Draw the element edges over the shading (the refined mesh of an adaptive job)");
  int render_spp = 4, render_gather = 0;
  render->add_option("--samples-per-pixel", render_spp, "Rays per pixel (default 4)")
      ->check(CLI::Range(1, 4096));
  render
      ->add_option("--final-gather", render_gather,
                   "N: where a ray reaches a diffuse surface, gather its light there (direct "
                   "light computed, N rays into the solution) instead of interpolating the "
                   "elements: sharp shadows, no mesh (default 0: interpolate)")
      ->check(CLI::Range(0, 1 << 20));

  CLI::App* report = app.add_subcommand(
      "report", "Write an HTML report of a finished solve (image, convergence, energy, sensors)");
  report->add_option("job", job_arg, "Job name")->required();
  report->add_option("--out", out, "Directory for report.html and the files it shows")->required();
  CLI::App* completion = app.add_subcommand(
      "completion", "Print a shell completion script: source <(radiosity completion bash)");
  std::string shell;
  completion->add_option("shell", shell, "The shell (bash)")
      ->required()
      ->check(CLI::IsMember({"bash"}));
  CLI::App* health = app.add_subcommand("health", "Check that the service is SERVING");
  CLI::App* methods = app.add_subcommand(
      "methods",
      "List the solution methods and form-factor estimators, and the options each reads");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    int code = app.exit(e);
    return code == 0 ? kExitOk : kExitUsage;
  }
  try {
    if (cmd->parsed()) return RunSolve(g, solve);
    if (upload->parsed()) return RunUpload(g, upload_scene);
    if (watch->parsed()) {
      return RunWatch(g, job_arg, after, preview_dir, preview_width, preview_height, watch_quiet);
    }
    if (jobs->parsed()) return RunJobs(g, states, jobs_scene, limit);
    if (scenes->parsed()) return RunScenes(g);
    if (cancel->parsed()) return RunCancel(g, job_arg);
    if (get->parsed()) return RunGet(g, job_arg, out, wait);
    if (viewfactor->parsed()) return RunViewFactor(g, vf_scene, vf, out, vf_check, vf_files);
    if (render->parsed()) {
      return RunRender(g, job_arg, out, render_camera, render_width, render_height,
                       render_wireframe, render_false_color, render_spp, render_gather);
    }
    if (health->parsed()) return RunHealth(g);
    if (report->parsed()) return RunReport(g, job_arg, out);
    if (completion->parsed()) {
      std::fputs(client::BashCompletion(app).c_str(), stdout);
      return kExitOk;
    }
    if (methods->parsed()) {
      std::fputs(MethodTables().c_str(), stdout);
      return kExitOk;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "radiosity: error: %s\n", e.what());
    return kExitInternal;
  }
  return kExitUsage;
}

}  // namespace
}  // namespace radiosity

int main(int argc, char** argv) { return radiosity::Main(argc, argv); }
