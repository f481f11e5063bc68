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

std::string Json(double v) { return std::isfinite(v) ? absl::StrFormat("%.10g", v) : "null"; }
std::string Json(const Rgb& c) {
  return absl::StrCat("[", Json(c.r), ", ", Json(c.g), ", ", Json(c.b), "]");
}
std::string JsonString(const std::string& s) {
  std::string out = "\"";
  for (char ch : s) {
    switch (ch) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\n':
        out += "\\n";
        break;
      default:
        if (static_cast<unsigned char>(ch) < 0x20) {
          out += absl::StrFormat("\\u%04x", static_cast<int>(ch));
        } else {
          out += ch;
        }
    }
  }
  return out + "\"";
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
  double element_size = 0;
  int64_t max_elements = 4096;
  int patch_depth = 2;
  double tolerance = 1e-3;
  int64_t max_rays = 0;
  double max_seconds = 0;
  uint64_t seed = 1;
  int threads = 0;
  double rays_per_element = 1000;
  std::string shooting = "weighted";
  std::string camera;
  int width = 512, height = 512;
  bool quiet = false;
};

absl::Status WriteSummary(const std::string& path, const SolveArgs& args, const Scene& scene,
                          const Mesh& mesh, const Solution& sol, StopReason reason,
                          double mesh_seconds, int threads) {
  double balance =
      sol.emitted_power.Sum() > 0
          ? (sol.emitted_power - sol.absorbed_power - sol.escaped_power - sol.unshot_power).Sum() /
                sol.emitted_power.Sum()
          : 0;
  std::string json = absl::StrCat(
      "{\n", "  \"scene\": ", JsonString(args.scene), ",\n", "  \"method\": ",
      JsonString(sol.method), ",\n", "  \"seed\": ", sol.seed, ",\n", "  \"threads\": ", threads,
      ",\n", "  \"surfaces\": ", scene.surfaces.size(), ",\n", "  \"faces\": ", mesh.faces().size(),
      ",\n", "  \"patches\": ", mesh.patches().size(), ",\n", "  \"elements\": ",
      mesh.elements().size(), ",\n", "  \"element_size\": ", Json(mesh.element_size()), ",\n",
      "  \"rays\": ", sol.rays, ",\n", "  \"shots\": ", sol.shots, ",\n",
      "  \"seconds\": ", Json(sol.seconds), ",\n", "  \"mesh_seconds\": ", Json(mesh_seconds),
      ",\n", "  \"rays_per_second\": ", Json(sol.seconds > 0 ? sol.rays / sol.seconds : 0), ",\n",
      "  \"unshot_fraction\": ", Json(sol.unshot_fraction), ",\n", "  \"tolerance\": ",
      Json(args.tolerance), ",\n", "  \"stop_reason\": ", JsonString(StopReasonName(reason)),
      ",\n", "  \"emitted_power\": ", Json(sol.emitted_power), ",\n", "  \"absorbed_power\": ",
      Json(sol.absorbed_power), ",\n", "  \"escaped_power\": ", Json(sol.escaped_power), ",\n",
      "  \"unshot_power\": ", Json(sol.unshot_power), ",\n", "  \"energy_balance_error\": ",
      Json(balance), "\n}\n");
  std::ofstream out(path);
  out << json;
  if (!out) return absl::InternalError(absl::StrCat(path, ": cannot write"));
  return absl::OkStatus();
}

