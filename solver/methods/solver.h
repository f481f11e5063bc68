// The interface every solution method implements, and the loop that drives one.
//
// A solver advances in steps (a batch of patch shots, a sweep, a round of packets); between steps
// a caller may read progress, take a snapshot of the current solution, or stop it. Following
// Mitsuba 3's should_stop(), the stop flag and the time limit are also checked inside long steps.
#ifndef RADIOSITY_SOLVER_METHODS_SOLVER_H_
#define RADIOSITY_SOLVER_METHODS_SOLVER_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/transport/formfactor.h"
#include "solver/transport/visibility.h"

namespace radiosity {

struct SolveOptions {
  // progressive, jacobi, gauss-seidel, reflection, hierarchical, or auto (ChooseMethod below).
  std::string method = "progressive";
  // Stop when the unshot power falls below this fraction of the emitted power.
  double tolerance = 1e-3;
  // Stop after this many rays (0: no limit).
  int64_t max_rays = 0;
  // Stop after this many seconds of solving (0: no limit).
  double max_seconds = 0;
  uint64_t seed = 1;
  // Worker threads (0: all cores). Results do not depend on it.
  int threads = 0;
  // Monte Carlo ray density: each ray carries emitted_power / (rays_per_element x elements), so
  // the rays spent grow linearly with the element count (Shirley, 6.2: O(N) rays).
  double rays_per_element = 1000;
  // Shooting origins within a patch: false, uniform over the patch (the chapter's
  // substructuring); true, weighted by each element's unshot power (same cost, and converges to
  // the element-level solution).
  bool weighted_shooting = true;
  // How form factors are estimated by the solvers that need them (progressive with a non-Monte
  // Carlo estimator, jacobi, gauss-seidel).
  FormFactorOptions formfactor;
  // Progressive: add an ambient term (Cohen et al. 1988) to snapshots taken before convergence,
  // for previews; it never enters the converged answer or elements.csv of a converged solve.
  bool ambient = false;
  // Progressive: overshooting factor (1 = none); a shooter also shoots this multiple of its unshot
  // power, the excess recorded as negative unshot power (Feda & Purgathofer 1992).
  double overshoot = 1.0;
  // Progressive: also record each element side's incident irradiance and the part of it that
  // came straight from the emitters (Solution::irradiance, direct_irradiance), for adaptive
  // refinement's re-gathering (adaptive.h). Costs two colours per element side.
  bool track_direct = false;
  // jacobi / gauss-seidel: refuse when the form-factor matrix would exceed this many MiB.
  double max_matrix_mb = 4096;

  std::string ToString() const;
};

struct Progress {
  int64_t step = 0;
  int64_t shots = 0;
  int64_t rays = 0;
  double unshot_fraction = 1;
  double seconds = 0;
  std::string ToString() const;
};

// Why a solve ended.
enum class StopReason { kConverged, kMaxRays, kMaxSeconds, kCancelled };
std::string StopReasonName(StopReason reason);

class Solver {
 public:
  virtual ~Solver() = default;
  // Advances by one step. Returns false when there is nothing left to do.
  virtual absl::StatusOr<bool> Step() = 0;
  virtual Progress progress() const = 0;
  // The current solution (radiosity of every element side, energy books), for previews: it may
  // include an ambient estimate of the light not yet propagated (SolveOptions::ambient).
  virtual Solution Snapshot() const = 0;
  // The solution itself, never with a preview-only term: what results are written from.
  virtual Solution Final() const { return Snapshot(); }
};

// What method "auto" runs for a scene, and why (logged, and written to summary.json).
//
// Hierarchical radiosity where it was measured to converge fastest: a bright scene (the
// area-weighted mean of R + T, its largest channel, at least kAutoMinAlbedo) of few polygons (at
// most kAutoMaxFaces, since refinement starts from every pair of faces: F^2 links, no
// clustering). Everywhere else progressive refinement. bench/REPORT.md, "High reflectance: which
// method converges fastest": to a 1 % largest element error, hierarchical took 0.3 to 10 s where
// progressive took 12 to 21 s at rho = 0.9 to 0.999; progressive's rays grow like
// K N / (1 - rho) (Shirley 6.2), the hierarchical solver's Jacobi sweeps like
// log(tolerance) / log(rho) over links it builds once. Overshooting, the other remedy tried,
// diverges with Monte Carlo rows (README, "Hard cases").
inline constexpr double kAutoMinAlbedo = 0.9;
inline constexpr int64_t kAutoMaxFaces = 200;

struct MethodChoice {
  std::string method;  // progressive or hierarchical.
  std::string reason;  // e.g. "mean albedo 0.95 >= 0.9 and 6 faces <= 200".
  double mean_albedo = 0;
  std::string ToString() const;
};

// Area-weighted mean over the element sides that exist of R + T, the largest channel: the
// fraction of arriving light a surface sends on; a closed scene multiplies its emitted power by
// about 1 / (1 - it).
double MeanAlbedo(const Scene& scene, const Mesh& mesh);

MethodChoice ChooseMethod(const Scene& scene, const Mesh& mesh);

// Creates the solver named by options.method ("auto": ChooseMethod) for a mesh; the mesh, scene and
// visibility must outlive it. Fails for an unknown method or a scene with no emitter.
absl::StatusOr<std::unique_ptr<Solver>> CreateSolver(const Scene& scene, const Mesh& mesh,
                                                     const Visibility& visibility,
                                                     const SolveOptions& options,
                                                     const std::atomic<bool>* stop);

// Runs a solver until it converges or a limit in `options` is reached, or *stop becomes true.
// `on_progress` (may be empty) is called after every step. Returns the reason it stopped.
absl::StatusOr<StopReason> RunSolver(Solver& solver, const SolveOptions& options,
                                     const std::atomic<bool>* stop,
                                     const std::function<void(const Progress&)>& on_progress);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_SOLVER_H_
