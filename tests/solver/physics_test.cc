// Physics beyond plain progressive shooting: diffuse transmission, sensor irradiance by final
// gather, ambient previews and overshooting, each against a closed form or a conservation law.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <memory>

#include "solver/geometry/mesh.h"
#include "solver/input/sensors_file.h"
#include "solver/methods/progressive.h"
#include "solver/transport/formfactor.h"
#include "solver/transport/gather.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

// Opposed unit squares at unit distance (Howell C-11).
constexpr double kOpposedUnitSquares = 0.199824895698;
// Point under the corner of a unit square at distance 1 (Howell B-3 / Lambert's formula).
constexpr double kPointUnderCorner = 0.138531605995;

// A unit square in the plane z = `z`, facing +z (up) or -z.
void AddSquare(Scene* s, const std::string& name, int material, double z, bool up) {
  int base = static_cast<int>(s->vertices.size());
  s->vertices.push_back({0, 0, z});
  s->vertices.push_back({1, 0, z});
  s->vertices.push_back({1, 1, z});
  s->vertices.push_back({0, 1, z});
  s->surfaces.push_back({name, material, 0});
  Face f;
  f.surface = static_cast<int>(s->surfaces.size()) - 1;
  f.vertices = up ? std::vector<int>{base, base + 1, base + 2, base + 3}
                  : std::vector<int>{base, base + 3, base + 2, base + 1};
  s->faces.push_back(f);
}

// A scene meshed at `element_size`, and its solver, not yet run.
struct Prepared {
  std::unique_ptr<testing::World> world;
  std::unique_ptr<Solver> solver;
};

absl::StatusOr<Prepared> Prepare(const Scene& scene, double element_size, const SolveOptions& opt) {
  Prepared run;
  absl::StatusOr<std::unique_ptr<testing::World>> world = testing::MakeWorld(scene, element_size);
  if (!world.ok()) return world.status();
  run.world = *std::move(world);
  absl::StatusOr<std::unique_ptr<Solver>> solver =
      CreateSolver(run.world->scene, *run.world->mesh, *run.world->vis, opt, nullptr);
  if (!solver.ok()) return solver.status();
  run.solver = *std::move(solver);
  return run;
}

TEST(TransmissionTest, SheetPassesItsShareOutOfItsBack) {
  // Emitter (E = 1, black) at z = 0 facing up; a sheet at z = 1 facing down with Tf = t, Kd = 0.
  // The sheet's front receives E F power (F of opposed unit squares); its back re-emits t of it,
  // so the area-integrated radiosity of its back is t E F and of its front 0.
  const double t = 0.6;
  Scene s;
  s.materials.push_back({"light", Rgb(), Rgb::Gray(1), Rgb(), false, 0});
  s.materials.push_back({"sheet", Rgb(), Rgb(), Rgb(t, t / 2, 0), false, 0});
  AddSquare(&s, "emitter", 0, 0, true);
  AddSquare(&s, "sheet", 1, 1, false);
  const SolveOptions opt = testing::Budget(50000, 1e-6);
  ASSERT_OK_AND_ASSIGN(Prepared run, Prepare(s, 0.25, opt));
  ASSERT_TRUE(RunSolver(*run.solver, opt, nullptr, nullptr).ok());
  Solution sol = run.solver->Final();
  Rgb back, front;
  for (size_t e = 0; e < run.world->mesh->elements().size(); ++e) {
    const Element& el = run.world->mesh->elements()[e];
    if (el.surface != 1) continue;
    back += sol.radiosity[Slot(static_cast<int>(e), 1)] * el.area;
    front += sol.radiosity[Slot(static_cast<int>(e), 0)] * el.area;
  }
  const double n = static_cast<double>(sol.rays);
  // The emitter's rays are binomial trials with p = F; the transmitted share scales it.
  const double se = std::sqrt(kOpposedUnitSquares * (1 - kOpposedUnitSquares) / (n / 2));
  EXPECT_NEAR(back.r, t * kOpposedUnitSquares, 4 * t * se + 1e-9);
  EXPECT_NEAR(back.g, t / 2 * kOpposedUnitSquares, 4 * t / 2 * se + 1e-9);
  EXPECT_EQ(back.b, 0.0);
  EXPECT_EQ(front.Sum(), 0.0);
  // Conservation: what the sheet passes on leaves the scene.
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(sol.absorbed_power[c] + sol.escaped_power[c] + sol.unshot_power[c],
                sol.emitted_power[c], 1e-9);
  }
}

