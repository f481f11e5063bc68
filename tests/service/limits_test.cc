// Limits that hold (docs/service/server.md): open watch streams (full and progress-only), open
// uploads, an upload's idle time and the bytes the server stores are capped; past a cap the call is
// RESOURCE_EXHAUSTED naming the flag, and a place freed is taken again. An upload of many files
// holds one file descriptor, not one per file.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "server/server.h"
#include "solver/geometry/scene.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

namespace fs = std::filesystem;
using service::ServerOptions;
using service::testing::LongSolve;
using service::testing::ServiceTest;
using service::testing::ShortSolve;
using service::testing::TestServerOptions;
using service::testing::UploadChunk;
using service::testing::UploadHeader;
using service::testing::WaitFor;
using testing::ReadFile;
using testing::SourcePath;
using testing::TempDir;

class ServiceLimitsTest : public ServiceTest {};

// An open WatchJob stream: admitted when its first message arrives, refused when the stream ends
// at once with RESOURCE_EXHAUSTED.
struct OpenWatch {
  grpc::ClientContext context;
  std::unique_ptr<grpc::ClientReader<v1::WatchJobResponse>> reader;
  v1::WatchJobResponse first;
  bool admitted = false;
  grpc::Status refusal;

  OpenWatch(client::Client& c, const std::string& job, bool progress_only) {
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    v1::WatchJobRequest request;
    request.set_name(job);
    request.set_progress_only(progress_only);
    reader = c.stub().WatchJob(&context, request);
    admitted = reader->Read(&first);
    if (!admitted) refusal = reader->Finish();
  }
  ~OpenWatch() {
    if (!admitted) return;  // Finished already.
    context.TryCancel();
    v1::WatchJobResponse ignored;
    while (reader->Read(&ignored)) {
    }
    (void)reader->Finish();
  }
};

TEST_F(ServiceLimitsTest, WatchStreamsAreCappedFullAndProgressOnlyApart) {
  ServerOptions o = TestServerOptions(data_.path());
  o.service.limits.max_full_watchers = 2;
  o.service.limits.max_progress_watchers = 3;
  ASSERT_NO_FATAL_FAILURE(Restart(o));
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo scene,
                       client_->UploadSceneFile(SourcePath("scenes/cornell_box.obj")));
  ASSERT_OK_AND_ASSIGN(v1::Job job, client_->CreateJob(LongSolve(scene.name(), 200, 8)));
  std::vector<std::unique_ptr<OpenWatch>> full, progress;
  for (int i = 0; i < 2; ++i) {
    full.push_back(std::make_unique<OpenWatch>(*client_, job.name(), false));
    ASSERT_TRUE(full.back()->admitted) << full.back()->refusal.error_message();
  }
  auto third = std::make_unique<OpenWatch>(*client_, job.name(), false);
  EXPECT_FALSE(third->admitted);
  EXPECT_EQ(third->refusal.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(third->refusal.error_message().find("--max-watchers 2"), std::string::npos)
      << third->refusal.error_message();
  // Progress-only streams have places of their own.
  for (int i = 0; i < 3; ++i) {
    progress.push_back(std::make_unique<OpenWatch>(*client_, job.name(), true));
    ASSERT_TRUE(progress.back()->admitted) << progress.back()->refusal.error_message();
  }
  auto fourth = std::make_unique<OpenWatch>(*client_, job.name(), true);
  EXPECT_FALSE(fourth->admitted);
  EXPECT_NE(fourth->refusal.error_message().find("--max-progress-watchers 3"), std::string::npos)
      << fourth->refusal.error_message();
  // A stream that ends gives its place back.
  full.pop_back();
  EXPECT_TRUE(WaitFor(
      [&] { return std::make_unique<OpenWatch>(*client_, job.name(), false)->admitted; }, 5));
  ASSERT_TRUE(client_->CancelJob(job.name()).ok());
}

// An upload stream held open by the test: its header sent, nothing more.
struct OpenUpload {
  grpc::ClientContext context;
  v1::SceneInfo response;
  std::unique_ptr<grpc::ClientWriter<v1::UploadSceneRequest>> writer;

  OpenUpload(client::Client& c, const std::vector<v1::UploadSceneRequest>& messages) {
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    writer = c.stub().UploadScene(&context, &response);
    for (const v1::UploadSceneRequest& m : messages) {
      if (!writer->Write(m)) break;
    }
  }
  // Ends the stream: the call's status.
  grpc::Status Close() {
    writer->WritesDone();
    return writer->Finish();
  }
};

// Open file descriptors of this process (the server runs in it).
int OpenDescriptors() {
  int n = 0;
  for (const auto& entry : fs::directory_iterator("/proc/self/fd")) {
    (void)entry;
    ++n;
  }
  return n;
}

