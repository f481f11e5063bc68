// The interface every solution method implements, the base that holds what they share, and the
// loop that drives one.
//
// A solver advances in steps (a batch of patch shots, a sweep, a round of packets); between steps
// a caller may read progress, take a snapshot of the current solution, or stop it. Following
// Mitsuba 3's should_stop(), the stop flag and the time limit are also checked inside long steps
// (SolverBase::ShouldStop): a step cut short leaves the solver as it was before the step, or in
// another state whose energy books balance, and reports Interrupted().
#ifndef RADIOSITY_SOLVER_METHODS_SOLVER_H_
#define RADIOSITY_SOLVER_METHODS_SOLVER_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/geometry/compensated_sum.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/sides.h"
#include "solver/geometry/solution.h"
#include "solver/methods/checkpoint.h"
#include "solver/methods/solve_options.h"
#include "solver/transport/visibility.h"
#include "solver/util/stop.h"
#include "tbb/task_arena.h"

namespace radiosity {

struct Progress {
  int64_t step = 0;
  int64_t shots = 0;
  int64_t rays = 0;
  double unshot_fraction = 1;
  double seconds = 0;
  // Progressive refinement's computed direct light (and sky and luminaire light): the fraction
  // of the elements that have it (1 where the method computes none).
  double direct_fraction = 1;
  std::string ToString() const;
};

// Why a solve ended.
// kStalled: the method stopped at its documented bound short of the tolerance (Solver::Stalled).
enum class StopReason { kConverged, kMaxRays, kMaxSeconds, kCancelled, kStalled };
std::string StopReasonName(StopReason reason);

class Solver {
 public:
  virtual ~Solver() = default;
  // Advances by one step. Returns false when there is nothing left to do.
  virtual absl::StatusOr<bool> Step() = 0;
  virtual Progress progress() const = 0;
  // Why the last step was cut short (kCancelled: the stop flag; kMaxSeconds: the deadline), or
  // nullopt when it ran to its end.
  virtual std::optional<StopReason> Interrupted() const = 0;
  // Once Step has returned false: whether the method gave up short of its tolerance (its
  // residual stopped falling, or its bound on work was reached) rather than converging.
  virtual bool Stalled() const { return false; }
  // The current solution (radiosity of every element side, energy books), for previews.
  virtual Solution Snapshot() const = 0;
  // What results are written from. Before convergence (a deadline, a cancel, a ray budget) it is
  // a complete estimate: what has been propagated, and an estimate of what has not
  // (SolverBase::AddAmbient).
  virtual Solution Final() const { return Snapshot(); }

  // Checkpoints (checkpoint.h): after a step that ran to its end, SaveState writes what a new
  // solver of the same scene, mesh and options needs to continue exactly as this one would, and
  // returns true; false where the method cannot (its jobs restart from the beginning).
  // RestoreState, on a solver that has not stepped yet, takes such a state; an error
  // (FAILED_PRECONDITION for a state of another mesh or other options, DATA_LOSS for a damaged
  // one) may leave the solver unusable.
  virtual bool SaveState(StateWriter* /*out*/) const { return false; }
  virtual absl::Status RestoreState(StateReader* /*in*/) {
    return absl::UnimplementedError("this method does not resume from checkpoints");
  }
};

// What every method shares (Mitsuba 3's Integrator): the scene, mesh and visibility, the options,
// a task arena of options.threads, the start time and the deadline (options.max_seconds from
// construction), the stop check for inside long loops, progress, and the energy books
// (emitted = absorbed + escaped + unshot).
class SolverBase : public Solver {
 public:
  ~SolverBase() override;
  Progress progress() const override { return progress_; }
  std::optional<StopReason> Interrupted() const override { return interrupted_; }

 protected:
  SolverBase(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
             const SolveOptions& options, const std::atomic<bool>* stop, std::string method);

  // True once the stop flag is raised or the deadline has passed; stays true. Cheap: call it
  // every few thousand rays.
  bool ShouldStop() const { return stop_.ShouldStop(); }
  const StopToken& stop_token() const { return stop_; }
  tbb::task_arena& arena() const { return *arena_; }
  const SideTable& sides() const { return mesh_.sides(); }
  double Elapsed() const;
  // Ends a step: the step count and the elapsed time; `interrupted` marks it cut short.
  void EndStep(bool interrupted);
  // A solution with the method, seed, progress and energy books filled in (radiosity and unshot
  // power are the method's).
  Solution NewSolution() const;
  // The power each slot emits, exitance x area (W per channel).
  std::vector<Rgb> EmittedPerSlot() const;
  // Completes a solution stopped before convergence with the light its unshot power (or
  // residual) will bring: Cohen, Chen, Wallace & Greenberg's (1988) ambient term, that power U
  // spread uniformly over the scene's area A and interreflected,
  //   B_i += rho_i U rho_eff / (rho_mean A (1 - rho_eff))   (per channel),
  // rho_mean the area-mean reflectance and rho_eff the fraction of what is shot that surfaces send
  // on (`sent_on`, as measured by the method; rho_mean where not given, which is Cohen's term:
  // B_i += rho_i U / (A (1 - rho_mean))): the added exitance sums to rho_eff U / (1 - rho_eff),
  // the geometric series of U's bounces. Exact in a closed furnace of one reflectance; elsewhere
  // an estimate that vanishes with U. `power` is U (sol->unshot_power where not given); the
  // ambient radiosity per unit reflectance is recorded in sol->ambient. With `open` (per slot, the
  // fraction of the side's area light can reach: openness.h), A counts only open area and a side
  // partly covered by a block gets its open fraction of the term.
  void AddAmbient(Solution* sol, const Rgb* power = nullptr, const Rgb* sent_on = nullptr,
                  const std::vector<float>* open = nullptr) const;
  // What every method's state holds: progress and the books. RestoreBase also moves the start
  // time back by the saved seconds, so that progress goes on counting from them.
  void SaveBase(StateWriter* out) const;
  absl::Status RestoreBase(StateReader* in);

  const Scene& scene_;
  const Mesh& mesh_;
  const Visibility& visibility_;
  const SolveOptions options_;
  const std::string method_;
  Progress progress_;
  // The books. Sums of one term per ray are compensated (10^9 terms in a long solve).
  Rgb emitted_;
  CompensatedRgb absorbed_, escaped_;

 private:
  StopToken stop_;
  std::unique_ptr<tbb::task_arena> arena_;
  std::chrono::steady_clock::time_point start_;
  std::optional<StopReason> interrupted_;
};

// Creates the solver named by options.method (registry.h; "auto": ChooseMethod) for a mesh; the
// mesh, scene and visibility must outlive it. Fails for an unknown method, invalid options
// (Validate) or a scene with no emitter.
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
