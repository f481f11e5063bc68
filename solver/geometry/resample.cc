#include "solver/geometry/resample.h"

#include <algorithm>

#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace radiosity {

std::vector<Rgb> ResampleRadiosity(const Mesh& from, const Solution& solution,
                                   const std::vector<std::array<Rgb, 4>>& corners, Reading reading,
                                   const Mesh& to, int samples) {
  const auto& elements = to.elements();
  std::vector<Rgb> out(2 * elements.size());
  if (from.faces().size() != to.faces().size()) return {};
  const int k = std::max(1, samples);
  const size_t slots = reading == Reading::kInterpolated
                           ? std::min(solution.radiosity.size(), corners.size())
                           : solution.radiosity.size();
  const auto& src = from.elements();
  tbb::parallel_for(tbb::blocked_range<size_t>(0, elements.size()), [&](const auto& range) {
    for (size_t j = range.begin(); j < range.end(); ++j) {
      const Element& e = elements[j];
      const MeshFace& f = to.faces()[e.face];
      Rgb sum[2];
      double weight = 0;
      for (int a = 0; a < k; ++a) {
        const double u = e.u0 + (a + 0.5) / k * (e.u1 - e.u0);
        for (int b = 0; b < k; ++b) {
          const double v = e.v0 + (b + 0.5) / k * (e.v1 - e.v0);
          const double w = f.jacobian[f.Half(u, v)];
          if (!(w > 0)) continue;  // Beyond a triangle's diagonal.
          const int s = from.FindElement(e.face, u, v);
          if (s < 0) continue;
          for (int side = 0; side < 2; ++side) {
            const size_t slot = static_cast<size_t>(Slot(s, side));
            if (slot >= slots) continue;
            Rgb value = solution.radiosity[slot];
            if (reading == Reading::kInterpolated) {
              // Bilinear in the source element's local coordinates (as RenderImage shades).
              const Element& se = src[s];
              const double du = se.u1 - se.u0, dv = se.v1 - se.v0;
              const double ls = du > 0 ? std::clamp((u - se.u0) / du, 0.0, 1.0) : 0.5;
              const double lt = dv > 0 ? std::clamp((v - se.v0) / dv, 0.0, 1.0) : 0.5;
              const std::array<Rgb, 4>& c = corners[slot];
              value = c[0] * ((1 - ls) * (1 - lt)) + c[1] * (ls * (1 - lt)) +
                      c[2] * ((1 - ls) * lt) + c[3] * (ls * lt);
            }
            sum[side] += value * w;
          }
          weight += w;
        }
      }
      if (weight <= 0) {
        // A sliver thinner than the grid: read the element's centroid cell instead.
        const int s = from.FindElement(e.face, 0.5 * (e.u0 + e.u1), 0.5 * (e.v0 + e.v1));
        for (int side = 0; side < 2 && s >= 0; ++side) {
          const size_t slot = static_cast<size_t>(Slot(s, side));
          if (slot < solution.radiosity.size()) out[2 * j + side] = solution.radiosity[slot];
        }
        continue;
      }
      out[2 * j] = sum[0] / weight;
      out[2 * j + 1] = sum[1] / weight;
    }
  });
  return out;
}

}  // namespace radiosity
