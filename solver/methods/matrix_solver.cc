#include "solver/methods/matrix_solver.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include "absl/strings/str_format.h"
#include "solver/methods/checkpoint.h"
#include "solver/transport/rng.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace radiosity {

namespace {

// Distinguishes the matrix rows' random streams from every other stream of a seed.
constexpr uint64_t kMatrixStream = 0x4d41545249582d46ULL;  // "MATRIX-F"
constexpr double kMiB = 1024.0 * 1024.0;
// Bytes a stored entry takes: a float value and a 32-bit slot index.
constexpr double kEntryBytes = sizeof(float) + sizeof(int32_t);

Rgb Abs(const Rgb& c) { return {std::fabs(c.r), std::fabs(c.g), std::fabs(c.b)}; }

}  // namespace

absl::StatusOr<std::unique_ptr<MatrixSolver>> MatrixSolver::Create(const Scene& scene,
                                                                   const Mesh& mesh,
                                                                   const Visibility& visibility,
                                                                   const SolveOptions& options,
                                                                   const std::atomic<bool>* stop) {
  Iteration iteration;
  if (options.method == "jacobi") {
    iteration = Iteration::kJacobi;
  } else if (options.method == "gauss-seidel") {
    iteration = Iteration::kGaussSeidel;
  } else {
    return absl::InvalidArgumentError(absl::StrFormat(
        "matrix solver: unknown method '%s' (jacobi or gauss-seidel)", options.method));
  }
  if (!(options.max_matrix_mb > 0) || !std::isfinite(options.max_matrix_mb)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("max matrix MiB must be > 0, got %g", options.max_matrix_mb));
  }
  absl::StatusOr<std::unique_ptr<FormFactorEstimator>> estimator =
      CreateFormFactorEstimator(mesh, visibility, options.formfactor);
  if (!estimator.ok()) return estimator.status();
  std::unique_ptr<MatrixSolver> solver(
      new MatrixSolver(scene, mesh, visibility, options, stop, iteration, *std::move(estimator)));
  // The check comes before any row is estimated or stored (the solver so far holds O(slots)).
  const double limit = options.max_matrix_mb * kMiB;
  if (solver->worst_case_bytes_ > limit) {
    const bool mc = options.formfactor.method == "montecarlo";
    return absl::ResourceExhaustedError(absl::StrFormat(
        "the %s form-factor matrix could need %.1f MiB, over the limit of --max-matrix-mb %g: "
        "%d rows (element sides that send light) of up to %.0f entries on average, %g bytes "
        "each, held twice while the rows are transposed; raise --max-matrix-mb, use fewer "
        "elements (--element-size, --max-elements)%s, or a method without a matrix (--method "
        "progressive or reflection)",
        options.formfactor.method, solver->worst_case_bytes_ / kMiB, options.max_matrix_mb,
        solver->sources_.size(), solver->per_row_bound_, kEntryBytes,
        mc ? ", fewer --rays-per-element" : ""));
  }
  return solver;
}

MatrixSolver::MatrixSolver(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
                           const SolveOptions& options, const std::atomic<bool>* stop,
                           Iteration iteration, std::unique_ptr<FormFactorEstimator> estimator)
    : SolverBase(scene, mesh, visibility, options, stop,
                 iteration == Iteration::kJacobi ? "jacobi" : "gauss-seidel"),
      iteration_(iteration),
      estimator_(std::move(estimator)) {
  const auto& elements = mesh.elements();
  const size_t n = elements.size();
  const int slots = static_cast<int>(2 * n);
  emitted_slot_ = EmittedPerSlot();
  // A slot sends power if it emits, reflects, or passes on what its other side receives; the
  // rest (black, non-emitting sides) always have P = 0 and need no row.
  for (int s = 0; s < slots; ++s) {
    if (sides()[s].Sends()) sources_.push_back(s);
  }
  power_ = emitted_slot_;
  incident_.assign(2 * n, Rgb());
  row_sum_.assign(sources_.size(), 0.0);
  receiver_count_.assign(2 * n + 1, 0);

  // Monte Carlo rows: rays_per_element rays each, and an emitter's row as many as the progressive
  // solver's first shot of it would take (rays_per_element x N x its share of the emitted power):
  // direct light comes from few rows, and would otherwise be the noisiest part of the answer.
  monte_carlo_ = options.formfactor.method == "montecarlo";
  const int64_t budget = std::max<int64_t>(1, std::llround(options.rays_per_element));
  double entries_bound = 0;  // Entries all rows may hold at most.
  row_budget_.assign(sources_.size(), 0);
  for (size_t r = 0; r < sources_.size(); ++r) {
    const double share = emitted_slot_[sources_[r]].Sum() / emitted_.Sum() * n;
    row_budget_[r] = budget * std::max<int64_t>(1, std::llround(share));
    // A row holds at most an entry for every slot, a Monte Carlo row one per ray, and a hemicube
    // row one per cell (3 res^2 cells, top res^2 and four sides res x res/2, per hemicube) and
    // as many near-field entries at most.
    double row_bound = 2.0 * n;
    if (monte_carlo_) row_bound = std::min<double>(static_cast<double>(row_budget_[r]), row_bound);
    if (options.formfactor.method == "hemicube") {
      const double res = options.formfactor.hemicube_resolution;
      row_bound = std::min(row_bound,
                           2 * 3.0 * res * res * std::max(1, options.formfactor.hemicube_points));
    }
    entries_bound += row_bound;
  }
  per_row_bound_ = sources_.empty() ? 0 : entries_bound / sources_.size();
  // Rows are held twice while being transposed.
  worst_case_bytes_ =
      2 * entries_bound * kEntryBytes + (2.0 * n + 1 + sources_.size()) * sizeof(int64_t);

  // Nothing has been propagated yet: all the emitted power is unaccounted for.
  unshot_ = emitted_;
  residual_ = emitted_.Sum();
  progress_.unshot_fraction = 1;
}

