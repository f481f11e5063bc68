// Test support (header only, for tests/service/*_test.cc): a real server on 127.0.0.1 with a free
// port and a data directory, a client connected to it over TCP (the ServiceTest fixture), the job
// requests the tests send, and bounded waiting.
#ifndef RADIOSITY_TESTS_SERVICE_FIXTURE_H_
#define RADIOSITY_TESTS_SERVICE_FIXTURE_H_

#include <gtest/gtest.h>

#include <chrono>
#include <cstdlib>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "proto/api/sha256.h"
#include "server/server.h"
#include "tests/testing/test_util.h"

namespace radiosity::service::testing {

// Options of a test server on 127.0.0.1:0 with the given data directory. Logs are off unless
// RADIOSITY_TEST_LOG names a level.
inline ServerOptions TestServerOptions(const std::string& data_dir) {
  ServerOptions o;
  o.listen = "127.0.0.1:0";
  o.service.data_dir = data_dir;
  o.service.workers = 1;
  o.service.threads_per_job = 2;
  const char* level = std::getenv("RADIOSITY_TEST_LOG");
  o.log_level = level && *level ? level : "off";
  o.shutdown_grace_seconds = 2;
  return o;
}

// A client over TCP to a test server (never the in-process channel: the tests exercise the wire).
inline std::unique_ptr<client::Client> ConnectTo(const Server& server,
                                                 client::ClientOptions options = {}) {
  return std::make_unique<client::Client>(
      client::MakeChannel(absl::StrCat("127.0.0.1:", server.port())), options);
}

// Polls `done` every 10 ms until it holds or `seconds` pass; returns whether it held.
inline bool WaitFor(const std::function<bool()>& done, double seconds) {
  const auto end = std::chrono::steady_clock::now() +
                   std::chrono::milliseconds(static_cast<int64_t>(seconds * 1000));
  while (std::chrono::steady_clock::now() < end) {
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return done();
}

// A solve of `scene` of a few milliseconds (200 elements, 20000 rays, 8 x 8 images).
inline v1::CreateJobRequest ShortSolve(const std::string& scene, uint64_t seed) {
  v1::CreateJobRequest r;
  r.set_scene(scene);
  v1::SolveSpec* s = r.mutable_solve();
  s->mutable_mesh()->set_max_elements(200);
  s->set_max_rays(20000);
  s->set_seed(seed);
  s->set_width(8);
  s->set_height(8);
  return r;
}

// A solve of `scene` that runs until cancelled (or 60 s): a tolerance it never reaches and a
// million rays per element, on at most `max_elements` elements, with square images of
// `image_size` pixels.
inline v1::CreateJobRequest LongSolve(const std::string& scene, int64_t max_elements,
                                      int image_size) {
  v1::CreateJobRequest r;
  r.set_scene(scene);
  v1::SolveSpec* s = r.mutable_solve();
  s->mutable_mesh()->set_max_elements(max_elements);
  s->set_tolerance(1e-15);
  s->set_max_seconds(60);
  s->set_rays_per_element(1e6);
  s->set_width(image_size);
  s->set_height(image_size);
  return r;
}

// An upload's header message announcing `files` (name, contents).
inline v1::UploadSceneRequest UploadHeader(
    const std::vector<std::pair<std::string, std::string>>& files) {
  v1::UploadSceneRequest r;
  for (const auto& [name, bytes] : files) {
    v1::FileInfo* f = r.mutable_header()->add_files();
    f->set_name(name);
    f->set_size(static_cast<int64_t>(bytes.size()));
    f->set_sha256(Sha256Hex(bytes));
  }
  return r;
}

// An upload's chunk message.
inline v1::UploadSceneRequest UploadChunk(const std::string& file, int64_t offset,
                                          const std::string& data) {
  v1::UploadSceneRequest r;
  r.mutable_chunk()->set_file(file);
  r.mutable_chunk()->set_offset(offset);
  r.mutable_chunk()->set_data(data);
  return r;
}

// 2 x cells^2 triangles in a square facing up, under a ceiling of one quad facing down (so that
// light goes back and forth): reading, meshing and agglomerating take long.
inline std::string TriangleGridObj(int cells) {
  const int n = (cells + 1) * (cells + 1);
  std::string text;
  for (int j = 0; j <= cells; ++j) {
    for (int i = 0; i <= cells; ++i) absl::StrAppend(&text, "v ", i, " ", j, " 0\n");
  }
  absl::StrAppend(&text, "v 0 0 ", cells / 4, "\nv 0 ", cells, " ", cells / 4, "\nv ", cells, " ",
                  cells, " ", cells / 4, "\nv ", cells, " 0 ", cells / 4, "\n");
  absl::StrAppend(&text, "f ", n + 1, " ", n + 2, " ", n + 3, " ", n + 4, "\n");
  auto at = [&](int i, int j) { return j * (cells + 1) + i + 1; };
  for (int j = 0; j < cells; ++j) {
    for (int i = 0; i < cells; ++i) {
      absl::StrAppend(&text, "f ", at(i, j), " ", at(i + 1, j), " ", at(i + 1, j + 1), "\n");
      absl::StrAppend(&text, "f ", at(i, j), " ", at(i + 1, j + 1), " ", at(i, j + 1), "\n");
    }
  }
  return text;
}

// The fixture of the service tests: a server started in SetUp with TestServerOptions over a
// temporary data directory, and a client connected to it; both shut down in TearDown. Tests that
// need other options, or a restart on the same data, call Restart.
class ServiceTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_NO_FATAL_FAILURE(Start(TestServerOptions(data_.path()))); }
  void TearDown() override { Stop(); }

