// Surface emissivities and temperatures for radiative exchange (`radiosity viewfactor --thermal`):
// a CSV file with the header "surface,emissivity,temperature" (temperature in kelvin), one
// surface a line; the surface "*" gives the values of every surface not named. Surface names may
// be quoted as in RFC 4180 ("a, b" or "say ""hi"""); blank lines and lines starting with # are
// skipped.
#ifndef RADIOSITY_SOLVER_INPUT_THERMAL_FILE_H_
#define RADIOSITY_SOLVER_INPUT_THERMAL_FILE_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/scene.h"

namespace radiosity {

// Errors name `source`, the line and the problem (header, field count, quoting, a value that is
// not a number or out of range, a surface named twice, no rows).
absl::StatusOr<std::vector<SurfaceThermal>> ParseThermal(const std::string& text,
                                                         const std::string& source);
absl::StatusOr<std::vector<SurfaceThermal>> LoadThermal(const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_INPUT_THERMAL_FILE_H_
