// Adaptive element refinement: model a scene with only the detail it needs.
//
// Starting from a coarse mesh, the first pass solves; each later pass splits the elements whose
// radiosity differs from a neighbour's by more than a tolerance, or across which the visibility of
// the emitters changes (shadow boundaries), and re-gathers what the new elements receive
// (RegatherRefinement), or, with RefineOptions::resolve, solves again on the refined mesh. Leaves
// stay within 2:1 of their neighbours in each face (a balanced quadtree), and CornerRadiosity
// constrains T-vertices to their edge, so shaded output has no cracks. It stops when nothing needs
// refining, at the element budget, or at the minimum size.
#ifndef RADIOSITY_SOLVER_METHODS_ADAPTIVE_H_
#define RADIOSITY_SOLVER_METHODS_ADAPTIVE_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/refine_mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/transport/visibility.h"

namespace radiosity {

struct RefineOptions {
  // Split an element when its luminance differs from a neighbour's by more than this fraction of
  // the larger of the two (0 disables adaptive refinement).
  double tolerance = 0;
  // Never split an element whose longer side is below this (scene units); 0: initial size / 64.
  double min_element_size = 0;
  // Emitter sample points tested for visibility changes across an element.
  int light_samples = 16;
  // Refinement passes at most.
  int max_passes = 6;
  // How a pass gives the new elements their values: false, re-gathering (RegatherRefinement:
  // only their direct light is computed again, in a fraction of a solve's time); true, solving
  // again from scratch on the refined mesh (every gradient, indirect ones too, at a full solve's
  // cost per pass).
  bool resolve = false;
  // Re-gathering: shadow rays per new element and emitting face where they disagree (penumbrae;
  // elsewhere DirectOptions::shadow_rays).
  int direct_samples = 128;
  std::string ToString() const;
};

// Why an element was selected.
struct RefineCandidate {
  int element;
  double priority;  // Larger first: relative difference, or 1 + covered fraction for shadows.
};

// Elements that need splitting under `options` (without the budget applied), in priority order.
std::vector<RefineCandidate> SelectForRefinement(const Scene& scene, const Mesh& mesh,
                                                 const Visibility& visibility,
                                                 const Solution& solution,
                                                 const RefineOptions& options);

// The solution on `refined` (a RefineMesh of `coarse`, with `visibility` built on it) from the
// converged `solution` on `coarse`, without solving again: elements that were not split keep
// their values; the elements an element c was split into re-gather their direct light, the part
// of the light that makes shadow edges and the sharp gradients refinement is for, computed by
// DirectIrradiance (up to options.direct_samples shadow rays per element and emitting face in
// penumbrae) and keep c's indirect light:
//  - when the solver recorded what part of c's irradiance H_c came straight from the emitters
//    (Solution::direct_irradiance, SolveOptions::track_direct), a new element e gets
//      B_e = E + R (H_d,e + H_i,c) + T (H_d,e' + H_i,c')   with H_i,c = H_c - H_direct,c,
//    (' : the other side; T: transmittance), so the Monte Carlo noise of c's direct light is
//    replaced by the re-gathered estimate (a piece in full shadow gets c's indirect light only);
//  - otherwise, with <H_d> the area mean of H_d over c's new elements,
//      B_e = B_c + R (H_d,e - <H_d>) + T (H_d,e' - <H_d'>),
//    which redistributes the power c reflects among its pieces (values floored at emission).
// c's indirect light is spread evenly over its pieces either way: gradients of indirect light
// inside c need RefineOptions::resolve. The energy books stay those of the solve. The rays spent
// are added to the solution's. Deterministic for a seed and pass, whatever the thread count.
Solution RegatherRefinement(const Scene& scene, const Mesh& coarse, const Solution& solution,
                            const Mesh& refined, const Visibility& visibility,
                            const RefineOptions& options, uint64_t seed, int pass);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_ADAPTIVE_H_
