// The speed-against-error benchmark driver (issue 5; bench/run calls it, bench/REPORT.md).
//
//   radiosity_bench run        --scene S --elements N --method M [--estimator E] --budgets B,B,...
//                              --reference R.ref.gz --csv OUT.csv [--suite NAME]
//       meshes S at about N elements, solves it with M x E at each budget of the ladder (rays per
//       element for Monte Carlo, hemicube resolution, analytic points x shadow rays), and appends
//       one CSV row per solve: wall and CPU time, rays, peak memory, and the errors against the
//       reference of the same mesh.
//   radiosity_bench reference  --scene S --elements N --method M ... --out R.ref.gz
//       solves to a tiny tolerance (with one or more seeds, averaged, the noise estimated from
//       their spread) or takes the closed form (--closed-form: a furnace, B = E / (1 - rho)), and
//       writes the reference with the mesh parameters and the command that made it.
//   radiosity_bench compare    A.ref.gz B.ref.gz         errors of A against B (same mesh)
//   radiosity_bench throughput --scene S --elements N    rays/s inside the progressive solver
//       against raw Embree (Visibility::Intersect) on the same scene and kind of rays.
//   radiosity_bench high_rho   --csv OUT.csv             reflectance near 1: every method on a
//       furnace and a closed bright room at rho = 0.9, 0.99, 0.999 (and the progressive solver's
//       overshooting on the published Cornell box), a ladder of budgets each, the largest element
//       error against the closed form or a stored reference (bench/REPORT.md "High reflectance").
//   radiosity_bench report     --bench-dir bench         plots and bench/REPORT.md
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <thread>
#include <tuple>
#include <vector>

#include "CLI/CLI.hpp"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "bench/bench_util.h"
#include "solver/geometry/interpolation.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/resample.h"
#include "solver/input/scene_files.h"
#include "solver/methods/hierarchical.h"
#include "solver/methods/solver.h"
#include "solver/pipeline/job.h"
#include "solver/results/camera.h"
#include "solver/results/image.h"
#include "solver/results/render.h"
#include "solver/transport/gather.h"
#include "solver/transport/rng.h"
#include "solver/transport/visibility.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"
#include "tbb/task_arena.h"

