// Sensor points against a deterministic reference (bench/REPORT.md): the cube room
// of issue 13, irradiance at a grid of floor points.
//
// The reference needs no random number: in an empty convex enclosure nothing blocks anything, so
// every element-to-element form factor is the unoccluded one, integrated to 1e-9 by adaptive
// quadrature of Lambert's formula (area_to_polygon.h); Gauss-Seidel solves B = E + R F B to a
// residual of 1e-14; a sensor's irradiance is sum_j B_j F(x -> element j), exact for the
// piecewise-constant B. What remains is the discretisation of B, measured by solving at two
// resolutions (the second with 4x the elements) and extrapolated (Richardson, error ~ h^2 for the
// gathered irradiance); the reference file records both and their difference.
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "bench/bench_util.h"
#include "solver/input/scene_files.h"
#include "solver/input/sensors_file.h"
#include "solver/methods/solver.h"
#include "solver/transport/area_to_polygon.h"
#include "solver/transport/formfactor.h"
#include "solver/transport/gather.h"
#include "solver/transport/visibility.h"
#include "tbb/global_control.h"
#include "tbb/parallel_for.h"

namespace radiosity::bench {

namespace {

using Clock = std::chrono::steady_clock;

double LoadAverage() {
  std::ifstream in("/proc/loadavg");
  double load = -1;
  in >> load;
  return load;
}

double Seconds(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// Irradiance at every sensor from the deterministic solution on a mesh of about `elements`.
absl::StatusOr<std::vector<Rgb>> ConvexRoomIrradiance(const Scene& scene, int64_t elements,
                                                      const std::vector<SensorPoint>& sensors) {
  MeshOptions mo;
  mo.max_elements = elements;
  absl::StatusOr<Mesh> built = Mesh::Build(scene, mo);
  if (!built.ok()) return built.status();
  const Mesh& mesh = *built;
  const auto& els = mesh.elements();
  const size_t n = els.size();
  std::vector<std::vector<SpacePolygon>> polys(n);
  for (size_t e = 0; e < n; ++e) ElementPolygons(mesh, static_cast<int>(e), kFront, &polys[e]);
  QuadratureOptions q;
  q.relative = 1e-9;
  q.absolute = 1e-12;
  // F[i][j]: from element i's front to element j's front (j's polygons send from their front).
  std::vector<float> f(n * n, 0.0f);
  std::cerr << absl::StrFormat("room reference: %d elements, %d form factors\n", n, n * n);
  tbb::parallel_for(size_t{0}, n, [&](size_t i) {
    for (size_t j = 0; j < n; ++j) {
      if (i == j || els[i].face == els[j].face) continue;
      double sum = 0;
      for (const SpacePolygon& p : polys[j]) {
        sum += AreaToPolygon(polys[i], els[i].area, p, q).front;
      }
      f[i * n + j] = static_cast<float>(sum);
    }
  });
  std::vector<Rgb> b(n), e(n), rho(n);
  for (size_t i = 0; i < n; ++i) {
    const SideRule& rule = mesh.sides().at(static_cast<int>(i), kFront);
    e[i] = rule.exitance;
    rho[i] = rule.reflectance;
    b[i] = e[i];
  }
  for (int sweep = 0; sweep < 10000; ++sweep) {
    double change = 0, total = 0;
    for (size_t i = 0; i < n; ++i) {
      Rgb h;
      const float* row = &f[i * n];
      for (size_t j = 0; j < n; ++j) h += b[j] * static_cast<double>(row[j]);
      const Rgb next = e[i] + rho[i] * h;
      change += std::fabs((next - b[i]).Sum()) * els[i].area;
      total += next.Sum() * els[i].area;
      b[i] = next;
    }
    if (change <= 1e-14 * total) break;
  }
  std::vector<Rgb> out(sensors.size());
  tbb::parallel_for(size_t{0}, sensors.size(), [&](size_t k) {
    const Vec3 x = sensors[k].p - mesh.origin();
    Rgb h;
    for (size_t j = 0; j < n; ++j) {
      for (const SpacePolygon& p : polys[j]) {
        if (Dot(x - p.v[0], p.normal) <= 0) continue;
        h += b[j] * PointToPolygonFormFactorClipped(x, sensors[k].n, p.v.data(), p.n);
      }
    }
    out[k] = h;
  });
  return out;
}

absl::Status WriteSensorValues(const std::string& path, const std::vector<SensorPoint>& sensors,
                               const std::vector<Rgb>& values, const std::string& comment) {
  std::ofstream out(path);
  if (!out) return absl::InternalError(absl::StrCat(path, ": cannot write"));
  out << "# " << comment << "\n";
  out << "x,y,z,nx,ny,nz,r,g,b\n";
  for (size_t i = 0; i < sensors.size(); ++i) {
    const SensorPoint& s = sensors[i];
    out << absl::StrFormat("%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.12g,%.12g,%.12g\n", s.p.x, s.p.y, s.p.z,
                           s.n.x, s.n.y, s.n.z, values[i].r, values[i].g, values[i].b);
  }
  return out ? absl::OkStatus() : absl::InternalError(absl::StrCat(path, ": cannot write"));
}

absl::StatusOr<std::vector<Rgb>> ReadSensorValues(const std::string& path, size_t count) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot read"));
  std::vector<Rgb> out;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#' || line[0] == 'x') continue;
    std::vector<std::string> cells = absl::StrSplit(line, ',');
    if (cells.size() < 9) return absl::InvalidArgumentError(absl::StrCat(path, ": short line"));
    out.push_back(Rgb(std::stod(cells[6]), std::stod(cells[7]), std::stod(cells[8])));
  }
  if (out.size() != count) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": ", out.size(), " values for ", count, " sensors"));
  }
  return out;
}

}  // namespace