MatrixSolver::~MatrixSolver() = default;

absl::StatusOr<bool> MatrixSolver::AssembleBatch() {
  // A batch of at least 16 rows and about kRaysPerStep rays.
  const size_t first = next_source_;
  size_t count = 0;
  if (monte_carlo_) {
    int64_t rays = 0;
    while (first + count < sources_.size() && (count < 16 || rays < kRaysPerStep)) {
      rays += row_budget_[first + count++];
    }
  } else {
    count = std::min(static_cast<size_t>(rows_per_batch_), sources_.size() - first);
  }
  std::vector<FormFactorRow> rows(count);
  // Each row from one element side, with its own stream keyed by (seed, slot): the matrix does
  // not depend on how rows are spread over threads.
  arena().execute([&] {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count, 1),
                      [&](const tbb::blocked_range<size_t>& range) {
                        for (size_t i = range.begin(); i < range.end() && !ShouldStop(); ++i) {
                          const int slot = sources_[first + i];
                          FormFactorSource source;
                          source.first_element = ElementOfSlot(slot);
                          source.num_elements = 1;
                          source.side = SideOfSlot(slot);
                          estimator_->Estimate(
                              source, row_budget_[first + i],
                              StreamKey(options_.seed, kMatrixStream, static_cast<uint64_t>(slot)),
                              stop_token(), &rows[i]);
                        }
                      });
  });
  if (absl::Status s = visibility_.status(); !s.ok()) return s;
  if (ShouldStop()) return false;  // Some rows may be incomplete: the batch is dropped.

  // Keep the rows in order, as stored (float), each row's sum from the stored values so that the
  // energy books balance exactly.
  RowBatch batch;
  batch.first_source = first;
  size_t entries = 0;
  for (const FormFactorRow& row : rows) entries += row.slots.size();
  batch.start.reserve(count + 1);
  batch.slot.reserve(entries);
  batch.f.reserve(entries);
  batch.start.push_back(0);
  int64_t rays = 0;
  for (size_t i = 0; i < count; ++i) {
    const FormFactorRow& row = rows[i];
    double sum = 0;
    for (size_t k = 0; k < row.slots.size(); ++k) {
      const float f = static_cast<float>(row.f[k]);
      if (!(f > 0)) continue;
      batch.slot.push_back(static_cast<int32_t>(row.slots[k]));
      batch.f.push_back(f);
      ++receiver_count_[row.slots[k] + 1];
      sum += f;
    }
    row_sum_[first + i] = sum;
    batch.start.push_back(static_cast<int64_t>(batch.f.size()));
    rays += row.rays;
  }
  stored_entries_ += static_cast<int64_t>(batch.f.size());
  batches_.push_back(std::move(batch));
  next_source_ += count;
  progress_.rays += rays;

  // The measured size, in case an estimator returns more entries than the worst case assumed.
  const double bytes = 2 * static_cast<double>(stored_entries_) * kEntryBytes;
  if (bytes > options_.max_matrix_mb * kMiB) {
    return absl::ResourceExhaustedError(absl::StrFormat(
        "the form-factor matrix grew past --max-matrix-mb %g (%.1f MiB after %d of %d rows); "
        "raise --max-matrix-mb or use fewer elements",
        options_.max_matrix_mb, bytes / kMiB, next_source_, sources_.size()));
  }
  // Batches of about kRaysPerStep rays, from the rays rows have taken so far.
  const double rays_per_row =
      static_cast<double>(progress_.rays) / static_cast<double>(next_source_);
  rows_per_batch_ = std::clamp<int64_t>(
      static_cast<int64_t>(kRaysPerStep / std::max(1.0, rays_per_row)), 16, 1 << 16);
  return true;
}

