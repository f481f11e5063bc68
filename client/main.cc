// The radiosity command-line tool (README "CLI").
//
//   radiosity solve SCENE --out DIR [options]   solve a scene and write results to DIR
//
// Exit codes are in solver/exit_codes.h.
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "CLI/CLI.hpp"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "proto/scene_codec.h"
#include "solver/exit_codes.h"
#include "solver/job.h"
#include "solver/sensors.h"
#include "solver/mesh.h"
#include "solver/output.h"
#include "solver/scene.h"
#include "solver/solver.h"
#include "solver/visibility.h"

namespace radiosity {
namespace {

std::atomic<bool> g_stop{false};

void OnSignal(int) { g_stop.store(true); }

int Fail(int code, const absl::Status& status) {
  std::fprintf(stderr, "radiosity: error: %s\n", std::string(status.message()).c_str());
  return code;
}

// Exit code for a failed status from loading or validating input.
int InputExit(const absl::Status& status) {
  switch (status.code()) {
    case absl::StatusCode::kInvalidArgument:
    case absl::StatusCode::kNotFound:
    case absl::StatusCode::kFailedPrecondition:
    case absl::StatusCode::kPermissionDenied:
      return kExitInput;
    default:
      return kExitInternal;
  }
}

// Prints progress on stderr: one updating line on a terminal, a plain line a second otherwise.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(double tolerance, bool quiet)
      : tty_(isatty(STDERR_FILENO)), tolerance_(tolerance), quiet_(quiet) {}

  void Update(const Progress& p, bool final = false) {
    if (quiet_) return;
    if (!final && !tty_ && p.seconds - last_ < 1.0) return;
    if (!final && tty_ && p.seconds - last_ < 0.1) return;
    last_ = p.seconds;
    // Fraction done on a log scale: unshot falls from 1 to the tolerance.
    double done = std::clamp(std::log(std::max(p.unshot_fraction, 1e-300)) / std::log(tolerance_),
                             0.0, 1.0);
    int filled = static_cast<int>(done * 20 + 0.5);
    std::string bar = std::string(filled, '#') + std::string(20 - filled, '.');
    double rate = p.seconds > 0 ? p.rays / p.seconds : 0;
    std::string line = absl::StrFormat(
        "solve [%s] %3.0f%%  unshot %.3g%% (target %.3g%%)  rays %s  %.1f s  %.1f Mrays/s", bar,
        100 * done, 100 * p.unshot_fraction, 100 * tolerance_, HumanCount(p.rays), p.seconds,
        rate / 1e6);
    if (tty_) {
      std::fprintf(stderr, "\r%s\033[K%s", line.c_str(), final ? "\n" : "");
    } else {
      std::fprintf(stderr, "%s\n", line.c_str());
    }
    std::fflush(stderr);
  }

