#include "solver/methods/method_choice.h"

#include <algorithm>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace radiosity {

std::string MethodChoice::ToString() const {
  return absl::StrFormat("MethodChoice{method=%s reason=\"%s\"}", method, reason);
}

double MeanAlbedo(const Mesh& mesh) {
  const SideTable& sides = mesh.sides();
  double area = 0;
  Rgb sum;
  const auto& elements = mesh.elements();
  for (int e = 0; e < static_cast<int>(elements.size()); ++e) {
    for (int side : {kFront, kBack}) {
      const SideRule& rule = sides.at(e, side);
      if (!rule.exists) continue;
      sum += (rule.reflectance + rule.transmittance) * elements[e].area;
      area += elements[e].area;
    }
  }
  if (!(area > 0)) return 0;
  return std::max({sum.r, sum.g, sum.b}) / area;
}

bool TakesAgglomeratedMesh(const SolveOptions& options) {
  const bool shooter =
      options.method == "auto" || options.method == "progressive" || options.method == "reflection";
  return shooter && options.formfactor.method == FormFactorOptions().method;
}

MethodChoice ChooseMethod(const Mesh& mesh, const SolveOptions& options) {
  MethodChoice c;
  c.mean_albedo = MeanAlbedo(mesh);
  const int64_t faces = static_cast<int64_t>(mesh.faces().size());
  // The default estimator (montecarlo) means "none requested"; analytic is what hierarchical
  // radiosity uses itself.
  const std::string& estimator = options.formfactor.method;
  const bool estimator_fits = estimator == FormFactorOptions().method || estimator == "analytic";
  if (mesh.sides().any_specular()) {
    c.method = "progressive";
    c.reason =
        "specular surfaces (mirror, glossy, glass): progressive refinement's rays carry "
        "light through them";
  } else if (options.sky.enabled() || !options.luminaires.empty()) {
    c.method = "progressive";
    c.reason =
        absl::StrCat(options.sky.enabled() ? "--sky" : "--luminaire",
                     " (light from outside the mesh is progressive refinement's first step)");
  } else if (c.mean_albedo >= kAutoMinAlbedo && faces <= kAutoMaxFaces && estimator_fits) {
    c.method = "hierarchical";
    c.reason = absl::StrFormat("mean albedo %.3g >= %g and %d faces <= %d", c.mean_albedo,
                               kAutoMinAlbedo, faces, kAutoMaxFaces);
  } else if (c.mean_albedo >= kAutoHierarchicalAlbedo && estimator_fits) {
    c.method = "hierarchical";
    c.reason = absl::StrFormat(
        "mean albedo %.3g >= %g (progressive refinement's rays grow like 1 / (1 - rho))",
        c.mean_albedo, kAutoHierarchicalAlbedo);
  } else {
    c.method = "progressive";
    c.reason = c.mean_albedo < kAutoMinAlbedo
                   ? absl::StrFormat("mean albedo %.3g < %g", c.mean_albedo, kAutoMinAlbedo)
               : faces > kAutoMaxFaces
                   ? absl::StrFormat(
                         "%d faces > %d (hierarchical radiosity was not measured "
                         "to win on many faces)",
                         faces, kAutoMaxFaces)
                   : absl::StrFormat("--formfactor %s (hierarchical radiosity computes its own)",
                                     estimator);
  }
  return c;
}

MethodChoice ResolveMethod(const Mesh& mesh, const SolveOptions& options) {
  if (options.method == "auto") return ChooseMethod(mesh, options);
  MethodChoice c;
  c.method = options.method;
  c.reason = "requested";
  c.mean_albedo = MeanAlbedo(mesh);
  return c;
}

}  // namespace radiosity