TEST_F(ServiceLimitsTest, OpenUploadsAreCappedAndHoldOneDescriptorEach) {
  ServerOptions o = TestServerOptions(data_.path());
  o.service.limits.max_uploads = 3;
  ASSERT_NO_FATAL_FAILURE(Restart(o));
  // Three uploads of 64 files each, every file begun: one descriptor each (not 64).
  std::vector<std::pair<std::string, std::string>> files = {{"scene.obj", "v 0 0 0\n"}};
  for (int i = 1; i < 64; ++i) files.emplace_back(absl::StrCat("f", i, ".mtl"), "newmtl m\n");
  const int before = OpenDescriptors();
  std::vector<std::unique_ptr<OpenUpload>> open;
  for (int u = 0; u < 3; ++u) {
    std::vector<v1::UploadSceneRequest> messages = {UploadHeader(files)};
    for (const auto& [name, bytes] : files) {
      messages.push_back(UploadChunk(name, 0, bytes.substr(0, 3)));
    }
    open.push_back(std::make_unique<OpenUpload>(*client_, messages));
  }
  // The server has received them all once every temporary file has its first bytes.
  const std::string uploads = data_.path() + "/uploads";
  auto begun = [&] {
    int n = 0;
    for (const auto& e : fs::recursive_directory_iterator(uploads)) {
      if (e.is_regular_file() && e.file_size() > 0) ++n;
    }
    return n;
  };
  // (A file's bytes reach the disk when the server moves on to the next file: all but the last.)
  ASSERT_TRUE(WaitFor([&] { return begun() == 3 * 63; }, 10)) << begun();
  EXPECT_LE(OpenDescriptors() - before, 3 + 8) << "uploads hold a descriptor per file";
  // A fourth is refused at once, naming the flag.
  grpc::Status refused = RawUpload({UploadHeader({{"a.obj", "v 0 0 0\n"}})});
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(refused.error_message().find("--max-uploads 3"), std::string::npos)
      << refused.error_message();
  // One ends (incomplete: INVALID_ARGUMENT): its place is free again.
  EXPECT_EQ(open.back()->Close().error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  open.pop_back();
  const std::string json = ReadFile(SourcePath("scenes/furnace.json"));
  EXPECT_TRUE(WaitFor(
      [&] {
        return RawUpload(
                   {UploadHeader({{"furnace.json", json}}), UploadChunk("furnace.json", 0, json)})
            .ok();
      },
      5));
}

TEST_F(ServiceLimitsTest, AnUploadThatStopsSendingIsCancelledAndCleanedUp) {
  ServerOptions o = TestServerOptions(data_.path());
  o.service.limits.max_uploads = 1;
  o.service.limits.upload_idle_seconds = 0.5;
  ASSERT_NO_FATAL_FAILURE(Restart(o));
  const std::string json = ReadFile(SourcePath("scenes/furnace.json"));
  OpenUpload stalled(*client_, {UploadHeader({{"furnace.json", json}}),
                                UploadChunk("furnace.json", 0, json.substr(0, 10))});
  // The stalled upload takes the only place, until the idle time passes: then it is cancelled
  // and its temporary files removed.
  const std::string uploads = data_.path() + "/uploads";
  ASSERT_TRUE(WaitFor([&] { return !fs::is_empty(uploads); }, 5));
  EXPECT_TRUE(WaitFor([&] { return fs::is_empty(uploads); }, 5)) << "temporary files left";
  const grpc::Status ended = stalled.Close();
  EXPECT_EQ(ended.error_code(), grpc::StatusCode::CANCELLED) << ended.error_message();
  EXPECT_TRUE(
      RawUpload({UploadHeader({{"furnace.json", json}}), UploadChunk("furnace.json", 0, json)})
          .ok());
}

// A client that cancels while its upload is validated (a 2 000 000-triangle OBJ, which takes
// seconds to parse) stops the validation within a second: the server does not go on parsing for
// nobody, and the upload's temporary files are removed.
TEST_F(ServiceLimitsTest, CancellingAnUploadStopsItsValidation) {
  const std::string obj = service::testing::TriangleGridObj(1000);
  std::atomic<bool> sent{false};
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
  grpc::Status status;
  std::thread upload([&] {
    v1::SceneInfo response;
    auto writer = client_->stub().UploadScene(&context, &response);
    bool ok = writer->Write(UploadHeader({{"grid.obj", obj}}));
    const size_t chunk = 1 << 20;
    for (size_t at = 0; ok && at < obj.size(); at += chunk) {
      ok = writer->Write(UploadChunk("grid.obj", static_cast<int64_t>(at), obj.substr(at, chunk)));
    }
    writer->WritesDone();
    sent = true;
    status = writer->Finish();
  });
  auto& validating = server_->metrics().uploads_validating;
  const bool started = WaitFor([&] { return validating.load() > 0; }, 60);
  context.TryCancel();
  const auto cancelled = std::chrono::steady_clock::now();
  EXPECT_TRUE(started) << "the upload never reached validation";
  EXPECT_TRUE(WaitFor([&] { return validating.load() == 0; }, 1.0))
      << "validation went on after the client cancelled";
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - cancelled).count();
  upload.join();
  EXPECT_TRUE(sent);
  EXPECT_EQ(status.error_code(), grpc::StatusCode::CANCELLED);
  RecordProperty("seconds_to_stop", std::to_string(seconds));
  const std::string uploads = data_.path() + "/uploads";
  EXPECT_TRUE(WaitFor([&] { return fs::is_empty(uploads); }, 5)) << "temporary files left";
  ASSERT_OK_AND_ASSIGN(v1::ListScenesResponse scenes, client_->ListScenes(v1::ListScenesRequest()));
  EXPECT_EQ(scenes.scenes_size(), 0);
}

