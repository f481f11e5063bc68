// Snapshot streams against a real server on 127.0.0.1: two watchers of one job, a slow reader
// (latest wins, bounded memory), a dropped stream resumed after its last sequence, a deadline
// that never cancels the job, and a watch that survives a server restart.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <thread>

#include "client/client.h"
#include "server/metrics.h"
#include "server/server.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using client::Snapshot;
using service::testing::ConnectTo;
using service::testing::WaitFor;

class ServiceWatchTest : public service::testing::ServiceTest {
 protected:
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(ServiceTest::SetUp());
    ASSERT_OK_AND_ASSIGN(const v1::SceneInfo scene,
                         client_->UploadSceneFile(testing::SourcePath("scenes/cornell_box.obj")));
    scene_ = scene.name();
  }

  // Starts a solve that runs until cancelled (or 60 s), with `elements` elements: its name.
  absl::StatusOr<std::string> StartLongSolve(int64_t elements) {
    v1::CreateJobRequest r = service::testing::LongSolve(scene_, elements, 8);
    r.mutable_solve()->set_snapshot_interval(0.01);
    r.mutable_solve()->set_skip_mesh_ply(true);
    return CreateJobNamed(r);
  }

  std::string scene_;
};

TEST_F(ServiceWatchTest, TwoClientsWatchOneJob) {
  v1::CreateJobRequest r;
  r.set_scene(scene_);
  r.mutable_solve()->mutable_mesh()->set_max_elements(1000);
  r.mutable_solve()->set_rays_per_element(800);
  r.mutable_solve()->set_snapshot_interval(0.01);
  r.mutable_solve()->set_width(8);
  r.mutable_solve()->set_height(8);
  absl::StatusOr<v1::Job> job = client_->CreateJob(r);
  ASSERT_TRUE(job.ok()) << job.status();

  struct Watcher {
    std::vector<int64_t> sequences;
    absl::StatusOr<Snapshot> last = absl::UnknownError("not run");
  };
  Watcher w[2];
  std::vector<std::thread> threads;
  for (Watcher& watcher : w) {
    threads.emplace_back([&, server = server_.get()] {
      std::unique_ptr<client::Client> c =
          ConnectTo(*server);  // A client of its own: its own connection.
      watcher.last = c->Watch(job->name(), 0, false, [&](const Snapshot& s) {
        watcher.sequences.push_back(s.sequence);
        return true;
      });
    });
  }
  for (std::thread& t : threads) t.join();
  for (const Watcher& watcher : w) {
    ASSERT_TRUE(watcher.last.ok()) << watcher.last.status();
    EXPECT_EQ(watcher.last->state, v1::JOB_STATE_SUCCEEDED);
    ASSERT_FALSE(watcher.sequences.empty());
    EXPECT_TRUE(std::is_sorted(watcher.sequences.begin(), watcher.sequences.end()));
    EXPECT_EQ(std::adjacent_find(watcher.sequences.begin(), watcher.sequences.end()),
              watcher.sequences.end());
  }
  EXPECT_EQ(w[0].last->sequence, w[1].last->sequence);
  ASSERT_FALSE(w[0].last->radiosity.empty());
  EXPECT_EQ(w[0].last->radiosity, w[1].last->radiosity);
  // Watching the ended job gives the same final snapshot, now read from disk.
  absl::StatusOr<Snapshot> later = client_->Watch(job->name(), 0, false, nullptr);
  ASSERT_TRUE(later.ok()) << later.status();
  EXPECT_EQ(later->sequence, w[0].last->sequence);
  EXPECT_EQ(later->radiosity, w[0].last->radiosity);
  EXPECT_TRUE(WaitFor([&] { return server_->metrics().watchers.load() == 0; }, 10));
}

