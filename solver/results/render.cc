#include "solver/results/render.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>

#include "solver/geometry/interpolation.h"
#include "solver/transport/sampling.h"

namespace radiosity {

namespace {

// Deterministic per-pixel random numbers: SplitMix64 (Steele, Lea & Flood 2014).
class PixelRng {
 public:
  PixelRng(uint64_t x, uint64_t y) : state_(0x5EED5EED12345678ull ^ (x << 32) ^ y) { Next(); }
  uint64_t Next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1).
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }

 private:
  uint64_t state_;
};

// The first element side seen along a ray from `eye` (ignoring face `skip`), skipping the backs
// of one-sided surfaces (up to 16 of them): its slot, or -1; the face hit and (u, v) of the hit
// on it, and (when `hit_out` is not null) the hit.
int VisibleSlot(const Mesh& mesh, const Visibility& visibility, const Vec3& eye, const Vec3& dir,
                size_t slots, double* u, double* v, int* face, int skip = -1,
                Hit* hit_out = nullptr) {
  const double eps = visibility.epsilon();
  double tnear = 0;
  int skipped = skip;
  for (int pass = 0; pass <= 16; ++pass) {
    Hit hit =
        visibility.Intersect(eye, dir, tnear, std::numeric_limits<double>::infinity(), skipped);
    if (!hit.valid()) return -1;
    const MeshFace& f = mesh.faces()[hit.face];
    const int side = Dot(dir, f.normal[f.Half(hit.u, hit.v)]) < 0 ? 0 : 1;
    const int e = mesh.FindElement(hit.face, hit.u, hit.v);
    if (e >= 0 && mesh.sides().exists(Slot(e, side)) &&
        static_cast<size_t>(Slot(e, side)) < slots) {
      *u = hit.u;
      *v = hit.v;
      *face = hit.face;
      if (hit_out != nullptr) *hit_out = hit;
      return Slot(e, side);
    }
    // Past the hit by the scene epsilon, and by more than float rounding of t; the face just
    // skipped is also ignored outright.
    tnear = hit.t + std::max(eps, 1e-6 * hit.t);
    skipped = hit.face;
  }
  return -1;
}

}  // namespace

Image RenderImage(const Mesh& mesh, const Visibility& visibility, const Solution& solution,
                  const std::vector<std::array<Rgb, 4>>& corners, const Camera& camera, int width,
                  int height, int samples_per_pixel, const StopToken* stop,
                  const SpecularTable* specular) {
  RenderOptions options;
  options.samples_per_pixel = samples_per_pixel;
  options.stop = stop;
  options.specular = specular;
  return RenderImage(mesh, visibility, solution, corners, camera, width, height, options);
}