TEST(SensorTest, PointUnderTheCornerOfAnEmittingSquare) {
  // A unit square at height 1 emitting M = 3 W/m^2 downwards; a sensor under its corner facing up
  // receives E = M F(dA -> square) = 3 x 0.138531605995 (Lambert's contour formula), computed
  // exactly: nothing blocks it, and nothing else reflects.
  Scene s;
  s.materials.push_back({"light", Rgb(), Rgb(3, 2, 1), Rgb(), false, 0});
  AddSquare(&s, "light", 0, 1, false);
  SolveOptions opt;
  opt.rays_per_element = 10;
  ASSERT_OK_AND_ASSIGN(Prepared run, Prepare(s, 0.1, opt));
  ASSERT_TRUE(RunSolver(*run.solver, opt, nullptr, nullptr).ok());
  std::vector<SensorPoint> sensors = {
      {{0, 0, 0}, {0, 0, 1}}, {{0.5, 0.5, 0}, {0, 0, 1}}, {{0.5, 0.5, 2}, {0, 0, 1}}};
  const SensorIrradiance g = GatherIrradiance(s, *run.world->mesh, *run.world->vis,
                                              run.solver->Final(), sensors, GatherOptions());
  ASSERT_TRUE(g.complete);
  const std::vector<Rgb>& e = g.irradiance;
  ASSERT_EQ(e.size(), 3u);
  EXPECT_NEAR(e[0].r, 3 * kPointUnderCorner, 1e-9 * 3 * kPointUnderCorner);
  EXPECT_NEAR(e[0].b, 1 * kPointUnderCorner, 1e-9 * kPointUnderCorner);
  EXPECT_EQ(g.std_error[0].r, 0);
  // Under the centre: four quarter squares of 0.5 x 0.5 at height 1, each a corner case with
  // X = Y = 0.5: F = (1/2pi)[X/sqrt(1+X^2) atan(Y/sqrt(1+X^2)) + Y/sqrt(1+Y^2)
  // atan(X/sqrt(1+Y^2))].
  const double x = 0.5, a = x / std::sqrt(1 + x * x);
  const double quarter = (1 / (2 * kPi)) * (2 * a * std::atan(a));
  EXPECT_NEAR(e[1].r, 3 * 4 * quarter, 1e-9 * 3 * 4 * quarter);
  // Above the emitter, facing up: it sees nothing.
  EXPECT_EQ(e[2].Sum(), 0.0);
}

TEST(SensorTest, InsideAnIsothermalEnclosureEverySensorReadsItsRadiosity) {
  // A closed box whose walls all emit M = 1 and have radiosity B = 2 (given, not solved): the
  // irradiance at any point inside, facing anywhere, is exactly B. The direct part computes the
  // emitters' M (form factors of a closed box sum to 1), the gather their B - M: no sample
  // differs from another, so the standard error is 0.
  Material m{"wall", Rgb::Gray(0.5), Rgb::Gray(1), Rgb(), false, 0};
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w,
                       testing::MakeWorld(testing::MakeClosedBox(2, 1, 3, m), 0.25));
  Solution sol;
  sol.radiosity.assign(2 * w->mesh->elements().size(), Rgb());
  for (size_t e = 0; e < w->mesh->elements().size(); ++e) sol.radiosity[2 * e] = Rgb::Gray(2);
  const std::vector<SensorPoint> sensors = {{{1, 0.5, 1.5}, {0, 0, 1}},
                                            {{0.1, 0.9, 0.2}, Normalize(Vec3(1, -2, 3))},
                                            {{1.9, 0.05, 2.9}, {0, 1, 0}}};
  GatherOptions go;
  go.samples = 256;
  const SensorIrradiance g = GatherIrradiance(w->scene, *w->mesh, *w->vis, sol, sensors, go);
  for (size_t i = 0; i < sensors.size(); ++i) {
    EXPECT_NEAR(g.irradiance[i].g, 2, 2e-6) << i;
    EXPECT_LT(g.std_error[i].g, 1e-9) << i;
  }
}

