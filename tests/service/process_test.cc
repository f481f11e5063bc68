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
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "client/client.h"
#include "server/server.h"
#include "solver/geometry/scene.h"
#include "solver/util/file_io.h"
#include "tests/service/fixture.h"
#include "tests/service/server_process.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using client::Client;
using service::testing::FreePort;
using service::testing::ServerProcess;
using service::testing::WaitFor;
using testing::ReadFile;
using testing::SourcePath;
using testing::TempDir;

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

// A long solve of the Cornell box on `c`'s server: the job's name.
std::string StartLongSolve(Client& c) {
  absl::StatusOr<v1::SceneInfo> scene = c.UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
  EXPECT_TRUE(scene.ok()) << scene.status();
  if (!scene.ok()) return "";
  v1::CreateJobRequest r;
  r.set_scene(scene->name());
  r.mutable_solve()->mutable_mesh()->set_max_elements(1000);
  r.mutable_solve()->set_tolerance(1e-15);
  r.mutable_solve()->set_max_seconds(120);
  r.mutable_solve()->set_rays_per_element(1e6);
  absl::StatusOr<v1::Job> created = c.CreateJob(r);
  EXPECT_TRUE(created.ok()) << created.status();
  return created.ok() ? created->name() : "";
}

// Whether `job` runs its `attempt`-th attempt and has traced rays.
bool RunsAttempt(Client& c, const std::string& job, int attempt) {
  absl::StatusOr<v1::Job> j = c.GetJob(job);
  return j.ok() && j->state() == v1::JOB_STATE_RUNNING && j->attempts() == attempt &&
         j->progress().rays() > 0;
}

