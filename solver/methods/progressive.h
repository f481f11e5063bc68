// Progressive refinement by Monte Carlo shooting: absorb and re-emit (Shirley's thesis 6.1.3 and
// 6.2; Cohen, Chen, Wallace & Greenberg 1988).
//
// Every element side keeps the power it has received but not yet passed on ("unshot"). A step
// picks the patch sides with the most unshot power (Southwell order; several per step so that the
// rays fill all cores), and each shoots its unshot power as rays of equal power from points of its
// elements, in cosine-distributed directions: the number of rays is proportional to the power, so
// the rays spent over the whole solve are O(N) for N elements (6.2). A ray hitting element side j
// deposits its power there: R_j of it is added to j's unshot power and to its exitance, T_j goes
// to the other side, the rest is absorbed. A ray that hits nothing escapes.
//
// Energy is conserved exactly (up to rounding): emitted = absorbed + escaped + unshot at every
// step. Results depend only on the seed: rays are generated in fixed chunks, each with its own
// random stream, and merged in order, whatever the thread count.
#ifndef RADIOSITY_SOLVER_METHODS_PROGRESSIVE_H_
#define RADIOSITY_SOLVER_METHODS_PROGRESSIVE_H_

#include <atomic>
#include <memory>
#include <vector>

#include "solver/methods/solver.h"

namespace radiosity {

class ProgressiveSolver : public SolverBase {
 public:
  ProgressiveSolver(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
                    const SolveOptions& options, const std::atomic<bool>* stop);
  ~ProgressiveSolver() override;

  // Creates the form-factor estimator when options.formfactor.method is not "montecarlo" (then
  // each shot distributes the patch's power by an estimated row, F_pj, instead of by its own rays).
  absl::Status Init();

  // Checks the stop flag and the deadline between chunks of rays (or rows); a step cut short
  // gives the power of the rays it did not trace back to their shooters.
  absl::StatusOr<bool> Step() override;
  Solution Snapshot() const override;
  Solution Final() const override;

  // Rays per step at most (a step is the unit of progress reports and cancellation).
  static constexpr int64_t kMaxRaysPerStep = 1 << 18;
  // Rays per independent random stream.
  static constexpr int kChunk = 4096;

 private:
  // A run of rays from one element side, each carrying `power`.
  struct RayGroup {
    int element;
    int side;
    int64_t first_ray;
    int64_t count;
    Rgb power;
    Rgb direct;  // The part of `power` that is emission never shot before (track_direct).
  };
  // Where a ray's power went: a slot (element side), or a sink.
  static constexpr int32_t kEscaped = -1;
  static constexpr int32_t kAbsorbedBack = -2;  // Hit the back of a one-sided surface.
  struct RayResult {
    int32_t slot;
    int32_t group;
  };

  void TraceChunk(int64_t chunk, int64_t total_rays, RayResult* out) const;
  // Gives rays [first_ray, end of the step) back to their shooters' unshot power (a step cut
  // short).
  void ReturnUntraced(int64_t first_ray);
  // One step shooting with form-factor rows: the shooters within a factor 4 of the largest (at
  // most kRowsPerStep), each row estimated in parallel, deposited in order.
  absl::StatusOr<bool> StepWithRows(double w_max);
  static constexpr int kRowsPerStep = 64;
  // Adds power arriving at a slot (or a sink); `direct` is the part of it straight from an
  // emitter.
  void Deposit(int slot_hit, const Rgb& power, const Rgb& direct);

  std::unique_ptr<FormFactorEstimator> estimator_;  // Only for non-Monte Carlo shooting.

  // Per slot (Slot(element, side)).
  std::vector<Rgb> unshot_;
  std::vector<Rgb> exitant_;       // Emitted + reflected + transmitted power that left the side.
  std::vector<double> hits_;       // Rays arrived per slot (a float would stop at 2^24).
  std::vector<Rgb> patch_unshot_;  // Per patch side: 2 * patch + side.
  // track_direct only (else empty), per slot: the part of unshot_ that is emission never shot,
  // the power that arrived, and the part of that straight from an emitter. Every operation on
  // unshot_ is linear, so the emission's part follows it exactly (overshooting included).
  std::vector<Rgb> emitted_unshot_, incident_, direct_in_;

  double ray_power_ = 0;  // Scalar (channel sum) power one ray carries.
  std::vector<RayGroup> groups_;
  std::vector<RayResult> results_;
  bool done_ = false;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_PROGRESSIVE_H_
