#include "solver/methods/solve_options.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "solver/methods/registry.h"
#include "solver/util/field_checker.h"

namespace radiosity {

std::string SolveOptions::ToString() const {
  return absl::StrFormat(
      "SolveOptions{method=%s tolerance=%g max_rays=%d max_seconds=%g seed=%d threads=%d "
      "rays_per_element=%g weighted_shooting=%d formfactor=%s sampling=%s direct=%s "
      "indirect=%s sky=%s luminaires=[%s] luminaire_samples=%d}",
      method, tolerance, max_rays, max_seconds, seed, threads, rays_per_element, weighted_shooting,
      formfactor.method, formfactor.sampling, direct, indirect, sky.ToString(),
      absl::StrJoin(luminaires, ", ",
                    [](std::string* out, const Luminaire& l) {
                      absl::StrAppendFormat(out,
                                            "%s@(%.17g,%.17g,%.17g)/(%.17g,%.17g,%.17g)/"
                                            "(%.17g,%.17g,%.17g)x%.17g%s",
                                            l.file, l.position.x, l.position.y, l.position.z,
                                            l.aim.x, l.aim.y, l.aim.z, l.c0.x, l.c0.y, l.c0.z,
                                            l.multiplier, l.color.ToString());
                    }),
      luminaire_samples);
}

const std::vector<OptionName>& SolveOptionNames() {
  static const auto* names = new std::vector<OptionName>{
      {"method", "--method"},
      {"tolerance", "--tolerance"},
      {"max_rays", "--max-rays"},
      {"max_seconds", "--max-seconds"},
      {"seed", "--seed"},
      {"threads", "--threads"},
      {"rays_per_element", "--rays-per-element"},
      {"shooting", "--shooting"},
      {"formfactor.method", "--formfactor"},
      {"formfactor.sampling", "--sampling"},
      {"formfactor.analytic_points", ""},
      {"formfactor.shadow_rays", "--shadow-rays"},
      {"formfactor.hemicube_resolution", "--hemicube-resolution"},
      {"formfactor.hemicube_points", ""},
      {"overshoot", "--overshoot"},
      {"direct", "--direct"},
      {"direct_shadow_rays", "--direct-shadow-rays"},
      {"indirect", "--indirect"},
      {"max_matrix_mb", "--max-matrix-mb"},
      {"sky.model", "--sky"},
      {"sky.up", "--sky-up"},
      {"sky.samples", "--sky-samples"},
      {"luminaires", "--luminaire"},
      {"luminaire_samples", "--luminaire-samples"},
  };
  return *names;
}

std::string OptionLabel(const std::string& key, FieldNaming naming) {
  if (naming == FieldNaming::kField) return "solve." + key;
  for (const OptionName& o : SolveOptionNames()) {
    if (o.key == key && *o.flag != '\0') return o.flag;
  }
  return key;
}

namespace {

std::vector<std::string> EstimatorNames() {
  std::vector<std::string> names;
  for (const EstimatorInfo& e : FormFactorEstimators()) names.push_back(e.name);
  return names;
}

// Whether the option `key` of `o` differs from its default.
bool IsSet(const SolveOptions& o, const std::string& key) {
  const SolveOptions d;
  const FormFactorOptions& f = o.formfactor;
  const FormFactorOptions& df = d.formfactor;
  if (key == "tolerance") return o.tolerance != d.tolerance;
  if (key == "rays_per_element") return o.rays_per_element != d.rays_per_element;
  if (key == "shooting") return o.weighted_shooting != d.weighted_shooting;
  if (key == "formfactor.method") return f.method != df.method;
  if (key == "formfactor.sampling") return f.sampling != df.sampling;
  if (key == "formfactor.analytic_points") return f.analytic_points != df.analytic_points;
  if (key == "formfactor.shadow_rays") return f.shadow_rays != df.shadow_rays;
  if (key == "formfactor.hemicube_resolution") {
    return f.hemicube_resolution != df.hemicube_resolution;
  }
  if (key == "formfactor.hemicube_points") return f.hemicube_points != df.hemicube_points;
  if (key == "overshoot") return o.overshoot != d.overshoot;
  if (key == "max_matrix_mb") return o.max_matrix_mb != d.max_matrix_mb;
  if (key == "direct") return o.direct != d.direct;
  if (key == "direct_shadow_rays") return o.direct_shadow_rays != d.direct_shadow_rays;
  if (key == "indirect") return o.indirect != d.indirect;
  if (key == "sky.model") return o.sky.enabled();
  if (key == "sky.up") return !(o.sky.up == d.sky.up);
  if (key == "sky.samples") return o.sky.samples != d.sky.samples;
  if (key == "luminaires") return !o.luminaires.empty();
  if (key == "luminaire_samples") return o.luminaire_samples != d.luminaire_samples;
  return false;  // method, max_rays, max_seconds, seed, threads: every method reads them.
}

}  // namespace

absl::Status Validate(const SolveOptions& o, FieldNaming naming) {
  FieldChecker c([naming](const std::string& key) { return OptionLabel(key, naming); });
  c.OneOf("method", o.method, MethodNames());
  const FormFactorOptions& f = o.formfactor;
  c.OneOf("formfactor.method", f.method, EstimatorNames());
  c.OneOf("formfactor.sampling", f.sampling, {"sobol", "random", "stratified", "halton"});
  c.OneOf("direct", o.direct, {"computed", "shot"});
  c.InBounds("direct_shadow_rays", o.direct_shadow_rays, kDirectShadowRaysBounds);
  c.OneOf("indirect", o.indirect, {"patch", "element"});
  c.InBounds("formfactor.hemicube_resolution", f.hemicube_resolution, kHemicubeResolutionBounds);
  if (f.hemicube_resolution % 2 != 0) {
    c.Fail("formfactor.hemicube_resolution", absl::StrCat(f.hemicube_resolution, " is not even"));
  }
  c.InBounds("formfactor.hemicube_points", f.hemicube_points, kHemicubePointsBounds);
  c.InBounds("formfactor.analytic_points", f.analytic_points, kAnalyticPointsBounds);
  c.InBounds("formfactor.shadow_rays", f.shadow_rays, kShadowRaysBounds);
  c.InBounds("overshoot", o.overshoot, kOvershootBounds);
  c.Positive("max_matrix_mb", o.max_matrix_mb);
  c.InBounds("tolerance", o.tolerance, kToleranceBounds);
  c.InBounds("max_rays", static_cast<double>(o.max_rays), kMaxRaysBounds);
  c.InBounds("max_seconds", o.max_seconds, kMaxSecondsBounds);
  c.InBounds("threads", o.threads, kThreadsBounds);
  c.Positive("rays_per_element", o.rays_per_element);
  c.OneOf("sky.model", o.sky.model, {"none", "uniform", "overcast"});
  for (int ch = 0; ch < 3; ++ch) {
    if (!std::isfinite(o.sky.irradiance[ch]) || o.sky.irradiance[ch] < 0) {
      c.Fail("sky.model", absl::StrCat("the horizontal irradiance ", o.sky.irradiance.ToString(),
                                       " must be finite and >= 0"));
      break;
    }
  }
  if (o.sky.enabled() && !(o.sky.irradiance.Sum() > 0)) {
    c.Fail("sky.model", absl::StrCat("'", o.sky.model,
                                     "' needs a horizontal irradiance > 0 (e.g. overcast=100)"));
  }
  if (!std::isfinite(Length(o.sky.up)) || !(Length(o.sky.up) > 0)) {
    c.Fail("sky.up",
           absl::StrFormat("(%g, %g, %g) is not a direction", o.sky.up.x, o.sky.up.y, o.sky.up.z));
  }
  c.InBounds("sky.samples", o.sky.samples, kSkySamplesBounds);
  c.InBounds("luminaire_samples", o.luminaire_samples, kLuminaireSamplesBounds);
  if (o.luminaires.size() > kMaxLuminaires) {
    c.Fail("luminaires",
           absl::StrCat(o.luminaires.size(), " luminaires, more than ", kMaxLuminaires));
  }
  for (size_t i = 0; i < o.luminaires.size() && c.status().ok(); ++i) {
    const Luminaire& l = o.luminaires[i];
    const std::string which = absl::StrCat("luminaire ", i + 1, " (", l.file, "): ");
    auto vec = [](const Vec3& v) { return absl::StrFormat("(%g, %g, %g)", v.x, v.y, v.z); };
    if (l.file.empty()) {
      c.Fail("luminaires", absl::StrCat("luminaire ", i + 1, " names no photometric file"));
    } else if (!IsFinite(l.position)) {
      c.Fail("luminaires", absl::StrCat(which, "position ", vec(l.position), " is not finite"));
    } else if (!IsFinite(l.aim) || !(Length(l.aim) > 0)) {
      c.Fail("luminaires", absl::StrCat(which, "aim ", vec(l.aim), " is not a direction"));
    } else if (!IsFinite(l.c0)) {
      c.Fail("luminaires", absl::StrCat(which, "c0 ", vec(l.c0), " is not finite"));
    } else if (!std::isfinite(l.multiplier) || !(l.multiplier > 0)) {
      c.Fail("luminaires", absl::StrCat(which, "multiplier ", l.multiplier, " is not > 0"));
    } else if (!l.color.IsFinite() || l.color.r < 0 || l.color.g < 0 || l.color.b < 0 ||
               !(l.color.Luminance() > 0)) {
      c.Fail("luminaires", absl::StrCat(which, "colour ", l.color.ToString(),
                                        " needs channels >= 0 and a luminance > 0"));
    }
  }
  if (!c.status().ok()) return c.status();
  // The sky is progressive refinement's first step; other methods have no place for light from
  // outside ("auto" chooses progressive when a sky is given).
  if (!o.luminaires.empty() && o.method != "progressive" && o.method != "auto") {
    c.Fail("luminaires", absl::StrCat("luminaires shoot first in ", OptionLabel("method", naming),
                                      " progressive (or auto), not '", o.method, "'"));
  }
  if (o.sky.enabled() && o.method != "progressive" && o.method != "auto") {
    c.Fail("sky.model",
           absl::StrCat("light from outside applies to ", OptionLabel("method", naming),
                        " progressive (or auto), not '", o.method, "'"));
  }
  // Progressive shooting draws its rays from Sobol' points or a random stream only.
  if (o.method == "progressive" && f.method == "montecarlo" && f.sampling != "sobol" &&
      f.sampling != "random") {
    c.Fail("formfactor.sampling",
           absl::StrCat("'", f.sampling, "' does not apply to ", OptionLabel("method", naming),
                        " 'progressive', which shoots with sobol or random"));
  }
  // An estimator the method does not use is meaningless: the answer would not be what was asked.
  const MethodInfo* method = FindMethod(o.method);
  if (method != nullptr && !method->Accepts(f.method)) {
    c.Fail("formfactor.method",
           absl::StrCat("'", f.method, "' does not apply to ", OptionLabel("method", naming), " '",
                        o.method, "', which uses ", absl::StrJoin(method->estimators, " or "),
                        " form factors"));
  }
  return c.status();
}

std::vector<std::string> IgnoredOptions(const std::string& method_name, const SolveOptions& o,
                                        FieldNaming naming) {
  std::vector<std::string> out;
  const MethodInfo* method = FindMethod(method_name);
  if (method == nullptr) return out;
  const std::string by = absl::StrCat(OptionLabel("method", naming), " ", method_name);
  // What it reads: its own options, and its estimator's.
  std::vector<std::string> reads = method->reads;
  if (method->Reads("formfactor.method")) {
    if (const EstimatorInfo* e = FindEstimator(o.formfactor.method)) {
      reads.insert(reads.end(), e->reads.begin(), e->reads.end());
    }
  }
  const bool monte_carlo = o.formfactor.method == "montecarlo";
  for (const OptionName& option : SolveOptionNames()) {
    const std::string key = option.key;
    if (!IsSet(o, key)) continue;
    bool read = std::find(reads.begin(), reads.end(), key) != reads.end();
    // Progressive shooting by form-factor rows shoots each patch uniformly, and deposits per
    // element.
    if (method_name == "progressive" && (key == "shooting" || key == "indirect") && !monte_carlo) {
      read = false;
    }
    // Direct light shot as rays traces no shadow rays of its own.
    if (key == "direct_shadow_rays" && o.direct == "shot") read = false;
    if (read) continue;
    // Options of the estimator are ignored with this estimator, not by the method as such.
    const bool estimator_option =
        key == "shooting" || key == "rays_per_element" || key.rfind("formfactor.", 0) == 0;
    std::string with;
    if (estimator_option && method->Reads("formfactor.method")) {
      with = absl::StrCat(" with ", OptionLabel("formfactor.method", naming), " ",
                          o.formfactor.method);
    }
    out.push_back(absl::StrCat(OptionLabel(key, naming), " is ignored by ", by, with));
  }
  // docs/guide/methods.md: with Monte Carlo rows the total |unshot| grows by about
  // W (1 + rho) - 1 a shot once it is mostly noise; it diverged in every bench run.
  if (method_name == "progressive" && o.overshoot > 1 && monte_carlo) {
    out.push_back(absl::StrFormat(
        "%s %g with Monte Carlo shooting usually diverges (docs/guide/methods.md, "
        "hard cases); it is meant for %s hemicube or analytic",
        OptionLabel("overshoot", naming), o.overshoot, OptionLabel("formfactor.method", naming)));
  }
  return out;
}

}  // namespace radiosity
