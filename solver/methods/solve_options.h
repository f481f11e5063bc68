// The options of a solve, and their validation: one definition of every option's bounds, checked
// by the CLI and the service alike (Validate), with errors that name the field as the caller
// spells it (a CLI flag or a field of radiosity.v1.SolveSpec).
#ifndef RADIOSITY_SOLVER_METHODS_SOLVE_OPTIONS_H_
#define RADIOSITY_SOLVER_METHODS_SOLVE_OPTIONS_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "solver/transport/formfactor.h"
#include "solver/transport/luminaire.h"
#include "solver/transport/sky.h"
#include "solver/util/bounds.h"

namespace radiosity {

struct SolveOptions {
  // A name of the method registry (registry.h), or "auto" (method_choice.h).
  std::string method = "progressive";
  // Stop when the unshot power falls below this fraction of the emitted power.
  double tolerance = 1e-3;
  // Stop after this many rays (0: no limit).
  int64_t max_rays = 0;
  // Stop after this many seconds of solving (0: no limit). A job (RunJob) counts its meshing too.
  double max_seconds = 0;
  uint64_t seed = 1;
  // Worker threads (0: all cores). Results do not depend on it.
  int threads = 0;
  // Monte Carlo ray density: each ray carries emitted_power / (rays_per_element x elements), so
  // the rays spent grow linearly with the element count (Shirley, 6.2: O(N) rays).
  double rays_per_element = 1000;
  // Shooting origins within a patch: false, uniform over the patch (the chapter's
  // substructuring); true, weighted by each element's unshot power (same cost, and converges to
  // the element-level solution).
  bool weighted_shooting = true;
  // How form factors are estimated by the methods that use them.
  FormFactorOptions formfactor;
  // Progressive: overshooting factor (1 = none); a shooter also shoots this multiple of its unshot
  // power, the excess recorded as negative unshot power (Feda & Purgathofer 1992).
  double overshoot = 1.0;
  // Progressive: also record each element side's incident irradiance and the part of it that
  // came straight from the emitters (Solution::irradiance, direct_irradiance), for adaptive
  // refinement's re-gathering (adaptive.h). Costs two colours per element side.
  bool track_direct = false;
  // Progressive: direct light from the emitters "computed" (direct_irradiance.h: exact unoccluded
  // form factors times visible fractions from shadow rays, as the first step) or "shot" as rays
  // like the rest of the light.
  std::string direct = "computed";
  // Computed direct light: shadow rays per receiving element and emitting face (16 times as many
  // where they disagree, in penumbrae).
  int direct_shadow_rays = 16;
  // Progressive with Monte Carlo shooting: where light that has left a reflector is received,
  // "patch" (tallied per patch and carried to its elements by interpolation between patches,
  // direct light staying per element) or "element".
  std::string indirect = "patch";
  // Methods that store form factors or links: refuse when they would exceed this many MiB.
  double max_matrix_mb = 4096;
  // Progressive: daylight from outside the scene (sky.h), received as the first step.
  SkyOptions sky;
  // Progressive: luminaires from photometric files (luminaire.h), received with the sky as the
  // first step; their `photometry` is read by the caller (LoadScenePhotometry).
  std::vector<Luminaire> luminaires;
  // Luminaires: Sobol' points per element side (and per sensor, for area luminaires).
  int luminaire_samples = kDefaultLuminaireSamples;

  std::string ToString() const;
};

// How a validation error names a field: as the CLI's flag ("--tolerance") or as the field of the
// wire message ("solve.tolerance").
enum class FieldNaming { kFlag, kField };

// Bounds of the options (closed intervals), used by Validate and documented in the README; the
// estimators' own are in formfactor.h.
inline constexpr Bounds kToleranceBounds{1e-15, 0.999999, "[1e-15, 0.999999]"};
inline constexpr Bounds kMaxSecondsBounds{0, 1e9, "[0, 1e9]"};
inline constexpr Bounds kThreadsBounds{0, 1024, "[0, 1024]"};
inline constexpr Bounds kOvershootBounds{1, 2, "[1, 2]"};
inline constexpr Bounds kMaxRaysBounds{0, 9.2e18, "[0, 2^63)"};
inline constexpr Bounds kDirectShadowRaysBounds{1, 4096, "[1, 4096]"};

// One option of a solve: its key (the SolveSpec field path below "solve.") and its CLI flag.
struct OptionName {
  const char* key;   // "formfactor.shadow_rays"
  const char* flag;  // "--shadow-rays", or "" where the CLI has none.
};
// Every option of SolveOptions that a method may or may not read.
const std::vector<OptionName>& SolveOptionNames();
// "solve.KEY" or the flag (the key when there is no flag).
std::string OptionLabel(const std::string& key, FieldNaming naming);

// Checks every field of `options` (INVALID_ARGUMENT naming the first bad field, e.g.
// "solve.tolerance: 2 is outside [1e-15, 0.999999]"), and that the method and the estimator go
// together (a form-factor estimator for a method that uses none is meaningless).
absl::Status Validate(const SolveOptions& options, FieldNaming naming);

// The options `options` sets away from their defaults that `method` (a registry name, not
// "auto") does not read, as warnings ("--overshoot is ignored by --method jacobi"), plus those
// that are known to misbehave with it.
std::vector<std::string> IgnoredOptions(const std::string& method, const SolveOptions& options,
                                        FieldNaming naming);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_SOLVE_OPTIONS_H_
