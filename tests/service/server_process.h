// radiosity-server as a child process on 127.0.0.1, for the tests that need real processes
// (signals, kill -9, several replicas).
#ifndef RADIOSITY_TESTS_SERVICE_SERVER_PROCESS_H_
#define RADIOSITY_TESTS_SERVICE_SERVER_PROCESS_H_

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity::service::testing {

// A free TCP port on 127.0.0.1 (bound, read, released).
inline int FreePort() {
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = 0;
  bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr));
  socklen_t len = sizeof(addr);
  getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  close(fd);
  return ntohs(addr.sin_port);
}

// radiosity-server as a child process; killed (SIGKILL) if still running when destroyed.
class ServerProcess {
 public:
  // `more_args` are added to the defaults below, and replace those of the same flags.
  ServerProcess(const std::string& data_dir, const std::string& log_path, int metrics_port,
                const std::vector<std::string>& more_args = {})
      : port_file_(data_dir + ".port") {
    std::remove(port_file_.c_str());
    std::vector<std::string> args = {RADIOSITY_SERVER_BIN, "--data-dir", data_dir,
                                     "--port-file",        port_file_,   "--reflection"};
    const std::vector<std::pair<std::string, std::string>> defaults = {
        {"--listen", "127.0.0.1:0"},
        {"--metrics-port", absl::StrCat(metrics_port)},
        {"--threads-per-job", "2"}};
    for (const auto& [flag, value] : defaults) {
      if (std::find(more_args.begin(), more_args.end(), flag) != more_args.end()) continue;
      args.push_back(flag);
      args.push_back(value);
    }
    args.insert(args.end(), more_args.begin(), more_args.end());
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    pid_ = fork();
    if (pid_ == 0) {
      int log = open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      dup2(log, STDERR_FILENO);
      execv(RADIOSITY_SERVER_BIN, argv.data());
      _exit(127);
    }
  }
  ~ServerProcess() {
    if (pid_ > 0 && !exited_) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  // The port from --port-file, once written (0 after 30 s).
  int WaitForPort() {
    int port = 0;
    WaitFor(
        [&] {
          std::string text(absl::StripAsciiWhitespace(radiosity::testing::ReadFile(port_file_)));
          return absl::SimpleAtoi(text, &port) && port > 0;
        },
        30);
    return port;
  }
  // Sends SIGTERM and waits (up to 30 s); returns the exit status, or -1.
  int Terminate() {
    kill(pid_, SIGTERM);
    int status = 0;
    bool done = WaitFor([&] { return waitpid(pid_, &status, WNOHANG) == pid_; }, 30);
    if (!done) return -1;
    exited_ = true;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }
  // kill -9, as a crash or the kernel's memory killer would end it.
  void Kill() {
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    exited_ = true;
  }

  // SIGSTOP / SIGCONT: a process that stops answering without dying (a long GC-like pause, a
  // frozen VM, a partition as the others see it).
  void Pause() { kill(pid_, SIGSTOP); }
  void Resume() { kill(pid_, SIGCONT); }
  bool exited() const { return exited_; }

 private:
  std::string port_file_;
  pid_t pid_ = -1;
  bool exited_ = false;
};

}  // namespace radiosity::service::testing

#endif  // RADIOSITY_TESTS_SERVICE_SERVER_PROCESS_H_
