// Form-factor estimators (montecarlo, analytic, hemicube) and Lambert's formula against closed
// forms (Howell's catalogue: C-11 parallel rectangles, B-3 point to polygon), conservation (rows
// of a closed box sum to 1), and convergence as each estimator's budget grows.
#include "solver/transport/formfactor.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/solution.h"
#include "solver/transport/rng.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

using testing::OpposedRectangles;
using testing::PointUnderCorner;
using testing::PolygonScene;
using testing::World;

Scene OpposedScene(double a, double b, double c) {
  return testing::OpposedRectanglesScene(a, b, c);
}

absl::StatusOr<std::unique_ptr<World>> Build(const Scene& scene, double element_size,
                                             int patch_depth = 0) {
  MeshOptions mo;
  mo.element_size = element_size;
  mo.patch_depth = patch_depth;
  return testing::MakeWorld(scene, mo);
}

absl::StatusOr<std::unique_ptr<FormFactorEstimator>> Make(const World& w,
                                                          const FormFactorOptions& o) {
  return CreateFormFactorEstimator(*w.mesh, *w.vis, o);
}

double Entry(const FormFactorRow& row, int slot) {
  for (size_t k = 0; k < row.slots.size(); ++k) {
    if (row.slots[k] == slot) return row.f[k];
  }
  return 0;
}

void ExpectWellFormed(const FormFactorRow& row) {
  ASSERT_EQ(row.slots.size(), row.f.size());
  for (size_t k = 0; k < row.slots.size(); ++k) {
    EXPECT_GT(row.f[k], 0) << "slot " << row.slots[k];
    if (k > 0) {
      EXPECT_LT(row.slots[k - 1], row.slots[k]);
    }
  }
}

// Root mean square error, over `streams` rows, of the estimate of F from element 0 to the front of
// element 1 (the two-element scenes above).
double RmsError(const FormFactorEstimator& est, int64_t budget, int streams, double exact) {
  double s2 = 0;
  FormFactorRow row;
  for (int k = 0; k < streams; ++k) {
    est.Estimate({0, 1, 0}, budget, StreamKey(7, static_cast<uint64_t>(k)), &row);
    const double e = Entry(row, Slot(1, 0)) - exact;
    s2 += e * e;
  }
  return std::sqrt(s2 / streams);
}

