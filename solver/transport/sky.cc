#include "solver/transport/sky.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <cmath>

#include "absl/strings/str_format.h"
#include "solver/geometry/sides.h"
#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "solver/transport/sobol.h"

namespace radiosity {

Rgb SkyOptions::Radiance(const Vec3& dir) const {
  const double cos_theta = Dot(dir, Normalize(up));
  if (cos_theta <= 0) return Rgb();  // Below the horizon: no light.
  if (model == "uniform") return irradiance / kPi;
  if (model == "overcast") return irradiance * (9 / (7 * kPi) * (1 + 2 * cos_theta) / 3);
  return Rgb();
}

std::string SkyOptions::ToString() const {
  return absl::StrFormat("SkyOptions{model=%s irradiance=%s up=(%g, %g, %g) samples=%d}", model,
                         irradiance.ToString(), up.x, up.y, up.z, samples);
}

ElementIrradiance SkyIrradiance(const Mesh& mesh, const Visibility& visibility, const SkyOptions& sky,
                          uint64_t seed, const StopToken& stop, const ElementRange& range) {
  const size_t n = mesh.elements().size();
  ElementIrradiance out;
  out.irradiance.assign(2 * n, Rgb());
  out.std_error.assign(2 * n, Rgb());
  if (!sky.enabled()) return out;
  const SideTable& sides = mesh.sides();
  std::atomic<int64_t> rays{0};
  std::atomic<bool> stopped{false};
  const int samples = sky.samples;
  const size_t count = range.size(n);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 8), [&](const tbb::blocked_range<size_t>& r) {
    int64_t local_rays = 0;
    for (size_t i = r.begin(); i < r.end(); ++i) {
      const size_t e = static_cast<size_t>(range.Element(i));
      if (stop.ShouldStop()) {
        stopped = true;
        break;
      }
      for (int side : {kFront, kBack}) {
        const int slot = Slot(static_cast<int>(e), side);
        if (!sides.exists(slot)) continue;
        const OwenSobol points(StreamKey(seed, 0x736b79 /* "sky" */, static_cast<uint64_t>(slot)));
        Rgb sum, sum_sq;
        for (int k = 0; k < samples; ++k) {
          double u[5];
          points.GetPoint(static_cast<uint32_t>(k), 0, 5, u);
          int half = 0, face = 0;
          const Vec3 x = mesh.SampleElement(static_cast<int>(e), u[0], u[1], u[2], &half, &face);
          const Vec3& front = mesh.faces()[face].normal[half];
          const Vec3 normal = side == kFront ? front : -front;
          const Vec3 dir = CosineDirection(normal, u[3], u[4]);
          const Rgb radiance = sky.Radiance(dir);
          if (radiance.IsZero()) continue;
          ++local_rays;
          if (visibility.Occluded(x, dir, 0, 1e30, face)) {
            continue;
          }
          sum += radiance;
          sum_sq += radiance * radiance;
        }
        // H = pi E[L V] under the cosine-weighted pdf; its standard error from the sample
        // variance (conservative for scrambled Sobol' points).
        const Rgb mean = sum / samples;
        Rgb variance = (sum_sq / samples - mean * mean) / std::max(1, samples - 1);
        out.irradiance[slot] = mean * kPi;
        for (int c = 0; c < 3; ++c) {
          out.std_error[slot][c] = kPi * std::sqrt(std::max(0.0, variance[c]));
        }
      }
    }
    rays += local_rays;
  });
  out.rays = rays;
  out.complete = !stopped && !stop.ShouldStop();
  return out;
}

}  // namespace radiosity
