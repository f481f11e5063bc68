// radiosity-loadtest: a bounded loopback load test of the radiosity service
// (docs/service/server.md).
//
//   radiosity-loadtest [--seconds 60] [--clients 4] [--inflight 2] [--watchers 2]
//                      [--server HOST:PORT | --server-bin PATH --workers 2 --threads-per-job 1]
//                      [--grace 60] [--max-rays 100000] [--max-elements 200] [--json FILE]
//                      [--tls-dir DIR]
//
// Without --server it starts `radiosity-server` (next to this binary, or --server-bin) as a child
// process on 127.0.0.1 with a port it picks itself (--port-file) and a temporary data directory,
// and stops it with SIGTERM at the end. Only loopback or the given address is ever contacted.
//
// For --seconds, N client threads each keep --inflight small solves of one small scene
// outstanding (create, poll GetJob until it has ended, create the next), and M watcher threads
// stream WatchJob (full snapshots) on jobs that are running. When the time is up no more jobs are
// created, and every job created must reach a terminal state within --grace seconds: a job the
// server no longer knows is LOST, one still queued or running is STUCK. Finally every job is
// looked up again through ListJobs. The exit status is 0 only if no job was lost or stuck, every
// job SUCCEEDED, and no watch stream failed; timing never affects it.
//
// Reported: jobs submitted / succeeded / failed / lost / stuck, creates refused because the queue
// was full, throughput (jobs ended per second of the loaded period), submit-to-done latency
// (the server's create_time to end_time) p50/p95/p99/max, snapshots received by the watchers,
// and the server's peak resident memory (VmHWM of the child's /proc/PID/status).
#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "CLI/CLI.hpp"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/strip.h"
#include "client/client.h"
#include "server/server.h"
#include "server/store.h"

namespace radiosity::loadtest {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// A closed unit box whose ceiling emits: six quads facing inward (as scenes/furnace.json).
constexpr char kScene[] = R"({
  "name": "loadtest_box",
  "materials": [
    {"name": "wall", "reflectance": {"r": 0.6, "g": 0.5, "b": 0.4}},
    {"name": "lamp", "reflectance": {"r": 0.5, "g": 0.5, "b": 0.5},
     "emission": {"r": 10, "g": 10, "b": 10}}
  ],
  "surfaces": [
    {"name": "x0", "material": "wall", "vertices": [0,0,0, 0,1,0, 0,1,1, 0,0,1],
     "faces": [{"indices": [0, 1, 2, 3]}]},
    {"name": "x1", "material": "wall", "vertices": [1,0,0, 1,0,1, 1,1,1, 1,1,0],
     "faces": [{"indices": [0, 1, 2, 3]}]},
    {"name": "y0", "material": "wall", "vertices": [0,0,0, 0,0,1, 1,0,1, 1,0,0],
     "faces": [{"indices": [0, 1, 2, 3]}]},
    {"name": "y1", "material": "wall", "vertices": [0,1,0, 1,1,0, 1,1,1, 0,1,1],
     "faces": [{"indices": [0, 1, 2, 3]}]},
    {"name": "z0", "material": "wall", "vertices": [0,0,0, 1,0,0, 1,1,0, 0,1,0],
     "faces": [{"indices": [0, 1, 2, 3]}]},
    {"name": "z1", "material": "lamp", "vertices": [0,0,1, 0,1,1, 1,1,1, 1,0,1],
     "faces": [{"indices": [0, 1, 2, 3]}]}
  ]
}
)";

struct Options {
  double seconds = 60;
  int clients = 4;
  int inflight = 2;
  int watchers = 2;
  std::string server;
  // Replicas: HOST:PORT of each running server of one service; clients and watchers are spread
  // over them (watcher i on the server after client i's, so most watch through a replica that
  // does not run the job).
  std::vector<std::string> servers;
  // --store-cost SPEC: time the store's part of a job's life instead (no server).
  std::string store_cost;
  int store_jobs = 500;
  std::string server_bin;
  int workers = 2;
  int threads_per_job = 1;
  int max_queued = 64;
  double grace = 60;
  int64_t max_rays = 100000;
  int64_t max_elements = 200;
  std::string json;
  bool keep = false;
  // A directory made by deploy/make-test-pki.sh: the child server serves TLS with its server
  // certificate and checks bearer tokens of two tenants; clients and watchers alternate tenants.
  std::string tls_dir;
  // Flood mode: this many full WatchJob streams on one long solve; reports the server's memory.
  int flood_watchers = 0;
  bool flood_progress_only = false;  // The flood's streams ask for progress only.
  // More arguments for the child server (e.g. --max-watchers 64).
  std::vector<std::string> server_args;
};

bool IsEnded(v1::JobState s) {
  return s == v1::JOB_STATE_SUCCEEDED || s == v1::JOB_STATE_FAILED || s == v1::JOB_STATE_CANCELLED;
}

double Seconds(const google::protobuf::Timestamp& t) { return t.seconds() + t.nanos() * 1e-9; }

// ---------------------------------------------------------------------------------------------
// The server child process.

