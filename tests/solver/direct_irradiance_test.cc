// Direct light computed, not sampled (direct_irradiance.h, area_to_polygon.h), against closed
// forms: Howell's and Ehlert & Smith's form factors for the unoccluded parts (to 1e-6 relative,
// also beside a shared edge, where the kernel is singular), a closed box whose walls all emit
// (every element receives exactly M), and a plane blocker whose shadow is computable by clipping
// (within four of the reported standard errors).
#include "solver/transport/direct_irradiance.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "solver/geometry/rect_sampler.h"
#include "solver/input/scene_files.h"
#include "solver/transport/area_to_polygon.h"
#include "solver/transport/formfactor.h"
#include "solver/transport/rng.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

using testing::MakeWorld;
using testing::World;

SpacePolygon Quad(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d) {
  SpacePolygon p;
  p.n = 4;
  p.v = {a, b, c, d};
  p.normal = Normalize(Cross(b - a, d - a));
  return p;
}

TEST(AreaToPolygonTest, OpposedSquaresMatchHowellC11) {
  // Receiver z = 0 facing +z; emitter z = c facing -z.
  for (double c : {0.1, 1.0, 5.0}) {
    const SpacePolygon rec = Quad({0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0});
    const SpacePolygon em = Quad({0, 0, c}, {0, 1, c}, {1, 1, c}, {1, 0, c});
    const AreaFormFactor f = AreaToPolygon({rec}, 1.0, em);
    EXPECT_NEAR(f.front, testing::OpposedRectangles(1, 1, c),
                1e-6 * testing::OpposedRectangles(1, 1, c))
        << "c = " << c << ", " << f.evaluations << " evaluations";
    EXPECT_EQ(f.back, 0);
  }
}

TEST(AreaToPolygonTest, OpposedSliversMatchHowellC11) {
  // 1000:1 rectangles one width apart: the kernel varies on the short side's scale along the
  // long one, so the refinement must reach well-shaped pieces (bisection of the longest edge).
  const SpacePolygon rec = Quad({0, 0, 0}, {1000, 0, 0}, {1000, 1, 0}, {0, 1, 0});
  const SpacePolygon em = Quad({0, 0, 1}, {0, 1, 1}, {1000, 1, 1}, {1000, 0, 1});
  const AreaFormFactor f = AreaToPolygon({rec}, 1000.0, em);
  const double exact = testing::OpposedRectangles(1000, 1, 1);
  EXPECT_NEAR(f.front, exact, 1e-5 * exact) << f.evaluations << " evaluations";
}

TEST(AreaToPolygonTest, PerpendicularSquaresSharingAnEdgeMatchHowellC14) {
  // Floor [0,1]^2 at z = 0 facing +z; wall x = 0 facing +x: they share the edge x = z = 0. The
  // point-to-polygon factor tends to 1/2 at the edge with an infinite slope.
  const SpacePolygon floor = Quad({0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0});
  const SpacePolygon wall = Quad({0, 0, 0}, {0, 1, 0}, {0, 1, 1}, {0, 0, 1});
  ASSERT_GT(wall.normal.x, 0);
  const AreaFormFactor f = AreaToPolygon({floor}, 1.0, wall);
  const double exact = testing::PerpendicularRectangles(1, 1, 1);
  EXPECT_NEAR(f.front, exact, 1e-6 * exact);
  // Strips of the floor beside the edge, [0, d] and [d, 2d] (superposition of C-14).
  for (double d : {1e-3, 0.05, 0.25}) {
    const SpacePolygon strip = Quad({0, 0, 0}, {d, 0, 0}, {d, 1, 0}, {0, 1, 0});
    const double near = testing::PerpendicularRectangles(1, d, 1);
    EXPECT_NEAR(AreaToPolygon({strip}, d, wall).front, near, 1e-6 * near) << d;
    const SpacePolygon next = Quad({d, 0, 0}, {2 * d, 0, 0}, {2 * d, 1, 0}, {d, 1, 0});
    const double far = (2 * d * testing::PerpendicularRectangles(1, 2 * d, 1) - d * near) / d;
    EXPECT_NEAR(AreaToPolygon({next}, d, wall).front, far, 1e-6 * far) << d;
  }
}

TEST(AreaToPolygonTest, ParallelRectanglesInGeneralPositionMatchEhlertAndSmith) {
  const SpacePolygon rec = Quad({0.2, -0.3, 0}, {0.9, -0.3, 0}, {0.9, 0.4, 0}, {0.2, 0.4, 0});
  const SpacePolygon em = Quad({1, 0, 0.5}, {1, 2, 0.5}, {3, 2, 0.5}, {3, 0, 0.5});
  const double exact = testing::ParallelRectangles(0.2, 0.9, -0.3, 0.4, 1, 3, 0, 2, 0.5);
  EXPECT_NEAR(AreaToPolygon({rec}, 0.49, em).front, exact, 1e-6 * exact);
}

