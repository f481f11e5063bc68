// Adaptive refinement: it concentrates elements at shadow boundaries, keeps quadtrees balanced,
// leaves no shading cracks at T-vertices, and keeps the furnace exact.
#include "solver/methods/adaptive.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "solver/geometry/interpolation.h"
#include "solver/methods/solver.h"
#include "solver/pipeline/job.h"
#include "solver/transport/formfactor.h"
#include "solver/transport/rng.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using testing::AddRect;

// A 10 x 10 floor (y = 0), a small light 0.2 x 0.2 at height 12 facing down over the centre, and
// a 2 x 2 occluder at height 6 (both sides black): the shadow on the floor is the 4 x 4 square
// centred under the light (by similar triangles), with a penumbra 0.2 wide at its edge. Away
// from the shadow the floor's irradiance changes by at most 12 % per unit length.
Scene ShadowScene() {
  Scene s;
  s.materials.push_back({"floor", Rgb::Gray(0.5), Rgb(), Rgb(), false, 0});
  s.materials.push_back({"light", Rgb(), Rgb::Gray(100), Rgb(), false, 0});
  s.materials.push_back({"occluder", Rgb(), Rgb(), Rgb(), false, 0});
  AddRect(&s, "floor", 0, {-5, 0, -5}, {0, 0, 10}, {10, 0, 0});
  AddRect(&s, "light", 1, {-0.1, 12, -0.1}, {0.2, 0, 0}, {0, 0, 0.2});
  AddRect(&s, "occluder", 2, {-1, 6, -1}, {2, 0, 0}, {0, 0, 2});
  return s;
}

struct AdaptiveRun {
  Mesh mesh;
  Solution solution;
  int passes;
};

absl::StatusOr<AdaptiveRun> RunAdaptive(const Scene& scene, double start_size, int64_t budget,
                                        double tolerance, double rays_per_element,
                                        bool resolve = false) {
  JobSpec spec;
  spec.refine.resolve = resolve;
  spec.mesh.element_size = start_size;
  spec.mesh.max_elements = budget;
  spec.refine.tolerance = tolerance;
  spec.solve.rays_per_element = rays_per_element;
  spec.write_image = false;
  spec.write_ply = false;
  std::vector<Mesh> meshes;
  JobObserver observer;
  observer.on_mesh = [&](const Mesh& m) { meshes.push_back(m); };
  testing::TempDir dir;
  absl::StatusOr<JobResult> result = RunJob(scene, spec, dir.path(), nullptr, observer);
  if (!result.ok()) return result.status();
  if (meshes.empty()) return absl::InternalError("RunJob reported no mesh");
  return AdaptiveRun{meshes.back(), result->solution, result->passes};
}

TEST(AdaptiveTest, RefinementConcentratesAtTheShadowBoundary) {
  Scene s = ShadowScene();
  ASSERT_OK_AND_ASSIGN(AdaptiveRun run, RunAdaptive(s, 1.0, 6000, 0.2, 2000));
  ASSERT_GT(run.passes, 1);
  // Element density (elements per unit area) in a band of half-width 0.5 around the shadow's
  // edge (|x| or |z| = 2) against the lit floor beyond 3.5 from the centre.
  double band_area = 0, open_area = 0;
  int band = 0, open = 0;
  for (const Element& e : run.mesh.elements()) {
    if (e.surface != 0) continue;
    double ax = std::fabs(e.centroid.x), az = std::fabs(e.centroid.z);
    double d = std::max(ax, az);
    if (std::fabs(d - 2) < 0.5) {
      ++band;
      band_area += e.area;
    } else if (d > 3.5) {
      ++open;
      open_area += e.area;
    }
  }
  ASSERT_GT(band, 0);
  ASSERT_GT(open, 0);
  double band_density = band / band_area, open_density = open / open_area;
  EXPECT_GT(band_density, 4 * open_density)
      << band << " elements on " << band_area << " vs " << open << " on " << open_area;
  EXPECT_LE(static_cast<int64_t>(run.mesh.elements().size()), 6000);
}

