#include "proto/api/spec.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <initializer_list>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "absl/strings/str_split.h"
#include "solver/input/sensors_file.h"

// This file is the compatibility layer between the enums and the deprecated strings they replace:
// it reads and writes both.
#pragma GCC diagnostic ignored "-Wdeprecated-declarations"

namespace radiosity::service {
namespace {

absl::Status OutOfRange(const std::string& field, double value, const std::string& range) {
  return absl::InvalidArgumentError(absl::StrCat(field, ": ", value, " is outside ", range));
}

absl::Status CheckMember(const std::string& field, const std::string& value,
                         std::initializer_list<const char*> allowed) {
  for (const char* a : allowed) {
    if (value == a) return absl::OkStatus();
  }
  return absl::InvalidArgumentError(
      absl::StrCat(field, ": '", value, "' is not one of ", absl::StrJoin(allowed, ", ")));
}

bool InRange(double v, double lo, double hi) { return std::isfinite(v) && v >= lo && v <= hi; }

Vec3 FromProto(const v1::Vector3& v) { return {v.x(), v.y(), v.z()}; }

void ToProto(const Vec3& v, v1::Vector3* out) {
  out->set_x(v.x);
  out->set_y(v.y);
  out->set_z(v.z);
}

template <typename Enum>
struct Named {
  Enum value;
  const char* name;
};

constexpr Named<v1::SolveMethod> kSolveMethods[] = {
    {v1::SOLVE_METHOD_AUTO, "auto"},
    {v1::SOLVE_METHOD_PROGRESSIVE, "progressive"},
    {v1::SOLVE_METHOD_GAUSS_SEIDEL, "gauss-seidel"},
    {v1::SOLVE_METHOD_JACOBI, "jacobi"},
    {v1::SOLVE_METHOD_REFLECTION, "reflection"},
    {v1::SOLVE_METHOD_HIERARCHICAL, "hierarchical"},
};
constexpr Named<v1::Estimator> kEstimators[] = {
    {v1::ESTIMATOR_MONTECARLO, "montecarlo"},
    {v1::ESTIMATOR_ANALYTIC, "analytic"},
    {v1::ESTIMATOR_HEMICUBE, "hemicube"},
};
constexpr Named<v1::Sampling> kSamplings[] = {
    {v1::SAMPLING_SOBOL, "sobol"},
    {v1::SAMPLING_RANDOM, "random"},
    {v1::SAMPLING_STRATIFIED, "stratified"},
    {v1::SAMPLING_HALTON, "halton"},
};
constexpr Named<v1::Shooting> kShootings[] = {
    {v1::SHOOTING_WEIGHTED, "weighted"},
    {v1::SHOOTING_UNIFORM, "uniform"},
};

template <typename Enum, size_t N>
Enum ValueOf(const Named<Enum> (&table)[N], const std::string& name) {
  for (const auto& n : table) {
    if (name == n.name) return n.value;
  }
  return static_cast<Enum>(0);
}

template <typename Enum, size_t N>
std::string NameOf(const Named<Enum> (&table)[N], Enum value) {
  for (const auto& n : table) {
    if (value == n.value) return n.name;
  }
  return "";
}

// One named choice in its two forms, `text` (deprecated) and `value`: the unset one is filled
// from the other; both set must agree; both unset take `default_value`, written out in both, so
// that a request that spells the default is the same request.
template <typename Enum, size_t N>
absl::Status Reconcile(const Named<Enum> (&table)[N], const std::string& text_field,
                       std::string* text, const std::string& enum_field, int value,
                       bool (*is_valid)(int), const std::function<void(Enum)>& set_value,
                       Enum default_value) {
  if (!is_valid(value)) {
    return absl::InvalidArgumentError(
        absl::StrCat(enum_field, ": ", value, " is not a value service.proto defines"));
  }
  if (value == 0 && text->empty()) {
    value = default_value;
    set_value(default_value);
  }
  const Enum e = static_cast<Enum>(value);
  if (value == 0) {
    const Enum from_text = ValueOf(table, *text);
    if (from_text != static_cast<Enum>(0)) set_value(from_text);
    return absl::OkStatus();  // A name that is not defined is left to the validation.
  }
  const std::string name = NameOf(table, e);
  if (text->empty()) {
    *text = name;
  } else if (*text != name) {
    return absl::InvalidArgumentError(absl::StrCat(text_field, " '", *text, "' and ", enum_field,
                                                   " (", name, ") disagree; set one of them"));
  }
  return absl::OkStatus();
}

std::string Num(double v) { return absl::StrFormat("%.17g", v); }

std::string CameraText(const v1::Camera& c) {
  std::vector<std::string> parts;
  auto vec = [&](const char* key, bool has, const v1::Vector3& v) {
    if (has) parts.push_back(absl::StrCat(key, "=", Num(v.x()), ",", Num(v.y()), ",", Num(v.z())));
  };
  vec("eye", c.has_eye(), c.eye());
  vec("look", c.has_look(), c.look());
  vec("up", c.has_up(), c.up());
  if (c.has_fov_degrees()) parts.push_back(absl::StrCat("fov=", Num(c.fov_degrees())));
  return absl::StrJoin(parts, " ");
}

// The camera string's keys as a message; false when it does not parse (left to the validation,
// which names the problem).
bool ParseCameraText(const std::string& text, v1::Camera* out) {
  v1::Camera c;
  for (absl::string_view token :
       absl::StrSplit(text, absl::ByAnyChar(" \t\r\n"), absl::SkipEmpty())) {
    const size_t eq = token.find('=');
    if (eq == absl::string_view::npos) return false;
    const absl::string_view key = token.substr(0, eq), value = token.substr(eq + 1);
    if (key == "fov") {
      double fov = 0;
      if (c.has_fov_degrees() || !absl::SimpleAtod(value, &fov)) return false;
      c.set_fov_degrees(fov);
      continue;
    }
    v1::Vector3* v = key == "eye"    ? (c.has_eye() ? nullptr : c.mutable_eye())
                     : key == "look" ? (c.has_look() ? nullptr : c.mutable_look())
                     : key == "up"   ? (c.has_up() ? nullptr : c.mutable_up())
                                     : nullptr;
    std::vector<absl::string_view> xyz = absl::StrSplit(value, ',');
    double x = 0, y = 0, z = 0;
    if (v == nullptr || xyz.size() != 3 || !absl::SimpleAtod(xyz[0], &x) ||
        !absl::SimpleAtod(xyz[1], &y) || !absl::SimpleAtod(xyz[2], &z)) {
      return false;
    }
    v->set_x(x);
    v->set_y(y);
    v->set_z(z);
  }
  *out = std::move(c);
  return true;
}

}  // namespace

v1::SolveMethod SolveMethodOf(const std::string& name) { return ValueOf(kSolveMethods, name); }
std::string SolveMethodName(v1::SolveMethod method) { return NameOf(kSolveMethods, method); }

absl::Status NormalizeSpec(v1::SolveSpec* s) {
  v1::FormFactorSpec* ff = s->mutable_formfactor();
  for (absl::Status st : {
           Reconcile<v1::SolveMethod>(
               kSolveMethods, "solve.method", s->mutable_method(), "solve.solve_method",
               s->solve_method(), v1::SolveMethod_IsValid,
               [&](v1::SolveMethod v) { s->set_solve_method(v); }, v1::SOLVE_METHOD_AUTO),
           Reconcile<v1::Shooting>(
               kShootings, "solve.shooting", s->mutable_shooting(), "solve.shooting_start",
               s->shooting_start(), v1::Shooting_IsValid,
               [&](v1::Shooting v) { s->set_shooting_start(v); }, v1::SHOOTING_WEIGHTED),
           Reconcile<v1::Estimator>(
               kEstimators, "solve.formfactor.method", ff->mutable_method(),
               "solve.formfactor.estimator", ff->estimator(), v1::Estimator_IsValid,
               [&](v1::Estimator v) { ff->set_estimator(v); }, v1::ESTIMATOR_MONTECARLO),
           Reconcile<v1::Sampling>(
               kSamplings, "solve.formfactor.sampling", ff->mutable_sampling(),
               "solve.formfactor.sampling_pattern", ff->sampling_pattern(), v1::Sampling_IsValid,
               [&](v1::Sampling v) { ff->set_sampling_pattern(v); }, v1::SAMPLING_SOBOL),
       }) {
    if (!st.ok()) return st;
  }
  if (s->has_view() && s->view().ByteSizeLong() == 0) s->clear_view();  // Set but empty: unset.
  // The camera: compared and stored in one spelling (CameraText), so that the same camera
  // written otherwise is the same request.
  v1::Camera parsed;
  const bool parses = !s->camera().empty() && ParseCameraText(s->camera(), &parsed);
  if (s->has_view()) {
    if (!s->camera().empty() && (!parses || CameraText(parsed) != CameraText(s->view()))) {
      return absl::InvalidArgumentError(
          absl::StrCat("solve.camera '", s->camera(), "' and solve.view (", CameraText(s->view()),
                       ") are not the same camera (each key given in one must be given, with "
                       "the same value, in the other); set one of them"));
    }
    s->set_camera(CameraText(s->view()));
  } else if (parses) {
    *s->mutable_view() = parsed;
    s->set_camera(CameraText(parsed));
  }
  return absl::OkStatus();
}

std::string CameraOf(const v1::SolveSpec& spec) {
  return spec.has_view() ? CameraText(spec.view()) : spec.camera();
}

absl::Status NormalizeSpec(v1::ViewFactorSpec* s) {
  for (absl::Status st : {
           Reconcile<v1::Estimator>(
               kEstimators, "view_factor.method", s->mutable_method(), "view_factor.estimator",
               s->estimator(), v1::Estimator_IsValid, [&](v1::Estimator v) { s->set_estimator(v); },
               v1::ESTIMATOR_ANALYTIC),
           Reconcile<v1::Sampling>(
               kSamplings, "view_factor.sampling", s->mutable_sampling(),
               "view_factor.sampling_pattern", s->sampling_pattern(), v1::Sampling_IsValid,
               [&](v1::Sampling v) { s->set_sampling_pattern(v); }, v1::SAMPLING_STRATIFIED),
       }) {
    if (!st.ok()) return st;
  }
  return absl::OkStatus();
}

absl::StatusOr<JobSpec> ToJobSpec(const v1::SolveSpec& wire) {
  v1::SolveSpec s = wire;
  if (absl::Status st = NormalizeSpec(&s); !st.ok()) return st;
  // Unset fields (0 or empty) keep the solver's defaults; everything is then checked by the
  // solver's own validation, which names the wire's fields.
  JobSpec spec;
  const v1::MeshSpec& mesh = s.mesh();
  if (mesh.element_size() != 0) spec.mesh.element_size = mesh.element_size();
  if (mesh.max_elements() != 0) spec.mesh.max_elements = mesh.max_elements();
  if (mesh.has_patch_depth()) spec.mesh.patch_depth = mesh.patch_depth();
  if (mesh.has_agglomerate_degrees()) spec.mesh.agglomerate_degrees = mesh.agglomerate_degrees();
  SolveOptions& o = spec.solve;
  if (!s.method().empty()) o.method = s.method();
  const v1::FormFactorSpec& ff = s.formfactor();
  if (!ff.method().empty()) o.formfactor.method = ff.method();
  if (!ff.sampling().empty()) o.formfactor.sampling = ff.sampling();
  if (ff.hemicube_resolution() != 0) o.formfactor.hemicube_resolution = ff.hemicube_resolution();
  if (ff.shadow_rays() != 0) o.formfactor.shadow_rays = ff.shadow_rays();
  if (s.overshoot() != 0) o.overshoot = s.overshoot();
  if (s.max_matrix_mb() != 0) o.max_matrix_mb = s.max_matrix_mb();
  if (s.tolerance() != 0) o.tolerance = s.tolerance();
  o.max_rays = s.max_rays();
  o.max_seconds = s.max_seconds();
  if (s.has_seed()) o.seed = s.seed();
  o.threads = s.threads();
  if (s.rays_per_element() != 0) o.rays_per_element = s.rays_per_element();
  if (!s.direct().empty()) o.direct = s.direct();
  if (s.direct_shadow_rays() != 0) o.direct_shadow_rays = s.direct_shadow_rays();
  if (!s.indirect().empty()) o.indirect = s.indirect();
  if (s.sensor_samples() != 0) spec.sensor_samples = s.sensor_samples();
  for (const v1::EmitOverride& e : s.emit()) {
    spec.emit.push_back({e.name(), Rgb(e.r(), e.g(), e.b())});
  }
  if (s.has_sky()) {
    const v1::SkySpec& k = s.sky();
    if (!k.model().empty()) o.sky.model = k.model();
    o.sky.irradiance = Rgb(k.r(), k.g(), k.b());
    if (k.has_up()) o.sky.up = FromProto(k.up());
    if (k.samples() != 0) o.sky.samples = k.samples();
  }
  if (s.luminaires_size() > static_cast<int>(kMaxLuminaires)) {
    return absl::InvalidArgumentError(absl::StrCat("solve.luminaires: ", s.luminaires_size(),
                                                   " luminaires, more than ", kMaxLuminaires));
  }
  for (const v1::LuminaireSpec& l : s.luminaires()) {
    Luminaire lum;
    lum.file = l.file();
    lum.position = FromProto(l.position());
    if (l.has_aim()) lum.aim = FromProto(l.aim());
    if (l.has_c0()) lum.c0 = FromProto(l.c0());
    if (l.multiplier() != 0) lum.multiplier = l.multiplier();
    if (l.r() != 0 || l.g() != 0 || l.b() != 0) lum.color = Rgb(l.r(), l.g(), l.b());
    o.luminaires.push_back(std::move(lum));
  }
  if (s.luminaire_samples() != 0) o.luminaire_samples = s.luminaire_samples();
  if (!s.shooting().empty()) {
    if (auto st = CheckMember("solve.shooting", s.shooting(), {"weighted", "uniform"}); !st.ok()) {
      return st;
    }
    o.weighted_shooting = s.shooting() == "weighted";
  }
  spec.camera = s.camera();
  if (s.width() != 0) spec.width = s.width();
  if (s.height() != 0) spec.height = s.height();
  for (int i = 0; i < s.sensors_size(); ++i) {
    SensorPoint point{FromProto(s.sensors(i).position()), FromProto(s.sensors(i).normal()),
                      s.sensors(i).grid()};
    if (absl::Status st = point.grid.empty() ? absl::OkStatus() : CheckSensorGridName(point.grid);
        !st.ok()) {
      return absl::InvalidArgumentError(
          absl::StrCat("solve.sensors[", i, "].grid: ", st.message()));
    }
    // ParseSensors already normalised the CLI's points; leave unit normals bit for bit.
    const double length = Length(point.n);
    if (length > 0 && std::isfinite(length) && std::abs(length - 1) > 1e-12) {
      point.n = Normalize(point.n);
    }
    spec.sensors.push_back(point);
  }
  if (s.snapshot_interval() != 0 && !InRange(s.snapshot_interval(), 0.01, 3600)) {
    return OutOfRange("solve.snapshot_interval", s.snapshot_interval(), "[0.01, 3600]");
  }
  spec.write_ply = !s.skip_mesh_ply();
  spec.write_image = !s.skip_image();
  const v1::RefineSpec& r = s.refine();
  spec.refine.tolerance = r.tolerance();
  spec.refine.min_element_size = r.min_element_size();
  if (r.light_samples() != 0) spec.refine.light_samples = r.light_samples();
  if (r.max_passes() != 0) spec.refine.max_passes = r.max_passes();
  spec.refine.resolve = r.resolve();
  if (r.direct_samples() != 0) spec.refine.direct_samples = r.direct_samples();
  if (absl::Status st = ValidateJobSpec(spec, FieldNaming::kField); !st.ok()) {
    // A camera the client gave as `view` is named as such (its string form is derived).
    if (wire.has_view() && wire.camera().empty() &&
        absl::StrContains(st.message(), "solve.camera")) {
      return absl::Status(st.code(),
                          absl::StrReplaceAll(st.message(), {{"solve.camera", "solve.view"}}));
    }
    return st;
  }
  return spec;
}

double SnapshotInterval(const v1::SolveSpec& spec) {
  return spec.snapshot_interval() > 0 ? spec.snapshot_interval() : kDefaultSnapshotInterval;
}

v1::SolveSpec ToSolveSpec(const JobSpec& spec, double snapshot_interval) {
  v1::SolveSpec s;
  s.mutable_mesh()->set_element_size(spec.mesh.element_size);
  s.mutable_mesh()->set_max_elements(spec.mesh.max_elements);
  s.mutable_mesh()->set_patch_depth(spec.mesh.patch_depth);
  s.mutable_mesh()->set_agglomerate_degrees(spec.mesh.agglomerate_degrees);
  const SolveOptions& o = spec.solve;
  s.set_method(o.method);
  s.mutable_formfactor()->set_method(o.formfactor.method);
  s.mutable_formfactor()->set_sampling(o.formfactor.sampling);
  s.mutable_formfactor()->set_hemicube_resolution(o.formfactor.hemicube_resolution);
  s.mutable_formfactor()->set_shadow_rays(o.formfactor.shadow_rays);
  s.set_overshoot(o.overshoot);
  s.set_max_matrix_mb(o.max_matrix_mb);
  s.set_tolerance(o.tolerance);
  s.set_max_rays(o.max_rays);
  s.set_max_seconds(o.max_seconds);
  s.set_seed(o.seed);
  s.set_threads(o.threads);
  s.set_rays_per_element(o.rays_per_element);
  s.set_direct(o.direct);
  s.set_direct_shadow_rays(o.direct_shadow_rays);
  s.set_indirect(o.indirect);
  s.set_sensor_samples(spec.sensor_samples);
  if (o.sky.enabled()) {
    v1::SkySpec* k = s.mutable_sky();
    k->set_model(o.sky.model);
    k->set_r(o.sky.irradiance.r);
    k->set_g(o.sky.irradiance.g);
    k->set_b(o.sky.irradiance.b);
    ToProto(o.sky.up, k->mutable_up());
    k->set_samples(o.sky.samples);
  }
  for (const Luminaire& l : o.luminaires) {
    v1::LuminaireSpec* out = s.add_luminaires();
    out->set_file(l.file);
    ToProto(l.position, out->mutable_position());
    ToProto(l.aim, out->mutable_aim());
    ToProto(l.c0, out->mutable_c0());
    out->set_multiplier(l.multiplier);
    out->set_r(l.color.r);
    out->set_g(l.color.g);
    out->set_b(l.color.b);
  }
  s.set_luminaire_samples(o.luminaire_samples);
  for (const EmitOverride& e : spec.emit) {
    v1::EmitOverride* out = s.add_emit();
    out->set_name(e.name);
    out->set_r(e.exitance.r);
    out->set_g(e.exitance.g);
    out->set_b(e.exitance.b);
  }
  s.set_shooting(o.weighted_shooting ? "weighted" : "uniform");
  s.set_camera(spec.camera);
  s.set_width(spec.width);
  s.set_height(spec.height);
  for (const SensorPoint& p : spec.sensors) {
    v1::SensorPoint* out = s.add_sensors();
    ToProto(p.p, out->mutable_position());
    ToProto(p.n, out->mutable_normal());
    out->set_grid(p.grid);
  }
  s.set_snapshot_interval(snapshot_interval);
  s.set_skip_mesh_ply(!spec.write_ply);
  s.set_skip_image(!spec.write_image);
  s.mutable_refine()->set_tolerance(spec.refine.tolerance);
  s.mutable_refine()->set_min_element_size(spec.refine.min_element_size);
  s.mutable_refine()->set_light_samples(spec.refine.light_samples);
  s.mutable_refine()->set_max_passes(spec.refine.max_passes);
  s.mutable_refine()->set_resolve(spec.refine.resolve);
  s.mutable_refine()->set_direct_samples(spec.refine.direct_samples);
  // Both forms of each choice (servers before the enums read the strings).
  (void)NormalizeSpec(&s);
  return s;
}

absl::StatusOr<ViewFactorOptions> ToViewFactorOptions(const v1::ViewFactorSpec& wire) {
  v1::ViewFactorSpec s = wire;
  if (absl::Status st = NormalizeSpec(&s); !st.ok()) return st;
  ViewFactorOptions o;
  if (!s.method().empty()) o.method = s.method();
  if (s.tolerance() != 0) o.tolerance = s.tolerance();
  if (s.shadow_rays() != 0) o.shadow_rays = s.shadow_rays();
  if (!s.occlusion().empty()) o.occlusion = s.occlusion();
  if (!s.enforce().empty()) o.enforce = s.enforce();
  if (s.rays_per_surface() != 0) o.rays_per_surface = s.rays_per_surface();
  if (!s.sampling().empty()) o.sampling = s.sampling();
  if (s.hemicube_resolution() != 0) o.hemicube_resolution = s.hemicube_resolution();
  if (s.hemicube_points() != 0) o.hemicube_points = s.hemicube_points();
  if (s.has_seed()) o.seed = s.seed();
  o.threads = s.threads();
  for (int k = 0; k < s.thermal_size(); ++k) {
    const v1::SurfaceThermal& t = s.thermal(k);
    if (!t.has_emissivity()) {
      return absl::InvalidArgumentError(absl::StrCat("view_factor.thermal[", k, "] (surface '",
                                                     t.surface(), "'): emissivity is required"));
    }
    o.thermal.surfaces.push_back({t.surface(), t.emissivity(), t.temperature()});
  }
  o.thermal.ambient_temperature = s.ambient_temperature();
  if (s.near() != 0) o.near = s.near();
  o.from.assign(s.from_surfaces().begin(), s.from_surfaces().end());
  if (absl::Status st = Validate(o, FieldNaming::kField); !st.ok()) return st;
  return o;
}

v1::ViewFactorSpec ToViewFactorSpec(const ViewFactorOptions& o) {
  v1::ViewFactorSpec s;
  s.set_method(o.method);
  s.set_tolerance(o.tolerance);
  s.set_shadow_rays(o.shadow_rays);
  s.set_occlusion(o.occlusion);
  s.set_enforce(o.enforce);
  s.set_rays_per_surface(o.rays_per_surface);
  s.set_sampling(o.sampling);
  s.set_hemicube_resolution(o.hemicube_resolution);
  s.set_hemicube_points(o.hemicube_points);
  s.set_seed(o.seed);
  s.set_threads(o.threads);
  for (const SurfaceThermal& t : o.thermal.surfaces) {
    v1::SurfaceThermal* w = s.add_thermal();
    w->set_surface(t.surface);
    w->set_emissivity(t.emissivity);
    w->set_temperature(t.temperature);
  }
  s.set_ambient_temperature(o.thermal.ambient_temperature);
  s.set_near(o.near);
  for (const std::string& name : o.from) s.add_from_surfaces(name);
  (void)NormalizeSpec(&s);
  return s;
}

std::string StateName(v1::JobState state) {
  std::string name = v1::JobState_Name(state);
  constexpr std::string_view kPrefix = "JOB_STATE_";
  if (name.rfind(kPrefix, 0) == 0) name = name.substr(kPrefix.size());
  return name;
}

const char* PhaseName(v1::JobPhase phase) {
  switch (phase) {
    case v1::JOB_PHASE_MESHING:
      return "meshing";
    case v1::JOB_PHASE_SOLVING:
      return "solving";
    case v1::JOB_PHASE_WRITING:
      return "writing";
    default:
      return "";
  }
}

bool ParseStateName(const std::string& name, v1::JobState* state) {
  std::string upper = absl::AsciiStrToUpper(name);
  if (upper.rfind("JOB_STATE_", 0) != 0) upper = "JOB_STATE_" + upper;
  return v1::JobState_Parse(upper, state) && *state != v1::JOB_STATE_UNSPECIFIED;
}

}  // namespace radiosity::service
