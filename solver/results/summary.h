// summary.json: what a solve did and how well (README "Outputs"), one JSON object.
#ifndef RADIOSITY_SOLVER_RESULTS_SUMMARY_H_
#define RADIOSITY_SOLVER_RESULTS_SUMMARY_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/methods/method_choice.h"
#include "solver/methods/solver.h"

namespace radiosity {

// What the solve pipeline knows of a run beyond the scene, the mesh and the solution.
struct SummaryFacts {
  std::string method_requested;
  MethodChoice method;  // What ran, and why.
  std::string formfactor;
  int threads = 0;
  double refine_tolerance = 0;
  int refine_passes = 1;
  std::string refine_mode = "off";  // off, regather or resolve.
  double mesh_seconds = 0;
  double tolerance = 0;
  StopReason reason = StopReason::kConverged;
  // Options the method ignored, and other warnings of the run (key "warnings", always present).
  std::vector<std::string> warnings;
};

absl::Status WriteSummary(const std::string& path, const Scene& scene, const Mesh& mesh,
                          const Solution& solution, const SummaryFacts& facts);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_SUMMARY_H_
