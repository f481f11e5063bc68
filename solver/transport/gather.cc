#include "solver/transport/gather.h"

#include <atomic>
#include <cmath>

#include "solver/transport/direct_irradiance.h"
#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "solver/transport/sobol.h"
#include "solver/transport/specular.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace radiosity {

PointGather::PointGather(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
                         const Solution& solution, const GatherOptions& options, int64_t receivers)
    : mesh_(mesh),
      visibility_(visibility),
      solution_(solution),
      options_(options),
      direct_(
          mesh, visibility,
          [&] {
            DirectOptions d;
            d.shadow_rays = options.shadow_rays;
            d.max_shadow_rays = std::max(options.shadow_rays, options.max_shadow_rays);
            d.seed = options.seed;
            d.replicates = options.replicates;
            d.mirror_images = true;
            return d;
          }(),
          receivers),
      specular_(scene) {}

Rgb PointGather::At(const Vec3& x, const Vec3& n, uint64_t index, Rgb* std_error, int64_t* rays,
                    const StopToken& stop) const {
  const auto& faces = mesh_.faces();
  const double eps = visibility_.epsilon();
  int64_t traced = 0;
  Rgb direct_se;
  Rgb e_direct =
      direct_.AtPoint(x, n, StreamKey(options_.seed, index, 0x5e45), &direct_se, &traced, stop);
  Rgb luminaire_variance;
  e_direct += LuminaireIrradianceAt(
      mesh_, visibility_, options_.luminaires, x, n, options_.luminaire_samples,
      StreamKey(options_.seed, index, 0x6c756d), &luminaire_variance, &traced);
  for (int c = 0; c < 3; ++c) {
    direct_se[c] = std::sqrt(direct_se[c] * direct_se[c] + luminaire_variance[c]);
  }
  // Indirect: the radiosity seen, less the emission the direct part computed; kReplicates
  // independently scrambled sequences, whose spread is the estimate's standard error.
  Rng rng(StreamKey(options_.seed, index, 0x5bec));  // Glossy directions.
  struct Pending {
    Vec3 origin, dir;
    Rgb weight;
    int skip, bounces;
    // After one ideal reflection in side `via_side` of mirror face `via` (else -1): the
    // mirror's part of the weight, whose view of an emitter the direct part computed as its
    // image.
    int via, via_side;
    Rgb image_weight;
  };
  Pending stack[2 * kMaxSpecularBounces + 4];
  Rgb replicate[kReplicates], mean;
  const int per = std::max(1, options_.samples / kReplicates);
  for (int r = 0; r < kReplicates; ++r) {
    const OwenSobol seq(StreamKey(options_.seed, index, 0x1d1ec7, static_cast<uint64_t>(r)));
    Rgb sum;
    for (int k = 0; k < per; ++k) {
      const Vec3 dir = CosineDirection(n, seq.Get(static_cast<uint32_t>(k), 0),
                                       seq.Get(static_cast<uint32_t>(k), 1));
      // The radiosity seen along the ray and, through specular parts, along their branches
      // times their weights (specular.h); emission the direct part computed is
      // left out only where it is seen straight.
      int top = 0, segments = 0;
      stack[top++] = {x + n * eps, dir, Rgb::Gray(1), -1, 0, -1, 0, Rgb()};
      while (top > 0 && segments++ < kMaxSpecularSegments) {
        const Pending at = stack[--top];
        const Hit hit = visibility_.Intersect(at.origin, at.dir, 0, 1e30, at.skip);
        ++traced;
        if (!hit.valid()) {
          // Only seen straight: the solve passed the sky's light arriving at specular parts on
          // diffusely (progressive.h), so the radiosity of the mirror or pane stands for it.
          if (options_.sky.enabled() && at.bounces == 0) {
            sum += options_.sky.Radiance(at.dir) * kPi;
          }
          continue;
        }
        const int e = mesh_.FindElement(hit.face, hit.u, hit.v);
        if (e < 0) continue;
        const MeshFace& f = faces[hit.face];
        const int side = Dot(at.dir, f.normal[f.Half(hit.u, hit.v)]) < 0 ? kFront : kBack;
        const int slot = Slot(e, side);
        Rgb seen = solution_.radiosity[slot] * at.weight;
        if (at.bounces == 0 && direct_.Computes(hit.face, side)) {
          seen -= mesh_.sides()[slot].exitance;
        }
        if (at.via >= 0 && direct_.ComputesImage(hit.face, side, at.via, at.via_side)) {
          seen -= mesh_.sides()[slot].exitance * at.image_weight;
        }
        sum += seen;
        const SideRule& rule = mesh_.sides()[slot];
        if (specular_.empty() || !rule.Specular() || at.bounces >= kMaxSpecularBounces) {
          continue;
        }
        const SpecularRule& spec = specular_.Rule(f.surface, side);
        Vec3 hn = Normalize(Vec3(hit.ng[0], hit.ng[1], hit.ng[2]));
        if (side == kBack) hn = -hn;
        const double r1 = spec.glossy.IsZero() ? 0 : rng.Uniform();
        const double r2 = spec.glossy.IsZero() ? 0 : rng.Uniform();
        SpecularBranch branches[3];
        const int count = ScatterSpecular(spec, at.dir, hn, r1, r2, branches, /*radiance=*/true);
        const Vec3 p = at.origin + at.dir * static_cast<double>(hit.t);
        for (int b = 0; b < count; ++b) {
          const Rgb w = at.weight * branches[b].weight;
          if (w.Max() < kSpecularCutWeight) continue;
          const bool image = at.bounces == 0 && branches[b].mirror_direction;
          stack[top++] = {p,
                          branches[b].dir,
                          w,
                          hit.face,
                          at.bounces + 1,
                          image ? hit.face : -1,
                          side,
                          image ? spec.mirror : Rgb()};
        }
      }
    }
    replicate[r] = sum / per;
    mean += replicate[r] / kReplicates;
  }
  Rgb var;
  for (const Rgb& r : replicate) var += (r - mean) * (r - mean);
  var = var / (kReplicates * (kReplicates - 1.0));
  if (std_error != nullptr) {
    *std_error = Rgb(std::sqrt(direct_se.r * direct_se.r + var.r),
                     std::sqrt(direct_se.g * direct_se.g + var.g),
                     std::sqrt(direct_se.b * direct_se.b + var.b));
  }
  *rays += traced;
  return e_direct + mean;
}

