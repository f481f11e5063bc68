// Matrix radiosity: Jacobi and Gauss-Seidel iteration on the full element-level system (Shirley's
// thesis, eq. 6.2 / 6.3), the form-factor matrix assembled once with any estimator
// (`--formfactor`).
//
// The unknowns are the element sides ("slots", Slot(element, side)). In power terms, with P_i the
// power leaving slot i (P_i = A_i B_i), Phi_i its emitted power and H_k the power arriving at slot
// k:
//
//   H_k = sum_j F_jk P_j                                     (F_jk: from j, arriving at k)
//   P_i = Phi_i + R_i H_i + T_i' H_i'                        (i' = the other side of i's element)
//
// which is eq. 6.2, B_i = E_i + R_i sum_j F_ij B_j, with F_ij written through reciprocity
// (A_i F_ij = A_j F_ji) and with diffuse transmission added as the progressive solver does it
// (power arriving at one side passes T to the other side). Writing the system with the rows as
// they are estimated (from each source j) keeps power exactly conserved by the estimated matrix,
// like the progressive solver's shooting, so both converge to the same answer.
//
// Assembly estimates one row per slot that can send power (emitting, reflecting or receiving
// transmitted power), from that element side alone, in parallel, each row with its own random
// stream keyed by (seed, slot): the matrix depends only on the seed. A Monte Carlo row takes
// rays_per_element rays, and an emitter's row as many as the progressive solver's first shot of
// it would (rays_per_element x N x its share of the emitted power): the direct light comes from
// those few rows, and with equal budgets it would dominate the error. Rows are stored sparse (float
// values, 32-bit source indices) and transposed once to receiver order, so that both iterations
// gather. Before anything is allocated the matrix's worst-case size is checked against
// SolveOptions::max_matrix_mb.
//
// Stopping is on the residual, not on the change between sweeps: u = Phi + R H + T H' - P, the
// power that has arrived but is not yet accounted for in P. Starting from P = Phi both iterations
// increase P monotonically (the matrix is non-negative), so u >= 0 and u is exactly the "unshot"
// power of the energy books: emitted = absorbed + escaped + unshot to rounding, at every sweep.
#ifndef RADIOSITY_SOLVER_METHODS_MATRIX_SOLVER_H_
#define RADIOSITY_SOLVER_METHODS_MATRIX_SOLVER_H_

#include <atomic>
#include <cstdint>
#include <memory>
#include <vector>

#include "solver/methods/solver.h"
#include "solver/transport/formfactor.h"

namespace radiosity {

class MatrixSolver : public SolverBase {
 public:
  enum class Iteration { kJacobi, kGaussSeidel };

  // Creates the solver for options.method "jacobi" or "gauss-seidel" with the estimator of
  // options.formfactor. Fails with RESOURCE_EXHAUSTED (naming --max-matrix-mb) when the matrix
  // could exceed options.max_matrix_mb, INVALID_ARGUMENT for a bad method or estimator options.
  // Nothing large is allocated before the check.
  static absl::StatusOr<std::unique_ptr<MatrixSolver>> Create(const Scene& scene, const Mesh& mesh,
                                                              const Visibility& visibility,
                                                              const SolveOptions& options,
                                                              const std::atomic<bool>* stop);
  ~MatrixSolver() override;

  // While assembling, a step estimates a batch of rows (about kRaysPerStep rays); then a step is
  // one sweep (Jacobi: every slot from the previous iterate; Gauss-Seidel: in place, element by
  // element in index order) followed by the residual.
  // The stop flag and the deadline are checked between rows, between slots of a sweep and while
  // transposing; a step cut short leaves the iterate (and the books) as they were.
  absl::StatusOr<bool> Step() override;
  Solution Snapshot() const override;
  // The state holds the rows estimated so far while assembling, then the matrix and the iterate:
  // a checkpoint is about as large as the matrix (docs/service/server.md).
  bool SaveState(StateWriter* out) const override;
  absl::Status RestoreState(StateReader* in) override;

  // Largest number of bytes the matrix may take while it is assembled (the rows are held twice
  // while they are transposed): sources x (entries a row at most) x 8 bytes x 2.
  double WorstCaseBytes() const { return worst_case_bytes_; }
  bool assembled() const { return assembled_; }

  // The assembled matrix, in receiver order: for receiving slot k, the entries
  // [row_start[k], row_start[k + 1]) give source slots and F_{source -> k}. Empty until
  // assembled().
  struct Matrix {
    std::vector<int64_t> row_start;
    std::vector<int32_t> source;
    std::vector<float> f;
    int64_t nonzeros() const { return static_cast<int64_t>(f.size()); }
  };
  const Matrix& matrix() const { return matrix_; }

  // Rays per assembly step, roughly (a step is the unit of progress and cancellation).
  static constexpr int64_t kRaysPerStep = 1 << 18;

 private:
  MatrixSolver(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
               const SolveOptions& options, const std::atomic<bool>* stop, Iteration iteration,
               std::unique_ptr<FormFactorEstimator> estimator);

  // Estimates and stores the next batch of rows; false when cut short (nothing stored).
  absl::StatusOr<bool> AssembleBatch();
  // Moves the stored rows to receiver order; false when cut short (a later call goes on).
  bool Transpose();
  // H = F^T P for every receiving slot (parallel over receivers, deterministic); false when cut
  // short (incident_ is then partly updated).
  bool Gather();
  // One Jacobi or Gauss-Seidel sweep, its Gather and books; false (and undone) when cut short.
  bool Sweep();
  // Incident power at slot k from the current power_ (one row of F^T P).
  Rgb GatherRow(int k) const;
  // Target power of slot s given the incident power at both sides of its element.
  Rgb Target(int s, const Rgb& h_same, const Rgb& h_other) const;
  // From power_ and incident_: residual, unshot, absorbed and escaped power, progress.
  void UpdateBooks();

  Iteration iteration_;
  std::unique_ptr<FormFactorEstimator> estimator_;

  // Per slot (Slot(element, side)).
  std::vector<Rgb> emitted_slot_;  // Phi.
  std::vector<Rgb> power_;         // P: power leaving the side (current iterate).
  std::vector<Rgb> incident_;      // H = F^T P.
  std::vector<double> row_sum_;    // sum_k F_jk of each source row (as stored, in float).
  std::vector<Rgb> saved_power_, saved_incident_;  // The iterate before the current sweep.

  // Source slots in increasing order, and assembly state.
  std::vector<int> sources_;
  size_t next_source_ = 0;
  bool monte_carlo_ = false;
  std::vector<int64_t> row_budget_;  // Rays per source row (montecarlo).
  int64_t rows_per_batch_ = 16;      // Other estimators: adapted to the measured rays per row.
  // Rows by source while assembling, one batch of consecutive sources_ at a time, each stored
  // with exact sizes (CSR within the batch) and freed as it is transposed.
  struct RowBatch {
    size_t first_source = 0;
    std::vector<int64_t> start;
    std::vector<int32_t> slot;
    std::vector<float> f;
  };
  std::vector<RowBatch> batches_;
  int64_t stored_entries_ = 0;
  std::vector<int64_t> receiver_count_;  // Entries stored per receiving slot (at k + 1).
  std::vector<int64_t> transpose_cursor_;
  size_t next_transpose_batch_ = 0;
  bool transposed_ = false;
  double per_row_bound_ = 0;  // Entries a row may hold at most.
  Matrix matrix_;
  bool assembled_ = false;
  double worst_case_bytes_ = 0;

  Rgb unshot_;
  double residual_ = 0;  // sum over slots and channels of |u|.
  bool done_ = false;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_MATRIX_SOLVER_H_
