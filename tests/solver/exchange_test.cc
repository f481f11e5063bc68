// Gebhart factors and net radiative exchange against the closed forms of grey-body radiation
// (Modest, Radiative Heat Transfer, 3rd ed., ch. 5; Incropera, eqs. 13.24 and 13.25): two
// infinite parallel plates, concentric spheres (any convex body inside an enclosure), two surfaces
// with a reradiating third (the network method); Kirchhoff's law (no net exchange at one
// temperature, with or without an environment) and the thermal CSV's contract.
#include "solver/methods/exchange.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "solver/input/thermal_file.h"
#include "solver/methods/viewfactor.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

constexpr double kSigma = kStefanBoltzmann;

// A view-factor matrix given by hand.
ViewFactorMatrix Matrix(std::vector<std::string> names, std::vector<double> area,
                        std::vector<double> f) {
  ViewFactorMatrix m;
  m.surfaces = std::move(names);
  m.area = std::move(area);
  m.SetDense(f);
  return m;
}

ThermalInput Thermal(std::vector<SurfaceThermal> surfaces, double ambient = 0) {
  ThermalInput t;
  t.surfaces = std::move(surfaces);
  t.ambient_temperature = ambient;
  return t;
}

double T4(double t) { return t * t * t * t; }

class ParallelPlatesTest : public ::testing::TestWithParam<std::pair<double, double>> {};

// Two infinite parallel plates (F_12 = F_21 = 1, per unit area): q = sigma (T1^4 - T2^4) /
// (1/eps1 + 1/eps2 - 1), and B_12 = eps2 / (1 - rho1 rho2) (the geometric series of reflections).
TEST_P(ParallelPlatesTest, NetFluxIsTheClosedForm) {
  const auto [e1, e2] = GetParam();
  const double t1 = 1000, t2 = 300;
  ViewFactorMatrix m = Matrix({"hot", "cold"}, {1, 1}, {0, 1, 1, 0});
  absl::StatusOr<RadiantExchange> x =
      ComputeExchange(m, Thermal({{"hot", e1, t1}, {"cold", e2, t2}}));
  ASSERT_TRUE(x.ok()) << x.status();
  const double q = kSigma * (T4(t1) - T4(t2)) / (1 / e1 + 1 / e2 - 1);
  EXPECT_NEAR(x->net[0], q, 1e-12 * q);
  EXPECT_NEAR(x->net[1], -q, 1e-12 * q);
  EXPECT_NEAR(x->NetPair(0, 1), q, 1e-12 * q);
  const double r1 = 1 - e1, r2 = 1 - e2;
  EXPECT_NEAR(x->b(0, 1), e2 / (1 - r1 * r2), 1e-13);
  EXPECT_NEAR(x->b(0, 0), r2 * e1 / (1 - r1 * r2), 1e-13);
  EXPECT_NEAR(x->b(1, 0), e1 / (1 - r1 * r2), 1e-13);
  EXPECT_LT(x->max_closure_error, 1e-13);
  EXPECT_LT(x->max_reciprocity_error, 1e-12);
  EXPECT_NEAR(x->to_environment[0], 0, 1e-12 * x->emitted[0]);
}

INSTANTIATE_TEST_SUITE_P(Emissivities, ParallelPlatesTest,
                         ::testing::Values(std::pair{1.0, 1.0}, std::pair{0.8, 0.3},
                                           std::pair{0.05, 0.9}, std::pair{0.01, 0.02}));

// Two surfaces and a reradiating one (emissivity 0: it absorbs nothing, so loses nothing) in a
// long duct of equilateral cross-section (every F_ij = 1/2, equal areas). The network method
// (Incropera eq. 13.30): q_1 = sigma (T1^4 - T2^4) / (R1 + R12 + R2), R_i = (1 - eps_i) / (A_i
// eps_i), R12 = 1 / (A1 F12 + 1 / (1 / (A1 F1R) + 1 / (A2 F2R))).
TEST(ExchangeTest, ReradiatingSurfaceMatchesTheNetworkMethod) {
  const double e1 = 0.7, e2 = 0.4, t1 = 900, t2 = 400;
  ViewFactorMatrix m =
      Matrix({"one", "two", "wall"}, {1, 1, 1}, {0, 0.5, 0.5, 0.5, 0, 0.5, 0.5, 0.5, 0});
  absl::StatusOr<RadiantExchange> x =
      ComputeExchange(m, Thermal({{"one", e1, t1}, {"two", e2, t2}, {"wall", 0, 12345}}));
  ASSERT_TRUE(x.ok()) << x.status();
  const double r12 = 1 / (0.5 + 1 / (1 / 0.5 + 1 / 0.5));
  const double q = kSigma * (T4(t1) - T4(t2)) / ((1 - e1) / e1 + r12 + (1 - e2) / e2);
  EXPECT_NEAR(x->net[0], q, 1e-12 * q);
  EXPECT_NEAR(x->net[1], -q, 1e-12 * q);
  EXPECT_NEAR(x->net[2], 0, 1e-12 * q);
  EXPECT_EQ(x->emitted[2], 0);  // Its temperature plays no part.
}