namespace radiosity::bench {
namespace {

using Clock = std::chrono::steady_clock;
double Since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

double LoadAverage() {
  std::ifstream in("/proc/loadavg");
  double load = -1;
  in >> load;
  return load;
}

int HardwareThreads() {
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

// Options shared by the commands that mesh a scene.
struct MeshArgs {
  std::string scene;
  int64_t elements = 1000;
  int patch_depth = 2;
};

void AddMeshArgs(CLI::App* cmd, MeshArgs* args) {
  cmd->add_option("--scene", args->scene, "scene file (.obj, .json, .pb)")->required();
  cmd->add_option("--elements", args->elements, "the largest element count of the mesh")
      ->check(CLI::Range(int64_t{1}, int64_t{20'000'000}));
  cmd->add_option("--patch-depth", args->patch_depth, "elements per patch edge = 2^D");
}

// A scene, its mesh and its Embree scene.
struct Setup {
  Scene scene;
  std::unique_ptr<Mesh> mesh;
  std::unique_ptr<Visibility> visibility;
  double mesh_seconds = 0;
  double mesh_peak_mib = 0;  // Peak RSS after meshing (whole process so far).
};

// Meshes a scene already in memory (args.scene is only its name).
absl::StatusOr<Setup> PrepareScene(Scene scene, const MeshArgs& args) {
  Setup setup;
  setup.scene = std::move(scene);
  auto start = Clock::now();
  MeshOptions mo;
  mo.max_elements = args.elements;
  mo.patch_depth = args.patch_depth;
  absl::StatusOr<Mesh> mesh = Mesh::Build(setup.scene, mo);
  if (!mesh.ok()) return mesh.status();
  setup.mesh = std::make_unique<Mesh>(*std::move(mesh));
  absl::StatusOr<std::unique_ptr<Visibility>> vis = Visibility::Build(*setup.mesh);
  if (!vis.ok()) return vis.status();
  setup.visibility = *std::move(vis);
  setup.mesh_seconds = Since(start);
  setup.mesh_peak_mib = PeakRssMiB();
  return setup;
}

absl::StatusOr<Setup> Prepare(const MeshArgs& args) {
  absl::StatusOr<Scene> scene = LoadSceneFile(args.scene, nullptr);
  if (!scene.ok()) return scene.status();
  return PrepareScene(*std::move(scene), args);
}

// What one budget of a ladder means for an estimator.
struct Budget {
  std::string label;
  double rays_per_element = 1000;            // montecarlo
  int hemicube_resolution = 0;               // hemicube
  int analytic_points = 0, shadow_rays = 0;  // analytic
};

absl::StatusOr<Budget> ParseBudget(const std::string& estimator, const std::string& text) {
  Budget b;
  b.label = text;
  if (estimator == "hemicube") {
    if (!absl::SimpleAtoi(text, &b.hemicube_resolution) || b.hemicube_resolution < 2 ||
        b.hemicube_resolution % 2 != 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("hemicube budget '", text, "' is not an even resolution"));
    }
  } else if (estimator == "analytic") {
    std::vector<std::string> parts = absl::StrSplit(text, 'x');
    if (parts.size() == 1) parts.push_back(parts[0]);
    if (parts.size() != 2 || !absl::SimpleAtoi(parts[0], &b.analytic_points) ||
        !absl::SimpleAtoi(parts[1], &b.shadow_rays) || b.analytic_points < 1 || b.shadow_rays < 1) {
      return absl::InvalidArgumentError(
          absl::StrCat("analytic budget '", text, "' is not POINTSxSHADOWRAYS"));
    }
  } else {
    if (!absl::SimpleAtod(text, &b.rays_per_element) || !(b.rays_per_element > 0)) {
      return absl::InvalidArgumentError(
          absl::StrCat("Monte Carlo budget '", text, "' is not a positive rays-per-element"));
    }
  }
  return b;
}

// Method and estimator options of one solve.
struct MethodArgs {
  std::string method = "progressive";
  // montecarlo (progressive and reflection are always Monte Carlo), analytic or hemicube.
  std::string estimator = "montecarlo";
  std::string sampling = "sobol";
  std::string direct = "computed";
  std::string indirect = "patch";
  int direct_shadow_rays = 16;
  double tolerance = 1e-4;
  int threads = 0;
  double max_seconds = 0;
  double max_matrix_mb = 12000;
  bool uniform_shooting = false;
  double overshoot = 1;
};

void AddMethodArgs(CLI::App* cmd, MethodArgs* args) {
  cmd->add_option("--method", args->method, "progressive, reflection, jacobi, gauss-seidel");
  cmd->add_option("--estimator", args->estimator,
                  "form factors of the matrix methods: montecarlo, analytic, hemicube");
  cmd->add_option("--sampling", args->sampling,
                  "Monte Carlo rays: sobol, random (and for matrix rows stratified, halton)");
  cmd->add_option("--direct", args->direct, "progressive: direct light computed or shot");
  cmd->add_option("--indirect", args->indirect,
                  "progressive: indirect received per patch or element");
  cmd->add_option("--direct-shadow-rays", args->direct_shadow_rays,
                  "computed direct light: shadow rays per element and emitting face");
  cmd->add_option("--tolerance", args->tolerance, "unshot power / residual to stop at");
  cmd->add_option("--threads", args->threads, "worker threads (0: all cores)");
  cmd->add_option("--max-seconds", args->max_seconds, "stop a solve after this long (0: never)");
  cmd->add_option("--max-matrix-mb", args->max_matrix_mb, "matrix methods' memory limit");
  cmd->add_flag("--uniform-shooting", args->uniform_shooting,
                "progressive: shoot uniformly over a patch (the chapter's substructuring)");
  cmd->add_option("--overshoot", args->overshoot, "progressive: overshooting factor (1 = none)")
      ->check(CLI::Range(1.0, 2.0));
}

SolveOptions MakeSolveOptions(const MethodArgs& m, const Budget& b, uint64_t seed) {
  SolveOptions o;
  o.method = m.method;
  o.tolerance = m.tolerance;
  o.seed = seed;
  o.threads = m.threads;
  o.max_seconds = m.max_seconds;
  o.max_matrix_mb = m.max_matrix_mb;
  o.weighted_shooting = !m.uniform_shooting;
  o.overshoot = m.overshoot;
  o.rays_per_element = b.rays_per_element;
  o.formfactor.method = m.estimator;
  o.formfactor.sampling = m.sampling;
  o.direct = m.direct;
  o.indirect = m.indirect;
  o.direct_shadow_rays = m.direct_shadow_rays;
  if (b.hemicube_resolution > 0) o.formfactor.hemicube_resolution = b.hemicube_resolution;
  if (b.analytic_points > 0) {
    o.formfactor.analytic_points = b.analytic_points;
    o.formfactor.shadow_rays = b.shadow_rays;
  }
  return o;
}

// The estimator as reported: progressive and reflection always shoot Monte Carlo rays.
std::string EstimatorLabel(const MethodArgs& m) {
  // Progressive's variants away from the defaults, e.g. montecarlo-random-shot-element for the
  // shooting of the chapter (pseudo-random rays, direct light shot, received per element).
  if (m.method == "progressive" && m.estimator == "montecarlo") {
    std::string label = "montecarlo";
    if (m.uniform_shooting) label += "-uniform";
    if (m.sampling != "sobol") label += "-" + m.sampling;
    if (m.direct != "computed") label += "-" + m.direct;
    if (m.indirect != "patch") label += "-" + m.indirect;
    return label;
  }
  if (m.method == "reflection") return "montecarlo";
  if (m.estimator == "montecarlo" && m.sampling != "sobol") return "montecarlo-" + m.sampling;
  if (m.method == "progressive" && m.direct != "computed") return m.estimator + "-" + m.direct;
  return m.estimator;
}

struct SolveRecord {
  Solution solution;
  StopReason reason = StopReason::kConverged;
  double wall = 0, cpu = 0;
  double base_mib = 0, peak_mib = 0;
};

absl::StatusOr<SolveRecord> Solve(const Setup& setup, const SolveOptions& options) {
  SolveRecord rec;
  rec.base_mib = CurrentRssMiB();
  ResetPeakRss();
  const double cpu0 = CpuSeconds();
  const auto t0 = Clock::now();
  absl::StatusOr<std::unique_ptr<Solver>> solver =
      CreateSolver(setup.scene, *setup.mesh, *setup.visibility, options, nullptr);
  if (!solver.ok()) return solver.status();
  absl::StatusOr<StopReason> reason = RunSolver(**solver, options, nullptr, nullptr);
  if (!reason.ok()) return reason.status();
  rec.reason = *reason;
  rec.solution = (*solver)->Final();
  rec.wall = Since(t0);
  rec.cpu = CpuSeconds() - cpu0;
  rec.peak_mib = PeakRssMiB();
  return rec;
}

std::string CommandLine(int argc, char** argv) {
  std::vector<std::string> parts;
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    if (i == 0) a = "radiosity_bench";
    if (a.find_first_of(" \t'\"") != std::string::npos) a = "'" + a + "'";
    parts.push_back(a);
  }
  return absl::StrJoin(parts, " ");
}

std::string SceneName(const std::string& path) {
  return std::filesystem::path(path).stem().string();
}

// ---------------------------------------------------------------------------------------------
// run

constexpr char kRunHeader[] =
    "suite,scene,elements,patches,method,estimator,budget,threads,seed,wall_s,cpu_s,mesh_s,rays,"
    "peak_rss_mib,start_rss_mib,bytes_per_element,rms_lum,rms_r,rms_g,rms_b,p99_lum,max_lum,"
    "power_error,balance_error,unshot_fraction,stop,ref_noise,load,est_rms_lum";

// The reference may also be "none" (no errors: timing and memory only) or "pair" (two seeds per
// budget; the error of one run estimated as RMS(a - b) / sqrt(2), valid for an unbiased method).
int RunCommand(const MeshArgs& mesh_args, const MethodArgs& method, const std::string& budgets,
               const std::string& seeds_text, const std::string& reference_path,
               const std::string& csv_path, std::string suite, double stop_after,
               double start_rss) {
  absl::StatusOr<Setup> setup = Prepare(mesh_args);
  if (!setup.ok()) {
    std::cerr << "radiosity_bench: " << setup.status() << "\n";
    return 1;
  }
  const bool pair = reference_path == "pair", none = reference_path == "none";
  Reference ref;
  if (!pair && !none) {
    absl::StatusOr<Reference> loaded = ReadReference(reference_path);
    if (!loaded.ok()) {
      std::cerr << "radiosity_bench: " << loaded.status() << "\n";
      return 1;
    }
    if (absl::Status s = CheckReferenceMesh(*loaded, *setup->mesh); !s.ok()) {
      std::cerr << "radiosity_bench: " << reference_path << ": " << s << "\n";
      return 1;
    }
    ref = *std::move(loaded);
  }
  std::vector<uint64_t> seeds;
  for (const std::string& seed_text : SplitList(seeds_text)) {
    uint64_t seed = 1;
    if (!absl::SimpleAtoi(seed_text, &seed)) {
      std::cerr << "radiosity_bench: bad seed '" << seed_text << "'\n";
      return 2;
    }
    seeds.push_back(seed);
  }
  if (seeds.empty() || (pair && seeds.size() != 2)) {
    std::cerr << "radiosity_bench: give one or more seeds (exactly two with --reference pair)\n";
    return 2;
  }
  const std::vector<uint8_t> exists = ExistingSlots(setup->scene, *setup->mesh);
  if (suite.empty()) suite = SceneName(mesh_args.scene);
  const bool new_file = !std::filesystem::exists(csv_path);
  std::ofstream csv(csv_path, std::ios::app);
  if (!csv) {
    std::cerr << "radiosity_bench: " << csv_path << ": cannot write\n";
    return 1;
  }
  if (new_file) csv << kRunHeader << "\n";
  const int64_t n = static_cast<int64_t>(setup->mesh->elements().size());
  const int threads = method.threads > 0 ? method.threads : HardwareThreads();
  const std::string estimator = EstimatorLabel(method);
  const std::string noise =
      pair ? "0" : (ref.meta.count("noise_rms") ? ref.meta.at("noise_rms") : "nan");
  for (const std::string& budget_text : SplitList(budgets)) {
    absl::StatusOr<Budget> budget = ParseBudget(method.estimator, budget_text);
    if (!budget.ok()) {
      std::cerr << "radiosity_bench: " << budget.status() << "\n";
      return 2;
    }
    bool slow = false;
    std::vector<SolveRecord> records;
    double load = 0;
    for (uint64_t seed : seeds) {
      load = LoadAverage();
      absl::StatusOr<SolveRecord> rec = Solve(*setup, MakeSolveOptions(method, *budget, seed));
      if (!rec.ok()) {
        // A matrix over the memory limit, say: reported here, and the rest of the ladder skipped.
        std::cerr << absl::StrFormat("radiosity_bench: %s %s/%s budget %s: %s\n", suite,
                                     method.method, estimator, budget_text,
                                     rec.status().ToString());
        slow = true;
        break;
      }
      if (stop_after > 0 && rec->wall > stop_after) slow = true;
      records.push_back(*std::move(rec));
    }
    // Rows: one per seed against the reference, or one for the pair.
    std::vector<std::pair<std::string, SolveRecord*>> rows;
    if (pair) {
      if (records.size() == 2) rows.push_back({absl::StrCat(seeds[0], "+", seeds[1]), &records[0]});
    } else {
      for (size_t i = 0; i < records.size(); ++i)
        rows.push_back({absl::StrCat(seeds[i]), &records[i]});
    }
    for (auto& [seed_label, rec] : rows) {
      ErrorMetrics m;
      double wall = rec->wall, cpu = rec->cpu, peak = rec->peak_mib;
      if (pair) {
        // Against the mean of the two runs (a symmetric denominator): |a - m| = |a - b| / 2, so
        // the error of one run is sqrt(2) x that (RMS(a - b) / sqrt(2) relative to the mean).
        // Biased upwards where an element gets only a few rays (its mean is itself noisy).
        std::vector<Rgb> mean(records[0].solution.radiosity.size());
        for (size_t k = 0; k < mean.size(); ++k) {
          mean[k] = (records[0].solution.radiosity[k] + records[1].solution.radiosity[k]) * 0.5;
        }
        m = CompareRadiosity(*setup->mesh, exists, records[0].solution.radiosity, mean);
        const double r2 = std::sqrt(2.0);
        m.rms_lum *= r2;
        for (double& v : m.rms_rgb) v *= r2;
        m.p99_lum *= r2;
        m.max_lum *= r2;
        m.power_error *= r2;
        wall = 0.5 * (records[0].wall + records[1].wall);
        cpu = 0.5 * (records[0].cpu + records[1].cpu);
        peak = std::max(records[0].peak_mib, records[1].peak_mib);
      } else if (!none) {
        m = CompareRadiosity(*setup->mesh, exists, rec->solution.radiosity, ref.radiosity);
      }
      peak = std::max(peak, setup->mesh_peak_mib);
      const double estimated =
          none ? std::nan("")
               : EstimatedRmsLum(*setup->mesh, exists, rec->solution.std_error,
                                 pair ? records[0].solution.radiosity : ref.radiosity);
      const double per_element = (peak - start_rss) * 1048576.0 / static_cast<double>(n);
      auto err = [&](double v) { return none ? std::string("nan") : absl::StrFormat("%.6g", v); };
      std::string row = absl::StrFormat(
          "%s,%s,%d,%d,%s,%s,%s,%d,%s,%.6g,%.6g,%.6g,%d,%.6g,%.6g,%.6g,%s,%s,%s,%s,%s,%s,%s,%.6g,"
          "%.6g,%s,%s,%.3g,%.6g",
          suite, SceneName(mesh_args.scene), n, setup->mesh->patches().size(), method.method,
          estimator, budget_text, threads, seed_label, wall, cpu, setup->mesh_seconds,
          rec->solution.rays, peak, start_rss, per_element, err(m.rms_lum), err(m.rms_rgb[0]),
          err(m.rms_rgb[1]), err(m.rms_rgb[2]), err(m.p99_lum), err(m.max_lum), err(m.power_error),
          BalanceError(rec->solution), rec->solution.unshot_fraction, StopReasonName(rec->reason),
          noise, load, estimated);
      csv << row << "\n";
      csv.flush();
      std::cerr << absl::StrFormat(
          "%-14s %-12s %-18s %-8s N=%-8d %8.3f s  %6.2f cpu-s  %11d rays  rms %s (est %.4g)  "
          "p99 %s  %.0f MiB  %s\n",
          suite, method.method, estimator, budget_text, n, wall, cpu, rec->solution.rays,
          err(m.rms_lum), estimated, err(m.p99_lum), peak, StopReasonName(rec->reason));
    }
    if (slow) {
      std::cerr << absl::StrFormat("%-14s %-12s %-18s: later budgets skipped\n", suite,
                                   method.method, estimator);
      break;
    }
  }
  return 0;
}

// ---------------------------------------------------------------------------------------------
// reference

int ReferenceCommand(const MeshArgs& mesh_args, const MethodArgs& method,
                     const std::string& budget_text, const std::string& seeds_text,
                     bool closed_form, const std::vector<std::string>& checks,
                     const std::string& out, const std::string& command) {
  absl::StatusOr<Setup> setup = Prepare(mesh_args);
  if (!setup.ok()) {
    std::cerr << "radiosity_bench: " << setup.status() << "\n";
    return 1;
  }
  const Mesh& mesh = *setup->mesh;
  const std::vector<uint8_t> exists = ExistingSlots(setup->scene, mesh);
  Reference ref;
  ref.meta["scene"] = mesh_args.scene;
  ref.meta["max_elements"] = absl::StrCat(mesh_args.elements);
  ref.meta["patch_depth"] = absl::StrCat(mesh_args.patch_depth);
  ref.meta["element_size"] = absl::StrFormat("%.17g", mesh.element_size());
  ref.meta["elements"] = absl::StrCat(mesh.elements().size());
  ref.meta["patches"] = absl::StrCat(mesh.patches().size());
  ref.meta["mesh_hash"] = absl::StrCat(MeshHash(mesh));
  ref.meta["command"] = command;
  ref.radiosity.assign(2 * mesh.elements().size(), Rgb());
  const auto start = Clock::now();
  if (closed_form) {
    // A closed furnace: every surface sees only the enclosure, so the radiosity is uniform,
    // B = E + rho B, B = E / (1 - rho) (Shirley eq. 6.2 with sum_j F_ij = 1).
    for (size_t s = 0; s < ref.radiosity.size(); ++s) {
      if (!exists[s]) continue;
      const Element& e = mesh.elements()[ElementOfSlot(static_cast<int>(s))];
      const Material& m = setup->scene.materials[setup->scene.surfaces[e.surface].material];
      for (int k = 0; k < 3; ++k) ref.radiosity[s][k] = m.emission[k] / (1 - m.reflectance[k]);
    }
    ref.meta["method"] = "closed-form B = E / (1 - rho)";
    ref.meta["noise_rms"] = "0";
  } else {
    absl::StatusOr<Budget> budget = ParseBudget(method.estimator, budget_text);
    if (!budget.ok()) {
      std::cerr << "radiosity_bench: " << budget.status() << "\n";
      return 2;
    }
    std::vector<std::vector<Rgb>> runs;
    int64_t rays = 0;
    std::string reasons;
    for (const std::string& seed_text : SplitList(seeds_text)) {
      uint64_t seed = 1;
      if (!absl::SimpleAtoi(seed_text, &seed)) {
        std::cerr << "radiosity_bench: bad seed '" << seed_text << "'\n";
        return 2;
      }
      absl::StatusOr<SolveRecord> rec = Solve(*setup, MakeSolveOptions(method, *budget, seed));
      if (!rec.ok()) {
        std::cerr << "radiosity_bench: " << rec.status() << "\n";
        return 1;
      }
      std::cerr << absl::StrFormat("reference seed %d: %.1f s, %d rays, unshot %.3g, %s\n", seed,
                                   rec->wall, rec->solution.rays, rec->solution.unshot_fraction,
                                   StopReasonName(rec->reason));
      rays += rec->solution.rays;
      absl::StrAppend(&reasons, reasons.empty() ? "" : " ", StopReasonName(rec->reason));
      ref.meta["unshot_fraction"] = absl::StrFormat("%.3g", rec->solution.unshot_fraction);
      ref.meta["balance_error"] = absl::StrFormat("%.3g", BalanceError(rec->solution));
      runs.push_back(std::move(rec->solution.radiosity));
    }
    if (runs.empty()) {
      std::cerr << "radiosity_bench: no seeds\n";
      return 2;
    }
    // The average of the runs; with two or more independent seeds, the noise of one run is
    // RMS(a - b) / sqrt(2) and that of the average of k runs 1/sqrt(k) of it.
    for (const auto& r : runs) {
      for (size_t s = 0; s < r.size(); ++s)
        ref.radiosity[s] += r[s] / static_cast<double>(runs.size());
    }
    if (runs.size() >= 2) {
      ErrorMetrics d = CompareRadiosity(mesh, exists, runs[0], runs[1]);
      const double single = d.rms_lum / std::sqrt(2.0);
      ref.meta["noise_single_run_rms"] = absl::StrFormat("%.4g", single);
      ref.meta["noise_rms"] = absl::StrFormat("%.4g", single / std::sqrt(runs.size()));
      ref.meta["noise_p99"] = absl::StrFormat("%.4g", d.p99_lum / std::sqrt(2.0 * runs.size()));
      std::cerr << absl::StrFormat(
          "seed spread: RMS %.4g -> noise of one run %.4g, of the mean %.4g\n", d.rms_lum, single,
          single / std::sqrt(runs.size()));
    } else {
      ref.meta["noise_rms"] = "unknown";
    }
    ref.meta["method"] = absl::StrCat(method.method, "/", EstimatorLabel(method), " budget ",
                                      budget_text, " tolerance ", method.tolerance);
    ref.meta["seeds"] = seeds_text;
    ref.meta["rays"] = absl::StrCat(rays);
    ref.meta["stop"] = reasons;
  }
  ref.meta["seconds"] = absl::StrFormat("%.1f", Since(start));
  ref.meta["threads"] = absl::StrCat(method.threads > 0 ? method.threads : HardwareThreads());
  for (const std::string& other_path : checks) {
    absl::StatusOr<Reference> other = ReadReference(other_path);
    if (!other.ok() || !CheckReferenceMesh(*other, mesh).ok()) {
      std::cerr << "radiosity_bench: cannot cross-check against " << other_path << "\n";
      return 1;
    }
    ErrorMetrics d = CompareRadiosity(mesh, exists, ref.radiosity, other->radiosity);
    std::string name = std::filesystem::path(other_path).filename().string();
    ref.meta["check " + name] = absl::StrFormat(
        "rms %.4g p99 %.4g max %.4g power %.3g (its noise %s)", d.rms_lum, d.p99_lum, d.max_lum,
        d.power_error, other->meta.count("noise_rms") ? other->meta.at("noise_rms") : "?");
    std::cerr << "check against " << name << ": " << ref.meta["check " + name] << "\n";
  }
  if (absl::Status s = WriteReference(out, ref); !s.ok()) {
    std::cerr << "radiosity_bench: " << s << "\n";
    return 1;
  }
  std::cerr << "wrote " << out << " (" << mesh.elements().size() << " elements)\n";
  return 0;
}

int CompareCommand(const std::string& a_path, const std::string& b_path, const std::string& scene,
                   const std::string& dump) {
  absl::StatusOr<Reference> a = ReadReference(a_path), b = ReadReference(b_path);
  if (!a.ok() || !b.ok()) {
    std::cerr << "radiosity_bench: " << (a.ok() ? b.status() : a.status()) << "\n";
    return 1;
  }
  if (a->meta["mesh_hash"] != b->meta["mesh_hash"]) {
    std::cerr << "radiosity_bench: the two references are on different meshes\n";
    return 1;
  }
  MeshArgs args;
  args.scene = scene.empty() ? a->meta["scene"] : scene;
  absl::SimpleAtoi(a->meta["max_elements"], &args.elements);
  absl::SimpleAtoi(a->meta["patch_depth"], &args.patch_depth);
  absl::StatusOr<Setup> setup = Prepare(args);
  if (!setup.ok() || !CheckReferenceMesh(*a, *setup->mesh).ok()) {
    std::cerr << "radiosity_bench: cannot rebuild the references' mesh\n";
    return 1;
  }
  ErrorMetrics d = CompareRadiosity(*setup->mesh, ExistingSlots(setup->scene, *setup->mesh),
                                    a->radiosity, b->radiosity);
  std::cout << absl::StrFormat("rms_lum %.5g rms_rgb %.5g %.5g %.5g p99 %.5g max %.5g power %.4g\n",
                               d.rms_lum, d.rms_rgb[0], d.rms_rgb[1], d.rms_rgb[2], d.p99_lum,
                               d.max_lum, d.power_error);
  if (!dump.empty()) {
    // Every element side: where it is, both values and the relative error (luminance), for
    // finding where two solutions disagree.
    std::ofstream out(dump);
    out << "surface,element,side,cx,cy,cz,area,lum_a,lum_b,rel_error\n";
    const auto& elements = setup->mesh->elements();
    const std::vector<uint8_t> exists = ExistingSlots(setup->scene, *setup->mesh);
    double area = 0, mean = 0;
    for (size_t s = 0; s < exists.size(); ++s) {
      if (!exists[s]) continue;
      area += elements[ElementOfSlot(static_cast<int>(s))].area;
      mean += elements[ElementOfSlot(static_cast<int>(s))].area * b->radiosity[s].Luminance();
    }
    mean /= area;
    for (size_t s = 0; s < exists.size(); ++s) {
      if (!exists[s]) continue;
      const Element& e = elements[ElementOfSlot(static_cast<int>(s))];
      const double la = a->radiosity[s].Luminance(), lb = b->radiosity[s].Luminance();
      out << absl::StrFormat("%s,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g\n",
                             setup->scene.surfaces[e.surface].name, e.index_in_surface, s & 1,
                             e.centroid.x, e.centroid.y, e.centroid.z, e.area, la, lb,
                             std::fabs(la - lb) / std::max(lb, kFloor * mean));
    }
  }
  return 0;
}

// ---------------------------------------------------------------------------------------------
// throughput

// The progressive solver's kind of ray: cosine-distributed about n (Malley's method).
Vec3 CosineDirection(const Vec3& n, double r1, double r2) {
  Vec3 t, b;
  OrthonormalBasis(n, &t, &b);
  float sin_phi, cos_phi;
  ::sincosf(static_cast<float>(2 * kPi * r1), &sin_phi, &cos_phi);
  const double sin_theta = std::sqrt(r2), cos_theta = std::sqrt(std::max(0.0, 1 - r2));
  return t * (sin_theta * cos_phi) + b * (sin_theta * sin_phi) + n * cos_theta;
}

constexpr char kThroughputHeader[] =
    "scene,elements,threads,solver_rays,solver_s,solver_rays_per_s,trace_s,raw_rays,raw_s,"
    "raw_rays_per_s,raw_gen_s,raw_gen_rays_per_s,ratio_solver_raw,ratio_solver_raw_gen,load";

int ThroughputCommand(const MeshArgs& mesh_args, double rays_per_element, int threads,
                      int64_t raw_rays, const std::string& csv_path) {
  absl::StatusOr<Setup> setup = Prepare(mesh_args);
  if (!setup.ok()) {
    std::cerr << "radiosity_bench: " << setup.status() << "\n";
    return 1;
  }
  const Mesh& mesh = *setup->mesh;
  const Visibility& vis = *setup->visibility;
  const int nthreads = threads > 0 ? threads : HardwareThreads();
  const double load = LoadAverage();

  // 1. The progressive solver, to convergence (tolerance 1e-3): rays / solve wall time.
  MethodArgs method;
  method.threads = threads;
  method.tolerance = 1e-3;
  Budget budget;
  budget.rays_per_element = rays_per_element;
  absl::StatusOr<SolveRecord> rec = Solve(*setup, MakeSolveOptions(method, budget, 1));
  if (!rec.ok()) {
    std::cerr << "radiosity_bench: " << rec.status() << "\n";
    return 1;
  }
  const double solver_rate = static_cast<double>(rec->solution.rays) / rec->wall;
  if (raw_rays <= 0) raw_rays = rec->solution.rays;

  // 2. Raw Embree on the same scene and kind of rays: origins area-uniform over the whole scene
  // (an element chosen with probability proportional to its area, then a uniform point of it),
  // cosine-distributed directions, the origin's face skipped, as the solver traces them.
  const auto& elements = mesh.elements();
  // Area-uniform origins: a table of elements by systematic sampling of their areas (a cheap
  // lookup, like the solver's precomputed ray groups), then a uniform point of the element.
  double total = 0;
  for (const Element& e : elements) total += e.area;
  const size_t table_size = std::max<size_t>(1 << 16, 8 * elements.size());
  std::vector<int32_t> table;
  table.reserve(table_size);
  {
    double cumulative = 0;
    size_t next = 0;
    for (size_t e = 0; e < elements.size(); ++e) {
      cumulative += elements[e].area;
      while (next < table_size && (next + 0.5) * total / table_size < cumulative) {
        table.push_back(static_cast<int32_t>(e));
        ++next;
      }
    }
    while (table.size() < table_size) table.push_back(static_cast<int32_t>(elements.size() - 1));
  }
  struct RawRay {
    Vec3 origin, dir;
    int ignore;
  };
  std::vector<RawRay> rays(static_cast<size_t>(raw_rays));
  constexpr int64_t kChunk = 4096;
  const int64_t chunks = (raw_rays + kChunk - 1) / kChunk;
  auto make_ray = [&](Rng& rng) {
    const int e = table[rng.Next() % table_size];
    int half = 0;
    const double r1 = rng.Uniform(), r2 = rng.Uniform(), r3 = rng.Uniform();
    RawRay ray;
    ray.origin = mesh.SampleElement(e, r1, r2, r3, &half, &ray.ignore);
    ray.dir = CosineDirection(mesh.faces()[ray.ignore].normal[half], rng.Uniform(), rng.Uniform());
    return ray;
  };
  tbb::task_arena arena(nthreads);
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, chunks, 1), [&](const auto& range) {
      for (int64_t c = range.begin(); c < range.end(); ++c) {
        Rng rng(StreamKey(7, static_cast<uint64_t>(c)));
        for (int64_t r = c * kChunk; r < std::min(raw_rays, (c + 1) * kChunk); ++r) {
          rays[r] = make_ray(rng);
        }
      }
    });
  });
  // 2a. Pre-generated rays: rtcIntersect1 (through Visibility::Intersect) alone.
  std::atomic<int64_t> hits{0};
  auto t0 = Clock::now();
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, chunks, 1), [&](const auto& range) {
      int64_t local = 0;
      for (int64_t c = range.begin(); c < range.end(); ++c) {
        for (int64_t r = c * kChunk; r < std::min(raw_rays, (c + 1) * kChunk); ++r) {
          Hit h = vis.Intersect(rays[r].origin, rays[r].dir, 0, 1e30, rays[r].ignore);
          local += h.valid();
        }
      }
      hits += local;
    });
  });
  const double raw_s = Since(t0);
  // 2b. Generating each ray and finding the element hit, as the solver does per ray.
  std::atomic<int64_t> found{0};
  t0 = Clock::now();
  arena.execute([&] {
    tbb::parallel_for(tbb::blocked_range<int64_t>(0, chunks, 1), [&](const auto& range) {
      int64_t local = 0;
      for (int64_t c = range.begin(); c < range.end(); ++c) {
        Rng rng(StreamKey(7, static_cast<uint64_t>(c)));
        for (int64_t r = c * kChunk; r < std::min(raw_rays, (c + 1) * kChunk); ++r) {
          RawRay ray = make_ray(rng);
          Hit h = vis.Intersect(ray.origin, ray.dir, 0, 1e30, ray.ignore);
          if (h.valid()) local += mesh.FindElement(h.face, h.u, h.v) >= 0;
        }
      }
      found += local;
    });
  });
  const double gen_s = Since(t0);
  const double raw_rate = static_cast<double>(raw_rays) / raw_s;
  const double gen_rate = static_cast<double>(raw_rays) / gen_s;
  const bool new_file = !csv_path.empty() && !std::filesystem::exists(csv_path);
  std::string row =
      absl::StrFormat("%s,%d,%d,%d,%.6g,%.6g,%.6g,%d,%.6g,%.6g,%.6g,%.6g,%.4g,%.4g,%.3g",
                      SceneName(mesh_args.scene), elements.size(), nthreads, rec->solution.rays,
                      rec->wall, solver_rate, rec->wall, raw_rays, raw_s, raw_rate, gen_s, gen_rate,
                      solver_rate / raw_rate, solver_rate / gen_rate, load);
  if (!csv_path.empty()) {
    std::ofstream csv(csv_path, std::ios::app);
    if (new_file) csv << kThroughputHeader << "\n";
    csv << row << "\n";
  }
  std::cout << absl::StrFormat(
      "%s N=%d threads=%d: solver %.3g rays/s (%d rays, %.2f s); raw Embree %.3g rays/s "
      "(hit %.1f %%), with ray generation and element lookup %.3g rays/s; solver / raw = %.2f, "
      "solver / raw+generation = %.2f\n",
      SceneName(mesh_args.scene), elements.size(), nthreads, solver_rate, rec->solution.rays,
      rec->wall, raw_rate, 100.0 * hits.load() / raw_rays, gen_rate, solver_rate / raw_rate,
      solver_rate / gen_rate);
  return 0;
}