class ServerChild {
 public:
  ~ServerChild() { Stop(5); }

  // Starts `bin` on 127.0.0.1 with a free port (it writes the port to a file).
  absl::Status Start(const std::string& bin, const std::string& dir, const Options& o,
                     const std::string& tokens_file) {
    data_dir_ = dir + "/data";
    const std::string port_file = dir + "/port";
    const std::string log = dir + "/server.log";
    log_ = log;
    const std::vector<std::string> args = {bin,
                                           "--listen",
                                           "127.0.0.1:0",
                                           "--data-dir",
                                           data_dir_,
                                           "--port-file",
                                           port_file,
                                           "--workers",
                                           absl::StrCat(o.workers),
                                           "--threads-per-job",
                                           absl::StrCat(o.threads_per_job),
                                           "--max-queued",
                                           absl::StrCat(o.max_queued),
                                           "--log-level",
                                           "warn",
                                           "--no-reflection"};
    std::vector<std::string> all = args;
    all.insert(all.end(), o.server_args.begin(), o.server_args.end());
    if (!o.tls_dir.empty()) {
      all.insert(all.end(), {"--tls-cert", o.tls_dir + "/server.pem", "--tls-key",
                             o.tls_dir + "/server.key", "--tokens-file", tokens_file});
    }
    const pid_t parent = getpid();
    pid_ = fork();
    if (pid_ < 0) return absl::InternalError("fork failed");
    if (pid_ == 0) {
      // The server must not outlive this process, however it ends.
      prctl(PR_SET_PDEATHSIG, SIGKILL);
      if (getppid() != parent) _exit(127);
      int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      if (fd >= 0) dup2(fd, STDERR_FILENO);
      std::vector<char*> argv;
      for (const std::string& a : all) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(bin.c_str(), argv.data());
      _exit(127);
    }
    const auto deadline = Clock::now() + std::chrono::seconds(30);
    while (Clock::now() < deadline) {
      std::ifstream in(port_file);
      std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      int port = 0;
      if (absl::SimpleAtoi(absl::StripAsciiWhitespace(text), &port) && port > 0) {
        address_ = absl::StrCat("127.0.0.1:", port);
        return absl::OkStatus();
      }
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        return absl::UnavailableError(
            absl::StrCat(bin, " exited before listening (status ", status, "); see ", log));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return absl::DeadlineExceededError(absl::StrCat(bin, " did not listen within 30 s"));
  }

  // VmHWM (peak resident set) of the child, bytes; -1 if unknown.
  int64_t PeakRss() const { return Status("VmHWM:"); }
  // VmRSS (resident set now) of the child, bytes; -1 if unknown.
  int64_t Rss() const { return Status("VmRSS:"); }

  // A "Vm...:" line of the child's /proc/PID/status, bytes.
  int64_t Status(const std::string& key) const {
    if (pid_ <= 0) return -1;
    std::ifstream in(absl::StrCat("/proc/", pid_, "/status"));
    std::string line;
    while (std::getline(in, line)) {
      if (line.rfind(key, 0) == 0) {
        int64_t kb = 0;
        std::string value(absl::StripAsciiWhitespace(line.substr(key.size())));
        value = value.substr(0, value.find(' '));
        if (absl::SimpleAtoi(value, &kb)) return kb * 1024;
      }
    }
    return -1;
  }

  // SIGTERM, then SIGKILL after `grace` seconds; returns the exit status text.
  std::string Stop(double grace) {
    if (pid_ <= 0) return "";
    kill(pid_, SIGTERM);
    const auto deadline =
        Clock::now() + std::chrono::milliseconds(static_cast<int64_t>(grace * 1e3));
    int status = 0;
    std::string result;
    while (true) {
      pid_t r = waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        result = WIFEXITED(status) ? absl::StrCat("exit ", WEXITSTATUS(status))
                                   : absl::StrCat("signal ", WTERMSIG(status));
        break;
      }
      if (Clock::now() > deadline) {
        kill(pid_, SIGKILL);
        waitpid(pid_, &status, 0);
        result = "killed after SIGTERM was ignored";
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    pid_ = -1;
    return result;
  }

  const std::string& address() const { return address_; }
  const std::string& log() const { return log_; }

 private:
  pid_t pid_ = -1;
  std::string address_, data_dir_, log_;
};

// ---------------------------------------------------------------------------------------------
// Shared state of the run.

struct Finished {
  v1::JobState state = v1::JOB_STATE_UNSPECIFIED;
  double server_latency = 0;  // create_time -> end_time, seconds.
  double client_latency = 0;  // CreateJob call -> seen ended by polling, seconds.
  std::string error;
};

struct Run {
  Options options;
  // Per tenant (one without --tls-dir): its bearer token ("" without) and its scene.
  std::vector<std::string> tokens;
  std::vector<std::string> scenes;
  std::string run_id;
  Clock::time_point start, end;
  std::atomic<bool> submitting{true};
  std::atomic<bool> stop{false};  // Watchers stop.

  std::mutex mu;
  std::vector<std::string> submitted;        // Every job created, in order.
  std::map<std::string, int> tenant_of;      // Every job created: its tenant's index.
  std::map<std::string, Finished> finished;  // Ended jobs.
  std::vector<std::string> lost, stuck;
  // Created and not yet seen ended, with the tenant's index: what watchers pick from.
  std::vector<std::pair<std::string, int>> active;
  std::vector<std::string> errors;  // First few unexpected errors, for the report.

  std::atomic<int64_t> rejected{0};       // CreateJob refused: queue full.
  std::atomic<int64_t> create_errors{0};  // CreateJob failed otherwise.
  std::atomic<int64_t> poll_errors{0};    // GetJob failed transiently.
  std::atomic<int64_t> watches{0};        // Watch streams that ended with the final snapshot.
  std::atomic<int64_t> watch_errors{0};
  std::atomic<int64_t> snapshots{0};  // Complete snapshots received (final ones included).
  std::atomic<int64_t> snapshot_floats{0};
  Clock::time_point last_end;  // When the last job was seen ended.

  void Error(const std::string& what) {
    std::lock_guard<std::mutex> lock(mu);
    if (errors.size() < 10) errors.push_back(what);
  }
  void Deactivate(const std::string& name) {
    std::lock_guard<std::mutex> lock(mu);
    active.erase(
        std::remove_if(active.begin(), active.end(),
                       [&](const std::pair<std::string, int>& a) { return a.first == name; }),
        active.end());
  }
  int Tenants() const { return static_cast<int>(scenes.size()); }
};

// A client of `tenant` (TLS against the test CA and the tenant's token with --tls-dir).
std::unique_ptr<client::Client> Connect(const Run& run, const std::string& address, int tenant,
                                        const client::ClientOptions& options) {
  if (run.options.tls_dir.empty()) {
    return std::make_unique<client::Client>(client::MakeChannel(address), options);
  }
  client::ChannelSecurity security;
  security.ca_file = run.options.tls_dir + "/ca.pem";
  security.token = run.tokens[static_cast<size_t>(tenant)];
  absl::StatusOr<std::shared_ptr<grpc::Channel>> channel = client::MakeChannel(address, security);
  if (!channel.ok()) {
    std::fprintf(stderr, "radiosity-loadtest: %s\n", channel.status().ToString().c_str());
    std::exit(2);
  }
  return std::make_unique<client::Client>(*channel, options);
}

v1::CreateJobRequest SmallSolve(const Run& run, int client, int64_t n) {
  v1::CreateJobRequest r;
  r.set_scene(run.scenes[static_cast<size_t>(client % run.Tenants())]);
  r.set_request_id(absl::StrCat("loadtest-", run.run_id, "-", client, "-", n));
  v1::SolveSpec* s = r.mutable_solve();
  s->mutable_mesh()->set_max_elements(run.options.max_elements);
  s->set_max_rays(run.options.max_rays);
  s->set_seed(static_cast<uint64_t>(client) * 1'000'000 + static_cast<uint64_t>(n) + 1);
  s->set_threads(1);
  s->set_width(16);
  s->set_height(16);
  s->set_snapshot_interval(0.01);
  return r;
}

void ClientLoop(Run* run, const std::string& address, int index) {
  client::ClientOptions co;
  co.timeout_seconds = 30;
  const int tenant = index % run->Tenants();
  std::unique_ptr<client::Client> connection = Connect(*run, address, tenant, co);
  client::Client& c = *connection;
  struct Outstanding {
    std::string name;
    Clock::time_point submitted;
  };
  std::vector<Outstanding> outstanding;
  int64_t n = 0;
  const Clock::time_point grace_end =
      run->end + std::chrono::milliseconds(static_cast<int64_t>(run->options.grace * 1e3));
  while (true) {
    const Clock::time_point now = Clock::now();
    const bool submitting = now < run->end;
    if (!submitting && outstanding.empty()) break;
    if (!submitting && now > grace_end) break;
    while (submitting && static_cast<int>(outstanding.size()) < run->options.inflight) {
      const Clock::time_point t0 = Clock::now();
      absl::StatusOr<v1::Job> job = c.CreateJob(SmallSolve(*run, index, n));
      if (job.ok()) {
        ++n;
        outstanding.push_back({job->name(), t0});
        std::lock_guard<std::mutex> lock(run->mu);
        run->submitted.push_back(job->name());
        run->tenant_of[job->name()] = tenant;
        run->active.emplace_back(job->name(), tenant);
      } else if (job.status().code() == absl::StatusCode::kResourceExhausted) {
        ++run->rejected;  // Queue full: back off (the same request id is safe to retry).
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        break;
      } else {
        ++run->create_errors;
        run->Error(absl::StrCat("CreateJob: ", job.status().ToString()));
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
        break;
      }
    }
    for (size_t i = 0; i < outstanding.size();) {
      absl::StatusOr<v1::Job> job = c.GetJob(outstanding[i].name);
      if (!job.ok()) {
        if (job.status().code() == absl::StatusCode::kNotFound) {
          std::lock_guard<std::mutex> lock(run->mu);
          run->lost.push_back(outstanding[i].name);
        } else {
          ++run->poll_errors;
          ++i;
          continue;
        }
      } else if (IsEnded(job->state())) {
        Finished f;
        f.state = job->state();
        f.server_latency = Seconds(job->end_time()) - Seconds(job->create_time());
        f.client_latency =
            std::chrono::duration<double>(Clock::now() - outstanding[i].submitted).count();
        f.error = job->error().message();
        std::lock_guard<std::mutex> lock(run->mu);
        run->finished[job->name()] = f;
        run->last_end = Clock::now();
      } else {
        ++i;
        continue;
      }
      run->Deactivate(outstanding[i].name);
      outstanding.erase(outstanding.begin() + static_cast<std::ptrdiff_t>(i));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::lock_guard<std::mutex> lock(run->mu);
  for (const Outstanding& o : outstanding) run->stuck.push_back(o.name);
}

void WatcherLoop(Run* run, const std::string& address, int index) {
  client::ClientOptions co;
  co.watch_stream_seconds = 120;
  const int tenant = index % run->Tenants();
  std::unique_ptr<client::Client> connection = Connect(*run, address, tenant, co);
  client::Client& c = *connection;
  std::mt19937_64 rng(static_cast<uint64_t>(index) + 12345);
  while (!run->stop) {
    std::string name;
    {
      std::lock_guard<std::mutex> lock(run->mu);
      std::vector<std::string> mine;
      for (const auto& [job, owner] : run->active) {
        if (owner == tenant) mine.push_back(job);
      }
      if (!mine.empty()) {
        name = mine[std::uniform_int_distribution<size_t>(0, mine.size() - 1)(rng)];
      }
    }
    if (name.empty()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      continue;
    }
    absl::StatusOr<client::Snapshot> last = c.Watch(
        name, 0, /*progress_only=*/false,
        [&](const client::Snapshot& s) {
          ++run->snapshots;
          run->snapshot_floats += static_cast<int64_t>(s.radiosity.size());
          return true;
        },
        &run->stop);
    if (last.ok()) {
      if (last->final && IsEnded(last->state)) {
        ++run->watches;
      } else {
        ++run->watch_errors;
        run->Error(absl::StrCat("WatchJob ", name, ": ended without a final snapshot"));
      }
    } else if (!(run->stop && last.status().code() == absl::StatusCode::kCancelled)) {
      ++run->watch_errors;
      run->Error(absl::StrCat("WatchJob ", name, ": ", last.status().ToString()));
    }
  }
}

double Percentile(std::vector<double> v, double p) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  // Nearest rank.
  size_t rank = static_cast<size_t>(std::ceil(p / 100 * static_cast<double>(v.size())));
  return v[std::min(v.size() - 1, rank > 0 ? rank - 1 : 0)];
}

std::string DefaultServerBin() {
  std::error_code ec;
  fs::path self = fs::read_symlink("/proc/self/exe", ec);
  if (ec) return "radiosity-server";
  return (self.parent_path() / "radiosity-server").string();
}

std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string a, b, c;
  in >> a >> b >> c;
  return absl::StrCat(a, " ", b, " ", c);
}

// Flood mode: --flood-watchers full WatchJob streams on one solve of --max-elements elements that
// runs for --seconds; reports how many streams were admitted and refused, and the server's
// resident memory before and with them (the cost of a watcher, for --max-watchers).
int Flood(const Run& run, const ServerChild& child, const std::string& address) {
  const Options& o = run.options;
  std::unique_ptr<client::Client> admin = Connect(run, address, 0, {});
  v1::CreateJobRequest r;
  r.set_scene(run.scenes[0]);
  v1::SolveSpec* s = r.mutable_solve();
  s->mutable_mesh()->set_max_elements(o.max_elements);
  s->set_tolerance(1e-15);
  s->set_rays_per_element(1e6);
  s->set_max_seconds(o.seconds + 30);
  s->set_snapshot_interval(0.2);
  s->set_width(8);
  s->set_height(8);
  absl::StatusOr<v1::Job> job = admin->CreateJob(r);
  if (!job.ok()) {
    std::fprintf(stderr, "radiosity-loadtest: CreateJob: %s\n", job.status().ToString().c_str());
    return 2;
  }
  // Running, with snapshots published, before the baseline is taken.
  for (int i = 0; i < 600; ++i) {
    absl::StatusOr<v1::Job> j = admin->GetJob(job->name());
    if (j.ok() && j->last_sequence() > 1) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  std::this_thread::sleep_for(std::chrono::seconds(1));
  const int64_t before = child.Rss();
  std::atomic<bool> stop{false};
  std::atomic<int64_t> refused{0}, snapshots{0}, other{0};
  std::vector<std::thread> threads;
  for (int i = 0; i < o.flood_watchers; ++i) {
    threads.emplace_back([&] {
      client::ClientOptions co;
      co.watch_stream_seconds = 600;
      std::unique_ptr<client::Client> c = Connect(run, address, 0, co);
      absl::StatusOr<client::Snapshot> last = c->Watch(
          job->name(), 0, o.flood_progress_only,
          [&](const client::Snapshot&) {
            ++snapshots;
            return true;
          },
          &stop);
      if (last.ok() || stop) return;
      if (last.status().code() == absl::StatusCode::kResourceExhausted) {
        ++refused;
      } else {
        ++other;
      }
    });
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(static_cast<int64_t>(o.seconds * 1e3)));
  const int64_t during = child.Rss();
  const int64_t peak = child.PeakRss();
  const int64_t refused_now = refused;
  stop = true;
  (void)admin->CancelJob(job->name());
  for (std::thread& t : threads) t.join();
  const int64_t admitted = o.flood_watchers - refused_now - other;
  std::printf(
      "flood: %d %s watchers asked on a %lld-element solve: %lld refused (RESOURCE_EXHAUSTED), "
      "%lld failed otherwise; %lld snapshots received\n",
      o.flood_watchers, o.flood_progress_only ? "progress-only" : "full",
      static_cast<long long>(o.max_elements), static_cast<long long>(refused_now),
      static_cast<long long>(other.load()), static_cast<long long>(snapshots.load()));
  std::printf(
      "flood: server RSS %.1f MiB before, %.1f MiB with the watchers (peak %.1f MiB): "
      "%.2f MiB per admitted watcher\n",
      before / 1048576.0, during / 1048576.0, peak / 1048576.0,
      admitted > 0 ? (during - before) / 1048576.0 / static_cast<double>(admitted) : 0.0);
  return 0;
}

// --store-cost: the store's operations of one job's life, timed per job over --store-jobs jobs
// (each claimed by id, so that a store in use is not disturbed); the rows are deleted after.
int StoreCost(const Options& o) {
  absl::StatusOr<std::unique_ptr<service::Store>> store = service::OpenStore(o.store_cost, "");
  if (!store.ok()) {
    std::fprintf(stderr, "radiosity-loadtest: %s\n", std::string(store.status().message()).c_str());
    return 2;
  }
  const std::string run_id = absl::StrFormat(
      "%x", static_cast<uint64_t>(std::chrono::system_clock::now().time_since_epoch().count()));
  const std::string owner = "loadtest-" + run_id;
  std::vector<double> per_job;
  absl::Status failed;
  for (int i = 0; i < o.store_jobs && failed.ok(); ++i) {
    const std::string id = absl::StrCat("cost", run_id, "-", i);
    v1::Job job;
    job.set_name("jobs/" + id);
    job.set_scene("scenes/loadtest");
    job.set_state(v1::JOB_STATE_QUEUED);
    job.mutable_solve()->mutable_mesh()->set_max_elements(o.max_elements);
    const auto start = Clock::now();
    failed = (*store)->InsertJob(id, job).status();
    absl::StatusOr<std::optional<service::Store::Claim>> claim;
    if (failed.ok()) {
      claim = (*store)->ClaimJobById(id, owner, absl::Seconds(30));
      failed = claim.ok() && claim->has_value() ? absl::OkStatus()
               : claim.ok() ? absl::InternalError(absl::StrCat(id, ": not claimed"))
                            : claim.status();
    }
    job.set_state(v1::JOB_STATE_RUNNING);
    for (int write = 0; write < 3 && failed.ok(); ++write) {
      job.mutable_progress()->set_step(write);
      failed = (*store)->UpdateLeasedJob(id, owner, job);
    }
    if (failed.ok()) failed = (*store)->RenewLease(id, owner, absl::Seconds(30)).status();
    job.set_state(v1::JOB_STATE_SUCCEEDED);
    if (failed.ok()) failed = (*store)->UpdateLeasedJob(id, owner, job);
    per_job.push_back(std::chrono::duration<double>(Clock::now() - start).count());
    (void)(*store)->DeleteJob(id);
  }
  if (!failed.ok()) {
    std::fprintf(stderr, "radiosity-loadtest: %s\n", std::string(failed.message()).c_str());
    return 1;
  }
  double sum = 0;
  for (double t : per_job) sum += t;
  std::printf(
      "store %s: %zu jobs, per job (insert, claim, 3 writes, renewal, end: 7 statements) "
      "mean %.2f ms, p50 %.2f ms, p99 %.2f ms; %.0f jobs/s through the store alone\n",
      (*store)->ToString().c_str(), per_job.size(), sum / per_job.size() * 1e3,
      Percentile(per_job, 50) * 1e3, Percentile(per_job, 99) * 1e3, per_job.size() / sum);
  return 0;
}

int Main(int argc, char** argv) {
  CLI::App app{"radiosity-loadtest: bounded loopback load test of the radiosity service"};
  app.option_defaults()->always_capture_default();
  Options o;
  app.add_option("--seconds", o.seconds, "Seconds of load")->check(CLI::Range(0.1, 86400.0));
  app.add_option("--clients", o.clients, "Client threads creating jobs")->check(CLI::Range(1, 256));
  app.add_option("--inflight", o.inflight, "Jobs each client keeps outstanding")
      ->check(CLI::Range(1, 64));
  app.add_option("--watchers", o.watchers, "Threads streaming WatchJob on running jobs")
      ->check(CLI::Range(0, 256));
  app.add_option("--server", o.server, "HOST:PORT of a running server (default: start a child)");
  app.add_option("--servers", o.servers,
                 "HOST:PORT,... of running replicas of one service (docs/service/stores.md): "
                 "clients and watchers spread over them")
      ->delimiter(',');
  app.add_option("--store-cost", o.store_cost,
                 "Time the store's part of --store-jobs jobs' lives (insert, claim, four writes "
                 "under the lease, a renewal) on this --store spec, and exit");
  app.add_option("--store-jobs", o.store_jobs, "Jobs for --store-cost")
      ->check(CLI::Range(1, 1'000'000));
  app.add_option("--server-bin", o.server_bin,
                 "radiosity-server binary for the child (default: next to this binary)");
  app.add_option("--workers", o.workers, "Child server: --workers")->check(CLI::Range(1, 256));
  app.add_option("--threads-per-job", o.threads_per_job, "Child server: --threads-per-job")
      ->check(CLI::Range(1, 1024));
  app.add_option("--max-queued", o.max_queued, "Child server: --max-queued")
      ->check(CLI::Range(1, 1'000'000));
  app.add_option("--grace", o.grace, "Seconds every job has to end after the load stops")
      ->check(CLI::Range(0.0, 3600.0));
  app.add_option("--max-rays", o.max_rays, "Ray budget of each solve")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 40));
  app.add_option("--max-elements", o.max_elements, "Elements of each solve's mesh")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 24));
  app.add_option("--json", o.json, "Also write the figures to this JSON file");
  app.add_option("--tls-dir", o.tls_dir,
                 "Directory made by deploy/make-test-pki.sh: the child server serves TLS and "
                 "checks the bearer tokens of two tenants, which the clients alternate")
      ->check(CLI::ExistingDirectory);
  app.add_option("--flood-watchers", o.flood_watchers,
                 "Instead of the load: this many full WatchJob streams on one solve of "
                 "--max-elements elements for --seconds; reports refusals and server memory")
      ->check(CLI::Range(0, 100000));
  app.add_flag("--flood-progress-only", o.flood_progress_only,
               "The flood's streams ask for progress only (for --max-progress-watchers)");
  app.add_option("--server-arg", o.server_args,
                 "An argument for the child server (repeat: --server-arg=--max-watchers "
                 "--server-arg=64)");
  app.add_flag("--keep", o.keep, "Keep the child's temporary directory (data and log)");
  CLI11_PARSE(app, argc, argv);
  signal(SIGPIPE, SIG_IGN);
  if (!o.store_cost.empty()) return StoreCost(o);
  if (!o.servers.empty()) {
    if (!o.server.empty()) {
      std::fprintf(stderr, "radiosity-loadtest: --server or --servers, not both\n");
      return 2;
    }
    o.server = o.servers[0];
  } else if (!o.server.empty()) {
    o.servers = {o.server};
  }

  if (!o.tls_dir.empty() && !o.server.empty()) {
    std::fprintf(stderr, "radiosity-loadtest: --tls-dir is for the child server (no --server)\n");
    return 2;
  }
  // The child server and its temporary directory.
  ServerChild child;
  std::string tmp;
  std::string tokens_file;
  std::vector<std::string> tokens;
  std::string address = o.server;
  if (address.empty()) {
    const char* base = std::getenv("TMPDIR");
    std::string pattern = absl::StrCat(base && *base ? base : "/tmp", "/radiosity-loadtest-XXXXXX");
    if (!mkdtemp(pattern.data())) {
      std::fprintf(stderr, "radiosity-loadtest: cannot create a temporary directory\n");
      return 2;
    }
    tmp = pattern;
    tokens_file = tmp + "/tokens";
    std::string bin = o.server_bin.empty() ? DefaultServerBin() : o.server_bin;
    if (!o.tls_dir.empty()) {
      // Two tenants with fresh random tokens.
      std::random_device random;
      for (int t = 0; t < 2; ++t) {
        std::string token = "loadtest-";
        for (int i = 0; i < 4; ++i) absl::StrAppend(&token, absl::Hex(random(), absl::kZeroPad8));
        tokens.push_back(token);
      }
      std::ofstream(tokens_file) << tokens[0] << " tenant-a\n" << tokens[1] << " tenant-b\n";
    }
    if (absl::Status st = child.Start(bin, tmp, o, tokens_file); !st.ok()) {
      std::fprintf(stderr, "radiosity-loadtest: %s\n", std::string(st.message()).c_str());
      return 2;
    }
    address = child.address();
  }
  auto cleanup = [&] {
    if (!tmp.empty() && !o.keep) {
      std::error_code ec;
      fs::remove_all(tmp, ec);
    }
  };

  Run run;
  run.options = o;
  run.run_id = absl::StrFormat(
      "%x", static_cast<uint64_t>(std::chrono::system_clock::now().time_since_epoch().count()));
  run.tokens = tokens.empty() ? std::vector<std::string>{""} : tokens;
  run.scenes.resize(run.tokens.size());
  // One administrative client per tenant: each uploads the tenant's scene.
  std::vector<std::unique_ptr<client::Client>> admins;
  for (int t = 0; t < static_cast<int>(run.tokens.size()); ++t) {
    admins.push_back(Connect(run, address, t, {}));
    std::string dir = tmp.empty() ? fs::temp_directory_path().string() : tmp;
    std::string path = absl::StrCat(dir, "/loadtest_box_", run.run_id, "_", t, ".json");
    std::ofstream(path) << kScene;
    absl::StatusOr<v1::SceneInfo> scene = admins.back()->UploadSceneFile(path);
    std::error_code ec;
    fs::remove(path, ec);
    if (!scene.ok()) {
      std::fprintf(stderr, "radiosity-loadtest: upload: %s\n", scene.status().ToString().c_str());
      child.Stop(10);
      cleanup();
      return 2;
    }
    run.scenes[static_cast<size_t>(t)] = scene->name();
  }
  client::Client& admin = *admins[0];
  absl::StatusOr<bool> healthy = admin.CheckHealth(service::kServiceName);

  if (o.flood_watchers > 0) {
    const int code = Flood(run, child, address);
    if (o.server.empty()) child.Stop(30);
    cleanup();
    return code;
  }
  std::printf("radiosity-loadtest: %s, %.0f s, %d clients x %d in flight, %d watchers",
              o.servers.size() > 1 ? absl::StrJoin(o.servers, ",").c_str() : address.c_str(),
              o.seconds, o.clients, o.inflight, o.watchers);
  if (o.server.empty()) {
    std::printf("; child server: %d workers x %d threads", o.workers, o.threads_per_job);
  }
  if (!o.tls_dir.empty()) std::printf("; TLS, bearer tokens of 2 tenants");
  std::printf("; solve: %lld elements, %lld rays; load average at start %s\n",
              static_cast<long long>(o.max_elements), static_cast<long long>(o.max_rays),
              LoadAverage().c_str());
  std::fflush(stdout);

  run.start = Clock::now();
  run.end = run.start + std::chrono::milliseconds(static_cast<int64_t>(o.seconds * 1e3));
  run.last_end = run.start;
  std::vector<std::thread> clients, watchers;
  // Over the replicas when there are several (the child, or --server, else).
  const std::vector<std::string> spread =
      o.servers.empty() ? std::vector<std::string>{address} : o.servers;
  const size_t n = spread.size();
  for (int i = 0; i < o.clients; ++i) {
    clients.emplace_back(ClientLoop, &run, spread[static_cast<size_t>(i) % n], i);
  }
  for (int i = 0; i < o.watchers; ++i) {
    watchers.emplace_back(WatcherLoop, &run, spread[static_cast<size_t>(i + 1) % n], i);
  }
  for (std::thread& t : clients) t.join();
  run.stop = true;
  for (std::thread& t : watchers) t.join();
  const std::string load_after = LoadAverage();

  // Every submitted job again, through its tenant's ListJobs: present and ended as seen, and no
  // tenant's list holds another's job.
  std::map<std::string, v1::JobState> listed;
  int64_t missing_from_list = 0;
  for (int t = 0; t < run.Tenants(); ++t) {
    v1::ListJobsRequest request;
    request.set_page_size(1000);
    for (int page = 0; page < 100000; ++page) {
      absl::StatusOr<v1::ListJobsResponse> list = admins[static_cast<size_t>(t)]->ListJobs(request);
      if (!list.ok()) {
        run.Error(absl::StrCat("ListJobs: ", list.status().ToString()));
        break;
      }
      for (const v1::Job& j : list->jobs()) {
        auto owner = run.tenant_of.find(j.name());
        if (owner != run.tenant_of.end() && owner->second != t) {
          ++missing_from_list;
          run.Error(
              absl::StrCat(j.name(), ": listed to tenant ", t, ", created by ", owner->second));
        }
        listed[j.name()] = j.state();
      }
      if (list->next_page_token().empty()) break;
      request.set_page_token(list->next_page_token());
    }
  }
  for (const std::string& name : run.submitted) {
    auto it = listed.find(name);
    if (it == listed.end()) {
      ++missing_from_list;
      run.Error(absl::StrCat(name, ": not in ListJobs"));
    } else if (run.finished.count(name) && it->second != run.finished[name].state) {
      ++missing_from_list;
      run.Error(absl::StrCat(name, ": ListJobs says ", v1::JobState_Name(it->second)));
    }
  }
  absl::StatusOr<bool> healthy_after = admin.CheckHealth(service::kServiceName);
  const int64_t peak_rss = child.PeakRss();
  std::string child_exit;
  if (o.server.empty()) child_exit = child.Stop(30);

  // Figures.
  int64_t succeeded = 0, failed = 0, cancelled = 0;
  std::vector<double> server_latency, client_latency;
  for (const auto& [name, f] : run.finished) {
    if (f.state == v1::JOB_STATE_SUCCEEDED) ++succeeded;
    if (f.state == v1::JOB_STATE_FAILED) {
      ++failed;
      run.Error(absl::StrCat(name, " FAILED: ", f.error));
    }
    if (f.state == v1::JOB_STATE_CANCELLED) ++cancelled;
    server_latency.push_back(f.server_latency);
    client_latency.push_back(f.client_latency);
  }
  const int64_t submitted = static_cast<int64_t>(run.submitted.size());
  const double loaded =
      std::chrono::duration<double>(std::max(run.end, run.last_end) - run.start).count();
  const double throughput = loaded > 0 ? static_cast<double>(run.finished.size()) / loaded : 0;
  const bool pass = run.lost.empty() && run.stuck.empty() && failed == 0 && cancelled == 0 &&
                    succeeded == submitted && run.watch_errors == 0 && missing_from_list == 0 &&
                    run.create_errors == 0 && healthy.ok() && *healthy && healthy_after.ok() &&
                    *healthy_after && (child_exit.empty() || child_exit == "exit 0");

  std::printf(
      "jobs: submitted %lld, succeeded %lld, failed %lld, cancelled %lld, lost %zu, "
      "stuck %zu; creates refused (queue full) %lld, other create errors %lld\n",
      static_cast<long long>(submitted), static_cast<long long>(succeeded),
      static_cast<long long>(failed), static_cast<long long>(cancelled), run.lost.size(),
      run.stuck.size(), static_cast<long long>(run.rejected.load()),
      static_cast<long long>(run.create_errors.load()));
  std::printf("throughput: %.2f jobs/s over %.1f s\n", throughput, loaded);
  std::printf(
      "latency submit->done, server create_time->end_time (s): p50 %.3f  p95 %.3f  "
      "p99 %.3f  max %.3f\n",
      Percentile(server_latency, 50), Percentile(server_latency, 95),
      Percentile(server_latency, 99), Percentile(server_latency, 100));
  std::printf(
      "latency submit->done, client call->seen ended (s):     p50 %.3f  p95 %.3f  "
      "p99 %.3f  max %.3f\n",
      Percentile(client_latency, 50), Percentile(client_latency, 95),
      Percentile(client_latency, 99), Percentile(client_latency, 100));
  std::printf(
      "watch: %lld streams to the final snapshot, %lld snapshots received (%.1f MiB of "
      "radiosity), %lld stream errors\n",
      static_cast<long long>(run.watches.load()), static_cast<long long>(run.snapshots.load()),
      static_cast<double>(run.snapshot_floats.load()) * 4 / (1 << 20),
      static_cast<long long>(run.watch_errors.load()));
  if (peak_rss >= 0) {
    std::printf("server peak RSS (VmHWM): %.1f MiB\n", static_cast<double>(peak_rss) / (1 << 20));
  } else {
    std::printf("server peak RSS (VmHWM): unknown (not a child of this process)\n");
  }
  std::printf("health: %s before, %s after; child server %s; load average at end %s\n",
              healthy.ok() && *healthy ? "SERVING" : "NOT SERVING",
              healthy_after.ok() && *healthy_after ? "SERVING" : "NOT SERVING",
              child_exit.empty() ? "n/a" : child_exit.c_str(), load_after.c_str());
  for (const std::string& name : run.lost) std::printf("LOST: %s\n", name.c_str());
  for (const std::string& name : run.stuck) std::printf("STUCK: %s\n", name.c_str());
  for (const std::string& e : run.errors) std::printf("error: %s\n", e.c_str());
  std::printf("result: %s\n", pass ? "PASS" : "FAIL");

  if (!o.json.empty()) {
    std::ofstream out(o.json);
    out << absl::StrFormat(
        "{\"seconds\": %g, \"clients\": %d, \"inflight\": %d, \"watchers\": %d, "
        "\"submitted\": %d, \"succeeded\": %d, \"failed\": %d, \"cancelled\": %d, \"lost\": %d, "
        "\"stuck\": %d, \"rejected\": %d, \"throughput_jobs_per_s\": %.3f, "
        "\"latency_s\": {\"p50\": %.4f, \"p95\": %.4f, \"p99\": %.4f, \"max\": %.4f}, "
        "\"snapshots\": %d, \"watch_errors\": %d, \"peak_rss_bytes\": %d, \"pass\": %s}\n",
        o.seconds, o.clients, o.inflight, o.watchers, submitted, succeeded, failed, cancelled,
        run.lost.size(), run.stuck.size(), run.rejected.load(), throughput,
        Percentile(server_latency, 50), Percentile(server_latency, 95),
        Percentile(server_latency, 99), Percentile(server_latency, 100), run.snapshots.load(),
        run.watch_errors.load(), peak_rss, pass ? "true" : "false");
  }
  if (!pass && !tmp.empty()) std::printf("server log: %s\n", child.log().c_str());
  if (pass) cleanup();
  return pass ? 0 : 1;
}

}  // namespace
}  // namespace radiosity::loadtest

int main(int argc, char** argv) {
  try {
    return radiosity::loadtest::Main(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "radiosity-loadtest: error: %s\n", e.what());
    return 2;
  }
}
