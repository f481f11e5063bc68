// The furnace against every method, after pbrt-v4's integrators_test.cpp: analytic scenes x
// methods. A closed box whose walls all have reflectance R and emission E: whatever the mesh, the
// power arriving at a wall's front equals what leaves the walls (rows of the form-factor matrix
// sum to 1), so B = E / (1 - R) on every element (Shirley 6.2). Any leak or wrong form factor
// shows on some element, the more so as hierarchical links mix levels. With transmittance T the
// back of every wall passes T of what arrives at the front out of the box: B_back = T E / (1 - R),
// and T / (1 - R) of the emitted power escapes; two-sided walls emit E from their backs too, where
// nothing arrives: B_back = E, and half the power escapes. Opaque one-sided walls have no back:
// B_back = 0 exactly, and nothing escapes.
//
// Each method runs every wall kind with its own mesh and budget (MethodSetup), and must come as
// close as that budget allows (Accuracy); the hard scenes (a 1000:1 sliver tunnel, reflectance up
// to 0.999) run on progressive refinement, whose Monte Carlo shooting sends each ray to exactly one
// place, so the implied form factors never sum above 1 and the iteration cannot diverge however
// close R is to 1.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <memory>
#include <ostream>
#include <string>
#include <vector>

#include "solver/geometry/sides.h"
#include "solver/methods/registry.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

using testing::SolveRun;
using testing::World;

// The methods under test: every method of the registry.
const std::vector<std::string>& Methods() {
  static const auto* methods = [] {
    auto* names = new std::vector<std::string>;
    for (const MethodInfo& m : radiosity::Methods()) names->push_back(m.name);
    return names;
  }();
  return *methods;
}

// An analytic scene: a closed box [0, sx] x [0, sy] x [0, sz] (testing::MakeClosedBox) of one
// material with E = 1.
struct FurnaceScene {
  std::string name;
  double sx, sy, sz;
  double rho;
  double tau = 0;
  bool two_sided = false;

  double Front() const { return 1 / (1 - rho); }
  double Back() const { return two_sided ? 1 : tau / (1 - rho); }
  double EscapedFraction() const { return two_sided ? 0.5 : tau / (1 - rho); }
};

// The wall kinds every method runs.
std::vector<FurnaceScene> WallScenes() {
  return {
      {"Opaque", 1, 1.5, 0.8, 0.5},
      {"Transmitting", 1, 1.5, 0.8, 0.3, 0.2},
      {"StronglyTransmitting", 1, 1.5, 0.8, 0.3, 0.4},
      {"TwoSided", 1, 1.5, 0.8, 0.5, 0, true},
  };
}

// How close a solve must come, as largest errors.
struct Accuracy {
  double front;             // |B_front / closed form - 1| on every element and channel.
  double back;              // The same on the backs, where they have radiosity (else it must be 0).
  double escaped;           // |escaped / emitted - closed form| where power escapes...
  double leak;              // ...and where none may (opaque walls).
  bool exact_books = true;  // emitted = absorbed + escaped + unshot to rounding.
};

// How a method is run: its mesh, its options (method set by the test) and the accuracy they buy.
struct MethodSetup {
  std::string variant;  // Names the options where a method has several setups, else "".
  MeshOptions mesh;
  SolveOptions options;
  Accuracy accuracy;
  bool defined = true;  // False for a method SetupsOf does not know (the test then fails).
};

MethodSetup MakeMethodSetup(const std::string& variant, double element_size,
                            const Accuracy& accuracy) {
  MethodSetup s;
  s.variant = variant;
  s.mesh.element_size = element_size;
  s.accuracy = accuracy;
  return s;
}