// ---------------------------------------------------------------------------------------------
// meshes: uniform meshes against adaptive refinement and hierarchical radiosity at equal error
// (issue 7; bench/REPORT.md "Adaptive and hierarchical against uniform meshes").
//
// The three variants solve on different meshes, so every solution is carried onto the mesh of
// the stored reference (ResampleRadiosity: the area average of the solution over each reference
// element, read piecewise constant, and also bilinearly interpolated as images show it) and
// compared there with the usual metrics (CompareRadiosity). The error so measured is that of the
// radiosity as a function on the surfaces, at the reference's resolution: it includes the
// discretisation error of a coarse mesh (a uniform mesh cannot follow a shadow edge) as well as
// the Monte Carlo noise and bias of the solve.

constexpr char kMeshesHeader[] =
    "suite,scene,variant,method,max_elements,elements,pieces,budget,refine,passes,wall_s,cpu_s,"
    "rays,links,link_mib,peak_rss_mib,base_rss_mib,l2_lum,l2_interp,rms_lum,p99_lum,max_lum,"
    "power_error,rms_interp,p99_interp,ref_noise,ref_elements,load";

// Normwise relative error of luminance over the slots in `mask` (the L2 norm of the radiosity
// function over the surfaces, area-weighted): sqrt(sum A_i (B_i - B_i^ref)^2 / sum A_i B_i^ref^2).
// Unlike the per-element relative RMS it does not divide by the (near-zero) radiosity of contact
// shadows, which a coarse element straddling them cannot follow.
double NormwiseError(const Mesh& mesh, const std::vector<uint8_t>& mask,
                     const std::vector<Rgb>& estimate, const std::vector<Rgb>& reference) {
  double num = 0, den = 0;
  const size_t slots = std::min({mask.size(), estimate.size(), reference.size()});
  for (size_t s = 0; s < slots; ++s) {
    if (!mask[s]) continue;
    const double a = mesh.elements()[ElementOfSlot(static_cast<int>(s))].area;
    const double r = reference[s].Luminance(), d = estimate[s].Luminance() - r;
    num += a * d * d;
    den += a * r * r;
  }
  return den > 0 ? std::sqrt(num / den) : 0;
}

