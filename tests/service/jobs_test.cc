// Job life cycle against a real server on 127.0.0.1: cancel (queued and running), the bounded
// queue, and a restart with queued, running and finished jobs (nothing is lost), in SQLite and in
// PostgreSQL (tests/testing/postgres.h).
#include <gtest/gtest.h>

#include <thread>

#include "client/client.h"
#include "proto/api/sha256.h"
#include "proto/api/spec.h"
#include "server/server.h"
#include "server/store.h"
#include "tests/service/fixture.h"
#include "tests/testing/postgres.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using client::Client;
using service::testing::ShortSolve;
using service::testing::WaitFor;

// A solve that runs until cancelled (or 60 s).
v1::CreateJobRequest LongSolve(const std::string& scene) {
  v1::CreateJobRequest r = service::testing::LongSolve(scene, 2000, 16);
  r.mutable_solve()->set_snapshot_interval(0.02);
  return r;
}

// Solving, with a snapshot taken (meshing's progress comes in snapshots too).
bool IsRunningWithSnapshot(Client& c, const std::string& job, int64_t after_sequence = 0) {
  absl::StatusOr<v1::Job> j = c.GetJob(job);
  return j.ok() && j->state() == v1::JOB_STATE_RUNNING &&
         j->progress().phase() == v1::JOB_PHASE_SOLVING && j->last_sequence() > after_sequence;
}

class ServiceJobsTest : public service::testing::ServiceTest {
 protected:
  void RestartKeepsFinishedQueuedAndRunningJobs(const service::ServerOptions& options);
};

TEST_F(ServiceJobsTest, CancelQueuedAndRunningJobs) {
  Client* c = client_.get();
  absl::StatusOr<v1::SceneInfo> scene =
      c->UploadSceneFile(testing::SourcePath("scenes/cornell_box.obj"));
  ASSERT_TRUE(scene.ok()) << scene.status();

  absl::StatusOr<v1::Job> running = c->CreateJob(LongSolve(scene->name()));
  absl::StatusOr<v1::Job> queued = c->CreateJob(ShortSolve(scene->name(), 1));
  ASSERT_TRUE(running.ok() && queued.ok());
  ASSERT_TRUE(WaitFor([&] { return IsRunningWithSnapshot(*c, running->name()); }, 30));

  // Queued: cancelled at once, never ran, has no results.
  absl::StatusOr<v1::Job> q = c->CancelJob(queued->name());
  ASSERT_TRUE(q.ok()) << q.status();
  EXPECT_EQ(q->state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(q->attempts(), 0);
  EXPECT_EQ(c->CancelJob(queued->name()).status().code(), absl::StatusCode::kFailedPrecondition);
  testing::TempDir out;
  EXPECT_EQ(c->DownloadResults(queued->name(), out.path()).status().code(),
            absl::StatusCode::kFailedPrecondition);
  // Running: stops at the solver's next check and keeps the results so far.
  EXPECT_EQ(c->DownloadResults(running->name(), out.path()).status().code(),
            absl::StatusCode::kFailedPrecondition);
  absl::StatusOr<v1::Job> r = c->CancelJob(running->name());
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_TRUE(r->cancel_requested());
  absl::StatusOr<client::Snapshot> last = c->Watch(running->name(), 0, true, nullptr);
  ASSERT_TRUE(last.ok()) << last.status();
  EXPECT_EQ(last->state, v1::JOB_STATE_CANCELLED);
  EXPECT_GT(last->progress.unshot_fraction(), 1e-15);
  EXPECT_LT(last->progress.elapsed_seconds(), 50);
  ASSERT_TRUE(c->DownloadResults(running->name(), out.path()).ok());
  EXPECT_NE(testing::ReadFile(out.File("summary.json")).find("\"stop_reason\": \"cancelled\""),
            std::string::npos);
  EXPECT_EQ(
      testing::ReadFile(out.File("elements.csv")).rfind("surface,element,cx,cy,cz,area,r,g,b\n", 0),
      0u);
}

TEST_F(ServiceJobsTest, FullQueueIsResourceExhausted) {
  service::ServerOptions options = service::testing::TestServerOptions(data_.path());
  options.service.max_queued = 1;
  ASSERT_NO_FATAL_FAILURE(Restart(options));
  Client* c = client_.get();
  absl::StatusOr<v1::SceneInfo> scene =
      c->UploadSceneFile(testing::SourcePath("scenes/cornell_box.obj"));
  ASSERT_TRUE(scene.ok()) << scene.status();
  absl::StatusOr<v1::Job> a = c->CreateJob(LongSolve(scene->name()));
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(WaitFor([&] { return IsRunningWithSnapshot(*c, a->name()); }, 30));
  absl::StatusOr<v1::Job> b = c->CreateJob(ShortSolve(scene->name(), 1));  // Queued.
  ASSERT_TRUE(b.ok()) << b.status();
  absl::StatusOr<v1::Job> full = c->CreateJob(ShortSolve(scene->name(), 2));
  EXPECT_EQ(full.status().code(), absl::StatusCode::kResourceExhausted);
  EXPECT_EQ(server_->metrics().jobs_rejected.load(), 1);
  EXPECT_EQ(server_->jobs().QueueDepth(), 1);
  // A place frees up once the running job ends and the queued one starts.
  ASSERT_TRUE(c->CancelJob(a->name()).ok());
  absl::StatusOr<client::Snapshot> done = c->Watch(b->name(), 0, true, nullptr);
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->state, v1::JOB_STATE_SUCCEEDED);
  EXPECT_TRUE(c->CreateJob(ShortSolve(scene->name(), 2)).ok());
}

