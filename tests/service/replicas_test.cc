// Replicas: several radiosity-server processes sharing one PostgreSQL store (a throwaway cluster,
// tests/testing/postgres.h) and one --blob-dir. Jobs are claimed under leases; a replica killed
// mid-solve has its job taken over by another, from its checkpoint, to the result of an
// uninterrupted run; a cancel reaches the replica that runs the job; SIGTERM gives jobs back.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <atomic>
#include <cstdlib>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/strip.h"
#include "client/client.h"
#include "server/server.h"
#include "server/store.h"
#include "solver/util/file_io.h"
#include "tests/service/fixture.h"
#include "tests/service/server_process.h"
#include "tests/testing/postgres.h"
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
using testing::ThrowawayPostgres;

// A progressive solve of `scene` that ends at `max_rays` after many steps (so that it has
// checkpoints to resume from), the same for every run with the same seed.
v1::CreateJobRequest CheckpointedSolve(const std::string& scene, int seed, int64_t max_elements,
                                       int64_t max_rays) {
  v1::CreateJobRequest r;
  r.set_scene(scene);
  r.mutable_solve()->set_solve_method(v1::SOLVE_METHOD_PROGRESSIVE);
  r.mutable_solve()->set_seed(seed);
  r.mutable_solve()->mutable_mesh()->set_max_elements(max_elements);
  r.mutable_solve()->set_tolerance(1e-15);
  r.mutable_solve()->set_rays_per_element(1e6);
  r.mutable_solve()->set_max_rays(max_rays);
  r.mutable_solve()->set_max_seconds(600);
  return r;
}

// Replicas of one store and blob directory, each with its own data directory and log.
class ReplicasTest : public ::testing::Test {
 protected:
  void SetUp() override {
    absl::StatusOr<ThrowawayPostgres*> pg = ThrowawayPostgres::Shared();
    if (absl::IsNotFound(pg.status())) GTEST_SKIP() << pg.status().message();
    ASSERT_TRUE(pg.ok()) << pg.status();
    absl::StatusOr<std::string> uri = (*pg)->NewDatabase();
    ASSERT_TRUE(uri.ok()) << uri.status();
    uri_ = *uri;
  }

