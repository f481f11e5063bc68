// Reflection simulation (Shirley's thesis 6.1.2): energy packets leave the emitters and bounce
// from surface to surface until they are absorbed or leave the scene.
//
// Packets leave each emitting element side in numbers proportional to its power (in all about
// rays_per_element x elements packets, each carrying emitted_power / (rays_per_element x
// elements), the progressive solver's ray power), from uniform points of the element in
// cosine-distributed directions. A packet arriving at element side k adds its power to k's
// incident power; it then continues with probability p_R (reflected, from side k) or p_T
// (transmitted, from the other side), or is absorbed, where p_R and p_T are the fractions of its
// power (summed over channels) that R_k and T_k would pass on. A surviving packet's colour is
// reweighted by R_k / p_R (or T_k / p_T), so its power summed over the channels never changes
// (Russian roulette with packets of constant power: unbiased but for the kMaxBounces guard). Like
// the other zonal methods, a continuing packet leaves from a uniform point of the element it hit,
// the zonal assumption that an element's radiosity is uniform over it, so the four methods solve
// the same element-level system (leaving from the hit point would solve the continuous problem,
// which differs from it by the discretisation error).
//
// The radiosity is the expected exitance given the tallied incident power:
//   B_k = E_k + (R_k H_k + T_k' H_k') / A_k     (k' = the other side of k's element),
// an unbiased estimate. Packets run interleaved over the emitters (a stride through the planned
// packets), so the packets of a solve stopped early are a sample of all of them: their tallies,
// scaled by planned / traced, are an unbiased estimate of the whole answer (Snapshot). The books: emitted is the scene's (the power of packets not yet emitted
// counts as unshot); absorbed is tallied at every arrival as (1 - R_k - T_k) of the packet's power
// (all of it on the back of a one-sided surface); escaped is the power of packets that hit
// nothing. The roulette conserves power only in expectation, so emitted = absorbed + escaped +
// unshot holds to Monte Carlo noise, not to rounding.
//
// A packet meeting a side with specular parts S_k (transport/specular.h) continues along one of
// its specular directions with the probability of that branch's share, from the point it hit;
// the expected absorption is booked as above with S_k passed on.
//
// Results depend only on the seed: packets run in fixed chunks of kChunk, each with its own random
// stream keyed by (seed, chunk index among all planned packets), merged in order; a step is a
// whole number of chunks, so neither the thread count nor the step sizes change the answer.
#ifndef RADIOSITY_SOLVER_METHODS_REFLECTION_H_
#define RADIOSITY_SOLVER_METHODS_REFLECTION_H_

#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

#include "solver/methods/solver.h"
#include "solver/transport/specular.h"

namespace radiosity {

class ReflectionSolver : public SolverBase {
 public:
  ReflectionSolver(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
                   const SolveOptions& options, const std::atomic<bool>* stop);
  ~ReflectionSolver() override;

  // Emits the next kPacketsPerStep planned packets (fewer, in whole chunks, when the ray budget is
  // nearly spent) and follows each until it is absorbed or escapes. Returns false once every
  // planned packet is done (the tolerance does not apply: the answer is complete only when all
  // planned packets are).
  // The stop flag and the deadline are checked between packets; a step cut short is dropped
  // whole (the packets of a step are emitted again by the next one).
  absl::StatusOr<bool> Step() override;
  Solution Snapshot() const override;
  // The tallies and the next packet.
  bool SaveState(StateWriter* out) const override;
  absl::Status RestoreState(StateReader* in) override;

  // Packets emitted per step.
  static constexpr int64_t kPacketsPerStep = 1 << 16;
  // Packets per independent random stream.
  static constexpr int64_t kChunk = 1024;
  // Packets between checks of the stop flag and the deadline.
  static constexpr int64_t kStopCheck = 16;
  // A packet is absorbed after this many bounces, a guard for R + T close to 1. It biases the
  // answer by the share of power still travelling then, about exp(-kMaxBounces (1 - rho))
  // (bench/REPORT.md, "High reflectance", measures it).
  static constexpr int kMaxBounces = 1 << 16;

  // Packets planned in all.
  int64_t planned_packets() const { return planned_; }

 private:
  // The planned packets of one emitting slot: [first, first + count), each carrying `power`.
  struct Emitter {
    int slot;
    int64_t first;
    int64_t count;
    Rgb power;
  };
  // A packet's arrival at a slot.
  struct Arrival {
    int32_t slot;
    Rgb power;
  };
  struct ChunkResult {
    std::vector<Arrival> arrivals;
    Rgb emitted, absorbed, escaped;
    int64_t rays = 0;
  };

  void TraceChunk(int64_t chunk, int64_t begin, int64_t end, ChunkResult* out) const;

  // Per slot (Slot(element, side)).
  std::vector<Rgb> emitted_slot_;
  std::vector<Rgb> incident_;  // Power of every packet arrival, tallied.

  std::vector<Emitter> emitters_;  // Sorted by first.
  int64_t planned_ = 0;
  int64_t stride_ = 1;  // Packet order (see the constructor).
  int64_t next_packet_ = 0;

  Rgb emitted_so_far_;  // The power of the packets emitted so far (emitted_: all planned).
  std::vector<ChunkResult> chunks_;
  SpecularTable specular_;  // Per surface side: its specular parts.
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_REFLECTION_H_
