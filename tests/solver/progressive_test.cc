// Progressive refinement against independent truth (the furnace's closed form, for every method,
// is in furnace_test.cc): conservation of energy, the closed-form view factor of opposed squares,
// determinism, stopping, and shooting with estimated form-factor rows.
#include "solver/methods/progressive.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>

#include "solver/geometry/mesh.h"
#include "solver/input/scene_files.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

using testing::SolvedWorld;
using testing::World;

// Meshes `scene` at `element_size` and solves it with `options`.
absl::StatusOr<SolvedWorld> Solve(const Scene& scene, double element_size,
                                  const SolveOptions& options) {
  MeshOptions mo;
  mo.element_size = element_size;
  return testing::MeshAndSolve(scene, mo, options);
}

TEST(ProgressiveTest, EnergyBalanceOnTheCornellBox) {
  std::vector<std::string> warnings;
  ASSERT_OK_AND_ASSIGN(Scene scene,
                       LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), &warnings));
  SolveOptions opt;
  opt.tolerance = 1e-4;
  opt.rays_per_element = 200;
  ASSERT_OK_AND_ASSIGN(SolvedWorld s, Solve(scene, 60, opt));
  ASSERT_EQ(s.run.reason, StopReason::kConverged);
  const Solution& sol = s.run.solution;
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
  ASSERT_OK_AND_ASSIGN(Scene scene,
                       LoadSceneFile(testing::SourcePath("tests/data/two_squares.json"), nullptr));
  const double exact = testing::OpposedRectangles(1, 1, 1);
  ASSERT_NEAR(exact, 0.199824895698, 1e-11);
  for (uint64_t seed : {1, 2, 3}) {
    SolveOptions opt;
    opt.rays_per_element = 200000;
    opt.seed = seed;
    ASSERT_OK_AND_ASSIGN(SolvedWorld s, Solve(scene, 10, opt));
    ASSERT_EQ(s.world->mesh->elements().size(), 2u);
    const Solution& sol = s.run.solution;
    const double n = static_cast<double>(sol.rays);
    const double f = sol.absorbed_power.Sum() / sol.emitted_power.Sum();
    const double se = std::sqrt(exact * (1 - exact) / n);
    EXPECT_NEAR(f, exact, 4 * se) << "seed " << seed << ", " << n << " rays";
    EXPECT_NEAR(sol.escaped_power.Sum() / sol.emitted_power.Sum(), 1 - f, 1e-10);
  }
}

TEST(ProgressiveTest, SameSeedSameResultWhateverTheThreads) {
  ASSERT_OK_AND_ASSIGN(Scene scene,
                       LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr));
  SolveOptions opt;
  opt.rays_per_element = 100;
  opt.seed = 42;
  opt.threads = 1;
  ASSERT_OK_AND_ASSIGN(SolvedWorld a, Solve(scene, 50, opt));
  opt.threads = 2;
  ASSERT_OK_AND_ASSIGN(SolvedWorld b, Solve(scene, 50, opt));
  const Solution &one = a.run.solution, &two = b.run.solution;
  ASSERT_EQ(one.radiosity.size(), two.radiosity.size());
  EXPECT_EQ(one.rays, two.rays);
  // The defaults: computed direct light, Owen-scrambled Sobol' shooting keyed per patch and shot,
  // so the points a patch takes do not depend on which thread shoots it; the standard errors too.
  ASSERT_EQ(opt.formfactor.sampling, "sobol");
  ASSERT_EQ(one.std_error.size(), one.radiosity.size());
  for (size_t i = 0; i < one.radiosity.size(); ++i) {
    ASSERT_EQ(one.radiosity[i], two.radiosity[i]) << "slot " << i;
    ASSERT_EQ(one.std_error[i], two.std_error[i]) << "slot " << i;
  }
  opt.seed = 43;
  ASSERT_OK_AND_ASSIGN(SolvedWorld c, Solve(scene, 50, opt));
  EXPECT_NE(one.radiosity, c.run.solution.radiosity);
}

