// Direct light from the emitters: the estimator shared by the sensors' final gather (sensors.h)
// and the re-gathering of adaptive refinement passes (adaptive.h).
#ifndef RADIOSITY_SOLVER_TRANSPORT_DIRECT_LIGHT_H_
#define RADIOSITY_SOLVER_TRANSPORT_DIRECT_LIGHT_H_

#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/transport/visibility.h"

namespace radiosity {

// The direct irradiance at x with unit normal n,
//   E(x) = integral over the hemisphere of L_e cos(theta_x) d omega,  L_e = M_e / pi,
// by multiple importance sampling (Veach and Guibas 1995, balance heuristic) of two strategies,
// one sample of each per call:
//  - emitter sampling: an emitting element side chosen by power, a uniform point y on it, a
//    shadow ray; its solid-angle pdf p_l = (M_e.Sum() / total power) r^2 / cos(theta_y);
//  - cosine sampling: a direction with pdf p_c = cos(theta_x) / pi, counted when its first hit is
//    an emitting side.
// Each contributes L_e cos(theta_x) / (p_l + p_c), so a sample is bounded by M_e (the 1 / r^2 of
// emitter sampling, unbounded next to a touching emitter, is what p_c takes over), while small
// distant emitters are still found by emitter sampling. The mean of Sample over
// t_k = (k + xi) / K, k < K (systematic sampling of the emitters, which keeps each sample's
// marginal) with the other numbers uniform in [0, 1) is an unbiased estimate of E(x).
class DirectLight {
 public:
  DirectLight(const Scene& scene, const Mesh& mesh, const Visibility& visibility);

  // No emitter with positive power: every sample is zero.
  bool empty() const { return total_power_ <= 0; }

  // One sample of each strategy at x (mesh coordinates): t picks the emitter side, (r1, r2, r3)
  // the point on it (Mesh::SampleElement), (r4, r5) the cosine direction. Rays leave from
  // x + epsilon n; receiver_face >= 0 (the face x lies on) is never a blocker or a hit; with -1
  // (a free point, such as a sensor) the sampled emitter's own face does not block its ray.
  Rgb Sample(const Vec3& x, const Vec3& n, int receiver_face, double t, double r1, double r2,
             double r3, double r4, double r5) const;

 private:
  struct Emitter {
    int element;
    int side;
    Rgb exitance;
    double power;
  };
  // Exitance of the side of face `face` that `dir` arrives at (zero if it does not emit).
  Rgb EmissionSeen(int face, float u, float v, const Vec3& dir, double* cos_y) const;

  const Scene& scene_;
  const Mesh& mesh_;
  const Visibility& visibility_;
  std::vector<Emitter> emitters_;
  std::vector<double> cumulative_;  // cumulative_[i]: power of emitters 0..i.
  double total_power_ = 0;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_DIRECT_LIGHT_H_
