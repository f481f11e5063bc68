// Checkpoints (solver/methods/checkpoint.h, RunJob's JobSpec::checkpoint_path): a solver restored
// from the state another saved after k steps ends, element for element and bit for bit, where the
// uninterrupted one ends (same seed), for each method that saves its state and the options that
// give its state other parts; a state of another mesh or method is refused, a damaged or foreign
// checkpoint file is recognised, and a job stopped after a checkpoint resumes from it through
// RunJob to the same elements.csv as a job never stopped.
#include "solver/methods/checkpoint.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <atomic>
#include <filesystem>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

#include "nlohmann/json.hpp"
#include "solver/input/scene_files.h"
#include "solver/methods/registry.h"
#include "solver/methods/solver.h"
#include "solver/pipeline/job.h"
#include "solver/util/file_io.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

struct Case {
  std::string name;
  SolveOptions options;
  int steps_before;   // Steps the first solver runs before its state is saved.
  std::string scene;  // A scene file (scenes/) instead of the Cornell box.
};

void PrintTo(const Case& c, std::ostream* os) { *os << c.name; }

std::vector<Case> Cases() {
  SolveOptions base;
  base.method = "progressive";
  base.rays_per_element = 64;
  base.max_rays = 2'000'000;
  base.tolerance = 1e-4;
  base.threads = 2;
  std::vector<Case> cases;
  for (int k : {0, 1, 3}) {
    cases.push_back({"ProgressiveDefaultsAfter" + std::to_string(k), base, k});
  }
  SolveOptions random = base;
  random.formfactor.sampling = "random";
  random.direct = "shot";
  random.indirect = "element";
  cases.push_back({"ProgressiveRandomShotElement", random, 2});
  // Direct light costly enough per element (2048 shadow rays) that it comes in several blocks
  // and chunks are computed ahead of the block being applied when the state is saved (the
  // restored solver computes them again: progress and the ray budget must not count them twice).
  SolveOptions ahead = base;
  ahead.direct_shadow_rays = 2048;
  ahead.max_rays = 40'000'000;
  for (int k : {2, 4}) {
    cases.push_back({"ProgressiveDirectAheadAfter" + std::to_string(k), ahead, k});
  }
  SolveOptions tracked = base;
  tracked.track_direct = true;
  cases.push_back({"ProgressiveTrackDirect", tracked, 2});
  // Mirrors: before and after the hybrid direct step, and while the source shoots what goes on
  // specularly.
  for (int k : {1, 2, 3}) {
    cases.push_back({"ProgressiveMirrorsAfter" + std::to_string(k), base, k,
                     "scenes/test_room_mirror_y0_x0.json"});
  }
  SolveOptions rows = base;
  rows.formfactor.method = "analytic";
  rows.rays_per_element = 1;
  rows.max_rays = 300'000;  // Rows cost by the elements: a few steps.
  cases.push_back({"ProgressiveAnalyticRows", rows, 2});
  SolveOptions sky = base;
  sky.sky.model = "overcast";
  sky.sky.irradiance = Rgb::Gray(100);
  cases.push_back({"ProgressiveSky", sky, 2});
  SolveOptions reflection = base;
  reflection.method = "reflection";
  reflection.rays_per_element = 256;
  cases.push_back({"Reflection", reflection, 2});
  // Matrix methods: saved while the rows are assembled (several batches of rows), and after.
  SolveOptions assembling = base;
  assembling.method = "jacobi";
  assembling.rays_per_element = 1024;
  assembling.max_rays = 20'000'000;
  cases.push_back({"JacobiWhileAssembling", assembling, 2});
  SolveOptions sweeping = base;
  sweeping.method = "gauss-seidel";
  cases.push_back({"GaussSeidelWhileSweeping", sweeping, 3});
  SolveOptions hemicube = base;
  hemicube.method = "jacobi";
  hemicube.formfactor.method = "hemicube";
  hemicube.formfactor.hemicube_resolution = 32;
  cases.push_back({"JacobiHemicube", hemicube, 2});
  // Hierarchical: after the openness and the first links, and after a refinement pass.
  SolveOptions hierarchical = base;
  hierarchical.method = "hierarchical";
  hierarchical.tolerance = 1e-3;
  cases.push_back({"HierarchicalAfterLinking", hierarchical, 2});
  cases.push_back({"HierarchicalAfterRefining", hierarchical, 5});
  return cases;
}

class CheckpointTest : public ::testing::TestWithParam<Case> {};

// Runs `solver` until it has nothing left to do or the ray budget is spent.
void RunToEnd(Solver& solver, const SolveOptions& options) {
  ASSERT_OK_AND_ASSIGN(StopReason reason, RunSolver(solver, options, nullptr, {}));
  EXPECT_NE(reason, StopReason::kCancelled);
}