// Stopped before its first step measured how open the elements are (a job cancelled, or a server
// shutting down, just as the solve starts): the patch-level estimate has nothing yet, and the
// solution is the emission and the ambient estimate of all the light it will bring, with books
// that balance. (It read the patches' open areas before they existed: a server crashed on
// shutdown.)
TEST(ProgressiveTest, StoppedBeforeTheFirstStepGivesTheEmissionAndTheAmbientTerm) {
  ASSERT_OK_AND_ASSIGN(Scene scene,
                       LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr));
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w,
                       testing::MakeWorld(std::move(scene), MeshOptions()));
  ASSERT_TRUE(PatchesFineEnough(*w->mesh));  // The defaults estimate at the patch level here.
  std::atomic<bool> stop{true};
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Solver> solver,
                       CreateSolver(w->scene, *w->mesh, *w->vis, SolveOptions(), &stop));
  ASSERT_OK_AND_ASSIGN(bool more, solver->Step());
  EXPECT_TRUE(more);
  EXPECT_EQ(solver->Interrupted(), StopReason::kCancelled);
  for (const Solution& s : {solver->Final(), solver->Snapshot()}) {
    testing::ExpectBooksBalance(s);
    ASSERT_EQ(s.radiosity.size(), 2 * w->mesh->elements().size());
    // All the emission is unshot: the ambient radiosity is its bounces spread over the area,
    // sum U / (A (1 - rho_mean)) (Cohen et al. 1988).
    EXPECT_NEAR(s.unshot_power.g, s.emitted_power.g, 1e-12 * s.emitted_power.g);
    double area = 0, rho_area = 0;
    for (size_t slot = 0; slot < s.radiosity.size(); ++slot) {
      const SideRule& rule = w->mesh->sides()[static_cast<int>(slot)];
      if (!rule.exists) continue;
      area += w->mesh->elements()[slot / 2].area;
      rho_area += rule.reflectance.g * w->mesh->elements()[slot / 2].area;
    }
    EXPECT_GT(s.ambient.g, 0);
    const double ambient = s.emitted_power.g / area / (1 - rho_area / area);
    for (size_t slot = 0; slot < s.radiosity.size(); ++slot) {
      const SideRule& rule = w->mesh->sides()[static_cast<int>(slot)];
      if (!rule.exists) continue;
      const double expected = rule.exitance.g + rule.reflectance.g * ambient;
      EXPECT_NEAR(s.radiosity[slot].g, expected, 1e-9 * expected) << "slot " << slot;
    }
  }
}

TEST(ProgressiveTest, StopsOnRayBudgetAndOnTheStopFlag) {
  ASSERT_OK_AND_ASSIGN(Scene scene,
                       LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr));
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, testing::MakeWorld(std::move(scene), 30));
  SolveOptions opt;
  opt.max_rays = 100000;
  opt.tolerance = 1e-9;
  // Shooting steps stop exactly at the budget.
  opt.direct = "shot";
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Solver> solver,
                       CreateSolver(w->scene, *w->mesh, *w->vis, opt, nullptr));
  ASSERT_OK_AND_ASSIGN(StopReason reason, RunSolver(*solver, opt, nullptr, nullptr));
  EXPECT_EQ(reason, StopReason::kMaxRays);
  EXPECT_EQ(solver->progress().rays, opt.max_rays);
  // The direct step's shadow rays count too; it is not cut short, so it may pass the budget.
  opt.direct = "computed";
  opt.max_rays = 1000;
  ASSERT_OK_AND_ASSIGN(solver, CreateSolver(w->scene, *w->mesh, *w->vis, opt, nullptr));
  ASSERT_OK_AND_ASSIGN(reason, RunSolver(*solver, opt, nullptr, nullptr));
  EXPECT_EQ(reason, StopReason::kMaxRays);
  EXPECT_GE(solver->progress().rays, opt.max_rays);
  EXPECT_EQ(solver->progress().step, 1);
  opt.direct = "shot";

  std::atomic<bool> stop{false};
  opt.max_rays = 0;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Solver> solver2,
                       CreateSolver(w->scene, *w->mesh, *w->vis, opt, &stop));
  int steps = 0;
  ASSERT_OK_AND_ASSIGN(reason, RunSolver(*solver2, opt, &stop, [&](const Progress&) {
                         if (++steps == 3) stop = true;
                       }));
  EXPECT_EQ(reason, StopReason::kCancelled);
  EXPECT_EQ(steps, 3);
}