TEST(SensorTest, PastAnObstructionWithinItsStandardErrors) {
  // HalfBlockedSquaresScene with its top emitting: a point of the bottom's half x < 0.5 sees
  // exactly the top's half x < 0.5 (the wall at x = 0.5 stands between), so its irradiance is
  // Lambert's formula for that half. Only the visible fraction is estimated (shadow rays from
  // 8 replicated scrambled sequences): within 0.2 % at the default settings, and within the
  // reported standard errors (a t distribution with 7 degrees of freedom).
  Scene s = testing::HalfBlockedSquaresScene();
  s.materials.push_back({"lamp", Rgb(), Rgb::Gray(1), Rgb(), false, 0});
  s.surfaces[1].material = 1;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w, testing::MakeWorld(s, 0.125));
  std::vector<SensorPoint> sensors;
  for (int i = 0; i < 10; ++i) {
    for (int j = 0; j < 10; ++j)
      sensors.push_back({{0.025 + 0.05 * i, 0.05 + 0.1 * j, 0}, {0, 0, 1}});
  }
  Solution sol;  // Nothing reflects: the radiosity is the emission.
  sol.radiosity.assign(2 * w->mesh->elements().size(), Rgb());
  for (size_t e = 0; e < w->mesh->elements().size(); ++e) {
    sol.radiosity[2 * e] = w->mesh->sides().at(static_cast<int>(e), kFront).exitance;
  }
  const SensorIrradiance g =
      GatherIrradiance(w->scene, *w->mesh, *w->vis, sol, sensors, GatherOptions());
  const Vec3 half[4] = {{0, 0, 1}, {0.5, 0, 1}, {0.5, 1, 1}, {0, 1, 1}};
  int within2 = 0;
  for (size_t k = 0; k < sensors.size(); ++k) {
    const double exact = PointToPolygonFormFactor(sensors[k].p, {0, 0, 1}, half, 4);
    const double error = std::fabs(g.irradiance[k].r - exact);
    EXPECT_LT(error, 0.002 * exact) << k;
    EXPECT_LE(error, 8 * g.std_error[k].r + 1e-12) << k;
    within2 += error <= 2 * g.std_error[k].r + 1e-12;
  }
  EXPECT_GE(within2, 80);
}

TEST(SensorTest, StopsWhenAsked) {
  Material m{"wall", Rgb::Gray(0.5), Rgb::Gray(1), Rgb(), false, 0};
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w,
                       testing::MakeWorld(testing::MakeClosedBox(1, 1, 1, m), 0.25));
  Solution sol;
  sol.radiosity.assign(2 * w->mesh->elements().size(), Rgb::Gray(2));
  std::vector<SensorPoint> sensors(1000, {{0.5, 0.5, 0.5}, {0, 0, 1}});
  std::atomic<bool> stop{true};
  const SensorIrradiance g = GatherIrradiance(w->scene, *w->mesh, *w->vis, sol, sensors,
                                              GatherOptions(), StopToken(&stop, 0));
  EXPECT_FALSE(g.complete);
  EXPECT_EQ(g.rays, 0);
}