// The setups of each method on the walls of WallScenes().
std::vector<MethodSetup> SetupsOf(const std::string& method) {
  if (method == "progressive") {
    // Both ways of choosing shooting origins within a patch.
    std::vector<MethodSetup> setups;
    for (bool weighted : {true, false}) {
      MethodSetup s =
          MakeMethodSetup(weighted ? "Weighted" : "Uniform", 0.3, {0.01, 0.02, 0.005, 1e-7});
      s.options.tolerance = 1e-5;
      s.options.rays_per_element = 40000;
      s.options.seed = 11;
      s.options.weighted_shooting = weighted;
      setups.push_back(s);
    }
    return setups;
  }
  if (method == "jacobi" || method == "gauss-seidel" || method == "reflection") {
    // 40 elements. Each element's incident power is estimated from about rays_per_element (matrix
    // rows) or twice as many (packets bounce about 1 / (1 - R) times) Monte Carlo samples. The
    // backs pass T of the incident power with its Monte Carlo noise undamped (the front adds E to
    // R times it): 2 %. Reflection's Russian roulette conserves power per channel only in
    // expectation.
    const bool reflection = method == "reflection";
    MethodSetup s = MakeMethodSetup("", 0.5, {0.01, 0.02, 0.005, 0.005, !reflection});
    s.options.tolerance = 1e-5;
    s.options.rays_per_element = reflection ? 40000 : 100000;
    s.options.seed = 11;
    return {s};
  }
  if (method == "hierarchical") {
    // 832 elements; the default tolerance, hence the default refinement epsilon. Shadow-ray
    // visibility of partly hidden links is estimated: 2 %.
    MethodSetup s = MakeMethodSetup("", 0.1, {0.02, 0.02, 0.01, 0.01});
    s.options.seed = 3;
    return {s};
  }
  // A method added to Methods() without a setup here: its cases fail, saying so.
  MethodSetup unknown;
  unknown.defined = false;
  return {unknown};
}

struct FurnaceCase {
  FurnaceScene scene;
  std::string method;
  MethodSetup setup;
};

void PrintTo(const FurnaceCase& c, std::ostream* os) {
  *os << c.scene.name << " furnace (rho " << c.scene.rho << ", tau " << c.scene.tau
      << (c.scene.two_sided ? ", two-sided" : "") << ") by " << c.method
      << (c.setup.variant.empty() ? "" : " " + c.setup.variant);
}

// "Opaque_GaussSeidel", "Opaque_ProgressiveUniform".
std::string CaseName(const ::testing::TestParamInfo<FurnaceCase>& info) {
  std::string name = info.param.scene.name + "_";
  bool upper = true;
  for (char c : info.param.method) {
    if (c == '-') {
      upper = true;
      continue;
    }
    name += upper ? static_cast<char>(std::toupper(static_cast<unsigned char>(c))) : c;
    upper = false;
  }
  return name + info.param.setup.variant;
}

// Every wall kind by every method, in each of its setups.
std::vector<FurnaceCase> WallCases() {
  std::vector<FurnaceCase> cases;
  for (const FurnaceScene& scene : WallScenes()) {
    for (const std::string& method : Methods()) {
      for (const MethodSetup& setup : SetupsOf(method)) cases.push_back({scene, method, setup});
    }
  }
  return cases;
}

// The hard scenes, by progressive refinement.
std::vector<FurnaceCase> HardCases() {
  std::vector<FurnaceCase> cases;
  // A 1000 x 1 x 1 tunnel: its long walls are 1000:1 slivers.
  MethodSetup sliver = MakeMethodSetup("", 5, {0.02, 0, 0, 1e-6});
  sliver.options.rays_per_element = 20000;
  sliver.options.tolerance = 1e-5;
  cases.push_back({{"Sliver", 1000, 1, 1, 0.5}, "progressive", sliver});
  // B = E / (1 - rho) = 10, 100, 1000 x E. Rays carry equal power, so the solve spends
  // K N / (1 - rho) rays; K = 4e5 (1 - rho) keeps every element near 4e5 hits whatever rho (about
  // 1e7 rays, a few seconds, for each rho).
  for (double rho : {0.9, 0.99, 0.999}) {
    MethodSetup bright = MakeMethodSetup("", 0.5, {0.01, 0, 0, 1e-6});
    bright.options.rays_per_element = 4e5 * (1 - rho);
    bright.options.tolerance = 1e-4;
    const std::string name = "Rho" + std::to_string(std::lround(rho * 1000));
    cases.push_back({{name, 1, 1, 1, rho}, "progressive", bright});
  }
  return cases;
}

