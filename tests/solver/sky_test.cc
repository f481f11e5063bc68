// Daylight from outside (--sky, solver/transport/sky.h) against closed forms: the open sky on
// horizontal and vertical surfaces (uniform: E_h and E_h / 2; CIE overcast: E_h and 0.3961 E_h),
// the floor of a well (E_h times the view factor to its opening, Howell C-11), the books of a
// solve lit only by the sky, and where --sky is refused.
#include "solver/transport/sky.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <memory>

#include "solver/geometry/mesh.h"
#include "solver/geometry/sides.h"
#include "solver/methods/solve_options.h"
#include "solver/methods/solver.h"
#include "solver/transport/gather.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

using testing::AddRect;
using testing::MakeWorld;
using testing::World;

constexpr double kEh = 100;  // W/m^2 under the open sky.

Material Grey(double rho) {
  Material m;
  m.name = "grey";
  m.reflectance = Rgb::Gray(rho);
  return m;
}

// One unit square facing `normal` (+y: up, +x: a wall), alone under the sky.
Scene Square(const Vec3& normal) {
  Scene s;
  s.materials.push_back(Grey(0.5));
  if (normal.y > 0) {
    AddRect(&s, "square", 0, Vec3(0, 0, 0), Vec3(0, 0, 1), Vec3(1, 0, 0));
  } else {
    AddRect(&s, "square", 0, Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1));
  }
  return s;
}

SkyOptions Sky(const std::string& model) {
  SkyOptions sky;
  sky.model = model;
  sky.irradiance = Rgb::Gray(kEh);
  return sky;
}

// Area-weighted mean front irradiance of surface `surface`, and the largest standard error.
struct Mean {
  double irradiance = 0, worst_se = 0;
};
Mean MeanOf(const World& world, const ElementIrradiance& sky, int surface) {
  Mean m;
  double area = 0;
  for (size_t e = 0; e < world.mesh->elements().size(); ++e) {
    const Element& element = world.mesh->elements()[e];
    if (element.surface != surface) continue;
    const int slot = Slot(static_cast<int>(e), kFront);
    m.irradiance += element.area * sky.irradiance[slot].g;
    m.worst_se = std::max(m.worst_se, sky.std_error[slot].g);
    area += element.area;
  }
  m.irradiance /= area;
  return m;
}

TEST(SkyTest, OpenSkyOnHorizontalAndVerticalSurfaces) {
  struct Case {
    const char* model;
    Vec3 normal;
    double expected;  // / E_h
  };
  const double overcast_vertical = (kPi / 2 + 4.0 / 3) / (7 * kPi / 3);
  for (const Case& c :
       {Case{"uniform", Vec3(0, 1, 0), 1}, Case{"uniform", Vec3(1, 0, 0), 0.5},
        Case{"overcast", Vec3(0, 1, 0), 1}, Case{"overcast", Vec3(1, 0, 0), overcast_vertical}}) {
    SCOPED_TRACE(::testing::Message() << c.model << " normal " << c.normal.x << "," << c.normal.y);
    ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Square(c.normal), 0.25));
    const ElementIrradiance sky =
        SkyIrradiance(*world->mesh, *world->vis, Sky(c.model), /*seed=*/3, StopToken());
    ASSERT_TRUE(sky.complete);
    for (size_t e = 0; e < world->mesh->elements().size(); ++e) {
      const int slot = Slot(static_cast<int>(e), kFront);
      // Every element sees the same open sky: within 4 of its standard errors, and 1 %.
      EXPECT_NEAR(sky.irradiance[slot].g, c.expected * kEh, 4 * sky.std_error[slot].g + 1e-9 * kEh);
      EXPECT_NEAR(sky.irradiance[slot].g / kEh, c.expected, 0.01);
      // The one-sided square's back does not exist: nothing is computed there.
      EXPECT_EQ(sky.irradiance[Slot(static_cast<int>(e), kBack)].g, 0);
    }
  }
}

