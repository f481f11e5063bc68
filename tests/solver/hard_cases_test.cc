// Numerical stability on hard cases (issue 6): contact edges and T-junctions, far-off
// coordinates, slivers, tiny emitters, area ranges of 1e12, two-sided surfaces, high reflectance.
// Every expectation comes from a closed form or a conservation law.
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

namespace radiosity {
namespace {

// Adds a parallelogram face to `surface` (material 0); see testing::AddRect.
void AddRect(Scene* s, const std::string& surface, const Vec3& corner, const Vec3& u,
             const Vec3& v) {
  testing::AddRect(s, surface, 0, corner, u, v);
}

struct Solved {
  std::unique_ptr<Mesh> mesh;
  Solution solution;
  StopReason reason;
};

Solved Solve(const Scene& scene, const MeshOptions& mo, const SolveOptions& opt) {
  Solved out;
  auto mesh = Mesh::Build(scene, mo);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  out.mesh = std::make_unique<Mesh>(*std::move(mesh));
  auto vis = Visibility::Build(*out.mesh);
  EXPECT_TRUE(vis.ok()) << vis.status();
  auto solver = CreateSolver(scene, *out.mesh, **vis, opt, nullptr);
  EXPECT_TRUE(solver.ok()) << solver.status();
  auto reason = RunSolver(**solver, opt, nullptr, nullptr);
  EXPECT_TRUE(reason.ok()) << reason.status();
  out.reason = *reason;
  out.solution = (*solver)->Final();
  return out;
}

// Largest relative deviation from `expected` over the element sides that exist.
double WorstDeviation(const Solved& s, double expected, int side = 0) {
  double worst = 0;
  for (size_t e = 0; e < s.mesh->elements().size(); ++e) {
    const Rgb& b = s.solution.radiosity[Slot(static_cast<int>(e), side)];
    for (int c = 0; c < 3; ++c) worst = std::max(worst, std::fabs(b[c] / expected - 1));
  }
  return worst;
}

void ExpectBooksBalance(const Solution& sol) {
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(sol.absorbed_power[c] + sol.escaped_power[c] + sol.unshot_power[c],
                sol.emitted_power[c], 1e-9 * sol.emitted_power[c]);
    EXPECT_TRUE(std::isfinite(sol.absorbed_power[c]));
  }
}

// A furnace room [0,4]^3 with a unit block in the corner at the origin, resting on the floor and
// against two walls. Floor and walls have conforming holes where the block touches them, made of
// coplanar pieces that meet in T-junctions; the block shows only its three room-facing faces. The
// enclosure is closed, so with uniform rho and E every element has B = E / (1 - rho) unless light
// leaks through a contact edge or a T-junction.
Scene CornerBlockFurnace(double rho) {
  Scene s;
  s.materials.push_back({"furnace", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), false, 0});
  const double L = 4;
  // Floor y = 0 facing +y, minus [0,1]x[0,1] in (x, z): two pieces.
  AddRect(&s, "floor", {1, 0, 0}, {0, 0, 1}, {L - 1, 0, 0});
  AddRect(&s, "floor", {0, 0, 1}, {0, 0, L - 1}, {L, 0, 0});
  // Wall x = 0 facing +x, minus [0,1]x[0,1] in (y, z).
  AddRect(&s, "wall_x0", {0, 1, 0}, {0, L - 1, 0}, {0, 0, 1});
  AddRect(&s, "wall_x0", {0, 0, 1}, {0, L, 0}, {0, 0, L - 1});
  // Wall z = 0 facing +z, minus [0,1]x[0,1] in (x, y).
  AddRect(&s, "wall_z0", {1, 0, 0}, {L - 1, 0, 0}, {0, 1, 0});
  AddRect(&s, "wall_z0", {0, 1, 0}, {L, 0, 0}, {0, L - 1, 0});
  // The other three sides, whole.
  AddRect(&s, "ceiling", {0, L, 0}, {L, 0, 0}, {0, 0, L});
  AddRect(&s, "wall_x4", {L, 0, 0}, {0, 0, L}, {0, L, 0});
  AddRect(&s, "wall_z4", {0, 0, L}, {0, L, 0}, {L, 0, 0});
  // The block's room-facing faces.
  AddRect(&s, "block", {0, 1, 0}, {0, 0, 1}, {1, 0, 0});  // top, +y
  AddRect(&s, "block", {1, 0, 0}, {0, 1, 0}, {0, 0, 1});  // x = 1, +x
  AddRect(&s, "block", {0, 0, 1}, {1, 0, 0}, {0, 1, 0});  // z = 1, +z
  return s;
}

TEST(HardCasesTest, ContactEdgesAndTJunctionsDoNotLeak) {
  const double rho = 0.5;
  Scene s = CornerBlockFurnace(rho);
  ASSERT_TRUE(ValidateScene(s).ok());
  MeshOptions mo;
  mo.element_size = 0.5;
  SolveOptions opt;
  opt.rays_per_element = 20000;
  opt.tolerance = 1e-5;
  Solved r = Solve(s, mo, opt);
  // Leaks show up as escaped power (rays slipping out between pieces) and dark elements.
  EXPECT_LT(r.solution.escaped_power.Sum(), 1e-6 * r.solution.emitted_power.Sum());
  EXPECT_LT(WorstDeviation(r, 1 / (1 - rho)), 0.02) << r.mesh->elements().size() << " elements";
  ExpectBooksBalance(r.solution);
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
  Solved a = Solve(near, mo, opt), b = Solve(far, mo, opt);
  ASSERT_EQ(a.mesh->elements().size(), b.mesh->elements().size());
  double worst = 0;
  for (size_t i = 0; i < a.solution.radiosity.size(); ++i) {
    for (int c = 0; c < 3; ++c) {
      double x = a.solution.radiosity[i][c], y = b.solution.radiosity[i][c];
      if (x > 0) worst = std::max(worst, std::fabs(y / x - 1));
    }
  }
  EXPECT_LT(worst, 1e-3);
}

