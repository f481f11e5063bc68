// Luminaires, speed against error (docs/guide/light.md): the direct light
// of an isotropic point source on the elements of a floor, computed with 1 to 1024 points per
// element, against the closed form I x (the element's solid angle) / (its area), the solid angle
// of an axis-aligned rectangle by the corner formula atan(ab / (h sqrt(h^2 + a^2 + b^2))).
#include "solver/transport/luminaire.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>

#include "absl/strings/str_format.h"
#include "bench/bench_util.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/sides.h"
#include "solver/results/element_polygons.h"
#include "solver/transport/visibility.h"

namespace radiosity::bench {
namespace {

double SolidAngle(double x0, double x1, double z0, double z1, double h) {
  auto f = [&](double a, double b) {
    return std::atan(a * b / (h * std::sqrt(h * h + a * a + b * b)));
  };
  return f(x1, z1) - f(x0, z1) - f(x1, z0) + f(x0, z0);
}

}  // namespace

int LuminaireCommand(double element_size, const std::string& samples_list,
                     const std::string& csv_path) {
  // A 10 m x 10 m floor, an isotropic 1000 cd source 2 m above a point off its centre.
  Scene scene;
  scene.source = "floor";
  Material grey;
  grey.name = "grey";
  grey.reflectance = Rgb::Gray(0.5);
  scene.materials.push_back(grey);
  scene.surfaces.push_back({"floor", 0, 0});
  scene.vertices = {Vec3(-5, 0, -5), Vec3(-5, 0, 5), Vec3(5, 0, 5), Vec3(5, 0, -5)};
  Face face;
  face.surface = 0;
  face.vertices = {0, 1, 2, 3};
  scene.faces.push_back(face);
  MeshOptions mesh_options;
  mesh_options.element_size = element_size;
  absl::StatusOr<Mesh> mesh = Mesh::Build(scene, mesh_options);
  if (!mesh.ok()) {
    std::fprintf(stderr, "radiosity_bench: %s\n", mesh.status().ToString().c_str());
    return 1;
  }
  absl::StatusOr<std::unique_ptr<Visibility>> vis = Visibility::Build(*mesh);
  if (!vis.ok()) return 1;
  const double h = 2, intensity = 1000;
  const Vec3 at(0.3, h, -0.2);
  auto photometry = std::make_shared<Photometry>();
  photometry->gamma = {0, 180};
  photometry->c = {0};
  photometry->candela = {intensity, intensity};
  CheckPhotometry(photometry.get());
  Luminaire luminaire;
  luminaire.file = "isotropic";
  luminaire.position = at;
  luminaire.photometry = photometry;
  // The closed form per element, from its extent.
  const size_t n = mesh->elements().size();
  std::vector<double> exact(n);
  for (size_t e = 0; e < n; ++e) {
    Vec3 lo(1e30, 1e30, 1e30), hi(-1e30, -1e30, -1e30);
    // Its extent, from the corners of the polygons it is drawn as.
    ForEachElementVertex(*mesh, static_cast<int64_t>(e), [&](const Vec3& p, int, double, double) {
      lo = Min(lo, p);
      hi = Max(hi, p);
    });
    exact[e] = intensity * SolidAngle(lo.x - at.x, hi.x - at.x, lo.z - at.z, hi.z - at.z, h) /
               mesh->elements()[e].area;
  }
  std::ofstream csv(csv_path, std::ios::app);
  if (csv.tellp() == 0) {
    csv << "samples,elements,seconds,rays,rays_per_second,max_rel_error,rms_rel_error,"
           "rms_rel_std_error\n";
  }
  std::printf("%8s %9s %9s %12s %12s %12s %14s\n", "samples", "elements", "seconds", "rays",
              "max rel err", "rms rel err", "rms rel s.e.");
  for (const std::string& s : SplitList(samples_list)) {
    const int samples = std::stoi(s);
    const auto start = std::chrono::steady_clock::now();
    const ElementIrradiance out =
        LuminaireIrradiance(*mesh, **vis, {luminaire}, samples, 1, StopToken());
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    double worst = 0, sq = 0, se_sq = 0;
    for (size_t e = 0; e < n; ++e) {
      const int slot = Slot(static_cast<int>(e), kFront);
      const double rel = out.irradiance[slot].g / exact[e] - 1;
      worst = std::max(worst, std::fabs(rel));
      sq += rel * rel;
      se_sq += std::pow(out.std_error[slot].g / exact[e], 2);
    }
    const double rms = std::sqrt(sq / n), rms_se = std::sqrt(se_sq / n);
    std::printf("%8d %9zu %9.4f %12lld %12.3g %12.3g %14.3g\n", samples, n, seconds,
                static_cast<long long>(out.rays), worst, rms, rms_se);
    csv << absl::StrFormat("%d,%d,%.6g,%d,%.6g,%.6g,%.6g,%.6g\n", samples, n, seconds, out.rays,
                           seconds > 0 ? out.rays / seconds : 0, worst, rms, rms_se);
  }
  return 0;
}

}  // namespace radiosity::bench