TEST_F(ServiceWatchTest, SlowReaderGetsTheNewestSnapshotInBoundedMemory) {
  ASSERT_OK_AND_ASSIGN(const std::string job, StartLongSolve(40000));
  ASSERT_TRUE(WaitFor(
      [&] {
        // Solving (meshing's progress comes in snapshots too, before the mesh exists).
        absl::StatusOr<v1::Job> j = client_->GetJob(job);
        return j.ok() && j->last_sequence() > 0 && j->mesh().elements() > 0;
      },
      30));
  absl::StatusOr<v1::Job> j = client_->GetJob(job);
  ASSERT_TRUE(j.ok());
  const int64_t snapshot_bytes = j->mesh().elements() * 6 * static_cast<int64_t>(sizeof(float));
  ASSERT_GT(snapshot_bytes, 4 * 196'608);  // Two messages per snapshot.

  std::atomic<bool> sampling{true};
  std::atomic<int64_t> peak{0};
  std::thread sampler([&] {
    while (sampling) {
      peak = std::max(peak.load(), service::SnapshotBytesLive().load());
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
  });
  const int64_t published_before = server_->metrics().snapshots.load();
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
  v1::WatchJobRequest request;
  request.set_name(job);
  auto reader = client_->stub().WatchJob(&context, request);
  int messages = 0, snapshots = 0, resyncs = 0;
  int64_t last_sequence = 0;
  v1::WatchJobResponse m;
  auto take = [&] {
    ++messages;
    EXPECT_GE(m.sequence(), last_sequence);
    last_sequence = m.sequence();
    if (m.chunk_index() + 1 == m.chunk_count()) ++snapshots;
    resyncs += m.chunk_index() == 0 && m.resync();
    EXPECT_LE(m.ByteSizeLong(), size_t{1} << 20);
  };
  // One message every 250 ms for 3 s: much slower than the solver publishes.
  for (int i = 0; i < 12 && reader->Read(&m); ++i) {
    take();
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
  }
  EXPECT_EQ(messages, 12);
  // Then not at all until the server has dropped a snapshot for this reader: waiting on the
  // server's count rather than on the clock keeps this test independent of how fast the solver
  // publishes (slow under sanitizers) and of how much the transport buffers.
  EXPECT_TRUE(WaitFor([&] { return server_->metrics().snapshots_skipped.load() > 0; }, 60));
  // Then at full speed until the stream says snapshots were skipped (the few messages the
  // transport had buffered come first).
  for (int i = 0; i < 200 && resyncs == 0 && reader->Read(&m); ++i) take();
  const int64_t published = server_->metrics().snapshots.load() - published_before;
  context.TryCancel();  // The reader goes away...
  (void)reader->Finish();
  sampling = false;
  sampler.join();

  EXPECT_GT(published, snapshots);  // It did not get them all...
  EXPECT_GT(resyncs, 0) << "published " << published << ", received " << snapshots << ", skipped "
                        << server_->metrics().snapshots_skipped.load();  // ...it was told so...
  EXPECT_GT(server_->metrics().snapshots_skipped.load(), 0);
  // ...and the server held a handful of snapshots, never a backlog: the solver's newest, the
  // channel's, and the watcher's current and pending one.
  EXPECT_LE(peak.load(), 6 * snapshot_bytes) << "published " << published;
  // ...and its leaving did not cancel the job.
  EXPECT_EQ(State(job), v1::JOB_STATE_RUNNING);
  ASSERT_TRUE(WaitFor([&] { return server_->metrics().watchers.load() == 0; }, 10));
  ASSERT_TRUE(client_->CancelJob(job).ok());
  ASSERT_TRUE(client_->Watch(job, 0, true, nullptr).ok());
}

TEST_F(ServiceWatchTest, DroppedStreamResumesAfterItsLastSequence) {
  ASSERT_OK_AND_ASSIGN(const std::string job, StartLongSolve(1000));
  int64_t last_complete = 0;
  {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
    v1::WatchJobRequest request;
    request.set_name(job);
    auto reader = client_->stub().WatchJob(&context, request);
    v1::WatchJobResponse m;
    int complete = 0;
    for (int i = 0; i < 1000 && complete < 2 && reader->Read(&m); ++i) {
      if (m.chunk_index() + 1 == m.chunk_count()) {
        ++complete;
        last_complete = m.sequence();
      }
    }
    ASSERT_EQ(complete, 2);
    context.TryCancel();  // The connection drops.
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::CANCELLED);
  }
  // Snapshots pass meanwhile: at least two, so the resumed stream must skip one (a sanitizer
  // build under load may take longer than the 10 ms interval suggests).
  ASSERT_TRUE(WaitFor(
      [&] {
        absl::StatusOr<v1::Job> j = client_->GetJob(job);
        return j.ok() && j->last_sequence() >= last_complete + 2;
      },
      30));
  EXPECT_EQ(State(job), v1::JOB_STATE_RUNNING);

  // An expired deadline does not cancel the job either.
  {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(200));
    v1::WatchJobRequest request;
    request.set_name(job);
    request.set_progress_only(true);
    auto reader = client_->stub().WatchJob(&context, request);
    v1::WatchJobResponse m;
    for (int i = 0; i < 100000 && reader->Read(&m);) ++i;
    EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  }
  EXPECT_EQ(State(job), v1::JOB_STATE_RUNNING);

  // Resume: only newer snapshots, the first flagged as a resync (some were never sent).
  std::vector<Snapshot> resumed;
  absl::StatusOr<Snapshot> last = client_->Watch(job, last_complete, false, [&](const Snapshot& s) {
    resumed.push_back(s);
    return resumed.size() < 3;
  });
  EXPECT_EQ(last.status().code(), absl::StatusCode::kCancelled);  // We stopped after 3.
  ASSERT_EQ(resumed.size(), 3u);
  EXPECT_GT(resumed[0].sequence, last_complete + 1);
  EXPECT_TRUE(resumed[0].resync);
  EXPECT_FALSE(resumed[0].radiosity.empty());
  ASSERT_TRUE(client_->CancelJob(job).ok());
  absl::StatusOr<Snapshot> final_snapshot =
      client_->Watch(job, resumed.back().sequence, true, nullptr);
  ASSERT_TRUE(final_snapshot.ok()) << final_snapshot.status();
  EXPECT_EQ(final_snapshot->state, v1::JOB_STATE_CANCELLED);
  EXPECT_GT(final_snapshot->sequence, resumed.back().sequence);
}