TEST(AreaToPolygonTest, OnlyThePartInFrontOfEachSideCounts) {
  // An emitter standing across the receiver's plane: a vertical square x = 2 facing -x, z in
  // [-1, 1]. The front (+z) sees its upper half, the back its lower half, equally.
  const SpacePolygon rec = Quad({0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0});
  const SpacePolygon em = Quad({2, 0, -1}, {2, 0, 1}, {2, 1, 1}, {2, 1, -1});
  ASSERT_LT(em.normal.x, 0);
  const AreaFormFactor f = AreaToPolygon({rec}, 1.0, em);
  // Receiver [0,1]^2 at distance 1..2 from the wall: the upper half is a perpendicular
  // rectangle problem by superposition: F([0,2] strip) - F([1,2] strip) in C-14 terms.
  const double exact = (2 * testing::PerpendicularRectangles(1, 2, 1) -
                        1 * testing::PerpendicularRectangles(1, 1, 1));
  EXPECT_NEAR(f.front, exact, 1e-6 * exact);
  EXPECT_NEAR(f.back, exact, 1e-6 * exact);
}

// A material that emits M (one-sided, black).
Material Emitter(double m) {
  Material mat;
  mat.name = "lamp";
  mat.emission = Rgb::Gray(m);
  return mat;
}

TEST(DirectIrradianceTest, ClosedBoxWhoseWallsAllEmitGivesMEverywhere) {
  // Sum of the form factors from any element to the rest of a closed box is 1, corners and
  // edges included, so each element receives exactly M from the six emitting walls.
  Material m = Emitter(1);
  m.reflectance = Rgb::Gray(0.5);
  MeshOptions mo;
  mo.max_elements = 600;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, MakeWorld(testing::MakeClosedBox(1, 2, 3, m), mo));
  DirectIrradiance direct(*w->mesh, *w->vis, DirectOptions(), 600);
  ASSERT_EQ(direct.emitters().size(), 6u);
  const DirectElements d = direct.ForElements(StopToken());
  ASSERT_TRUE(d.complete);
  double worst = 0;
  for (size_t e = 0; e < w->mesh->elements().size(); ++e) {
    worst = std::max(worst, std::fabs(d.irradiance[Slot(static_cast<int>(e), kFront)].r - 1));
    EXPECT_EQ(d.irradiance[Slot(static_cast<int>(e), kBack)].r, 0);
    EXPECT_EQ(d.std_error[Slot(static_cast<int>(e), kFront)].r, 0);
    EXPECT_EQ(d.penumbra[e], 0);
  }
  EXPECT_LT(worst, 2e-6);
}

// Element e's rectangle in scene coordinates (x range, y range) on a face in the plane z = 0.
void ElementRect(const Mesh& mesh, int e, double* x0, double* x1, double* y0, double* y1) {
  const Element& el = mesh.elements()[e];
  const MeshFace& f = mesh.faces()[el.face];
  const Vec3 a = f.Eval(el.u0, el.v0) + mesh.origin(), b = f.Eval(el.u1, el.v1) + mesh.origin();
  *x0 = std::min(a.x, b.x);
  *x1 = std::max(a.x, b.x);
  *y0 = std::min(a.y, b.y);
  *y1 = std::max(a.y, b.y);
}

TEST(DirectIrradianceTest, ElementsUnderAnOpposedEmitterMatchEhlertAndSmith) {
  Scene s = testing::OpposedRectanglesScene(1, 1, 0.5);
  s.materials.push_back(Emitter(3));
  s.surfaces[1].material = 1;  // "top" emits 3 W/m^2 downwards.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, MakeWorld(s, 0.1));
  DirectIrradiance direct(*w->mesh, *w->vis, DirectOptions(), 1000);
  const DirectElements d = direct.ForElements(StopToken());
  int checked = 0;
  for (int e = 0; e < static_cast<int>(w->mesh->elements().size()); ++e) {
    if (w->mesh->elements()[e].surface != 0) continue;
    double x0, x1, y0, y1;
    ElementRect(*w->mesh, e, &x0, &x1, &y0, &y1);
    const double exact = 3 * testing::ParallelRectangles(x0, x1, y0, y1, 0, 1, 0, 1, 0.5);
    EXPECT_NEAR(d.irradiance[Slot(e, kFront)].g, exact, 1e-6 * exact) << e;
    EXPECT_EQ(d.std_error[Slot(e, kFront)].g, 0);
    ++checked;
  }
  EXPECT_GE(checked, 100);
}

