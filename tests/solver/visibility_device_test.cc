// The process's one Embree device (solver/transport/visibility.h): an error goes to the
// Visibility whose call failed and to no other, however many share the device and trace at the
// same time; builds and traces from many threads at once; a BVH build runs in the arena it is
// given (so a job's thread count holds for it).
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <memory>
#include <thread>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/transport/visibility.h"
#include "tbb/global_control.h"
#include "tbb/task_arena.h"
#include "tbb/task_scheduler_observer.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

const Material kWhite{"white", Rgb::Gray(0.5), Rgb(), Rgb(), false, 0};

Mesh BoxMesh() {
  MeshOptions options;
  options.max_elements = 600;
  absl::StatusOr<Mesh> mesh = Mesh::Build(testing::MakeClosedBox(1, 1, 1, kWhite), options);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return mesh.ok() ? *std::move(mesh) : Mesh();
}

// A floor of n x n small quads under a ceiling: n^2 + 1 faces to build a BVH over.
Mesh GridMesh(int n) {
  Scene scene;
  scene.materials.push_back(kWhite);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      testing::AddRect(&scene, "floor", 0, {i * 1.0, 0, j * 1.0}, {0, 0, 1}, {1, 0, 0});
    }
  }
  testing::AddRect(&scene, "ceiling", 0, {0, 1, 0}, {n * 1.0, 0, 0}, {0, 0, n * 1.0});
  MeshOptions options;
  options.element_size = 2;  // One element per quad.
  absl::StatusOr<Mesh> mesh = Mesh::Build(scene, options);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return mesh.ok() ? *std::move(mesh) : Mesh();
}

std::unique_ptr<Visibility> BuildOrDie(const Mesh& mesh, tbb::task_arena* arena = nullptr) {
  absl::StatusOr<std::unique_ptr<Visibility>> vis = Visibility::Build(mesh, arena);
  EXPECT_TRUE(vis.ok()) << vis.status();
  return vis.ok() ? *std::move(vis) : nullptr;
}

// From the centre of the box (mesh coordinates are recentred) along +x, the wall is 0.5 away.
bool HitsTheWall(const Visibility& vis) {
  Hit hit = vis.Intersect({0, 0, 0}, {1, 0, 0}, 0, 10);
  return hit.valid() && std::abs(hit.t - 0.5f) < 1e-4f;
}

TEST(VisibilityDeviceTest, AnErrorReachesOnlyTheVisibilityWhoseCallFailed) {
  const Mesh mesh = BoxMesh();
  std::unique_ptr<Visibility> failing = BuildOrDie(mesh);
  std::unique_ptr<Visibility> tracing = BuildOrDie(mesh);
  ASSERT_TRUE(failing && tracing);
  ASSERT_TRUE(failing->status().ok());

  // One thread traces with `tracing` while another makes `failing` fail, on the same device.
  std::atomic<bool> stop{false};
  std::atomic<int64_t> misses{0};
  std::thread tracer([&] {
    while (!stop.load()) misses += HitsTheWall(*tracing) ? 0 : 1;
  });
  std::thread failer([&] { failing->FailAnEmbreeCallForTesting(); });
  failer.join();
  stop = true;
  tracer.join();

  absl::Status error = failing->status();
  EXPECT_EQ(error.code(), absl::StatusCode::kInternal) << error;
  EXPECT_NE(error.message().find("Embree error"), absl::string_view::npos) << error;
  EXPECT_TRUE(tracing->status().ok()) << tracing->status();
  EXPECT_EQ(misses.load(), 0);
  // The first error is kept; the failing Visibility still traces.
  failing->FailAnEmbreeCallForTesting();
  EXPECT_EQ(failing->status(), error);
  EXPECT_TRUE(HitsTheWall(*failing));
  // A Visibility built afterwards on the same device starts clean.
  std::unique_ptr<Visibility> later = BuildOrDie(mesh);
  ASSERT_TRUE(later);
  EXPECT_TRUE(later->status().ok()) << later->status();
}

TEST(VisibilityDeviceTest, ManyThreadsBuildAndTraceAtOnce) {
  const Mesh mesh = BoxMesh();
  constexpr int kThreads = 6;
  std::atomic<int> ready{0};
  std::vector<int> good(kThreads, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      ++ready;
      while (ready.load() < kThreads) std::this_thread::yield();
      tbb::task_arena arena(1 + t % 2);
      for (int round = 0; round < 5; ++round) {
        std::unique_ptr<Visibility> vis = BuildOrDie(mesh, t % 3 == 0 ? nullptr : &arena);
        if (vis && vis->status().ok() && HitsTheWall(*vis) && vis->status().ok()) ++good[t];
      }
    });
  }
  for (std::thread& t : threads) t.join();
  for (int t = 0; t < kThreads; ++t) EXPECT_EQ(good[t], 5) << "thread " << t;
}

// Counts the worker threads that join one arena.
class WorkersJoining : public tbb::task_scheduler_observer {
 public:
  explicit WorkersJoining(tbb::task_arena& arena) : tbb::task_scheduler_observer(arena) {
    observe(true);
  }
  // A worker still in the arena holds a reference to the observer's proxy, which TBB would then
  // never free: the workers are given a few seconds to leave first.
  ~WorkersJoining() override {
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
    while (left.load() < count.load() && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    observe(false);
  }
  void on_scheduler_entry(bool worker) override {
    if (worker) ++count;
  }
  void on_scheduler_exit(bool worker) override {
    if (worker) ++left;
  }
  std::atomic<int> count{0};
  std::atomic<int> left{0};
};

TEST(VisibilityDeviceTest, TheBuildRunsInTheArenaItIsGiven) {
  const Mesh mesh = GridMesh(300);
  ASSERT_GT(mesh.faces().size(), 90000u);
  // An arena of four: the caller and three workers (TBB may run that many even on fewer cores).
  // Only tasks spawned into the arena make a worker join it, so a join shows that Embree's build
  // tasks ran there (not in the caller's implicit arena, nor in one of Embree's own). On a busy
  // machine the workers may come too late for one build, so several are allowed.
  tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism, 4);
  tbb::task_arena arena(4);
  arena.initialize();
  WorkersJoining workers(arena);
  std::unique_ptr<Visibility> vis;
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (workers.count.load() == 0 && std::chrono::steady_clock::now() < end) {
    vis = BuildOrDie(mesh, &arena);
    ASSERT_TRUE(vis);
    EXPECT_TRUE(vis->status().ok()) << vis->status();
  }
  EXPECT_GT(workers.count.load(), 0);
  // Down from under the ceiling onto the floor (1 below it).
  const Vec3 above = Vec3{150, 0.5, 150} - mesh.origin();
  Hit hit = vis->Intersect(above, {0, -1, 0}, 0, 10);
  ASSERT_TRUE(hit.valid());
  EXPECT_NEAR(hit.t, 0.5, 1e-4);
}

}  // namespace
}  // namespace radiosity
