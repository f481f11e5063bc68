// Hostile input against a real server on 127.0.0.1 (a free port): truncated and corrupt uploads,
// sizes meant to exhaust memory, oversized chunks, undefined enum numbers, names and page tokens
// that are not ours, negative budgets, a cancel after the end, and concurrent deletes of a busy
// scene. Every refusal is asserted by its gRPC status code AND by the words of its message that
// name the problem; after every case the server must still answer grpc.health.v1 Check with
// SERVING (the health service, not another RPC), and no upload may leave files behind.
//
// Status codes chosen (docs/service/server.md):
//   truncated upload, wrong or malformed checksum, chunk over 1 MiB, bad names, duplicate files,
//   undefined enum numbers, unknown method strings, negative or non-finite numbers, garbage page
//   tokens, a mesh over the element limit (10^12 elements)            -> INVALID_ARGUMENT
//   a header announcing more bytes than --max-upload-mb (100 GB), a solve whose estimated memory
//   is above --max-memory-mb, a message over gRPC's 4 MiB limit        -> RESOURCE_EXHAUSTED
//   cancel or delete in the wrong state, delete of a busy scene        -> FAILED_PRECONDITION
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <set>
#include <thread>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "proto/api/sha256.h"
#include "proto/api/status.h"
#include "server/server.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

// These tests check that bad values of the deprecated string fields are still refused.
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"