int RoomReferenceCommand(const std::string& scene_path, const std::string& sensors_path,
                         int64_t elements, const std::string& out_path) {
  absl::StatusOr<Scene> scene = LoadSceneFile(scene_path, nullptr);
  absl::StatusOr<std::vector<SensorPoint>> sensors = LoadSensors(sensors_path);
  if (!scene.ok() || !sensors.ok()) {
    std::cerr << "radiosity_bench: " << (scene.ok() ? sensors.status() : scene.status()) << "\n";
    return 1;
  }
  const auto start = Clock::now();
  absl::StatusOr<std::vector<Rgb>> coarse = ConvexRoomIrradiance(*scene, elements, *sensors);
  absl::StatusOr<std::vector<Rgb>> fine = ConvexRoomIrradiance(*scene, 4 * elements, *sensors);
  if (!coarse.ok() || !fine.ok()) {
    std::cerr << "radiosity_bench: " << (coarse.ok() ? fine.status() : coarse.status()) << "\n";
    return 1;
  }
  // Richardson: halving h divides an h^2 error by 4, so I = I_fine + (I_fine - I_coarse) / 3.
  std::vector<Rgb> extrapolated(sensors->size());
  double rms_step = 0, mean = 0;
  for (size_t k = 0; k < sensors->size(); ++k) {
    extrapolated[k] = (*fine)[k] + ((*fine)[k] - (*coarse)[k]) * (1.0 / 3);
    const double d = ((*fine)[k].g - (*coarse)[k].g) / (*fine)[k].g;
    rms_step += d * d / sensors->size();
    mean += (*fine)[k].g / sensors->size();
  }
  const std::string comment = absl::StrFormat(
      "deterministic convex-room reference of %s at %s: exact form factors, Gauss-Seidel, "
      "Richardson from %d and %d elements (their RMS relative difference %.3g%%; the "
      "extrapolation's error is well below it); %.0f s",
      scene_path, sensors_path, elements, 4 * elements, 100 * std::sqrt(rms_step), Seconds(start));
  std::cerr << comment << "\n";
  if (absl::Status s = WriteSensorValues(out_path, *sensors, extrapolated, comment); !s.ok()) {
    std::cerr << "radiosity_bench: " << s << "\n";
    return 1;
  }
  return 0;
}