TEST(DirectIrradianceTest, HalfBlockedElementsAgreeWithClippingWithinTheirStandardErrors) {
  // HalfBlockedSquaresScene: a wall at x = 0.5 between the squares, touching both; an element of
  // the bottom's half x < 0.5 sees only the top's half x < 0.5, and so on.
  Scene s = testing::HalfBlockedSquaresScene();
  s.materials.push_back(Emitter(1));
  s.surfaces[1].material = 1;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, MakeWorld(s, 0.125));
  DirectIrradiance direct(*w->mesh, *w->vis, DirectOptions(), 1000);
  const DirectElements d = direct.ForElements(StopToken());
  // The standard errors come from 8 replicates (a t distribution with 7 degrees of freedom):
  // about 91 % of errors lie within 2 of them, 99.5 % within 4; none is allowed beyond 8.
  int checked = 0, with_error = 0, within2 = 0;
  for (int e = 0; e < static_cast<int>(w->mesh->elements().size()); ++e) {
    if (w->mesh->elements()[e].surface != 0) continue;
    double x0, x1, y0, y1;
    ElementRect(*w->mesh, e, &x0, &x1, &y0, &y1);
    const bool left = x1 <= 0.5 + 1e-9;
    const double exact = left ? testing::ParallelRectangles(x0, x1, y0, y1, 0, 0.5, 0, 1, 1)
                              : testing::ParallelRectangles(x0, x1, y0, y1, 0.5, 1, 0, 1, 1);
    const double se = d.std_error[Slot(e, kFront)].r;
    const double error = std::fabs(d.irradiance[Slot(e, kFront)].r - exact);
    EXPECT_LE(error, 8 * se + 1e-9 * exact) << e;
    within2 += error <= 2 * se + 1e-9 * exact;
    if (se > 0) ++with_error;
    ++checked;
  }
  EXPECT_EQ(checked, 64);
  EXPECT_GT(with_error, 32);  // Every element is half in shadow: a penumbra with an error bar.
  EXPECT_GE(within2, 0.8 * checked);
}

TEST(DirectIrradianceTest, AtAPointMatchesLambertExactlyAndSeesTheBlocker) {
  Scene s = testing::OpposedRectanglesScene(2, 3, 1);
  s.materials.push_back(Emitter(2));
  s.surfaces[1].material = 1;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, MakeWorld(s, 0.5));
  DirectIrradiance direct(*w->mesh, *w->vis, DirectOptions(), 100);
  // A point under the top's corner (0, 0), facing up: Howell's corner case, exact.
  const Vec3 x = Vec3(0, 0, 0.25) - w->mesh->origin();
  Rgb se;
  int64_t rays = 0;
  const Rgb h = direct.AtPoint(x, {0, 0, 1}, 7, &se, &rays);
  const double exact = 2 * testing::PointUnderCorner(2, 3, 0.75);
  EXPECT_NEAR(h.b, exact, 1e-12 + 1e-9 * exact);
  EXPECT_EQ(se.b, 0);
  EXPECT_GT(rays, 0);

  // Behind the half-blocking wall: a point at x = 0.25 sees only the top's half x < 0.5.
  Scene b = testing::HalfBlockedSquaresScene();
  b.materials.push_back(Emitter(1));
  b.surfaces[1].material = 1;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> wb, MakeWorld(b, 0.25));
  DirectIrradiance blocked(*wb->mesh, *wb->vis, DirectOptions(), 100);
  const Vec3 p = Vec3(0.25, 0.5, 0.5) - wb->mesh->origin();
  const Rgb hb = blocked.AtPoint(p, {0, 0, 1}, 3, &se, &rays);
  // The half [0, 0.5] x [0, 1] at height 0.5 seen from (0.25, 0.5): four corner rectangles.
  const double half = 2 * testing::PointUnderCorner(0.25, 0.5, 0.5) * 2;
  EXPECT_NEAR(hb.r, half, 4 * se.r + 1e-9);
  EXPECT_GT(se.r, 0);
}

TEST(DirectIrradianceTest, MaxPairsLeavesTheDimmestEmittersToTheCaller) {
  Scene s = testing::OpposedRectanglesScene(1, 1, 1);
  s.materials.push_back(Emitter(1));
  s.materials.push_back(Emitter(5));
  s.surfaces[0].material = 1;
  s.surfaces[1].material = 2;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, MakeWorld(s, 0.25));
  DirectOptions o;
  o.max_pairs = 40;  // 32 elements x one face.
  DirectIrradiance direct(*w->mesh, *w->vis, o, 32);
  ASSERT_EQ(direct.emitters().size(), 1u);
  EXPECT_EQ(direct.emitters()[0].exitance.r, 5);
  EXPECT_EQ(direct.skipped(), 1);
}

