// Sensor points from a text file, one point a line, "x y z nx ny nz" (the format Radiance's
// rtrace reads): where lighting engineers want irradiance (`radiosity solve --sensors`).
#ifndef RADIOSITY_SOLVER_INPUT_SENSORS_FILE_H_
#define RADIOSITY_SOLVER_INPUT_SENSORS_FILE_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/scene.h"

namespace radiosity {

// OK when `name` may name a sensor grid: 1 to 64 of A-Z a-z 0-9 _ . - (it becomes a CSV cell).
absl::Status CheckSensorGridName(const std::string& name);

// Parses one point a line; blank lines and lines starting with # are skipped, except
// `# grid: NAME`, which puts the points after it into the grid NAME. The normal is
// normalised. Errors name `source`, the line and the problem (wrong field count, not a number,
// zero normal, no points).
absl::StatusOr<std::vector<SensorPoint>> ParseSensors(const std::string& text,
                                                      const std::string& source);
absl::StatusOr<std::vector<SensorPoint>> LoadSensors(const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_INPUT_SENSORS_FILE_H_