// A job during which the server process dies (kill -9, as a crash or the memory killer would)
// is run again after each restart only up to --max-attempts; then it ends FAILED and says why,
// on the Job and on its final snapshot, and is not run again.
TEST(ServiceProcessTest, AJobThatKeepsEndingTheServerFailsAtTheAttemptLimit) {
  TempDir dir;
  const std::string data = dir.File("data");
  const std::string log = dir.File("server.log");
  const std::vector<std::string> args = {"--max-attempts", "2"};
  std::string job;
  for (int attempt = 1; attempt <= 2; ++attempt) {
    ServerProcess server(data, log, -1, args);
    const int port = server.WaitForPort();
    ASSERT_GT(port, 0) << ReadFile(log);
    Client c(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
    if (attempt == 1) job = StartLongSolve(c);
    ASSERT_FALSE(job.empty());
    ASSERT_TRUE(WaitFor([&] { return RunsAttempt(c, job, attempt); }, 60)) << ReadFile(log);
    absl::StatusOr<v1::Job> before = c.GetJob(job);
    ASSERT_TRUE(before.ok());
    EXPECT_EQ(before->lost_attempts(), attempt - 1);
    server.Kill();
  }
  ServerProcess server(data, log, -1, args);
  const int port = server.WaitForPort();
  ASSERT_GT(port, 0) << ReadFile(log);
  Client c(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
  absl::StatusOr<v1::Job> failed = c.GetJob(job);
  ASSERT_TRUE(failed.ok()) << failed.status();
  EXPECT_EQ(failed->state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(failed->attempts(), 2);
  EXPECT_EQ(failed->lost_attempts(), 2);
  EXPECT_EQ(failed->error().code(), static_cast<int>(absl::StatusCode::kInternal));
  EXPECT_NE(failed->error().message().find("ended while this job ran, 2 times"), std::string::npos)
      << failed->error().message();
  EXPECT_NE(failed->error().message().find("--max-attempts is 2"), std::string::npos);
  absl::StatusOr<client::Snapshot> last = c.Watch(job, 0, true, nullptr);
  ASSERT_TRUE(last.ok()) << last.status();
  EXPECT_EQ(last->state, v1::JOB_STATE_FAILED);
  EXPECT_EQ(last->attempts, 2);
  // Not run again: still FAILED a moment later.
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  absl::StatusOr<v1::Job> still = c.GetJob(job);
  ASSERT_TRUE(still.ok());
  EXPECT_EQ(still->state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(server.Terminate(), 0);
}

// SIGTERM with a solve running on a scene whose rays are slow (2047 coincident pieces): the
// process exits within --shutdown-grace, cleanly, and releases the data directory, so the next
// process starts at once and runs the job again (a graceful re-queue is not a lost attempt).
TEST(ServiceProcessTest, SigtermEndsWithinTheGracePeriodWithAHostileSolveRunning) {
  TempDir dir;
  const std::string data = dir.File("data");
  const std::string log = dir.File("server.log");
  std::string scene_obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf";
  for (int k = 0; k < 1024; ++k) scene_obj += " 1 2 3 4";
  const std::string path = dir.File("repeated.obj");
  ASSERT_TRUE(WriteWholeFile(path, scene_obj + "\n").ok());
  const std::vector<std::string> args = {"--shutdown-grace", "2"};
  std::string job;
  {
    ServerProcess server(data, log, -1, args);
    const int port = server.WaitForPort();
    ASSERT_GT(port, 0) << ReadFile(log);
    Client c(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
    absl::StatusOr<v1::SceneInfo> scene = c.UploadSceneFile(path);
    ASSERT_TRUE(scene.ok()) << scene.status();
    v1::CreateJobRequest r;
    r.set_scene(scene->name());
    r.mutable_solve()->set_tolerance(1e-15);
    r.mutable_solve()->set_max_seconds(120);
    v1::EmitOverride* emit = r.mutable_solve()->add_emit();
    emit->set_name(kDefaultMaterialName);
    emit->set_r(1);
    absl::StatusOr<v1::Job> created = c.CreateJob(r);
    ASSERT_TRUE(created.ok()) << created.status();
    job = created->name();
    ASSERT_TRUE(WaitFor([&] { return RunsAttempt(c, job, 1); }, 60)) << ReadFile(log);
    const auto start = std::chrono::steady_clock::now();
    EXPECT_EQ(server.Terminate(), 0) << ReadFile(log);
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_LT(seconds, 2.5);  // The grace period and the 10 ms of WaitFor's polling.
  }
  ServerProcess server(data, log, -1, args);
  const int port = server.WaitForPort();
  ASSERT_GT(port, 0) << ReadFile(log);
  Client c(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
  ASSERT_TRUE(WaitFor([&] { return RunsAttempt(c, job, 2); }, 60)) << ReadFile(log);
  absl::StatusOr<v1::Job> again = c.GetJob(job);
  ASSERT_TRUE(again.ok());
  EXPECT_EQ(again->lost_attempts(), 0);
  ASSERT_TRUE(c.CancelJob(job).ok());
  EXPECT_EQ(server.Terminate(), 0);
}

// kill -9 in the middle of a solve that has written a checkpoint: the next process resumes the job
// from it (the log says so, at a step past 0), the snapshot numbers continue from the last one
// published, and the result equals, element for element, that of the same job run without
// interruption on the same server (same seed). The checkpoint is removed once the job ends.
TEST(ServiceProcessTest, KilledMidSolveResumesFromItsCheckpointToTheUninterruptedResult) {
  TempDir dir;
  const std::string data = dir.File("data");
  const std::string log = dir.File("server.log");
  const std::vector<std::string> args = {"--checkpoint-seconds", "0.3"};
  v1::CreateJobRequest r;
  r.mutable_solve()->set_solve_method(v1::SOLVE_METHOD_PROGRESSIVE);
  r.mutable_solve()->set_seed(7);
  r.mutable_solve()->mutable_mesh()->set_max_elements(1000);
  r.mutable_solve()->set_tolerance(1e-15);
  r.mutable_solve()->set_rays_per_element(1e6);  // Ends at max_rays, after many steps.
  r.mutable_solve()->set_max_rays(60'000'000);
  r.mutable_solve()->set_max_seconds(600);
  std::string job, checkpoint;
  int64_t sequence_before = 0;
  {
    ServerProcess server(data, log, -1, args);
    const int port = server.WaitForPort();
    ASSERT_GT(port, 0) << ReadFile(log);
    Client c(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
    absl::StatusOr<v1::SceneInfo> scene = c.UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
    ASSERT_TRUE(scene.ok()) << scene.status();
    r.set_scene(scene->name());
    absl::StatusOr<v1::Job> created = c.CreateJob(r);
    ASSERT_TRUE(created.ok()) << created.status();
    job = created->name();
    checkpoint = data + "/jobs/" + std::string(absl::StripPrefix(job, "jobs/")) + "/checkpoint";
    ASSERT_TRUE(WaitFor([&] { return RunsAttempt(c, job, 1) && FileExists(checkpoint); }, 60))
        << ReadFile(log);
    absl::StatusOr<v1::Job> running = c.GetJob(job);
    ASSERT_TRUE(running.ok());
    ASSERT_EQ(running->state(), v1::JOB_STATE_RUNNING) << "the solve ended before the kill";
    server.Kill();
    sequence_before = running->last_sequence();
    // As a write killed half way leaves it: removed at the restart.
    ASSERT_TRUE(WriteWholeFile(checkpoint + ".tmp-1-1", "half").ok());
  }
  ServerProcess server(data, log, -1, args);
  const int port = server.WaitForPort();
  ASSERT_GT(port, 0) << ReadFile(log);
  Client c(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
  absl::StatusOr<v1::Job> recovered = c.GetJob(job);
  ASSERT_TRUE(recovered.ok());
  // Every number published was persisted first: the store has the last one, and the next
  // attempt's first snapshot follows it.
  const int64_t last_published = recovered->last_sequence();
  EXPECT_GE(last_published, sequence_before);
  int64_t first_resumed = 0;
  absl::StatusOr<client::Snapshot> end =
      c.Watch(job, last_published, true, [&](const client::Snapshot& s) {
        if (first_resumed == 0) first_resumed = s.sequence;
        return true;
      });
  ASSERT_TRUE(end.ok()) << end.status();
  EXPECT_EQ(first_resumed, last_published + 1);
  absl::StatusOr<v1::Job> resumed = c.GetJob(job);
  ASSERT_TRUE(resumed.ok());
  ASSERT_EQ(resumed->state(), v1::JOB_STATE_SUCCEEDED) << resumed->error().message();
  EXPECT_EQ(resumed->attempts(), 2);
  EXPECT_EQ(resumed->lost_attempts(), 1);
  EXPECT_EQ(resumed->progress().rays(), 60'000'000);
  EXPECT_FALSE(FileExists(checkpoint));
  EXPECT_FALSE(FileExists(checkpoint + ".tmp-1-1"));
  const std::string text = ReadFile(log);
  const size_t at = text.find("\"event\":\"job_resumed\"");
  ASSERT_NE(at, std::string::npos) << text;
  const std::string line = text.substr(at, text.find('\n', at) - at);
  EXPECT_EQ(line.find("\"step\":0,"), std::string::npos) << line;

  // The same job, never interrupted.
  r.set_request_id("uninterrupted");
  absl::StatusOr<v1::Job> plain = c.CreateJob(r);
  ASSERT_TRUE(plain.ok()) << plain.status();
  ASSERT_TRUE(c.Watch(plain->name(), 0, true, nullptr).ok());
  ASSERT_TRUE(c.DownloadResults(job, dir.File("resumed"), "elements.csv").ok());
  ASSERT_TRUE(c.DownloadResults(plain->name(), dir.File("plain"), "elements.csv").ok());
  const std::string want = ReadFile(dir.File("plain") + "/elements.csv");
  EXPECT_GT(want.size(), 1000u);
  EXPECT_TRUE(ReadFile(dir.File("resumed") + "/elements.csv") == want)
      << "the resumed job's elements.csv differs from the uninterrupted job's";
  EXPECT_EQ(server.Terminate(), 0);
}

}  // namespace
}  // namespace radiosity