TEST(AdaptiveTest, QuadtreesStayBalancedAndShadingHasNoCracks) {
  Scene s = ShadowScene();
  ASSERT_OK_AND_ASSIGN(AdaptiveRun run, RunAdaptive(s, 1.0, 4000, 0.2, 500));
  const Mesh& mesh = run.mesh;
  // A synthetic field with a distinct value per element, to see any mismatch at shared edges.
  Solution field;
  field.radiosity.resize(2 * mesh.elements().size());
  Rng rng(5);
  for (auto& b : field.radiosity) b = Rgb::Gray(1 + rng.Uniform());
  auto corners = CornerRadiosity(mesh, field);
  auto interpolate = [&](int e, double u, double v) {
    const Element& el = mesh.elements()[e];
    double s0 = (u - el.u0) / (el.u1 - el.u0), t0 = (v - el.v0) / (el.v1 - el.v0);
    const auto& c = corners[Slot(e, 0)];
    return ((c[0] * (1 - s0) + c[1] * s0) * (1 - t0) + (c[2] * (1 - s0) + c[3] * s0) * t0).r;
  };
  int shared_edges = 0, t_junctions = 0;
  for (int e = 0; e < static_cast<int>(mesh.elements().size()); ++e) {
    const Element& el = mesh.elements()[e];
    for (int edge = 0; edge < 4; ++edge) {
      bool along_u = edge < 2;
      double fixed = edge == 0 ? el.v0 : edge == 1 ? el.v1 : edge == 2 ? el.u0 : el.u1;
      double out = (edge == 0 || edge == 2) ? -1e-6 : 1e-6;
      if (fixed + out < 0 || fixed + out > 1) continue;
      for (double t : {0.1, 0.25, 0.5, 0.75, 0.9}) {
        double u = along_u ? el.u0 + t * (el.u1 - el.u0) : fixed;
        double v = along_u ? fixed : el.v0 + t * (el.v1 - el.v0);
        int other =
            along_u ? mesh.FindElement(el.face, u, v + out) : mesh.FindElement(el.face, u + out, v);
        if (other < 0 || other == e) continue;
        const Element& o = mesh.elements()[other];
        // Balanced: the neighbour's edge is at most twice as long as ours, and vice versa.
        double mine = along_u ? el.u1 - el.u0 : el.v1 - el.v0;
        double theirs = along_u ? o.u1 - o.u0 : o.v1 - o.v0;
        ASSERT_LE(theirs, 2 * mine * (1 + 1e-3)) << "element " << e << " edge " << edge;
        t_junctions += theirs != mine;
        ++shared_edges;
        // No crack: both sides interpolate the same value on the shared edge (to the float
        // precision of the element corners, ~1e-6; an unconstrained T-vertex differs by ~0.05).
        EXPECT_NEAR(interpolate(e, u, v), interpolate(other, u, v), 1e-5)
            << "element " << e << " edge " << edge << " t " << t << " rect " << el.u0 << ","
            << el.v0 << "," << el.u1 << "," << el.v1 << " other " << o.u0 << "," << o.v0 << ","
            << o.u1 << "," << o.v1 << " face " << el.face;
      }
    }
  }
  EXPECT_GT(shared_edges, 1000);
  EXPECT_GT(t_junctions, 10);  // The test means something only if the mesh has T-vertices.
}

// Both ways of giving refined elements their values: re-gathering (the default) and re-solving.
class AdaptiveModeTest : public ::testing::TestWithParam<bool> {};
INSTANTIATE_TEST_SUITE_P(Modes, AdaptiveModeTest, ::testing::Values(false, true),
                         [](const auto& param) { return param.param ? "Resolve" : "Regather"; });

