// Progressive refinement against independent truth: the furnace closed form, conservation of
// energy, the closed-form view factor of opposed squares, and determinism.
#include "solver/methods/progressive.h"

#include <gtest/gtest.h>

#include <cmath>

#include "solver/geometry/mesh.h"
#include "solver/input/scene_files.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

struct Solved {
  Mesh mesh;
  Solution solution;
  StopReason reason;
};

Solved Solve(const Scene& scene, double element_size, SolveOptions options) {
  MeshOptions mo;
  mo.element_size = element_size;
  auto mesh = Mesh::Build(scene, mo);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  auto vis = Visibility::Build(*mesh);
  EXPECT_TRUE(vis.ok()) << vis.status();
  auto solver = CreateSolver(scene, *mesh, **vis, options, nullptr);
  EXPECT_TRUE(solver.ok()) << solver.status();
  auto reason = RunSolver(**solver, options, nullptr, nullptr);
  EXPECT_TRUE(reason.ok()) << reason.status();
  Solution solution = (*solver)->Snapshot();  // Before the mesh is moved away.
  return {std::move(*mesh), std::move(solution), *reason};
}

// Parallel, directly opposed rectangles a x b at separation c (Howell C-11).
double ParallelRectangles(double a, double b, double c) {
  double x = a / c, y = b / c;
  double x2 = x * x, y2 = y * y;
  return 2 / (kPi * x * y) *
         (std::log(std::sqrt((1 + x2) * (1 + y2) / (1 + x2 + y2))) +
          x * std::sqrt(1 + y2) * std::atan(x / std::sqrt(1 + y2)) +
          y * std::sqrt(1 + x2) * std::atan(y / std::sqrt(1 + x2)) - x * std::atan(x) -
          y * std::atan(y));
}

class ProgressiveFurnaceTest : public ::testing::TestWithParam<bool> {};

TEST_P(ProgressiveFurnaceTest, EveryElementReachesEOverOneMinusRho) {
  // A closed box with uniform reflectance rho and emission E: B = E / (1 - rho) on every element,
  // whatever the mesh (rows of the form-factor matrix sum to 1).
  const double rho = 0.5, e = 1.0;
  Material m{"furnace", Rgb::Gray(rho), Rgb::Gray(e), Rgb(), false, 0};
  Scene scene = testing::MakeClosedBox(1, 1.5, 0.8, m);
  SolveOptions opt;
  opt.tolerance = 1e-5;
  opt.rays_per_element = 40000;
  opt.seed = 11;
  opt.weighted_shooting = GetParam();
  Solved s = Solve(scene, 0.3, opt);
  EXPECT_EQ(s.reason, StopReason::kConverged);
  const double expected = e / (1 - rho);
  double worst = 0;
  for (size_t el = 0; el < s.mesh.elements().size(); ++el) {
    const Rgb& b = s.solution.radiosity[Slot(static_cast<int>(el), 0)];
    for (int c = 0; c < 3; ++c) worst = std::max(worst, std::fabs(b[c] / expected - 1));
  }
  EXPECT_LT(worst, 0.01) << s.mesh.elements().size() << " elements";
  // Closed: nothing escapes (but for rays from within a float's rounding of an edge).
  EXPECT_LT(s.solution.escaped_power.Sum(), 1e-7 * s.solution.emitted_power.Sum());
}

INSTANTIATE_TEST_SUITE_P(Shooting, ProgressiveFurnaceTest, ::testing::Values(true, false),
                         [](const auto& param_info) {
                           return param_info.param ? "Weighted" : "Uniform";
                         });

TEST(ProgressiveTest, EnergyBalanceOnTheCornellBox) {
  std::vector<std::string> warnings;
  auto scene = LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), &warnings);
  ASSERT_TRUE(scene.ok()) << scene.status();
  SolveOptions opt;
  opt.tolerance = 1e-4;
  opt.rays_per_element = 200;
  Solved s = Solve(*scene, 60, opt);
  ASSERT_EQ(s.reason, StopReason::kConverged);
  const Solution& sol = s.solution;
  for (int c = 0; c < 3; ++c) {
    // At convergence: emitted = absorbed + escaped within 0.1 %.
    EXPECT_NEAR(sol.absorbed_power[c] + sol.escaped_power[c], sol.emitted_power[c],
                1e-3 * sol.emitted_power[c]);
    // At any time, exactly (up to rounding): emitted = absorbed + escaped + unshot.
    EXPECT_NEAR(sol.absorbed_power[c] + sol.escaped_power[c] + sol.unshot_power[c],
                sol.emitted_power[c], 1e-9 * sol.emitted_power[c]);
  }
  // The box is open at z = 0: some light must escape, and most is absorbed.
  EXPECT_GT(sol.escaped_power.Sum(), 0.0);
  EXPECT_GT(sol.absorbed_power.Sum(), sol.escaped_power.Sum());
}