TEST_P(CheckpointTest, RestoredSolverEndsBitForBitWhereTheUninterruptedOneEnds) {
  const Case& c = GetParam();
  std::unique_ptr<testing::World> world;
  if (c.scene.empty()) {
    ASSERT_OK_AND_ASSIGN(world, testing::CornellBoxWorld(600));
  } else {
    ASSERT_OK_AND_ASSIGN(Scene scene, LoadSceneFile(testing::SourcePath(c.scene), nullptr));
    MeshOptions mesh;
    mesh.max_elements = 600;
    ASSERT_OK_AND_ASSIGN(world, testing::MakeWorld(std::move(scene), mesh));
  }
  ASSERT_OK_AND_ASSIGN(auto first,
                       CreateSolver(world->scene, *world->mesh, *world->vis, c.options, nullptr));
  for (int i = 0; i < c.steps_before; ++i) {
    ASSERT_OK_AND_ASSIGN(bool more, first->Step());
    ASSERT_TRUE(more) << "the solve ended before the checkpoint";
  }
  StateWriter state;
  ASSERT_TRUE(first->SaveState(&state));
  RunToEnd(*first, c.options);
  const Solution expected = first->Final();

  ASSERT_OK_AND_ASSIGN(auto second,
                       CreateSolver(world->scene, *world->mesh, *world->vis, c.options, nullptr));
  StateReader reader(state.data());
  ASSERT_OK(second->RestoreState(&reader));
  EXPECT_EQ(second->progress().step, c.steps_before);
  RunToEnd(*second, c.options);
  const Solution got = second->Final();

  EXPECT_EQ(got.rays, expected.rays);
  EXPECT_EQ(got.shots, expected.shots);
  EXPECT_GT(got.rays, 0);
  ASSERT_EQ(got.radiosity.size(), expected.radiosity.size());
  int differ = 0;
  for (size_t s = 0; s < got.radiosity.size(); ++s) {
    const Rgb& a = got.radiosity[s];
    const Rgb& b = expected.radiosity[s];
    differ += a.r != b.r || a.g != b.g || a.b != b.b;
  }
  EXPECT_EQ(differ, 0) << "element sides whose radiosity differs from the uninterrupted run's";
  ASSERT_EQ(got.std_error.size(), expected.std_error.size());
  for (size_t s = 0; s < got.std_error.size(); ++s) {
    ASSERT_EQ(got.std_error[s].r, expected.std_error[s].r) << "slot " << s;
  }
  EXPECT_EQ(got.absorbed_power.Sum(), expected.absorbed_power.Sum());
  EXPECT_EQ(got.escaped_power.Sum(), expected.escaped_power.Sum());
  EXPECT_EQ(got.emitted_power.Sum(), expected.emitted_power.Sum());
  // Reflection simulation's books balance only in expectation (its noise).
  testing::ExpectBooksBalance(got, c.options.method == "reflection" ? 0.01 : 1e-9);
}

INSTANTIATE_TEST_SUITE_P(Methods, CheckpointTest, ::testing::ValuesIn(Cases()),
                         [](const auto& p) { return p.param.name; });

TEST(CheckpointRefusalTest, StateOfAnotherMeshOrMethodIsRefused) {
  ASSERT_OK_AND_ASSIGN(auto coarse, testing::CornellBoxWorld(200));
  ASSERT_OK_AND_ASSIGN(auto fine, testing::CornellBoxWorld(800));
  SolveOptions o;
  o.method = "progressive";
  o.rays_per_element = 16;
  ASSERT_OK_AND_ASSIGN(auto solver,
                       CreateSolver(coarse->scene, *coarse->mesh, *coarse->vis, o, nullptr));
  ASSERT_OK(solver->Step().status());
  StateWriter state;
  ASSERT_TRUE(solver->SaveState(&state));

  ASSERT_OK_AND_ASSIGN(auto other, CreateSolver(fine->scene, *fine->mesh, *fine->vis, o, nullptr));
  StateReader on_fine(state.data());
  EXPECT_EQ(other->RestoreState(&on_fine).code(), absl::StatusCode::kFailedPrecondition);

  SolveOptions r = o;
  r.method = "reflection";
  ASSERT_OK_AND_ASSIGN(auto reflection,
                       CreateSolver(coarse->scene, *coarse->mesh, *coarse->vis, r, nullptr));
  StateReader as_reflection(state.data());
  EXPECT_EQ(reflection->RestoreState(&as_reflection).code(), absl::StatusCode::kFailedPrecondition);

  // Every method saves its state, and no other method takes it.
  for (const char* method : {"hierarchical", "jacobi", "gauss-seidel"}) {
    SolveOptions m = o;
    m.method = method;
    ASSERT_OK_AND_ASSIGN(auto other_method,
                         CreateSolver(coarse->scene, *coarse->mesh, *coarse->vis, m, nullptr));
    StateReader as_other(state.data());
    EXPECT_EQ(other_method->RestoreState(&as_other).code(), absl::StatusCode::kFailedPrecondition)
        << method;
    ASSERT_OK(other_method->Step().status());
    StateWriter saved;
    EXPECT_TRUE(other_method->SaveState(&saved)) << method;
  }
}

