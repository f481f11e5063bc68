#include "proto/api/spec.h"

#include <algorithm>
#include <cmath>
#include <initializer_list>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "solver/results/camera.h"

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
  JobSpec spec;
  // Meshing.
  const v1::MeshSpec& mesh = s.mesh();
  if (mesh.element_size() != 0) {
    if (!(mesh.element_size() > 0) || !std::isfinite(mesh.element_size())) {
      return absl::InvalidArgumentError(absl::StrCat(
          "solve.mesh.element_size: ", mesh.element_size(), " is not a positive number"));
    }
    spec.mesh.element_size = mesh.element_size();
  }
  if (mesh.max_elements() != 0) {
    if (mesh.max_elements() < 1 || mesh.max_elements() > (int64_t{1} << 40)) {
      return OutOfRange("solve.mesh.max_elements", static_cast<double>(mesh.max_elements()),
                        "[1, 2^40]");
    }
    spec.mesh.max_elements = mesh.max_elements();
  }
  if (mesh.has_patch_depth()) {
    if (mesh.patch_depth() < 0 || mesh.patch_depth() > 8) {
      return OutOfRange("solve.mesh.patch_depth", mesh.patch_depth(), "[0, 8]");
    }
    spec.mesh.patch_depth = mesh.patch_depth();
  }
  // Method and form factors.
  SolveOptions& o = spec.solve;
  if (!s.method().empty()) {
    const std::vector<std::string>& methods = SolveMethods();
    if (std::find(methods.begin(), methods.end(), s.method()) == methods.end()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "solve.method: '", s.method(), "' is not one of ", absl::StrJoin(methods, ", ")));
    }
    o.method = s.method();
  }
  const v1::FormFactorSpec& ff = s.formfactor();
  if (!ff.method().empty()) {
    if (auto st = CheckMember("solve.formfactor.method", ff.method(),
                              {"montecarlo", "analytic", "hemicube"});
        !st.ok()) {
      return st;
    }
    o.formfactor.method = ff.method();
  }
  if (!ff.sampling().empty()) {
    if (auto st = CheckMember("solve.formfactor.sampling", ff.sampling(),
                              {"random", "stratified", "halton"});
        !st.ok()) {
      return st;
    }
    o.formfactor.sampling = ff.sampling();
  }
  if (ff.hemicube_resolution() != 0) {
    if (ff.hemicube_resolution() < 4 || ff.hemicube_resolution() > 4096) {
      return OutOfRange("solve.formfactor.hemicube_resolution", ff.hemicube_resolution(),
                        "[4, 4096]");
    }
    o.formfactor.hemicube_resolution = ff.hemicube_resolution();
  }
  if (ff.shadow_rays() != 0) {
    if (ff.shadow_rays() < 1 || ff.shadow_rays() > 4096) {
      return OutOfRange("solve.formfactor.shadow_rays", ff.shadow_rays(), "[1, 4096]");
    }
    o.formfactor.shadow_rays = ff.shadow_rays();
  }
  o.ambient = s.ambient();
  if (s.overshoot() != 0) {
    if (!InRange(s.overshoot(), 1, 2))
      return OutOfRange("solve.overshoot", s.overshoot(), "[1, 2]");
    o.overshoot = s.overshoot();
  }
  if (s.max_matrix_mb() != 0) {
    if (!(s.max_matrix_mb() > 0) || !std::isfinite(s.max_matrix_mb())) {
      return absl::InvalidArgumentError(
          absl::StrCat("solve.max_matrix_mb: ", s.max_matrix_mb(), " is not a positive number"));
    }
    o.max_matrix_mb = s.max_matrix_mb();
  }
  // Budgets.
  if (s.tolerance() != 0) {
    if (!InRange(s.tolerance(), 1e-15, 0.999999)) {
      return OutOfRange("solve.tolerance", s.tolerance(), "[1e-15, 0.999999]");
    }
    o.tolerance = s.tolerance();
  }
  if (s.max_rays() < 0) return OutOfRange("solve.max_rays", s.max_rays(), "[0, 2^63)");
  o.max_rays = s.max_rays();
  if (!InRange(s.max_seconds(), 0, 1e9)) {
    return OutOfRange("solve.max_seconds", s.max_seconds(), "[0, 1e9]");
  }
  o.max_seconds = s.max_seconds();
  if (s.has_seed()) o.seed = s.seed();
  if (s.threads() < 0 || s.threads() > 1024) {
    return OutOfRange("solve.threads", s.threads(), "[0, 1024]");
  }
  o.threads = s.threads();
  if (s.rays_per_element() != 0) {
    if (!(s.rays_per_element() > 0) || !std::isfinite(s.rays_per_element())) {
      return absl::InvalidArgumentError(absl::StrCat(
          "solve.rays_per_element: ", s.rays_per_element(), " is not a positive number"));
    }
    o.rays_per_element = s.rays_per_element();
  }
  if (!s.shooting().empty()) {
    if (auto st = CheckMember("solve.shooting", s.shooting(), {"weighted", "uniform"}); !st.ok()) {
      return st;
    }
    o.weighted_shooting = s.shooting() == "weighted";
  }
  // Outputs.
  if (!s.camera().empty()) {
    absl::StatusOr<Camera> camera = ParseCamera(s.camera(), Camera());
    if (!camera.ok()) return absl::InvalidArgumentError(camera.status().message());
    spec.camera = s.camera();
  }
  if (s.width() != 0) {
    if (s.width() < 1 || s.width() > 16384)
      return OutOfRange("solve.width", s.width(), "[1, 16384]");
    spec.width = s.width();
  }
  if (s.height() != 0) {
    if (s.height() < 1 || s.height() > 16384) {
      return OutOfRange("solve.height", s.height(), "[1, 16384]");
    }
    spec.height = s.height();
  }
  for (int i = 0; i < s.sensors_size(); ++i) {
    SensorPoint point{FromProto(s.sensors(i).position()), FromProto(s.sensors(i).normal())};
    double length = Length(point.n);
    if (!IsFinite(point.p) || !IsFinite(point.n) || !(length > 0) || !std::isfinite(length)) {
      return absl::InvalidArgumentError(
          absl::StrCat("solve.sensors[", i,
                       "]: the position must be finite and the normal finite and not zero"));
    }
    // ParseSensors already normalised the CLI's points; leave unit normals bit for bit.
    if (std::abs(length - 1) > 1e-12) point.n = Normalize(point.n);
    spec.sensors.push_back(point);
  }
  if (s.snapshot_interval() != 0 && !InRange(s.snapshot_interval(), 0.01, 3600)) {
    return OutOfRange("solve.snapshot_interval", s.snapshot_interval(), "[0.01, 3600]");
  }
  spec.write_ply = !s.skip_mesh_ply();
  spec.write_image = !s.skip_image();
  // Adaptive refinement.
  const v1::RefineSpec& r = s.refine();
  if (!InRange(r.tolerance(), 0, 0.999999)) {
    return OutOfRange("solve.refine.tolerance", r.tolerance(), "[0, 1)");
  }
  spec.refine.tolerance = r.tolerance();
  if (!InRange(r.min_element_size(), 0, 1e300)) {
    return OutOfRange("solve.refine.min_element_size", r.min_element_size(), "[0, inf)");
  }
  spec.refine.min_element_size = r.min_element_size();
  if (r.light_samples() != 0) {
    if (r.light_samples() < 1 || r.light_samples() > 4096) {
      return OutOfRange("solve.refine.light_samples", r.light_samples(), "[1, 4096]");
    }
    spec.refine.light_samples = r.light_samples();
  }
  if (r.max_passes() != 0) {
    if (r.max_passes() < 1 || r.max_passes() > 64) {
      return OutOfRange("solve.refine.max_passes", r.max_passes(), "[1, 64]");
    }
    spec.refine.max_passes = r.max_passes();
  }
  spec.refine.resolve = r.resolve();
  if (r.direct_samples() != 0) {
    if (r.direct_samples() < 1 || r.direct_samples() > 65536) {
      return OutOfRange("solve.refine.direct_samples", r.direct_samples(), "[1, 65536]");
    }
    spec.refine.direct_samples = r.direct_samples();
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
  if (!s.method().empty()) {
    if (auto st =
            CheckMember("view_factor.method", s.method(), {"analytic", "montecarlo", "hemicube"});
        !st.ok()) {
      return st;
    }
    o.method = s.method();
  }
  if (s.tolerance() != 0) {
    if (!InRange(s.tolerance(), 1e-12, 0.5)) {
      return OutOfRange("view_factor.tolerance", s.tolerance(), "[1e-12, 0.5]");
    }
    o.tolerance = s.tolerance();
  }
  if (s.shadow_rays() != 0) {
    if (s.shadow_rays() < 1 || s.shadow_rays() > 4096) {
      return OutOfRange("view_factor.shadow_rays", s.shadow_rays(), "[1, 4096]");
    }
    o.shadow_rays = s.shadow_rays();
  }
  if (s.rays_per_surface() != 0) {
    if (s.rays_per_surface() < 1 || s.rays_per_surface() > (int64_t{1} << 40)) {
      return OutOfRange("view_factor.rays_per_surface", static_cast<double>(s.rays_per_surface()),
                        "[1, 2^40]");
    }
    o.rays_per_surface = s.rays_per_surface();
  }
  if (!s.sampling().empty()) {
    if (auto st =
            CheckMember("view_factor.sampling", s.sampling(), {"random", "stratified", "halton"});
        !st.ok()) {
      return st;
    }
    o.sampling = s.sampling();
  }
  if (s.hemicube_resolution() != 0) {
    if (s.hemicube_resolution() < 4 || s.hemicube_resolution() > 4096) {
      return OutOfRange("view_factor.hemicube_resolution", s.hemicube_resolution(), "[4, 4096]");
    }
    o.hemicube_resolution = s.hemicube_resolution();
  }
  if (s.hemicube_points() != 0) {
    if (s.hemicube_points() < 1 || s.hemicube_points() > 1'000'000) {
      return OutOfRange("view_factor.hemicube_points", s.hemicube_points(), "[1, 1000000]");
    }
    o.hemicube_points = s.hemicube_points();
  }
  if (s.has_seed()) o.seed = s.seed();
  if (s.threads() < 0 || s.threads() > 1024) {
    return OutOfRange("view_factor.threads", s.threads(), "[0, 1024]");
  }
  o.threads = s.threads();
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
