#include "solver/methods/solver.h"

#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/methods/method_choice.h"
#include "solver/methods/registry.h"

namespace radiosity {

std::string Progress::ToString() const {
  return absl::StrFormat(
      "Progress{step=%d shots=%d rays=%d unshot=%.3g%% direct=%.3g%% seconds=%.2f}", step, shots,
      rays, 100 * unshot_fraction, 100 * direct_fraction, seconds);
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
    case StopReason::kStalled:
      return "stalled";
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

void SolverBase::AddAmbient(Solution* sol, const Rgb* power, const Rgb* sent_on,
                            const std::vector<float>* open) const {
  const auto& elements = mesh_.elements();
  if (open != nullptr && open->size() != 2 * elements.size()) open = nullptr;
  auto open_of = [&](int s) { return open != nullptr ? static_cast<double>((*open)[s]) : 1.0; };
  double area = 0;
  Rgb rho_area;
  for (int s = 0; s < static_cast<int>(2 * elements.size()); ++s) {
    const SideRule& rule = sides()[s];
    if (!rule.exists) continue;
    const double a = elements[ElementOfSlot(s)].area * open_of(s);
    area += a;
    rho_area += rule.reflectance * a;
  }
  if (!(area > 0) || sol->radiosity.size() != 2 * elements.size()) return;
  const Rgb& u = power != nullptr ? *power : sol->unshot_power;
  Rgb ambient;
  for (int c = 0; c < 3; ++c) {
    const double rho_mean = rho_area[c] / area;
    if (!(rho_mean > 0)) continue;
    const double rho = std::clamp(sent_on != nullptr ? (*sent_on)[c] : rho_mean, 0.0, 1 - 1e-6);
    // Negative unshot power (overshooting) is left to its own shots.
    ambient[c] = std::max(0.0, u[c]) * rho / (rho_mean * area * (1 - rho));
  }
  if (ambient.IsZero()) return;
  for (int s = 0; s < static_cast<int>(sol->radiosity.size()); ++s) {
    const SideRule& rule = sides()[s];
    if (rule.exists) sol->radiosity[s] += rule.reflectance * ambient * open_of(s);
  }
  sol->ambient = ambient;
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

void SolverBase::SaveBase(StateWriter* out) const {
  out->Put("base.method_size", method_.size());
  Rgb mesh_emitted;
  for (const Rgb& power : EmittedPerSlot()) mesh_emitted += power;
  out->Put("base.mesh_emitted", mesh_emitted);
  out->Put("base.progress.step", progress_.step);
  out->Put("base.progress.shots", progress_.shots);
  out->Put("base.progress.rays", progress_.rays);
  out->Put("base.progress.unshot_fraction", progress_.unshot_fraction);
  out->Put("base.progress.seconds", progress_.seconds);
  out->Put("base.emitted", emitted_);
  out->Put("base.absorbed", absorbed_);
  out->Put("base.escaped", escaped_);
}

absl::Status SolverBase::RestoreBase(StateReader* in) {
  size_t method_size = 0;
  Rgb mesh_emitted, emitted;
  Progress p;
  for (absl::Status st :
       {in->Get("base.method_size", &method_size), in->Get("base.mesh_emitted", &mesh_emitted),
        in->Get("base.progress.step", &p.step), in->Get("base.progress.shots", &p.shots),
        in->Get("base.progress.rays", &p.rays),
        in->Get("base.progress.unshot_fraction", &p.unshot_fraction),
        in->Get("base.progress.seconds", &p.seconds), in->Get("base.emitted", &emitted),
        in->Get("base.absorbed", &absorbed_), in->Get("base.escaped", &escaped_)}) {
    if (!st.ok()) return st;
  }
  // The power the mesh emits (before a sky's adds to the books): a state of another scene or
  // mesh shows here. emitted_ is still the mesh's (the solver has not stepped).
  if (method_size != method_.size() || mesh_emitted.r != emitted_.r ||
      mesh_emitted.g != emitted_.g || mesh_emitted.b != emitted_.b) {
    return absl::FailedPreconditionError(
        absl::StrCat("the state is of another method or mesh (it emitted ", mesh_emitted.ToString(),
                     ", this mesh emits ", emitted_.ToString(), ")"));
  }
  emitted_ = emitted;
  progress_ = p;
  start_ -= std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(p.seconds));
  return absl::OkStatus();
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
  if (!has_emitter && !options.sky.enabled() && options.luminaires.empty()) {
    return absl::FailedPreconditionError(absl::StrCat(scene.Where(0), kNoEmitterMessage));
  }
  for (const Luminaire& l : options.luminaires) {
    if (!l.photometry) {
      return absl::FailedPreconditionError(
          absl::StrCat("luminaire ", l.file, ": its photometric file was not loaded"));
    }
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
    if (!*more) return solver.Stalled() ? StopReason::kStalled : StopReason::kConverged;
  }
}

}  // namespace radiosity
