// Luminaires (solver/transport/luminaire.h) against closed forms: an isotropic point source over
// a plane (E = I cos^3(theta) / h^2), a Lambertian one (E = I0 h^2 / d^4), the mean over an
// element (I x its solid angle / its area), flux conservation in a closed black room (every
// lumen the file's distribution sends arrives), the file's candela reproduced at points around a
// luminaire and unchanged when luminaire and points turn together, an area luminaire far away
// acting as a point, and a solve's books.
#include "solver/transport/luminaire.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <memory>

#include "solver/geometry/sides.h"
#include "solver/input/photometry_file.h"
#include "solver/methods/solve_options.h"
#include "solver/methods/solver.h"
#include "solver/results/element_polygons.h"
#include "solver/transport/gather.h"
#include "solver/util/file_io.h"
#include "tests/testing/photometry_files.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

using testing::Angles;
using testing::IesText;
using testing::MakeWorld;
using testing::Tabulate;
using testing::World;

double Rad(double deg) { return deg * kPi / 180; }

Material Grey(double rho) {
  Material m;
  m.name = "grey";
  m.reflectance = Rgb::Gray(rho);
  return m;
}

// The square [-l, l] x [-l, l] of the plane y = 0, facing up.
Scene Floor(double rho, double l) {
  Scene s;
  s.materials.push_back(Grey(rho));
  testing::AddRect(&s, "floor", 0, Vec3(-l, 0, -l), Vec3(0, 0, 2 * l), Vec3(2 * l, 0, 0));
  return s;
}

std::shared_ptr<const Photometry> Parsed(const std::string& ies) {
  absl::StatusOr<Photometry> p = ParseIes(ies, "test.ies");
  EXPECT_OK(p.status());
  return std::make_shared<const Photometry>(p.ok() ? *p : Photometry());
}

std::shared_ptr<const Photometry> Isotropic(double candela) {
  return Parsed(IesText(Tabulate({0}, {0, 180}, [&](double, double) { return candela; })));
}

double Asymmetric(double c, double g) {
  return 500 * (1 + 0.5 * std::cos(Rad(c)) * std::sin(Rad(g)) +
                0.2 * std::sin(Rad(2 * c)) * std::sin(Rad(g)) + 0.1 * std::cos(Rad(g)));
}

Luminaire At(const Vec3& p, std::shared_ptr<const Photometry> photometry) {
  Luminaire l;
  l.file = "test.ies";
  l.position = p;
  l.photometry = std::move(photometry);
  return l;
}

// Sensor irradiance with the given luminaires after a solve of `world` lit by them.
SensorIrradiance Sensed(const World& world, const std::vector<Luminaire>& luminaires,
                        const std::vector<SensorPoint>& sensors) {
  SolveOptions o;
  o.luminaires = luminaires;
  absl::StatusOr<testing::SolveRun> run = testing::Solve(world, o);
  EXPECT_OK(run.status());
  GatherOptions g;
  g.luminaires = luminaires;
  g.samples = 64;
  return GatherIrradiance(world.scene, *world.mesh, *world.vis, run->solution, sensors, g);
}

TEST(LuminaireTest, IsotropicPointOverAPlaneFollowsTheCosineCubedLaw) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Floor(0.5, 6), 0.5));
  const double h = 3, intensity = 1000;
  std::vector<SensorPoint> sensors;
  for (int k = 0; k < 10; ++k) {
    sensors.push_back({Vec3(0.5 * k, 0, -0.3 * k), Vec3(0, 1, 0), ""});
  }
  const SensorIrradiance out = Sensed(*world, {At(Vec3(0, h, 0), Isotropic(intensity))}, sensors);
  ASSERT_TRUE(out.complete);
  for (size_t i = 0; i < sensors.size(); ++i) {
    const double r = Length(sensors[i].p), cos_theta = h / std::sqrt(h * h + r * r);
    const double expected = intensity * std::pow(cos_theta, 3) / (h * h);
    // The floor sees nothing of itself: the sensor's light is the luminaire's alone, computed.
    EXPECT_NEAR(out.irradiance[i].g, expected, 1e-9 * expected) << "r = " << r;
  }
}

TEST(LuminaireTest, LambertianPointSourceFollowsTheInverseFourthPower) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Floor(0.5, 6), 0.5));
  const double h = 3, i0 = 1000;
  // I = I0 cos(gamma), every degree, read from the file.
  const auto lambert = Parsed(IesText(
      Tabulate({0}, Angles(0, 1, 90), [&](double, double g) { return i0 * std::cos(Rad(g)); })));
  std::vector<SensorPoint> sensors;
  for (int k = 0; k < 10; ++k) sensors.push_back({Vec3(0.55 * k, 0, 0.2 * k), Vec3(0, 1, 0), ""});
  const SensorIrradiance out = Sensed(*world, {At(Vec3(0, h, 0), lambert)}, sensors);
  for (size_t i = 0; i < sensors.size(); ++i) {
    const double d2 = h * h + Dot(sensors[i].p, sensors[i].p);
    const double expected = i0 * h * h / (d2 * d2);
    // Linear interpolation of cos between degrees: within 4e-5.
    EXPECT_NEAR(out.irradiance[i].g, expected, 4e-5 * expected) << "d^2 = " << d2;
  }
}