TEST(AdaptiveTest, ProgressiveRecordsTheDirectPartOfTheIrradiance) {
  // SolveOptions::track_direct, which re-gathering relies on. ShadowScene's floor sees only the
  // light and a black occluder: all its irradiance is direct. In a closed white box with an
  // emitting ceiling all emitted power lands somewhere first: sum A H_direct = emitted power
  // exactly (every ray's first flight is counted once), and H_direct <= H everywhere.
  for (int scene_index = 0; scene_index < 2; ++scene_index) {
    Scene s;
    if (scene_index == 0) {
      s = ShadowScene();
    } else {
      s.materials.push_back({"white", Rgb::Gray(0.7), Rgb(), Rgb(), false, 0});
      s.materials.push_back({"lamp", Rgb::Gray(0.5), Rgb(2, 1, 0.5), Rgb(), false, 0});
      AddRect(&s, "floor", 0, {0, 0, 0}, {0, 0, 2}, {2, 0, 0});
      AddRect(&s, "ceiling", 1, {0, 2, 0}, {2, 0, 0}, {0, 0, 2});
      AddRect(&s, "x0", 0, {0, 0, 0}, {0, 2, 0}, {0, 0, 2});
      AddRect(&s, "x2", 0, {2, 0, 0}, {0, 0, 2}, {0, 2, 0});
      AddRect(&s, "z0", 0, {0, 0, 0}, {2, 0, 0}, {0, 2, 0});
      AddRect(&s, "z2", 0, {0, 0, 2}, {0, 2, 0}, {2, 0, 0});
    }
    ASSERT_TRUE(ValidateScene(s).ok());
    MeshOptions mo;
    mo.max_elements = 400;
    auto mesh = Mesh::Build(s, mo);
    ASSERT_TRUE(mesh.ok()) << mesh.status();
    auto vis = Visibility::Build(*mesh);
    ASSERT_TRUE(vis.ok()) << vis.status();
    SolveOptions so;
    so.track_direct = true;
    so.rays_per_element = 200;
    auto solver = CreateSolver(s, *mesh, **vis, so, nullptr);
    ASSERT_TRUE(solver.ok()) << solver.status();
    ASSERT_TRUE(RunSolver(**solver, so, nullptr, nullptr).ok());
    const Solution sol = (*solver)->Final();
    ASSERT_EQ(sol.irradiance.size(), sol.radiosity.size());
    ASSERT_EQ(sol.direct_irradiance.size(), sol.radiosity.size());
    Rgb direct_power;
    for (size_t slot = 0; slot < sol.radiosity.size(); ++slot) {
      const Element& e = mesh->elements()[slot / 2];
      for (int c = 0; c < 3; ++c) {
        EXPECT_LE(sol.direct_irradiance[slot][c], sol.irradiance[slot][c] * (1 + 1e-12));
        if (scene_index == 0 && e.surface == 0) {
          EXPECT_NEAR(sol.direct_irradiance[slot][c], sol.irradiance[slot][c],
                      1e-12 * sol.irradiance[slot][c]);
        }
      }
      direct_power += sol.direct_irradiance[slot] * e.area;
    }
    if (scene_index == 1) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(direct_power[c], sol.emitted_power[c], 1e-9 * sol.emitted_power[c]);
      }
    }
  }
}

TEST_P(AdaptiveModeTest, FurnaceStaysExactAfterRefinement) {
  // A closed furnace with a block in a corner (conforming holes, see hard_cases_test): adaptive
  // refinement splits elements near the block, and every element still has B = E / (1 - rho).
  const double rho = 0.5;
  Scene s = testing::CornerBlockFurnace(rho);
  ASSERT_TRUE(ValidateScene(s).ok());
  ASSERT_OK_AND_ASSIGN(AdaptiveRun run, RunAdaptive(s, 1.0, 600, 0.05, 5000, GetParam()));
  EXPECT_GT(run.passes, 1);
  ASSERT_EQ(run.solution.hits.size(), run.solution.radiosity.size());
  // B = E + rho H with H = B here, so B's relative standard error is about rho / sqrt(hits)
  // (re-solved elements are smaller and get fewer hits; re-gathered ones carry the noise, and the
  // hits, of the element they were split from, plus 128 direct samples'). Every element within 5
  // of its standard errors (the estimate ignores the correlation between bounces), or 1 % where
  // that is looser: no bias from refinement (a leak or a lost re-gather would show as a few %
  // everywhere).
  int worst_element = -1;
  double worst = 0;
  for (size_t e = 0; e < run.mesh.elements().size(); ++e) {
    int slot = Slot(static_cast<int>(e), 0);
    double deviation = std::fabs(run.solution.radiosity[slot].g * (1 - rho) - 1);
    double allowed = std::max(0.01, 5 * rho / std::sqrt(std::max(1.0, run.solution.hits[slot])));
    if (deviation / allowed > worst) {
      worst = deviation / allowed;
      worst_element = static_cast<int>(e);
    }
  }
  EXPECT_LT(worst, 1.0) << "element " << worst_element << " of " << run.mesh.elements().size();
}

