// Models read in a child process (ModelOptions::importer): the parent side (LoadModel's isolated
// path) and the child's main (ModelImportMain).
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <new>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "solver/input/model_loader.h"
#include "solver/input/scene_codec.h"
#include "solver/util/file_io.h"

extern char** environ;

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define RADIOSITY_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer) || __has_feature(thread_sanitizer)
#define RADIOSITY_SANITIZED 1
#endif
#endif

namespace radiosity {

// Declared here, defined in model_loader.cc: LoadModel without the child process.
absl::StatusOr<Scene> LoadModelInProcess(const std::string& path,
                                         std::vector<std::string>* warnings,
                                         const ModelOptions& options);
// Defined in model_loader.cc: OpenImageIO decodes on the calling thread only.
void UseOneDecodingThread();

namespace {

// A temporary directory removed with everything in it when this goes out of scope.
class ScratchDir {
 public:
  ScratchDir() {
    std::error_code ec;
    std::filesystem::path tmp = std::filesystem::temp_directory_path(ec);
    if (ec) tmp = "/tmp";
    std::string pattern = (tmp / "radiosity-import-XXXXXX").string();
    if (mkdtemp(pattern.data()) != nullptr) path_ = pattern;
  }
  ~ScratchDir() {
    std::error_code ec;
    if (!path_.empty()) std::filesystem::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }

 private:
  std::string path_;
};

bool IsExecutable(const std::string& path) {
  return !path.empty() && access(path.c_str(), X_OK) == 0 && !std::filesystem::is_directory(path);
}

}  // namespace

std::string ModelImporter() {
  static const std::string found = [] {
    if (const char* env = std::getenv("RADIOSITY_IMPORT"); env != nullptr && IsExecutable(env)) {
      return std::string(env);
    }
    std::error_code ec;
    const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
    if (ec) return std::string();
    const std::string beside = (self.parent_path() / "radiosity-import").string();
    return IsExecutable(beside) ? beside : std::string();
  }();
  return found;
}

absl::StatusOr<Scene> LoadModelInChild(const std::string& path, std::vector<std::string>* warnings,
                                       const ModelOptions& options) {
  ScratchDir scratch;
  if (scratch.path().empty()) {
    return absl::InternalError(absl::StrCat(path,
                                            ": cannot make a temporary directory to read "
                                            "the model in: ",
                                            std::strerror(errno)));
  }
  const std::string out = scratch.path() + "/scene.pb";
  std::vector<std::string> args = {
      options.importer,
      path,
      out,
      "--memory-mb",
      std::to_string(options.import_memory_mb),
      "--seconds",
      std::to_string(static_cast<int64_t>(std::ceil(options.import_seconds)))};
  if (options.confine_to_directory) args.push_back("--confine");
  if (options.vertex_colors) args.push_back("--vertex-colors");
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
  // Nothing else the caller has open (the service's files and sockets) reaches the child.
  posix_spawn_file_actions_addclosefrom_np(&actions, 3);
  pid_t pid = -1;
  const int spawned =
      posix_spawn(&pid, options.importer.c_str(), &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (spawned != 0) {
    return absl::InternalError(absl::StrCat(path, ": cannot start the model importer ",
                                            options.importer, ": ", std::strerror(spawned)));
  }

  // Wait for it, checking the stop token and the wall-clock limit.
  const auto start = std::chrono::steady_clock::now();
  int status = 0;
  bool stopped = false, timed_out = false;
  for (auto pause = std::chrono::milliseconds(1);;
       pause = std::min(2 * pause, decltype(pause)(20))) {
    const pid_t done = waitpid(pid, &status, WNOHANG);
    if (done == pid) break;
    if (done < 0 && errno != EINTR) {
      return absl::InternalError(
          absl::StrCat(path, ": waiting for the model importer: ", std::strerror(errno)));
    }
    stopped = options.stop != nullptr && options.stop->ShouldStop();
    timed_out = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() >
                options.import_seconds;
    if (stopped || timed_out) {
      kill(pid, SIGKILL);
      while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
      }
      break;
    }
    std::this_thread::sleep_for(pause);
  }
  if (stopped) {
    return absl::CancelledError(absl::StrCat(path, ": reading the model was stopped"));
  }
  if (timed_out) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": the model importer took longer than ", options.import_seconds,
                     " s on this file and was stopped; the file is refused"));
  }
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": the model importer (assimp) died of signal ", sig, " (",
                     strsignal(sig), ") reading this file",
                     sig == SIGKILL || sig == SIGSEGV
                         ? absl::StrCat(" (limit ", options.import_memory_mb, " MiB of memory)")
                         : "",
                     "; the file is refused"));
  }
  const int code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (code == 1) {
    absl::StatusOr<std::string> error = ReadWholeFile(out + ".error");
    if (!error.ok()) {
      return absl::InternalError(absl::StrCat(
          path,
          ": the model importer failed and its error is unreadable: ", error.status().message()));
    }
    const size_t newline = error->find('\n');
    int status_code = 0;
    if (newline == std::string::npos ||
        !absl::SimpleAtoi(error->substr(0, newline), &status_code) || status_code <= 0 ||
        status_code > 16) {
      return absl::InternalError(absl::StrCat(path, ": the model importer's error is garbled"));
    }
    return absl::Status(static_cast<absl::StatusCode>(status_code), error->substr(newline + 1));
  }
  if (code != 0) {
    return absl::InternalError(
        absl::StrCat(path, ": the model importer ", options.importer, " failed (exit ", code, ")"));
  }
  absl::StatusOr<std::string> bytes = ReadWholeFile(out);
  if (!bytes.ok()) {
    return absl::InternalError(absl::StrCat(
        path, ": the model importer's result is unreadable: ", bytes.status().message()));
  }
  absl::StatusOr<Scene> scene = ParseNativeScene(*bytes, /*json=*/false, path, nullptr);
  if (!scene.ok()) return scene.status();
  scene->source = path;
  if (warnings != nullptr) {
    absl::StatusOr<std::string> lines = ReadWholeFile(out + ".warnings");
    if (lines.ok()) {
      for (absl::string_view line : absl::StrSplit(*lines, '\n', absl::SkipEmpty())) {
        warnings->emplace_back(line);
      }
    }
  }
  return scene;
}