// Solid angle of [x0, x1] x [z0, z1] of a plane seen from height h above the origin (the corner
// formula atan(ab / (h sqrt(h^2 + a^2 + b^2))) by inclusion and exclusion).
double SolidAngle(double x0, double x1, double z0, double z1, double h) {
  auto f = [&](double a, double b) {
    return std::atan(a * b / (h * std::sqrt(h * h + a * a + b * b)));
  };
  return f(x1, z1) - f(x0, z1) - f(x1, z0) + f(x0, z0);
}

TEST(LuminaireTest, ElementsReceiveTheIntensityTimesTheirSolidAngle) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Floor(0.5, 3), 0.5));
  const double h = 2, intensity = 800;
  const ElementIrradiance out =
      LuminaireIrradiance(*world->mesh, *world->vis, {At(Vec3(0.3, h, -0.2), Isotropic(intensity))},
                          kDefaultLuminaireSamples, 7, StopToken());
  ASSERT_TRUE(out.complete);
  const Mesh& mesh = *world->mesh;
  double worst = 0, total = 0;
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    // Its extent in scene coordinates, from the corners of the polygons it is drawn as.
    Vec3 lo(1e30, 1e30, 1e30), hi(-1e30, -1e30, -1e30);
    ForEachElementVertex(mesh, static_cast<int64_t>(e), [&](const Vec3& p, int, double, double) {
      lo = Min(lo, p);
      hi = Max(hi, p);
    });
    const double area = mesh.elements()[e].area;
    ASSERT_NEAR((hi.x - lo.x) * (hi.z - lo.z), area, 1e-4 * area);
    const double expected =
        intensity * SolidAngle(lo.x - 0.3, hi.x - 0.3, lo.z + 0.2, hi.z + 0.2, h) / area;
    const int slot = Slot(static_cast<int>(e), kFront);
    worst = std::max(worst, std::fabs(out.irradiance[slot].g / expected - 1));
    EXPECT_NEAR(out.irradiance[slot].g, expected,
                std::max(4 * out.std_error[slot].g, 2e-3 * expected));
    total += out.irradiance[slot].g * area;
  }
  EXPECT_LT(worst, 0.01);
  EXPECT_NEAR(total, intensity * SolidAngle(-3.3, 2.7, -2.8, 3.2, h), 1e-3 * total);
  EXPECT_GT(out.rays, 0);
}

// A closed black room: every lumen the luminaire sends arrives on its walls.
void ExpectAllLumensArrive(const Luminaire& luminaire) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world,
                       MakeWorld(testing::MakeClosedBox(4, 3, 5, Grey(0)), 0.25));
  const ElementIrradiance out = LuminaireIrradiance(*world->mesh, *world->vis, {luminaire},
                                                    kDefaultLuminaireSamples, 3, StopToken());
  double arrived = 0, variance = 0;
  for (size_t e = 0; e < world->mesh->elements().size(); ++e) {
    const double area = world->mesh->elements()[e].area;
    for (int side : {kFront, kBack}) {
      const int slot = Slot(static_cast<int>(e), side);
      arrived += out.irradiance[slot].g * area;
      variance += std::pow(out.std_error[slot].g * area, 2);
    }
  }
  const double flux = luminaire.Flux().g;
  EXPECT_NEAR(flux, luminaire.photometry->flux, 1e-12 * flux);  // White: luminance 1.
  EXPECT_NEAR(arrived, flux, std::max(4 * std::sqrt(variance), 1e-3 * flux))
      << "standard error " << std::sqrt(variance);
  EXPECT_NEAR(arrived, flux, 5e-3 * flux);
}

TEST(LuminaireTest, AClosedBlackRoomReceivesEveryLumen) {
  const auto table = Parsed(IesText(Tabulate(Angles(0, 15, 345), Angles(0, 5, 180), Asymmetric)));
  Luminaire l = At(Vec3(1.3, 2.1, 3.2), table);
  l.aim = Vec3(0.3, -1, 0.2);
  l.c0 = Vec3(1, 0, 0.4);
  ExpectAllLumensArrive(l);
  // An area luminaire: a 0.6 m x 0.4 m opening sends the same lumens.
  const auto area = Parsed(IesText(Tabulate(Angles(0, 15, 345), Angles(0, 5, 180), Asymmetric),
                                   /*width=*/0.4, /*length=*/0.6));
  Luminaire a = At(Vec3(2, 2.5, 2.5), area);
  ASSERT_TRUE(a.IsArea());
  ExpectAllLumensArrive(a);
}

