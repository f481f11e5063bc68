// What a solve produces: per-element radiosity and the energy books.
#ifndef RADIOSITY_SOLVER_GEOMETRY_SOLUTION_H_
#define RADIOSITY_SOLVER_GEOMETRY_SOLUTION_H_

#include <cstdint>
#include <string>
#include <vector>

#include "solver/geometry/sides.h"
#include "solver/geometry/vec.h"

namespace radiosity {

struct Solution {
  // Radiosity B (exitance leaving the side, emission included), W/m^2 per channel, indexed by
  // Slot(element, side). Back-side entries of one-sided surfaces are zero.
  std::vector<Rgb> radiosity;
  // Rays (or packets) that arrived at each slot, where the method counts them (Monte Carlo
  // shooting); empty otherwise. Adaptive refinement uses it to tell gradients from noise.
  std::vector<double> hits;
  // The estimated standard error of each slot's radiosity (W/m^2 per channel), from the
  // estimator's own variance, where the method estimates it; empty otherwise.
  std::vector<Rgb> std_error;

  // Irradiance arriving at each slot (W/m^2 per channel), and the part of it that came straight
  // from the emitters: only where the method records them (SolveOptions::track_direct), else
  // empty.
  std::vector<Rgb> irradiance;
  std::vector<Rgb> direct_irradiance;

  Rgb emitted_power;   // Total power emitted by all emitters (W per channel).
  Rgb absorbed_power;  // Power absorbed by surfaces so far.
  Rgb escaped_power;   // Power that left the scene (rays that hit nothing).
  Rgb unshot_power;    // Power received and reflected but not yet propagated.
  // Before convergence: the ambient radiosity (Cohen, Chen, Wallace & Greenberg 1988) that
  // `radiosity` includes, times each side's reflectance, as the estimate of the light not yet
  // propagated (SolverBase::AddAmbient); zero once converged.
  Rgb ambient;

  std::string method;
  uint64_t seed = 0;
  int64_t rays = 0;
  int64_t shots = 0;           // Patch shots (progressive) or sweeps (matrix solvers).
  double seconds = 0;          // Wall time of the solve (not counting meshing).
  double unshot_fraction = 1;  // unshot_power.Sum() / emitted_power.Sum().
  // Hierarchical radiosity only (0 otherwise): links between pieces of the hierarchies, and the
  // bytes held by the hierarchy and its links (Hanrahan, Salzman and Aupperle 1991).
  int64_t links = 0;
  int64_t link_memory_bytes = 0;

  std::string ToString() const;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_GEOMETRY_SOLUTION_H_
