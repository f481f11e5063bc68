// elements.csv (and elements_back.csv): the radiosity of every element, one row each.
#ifndef RADIOSITY_SOLVER_RESULTS_ELEMENTS_CSV_H_
#define RADIOSITY_SOLVER_RESULTS_ELEMENTS_CSV_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"

namespace radiosity {

// elements.csv: header exactly "surface,element,cx,cy,cz,area,r,g,b", one row per element, front
// side. Surfaces with a back side (two-sided or transmitting) also get their back sides in
// `back_path` (same header), which is not written when no element has a back side.
absl::Status WriteElementsCsv(const Scene& scene, const Mesh& mesh, const Solution& solution,
                              const std::string& path, const std::string& back_path);

// Every slot's estimated standard error: Solution::std_error where the method gives it; else,
// where it counted Monte Carlo hits, (B - E) / sqrt(hits) (the Poisson estimate); else NaN.
std::vector<Rgb> StdErrors(const Mesh& mesh, const Solution& solution);

// elements_error.csv (and elements_back_error.csv beside elements_back.csv): header exactly
// "surface,element,r,g,b", the rows of elements.csv in the same order, each value the estimated
// standard error of that element's r, g, b (absolute, W/m^2; "nan" where the method gives none).
absl::Status WriteElementsErrorCsv(const Scene& scene, const Mesh& mesh,
                                   const std::vector<Rgb>& std_error, const std::string& path,
                                   const std::string& back_path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_ELEMENTS_CSV_H_