 private:
  static std::string HumanCount(int64_t n) {
    if (n >= 1'000'000'000) return absl::StrFormat("%.2fG", n / 1e9);
    if (n >= 1'000'000) return absl::StrFormat("%.2fM", n / 1e6);
    if (n >= 1'000) return absl::StrFormat("%.1fk", n / 1e3);
    return absl::StrCat(n);
  }
  bool tty_;
  double tolerance_;
  bool quiet_;
  double last_ = -1e9;
};

struct SolveArgs {
  std::string scene;
  std::string out;
  JobSpec spec;
  std::string sensors;
  bool quiet = false;
};

int RunSolve(SolveArgs& args) {
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadSceneFile(args.scene, &warnings);
  for (const auto& w : warnings) std::fprintf(stderr, "radiosity: warning: %s\n", w.c_str());
  if (!scene.ok()) return Fail(InputExit(scene.status()), scene.status());
  if (!args.sensors.empty()) {
    auto sensors = LoadSensors(args.sensors);
    if (!sensors.ok()) return Fail(InputExit(sensors.status()), sensors.status());
    args.spec.sensors = *std::move(sensors);
  }
  if (!args.spec.camera.empty()) {
    if (auto cam = ParseCamera(args.spec.camera, Camera()); !cam.ok()) {
      return Fail(kExitUsage, cam.status());
    }
  }

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  ProgressPrinter printer(args.spec.solve.tolerance, args.quiet);
  JobObserver observer;
  observer.on_mesh = [&](const Mesh& mesh) {
    if (args.quiet) return;
    std::fprintf(stderr,
                 "radiosity: %s: %zu surfaces, %zu faces, %zu patches, %zu elements "
                 "(element size %.4g), method %s\n",
                 args.scene.c_str(), scene->surfaces.size(), mesh.faces().size(),
                 mesh.patches().size(), mesh.elements().size(), mesh.element_size(),
                 args.spec.solve.method.c_str());
  };
  Progress last;
  observer.on_progress = [&](const Progress& p) {
    last = p;
    printer.Update(p);
  };
  absl::StatusOr<JobResult> result = RunJob(*scene, args.spec, args.out, &g_stop, observer);
  printer.Update(last, /*final=*/true);
  if (!result.ok()) {
    const absl::Status& st = result.status();
    switch (st.code()) {
      case absl::StatusCode::kFailedPrecondition:
        return Fail(kExitInput, st);
      case absl::StatusCode::kInvalidArgument:
      case absl::StatusCode::kResourceExhausted:
        return Fail(kExitUsage, st);
      default:
        return Fail(kExitInternal, st);
    }
  }
  if (!args.quiet) {
    std::string files;
    for (const auto& f : result->files) files += (files.empty() ? "" : ",") + f;
    std::fprintf(stderr, "radiosity: %s after %.2f s; wrote %s/{%s}\n",
                 StopReasonName(result->reason).c_str(), result->solution.seconds,
                 args.out.c_str(), files.c_str());
  }
  return result->reason == StopReason::kCancelled ? kExitCancelled : kExitOk;
}

int Main(int argc, char** argv) {
  CLI::App app{"radiosity: diffuse global illumination by zonal (radiosity) methods"};
  app.require_subcommand(1);
  SolveArgs solve;
  JobSpec& spec = solve.spec;
  CLI::App* cmd = app.add_subcommand("solve", "Solve a scene and write results to --out DIR");
  cmd->add_option("scene", solve.scene, "Scene file (.obj, .json or .pb)")->required();
  cmd->add_option("--out", solve.out, "Output directory")->required();
  auto* size_opt = cmd->add_option("--element-size", spec.mesh.element_size,
                                   "Target element edge length (scene units)")
                       ->check(CLI::PositiveNumber);
  cmd->add_option("--max-elements", spec.mesh.max_elements,
                  "Largest element count (used when --element-size is not given)")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 40))
      ->excludes(size_opt);
  cmd->add_option("--patch-depth", spec.mesh.patch_depth,
                  "Elements per patch edge = 2^depth (patches shoot, elements receive)")
      ->check(CLI::Range(0, 8));
  cmd->add_option("--method", spec.solve.method,
                  "progressive, gauss-seidel, jacobi or reflection")
      ->check(CLI::IsMember({"progressive", "gauss-seidel", "jacobi", "reflection"}));
  cmd->add_option("--formfactor", spec.solve.formfactor.method,
                  "Form-factor estimator: montecarlo, analytic or hemicube")
      ->check(CLI::IsMember({"montecarlo", "analytic", "hemicube"}));
  cmd->add_option("--sampling", spec.solve.formfactor.sampling,
                  "Monte Carlo sampling: random, stratified or halton")
      ->check(CLI::IsMember({"random", "stratified", "halton"}));
  cmd->add_option("--hemicube-resolution", spec.solve.formfactor.hemicube_resolution,
                  "Hemicube cells along the top face's edge")
      ->check(CLI::Range(4, 4096));
  cmd->add_option("--shadow-rays", spec.solve.formfactor.shadow_rays,
                  "analytic: shadow rays per receiver sample point")
      ->check(CLI::Range(1, 4096));
  cmd->add_flag("--ambient", spec.solve.ambient,
                "progressive: add an ambient term to previews (never to converged results)");
  cmd->add_option("--overshoot", spec.solve.overshoot,
                  "progressive: overshooting factor (1 = none)")
      ->check(CLI::Range(1.0, 2.0));
  cmd->add_option("--max-matrix-mb", spec.solve.max_matrix_mb,
                  "jacobi/gauss-seidel: refuse matrices larger than this (MiB)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--tolerance", spec.solve.tolerance,
                  "Stop when unshot power (or the residual) < this fraction of emitted power")
      ->check(CLI::Range(1e-15, 0.999999));
  cmd->add_option("--max-rays", spec.solve.max_rays, "Stop after this many rays (0: no limit)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--max-seconds", spec.solve.max_seconds,
                  "Stop after this many seconds (0: no limit)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--seed", spec.solve.seed, "Random seed (results are identical for a seed)");
  cmd->add_option("--threads", spec.solve.threads, "Worker threads (0: all cores)")
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--rays-per-element", spec.solve.rays_per_element,
                  "Ray density: each ray carries emitted power / (this x elements)")
      ->check(CLI::PositiveNumber);
  std::string shooting = "weighted";
  cmd->add_option("--shooting", shooting,
                  "Origins of a patch's rays: weighted (by element unshot power) or uniform")
      ->check(CLI::IsMember({"weighted", "uniform"}));
  cmd->add_option("--sensors", solve.sensors,
                  "Points \"x y z nx ny nz\" a line; writes sensors.csv (irradiance)");
  cmd->add_option("--camera", spec.camera,
                  "View for the image: \"eye=x,y,z look=x,y,z up=x,y,z fov=deg\"");
  cmd->add_option("--width", spec.width, "Image width in pixels")->check(CLI::Range(1, 16384));
  cmd->add_option("--height", spec.height, "Image height in pixels")->check(CLI::Range(1, 16384));
  cmd->add_flag("--quiet,-q", solve.quiet, "No progress output");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    int code = app.exit(e);
    return code == 0 ? kExitOk : kExitUsage;
  }
  try {
    spec.solve.weighted_shooting = shooting == "weighted";
    if (cmd->parsed()) return RunSolve(solve);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "radiosity: error: %s\n", e.what());
    return kExitInternal;
  }
  return kExitUsage;
}

}  // namespace
}  // namespace radiosity

int main(int argc, char** argv) { return radiosity::Main(argc, argv); }