TEST(PointToPolygonTest, LambertFormulaMatchesClosedForms) {
  const Vec3 square[4] = {{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  EXPECT_NEAR(PointToPolygonFormFactor({0, 0, 0}, {0, 0, 1}, square, 4), 0.138531605995, 1e-12);
  // Orientation does not matter.
  const Vec3 reversed[4] = {square[3], square[2], square[1], square[0]};
  EXPECT_NEAR(PointToPolygonFormFactor({0, 0, 0}, {0, 0, 1}, reversed, 4), 0.138531605995, 1e-12);
  for (auto [a, b, c] : {std::tuple{2.0, 0.5, 1.0}, {1e3, 1.0, 1.0}, {0.01, 3.0, 0.2}}) {
    const Vec3 rect[4] = {{0, 0, c}, {a, 0, c}, {a, b, c}, {0, b, c}};
    EXPECT_NEAR(PointToPolygonFormFactor({0, 0, 0}, {0, 0, 1}, rect, 4), PointUnderCorner(a, b, c),
                1e-12)
        << a << " x " << b << " at " << c;
  }
  // A point under the centre of a 2 x 2 square: four corner cases.
  const Vec3 big[4] = {{-1, -1, 1}, {1, -1, 1}, {1, 1, 1}, {-1, 1, 1}};
  EXPECT_NEAR(PointToPolygonFormFactor({0, 0, 0}, {0, 0, 1}, big, 4), 4 * 0.138531605995, 1e-11);
  // A huge square fills the hemisphere.
  const Vec3 huge[4] = {{-1e6, -1e6, 1}, {1e6, -1e6, 1}, {1e6, 1e6, 1}, {-1e6, 1e6, 1}};
  EXPECT_NEAR(PointToPolygonFormFactor({0, 0, 0}, {0, 0, 1}, huge, 4), 1.0, 1e-5);
}

TEST(PointToPolygonTest, ClippingKeepsOnlyWhatIsInFront) {
  // A square in front: clipping changes nothing.
  const Vec3 square[4] = {{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  EXPECT_NEAR(PointToPolygonFormFactorClipped({0, 0, 0}, {0, 0, 1}, square, 4), 0.138531605995,
              1e-12);
  // Tilt the point's normal to +x: only the half of a square straddling the plane x = 0 that lies
  // at x > 0 counts, seen as a perpendicular rectangle.
  const Vec3 straddling[4] = {{-1, 0, 1}, {1, 0, 1}, {1, 1, 1}, {-1, 1, 1}};
  const Vec3 front_half[4] = {{0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  EXPECT_NEAR(PointToPolygonFormFactorClipped({0, 0, 0}, {1, 0, 0}, straddling, 4),
              PointToPolygonFormFactor({0, 0, 0}, {1, 0, 0}, front_half, 4), 1e-14);
  // Wholly behind: zero.
  EXPECT_EQ(PointToPolygonFormFactorClipped({0, 0, 2}, {0, 0, 1}, square, 4), 0.0);
  // Unclipped, the behind case would count (the formula assumes the polygon is in front).
  EXPECT_GT(PointToPolygonFormFactor({0, 0, 2}, {0, 0, 1}, square, 4), 0.0);
}

TEST(HemicubeTest, DeltaFormFactorsSumToOne) {
  for (int res : {2, 8, 64, 256}) {
    HemicubeDeltas exact = ComputeHemicubeDeltas(res, true);
    ASSERT_EQ(exact.top.size(), static_cast<size_t>(res * res));
    ASSERT_EQ(exact.side.size(), static_cast<size_t>(res * res / 2));
    EXPECT_NEAR(exact.Sum(), 1.0, 1e-12) << res;
  }
  // The classic midpoint deltas converge to 1 at second order.
  double prev = 1;
  for (int res : {8, 32, 128, 512}) {
    const double err = std::fabs(ComputeHemicubeDeltas(res, false).Sum() - 1);
    EXPECT_LT(err, 1.0 / (res * res)) << res;
    if (res > 8) {
      EXPECT_LT(err, prev / 8) << res;
    }
    prev = err;
  }
  // Both agree cell by cell to second order, e.g. at the centre of the top.
  HemicubeDeltas a = ComputeHemicubeDeltas(256, true), b = ComputeHemicubeDeltas(256, false);
  const size_t centre = 128 * 256 + 128;
  EXPECT_NEAR(a.top[centre] / b.top[centre], 1.0, 1e-4);
  EXPECT_NEAR(a.top[centre] / (1 / kPi * (2.0 / 256) * (2.0 / 256)), 1.0, 1e-4);
  EXPECT_TRUE(ComputeHemicubeDeltas(7, true).top.empty());
}

TEST(FormFactorTest, RejectsBadOptions) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> s, Build(OpposedScene(1, 1, 1), 10));
  auto bad = [&](FormFactorOptions o) {
    auto est = CreateFormFactorEstimator(*s->mesh, *s->vis, o);
    EXPECT_EQ(est.status().code(), absl::StatusCode::kInvalidArgument);
  };
  FormFactorOptions o;
  o.method = "radiance";
  bad(o);
  o = {};
  o.sampling = "bogus";
  bad(o);
  o = {};
  o.method = "hemicube";
  o.hemicube_resolution = 31;
  bad(o);
  o.hemicube_resolution = 0;
  bad(o);
  o = {};
  o.method = "analytic";
  o.analytic_points = 0;
  bad(o);
  o = {};
  o.method = "analytic";
  o.shadow_rays = 0;
  bad(o);
}

TEST(FormFactorTest, MonteCarloMatchesOpposedSquares) {
  // Binomial estimate: within 4 standard errors of Howell C-11 for each sampling.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> s, Build(OpposedScene(1, 1, 1), 10));
  const double exact = 0.199824895698;
  ASSERT_NEAR(OpposedRectangles(1, 1, 1), exact, 1e-11);
  const int64_t n = 200000;
  for (const char* sampling : {"random", "stratified", "halton"}) {
    FormFactorOptions o;
    o.sampling = sampling;
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*s, o));
    FormFactorRow row;
    est->Estimate({0, 1, 0}, n, 11, &row);
    ExpectWellFormed(row);
    EXPECT_EQ(row.rays, n);
    ASSERT_EQ(row.slots.size(), 1u) << sampling;  // Only the top's front is ever hit.
    EXPECT_EQ(row.slots[0], Slot(1, 0));
    EXPECT_NEAR(row.f[0], exact, 4 * std::sqrt(exact * (1 - exact) / n)) << sampling;
    // Same stream, same row; another stream, another row.
    FormFactorRow again, other;
    est->Estimate({0, 1, 0}, n, 11, &again);
    est->Estimate({0, 1, 0}, n, 12, &other);
    EXPECT_EQ(row.f, again.f);
    EXPECT_NE(row.f, other.f);
  }
}

TEST(FormFactorTest, StratifiedAndHaltonBeatRandomAtEqualBudget) {
  // RMS error over 24 rows of 4096 rays each, opposed unit squares.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> s, Build(OpposedScene(1, 1, 1), 10));
  const double exact = OpposedRectangles(1, 1, 1);
  double err[3];
  const char* names[3] = {"random", "stratified", "halton"};
  for (int k = 0; k < 3; ++k) {
    FormFactorOptions o;
    o.sampling = names[k];
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*s, o));
    err[k] = RmsError(*est, 4096, 24, exact);
  }
  // Random is binomial: sqrt(F (1 - F) / n) = 6.2e-3 (within a generous band for 24 rows).
  const double se = std::sqrt(exact * (1 - exact) / 4096);
  EXPECT_GT(err[0], 0.6 * se);
  EXPECT_LT(err[0], 1.5 * se);
  EXPECT_LT(err[1], 0.7 * err[0]) << "stratified " << err[1] << " random " << err[0];
  EXPECT_LT(err[2], 0.7 * err[0]) << "halton " << err[2] << " random " << err[0];
  std::printf("rms error at 4096 rays: random %.3g, stratified %.3g, halton %.3g\n", err[0], err[1],
              err[2]);
}