// Concentric spheres (an icosphere of radius 1 facing out inside one of radius 2 facing in; the
// closed form needs only F_11 = 0 and closure, so it holds for the facetted spheres with their
// facetted areas): q = sigma A1 (T1^4 - T2^4) / (1/eps1 + (A1/A2) (1/eps2 - 1)). The view factors
// come from the geometry: Monte Carlo rays (F_11 = 0 exactly: no ray from a convex body returns to
// it), then closure enforced, which makes F_12 = 1 and F_21 = A1/A2 exact; without it the noise of
// the rays stays within 1 %.
TEST(ExchangeTest, ConcentricSpheresFromTheirGeometry) {
  const Scene scene = testing::ConcentricIcospheres(1);
  const double e1 = 0.6, e2 = 0.2, t1 = 600, t2 = 290;
  for (const char* enforce : {"closure", "none"}) {
    SCOPED_TRACE(enforce);
    ViewFactorOptions o;
    o.method = "montecarlo";
    o.rays_per_surface = 200'000;
    o.enforce = enforce;
    absl::StatusOr<ViewFactorMatrix> m = ComputeViewFactors(scene, o, nullptr);
    ASSERT_TRUE(m.ok()) << m.status();
    EXPECT_EQ(m->at(0, 0), 0);
    absl::StatusOr<RadiantExchange> x =
        ComputeExchange(*m, Thermal({{"inner", e1, t1}, {"outer", e2, t2}}));
    ASSERT_TRUE(x.ok()) << x.status();
    const double a1 = m->area[0], a2 = m->area[1];
    EXPECT_NEAR(a2 / a1, 4, 1e-12);
    const double q = kSigma * a1 * (T4(t1) - T4(t2)) / (1 / e1 + (a1 / a2) * (1 / e2 - 1));
    const double tol = std::string(enforce) == "closure" ? 1e-9 : 1e-2;
    EXPECT_NEAR(x->net[0], q, tol * q);
    EXPECT_NEAR(x->net[1], -q, tol * q);
    EXPECT_LT(x->max_closure_error, tol);
  }
}

// Kirchhoff: in a closed box at one temperature no surface gains or loses, whatever the
// emissivities; in an open scene the same holds when the environment is at that temperature too,
// and with a colder environment every surface loses exactly what its escaping emission carries
// minus what the environment sends back.
TEST(ExchangeTest, NoNetExchangeAtOneTemperature) {
  const Material black{"black", Rgb(), Rgb(), Rgb(), false, 0};
  absl::StatusOr<ViewFactorMatrix> box =
      ComputeViewFactors(testing::MakeClosedBox(1, 2, 3, black), ViewFactorOptions(), nullptr);
  ASSERT_TRUE(box.ok()) << box.status();
  const std::vector<SurfaceThermal> emissivities = {
      {"x0", 0.9, 500}, {"x1", 0.1, 500}, {"y0", 0.5, 500}, {"*", 0.3, 500}};
  absl::StatusOr<RadiantExchange> x = ComputeExchange(*box, Thermal(emissivities));
  ASSERT_TRUE(x.ok()) << x.status();
  for (int i = 0; i < x->size(); ++i) {
    EXPECT_NEAR(x->net[i], 0, 1e-5 * x->emitted[i]) << x->surfaces[i];
    EXPECT_NEAR(x->to_environment[i], 0, 1e-5 * x->emitted[i]) << x->surfaces[i];
  }
  EXPECT_DOUBLE_EQ(x->emissivity[5], 0.3);  // z1 took the default row.

  absl::StatusOr<ViewFactorMatrix> open =
      ComputeViewFactors(testing::OpposedRectanglesScene(1, 2, 1), ViewFactorOptions(), nullptr);
  ASSERT_TRUE(open.ok()) << open.status();
  const std::vector<SurfaceThermal> plates = {{"bottom", 0.8, 400}, {"top", 0.35, 400}};
  x = ComputeExchange(*open, Thermal(plates, 400));
  ASSERT_TRUE(x.ok()) << x.status();
  for (int i = 0; i < 2; ++i) {
    EXPECT_GT(x->to_environment[i], 0.3 * x->emitted[i]);
    EXPECT_NEAR(x->net[i], 0, 1e-5 * x->emitted[i]) << x->surfaces[i];
  }
  // Black plates facing a 0 K sky: each absorbs exactly what the other sends it, so the bottom
  // loses E_b (1 - F_bt) + (E_b F_bt - E_t F_tb) and sends E_b (1 - F_bt) away.
  const std::vector<SurfaceThermal> black_plates = {{"bottom", 1, 500}, {"top", 1, 300}};
  x = ComputeExchange(*open, Thermal(black_plates, 0));
  ASSERT_TRUE(x.ok()) << x.status();
  const double fbt = open->at(0, 1), ftb = open->at(1, 0);
  const double eb = 2 * kSigma * T4(500), et = 2 * kSigma * T4(300);
  EXPECT_NEAR(x->emitted[0], eb, 1e-12 * eb);
  EXPECT_NEAR(x->to_environment[0], eb * (1 - fbt), 1e-12 * eb);
  EXPECT_NEAR(x->net[0], eb - et * ftb, 1e-12 * eb);
  EXPECT_NEAR(x->NetPair(0, 1), eb * fbt - et * ftb, 1e-12 * eb);
}

