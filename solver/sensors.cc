#include "solver/sensors.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "solver/direct_light.h"
#include "solver/obj_loader.h"
#include "solver/rng.h"
#include "solver/sampling.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace radiosity {

absl::StatusOr<std::vector<SensorPoint>> ParseSensors(const std::string& text,
                                                      const std::string& source) {
  if (absl::Status s = CheckText(text, source); !s.ok()) return s;
  std::vector<SensorPoint> out;
  int line_no = 0;
  for (absl::string_view line : absl::StrSplit(text, '\n')) {
    ++line_no;
    std::vector<absl::string_view> fields =
        absl::StrSplit(line, absl::ByAnyChar(" \t\r"), absl::SkipEmpty());
    if (fields.empty() || fields[0][0] == '#') continue;
    if (fields.size() != 6) {
      return absl::InvalidArgumentError(
          absl::StrCat(source, ":", line_no, ": expected 6 numbers \"x y z nx ny nz\", found ",
                       fields.size(), " fields"));
    }
    double v[6];
    for (int k = 0; k < 6; ++k) {
      std::string field(fields[k]);
      char* end = nullptr;
      errno = 0;
      v[k] = std::strtod(field.c_str(), &end);
      if (end == field.c_str() || *end != '\0' || !std::isfinite(v[k])) {
        return absl::InvalidArgumentError(absl::StrCat(source, ":", line_no, ": field ", k + 1,
                                                       " '", field, "' is not a finite number"));
      }
    }
    Vec3 n{v[3], v[4], v[5]};
    if (!(Length(n) > 0)) {
      return absl::InvalidArgumentError(absl::StrCat(source, ":", line_no, ": the normal (", v[3],
                                                     ", ", v[4], ", ", v[5], ") has zero length"));
    }
    out.push_back({{v[0], v[1], v[2]}, Normalize(n)});
  }
  if (out.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(source, ": no sensor points"));
  }
  return out;
}

absl::StatusOr<std::vector<SensorPoint>> LoadSensors(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return absl::NotFoundError(absl::StrCat(path, ": cannot open: ", std::strerror(errno)));
  }
  std::stringstream ss;
  ss << in.rdbuf();
  return ParseSensors(ss.str(), path);
}

std::vector<Rgb> GatherIrradiance(const Scene& scene, const Mesh& mesh,
                                  const Visibility& visibility, const Solution& solution,
                                  const std::vector<SensorPoint>& sensors,
                                  const GatherOptions& options) {
  const auto& elements = mesh.elements();
  const auto& faces = mesh.faces();
  const DirectLight direct_light(scene, mesh, visibility);
  auto emission_of = [&](int slot) {
    const Material& m = scene.materials[scene.surfaces[elements[slot >> 1].surface].material];
    return (slot & 1) == 0 || m.two_sided ? m.emission : Rgb();
  };
  const double eps = visibility.epsilon();
  std::vector<Rgb> out(sensors.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, sensors.size()), [&](const auto& range) {
    for (size_t i = range.begin(); i < range.end(); ++i) {
      Rng rng(StreamKey(options.seed, i, 0x5e45));
      const Vec3 x = sensors[i].p - mesh.origin();
      const Vec3 n = sensors[i].n;
      // Direct: emitter and cosine sampling combined (direct_light.h).
      Rgb direct;
      if (!direct_light.empty() && options.direct_samples > 0) {
        const double xi = rng.Uniform();
        for (int k = 0; k < options.direct_samples; ++k) {
          const double r1 = rng.Uniform(), r2 = rng.Uniform(), r3 = rng.Uniform();
          const double r4 = rng.Uniform(), r5 = rng.Uniform();
          direct +=
              direct_light.Sample(x, n, -1, (k + xi) / options.direct_samples, r1, r2, r3, r4, r5);
        }
        direct *= 1.0 / options.direct_samples;
      }
      // Indirect: E = integral of L cos(theta) d omega = pi x mean over cosine-distributed
      // directions of L = (B - M_emitted) / pi of the element side seen.
      Rgb indirect;
      if (options.indirect_samples > 0) {
        for (int k = 0; k < options.indirect_samples; ++k) {
          const double r1 = rng.Uniform(), r2 = rng.Uniform();
          Vec3 dir = CosineDirection(n, r1, r2);
          Hit hit = visibility.Intersect(x + n * eps, dir, 0, 1e30);
          if (!hit.valid()) continue;
          int e = mesh.FindElement(hit.face, hit.u, hit.v);
          if (e < 0) continue;
          const MeshFace& f = faces[hit.face];
          int slot = Slot(e, Dot(dir, f.normal[f.Half(hit.u, hit.v)]) < 0 ? 0 : 1);
          indirect += solution.radiosity[slot] - emission_of(slot);
        }
        indirect *= 1.0 / options.indirect_samples;
      }
      out[i] = direct + indirect;
    }
  });
  return out;
}

absl::Status WriteSensorsCsv(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
                             const Solution& solution, const std::vector<SensorPoint>& sensors,
                             const std::string& path) {
  GatherOptions options;
  options.seed = solution.seed;
  std::vector<Rgb> e = GatherIrradiance(scene, mesh, visibility, solution, sensors, options);
  FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) {
    return absl::InternalError(absl::StrCat(path, ": cannot write: ", std::strerror(errno)));
  }
  std::fprintf(f, "x,y,z,nx,ny,nz,r,g,b\n");
  for (size_t i = 0; i < sensors.size(); ++i) {
    const SensorPoint& s = sensors[i];
    std::fprintf(f, "%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", s.p.x, s.p.y, s.p.z, s.n.x,
                 s.n.y, s.n.z, e[i].r, e[i].g, e[i].b);
  }
  if (std::fclose(f) != 0) {
    return absl::InternalError(absl::StrCat(path, ": cannot write: ", std::strerror(errno)));
  }
  return absl::OkStatus();
}

}  // namespace radiosity