TEST_F(ServiceWatchTest, WatchSurvivesAServerRestart) {
  ASSERT_OK_AND_ASSIGN(const std::string job, StartLongSolve(1000));
  const int port = server_->port();
  const service::ServerOptions options = [&] {
    service::ServerOptions o = service::testing::TestServerOptions(data_.path());
    o.listen = absl::StrCat("127.0.0.1:", port);  // Same address after the restart.
    return o;
  }();
  std::unique_ptr<client::Client> watcher = ConnectTo(*server_);
  std::vector<int64_t> sequences;
  std::atomic<int> seen{0};
  absl::StatusOr<Snapshot> last = absl::UnknownError("not run");
  std::thread thread([&] {
    last = watcher->Watch(job, 0, true, [&](const Snapshot& s) {
      sequences.push_back(s.sequence);
      ++seen;
      return true;
    });
  });
  ASSERT_TRUE(WaitFor([&] { return seen.load() >= 2; }, 30));
  // The stream ends UNAVAILABLE; the job goes back to the queue.
  ASSERT_NO_FATAL_FAILURE(Restart(options));
  const int before = seen.load();
  ASSERT_TRUE(WaitFor([&] { return seen.load() >= before + 2; }, 30));  // Resumed by itself.
  ASSERT_TRUE(client_->CancelJob(job).ok());
  thread.join();
  ASSERT_TRUE(last.ok()) << last.status();
  EXPECT_EQ(last->state, v1::JOB_STATE_CANCELLED);
  EXPECT_TRUE(std::is_sorted(sequences.begin(), sequences.end()));
  EXPECT_EQ(std::adjacent_find(sequences.begin(), sequences.end()), sequences.end());
}

}  // namespace
}  // namespace radiosity