TEST(CheckpointFileTest, DamagedOrForeignFilesAreRecognised) {
  const std::string dir = ::testing::TempDir() + "/checkpoint_file_test";
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/state.ckpt";
  std::filesystem::remove(path);
  EXPECT_EQ(ReadCheckpoint(path, "job a").status().code(), absl::StatusCode::kNotFound);

  StateWriter state;
  state.Put("x", 1.5);
  state.PutVector("v", std::vector<int>{1, 2, 3});
  ASSERT_OK(WriteCheckpoint(path, "job a", state.data()));
  ASSERT_OK_AND_ASSIGN(std::string read, ReadCheckpoint(path, "job a"));
  StateReader reader(read);
  double x = 0;
  std::vector<int> v(3);
  ASSERT_OK(reader.Get("x", &x));
  ASSERT_OK(reader.GetVector("v", &v));
  ASSERT_OK(reader.Finish());
  EXPECT_EQ(x, 1.5);
  EXPECT_EQ(v, (std::vector<int>{1, 2, 3}));

  EXPECT_EQ(ReadCheckpoint(path, "job b").status().code(), absl::StatusCode::kFailedPrecondition);

  ASSERT_OK_AND_ASSIGN(std::string bytes, ReadWholeFile(path));
  std::string flipped = bytes;
  flipped[flipped.size() / 2] ^= 0x10;
  ASSERT_OK(WriteWholeFile(path, flipped));
  EXPECT_EQ(ReadCheckpoint(path, "job a").status().code(), absl::StatusCode::kDataLoss);
  ASSERT_OK(WriteWholeFile(path, bytes.substr(0, bytes.size() - 5)));
  EXPECT_EQ(ReadCheckpoint(path, "job a").status().code(), absl::StatusCode::kDataLoss);

  // Anything but a regular file is not read (a FIFO would block the job).
  const std::string fifo = dir + "/fifo.ckpt";
  std::filesystem::remove(fifo);
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_EQ(ReadCheckpoint(fifo, "job a").status().code(), absl::StatusCode::kDataLoss);
  EXPECT_EQ(ReadCheckpoint(dir, "job a").status().code(), absl::StatusCode::kDataLoss);

  // A reader expecting other sections or sizes says which.
  StateReader wrong(read);
  float f = 0;
  EXPECT_EQ(wrong.Get("x", &f).code(), absl::StatusCode::kFailedPrecondition);
  StateReader misnamed(read);
  EXPECT_EQ(misnamed.Get("y", &x).code(), absl::StatusCode::kFailedPrecondition);
}

// RunJob: a job stopped after its third checkpoint resumes from the last one and writes the same
// elements.csv as a job never stopped; its solve's rays and steps continue from the checkpoint.
// Jacobi is stopped while it assembles its matrix (about 10 steps of rows).
class CheckpointJobTest : public ::testing::TestWithParam<std::string> {};