struct MeshesArgs {
  std::string suite, scene, reference, csv, variant = "uniform", png, camera;
  std::string elements = "1000", budgets = "1000";
  double refine = 0.1;
  int refine_passes = 6;
  int threads = 0;
  int width = 640, height = 640;
  uint64_t seed = 1;
};

// One solve of a variant: its mesh, solution and costs.
struct MeshesRun {
  std::unique_ptr<Mesh> mesh;
  Solution solution;
  std::vector<int> pieces;  // Hierarchical: receiver piece of each element.
  int64_t piece_count = 0, passes = 1, links = 0;
  double link_mib = 0, wall = 0, cpu = 0, base_mib = 0, peak_mib = 0;
};

absl::StatusOr<MeshesRun> SolveVariant(const Scene& scene, const MeshesArgs& a, int64_t elements,
                                       const std::string& budget) {
  MeshesRun run;
  const bool adaptive = a.variant == "adaptive" || a.variant == "adaptive-resolve";
  if (adaptive) {
    // The CLI's own path (`radiosity solve --refine`, with --refine-resolve for
    // adaptive-resolve): RunJob, images and PLY off. Its time is from after the first (coarse)
    // mesh to the end of the last pass: every refinement, re-meshing, Embree rebuild and
    // re-gather (or re-solve) included.
    JobSpec spec;
    spec.mesh.max_elements = elements;
    spec.refine.tolerance = a.refine;
    spec.refine.max_passes = a.refine_passes;
    spec.refine.resolve = a.variant == "adaptive-resolve";
    spec.solve.method = "progressive";
    spec.solve.seed = a.seed;
    spec.solve.threads = a.threads;
    if (!absl::SimpleAtod(budget, &spec.solve.rays_per_element)) {
      return absl::InvalidArgumentError(absl::StrCat("bad rays per element '", budget, "'"));
    }
    spec.write_image = spec.write_ply = false;
    Mesh last;
    JobObserver observer;
    observer.on_mesh = [&](const Mesh& m) { last = m; };
    char pattern[] = "/tmp/radiosity_bench_meshes.XXXXXX";
    if (!mkdtemp(pattern)) return absl::InternalError("cannot create a temporary directory");
    run.base_mib = CurrentRssMiB();
    ResetPeakRss();
    const double cpu0 = CpuSeconds();
    absl::StatusOr<JobResult> result = RunJob(scene, spec, pattern, nullptr, observer);
    run.cpu = CpuSeconds() - cpu0;
    run.peak_mib = PeakRssMiB();
    std::error_code ec;
    std::filesystem::remove_all(pattern, ec);
    if (!result.ok()) return result.status();
    run.solution = result->solution;
    run.wall = result->solution.seconds;
    run.passes = result->passes;
    run.mesh = std::make_unique<Mesh>(std::move(last));
    run.piece_count = static_cast<int64_t>(run.mesh->elements().size());
    return run;
  }
  MeshOptions mo;
  mo.max_elements = elements;
  absl::StatusOr<Mesh> mesh = Mesh::Build(scene, mo);
  if (!mesh.ok()) return mesh.status();
  run.mesh = std::make_unique<Mesh>(*std::move(mesh));
  absl::StatusOr<std::unique_ptr<Visibility>> vis = Visibility::Build(*run.mesh);
  if (!vis.ok()) return vis.status();
  SolveOptions o;
  o.seed = a.seed;
  o.threads = a.threads;
  if (a.variant == "hierarchical") {
    // The budget is the tolerance: the residual to stop at, and (x 0.1) the refinement epsilon.
    o.method = "hierarchical";
    if (!absl::SimpleAtod(budget, &o.tolerance)) {
      return absl::InvalidArgumentError(absl::StrCat("bad tolerance '", budget, "'"));
    }
    o.max_matrix_mb = 20000;
  } else if (a.variant == "uniform") {
    o.method = "progressive";
    o.tolerance = 1e-3;  // The CLI's default, as in the adaptive runs.
    if (!absl::SimpleAtod(budget, &o.rays_per_element)) {
      return absl::InvalidArgumentError(absl::StrCat("bad rays per element '", budget, "'"));
    }
  } else {
    return absl::InvalidArgumentError(absl::StrCat("unknown variant '", a.variant, "'"));
  }
  run.base_mib = CurrentRssMiB();
  ResetPeakRss();
  const double cpu0 = CpuSeconds();
  const auto t0 = Clock::now();
  absl::StatusOr<std::unique_ptr<Solver>> solver =
      CreateSolver(scene, *run.mesh, **vis, o, nullptr);
  if (!solver.ok()) return solver.status();
  absl::StatusOr<StopReason> reason = RunSolver(**solver, o, nullptr, nullptr);
  if (!reason.ok()) return reason.status();
  run.solution = (*solver)->Final();
  run.wall = Since(t0);
  run.cpu = CpuSeconds() - cpu0;
  run.peak_mib = PeakRssMiB();
  run.piece_count = static_cast<int64_t>(run.mesh->elements().size());
  if (auto* h = dynamic_cast<HierarchicalSolver*>(solver->get())) {
    run.links = h->links();
    run.link_mib = static_cast<double>(h->memory_bytes()) / 1048576.0;
    run.pieces = h->ReceiverPieces();
    std::vector<int> distinct = run.pieces;
    std::sort(distinct.begin(), distinct.end());
    run.piece_count = std::unique(distinct.begin(), distinct.end()) - distinct.begin();
  }
  return run;
}