TEST(FormFactorTest, MonteCarloErrorShrinksWithRays) {
  // Opposed unit squares and opposed 1000:1 slivers: every sampling's RMS error over 16 rows stays
  // within 1.6 binomial standard errors sqrt(F (1 - F) / n) at each budget, so it shrinks as
  // 1/sqrt(n) (or faster), and falls at least 4-fold from 1e3 to 1e5 rays.
  struct Case {
    Scene scene;
    double exact;
  };
  const Case cases[] = {{OpposedScene(1, 1, 1), OpposedRectangles(1, 1, 1)},
                        {OpposedScene(1000, 1, 1), OpposedRectangles(1000, 1, 1)}};
  for (const Case& c : cases) {
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> s, Build(c.scene, 1e4));
    for (const char* sampling : {"random", "stratified", "halton"}) {
      FormFactorOptions o;
      o.sampling = sampling;
      ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*s, o));
      double first = 0, last = 0;
      for (int64_t n : {1000, 10000, 100000}) {
        const double e = RmsError(*est, n, 16, c.exact);
        EXPECT_LT(e, 1.6 * std::sqrt(c.exact * (1 - c.exact) / n)) << sampling << " at " << n;
        if (n == 1000) first = e;
        last = e;
      }
      EXPECT_LT(last, first / 4) << sampling;
    }
  }
}

TEST(FormFactorTest, AnalyticRowsAreExactWhereNothingBlocks) {
  // Opposed squares, perpendicular unit squares sharing an edge (0.200043776075, where the kernel
  // is singular) and opposed 1000:1 slivers: the unoccluded factor is integrated over the
  // receiver to 1e-5 (area_to_polygon.h) and the shadow rays all arrive, so the row is exact to
  // that tolerance whatever the number of points.
  struct Case {
    Scene scene;
    double exact;
  };
  const Case cases[] = {
      {OpposedScene(1, 1, 1), OpposedRectangles(1, 1, 1)},
      {PolygonScene({{"floor", {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}},
                     {"wall", {{0, 0, 0}, {0, 0, 1}, {1, 0, 1}, {1, 0, 0}}}}),
       0.200043776075},
      {OpposedScene(1000, 1, 1), OpposedRectangles(1000, 1, 1)},
  };
  for (const Case& c : cases) {
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> s, Build(c.scene, 1e4));
    for (int points : {1, 4, 64}) {
      FormFactorOptions o;
      o.method = "analytic";
      o.analytic_points = points;
      o.shadow_rays = 1;
      ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*s, o));
      EXPECT_LT(RmsError(*est, 0, 16, c.exact), 2e-5 * c.exact)
          << points << " points, exact " << c.exact;
    }
  }
}