class FurnaceTest : public ::testing::TestWithParam<FurnaceCase> {};

TEST_P(FurnaceTest, EveryElementReachesTheClosedForm) {
  const FurnaceScene& fs = GetParam().scene;
  const MethodSetup& setup = GetParam().setup;
  const Accuracy& accuracy = setup.accuracy;
  ASSERT_TRUE(setup.defined) << "no furnace setup for method '" << GetParam().method
                             << "': add one to SetupsOf";
  const Material m{"furnace", Rgb::Gray(fs.rho), Rgb::Gray(1), Rgb::Gray(fs.tau), fs.two_sided, 0};
  ASSERT_OK_AND_ASSIGN(
      std::unique_ptr<World> w,
      testing::MakeWorld(testing::MakeClosedBox(fs.sx, fs.sy, fs.sz, m), setup.mesh));
  SolveOptions opt = setup.options;
  opt.method = GetParam().method;
  ASSERT_OK_AND_ASSIGN(SolveRun r, testing::Solve(*w, opt));
  EXPECT_EQ(r.reason, StopReason::kConverged);
  const Solution& sol = r.solution;
  EXPECT_EQ(sol.method, opt.method);
  const size_t n = w->mesh->elements().size();
  const std::string what = std::to_string(n) + " elements, " + std::to_string(sol.rays) +
                           " rays, " + std::to_string(sol.links) + " links";

  EXPECT_LT(testing::WorstDeviation(*w->mesh, sol, fs.Front(), 0), accuracy.front) << what;
  if (fs.Back() > 0) {
    EXPECT_LT(testing::WorstDeviation(*w->mesh, sol, fs.Back(), 1), accuracy.back) << what;
  } else {
    double worst_back = 0;
    for (size_t e = 0; e < n; ++e) {
      const Rgb& b = sol.radiosity[Slot(static_cast<int>(e), 1)];
      for (int c = 0; c < 3; ++c) worst_back = std::max(worst_back, std::fabs(b[c]));
    }
    EXPECT_EQ(worst_back, 0.0) << what;
  }

  // Books: what is emitted is absorbed, or escapes through the walls (T / (1 - R) of it, or the
  // half emitted by the backs of two-sided walls); closed opaque walls let nothing out (but for
  // rays from within a float's rounding of an edge).
  const double emitted = sol.emitted_power.Sum();
  const double escaped = sol.escaped_power.Sum() / emitted;
  EXPECT_LT(std::fabs(escaped - fs.EscapedFraction()),
            fs.EscapedFraction() > 0 ? accuracy.escaped : accuracy.leak)
      << "escaped " << escaped;
  EXPECT_LT(std::fabs((sol.absorbed_power + sol.escaped_power).Sum() / emitted - 1), 0.005);
  if (accuracy.exact_books) testing::ExpectBooksBalance(sol);
  EXPECT_LE(sol.unshot_fraction, opt.tolerance);
  if (opt.method == "hierarchical") {
    // Far fewer links than element pairs (a handful per element here).
    EXPECT_LT(static_cast<double>(sol.links),
              0.05 * static_cast<double>(n) * static_cast<double>(n));
  }
}

INSTANTIATE_TEST_SUITE_P(Walls, FurnaceTest, ::testing::ValuesIn(WallCases()), CaseName);
INSTANTIATE_TEST_SUITE_P(HardCases, FurnaceTest, ::testing::ValuesIn(HardCases()), CaseName);

}  // namespace
}  // namespace radiosity