TEST_F(ServiceLimitsTest, StoredBytesAreCappedForUploadsAndJobs) {
  const std::string box = SourcePath("scenes/cornell_box.obj");
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo scene, client_->UploadSceneFile(box));
  // Room for this scene and a byte; a job's results pass it.
  ServerOptions o = TestServerOptions(data_.path());
  o.service.quotas.server_max_stored_bytes = scene.total_size() + 1;
  ASSERT_NO_FATAL_FAILURE(Restart(o));
  TempDir other;
  absl::Status full =
      client_->UploadSceneFile(other.Write("b.obj", ReadFile(box) + "# other\n")).status();
  EXPECT_EQ(full.code(), absl::StatusCode::kResourceExhausted) << full;
  EXPECT_NE(full.message().find("--max-stored-mb"), std::string::npos) << full;
  // A job is taken while the server stores less than its limit; its results fill it.
  ASSERT_OK_AND_ASSIGN(v1::Job job, client_->CreateJob(ShortSolve(scene.name(), 1)));
  ASSERT_TRUE(WaitFor([&] { return State(job.name()) == v1::JOB_STATE_SUCCEEDED; }, 60));
  absl::Status refused = client_->CreateJob(ShortSolve(scene.name(), 2)).status();
  EXPECT_EQ(refused.code(), absl::StatusCode::kResourceExhausted) << refused;
  // Deleting the job makes room again.
  ASSERT_TRUE(client_->DeleteJob(job.name()).ok());
  EXPECT_TRUE(client_->CreateJob(ShortSolve(scene.name(), 3)).ok());
}

}  // namespace
}  // namespace radiosity

namespace radiosity {
namespace {

// The hard memory cap: a job admitted by its estimate (which counts elements and pixels, not the
// scene's triangles) that grows the process past --max-memory-mb is stopped and FAILED with
// RESOURCE_EXHAUSTED naming the flag; a job within it is untouched, and the server goes on.
TEST_F(ServiceLimitsTest, AJobThatOutgrowsMaxMemoryFailsCleanly) {
  ServerOptions o = TestServerOptions(data_.path());
  o.service.max_memory_mb = 80;  // The estimate of the solve below is 72 MiB.
  ASSERT_NO_FATAL_FAILURE(Restart(o));
  TempDir dir;
  const std::string grid = dir.Write("grid.obj", service::testing::TriangleGridObj(400));
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo big, client_->UploadSceneFile(grid));
  v1::CreateJobRequest request = LongSolve(big.name(), 4096, 256);
  v1::EmitOverride* emit = request.mutable_solve()->add_emit();
  emit->set_name(kDefaultMaterialName);
  emit->set_r(1);
  emit->set_g(1);
  emit->set_b(1);
  ASSERT_OK_AND_ASSIGN(v1::Job job, client_->CreateJob(request));
  ASSERT_TRUE(WaitFor(
      [&] {
        absl::StatusOr<v1::Job> j = client_->GetJob(job.name());
        return j.ok() && j->state() == v1::JOB_STATE_FAILED;
      },
      60))
      << "state " << v1::JobState_Name(State(job.name()));
  ASSERT_OK_AND_ASSIGN(v1::Job failed, client_->GetJob(job.name()));
  EXPECT_EQ(failed.error().code(), static_cast<int>(absl::StatusCode::kResourceExhausted));
  EXPECT_NE(failed.error().message().find("--max-memory-mb 80"), std::string::npos)
      << failed.error().message();
  // A small job on the same server runs to the end.
  ASSERT_OK_AND_ASSIGN(v1::SceneInfo box,
                       client_->UploadSceneFile(SourcePath("scenes/cornell_box.obj")));
  ASSERT_OK_AND_ASSIGN(v1::Job small, client_->CreateJob(ShortSolve(box.name(), 1)));
  EXPECT_TRUE(WaitFor([&] { return State(small.name()) == v1::JOB_STATE_SUCCEEDED; }, 60));
}

}  // namespace
}  // namespace radiosity
