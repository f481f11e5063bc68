// How open each element side is: the fraction of probe rays from it that meet a side that exists
// or the open sky, rather than the back of a one-sided face. A side under a block resting on its
// face (enclosed between the face and the block's underside) has openness 0 and can receive no
// light; methods that receive light at a coarser level than the element (hierarchical links,
// progressive shooting's patch-level tallies) share it out in proportion to openness, so no light
// leaks into enclosed elements.
#ifndef RADIOSITY_SOLVER_TRANSPORT_OPENNESS_H_
#define RADIOSITY_SOLVER_TRANSPORT_OPENNESS_H_

#include <cstdint>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/transport/visibility.h"
#include "solver/util/stop.h"

namespace radiosity {

// Probes per element side, each from a point of the element in a cosine-distributed direction:
// with `corners`, from its four corners (inset by 1e-3 of its size) and 16 stratified points (the
// corners matter where openness 0 must mean enclosed: where a convex footprint covers part of a
// rectangular element, the uncovered part holds one of its corners, so a partly covered element
// never gets 0, however thin its uncovered sliver); without, from `points` stratified points,
// which estimates the uncovered fraction of the element's area (an uncovered point's probes all
// meet sides that exist, a covered point's none).
struct OpennessProbes {
  bool corners = true;
  int points = 16;
  // Where the first probes disagree (a partly enclosed element), measured again from this many
  // stratified points (0: not).
  int refine_points = 0;
};

// Openness per slot (Slot(element, side)), in [0, 1]; sides that neither reflect nor transmit are
// not probed and get 1. Runs in parallel in the caller's task arena; returns an empty vector when
// `stop` stops it. Adds the probes traced to *rays. Deterministic for a seed.
// With `escaped`, adds the probes that met nothing (left the scene: 0 in a closed one).
std::vector<float> MeasureOpenness(const Mesh& mesh, const Visibility& visibility, uint64_t seed,
                                   const StopToken& stop, int64_t* rays,
                                   const OpennessProbes& probes = {}, int64_t* escaped = nullptr);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_OPENNESS_H_