// A finished job keeps its results, a running one runs again, a queued one waits, across a
// graceful restart of a server started with `options` (running as the test starts).
void ServiceJobsTest::RestartKeepsFinishedQueuedAndRunningJobs(
    const service::ServerOptions& options) {
  std::string finished, running, queued, finished_sha;
  int64_t running_sequence = 0;
  {
    // One server per data directory.
    EXPECT_EQ(service::Server::Start(options).status().code(),
              absl::StatusCode::kFailedPrecondition);
    if (!options.service.store.empty()) {
      // And one per store, whatever its data directory.
      testing::TempDir other;
      service::ServerOptions second = options;
      second.service.data_dir = other.path();
      EXPECT_TRUE(testing::Refused(service::Server::Start(second).status(),
                                   absl::StatusCode::kFailedPrecondition,
                                   {"another radiosity-server"}));
    }
    Client* c = client_.get();
    absl::StatusOr<v1::SceneInfo> box =
        c->UploadSceneFile(testing::SourcePath("scenes/cornell_box.obj"));
    ASSERT_TRUE(box.ok()) << box.status();
    absl::StatusOr<v1::Job> f = c->CreateJob(ShortSolve(box->name(), 5));
    ASSERT_TRUE(f.ok());
    finished = f->name();
    absl::StatusOr<client::Snapshot> done = c->Watch(finished, 0, true, nullptr);
    ASSERT_TRUE(done.ok() && done->state == v1::JOB_STATE_SUCCEEDED);
    absl::StatusOr<v1::Job> fj = c->GetJob(finished);
    ASSERT_TRUE(fj.ok());
    for (const auto& file : fj->results()) {
      if (file.name() == "elements.csv") finished_sha = file.sha256();
    }
    absl::StatusOr<v1::Job> r = c->CreateJob(LongSolve(box->name()));
    absl::StatusOr<v1::Job> q = c->CreateJob(ShortSolve(box->name(), 9));
    ASSERT_TRUE(r.ok() && q.ok());
    running = r->name();
    queued = q->name();
    ASSERT_TRUE(WaitFor([&] { return IsRunningWithSnapshot(*c, running); }, 30));
    absl::StatusOr<v1::Job> rj = c->GetJob(running);
    ASSERT_TRUE(rj.ok());
    running_sequence = rj->last_sequence();
  }
  Stop();  // Graceful: the running solve goes back to the queue.
  ASSERT_FALSE(finished_sha.empty());

  ASSERT_NO_FATAL_FAILURE(Start(options));
  Client* c = client_.get();
  // The finished job and its results are still there, byte for byte.
  absl::StatusOr<v1::Job> f = c->GetJob(finished);
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_EQ(f->state(), v1::JOB_STATE_SUCCEEDED);
  testing::TempDir out;
  ASSERT_TRUE(c->DownloadResults(finished, out.path(), "elements.csv").ok());
  absl::StatusOr<std::pair<std::string, int64_t>> sum =
      service::Sha256File(out.File("elements.csv"));
  ASSERT_TRUE(sum.ok());
  EXPECT_EQ(sum->first, finished_sha);
  // The interrupted solve runs again, its snapshot numbers still growing; the queued one waits.
  ASSERT_TRUE(WaitFor([&] { return IsRunningWithSnapshot(*c, running, running_sequence); }, 30));
  absl::StatusOr<v1::Job> r = c->GetJob(running);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->attempts(), 2);
  EXPECT_GT(r->last_sequence(), running_sequence);
  absl::StatusOr<v1::Job> q = c->GetJob(queued);
  ASSERT_TRUE(q.ok());
  EXPECT_EQ(q->state(), v1::JOB_STATE_QUEUED);
  EXPECT_EQ(q->solve().seed(), 9u);
  ASSERT_TRUE(c->CancelJob(running).ok());
  absl::StatusOr<client::Snapshot> done = c->Watch(queued, 0, true, nullptr);
  ASSERT_TRUE(done.ok()) << done.status();
  EXPECT_EQ(done->state, v1::JOB_STATE_SUCCEEDED);
}

TEST_F(ServiceJobsTest, RestartKeepsFinishedQueuedAndRunningJobs) {
  RestartKeepsFinishedQueuedAndRunningJobs(service::testing::TestServerOptions(data_.path()));
}

TEST_F(ServiceJobsTest, RestartKeepsFinishedQueuedAndRunningJobsInPostgreSQL) {
  absl::StatusOr<testing::ThrowawayPostgres*> pg = testing::ThrowawayPostgres::Shared();
  if (absl::IsNotFound(pg.status())) GTEST_SKIP() << pg.status().message();
  ASSERT_TRUE(pg.ok()) << pg.status();
  absl::StatusOr<std::string> uri = (*pg)->NewDatabase();
  ASSERT_TRUE(uri.ok()) << uri.status();
  service::ServerOptions options = service::testing::TestServerOptions(data_.path());
  options.service.store = *uri;
  ASSERT_NO_FATAL_FAILURE(Restart(options));
  RestartKeepsFinishedQueuedAndRunningJobs(options);
  // The rows are PostgreSQL's: another instance of the store (no claim) lists the jobs.
  absl::StatusOr<std::unique_ptr<service::Store>> store = service::OpenStore(*uri, "");
  ASSERT_TRUE(store.ok()) << store.status();
  absl::StatusOr<v1::ListJobsResponse> jobs = (*store)->ListJobs("", v1::ListJobsRequest());
  ASSERT_TRUE(jobs.ok()) << jobs.status();
  EXPECT_EQ(jobs->jobs_size(), 3);
}

}  // namespace
}  // namespace radiosity
