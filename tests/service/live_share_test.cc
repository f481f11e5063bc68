// The live snapshot a replica shares with the replicas that follow its job (server/live_share.h):
// what is written is read back whole, only when newer, with its mesh from its own file (or the
// one already at hand); interest expires; a damaged file is an error, not a snapshot.
#include "server/live_share.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "solver/util/file_io.h"
#include "tests/testing/test_util.h"

namespace radiosity::service {
namespace {

using radiosity::testing::TempDir;

MeshPtr TwoElementMesh(int64_t version) {
  v1::MeshGeometry chunk;
  chunk.set_version(version);
  chunk.set_elements(2);
  chunk.set_chunk_count(1);
  return std::make_shared<MeshAnnouncement>(std::vector<v1::MeshGeometry>{chunk});
}

Snapshot Running(int64_t sequence, MeshPtr mesh, float base) {
  Snapshot s;
  s.sequence = sequence;
  s.state = v1::JOB_STATE_RUNNING;
  s.elements = 2;
  s.attempts = 2;
  s.progress.set_step(7);
  s.progress.set_rays(123456);
  s.progress.set_unshot_fraction(0.25);
  std::vector<float> radiosity(12), std_error(12);
  for (int i = 0; i < 12; ++i) {
    radiosity[i] = base + i;
    std_error[i] = 0.5f * i;
  }
  s.radiosity = std::make_shared<FloatBlock>(radiosity);
  s.std_error = std::make_shared<FloatBlock>(std_error);
  s.mesh_version = mesh->version();
  s.mesh = std::move(mesh);
  return s;
}

TEST(LiveShareTest, ASnapshotIsReadBackWholeOnlyWhenNewerWithItsMesh) {
  TempDir dir;
  const std::string job = dir.File("job");
  MeshPtr cache;
  ASSERT_TRUE(ReadLiveSnapshot(job, 0, &cache).ok());
  EXPECT_EQ(*ReadLiveSnapshot(job, 0, &cache), nullptr) << "nothing shared yet";

  ASSERT_TRUE(WriteLiveSnapshot(job, Running(40, TwoElementMesh(3), 1.0f)).ok());
  absl::StatusOr<SnapshotPtr> read = ReadLiveSnapshot(job, 39, &cache);
  ASSERT_TRUE(read.ok()) << read.status();
  ASSERT_NE(*read, nullptr);
  const Snapshot& s = **read;
  EXPECT_EQ(s.sequence, 40);
  EXPECT_EQ(s.state, v1::JOB_STATE_RUNNING);
  EXPECT_EQ(s.elements, 2);
  EXPECT_EQ(s.attempts, 2);
  EXPECT_EQ(s.progress.step(), 7);
  EXPECT_EQ(s.progress.rays(), 123456);
  EXPECT_EQ(s.progress.unshot_fraction(), 0.25);
  EXPECT_EQ(s.radiosity->data(), Running(40, TwoElementMesh(3), 1.0f).radiosity->data());
  ASSERT_NE(s.std_error, nullptr);
  EXPECT_EQ(s.std_error->data()[11], 5.5f);
  ASSERT_NE(s.mesh, nullptr);
  EXPECT_EQ(s.mesh_version, 3);
  EXPECT_EQ(s.mesh->version(), 3);
  EXPECT_EQ(cache, s.mesh);

  // Not newer than what the follower has: nothing.
  EXPECT_EQ(*ReadLiveSnapshot(job, 40, &cache), nullptr);
  // A newer one on the same mesh reuses the mesh at hand (its file is not read again).
  const MeshPtr before = cache;
  std::filesystem::remove(LiveDir(job) + "/mesh-3");
  ASSERT_TRUE(WriteLiveSnapshot(job, Running(41, TwoElementMesh(3), 2.0f)).ok());
  std::filesystem::remove(LiveDir(job) + "/mesh-3");
  read = ReadLiveSnapshot(job, 40, &cache);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ((*read)->radiosity->data()[0], 2.0f);
  EXPECT_EQ(cache, before);
  // A new mesh version: read from its file.
  ASSERT_TRUE(WriteLiveSnapshot(job, Running(42, TwoElementMesh(4), 3.0f)).ok());
  read = ReadLiveSnapshot(job, 41, &cache);
  ASSERT_TRUE(read.ok()) << read.status();
  EXPECT_EQ((*read)->mesh_version, 4);
  EXPECT_EQ(cache->version(), 4);
}

TEST(LiveShareTest, ADamagedSnapshotIsAnErrorNotASnapshot) {
  TempDir dir;
  const std::string job = dir.File("job");
  ASSERT_TRUE(WriteLiveSnapshot(job, Running(5, TwoElementMesh(1), 1.0f)).ok());
  const std::string path = LiveDir(job) + "/snapshot";
  absl::StatusOr<std::string> bytes = ReadWholeFile(path);
  ASSERT_TRUE(bytes.ok());
  ASSERT_TRUE(WriteWholeFile(path, bytes->substr(0, bytes->size() - 3)).ok());  // Cut short.
  MeshPtr cache;
  absl::StatusOr<SnapshotPtr> read = ReadLiveSnapshot(job, 0, &cache);
  ASSERT_FALSE(read.ok());
  EXPECT_EQ(read.status().code(), absl::StatusCode::kDataLoss);
  EXPECT_NE(read.status().message().find("not a live snapshot"), absl::string_view::npos);
  ASSERT_TRUE(WriteWholeFile(path, "something else entirely, long enough to hold a header").ok());
  EXPECT_EQ(ReadLiveSnapshot(job, 0, &cache).status().code(), absl::StatusCode::kDataLoss);
}

TEST(LiveShareTest, InterestLastsAFewSecondsAfterTheLastTouch) {
  TempDir dir;
  const std::string job = dir.File("job");
  EXPECT_FALSE(LiveWatched(job));
  TouchLiveInterest(job);
  EXPECT_TRUE(LiveWatched(job));
  // An old touch (its time set back past kLiveInterest) is no interest.
  const auto old =
      std::filesystem::file_time_type::clock::now() - kLiveInterest - std::chrono::seconds(1);
  std::filesystem::last_write_time(LiveDir(job) + "/watched", old);
  EXPECT_FALSE(LiveWatched(job));
  TouchLiveInterest(job);
  EXPECT_TRUE(LiveWatched(job));
}

}  // namespace
}  // namespace radiosity::service
