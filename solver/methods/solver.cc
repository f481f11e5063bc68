#include "solver/methods/solver.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/methods/method_choice.h"
#include "solver/methods/registry.h"

namespace radiosity {

std::string Progress::ToString() const {
  return absl::StrFormat("Progress{step=%d shots=%d rays=%d unshot=%.3g%% seconds=%.2f}", step,
                         shots, rays, 100 * unshot_fraction, seconds);
}

std::string Solution::ToString() const {
  return absl::StrFormat(
      "Solution{method=%s seed=%d rays=%d seconds=%.3f unshot=%.3g emitted=%s absorbed=%s "
      "escaped=%s}",
      method, seed, rays, seconds, unshot_fraction, emitted_power.ToString(),
      absorbed_power.ToString(), escaped_power.ToString());
}

std::string StopReasonName(StopReason reason) {
  switch (reason) {
    case StopReason::kConverged:
      return "converged";
    case StopReason::kMaxRays:
      return "max_rays";
    case StopReason::kMaxSeconds:
      return "max_seconds";
    case StopReason::kCancelled:
      return "cancelled";
  }
  return "?";
}

SolverBase::SolverBase(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
                       const SolveOptions& options, const std::atomic<bool>* stop,
                       std::string method)
    : scene_(scene),
      mesh_(mesh),
      visibility_(visibility),
      options_(options),
      method_(std::move(method)),
      stop_(stop, options.max_seconds),
      arena_(std::make_unique<tbb::task_arena>(
          options.threads > 0 ? options.threads : static_cast<int>(tbb::task_arena::automatic))),
      start_(std::chrono::steady_clock::now()) {
  for (const Rgb& power : EmittedPerSlot()) emitted_ += power;
}

SolverBase::~SolverBase() = default;

std::vector<Rgb> SolverBase::EmittedPerSlot() const {
  const auto& elements = mesh_.elements();
  std::vector<Rgb> emitted(2 * elements.size());
  for (int s = 0; s < static_cast<int>(emitted.size()); ++s) {
    emitted[s] = sides()[s].exitance * elements[ElementOfSlot(s)].area;
  }
  return emitted;
}

double SolverBase::Elapsed() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void SolverBase::EndStep(bool interrupted) {
  interrupted_.reset();
  if (interrupted) {
    interrupted_ = stop_.Cancelled() ? StopReason::kCancelled : StopReason::kMaxSeconds;
  } else {
    progress_.step += 1;
  }
  progress_.seconds = Elapsed();
}

Solution SolverBase::NewSolution() const {
  Solution sol;
  sol.method = method_;
  sol.seed = options_.seed;
  sol.rays = progress_.rays;
  sol.shots = progress_.shots;
  sol.seconds = progress_.seconds;
  sol.unshot_fraction = progress_.unshot_fraction;
  sol.emitted_power = emitted_;
  sol.absorbed_power = absorbed_.Total();
  sol.escaped_power = escaped_.Total();
  return sol;
}

absl::StatusOr<std::unique_ptr<Solver>> CreateSolver(const Scene& scene, const Mesh& mesh,
                                                     const Visibility& visibility,
                                                     const SolveOptions& options,
                                                     const std::atomic<bool>* stop) {
  if (absl::Status s = Validate(options, FieldNaming::kFlag); !s.ok()) return s;
  bool has_emitter = false;
  for (int e = 0; e < static_cast<int>(mesh.elements().size()) && !has_emitter; ++e) {
    has_emitter = mesh.sides().at(e, kFront).Emits() || mesh.sides().at(e, kBack).Emits();
  }
  if (!has_emitter && !options.sky.enabled()) {
    return absl::FailedPreconditionError(absl::StrCat(scene.Where(0), kNoEmitterMessage));
  }
  SolveOptions resolved = options;
  resolved.method = ResolveMethod(mesh, options).method;
  const MethodInfo* method = FindMethod(resolved.method);
  if (method == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat("unknown method '", resolved.method, "'"));
  }
  return method->create(scene, mesh, visibility, resolved, stop);
}

absl::StatusOr<StopReason> RunSolver(Solver& solver, const SolveOptions& options,
                                     const std::atomic<bool>* stop,
                                     const std::function<void(const Progress&)>& on_progress) {
  const StopToken token(stop, options.max_seconds);
  for (;;) {
    if (token.Cancelled()) return StopReason::kCancelled;
    if (token.Expired()) return StopReason::kMaxSeconds;
    if (options.max_rays > 0 && solver.progress().rays >= options.max_rays) {
      return StopReason::kMaxRays;
    }
    absl::StatusOr<bool> more = solver.Step();
    if (!more.ok()) return more.status();
    if (on_progress) on_progress(solver.progress());
    // Cut short inside the step, by the solver's own flag or deadline.
    if (std::optional<StopReason> why = solver.Interrupted()) return *why;
    if (!*more) return StopReason::kConverged;
  }
}

}  // namespace radiosity
