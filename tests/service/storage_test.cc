// Storage failures are states, not ghosts (issue 15): with the data directory on a small tmpfs
// that fills up while a job runs, the job ends FAILED with RESOURCE_EXHAUSTED and the OS's
// reason (no server path), Get, Cancel and Watch say so although the store could not take it,
// health is NOT_SERVING while the store cannot be written, and once space is freed the end is
// written and health recovers. Skipped where mounting a tmpfs is not allowed.
#include <gtest/gtest.h>
#include <sys/mount.h>
#include <sys/stat.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using service::testing::ConnectTo;
using service::testing::LongSolve;
using service::testing::TestServerOptions;
using service::testing::WaitFor;
using testing::TempDir;

// Writes zeros to `path` until the file system is full; returns the bytes written.
int64_t FillDisk(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) return 0;
  std::setvbuf(f, nullptr, _IONBF, 0);
  const std::vector<char> block(4096, 0);
  int64_t written = 0;
  for (size_t size : {size_t{4096}, size_t{1}}) {
    while (std::fwrite(block.data(), 1, size, f) == size) written += static_cast<int64_t>(size);
    std::clearerr(f);
  }
  std::fclose(f);
  return written;
}

bool Serving(client::Client& c) {
  absl::StatusOr<bool> serving = c.CheckHealth(service::kServiceName);
  return serving.ok() && *serving;
}

TEST(ServiceStorageTest, AFullDiskFailsTheJobTruthfullyAndHealthFollowsTheStore) {
  TempDir dir;
  const std::string mount_point = dir.File("small");
  ASSERT_EQ(::mkdir(mount_point.c_str(), 0755), 0);
  if (::mount("tmpfs", mount_point.c_str(), "tmpfs", 0, "size=24m") != 0) {
    GTEST_SKIP() << "cannot mount a tmpfs here (" << std::strerror(errno)
                 << "): the full-disk test needs it";
  }
  struct Unmount {
    std::string path;
    ~Unmount() { ::umount2(path.c_str(), MNT_DETACH); }
  } unmount{mount_point};
  const std::string data = mount_point + "/data";
  const std::string fill = mount_point + "/fill.bin";

  std::string job;
  {
    absl::StatusOr<std::unique_ptr<service::Server>> server =
        service::Server::Start(TestServerOptions(data));
    ASSERT_TRUE(server.ok()) << server.status();
    std::unique_ptr<client::Client> c = ConnectTo(**server);
    absl::StatusOr<v1::SceneInfo> scene =
        c->UploadSceneFile(testing::SourcePath("scenes/cornell_box.obj"));
    ASSERT_TRUE(scene.ok()) << scene.status();
    absl::StatusOr<v1::Job> created = c->CreateJob(LongSolve(scene->name(), 2000, 64));
    ASSERT_TRUE(created.ok()) << created.status();
    job = created->name();
    ASSERT_TRUE(WaitFor(
        [&] {
          absl::StatusOr<v1::Job> j = c->GetJob(job);
          return j.ok() && j->state() == v1::JOB_STATE_RUNNING && j->progress().rays() > 0;
        },
        60))
        << c->GetJob(job)->ShortDebugString();
    EXPECT_TRUE(Serving(*c));

    // The disk fills up; the cancelled job cannot write its results, nor the store its end.
    ASSERT_GT(FillDisk(fill), 0);
    ASSERT_TRUE(c->CancelJob(job).ok());
    ASSERT_TRUE(WaitFor(
        [&] {
          absl::StatusOr<v1::Job> j = c->GetJob(job);
          return j.ok() && j->state() == v1::JOB_STATE_FAILED;
        },
        30));
    absl::StatusOr<v1::Job> failed = c->GetJob(job);
    ASSERT_TRUE(failed.ok());
    EXPECT_EQ(failed->error().code(), static_cast<int>(absl::StatusCode::kResourceExhausted))
        << failed->error().message();
    EXPECT_NE(failed->error().message().find(std::strerror(ENOSPC)), std::string::npos)
        << failed->error().message();
    EXPECT_EQ(failed->error().message().find(mount_point), std::string::npos)
        << failed->error().message();
    // Not a ghost: every call tells the same end.
    absl::StatusOr<v1::Job> cancel_again = c->CancelJob(job);
    EXPECT_EQ(cancel_again.status().code(), absl::StatusCode::kFailedPrecondition);
    EXPECT_NE(cancel_again.status().message().find("has already ended (FAILED)"), std::string::npos)
        << cancel_again.status();
    absl::StatusOr<client::Snapshot> last = c->Watch(job, 0, true, nullptr);
    ASSERT_TRUE(last.ok()) << last.status();
    EXPECT_EQ(last->state, v1::JOB_STATE_FAILED);
    v1::ListJobsRequest list;
    absl::StatusOr<v1::ListJobsResponse> listed = c->ListJobs(list);
    ASSERT_TRUE(listed.ok()) << listed.status();
    ASSERT_EQ(listed->jobs_size(), 1);
    EXPECT_EQ(listed->jobs(0).state(), v1::JOB_STATE_FAILED);
    EXPECT_TRUE(WaitFor([&] { return !Serving(*c); }, 10)) << "health stayed SERVING";

    // Space again: the end is written within seconds and health recovers.
    ASSERT_EQ(std::remove(fill.c_str()), 0);
    EXPECT_TRUE(WaitFor([&] { return Serving(*c); }, 10)) << "health stayed NOT_SERVING";
    c.reset();
    (*server)->Shutdown();
  }
  // The store has the end: a new server on the same data reports it.
  absl::StatusOr<std::unique_ptr<service::Server>> server =
      service::Server::Start(TestServerOptions(data));
  ASSERT_TRUE(server.ok()) << server.status();
  std::unique_ptr<client::Client> c = ConnectTo(**server);
  absl::StatusOr<v1::Job> stored = c->GetJob(job);
  ASSERT_TRUE(stored.ok()) << stored.status();
  EXPECT_EQ(stored->state(), v1::JOB_STATE_FAILED);
  EXPECT_EQ(stored->error().code(), static_cast<int>(absl::StatusCode::kResourceExhausted));
  c.reset();
  (*server)->Shutdown();
}

}  // namespace
}  // namespace radiosity