int RunSolve(const SolveArgs& args) {
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadSceneFile(args.scene, &warnings);
  for (const auto& w : warnings) std::fprintf(stderr, "radiosity: warning: %s\n", w.c_str());
  if (!scene.ok()) return Fail(InputExit(scene.status()), scene.status());

  auto mesh_start = std::chrono::steady_clock::now();
  MeshOptions mesh_options;
  mesh_options.element_size = args.element_size;
  mesh_options.max_elements = args.max_elements;
  mesh_options.patch_depth = args.patch_depth;
  absl::StatusOr<Mesh> mesh = Mesh::Build(*scene, mesh_options);
  if (!mesh.ok()) return Fail(kExitUsage, mesh.status());
  auto visibility = Visibility::Build(*mesh);
  if (!visibility.ok()) return Fail(kExitInternal, visibility.status());
  double mesh_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - mesh_start).count();

  SolveOptions options;
  options.tolerance = args.tolerance;
  options.max_rays = args.max_rays;
  options.max_seconds = args.max_seconds;
  options.seed = args.seed;
  options.threads = args.threads;
  options.rays_per_element = args.rays_per_element;
  options.weighted_shooting = args.shooting == "weighted";
  auto solver = CreateSolver(*scene, *mesh, **visibility, options, &g_stop);
  if (!solver.ok()) {
    return Fail(solver.status().code() == absl::StatusCode::kFailedPrecondition ? kExitInput
                                                                               : kExitUsage,
                solver.status());
  }
  int threads = args.threads > 0 ? args.threads : static_cast<int>(std::thread::hardware_concurrency());
  if (!args.quiet) {
    std::fprintf(stderr, "radiosity: %s: %zu surfaces, %zu faces, %zu patches, %zu elements "
                 "(element size %.4g), %d threads\n",
                 args.scene.c_str(), scene->surfaces.size(), mesh->faces().size(),
                 mesh->patches().size(), mesh->elements().size(), mesh->element_size(), threads);
  }

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  ProgressPrinter printer(args.tolerance, args.quiet);
  absl::StatusOr<StopReason> reason =
      RunSolver(**solver, options, &g_stop, [&](const Progress& p) { printer.Update(p); });
  printer.Update((*solver)->progress(), /*final=*/true);
  if (!reason.ok()) return Fail(kExitInternal, reason.status());
  Solution sol = (*solver)->Snapshot();

  std::error_code ec;
  std::filesystem::create_directories(args.out, ec);
  if (ec) {
    return Fail(kExitInput, absl::InvalidArgumentError(
                                absl::StrCat(args.out, ": cannot create directory: ", ec.message())));
  }
  auto path = [&](const char* name) { return (std::filesystem::path(args.out) / name).string(); };
  absl::Status st =
      WriteElementsCsv(*scene, *mesh, sol, path("elements.csv"), path("elements_back.csv"));
  if (st.ok()) {
    st = WriteSummary(path("summary.json"), args, *scene, *mesh, sol, *reason, mesh_seconds,
                      threads);
  }
  auto corners = CornerRadiosity(*mesh, sol);
  if (st.ok()) st = WritePly(*scene, *mesh, sol, corners, path("mesh.ply"));
  if (st.ok()) {
    Camera camera = DefaultCamera(*mesh);
    if (!args.camera.empty()) {
      absl::StatusOr<Camera> parsed = ParseCamera(args.camera, camera);
      if (!parsed.ok()) return Fail(kExitUsage, parsed.status());
      camera = *parsed;
    }
    Image image = RenderImage(*mesh, **visibility, sol, corners, *scene, camera, args.width,
                              args.height);
    st = WriteImage(image, path("image.exr"), path("image.png"));
  }
  if (!st.ok()) return Fail(kExitInternal, st);
  if (!args.quiet) {
    std::fprintf(stderr, "radiosity: %s after %.2f s; wrote %s/{elements.csv,summary.json,"
                 "mesh.ply,image.exr,image.png}\n",
                 StopReasonName(*reason).c_str(), sol.seconds, args.out.c_str());
  }
  return *reason == StopReason::kCancelled ? kExitCancelled : kExitOk;
}

int Main(int argc, char** argv) {
  CLI::App app{"radiosity: diffuse global illumination by zonal (radiosity) methods"};
  app.require_subcommand(1);
  SolveArgs solve;
  CLI::App* cmd = app.add_subcommand("solve", "Solve a scene and write results to --out DIR");
  cmd->add_option("scene", solve.scene, "Scene file (.obj, .json or .pb)")->required();
  cmd->add_option("--out", solve.out, "Output directory")->required();
  auto* size_opt = cmd->add_option("--element-size", solve.element_size,
                                   "Target element edge length (scene units)")
                       ->check(CLI::PositiveNumber);
  cmd->add_option("--max-elements", solve.max_elements,
                  "Largest element count (used when --element-size is not given)")
      ->check(CLI::Range(int64_t{1}, int64_t{1} << 40))
      ->excludes(size_opt);
  cmd->add_option("--patch-depth", solve.patch_depth,
                  "Elements per patch edge = 2^depth (patches shoot, elements receive)")
      ->check(CLI::Range(0, 8));
  cmd->add_option("--tolerance", solve.tolerance,
                  "Stop when unshot power < this fraction of emitted power")
      ->check(CLI::Range(1e-15, 0.999999));
  cmd->add_option("--max-rays", solve.max_rays, "Stop after this many rays (0: no limit)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--max-seconds", solve.max_seconds, "Stop after this many seconds (0: no limit)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--seed", solve.seed, "Random seed (results are identical for a seed)");
  cmd->add_option("--threads", solve.threads, "Worker threads (0: all cores)")
      ->check(CLI::Range(0, 1024));
  cmd->add_option("--rays-per-element", solve.rays_per_element,
                  "Ray density: each ray carries emitted power / (this x elements)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--shooting", solve.shooting,
                  "Origins of a patch's rays: weighted (by element unshot power) or uniform")
      ->check(CLI::IsMember({"weighted", "uniform"}));
  cmd->add_option("--camera", solve.camera,
                  "View for the image: \"eye=x,y,z look=x,y,z up=x,y,z fov=deg\"");
  cmd->add_option("--width", solve.width, "Image width in pixels")->check(CLI::Range(1, 16384));
  cmd->add_option("--height", solve.height, "Image height in pixels")->check(CLI::Range(1, 16384));
  cmd->add_flag("--quiet,-q", solve.quiet, "No progress output");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    int code = app.exit(e);
    return code == 0 ? kExitOk : kExitUsage;
  }
  try {
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
