// The speed-against-error benchmark driver (issue 5; bench/run calls it, README "Benchmark").
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
#include <vector>

#include "CLI/CLI.hpp"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "bench/bench_util.h"
#include "proto/scene_codec.h"
#include "solver/hierarchical.h"
#include "solver/job.h"
#include "solver/mesh.h"
#include "solver/output.h"
#include "solver/resample.h"
#include "solver/rng.h"
#include "solver/solver.h"
#include "solver/visibility.h"
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

int HardwareThreads() { return static_cast<int>(std::max(1u, std::thread::hardware_concurrency())); }

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

absl::StatusOr<Setup> Prepare(const MeshArgs& args) {
  Setup setup;
  absl::StatusOr<Scene> scene = LoadSceneFile(args.scene, nullptr);
  if (!scene.ok()) return scene.status();
  setup.scene = *std::move(scene);
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

// What one budget of a ladder means for an estimator.
struct Budget {
  std::string label;
  double rays_per_element = 1000;  // montecarlo
  int hemicube_resolution = 0;     // hemicube
  int analytic_points = 0, shadow_rays = 0;  // analytic
};

absl::StatusOr<Budget> ParseBudget(const std::string& estimator, const std::string& text) {
  Budget b;
  b.label = text;
  if (estimator == "hemicube") {
    if (!absl::SimpleAtoi(text, &b.hemicube_resolution) || b.hemicube_resolution < 2 ||
        b.hemicube_resolution % 2 != 0) {
      return absl::InvalidArgumentError(absl::StrCat("hemicube budget '", text,
                                                     "' is not an even resolution"));
    }
  } else if (estimator == "analytic") {
    std::vector<std::string> parts = absl::StrSplit(text, 'x');
    if (parts.size() == 1) parts.push_back(parts[0]);
    if (parts.size() != 2 || !absl::SimpleAtoi(parts[0], &b.analytic_points) ||
        !absl::SimpleAtoi(parts[1], &b.shadow_rays) || b.analytic_points < 1 ||
        b.shadow_rays < 1) {
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
  std::string sampling = "random";
  double tolerance = 1e-4;
  int threads = 0;
  double max_seconds = 0;
  double max_matrix_mb = 12000;
  bool uniform_shooting = false;
};

void AddMethodArgs(CLI::App* cmd, MethodArgs* args) {
  cmd->add_option("--method", args->method, "progressive, reflection, jacobi, gauss-seidel");
  cmd->add_option("--estimator", args->estimator,
                  "form factors of the matrix methods: montecarlo, analytic, hemicube");
  cmd->add_option("--sampling", args->sampling, "Monte Carlo rows: random, stratified, halton");
  cmd->add_option("--tolerance", args->tolerance, "unshot power / residual to stop at");
  cmd->add_option("--threads", args->threads, "worker threads (0: all cores)");
  cmd->add_option("--max-seconds", args->max_seconds, "stop a solve after this long (0: never)");
  cmd->add_option("--max-matrix-mb", args->max_matrix_mb, "matrix methods' memory limit");
  cmd->add_flag("--uniform-shooting", args->uniform_shooting,
                "progressive: shoot uniformly over a patch (the chapter's substructuring)");
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
  o.rays_per_element = b.rays_per_element;
  o.formfactor.method = m.estimator;
  o.formfactor.sampling = m.sampling;
  if (b.hemicube_resolution > 0) o.formfactor.hemicube_resolution = b.hemicube_resolution;
  if (b.analytic_points > 0) {
    o.formfactor.analytic_points = b.analytic_points;
    o.formfactor.shadow_rays = b.shadow_rays;
  }
  return o;
}

// The estimator as reported: progressive and reflection always shoot Monte Carlo rays.
std::string EstimatorLabel(const MethodArgs& m) {
  if (m.method == "progressive" || m.method == "reflection") {
    return m.uniform_shooting ? "montecarlo-uniform" : "montecarlo";
  }
  if (m.estimator == "montecarlo" && m.sampling != "random") return "montecarlo-" + m.sampling;
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
    "power_error,balance_error,unshot_fraction,stop,ref_noise,load";

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
      for (size_t i = 0; i < records.size(); ++i) rows.push_back({absl::StrCat(seeds[i]), &records[i]});
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
      const double per_element = (peak - start_rss) * 1048576.0 / static_cast<double>(n);
      auto err = [&](double v) { return none ? std::string("nan") : absl::StrFormat("%.6g", v); };
      std::string row = absl::StrFormat(
          "%s,%s,%d,%d,%s,%s,%s,%d,%s,%.6g,%.6g,%.6g,%d,%.6g,%.6g,%.6g,%s,%s,%s,%s,%s,%s,%s,%.6g,"
          "%.6g,%s,%s,%.3g",
          suite, SceneName(mesh_args.scene), n, setup->mesh->patches().size(), method.method,
          estimator, budget_text, threads, seed_label, wall, cpu, setup->mesh_seconds,
          rec->solution.rays, peak, start_rss, per_element, err(m.rms_lum), err(m.rms_rgb[0]),
          err(m.rms_rgb[1]), err(m.rms_rgb[2]), err(m.p99_lum), err(m.max_lum),
          err(m.power_error), BalanceError(rec->solution), rec->solution.unshot_fraction,
          StopReasonName(rec->reason), noise, load);
      csv << row << "\n";
      csv.flush();
      std::cerr << absl::StrFormat(
          "%-14s %-12s %-18s %-8s N=%-8d %8.3f s  %6.2f cpu-s  %11d rays  rms %s  p99 %s  "
          "%.0f MiB  %s\n",
          suite, method.method, estimator, budget_text, n, wall, cpu, rec->solution.rays,
          err(m.rms_lum), err(m.p99_lum), peak, StopReasonName(rec->reason));
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

int ReferenceCommand(const MeshArgs& mesh_args, const MethodArgs& method, const std::string& budget_text,
                     const std::string& seeds_text, bool closed_form,
                     const std::vector<std::string>& checks, const std::string& out,
                     const std::string& command) {
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
      const Element& e = mesh.elements()[s >> 1];
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
      for (size_t s = 0; s < r.size(); ++s) ref.radiosity[s] += r[s] / static_cast<double>(runs.size());
    }
    if (runs.size() >= 2) {
      ErrorMetrics d = CompareRadiosity(mesh, exists, runs[0], runs[1]);
      const double single = d.rms_lum / std::sqrt(2.0);
      ref.meta["noise_single_run_rms"] = absl::StrFormat("%.4g", single);
      ref.meta["noise_rms"] = absl::StrFormat("%.4g", single / std::sqrt(runs.size()));
      ref.meta["noise_p99"] = absl::StrFormat("%.4g", d.p99_lum / std::sqrt(2.0 * runs.size()));
      std::cerr << absl::StrFormat("seed spread: RMS %.4g -> noise of one run %.4g, of the mean %.4g\n",
                                   d.rms_lum, single, single / std::sqrt(runs.size()));
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
    ref.meta["check " + name] =
        absl::StrFormat("rms %.4g p99 %.4g max %.4g power %.3g (its noise %s)", d.rms_lum,
                        d.p99_lum, d.max_lum, d.power_error,
                        other->meta.count("noise_rms") ? other->meta.at("noise_rms") : "?");
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
      area += elements[s >> 1].area;
      mean += elements[s >> 1].area * b->radiosity[s].Luminance();
    }
    mean /= area;
    for (size_t s = 0; s < exists.size(); ++s) {
      if (!exists[s]) continue;
      const Element& e = elements[s >> 1];
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

constexpr double kPi = 3.14159265358979323846;

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
    ray.origin = mesh.SampleElement(e, r1, r2, r3, &half);
    ray.ignore = elements[e].face;
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
  std::string row = absl::StrFormat(
      "%s,%d,%d,%d,%.6g,%.6g,%.6g,%d,%.6g,%.6g,%.6g,%.6g,%.4g,%.4g,%.3g",
      SceneName(mesh_args.scene), elements.size(), nthreads, rec->solution.rays, rec->wall,
      solver_rate, rec->wall, raw_rays, raw_s, raw_rate, gen_s, gen_rate, solver_rate / raw_rate,
      solver_rate / gen_rate, load);
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
    const double a = mesh.elements()[s >> 1].area;
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
  if (a.variant == "adaptive") {
    // The CLI's own path (`radiosity solve --refine`): RunJob, images and PLY off. Its time is
    // from after the first (coarse) mesh to the end of the last solve: every refinement pass,
    // re-meshing, Embree rebuild and re-solve included.
    JobSpec spec;
    spec.mesh.max_elements = elements;
    spec.refine.tolerance = a.refine;
    spec.refine.max_passes = a.refine_passes;
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
  absl::StatusOr<std::unique_ptr<Solver>> solver = CreateSolver(scene, *run.mesh, **vis, o, nullptr);
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
    const Element& e = ref_mesh.elements()[s >> 1];
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
      std::vector<Rgb> constant = ResampleRadiosity(*run->mesh, run->solution, {},
                                                    Reading::kConstant, ref_mesh);
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
          run->piece_count, budget, a.variant == "adaptive" ? absl::StrCat(a.refine) : "0",
          run->passes, run->wall, run->cpu, run->solution.rays, run->links, run->link_mib,
          run->peak_mib, run->base_mib, l2c, l2i, mc.rms_lum, mc.p99_lum, mc.max_lum, mc.power_error,
          mi.rms_lum, mi.p99_lum, noise, ref_mesh.elements().size(), load);
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
    Image image = RenderImage(*last.mesh, **vis, last.solution,
                              CornerRadiosity(*last.mesh, last.solution), scene, camera, a.width,
                              a.height);
    DrawWireframe(*last.mesh, **vis, scene, camera, last.pieces, &image);
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
                            CornerRadiosity(*setup->mesh, solution), setup->scene, camera, width,
                            height);
  if (absl::Status s = WriteImage(image, "", png); !s.ok()) {
    std::cerr << "radiosity_bench: " << s << "\n";
    return 1;
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
  meshes->add_option("--variant", ma.variant, "uniform, adaptive or hierarchical");
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

  CLI11_PARSE(app, argc, argv);
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