TEST(ProgressiveTest, MonteCarloViewFactorOfOpposedSquares) {
  // Two black unit squares at unit distance: the fraction of the emitter's rays reaching the
  // receiver estimates F12 = 0.199824895698 (Howell C-11); a binomial estimate has standard error
  // sqrt(F (1 - F) / n).
  auto scene = LoadSceneFile(testing::SourcePath("tests/data/two_squares.json"), nullptr);
  ASSERT_TRUE(scene.ok()) << scene.status();
  const double exact = ParallelRectangles(1, 1, 1);
  ASSERT_NEAR(exact, 0.199824895698, 1e-11);
  for (uint64_t seed : {1, 2, 3}) {
    SolveOptions opt;
    opt.rays_per_element = 200000;
    opt.seed = seed;
    Solved s = Solve(*scene, 10, opt);
    ASSERT_EQ(s.mesh.elements().size(), 2u);
    const double n = static_cast<double>(s.solution.rays);
    const double f = s.solution.absorbed_power.Sum() / s.solution.emitted_power.Sum();
    const double se = std::sqrt(exact * (1 - exact) / n);
    EXPECT_NEAR(f, exact, 4 * se) << "seed " << seed << ", " << n << " rays";
    EXPECT_NEAR(s.solution.escaped_power.Sum() / s.solution.emitted_power.Sum(), 1 - f, 1e-10);
  }
}

TEST(ProgressiveTest, SameSeedSameResultWhateverTheThreads) {
  auto scene = LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr);
  ASSERT_TRUE(scene.ok());
  SolveOptions opt;
  opt.rays_per_element = 100;
  opt.seed = 42;
  opt.threads = 1;
  Solved a = Solve(*scene, 50, opt);
  opt.threads = 2;
  Solved b = Solve(*scene, 50, opt);
  ASSERT_EQ(a.solution.radiosity.size(), b.solution.radiosity.size());
  EXPECT_EQ(a.solution.rays, b.solution.rays);
  for (size_t i = 0; i < a.solution.radiosity.size(); ++i) {
    ASSERT_EQ(a.solution.radiosity[i], b.solution.radiosity[i]) << "slot " << i;
  }
  opt.seed = 43;
  Solved c = Solve(*scene, 50, opt);
  EXPECT_NE(a.solution.radiosity, c.solution.radiosity);
}

TEST(ProgressiveTest, StopsOnRayBudgetAndOnTheStopFlag) {
  auto scene = LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr);
  ASSERT_TRUE(scene.ok());
  MeshOptions mo;
  mo.element_size = 30;
  auto mesh = Mesh::Build(*scene, mo);
  ASSERT_TRUE(mesh.ok());
  auto vis = Visibility::Build(*mesh);
  ASSERT_TRUE(vis.ok());
  SolveOptions opt;
  opt.max_rays = 100000;
  opt.tolerance = 1e-9;
  auto solver = CreateSolver(*scene, *mesh, **vis, opt, nullptr);
  ASSERT_TRUE(solver.ok());
  auto reason = RunSolver(**solver, opt, nullptr, nullptr);
  ASSERT_TRUE(reason.ok());
  EXPECT_EQ(*reason, StopReason::kMaxRays);
  EXPECT_EQ((*solver)->progress().rays, opt.max_rays);

  std::atomic<bool> stop{false};
  opt.max_rays = 0;
  auto solver2 = CreateSolver(*scene, *mesh, **vis, opt, &stop);
  ASSERT_TRUE(solver2.ok());
  int steps = 0;
  reason = RunSolver(**solver2, opt, &stop, [&](const Progress&) {
    if (++steps == 3) stop = true;
  });
  ASSERT_TRUE(reason.ok());
  EXPECT_EQ(*reason, StopReason::kCancelled);
  EXPECT_EQ(steps, 3);
}

TEST(ProgressiveTest, SceneWithoutEmitterIsRefused) {
  Material m{"grey", Rgb::Gray(0.5), Rgb(), Rgb(), false, 0};
  Scene scene = testing::MakeClosedBox(1, 1, 1, m);
  MeshOptions mo;
  auto mesh = Mesh::Build(scene, mo);
  ASSERT_TRUE(mesh.ok());
  auto vis = Visibility::Build(*mesh);
  ASSERT_TRUE(vis.ok());
  auto solver = CreateSolver(scene, *mesh, **vis, SolveOptions(), nullptr);
  ASSERT_FALSE(solver.ok());
  EXPECT_EQ(solver.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(solver.status().message().find("no emitter"), std::string::npos);
}

}  // namespace
}  // namespace radiosity