TEST(SkyTest, TheUpDirectionTurnsTheSky) {
  // A square facing +x under a sky whose zenith is +x is horizontal to it: all of E_h.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Square(Vec3(1, 0, 0)), 0.5));
  SkyOptions sky = Sky("overcast");
  sky.up = Vec3(2, 0, 0);  // Need not be unit length.
  const ElementIrradiance out = SkyIrradiance(*world->mesh, *world->vis, sky, 1, StopToken());
  EXPECT_NEAR(MeanOf(*world, out, 0).irradiance / kEh, 1, 0.005);
  // Facing away from the zenith (down), no sky at all.
  sky.up = Vec3(-1, 0, 0);
  const ElementIrradiance none = SkyIrradiance(*world->mesh, *world->vis, sky, 1, StopToken());
  EXPECT_EQ(MeanOf(*world, none, 0).irradiance, 0);
}

// A well: a unit-square floor at the bottom of four black walls of height 1, open at the top.
// Under a uniform sky the floor receives E_h F(floor -> opening) (Howell C-11, opposed unit
// squares at distance 1: 0.19982); the walls, black, take no light into the books.
Scene Well(double wall_reflectance) {
  Scene s;
  s.materials.push_back(Grey(0.5));
  s.materials.push_back(Grey(wall_reflectance));
  s.materials[1].name = "wall";
  AddRect(&s, "floor", 0, Vec3(0, 0, 0), Vec3(0, 0, 1), Vec3(1, 0, 0));
  AddRect(&s, "wall", 1, Vec3(0, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1));  // x = 0, facing +x
  AddRect(&s, "wall", 1, Vec3(1, 0, 0), Vec3(0, 0, 1), Vec3(0, 1, 0));  // x = 1, facing -x
  AddRect(&s, "wall", 1, Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0));  // z = 0, facing +z
  AddRect(&s, "wall", 1, Vec3(0, 0, 1), Vec3(0, 1, 0), Vec3(1, 0, 0));  // z = 1, facing -z
  return s;
}

TEST(SkyTest, WellFloorReceivesTheSkyThroughItsOpening) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Well(0), 0.1));
  SkyOptions sky = Sky("uniform");
  const ElementIrradiance out = SkyIrradiance(*world->mesh, *world->vis, sky, 5, StopToken());
  const Mean floor = MeanOf(*world, out, 0);
  const double f = testing::OpposedRectangles(1, 1, 1);
  ASSERT_NEAR(f, 0.19982, 1e-4);
  EXPECT_NEAR(floor.irradiance, kEh * f, 0.01 * kEh * f);

  // Solved with the walls black: the floor's radiosity is rho E_h F per element on average, and
  // the books balance with the sky's light counted as emitted.
  SolveOptions options;
  options.sky = sky;
  options.sky.samples = 1024;
  ASSERT_OK_AND_ASSIGN(testing::SolveRun run, testing::Solve(*world, options));
  testing::ExpectBooksBalance(run.solution);
  double area = 0, mean = 0;
  for (size_t e = 0; e < world->mesh->elements().size(); ++e) {
    const Element& element = world->mesh->elements()[e];
    if (element.surface != 0) continue;
    area += element.area;
    mean += element.area * run.solution.radiosity[Slot(static_cast<int>(e), kFront)].g;
  }
  EXPECT_NEAR(mean / area, 0.5 * kEh * f, 0.01 * 0.5 * kEh * f);
  EXPECT_GT(run.solution.emitted_power.g, 0);
}

TEST(SkyTest, ReflectingWellBalancesItsBooksAndOutshinesTheBlackOne) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> black, MakeWorld(Well(0), 0.1));
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> white, MakeWorld(Well(0.8), 0.1));
  SolveOptions options;
  options.sky = Sky("overcast");
  ASSERT_OK_AND_ASSIGN(testing::SolveRun dark, testing::Solve(*black, options));
  ASSERT_OK_AND_ASSIGN(testing::SolveRun lit, testing::Solve(*white, options));
  testing::ExpectBooksBalance(lit.solution);
  EXPECT_LE(lit.solution.unshot_fraction, options.tolerance);
  const std::vector<Rgb> d = testing::SurfaceMeans(*black, dark.solution);
  const std::vector<Rgb> l = testing::SurfaceMeans(*white, lit.solution);
  // Light reflected off white walls adds to what the floor receives straight from the sky.
  EXPECT_GT(l[0].g, 1.3 * d[0].g);
}