TEST_P(CheckpointJobTest, StoppedJobResumesToTheUninterruptedResult) {
  ASSERT_OK_AND_ASSIGN(auto world, testing::CornellBoxWorld(600));
  const std::string dir = ::testing::TempDir() + "/checkpoint_job_test_" + GetParam();
  std::filesystem::remove_all(dir);
  JobSpec spec;
  spec.solve.method = GetParam();
  spec.solve.rays_per_element = 4096;
  if (GetParam() == "progressive") {
    spec.solve.max_rays = 4'000'000;  // About 16 steps; the tolerance is not reached.
    spec.solve.tolerance = 1e-9;
  } else {
    spec.solve.tolerance = 1e-6;
  }
  spec.solve.threads = 2;
  spec.mesh.max_elements = 600;
  spec.write_ply = false;
  spec.write_image = false;

  ASSERT_OK_AND_ASSIGN(JobResult plain,
                       RunJob(world->scene, spec, dir + "/plain", nullptr, JobObserver()));

  spec.checkpoint_path = dir + "/job.ckpt";
  spec.checkpoint_seconds = 0.01;  // Every step.
  std::atomic<bool> stop{false};
  std::vector<CheckpointEvent> events;
  JobObserver observer;
  // Called from the writing thread, one at a time; RunJob waits for the last before it returns.
  observer.on_checkpoint = [&](const CheckpointEvent& e) {
    events.push_back(e);
    if (events.size() == 3) stop = true;  // As if the process were killed now.
  };
  ASSERT_OK_AND_ASSIGN(JobResult stopped, RunJob(world->scene, spec, dir + "/a", &stop, observer));
  EXPECT_EQ(stopped.reason, StopReason::kCancelled);
  // A fourth may have started before the solve saw the flag.
  ASSERT_GE(events.size(), 3u);
  for (const CheckpointEvent& e : events) {
    EXPECT_EQ(e.kind, CheckpointEvent::Kind::kWritten) << e.ToString();
  }
  const Progress saved = events.back().progress;
  if (GetParam() == "jacobi") {
    EXPECT_EQ(saved.shots, 0) << "saved after the matrix was assembled";
  }
  ASSERT_TRUE(FileExists(spec.checkpoint_path));

  events.clear();
  std::vector<Progress> progress;
  JobObserver resumed_observer;
  resumed_observer.on_checkpoint = [&](const CheckpointEvent& e) { events.push_back(e); };
  resumed_observer.on_progress = [&](const Progress& p) { progress.push_back(p); };
  ASSERT_OK_AND_ASSIGN(JobResult resumed,
                       RunJob(world->scene, spec, dir + "/b", nullptr, resumed_observer));
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events[0].kind, CheckpointEvent::Kind::kResumed) << events[0].ToString();
  EXPECT_EQ(events[0].progress.step, saved.step);
  EXPECT_EQ(events[0].progress.rays, saved.rays);
  ASSERT_FALSE(progress.empty());
  EXPECT_EQ(progress.front().step, saved.step + 1);
  EXPECT_GT(progress.front().rays, saved.rays);

  EXPECT_EQ(resumed.solution.rays, plain.solution.rays);
  // The convergence history spans the run (rays never go back, the last point is the result's)
  // and is carried through the checkpoint: the resumed job's has the same points.
  ASSERT_GE(plain.convergence.size(), 3u);
  for (size_t i = 1; i < plain.convergence.size(); ++i) {
    EXPECT_GE(plain.convergence[i].rays, plain.convergence[i - 1].rays) << i;
    EXPECT_GE(plain.convergence[i].seconds, plain.convergence[i - 1].seconds) << i;
  }
  EXPECT_EQ(plain.convergence.back().rays, plain.solution.rays);
  EXPECT_EQ(plain.convergence.back().unshot_fraction, plain.solution.unshot_fraction);
  ASSERT_EQ(resumed.convergence.size(), plain.convergence.size());
  for (size_t i = 0; i < plain.convergence.size(); ++i) {
    EXPECT_EQ(resumed.convergence[i].rays, plain.convergence[i].rays) << i;
    EXPECT_EQ(resumed.convergence[i].unshot_fraction, plain.convergence[i].unshot_fraction) << i;
  }
  const nlohmann::json summary =
      nlohmann::json::parse(testing::ReadFile(dir + "/b/summary.json"), nullptr, false);
  ASSERT_TRUE(summary.contains("convergence"));
  EXPECT_EQ(summary["convergence"]["rays"].size(), plain.convergence.size());
  EXPECT_EQ(summary["convergence"]["seconds"].size(), plain.convergence.size());
  EXPECT_NEAR(summary["convergence"]["unshot_fraction"].back().get<double>(),
              plain.solution.unshot_fraction, 1e-9 * plain.solution.unshot_fraction);
  ASSERT_OK_AND_ASSIGN(std::string want, ReadWholeFile(dir + "/plain/elements.csv"));
  ASSERT_OK_AND_ASSIGN(std::string got, ReadWholeFile(dir + "/b/elements.csv"));
  EXPECT_EQ(got, want);

  // A checkpoint of another spec (another seed) is discarded, and the job starts over.
  spec.solve.seed += 1;
  events.clear();
  ASSERT_OK_AND_ASSIGN(JobResult other,
                       RunJob(world->scene, spec, dir + "/c", nullptr, resumed_observer));
  ASSERT_FALSE(events.empty());
  EXPECT_EQ(events[0].kind, CheckpointEvent::Kind::kDiscarded) << events[0].ToString();
  EXPECT_EQ(events[0].status.code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_EQ(other.reason, plain.reason);
}

INSTANTIATE_TEST_SUITE_P(Methods, CheckpointJobTest, ::testing::Values("progressive", "jacobi"),
                         [](const auto& p) { return p.param; });

}  // namespace
}  // namespace radiosity
