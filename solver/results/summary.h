// summary.json: what a solve did and how well (docs/guide/outputs.md), one JSON object.
#ifndef RADIOSITY_SOLVER_RESULTS_SUMMARY_H_
#define RADIOSITY_SOLVER_RESULTS_SUMMARY_H_

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/methods/method_choice.h"
#include "solver/methods/solver.h"
#include "solver/transport/luminaire.h"

namespace radiosity {

// One point of a solve's convergence: after a step, the job's elapsed seconds, its rays so far
// and the unshot fraction (the methods' residual).
struct ConvergencePoint {
  double seconds = 0;
  int64_t rays = 0;
  double unshot_fraction = 1;
  // The estimated error then (RelativeStdErrorRms), where it was measured (at snapshots and at
  // the end); NaN elsewhere.
  double std_error_relative = std::numeric_limits<double>::quiet_NaN();
};

// The area-weighted RMS of the elements' standard errors relative to their luminance (floored at
// 1e-3 of the area mean, as the bench measures errors): summary.json's std_error_rms_relative.
// NaN when the solution gives no standard errors.
double RelativeStdErrorRms(const Mesh& mesh, const Solution& solution);

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
  // The convergence history (key "convergence": arrays "seconds", "rays", "unshot_fraction").
  std::vector<ConvergencePoint> convergence;
  // The job's luminaires (key "luminaires", present when there are any): file, format, position,
  // flux (lm per channel), peak intensity (cd), the lamps' rated flux and the opening.
  std::vector<Luminaire> luminaires;
};

absl::Status WriteSummary(const std::string& path, const Scene& scene, const Mesh& mesh,
                          const Solution& solution, const SummaryFacts& facts);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_SUMMARY_H_
