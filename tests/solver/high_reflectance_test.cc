// Reflectance near 1: a closed furnace of reflectance rho and exitance E has B = E / (1 - rho)
// on every element, 10^5 and 10^6 times the emission at rho = 0.99999 and 0.999999. The default
// method (auto: hierarchical radiosity, whose Krylov cycles and closure-normalised factors do not
// slow down or diverge as rho nears 1) reaches it with a residual that never grows; progressive
// refinement, whose rays grow like 1 / (1 - rho), stops at its documented bound as stalled, with
// the complete estimate (the ambient term) in place of what it could not shoot.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "solver/methods/method_choice.h"
#include "solver/methods/solver.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

Scene Furnace(double rho) {
  Material m;
  m.name = "white";
  m.reflectance = Rgb::Gray(rho);
  m.emission = Rgb::Gray(1);
  return testing::MakeClosedBox(1, 1, 1, m);
}

double WorstRelativeError(const Mesh& mesh, const Solution& sol, double expected) {
  double worst = 0;
  for (int e = 0; e < static_cast<int>(mesh.elements().size()); ++e) {
    worst = std::max(worst, std::fabs(sol.radiosity[Slot(e, kFront)].g / expected - 1));
  }
  return worst;
}

class HighReflectanceTest : public ::testing::TestWithParam<double> {};

TEST_P(HighReflectanceTest, DefaultMethodReachesTheClosedFormWithAResidualThatNeverGrows) {
  const double rho = GetParam();
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w, testing::MakeWorld(Furnace(rho), 0.1));
  SolveOptions options;
  options.method = "auto";
  EXPECT_EQ(ChooseMethod(*w->mesh, options).method, "hierarchical");
  ASSERT_OK_AND_ASSIGN(testing::SolveRun run, testing::Solve(*w, options));
  EXPECT_EQ(run.reason, StopReason::kConverged) << StopReasonName(run.reason);
  EXPECT_LT(WorstRelativeError(*w->mesh, run.solution, 1 / (1 - rho)), 0.01);
  // Never up, to rounding (below 1e-9 of the emission, the residual is rounding of B = 10^6).
  for (size_t k = 1; k < run.fractions.size(); ++k) {
    EXPECT_LE(run.fractions[k], run.fractions[k - 1] + 1e-9) << "step " << k;
  }
}

INSTANTIATE_TEST_SUITE_P(Rho, HighReflectanceTest, ::testing::Values(0.99999, 0.999999));

TEST(HighReflectanceTest, ProgressiveStopsAsStalledWithACompleteEstimate) {
  const double rho = 0.99999;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w, testing::MakeWorld(Furnace(rho), 0.25));
  SolveOptions options = testing::Budget(200);
  options.method = "progressive";
  ASSERT_OK_AND_ASSIGN(testing::SolveRun run, testing::Solve(*w, options));
  EXPECT_EQ(run.reason, StopReason::kStalled);
  EXPECT_GT(run.solution.unshot_fraction, options.tolerance);
  EXPECT_GT(run.solution.ambient.g, 0);
  testing::ExpectBooksBalance(run.solution);
  // The ambient term is exact in a furnace of one reflectance: the estimate holds every element
  // to the closed form though almost all the light is still unshot.
  EXPECT_LT(WorstRelativeError(*w->mesh, run.solution, 1 / (1 - rho)), 0.01);
}

}  // namespace
}  // namespace radiosity
