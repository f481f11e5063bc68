// Form-factor estimators (Shirley's thesis 6.2-6.3), behind one interface so that every solver
// that needs form factors can use any of them (`--formfactor montecarlo|analytic|hemicube`).
//
// A row holds the form factors F_{s->j} from one source s (the elements of a patch, or a single
// element, on one side) to every element side j it sees: the fraction of the diffuse power
// leaving s, uniformly over its area, that arrives at j. Rows are the unit of work of the
// progressive solver (one shot) and of matrix assembly (one matrix row).
#ifndef RADIOSITY_SOLVER_FORMFACTOR_H_
#define RADIOSITY_SOLVER_FORMFACTOR_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/mesh.h"
#include "solver/visibility.h"

namespace radiosity {

// The source of a row: elements [first_element, first_element + num_elements) (contiguous, as the
// elements of a patch are), all on `side` (0 front, 1 back).
struct FormFactorSource {
  int first_element = 0;
  int num_elements = 1;
  int side = 0;
};

struct FormFactorRow {
  // Receiving slots (Slot(element, side)) and their form factors, in increasing slot order, each
  // slot once; only entries with F > 0.
  std::vector<int> slots;
  std::vector<double> f;
  // Rays traced to compute the row (primary and shadow rays).
  int64_t rays = 0;
  double Sum() const;
  void Clear() {
    slots.clear();
    f.clear();
    rays = 0;
  }
};

struct FormFactorOptions {
  // "montecarlo", "analytic" or "hemicube".
  std::string method = "montecarlo";
  // Monte Carlo sampling of ray origins and directions: "random", "stratified" (jittered strata)
  // or "halton" (scrambled Halton points, randomised by a per-row shift).
  std::string sampling = "random";
  // analytic: receiver sample points per element and shadow rays per sample point.
  int analytic_points = 4;
  int shadow_rays = 4;
  // hemicube: cells along the top face's edge (the side faces are res x res/2).
  int hemicube_resolution = 128;
};

class FormFactorEstimator {
 public:
  virtual ~FormFactorEstimator() = default;
  // Estimates the row of `source`. `budget` is the number of rays (montecarlo) and is ignored by
  // the deterministic-cost methods; `stream` keys the random numbers (same stream, same row).
  // Thread-safe: rows may be estimated concurrently.
  virtual void Estimate(const FormFactorSource& source, int64_t budget, uint64_t stream,
                        FormFactorRow* row) const = 0;
  virtual std::string name() const = 0;
};

// Creates the estimator named by options.method; the mesh and visibility must outlive it.
// Fails with INVALID_ARGUMENT for an unknown method or sampling, or out-of-range parameters.
absl::StatusOr<std::unique_ptr<FormFactorEstimator>> CreateFormFactorEstimator(
    const Mesh& mesh, const Visibility& visibility, const FormFactorOptions& options);

// Differential area (at p with unit normal n) to polygon form factor, Lambert's contour formula:
//   F = 1/(2 pi) | sum_k gamma_k n . (R_k x R_k+1) / |R_k x R_k+1| |
// exact for an unoccluded polygon wholly in front of p (Howell's catalogue, B-3).
double PointToPolygonFormFactor(const Vec3& p, const Vec3& n, const Vec3* polygon, int count);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_FORMFACTOR_H_