  // Starts a server with `options` (none may be running) and connects client_ to it.
  void Start(const ServerOptions& options) {
    absl::StatusOr<std::unique_ptr<Server>> s = Server::Start(options);
    ASSERT_TRUE(s.ok()) << s.status();
    server_ = *std::move(s);
    ASSERT_GT(server_->port(), 0);
    client_ = ConnectTo(*server_);
  }
  // Drops the client and shuts the server down gracefully (running solves go back to the queue).
  void Stop() {
    client_.reset();
    if (server_) server_->Shutdown();
    server_.reset();
  }
  // Stop, then Start with `options`.
  void Restart(const ServerOptions& options) {
    Stop();
    ASSERT_NO_FATAL_FAILURE(Start(options));
  }

  // "127.0.0.1:port" of the running server.
  std::string address() const { return absl::StrCat("127.0.0.1:", server_->port()); }

  // Sends raw upload messages, then closes the stream; returns the call's status.
  grpc::Status RawUpload(const std::vector<v1::UploadSceneRequest>& messages) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
    v1::SceneInfo response;
    auto writer = client_->stub().UploadScene(&context, &response);
    for (const auto& m : messages) {
      if (!writer->Write(m)) break;
    }
    writer->WritesDone();
    return writer->Finish();
  }

  // Creates the job: its name.
  absl::StatusOr<std::string> CreateJobNamed(const v1::CreateJobRequest& request) {
    absl::StatusOr<v1::Job> job = client_->CreateJob(request);
    if (!job.ok()) return job.status();
    return job->name();
  }

  // The job's state, or JOB_STATE_UNSPECIFIED when it cannot be read.
  v1::JobState State(const std::string& job) {
    absl::StatusOr<v1::Job> j = client_->GetJob(job);
    return j.ok() ? j->state() : v1::JOB_STATE_UNSPECIFIED;
  }

  radiosity::testing::TempDir data_;
  std::unique_ptr<Server> server_;
  std::unique_ptr<client::Client> client_;
};

}  // namespace radiosity::service::testing

#endif  // RADIOSITY_TESTS_SERVICE_FIXTURE_H_