int ModelImportMain(int argc, char** argv) {
  std::vector<std::string> positional;
  ModelOptions options;
  int64_t seconds = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--confine") {
      options.confine_to_directory = true;
    } else if (arg == "--vertex-colors") {
      options.vertex_colors = true;
    } else if (arg == "--memory-mb" && i + 1 < argc &&
               absl::SimpleAtoi(argv[i + 1], &options.import_memory_mb) &&
               options.import_memory_mb > 0) {
      ++i;
    } else if (arg == "--seconds" && i + 1 < argc && absl::SimpleAtoi(argv[i + 1], &seconds) &&
               seconds > 0) {
      ++i;
    } else if (!arg.empty() && arg[0] != '-') {
      positional.push_back(arg);
    } else {
      positional.clear();
      break;
    }
  }
  if (positional.size() != 2) {
    fprintf(
        stderr,
        "usage: radiosity-import MODEL OUT [--confine] [--vertex-colors] [--memory-mb N] "
        "[--seconds N]\n"
        "Reads MODEL through assimp for radiosity (its service runs this in a child process)\n");
    return 2;
  }
  const std::string& out = positional[1];
  // An address-space limit: a sanitizer's shadow memory alone exceeds any, so builds with one
  // (the CI's ASan stage) go without.
#if !defined(RADIOSITY_SANITIZED)
  const rlimit memory = {static_cast<rlim_t>(options.import_memory_mb) << 20,
                         static_cast<rlim_t>(options.import_memory_mb) << 20};
  setrlimit(RLIMIT_AS, &memory);
#endif
  const rlimit no_core = {0, 0};
  setrlimit(RLIMIT_CORE, &no_core);
  // Backstops for a parent that is gone (killed, crashed) and cannot kill a hung import: die
  // with it, and after the CPU time the parent would have allowed.
  prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (seconds > 0) {
    const rlimit cpu = {static_cast<rlim_t>(seconds + 5), static_cast<rlim_t>(seconds + 5)};
    setrlimit(RLIMIT_CPU, &cpu);
  }

  // One decoding thread: the address-space limit is for the model, not for thread stacks.
  UseOneDecodingThread();
  absl::Status status;
  try {
    std::vector<std::string> warnings;
    absl::StatusOr<Scene> scene = LoadModelInProcess(positional[0], &warnings, options);
    if (scene.ok()) {
      absl::StatusOr<std::string> bytes = EncodeNativeScene(*scene, /*json=*/false, out);
      status = bytes.status();
      if (status.ok()) {
        std::string lines;
        for (std::string& w : warnings) {
          std::replace(w.begin(), w.end(), '\n', ' ');
          absl::StrAppend(&lines, w, "\n");
        }
        status = WriteWholeFile(out + ".warnings", lines);
        if (status.ok()) status = WriteWholeFile(out, *bytes);
      }
    } else {
      status = scene.status();
    }
  } catch (const std::bad_alloc&) {
    status = absl::ResourceExhaustedError(
        absl::StrCat(positional[0], ": reading the model needs more than ",
                     options.import_memory_mb, " MiB of memory; the file is refused"));
  } catch (const std::exception& e) {
    status = absl::InvalidArgumentError(
        absl::StrCat(positional[0], ": cannot read the model (assimp): ", e.what()));
  }
  if (status.ok()) return 0;
  const absl::Status written = WriteWholeFile(
      out + ".error", absl::StrCat(static_cast<int>(status.code()), "\n", status.message()));
  return written.ok() ? 1 : 3;
}

}  // namespace radiosity