TEST(FormFactorTest, AnalyticShadowRaysResolvePartialOcclusion) {
  // The half-blocked pair: F = F(0.5 x 1 rectangles). With one shadow ray the visible fraction is
  // an area fraction (biased); the kernel-weighted fraction from more rays converges.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> s, Build(testing::HalfBlockedSquaresScene(), 1e4));
  const double exact = OpposedRectangles(0.5, 1, 1);
  // The visible fraction pools every point's rays (kernel-weighted), so its error falls with
  // points x rays: from 64 samples to 16384 by well over 4 times.
  double errors[2];
  int k = 0;
  for (int points : {16, 1024}) {
    FormFactorOptions o;
    o.method = "analytic";
    o.analytic_points = points;
    o.shadow_rays = points == 16 ? 4 : 16;
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*s, o));
    errors[k++] = RmsError(*est, 0, 4, exact);
  }
  EXPECT_LT(errors[1], errors[0] / 4) << errors[0] << " " << errors[1];
  EXPECT_LT(errors[1], 1e-4);

  ASSERT_OK_AND_ASSIGN(
      std::unique_ptr<World> blocked,
      Build(PolygonScene({{"bottom", {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}},
                          {"top", {{0, 0, 1}, {0, 1, 1}, {1, 1, 1}, {1, 0, 1}}},
                          {"blocker", {{-5, -5, 0.5}, {5, -5, 0.5}, {5, 5, 0.5}, {-5, 5, 0.5}}}}),
            1e4));
  for (const char* method : {"analytic", "montecarlo", "hemicube"}) {
    FormFactorOptions o;
    o.method = method;
    o.hemicube_resolution = 32;
    o.analytic_points = 1024;  // The blocker is large: its quadrature needs many points.
    FormFactorRow row;
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*blocked, o));
    est->Estimate({0, 1, 0}, 10000, 3, &row);
    EXPECT_EQ(Entry(row, Slot(1, 0)), 0.0) << method;
    // Nearly all of it lands on the blocker's back (a little escapes past its edges).
    EXPECT_NEAR(row.Sum(), 0.99, 0.01) << method;
    EXPECT_NEAR(Entry(row, Slot(2, 1)), row.Sum(), 1e-15) << method;
  }
}

TEST(FormFactorTest, HemicubeErrorShrinksWithResolution) {
  // A tiny source (0.01 x 0.01) centred under a 2 x 2 square at distance 1: its factor is that of
  // its centre, 4 x 0.138531605995 (Howell B-3), to O(1e-5), so the hemicube's error is its
  // aliasing, which falls about as 1/res (cells straddling the square's outline).
  ASSERT_OK_AND_ASSIGN(
      std::unique_ptr<World> s,
      Build(PolygonScene(
                {{"source",
                  {{-0.005, -0.005, 0}, {0.005, -0.005, 0}, {0.005, 0.005, 0}, {-0.005, 0.005, 0}}},
                 {"square", {{-1, -1, 1}, {-1, 1, 1}, {1, 1, 1}, {1, -1, 1}}}}),
            1e4));
  const double exact = 4 * PointUnderCorner(1, 1, 1);
  double prev = 1;
  for (int res : {4, 16, 64, 256}) {
    FormFactorOptions o;
    o.method = "hemicube";
    o.hemicube_resolution = res;
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*s, o));
    const double e = RmsError(*est, 0, 6, exact);
    if (res > 4) {
      EXPECT_LT(e, prev / 2) << res;
    }
    prev = e;
  }
  EXPECT_LT(prev, 2e-3);
  // On the opposed unit squares, 16 stratified hemicubes of resolution 64 per row.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> squares, Build(OpposedScene(1, 1, 1), 10));
  FormFactorOptions o;
  o.method = "hemicube";
  o.hemicube_resolution = 64;
  o.hemicube_points = 16;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*squares, o));
  EXPECT_LT(RmsError(*est, 0, 4, OpposedRectangles(1, 1, 1)), 5e-3);
}

