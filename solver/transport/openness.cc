#include "solver/transport/openness.h"

#include <atomic>

#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "tbb/parallel_for.h"

namespace radiosity {

std::vector<float> MeasureOpenness(const Mesh& mesh, const Visibility& visibility, uint64_t seed,
                                   const StopToken& stop, int64_t* rays,
                                   const OpennessProbes& probes, int64_t* escaped) {
  const int kCorners = probes.corners ? 4 : 0;
  const int kOpennessProbes = kCorners + probes.points;
  constexpr double kInset = 1e-3;
  const auto& elements = mesh.elements();
  const auto& faces = mesh.faces();
  std::vector<float> openness(2 * elements.size(), 1.0f);
  std::atomic<int64_t> traced{0}, left{0};
  std::atomic<bool> stopped{false};
  tbb::parallel_for(size_t{0}, elements.size(), [&](size_t e) {
    if (stopped.load(std::memory_order_relaxed)) return;
    if (stop.ShouldStop()) {
      stopped = true;
      return;
    }
    for (int side = 0; side < 2; ++side) {
      if (!mesh.sides().at(static_cast<int>(e), side).Receives()) continue;
      Rng rng(StreamKey(seed, 3ULL << 40, e, side));
      // The fraction of `count` probes that are open (with or without the corners first).
      auto measure = [&](int corners, int count) {
        int open = 0;
        for (int k = 0; k < count; ++k) {
          // Mesh::SampleElement takes (piece choice, u, v) over the element's parameter square.
          double u, v;
          if (k < corners) {
            u = (k & 1) ? 1 - kInset : kInset;
            v = (k & 2) ? 1 - kInset : kInset;
          } else {
            const Stratum cell = StratumCell(count - corners, k - corners);
            u = cell.u0 + cell.du * rng.Uniform();
            v = cell.v0 + cell.dv * rng.Uniform();
          }
          int half = 0, face = 0;
          const Vec3 origin =
              mesh.SampleElement(static_cast<int>(e), rng.Uniform(), u, v, &half, &face);
          const Vec3 normal = side == 0 ? faces[face].normal[half] : -faces[face].normal[half];
          const Vec3 dir = CosineDirection(normal, rng.Uniform(), rng.Uniform());
          const Hit hit = visibility.Intersect(origin, dir, 0, 1e30, face);
          if (!hit.valid()) {
            ++open;
            left.fetch_add(1, std::memory_order_relaxed);
            continue;
          }
          const MeshFace& f = faces[hit.face];
          const bool front = Dot(dir, f.normal[f.Half(hit.u, hit.v)]) < 0;
          if (mesh.sides().OfSurface(f.surface, front ? kFront : kBack).exists) ++open;
        }
        traced.fetch_add(count, std::memory_order_relaxed);
        return static_cast<float>(open) / static_cast<float>(count);
      };
      float o = measure(kCorners, kOpennessProbes);
      // Partly enclosed: measured again, finer.
      if (o > 0 && o < 1 && probes.refine_points > kOpennessProbes) {
        o = measure(0, probes.refine_points);
      }
      openness[Slot(static_cast<int>(e), side)] = o;
    }
  });
  *rays += traced.load();
  if (escaped != nullptr) *escaped += left.load();
  if (stopped) return {};
  return openness;
}

}  // namespace radiosity
