// The solve pipeline's contracts (pipeline/job.h): progress counts every pass's rays and seconds,
// so a watcher never sees them go back, in both refinement modes; the ignored options are
// reported to the observer and in summary.json.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "nlohmann/json.hpp"
#include "solver/input/scene_files.h"
#include "solver/pipeline/job.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using ::testing::HasSubstr;

struct Observed {
  std::vector<int64_t> progress_rays, snapshot_rays, solution_rays;
  std::vector<double> seconds;
  int meshes = 0;
  std::vector<std::string> warnings;
  const Mesh* mesh = nullptr;           // The mesh being solved (valid during the run).
  std::vector<double> snapshot_errors;  // RelativeStdErrorRms of each snapshot.
  // Every callback in order: "mesh", "snapshot", "meshing 0.5", "writing 0 elements.csv".
  std::vector<std::string> events;
  std::vector<PhaseProgress> phases;
};

absl::StatusOr<JobResult> RunObserved(const JobSpec& spec, const std::string& out, Observed* seen) {
  absl::StatusOr<Scene> scene =
      LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr);
  if (!scene.ok()) return scene.status();
  JobObserver observer;
  observer.on_mesh = [&](const Mesh& mesh) {
    ++seen->meshes;
    seen->mesh = &mesh;
    seen->events.push_back("mesh");
  };
  observer.on_phase = [&](const PhaseProgress& p) {
    seen->phases.push_back(p);
    seen->events.push_back(p.phase == PhaseProgress::Phase::kMeshing ? "meshing" : "writing");
  };
  observer.on_progress = [&](const Progress& p) {
    seen->progress_rays.push_back(p.rays);
    seen->seconds.push_back(p.seconds);
  };
  observer.on_snapshot = [&](const Progress& p, const Solution& s) {
    seen->snapshot_rays.push_back(p.rays);
    seen->solution_rays.push_back(s.rays);
    seen->snapshot_errors.push_back(RelativeStdErrorRms(*seen->mesh, s));
    seen->events.push_back("snapshot");
  };
  observer.on_warnings = [&](const std::vector<std::string>& w) { seen->warnings = w; };
  observer.snapshot_interval = 1e-9;  // A snapshot after every step.
  return RunJob(*scene, spec, out, nullptr, observer);
}

// A solve of `method` on at most `elements` elements, with no image or PLY.
JobSpec SmallJob(const std::string& method, int64_t elements) {
  JobSpec spec;
  spec.solve.method = method;
  spec.mesh.max_elements = elements;
  spec.write_image = false;
  spec.write_ply = false;
  return spec;
}

void ExpectNonDecreasing(const std::vector<int64_t>& v, const std::string& what) {
  for (size_t i = 1; i < v.size(); ++i) {
    EXPECT_GE(v[i], v[i - 1]) << what << " went back at " << i << " of " << v.size();
  }
}

class RaysTest : public ::testing::TestWithParam<bool> {};

TEST_P(RaysTest, RaysNeverGoBackAcrossRefinementPasses) {
  JobSpec spec = SmallJob("progressive", 1600);
  spec.solve.rays_per_element = 200;
  spec.refine.tolerance = 0.2;
  spec.refine.max_passes = 3;
  spec.refine.resolve = GetParam();
  testing::TempDir dir;
  Observed seen;
  absl::StatusOr<JobResult> result = RunObserved(spec, dir.path(), &seen);
  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_GE(result->passes, 2) << "no refinement happened, nothing to test";
  EXPECT_EQ(seen.meshes, result->passes);
  ExpectNonDecreasing(seen.progress_rays, "Progress.rays");
  ExpectNonDecreasing(seen.snapshot_rays, "snapshot Progress.rays");
  ExpectNonDecreasing(seen.solution_rays, "snapshot Solution.rays");
  for (size_t i = 1; i < seen.seconds.size(); ++i) EXPECT_GE(seen.seconds[i], seen.seconds[i - 1]);
  ASSERT_FALSE(seen.progress_rays.empty());
  EXPECT_EQ(seen.progress_rays.back(), result->solution.rays);
  EXPECT_EQ(seen.snapshot_rays.back(), result->solution.rays);
}

INSTANTIATE_TEST_SUITE_P(Modes, RaysTest, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& param_info) {
                           return param_info.param ? std::string("Resolve")
                                                   : std::string("Regather");
                         });

