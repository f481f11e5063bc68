// Meshing: exact areas, the (face, u, v) -> element map, element budgets and slivers.
#include "solver/geometry/mesh.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "solver/transport/rng.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

Scene SinglePolygon(const std::vector<Vec3>& pts) {
  Scene s;
  s.materials.push_back({"m", Rgb::Gray(0.5), Rgb::Gray(1), Rgb(), false, 0});
  s.surfaces.push_back({"poly", 0, 0});
  s.vertices = pts;
  Face f;
  f.surface = 0;
  for (size_t i = 0; i < pts.size(); ++i) f.vertices.push_back(static_cast<int>(i));
  s.faces.push_back(f);
  return s;
}

double TotalArea(const Mesh& mesh) {
  double a = 0;
  for (const Element& e : mesh.elements()) a += e.area;
  return a;
}

TEST(MeshTest, ElementAreasSumToPolygonArea) {
  // A trapezoid (like the Cornell floor), a triangle, and a convex hexagon.
  std::vector<std::vector<Vec3>> polys = {
      {{0, 0, 0}, {552.8, 0, 0}, {549.6, 0, 559.2}, {0, 0, 559.2}},
      {{0, 0, 0}, {3, 0, 0}, {0, 2, 0}},
      {{2, 0, 0}, {1, 1.7, 0}, {-1, 1.7, 0}, {-2, 0, 0}, {-1, -1.7, 0}, {1, -1.7, 0}},
  };
  for (const auto& pts : polys) {
    Scene s = SinglePolygon(pts);
    double exact = PolygonArea(s, s.faces[0]);
    for (double size : {10.0, 0.37, 0.05}) {
      ASSERT_OK_AND_ASSIGN(Mesh mesh, testing::BuildMesh(s, size * (pts.size() == 4 ? 100 : 1)));
      EXPECT_NEAR(TotalArea(mesh), exact, 1e-9 * exact) << pts.size() << " vertices, size " << size;
      double patch_area = 0;
      for (const Patch& p : mesh.patches()) patch_area += p.area;
      EXPECT_NEAR(patch_area, exact, 1e-9 * exact);
    }
  }
}

TEST(MeshTest, CountMatchesBuildAndBudgetIsRespected) {
  Scene s = SinglePolygon({{0, 0, 0}, {3, 0, 0}, {0, 2, 0}});
  for (double size : {1.0, 0.3, 0.07}) {
    ASSERT_OK_AND_ASSIGN(Mesh mesh, testing::BuildMesh(s, size));
    EXPECT_EQ(Mesh::CountElements(s, size, MeshOptions().patch_depth),
              static_cast<int64_t>(mesh.elements().size()));
  }
  Scene box = testing::MakeClosedBox(1, 2, 3, s.materials[0]);
  for (int64_t budget : {6, 100, 1000, 5000}) {
    MeshOptions opt;
    opt.max_elements = budget;
    auto mesh = Mesh::Build(box, opt);
    ASSERT_TRUE(mesh.ok());
    EXPECT_LE(static_cast<int64_t>(mesh->elements().size()), budget);
    // Within a factor 4 of the budget: a halving of the size at most quadruples the count.
    EXPECT_GT(static_cast<int64_t>(mesh->elements().size()) * 4, budget / 2) << budget;
  }
}

TEST(MeshTest, ElementsRespectTargetSizeOnSlivers) {
  // A 1000:1 sliver: elements must not be split along the short side more than needed.
  Scene s = SinglePolygon({{0, 0, 0}, {1000, 0, 0}, {1000, 1, 0}, {0, 1, 0}});
  ASSERT_OK_AND_ASSIGN(Mesh coarse, testing::BuildMesh(s, 10));
  EXPECT_EQ(coarse.elements().size(), 100u);
  ASSERT_OK_AND_ASSIGN(Mesh fine, testing::BuildMesh(s, 0.5));
  EXPECT_EQ(fine.elements().size(), 2000u * 2);
}

TEST(MeshTest, SampledPointsMapBackToTheirElement) {
  // Sample points of every element of a non-planar quad and a triangle; a ray fired at each point
  // along the normal must be found (through Embree's (face, u, v)) in the same element.
  Scene s = SinglePolygon({{0, 0, 0}, {4, 0, 0.2}, {4, 3, 0}, {0, 3, 0}});
  Scene t = SinglePolygon({{0, 0, 0}, {3, 0, 0}, {0.5, 2, 0}});
  for (const Scene* scene : {&s, &t}) {
    ASSERT_OK_AND_ASSIGN(Mesh built, testing::BuildMesh(*scene, 0.3));
    const Mesh* mesh = &built;
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<Visibility> vis, Visibility::Build(*mesh));
    Rng rng(7);
    int mismatches = 0, total = 0;
    for (int e = 0; e < static_cast<int>(mesh->elements().size()); ++e) {
      for (int k = 0; k < 8; ++k) {
        int half, face;
        Vec3 p = mesh->SampleElement(e, rng.Uniform(), rng.Uniform(), rng.Uniform(), &half, &face);
        Vec3 n = mesh->faces()[face].normal[half];
        Hit hit = vis->Intersect(p + n, -n, 0, 2);
        ASSERT_TRUE(hit.valid());
        ++total;
        // Float rounding may move a point lying within 1e-6 of an element edge across it.
        mismatches += mesh->FindElement(hit.face, hit.u, hit.v) != e;
      }
    }
    EXPECT_LE(mismatches, total / 1000 + 1) << "of " << total;
  }
}

TEST(MeshTest, SamplingIsUniformInArea) {
  // On the trapezoid, the fraction of samples of an element falling in its u < mid half equals
  // that half's share of the area (a uniform-in-(u,v) sampler would be biased on
  // non-parallelograms).
  Scene s = SinglePolygon({{0, 0, 0}, {4, 0, 0}, {3, 1, 0}, {1, 1, 0}});
  ASSERT_OK_AND_ASSIGN(Mesh built, testing::BuildMesh(s, 10));
  const Mesh* mesh = &built;
  ASSERT_EQ(mesh->elements().size(), 1u);
  Rng rng(3);
  const int n = 200000;
  int below = 0;
  for (int i = 0; i < n; ++i) {
    int half, face;
    Vec3 p = mesh->SampleElement(0, rng.Uniform(), rng.Uniform(), rng.Uniform(), &half, &face);
    below += (p.y + mesh->origin().y) < 0.5;
  }
  // Area of the trapezoid below y = 0.5: widths 4 -> 3, area 0.5 * (4 + 3) / 2 = 1.75 of 3.
  // But Embree's piecewise-linear quad map makes the surface two triangles (p0,p1,p3), (p2,p3,p1):
  // the exact region is still the same trapezoid (planar), so the share is 1.75 / 3.
  double expected = 1.75 / 3.0;
  double se = std::sqrt(expected * (1 - expected) / n);
  EXPECT_NEAR(static_cast<double>(below) / n, expected, 5 * se);
}

TEST(MeshTest, RejectsHugeMeshesBeforeAllocating) {
  Scene s = SinglePolygon({{0, 0, 0}, {1000, 0, 0}, {1000, 1000, 0}, {0, 1000, 0}});
  EXPECT_TRUE(testing::Refused(testing::BuildMesh(s, 1e-3),  // 10^12 elements
                               absl::StatusCode::kResourceExhausted, {"limit"}));
}

}  // namespace
}  // namespace radiosity
