#include "solver/transport/gather.h"

#include "solver/transport/direct_light.h"
#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace radiosity {

std::vector<Rgb> GatherIrradiance(const Scene& scene, const Mesh& mesh,
                                  const Visibility& visibility, const Solution& solution,
                                  const std::vector<SensorPoint>& sensors,
                                  const GatherOptions& options) {
  const auto& faces = mesh.faces();
  const DirectLight direct_light(scene, mesh, visibility);
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
          indirect += solution.radiosity[slot] - mesh.sides()[slot].exitance;
        }
        indirect *= 1.0 / options.indirect_samples;
      }
      out[i] = direct + indirect;
    }
  });
  return out;
}

}  // namespace radiosity