// Points at distance d from the luminaire in the directions of the table's (C, gamma), facing it:
// each receives I(C, gamma) / d^2, the file's value, for a downlight whose C0 is +x and C90 a
// quarter turn counterclockwise seen from above (-z, with y up), as LM-63 defines them.
TEST(LuminaireTest, TheFilesCandelaArriveAtPointsAroundIt) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Floor(0, 50), 5));
  const testing::CandelaTable table = Tabulate(Angles(0, 15, 345), Angles(0, 5, 180), Asymmetric);
  const Vec3 centre(0, 10, 0);
  const double d = 2;
  std::vector<SensorPoint> sensors;
  std::vector<double> expected;
  for (size_t i = 0; i < table.c.size(); i += 5) {
    for (size_t j = 1; j + 1 < table.gamma.size(); j += 4) {
      const double c = Rad(table.c[i]), g = Rad(table.gamma[j]);
      const Vec3 dir =
          Vec3(std::cos(c), 0, -std::sin(c)) * std::sin(g) + Vec3(0, -1, 0) * std::cos(g);
      sensors.push_back({centre + dir * d, -dir, ""});
      expected.push_back(table.candela[i * table.gamma.size() + j] / (d * d));
    }
  }
  Luminaire l = At(centre, Parsed(IesText(table)));
  const SensorIrradiance straight = Sensed(*world, {l}, sensors);
  for (size_t k = 0; k < sensors.size(); ++k) {
    EXPECT_NEAR(straight.irradiance[k].g, expected[k], 1e-9 * expected[k]) << k;
  }
  // Luminaire and points turned together (about an oblique axis): the same light at each point.
  auto turn = [](const Vec3& v) {
    const Vec3 axis = Normalize(Vec3(1, 2, 3));
    const double a = 0.7;
    return v * std::cos(a) + Cross(axis, v) * std::sin(a) + axis * Dot(axis, v) * (1 - std::cos(a));
  };
  std::vector<SensorPoint> turned;
  for (const SensorPoint& s : sensors) {
    turned.push_back({centre + turn(s.p - centre), turn(s.n), ""});
  }
  l.aim = turn(Vec3(0, -1, 0));
  l.c0 = turn(Vec3(1, 0, 0));
  const SensorIrradiance rotated = Sensed(*world, {l}, turned);
  for (size_t k = 0; k < sensors.size(); ++k) {
    EXPECT_NEAR(rotated.irradiance[k].g, expected[k], 1e-9 * expected[k]) << k;
  }
}

TEST(LuminaireTest, AnAreaLuminaireFarAwayActsAsAPoint) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Floor(0, 40), 4));
  const auto table = Tabulate(Angles(0, 15, 345), Angles(0, 5, 180), Asymmetric);
  const Luminaire point = At(Vec3(0, 20, 0), Parsed(IesText(table)));
  const Luminaire area = At(Vec3(0, 20, 0), Parsed(IesText(table, 0.2, 0.3)));
  std::vector<SensorPoint> sensors;
  for (int k = 0; k < 8; ++k) sensors.push_back({Vec3(2.0 * k, 0, -1.5 * k), Vec3(0, 1, 0), ""});
  // LM-63's round opening: width and length negative, the diameter.
  const Luminaire disc = At(Vec3(0, 20, 0), Parsed(IesText(table, -0.3, -0.3)));
  ASSERT_TRUE(area.IsArea());
  ASSERT_TRUE(disc.IsArea());
  for (int k = 0; k < 64; ++k) {
    const Vec3 y = disc.OpeningPoint((k % 8 + 0.5) / 8, (k / 8 + 0.5) / 8) - disc.position;
    EXPECT_LE(Length(y), 0.15 + 1e-12);
    EXPECT_NEAR(y.y, 0, 1e-12);  // In the plane across the aim.
  }
  const SensorIrradiance p = Sensed(*world, {point}, sensors);
  for (const Luminaire& l : {area, disc}) {
    const SensorIrradiance a = Sensed(*world, {l}, sensors);
    for (size_t k = 0; k < sensors.size(); ++k) {
      // The opening is 1/60 of the distance: its points differ by (1/60)^2 in 1/d^2 and a little
      // in angle.
      EXPECT_NEAR(a.irradiance[k].g, p.irradiance[k].g, 2e-3 * p.irradiance[k].g) << k;
      EXPECT_GT(a.std_error[k].g, 0);
    }
  }
}