int MeshesCommand(const MeshesArgs& a) {
  absl::StatusOr<Reference> ref = ReadReference(a.reference);
  if (!ref.ok()) {
    std::cerr << "radiosity_bench: " << ref.status() << "\n";
    return 1;
  }
  MeshArgs ref_args;
  ref_args.scene = a.scene.empty() ? ref->meta["scene"] : a.scene;
  absl::SimpleAtoi(ref->meta["max_elements"], &ref_args.elements);
  absl::SimpleAtoi(ref->meta["patch_depth"], &ref_args.patch_depth);
  absl::StatusOr<Setup> setup = Prepare(ref_args);
  if (!setup.ok() || !CheckReferenceMesh(*ref, *setup->mesh).ok()) {
    std::cerr << "radiosity_bench: cannot rebuild the reference's mesh\n";
    return 1;
  }
  const Scene& scene = setup->scene;
  const Mesh& ref_mesh = *setup->mesh;
  // Element sides the reference never lit (B = 0: the floor under the Cornell box's blocks) are
  // left out: nothing sees them, and a coarse element that straddles a block's footprint would
  // otherwise count its light against a zero there (an error of 1 / kFloor).
  std::vector<uint8_t> exists = ExistingSlots(scene, ref_mesh);
  int64_t unlit = 0;
  for (size_t s = 0; s < exists.size() && s < ref->radiosity.size(); ++s) {
    if (exists[s] && ref->radiosity[s].IsZero()) {
      exists[s] = 0;
      ++unlit;
    }
  }
  if (unlit > 0) std::cerr << "radiosity_bench: " << unlit << " unlit reference slots left out\n";
  // The normwise error leaves the emitters out too (B = E there is known; their large B would
  // only inflate the denominator), unless everything emits (a furnace).
  std::vector<uint8_t> lit = exists;
  bool any_lit = false;
  for (size_t s = 0; s < lit.size(); ++s) {
    const Element& e = ref_mesh.elements()[ElementOfSlot(static_cast<int>(s))];
    if (scene.materials[scene.surfaces[e.surface].material].IsEmitter()) lit[s] = 0;
    any_lit |= lit[s] != 0;
  }
  if (!any_lit) lit = exists;
  const std::string noise = ref->meta.count("noise_rms") ? ref->meta.at("noise_rms") : "nan";
  const std::string suite = a.suite.empty() ? SceneName(ref_args.scene) : a.suite;
  std::ofstream csv;
  if (!a.csv.empty()) {
    const bool new_file = !std::filesystem::exists(a.csv);
    csv.open(a.csv, std::ios::app);
    if (!csv) {
      std::cerr << "radiosity_bench: " << a.csv << ": cannot write\n";
      return 1;
    }
    if (new_file) csv << kMeshesHeader << "\n";
  }
  MeshesRun last;
  for (const std::string& n_text : SplitList(a.elements)) {
    int64_t n = 0;
    if (!absl::SimpleAtoi(n_text, &n) || n < 1) {
      std::cerr << "radiosity_bench: bad element count '" << n_text << "'\n";
      return 2;
    }
    for (const std::string& budget : SplitList(a.budgets)) {
      const double load = LoadAverage();
      absl::StatusOr<MeshesRun> run = SolveVariant(scene, a, n, budget);
      if (!run.ok()) {
        std::cerr << absl::StrFormat("radiosity_bench: %s %s N=%d budget %s: %s\n", suite,
                                     a.variant, n, budget, run.status().ToString());
        continue;
      }
      std::vector<Rgb> constant =
          ResampleRadiosity(*run->mesh, run->solution, {}, Reading::kConstant, ref_mesh);
      std::vector<Rgb> interpolated =
          ResampleRadiosity(*run->mesh, run->solution, CornerRadiosity(*run->mesh, run->solution),
                            Reading::kInterpolated, ref_mesh);
      const ErrorMetrics mc = CompareRadiosity(ref_mesh, exists, constant, ref->radiosity);
      const ErrorMetrics mi = CompareRadiosity(ref_mesh, exists, interpolated, ref->radiosity);
      const double l2c = NormwiseError(ref_mesh, lit, constant, ref->radiosity);
      const double l2i = NormwiseError(ref_mesh, lit, interpolated, ref->radiosity);
      const std::string method = a.variant == "hierarchical" ? "hierarchical" : "progressive";
      const std::string row = absl::StrFormat(
          "%s,%s,%s,%s,%d,%d,%d,%s,%s,%d,%.6g,%.6g,%d,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,"
          "%.6g,%.6g,%.6g,%s,%d,%.3g",
          suite, SceneName(ref_args.scene), a.variant, method, n, run->mesh->elements().size(),
          run->piece_count, budget,
          a.variant.rfind("adaptive", 0) == 0 ? absl::StrCat(a.refine) : "0", run->passes,
          run->wall, run->cpu, run->solution.rays, run->links, run->link_mib, run->peak_mib,
          run->base_mib, l2c, l2i, mc.rms_lum, mc.p99_lum, mc.max_lum, mc.power_error, mi.rms_lum,
          mi.p99_lum, noise, ref_mesh.elements().size(), load);
      if (csv.is_open()) {
        csv << row << "\n";
        csv.flush();
      }
      std::cerr << absl::StrFormat(
          "%-12s %-12s N<=%-7d elements %-7d pieces %-7d budget %-7s %8.3f s  rms %.2f %% "
          "L2 %.2f %% (interpolated %.2f %%)  peak %.0f MiB (+%.0f)\n",
          suite, a.variant, n, run->mesh->elements().size(), run->piece_count, budget, run->wall,
          100 * mc.rms_lum, 100 * l2c, 100 * l2i, run->peak_mib, run->peak_mib - run->base_mib);
      last = *std::move(run);
    }
  }
  if (!a.png.empty() && last.mesh) {
    // A picture of the last run: the shaded solution with its mesh (or hierarchical receiver
    // pieces) drawn over it.
    absl::StatusOr<std::unique_ptr<Visibility>> vis = Visibility::Build(*last.mesh);
    if (!vis.ok()) {
      std::cerr << "radiosity_bench: " << vis.status() << "\n";
      return 1;
    }
    Camera camera = DefaultCamera(*last.mesh);
    if (!a.camera.empty()) {
      absl::StatusOr<Camera> parsed = ParseCamera(a.camera, camera);
      if (!parsed.ok()) {
        std::cerr << "radiosity_bench: " << parsed.status() << "\n";
        return 2;
      }
      camera = *parsed;
    }
    Image image =
        RenderImage(*last.mesh, **vis, last.solution, CornerRadiosity(*last.mesh, last.solution),
                    camera, a.width, a.height);
    DrawWireframe(*last.mesh, **vis, camera, last.pieces, &image);
    if (absl::Status s = WriteImage(image, "", a.png); !s.ok()) {
      std::cerr << "radiosity_bench: " << s << "\n";
      return 1;
    }
  }
  return 0;
}

// Renders a reference solution (a picture of a benchmark scene for the report).
int RenderCommand(const std::string& ref_path, const std::string& camera_text, int width,
                  int height, const std::string& png) {
  absl::StatusOr<Reference> ref = ReadReference(ref_path);
  if (!ref.ok()) {
    std::cerr << "radiosity_bench: " << ref.status() << "\n";
    return 1;
  }
  MeshArgs args;
  args.scene = ref->meta["scene"];
  absl::SimpleAtoi(ref->meta["max_elements"], &args.elements);
  absl::SimpleAtoi(ref->meta["patch_depth"], &args.patch_depth);
  absl::StatusOr<Setup> setup = Prepare(args);
  if (!setup.ok() || !CheckReferenceMesh(*ref, *setup->mesh).ok()) {
    std::cerr << "radiosity_bench: cannot rebuild the reference's mesh\n";
    return 1;
  }
  Camera camera = DefaultCamera(*setup->mesh);
  if (!camera_text.empty()) {
    absl::StatusOr<Camera> parsed = ParseCamera(camera_text, camera);
    if (!parsed.ok()) {
      std::cerr << "radiosity_bench: " << parsed.status() << "\n";
      return 2;
    }
    camera = *parsed;
  }
  Solution solution;
  solution.radiosity = ref->radiosity;
  Image image = RenderImage(*setup->mesh, *setup->visibility, solution,
                            CornerRadiosity(*setup->mesh, solution), camera, width, height);
  if (absl::Status s = WriteImage(image, "", png); !s.ok()) {
    std::cerr << "radiosity_bench: " << s << "\n";
    return 1;
  }
  return 0;
}