TEST(PipelineTest, IgnoredOptionsAreReportedAndWrittenToTheSummary) {
  JobSpec spec = SmallJob("jacobi", 200);
  spec.solve.overshoot = 1.5;
  testing::TempDir dir;
  Observed seen;
  absl::StatusOr<JobResult> result = RunObserved(spec, dir.path(), &seen);
  ASSERT_TRUE(result.ok()) << result.status();
  ASSERT_EQ(seen.warnings.size(), 1u);
  EXPECT_EQ(seen.warnings[0], "--overshoot is ignored by --method jacobi");
  EXPECT_EQ(result->warnings, seen.warnings);
  const std::string summary = testing::ReadFile(dir.File("summary.json"));
  EXPECT_THAT(summary, HasSubstr("\"warnings\": [\"--overshoot is ignored by --method jacobi\"]"));

  spec.solve.overshoot = 1;
  Observed quiet;
  result = RunObserved(spec, dir.path(), &quiet);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_TRUE(quiet.warnings.empty());
  EXPECT_THAT(testing::ReadFile(dir.File("summary.json")), HasSubstr("\"warnings\": []"));
}

// The estimated error against time: measured at every snapshot (the error of the solution the
// watchers saw then) and at the end (the result's), in summary.json beside the unshot fraction.
TEST(PipelineTest, TheEstimatedErrorIsRecordedAgainstTime) {
  testing::TempDir dir;
  Observed seen;
  JobSpec spec = SmallJob("progressive", 400);
  spec.solve.tolerance = 1e-4;
  ASSERT_OK_AND_ASSIGN(JobResult result, RunObserved(spec, dir.path(), &seen));
  std::vector<double> measured;
  for (const ConvergencePoint& c : result.convergence) {
    if (!std::isnan(c.std_error_relative)) measured.push_back(c.std_error_relative);
  }
  ASSERT_GE(measured.size(), 3u);
  // Each snapshot's error, then the end's (the last snapshot is the result itself).
  ASSERT_EQ(measured.size(), seen.snapshot_errors.size());
  for (size_t i = 0; i < measured.size(); ++i) {
    EXPECT_EQ(measured[i], seen.snapshot_errors[i]) << i;
    EXPECT_GT(measured[i], 0);
    EXPECT_LT(measured[i], 1);
  }
  const nlohmann::json summary =
      nlohmann::json::parse(testing::ReadFile(dir.File("summary.json")), nullptr, false);
  const auto& series = summary["convergence"]["std_error_rms_relative"];
  ASSERT_EQ(series.size(), result.convergence.size());
  EXPECT_NEAR(series.back().get<double>(), summary["std_error_rms_relative"].get<double>(),
              1e-9 * series.back().get<double>());
}

// Meshing and writing report their progress: meshing from 0 to 1 before the mesh is announced,
// writing from 0 to 1 after the last snapshot, naming each file in the order written, and both
// never going back.
TEST(PipelineTest, MeshingAndWritingReportTheirProgress) {
  testing::TempDir dir;
  Observed seen;
  JobSpec spec = SmallJob("progressive", 20000);  // Faces of many elements: meshing takes steps.
  spec.solve.max_rays = 100000;
  spec.write_image = true;
  spec.write_ply = true;
  spec.width = spec.height = 16;
  ASSERT_OK_AND_ASSIGN(JobResult result, RunObserved(spec, dir.path(), &seen));
  // The order: meshing..., mesh, (snapshots), writing...
  std::vector<std::string> order;
  for (const std::string& e : seen.events) {
    if (order.empty() || order.back() != e) order.push_back(e);
  }
  EXPECT_THAT(order, ::testing::ElementsAre("meshing", "mesh", "snapshot", "writing"));
  std::vector<PhaseProgress> meshing, writing;
  for (const PhaseProgress& p : seen.phases) {
    (p.phase == PhaseProgress::Phase::kMeshing ? meshing : writing).push_back(p);
  }
  for (const auto* phase : {&meshing, &writing}) {
    ASSERT_GE(phase->size(), 3u);
    EXPECT_EQ(phase->front().fraction, 0);
    EXPECT_EQ(phase->back().fraction, 1);
    for (size_t i = 1; i < phase->size(); ++i) {
      EXPECT_GE((*phase)[i].fraction, (*phase)[i - 1].fraction) << i;
    }
  }
  // The mesh's steps and the ray-tracing structure's, not only its ends.
  EXPECT_GE(meshing.size(), 6u);
  std::vector<std::string> named;
  for (const PhaseProgress& p : writing) {
    if (!p.item.empty()) named.push_back(p.item);
  }
  // Every file written, in order; image.png stands for the pair rendered once.
  std::vector<std::string> files;
  for (const std::string& f : result.files) {
    if (f != "image.exr") files.push_back(f);
  }
  EXPECT_EQ(named, files);
  EXPECT_THAT(files, ::testing::Contains("mesh.glb"));
}