TEST(LuminaireTest, AWhiteRoomLitByALuminaireBalancesItsBooks) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world,
                       MakeWorld(testing::MakeClosedBox(4, 3, 5, Grey(0.6)), 0.4));
  SolveOptions o;
  o.luminaires = {At(Vec3(2, 2.9, 2.5), Isotropic(100))};
  ASSERT_OK_AND_ASSIGN(testing::SolveRun run, testing::Solve(*world, o));
  testing::ExpectBooksBalance(run.solution);
  EXPECT_LE(run.solution.unshot_fraction, o.tolerance);
  // Every lumen arrives on a reflecting wall: the books count them all as emitted.
  EXPECT_NEAR(run.solution.emitted_power.g, 4 * kPi * 100, 5e-3 * 4 * kPi * 100);
  // A closed room of reflectance rho: total exitance = Phi rho / (1 - rho) on the walls.
  double exitant = 0;
  for (size_t e = 0; e < world->mesh->elements().size(); ++e) {
    exitant += run.solution.radiosity[Slot(static_cast<int>(e), kFront)].g *
               world->mesh->elements()[e].area;
  }
  EXPECT_NEAR(exitant, 4 * kPi * 100 * 0.6 / 0.4, 0.01 * 4 * kPi * 100 * 0.6 / 0.4);
}

TEST(LuminaireTest, StopEndsTheStepEarly) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Floor(0.5, 3), 0.05));
  std::atomic<bool> stop{true};
  const ElementIrradiance out = LuminaireIrradiance(
      *world->mesh, *world->vis, {At(Vec3(0, 1, 0), Isotropic(1))}, 64, 1, StopToken(&stop, 0));
  EXPECT_FALSE(out.complete);
  EXPECT_EQ(out.rays, 0);
}

TEST(LuminaireTest, OptionsAreCheckedAndNeedProgressiveAndALoadedFile) {
  SolveOptions o;
  o.luminaires = {At(Vec3(0, 1, 0), Isotropic(1))};
  EXPECT_OK(Validate(o, FieldNaming::kFlag));
  o.method = "jacobi";
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"--luminaire", "progressive"}));
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kField), absl::StatusCode::kInvalidArgument,
                               {"solve.luminaires"}));
  o.method = "progressive";
  o.luminaires[0].aim = Vec3();
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"luminaire 1 (test.ies)", "aim"}));
  o.luminaires[0].aim = Vec3(0, -1, 0);
  o.luminaires[0].multiplier = -2;
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"multiplier -2"}));
  o.luminaires[0].multiplier = 1;
  o.luminaires[0].color = Rgb();
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"colour", "luminance > 0"}));
  o.luminaires[0].color = Rgb(1, 1, 1);
  o.luminaires[0].position = Vec3(std::nan(""), 0, 0);
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"position"}));
  // A luminaire whose file was never read.
  o.luminaires[0] = At(Vec3(0, 1, 0), nullptr);
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Floor(0.5, 1), 0.5));
  EXPECT_TRUE(
      testing::Refused(CreateSolver(world->scene, *world->mesh, *world->vis, o, nullptr).status(),
                       absl::StatusCode::kFailedPrecondition, {"test.ies", "not loaded"}));
}

TEST(LuminaireTest, LoadScenePhotometryReadsOnlyTheScenesFiles) {
  const std::string dir = ::testing::TempDir() + "/luminaire_files";
  std::filesystem::create_directories(dir);
  ASSERT_OK(WriteWholeFile(dir + "/lamp.ies",
                           IesText(Tabulate({0}, {0, 180}, [](double, double) { return 5.0; }))));
  ASSERT_OK(
      WriteWholeFile(dir + "/bad.ies", "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 2 1 1 2 0 0 0\n"));
  ASSERT_OK_AND_ASSIGN(Photometry p, LoadScenePhotometry(dir, "lamp.ies", "client/dir"));
  EXPECT_DOUBLE_EQ(p.Intensity(10, 20), 5);
  EXPECT_EQ(p.source, "client/dir/lamp.ies");
  for (const std::string name : {"../lamp.ies", "/etc/lamp.ies", "a/./lamp.ies", ""}) {
    EXPECT_TRUE(testing::Refused(LoadScenePhotometry(dir, name), absl::StatusCode::kInvalidArgument,
                                 {"relative name"}))
        << name;
  }
  EXPECT_TRUE(testing::Refused(LoadScenePhotometry(dir, "missing.ies"),
                               absl::StatusCode::kFailedPrecondition,
                               {"missing.ies", "not among the scene's files"}));
  EXPECT_TRUE(testing::Refused(LoadScenePhotometry(dir, "bad.ies", "client/dir"),
                               absl::StatusCode::kInvalidArgument,
                               {"client/dir/bad.ies:3:", "ends before"}));
}

}  // namespace
}  // namespace radiosity