// ---------------------------------------------------------------------------------------------
// high_rho: which method converges fastest when the reflectance is near 1 (bench/REPORT.md
// "High reflectance: which method converges fastest"; docs/guide/methods.md).
//
// Scenes, the first two at every rho of --rhos (0.9, 0.99, 0.999):
//   furnace         scenes/furnace.json (a closed unit box, E = 1 everywhere) with every
//                   reflectance set to rho: B = E / (1 - rho) on every element (Shirley eq. 6.2
//                   with sum_j F_ij = 1) is the reference.
//   cornell_closed  the Cornell box without its blocks, closed by a front wall at z = 0, every
//                   reflectance (the light's too) set to rho: a bright room lit by a small
//                   emitter, where the solution is not uniform. Its reference
//                   (bench/reference/high_rho_cornell_closed_rho*.ref.gz, made when missing or
//                   with --make-references) is hierarchical radiosity to a tight tolerance,
//                   cross-checked against two long Monte Carlo solves and against conservation:
//                   in a closed room of uniform rho every watt leaving a surface arrives at one,
//                   so the exitant power is Phi_exit = Phi_emitted + rho Phi_exit, that is
//                   Phi_emitted / (1 - rho).
//   cornell         the Cornell box as published (open, its own reflectances) against the stored
//                   cornell_1k reference: whether what helps at high rho hurts at ordinary rho.
// Every method runs a ladder of budgets and stops it once the largest element error is below
// --target (the next budget could only be slower) or a solve took longer than --stop-after.
// Budgets: progressive and reflection, the expected number of rays that land on an element
// over the whole solve, H = K / (1 - rho) (K rays per element of emitted power, each ray carries
// Phi / (K N), and a solve shoots Phi / (1 - rho) in all: K N / (1 - rho) rays); the matrix
// methods, rays per form-factor row; hierarchical, its tolerance.

constexpr char kHighRhoHeader[] =
    "scene,rho,elements,method,overshoot,budget,rays_per_element,expected_hits,threads,seed,"
    "wall_s,cpu_s,rays,rays_predicted,steps,rms_lum,p99_lum,max_lum,power_error,exitant_error,"
    "slots,unshot_fraction,stop,ref_noise,load";

struct HighRhoArgs {
  std::string csv, reference_dir = "bench/reference", mode = "quick";
  std::string scenes = "furnace,cornell_closed,cornell", rhos = "0.9,0.99,0.999";
  std::string methods;  // Empty: all.
  std::string furnace = "scenes/furnace.json", cornell = "scenes/cornell_box.obj";
  int64_t furnace_elements = 1600, cornell_elements = 1200;
  int threads = 0;
  double target = 0.01, stop_after = 8, max_seconds = 60;
  bool make_references = false;
};

// One series of a ladder.
struct HighRhoSeries {
  std::string method;
  double overshoot = 1;
  std::vector<double> budgets;
};

std::vector<HighRhoSeries> HighRhoLadders(const std::string& mode) {
  // Quick mode ends where a solve takes a few seconds; bench/REPORT.md extrapolates from there
  // (Monte Carlo error ~ t^(-1/2)). Full mode measures down to the target.
  const bool full = mode == "full";
  const std::vector<double> hits =
      full ? std::vector<double>{3e3, 1e4, 3e4, 1e5, 3e5} : std::vector<double>{3e3, 1e4, 3e4};
  const std::vector<double> rows =
      full ? std::vector<double>{100, 1000, 1e4, 1e5} : std::vector<double>{100, 1000, 1e4};
  return {
      {"progressive", 1, hits},
      {"progressive", 1.5, hits},
      {"progressive", 2, hits},
      {"reflection", 1, hits},
      {"gauss-seidel", 1, rows},
      {"jacobi", 1, full ? rows : std::vector<double>{1000, 1e4}},
      {"hierarchical", 1,
       full ? std::vector<double>{1e-2, 1e-3, 1e-4} : std::vector<double>{1e-2, 1e-3}},
  };
}

// The Cornell box without its two blocks, closed by a front wall (the published box is open at
// z = 0) of the back wall's material: floor, walls and ceiling meet its edge exactly (vertices 6,
// 5, 9, 12 of scenes/cornell_box.obj), counter-clockwise seen from inside. The blocks go because
// the uniform mesh does not conform to where they stand: a floor element partly under a block
// shoots from all its area (the zonal assumption), so part of its power starts inside the block
// and is absorbed by the back of its faces. With the blocks that sink takes 3 % of the exitant
// power at rho = 0.9 and 81 % at rho = 0.999 (measured: bench/REPORT.md), and the room is no
// longer one of uniform rho.
absl::Status CloseCornellBox(Scene* scene) {
  int white = -1;
  for (size_t m = 0; m < scene->materials.size(); ++m) {
    if (scene->materials[m].name == "white") white = static_cast<int>(m);
  }
  if (white < 0) return absl::InvalidArgumentError("no material 'white': not the Cornell box");
  std::vector<Face> kept;
  for (const Face& f : scene->faces) {
    const std::string& name = scene->surfaces[f.surface].name;
    if (name != "short_block" && name != "tall_block") kept.push_back(f);
  }
  scene->faces = std::move(kept);
  const int base = static_cast<int>(scene->vertices.size());
  for (const Vec3& v : {Vec3{0.0, 0.0, 0.0}, Vec3{552.8, 0.0, 0.0}, Vec3{556.0, 548.8, 0.0},
                        Vec3{0.0, 548.8, 0.0}}) {
    scene->vertices.push_back(v);
  }
  scene->surfaces.push_back({"front", white, 0});
  Face f;
  f.surface = static_cast<int>(scene->surfaces.size()) - 1;
  f.vertices = {base, base + 1, base + 2, base + 3};
  scene->faces.push_back(f);
  return ValidateScene(*scene);
}

// Area-weighted mean reflectance (luminance) of the element sides that exist.
double MeanReflectance(const Setup& setup, const std::vector<uint8_t>& exists) {
  double area = 0, rho = 0;
  for (size_t s = 0; s < exists.size(); ++s) {
    if (!exists[s]) continue;
    const Element& e = setup.mesh->elements()[ElementOfSlot(static_cast<int>(s))];
    area += e.area;
    rho += e.area *
           setup.scene.materials[setup.scene.surfaces[e.surface].material].reflectance.Luminance();
  }
  return area > 0 ? rho / area : 0;
}

// Total exitant power against Phi / (1 - rho) (a closed room of uniform rho), luminance.
double ExitantError(const Setup& setup, const std::vector<uint8_t>& exists,
                    const std::vector<Rgb>& radiosity, double rho) {
  double exitant = 0, emitted = 0;
  for (size_t s = 0; s < exists.size() && s < radiosity.size(); ++s) {
    if (!exists[s]) continue;
    const Element& e = setup.mesh->elements()[ElementOfSlot(static_cast<int>(s))];
    exitant += e.area * radiosity[s].Luminance();
    emitted += e.area * setup.mesh->sides()[static_cast<int>(s)].exitance.Luminance();
  }
  const double expected = emitted / (1 - rho);
  return (exitant - expected) / expected;
}

SolveOptions HighRhoOptions(const HighRhoSeries& series, double budget, double rho_mean,
                            int threads, double max_seconds, uint64_t seed) {
  SolveOptions o;
  o.method = series.method;
  o.seed = seed;
  o.threads = threads;
  o.max_seconds = max_seconds;
  o.max_matrix_mb = 12000;
  o.overshoot = series.overshoot;
  o.tolerance = 1e-3;  // The CLI's default: a bias of about rho x 1e-3, far below the target.
  if (series.method == "progressive" || series.method == "reflection") {
    o.rays_per_element = budget * (1 - rho_mean);
  } else if (series.method == "hierarchical") {
    o.tolerance = budget;
  } else {
    o.rays_per_element = budget;
  }
  return o;
}

