#include "tests/testing/world.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "solver/geometry/sides.h"
#include "solver/input/scene_files.h"
#include "tests/testing/test_util.h"

namespace radiosity::testing {

absl::StatusOr<std::unique_ptr<World>> MakeWorld(Scene scene, const MeshOptions& options) {
  auto world = std::make_unique<World>();
  world->scene = std::move(scene);
  absl::StatusOr<Mesh> mesh = Mesh::Build(world->scene, options);
  if (!mesh.ok()) return mesh.status();
  world->mesh = std::make_unique<Mesh>(*std::move(mesh));
  absl::StatusOr<std::unique_ptr<Visibility>> vis = Visibility::Build(*world->mesh);
  if (!vis.ok()) return vis.status();
  world->vis = *std::move(vis);
  return world;
}

absl::StatusOr<std::unique_ptr<World>> MakeWorld(Scene scene, double element_size) {
  MeshOptions options;
  options.element_size = element_size;
  return MakeWorld(std::move(scene), options);
}

absl::StatusOr<std::unique_ptr<World>> CornellBoxWorld(int64_t max_elements) {
  absl::StatusOr<Scene> scene = LoadSceneFile(SourcePath("scenes/cornell_box.obj"), nullptr);
  if (!scene.ok()) return scene.status();
  MeshOptions options;
  options.max_elements = max_elements;
  return MakeWorld(*std::move(scene), options);
}

absl::StatusOr<SolveRun> Solve(const World& world, const SolveOptions& options) {
  absl::StatusOr<std::unique_ptr<Solver>> solver =
      CreateSolver(world.scene, *world.mesh, *world.vis, options, nullptr);
  if (!solver.ok()) return solver.status();
  SolveRun run;
  absl::StatusOr<StopReason> reason = RunSolver(**solver, options, nullptr, [&](const Progress& p) {
    run.fractions.push_back(p.unshot_fraction);
  });
  if (!reason.ok()) return reason.status();
  run.reason = *reason;
  run.solution = (*solver)->Final();
  return run;
}

absl::StatusOr<SolvedWorld> MeshAndSolve(Scene scene, const MeshOptions& mesh_options,
                                         const SolveOptions& options) {
  SolvedWorld out;
  absl::StatusOr<std::unique_ptr<World>> world = MakeWorld(std::move(scene), mesh_options);
  if (!world.ok()) return world.status();
  out.world = *std::move(world);
  absl::StatusOr<SolveRun> run = Solve(*out.world, options);
  if (!run.ok()) return run.status();
  out.run = *std::move(run);
  return out;
}

absl::StatusOr<SolvedWorld> MeshAndSolve(Scene scene, double element_size,
                                         const SolveOptions& options) {
  MeshOptions mesh_options;
  mesh_options.element_size = element_size;
  return MeshAndSolve(std::move(scene), mesh_options, options);
}

SolveOptions Budget(double rays_per_element, double tolerance) {
  SolveOptions options;
  options.rays_per_element = rays_per_element;
  options.tolerance = tolerance;
  return options;
}

void ExpectBooksBalance(const Solution& solution, double relative) {
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(solution.absorbed_power[c] + solution.escaped_power[c] + solution.unshot_power[c],
                solution.emitted_power[c], relative * solution.emitted_power[c])
        << "channel " << c;
    EXPECT_TRUE(std::isfinite(solution.absorbed_power[c])) << "channel " << c;
  }
}

std::vector<Rgb> SurfaceMeans(const Scene& scene, const Mesh& mesh, const Solution& solution) {
  std::vector<Rgb> sum(scene.surfaces.size());
  std::vector<double> area(scene.surfaces.size(), 0);
  const auto& elements = mesh.elements();
  for (size_t e = 0; e < elements.size(); ++e) {
    sum[elements[e].surface] += solution.radiosity[Slot(static_cast<int>(e), 0)] * elements[e].area;
    area[elements[e].surface] += elements[e].area;
  }
  for (size_t s = 0; s < sum.size(); ++s) sum[s] = sum[s] / area[s];
  return sum;
}

std::vector<Rgb> SurfaceMeans(const World& world, const Solution& solution) {
  return SurfaceMeans(world.scene, *world.mesh, solution);
}

double WorstDeviation(const Mesh& mesh, const Solution& solution, double expected, int side) {
  double worst = 0;
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    const Rgb& b = solution.radiosity[Slot(static_cast<int>(e), side)];
    for (int c = 0; c < 3; ++c) worst = std::max(worst, std::fabs(b[c] / expected - 1));
  }
  return worst;
}

}  // namespace radiosity::testing