bool MatrixSolver::Transpose() {
  if (transposed_) return true;
  if (transpose_cursor_.empty()) {
    // The receivers' rows, from the entries counted as the batches were stored.
    matrix_.row_start = std::move(receiver_count_);
    for (size_t k = 0; k + 1 < matrix_.row_start.size(); ++k) {
      matrix_.row_start[k + 1] += matrix_.row_start[k];
    }
    matrix_.source.resize(static_cast<size_t>(stored_entries_));
    matrix_.f.resize(static_cast<size_t>(stored_entries_));
    transpose_cursor_.assign(matrix_.row_start.begin(), matrix_.row_start.end() - 1);
  }
  // Sources in increasing order, so every receiver row is sorted by source. Each batch is freed
  // once moved; an interrupted transposition goes on from the next batch.
  for (; next_transpose_batch_ < batches_.size(); ++next_transpose_batch_) {
    if (ShouldStop()) return false;
    RowBatch& batch = batches_[next_transpose_batch_];
    const size_t rows = batch.start.size() - 1;
    for (size_t r = 0; r < rows; ++r) {
      const int32_t source = sources_[batch.first_source + r];
      for (int64_t i = batch.start[r]; i < batch.start[r + 1]; ++i) {
        const int64_t at = transpose_cursor_[batch.slot[i]]++;
        matrix_.source[at] = source;
        matrix_.f[at] = batch.f[i];
      }
    }
    batch = RowBatch();
  }
  std::vector<RowBatch>().swap(batches_);
  std::vector<int64_t>().swap(transpose_cursor_);
  transposed_ = true;
  return true;
}

Rgb MatrixSolver::GatherRow(int k) const {
  Rgb h;
  for (int64_t i = matrix_.row_start[k]; i < matrix_.row_start[k + 1]; ++i) {
    h += power_[matrix_.source[i]] * static_cast<double>(matrix_.f[i]);
  }
  return h;
}

bool MatrixSolver::Gather() {
  const int slots = static_cast<int>(incident_.size());
  arena().execute([&] {
    tbb::parallel_for(tbb::blocked_range<int>(0, slots, 256),
                      [&](const tbb::blocked_range<int>& range) {
                        if (ShouldStop()) return;
                        for (int k = range.begin(); k < range.end(); ++k) {
                          incident_[k] = GatherRow(k);
                        }
                      });
  });
  return !ShouldStop();
}

Rgb MatrixSolver::Target(int s, const Rgb& h_same, const Rgb& h_other) const {
  // P_s = Phi_s + R_s H_s + T_s' H_s' (eq. 6.2 in power terms; transmission as in the
  // progressive solver's Deposit: power arriving at the other side passes T to this one).
  return emitted_slot_[s] + sides()[s].reflectance * h_same +
         sides()[OtherSide(s)].transmittance * h_other;
}

void MatrixSolver::UpdateBooks() {
  Rgb absorbed, unshot, escaped;
  double residual = 0;
  const Rgb one = Rgb::Gray(1);
  for (int s = 0; s < static_cast<int>(incident_.size()); ++s) {
    const Rgb& h = incident_[s];
    const SideRule& rule = sides()[s];
    // Arriving power neither reflected nor transmitted is absorbed (all of it on the back of a
    // one-sided surface, where R = T = 0).
    absorbed += (one - rule.reflectance - rule.transmittance) * h;
    if (!rule.exists) continue;
    const Rgb u = Target(s, h, incident_[OtherSide(s)]) - power_[s];
    unshot += u;
    residual += Abs(u).Sum();
  }
  for (size_t r = 0; r < sources_.size(); ++r) {
    escaped += power_[sources_[r]] * (1 - row_sum_[r]);
  }
  absorbed_ = CompensatedRgb();
  absorbed_ += absorbed;
  escaped_ = CompensatedRgb();
  escaped_ += escaped;
  unshot_ = unshot;
  residual_ = residual;
  progress_.unshot_fraction = residual_ / emitted_.Sum();
}

