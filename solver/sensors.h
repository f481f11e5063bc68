// Sensor points, as lighting engineers use them: irradiance at given points and normals from a
// converged solution, by a final gather (direct light from the emitters with shadow rays, indirect
// light from the element radiosities), so results compare point for point with other tools.
#ifndef RADIOSITY_SOLVER_SENSORS_H_
#define RADIOSITY_SOLVER_SENSORS_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/mesh.h"
#include "solver/scene.h"
#include "solver/solution.h"
#include "solver/visibility.h"

namespace radiosity {

// A point where irradiance is wanted: position (scene coordinates) and unit normal.
struct SensorPoint {
  Vec3 p;
  Vec3 n;
};

// Parses one point a line, "x y z nx ny nz" (the format Radiance's rtrace reads); blank lines and
// lines starting with # are skipped. The normal is normalised. Errors name `source`, the line and
// the problem (wrong field count, not a number, zero normal).
absl::StatusOr<std::vector<SensorPoint>> ParseSensors(const std::string& text,
                                                      const std::string& source);
absl::StatusOr<std::vector<SensorPoint>> LoadSensors(const std::string& path);

struct GatherOptions {
  // Shadow rays to the emitters per sensor (stratified over each emitting element, by power).
  int direct_samples = 4096;
  // Cosine-distributed rays per sensor for the indirect part.
  int indirect_samples = 4096;
  uint64_t seed = 1;
};

// Irradiance (W/m^2 per channel) at each sensor: E_direct + E_indirect, where the direct part
// integrates emitters' exitance over their solid angle with shadow rays and the indirect part
// gathers the radiosity of the element sides seen (excluding emission, already counted).
std::vector<Rgb> GatherIrradiance(const Scene& scene, const Mesh& mesh,
                                  const Visibility& visibility, const Solution& solution,
                                  const std::vector<SensorPoint>& sensors,
                                  const GatherOptions& options);

// sensors.csv: header exactly "x,y,z,nx,ny,nz,r,g,b".
absl::Status WriteSensorsCsv(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
                             const Solution& solution, const std::vector<SensorPoint>& sensors,
                             const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_SENSORS_H_
