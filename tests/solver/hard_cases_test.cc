// Numerical stability on hard cases (issue 6): contact edges and T-junctions, far-off
// coordinates, tiny emitters, area ranges of 1e12, two-sided surfaces (the sliver furnace and
// reflectance up to 0.999 are furnace_test.cc's hard cases). Every expectation comes from a closed
// form or a conservation law.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>

#include "solver/geometry/compensated_sum.h"
#include "solver/geometry/mesh.h"
#include "solver/input/scene_files.h"
#include "solver/methods/progressive.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

// Adds a parallelogram face to `surface` (material 0); see testing::AddRect.
void AddRect(Scene* s, const std::string& surface, const Vec3& corner, const Vec3& u,
             const Vec3& v) {
  testing::AddRect(s, surface, 0, corner, u, v);
}

using testing::ExpectBooksBalance;
using testing::SolvedWorld;

// Largest relative deviation from `expected` over the front of every element.
double WorstDeviation(const SolvedWorld& s, double expected) {
  return testing::WorstDeviation(*s.world->mesh, s.run.solution, expected);
}

TEST(HardCasesTest, ContactEdgesAndTJunctionsDoNotLeak) {
  const double rho = 0.5;
  // The furnace room with a block in a corner (testing::CornerBlockFurnace): closed, so every
  // element has B = E / (1 - rho) unless light leaks through a contact edge or a T-junction.
  Scene s = testing::CornerBlockFurnace(rho);
  ASSERT_TRUE(ValidateScene(s).ok());
  ASSERT_OK_AND_ASSIGN(SolvedWorld r, testing::MeshAndSolve(s, 0.5, testing::Budget(20000, 1e-5)));
  const Solution& sol = r.run.solution;
  // Leaks show up as escaped power (rays slipping out between pieces) and dark elements.
  EXPECT_LT(sol.escaped_power.Sum(), 1e-6 * sol.emitted_power.Sum());
  EXPECT_LT(WorstDeviation(r, 1 / (1 - rho)), 0.02)
      << r.world->mesh->elements().size() << " elements";
  ExpectBooksBalance(sol);
}

TEST(HardCasesTest, FarFromTheOriginGivesTheSameAnswer) {
  // A 1000-unit Cornell-like room moved 1e6 units away: coordinates are recentred in double
  // before Embree sees them as float, so the answer matches the one at the origin.
  auto scene = LoadSceneFile(testing::SourcePath("scenes/cornell_box.obj"), nullptr);
  ASSERT_TRUE(scene.ok());
  Scene far = *scene;
  for (Vec3& v : far.vertices) {
    v = v * (1000.0 / 556.0) + Vec3{1e6, -1e6, 1e6};
  }
  Scene near = *scene;
  for (Vec3& v : near.vertices) v = v * (1000.0 / 556.0);
  MeshOptions mo;
  mo.max_elements = 1500;
  SolveOptions opt;
  opt.rays_per_element = 500;
  ASSERT_OK_AND_ASSIGN(SolvedWorld a, testing::MeshAndSolve(near, mo, opt));
  ASSERT_OK_AND_ASSIGN(SolvedWorld b, testing::MeshAndSolve(far, mo, opt));
  ASSERT_EQ(a.world->mesh->elements().size(), b.world->mesh->elements().size());
  const std::vector<Rgb>& ba = a.run.solution.radiosity;
  const std::vector<Rgb>& bb = b.run.solution.radiosity;
  double worst = 0;
  for (size_t i = 0; i < ba.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      double x = ba[i][c], y = bb[i][c];
      if (x > 0) worst = std::max(worst, std::fabs(y / x - 1));
    }
  }
  EXPECT_LT(worst, 1e-3);
}

TEST(HardCasesTest, TinyEmitterAndAreasSpanning1e12) {
  // A 1000 x 1000 black floor and a 1e-3 x 1e-3 emitter 10 units above its centre facing down:
  // areas span 1e12. The irradiance right below a small Lambertian emitter is
  // E = M A / (pi r^2) (to a relative 1e-8 for this size), the floor's radiosity is rho E.
  const double rho = 0.5, m = 1e7, a = 1e-3, h = 10;
  Scene s;
  s.materials.push_back({"floor", Rgb::Gray(rho), Rgb(), Rgb(), false, 0});
  s.materials.push_back({"light", Rgb(), Rgb::Gray(m), Rgb(), false, 0});
  AddRect(&s, "floor", {-500, 0, -500}, {0, 0, 1000}, {1000, 0, 0});
  AddRect(&s, "light", {-a / 2, h, -a / 2}, {a, 0, 0}, {0, 0, a});
  s.surfaces[1].material = 1;
  std::vector<std::string> warnings;
  ASSERT_TRUE(DropDegenerateFaces(&s, &warnings).ok());
  ASSERT_EQ(s.faces.size(), 2u) << "the tiny emitter must not be dropped";
  // Elements of 4 x 4: 250 x 250 on the floor; the light is one element.
  ASSERT_OK_AND_ASSIGN(SolvedWorld r, testing::MeshAndSolve(s, 4, testing::Budget(200)));
  const Mesh& mesh = *r.world->mesh;
  const Solution& sol = r.run.solution;
  // Elements within 10 units of the axis: E varies as cos^4; compare each with the closed form.
  double worst = 0;
  int checked = 0;
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    const Element& el = mesh.elements()[e];
    if (el.surface != 0) continue;
    double d2 = el.centroid.x * el.centroid.x + el.centroid.z * el.centroid.z;
    if (d2 > 100) continue;
    // The element's mean of the closed form (it varies by a few % across a 4-unit element).
    double expected = 0;
    const int k = 8;
    for (int i = 0; i < k; ++i) {
      for (int j = 0; j < k; ++j) {
        double x = el.centroid.x + 4 * ((i + 0.5) / k - 0.5);
        double z = el.centroid.z + 4 * ((j + 0.5) / k - 0.5);
        double r2 = x * x + z * z + h * h;
        expected += rho * m * a * a * (h * h / r2) / (kPi * r2) / (k * k);
      }
    }
    worst =
        std::max(worst, std::fabs(sol.radiosity[Slot(static_cast<int>(e), 0)].r / expected - 1));
    ++checked;
  }
  ASSERT_GE(checked, 16);
  // Each floor element near the axis receives ~5e5 of the light's rays: 1 % holds.
  EXPECT_LT(worst, 0.01);
  ExpectBooksBalance(sol);
}