namespace radiosity {
namespace {

// WatchJobRequest.include_errors: every message with values carries as many standard errors,
// finite and not negative, each message below 1 MiB (a 120 k-element job needs several); without
// it, none.
TEST_F(ServiceWatchTest, IncludeErrorsSendsAStandardErrorPerValue) {
  v1::CreateJobRequest r;
  r.set_scene(scene_);
  r.mutable_solve()->mutable_mesh()->set_max_elements(120000);
  r.mutable_solve()->set_rays_per_element(20);
  r.mutable_solve()->set_width(8);
  r.mutable_solve()->set_height(8);
  r.mutable_solve()->set_skip_mesh_ply(true);
  ASSERT_OK_AND_ASSIGN(const std::string job, CreateJobNamed(r));
  // The third watch reads the ended job from disk. The deadline only guards against a hang: the
  // first watch lasts the whole solve, about 160 s under AddressSanitizer with CI's other shard
  // busy.
  for (bool include : {true, false, true}) {
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(400));
    v1::WatchJobRequest request;
    request.set_name(job);
    request.set_include_errors(include);
    auto reader = client_->stub().WatchJob(&context, request);
    v1::WatchJobResponse m;
    int64_t values = 0, errors = 0, positive = 0, messages = 0;
    bool final_seen = false;
    while (reader->Read(&m)) {
      ++messages;
      EXPECT_LT(m.ByteSizeLong(), size_t{1} << 20);
      values += m.radiosity_size();
      errors += m.std_error_size();
      if (include) {
        EXPECT_EQ(m.std_error_size(), m.radiosity_size()) << "message " << messages;
      }
      for (float se : m.std_error()) {
        EXPECT_TRUE(std::isfinite(se) && se >= 0) << se;
        positive += se > 0;
      }
      final_seen |= m.final();
    }
    EXPECT_TRUE(reader->Finish().ok());
    EXPECT_TRUE(final_seen);
    EXPECT_GT(values, 0);
    EXPECT_EQ(errors, include ? values : 0);
    if (include) {
      EXPECT_GT(messages, 2);
      EXPECT_GT(positive, values / 4);
    }
  }
}

// The values of an ended job's final snapshot as one raw stream sends them (no client-side
// expansion): the floats, the layout flag and the back ranges.
struct RawValues {
  std::vector<float> values;
  bool existing_sides_only = false;
  std::vector<int64_t> back_ranges;
  int64_t elements = 0;
};

RawValues WatchRaw(client::Client& c, const std::string& job, bool existing_sides_only) {
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
  v1::WatchJobRequest request;
  request.set_name(job);
  request.set_existing_sides_only(existing_sides_only);
  auto reader = c.stub().WatchJob(&context, request);
  RawValues raw;
  v1::WatchJobResponse m;
  while (reader->Read(&m)) {
    if (!m.final()) continue;
    if (m.chunk_index() == 0) {
      raw.values.assign(static_cast<size_t>(m.radiosity_total()), -1.0f);
      raw.existing_sides_only = m.existing_sides_only();
      raw.back_ranges.assign(m.back_ranges().begin(), m.back_ranges().end());
      raw.elements = m.elements();
    }
    EXPECT_EQ(m.existing_sides_only(), raw.existing_sides_only);
    std::copy(m.radiosity().begin(), m.radiosity().end(),
              raw.values.begin() + m.radiosity_offset());
  }
  EXPECT_TRUE(reader->Finish().ok());
  return raw;
}

// WatchJobRequest.existing_sides_only: a scene of one-sided surfaces streams each element's front
// only (half the floats), a scene with a two-sided partition streams backs for its elements
// alone, and the values are those of the full layout; the client asks for it and hands out the
// full layout, equal to the raw full stream's, bit for bit.
TEST_F(ServiceWatchTest, ExistingSidesOnlySendsBackValuesWhereBackSidesExist) {
  ASSERT_OK_AND_ASSIGN(const v1::SceneInfo room,
                       client_->UploadSceneFile(testing::SourcePath("scenes/occluded_room.json")));
  for (const std::string& scene : {scene_, room.name()}) {
    SCOPED_TRACE(scene);
    v1::CreateJobRequest r;
    r.set_scene(scene);
    r.mutable_solve()->mutable_mesh()->set_max_elements(2000);
    r.mutable_solve()->set_max_rays(200000);
    r.mutable_solve()->set_skip_image(true);
    ASSERT_OK_AND_ASSIGN(const std::string job, CreateJobNamed(r));
    ASSERT_OK_AND_ASSIGN(const Snapshot expanded, client_->Watch(job, 0, false, nullptr));
    const RawValues full = WatchRaw(*client_, job, false);
    const RawValues existing = WatchRaw(*client_, job, true);
    const int64_t n = full.elements;
    ASSERT_GT(n, 0);
    EXPECT_FALSE(full.existing_sides_only);
    ASSERT_EQ(static_cast<int64_t>(full.values.size()), 6 * n);
    ASSERT_TRUE(existing.existing_sides_only);
    int64_t backs = 0;
    std::vector<bool> has_back(static_cast<size_t>(n), false);
    for (size_t k = 0; k + 1 < existing.back_ranges.size(); k += 2) {
      backs += existing.back_ranges[k + 1] - existing.back_ranges[k];
      for (int64_t e = existing.back_ranges[k]; e < existing.back_ranges[k + 1]; ++e) {
        has_back[static_cast<size_t>(e)] = true;
      }
    }
    if (scene == scene_) {
      EXPECT_EQ(backs, 0);  // The Cornell box is one-sided: half the floats.
    } else {
      EXPECT_GT(backs, 0);  // The partition.
      EXPECT_LT(backs, n);
    }
    ASSERT_EQ(static_cast<int64_t>(existing.values.size()), 3 * (n + backs));
    size_t at = 0;
    int64_t lit_backs = 0;
    for (int64_t e = 0; e < n; ++e) {
      for (int k = 0; k < (has_back[static_cast<size_t>(e)] ? 6 : 3); ++k) {
        ASSERT_EQ(existing.values[at++], full.values[static_cast<size_t>(6 * e + k)]) << e;
      }
      lit_backs += has_back[static_cast<size_t>(e)] && full.values[6 * e + 3] > 0;
      if (!has_back[static_cast<size_t>(e)]) {
        // No back side: nothing there in the full layout either.
        EXPECT_EQ(full.values[static_cast<size_t>(6 * e + 3)], 0.0f) << e;
      }
    }
    EXPECT_EQ(lit_backs, backs);  // Every back side sent sees light.
    EXPECT_TRUE(expanded.radiosity == full.values);
  }
}

}  // namespace
}  // namespace radiosity
