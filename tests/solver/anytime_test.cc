// Progressive refinement stopped at any point gives a complete answer: the computed direct step
// runs in blocks between shooting steps, and whatever is not yet computed or shot is estimated
// (docs/guide/methods.md). The truth is a furnace's: in a closed enclosure whose
// every face emits E = 1 with reflectance rho = 0.5, B = E / (1 - rho) = 2 wherever light can
// reach, whatever rests where.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "solver/methods/solver.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

constexpr double kRho = 0.5;

// A box [lo, hi] of six one-sided faces facing out, as surface `name`.
void AddBox(Scene* s, const std::string& name, int material, const Vec3& lo, const Vec3& hi) {
  const Vec3 d = hi - lo;
  testing::AddRect(s, name, material, lo, Vec3(0, d.y, 0), Vec3(d.x, 0, 0));  // -z
  testing::AddRect(s, name, material, Vec3(lo.x, lo.y, hi.z), Vec3(d.x, 0, 0), Vec3(0, d.y, 0));
  testing::AddRect(s, name, material, lo, Vec3(0, 0, d.z), Vec3(0, d.y, 0));  // -x
  testing::AddRect(s, name, material, Vec3(hi.x, lo.y, lo.z), Vec3(0, d.y, 0), Vec3(0, 0, d.z));
  testing::AddRect(s, name, material, lo, Vec3(d.x, 0, 0), Vec3(0, 0, d.z));  // -y
  testing::AddRect(s, name, material, Vec3(lo.x, hi.y, lo.z), Vec3(0, 0, d.z), Vec3(d.x, 0, 0));
}

// The furnace room [0,4]x[0,3]x[0,2.5] (z up) with a unit block resting on the floor at
// [1,2]x[1,2] (on element boundaries at element size 0.25) and a slab 0.2 thick and 1.2 long,
// tilted 25 degrees, whose lowest edge rests on the floor and top edge on the wall x = 4: line
// contacts, with wedges of floor and wall beside them.
Scene FurnaceWithResting(double block_offset = 0) {
  Material m;
  m.name = "f";
  m.reflectance = Rgb::Gray(kRho);
  m.emission = Rgb::Gray(1);
  Scene s = testing::MakeClosedBox(4, 3, 2.5, m);
  AddBox(&s, "block", 0, Vec3(1 + block_offset, 1 + block_offset, 0),
         Vec3(2 + block_offset, 2 + block_offset, 1));
  const double a = 25 * M_PI / 180, h = 1.2, t = 0.2, y0 = 0.5, y1 = 2.5;
  const double dx = std::sin(a), dz = std::cos(a), nx = std::cos(a), nz = -std::sin(a);
  const double x0 = 4 - h * dx - t * nx, z0 = t * std::sin(a);
  // The cross-section's corners, counter-clockwise seen from -y (so each side quad below faces
  // out).
  const double sx[4] = {x0, x0 + h * dx, x0 + h * dx + t * nx, x0 + t * nx};
  const double sz[4] = {z0, z0 + h * dz, z0 + h * dz + t * nz, z0 + t * nz};
  for (int k = 0; k < 4; ++k) {
    const int j = (k + 1) % 4;
    testing::AddPolygon(&s, "slab_" + std::to_string(k), 0,
                        {Vec3(sx[k], y0, sz[k]), Vec3(sx[j], y0, sz[j]), Vec3(sx[j], y1, sz[j]),
                         Vec3(sx[k], y1, sz[k])});
  }
  testing::AddPolygon(&s, "slab_y0", 0,
                      {Vec3(sx[3], y0, sz[3]), Vec3(sx[2], y0, sz[2]), Vec3(sx[1], y0, sz[1]),
                       Vec3(sx[0], y0, sz[0])});
  testing::AddPolygon(&s, "slab_y1", 0,
                      {Vec3(sx[0], y1, sz[0]), Vec3(sx[1], y1, sz[1]), Vec3(sx[2], y1, sz[2]),
                       Vec3(sx[3], y1, sz[3])});
  return s;
}