TEST(FormFactorTest, PatchRowsInAClosedBoxConserveAndAgree) {
  // A closed unit box meshed at 0.25 with 2 x 2-element patches. From every patch of the floor:
  // rows are sorted, positive, sum to 1 (closure), and the area-weighted sum over the floor's
  // patches of the factors to the ceiling's elements is F(opposed unit squares).
  Material black{"black", Rgb(), Rgb(), Rgb(), false, 0};
  Scene box = testing::MakeClosedBox(1, 1, 1, black);
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> s, Build(box, 0.25, 1));
  const Mesh& mesh = *s->mesh;
  int floor_surface = -1, ceiling_surface = -1;
  for (size_t i = 0; i < box.surfaces.size(); ++i) {
    if (box.surfaces[i].name == "z0") floor_surface = static_cast<int>(i);
    if (box.surfaces[i].name == "z1") ceiling_surface = static_cast<int>(i);
  }
  struct Method {
    const char* name;
    double closure_tol, value_tol;
  };
  for (const Method& m : {Method{"montecarlo", 1e-3, 3e-3}, Method{"analytic", 5e-3, 2e-3},
                          Method{"hemicube", 1e-9, 3e-3}}) {
    FormFactorOptions o;
    o.method = m.name;
    o.sampling = "stratified";
    o.analytic_points = 64;
    o.hemicube_resolution = 64;
    o.hemicube_points = 16;
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*s, o));
    double to_ceiling = 0, floor_area = 0;
    for (size_t p = 0; p < mesh.patches().size(); ++p) {
      const Patch& patch = mesh.patches()[p];
      if (mesh.faces()[patch.face].surface != floor_surface) continue;
      FormFactorRow row;
      est->Estimate({patch.first_element, patch.num_elements, 0}, 50000,
                    StreamKey(5, static_cast<uint64_t>(p)), &row);
      ExpectWellFormed(row);
      EXPECT_NEAR(row.Sum(), 1.0, m.closure_tol) << m.name << " patch " << p;
      for (size_t k = 0; k < row.slots.size(); ++k) {
        const Element& e = mesh.elements()[row.slots[k] >> 1];
        EXPECT_NE(e.surface, floor_surface) << m.name;  // A plane never sees itself.
        EXPECT_EQ(row.slots[k] & 1, 0) << m.name;       // Inside a closed box: fronts only.
        if (e.surface == ceiling_surface) to_ceiling += patch.area * row.f[k];
      }
      floor_area += patch.area;
    }
    EXPECT_NEAR(floor_area, 1.0, 1e-12);
    EXPECT_NEAR(to_ceiling / floor_area, OpposedRectangles(1, 1, 1), m.value_tol) << m.name;
  }
}

}  // namespace
}  // namespace radiosity

namespace radiosity {
namespace {

// Beside a shared edge a single hemicube at the source's centre sees the neighbour at the wrong
// angles (the point assumption fails, Baum, Rushmeier & Winget 1989): the near-field entries are
// the analytic factors. A unit floor tile (its row) and a unit wall standing on its edge: F from
// the floor to the wall is Howell's C-14 to the quadrature's tolerance and the shadow rays (none
// blocked), and the row keeps the hemicube's total.
TEST(HemicubeTest, NearFieldEntriesBesideASharedEdgeAreAnalytic) {
  ASSERT_OK_AND_ASSIGN(
      std::unique_ptr<World> w,
      Build(PolygonScene({{"floor", {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}},
                          {"wall", {{0, 0, 0}, {0, 1, 0}, {0, 1, 1}, {0, 0, 1}}}}),
            10));
  FormFactorOptions o;
  o.method = "hemicube";
  o.hemicube_resolution = 16;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<FormFactorEstimator> est, Make(*w, o));
  FormFactorRow row;
  est->Estimate({0, 1, 0}, 0, 7, &row);
  ExpectWellFormed(row);
  const double exact = testing::PerpendicularRectangles(1, 1, 1);
  EXPECT_NEAR(Entry(row, Slot(1, 0)), exact, 1e-4 * exact);
  // What the hemicube alone gives there (its centre's factor, 0.0908 less cells' aliasing): off by
  // more than half.
  EXPECT_NEAR(row.Sum(), exact, 1e-4 * exact);
}

// A furnace solved with hemicube rows (progressive refinement shooting rows): every element
// within 1 % of B = E / (1 - rho), shared edges and corners included (without the near-field
// factors the elements along the edges were off by up to 100 %).
TEST(HemicubeTest, FurnaceRowsReachTheClosedFormAtSharedEdges) {
  Material m;
  m.name = "f";
  m.reflectance = Rgb::Gray(0.5);
  m.emission = Rgb::Gray(1);
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> w, Build(testing::MakeClosedBox(1, 1, 1, m), 0.125));
  SolveOptions options = testing::Budget(100, 1e-4);
  options.formfactor.method = "hemicube";
  ASSERT_OK_AND_ASSIGN(testing::SolveRun run, testing::Solve(*w, options));
  EXPECT_EQ(run.reason, StopReason::kConverged);
  double worst = 0;
  for (int e = 0; e < static_cast<int>(w->mesh->elements().size()); ++e) {
    worst = std::max(worst, std::fabs(run.solution.radiosity[Slot(e, kFront)].g / 2 - 1));
  }
  EXPECT_LT(worst, 0.01);
}

}  // namespace
}  // namespace radiosity