TEST(HardCasesTest, TwoSidedSheetInAFurnace) {
  // A two-sided sheet across the middle of a closed furnace divides it into two closed halves;
  // both its sides emit and reflect, so both sides reach B = E / (1 - rho).
  const double rho = 0.5;
  Material m{"f", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), true, 0};
  Scene s = testing::MakeClosedBox(2, 1, 1, m);
  s.materials[0].two_sided = false;
  s.materials.push_back(m);
  AddRect(&s, "sheet", {1, 0, 0}, {0, 1, 0}, {0, 0, 1});
  s.surfaces.back().material = 1;
  ASSERT_OK_AND_ASSIGN(SolvedWorld r, testing::MeshAndSolve(s, 0.25, testing::Budget(20000, 1e-5)));
  const Solution& sol = r.run.solution;
  double worst_back = 0;
  for (size_t e = 0; e < r.world->mesh->elements().size(); ++e) {
    if (r.world->mesh->elements()[e].surface != 6) continue;
    worst_back = std::max(worst_back,
                          std::fabs(sol.radiosity[Slot(static_cast<int>(e), 1)].g * (1 - rho) - 1));
  }
  EXPECT_LT(WorstDeviation(r, 1 / (1 - rho)), 0.02);
  EXPECT_LT(worst_back, 0.02);
  ExpectBooksBalance(sol);
}

TEST(HardCasesTest, EmitterInsideAClosedBlackBoxConvergesWithoutNaN) {
  // All light is absorbed at the first bounce: the solve ends at once, finite, books balanced.
  Scene s = testing::MakeClosedBox(1, 1, 1, {"black", Rgb(), Rgb(), Rgb(), false, 0});
  s.materials.push_back({"light", Rgb(), Rgb::Gray(5), Rgb(), false, 0});
  AddRect(&s, "light", {0.4, 0.5, 0.4}, {0.2, 0, 0}, {0, 0, 0.2});  // facing -y, two-sided: no
  s.surfaces.back().material = 1;
  ASSERT_OK_AND_ASSIGN(SolvedWorld r, testing::MeshAndSolve(s, 0.25, testing::Budget(100)));
  EXPECT_EQ(r.run.reason, StopReason::kConverged);
  const Solution& sol = r.run.solution;
  EXPECT_EQ(sol.unshot_fraction, 0.0);
  ExpectBooksBalance(sol, 1e-12);
  // The box is closed: only the computed direct light's quadrature error (1e-6 relative) escapes.
  EXPECT_NEAR(sol.absorbed_power.Sum(), sol.emitted_power.Sum(), 1e-6 * sol.emitted_power.Sum());
}

// The energy books take one term per ray. Terms k 2^-52 with k a random 52-bit integer have full
// mantissas, so a plain double sum (which reaches 2^29) rounds away most bits of every term, yet
// their exact sum is an integer times 2^-52 that 128-bit integer arithmetic holds exactly.
TEST(HardCasesTest, BillionRayContributionsSumToTheExactTotal) {
  constexpr int64_t kTerms = 1'000'000'000;
  uint64_t state = 0x9E3779B97F4A7C15ULL;
  __extension__ typedef unsigned __int128 Uint128;  // GCC and clang; not ISO C++.
  Uint128 exact = 0;                                // In units of 2^-52.
  CompensatedSum books;
  double plain = 0;
  for (int64_t i = 0; i < kTerms; ++i) {
    state ^= state << 13;  // xorshift64 (Marsaglia 2003).
    state ^= state >> 7;
    state ^= state << 17;
    const uint64_t k = state >> 12;  // 52 bits.
    exact += k;
    const double term = std::ldexp(static_cast<double>(k), -52);
    books.Add(term);
    plain += term;
  }
  const double truth = std::ldexp(static_cast<double>(exact), -52);  // One rounding.
  const double error = std::fabs(books.Total() - truth) / truth;
  EXPECT_LT(error, 4e-16) << "compensated " << books.Total() << " exact " << truth;
  // For the record: plain double summation of the same terms.
  std::printf("1e9 terms: compensated relative error %.2e, plain double %.2e\n", error,
              std::fabs(plain - truth) / truth);

  // The RGB books the solvers keep add channel by channel through the same sums.
  CompensatedRgb rgb;
  for (int i = 0; i < 1000; ++i) rgb += Rgb(0.1, 0.2, 0.3);
  EXPECT_NEAR(rgb.Total().r, 100, 1e-13);
  EXPECT_NEAR(rgb.Total().g, 200, 1e-13);
  EXPECT_NEAR(rgb.Total().b, 300, 1e-13);
}

TEST(HardCasesTest, ReflectanceOfOneIsRefusedByValidation) {
  Scene s = testing::MakeClosedBox(1, 1, 1, {"white", Rgb::Gray(1), Rgb::Gray(1), Rgb(), false, 0});
  absl::Status st = ValidateScene(s);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("outside [0, 1)"), std::string::npos) << st;
}

}  // namespace
}  // namespace radiosity