TEST(PipelineTest, AnInvalidSpecIsRefusedBeforeMeshing) {
  JobSpec spec;
  spec.refine.max_passes = 0;
  testing::TempDir dir;
  Observed seen;
  absl::StatusOr<JobResult> result = RunObserved(spec, dir.path(), &seen);
  EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(result.status().message()), HasSubstr("--refine-passes"));
  EXPECT_EQ(seen.meshes, 0);
}

}  // namespace
}  // namespace radiosity

namespace radiosity {
namespace {

using ::testing::AllOf;

// --emit (issue 14): light for a model that has none.
TEST(EmitOverrideTest, AMaterialMadeToEmitLightsAClosedBoxToTheFurnaceValue) {
  // A closed unit box of reflectance 0.5 and no emitter; emitting E = 1 everywhere makes it a
  // furnace, B = E / (1 - rho) = 2 on every element.
  const Scene dark =
      testing::MakeClosedBox(1, 1, 1, {"wall", Rgb::Gray(0.5), Rgb(), Rgb(), false, 0});
  JobSpec spec = SmallJob("progressive", 600);
  spec.solve.rays_per_element = 8000;
  testing::TempDir dir;
  absl::StatusOr<JobResult> refused = RunJob(dark, spec, dir.path(), nullptr, {});
  ASSERT_FALSE(refused.ok());
  EXPECT_THAT(refused.status().message(), HasSubstr("--emit NAME=R,G,B"));
  spec.emit = {{"wall", Rgb::Gray(1)}};
  absl::StatusOr<JobResult> lit = RunJob(dark, spec, dir.path(), nullptr, {});
  ASSERT_TRUE(lit.ok()) << lit.status();
  EXPECT_NEAR(lit->solution.emitted_power.g, 6.0, 1e-9);  // Six unit faces.
  for (size_t s = 0; s < lit->solution.radiosity.size(); s += 2) {
    EXPECT_NEAR(lit->solution.radiosity[s].g, 2.0, 0.02) << "element " << s / 2;
  }
}

TEST(EmitOverrideTest, ASurfaceNamedGetsAnEmittingCopyOfItsMaterial) {
  Scene box = testing::MakeClosedBox(2, 1, 1, {"wall", Rgb::Gray(0.5), Rgb(), Rgb(), false, 0});
  ASSERT_TRUE(ApplyEmitOverrides({{"y1", Rgb(1, 2, 3)}}, &box).ok());
  ASSERT_EQ(box.materials.size(), 2u);
  EXPECT_EQ(box.materials[1].name, "wall@y1");
  EXPECT_EQ(box.materials[1].reflectance, Rgb::Gray(0.5));
  EXPECT_FALSE(box.materials[0].IsEmitter());
  // Only the ceiling (2 x 1) emits: power = exitance x its area.
  const Rgb power = EmittedPower(box);
  EXPECT_NEAR(power.r, 2, 1e-12);
  EXPECT_NEAR(power.b, 6, 1e-12);
  // Naming it again replaces the exitance, without another copy.
  ASSERT_TRUE(ApplyEmitOverrides({{"y1", Rgb::Gray(1)}}, &box).ok());
  EXPECT_EQ(box.materials.size(), 2u);
  EXPECT_NEAR(EmittedPower(box).b, 2, 1e-12);
}

TEST(EmitOverrideTest, AnUnknownNameIsRefusedNamingWhatThereIs) {
  Scene box = testing::MakeClosedBox(1, 1, 1, {"wall", Rgb::Gray(0.5), Rgb(), Rgb(), false, 0});
  absl::Status st = ApplyEmitOverrides({{"lamp", Rgb::Gray(1)}}, &box);
  ASSERT_FALSE(st.ok());
  EXPECT_THAT(st.message(), AllOf(HasSubstr("no material or surface is named 'lamp'"),
                                  HasSubstr("materials: wall"), HasSubstr("surfaces: x0, x1")));
  JobSpec spec;
  spec.emit = {{"wall", Rgb(1, -1, 1)}};
  st = ValidateJobSpec(spec, FieldNaming::kFlag);
  ASSERT_FALSE(st.ok());
  EXPECT_THAT(st.message(), AllOf(HasSubstr("--emit"), HasSubstr("wall=1,-1,1")));
}

}  // namespace
}  // namespace radiosity