TEST(ProgressiveTest, DefaultsReachTheFurnaceAndTheirErrorsCoverTheTruth) {
  // scenes/furnace.json at the default settings (direct light computed, Sobol' rays, indirect
  // light per patch; the CLI's 4096-element budget): B = E / (1 - rho) = 2 everywhere. Every
  // element within 0.5 % (issue 13's target), the books exact, and the reported standard errors
  // honest: at least 95 % of the elements within 2 of them, their RMS within a factor 2 of the
  // measured RMS (2.25 above it: the computed emitters' emission is booked, not traced, once the
  // direct light is complete, which leaves the measured error about half the reported one), over
  // three seeds.
  ASSERT_OK_AND_ASSIGN(Scene scene,
                       LoadSceneFile(testing::SourcePath("scenes/furnace.json"), nullptr));
  MeshOptions mo;
  mo.max_elements = 4096;
  int within2 = 0, elements = 0;
  for (uint64_t seed : {1, 2, 3}) {
    SolveOptions o;
    o.seed = seed;
    ASSERT_OK_AND_ASSIGN(SolvedWorld r, testing::MeshAndSolve(scene, mo, o));
    const Solution& sol = r.run.solution;
    testing::ExpectBooksBalance(sol);
    ASSERT_EQ(sol.std_error.size(), sol.radiosity.size());
    double sq_err = 0, sq_se = 0;
    for (size_t e = 0; e < r.world->mesh->elements().size(); ++e) {
      const double err = sol.radiosity[2 * e].g - 2, se = sol.std_error[2 * e].g;
      EXPECT_LT(std::fabs(err), 0.01) << "seed " << seed << " element " << e;
      within2 += std::fabs(err) <= 2 * se;
      sq_err += err * err;
      sq_se += se * se;
      ++elements;
    }
    EXPECT_LT(sq_se, 2.25 * 2.25 * sq_err) << "seed " << seed;
    EXPECT_GT(sq_se, sq_err / 4) << "seed " << seed;
  }
  EXPECT_GE(within2, 0.95 * elements);
}

TEST(ProgressiveTest, SceneWithoutEmitterIsRefused) {
  Material m{"grey", Rgb::Gray(0.5), Rgb(), Rgb(), false, 0};
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w,
                       testing::MakeWorld(testing::MakeClosedBox(1, 1, 1, m), MeshOptions()));
  auto solver = CreateSolver(w->scene, *w->mesh, *w->vis, SolveOptions(), nullptr);
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
  SolveOptions opt;
  opt.formfactor.method = GetParam();
  opt.formfactor.shadow_rays = 16;
  opt.formfactor.hemicube_resolution = 64;
  opt.tolerance = 1e-4;
  ASSERT_OK_AND_ASSIGN(SolvedWorld furnace, testing::MeshAndSolve(box, mo, opt));
  const Mesh& mesh = *furnace.world->mesh;
  const Solution& sol = furnace.run.solution;
  double worst = 0, mean = 0, area = 0;
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    double b = sol.radiosity[Slot(static_cast<int>(e), 0)].g * (1 - rho);
    worst = std::max(worst, std::fabs(b - 1));
    mean += b * mesh.elements()[e].area;
    area += mesh.elements()[e].area;
  }
  EXPECT_NEAR(mean / area, 1.0, GetParam() == "hemicube" ? 1e-3 : 0.02);
  EXPECT_LT(worst, 0.25) << GetParam();
  EXPECT_TRUE(sol.hits.empty());

  ASSERT_OK_AND_ASSIGN(Scene cornell,
                       LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr));
  mo.element_size = 100;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, testing::MakeWorld(std::move(cornell), mo));
  SolveOptions mc;
  mc.rays_per_element = 20000;
  mc.tolerance = 1e-3;
  opt.tolerance = 1e-3;
  ASSERT_OK_AND_ASSIGN(testing::SolveRun reference, testing::Solve(*w, mc));
  ASSERT_OK_AND_ASSIGN(testing::SolveRun rows, testing::Solve(*w, opt));
  // Area-weighted mean radiosity per surface within 8 % (the estimators' near-field error on a
  // coarse mesh; Monte Carlo's own noise here is under 1 %).
  const std::vector<Rgb> sa = testing::SurfaceMeans(*w, reference.solution);
  const std::vector<Rgb> sb = testing::SurfaceMeans(*w, rows.solution);
  for (size_t s = 0; s < sa.size(); ++s) {
    EXPECT_NEAR(sb[s].Sum() / sa[s].Sum(), 1.0, 0.08)
        << w->scene.surfaces[s].name << " " << GetParam();
  }
}

INSTANTIATE_TEST_SUITE_P(Estimators, ProgressiveRowsTest, ::testing::Values("analytic", "hemicube"),
                         [](const auto& param_info) { return param_info.param; });

}  // namespace
}  // namespace radiosity