Image RenderImage(const Mesh& mesh, const Visibility& visibility, const Solution& solution,
                  const std::vector<std::array<Rgb, 4>>& corners, const Camera& camera, int width,
                  int height, const RenderOptions& options) {
  const int samples_per_pixel = options.samples_per_pixel;
  const StopToken* stop = options.stop;
  const SpecularTable* specular = options.specular;
  const PointGather* gather = options.gather;
  Image image;
  if (width <= 0 || height <= 0) return image;
  image.width = width;
  image.height = height;
  image.rgb.assign(3 * static_cast<size_t>(width) * height, 0.0f);
  const int spp = std::max(1, samples_per_pixel);
  const PrimaryRays rays(mesh, camera, width, height);
  // Stratified jitter on a g x g grid, and plain random positions for the remaining samples.
  const int grid = static_cast<int>(std::sqrt(static_cast<double>(spp)));

  // Radiance along a ray (unit dir): L = B / pi of the diffuse part where it arrives, plus, where
  // that side has specular parts, the radiance along each specular branch times its weight (an
  // iterative walk over a small stack; transport/specular.h).
  const bool follow = specular != nullptr && !specular->empty();
  auto trace = [&](const Vec3& primary, PixelRng& rng, uint64_t key) -> Rgb {
    struct Pending {
      Vec3 origin, dir;
      Rgb weight;
      int skip, bounces;
    };
    Pending stack[2 * kMaxViewBounces + 4];
    int top = 0;
    stack[top++] = {rays.eye, primary, Rgb::Gray(1), -1, 0};
    Rgb radiance;
    int segments = 0;
    while (top > 0 && segments++ < kMaxViewSegments) {
      const Pending at = stack[--top];
      double u, v;
      int face;
      Hit hit;
      const int slot = VisibleSlot(mesh, visibility, at.origin, at.dir, corners.size(), &u, &v,
                                   &face, at.skip, &hit);
      if (slot < 0) continue;
      const int side = SideOfSlot(slot);
      Vec3 n = Normalize(Vec3(hit.ng[0], hit.ng[1], hit.ng[2]));
      if (side == kBack) n = -n;
      const Vec3 p = at.origin + at.dir * static_cast<double>(hit.t);
      const SideRule& rule = mesh.sides()[slot];
      const SideRule& other = mesh.sides()[OtherSide(slot)];
      if (gather != nullptr && (rule.Reflects() || other.Transmits() || rule.Emits())) {
        Rgb b = rule.exitance;
        int64_t gathered = 0;
        const uint64_t index = 4 * key + 2 * static_cast<uint64_t>(at.bounces > 0);
        if (rule.Reflects()) b += rule.reflectance * gather->At(p, n, index, nullptr, &gathered);
        if (other.Transmits()) {
          b += other.transmittance * gather->At(p, -n, index + 1, nullptr, &gathered);
        }
        radiance += at.weight * b / kPi;
      } else {
        radiance += at.weight *
                    InterpolatedRadiosity(mesh, corners, ElementOfSlot(slot), side, face, u, v) /
                    kPi;
      }
      if (!follow || at.bounces >= kMaxViewBounces || !rule.Specular()) continue;
      const SpecularRule& spec = specular->Rule(mesh.faces()[face].surface, side);
      const double r1 = spec.glossy.IsZero() ? 0 : rng.Uniform();
      const double r2 = spec.glossy.IsZero() ? 0 : rng.Uniform();
      SpecularBranch branches[3];
      const int count = ScatterSpecular(spec, at.dir, n, r1, r2, branches, /*radiance=*/true);
      for (int k = 0; k < count; ++k) {
        const Rgb w = at.weight * branches[k].weight;
        if (w.Max() < kSpecularCutWeight) continue;
        stack[top++] = {p, branches[k].dir, w, face, at.bounces + 1};
      }
    }
    return radiance;
  };

  std::atomic<bool> stopped{false};
  std::atomic<int> rows_done{0};
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      // Each row costs width x spp rays, whose cost depends on the scene.
      if (stopped.load(std::memory_order_relaxed)) return;
      if (stop != nullptr && stop->ShouldStop()) {
        stopped = true;
        return;
      }
      for (int x = 0; x < width; ++x) {
        PixelRng rng(static_cast<uint64_t>(x), static_cast<uint64_t>(y));
        Rgb sum;
        for (int k = 0; k < spp; ++k) {
          double jx, jy;
          if (k < grid * grid) {
            jx = (k % grid + rng.Uniform()) / grid;
            jy = (k / grid + rng.Uniform()) / grid;
          } else {
            jx = rng.Uniform();
            jy = rng.Uniform();
          }
          sum += trace(rays.Direction(x + jx, y + jy), rng,
                       (static_cast<uint64_t>(y) * width + x) * spp + k);
        }
        sum = sum / spp;
        float* out = &image.rgb[3 * (static_cast<size_t>(y) * width + x)];
        out[0] = static_cast<float>(sum.r);
        out[1] = static_cast<float>(sum.g);
        out[2] = static_cast<float>(sum.b);
      }
      if (options.progress) {
        options.progress(static_cast<double>(++rows_done) / height);
      }
    }
  });
  if (stopped) return Image();
  return image;
}

void DrawWireframe(const Mesh& mesh, const Visibility& visibility, const Camera& camera,
                   const std::vector<int>& pieces, Image* image) {
  const int width = image->width, height = image->height;
  if (width <= 0 || height <= 0 || image->rgb.size() != 3 * static_cast<size_t>(width) * height) {
    return;
  }
  const PrimaryRays rays(mesh, camera, width, height);
  const size_t slots = 2 * mesh.elements().size();
  // What each pixel centre sees: the piece (or element) and the side, -1 for nothing.
  std::vector<int64_t> id(static_cast<size_t>(width) * height, -1);
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int x = 0; x < width; ++x) {
        double u, v;
        int face;
        const int slot = VisibleSlot(mesh, visibility, rays.eye, rays.Direction(x + 0.5, y + 0.5),
                                     slots, &u, &v, &face);
        if (slot < 0) continue;
        const int e = ElementOfSlot(slot);
        const int64_t piece =
            static_cast<size_t>(e) < pieces.size() && pieces[e] >= 0 ? pieces[e] : e;
        id[static_cast<size_t>(y) * width + x] = 2 * piece + SideOfSlot(slot);
      }
    }
  });
  // An edge pixel sees a different piece than its right or lower neighbour: darkened, so the
  // lines stay visible over bright and mid-tone shading alike.
  constexpr float kLine = 0.15f;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t i = static_cast<size_t>(y) * width + x;
      const bool edge =
          (x + 1 < width && id[i + 1] != id[i]) || (y + 1 < height && id[i + width] != id[i]);
      if (!edge || id[i] < 0) continue;
      for (int c = 0; c < 3; ++c) image->rgb[3 * i + c] *= kLine;
    }
  }
}

}  // namespace radiosity
