// What method "auto" runs for a scene, and why (logged, and written to summary.json).
//
// Hierarchical radiosity where it was measured to converge fastest (bench/REPORT.md, "High
// reflectance: which method converges fastest"): a bright scene (the area-weighted mean of R + T,
// its largest channel, at least kAutoMinAlbedo) of few polygons (at most kAutoMaxFaces: with
// clusters above that it was faster than progressive on a smooth sphere of 1280 triangles and much
// slower on a furnished office, bench/REPORT.md "Clustering", and a face count cannot tell those
// apart). Everywhere else
// progressive refinement: its rays grow like K N / (1 - rho) (Shirley 6.2), the hierarchical
// solver's Jacobi sweeps like log(tolerance) / log(rho) over links it builds once.
#ifndef RADIOSITY_SOLVER_METHODS_METHOD_CHOICE_H_
#define RADIOSITY_SOLVER_METHODS_METHOD_CHOICE_H_

#include <cstdint>
#include <string>

#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/methods/solve_options.h"

namespace radiosity {

inline constexpr double kAutoMinAlbedo = 0.9;
inline constexpr int64_t kAutoMaxFaces = 200;
// From this mean albedo on, hierarchical whatever the face count: progressive refinement's rays
// grow like 1 / (1 - rho) and would not end (its bound stops it as stalled), while the
// hierarchical solver's Krylov cycles do not slow down as rho nears 1.
inline constexpr double kAutoHierarchicalAlbedo = 0.99;

struct MethodChoice {
  std::string method;  // progressive or hierarchical.
  std::string reason;  // e.g. "mean albedo 0.95 >= 0.9 and 6 faces <= 200".
  double mean_albedo = 0;
  std::string ToString() const;
};

// Area-weighted mean over the element sides that exist of R + T, the largest channel: the
// fraction of arriving light a surface sends on; a closed scene multiplies its emitted power by
// about 1 / (1 - it).
double MeanAlbedo(const Mesh& mesh);

// Hierarchical or progressive for the mesh, as the file comment says. Hierarchical radiosity
// computes its own (analytic) form factors, so a request for another estimator
// (options.formfactor.method hemicube, or montecarlo rows) keeps progressive.
MethodChoice ChooseMethod(const Mesh& mesh, const SolveOptions& options = SolveOptions());

// options.method itself ("requested") or, for "auto", ChooseMethod's choice.
MethodChoice ResolveMethod(const Mesh& mesh, const SolveOptions& options);

// Whether options.method runs on agglomerated meshes (MeshOptions::agglomerate_degrees): the ray
// shooters (progressive, reflection; "auto" until resolved) with Monte Carlo form factors. The
// others integrate over each face's quadtree: hierarchical links, the analytic and hemicube
// estimators, adaptive refinement.
bool TakesAgglomeratedMesh(const SolveOptions& options);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_METHOD_CHOICE_H_