SensorIrradiance GatherIrradiance(const Scene& scene, const Mesh& mesh,
                                  const Visibility& visibility, const Solution& solution,
                                  const std::vector<SensorPoint>& sensors,
                                  const GatherOptions& options, const StopToken& stop) {
  GatherOptions o = options;
  o.replicates = 8;  // Honest standard errors: sensors are few.
  const PointGather gather(scene, mesh, visibility, solution, o,
                           static_cast<int64_t>(sensors.size()));
  SensorIrradiance out;
  out.irradiance.assign(sensors.size(), Rgb());
  out.std_error.assign(sensors.size(), Rgb());
  std::atomic<int64_t> rays{0};
  std::atomic<bool> stopped{false};
  tbb::parallel_for(tbb::blocked_range<size_t>(0, sensors.size()), [&](const auto& range) {
    for (size_t i = range.begin(); i < range.end(); ++i) {
      if (stop.ShouldStop()) {
        stopped = true;
        return;
      }
      int64_t traced = 0;
      out.irradiance[i] = gather.At(sensors[i].p - mesh.origin(), sensors[i].n, i,
                                    &out.std_error[i], &traced, stop);
      rays += traced;
    }
  });
  out.rays = rays;
  out.complete = !stopped && !stop.ShouldStop();
  return out;
}

}  // namespace radiosity
