// The method registry and the one validation of solve options (solve_options.h, registry.h,
// ValidateJobSpec): names in one table, the options each method reads, options a method ignores
// reported, meaningless combinations refused, and one set of bounds whichever caller checks them,
// with messages naming the field as that caller spells it.
#include "solver/methods/registry.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <set>
#include <string>
#include <vector>

#include "solver/methods/solve_options.h"
#include "solver/methods/viewfactor.h"
#include "solver/pipeline/job.h"
#include "solver/transport/formfactor.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

std::string Message(const absl::Status& s) { return std::string(s.message()); }

// A closed box of 24 elements at rho = 0.5 and E = 1.
absl::StatusOr<std::unique_ptr<testing::World>> SmallFurnace() {
  MeshOptions mo;
  mo.max_elements = 24;
  return testing::MakeWorld(
      testing::MakeClosedBox(1, 1, 1, {"m", Rgb::Gray(0.5), Rgb::Gray(1), Rgb(), false, 0}), mo);
}

TEST(RegistryTest, NamesAreUniqueAndAutoComesFirst) {
  const std::vector<std::string> names = MethodNames();
  ASSERT_GE(names.size(), 6u);
  EXPECT_EQ(names[0], "auto");
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()).size(), names.size());
  for (const MethodInfo& m : Methods()) {
    EXPECT_EQ(FindMethod(m.name), &m);
    EXPECT_FALSE(m.description.empty()) << m.name;
    EXPECT_FALSE(m.estimators.empty()) << m.name;
    EXPECT_TRUE(m.create) << m.name;
  }
  EXPECT_EQ(FindMethod("auto"), nullptr);
  EXPECT_EQ(FindMethod("radiosity"), nullptr);
}

TEST(RegistryTest, EveryOptionAMethodOrEstimatorReadsIsAKnownOption) {
  std::set<std::string> known;
  for (const OptionName& o : SolveOptionNames()) known.insert(o.key);
  for (const MethodInfo& m : Methods()) {
    for (const std::string& key : m.reads) EXPECT_EQ(known.count(key), 1u) << m.name << " " << key;
    for (const std::string& e : m.estimators) EXPECT_NE(FindEstimator(e), nullptr) << e;
  }
  for (const EstimatorInfo& e : FormFactorEstimators()) {
    for (const std::string& key : e.reads) EXPECT_EQ(known.count(key), 1u) << e.name << " " << key;
  }
}

TEST(RegistryTest, DefaultsAreValidAndIgnoredByNoMethod) {
  for (const std::string& name : MethodNames()) {
    SolveOptions o;
    o.method = name;
    EXPECT_TRUE(Validate(o, FieldNaming::kFlag).ok()) << name;
    EXPECT_THAT(IgnoredOptions(name, o, FieldNaming::kFlag), IsEmpty()) << name;
  }
}

TEST(RegistryTest, OptionsAMethodIgnoresAreReported) {
  SolveOptions o;
  o.overshoot = 1.5;
  EXPECT_THAT(IgnoredOptions("jacobi", o, FieldNaming::kFlag),
              ElementsAre("--overshoot is ignored by --method jacobi"));
  EXPECT_THAT(IgnoredOptions("jacobi", o, FieldNaming::kField),
              ElementsAre("solve.overshoot is ignored by solve.method jacobi"));
  // Progressive reads it, but with Monte Carlo shooting it is known to diverge.
  std::vector<std::string> progressive = IgnoredOptions("progressive", o, FieldNaming::kFlag);
  ASSERT_EQ(progressive.size(), 1u);
  EXPECT_THAT(progressive[0], HasSubstr("usually diverges"));
  o.formfactor.method = "hemicube";
  EXPECT_THAT(IgnoredOptions("progressive", o, FieldNaming::kFlag), IsEmpty());

  SolveOptions r;
  r.tolerance = 1e-5;
  r.overshoot = 1.5;
  EXPECT_THAT(IgnoredOptions("reflection", r, FieldNaming::kFlag),
              ElementsAre("--tolerance is ignored by --method reflection",
                          "--overshoot is ignored by --method reflection"));
  // The options of an estimator the method shoots with are read; others are not.
  SolveOptions rows;
  rows.formfactor.method = "analytic";
  rows.formfactor.shadow_rays = 8;
  rows.formfactor.hemicube_resolution = 64;
  rows.weighted_shooting = false;
  rows.rays_per_element = 50;
  EXPECT_THAT(IgnoredOptions("progressive", rows, FieldNaming::kFlag),
              ElementsAre("--rays-per-element is ignored by --method progressive with "
                          "--formfactor analytic",
                          "--shooting is ignored by --method progressive with --formfactor "
                          "analytic",
                          "--hemicube-resolution is ignored by --method progressive with "
                          "--formfactor analytic"));
  SolveOptions h;
  h.formfactor.shadow_rays = 8;
  h.rays_per_element = 10;
  EXPECT_THAT(IgnoredOptions("hierarchical", h, FieldNaming::kFlag),
              ElementsAre("--rays-per-element is ignored by --method hierarchical"));
}

