#include "solver/results/sensors_csv.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>

#include "absl/strings/str_cat.h"
#include "solver/util/file_io.h"

namespace radiosity {

absl::Status WriteSensorsCsv(const std::vector<SensorPoint>& sensors, const std::vector<Rgb>& e,
                             const std::vector<Rgb>& se, const std::string& path) {
  if (e.size() != sensors.size() || se.size() != sensors.size()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", e.size(), " irradiance values for ",
                                                   sensors.size(), " sensor points"));
  }
  FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) {
    return WriteErrnoStatus(errno, path + ": cannot write: ");
  }
  // A grid column only when some point names its grid: files without grids keep their header.
  const bool grids = std::any_of(sensors.begin(), sensors.end(),
                                 [](const SensorPoint& s) { return !s.grid.empty(); });
  std::fprintf(f, "x,y,z,nx,ny,nz,r,g,b,se_r,se_g,se_b%s\n", grids ? ",grid" : "");
  for (size_t i = 0; i < sensors.size(); ++i) {
    const SensorPoint& s = sensors[i];
    std::fprintf(f, "%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.4g,%.4g,%.4g", s.p.x, s.p.y,
                 s.p.z, s.n.x, s.n.y, s.n.z, e[i].r, e[i].g, e[i].b, se[i].r, se[i].g, se[i].b);
    std::fprintf(f, grids ? ",%s\n" : "%s\n", grids ? s.grid.c_str() : "");
  }
  if (std::fclose(f) != 0) {
    return WriteErrnoStatus(errno, path + ": cannot write: ");
  }
  return absl::OkStatus();
}

}  // namespace radiosity
