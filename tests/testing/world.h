// Helpers of the solver tests: a scene with its mesh and visibility (a "world"), a solve of it
// through CreateSolver and RunSolver, and the measurements the tests take of a solution (energy
// books, surface means, the worst deviation from a closed form).
//
// Helpers that can fail return absl::StatusOr; a test asserts on them with ASSERT_OK_AND_ASSIGN
// (tests/testing/test_util.h), so nothing is dereferenced after a failure.
#ifndef RADIOSITY_TESTS_TESTING_WORLD_H_
#define RADIOSITY_TESTS_TESTING_WORLD_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/methods/solver.h"
#include "solver/transport/visibility.h"

namespace radiosity::testing {

// A scene with its mesh and visibility, built in place (the solvers keep references to all
// three, so a World does not move once built).
struct World {
  Scene scene;
  std::unique_ptr<Mesh> mesh;
  std::unique_ptr<Visibility> vis;
};

absl::StatusOr<std::unique_ptr<World>> MakeWorld(Scene scene, const MeshOptions& options);
// Meshed with MeshOptions::element_size = element_size (other options default).
absl::StatusOr<std::unique_ptr<World>> MakeWorld(Scene scene, double element_size);

// scenes/cornell_box.obj meshed to at most `max_elements` elements.
absl::StatusOr<std::unique_ptr<World>> CornellBoxWorld(int64_t max_elements);

// What a solve returned.
struct SolveRun {
  Solution solution;  // Solver::Final().
  StopReason reason = StopReason::kCancelled;
  std::vector<double> fractions;  // progress().unshot_fraction after every step.
};

// Creates the solver of options.method for the world and runs it to its stop (no stop flag).
absl::StatusOr<SolveRun> Solve(const World& world, const SolveOptions& options);

// Meshes `scene` with `mesh_options` and solves it: the world is returned for the caller to look
// at the mesh.
struct SolvedWorld {
  std::unique_ptr<World> world;
  SolveRun run;
};
absl::StatusOr<SolvedWorld> MeshAndSolve(Scene scene, const MeshOptions& mesh_options,
                                         const SolveOptions& options);
// Meshed with MeshOptions::element_size = element_size (other options default).
absl::StatusOr<SolvedWorld> MeshAndSolve(Scene scene, double element_size,
                                         const SolveOptions& options);

// SolveOptions of the default method with these rays per element and tolerance.
SolveOptions Budget(double rays_per_element, double tolerance = SolveOptions().tolerance);

// emitted = absorbed + escaped + unshot per channel, to `relative` of the emitted power, and
// every book finite.
void ExpectBooksBalance(const Solution& solution, double relative = 1e-9);

// Area-weighted mean front radiosity of every surface of the scene.
std::vector<Rgb> SurfaceMeans(const Scene& scene, const Mesh& mesh, const Solution& solution);
std::vector<Rgb> SurfaceMeans(const World& world, const Solution& solution);

// Largest relative deviation |B / expected - 1| over every element's `side` and channel.
double WorstDeviation(const Mesh& mesh, const Solution& solution, double expected, int side = 0);

}  // namespace radiosity::testing

#endif  // RADIOSITY_TESTS_TESTING_WORLD_H_
