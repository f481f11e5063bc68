// Service concurrency (issue 12, items 5 and 7) against a real server on 127.0.0.1: long work
// (validating an upload, loading a scene for CreateJob) runs off gRPC's callback threads and
// outside any lock over all scenes, so other calls answer meanwhile; a scene that a CreateJob is
// using is not deleted under it; a retried CreateJob answers alike whether its job is queued,
// running or ended.
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/str_cat.h"
#include "client/client.h"
#include "server/executor.h"
#include "server/logging.h"
#include "server/scene_refs.h"
#include "server/server.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using client::Client;
using google::protobuf::util::MessageDifferencer;
using service::testing::ConnectTo;
using service::testing::TestServerOptions;
using service::testing::WaitFor;
using testing::SourcePath;
using testing::TempDir;

std::unique_ptr<service::Server> StartServer(const service::ServerOptions& options) {
  absl::StatusOr<std::unique_ptr<service::Server>> s = service::Server::Start(options);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? *std::move(s) : nullptr;
}

// A client whose calls may last as long as a large upload under a sanitizer.
std::unique_ptr<Client> PatientClient(const service::Server& server) {
  client::ClientOptions options;
  options.timeout_seconds = 600;
  return ConnectTo(server, options);
}

// Writes `head` and then vertices that no face uses until the file has about `bytes` bytes: the
// loader parses and checks every one of them, so loading takes time in proportion to the size.
std::string WriteLargeObj(const std::string& path, const std::string& head, int64_t bytes) {
  std::ofstream out(path, std::ios::binary);
  out << head;
  std::string block;
  for (int i = 0; i < 32768; ++i) block += "v 0.1234567 1.2345678 2.3456789\n";
  for (int64_t written = static_cast<int64_t>(head.size()); written < bytes;
       written += static_cast<int64_t>(block.size())) {
    out.write(block.data(), static_cast<std::streamsize>(block.size()));
  }
  return path;
}

// An MTL file in `dir` (materials.mtl) with a white reflector and a lamp.
void WriteMaterials(const TempDir& dir) {
  dir.Write("materials.mtl",
            "newmtl white\nKd 0.5 0.5 0.5\n"
            "newmtl lamp\nKd 0 0 0\nKe 10 10 10\n");
}

// A white floor, lit by nothing (OBJ text using materials.mtl).
constexpr char kFloorObj[] =
    "mtllib materials.mtl\n"
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
    "o floor\nusemtl white\nf 1 2 3 4\n";

// A lamp above a white floor.
constexpr char kLitObj[] =
    "mtllib materials.mtl\n"
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
    "v 0 0 1\nv 0 1 1\nv 1 1 1\nv 1 0 1\n"
    "o floor\nusemtl white\nf 1 2 3 4\n"
    "o lamp\nusemtl lamp\nf 5 6 7 8\n";

// A solve of a few milliseconds.
v1::CreateJobRequest ShortSolve(const std::string& scene) {
  v1::CreateJobRequest r;
  r.set_scene(scene);
  v1::SolveSpec* s = r.mutable_solve();
  s->mutable_mesh()->set_max_elements(200);
  s->set_max_rays(20000);
  s->set_width(8);
  s->set_height(8);
  return r;
}

// A solve that runs until cancelled (or 60 s), publishing snapshots.
v1::CreateJobRequest LongSolve(const std::string& scene) {
  v1::CreateJobRequest r;
  r.set_scene(scene);
  v1::SolveSpec* s = r.mutable_solve();
  s->mutable_mesh()->set_max_elements(2000);
  s->set_tolerance(1e-15);
  s->set_max_seconds(60);
  s->set_rays_per_element(1e6);
  s->set_snapshot_interval(0.02);
  s->set_width(16);
  s->set_height(16);
  return r;
}

double MillisecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

// Solving, with a snapshot taken (meshing's progress comes in snapshots too).
bool IsRunningWithSnapshot(Client& c, const std::string& job, int64_t after_sequence = 0) {
  absl::StatusOr<v1::Job> j = c.GetJob(job);
  return j.ok() && j->state() == v1::JOB_STATE_RUNNING &&
         j->progress().phase() == v1::JOB_PHASE_SOLVING && j->last_sequence() > after_sequence;
}