TEST(RegistryTest, AnEstimatorTheMethodDoesNotUseIsRefused) {
  SolveOptions o;
  o.method = "reflection";
  o.formfactor.method = "analytic";
  absl::Status s = Validate(o, FieldNaming::kFlag);
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(Message(s), HasSubstr("--formfactor: 'analytic' does not apply to --method "
                                    "'reflection', which uses montecarlo"));
  o.method = "hierarchical";
  o.formfactor.method = "hemicube";
  s = Validate(o, FieldNaming::kField);
  EXPECT_THAT(Message(s), HasSubstr("solve.formfactor.method: 'hemicube' does not apply to "
                                    "solve.method 'hierarchical'"));
  o.formfactor.method = "analytic";
  EXPECT_TRUE(Validate(o, FieldNaming::kFlag).ok());
  // "auto" adapts: it never picks hierarchical radiosity for another estimator.
  o.method = "auto";
  o.formfactor.method = "hemicube";
  EXPECT_TRUE(Validate(o, FieldNaming::kFlag).ok());
}

struct Bad {
  std::function<void(SolveOptions*)> set;
  std::string flag_message, field_message;
};

TEST(ValidateTest, EveryBoundNamesTheFieldAsTheCallerSpellsIt) {
  const std::vector<Bad> cases = {
      {[](SolveOptions* o) { o->tolerance = 2; }, "--tolerance: 2 is outside [1e-15, 0.999999]",
       "solve.tolerance: 2 is outside [1e-15, 0.999999]"},
      {[](SolveOptions* o) { o->method = "7"; }, "--method: '7' is not one of auto, progressive",
       "solve.method: '7' is not one of auto, progressive"},
      {[](SolveOptions* o) { o->formfactor.method = "raytrace"; },
       "--formfactor: 'raytrace' is not one of montecarlo, analytic, hemicube",
       "solve.formfactor.method: 'raytrace'"},
      {[](SolveOptions* o) { o->formfactor.analytic_points = 4097; },
       "formfactor.analytic_points: 4097 is outside [1, 4096]",
       "solve.formfactor.analytic_points: 4097 is outside [1, 4096]"},
      {[](SolveOptions* o) { o->formfactor.shadow_rays = 0; },
       "--shadow-rays: 0 is outside [1, 4096]", "solve.formfactor.shadow_rays: 0"},
      {[](SolveOptions* o) { o->formfactor.hemicube_resolution = 66; }, "", ""},
      {[](SolveOptions* o) { o->formfactor.hemicube_resolution = 65; },
       "--hemicube-resolution: 65 is not even", "solve.formfactor.hemicube_resolution: 65"},
      {[](SolveOptions* o) { o->formfactor.hemicube_points = 1'000'001; },
       "formfactor.hemicube_points: 1000001 is outside [1, 1000000]", "hemicube_points"},
      {[](SolveOptions* o) { o->overshoot = 2.5; }, "--overshoot: 2.5 is outside [1, 2]",
       "solve.overshoot"},
      {[](SolveOptions* o) { o->max_matrix_mb = -1; }, "--max-matrix-mb: -1 is not a positive",
       "solve.max_matrix_mb"},
      {[](SolveOptions* o) { o->max_rays = -5; }, "--max-rays: -5 is outside [0, 2^63)",
       "solve.max_rays"},
      {[](SolveOptions* o) { o->max_seconds = -1; }, "--max-seconds: -1 is outside [0, 1e9]",
       "solve.max_seconds"},
      {[](SolveOptions* o) { o->threads = 2000; }, "--threads: 2000 is outside [0, 1024]",
       "solve.threads"},
      {[](SolveOptions* o) { o->rays_per_element = 0; },
       "--rays-per-element: 0 is not a positive number", "solve.rays_per_element"},
  };
  for (const Bad& c : cases) {
    SolveOptions o;
    c.set(&o);
    const absl::Status flag = Validate(o, FieldNaming::kFlag);
    const absl::Status field = Validate(o, FieldNaming::kField);
    if (c.flag_message.empty()) {
      EXPECT_TRUE(flag.ok()) << flag;
      continue;
    }
    EXPECT_EQ(flag.code(), absl::StatusCode::kInvalidArgument) << c.flag_message;
    EXPECT_THAT(Message(flag), HasSubstr(c.flag_message));
    EXPECT_THAT(Message(field), HasSubstr(c.field_message));
  }
}

