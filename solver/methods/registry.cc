#include "solver/methods/registry.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "solver/methods/hierarchical.h"
#include "solver/methods/matrix_solver.h"
#include "solver/methods/method_choice.h"
#include "solver/methods/progressive.h"
#include "solver/methods/reflection.h"

namespace radiosity {

namespace {

template <typename T>
absl::StatusOr<std::unique_ptr<Solver>> Upcast(absl::StatusOr<std::unique_ptr<T>> solver) {
  if (!solver.ok()) return solver.status();
  return std::unique_ptr<Solver>(*std::move(solver));
}

absl::StatusOr<std::unique_ptr<Solver>> CreateMatrix(const Scene& scene, const Mesh& mesh,
                                                     const Visibility& visibility,
                                                     const SolveOptions& options,
                                                     const std::atomic<bool>* stop) {
  return Upcast(MatrixSolver::Create(scene, mesh, visibility, options, stop));
}

const std::vector<std::string> kAllEstimators = {"montecarlo", "analytic", "hemicube"};

}  // namespace

bool MethodInfo::Reads(const std::string& key) const {
  return std::find(reads.begin(), reads.end(), key) != reads.end();
}

bool MethodInfo::Accepts(const std::string& estimator) const {
  return estimator == FormFactorOptions().method ||
         std::find(estimators.begin(), estimators.end(), estimator) != estimators.end();
}

const std::vector<MethodInfo>& Methods() {
  static const auto* methods = new std::vector<MethodInfo>{
      {"progressive",
       "progressive refinement: patches shoot their unshot power as rays, the same share of it "
       "everywhere a step (or by form-factor rows, largest first) (Shirley 6.2; Cohen et al. "
       "1988)",
       {"tolerance", "formfactor.method", "shooting", "overshoot", "direct", "direct_shadow_rays",
        "indirect", "sky.model", "sky.up", "sky.samples", "luminaires", "luminaire_samples"},
       kAllEstimators,
       [](const Scene& scene, const Mesh& mesh, const Visibility& visibility,
          const SolveOptions& options,
          const std::atomic<bool>* stop) -> absl::StatusOr<std::unique_ptr<Solver>> {
         auto solver = std::make_unique<ProgressiveSolver>(scene, mesh, visibility, options, stop);
         if (absl::Status s = solver->Init(); !s.ok()) return s;
         return std::unique_ptr<Solver>(std::move(solver));
       }},
      {"gauss-seidel",
       "Gauss-Seidel iteration on the element system B = E + R F B, the form-factor matrix "
       "assembled once (Shirley eq. 6.3)",
       {"tolerance", "formfactor.method", "max_matrix_mb"},
       kAllEstimators,
       CreateMatrix},
      {"jacobi",
       "Jacobi iteration on the same system (Shirley eq. 6.2)",
       {"tolerance", "formfactor.method", "max_matrix_mb"},
       kAllEstimators,
       CreateMatrix},
      {"reflection",
       "reflection simulation: energy packets bounce until absorbed (Shirley 6.1.2)",
       {"rays_per_element"},
       {"montecarlo"},
       [](const Scene& scene, const Mesh& mesh, const Visibility& visibility,
          const SolveOptions& options,
          const std::atomic<bool>* stop) -> absl::StatusOr<std::unique_ptr<Solver>> {
         return std::unique_ptr<Solver>(
             std::make_unique<ReflectionSolver>(scene, mesh, visibility, options, stop));
       }},
      {"hierarchical",
       "hierarchical radiosity: links between pieces at the level the BF oracle asks for, "
       "analytic form factors with shadow rays (Hanrahan, Salzman & Aupperle 1991)",
       {"tolerance", "formfactor.analytic_points", "formfactor.shadow_rays", "max_matrix_mb"},
       {"analytic"},
       [](const Scene& scene, const Mesh& mesh, const Visibility& visibility,
          const SolveOptions& options, const std::atomic<bool>* stop) {
         return Upcast(HierarchicalSolver::Create(scene, mesh, visibility, options, stop));
       }},
  };
  return *methods;
}

const MethodInfo* FindMethod(const std::string& name) {
  for (const MethodInfo& m : Methods()) {
    if (m.name == name) return &m;
  }
  return nullptr;
}

std::string MethodTables() {
  // The flags of the options (those the library alone sets, without a flag, are left out).
  auto flags = [](const std::vector<std::string>& keys) {
    std::vector<std::string> out;
    for (const std::string& key : keys) {
      const std::string label = OptionLabel(key, FieldNaming::kFlag);
      if (label.rfind("--", 0) == 0) out.push_back(absl::StrCat("`", label, "`"));
    }
    return absl::StrJoin(out, ", ");
  };
  std::string md = "| method | what it does | options it reads |\n|---|---|---|\n";
  absl::StrAppend(&md, "| `auto` (default) | hierarchical radiosity on bright scenes of few ",
                  "polygons (mean albedo >= ", kAutoMinAlbedo, ", at most ", kAutoMaxFaces,
                  " faces, and no `--sky` or `--luminaire`; from mean albedo ",
                  kAutoHierarchicalAlbedo,
                  " whatever the faces), progressive refinement "
                  "elsewhere | "
                  "those of the method it "
                  "runs |\n");
  for (const MethodInfo& m : Methods()) {
    absl::StrAppend(&md, "| `", m.name, "` | ", m.description, " | ", flags(m.reads),
                    m.Reads("formfactor.method") ? ", and the estimator's" : "", " |\n");
  }
  absl::StrAppend(&md, "\n| estimator (`--formfactor`) | what it does | options it reads |\n",
                  "|---|---|---|\n");
  for (const EstimatorInfo& e : FormFactorEstimators()) {
    absl::StrAppend(&md, "| `", e.name, "` | ", e.description, " | ", flags(e.reads), " |\n");
  }
  absl::StrAppend(&md,
                  "\nEvery method also reads `--max-rays`, `--max-seconds`, `--seed` and "
                  "`--threads`. An option the method that runs does not read is reported (a "
                  "warning on stderr, `warnings` in summary.json and in the Job); an estimator "
                  "the method does not use is an error.\n");
  return md;
}

std::vector<std::string> MethodNames() {
  std::vector<std::string> names = {"auto"};
  for (const MethodInfo& m : Methods()) names.push_back(m.name);
  return names;
}

}  // namespace radiosity