TEST(HardCasesTest, SliverFurnace) {
  // A 1000 x 1 x 1 tunnel: its long walls are 1000:1 slivers. Closed, so B = E / (1 - rho).
  const double rho = 0.5;
  Scene s =
      testing::MakeClosedBox(1000, 1, 1, {"f", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), false, 0});
  MeshOptions mo;
  mo.element_size = 5;
  SolveOptions opt;
  opt.rays_per_element = 20000;
  opt.tolerance = 1e-5;
  Solved r = Solve(s, mo, opt);
  EXPECT_LT(r.solution.escaped_power.Sum(), 1e-6 * r.solution.emitted_power.Sum());
  EXPECT_LT(WorstDeviation(r, 1 / (1 - rho)), 0.02);
  ExpectBooksBalance(r.solution);
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
  MeshOptions mo;
  mo.element_size = 4;  // 250 x 250 floor elements; the light is one element
  SolveOptions opt;
  opt.rays_per_element = 200;
  Solved r = Solve(s, mo, opt);
  // Elements within 10 units of the axis: E varies as cos^4; compare each with the closed form.
  double worst = 0;
  int checked = 0;
  for (size_t e = 0; e < r.mesh->elements().size(); ++e) {
    const Element& el = r.mesh->elements()[e];
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
    worst = std::max(
        worst, std::fabs(r.solution.radiosity[Slot(static_cast<int>(e), 0)].r / expected - 1));
    ++checked;
  }
  ASSERT_GE(checked, 16);
  // Each floor element near the axis receives ~5e5 of the light's rays: 1 % holds.
  EXPECT_LT(worst, 0.01);
  ExpectBooksBalance(r.solution);
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
  MeshOptions mo;
  mo.element_size = 0.25;
  SolveOptions opt;
  opt.rays_per_element = 20000;
  opt.tolerance = 1e-5;
  Solved r = Solve(s, mo, opt);
  double worst_back = 0;
  for (size_t e = 0; e < r.mesh->elements().size(); ++e) {
    if (r.mesh->elements()[e].surface != 6) continue;
    worst_back =
        std::max(worst_back,
                 std::fabs(r.solution.radiosity[Slot(static_cast<int>(e), 1)].g * (1 - rho) - 1));
  }
  EXPECT_LT(WorstDeviation(r, 1 / (1 - rho)), 0.02);
  EXPECT_LT(worst_back, 0.02);
  ExpectBooksBalance(r.solution);
}

TEST(HardCasesTest, EmitterInsideAClosedBlackBoxConvergesWithoutNaN) {
  // All light is absorbed at the first bounce: the solve ends at once, finite, books balanced.
  Scene s = testing::MakeClosedBox(1, 1, 1, {"black", Rgb(), Rgb(), Rgb(), false, 0});
  s.materials.push_back({"light", Rgb(), Rgb::Gray(5), Rgb(), false, 0});
  AddRect(&s, "light", {0.4, 0.5, 0.4}, {0.2, 0, 0}, {0, 0, 0.2});  // facing -y, two-sided: no
  s.surfaces.back().material = 1;
  MeshOptions mo;
  mo.element_size = 0.25;
  SolveOptions opt;
  opt.rays_per_element = 100;
  Solved r = Solve(s, mo, opt);
  EXPECT_EQ(r.reason, StopReason::kConverged);
  EXPECT_EQ(r.solution.unshot_fraction, 0.0);
  EXPECT_NEAR(r.solution.absorbed_power.Sum(), r.solution.emitted_power.Sum(),
              1e-12 * r.solution.emitted_power.Sum());
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

namespace radiosity {
namespace {

class HighReflectanceTest : public ::testing::TestWithParam<double> {};

TEST_P(HighReflectanceTest, FurnaceReachesEOverOneMinusRho) {
  // B = E / (1 - rho) = 10, 100, 1000 x E. Rays carry equal power, so the solve spends
  // K N / (1 - rho) rays; K = 4e5 (1 - rho) keeps every element near 4e5 hits whatever rho
  // (about 1e7 rays, a few seconds, for each rho).
  // Monte Carlo shooting sends each ray to exactly one place, so the implied form factors can
  // never sum above 1 and the iteration cannot diverge.
  const double rho = GetParam();
  Scene s = testing::MakeClosedBox(1, 1, 1, {"f", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), false, 0});
  MeshOptions mo;
  mo.element_size = 0.5;
  SolveOptions opt;
  opt.rays_per_element = 4e5 * (1 - rho);
  opt.tolerance = 1e-4;
  Solved r = Solve(s, mo, opt);
  EXPECT_EQ(r.reason, StopReason::kConverged);
  EXPECT_LT(WorstDeviation(r, 1 / (1 - rho)), 0.01) << r.solution.rays << " rays";
  ExpectBooksBalance(r.solution);
}

INSTANTIATE_TEST_SUITE_P(Rho, HighReflectanceTest, ::testing::Values(0.9, 0.99, 0.999),
                         [](const auto& param_info) {
                           return "rho" + std::to_string(static_cast<int>(
                                              std::lround(param_info.param * 1000)));
                         });

}  // namespace
}  // namespace radiosity
