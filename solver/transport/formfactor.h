// Form-factor estimators (Shirley's thesis 6.2-6.3), behind one interface so that every solver
// that needs form factors can use any of them (`--formfactor montecarlo|analytic|hemicube`).
//
// A row holds the form factors F_{s->j} from one source s (the elements of a patch, or a single
// element, on one side) to every element side j it sees: the fraction of the diffuse power
// leaving s, uniformly over its area, that arrives at j. Rows are the unit of work of the
// progressive solver (one shot) and of matrix assembly (one matrix row).
#ifndef RADIOSITY_SOLVER_TRANSPORT_FORMFACTOR_H_
#define RADIOSITY_SOLVER_TRANSPORT_FORMFACTOR_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/transport/visibility.h"
#include "solver/util/bounds.h"
#include "solver/util/stop.h"

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

// The estimators' parameters' bounds (FormFactorOptions).
inline constexpr Bounds kAnalyticPointsBounds{1, 4096, "[1, 4096]"};
inline constexpr Bounds kShadowRaysBounds{1, 4096, "[1, 4096]"};
inline constexpr Bounds kHemicubeResolutionBounds{4, 4096, "[4, 4096]"};  // And even.
inline constexpr Bounds kHemicubePointsBounds{1, 1'000'000, "[1, 1000000]"};

struct FormFactorOptions {
  // "montecarlo", "analytic" or "hemicube".
  std::string method = "montecarlo";
  // Monte Carlo sampling of ray origins and directions: "sobol" (Owen-scrambled Sobol' points,
  // sobol.h), "random", "stratified" (jittered strata) or "halton" (Halton points, randomised by
  // a per-row shift). Progressive shooting takes "sobol" or "random".
  std::string sampling = "sobol";
  // analytic: receiver sample points per element and shadow rays per sample point.
  int analytic_points = 4;
  int shadow_rays = 4;
  // hemicube: cells along the top face's edge (the side faces are res x res/2); even.
  int hemicube_resolution = 128;
  // hemicube: hemicubes per row, at stratified points of the source (each with its own random
  // rotation about the normal); 1 places a single hemicube at a point chosen by the stream.
  int hemicube_points = 1;
};

class FormFactorEstimator {
 public:
  virtual ~FormFactorEstimator() = default;
  // Estimates the row of `source`. `budget` is the number of rays (montecarlo) and is ignored by
  // the deterministic-cost methods; `stream` keys the random numbers (same stream, same row).
  // Checks `stop` as it goes: once stop.ShouldStop(), the row is incomplete and must be
  // discarded. Thread-safe: rows may be estimated concurrently.
  virtual void Estimate(const FormFactorSource& source, int64_t budget, uint64_t stream,
                        const StopToken& stop, FormFactorRow* row) const = 0;
  // The same, never stopped.
  void Estimate(const FormFactorSource& source, int64_t budget, uint64_t stream,
                FormFactorRow* row) const {
    Estimate(source, budget, stream, StopToken(), row);
  }
  virtual std::string name() const = 0;
};

// The estimators: their names (FormFactorOptions::method), one line each, and the options of
// FormFactorOptions each reads (keys as in SolveOptionNames, "formfactor.sampling").
struct EstimatorInfo {
  std::string name;
  std::string description;
  std::vector<std::string> reads;
};
const std::vector<EstimatorInfo>& FormFactorEstimators();
const EstimatorInfo* FindEstimator(const std::string& name);

// Creates the estimator named by options.method; the mesh and visibility must outlive it.
// Fails with INVALID_ARGUMENT for an unknown method or sampling, or out-of-range parameters.
absl::StatusOr<std::unique_ptr<FormFactorEstimator>> CreateFormFactorEstimator(
    const Mesh& mesh, const Visibility& visibility, const FormFactorOptions& options);

// Differential area (at p with unit normal n) to polygon form factor, Lambert's contour formula:
//   F = 1/(2 pi) | sum_k gamma_k n . (R_k x R_k+1) / |R_k x R_k+1| |
// exact for an unoccluded polygon wholly in front of p (Howell's catalogue, B-3).
double PointToPolygonFormFactor(const Vec3& p, const Vec3& n, const Vec3* polygon, int count);

// The same for any planar polygon: the polygon is first clipped to the half-space in front of the
// tangent plane at p, dot(x - p, n) >= 0 (Sutherland-Hodgman), so only the part p can see counts.
// Whether the polygon faces p is the caller's business (a polygon seen from behind emits nothing
// towards p).
double PointToPolygonFormFactorClipped(const Vec3& p, const Vec3& n, const Vec3* polygon,
                                       int count);

// Whether the segment between a point a on mesh face `face_a` and a point b on mesh face `face_b`
// is unblocked (a shadow ray). `cos_b` is the cosine between the segment and b's normal. Robust
// where the two faces meet at a shared edge: a single ray from a that skips face_a stops short of
// b by a margin that grows as the ray grazes b's face; when that margin would be large, two rays
// from either end (each skipping its own face) meet at the midpoint instead. Adds the rays traced
// to *rays.
bool SegmentVisible(const Visibility& visibility, const Vec3& a, int face_a, const Vec3& b,
                    int face_b, double cos_b, int64_t* rays);

// The delta form factors of a hemicube (Cohen & Greenberg 1985) of half-width 1 and height 1 over
// a point with normal +z, `resolution` (even) cells along the top face's edge.
struct HemicubeDeltas {
  int resolution = 0;
  // Top face z = 1: resolution x resolution cells, row-major (row: y from -1, column: x from -1).
  std::vector<double> top;
  // One side face x = 1 (the other three are the same by symmetry): resolution / 2 rows (z from 0
  // up) of resolution cells (y from -1).
  std::vector<double> side;
  // Sum over the whole hemicube (top + 4 sides).
  double Sum() const;
};

// exact = false: the classic midpoint values, top dA / (pi (x^2 + y^2 + 1)^2), sides
// z dA / (pi (y^2 + z^2 + 1)^2) at each cell's centre (they sum to 1 - O(1/res^2)).
// exact = true: each cell's own form factor, Lambert's formula over the cell (sum 1 to rounding);
// the hemicube estimator uses these.
HemicubeDeltas ComputeHemicubeDeltas(int resolution, bool exact);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_FORMFACTOR_H_
