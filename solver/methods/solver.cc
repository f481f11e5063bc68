#include "solver/methods/solver.h"

#include <algorithm>
#include <chrono>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/methods/hierarchical.h"
#include "solver/methods/matrix_solver.h"
#include "solver/methods/progressive.h"
#include "solver/methods/reflection.h"

namespace radiosity {

std::string SolveOptions::ToString() const {
  return absl::StrFormat(
      "SolveOptions{method=%s tolerance=%g max_rays=%d max_seconds=%g seed=%d threads=%d "
      "rays_per_element=%g weighted_shooting=%d}",
      method, tolerance, max_rays, max_seconds, seed, threads, rays_per_element, weighted_shooting);
}

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

std::string MethodChoice::ToString() const {
  return absl::StrFormat("MethodChoice{method=%s reason=\"%s\"}", method, reason);
}

double MeanAlbedo(const Scene& scene, const Mesh& mesh) {
  double area = 0;
  Rgb sum;
  for (const Element& e : mesh.elements()) {
    const Material& m = scene.materials[scene.surfaces[e.surface].material];
    // The front side, and the back where it exists (two-sided or transmitting).
    const int sides = m.HasBackSide() ? 2 : 1;
    for (int side = 0; side < sides; ++side) {
      const Rgb reflect = side == 0 || m.two_sided ? m.reflectance : Rgb();
      sum += (reflect + m.transmittance) * e.area;
      area += e.area;
    }
  }
  if (!(area > 0)) return 0;
  return std::max({sum.r, sum.g, sum.b}) / area;
}

MethodChoice ChooseMethod(const Scene& scene, const Mesh& mesh) {
  MethodChoice c;
  c.mean_albedo = MeanAlbedo(scene, mesh);
  const int64_t faces = static_cast<int64_t>(mesh.faces().size());
  if (c.mean_albedo >= kAutoMinAlbedo && faces <= kAutoMaxFaces) {
    c.method = "hierarchical";
    c.reason = absl::StrFormat("mean albedo %.3g >= %g and %d faces <= %d", c.mean_albedo,
                               kAutoMinAlbedo, faces, kAutoMaxFaces);
  } else {
    c.method = "progressive";
    c.reason = c.mean_albedo < kAutoMinAlbedo
                   ? absl::StrFormat("mean albedo %.3g < %g", c.mean_albedo, kAutoMinAlbedo)
                   : absl::StrFormat("%d faces > %d (hierarchical links start from every pair)",
                                     faces, kAutoMaxFaces);
  }
  return c;
}

absl::StatusOr<std::unique_ptr<Solver>> CreateSolver(const Scene& scene, const Mesh& mesh,
                                                     const Visibility& visibility,
                                                     const SolveOptions& options,
                                                     const std::atomic<bool>* stop) {
  if (!(options.tolerance > 0 && options.tolerance < 1)) {
    return absl::InvalidArgumentError(
        absl::StrCat("tolerance must be in (0, 1), got ", options.tolerance));
  }
  if (options.max_rays < 0) {
    return absl::InvalidArgumentError(
        absl::StrCat("max rays must be >= 0, got ", options.max_rays));
  }
  if (!(options.max_seconds >= 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("max seconds must be >= 0, got ", options.max_seconds));
  }
  if (options.threads < 0) {
    return absl::InvalidArgumentError(absl::StrCat("threads must be >= 0, got ", options.threads));
  }
  if (!(options.rays_per_element > 0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("rays per element must be > 0, got ", options.rays_per_element));
  }
  bool has_emitter = false;
  for (const Element& e : mesh.elements()) {
    has_emitter |= scene.materials[scene.surfaces[e.surface].material].IsEmitter();
  }
  if (!has_emitter) {
    return absl::FailedPreconditionError(absl::StrCat(
        scene.Where(0),
        "the scene has no emitter (no material with emission Ke > 0): there is no light to "
        "solve for (view factors need no emitter)"));
  }
  if (options.method == "auto") {
    SolveOptions chosen = options;
    chosen.method = ChooseMethod(scene, mesh).method;
    return CreateSolver(scene, mesh, visibility, chosen, stop);
  }
  if (options.method == "progressive") {
    auto solver = std::make_unique<ProgressiveSolver>(scene, mesh, visibility, options, stop);
    if (absl::Status s = solver->Init(); !s.ok()) return s;
    return std::unique_ptr<Solver>(std::move(solver));
  }
  if (options.method == "jacobi" || options.method == "gauss-seidel") {
    absl::StatusOr<std::unique_ptr<MatrixSolver>> solver =
        MatrixSolver::Create(scene, mesh, visibility, options, stop);
    if (!solver.ok()) return solver.status();
    return std::unique_ptr<Solver>(*std::move(solver));
  }
  if (options.method == "reflection") {
    return std::unique_ptr<Solver>(
        std::make_unique<ReflectionSolver>(scene, mesh, visibility, options, stop));
  }
  if (options.method == "hierarchical") {
    absl::StatusOr<std::unique_ptr<HierarchicalSolver>> solver =
        HierarchicalSolver::Create(scene, mesh, visibility, options, stop);
    if (!solver.ok()) return solver.status();
    return std::unique_ptr<Solver>(*std::move(solver));
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "unknown method '", options.method,
      "' (available: progressive, jacobi, gauss-seidel, reflection, hierarchical, auto)"));
}

absl::StatusOr<StopReason> RunSolver(Solver& solver, const SolveOptions& options,
                                     const std::atomic<bool>* stop,
                                     const std::function<void(const Progress&)>& on_progress) {
  auto start = std::chrono::steady_clock::now();
  for (;;) {
    if (stop != nullptr && stop->load(std::memory_order_relaxed)) return StopReason::kCancelled;
    double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (options.max_seconds > 0 && elapsed >= options.max_seconds) return StopReason::kMaxSeconds;
    if (options.max_rays > 0 && solver.progress().rays >= options.max_rays) {
      return StopReason::kMaxRays;
    }
    absl::StatusOr<bool> more = solver.Step();
    if (!more.ok()) return more.status();
    if (on_progress) on_progress(solver.progress());
    if (!*more) return StopReason::kConverged;
  }
}

}  // namespace radiosity
