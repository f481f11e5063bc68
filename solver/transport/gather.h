// Sensor points, as lighting engineers use them: irradiance at given points and normals from a
// converged solution, by a final gather, so results compare point for point with other tools:
//  - direct light computed (direct_irradiance.h): Lambert's exact unoccluded factor of every
//    emitting face times its visible fraction from shadow rays (many more in penumbrae);
//  - indirect light gathered: the radiosity, less the emission already counted, of the element
//    sides seen along cosine-distributed directions from Owen-scrambled Sobol' points (sobol.h),
//      E_i = integral of L cos(theta) d omega = mean over the directions of (B - M_direct),
//    in kReplicates independently scrambled sequences of samples / kReplicates points each,
//    whose spread gives the standard error (randomised quasi-Monte Carlo: the independent-
//    sampling formula would overstate the error of scrambled points several times);
//  - specular surfaces (specular.h): a gathered ray arriving at a specular part goes on along its
//    mirror, glossy and transmitted directions, adding the radiosity (emission included) seen
//    there times their weights, so emitters seen in mirrors and through glass count;
//  - light from outside the mesh: a sky's radiance along the gathered directions that escape the
//    scene (pi L each, as B = pi L for the sides seen), and every luminaire's direct light at the
//    point (luminaire.h: exact for point luminaires).
#ifndef RADIOSITY_SOLVER_TRANSPORT_GATHER_H_
#define RADIOSITY_SOLVER_TRANSPORT_GATHER_H_

#include <cstdint>
#include <string>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/transport/direct_irradiance.h"
#include "solver/transport/luminaire.h"
#include "solver/transport/sky.h"
#include "solver/transport/specular.h"
#include "solver/transport/visibility.h"
#include "solver/util/bounds.h"
#include "solver/util/stop.h"

namespace radiosity {

// Cosine-distributed rays per sensor for the indirect part (`--sensor-samples`).
inline constexpr int kDefaultSensorSamples = 8192;
inline constexpr Bounds kSensorSamplesBounds{1, 1 << 24, "[1, 16777216]"};
inline constexpr int kReplicates = 4;

struct GatherOptions {
  int samples = kDefaultSensorSamples;
  // Shadow rays per sensor and emitting face, and where they disagree, up to this many.
  int shadow_rays = 64;
  int max_shadow_rays = 4096;
  uint64_t seed = 1;
  // Light from outside the mesh, as the solve had it (SolveOptions::sky, ::luminaires).
  SkyOptions sky;
  std::vector<Luminaire> luminaires;
  int luminaire_samples = kDefaultLuminaireSamples;
  // Independently scrambled sequences of the direct part's shadow rays (DirectOptions): more
  // give honest standard errors (sensors take 8), 1 the most accurate value.
  int replicates = 1;
};

// The gather at free points: direct light computed (with emitters' images in planar mirrors,
// DirectOptions::mirror_images) plus indirect light gathered, as the file comment says. Built
// once (it lists the emitters and their images), then At() from many threads.
class PointGather {
 public:
  // `receivers`: how many points will be asked (bounds the direct part's emitter list).
  PointGather(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
              const Solution& solution, const GatherOptions& options, int64_t receivers);
  // Irradiance at x (mesh coordinates) with unit normal n, its standard error (may be null);
  // adds the rays traced to *rays. `index` keys the point's random streams. Checks `stop` every
  // 64 emitting faces of the direct part.
  Rgb At(const Vec3& x, const Vec3& n, uint64_t index, Rgb* std_error, int64_t* rays,
         const StopToken& stop = {}) const;
  const DirectIrradiance& direct() const { return direct_; }

 private:
  const Mesh& mesh_;
  const Visibility& visibility_;
  const Solution& solution_;
  GatherOptions options_;
  DirectIrradiance direct_;
  SpecularTable specular_;
};

struct SensorIrradiance {
  std::vector<Rgb> irradiance;  // W/m^2 per channel, per sensor.
  std::vector<Rgb> std_error;   // Its estimated standard error.
  int64_t rays = 0;
  bool complete = true;  // False when stopped (the values are then partial).
};

// Irradiance at each sensor: direct plus indirect (see the file comment). Runs in parallel in the
// caller's task arena and checks `stop` per sensor.
SensorIrradiance GatherIrradiance(const Scene& scene, const Mesh& mesh,
                                  const Visibility& visibility, const Solution& solution,
                                  const std::vector<SensorPoint>& sensors,
                                  const GatherOptions& options, const StopToken& stop = {});

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_GATHER_H_
