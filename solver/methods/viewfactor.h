// View factors as a product (`radiosity viewfactor`): the surface-to-surface matrix F_ij between
// the named surfaces of a scene, area-weighted over each surface.
//
// F_ij is the fraction of the diffuse power leaving the front of surface i (uniformly over its
// area) that arrives at the front of surface j; with front-to-front factors reciprocity
// A_i F_ij = A_j F_ji holds exactly, and in a closed enclosure of one-sided surfaces each row sums
// to 1 (closure). Thermal engineers compare these against NIST View3D.
#ifndef RADIOSITY_SOLVER_METHODS_VIEWFACTOR_H_
#define RADIOSITY_SOLVER_METHODS_VIEWFACTOR_H_

#include <atomic>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/geometry/scene.h"
#include "solver/methods/solve_options.h"

namespace radiosity {

inline constexpr Bounds kViewFactorToleranceBounds{1e-12, 0.5, "[1e-12, 0.5]"};
inline constexpr Bounds kNearBounds{0, 1000, "[0, 1000]"};
inline constexpr Bounds kRaysPerSurfaceBounds{1, 1099511627776.0, "[1, 2^40]"};
// Exact occlusion's bound on the triangles that may block one pair (beyond it, sampled).
inline constexpr int kMaxExactBlockers = 4096;

// Thermal data for radiative exchange (exchange.h): emissivity and temperature per surface (the
// surface "*" for every surface not named) and the temperature of the environment.
struct ThermalInput {
  std::vector<SurfaceThermal> surfaces;
  double ambient_temperature = 0;  // Kelvin: the black environment open scenes radiate to.

  bool empty() const { return surfaces.empty(); }
};

struct ViewFactorOptions {
  // "analytic" (adaptive quadrature of the exact point-to-polygon kernel, shadow rays for
  // occlusion), "montecarlo" (cosine-distributed rays) or "hemicube".
  std::string method = "analytic";
  // analytic: absolute accuracy target, shared over each row: a factor's estimated error is kept
  // within 0.5 tolerance (F_ij + 1 / n) for n surfaces, so that each factor, and each row's sum,
  // is within the tolerance (the near pairs of montecarlo: each factor within it).
  double tolerance = 1e-6;
  // analytic: how a pair that may be occluded sees past its obstructions: "exact" (the blockers
  // projected from each quadrature point and clipped away, as View3D does; pairs with more than
  // kMaxExactBlockers blockers cutting into their convex hull are sampled) or "sampled" (shadow
  // rays).
  std::string occlusion = "exact";
  // analytic, sampled occlusion: stratified shadow rays per quadrature point.
  int shadow_rays = 16;
  // montecarlo: rays shot from each surface.
  int64_t rays_per_surface = 1'000'000;
  // montecarlo: pairs of surfaces whose boxes are closer than `near` x the larger surface's
  // diagonal are integrated exactly (as analytic: --tolerance, --occlusion) and the rays'
  // estimates of them dropped; the rays then only estimate the far factors, which are small.
  // 0: every factor from rays.
  double near = 0;
  // Only the rows of these surfaces (names; empty: every row): the factors from each of them to
  // every surface, at the cost of those rows alone (a dense subset of a large model, or the few
  // surfaces a study needs). The other rows are left empty. Enforcement and thermal exchange
  // need every row and are refused with it.
  std::vector<std::string> from;
  // montecarlo sampling: "random", "stratified" or "halton".
  std::string sampling = "stratified";
  // hemicube: resolution, and hemicubes per surface (placed at stratified points).
  int hemicube_resolution = 256;
  int hemicube_points = 64;
  uint64_t seed = 1;
  int threads = 0;
  // Enforced on the result (viewfactor_correction.h): "none", "reciprocity" (A_i F_ij =
  // A_j F_ji exactly) or "closure" (also every row summing to 1: closed enclosures only).
  std::string enforce = "none";
  // When not empty, Gebhart factors and the net exchange are computed from the (enforced) matrix
  // (`radiosity viewfactor --thermal`; not used by ComputeViewFactors itself).
  ThermalInput thermal;
};

// F_ij stored by rows, sparse (compressed sparse rows): row i's nonzero factors are
// val[row_start[i] .. row_start[i + 1]), in ascending column col[k]. Large models see few of
// their facets from each one: memory grows with the nonzeros, not with n^2.
struct ViewFactorMatrix {
  std::vector<std::string> surfaces;  // Surface names, in scene order.
  std::vector<double> area;           // Front area of each surface.
  std::vector<int64_t> row_start;     // n + 1 offsets into col and val.
  std::vector<int32_t> col;
  std::vector<double> val;
  std::string method;
  int64_t rays = 0;
  double seconds = 0;
  // ViewFactorOptions::enforce applied: the checks before it, and the smallest F_ij after it.
  std::string enforced = "none";
  double max_reciprocity_error_before = 0;
  double max_closure_error_before = 0;
  double smallest_entry = 0;
  // montecarlo: the pairs integrated exactly (--near), and the largest standard error of a row's
  // sum of ray-estimated factors, sqrt(S (1 - S) / R) (before any enforcement).
  int64_t near_pairs = 0;
  double ray_row_error = 0;
  // ViewFactorOptions::from: the rows computed, ascending (empty: every row).
  std::vector<int32_t> rows_only;

  int size() const { return static_cast<int>(surfaces.size()); }
  int64_t nonzeros() const { return static_cast<int64_t>(val.size()); }
  // F_ij (0 where nothing is stored); a binary search in row i.
  double at(int i, int j) const;
  // Replaces the factors by the nonzero entries of the row-major n x n `dense` (n = size()).
  void SetDense(const std::vector<double>& dense);
  // Replaces the factors by per-row (column, F) lists in any order: entries of one column are
  // summed, zeros dropped; `rows` is emptied.
  void SetRows(std::vector<std::vector<std::pair<int32_t, double>>>* rows);
};

struct ViewFactorCheck {
  // max over pairs of |A_i F_ij - A_j F_ji| / max(A_i F_ij, A_j F_ji) (pairs with both 0 skipped).
  double max_reciprocity_error = 0;
  // max over rows of |1 - sum_j F_ij| (meaningful only in closed enclosures).
  double max_closure_error = 0;
  std::vector<double> row_sums;
};

// Checks every field of `options`; INVALID_ARGUMENT names the first bad one as `naming` says
// ("--shadow-rays" or "view_factor.shadow_rays").
absl::Status Validate(const ViewFactorOptions& options, FieldNaming naming);

// Computes the matrix. Fails for an unknown method or bad parameters, or if *stop becomes true.
absl::StatusOr<ViewFactorMatrix> ComputeViewFactors(const Scene& scene,
                                                    const ViewFactorOptions& options,
                                                    const std::atomic<bool>* stop);

// With ViewFactorMatrix::rows_only, over those rows and the pairs both of whose rows they are
// (the other rows' sums are 0).
ViewFactorCheck CheckViewFactors(const ViewFactorMatrix& matrix);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_VIEWFACTOR_H_
