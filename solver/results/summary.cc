#include "solver/results/summary.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "solver/results/elements_csv.h"
#include "solver/util/file_io.h"
#include "solver/util/json.h"

namespace radiosity {

namespace {

std::string JsonRgb(const Rgb& c) {
  return absl::StrCat("[", JsonNumber(c.r), ", ", JsonNumber(c.g), ", ", JsonNumber(c.b), "]");
}

}  // namespace

double RelativeStdErrorRms(const Mesh& mesh, const Solution& sol) {
  const std::vector<Rgb> se = StdErrors(mesh, sol);
  double area = 0, mean = 0;
  for (size_t s = 0; s < se.size() && s < sol.radiosity.size(); ++s) {
    if (!mesh.sides().exists(static_cast<int>(s)) || std::isnan(se[s].Sum())) continue;
    const double a = mesh.elements()[ElementOfSlot(static_cast<int>(s))].area;
    area += a;
    mean += a * sol.radiosity[s].Luminance();
  }
  if (!(area > 0)) return std::numeric_limits<double>::quiet_NaN();
  mean /= area;
  double rel = 0;
  for (size_t s = 0; s < se.size() && s < sol.radiosity.size(); ++s) {
    if (!mesh.sides().exists(static_cast<int>(s)) || std::isnan(se[s].Sum())) continue;
    const double a = mesh.elements()[ElementOfSlot(static_cast<int>(s))].area;
    const double d = std::max(sol.radiosity[s].Luminance(), 1e-3 * mean);
    const double e = d > 0 ? se[s].Luminance() / d : 0;
    rel += a * e * e;
  }
  return std::sqrt(rel / area);
}

absl::Status WriteSummary(const std::string& path, const Scene& scene, const Mesh& mesh,
                          const Solution& sol, const SummaryFacts& facts) {
  // emitted = absorbed + escaped + unshot, relative to the emitted power.
  const double balance =
      sol.emitted_power.Sum() > 0
          ? (sol.emitted_power - sol.absorbed_power - sol.escaped_power - sol.unshot_power).Sum() /
                sol.emitted_power.Sum()
          : 0;
  // The area-weighted RMS of the elements' standard errors (elements_error.csv), per channel, and
  // relative to each element's luminance (RelativeStdErrorRms); null where the method gives none.
  std::string std_error_rms = "null", std_error_relative = "null";
  {
    const std::vector<Rgb> se = StdErrors(mesh, sol);
    double area = 0;
    Rgb sq;
    for (size_t s = 0; s < se.size() && s < sol.radiosity.size(); ++s) {
      if (!mesh.sides().exists(static_cast<int>(s)) || std::isnan(se[s].Sum())) continue;
      const double a = mesh.elements()[ElementOfSlot(static_cast<int>(s))].area;
      area += a;
      sq += se[s] * se[s] * a;
    }
    if (area > 0) {
      std_error_rms =
          JsonRgb(Rgb(std::sqrt(sq.r / area), std::sqrt(sq.g / area), std::sqrt(sq.b / area)));
      std_error_relative = JsonNumber(RelativeStdErrorRms(mesh, sol));
    }
  }
  JsonObject json;
  json.Add("scene", scene.source)
      .Add("method", sol.method)
      .Add("method_requested", facts.method_requested)
      .Add("method_reason", facts.method.reason)
      .Add("mean_albedo", facts.method.mean_albedo)
      .Add("formfactor", facts.formfactor)
      .AddRaw("seed", absl::StrCat(sol.seed))
      .Add("threads", facts.threads)
      .Add("surfaces", static_cast<int64_t>(scene.surfaces.size()))
      .Add("faces", static_cast<int64_t>(mesh.faces().size()))
      .Add("patches", static_cast<int64_t>(mesh.patches().size()))
      .Add("elements", static_cast<int64_t>(mesh.elements().size()))
      .Add("refine_tolerance", facts.refine_tolerance)
      .Add("refine_passes", facts.refine_passes)
      .Add("refine_mode", facts.refine_mode)
      .Add("element_size", mesh.element_size())
      .Add("rays", sol.rays)
      .Add("shots", sol.shots)
      .Add("seconds", sol.seconds)
      .Add("mesh_seconds", facts.mesh_seconds)
      .Add("rays_per_second", sol.seconds > 0 ? sol.rays / sol.seconds : 0)
      .Add("unshot_fraction", sol.unshot_fraction)
      .Add("tolerance", facts.tolerance)
      .Add("stop_reason", StopReasonName(facts.reason))
      .AddRaw("emitted_power", JsonRgb(sol.emitted_power))
      .AddRaw("absorbed_power", JsonRgb(sol.absorbed_power))
      .AddRaw("escaped_power", JsonRgb(sol.escaped_power))
      .AddRaw("unshot_power", JsonRgb(sol.unshot_power))
      .AddRaw("ambient", JsonRgb(sol.ambient))
      .Add("energy_balance_error", balance)
      .AddRaw("std_error_rms", std_error_rms)
      .AddRaw("std_error_rms_relative", std_error_relative)
      .Add("warnings", facts.warnings);
  std::vector<std::string> seconds, rays, unshot, error;
  for (const ConvergencePoint& c : facts.convergence) {
    seconds.push_back(JsonNumber(c.seconds));
    rays.push_back(absl::StrCat(c.rays));
    unshot.push_back(JsonNumber(c.unshot_fraction));
    error.push_back(std::isnan(c.std_error_relative) ? "null" : JsonNumber(c.std_error_relative));
  }
  json.AddRaw("convergence",
              absl::StrCat("{\"seconds\": [", absl::StrJoin(seconds, ", "), "], \"rays\": [",
                           absl::StrJoin(rays, ", "), "], \"unshot_fraction\": [",
                           absl::StrJoin(unshot, ", "), "], \"std_error_rms_relative\": [",
                           absl::StrJoin(error, ", "), "]}"));
  if (!facts.luminaires.empty()) {
    std::vector<std::string> items;
    for (const Luminaire& l : facts.luminaires) {
      const Photometry* p = l.photometry.get();
      items.push_back(absl::StrCat(
          "{\"file\": ", JsonQuote(l.file), ", \"format\": ", JsonQuote(p ? p->format : ""),
          ", \"position\": [", JsonNumber(l.position.x), ", ", JsonNumber(l.position.y), ", ",
          JsonNumber(l.position.z), "], \"flux_lm\": ", JsonRgb(l.Flux()),
          ", \"max_candela\": ", JsonNumber(p ? p->MaxIntensity() * l.multiplier : 0),
          ", \"lamp_lumens\": ", JsonNumber(p ? p->lamp_lumens : 0), ", \"opening_m\": [",
          JsonNumber(p ? p->width : 0), ", ", JsonNumber(p ? p->length : 0), "]}"));
    }
    json.AddRaw("luminaires", absl::StrCat("[", absl::StrJoin(items, ", "), "]"));
  }
  if (sol.method == "hierarchical") {
    json.Add("links", sol.links).Add("link_memory_bytes", sol.link_memory_bytes);
  }
  return WriteWholeFile(path, json.Format());
}

}  // namespace radiosity
