// sensors.csv: the irradiance at each sensor point.
#ifndef RADIOSITY_SOLVER_RESULTS_SENSORS_CSV_H_
#define RADIOSITY_SOLVER_RESULTS_SENSORS_CSV_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/vec.h"

namespace radiosity {

// Header "x,y,z,nx,ny,nz,r,g,b,se_r,se_g,se_b": the first nine columns as they always were (a
// script reading them by name or position keeps working), then the estimated standard error of
// r, g and b. `irradiance[i]` and `std_error[i]` (W/m^2 per channel, GatherIrradiance) belong to
// sensors[i].
absl::Status WriteSensorsCsv(const std::vector<SensorPoint>& sensors,
                             const std::vector<Rgb>& irradiance, const std::vector<Rgb>& std_error,
                             const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_SENSORS_CSV_H_
