// radiosity-server: the solve service (docs/service/api.md).
//
//   radiosity-server --listen HOST:PORT --data-dir DIR [--store SPEC] [--blob-dir DIR]
//                    [--lease-seconds S] [--workers N] [--max-queued N]
//                    [--threads-per-job N] [--max-upload-mb N] [--max-elements N]
//                    [--max-memory-mb N] [--metrics-port P] [--http-port P] [--reflection]
//                    [--port-file F]
//                    [--tls-cert F --tls-key F [--tls-client-ca F]] [--tokens-file F] [--insecure]
//                    [--tenant-max-jobs N] [--tenant-max-stored-mb N]
//
//   radiosity-server --copy-from DIR --store postgresql://... --blob-dir BLOBS
//
// Stops gracefully on SIGTERM or SIGINT: running solves are queued again and resume after the
// next start; the process exits within --shutdown-grace seconds whatever is still running. Logs
// are JSON lines on stderr.
#include <signal.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include "CLI/CLI.hpp"
#include "absl/strings/str_cat.h"
#include "proto/api/exit_codes.h"
#include "server/logging.h"
#include "server/server.h"
#include "server/store_copy.h"
#include "solver/util/file_io.h"

namespace radiosity::service {
namespace {

std::atomic<int> g_signal{0};

void OnSignal(int signal_number) { g_signal.store(signal_number); }

void InstallSignalHandlers() {
  // SIGTERM / SIGINT only set a flag (whichever thread takes them); this thread acts on it.
  struct sigaction action = {};
  action.sa_handler = OnSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGTERM, &action, nullptr);
  sigaction(SIGINT, &action, nullptr);
  signal(SIGPIPE, SIG_IGN);
}

// radiosity-server --copy-from DIR --store SPEC --blob-dir BLOBS.
int CopyMain(const std::string& from, const ServiceOptions& s) {
  if (s.store.empty() || s.blob_dir.empty()) {
    std::fprintf(stderr,
                 "radiosity-server: error: --copy-from needs --store (the PostgreSQL store the "
                 "replicas share) and --blob-dir (their shared directory)\n");
    return kExitUsage;
  }
  InstallSignalHandlers();
  std::atomic<bool> stop{false};
  std::atomic<bool> done{false};
  std::thread watch([&] {
    while (!done) {
      if (g_signal.load() != 0) stop = true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
  });
  CopyReport report;
  absl::Status st = CopyDataDir(from, s.store, s.blob_dir, &stop, &report);
  done = true;
  watch.join();
  std::fprintf(stderr, "radiosity-server: %s\n", report.ToString().c_str());
  if (!st.ok()) {
    std::fprintf(stderr, "radiosity-server: error: %s\n", std::string(st.message()).c_str());
    return st.code() == absl::StatusCode::kInvalidArgument ? kExitUsage : kExitServer;
  }
  return kExitOk;
}

int Main(int argc, char** argv) {
  CLI::App app{"radiosity-server: the radiosity solve service (gRPC)"};
  app.option_defaults()->always_capture_default();
  ServerOptions options;
  ServiceOptions& s = options.service;
  int64_t max_upload_mb = s.max_upload_bytes >> 20;
  std::string port_file;
  app.add_option("--listen", options.listen,
                 "HOST:PORT to serve gRPC on (port 0: any free one); required unless --copy-from");
  app.add_option("--data-dir", s.data_dir,
                 "Directory for the database, scenes and results; required unless --copy-from");
  std::string copy_from;
  app.add_option("--copy-from", copy_from,
                 "Copy the data directory DIR of a stopped server (its SQLite store and files) "
                 "into --store (PostgreSQL) and --blob-dir, for replicas, then exit; run it "
                 "again to finish a copy that was interrupted");
  app.add_option("--store", s.store,
                 "Where scenes and jobs are recorded: sqlite:DIR (default: in --data-dir), "
                 "postgresql://USER@HOST/DB?..., or file:PATH (the address in a file)");
  app.add_option("--blob-dir", s.blob_dir,
                 "Replicas: scenes, checkpoints and results in this directory, shared by every "
                 "replica of one PostgreSQL --store; workers then claim jobs from the store "
                 "with leases (docs/service/stores.md)");
  app.add_option("--lease-seconds", s.lease_seconds,
                 "Replicas: how long a worker's claim on a job lasts without renewal (renewed "
                 "every quarter of it); a killed replica's jobs are taken over after it")
      ->check(CLI::Range(1.0, 3600.0));
  app.add_option("--workers", s.workers, "Jobs solved at the same time")->check(CLI::Range(1, 256));
  app.add_option("--max-queued", s.max_queued,
                 "Jobs waiting for a worker; more are refused (RESOURCE_EXHAUSTED)")
      ->check(CLI::Range(1, 1'000'000));
  app.add_option("--threads-per-job", s.threads_per_job, "Solver threads per job (0: all cores)")
      ->check(CLI::Range(0, 1024));
  app.add_option("--max-upload-mb", max_upload_mb, "Largest scene upload, MiB")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 20));
  app.add_option("--max-elements", s.max_elements, "Largest mesh of a solve, elements")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 40));
  app.add_option(
         "--max-memory-mb", s.max_memory_mb,
         "Memory one job may use, MiB: its estimate is checked at CreateJob, and a running job "
         "that grows the process past it fails (RESOURCE_EXHAUSTED; 0: no limit)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 30));
  app.add_option("--max-attempts", s.max_attempts,
                 "A job the server process ended this many times while it ran (crash, kill) is "
                 "failed instead of run again")
      ->check(CLI::Range(1, 1000));
  app.add_option("--checkpoint-seconds", s.checkpoint_seconds,
                 "Seconds of solving between checkpoints of a running job, from which it resumes "
                 "after a crash or kill -9 (0: none)")
      ->check(CLI::Range(0.0, 86400.0));
  app.add_option("--tls-cert", options.tls_cert_file,
                 "Serve TLS with this PEM certificate chain (with --tls-key)")
      ->check(CLI::ExistingFile);
  app.add_option("--tls-key", options.tls_key_file, "PEM private key of --tls-cert")
      ->check(CLI::ExistingFile);
  app.add_option("--tls-client-ca", options.tls_client_ca_file,
                 "Require client certificates signed by this PEM CA (mutual TLS)")
      ->check(CLI::ExistingFile);
  app.add_option(
         "--tokens-file", options.tokens_file,
         "Lines 'TOKEN TENANT': every call needs 'authorization: Bearer TOKEN' and sees only "
         "its tenant's scenes and jobs; re-read when the file changes (needs TLS)")
      ->check(CLI::ExistingFile);
  app.add_flag("--insecure", options.insecure,
               "Allow --listen on a non-loopback address without --tokens-file or --tls-client-ca");
  int64_t tenant_max_stored_mb = 0;
  app.add_option("--tenant-max-jobs", s.quotas.max_unfinished_jobs,
                 "Jobs queued or running per tenant; more are refused (RESOURCE_EXHAUSTED; 0: no "
                 "quota)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 40));
  app.add_option("--tenant-max-stored-mb", tenant_max_stored_mb,
                 "MiB of scenes and results per tenant; uploads and jobs past it are refused "
                 "(RESOURCE_EXHAUSTED; 0: no quota)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 30));
  int64_t max_stored_mb = 0;
  app.add_option("--max-stored-mb", max_stored_mb,
                 "MiB of scenes and results the server keeps; uploads and jobs past it are refused "
                 "(RESOURCE_EXHAUSTED; 0: no limit)")
      ->check(CLI::Range(int64_t{0}, int64_t{1} << 30));
  app.add_option("--max-uploads", s.limits.max_uploads,
                 "Uploads open at once; more are refused (RESOURCE_EXHAUSTED)")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 20));
  app.add_option("--upload-idle-seconds", s.limits.upload_idle_seconds,
                 "An upload that sends nothing this long is cancelled")
      ->check(CLI::Range(0.1, 86400.0));
  app.add_option("--max-watchers", s.limits.max_full_watchers,
                 "WatchJob streams with values open at once; more are refused (RESOURCE_EXHAUSTED)")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 24));
  app.add_option("--max-progress-watchers", s.limits.max_progress_watchers,
                 "Progress-only WatchJob streams open at once; more are refused")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 24));
  app.add_option("--metrics-port", options.metrics_port,
                 "Serve Prometheus text metrics over HTTP on this port (same host as --listen; "
                 "-1: off)")
      ->check(CLI::Range(-1, 65535));
  app.add_option("--http-port", options.http_port,
                 "Serve the browser preview (jobs converging, docs/service/preview.md) on this "
                 "port, same host as --listen, HTTPS with --tls-cert (0: any "
                 "free one, logged as http_port; -1: off)")
      ->check(CLI::Range(-1, 65535));
  app.add_flag("--reflection,!--no-reflection", options.reflection,
               "Serve gRPC server reflection (default on)")
      ->default_val(true);
  app.add_option("--shutdown-grace", options.shutdown_grace_seconds,
                 "Seconds the process takes at most to stop on SIGTERM: calls in flight finish "
                 "and running solves are queued again within it, or the process exits anyway")
      ->check(CLI::Range(0.5, 3600.0));
  app.add_option("--log-level", options.log_level, "trace, debug, info, warn, error or off");
  app.add_option("--port-file", port_file, "Write the port listened on to this file");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    int code = app.exit(e);
    return code == 0 ? kExitOk : kExitUsage;
  }
  if (!copy_from.empty()) return CopyMain(copy_from, s);
  for (const auto& [value, flag] :
       {std::pair<const std::string&, const char*>{options.listen, "--listen"},
        {s.data_dir, "--data-dir"}}) {
    if (value.empty()) {
      std::fprintf(stderr, "radiosity-server: error: %s is required\n", flag);
      return kExitUsage;
    }
  }
  s.max_upload_bytes = max_upload_mb << 20;
  s.quotas.max_stored_bytes = tenant_max_stored_mb << 20;
  s.quotas.server_max_stored_bytes = max_stored_mb << 20;

  InstallSignalHandlers();
  absl::StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
  if (!server.ok()) {
    std::fprintf(stderr, "radiosity-server: error: %s\n",
                 std::string(server.status().message()).c_str());
    return server.status().code() == absl::StatusCode::kInvalidArgument ? kExitUsage : kExitServer;
  }
  if (!port_file.empty()) {
    if (absl::Status st = WriteFileAtomically(port_file, absl::StrCat((*server)->port(), "\n"));
        !st.ok()) {
      std::fprintf(stderr, "radiosity-server: error: %s\n", std::string(st.message()).c_str());
      return kExitInternal;
    }
  }
  while (g_signal.load() == 0) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  LogLine("signal").Int("signal", g_signal.load()).Info();
  // Whatever does not end in time (a call, a step that does not stop) must not keep the process,
  // and with it the data directory's lock, past the grace period: then the process exits at once.
  // A job still RUNNING in the store counts a lost attempt at the next start (--max-attempts).
  const double grace = options.shutdown_grace_seconds;
  std::thread([grace] {
    std::this_thread::sleep_for(std::chrono::duration<double>(grace));
    LogLine("shutdown_forced")
        .Str("detail", "the shutdown did not finish within --shutdown-grace; exiting now")
        .Error();
    std::_Exit(kExitInternal);
  }).detach();
  (*server)->Shutdown();
  return kExitOk;
}

}  // namespace
}  // namespace radiosity::service

int main(int argc, char** argv) {
  try {
    return radiosity::service::Main(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "radiosity-server: error: %s\n", e.what());
    return radiosity::kExitInternal;
  }
}