// Elements light can reach: all but the floor under the block and the block's underside.
bool Open(const Mesh& mesh, int e) {
  const Vec3 c = mesh.elements()[e].centroid;
  return !(c.z < 1e-9 && c.x > 1 && c.x < 2 && c.y > 1 && c.y < 2);
}

struct Errors {
  double mean = 0;  // Mean of B / 2 - 1 (a partial sum of the light is far below 0).
  double rms = 0;
  double worst = 0;
};
Errors FurnaceErrors(const Mesh& mesh, const Solution& sol) {
  Errors out;
  int n = 0;
  for (int e = 0; e < static_cast<int>(mesh.elements().size()); ++e) {
    if (!Open(mesh, e)) continue;
    const double d = sol.radiosity[Slot(e, kFront)].g * (1 - kRho) - 1;
    out.mean += d;
    out.rms += d * d;
    out.worst = std::max(out.worst, std::fabs(d));
    ++n;
  }
  out.mean /= n;
  out.rms = std::sqrt(out.rms / n);
  return out;
}

// Every state a solve passes through, stopped after any step, is a complete answer with books
// that balance (the loan of computed direct light ahead of the emission keeps the unshot power
// within the emitted).
TEST(AnytimeTest, EveryStepOfAFurnaceWithRestingBlocksIsACompleteAnswer) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w,
                       testing::MakeWorld(FurnaceWithResting(), 0.25));
  const SolveOptions options = testing::Budget(1000, 1e-3);
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Solver> solver,
                       CreateSolver(w->scene, *w->mesh, *w->vis, options, nullptr));
  int steps = 0, with_direct_pending = 0;
  for (bool more = true; more; ++steps) {
    ASSERT_OK_AND_ASSIGN(more, solver->Step());
    const Progress p = solver->progress();
    if (p.direct_fraction < 1) ++with_direct_pending;
    const Solution sol = solver->Final();
    testing::ExpectBooksBalance(sol, 1e-9);
    EXPECT_LE(sol.unshot_fraction, 1 + 1e-9) << "step " << steps;
    const Errors err = FurnaceErrors(*w->mesh, sol);
    EXPECT_LT(std::fabs(err.mean), 0.02) << "step " << steps << ", direct " << p.direct_fraction;
    EXPECT_LT(err.worst, 0.35) << "step " << steps << ", direct " << p.direct_fraction;
  }
  // The direct light was computed in several blocks, each a step.
  EXPECT_GE(with_direct_pending, 3);
  const Errors done = FurnaceErrors(*w->mesh, solver->Final());
  EXPECT_LT(done.rms, 0.01);
  EXPECT_TRUE(solver->Final().ambient.IsZero());
}

// Stopped by ray budgets (the deadline's deterministic stand-in), the answer is complete at
// every budget and its error falls as the budget grows. (Before anything is shot the answer is
// the ambient term alone, exact in a furnace: the budgets start once the rays' noise has entered.)
TEST(AnytimeTest, ErrorFallsWithTheRayBudget) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w,
                       testing::MakeWorld(FurnaceWithResting(), 0.25));
  std::vector<double> rms;
  for (const int64_t budget : {600'000, 2'000'000, 0}) {  // 0: to convergence.
    SolveOptions options = testing::Budget(1000, 1e-4);
    options.max_rays = budget;
    ASSERT_OK_AND_ASSIGN(testing::SolveRun run, testing::Solve(*w, options));
    EXPECT_EQ(run.reason, budget > 0 ? StopReason::kMaxRays : StopReason::kConverged);
    testing::ExpectBooksBalance(run.solution, 1e-9);
    const Errors err = FurnaceErrors(*w->mesh, run.solution);
    EXPECT_LT(std::fabs(err.mean), 0.02) << budget << " rays";
    rms.push_back(err.rms);
  }
  EXPECT_GT(rms[0], rms[2]);
  EXPECT_LT(rms[2], 0.01);
}