namespace radiosity {
namespace {

namespace fs = std::filesystem;

using client::Snapshot;
using service::testing::ShortSolve;
using service::testing::UploadChunk;
using service::testing::UploadHeader;
using testing::ReadFile;
using testing::SourcePath;
using testing::TempDir;

using testing::Refused;

// Refused (tests/testing/test_util.h) for the status of a raw gRPC call.
::testing::AssertionResult Refused(const grpc::Status& status, absl::StatusCode code,
                                   std::initializer_list<std::string> words) {
  return Refused(
      absl::Status(static_cast<absl::StatusCode>(status.error_code()), status.error_message()),
      code, words);
}

class ServiceHostileTest : public service::testing::ServiceTest {
 protected:
  // After each case: grpc.health.v1.Health/Check says SERVING, for the server and for the
  // service, and no upload left a directory behind.
  void ExpectServing(const std::string& after) {
    SCOPED_TRACE("after: " + after);
    for (const std::string& name : {std::string(), std::string(service::kServiceName)}) {
      absl::StatusOr<bool> serving = client_->CheckHealth(name);
      ASSERT_TRUE(serving.ok()) << serving.status();
      EXPECT_TRUE(*serving) << "health of '" << name << "'";
    }
    const std::string uploads = data_.path() + "/uploads";
    EXPECT_TRUE(service::testing::WaitFor([&] { return fs::is_empty(uploads); }, 10))
        << "an upload left files in " << uploads;
  }
};

// Case 1: the stream closes before all announced bytes, or all announced files, arrive.
TEST_F(ServiceHostileTest, TruncatedUploadIsInvalidArgument) {
  const std::string json = ReadFile(SourcePath("scenes/furnace.json"));
  ASSERT_GT(json.size(), 100u);
  const std::string half = json.substr(0, json.size() / 2);
  grpc::Status st =
      RawUpload({UploadHeader({{"furnace.json", json}}), UploadChunk("furnace.json", 0, half)});
  EXPECT_TRUE(Refused(
      st, absl::StatusCode::kInvalidArgument,
      {"'furnace.json'", absl::StrCat("received ", half.size(), " of ", json.size(), " bytes")}));
  ExpectServing("truncated file");

  // OBJ + MTL announced, only the OBJ sent: the missing file is named.
  const std::string obj = ReadFile(SourcePath("scenes/cornell_box.obj"));
  const std::string mtl = ReadFile(SourcePath("scenes/cornell_box.mtl"));
  std::vector<v1::UploadSceneRequest> messages = {
      UploadHeader({{"cornell_box.obj", obj}, {"cornell_box.mtl", mtl}})};
  for (size_t at = 0; at < obj.size(); at += 4096) {
    messages.push_back(
        UploadChunk("cornell_box.obj", static_cast<int64_t>(at), obj.substr(at, 4096)));
  }
  st = RawUpload(messages);
  EXPECT_TRUE(Refused(st, absl::StatusCode::kInvalidArgument,
                      {"'cornell_box.mtl'", absl::StrCat("received 0 of ", mtl.size())}));
  ExpectServing("missing file");

  // Header only, then nothing; and no message at all.
  st = RawUpload({UploadHeader({{"furnace.json", json}})});
  EXPECT_TRUE(Refused(st, absl::StatusCode::kInvalidArgument, {"received 0 of"}));
  st = RawUpload({});
  EXPECT_TRUE(Refused(st, absl::StatusCode::kInvalidArgument, {"needs a header"}));
  ExpectServing("empty upload");

  // The client goes away mid-upload: nothing to answer, but the partial files are removed.
  {
    grpc::ClientContext context;
    v1::SceneInfo response;
    auto writer = client_->stub().UploadScene(&context, &response);
    ASSERT_TRUE(writer->Write(UploadHeader({{"furnace.json", json}})));
    ASSERT_TRUE(writer->Write(UploadChunk("furnace.json", 0, half)));
    const std::string uploads = data_.path() + "/uploads";
    EXPECT_TRUE(service::testing::WaitFor([&] { return !fs::is_empty(uploads); }, 10));
    context.TryCancel();
    EXPECT_EQ(writer->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  ExpectServing("cancelled upload");
  absl::StatusOr<v1::ListScenesResponse> scenes = client_->ListScenes({});
  ASSERT_TRUE(scenes.ok()) << scenes.status();
  EXPECT_EQ(scenes->scenes_size(), 0);
}

// Case 2: contents that do not match the announced checksum, and checksums that are not SHA-256.
TEST_F(ServiceHostileTest, WrongChecksumIsInvalidArgument) {
  const std::string json = ReadFile(SourcePath("scenes/furnace.json"));
  v1::UploadSceneRequest header = UploadHeader({{"furnace.json", json}});
  std::string flipped = json;
  flipped[flipped.size() / 2] ^= 1;  // Same size, one bit off.
  grpc::Status st = RawUpload({header, UploadChunk("furnace.json", 0, flipped)});
  EXPECT_TRUE(Refused(st, absl::StatusCode::kInvalidArgument,
                      {"'furnace.json'", "checksum mismatch", service::Sha256Hex(flipped),
                       service::Sha256Hex(json)}));
  ExpectServing("wrong checksum");

  for (const std::string& bad :
       {std::string(64, 'A'), std::string(63, '0'), std::string(""), std::string(64, 'g')}) {
    header.mutable_header()->mutable_files(0)->set_sha256(bad);
    st = RawUpload({header, UploadChunk("furnace.json", 0, json)});
    EXPECT_TRUE(Refused(st, absl::StatusCode::kInvalidArgument,
                        {"header.files[0] ('furnace.json')", "64 lowercase hex digits"}))
        << "sha256 '" << bad << "'";
  }
  ExpectServing("malformed checksum");
}

// Case 3: a header announcing 100 GB is refused on the header alone, before the server creates
// a file or reads a byte: RESOURCE_EXHAUSTED, the request is well formed but above this server's
// --max-upload-mb (as the queue limit and --max-memory-mb are). A negative size is malformed:
// INVALID_ARGUMENT.
TEST_F(ServiceHostileTest, HundredGigabyteHeaderIsRefusedBeforeAnyByte) {
  const int64_t kHundredGb = int64_t{100} << 30;
  for (const std::vector<int64_t>& sizes :
       {std::vector<int64_t>{kHundredGb}, std::vector<int64_t>{200 << 20, 200 << 20},
        std::vector<int64_t>{std::numeric_limits<int64_t>::max(),
                             std::numeric_limits<int64_t>::max()}}) {
    v1::UploadSceneRequest header;
    for (size_t i = 0; i < sizes.size(); ++i) {
      v1::FileInfo* f = header.mutable_header()->add_files();
      f->set_name(i == 0 ? "big.obj" : absl::StrCat("big", i, ".mtl"));
      f->set_size(sizes[i]);
      f->set_sha256(std::string(64, '0'));
    }
    // Only the header: had the server waited for data, it would answer "received 0 of ...".
    grpc::Status st = RawUpload({header});
    EXPECT_TRUE(Refused(st, absl::StatusCode::kResourceExhausted,
                        {"larger than this server's limit", "--max-upload-mb"}))
        << sizes[0];
    ExpectServing("huge header");
  }
  EXPECT_EQ(server_->metrics().upload_bytes.load(), 0);

  v1::UploadSceneRequest negative = UploadHeader({{"furnace.json", "x"}});
  negative.mutable_header()->mutable_files(0)->set_size(-1);
  EXPECT_TRUE(Refused(RawUpload({negative}), absl::StatusCode::kInvalidArgument,
                      {"header.files[0] ('furnace.json')", "negative size"}));
  ExpectServing("negative size");
}

// Case 4: a chunk over the documented 1 MiB is INVALID_ARGUMENT from the service; a message over
// gRPC's 4 MiB receive limit never reaches it and is RESOURCE_EXHAUSTED from gRPC itself.
TEST_F(ServiceHostileTest, ChunkOverOneMebibyteIsRefused) {
  const std::string data((1 << 20) + 1, ' ');
  v1::UploadSceneRequest header = UploadHeader({{"furnace.json", data}});
  grpc::Status st = RawUpload({header, UploadChunk("furnace.json", 0, data)});
  EXPECT_TRUE(Refused(st, absl::StatusCode::kInvalidArgument,
                      {"chunk of 'furnace.json'", "1048577 bytes", "above 1 MiB"}));
  ExpectServing("1 MiB + 1 chunk");

  const std::string huge(5 << 20, ' ');
  header = UploadHeader({{"furnace.json", huge}});
  st = RawUpload({header, UploadChunk("furnace.json", 0, huge)});
  EXPECT_TRUE(Refused(st, absl::StatusCode::kResourceExhausted, {"larger than max"}));
  ExpectServing("5 MiB message");
  EXPECT_EQ(server_->metrics().upload_bytes.load(), 0);
}

// Case 5: meshes of 10^12 elements are refused by CreateJob, before a job exists or anything
// is allocated for it (a job that got as far as meshing would fail later, or take the server
// down); so are images whose estimated memory is above --max-memory-mb.
TEST_F(ServiceHostileTest, TeraElementMeshIsRefusedBeforeAllocation) {
  ASSERT_OK_AND_ASSIGN(const v1::SceneInfo furnace,
                       client_->UploadSceneFile(SourcePath("scenes/furnace.json")));  // Area 6.
  v1::CreateJobRequest request = ShortSolve(furnace.name(), 1);
  request.mutable_solve()->mutable_mesh()->set_max_elements(0);
  request.mutable_solve()->mutable_mesh()->set_element_size(std::sqrt(6e-12));  // 10^12.
  EXPECT_TRUE(Refused(client_->CreateJob(request), absl::StatusCode::kInvalidArgument,
                      {"element size", "too small", "--max-elements"}));
  ExpectServing("element size");
  // With adaptive refinement the element size still counts.
  request.mutable_solve()->mutable_refine()->set_tolerance(0.1);
  request.mutable_solve()->mutable_mesh()->set_max_elements(1000);
  EXPECT_TRUE(Refused(client_->CreateJob(request), absl::StatusCode::kInvalidArgument,
                      {"solve.mesh.element_size", "element size", "too small"}));

  request = ShortSolve(furnace.name(), 1);
  request.mutable_solve()->mutable_mesh()->set_max_elements(1'000'000'000'000);
  EXPECT_TRUE(Refused(
      client_->CreateJob(request), absl::StatusCode::kInvalidArgument,
      {"solve.mesh.max_elements", "max elements 1000000000000", "above this server's limit"}));
  request.mutable_solve()->mutable_mesh()->set_max_elements(int64_t{1} << 41);
  EXPECT_TRUE(Refused(client_->CreateJob(request), absl::StatusCode::kInvalidArgument,
                      {"solve.mesh.max_elements", "[1, 2^40]"}));
  // Refinement's element budget is checked too.
  request.mutable_solve()->mutable_mesh()->set_max_elements(200);
  request.mutable_solve()->mutable_mesh()->set_element_size(0.5);
  request.mutable_solve()->mutable_refine()->set_tolerance(0.1);
  request.mutable_solve()->mutable_mesh()->set_max_elements(1'000'000'000'000);
  EXPECT_TRUE(Refused(client_->CreateJob(request), absl::StatusCode::kInvalidArgument,
                      {"max elements", "--max-elements"}));
  ExpectServing("max elements");

  // A 16384 x 16384 image is in range, but its memory is not.
  request = ShortSolve(furnace.name(), 1);
  request.mutable_solve()->set_width(16384);
  request.mutable_solve()->set_height(16384);
  EXPECT_TRUE(Refused(client_->CreateJob(request), absl::StatusCode::kResourceExhausted,
                      {"MiB", "--max-memory-mb"}));
  ExpectServing("image memory");

  absl::StatusOr<v1::ListJobsResponse> jobs = client_->ListJobs({});
  ASSERT_TRUE(jobs.ok()) << jobs.status();
  EXPECT_EQ(jobs->jobs_size(), 0);  // Nothing was queued.
  EXPECT_EQ(server_->metrics().jobs_created.load(), 0);
}

// Case 6: enum fields set to numbers the proto does not define (proto3 keeps them on the wire),
// and the string-valued choices (method, estimator, sampling) set to unknown names.
TEST_F(ServiceHostileTest, UndefinedEnumValuesAreInvalidArgument) {
  const std::string json = ReadFile(SourcePath("scenes/furnace.json"));
  for (int format : {42, -1}) {
    v1::UploadSceneRequest header = UploadHeader({{"furnace.json", json}});
    header.mutable_header()->set_format(static_cast<v1::SceneFormat>(format));
    EXPECT_TRUE(Refused(RawUpload({header, UploadChunk("furnace.json", 0, json)}),
                        absl::StatusCode::kInvalidArgument,
                        {"header.format", absl::StrCat(format), "not a SceneFormat"}));
    ExpectServing("scene format");
  }

  for (int state : {99, -3}) {
    v1::ListJobsRequest list;
    list.add_states(v1::JOB_STATE_SUCCEEDED);
    list.add_states(static_cast<v1::JobState>(state));
    EXPECT_TRUE(Refused(client_->ListJobs(list), absl::StatusCode::kInvalidArgument,
                        {"states[1]", absl::StrCat(state), "not a JobState"}));
    ExpectServing("state filter");
  }

  ASSERT_OK_AND_ASSIGN(const v1::SceneInfo furnace,
                       client_->UploadSceneFile(SourcePath("scenes/furnace.json")));
  struct Case {
    std::function<void(v1::CreateJobRequest*)> set;
    std::string field;
  };
  const std::vector<Case> cases = {
      {[](auto* r) { r->mutable_solve()->set_method("7"); }, "solve.method: '7'"},
      {[](auto* r) { r->mutable_solve()->set_method("PROGRESSIVE"); }, "solve.method"},
      {[](auto* r) { r->mutable_solve()->mutable_formfactor()->set_method("raytrace"); },
       "solve.formfactor.method: 'raytrace'"},
      {[](auto* r) { r->mutable_solve()->mutable_formfactor()->set_sampling("owen"); },
       "solve.formfactor.sampling: 'owen'"},
      {[](auto* r) { r->mutable_solve()->set_shooting("random"); }, "solve.shooting: 'random'"},
      {[](auto* r) { r->mutable_view_factor()->set_method("exact"); },
       "view_factor.method: 'exact'"},
      {[](auto* r) { r->mutable_view_factor()->set_sampling("x"); }, "view_factor.sampling: 'x'"},
      {[](auto* r) {
         v1::SurfaceThermal* t = r->mutable_view_factor()->add_thermal();
         t->set_surface("*");
         t->set_emissivity(1.5);
       },
       "view_factor.thermal[0]: surface '*': emissivity 1.5 is outside [0, 1]"},
      {[](auto* r) {
         v1::SurfaceThermal* t = r->mutable_view_factor()->add_thermal();
         t->set_surface("*");
         t->set_emissivity(1);
         r->mutable_view_factor()->set_ambient_temperature(-4);
       },
       "view_factor.ambient_temperature: -4 K"},
      {[](auto* r) { r->mutable_view_factor()->add_thermal()->set_surface("x0"); },
       "view_factor.thermal[0] (surface 'x0'): emissivity is required"},
  };
  for (const Case& c : cases) {
    v1::CreateJobRequest request = ShortSolve(furnace.name(), 1);
    c.set(&request);
    EXPECT_TRUE(
        Refused(client_->CreateJob(request), absl::StatusCode::kInvalidArgument, {c.field}));
  }
  // A method name of a megabyte is quoted in the message, which is cut to fit the trailers
  // (otherwise the client would see RESOURCE_EXHAUSTED for its metadata, not the answer).
  v1::CreateJobRequest huge = ShortSolve(furnace.name(), 1);
  huge.mutable_solve()->set_method(std::string(1 << 20, 'm'));
  absl::StatusOr<v1::Job> refused = client_->CreateJob(huge);
  EXPECT_TRUE(
      Refused(refused, absl::StatusCode::kInvalidArgument, {"solve.method: 'mmm", "more bytes)"}));
  EXPECT_LE(refused.status().message().size(), service::kMaxStatusMessage);
  ExpectServing("unknown methods");
}

// Case 7: cancelling a job that has ended is FAILED_PRECONDITION (as documented in
// service.proto), and leaves the job exactly as it was; cancelling a job that does not exist is
// NOT_FOUND.
TEST_F(ServiceHostileTest, CancelOfAFinishedJobIsFailedPrecondition) {
  ASSERT_OK_AND_ASSIGN(const v1::SceneInfo furnace,
                       client_->UploadSceneFile(SourcePath("scenes/furnace.json")));
  absl::StatusOr<v1::Job> job = client_->CreateJob(ShortSolve(furnace.name(), 1));
  ASSERT_TRUE(job.ok()) << job.status();
  absl::StatusOr<Snapshot> last = client_->Watch(job->name(), 0, true, nullptr);
  ASSERT_TRUE(last.ok()) << last.status();
  ASSERT_EQ(last->state, v1::JOB_STATE_SUCCEEDED);
  absl::StatusOr<v1::Job> before = client_->GetJob(job->name());
  ASSERT_TRUE(before.ok()) << before.status();

  for (int i = 0; i < 2; ++i) {
    EXPECT_TRUE(Refused(client_->CancelJob(job->name()), absl::StatusCode::kFailedPrecondition,
                        {job->name(), "has already ended", "SUCCEEDED"}));
  }
  ExpectServing("cancel of a finished job");
  absl::StatusOr<v1::Job> after = client_->GetJob(job->name());
  ASSERT_TRUE(after.ok()) << after.status();
  EXPECT_EQ(after->SerializeAsString(), before->SerializeAsString());
  EXPECT_FALSE(after->cancel_requested());
  TempDir out;
  EXPECT_TRUE(client_->DownloadResults(job->name(), out.path()).ok());

  EXPECT_TRUE(Refused(client_->CancelJob("jobs/doesnotexist"), absl::StatusCode::kNotFound,
                      {"jobs/doesnotexist", "does not exist"}));
  EXPECT_TRUE(Refused(client_->Watch("jobs/doesnotexist", 0, true, nullptr),
                      absl::StatusCode::kNotFound, {"jobs/doesnotexist", "does not exist"}));
  ExpectServing("cancel of a missing job");

  // The converse: deleting a job that has not ended is FAILED_PRECONDITION.
  v1::CreateJobRequest long_request = ShortSolve(furnace.name(), 2);
  long_request.mutable_solve()->set_max_rays(0);
  long_request.mutable_solve()->set_tolerance(1e-15);
  long_request.mutable_solve()->set_max_seconds(30);
  absl::StatusOr<v1::Job> running = client_->CreateJob(long_request);
  ASSERT_TRUE(running.ok()) << running.status();
  EXPECT_TRUE(Refused(client_->DeleteJob(running->name()), absl::StatusCode::kFailedPrecondition,
                      {running->name(), "queued or running", "cancel it first"}));
  ASSERT_TRUE(client_->CancelJob(running->name()).ok());
  absl::StatusOr<Snapshot> stopped = client_->Watch(running->name(), 0, true, nullptr);
  ASSERT_TRUE(stopped.ok()) << stopped.status();
  EXPECT_EQ(stopped->state, v1::JOB_STATE_CANCELLED);
  EXPECT_TRUE(client_->DeleteJob(running->name()).ok());
  EXPECT_TRUE(
      Refused(client_->GetJob(running->name()), absl::StatusCode::kNotFound, {running->name()}));
  ExpectServing("delete of a running job");
}

// Case 8: several threads delete a scene while jobs on it run, while more are created and some
// cancelled. Deletion is refused while a job is queued or running (a long job keeps the scene
// busy until the creator is done); every job ends cleanly; exactly one delete succeeds once they
// have; the stored jobs stay readable, also after a restart on the same data directory.
TEST_F(ServiceHostileTest, ConcurrentDeletesOfABusySceneLeaveJobsIntact) {
  service::ServerOptions options = service::testing::TestServerOptions(data_.path());
  options.service.workers = 2;
  options.service.threads_per_job = 1;
  ASSERT_NO_FATAL_FAILURE(Restart(options));

  ASSERT_OK_AND_ASSIGN(const v1::SceneInfo scene,
                       client_->UploadSceneFile(SourcePath("scenes/cornell_box.obj")));
  std::mutex mu;
  std::vector<std::string> jobs;
  auto create = [&](const v1::CreateJobRequest& r) -> absl::StatusOr<std::string> {
    absl::StatusOr<v1::Job> j = client_->CreateJob(r);
    if (!j.ok()) return j.status();
    std::lock_guard<std::mutex> lock(mu);
    jobs.push_back(j->name());
    return j->name();
  };
  auto short_solve = [&](uint64_t seed) {
    v1::CreateJobRequest r = ShortSolve(scene.name(), seed);
    r.mutable_solve()->set_max_rays(100000);  // Tens of milliseconds each.
    r.mutable_solve()->set_snapshot_interval(0.01);
    return r;
  };
  // Runs until cancelled (30 s at most).
  v1::CreateJobRequest long_request = ShortSolve(scene.name(), 1);
  long_request.mutable_solve()->set_max_rays(0);
  long_request.mutable_solve()->set_tolerance(1e-15);
  long_request.mutable_solve()->set_rays_per_element(1e6);
  long_request.mutable_solve()->set_max_seconds(30);
  absl::StatusOr<std::string> long_job = create(long_request);
  ASSERT_TRUE(long_job.ok()) << long_job.status();
  for (uint64_t seed = 2; seed <= 6; ++seed) ASSERT_TRUE(create(short_solve(seed)).ok());

  std::atomic<int> deleted{0}, refused{0}, not_found{0}, other{0};
  std::string other_error;
  auto deleter = [&] {
    std::unique_ptr<client::Client> c = service::testing::ConnectTo(*server_);
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (std::chrono::steady_clock::now() < end) {
      absl::Status st = c->DeleteScene(scene.name());
      if (st.ok()) {
        ++deleted;
      } else if (Refused(st, absl::StatusCode::kFailedPrecondition,
                         {scene.name(), "queued or running"})) {
        ++refused;
      } else if (Refused(st, absl::StatusCode::kNotFound, {scene.name(), "does not exist"})) {
        ++not_found;
        return;
      } else {
        std::lock_guard<std::mutex> lock(mu);
        other_error = st.ToString();
        ++other;
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
  };
  // Creates more jobs while the deleters try, cancels every third (queued, running or already
  // ended: all fine), then the long job, which lets the scene go once the queue drains.
  auto creator = [&] {
    for (uint64_t seed = 100; seed < 130; ++seed) {
      absl::StatusOr<std::string> name = create(short_solve(seed));
      EXPECT_TRUE(name.ok()) << name.status();
      if (name.ok() && seed % 3 == 0) (void)client_->CancelJob(*name);
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    absl::StatusOr<v1::Job> cancelled = client_->CancelJob(*long_job);
    EXPECT_TRUE(cancelled.ok()) << cancelled.status();
  };
  std::vector<std::thread> threads;
  for (int i = 0; i < 4; ++i) threads.emplace_back(deleter);
  threads.emplace_back(creator);
  for (std::thread& t : threads) t.join();

  EXPECT_EQ(deleted.load(), 1);
  EXPECT_EQ(other.load(), 0) << other_error;
  EXPECT_GT(refused.load(), 0);
  EXPECT_EQ(not_found.load(), 4);  // Every deleter, the successful one too, ends at NOT_FOUND.
  ExpectServing("concurrent deletes");

  // Every job ended (the delete could only succeed then): those never cancelled succeeded; each
  // reads back, and the listing by scene still finds them all.
  auto check_jobs = [&](client::Client& c) {
    for (const std::string& name : jobs) {
      absl::StatusOr<v1::Job> j = c.GetJob(name);
      ASSERT_TRUE(j.ok()) << name << ": " << j.status();
      if (j->cancel_requested()) {
        EXPECT_TRUE(j->state() == v1::JOB_STATE_SUCCEEDED || j->state() == v1::JOB_STATE_CANCELLED)
            << name << " is " << v1::JobState_Name(j->state()) << " " << j->error().message();
      } else {
        EXPECT_EQ(j->state(), v1::JOB_STATE_SUCCEEDED) << name << " " << j->error().message();
      }
      EXPECT_EQ(j->scene(), scene.name());
      EXPECT_TRUE(j->has_end_time());
    }
    v1::ListJobsRequest list;
    list.set_scene(scene.name());
    list.set_page_size(1000);
    absl::StatusOr<v1::ListJobsResponse> listed = c.ListJobs(list);
    ASSERT_TRUE(listed.ok()) << listed.status();
    EXPECT_EQ(listed->jobs_size(), static_cast<int>(jobs.size()));
  };
  check_jobs(*client_);
  absl::StatusOr<v1::Job> cancelled = client_->GetJob(*long_job);
  ASSERT_TRUE(cancelled.ok()) << cancelled.status();
  EXPECT_EQ(cancelled->state(), v1::JOB_STATE_CANCELLED);
  const std::string& last_job = jobs[1];  // seed 2: never cancelled.
  TempDir out;
  EXPECT_TRUE(client_->DownloadResults(last_job, out.path()).ok());
  absl::StatusOr<Snapshot> final_snapshot = client_->Watch(last_job, 0, false, nullptr);
  ASSERT_TRUE(final_snapshot.ok()) << final_snapshot.status();
  EXPECT_TRUE(final_snapshot->final);
  EXPECT_EQ(final_snapshot->state, v1::JOB_STATE_SUCCEEDED);
  EXPECT_TRUE(Refused(client_->CreateJob(ShortSolve(scene.name(), 1)), absl::StatusCode::kNotFound,
                      {scene.name()}));

  // The store survives a restart with every job intact.
  ASSERT_NO_FATAL_FAILURE(Restart(options));
  check_jobs(*client_);
  ExpectServing("restart");
}

// Case 9: names that are not ours, garbage page tokens, negative page sizes and budgets,
// non-finite numbers, duplicate and clashing file names, out-of-order chunks.
TEST_F(ServiceHostileTest, BadNamesTokensBudgetsAndFileListsAreInvalidArgument) {
  const absl::StatusCode kInvalid = absl::StatusCode::kInvalidArgument;
  for (const std::string& name :
       {std::string(), std::string("scenes/"), std::string("scenes/../x"), std::string("jobs/x"),
        std::string("scenes/ABC"), std::string(1000, 'a')}) {
    EXPECT_TRUE(Refused(client_->GetScene(name), kInvalid, {"is not a scenes/{id} name"}));
    EXPECT_TRUE(Refused(client_->DeleteScene(name), kInvalid, {"is not a scenes/{id} name"}));
  }
  for (const std::string& name : {std::string(), std::string("jobs/"), std::string("scenes/x")}) {
    EXPECT_TRUE(Refused(client_->GetJob(name), kInvalid, {"is not a jobs/{id} name"}));
    EXPECT_TRUE(Refused(client_->CancelJob(name), kInvalid, {"is not a jobs/{id} name"}));
    EXPECT_TRUE(Refused(client_->DeleteJob(name), kInvalid, {"is not a jobs/{id} name"}));
    EXPECT_TRUE(
        Refused(client_->Watch(name, 0, true, nullptr), kInvalid, {"is not a jobs/{id} name"}));
  }
  // Long strings are quoted cut short: the status must still fit in the client's trailers.
  const std::string long_name(100000, 'a');
  EXPECT_TRUE(Refused(client_->GetScene(long_name), kInvalid,
                      {"(100000 bytes)", "is not a scenes/{id} name"}));
  v1::CreateJobRequest no_scene;
  no_scene.mutable_solve();
  EXPECT_TRUE(Refused(client_->CreateJob(no_scene), kInvalid, {"scene: ''", "not a scene name"}));
  ExpectServing("bad names");

  for (const std::string& token : {std::string("garbage"), std::string("-5"), std::string("0"),
                                   std::string("99999999999999999999999"),
                                   std::string("1; DROP TABLE jobs"), std::string("1e3")}) {
    v1::ListScenesRequest scenes;
    scenes.set_page_token(token);
    EXPECT_TRUE(Refused(client_->ListScenes(scenes), kInvalid, {"page_token", "not valid"}));
    v1::ListJobsRequest jobs;
    jobs.set_page_token(token);
    EXPECT_TRUE(Refused(client_->ListJobs(jobs), kInvalid, {"page_token", "not valid"}));
  }
  v1::ListScenesRequest negative_page;
  negative_page.set_page_size(-1);
  EXPECT_TRUE(Refused(client_->ListScenes(negative_page), kInvalid, {"page_size", "negative"}));
  v1::ListJobsRequest negative_jobs_page;
  negative_jobs_page.set_page_size(std::numeric_limits<int32_t>::min());
  EXPECT_TRUE(Refused(client_->ListJobs(negative_jobs_page), kInvalid, {"page_size", "negative"}));
  v1::ListJobsRequest huge_page;
  huge_page.set_page_size(std::numeric_limits<int32_t>::max());  // Capped at 1000.
  EXPECT_TRUE(client_->ListJobs(huge_page).ok());
  ExpectServing("page tokens");

  // Negative and non-finite budgets and sizes, each named by its field.
  ASSERT_OK_AND_ASSIGN(const v1::SceneInfo furnace,
                       client_->UploadSceneFile(SourcePath("scenes/furnace.json")));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  struct Case {
    std::function<void(v1::SolveSpec*)> set;
    std::string field;
  };
  const std::vector<Case> cases = {
      {[](auto* s) { s->set_max_rays(-1); }, "solve.max_rays"},
      {[](auto* s) { s->set_max_seconds(-1); }, "solve.max_seconds"},
      {[&](auto* s) { s->set_max_seconds(nan); }, "solve.max_seconds"},
      {[](auto* s) { s->set_tolerance(-0.5); }, "solve.tolerance"},
      {[&](auto* s) { s->set_tolerance(inf); }, "solve.tolerance"},
      {[](auto* s) { s->set_rays_per_element(-1); }, "solve.rays_per_element"},
      {[](auto* s) { s->set_threads(-1); }, "solve.threads"},
      {[](auto* s) { s->set_width(-8); }, "solve.width"},
      {[](auto* s) { s->set_snapshot_interval(-1); }, "solve.snapshot_interval"},
      {[&](auto* s) { s->set_overshoot(nan); }, "solve.overshoot"},
      {[](auto* s) { s->set_max_matrix_mb(-1); }, "solve.max_matrix_mb"},
      {[&](auto* s) { s->mutable_mesh()->set_element_size(nan); }, "solve.mesh.element_size"},
      {[](auto* s) { s->mutable_mesh()->set_element_size(-1); }, "solve.mesh.element_size"},
      {[](auto* s) { s->mutable_mesh()->set_max_elements(-1); }, "solve.mesh.max_elements"},
      {[](auto* s) { s->mutable_mesh()->set_patch_depth(-1); }, "solve.mesh.patch_depth"},
      {[](auto* s) { s->mutable_refine()->set_tolerance(-0.1); }, "solve.refine.tolerance"},
      {[&](auto* s) { s->mutable_refine()->set_min_element_size(-inf); },
       "solve.refine.min_element_size"},
      {[&](auto* s) { s->add_sensors()->mutable_normal()->set_z(nan); }, "solve.sensors[0]"},
  };
  for (const Case& c : cases) {
    v1::CreateJobRequest request = ShortSolve(furnace.name(), 1);
    c.set(request.mutable_solve());
    EXPECT_TRUE(Refused(client_->CreateJob(request), kInvalid, {c.field}));
  }
  v1::CreateJobRequest vf;
  vf.set_scene(furnace.name());
  vf.mutable_view_factor()->set_rays_per_surface(-1);
  EXPECT_TRUE(Refused(client_->CreateJob(vf), kInvalid, {"view_factor.rays_per_surface"}));
  v1::CreateJobRequest no_spec;
  no_spec.set_scene(furnace.name());
  EXPECT_TRUE(Refused(client_->CreateJob(no_spec), kInvalid, {"one of solve or view_factor"}));
  ExpectServing("negative budgets");

  // Watch and download arguments.
  absl::StatusOr<v1::Job> job = client_->CreateJob(ShortSolve(furnace.name(), 1));
  ASSERT_TRUE(job.ok()) << job.status();
  ASSERT_TRUE(client_->Watch(job->name(), 0, true, nullptr).ok());
  {
    grpc::ClientContext context;
    v1::WatchJobRequest watch;
    watch.set_name(job->name());
    watch.set_after_sequence(-1);
    auto reader = client_->stub().WatchJob(&context, watch);
    v1::WatchJobResponse response;
    while (reader->Read(&response)) {
    }
    EXPECT_TRUE(Refused(reader->Finish(), kInvalid, {"after_sequence", "negative"}));
  }
  for (int64_t offset : {int64_t{-1}, int64_t{1} << 40}) {
    grpc::ClientContext context;
    v1::DownloadResultRequest download;
    download.set_name(job->name());
    download.set_file("elements.csv");
    download.set_offset(offset);
    auto reader = client_->stub().DownloadResult(&context, download);
    v1::FileChunk chunk;
    while (reader->Read(&chunk)) {
    }
    EXPECT_TRUE(Refused(reader->Finish(), absl::StatusCode::kOutOfRange, {"offset", "outside"}));
  }
  TempDir out;
  EXPECT_TRUE(Refused(client_->DownloadResults(job->name(), out.path(), "../etc/passwd"),
                      absl::StatusCode::kNotFound, {"no result file '../etc/passwd'"}));
  ExpectServing("watch and download arguments");

  // File lists: duplicates, a name that is both a file and a directory, unsafe names, too many.
  const std::string json = ReadFile(SourcePath("scenes/furnace.json"));
  EXPECT_TRUE(Refused(RawUpload({UploadHeader({{"a.obj", "x"}, {"a.mtl", "y"}, {"a.mtl", "y"}})}),
                      kInvalid, {"header.files[2] ('a.mtl')", "appears twice"}));
  EXPECT_TRUE(Refused(RawUpload({UploadHeader({{"a.obj", "x"}, {"m", "y"}, {"m/b.mtl", "z"}})}),
                      kInvalid, {"'m'", "'m/b.mtl'", "both a file and a directory"}));
  for (const std::string& name :
       {std::string("/etc/passwd"), std::string("a/../../b.obj"), std::string("a\\b.obj"),
        std::string("a//b.obj"), std::string("./a.obj"), std::string("a\nb.obj"),
        std::string("a\0b.obj", 7), std::string()}) {
    EXPECT_TRUE(Refused(RawUpload({UploadHeader({{name, json}})}), kInvalid,
                        {"header.files[0]", "not a relative path inside the scene"}))
        << name;
  }
  std::vector<std::pair<std::string, std::string>> many = {{"a.obj", "x"}};
  for (int i = 0; i < 64; ++i) many.emplace_back(absl::StrCat(i, ".mtl"), "y");
  EXPECT_TRUE(Refused(RawUpload({UploadHeader(many)}), kInvalid,
                      {"header.files", "65 files", "more than 64"}));
  v1::UploadSceneRequest no_files;
  no_files.mutable_header()->set_display_name("empty");
  EXPECT_TRUE(Refused(RawUpload({no_files}), kInvalid, {"header.files: no files"}));
  v1::UploadSceneRequest long_id = UploadHeader({{"furnace.json", json}});
  long_id.mutable_header()->set_request_id(std::string(257, 'k'));
  EXPECT_TRUE(Refused(RawUpload({long_id}), kInvalid, {"request_id", "longer than 256"}));
  ExpectServing("file lists");

  // Chunks: before the header, a second header, an unknown file, a gap, beyond the size.
  v1::UploadSceneRequest header = UploadHeader({{"furnace.json", json}});
  const std::string head = json.substr(0, 10);
  EXPECT_TRUE(Refused(RawUpload({UploadChunk("furnace.json", 0, json)}), kInvalid,
                      {"the first message of an upload must be its header"}));
  EXPECT_TRUE(Refused(RawUpload({header, header}), kInvalid, {"only chunks"}));
  EXPECT_TRUE(Refused(RawUpload({header, UploadChunk("other.json", 0, json)}), kInvalid,
                      {"'other.json'", "the header does not list"}));
  EXPECT_TRUE(Refused(RawUpload({header, UploadChunk("furnace.json", 0, head),
                                 UploadChunk("furnace.json", 20, json.substr(20, 10))}),
                      kInvalid, {"'furnace.json' at offset 20", "expected 10"}));
  EXPECT_TRUE(Refused(RawUpload({header, UploadChunk("furnace.json", 0, json + "  ")}), kInvalid,
                      {"'furnace.json' is longer than the", "bytes declared"}));
  ExpectServing("chunks");

  // A display name of a megabyte is refused. A scene of 200000 degenerate faces loads in linear
  // time (it took quadratic time, holding the upload lock) and is stored with the first 100
  // warnings and a count, so its SceneInfo stays far below gRPC's message limit and can be read
  // back (and listed) ever after; the server also keeps at most 200 warnings of any kind.
  v1::UploadSceneRequest long_display = UploadHeader({{"furnace.json", json}});
  long_display.mutable_header()->set_display_name(std::string(1 << 20, 'n'));
  EXPECT_TRUE(Refused(RawUpload({long_display, UploadChunk("furnace.json", 0, json)}), kInvalid,
                      {"header.display_name", "longer than 1024 bytes"}));
  TempDir scenes;
  const int kNoisy = 200000;
  scenes.Write("noisy.mtl", "newmtl m\nKd 0.5 0.5 0.5\n");
  std::string obj = "mtllib noisy.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\n";
  for (int i = 0; i < kNoisy; ++i) obj += "f 1 2 4\n";  // Collinear: zero area.
  absl::StatusOr<v1::SceneInfo> noisy = client_->UploadSceneFile(scenes.Write("noisy.obj", obj));
  ASSERT_TRUE(noisy.ok()) << noisy.status();
  ASSERT_EQ(noisy->warnings_size(), 101);
  EXPECT_NE(noisy->warnings(0).find("noisy.obj:8: surface 'noisy' face 1 has zero area"),
            std::string::npos)
      << noisy->warnings(0);
  EXPECT_NE(noisy->warnings(100).find("199900 more faces of zero area were dropped"),
            std::string::npos)
      << noisy->warnings(100);
  EXPECT_TRUE(client_->GetScene(noisy->name()).ok());
  absl::StatusOr<v1::ListScenesResponse> listed = client_->ListScenes({});
  ASSERT_TRUE(listed.ok()) << listed.status();
  ExpectServing("display name and warnings");

  // After all of that, a proper solve still runs.
  absl::StatusOr<v1::Job> again = client_->CreateJob(ShortSolve(furnace.name(), 2));
  ASSERT_TRUE(again.ok()) << again.status();
  absl::StatusOr<Snapshot> last = client_->Watch(again->name(), 0, true, nullptr);
  ASSERT_TRUE(last.ok()) << last.status();
  EXPECT_EQ(last->state, v1::JOB_STATE_SUCCEEDED);
}

}  // namespace
}  // namespace radiosity

namespace radiosity::service {
namespace {

// Text that is not UTF-8 never reaches a stored or sent message: a Latin-1 byte past the first
// 64 KiB of an OBJ (Debian's assimp-testmodels regr01.obj) uploads, and the tenant's scenes still
// list and read back; ValidUtf8 replaces what is not UTF-8 and keeps what is.
TEST_F(ServiceHostileTest, LatinOneLateInAFileKeepsTheSceneListReadable) {
  radiosity::testing::TempDir dir;
  dir.Write("late.mtl", "newmtl lamp\nKd 0.5 0.5 0.5\nKe 1 1 1\n");
  std::string obj = "mtllib late.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n";
  for (int i = 0; i < 14000; ++i) obj += "# padding\n";
  obj += "usemtl caf\xe9\nf 1 2 3\n";
  absl::StatusOr<v1::SceneInfo> info = client_->UploadSceneFile(dir.Write("late.obj", obj));
  ASSERT_TRUE(info.ok()) << info.status();
  absl::StatusOr<v1::ListScenesResponse> list = client_->ListScenes({});
  ASSERT_TRUE(list.ok()) << list.status();
  absl::StatusOr<v1::SceneInfo> again = client_->GetScene(info->name());
  ASSERT_TRUE(again.ok()) << again.status();
  bool named = false;
  for (const std::string& w : again->warnings())
    named |= w.find("caf\xC3\xA9") != std::string::npos;
  EXPECT_TRUE(named) << "the warning names the material as UTF-8";

  EXPECT_EQ(ValidUtf8("caf\xC3\xA9 \xE2\x82\xAC \xF0\x9F\x92\xA1"),
            "caf\xC3\xA9 \xE2\x82\xAC \xF0\x9F\x92\xA1");
  EXPECT_EQ(ValidUtf8("caf\xE9!"), "caf\xEF\xBF\xBD!");
  EXPECT_EQ(ValidUtf8("\xC3"), "\xEF\xBF\xBD");                                  // Cut short.
  EXPECT_EQ(ValidUtf8("\xED\xA0\x80"), "\xEF\xBF\xBD\xEF\xBF\xBD\xEF\xBF\xBD");  // A surrogate.
  EXPECT_EQ(ValidUtf8("\xC0\xAF"), "\xEF\xBF\xBD\xEF\xBF\xBD");                  // Overlong.
}

}  // namespace
}  // namespace radiosity::service