TEST(ExchangeTest, BadThermalDataIsNamed) {
  ViewFactorMatrix m = Matrix({"hot", "cold"}, {1, 1}, {0, 1, 1, 0});
  auto error = [&](const ThermalInput& t) {
    absl::StatusOr<RadiantExchange> x = ComputeExchange(m, t);
    return x.ok() ? std::string("ok") : std::string(x.status().message());
  };
  EXPECT_THAT(error(Thermal({{"hot", 0.5, 300}})),
              ::testing::HasSubstr("'cold' has no emissivity"));
  EXPECT_THAT(error(Thermal({{"hot", 0.5, 300}, {"warm", 0.5, 300}, {"*", 1, 3}})),
              ::testing::HasSubstr("'warm' is not a surface"));
  EXPECT_THAT(error(Thermal({{"hot", 1.5, 300}, {"*", 1, 3}})),
              ::testing::HasSubstr("emissivity 1.5 is outside [0, 1]"));
  EXPECT_THAT(error(Thermal({{"*", 1, 3}}, -1)), ::testing::HasSubstr("ambient temperature -1"));
  // Two mirrors facing each other: the light goes round for ever.
  absl::StatusOr<RadiantExchange> x = ComputeExchange(m, Thermal({{"*", 0, 300}}));
  EXPECT_EQ(x.status().code(), absl::StatusCode::kFailedPrecondition) << x.status();
  std::atomic<bool> stop{true};
  x = ComputeExchange(m, Thermal({{"*", 1, 300}}), &stop);
  EXPECT_EQ(x.status().code(), absl::StatusCode::kCancelled) << x.status();
}

TEST(ThermalFileTest, ParsesQuotedNamesAndDefaults) {
  absl::StatusOr<std::vector<SurfaceThermal>> t = ParseThermal(
      "# a satellite\nsurface,emissivity,temperature\r\n\"panel, \"\"A\"\"\",0.85,373.15\n"
      "*, 0.1 , 4\n",
      "sat.csv");
  ASSERT_TRUE(t.ok()) << t.status();
  ASSERT_EQ(t->size(), 2u);
  EXPECT_EQ((*t)[0].surface, "panel, \"A\"");
  EXPECT_DOUBLE_EQ((*t)[0].emissivity, 0.85);
  EXPECT_DOUBLE_EQ((*t)[0].temperature, 373.15);
  EXPECT_EQ((*t)[1].surface, "*");
  EXPECT_DOUBLE_EQ((*t)[1].temperature, 4);
}

TEST(ThermalFileTest, ErrorsNameTheFileAndLine) {
  auto error = [](const std::string& text) {
    absl::StatusOr<std::vector<SurfaceThermal>> t = ParseThermal(text, "t.csv");
    return t.ok() ? std::string("ok") : std::string(t.status().message());
  };
  EXPECT_THAT(error("name,eps,T\n"), ::testing::HasSubstr("t.csv:1: the header must be"));
  EXPECT_THAT(error("surface,emissivity,temperature\na,0.5\n"),
              ::testing::HasSubstr("t.csv:2: expected 3 fields"));
  EXPECT_THAT(error("surface,emissivity,temperature\na,half,300\n"),
              ::testing::HasSubstr("t.csv:2: emissivity 'half' is not a finite number"));
  EXPECT_THAT(error("surface,emissivity,temperature\na,0.5,-3\n"),
              ::testing::HasSubstr("t.csv:2: temperature -3 K is negative"));
  EXPECT_THAT(error("surface,emissivity,temperature\na,0.5,3\n\na,0.2,3\n"),
              ::testing::HasSubstr("t.csv:4: surface 'a' is named twice"));
  EXPECT_THAT(error("surface,emissivity,temperature\n\"a,0.5,3\n"),
              ::testing::HasSubstr("t.csv:2: badly quoted"));
  EXPECT_THAT(error("surface,emissivity,temperature\n"), ::testing::HasSubstr("no surfaces"));
  EXPECT_THAT(error(""), ::testing::HasSubstr("t.csv: empty"));
}

}  // namespace
}  // namespace radiosity