TEST(DirectIrradianceTest, StopsWhenAsked) {
  Material m = Emitter(1);
  MeshOptions mo;
  mo.max_elements = 2000;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, MakeWorld(testing::MakeClosedBox(1, 1, 1, m), mo));
  DirectIrradiance direct(*w->mesh, *w->vis, DirectOptions(), 2000);
  std::atomic<bool> stop{true};
  const DirectElements d = direct.ForElements(StopToken(&stop, 0));
  EXPECT_FALSE(d.complete);
  EXPECT_EQ(d.rays, 0);
}

}  // namespace
}  // namespace radiosity

namespace radiosity {
namespace {

TEST(DirectIrradianceTest, SliversBesideACornellBlockSeeTheLightThroughTheirGaps) {
  // Floor elements of the Cornell box mostly under a block: the uncovered sliver, itself half in
  // the block's shadow, sees 1-4 % of the light, so the first 16 shadow rays may all be blocked.
  // Against plain Monte Carlo over element x light pairs (independent, with its own error).
  ASSERT_OK_AND_ASSIGN(Scene scene,
                       LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr));
  MeshOptions mo;
  mo.max_elements = 10000;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, MakeWorld(std::move(scene), mo));
  const Mesh& mesh = *w->mesh;
  const DirectIrradiance direct(mesh, *w->vis, DirectOptions(),
                                static_cast<int64_t>(mesh.elements().size()));
  int light = -1;
  for (int f = 0; f < static_cast<int>(mesh.faces().size()); ++f) {
    if (mesh.sides().OfSurface(mesh.faces()[f].surface, kFront).Emits()) light = f;
  }
  ASSERT_GE(light, 0);
  const MeshFace& lf = mesh.faces()[light];
  const double exitance = mesh.sides().OfSurface(lf.surface, kFront).exitance.g;
  const RectSampler on_light(lf, 0, 0, 1, 1);
  std::vector<SpacePolygon> polygons;
  FacePolygons(lf, 0, 0, 1, 1, kFront, &polygons);
  double light_area = 0;
  for (const SpacePolygon& p : polygons) light_area += p.Area();
  // Beside the short block's edge (290, 114)-(240, 272) and the tall block's (423, 247)-(265, 296).
  for (const Vec3 target : {Vec3{268.57, 0, 160.77}, Vec3{364.67, 0, 272.61}}) {
    int e = -1;
    double nearest = 1e30;
    for (int k = 0; k < static_cast<int>(mesh.elements().size()); ++k) {
      const double d = Length(mesh.elements()[k].centroid - target);
      if (d < nearest) nearest = d, e = k;
    }
    ASSERT_LT(nearest, 1.0);
    Rgb h[2], variance[2];
    bool penumbra = false;
    int64_t evaluations = 0;
    direct.ForElement(e, h, variance, &penumbra, &evaluations, StopToken());
    const Element& el = mesh.elements()[e];
    Rng rng(StreamKey(7, static_cast<uint64_t>(e)));
    const int n = 400000;
    double sum = 0, sum2 = 0, unoccluded = 0;
    int64_t rays = 0;
    for (int i = 0; i < n; ++i) {
      int hx = 0, hy = 0, hx_face = 0;
      const Vec3 x = SampleElementArea(mesh, e, rng.Uniform(), rng.Uniform(), &hx, &hx_face);
      const Vec3 y = on_light.Sample(rng.Uniform(), rng.Uniform(), &hy);
      const Vec3 d = y - x;
      const double r2 = Dot(d, d), r = std::sqrt(r2);
      const double cos_y = -Dot(d, lf.normal[hy]) / r;
      const double cos_x = Dot(d, mesh.faces()[el.face].normal[hx]) / r;
      if (!(cos_y > 0) || !(cos_x > 0)) continue;
      const double k = exitance * cos_x * cos_y / (kPi * r2) * light_area;
      unoccluded += k;
      if (!SegmentVisible(*w->vis, x, el.face, y, light, cos_y, &rays)) continue;
      sum += k;
      sum2 += k * k;
    }
    const double mean = sum / n, se = std::sqrt((sum2 / n - mean * mean) / n);
    // The sliver sees a few per cent of what the whole element would.
    ASSERT_GT(sum, 0.005 * unoccluded);
    ASSERT_LT(sum, 0.2 * unoccluded);
    EXPECT_GT(h[kFront].g, 0) << "element " << e;
    EXPECT_NEAR(h[kFront].g, mean, 4 * std::hypot(std::sqrt(variance[kFront].g), se))
        << "element " << e << ": computed " << h[kFront].g << " against " << mean;
  }
}

}  // namespace
}  // namespace radiosity
