// Sensor points, as lighting engineers use them: irradiance at given points and normals from a
// converged solution, by a final gather (direct light from the emitters with shadow rays, indirect
// light from the element radiosities), so results compare point for point with other tools.
#ifndef RADIOSITY_SOLVER_TRANSPORT_GATHER_H_
#define RADIOSITY_SOLVER_TRANSPORT_GATHER_H_

#include <string>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/transport/visibility.h"

namespace radiosity {

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

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_GATHER_H_
