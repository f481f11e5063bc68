#include "proto/api/spec.h"

#include <algorithm>
#include <cmath>
#include <initializer_list>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"

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

}  // namespace

absl::StatusOr<JobSpec> ToJobSpec(const v1::SolveSpec& s) {
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
  o.ambient = s.ambient();
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
    SensorPoint point{FromProto(s.sensors(i).position()), FromProto(s.sensors(i).normal())};
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
  if (absl::Status st = ValidateJobSpec(spec, FieldNaming::kField); !st.ok()) return st;
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
  s.set_ambient(o.ambient);
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
  return s;
}

absl::StatusOr<ViewFactorOptions> ToViewFactorOptions(const v1::ViewFactorSpec& s) {
  ViewFactorOptions o;
  if (!s.method().empty()) o.method = s.method();
  if (s.tolerance() != 0) o.tolerance = s.tolerance();
  if (s.shadow_rays() != 0) o.shadow_rays = s.shadow_rays();
  if (s.rays_per_surface() != 0) o.rays_per_surface = s.rays_per_surface();
  if (!s.sampling().empty()) o.sampling = s.sampling();
  if (s.hemicube_resolution() != 0) o.hemicube_resolution = s.hemicube_resolution();
  if (s.hemicube_points() != 0) o.hemicube_points = s.hemicube_points();
  if (s.has_seed()) o.seed = s.seed();
  o.threads = s.threads();
  if (absl::Status st = Validate(o, FieldNaming::kField); !st.ok()) return st;
  return o;
}

v1::ViewFactorSpec ToViewFactorSpec(const ViewFactorOptions& o) {
  v1::ViewFactorSpec s;
  s.set_method(o.method);
  s.set_tolerance(o.tolerance);
  s.set_shadow_rays(o.shadow_rays);
  s.set_rays_per_surface(o.rays_per_surface);
  s.set_sampling(o.sampling);
  s.set_hemicube_resolution(o.hemicube_resolution);
  s.set_hemicube_points(o.hemicube_points);
  s.set_seed(o.seed);
  s.set_threads(o.threads);
  return s;
}

std::string StateName(v1::JobState state) {
  std::string name = v1::JobState_Name(state);
  constexpr std::string_view kPrefix = "JOB_STATE_";
  if (name.rfind(kPrefix, 0) == 0) name = name.substr(kPrefix.size());
  return name;
}

bool ParseStateName(const std::string& name, v1::JobState* state) {
  std::string upper = absl::AsciiStrToUpper(name);
  if (upper.rfind("JOB_STATE_", 0) != 0) upper = "JOB_STATE_" + upper;
  return v1::JobState_Parse(upper, state) && *state != v1::JOB_STATE_UNSPECIFIED;
}

}  // namespace radiosity::service