// A ceiling of 1 000 emitting tiles over a grey room: the computed direct light (1 000 faces a
// receiver) comes in blocks between which the solver returns (where the pipeline streams
// snapshots), and the light a snapshot shows midway is complete: the floor's mean near the
// converged answer while most elements still hold their placeholders (a partial sum would show
// the floor without the light not yet computed; the estimate of what is unshot spreads it
// uniformly, and so is off by some per cent until it is shot).
TEST(AnytimeTest, ThousandEmittersAreComputedInBlocksWithCompleteAnswersBetween) {
  Material grey;
  grey.name = "grey";
  grey.reflectance = Rgb::Gray(kRho);
  Scene s = testing::MakeClosedBox(4, 4, 3, grey);
  Material lamp;
  lamp.name = "lamp";
  lamp.emission = Rgb::Gray(10);
  s.materials.push_back(lamp);
  const int lamp_material = static_cast<int>(s.materials.size()) - 1;
  for (int i = 0; i < 40; ++i) {
    for (int j = 0; j < 25; ++j) {
      testing::AddRect(&s, "lamps", lamp_material, Vec3(0.05 + 0.1 * i, 0.06 + 0.16 * j, 2.99),
                       Vec3(0, 0.08, 0), Vec3(0.08, 0, 0));
    }
  }
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w, testing::MakeWorld(std::move(s), 0.5));
  int floor = 0;
  while (w->scene.surfaces[floor].name != "z0") ++floor;
  const SolveOptions options = testing::Budget(200, 1e-3);
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Solver> solver,
                       CreateSolver(w->scene, *w->mesh, *w->vis, options, nullptr));
  std::vector<double> midway;  // Floor means while some of the direct light is computed.
  int blocks = 0;
  for (bool more = true; more;) {
    ASSERT_OK_AND_ASSIGN(more, solver->Step());
    const double direct = solver->progress().direct_fraction;
    if (direct > 0 && direct < 1) {
      ++blocks;
      midway.push_back(testing::SurfaceMeans(*w, solver->Final())[floor].g);
    }
  }
  EXPECT_GE(blocks, 3);
  const double converged = testing::SurfaceMeans(*w, solver->Final())[floor].g;
  ASSERT_GT(converged, 0);
  for (double m : midway) EXPECT_NEAR(m / converged, 1, 0.1);
}

// The block moved off the element grid by 0.1 (elements 0.25): 16 floor elements straddle its
// footprint, each covered by a fraction c found by clipping here, and each one's mean is
// E + rho B (1 - c) = 2 - c (light reaches only the open part). Stopped early, the estimate of
// the light not yet shot reaches only that part too: without it those elements show 2.
TEST(AnytimeTest, StoppedEarlyAPartlyCoveredElementGetsItsOpenShare) {
  constexpr double kOffset = 0.1;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w,
                       testing::MakeWorld(FurnaceWithResting(kOffset), 0.25));
  SolveOptions options = testing::Budget(1000, 1e-4);
  options.max_rays = 600'000;
  ASSERT_OK_AND_ASSIGN(testing::SolveRun run, testing::Solve(*w, options));
  ASSERT_EQ(run.reason, StopReason::kMaxRays);
  ASSERT_GT(run.solution.unshot_fraction, 0.1);  // Much of the light is the estimate's.
  double sq = 0;
  int n = 0;
  for (int e = 0; e < static_cast<int>(w->mesh->elements().size()); ++e) {
    const Element& el = w->mesh->elements()[e];
    if (w->scene.surfaces[el.surface].name != "z0" || el.centroid.z > 1e-9) continue;
    const double h = std::sqrt(el.area) / 2;
    const double lo = 1 + kOffset, hi = 2 + kOffset;
    const double cx =
        std::max(0.0, std::min(el.centroid.x + h, hi) - std::max(el.centroid.x - h, lo));
    const double cy =
        std::max(0.0, std::min(el.centroid.y + h, hi) - std::max(el.centroid.y - h, lo));
    const double c = cx * cy / el.area;
    if (!(c > 1e-6 && c < 1 - 1e-6)) continue;
    const double d = run.solution.radiosity[Slot(e, kFront)].g / (2 - c) - 1;
    sq += d * d;
    ++n;
  }
  ASSERT_EQ(n, 16);  // The ring of 5 x 5 elements about the 3 x 3 wholly covered.
  EXPECT_LT(std::sqrt(sq / n), 0.05);
}

}  // namespace
}  // namespace radiosity