int SensorsCommand(const std::string& scene_path, const std::string& sensors_path,
                   const std::string& reference_path, const SolveOptions& options, int64_t elements,
                   int samples, const std::string& csv_path, const std::string& label) {
  absl::StatusOr<Scene> scene = LoadSceneFile(scene_path, nullptr);
  absl::StatusOr<std::vector<SensorPoint>> sensors = LoadSensors(sensors_path);
  if (!scene.ok() || !sensors.ok()) {
    std::cerr << "radiosity_bench: " << (scene.ok() ? sensors.status() : scene.status()) << "\n";
    return 1;
  }
  absl::StatusOr<std::vector<Rgb>> reference = ReadSensorValues(reference_path, sensors->size());
  if (!reference.ok()) {
    std::cerr << "radiosity_bench: " << reference.status() << "\n";
    return 1;
  }
  // The whole job but the files: meshing, solving and gathering, timed together.
  const int threads = options.threads > 0 ? options.threads : 0;
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0) {
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  threads);
  }
  const auto start = Clock::now();
  MeshOptions mo;
  mo.max_elements = elements;
  absl::StatusOr<Mesh> mesh = Mesh::Build(*scene, mo);
  if (!mesh.ok()) {
    std::cerr << "radiosity_bench: " << mesh.status() << "\n";
    return 1;
  }
  absl::StatusOr<std::unique_ptr<Visibility>> vis = Visibility::Build(*mesh);
  if (!vis.ok()) {
    std::cerr << "radiosity_bench: " << vis.status() << "\n";
    return 1;
  }
  absl::StatusOr<std::unique_ptr<Solver>> solver =
      CreateSolver(*scene, *mesh, **vis, options, nullptr);
  if (!solver.ok()) {
    std::cerr << "radiosity_bench: " << solver.status() << "\n";
    return 1;
  }
  absl::StatusOr<StopReason> reason = RunSolver(**solver, options, nullptr, nullptr);
  if (!reason.ok()) {
    std::cerr << "radiosity_bench: " << reason.status() << "\n";
    return 1;
  }
  const Solution solution = (*solver)->Final();
  GatherOptions go;
  go.samples = samples;
  go.seed = options.seed;
  const SensorIrradiance got = GatherIrradiance(*scene, *mesh, **vis, solution, *sensors, go);
  const double wall = Seconds(start);
  double sq = 0, est = 0, worst = 0;
  for (size_t k = 0; k < sensors->size(); ++k) {
    const double ref = (*reference)[k].g;
    const double e = (got.irradiance[k].g - ref) / ref;
    sq += e * e;
    est += (got.std_error[k].g / ref) * (got.std_error[k].g / ref);
    worst = std::max(worst, std::fabs(e));
  }
  const double rms = std::sqrt(sq / sensors->size()), est_rms = std::sqrt(est / sensors->size());
  const bool new_file = !std::ifstream(csv_path).good();
  std::ofstream csv(csv_path, std::ios::app);
  if (new_file) {
    csv << "label,scene,elements,rays_per_element,sensor_samples,threads,seed,wall_s,rays,rms,"
           "max,est_rms,load\n";
  }
  csv << absl::StrFormat("%s,%s,%d,%g,%d,%d,%d,%.6g,%d,%.6g,%.6g,%.6g,%.3g\n", label, scene_path,
                         mesh->elements().size(), options.rays_per_element, samples, threads,
                         options.seed, wall, solution.rays + got.rays, rms, worst, est_rms,
                         LoadAverage());
  std::cerr << absl::StrFormat(
      "%-24s N=%-6d rpe %-6g samples %-7d %6.3f s  sensors rms %.4f%%  max %.4f%%  (est %.4f%%)\n",
      label, mesh->elements().size(), options.rays_per_element, samples, wall, 100 * rms,
      100 * worst, 100 * est_rms);
  return 0;
}

}  // namespace radiosity::bench
