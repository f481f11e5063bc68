// sensors.csv: the irradiance at each sensor point.
#ifndef RADIOSITY_SOLVER_RESULTS_SENSORS_CSV_H_
#define RADIOSITY_SOLVER_RESULTS_SENSORS_CSV_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/vec.h"

namespace radiosity {

// Header exactly "x,y,z,nx,ny,nz,r,g,b"; `irradiance[i]` (W/m^2 per channel, GatherIrradiance)
// belongs to sensors[i].
absl::Status WriteSensorsCsv(const std::vector<SensorPoint>& sensors,
                             const std::vector<Rgb>& irradiance, const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_SENSORS_CSV_H_