TEST(SkyTest, StopEndsTheSkyStepEarly) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Well(0.5), 0.02));
  std::atomic<bool> stop{true};
  const ElementIrradiance out =
      SkyIrradiance(*world->mesh, *world->vis, Sky("uniform"), 1, StopToken(&stop, 0));
  EXPECT_FALSE(out.complete);
  EXPECT_EQ(out.rays, 0);
}

TEST(SkyTest, OnlyProgressiveTakesASkyAndItNeedsLight) {
  SolveOptions o;
  o.sky = Sky("overcast");
  EXPECT_OK(Validate(o, FieldNaming::kFlag));
  o.method = "auto";
  EXPECT_OK(Validate(o, FieldNaming::kFlag));
  o.method = "jacobi";
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"--sky", "progressive"}));
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kField), absl::StatusCode::kInvalidArgument,
                               {"solve.sky.model"}));
  o.method = "progressive";
  o.sky.irradiance = Rgb();
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"--sky", "irradiance > 0"}));
  o.sky = Sky("cloudy");
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"--sky", "cloudy"}));
  o.sky = Sky("uniform");
  o.sky.up = Vec3();
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"--sky-up"}));
  o.sky = Sky("uniform");
  o.sky.samples = 0;
  EXPECT_TRUE(testing::Refused(Validate(o, FieldNaming::kFlag), absl::StatusCode::kInvalidArgument,
                               {"--sky-samples"}));
}

TEST(SkyTest, ASceneWithoutEmittersSolvesUnderTheSkyAndIsRefusedWithout) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Well(0.5), 0.1));
  SolveOptions options;
  absl::StatusOr<std::unique_ptr<Solver>> none =
      CreateSolver(world->scene, *world->mesh, *world->vis, options, nullptr);
  EXPECT_TRUE(testing::Refused(none, absl::StatusCode::kFailedPrecondition, {"--sky"}));
  options.method = "auto";
  options.sky = Sky("uniform");
  EXPECT_OK(CreateSolver(world->scene, *world->mesh, *world->vis, options, nullptr));
}

}  // namespace
}  // namespace radiosity

namespace radiosity {
namespace {

// Sensors gather the sky they see: a point under the open sky receives E_h facing up and E_h / 2
// facing sideways (uniform), whatever the mesh.
TEST(SkyTest, SensorsUnderTheOpenSkyReceiveIt) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<World> world, MakeWorld(Square(Vec3(0, 1, 0)), 0.25));
  SolveOptions o;
  o.sky = Sky("uniform");
  ASSERT_OK_AND_ASSIGN(testing::SolveRun run, testing::Solve(*world, o));
  GatherOptions g;
  g.sky = o.sky;
  const std::vector<SensorPoint> sensors = {{Vec3(0.5, 0.01, 0.5), Vec3(0, 1, 0), ""},
                                            {Vec3(0.5, 0.5, 0.5), Vec3(1, 0, 0), ""}};
  const SensorIrradiance out =
      GatherIrradiance(world->scene, *world->mesh, *world->vis, run.solution, sensors, g);
  EXPECT_NEAR(out.irradiance[0].g, kEh, 1e-3 * kEh);
  // Sideways, half the sky and the lit square below (radiosity 0.5 E_h over part of the view).
  EXPECT_GT(out.irradiance[1].g, 0.5 * kEh * 0.98);
  EXPECT_LT(out.irradiance[1].g, 0.5 * kEh + 0.5 * 0.5 * kEh);
}

}  // namespace
}  // namespace radiosity
