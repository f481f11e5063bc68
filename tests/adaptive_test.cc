// Adaptive refinement: it concentrates elements at shadow boundaries, keeps quadtrees balanced,
// leaves no shading cracks at T-vertices, and keeps the furnace exact.
#include "solver/adaptive.h"

#include <gtest/gtest.h>

#include <cmath>

#include "solver/job.h"
#include "solver/output.h"
#include "solver/rng.h"
#include "tests/test_util.h"

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

AdaptiveRun RunAdaptive(const Scene& scene, double start_size, int64_t budget, double tolerance,
                        double rays_per_element) {
  JobSpec spec;
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
  auto result = RunJob(scene, spec, dir.path(), nullptr, observer);
  EXPECT_TRUE(result.ok()) << result.status();
  return {meshes.back(), result->solution, result->passes};
}

TEST(AdaptiveTest, RefinementConcentratesAtTheShadowBoundary) {
  Scene s = ShadowScene();
  AdaptiveRun run = RunAdaptive(s, 1.0, 6000, 0.2, 2000);
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
  AdaptiveRun run = RunAdaptive(s, 1.0, 4000, 0.2, 500);
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

TEST(AdaptiveTest, FurnaceStaysExactAfterRefinement) {
  // A closed furnace with a block in a corner (conforming holes, see hard_cases_test): adaptive
  // refinement splits elements near the block, and every element still has B = E / (1 - rho).
  const double rho = 0.5, L = 4;
  Scene s;
  s.materials.push_back({"furnace", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), false, 0});
  AddRect(&s, "floor", 0, {1, 0, 0}, {0, 0, 1}, {L - 1, 0, 0});
  AddRect(&s, "floor", 0, {0, 0, 1}, {0, 0, L - 1}, {L, 0, 0});
  AddRect(&s, "wall_x0", 0, {0, 1, 0}, {0, L - 1, 0}, {0, 0, 1});
  AddRect(&s, "wall_x0", 0, {0, 0, 1}, {0, L, 0}, {0, 0, L - 1});
  AddRect(&s, "wall_z0", 0, {1, 0, 0}, {L - 1, 0, 0}, {0, 1, 0});
  AddRect(&s, "wall_z0", 0, {0, 1, 0}, {L, 0, 0}, {0, L - 1, 0});
  AddRect(&s, "ceiling", 0, {0, L, 0}, {L, 0, 0}, {0, 0, L});
  AddRect(&s, "wall_x4", 0, {L, 0, 0}, {0, 0, L}, {0, L, 0});
  AddRect(&s, "wall_z4", 0, {0, 0, L}, {0, L, 0}, {L, 0, 0});
  AddRect(&s, "block", 0, {0, 1, 0}, {0, 0, 1}, {1, 0, 0});
  AddRect(&s, "block", 0, {1, 0, 0}, {0, 1, 0}, {0, 0, 1});
  AddRect(&s, "block", 0, {0, 0, 1}, {1, 0, 0}, {0, 1, 0});
  ASSERT_TRUE(ValidateScene(s).ok());
  AdaptiveRun run = RunAdaptive(s, 1.0, 600, 0.05, 5000);
  EXPECT_GT(run.passes, 1);
  ASSERT_EQ(run.solution.hits.size(), run.solution.radiosity.size());
  // B = E + rho H with H = B here, so B's relative standard error is about rho / sqrt(hits);
  // refined elements are smaller and get fewer hits. Every element within 5 of its standard
  // errors (the estimate ignores the correlation between bounces), or 1 % where that is looser:
  // no bias from refinement (a leak or a lost re-gather would show as a few % everywhere).
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

}  // namespace
}  // namespace radiosity
