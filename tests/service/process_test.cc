// The radiosity-server binary as a subprocess on 127.0.0.1: health, Prometheus metrics over HTTP,
// JSON-lines logs with job ids, graceful shutdown on SIGTERM with the running solve queued again,
// and its resumption by the next process on the same data directory.
#include <arpa/inet.h>
#include <fcntl.h>
#include <grpcpp/generic/generic_stub.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "client/client.h"
#include "server/server.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using client::Client;
using service::testing::WaitFor;
using testing::ReadFile;
using testing::SourcePath;
using testing::TempDir;

// A free TCP port on 127.0.0.1 (bound, read, released).
int FreePort() {
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

// GET / over HTTP/1.0 on 127.0.0.1:port; the whole response.
std::string HttpGet(int port) {
  int fd = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  addr.sin_port = htons(static_cast<uint16_t>(port));
  timeval tv{5, 0};
  setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
  if (connect(fd, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0) {
    close(fd);
    return "";
  }
  std::string request = "GET /metrics HTTP/1.0\r\n\r\n";
  (void)send(fd, request.data(), request.size(), MSG_NOSIGNAL);
  std::string response;
  char buffer[4096];
  for (int i = 0; i < 1000; ++i) {
    ssize_t n = recv(fd, buffer, sizeof(buffer), 0);
    if (n <= 0) break;
    response.append(buffer, static_cast<size_t>(n));
  }
  close(fd);
  return response;
}

// The services listed by grpc.reflection.v1alpha (Debian's gRPC serves that version), as the raw
// response bytes: ServerReflectionRequest{list_services: ""} is field 7, an empty string.
std::string ReflectionListServices(const std::shared_ptr<grpc::Channel>& channel) {
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  grpc::CompletionQueue cq;
  auto call = stub.PrepareCall(
      &context, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  void* tag;
  bool ok = false;
  auto step = [&](int id) {
    return cq.Next(&tag, &ok) && tag == reinterpret_cast<void*>(id) && ok;
  };
  call->StartCall(reinterpret_cast<void*>(1));
  if (!step(1)) return "";
  grpc::Slice slice(std::string("\x3a\x00", 2));
  grpc::ByteBuffer request(&slice, 1);
  call->Write(request, reinterpret_cast<void*>(2));
  if (!step(2)) return "";
  call->WritesDone(reinterpret_cast<void*>(3));
  if (!step(3)) return "";
  grpc::ByteBuffer response;
  call->Read(&response, reinterpret_cast<void*>(4));
  if (!step(4)) return "";
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(5));
  cq.Next(&tag, &ok);
  std::vector<grpc::Slice> slices;
  (void)response.Dump(&slices);
  std::string bytes;
  for (const grpc::Slice& s : slices)
    bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return bytes;
}

// radiosity-server as a child process; killed (SIGKILL) if still running when destroyed.
class ServerProcess {
 public:
  ServerProcess(const std::string& data_dir, const std::string& log_path, int metrics_port)
      : port_file_(data_dir + ".port") {
    std::remove(port_file_.c_str());
    pid_ = fork();
    if (pid_ == 0) {
      int log = open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
      dup2(log, STDERR_FILENO);
      std::string metrics = absl::StrCat(metrics_port);
      execl(RADIOSITY_SERVER_BIN, RADIOSITY_SERVER_BIN, "--listen", "127.0.0.1:0", "--data-dir",
            data_dir.c_str(), "--port-file", port_file_.c_str(), "--metrics-port", metrics.c_str(),
            "--threads-per-job", "2", "--reflection", nullptr);
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
          std::string text(absl::StripAsciiWhitespace(ReadFile(port_file_)));
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

 private:
  std::string port_file_;
  pid_t pid_ = -1;
  bool exited_ = false;
};

TEST(ServiceProcessTest, HealthMetricsLogsAndGracefulRestart) {
  TempDir dir;
  const std::string data = dir.File("data");
  const std::string log = dir.File("server.log");
  const int metrics_port = FreePort();
  std::string job;
  {
    ServerProcess server(data, log, metrics_port);
    const int port = server.WaitForPort();
    ASSERT_GT(port, 0) << ReadFile(log);
    Client c(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
    absl::StatusOr<bool> serving = c.CheckHealth(service::kServiceName);
    ASSERT_TRUE(serving.ok()) << serving.status();
    EXPECT_TRUE(*serving);
    const std::string services =
        ReflectionListServices(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
    EXPECT_NE(services.find("radiosity.v1.RadiosityService"), std::string::npos);
    EXPECT_NE(services.find("grpc.health.v1.Health"), std::string::npos);
    absl::StatusOr<v1::SceneInfo> scene = c.UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
    ASSERT_TRUE(scene.ok()) << scene.status();
    v1::CreateJobRequest r;
    r.set_scene(scene->name());
    r.mutable_solve()->mutable_mesh()->set_max_elements(1000);
    r.mutable_solve()->set_tolerance(1e-15);
    r.mutable_solve()->set_max_seconds(60);
    r.mutable_solve()->set_rays_per_element(1e6);
    r.mutable_solve()->set_snapshot_interval(0.05);
    absl::StatusOr<v1::Job> created = c.CreateJob(r);
    ASSERT_TRUE(created.ok()) << created.status();
    job = created->name();
    ASSERT_TRUE(WaitFor(
        [&] {
          absl::StatusOr<v1::Job> j = c.GetJob(job);
          return j.ok() && j->state() == v1::JOB_STATE_RUNNING && j->progress().rays() > 0;
        },
        30));
    std::string metrics = HttpGet(metrics_port);
    EXPECT_EQ(metrics.rfind("HTTP/1.0 200 OK", 0), 0u) << metrics;
    EXPECT_NE(metrics.find("\nradiosity_jobs_created_total 1\n"), std::string::npos) << metrics;
    EXPECT_NE(metrics.find("\nradiosity_running_jobs 1\n"), std::string::npos) << metrics;
    EXPECT_NE(metrics.find("\nradiosity_queue_depth 0\n"), std::string::npos) << metrics;
    EXPECT_NE(metrics.find("radiosity_rays_per_second"), std::string::npos);
    EXPECT_EQ(server.Terminate(), 0) << ReadFile(log);
  }
  // Every log line is a JSON object with an event; the job's id is in its lines.
  const std::string id = job.substr(std::string("jobs/").size());
  int lines = 0, with_job = 0;
  for (absl::string_view line : absl::StrSplit(ReadFile(log), '\n', absl::SkipEmpty())) {
    ++lines;
    EXPECT_EQ(line.front(), '{') << line;
    EXPECT_EQ(line.back(), '}') << line;
    EXPECT_NE(line.find("\"event\":"), absl::string_view::npos) << line;
    with_job += line.find(absl::StrCat("\"job\":\"", id, "\"")) != absl::string_view::npos;
  }
  EXPECT_GT(lines, 3);
  EXPECT_GE(with_job, 3);  // Created, started, meshed, re-queued.
  EXPECT_NE(ReadFile(log).find("\"event\":\"job_requeued\""), std::string::npos);

  // The next process on the same data directory runs the interrupted job again.
  ServerProcess server(data, log, FreePort());
  const int port = server.WaitForPort();
  ASSERT_GT(port, 0);
  Client c(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
  ASSERT_TRUE(WaitFor(
      [&] {
        absl::StatusOr<v1::Job> j = c.GetJob(job);
        return j.ok() && j->state() == v1::JOB_STATE_RUNNING && j->attempts() == 2;
      },
      30));
  ASSERT_TRUE(c.CancelJob(job).ok());
  absl::StatusOr<client::Snapshot> last = c.Watch(job, 0, true, nullptr);
  ASSERT_TRUE(last.ok()) << last.status();
  EXPECT_EQ(last->state, v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(server.Terminate(), 0);
}

}  // namespace
}  // namespace radiosity