TEST_P(AdaptiveModeTest, RefinedElementsGetTheDirectLightOfWhereTheyAre) {
  // In ShadowScene the floor sees only the light (the occluder is black, nothing else reflects),
  // so B_floor = rho M F(x -> light) exactly: Lambert's formula where the whole light is seen,
  // 0 in the umbra. Refinement splits elements straddling the shadow's edge; their pieces must
  // get the light of where they are, not the mean of the element they came from.
  Scene s = ShadowScene();
  ASSERT_OK_AND_ASSIGN(AdaptiveRun run, RunAdaptive(s, 1.0, 6000, 0.2, 2000, GetParam()));
  ASSERT_GT(run.passes, 1);
  const double rho = 0.5, m = 100;
  const Vec3 light[4] = {{-0.1, 12, -0.1}, {0.1, 12, -0.1}, {0.1, 12, 0.1}, {-0.1, 12, 0.1}};
  // The light is hidden from x exactly when the occluder (half way up) covers the segment to
  // every light point: |x|, |z| <= 1.9. It is wholly seen when |x| or |z| >= 2.1.
  int lit = 0, dark = 0, lit_near_edge = 0;
  double worst_lit = 0, worst_dark = 0;
  const double b_centre = rho * m * PointToPolygonFormFactor({0, 0, 0}, {0, 1, 0}, light, 4);
  for (size_t i = 0; i < run.mesh.elements().size(); ++i) {
    const Element& e = run.mesh.elements()[i];
    if (e.surface != 0) continue;
    const MeshFace& f = run.mesh.faces()[e.face];
    double x0 = 1e30, x1 = -1e30, z0 = 1e30, z1 = -1e30;
    for (double u : {double{e.u0}, double{e.u1}}) {
      for (double v : {double{e.v0}, double{e.v1}}) {
        const Vec3 p = f.Eval(u, v) + run.mesh.origin();
        x0 = std::min(x0, p.x), x1 = std::max(x1, p.x), z0 = std::min(z0, p.z);
        z1 = std::max(z1, p.z);
      }
    }
    const int slot = Slot(static_cast<int>(i), 0);
    const double b = run.solution.radiosity[slot].g;
    const double in_umbra = std::max({std::fabs(x0), std::fabs(x1), std::fabs(z0), std::fabs(z1)});
    const bool wholly_lit = x0 >= 2.1 || x1 <= -2.1 || z0 >= 2.1 || z1 <= -2.1;
    if (in_umbra <= 1.9) {
      ++dark;
      worst_dark = std::max(worst_dark, b / b_centre);
    } else if (wholly_lit) {
      // The element's mean of rho M F over 8 x 8 points.
      double exact = 0;
      for (int a = 0; a < 8; ++a) {
        for (int c = 0; c < 8; ++c) {
          const Vec3 p{x0 + (a + 0.5) / 8 * (x1 - x0), 0, z0 + (c + 0.5) / 8 * (z1 - z0)};
          exact += rho * m * PointToPolygonFormFactor(p, {0, 1, 0}, light, 4) / 64;
        }
      }
      // The value's relative standard error is about 1 / sqrt(hits) (Monte Carlo shooting; a
      // re-gathered element carries the hits of the element it came from).
      const double allowed = std::max(0.02, 5 / std::sqrt(std::max(1.0, run.solution.hits[slot])));
      worst_lit = std::max(worst_lit, std::fabs(b / exact - 1) / allowed);
      ++lit;
      lit_near_edge +=
          std::min({std::fabs(x0), std::fabs(x1), std::fabs(z0), std::fabs(z1)}) < 2.5 &&
          std::max(std::fabs(x0 + x1), std::fabs(z0 + z1)) / 2 < 2.5;
    }
  }
  ASSERT_GT(dark, 20);
  ASSERT_GT(lit_near_edge, 10);  // Lit elements right beside the penumbra were tested.
  EXPECT_LT(worst_dark, 0.02) << "light in the umbra (fraction of the lit centre's value)";
  EXPECT_LT(worst_lit, 1.0) << "of " << lit << " wholly lit elements";
}

}  // namespace
}  // namespace radiosity