TEST(SensorTest, ParsesRtraceFormatAndNamesBadLines) {
  auto ok = ParseSensors("# x y z nx ny nz\n1 2 3 0 0 2\n\n4 5 6 1 0 0\n", "s.txt");
  ASSERT_TRUE(ok.ok()) << ok.status();
  ASSERT_EQ(ok->size(), 2u);
  EXPECT_EQ((*ok)[0].n, Vec3(0, 0, 1));
  auto bad = ParseSensors("1 2 3 0 0 1\n1 2 3 0 0\n", "s.txt");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("s.txt:2"), std::string::npos) << bad.status();
  bad = ParseSensors("1 2 x 0 0 1\n", "s.txt");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("'x'"), std::string::npos) << bad.status();
  bad = ParseSensors("1 2 3 0 0 0\n", "s.txt");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("zero length"), std::string::npos) << bad.status();

  // Named grids: "# grid: NAME" puts the points after it in NAME; other comments do not.
  auto grids = ParseSensors(
      "1 2 3 0 0 1\n# grid: desk-1\n1 2 3 0 0 1\n# a comment\n1 2 3 0 0 1\n#grid: floor\n"
      "1 2 3 0 0 1\n",
      "s.txt");
  ASSERT_TRUE(grids.ok()) << grids.status();
  ASSERT_EQ(grids->size(), 4u);
  EXPECT_EQ((*grids)[0].grid, "");
  EXPECT_EQ((*grids)[1].grid, "desk-1");
  EXPECT_EQ((*grids)[2].grid, "desk-1");
  EXPECT_EQ((*grids)[3].grid, "floor");
  for (const char* name : {"a,b", "", "x y", "\xc3\xa9"}) {
    bad = ParseSensors(absl::StrCat("# grid: ", name, "\n1 2 3 0 0 1\n"), "s.txt");
    ASSERT_FALSE(bad.ok()) << name;
    EXPECT_NE(bad.status().message().find("s.txt:1: grid name"), std::string::npos) << bad.status();
  }
}

// Furnace helpers: closed box, uniform rho and E = 1, so B = 1 / (1 - rho).
double WorstFurnaceError(const Mesh& mesh, const Solution& sol, double rho) {
  double worst = 0;
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    const Rgb& b = sol.radiosity[Slot(static_cast<int>(e), 0)];
    worst = std::max(worst, std::fabs(b.g * (1 - rho) - 1));
  }
  return worst;
}

// Before convergence a solution is completed by the ambient term, which in a furnace of one
// reflectance is exact: after three steps, with most of the light not yet propagated (the
// propagated part alone is more than 20 % short of B = E / (1 - rho)), every element is close to
// the closed form; a converged solution has no ambient term.
TEST(AmbientTest, CompletesSolutionsBeforeConvergenceOnly) {
  const double rho = 0.8;
  Scene s = testing::MakeClosedBox(1, 1, 1, {"f", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), false, 0});
  const SolveOptions options = testing::Budget(2000, 1e-4);
  ASSERT_OK_AND_ASSIGN(Prepared run, Prepare(s, 0.25, options));
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(run.solver->Step().ok());
  for (const Solution& sol : {run.solver->Snapshot(), run.solver->Final()}) {
    testing::ExpectBooksBalance(sol, 1e-9);
    ASSERT_GT(sol.ambient.g, 0);
    // The propagated part: what the ambient term added taken away.
    Solution propagated = sol;
    for (Rgb& b : propagated.radiosity) b -= Rgb::Gray(rho) * sol.ambient;
    EXPECT_GT(WorstFurnaceError(*run.world->mesh, propagated, rho), 0.2);
    EXPECT_LT(WorstFurnaceError(*run.world->mesh, sol, rho), 0.02);
  }
  ASSERT_OK_AND_ASSIGN(StopReason reason, RunSolver(*run.solver, options, nullptr, nullptr));
  ASSERT_EQ(reason, StopReason::kConverged);
  EXPECT_TRUE(run.solver->Final().ambient.IsZero());
  EXPECT_EQ(run.solver->Final().radiosity, run.solver->Snapshot().radiosity);
}

TEST(OvershootTest, ConvergesToTheFurnaceAnswerWithExactBooks) {
  const double rho = 0.9;
  Scene s = testing::MakeClosedBox(1, 1, 1, {"f", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), false, 0});
  SolveOptions opt = testing::Budget(4000, 1e-4);
  opt.overshoot = 1.5;
  ASSERT_OK_AND_ASSIGN(Prepared run, Prepare(s, 0.5, opt));
  auto reason = RunSolver(*run.solver, opt, nullptr, nullptr);
  ASSERT_TRUE(reason.ok());
  EXPECT_EQ(*reason, StopReason::kConverged);
  Solution sol = run.solver->Final();
  EXPECT_LT(WorstFurnaceError(*run.world->mesh, sol, rho), 0.03);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(sol.absorbed_power[c] + sol.escaped_power[c] + sol.unshot_power[c],
                sol.emitted_power[c], 1e-9 * sol.emitted_power[c]);
  }
}

}  // namespace
}  // namespace radiosity