TEST(ValidateTest, TheEstimatorsAndHierarchicalRadiosityKeepTheSameBounds) {
  // Bounds that had drifted apart: whoever checks, 4096 points pass and 4097 do not.
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w, SmallFurnace());
  const Mesh& mesh = *w->mesh;
  const Visibility& vis = *w->vis;
  for (int points : {4096, 4097}) {
    SolveOptions o;
    o.formfactor.analytic_points = points;
    const bool valid = Validate(o, FieldNaming::kFlag).ok();
    EXPECT_EQ(valid, points <= 4096);
    FormFactorOptions ff = o.formfactor;
    ff.method = "analytic";
    EXPECT_EQ(CreateFormFactorEstimator(mesh, vis, ff).ok(), valid) << points;
  }
  for (int cubes : {1'000'000, 1'000'001}) {
    FormFactorOptions ff;
    ff.method = "hemicube";
    ff.hemicube_points = cubes;
    SolveOptions o;
    o.formfactor = ff;
    EXPECT_EQ(CreateFormFactorEstimator(mesh, vis, ff).ok(), Validate(o, FieldNaming::kFlag).ok())
        << cubes;
    ViewFactorOptions vf;
    vf.method = "hemicube";
    vf.hemicube_points = cubes;
    EXPECT_EQ(Validate(vf, FieldNaming::kFlag).ok(), cubes <= 1'000'000);
  }
}

TEST(ValidateTest, JobSpecFieldsBeyondTheSolve) {
  struct Case {
    std::function<void(JobSpec*)> set;
    std::string flag_message, field_message;
  };
  const std::vector<Case> cases = {
      {[](JobSpec* s) { s->refine.max_passes = 0; }, "--refine-passes: 0 is outside [1, 64]",
       "solve.refine.max_passes: 0 is outside [1, 64]"},
      {[](JobSpec* s) { s->mesh.element_size = -1; }, "--element-size: -1 is not a positive number",
       "solve.mesh.element_size: -1 is not a positive number"},
      {[](JobSpec* s) { s->mesh.max_elements = int64_t{1} << 41; },
       "--max-elements: 2199023255552 is outside [1, 2^40]", "solve.mesh.max_elements"},
      {[](JobSpec* s) { s->camera = "fov=200"; }, "--camera: fov must be in (0, 180)",
       "solve.camera: fov must be in (0, 180)"},
      {[](JobSpec* s) { s->width = 0; }, "--width: 0 is outside [1, 16384]", "solve.width"},
      {[](JobSpec* s) {
         s->sensors = {{{0, 0, 0}, {0, 0, 0}}};
       },
       "--sensors: sensor point 0", "solve.sensors[0]: sensor point 0"},
      {[](JobSpec* s) { s->refine.direct_samples = 70000; },
       "--refine-direct-samples: 70000 is outside [1, 65536]", "solve.refine.direct_samples"},
      {[](JobSpec* s) { s->solve.tolerance = 0; }, "--tolerance: 0 is outside",
       "solve.tolerance: 0 is outside"},
  };
  EXPECT_TRUE(ValidateJobSpec(JobSpec(), FieldNaming::kFlag).ok());
  for (const Case& c : cases) {
    JobSpec spec;
    c.set(&spec);
    EXPECT_THAT(Message(ValidateJobSpec(spec, FieldNaming::kFlag)), HasSubstr(c.flag_message));
    EXPECT_THAT(Message(ValidateJobSpec(spec, FieldNaming::kField)), HasSubstr(c.field_message));
  }
}

TEST(RegistryTest, CreateSolverRefusesAnUnknownMethodListingTheKnownOnes) {
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<testing::World> w, SmallFurnace());
  SolveOptions o;
  o.method = "photon-mapping";
  absl::StatusOr<std::unique_ptr<Solver>> solver =
      CreateSolver(w->scene, *w->mesh, *w->vis, o, nullptr);
  EXPECT_EQ(solver.status().code(), absl::StatusCode::kInvalidArgument);
  for (const std::string& name : MethodNames()) {
    EXPECT_THAT(Message(solver.status()), HasSubstr(name));
  }
  for (const MethodInfo& m : Methods()) {
    o.method = m.name;
    o.formfactor.method = m.estimators[0];
    absl::StatusOr<std::unique_ptr<Solver>> made =
        CreateSolver(w->scene, *w->mesh, *w->vis, o, nullptr);
    ASSERT_TRUE(made.ok()) << m.name << ": " << made.status();
    EXPECT_EQ((*made)->Snapshot().method, m.name);
  }
}

}  // namespace
}  // namespace radiosity