// The reference of cornell_closed at one rho (see above); returns it, written to `path`.
// Hierarchical radiosity to a tolerance of 1e-4: free of Monte Carlo noise (Lambert's exact
// point-to-polygon form factors, stratified receiver points) and fast at any rho. It is one of the
// methods measured, so it is checked against two independent Monte Carlo solutions: Gauss-Seidel
// with 10^5 rays a row and progressive with H = 10^5; their RMS spread from it should be their own
// noise (bench/REPORT.md: about 0.3 % in the furnace at the same budgets) and no more.
absl::StatusOr<Reference> MakeHighRhoReference(const Setup& setup, double rho, int threads,
                                               const std::string& path) {
  const Mesh& mesh = *setup.mesh;
  const std::vector<uint8_t> exists = ExistingSlots(setup.scene, mesh);
  Reference ref;
  ref.meta["scene"] = absl::StrFormat("cornell_closed rho %g", rho);
  ref.meta["elements"] = absl::StrCat(mesh.elements().size());
  ref.meta["element_size"] = absl::StrFormat("%.17g", mesh.element_size());
  ref.meta["patches"] = absl::StrCat(mesh.patches().size());
  ref.meta["mesh_hash"] = absl::StrCat(MeshHash(mesh));
  ref.meta["command"] = absl::StrFormat(
      "radiosity_bench high_rho --scenes cornell_closed --rhos %g --methods none "
      "--make-references",
      rho);
  constexpr double kTolerance = 1e-4, kRowRays = 1e5, kHits = 1e5;
  std::cerr << absl::StrFormat("high_rho: reference rho %g: hierarchical, tolerance %g ...\n", rho,
                               kTolerance);
  absl::StatusOr<SolveRecord> h =
      Solve(setup, HighRhoOptions({"hierarchical", 1, {}}, kTolerance, rho, threads, 0, 101));
  if (!h.ok()) return h.status();
  ref.radiosity = h->solution.radiosity;
  ref.meta["method"] = absl::StrFormat("hierarchical, tolerance %g, seed 101 (%.0f s, %s)",
                                       kTolerance, h->wall, StopReasonName(h->reason));
  ref.meta["noise_rms"] = "0";
  std::vector<std::string> conservation = {
      absl::StrFormat("reference %.3g", ExitantError(setup, exists, h->solution.radiosity, rho))};
  for (const auto& [method, budget, seed] : std::vector<std::tuple<std::string, double, uint64_t>>{
           {"gauss-seidel", kRowRays, 102}, {"progressive", kHits, 103}}) {
    std::cerr << absl::StrFormat("high_rho: reference rho %g: check %s %g ...\n", rho, method,
                                 budget);
    SolveOptions o = HighRhoOptions({method, 1, {}}, budget, rho, threads, 0, seed);
    o.tolerance = 1e-5;
    absl::StatusOr<SolveRecord> c = Solve(setup, o);
    if (!c.ok()) return c.status();
    const ErrorMetrics d = CompareRadiosity(mesh, exists, c->solution.radiosity, ref.radiosity);
    ref.meta["check " + method] = absl::StrFormat(
        "budget %g, seed %d (%.0f s, %d rays, %s): rms %.4g p99 %.4g max %.4g power %.3g", budget,
        seed, c->wall, c->solution.rays, StopReasonName(c->reason), d.rms_lum, d.p99_lum, d.max_lum,
        d.power_error);
    conservation.push_back(absl::StrFormat(
        "%s %.3g", method, ExitantError(setup, exists, c->solution.radiosity, rho)));
  }
  ref.meta["check conservation"] =
      absl::StrCat("exitant power / (Phi / (1 - rho)) - 1: ", absl::StrJoin(conservation, ", "));
  for (const auto& [k, v] : ref.meta) {
    if (k == "method" || k.rfind("check", 0) == 0) std::cerr << "  " << k << ": " << v << "\n";
  }
  if (absl::Status s = WriteReference(path, ref); !s.ok()) return s;
  return ref;
}

int HighRhoCommand(const HighRhoArgs& a) {
  std::vector<double> rhos;
  for (const std::string& t : SplitList(a.rhos)) {
    double rho = 0;
    if (!absl::SimpleAtod(t, &rho) || !(rho > 0 && rho < 1)) {
      std::cerr << "radiosity_bench: bad rho '" << t << "'\n";
      return 2;
    }
    rhos.push_back(rho);
  }
  const std::vector<std::string> methods = SplitList(a.methods);
  const bool new_file = !a.csv.empty() && !std::filesystem::exists(a.csv);
  std::ofstream csv;
  if (!a.csv.empty()) {
    csv.open(a.csv, std::ios::app);
    if (!csv) {
      std::cerr << "radiosity_bench: " << a.csv << ": cannot write\n";
      return 1;
    }
    if (new_file) csv << kHighRhoHeader << "\n";
  }
  const int threads = a.threads > 0 ? a.threads : HardwareThreads();
  for (const std::string& scene_name : SplitList(a.scenes)) {
    // (rho, reflectance override): the published Cornell box keeps its own (rho < 0).
    std::vector<double> scene_rhos = rhos;
    if (scene_name == "cornell") {
      scene_rhos = {-1};
    } else if (scene_name != "furnace" && scene_name != "cornell_closed") {
      std::cerr << "radiosity_bench: unknown scene '" << scene_name << "'\n";
      return 2;
    }
    for (double rho : scene_rhos) {
      MeshArgs mesh_args;
      mesh_args.scene = scene_name == "furnace" ? a.furnace : a.cornell;
      mesh_args.elements = scene_name == "furnace" ? a.furnace_elements : a.cornell_elements;
      if (scene_name == "cornell") mesh_args.elements = 1000;  // The stored cornell_1k mesh.
      absl::StatusOr<Scene> scene = LoadSceneFile(mesh_args.scene, nullptr);
      if (!scene.ok()) {
        std::cerr << "radiosity_bench: " << scene.status() << "\n";
        return 1;
      }
      if (scene_name == "cornell_closed") {
        if (absl::Status s = CloseCornellBox(&*scene); !s.ok()) {
          std::cerr << "radiosity_bench: " << s << "\n";
          return 1;
        }
      }
      if (rho > 0) {
        for (Material& m : scene->materials) m.reflectance = Rgb::Gray(rho);
      }
      absl::StatusOr<Setup> setup = PrepareScene(*std::move(scene), mesh_args);
      if (!setup.ok()) {
        std::cerr << "radiosity_bench: " << setup.status() << "\n";
        return 1;
      }
      const Mesh& mesh = *setup->mesh;
      const std::vector<uint8_t> exists = ExistingSlots(setup->scene, mesh);
      const double rho_mean = rho > 0 ? rho : MeanReflectance(*setup, exists);
      // The reference.
      Reference ref;
      if (scene_name == "furnace") {
        ref.radiosity.assign(2 * mesh.elements().size(), Rgb());
        for (size_t s = 0; s < ref.radiosity.size(); ++s) {
          if (!exists[s]) continue;
          const Element& e = mesh.elements()[ElementOfSlot(static_cast<int>(s))];
          const Material& m = setup->scene.materials[setup->scene.surfaces[e.surface].material];
          for (int k = 0; k < 3; ++k) ref.radiosity[s][k] = m.emission[k] / (1 - m.reflectance[k]);
        }
        ref.meta["noise_rms"] = "0";
      } else {
        const std::string path =
            scene_name == "cornell"
                ? a.reference_dir + "/cornell_1k.ref.gz"
                : absl::StrFormat("%s/high_rho_cornell_closed_rho%g.ref.gz", a.reference_dir, rho);
        absl::StatusOr<Reference> loaded = absl::NotFoundError(path);
        if (std::filesystem::exists(path) && !(a.make_references && rho > 0)) {
          loaded = ReadReference(path);
          if (loaded.ok()) {
            if (absl::Status s = CheckReferenceMesh(*loaded, mesh); !s.ok()) loaded = s;
          }
        } else if (rho > 0) {
          loaded = MakeHighRhoReference(*setup, rho, a.threads, path);
        }
        if (!loaded.ok()) {
          std::cerr << "radiosity_bench: " << path << ": " << loaded.status() << "\n";
          return 1;
        }
        ref = *std::move(loaded);
      }
      const std::string noise = ref.meta.count("noise_rms") ? ref.meta.at("noise_rms") : "nan";
      const std::string rho_text = rho > 0 ? absl::StrFormat("%g", rho) : "scene";
      const int64_t n = static_cast<int64_t>(mesh.elements().size());
      std::cerr << absl::StrFormat("high_rho: %s rho %s (mean %.3f), %d elements\n", scene_name,
                                   rho_text, rho_mean, n);
      for (const HighRhoSeries& series : HighRhoLadders(a.mode)) {
        // --methods names series: a method, or progressive@1.5 and progressive@2 (overshooting).
        const std::string label = series.overshoot == 1
                                      ? series.method
                                      : absl::StrFormat("%s@%g", series.method, series.overshoot);
        if (!methods.empty() && std::find(methods.begin(), methods.end(), label) == methods.end()) {
          continue;
        }
        // At ordinary reflectance only what the decision needs: progressive (the default there)
        // and hierarchical (the default at high reflectance).
        if (scene_name == "cornell" && series.method != "progressive" &&
            series.method != "hierarchical") {
          continue;
        }
        for (double budget : series.budgets) {
          const SolveOptions o =
              HighRhoOptions(series, budget, rho_mean, a.threads, a.max_seconds, 1);
          const double load = LoadAverage();
          absl::StatusOr<SolveRecord> rec = Solve(*setup, o);
          if (!rec.ok()) {
            std::cerr << absl::StrFormat("radiosity_bench: %s %s budget %g: %s\n", scene_name,
                                         series.method, budget, rec.status().ToString());
            break;
          }
          const ErrorMetrics m =
              CompareRadiosity(mesh, exists, rec->solution.radiosity, ref.radiosity);
          const bool shooting = series.method == "progressive" || series.method == "reflection";
          const double predicted = shooting ? o.rays_per_element * n / (1 - rho_mean) : NAN;
          const double exitant =
              rho > 0 ? ExitantError(*setup, exists, rec->solution.radiosity, rho) : NAN;
          const std::string row = absl::StrFormat(
              "%s,%s,%d,%s,%g,%g,%g,%g,%d,%d,%.6g,%.6g,%d,%.6g,%d,%.6g,%.6g,%.6g,%.6g,%.6g,%d,"
              "%.6g,%s,%s,%.3g,%.6g",
              scene_name, rho_text, n, series.method, series.overshoot, budget,
              shooting || series.method != "hierarchical" ? o.rays_per_element : NAN,
              shooting ? budget : NAN, threads, o.seed, rec->wall, rec->cpu, rec->solution.rays,
              predicted, rec->solution.shots, m.rms_lum, m.p99_lum, m.max_lum, m.power_error,
              exitant, m.slots, rec->solution.unshot_fraction, StopReasonName(rec->reason), noise,
              load);
          if (csv.is_open()) {
            csv << row << "\n";
            csv.flush();
          }
          std::cerr << absl::StrFormat(
              "%-14s rho %-5s %-12s w=%-3g budget %-8g %8.2f s %11d rays  rms %.3f %%  max "
              "%.3f %%  exitant %+.2g  %s\n",
              scene_name, rho_text, series.method, series.overshoot, budget, rec->wall,
              rec->solution.rays, 100 * m.rms_lum, 100 * m.max_lum, exitant,
              StopReasonName(rec->reason));
          if (m.max_lum <= a.target || rec->wall > a.stop_after) break;
        }
      }
    }
  }
  return 0;
}