namespace radiosity {
namespace {

class ProgressiveRowsTest : public ::testing::TestWithParam<std::string> {};

TEST_P(ProgressiveRowsTest, FurnaceAndCornellAgreeWithMonteCarloShooting) {
  // Shooting with estimated rows (F_pj from the analytic or hemicube estimator) instead of rays.
  // In the furnace, rows that sum to 1 conserve power, so the area-weighted mean radiosity is
  // exact (hemicube rows sum to 1 to rounding; analytic rows to about 1 %); single elements carry
  // the estimator's own near-field error (a hemicube at the centroid sees an adjacent
  // perpendicular element poorly: up to ~20 % at a corner of this coarse mesh).
  const double rho = 0.5;
  Scene box = testing::MakeClosedBox(1, 1, 1, {"f", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), false, 0});
  MeshOptions mo;
  mo.element_size = 0.25;
  mo.patch_depth = 0;
  auto mesh = Mesh::Build(box, mo);
  ASSERT_TRUE(mesh.ok());
  auto vis = Visibility::Build(*mesh);
  ASSERT_TRUE(vis.ok());
  SolveOptions opt;
  opt.formfactor.method = GetParam();
  opt.formfactor.shadow_rays = 16;
  opt.formfactor.hemicube_resolution = 64;
  opt.tolerance = 1e-4;
  auto solver = CreateSolver(box, *mesh, **vis, opt, nullptr);
  ASSERT_TRUE(solver.ok()) << solver.status();
  ASSERT_TRUE(RunSolver(**solver, opt, nullptr, nullptr).ok());
  Solution sol = (*solver)->Final();
  double worst = 0, mean = 0, area = 0;
  for (size_t e = 0; e < mesh->elements().size(); ++e) {
    double b = sol.radiosity[Slot(static_cast<int>(e), 0)].g * (1 - rho);
    worst = std::max(worst, std::fabs(b - 1));
    mean += b * mesh->elements()[e].area;
    area += mesh->elements()[e].area;
  }
  EXPECT_NEAR(mean / area, 1.0, GetParam() == "hemicube" ? 1e-3 : 0.02);
  EXPECT_LT(worst, 0.25) << GetParam();
  EXPECT_TRUE(sol.hits.empty());

  auto cornell = LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr);
  ASSERT_TRUE(cornell.ok());
  mo.element_size = 100;
  auto cmesh = Mesh::Build(*cornell, mo);
  ASSERT_TRUE(cmesh.ok());
  auto cvis = Visibility::Build(*cmesh);
  ASSERT_TRUE(cvis.ok());
  SolveOptions mc;
  mc.rays_per_element = 20000;
  mc.tolerance = 1e-3;
  opt.tolerance = 1e-3;
  auto reference = CreateSolver(*cornell, *cmesh, **cvis, mc, nullptr);
  auto rows = CreateSolver(*cornell, *cmesh, **cvis, opt, nullptr);
  ASSERT_TRUE(reference.ok() && rows.ok());
  ASSERT_TRUE(RunSolver(**reference, mc, nullptr, nullptr).ok());
  ASSERT_TRUE(RunSolver(**rows, opt, nullptr, nullptr).ok());
  Solution a = (*reference)->Final(), b = (*rows)->Final();
  // Area-weighted mean radiosity per surface within 8 % (the estimators' near-field error on a
  // coarse mesh; Monte Carlo's own noise here is under 1 %).
  std::vector<double> sa(cornell->surfaces.size()), sb(cornell->surfaces.size());
  for (size_t e = 0; e < cmesh->elements().size(); ++e) {
    const Element& el = cmesh->elements()[e];
    sa[el.surface] += a.radiosity[Slot(static_cast<int>(e), 0)].Sum() * el.area;
    sb[el.surface] += b.radiosity[Slot(static_cast<int>(e), 0)].Sum() * el.area;
  }
  for (size_t s = 0; s < sa.size(); ++s) {
    EXPECT_NEAR(sb[s] / sa[s], 1.0, 0.08) << cornell->surfaces[s].name << " " << GetParam();
  }
}

INSTANTIATE_TEST_SUITE_P(Estimators, ProgressiveRowsTest, ::testing::Values("analytic", "hemicube"),
                         [](const auto& param_info) { return param_info.param; });

}  // namespace
}  // namespace radiosity