bool MatrixSolver::Sweep() {
  const int slots = static_cast<int>(power_.size());
  // Kept to undo a sweep cut short: the books then stay those of the previous iterate.
  saved_power_ = power_;
  saved_incident_ = incident_;
  auto undo = [&] {
    power_.swap(saved_power_);
    incident_.swap(saved_incident_);
    return false;
  };
  constexpr int kStopCheck = 4096;  // Slots between checks of the stop flag and the deadline.
  if (iteration_ == Iteration::kJacobi) {
    // Every slot from the previous iterate: the incident power was gathered from it.
    for (int s = 0; s < slots; ++s) {
      if (s % kStopCheck == 0 && ShouldStop()) return undo();
      if (sides().exists(s)) power_[s] = Target(s, incident_[s], incident_[OtherSide(s)]);
    }
  } else {
    // Gauss-Seidel: in place, both sides of an element at once, in element order.
    for (int s = 0; s < slots; s += 2) {
      if (s % kStopCheck == 0 && ShouldStop()) return undo();
      const bool back = sides().exists(s + 1);
      const Rgb h0 = GatherRow(s);
      const Rgb h1 = back ? GatherRow(s + 1) : Rgb();
      power_[s] = Target(s, h0, h1);
      if (back) power_[s + 1] = Target(s + 1, h1, h0);
    }
  }
  // The residual of the new iterate (and its incident power, for the next sweep and the books).
  if (!Gather()) return undo();
  UpdateBooks();
  return true;
}

absl::StatusOr<bool> MatrixSolver::Step() {
  if (done_) return false;
  bool interrupted = false;
  if (!assembled_) {
    if (next_source_ < sources_.size()) {
      absl::StatusOr<bool> complete = AssembleBatch();
      if (!complete.ok()) return complete.status();
      interrupted = !*complete;
    }
    // Once the last batch is in: transpose, then the incident power and the books of P = Phi.
    if (!interrupted && next_source_ == sources_.size()) {
      interrupted = !Transpose() || !Gather();
      if (!interrupted) {
        assembled_ = true;
        UpdateBooks();
      }
    }
  } else {
    interrupted = !Sweep();
    if (!interrupted) progress_.shots += 1;
  }
  EndStep(interrupted);
  if (assembled_ && progress_.unshot_fraction <= options_.tolerance) done_ = true;
  return !done_;
}

bool MatrixSolver::SaveState(StateWriter* out) const {
  SaveBase(out);
  out->Put("matrix.flags", std::array<bool, 3>{monte_carlo_, assembled_, done_});
  out->Put("matrix.next_source", static_cast<uint64_t>(next_source_));
  out->Put("matrix.rows_per_batch", rows_per_batch_);
  out->Put("matrix.stored_entries", stored_entries_);
  out->PutVector("matrix.row_sum", row_sum_);
  if (!assembled_) {
    // The batches' rows as they are (a step that transposes also assembles: a state is never
    // saved half transposed).
    out->Reserve(static_cast<size_t>(stored_entries_) * static_cast<size_t>(kEntryBytes) +
                 (batches_.size() + next_source_) * sizeof(int64_t) + (1 << 16));
    out->Put("matrix.batches", static_cast<uint64_t>(batches_.size()));
    for (const RowBatch& batch : batches_) {
      out->Put("matrix.batch.first", static_cast<uint64_t>(batch.first_source));
      out->PutVector("matrix.batch.start", batch.start);
      out->PutVector("matrix.batch.slot", batch.slot);
      out->PutVector("matrix.batch.f", batch.f);
    }
    return true;
  }
  out->Reserve(matrix_.f.size() * static_cast<size_t>(kEntryBytes) +
               matrix_.row_start.size() * sizeof(int64_t) + 2 * power_.size() * sizeof(Rgb) +
               (1 << 16));
  out->PutVector("matrix.row_start", matrix_.row_start);
  out->PutVector("matrix.source", matrix_.source);
  out->PutVector("matrix.f", matrix_.f);
  out->PutVector("matrix.power", power_);
  out->PutVector("matrix.incident", incident_);
  out->Put("matrix.unshot", unshot_);
  out->Put("matrix.residual", residual_);
  return true;
}