::testing::AssertionResult SameMessage(const google::protobuf::Message& a,
                                       const google::protobuf::Message& b,
                                       MessageDifferencer* differencer = nullptr) {
  MessageDifferencer plain;
  MessageDifferencer& d = differencer ? *differencer : plain;
  std::string report;
  d.ReportDifferencesToString(&report);
  if (d.Compare(a, b)) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << report;
}

// The executor runs every task given, several at once, also those still queued when it is
// destroyed, and no exception escapes a task.
TEST(ServiceExecutorTest, RunsEveryTaskAndCatchesWhatTheyThrow) {
  const char* level = std::getenv("RADIOSITY_TEST_LOG");  // As TestServerOptions.
  ASSERT_TRUE(service::SetLogLevel(level && *level ? level : "off"));
  std::atomic<int> ran{0}, together{0}, most_together{0};
  {
    service::Executor executor(3);
    for (int i = 0; i < 30; ++i) {
      executor.Run([&, i] {
        const int now = ++together;
        int seen = most_together.load();
        while (now > seen && !most_together.compare_exchange_weak(seen, now)) {
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
        --together;
        ++ran;
        if (i % 7 == 0) throw std::runtime_error("a task that throws");
      });
    }
  }
  EXPECT_EQ(ran.load(), 30);
  EXPECT_GT(most_together.load(), 1);
  EXPECT_LE(most_together.load(), 3);
}

// A scene referenced by a CreateJob cannot start being deleted; a reference waits while a
// deletion decides and is taken once it has; deletions of one scene take turns.
TEST(ServiceSceneRefsTest, DeletionAndReferencesExcludeEachOther) {
  service::SceneRefs refs;
  int64_t references = -1;
  {
    service::SceneRefs::Ref a = refs.Acquire("s");
    service::SceneRefs::Ref b = refs.Acquire("s");
    EXPECT_FALSE(refs.BeginDelete("s", &references).has_value());
    EXPECT_EQ(references, 2);
    // Other scenes are not affected.
    EXPECT_TRUE(refs.BeginDelete("t", &references).has_value());
    EXPECT_EQ(references, 0);
  }
  std::optional<service::SceneRefs::Deletion> deletion = refs.BeginDelete("s", &references);
  ASSERT_TRUE(deletion.has_value());
  std::atomic<bool> referenced{false}, second_deletion{false};
  std::thread creator([&] {
    service::SceneRefs::Ref r = refs.Acquire("s");
    referenced = true;
  });
  std::thread deleter([&] {
    int64_t n = 0;
    (void)refs.BeginDelete("s", &n);
    second_deletion = true;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  EXPECT_FALSE(referenced.load());
  EXPECT_FALSE(second_deletion.load());
  deletion.reset();
  creator.join();
  deleter.join();
  EXPECT_TRUE(referenced.load());
  EXPECT_TRUE(second_deletion.load());
  EXPECT_TRUE(refs.BeginDelete("s", &references).has_value());
}

// Issue 12's test: while a 200 MiB upload is being validated, GetJob, ListScenes and the health
// check answer within 100 ms, and so does a CreateJob on another scene (which once waited for a
// lock that the validation held).
TEST(ServiceConcurrencyTest, CallsAnswerWithin100msWhileA200MiBUploadIsValidated) {
  TempDir data, files;
  service::ServerOptions options = TestServerOptions(data.path());
  options.service.max_upload_bytes = int64_t{256} << 20;
  std::unique_ptr<service::Server> server = StartServer(options);
  ASSERT_TRUE(server);
  std::unique_ptr<Client> c = PatientClient(*server);

  // A job that has ended, for GetJob; a scene without an emitter, which CreateJob loads and
  // then refuses (so no solve competes for the cores during the measurement).
  absl::StatusOr<v1::SceneInfo> furnace = c->UploadSceneFile(SourcePath("scenes/furnace.json"));
  ASSERT_TRUE(furnace.ok()) << furnace.status();
  absl::StatusOr<v1::Job> job = c->CreateJob(ShortSolve(furnace->name()));
  ASSERT_TRUE(job.ok()) << job.status();
  absl::StatusOr<client::Snapshot> last = c->Watch(job->name(), 0, true, nullptr);
  ASSERT_TRUE(last.ok()) << last.status();
  WriteMaterials(files);
  absl::StatusOr<v1::SceneInfo> dark = c->UploadSceneFile(files.Write("dark.obj", kFloorObj));
  ASSERT_TRUE(dark.ok()) << dark.status();
  ASSERT_FALSE(dark->has_emitter());
  v1::CreateJobRequest refused = ShortSolve(dark->name());

  const int64_t kBytes = int64_t{200} << 20;
  const std::string big = WriteLargeObj(files.File("big.obj"), kFloorObj, kBytes);
  std::atomic<bool> upload_done{false};
  absl::StatusOr<v1::SceneInfo> uploaded;
  std::thread uploader([&] {
    std::unique_ptr<Client> u = PatientClient(*server);
    uploaded = u->UploadSceneFile(big);
    upload_done = true;
  });
  service::Metrics& metrics = server->metrics();
  // The window: every byte has arrived and checked out, the scene is being parsed and validated.
  const bool validating =
      WaitFor([&] { return metrics.uploads_validating.load() > 0 || upload_done.load(); }, 600);
  const bool done_early = upload_done.load();

  std::map<std::string, double> slowest;
  std::map<std::string, std::string> errors;
  auto time = [&](const std::string& name, const std::function<absl::Status()>& call) {
    const auto start = std::chrono::steady_clock::now();
    absl::Status st = call();
    const double ms = MillisecondsSince(start);
    slowest[name] = std::max(slowest[name], ms);
    if (!st.ok()) errors[name] = st.ToString();
  };
  if (validating && !done_early) {
    for (int round = 0; round < 8; ++round) {
      time("GetJob", [&] { return c->GetJob(job->name()).status(); });
      time("ListScenes", [&] { return c->ListScenes(v1::ListScenesRequest()).status(); });
      time("health (server)", [&] { return c->CheckHealth("").status(); });
      time("health (service)", [&] { return c->CheckHealth(service::kServiceName).status(); });
      time("CreateJob (refused after loading its scene)", [&] {
        absl::Status st = c->CreateJob(refused).status();
        return st.code() == absl::StatusCode::kFailedPrecondition ? absl::OkStatus() : st;
      });
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  // Every measurement above was made inside the window, so none passes without the upload.
  const bool still_validating = metrics.uploads_validating.load() > 0 && !upload_done.load();
  uploader.join();

  ASSERT_TRUE(validating) << "the validation was never seen";
  ASSERT_FALSE(done_early) << "the upload ended before its validation was seen";
  EXPECT_TRUE(still_validating) << "the validation ended during the measurement";
  ASSERT_TRUE(uploaded.ok()) << uploaded.status();
  EXPECT_EQ(uploaded->total_size(),
            static_cast<int64_t>(std::filesystem::file_size(big) +
                                 std::filesystem::file_size(files.File("materials.mtl"))));
  EXPECT_EQ(uploaded->faces(), 1);
  EXPECT_EQ(metrics.uploads_validating.load(), 0);
  ASSERT_EQ(slowest.size(), 5u);
  for (const auto& [name, ms] : slowest) {
    EXPECT_TRUE(errors.count(name) == 0) << name << ": " << errors[name];
    EXPECT_LT(ms, 100) << name << " took " << ms << " ms while the upload was validated";
  }
}

// A DeleteScene that comes while a CreateJob on the scene is loading it (no lock is held over
// the load) is refused, and so is every one until the job has ended; the job runs as if no delete
// had been tried, and then the delete succeeds.
TEST(ServiceConcurrencyTest, DeleteSceneWaitsOutACreateJobLoadingIt) {
  TempDir data, files;
  std::unique_ptr<service::Server> server = StartServer(TestServerOptions(data.path()));
  ASSERT_TRUE(server);
  std::unique_ptr<Client> c = PatientClient(*server);
  WriteMaterials(files);
  absl::StatusOr<v1::SceneInfo> scene =
      c->UploadSceneFile(WriteLargeObj(files.File("lit.obj"), kLitObj, int64_t{48} << 20));
  ASSERT_TRUE(scene.ok()) << scene.status();
  ASSERT_TRUE(scene->has_emitter());

  std::atomic<bool> created{false};
  absl::StatusOr<v1::Job> job;
  std::thread creator([&] {
    std::unique_ptr<Client> c2 = PatientClient(*server);
    job = c2->CreateJob(ShortSolve(scene->name()));
    created = true;
  });
  service::Metrics& metrics = server->metrics();
  const bool checking =
      WaitFor([&] { return metrics.creates_in_progress.load() > 0 || created.load(); }, 60);
  const bool created_early = created.load();
  int refused_in_creation = 0, refused_busy = 0;
  std::vector<std::string> unexpected;
  // Tries to delete the scene; returns whether it was deleted.
  auto try_delete = [&] {
    absl::Status st = c->DeleteScene(scene->name());
    if (st.ok()) return true;
    if (st.code() == absl::StatusCode::kFailedPrecondition &&
        st.message().find("being created") != absl::string_view::npos) {
      ++refused_in_creation;
    } else if (st.code() == absl::StatusCode::kFailedPrecondition &&
               st.message().find("queued or running") != absl::string_view::npos) {
      ++refused_busy;
    } else {
      unexpected.push_back(st.ToString());
    }
    return false;
  };
  if (checking && !created_early) {
    while (!created.load()) {
      if (try_delete()) unexpected.push_back("deleted while a CreateJob was using it");
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  }
  creator.join();
  ASSERT_TRUE(checking);
  ASSERT_FALSE(created_early) << "CreateJob ended before it was seen checking";
  ASSERT_TRUE(job.ok()) << job.status();
  EXPECT_GT(refused_in_creation, 0);
  EXPECT_TRUE(unexpected.empty()) << unexpected.front();

  // Until the job ends, the scene stays (the job is queued or running); the delete that succeeds
  // comes after the end, and the job had its scene to the last.
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  bool deleted = false;
  while (!deleted && std::chrono::steady_clock::now() < end) {
    deleted = try_delete();
    if (!deleted) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      continue;
    }
    absl::StatusOr<v1::Job> now = c->GetJob(job->name());
    ASSERT_TRUE(now.ok()) << now.status();
    EXPECT_NE(now->state(), v1::JOB_STATE_QUEUED);
    EXPECT_NE(now->state(), v1::JOB_STATE_RUNNING);
  }
  EXPECT_TRUE(deleted);
  EXPECT_TRUE(unexpected.empty()) << unexpected.front();
  absl::StatusOr<v1::Job> ended = c->GetJob(job->name());
  ASSERT_TRUE(ended.ok()) << ended.status();
  EXPECT_EQ(ended->state(), v1::JOB_STATE_SUCCEEDED) << ended->error().message();
  EXPECT_EQ(c->GetScene(scene->name()).status().code(), absl::StatusCode::kNotFound);
}

// Item 7: CreateJob is idempotent by request_id, and a retry gets the same answer on every path:
// while the job is queued or running (the live copy) and after it has ended (the stored row),
// alone or with concurrent retries, and that answer is what GetJob says.
TEST(ServiceConcurrencyTest, RetriedCreateJobAnswersAsGetJobQueuedRunningAndEnded) {
  TempDir data;
  std::unique_ptr<service::Server> server = StartServer(TestServerOptions(data.path()));
  ASSERT_TRUE(server);
  std::unique_ptr<Client> c = ConnectTo(*server);
  absl::StatusOr<v1::SceneInfo> scene = c->UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
  ASSERT_TRUE(scene.ok()) << scene.status();

  // The only worker is busy, so the job stays queued.
  absl::StatusOr<v1::Job> blocker = c->CreateJob(LongSolve(scene->name()));
  ASSERT_TRUE(blocker.ok()) << blocker.status();
  ASSERT_TRUE(WaitFor([&] { return IsRunningWithSnapshot(*c, blocker->name()); }, 60));
  v1::CreateJobRequest request = LongSolve(scene->name());
  request.set_request_id("concurrency-test-retry");

  // Queued: the first answer, retries (one after another and concurrent) and GetJob agree.
  absl::StatusOr<v1::Job> first = c->CreateJob(request);
  ASSERT_TRUE(first.ok()) << first.status();
  ASSERT_EQ(first->state(), v1::JOB_STATE_QUEUED);
  absl::StatusOr<v1::Job> retry = c->CreateJob(request);
  ASSERT_TRUE(retry.ok()) << retry.status();
  absl::StatusOr<v1::Job> got = c->GetJob(first->name());
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_TRUE(SameMessage(*first, *retry));
  EXPECT_TRUE(SameMessage(*retry, *got));
  {
    std::vector<absl::StatusOr<v1::Job>> answers(4);
    std::vector<std::thread> threads;
    for (auto& answer : answers) {
      threads.emplace_back([&] { answer = ConnectTo(*server)->CreateJob(request); });
    }
    for (std::thread& t : threads) t.join();
    for (const auto& answer : answers) {
      ASSERT_TRUE(answer.ok()) << answer.status();
      EXPECT_TRUE(SameMessage(*answer, *got));
    }
  }

  // Running: a retry is the live job, as GetJob before and after it shows it; only what the
  // solve changes all the time (its progress and its latest snapshot number) may differ.
  ASSERT_TRUE(c->CancelJob(blocker->name()).ok());
  ASSERT_TRUE(WaitFor([&] { return IsRunningWithSnapshot(*c, first->name()); }, 60));
  absl::StatusOr<v1::Job> before = c->GetJob(first->name());
  absl::StatusOr<v1::Job> running = c->CreateJob(request);
  absl::StatusOr<v1::Job> after = c->GetJob(first->name());
  ASSERT_TRUE(before.ok() && running.ok() && after.ok());
  EXPECT_EQ(running->state(), v1::JOB_STATE_RUNNING);
  MessageDifferencer but_progress;
  but_progress.IgnoreField(v1::Job::descriptor()->FindFieldByName("progress"));
  but_progress.IgnoreField(v1::Job::descriptor()->FindFieldByName("last_sequence"));
  EXPECT_TRUE(SameMessage(*before, *running, &but_progress));
  EXPECT_TRUE(SameMessage(*running, *after, &but_progress));
  EXPECT_LE(before->last_sequence(), running->last_sequence());
  EXPECT_LE(running->last_sequence(), after->last_sequence());
  EXPECT_LE(before->progress().rays(), running->progress().rays());
  EXPECT_LE(running->progress().rays(), after->progress().rays());

  // Ended: a retry is the stored row, exactly as GetJob and ListJobs give it, also after a
  // restart.
  ASSERT_TRUE(c->CancelJob(first->name()).ok());
  absl::StatusOr<client::Snapshot> last = c->Watch(first->name(), 0, true, nullptr);
  ASSERT_TRUE(last.ok()) << last.status();
  absl::StatusOr<v1::Job> ended = c->CreateJob(request);
  ASSERT_TRUE(ended.ok()) << ended.status();
  EXPECT_EQ(ended->state(), v1::JOB_STATE_CANCELLED);
  got = c->GetJob(first->name());
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_TRUE(SameMessage(*ended, *got));
  EXPECT_EQ(ended->last_sequence(), last->sequence);
  v1::ListJobsRequest list;
  list.add_states(v1::JOB_STATE_CANCELLED);
  absl::StatusOr<v1::ListJobsResponse> listed = c->ListJobs(list);
  ASSERT_TRUE(listed.ok()) << listed.status();
  bool found = false;
  for (const v1::Job& j : listed->jobs()) {
    if (j.name() != first->name()) continue;
    found = true;
    EXPECT_TRUE(SameMessage(j, *ended));
  }
  EXPECT_TRUE(found);

  c.reset();
  server->Shutdown();
  server.reset();
  server = StartServer(TestServerOptions(data.path()));
  ASSERT_TRUE(server);
  c = ConnectTo(*server);
  absl::StatusOr<v1::Job> restarted = c->CreateJob(request);
  ASSERT_TRUE(restarted.ok()) << restarted.status();
  EXPECT_TRUE(SameMessage(*restarted, *ended));
}

}  // namespace
}  // namespace radiosity