int Main(int argc, char** argv) {
  const double start_rss = CurrentRssMiB();
  CLI::App app{"radiosity speed-against-error benchmark (bench/run drives it)"};
  app.require_subcommand(1);

  MeshArgs mesh_args;
  MethodArgs method;
  std::string budgets = "1000", seeds = "1", reference, csv, suite, out;
  double stop_after = 0;
  bool closed_form = false;
  std::vector<std::string> checks;

  CLI::App* run = app.add_subcommand("run", "solve at a ladder of budgets, append CSV rows");
  AddMeshArgs(run, &mesh_args);
  AddMethodArgs(run, &method);
  run->add_option("--budgets", budgets,
                  "ladder: rays per element (montecarlo), resolutions (hemicube), PxS (analytic)");
  run->add_option("--seeds", seeds, "seeds, one solve each per budget");
  run->add_option("--reference", reference,
                  "reference of the same mesh (.ref.gz), 'pair' (two seeds' spread) or 'none'")
      ->required();
  run->add_option("--csv", csv, "CSV to append to")->required();
  run->add_option("--suite", suite, "name of the scene/resolution in the CSV");
  run->add_option("--stop-after", stop_after,
                  "skip the rest of the ladder once a solve takes longer than this (s)");

  CLI::App* refcmd = app.add_subcommand("reference", "write a reference solution");
  AddMeshArgs(refcmd, &mesh_args);
  AddMethodArgs(refcmd, &method);
  refcmd->add_option("--budget", budgets, "one budget, as for run");
  refcmd->add_option("--seeds", seeds, "seeds to average (two or more: noise estimated)");
  refcmd->add_flag("--closed-form", closed_form, "a furnace: B = E / (1 - rho) everywhere");
  refcmd->add_option("--check", checks, "other references of the same mesh to compare with");
  refcmd->add_option("--out", out, "output file (.ref.gz)")->required();

  std::vector<std::string> pair;
  std::string compare_scene;
  CLI::App* cmp = app.add_subcommand("compare", "errors of reference A against reference B");
  cmp->add_option("files", pair, "A.ref.gz B.ref.gz")->required()->expected(2);
  cmp->add_option("--scene", compare_scene, "scene path (default: as stored in A)");
  std::string dump;
  cmp->add_option("--dump", dump, "write every element's values and error to this CSV");

  double tp_rpe = 300;
  int64_t raw_rays = 0;
  CLI::App* tp = app.add_subcommand("throughput", "solver rays/s against raw Embree");
  AddMeshArgs(tp, &mesh_args);
  tp->add_option("--rays-per-element", tp_rpe, "progressive solver budget");
  tp->add_option("--threads", method.threads, "worker threads (0: all cores)");
  tp->add_option("--raw-rays", raw_rays, "raw rays to trace (0: as many as the solver)");
  tp->add_option("--csv", csv, "CSV to append to");

  std::string camera;
  int width = 480, height = 360;
  CLI::App* render = app.add_subcommand("render", "render a reference solution to PNG");
  render->add_option("--reference", reference, "the reference (.ref.gz)")->required();
  render->add_option("--camera", camera, "\"eye=x,y,z look=x,y,z up=x,y,z fov=deg\"");
  render->add_option("--width", width, "pixels");
  render->add_option("--height", height, "pixels");
  render->add_option("--out", out, "PNG file")->required();

  MeshesArgs ma;
  CLI::App* meshes = app.add_subcommand(
      "meshes", "uniform, adaptive or hierarchical solves measured on a reference's mesh");
  meshes->add_option("--reference", ma.reference, "the reference (.ref.gz)")->required();
  meshes->add_option("--scene", ma.scene, "scene path (default: as stored in the reference)");
  meshes->add_option("--variant", ma.variant,
                     "uniform, adaptive (re-gathering), adaptive-resolve or hierarchical");
  meshes->add_option("--elements", ma.elements,
                     "element counts: the mesh (uniform, hierarchical leaves) or the budget "
                     "(adaptive)");
  meshes->add_option("--budgets", ma.budgets,
                     "rays per element (uniform, adaptive) or tolerances (hierarchical)");
  meshes->add_option("--refine", ma.refine, "adaptive: refinement tolerance");
  meshes->add_option("--refine-passes", ma.refine_passes, "adaptive: passes at most");
  meshes->add_option("--threads", ma.threads, "worker threads (0: all cores)");
  meshes->add_option("--seed", ma.seed, "seed");
  meshes->add_option("--suite", ma.suite, "name in the CSV");
  meshes->add_option("--csv", ma.csv, "CSV to append to");
  meshes->add_option("--png", ma.png, "wireframe picture of the last solve (PNG)");
  meshes->add_option("--camera", ma.camera, "\"eye=x,y,z look=x,y,z up=x,y,z fov=deg\"");
  meshes->add_option("--width", ma.width, "pixels");
  meshes->add_option("--height", ma.height, "pixels");

  ReportOptions report;
  report.mode = "quick";
  CLI::App* rep = app.add_subcommand("report", "plots and REPORT.md from bench/results");
  rep->add_option("--bench-dir", report.bench_dir, "the bench directory")->required();
  rep->add_option("--mode", report.mode, "quick or full (named in the report)");

  HighRhoArgs hr;
  CLI::App* high_rho = app.add_subcommand(
      "high_rho", "reflectance near 1: time to a max element error per method (REPORT.md)");
  high_rho->add_option("--csv", hr.csv, "CSV to append to");
  high_rho->add_option("--scenes", hr.scenes, "furnace, cornell_closed, cornell (comma list)");
  high_rho->add_option("--rhos", hr.rhos, "reflectances of furnace and cornell_closed");
  high_rho->add_option("--methods", hr.methods,
                       "only these series (comma list): progressive, progressive@1.5, "
                       "progressive@2, reflection, gauss-seidel, jacobi, hierarchical");
  high_rho->add_option("--mode", hr.mode, "quick or full (longer ladders)");
  high_rho->add_option("--reference-dir", hr.reference_dir, "stored references");
  high_rho->add_flag("--make-references", hr.make_references,
                     "remake the cornell_closed references (a few minutes each)");
  high_rho->add_option("--furnace", hr.furnace, "furnace scene");
  high_rho->add_option("--cornell", hr.cornell, "Cornell box scene");
  high_rho->add_option("--furnace-elements", hr.furnace_elements, "furnace mesh size");
  high_rho->add_option("--cornell-elements", hr.cornell_elements, "closed Cornell box mesh size");
  high_rho->add_option("--threads", hr.threads, "worker threads (0: all cores)");
  high_rho->add_option("--target", hr.target, "max element error that ends a ladder");
  high_rho->add_option("--stop-after", hr.stop_after,
                       "end a ladder once a solve takes longer than this (s)");
  high_rho->add_option("--max-seconds", hr.max_seconds, "stop a solve after this long (s)");

  std::string sensors_file, room_scene = "scenes/cube_room.json";
  int64_t room_elements = 3456;
  CLI::App* room = app.add_subcommand(
      "room-reference",
      "deterministic sensor irradiance of an empty convex room (bench/sensors.cc)");
  room->add_option("--scene", room_scene, "the room (nothing may block anything in it)");
  room->add_option("--sensors", sensors_file, "sensor points file")->required();
  room->add_option("--elements", room_elements, "the coarser of the two meshes (the finer: 4x)");
  room->add_option("--out", out, "reference CSV")->required();

  int sensor_samples = kDefaultSensorSamples;
  std::string label;
  CLI::App* sens = app.add_subcommand("sensors",
                                      "sensor points solved and gathered, against a "
                                      "room reference: time and RMS error");
  AddMeshArgs(sens, &mesh_args);
  AddMethodArgs(sens, &method);
  sens->add_option("--sensors", sensors_file, "sensor points file")->required();
  sens->add_option("--reference", reference, "reference CSV (room-reference)")->required();
  sens->add_option("--budgets", budgets, "rays per element, a comma list");
  sens->add_option("--sensor-samples", sensor_samples, "gather rays per sensor");
  sens->add_option("--seeds", seeds, "seeds");
  sens->add_option("--label", label, "name of the row");
  sens->add_option("--csv", csv, "CSV to append to")->required();

  double lum_element_size = 0.1;
  std::string lum_samples = "1,4,16,64,256,1024", lum_csv = "/dev/null";
  CLI::App* lum =
      app.add_subcommand("luminaire",
                         "a point luminaire's direct light on a floor: time and error against the "
                         "closed form per --luminaire-samples (bench/luminaire.cc)");
  lum->add_option("--element-size", lum_element_size, "element edge (m) of the 10 m floor");
  lum->add_option("--samples", lum_samples, "points per element, a comma list");
  lum->add_option("--csv", lum_csv, "CSV to append to");

  CLI11_PARSE(app, argc, argv);
  if (lum->parsed()) return LuminaireCommand(lum_element_size, lum_samples, lum_csv);
  if (room->parsed()) {
    return RoomReferenceCommand(room_scene, sensors_file, room_elements, out);
  }
  if (sens->parsed()) {
    for (const std::string& b : SplitList(budgets)) {
      for (const std::string& s : SplitList(seeds)) {
        absl::StatusOr<Budget> budget = ParseBudget(method.estimator, b);
        uint64_t seed = 1;
        if (!budget.ok() || !absl::SimpleAtoi(s, &seed)) {
          std::cerr << "radiosity_bench: bad budget or seed\n";
          return 2;
        }
        const int rc = SensorsCommand(mesh_args.scene, sensors_file, reference,
                                      MakeSolveOptions(method, *budget, seed), mesh_args.elements,
                                      sensor_samples, csv, label.empty() ? "default" : label);
        if (rc != 0) return rc;
      }
    }
    return 0;
  }
  if (high_rho->parsed()) return HighRhoCommand(hr);
  if (run->parsed()) {
    return RunCommand(mesh_args, method, budgets, seeds, reference, csv, suite, stop_after,
                      start_rss);
  }
  if (refcmd->parsed()) {
    return ReferenceCommand(mesh_args, method, budgets, seeds, closed_form, checks, out,
                            CommandLine(argc, argv));
  }
  if (cmp->parsed()) return CompareCommand(pair[0], pair[1], compare_scene, dump);
  if (tp->parsed()) return ThroughputCommand(mesh_args, tp_rpe, method.threads, raw_rays, csv);
  if (render->parsed()) return RenderCommand(reference, camera, width, height, out);
  if (meshes->parsed()) return MeshesCommand(ma);
  if (rep->parsed()) {
    report.results_dir = report.bench_dir + "/results";
    report.figures_dir = report.bench_dir + "/figures";
    report.out = report.bench_dir + "/REPORT.md";
    if (absl::Status s = WriteReport(report); !s.ok()) {
      std::cerr << "radiosity_bench: " << s << "\n";
      return 1;
    }
    return 0;
  }
  return 2;
}

}  // namespace
}  // namespace radiosity::bench

int main(int argc, char** argv) { return radiosity::bench::Main(argc, argv); }