absl::Status MatrixSolver::RestoreState(StateReader* in) {
  if (absl::Status st = RestoreBase(in); !st.ok()) return st;
  std::array<bool, 3> flags{};
  uint64_t next_source = 0;
  for (absl::Status st :
       {in->Get("matrix.flags", &flags), in->Get("matrix.next_source", &next_source),
        in->Get("matrix.rows_per_batch", &rows_per_batch_),
        in->Get("matrix.stored_entries", &stored_entries_),
        in->GetVector("matrix.row_sum", &row_sum_)}) {
    if (!st.ok()) return st;
  }
  if (flags[0] != monte_carlo_) {
    return absl::FailedPreconditionError("the state is of another form-factor estimator");
  }
  assembled_ = flags[1];
  done_ = flags[2];
  const size_t slots = power_.size();
  const auto bad = [](absl::string_view what) {
    return absl::DataLossError(absl::StrCat("the matrix state is inconsistent: ", what));
  };
  if (next_source > sources_.size() || stored_entries_ < 0 ||
      (assembled_ && next_source != sources_.size())) {
    return bad("rows assembled");
  }
  next_source_ = static_cast<size_t>(next_source);
  // Every index is checked before it is used: the iteration indexes without checks.
  const auto slots_in_range = [&](const std::vector<int32_t>& v) {
    return std::all_of(v.begin(), v.end(),
                       [&](int32_t s) { return s >= 0 && static_cast<size_t>(s) < slots; });
  };
  if (!assembled_) {
    uint64_t count = 0;
    if (absl::Status st = in->Get("matrix.batches", &count); !st.ok()) return st;
    if (count > next_source_) return bad("batches");
    batches_.clear();
    size_t source = 0;
    int64_t entries = 0;
    for (uint64_t b = 0; b < count; ++b) {
      RowBatch batch;
      uint64_t first = 0;
      for (absl::Status st : {in->Get("matrix.batch.first", &first),
                              in->GetAnyVector("matrix.batch.start", &batch.start),
                              in->GetAnyVector("matrix.batch.slot", &batch.slot),
                              in->GetAnyVector("matrix.batch.f", &batch.f)}) {
        if (!st.ok()) return st;
      }
      batch.first_source = static_cast<size_t>(first);
      if (first != source || batch.start.empty() || batch.start.front() != 0 ||
          !std::is_sorted(batch.start.begin(), batch.start.end()) ||
          batch.start.back() != static_cast<int64_t>(batch.f.size()) ||
          batch.slot.size() != batch.f.size() || !slots_in_range(batch.slot)) {
        return bad("batch rows");
      }
      source += batch.start.size() - 1;
      entries += static_cast<int64_t>(batch.f.size());
      for (int32_t slot : batch.slot) ++receiver_count_[slot + 1];
      batches_.push_back(std::move(batch));
    }
    if (source != next_source_ || entries != stored_entries_) return bad("batch totals");
  } else {
    matrix_.row_start.resize(slots + 1);
    for (absl::Status st :
         {in->GetVector("matrix.row_start", &matrix_.row_start),
          in->GetAnyVector("matrix.source", &matrix_.source),
          in->GetAnyVector("matrix.f", &matrix_.f), in->GetVector("matrix.power", &power_),
          in->GetVector("matrix.incident", &incident_), in->Get("matrix.unshot", &unshot_),
          in->Get("matrix.residual", &residual_)}) {
      if (!st.ok()) return st;
    }
    if (matrix_.row_start.front() != 0 ||
        !std::is_sorted(matrix_.row_start.begin(), matrix_.row_start.end()) ||
        matrix_.row_start.back() != static_cast<int64_t>(matrix_.f.size()) ||
        matrix_.source.size() != matrix_.f.size() || !slots_in_range(matrix_.source)) {
      return bad("matrix rows");
    }
    std::vector<int64_t>().swap(receiver_count_);
    transposed_ = true;
  }
  return in->Finish();
}

Solution MatrixSolver::Snapshot() const {
  Solution sol = NewSolution();
  const auto& elements = mesh_.elements();
  sol.radiosity.assign(power_.size(), Rgb());
  for (int s = 0; s < static_cast<int>(power_.size()); ++s) {
    if (sides().exists(s)) sol.radiosity[s] = power_[s] / elements[ElementOfSlot(s)].area;
  }
  sol.unshot_power = unshot_;
  // Before convergence (and while the matrix is assembled, when nothing has moved yet) the
  // residual's light is estimated.
  if (!done_) AddAmbient(&sol);
  return sol;
}

}  // namespace radiosity