  // Starts replica `i` (its data directory and log named by i) and connects a client to it.
  void Start(int i, const std::vector<std::string>& more_args = {}) {
    std::vector<std::string> args = {"--store",         uri_, "--blob-dir", dir_.File("blobs"),
                                     "--lease-seconds", "3",  "--workers",  "1"};
    args.insert(args.end(), more_args.begin(), more_args.end());
    if (static_cast<int>(servers_.size()) <= i) {
      servers_.resize(i + 1);
      clients_.resize(i + 1);
    }
    servers_[i] =
        std::make_unique<ServerProcess>(dir_.File(absl::StrCat("replica", i)), Log(i), -1, args);
    const int port = servers_[i]->WaitForPort();
    ASSERT_GT(port, 0) << ReadFile(Log(i));
    clients_[i] = std::make_unique<Client>(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
  }
  std::string Log(int i) { return dir_.File(absl::StrCat("replica", i, ".log")); }
  // Starts replicas 0 and 1 (checkpoints every 0.3 s), uploads the Cornell box, submits
  // CheckpointedSolve(seed, max_elements, max_rays) and waits until a replica runs it and has
  // written its checkpoint: the request in *r, the job's name in *job, the checkpoint's path in
  // *checkpoint.
  void StartCheckpointedJob(int seed, int64_t max_elements, int64_t max_rays,
                            v1::CreateJobRequest* r, std::string* job, std::string* checkpoint) {
    ASSERT_NO_FATAL_FAILURE(Start(0, {"--checkpoint-seconds", "0.3"}));
    ASSERT_NO_FATAL_FAILURE(Start(1, {"--checkpoint-seconds", "0.3"}));
    absl::StatusOr<v1::SceneInfo> scene =
        clients_[0]->UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
    ASSERT_TRUE(scene.ok()) << scene.status();
    *r = CheckpointedSolve(scene->name(), seed, max_elements, max_rays);
    absl::StatusOr<v1::Job> created = clients_[0]->CreateJob(*r);
    ASSERT_TRUE(created.ok()) << created.status();
    *job = created->name();
    *checkpoint =
        absl::StrCat(dir_.File("blobs"), "/jobs/", absl::StripPrefix(*job, "jobs/"), "/checkpoint");
    ASSERT_TRUE(WaitFor(
        [&] {
          const v1::Job j = Get(0, *job);
          return j.state() == v1::JOB_STATE_RUNNING && j.progress().rays() > 0 &&
                 FileExists(*checkpoint) && Holder(*job) >= 0;
        },
        60))
        << Logs();
  }
  // SIGTERM to replica i, after closing this test's connection to it (a connected client, even
  // idle, holds a gRPC server's shutdown until its deadline); its exit status.
  int Stop(int i) {
    clients_[i].reset();
    return servers_[i]->Terminate();
  }
  // The running replica whose log says it claimed `job` last (by the lines' times; -1: none).
  int Holder(const std::string& job) {
    const std::string claimed =
        absl::StrCat("\"event\":\"job_claimed\",\"job\":\"", absl::StripPrefix(job, "jobs/"), "\"");
    int holder = -1;
    std::string latest;
    for (int i = 0; i < static_cast<int>(servers_.size()); ++i) {
      if (!servers_[i] || servers_[i]->exited()) continue;
      const std::string log = ReadFile(Log(i));
      const size_t at = log.rfind(claimed);
      if (at == std::string::npos) continue;
      // The line's "time" (ISO 8601 UTC, milliseconds): ordered as strings.
      const size_t line = log.rfind('\n', at) == std::string::npos ? 0 : log.rfind('\n', at) + 1;
      const std::string time = log.substr(line, at - line);
      if (holder < 0 || time >= latest) {
        holder = i;
        latest = time;
      }
    }
    return holder;
  }
  // The job as `replica` reads it from the store (or its live copy).
  v1::Job Get(int replica, const std::string& job) {
    absl::StatusOr<v1::Job> j = clients_[replica]->GetJob(job);
    return j.ok() ? *j : v1::Job();
  }
  std::string Logs() {
    std::string all;
    for (int i = 0; i < static_cast<int>(servers_.size()); ++i) {
      absl::StrAppend(&all, "--- replica ", i, "\n", ReadFile(Log(i)));
    }
    return all;
  }
  int64_t Leased() {
    absl::StatusOr<std::unique_ptr<service::Store>> store = service::OpenStore(uri_, "");
    if (!store.ok()) return -1;
    absl::StatusOr<int64_t> n = (*store)->CountLeased();
    return n.ok() ? *n : -1;
  }

  TempDir dir_;
  std::string uri_;
  std::vector<std::unique_ptr<ServerProcess>> servers_;
  std::vector<std::unique_ptr<Client>> clients_;
};

v1::CreateJobRequest LongSolve(const std::string& scene) {
  v1::CreateJobRequest r;
  r.set_scene(scene);
  r.mutable_solve()->mutable_mesh()->set_max_elements(1000);
  r.mutable_solve()->set_tolerance(1e-15);
  r.mutable_solve()->set_max_seconds(120);
  r.mutable_solve()->set_rays_per_element(1e6);
  return r;
}

bool Ended(const v1::Job& job) {
  return job.state() == v1::JOB_STATE_SUCCEEDED || job.state() == v1::JOB_STATE_FAILED ||
         job.state() == v1::JOB_STATE_CANCELLED;
}

TEST(ReplicasFlagsTest, ABlobDirectoryNeedsAStoreThatReplicasCanShare) {
  TempDir dir;
  service::ServerOptions options;
  options.service.data_dir = dir.File("data");
  options.service.blob_dir = dir.File("blobs");
  absl::StatusOr<std::unique_ptr<service::Server>> server = service::Server::Start(options);
  ASSERT_FALSE(server.ok());
  EXPECT_EQ(server.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_TRUE(absl::StrContains(server.status().message(), "--blob-dir")) << server.status();
  EXPECT_TRUE(absl::StrContains(server.status().message(), "PostgreSQL")) << server.status();
}

// The job is claimed by one replica, which is killed (kill -9) once the job has a checkpoint;
// the other claims it when the lease runs out, resumes from the checkpoint and ends with exactly
// the elements of an uninterrupted run; nothing stays leased.
TEST_F(ReplicasTest, AKilledReplicasJobIsTakenOverFromItsCheckpointToTheUninterruptedResult) {
  v1::CreateJobRequest r;
  std::string job, checkpoint;
  ASSERT_NO_FATAL_FAILURE(StartCheckpointedJob(7, 1000, 30'000'000, &r, &job, &checkpoint));
  const int holder = Holder(job);
  const int other = 1 - holder;
  servers_[holder]->Kill();

  ASSERT_TRUE(WaitFor([&] { return Ended(Get(other, job)); }, 120)) << Logs();
  const v1::Job resumed = Get(other, job);
  ASSERT_EQ(resumed.state(), v1::JOB_STATE_SUCCEEDED) << resumed.error().message() << Logs();
  EXPECT_EQ(resumed.attempts(), 2);
  EXPECT_EQ(resumed.lost_attempts(), 1);
  EXPECT_EQ(resumed.progress().rays(), 30'000'000);
  EXPECT_EQ(Holder(job), other);
  EXPECT_FALSE(FileExists(checkpoint));
  const std::string log = ReadFile(Log(other));
  const size_t at = log.find("\"event\":\"job_resumed\"");
  ASSERT_NE(at, std::string::npos) << log;
  EXPECT_EQ(log.substr(at, log.find('\n', at) - at).find("\"step\":0,"), std::string::npos);
  EXPECT_EQ(Leased(), 0);

  // The same job, never interrupted, on the surviving replica.
  r.set_request_id("uninterrupted");
  absl::StatusOr<v1::Job> plain = clients_[other]->CreateJob(r);
  ASSERT_TRUE(plain.ok()) << plain.status();
  ASSERT_TRUE(WaitFor([&] { return Ended(Get(other, plain->name())); }, 120)) << Logs();
  ASSERT_TRUE(clients_[other]->DownloadResults(job, dir_.File("resumed"), "elements.csv").ok());
  ASSERT_TRUE(
      clients_[other]->DownloadResults(plain->name(), dir_.File("plain"), "elements.csv").ok());
  const std::string want = ReadFile(dir_.File("plain") + "/elements.csv");
  EXPECT_GT(want.size(), 1000u);
  EXPECT_TRUE(ReadFile(dir_.File("resumed") + "/elements.csv") == want)
      << "the resumed job's elements.csv differs from the uninterrupted job's";
  EXPECT_EQ(Stop(other), 0);
}

// Two replicas of one worker each run a job each; a third waits in the store. A cancel through
// either replica ends the waiting job at once, and reaches the replica that runs each of the
// others; SIGTERM of a replica gives its job back, and the other takes it.
TEST_F(ReplicasTest, CancelsReachTheHolderAndSigtermGivesTheJobBack) {
  ASSERT_NO_FATAL_FAILURE(Start(0));
  ASSERT_NO_FATAL_FAILURE(Start(1));
  absl::StatusOr<v1::SceneInfo> scene =
      clients_[0]->UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
  ASSERT_TRUE(scene.ok()) << scene.status();
  std::vector<std::string> jobs;
  for (int i = 0; i < 2; ++i) {
    absl::StatusOr<v1::Job> created = clients_[i]->CreateJob(LongSolve(scene->name()));
    ASSERT_TRUE(created.ok()) << created.status();
    jobs.push_back(created->name());
  }
  // Both run, one on each replica (a replica's one worker runs one job at a time).
  ASSERT_TRUE(WaitFor(
      [&] {
        return Get(0, jobs[0]).state() == v1::JOB_STATE_RUNNING &&
               Get(0, jobs[1]).state() == v1::JOB_STATE_RUNNING;
      },
      60))
      << Logs();
  ASSERT_NE(Holder(jobs[0]), Holder(jobs[1])) << Logs();

  // The third waits; a cancel on either replica ends it at once.
  absl::StatusOr<v1::Job> waiting = clients_[1]->CreateJob(LongSolve(scene->name()));
  ASSERT_TRUE(waiting.ok()) << waiting.status();
  EXPECT_EQ(waiting->state(), v1::JOB_STATE_QUEUED);
  absl::StatusOr<v1::Job> cancelled = clients_[0]->CancelJob(waiting->name());
  ASSERT_TRUE(cancelled.ok()) << cancelled.status();
  EXPECT_EQ(cancelled->state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(Get(1, waiting->name()).state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(Get(1, waiting->name()).results_size(), 0);

  // The first job, cancelled through the replica that does not run it.
  const int runs_first = Holder(jobs[0]);
  absl::StatusOr<v1::Job> asked = clients_[1 - runs_first]->CancelJob(jobs[0]);
  ASSERT_TRUE(asked.ok()) << asked.status();
  EXPECT_TRUE(asked->cancel_requested());
  ASSERT_TRUE(WaitFor([&] { return Ended(Get(1 - runs_first, jobs[0])); }, 30)) << Logs();
  EXPECT_EQ(Get(1 - runs_first, jobs[0]).state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(Get(1 - runs_first, jobs[0]).stop_reason(), "cancelled");

  // SIGTERM of the second job's replica: the job goes back to the store's queue and the other
  // replica, now idle, takes it (a new attempt, not a lost one).
  const int runs_second = Holder(jobs[1]);
  EXPECT_EQ(Stop(runs_second), 0);
  const int survivor = 1 - runs_second;
  ASSERT_TRUE(WaitFor(
      [&] {
        const v1::Job j = Get(survivor, jobs[1]);
        return j.state() == v1::JOB_STATE_RUNNING && j.attempts() == 2 &&
               Holder(jobs[1]) == survivor;
      },
      30))
      << Logs();
  EXPECT_EQ(Get(survivor, jobs[1]).lost_attempts(), 0);
  ASSERT_TRUE(clients_[survivor]->CancelJob(jobs[1]).ok());
  ASSERT_TRUE(WaitFor([&] { return Ended(Get(survivor, jobs[1])); }, 30)) << Logs();
  EXPECT_EQ(Get(survivor, jobs[1]).state(), v1::JOB_STATE_CANCELLED);
  EXPECT_EQ(Leased(), 0);
  EXPECT_EQ(Stop(survivor), 0);
}

// WatchJob through a replica that does not run the job follows it: progress snapshots numbered as
// the holder numbers them, with live radiosity and its mesh once the holder shares them, then the
// final snapshot with the radiosity (from the shared results); a watch resumed on the holder after
// one of those numbers goes on from there.
TEST_F(ReplicasTest, AJobIsWatchedThroughAReplicaThatDoesNotRunIt) {
  ASSERT_NO_FATAL_FAILURE(Start(0));
  ASSERT_NO_FATAL_FAILURE(Start(1));
  absl::StatusOr<v1::SceneInfo> scene =
      clients_[0]->UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
  ASSERT_TRUE(scene.ok()) << scene.status();
  const v1::CreateJobRequest r = CheckpointedSolve(scene->name(), 1, 1000, 40'000'000);
  absl::StatusOr<v1::Job> created = clients_[0]->CreateJob(r);
  ASSERT_TRUE(created.ok()) << created.status();
  const std::string job = created->name();
  ASSERT_TRUE(WaitFor([&] { return Holder(job) >= 0; }, 30)) << Logs();
  const int holder = Holder(job);
  const int other = 1 - holder;

  std::vector<client::Snapshot> seen;
  absl::StatusOr<client::Snapshot> end = clients_[other]->Watch(
      job, 0, /*progress_only=*/false,
      [&](const client::Snapshot& s) {
        seen.push_back(s);
        return true;
      },
      nullptr, /*include_mesh=*/true);
  ASSERT_TRUE(end.ok()) << end.status() << Logs();
  EXPECT_EQ(Holder(job), holder) << "the job moved: the test no longer watches from elsewhere";
  ASSERT_TRUE(end->final);
  EXPECT_EQ(end->state, v1::JOB_STATE_SUCCEEDED);
  EXPECT_EQ(end->sequence, Get(other, job).last_sequence());
  EXPECT_EQ(end->radiosity.size(), static_cast<size_t>(end->elements) * 6);
  // Progress on the way, in order, rays growing.
  std::vector<client::Snapshot> running;
  for (const client::Snapshot& s : seen) {
    if (!s.final && s.state == v1::JOB_STATE_RUNNING) running.push_back(s);
  }
  ASSERT_GE(running.size(), 2u) << Logs();
  for (size_t i = 1; i < running.size(); ++i) {
    EXPECT_GT(running[i].sequence, running[i - 1].sequence);
    EXPECT_GE(running[i].progress.rays(), running[i - 1].progress.rays());
  }
  EXPECT_GT(running.back().progress.rays(), running.front().progress.rays());
  // The holder shares its latest snapshot once it sees the interest: live radiosity on the mesh
  // it refers to, announced on this stream.
  int live = 0;
  for (const client::Snapshot& s : running) {
    if (s.radiosity.empty()) continue;
    ++live;
    ASSERT_NE(s.mesh, nullptr);
    EXPECT_EQ(s.radiosity.size(), static_cast<size_t>(s.elements) * 6);
    EXPECT_EQ(s.mesh_version, end->mesh_version);
  }
  EXPECT_GE(live, 1) << Logs();

  // Resumed on the holder (an ended job: its final snapshot) after a number seen elsewhere.
  int64_t first_after = 0;
  absl::StatusOr<client::Snapshot> again = clients_[holder]->Watch(
      job, running.front().sequence, /*progress_only=*/true, [&](const client::Snapshot& s) {
        if (first_after == 0) first_after = s.sequence;
        return true;
      });
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_GT(first_after, running.front().sequence);
  EXPECT_EQ(again->sequence, end->sequence);
  EXPECT_EQ(Stop(0), 0);
  EXPECT_EQ(Stop(1), 0);
}

// A replica that stops answering (SIGSTOP) past its lease, with the store reachable by the
// others: another replica takes the job over from its checkpoint; when the first one wakes up it
// learns by its own clock that it lost the lease, stops, and writes nothing: the job ends once,
// with the uninterrupted result, and its results are the holder's (their checksums verified by
// the download).
TEST_F(ReplicasTest, AReplicaPausedPastItsLeaseStopsAndWritesNothing) {
  v1::CreateJobRequest r;
  std::string job, checkpoint;
  ASSERT_NO_FATAL_FAILURE(StartCheckpointedJob(11, 500, 40'000'000, &r, &job, &checkpoint));
  const int paused = Holder(job);
  const int other = 1 - paused;
  servers_[paused]->Pause();
  // The other replica claims it once the lease (3 s) has run out.
  ASSERT_TRUE(WaitFor([&] { return Holder(job) == other || Ended(Get(other, job)); }, 30))
      << Logs();
  servers_[paused]->Resume();
  ASSERT_TRUE(WaitFor([&] { return Ended(Get(other, job)); }, 120)) << Logs();
  ASSERT_TRUE(WaitFor(
      [&] { return ReadFile(Log(paused)).find("\"event\":\"job_dropped\"") != std::string::npos; },
      30))
      << Logs();
  const v1::Job ended = Get(other, job);
  ASSERT_EQ(ended.state(), v1::JOB_STATE_SUCCEEDED) << ended.error().message() << Logs();
  EXPECT_EQ(ended.lost_attempts(), 1);
  EXPECT_EQ(ended.progress().rays(), 40'000'000);
  const std::string paused_log = ReadFile(Log(paused));
  EXPECT_NE(paused_log.find("\"event\":\"job_lease_lost\""), std::string::npos) << paused_log;
  EXPECT_EQ(paused_log.find("\"event\":\"job_succeeded\""), std::string::npos) << paused_log;
  ASSERT_TRUE(clients_[paused]->DownloadResults(job, dir_.File("taken"), "elements.csv").ok());

  r.set_request_id("uninterrupted");
  absl::StatusOr<v1::Job> plain = clients_[other]->CreateJob(r);
  ASSERT_TRUE(plain.ok()) << plain.status();
  ASSERT_TRUE(WaitFor([&] { return Ended(Get(other, plain->name())); }, 120)) << Logs();
  ASSERT_TRUE(
      clients_[other]->DownloadResults(plain->name(), dir_.File("plain"), "elements.csv").ok());
  EXPECT_TRUE(ReadFile(dir_.File("taken") + "/elements.csv") ==
              ReadFile(dir_.File("plain") + "/elements.csv"));
  EXPECT_EQ(Leased(), 0);
  EXPECT_EQ(Stop(0), 0);
  EXPECT_EQ(Stop(1), 0);
}

// radiosity-server --copy-from DIR with its arguments; the exit status, and its stderr in *out.
int CopyFrom(const std::string& dir, const std::string& uri, const std::string& blobs,
             const std::string& log, std::string* out) {
  const std::string command =
      absl::StrCat(RADIOSITY_SERVER_BIN, " --copy-from '", dir, "' --store '", uri,
                   "' --blob-dir '", blobs, "' 2> '", log, "'");
  const int status = std::system(command.c_str());
  *out = ReadFile(log);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// One server's data directory (SQLite) moved to replicas: a finished job's results, a job that
// was running when the server was killed, and its scene; the copy refuses a directory in use,
// skips what an earlier run copied, and the replica serves the results and resumes the job from
// its checkpoint to the uninterrupted result.
TEST_F(ReplicasTest, AServersDataDirectoryIsCopiedIntoTheReplicasStore) {
  const std::string single = dir_.File("single");
  v1::CreateJobRequest r = CheckpointedSolve("", 3, 500, 30'000'000);
  std::string done, killed;
  {
    ServerProcess server(single, dir_.File("single.log"), -1, {"--checkpoint-seconds", "0.3"});
    const int port = server.WaitForPort();
    ASSERT_GT(port, 0) << ReadFile(dir_.File("single.log"));
    Client c(client::MakeChannel(absl::StrCat("127.0.0.1:", port)));
    absl::StatusOr<v1::SceneInfo> scene = c.UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
    ASSERT_TRUE(scene.ok()) << scene.status();
    r.set_scene(scene->name());
    absl::StatusOr<v1::Job> first = c.CreateJob(r);
    ASSERT_TRUE(first.ok()) << first.status();
    done = first->name();
    ASSERT_TRUE(c.Watch(done, 0, true, nullptr).ok());
    ASSERT_TRUE(c.DownloadResults(done, dir_.File("before"), "elements.csv").ok());
    // The copy refuses a directory a server is using.
    std::string out;
    EXPECT_NE(CopyFrom(single, uri_, dir_.File("blobs"), dir_.File("copy.log"), &out), 0);
    EXPECT_TRUE(absl::StrContains(out, "in use by another radiosity server")) << out;
    r.set_request_id("second");
    absl::StatusOr<v1::Job> second = c.CreateJob(r);
    ASSERT_TRUE(second.ok()) << second.status();
    killed = second->name();
    const std::string checkpoint =
        single + "/jobs/" + std::string(absl::StripPrefix(killed, "jobs/")) + "/checkpoint";
    ASSERT_TRUE(WaitFor(
        [&] {
          absl::StatusOr<v1::Job> j = c.GetJob(killed);
          return j.ok() && j->state() == v1::JOB_STATE_RUNNING && FileExists(checkpoint);
        },
        60));
    server.Kill();
  }

  std::string out;
  ASSERT_EQ(CopyFrom(single, uri_, dir_.File("blobs"), dir_.File("copy.log"), &out), 0) << out;
  EXPECT_TRUE(absl::StrContains(out, "1 scenes and 2 jobs copied")) << out;
  // Again: nothing more to copy.
  ASSERT_EQ(CopyFrom(single, uri_, dir_.File("blobs"), dir_.File("copy.log"), &out), 0) << out;
  EXPECT_TRUE(absl::StrContains(out, "0 scenes and 0 jobs copied")) << out;
  EXPECT_TRUE(absl::StrContains(out, "1 scenes and 2 jobs were there already")) << out;

  ASSERT_NO_FATAL_FAILURE(Start(0));
  EXPECT_EQ(Get(0, done).state(), v1::JOB_STATE_SUCCEEDED);
  ASSERT_TRUE(clients_[0]->DownloadResults(done, dir_.File("after"), "elements.csv").ok());
  EXPECT_TRUE(ReadFile(dir_.File("after") + "/elements.csv") ==
              ReadFile(dir_.File("before") + "/elements.csv"));
  ASSERT_TRUE(WaitFor([&] { return Ended(Get(0, killed)); }, 120)) << Logs();
  const v1::Job resumed = Get(0, killed);
  ASSERT_EQ(resumed.state(), v1::JOB_STATE_SUCCEEDED) << resumed.error().message();
  EXPECT_EQ(resumed.lost_attempts(), 1);
  EXPECT_EQ(resumed.progress().rays(), 30'000'000);
  EXPECT_NE(ReadFile(Log(0)).find("\"event\":\"job_resumed\""), std::string::npos);
  // Same request as the first job, never interrupted: the same elements.
  ASSERT_TRUE(clients_[0]->DownloadResults(killed, dir_.File("resumed"), "elements.csv").ok());
  EXPECT_TRUE(ReadFile(dir_.File("resumed") + "/elements.csv") ==
              ReadFile(dir_.File("before") + "/elements.csv"));
  EXPECT_EQ(Stop(0), 0);
}

// A scene file changed on the shared blob directory (another machine's write gone wrong) is
// refused by its checksum, naming the scene and the file, rather than solved.
TEST_F(ReplicasTest, AScenesFilesAreCheckedAgainstTheirUploadsChecksums) {
  ASSERT_NO_FATAL_FAILURE(Start(0));
  absl::StatusOr<v1::SceneInfo> scene =
      clients_[0]->UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
  ASSERT_TRUE(scene.ok()) << scene.status();
  const std::string file = dir_.File("blobs") + "/" + scene->name() + "/cornell_box.obj";
  ASSERT_TRUE(FileExists(file));
  std::string text = ReadFile(file);
  text[text.size() / 2] ^= 1;
  ASSERT_TRUE(WriteWholeFile(file, text).ok());
  absl::StatusOr<v1::Job> created = clients_[0]->CreateJob(LongSolve(scene->name()));
  ASSERT_FALSE(created.ok());
  EXPECT_EQ(created.status().code(), absl::StatusCode::kDataLoss) << created.status();
  EXPECT_TRUE(absl::StrContains(created.status().message(), scene->name())) << created.status();
  EXPECT_TRUE(
      absl::StrContains(created.status().message(), "'cornell_box.obj' is not the file uploaded"))
      << created.status();
  EXPECT_EQ(Stop(0), 0);
}

// How many times `needle` occurs in `text`.
int Count(const std::string& text, const std::string& needle) {
  int n = 0;
  for (size_t at = text.find(needle); at != std::string::npos; at = text.find(needle, at + 1)) ++n;
  return n;
}

// Three replicas; RADIOSITY_CHAOS_JOBS small checkpointed solves (24 by default; ctest
// ReplicasChaosLong: 200) of three different requests, each job with a watcher; while they run,
// replicas are killed with SIGKILL at random moments and started again at once (as Kubernetes
// would), and one is stopped with SIGTERM and started again. Every job ends exactly once (one
// job_succeeded in all the logs together), SUCCEEDED with the elements of an uninterrupted run of
// its request; every watcher reaches the job's final snapshot; nothing is left leased.
TEST_F(ReplicasTest, EveryJobEndsOnceWithTheUninterruptedResultWhenReplicasAreKilled) {
  const char* env = std::getenv("RADIOSITY_CHAOS_JOBS");
  const int jobs = env ? std::max(3, std::atoi(env)) : 24;
  constexpr int kReplicas = 3;
  std::vector<int> ports;
  for (int i = 0; i < kReplicas; ++i) ports.push_back(FreePort());
  auto args = [&](int i) {
    return std::vector<std::string>{"--listen",
                                    absl::StrCat("127.0.0.1:", ports[i]),
                                    "--threads-per-job",
                                    "1",
                                    "--checkpoint-seconds",
                                    "0.2",
                                    "--max-attempts",
                                    "50",
                                    "--max-queued",
                                    absl::StrCat(jobs + 10)};
  };
  for (int i = 0; i < kReplicas; ++i) ASSERT_NO_FATAL_FAILURE(Start(i, args(i)));
  absl::StatusOr<v1::SceneInfo> scene =
      clients_[0]->UploadSceneFile(SourcePath("scenes/cornell_box.obj"));
  ASSERT_TRUE(scene.ok()) << scene.status();
  auto request = [&](int seed) { return CheckpointedSolve(scene->name(), seed, 300, 3'000'000); };

  // Clients by address, made once: a replica started again listens on the same port.
  std::vector<std::shared_ptr<Client>> clients;
  for (int i = 0; i < kReplicas; ++i) {
    clients.push_back(
        std::make_shared<Client>(client::MakeChannel(absl::StrCat("127.0.0.1:", ports[i]))));
  }
  std::vector<std::string> names(jobs);
  std::vector<int> seeds(jobs);
  for (int j = 0; j < jobs; ++j) {
    seeds[j] = 1 + j % 3;
    absl::StatusOr<v1::Job> created = clients[j % kReplicas]->CreateJob(request(seeds[j]));
    ASSERT_TRUE(created.ok()) << created.status();
    names[j] = created->name();
  }

  // A watcher per job, on the replicas in turn: a stream that fails (its replica killed, or the
  // job not followed there yet) is opened again on the next, after the last snapshot it saw.
  std::atomic<bool> give_up{false};
  std::vector<client::Snapshot> finals(jobs);
  std::vector<std::thread> watchers;
  for (int j = 0; j < jobs; ++j) {
    watchers.emplace_back([&, j] {
      int64_t after = 0;
      for (int attempt = 0; !give_up; ++attempt) {
        absl::StatusOr<client::Snapshot> end = clients[(j + attempt) % kReplicas]->Watch(
            names[j], after, /*progress_only=*/true, [&](const client::Snapshot& s) {
              after = std::max(after, s.sequence);
              return true;
            });
        if (end.ok()) {
          finals[j] = *end;
          return;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(200));
      }
    });
  }

  // Chaos while jobs wait: kill -9 a random replica and start it again, then SIGTERM one.
  auto any_waiting = [&] {
    for (int i = 0; i < kReplicas; ++i) {
      absl::StatusOr<v1::ListJobsResponse> listed = clients[i]->ListJobs(v1::ListJobsRequest());
      if (!listed.ok()) continue;
      for (const v1::Job& job : listed->jobs()) {
        if (job.state() == v1::JOB_STATE_QUEUED) return true;
      }
      return false;
    }
    return true;
  };
  std::mt19937 random(12345);
  const int kills = std::max(3, jobs / 8);
  int killed = 0;
  for (int k = 0; k < kills && any_waiting(); ++k) {
    std::this_thread::sleep_for(
        std::chrono::milliseconds(std::uniform_int_distribution<int>(300, 1500)(random)));
    // The replica running the oldest running job (jobs run oldest first), else any.
    int victim = -1;
    for (const std::string& name : names) {
      if (Get(0, name).state() == v1::JOB_STATE_RUNNING) {
        victim = Holder(name);
        break;
      }
    }
    if (victim < 0) victim = std::uniform_int_distribution<int>(0, kReplicas - 1)(random);
    servers_[victim]->Kill();
    ++killed;
    ASSERT_NO_FATAL_FAILURE(Start(victim, args(victim)));
  }
  const int stopped = std::uniform_int_distribution<int>(0, kReplicas - 1)(random);
  EXPECT_EQ(Stop(stopped), 0);
  ASSERT_NO_FATAL_FAILURE(Start(stopped, args(stopped)));

  const bool all_ended = WaitFor(
      [&] {
        for (const std::string& name : names) {
          if (!Ended(Get(0, name))) return false;
        }
        return true;
      },
      60 + jobs * 5);
  give_up = !all_ended;
  for (std::thread& t : watchers) t.join();
  ASSERT_TRUE(all_ended) << Logs();

  // The results of uninterrupted runs, one per request, on the quiet replicas.
  std::map<int, std::string> want;
  for (int seed = 1; seed <= 3; ++seed) {
    v1::CreateJobRequest r = request(seed);
    r.set_request_id(absl::StrCat("uninterrupted-", seed));
    absl::StatusOr<v1::Job> plain = clients[0]->CreateJob(r);
    ASSERT_TRUE(plain.ok()) << plain.status();
    ASSERT_TRUE(WaitFor([&] { return Ended(Get(0, plain->name())); }, 120)) << Logs();
    const std::string out = dir_.File(absl::StrCat("plain", seed));
    ASSERT_TRUE(clients[0]->DownloadResults(plain->name(), out, "elements.csv").ok());
    want[seed] = ReadFile(out + "/elements.csv");
    ASSERT_GT(want[seed].size(), 1000u);
  }
  ASSERT_NE(want[1], want[2]) << "the requests must differ for the comparison to mean anything";

  std::string logs;
  for (int i = 0; i < kReplicas; ++i) logs += ReadFile(Log(i));
  int lost_attempts = 0;
  for (int j = 0; j < jobs; ++j) {
    SCOPED_TRACE(names[j]);
    const v1::Job job = Get(j % kReplicas, names[j]);
    ASSERT_EQ(job.state(), v1::JOB_STATE_SUCCEEDED) << job.error().message();
    lost_attempts += job.lost_attempts();
    const std::string id(absl::StripPrefix(names[j], "jobs/"));
    // Logged once its end is written: never twice (a kill between the write and the line may
    // leave none).
    EXPECT_LE(Count(logs, absl::StrCat("\"event\":\"job_succeeded\",\"job\":\"", id, "\"")), 1);
    const std::string out = dir_.File(absl::StrCat("job", j));
    ASSERT_TRUE(clients[(j + 1) % kReplicas]->DownloadResults(names[j], out, "elements.csv").ok());
    EXPECT_TRUE(ReadFile(out + "/elements.csv") == want[seeds[j]])
        << "differs from the uninterrupted run of seed " << seeds[j];
    EXPECT_TRUE(finals[j].final);
    EXPECT_EQ(finals[j].state, v1::JOB_STATE_SUCCEEDED);
    EXPECT_EQ(finals[j].sequence, job.last_sequence());
  }
  // The kills hit the replicas of running jobs.
  EXPECT_GE(lost_attempts, 1) << killed << " kills";
  std::cout << "chaos: " << jobs << " jobs, " << killed << " replicas killed, 1 stopped, "
            << lost_attempts << " attempts lost and taken over, "
            << Count(logs, "\"event\":\"job_resumed\"") << " resumed from a checkpoint\n";
  EXPECT_EQ(Leased(), 0);
  clients.clear();
  for (int i = 0; i < kReplicas; ++i) EXPECT_EQ(Stop(i), 0);
}

}  // namespace
}  // namespace radiosity
