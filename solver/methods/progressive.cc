#include "solver/methods/progressive.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "tbb/parallel_for.h"
#include "tbb/parallel_pipeline.h"

namespace radiosity {

namespace {

// Magnitude of a (possibly negative, with overshooting) unshot power, for ranking and budgets.
double Magnitude(const Rgb& c) { return std::fabs(c.r) + std::fabs(c.g) + std::fabs(c.b); }

}  // namespace

ProgressiveSolver::ProgressiveSolver(const Scene& scene, const Mesh& mesh,
                                     const Visibility& visibility, const SolveOptions& options,
                                     const std::atomic<bool>* stop)
    : SolverBase(scene, mesh, visibility, options, stop, "progressive") {
  const auto& elements = mesh.elements();
  const size_t n = elements.size();
  unshot_.assign(2 * n, Rgb());
  exitant_.assign(2 * n, Rgb());
  hits_.assign(2 * n, 0.0);
  patch_unshot_.assign(2 * mesh.patches().size(), Rgb());
  for (int e = 0; e < static_cast<int>(n); ++e) {
    for (int side : {kFront, kBack}) {
      const Rgb power = sides().at(e, side).exitance * elements[e].area;
      if (power.IsZero()) continue;
      unshot_[Slot(e, side)] = power;
      exitant_[Slot(e, side)] = power;
      patch_unshot_[Slot(elements[e].patch, side)] += power;
    }
  }
  if (options.track_direct) {
    emitted_unshot_ = unshot_;
    incident_.assign(2 * n, Rgb());
    direct_in_.assign(2 * n, Rgb());
  }
  // Rays carry equal power: emitted / (rays per element x elements), Shirley 6.2.
  ray_power_ = emitted_.Sum() / (options.rays_per_element * static_cast<double>(n));
  progress_.unshot_fraction = 1;
}

ProgressiveSolver::~ProgressiveSolver() = default;

absl::Status ProgressiveSolver::Init() {
  if (options_.formfactor.method == "montecarlo") return absl::OkStatus();
  auto estimator = CreateFormFactorEstimator(mesh_, visibility_, options_.formfactor);
  if (!estimator.ok()) return estimator.status();
  estimator_ = *std::move(estimator);
  return absl::OkStatus();
}

absl::StatusOr<bool> ProgressiveSolver::StepWithRows(double w_max) {
  const auto& patches = mesh_.patches();
  std::vector<int> shooters;
  for (int s = 0; s < static_cast<int>(patch_unshot_.size()) &&
                  static_cast<int>(shooters.size()) < kRowsPerStep;
       ++s) {
    if (Magnitude(patch_unshot_[s]) >= w_max / 4) shooters.push_back(s);
  }
  std::vector<FormFactorRow> rows(shooters.size());
  arena().execute([&] {
    tbb::parallel_for(size_t{0}, shooters.size(), [&](size_t i) {
      const int p = PatchOfSlot(shooters[i]), side = SideOfSlot(shooters[i]);
      FormFactorSource source{patches[p].first_element, patches[p].num_elements, side};
      int64_t budget =
          std::max<int64_t>(1, std::llround(Magnitude(patch_unshot_[shooters[i]]) / ray_power_));
      estimator_->Estimate(source, budget,
                           StreamKey(options_.seed, static_cast<uint64_t>(progress_.step),
                                     2ULL << 40, static_cast<uint64_t>(shooters[i])),
                           stop_token(), &rows[i]);
    });
  });
  if (absl::Status s = visibility_.status(); !s.ok()) return s;
  if (ShouldStop()) {  // Rows may be incomplete: nothing was shot yet, so drop them all.
    EndStep(/*interrupted=*/true);
    return true;
  }
  for (size_t i = 0; i < shooters.size(); ++i) {
    const int shooter = shooters[i], p = PatchOfSlot(shooter), side = SideOfSlot(shooter);
    // Substructuring (Cohen et al. 1986): the patch shoots its power uniformly over its area.
    // Overshooting leaves (1 - omega) of it behind, negative.
    const Rgb power = patch_unshot_[shooter] * options_.overshoot;
    const double keep = 1 - options_.overshoot;
    const Patch& patch = patches[p];
    Rgb direct;
    for (int e = patch.first_element; e < patch.first_element + patch.num_elements; ++e) {
      unshot_[Slot(e, side)] *= keep;
      if (!emitted_unshot_.empty()) {
        direct += emitted_unshot_[Slot(e, side)] * options_.overshoot;
        emitted_unshot_[Slot(e, side)] *= keep;
      }
    }
    patch_unshot_[shooter] *= keep;
    // A row whose estimate drifted above 1 is scaled back: form factors from a patch never sum
    // above 1, or near rho = 1 the iteration would create energy.
    const double sum = rows[i].Sum();
    const double scale = sum > 1 ? 1 / sum : 1;
    for (size_t k = 0; k < rows[i].slots.size(); ++k) {
      const int slot = rows[i].slots[k];
      Deposit(sides().exists(slot) ? slot : kAbsorbedBack, power * (rows[i].f[k] * scale),
              direct * (rows[i].f[k] * scale));
    }
    escaped_ += power * (1 - sum * scale);
    progress_.rays += rows[i].rays;
  }
  progress_.shots += static_cast<int64_t>(shooters.size());
  EndStep(/*interrupted=*/false);
  double unshot_total = 0;
  for (const Rgb& u : patch_unshot_) unshot_total += Magnitude(u);
  progress_.unshot_fraction = unshot_total / emitted_.Sum();
  if (progress_.unshot_fraction <= options_.tolerance) done_ = true;
  return !done_;
}

void ProgressiveSolver::TraceChunk(int64_t chunk, int64_t total_rays, RayResult* out) const {
  Rng rng(StreamKey(options_.seed, static_cast<uint64_t>(progress_.step),
                    static_cast<uint64_t>(chunk)));
  const int64_t begin = chunk * kChunk;
  const int64_t end = std::min(total_rays, begin + kChunk);
  // The group holding ray `begin`: groups are sorted by first_ray.
  auto it = std::upper_bound(groups_.begin(), groups_.end(), begin,
                             [](int64_t r, const RayGroup& g) { return r < g.first_ray; });
  int g = static_cast<int>(it - groups_.begin()) - 1;
  const auto& faces = mesh_.faces();
  for (int64_t r = begin; r < end; ++r) {
    while (r >= groups_[g].first_ray + groups_[g].count) ++g;
    const RayGroup& group = groups_[g];
    int half = 0;
    double r1 = rng.Uniform(), r2 = rng.Uniform(), r3 = rng.Uniform();
    Vec3 origin = mesh_.SampleElement(group.element, r1, r2, r3, &half);
    const int source_face = mesh_.elements()[group.element].face;
    Vec3 normal = faces[source_face].normal[half];
    if (group.side == 1) normal = -normal;
    Vec3 dir = CosineDirection(normal, rng.Uniform(), rng.Uniform());
    // The shooting face is skipped (a planar face cannot see itself; the slight fold of a
    // non-planar quad is neglected), so rays start exactly on the surface.
    Hit hit = visibility_.Intersect(origin, dir, 0, 1e30, source_face);
    RayResult& res = out[r - begin];
    res.group = g;
    if (!hit.valid()) {
      res.slot = kEscaped;
      continue;
    }
    const MeshFace& f = faces[hit.face];
    int e = mesh_.FindElement(hit.face, hit.u, hit.v);
    bool front = Dot(dir, f.normal[f.Half(hit.u, hit.v)]) < 0;
    int slot = Slot(e, front ? 0 : 1);
    res.slot = e >= 0 && sides().exists(slot) ? slot : kAbsorbedBack;
  }
}

void ProgressiveSolver::Deposit(int slot, const Rgb& power, const Rgb& direct) {
  if (slot == kEscaped) {
    escaped_ += power;
    return;
  }
  if (slot == kAbsorbedBack) {
    absorbed_ += power;
    return;
  }
  const int element = ElementOfSlot(slot);
  const int patch = mesh_.elements()[element].patch;
  hits_[slot] += 1;
  if (!incident_.empty()) {
    incident_[slot] += power;
    direct_in_[slot] += direct;
  }
  const SideRule& rule = sides()[slot];
  Rgb reflected = rule.reflectance * power;
  Rgb transmitted = rule.transmittance * power;
  unshot_[slot] += reflected;
  exitant_[slot] += reflected;
  patch_unshot_[Slot(patch, SideOfSlot(slot))] += reflected;
  if (!transmitted.IsZero()) {
    const int other = OtherSide(slot);
    unshot_[other] += transmitted;
    exitant_[other] += transmitted;
    patch_unshot_[Slot(patch, SideOfSlot(other))] += transmitted;
  }
  absorbed_ += power - reflected - transmitted;
}

absl::StatusOr<bool> ProgressiveSolver::Step() {
  if (done_) return false;
  const auto& patches = mesh_.patches();
  const auto& elements = mesh_.elements();
  const int num_shooters = static_cast<int>(patch_unshot_.size());

  // Southwell order: shooters with the most unshot power first, in bands of a factor 4 below the
  // largest, until the step holds kMaxRaysPerStep rays (or fewer when the ray budget is nearly
  // spent).
  double unshot_total = 0, w_max = 0;
  for (int s = 0; s < num_shooters; ++s) {
    double w = Magnitude(patch_unshot_[s]);
    unshot_total += w;
    w_max = std::max(w_max, w);
  }
  progress_.unshot_fraction = unshot_total / emitted_.Sum();
  if (progress_.unshot_fraction <= options_.tolerance || w_max <= 0) {
    done_ = true;
    return false;
  }
  if (estimator_) return StepWithRows(w_max);
  int64_t cap = kMaxRaysPerStep;
  if (options_.max_rays > 0)
    cap = std::min(cap, std::max<int64_t>(1, options_.max_rays - progress_.rays));

  struct Shot {
    int shooter;
    int64_t rays;
    double fraction;  // Of the shooter's unshot power shot now (< 1 only when the step is full).
  };
  std::vector<Shot> shots;
  int64_t step_rays = 0;
  double hi = std::numeric_limits<double>::infinity();
  for (double lo = w_max / 4; step_rays < cap && hi > w_max * 1e-30; hi = lo, lo /= 4) {
    for (int s = 0; s < num_shooters && step_rays < cap; ++s) {
      double w = Magnitude(patch_unshot_[s]);
      if (!(w >= lo && w < hi) || w <= 0) continue;
      int64_t n = std::max<int64_t>(1, std::llround(options_.overshoot * w / ray_power_));
      int64_t take = std::min(n, cap - step_rays);
      shots.push_back({s, take, take == n ? 1.0 : static_cast<double>(take) / n});
      step_rays += take;
    }
  }

  // Spread each shot over the shooter's elements by systematic sampling of their weights (unshot
  // power, or area for the uniform substructuring of the chapter), so every ray carries the same
  // share of its element's power and the power shot is exactly the power removed.
  groups_.clear();
  int64_t ray_cursor = 0;
  for (const Shot& shot : shots) {
    const int p = PatchOfSlot(shot.shooter), side = SideOfSlot(shot.shooter);
    const Patch& patch = patches[p];
    const Rgb patch_power = patch_unshot_[shot.shooter];
    const bool track = !emitted_unshot_.empty();
    Rgb patch_emitted;
    if (track && !options_.weighted_shooting) {
      for (int e = patch.first_element; e < patch.first_element + patch.num_elements; ++e) {
        patch_emitted += emitted_unshot_[Slot(e, side)];
      }
    }
    double total_weight = 0;
    for (int e = patch.first_element; e < patch.first_element + patch.num_elements; ++e) {
      total_weight +=
          options_.weighted_shooting ? Magnitude(unshot_[Slot(e, side)]) : elements[e].area;
    }
    Rng rng(StreamKey(options_.seed, static_cast<uint64_t>(progress_.step), 1ULL << 40,
                      static_cast<uint64_t>(shot.shooter)));
    const double xi = rng.Uniform();
    double cumulative = 0;
    Rgb remaining;
    for (int e = patch.first_element; e < patch.first_element + patch.num_elements; ++e) {
      const int slot = Slot(e, side);
      double w = options_.weighted_shooting ? Magnitude(unshot_[slot]) : elements[e].area;
      double lo = cumulative / total_weight * shot.rays - xi;
      cumulative += w;
      double hi_pos = cumulative / total_weight * shot.rays - xi;
      int64_t count = static_cast<int64_t>(std::ceil(hi_pos) - std::ceil(lo));
      if (w <= 0) count = 0;
      Rgb share = options_.weighted_shooting ? unshot_[slot]
                                             : patch_power * (elements[e].area / patch.area);
      Rgb keep = options_.weighted_shooting ? unshot_[slot] : share;
      // The same for the emission's part of it (track_direct).
      Rgb share_emitted;
      if (track) {
        share_emitted = options_.weighted_shooting
                            ? emitted_unshot_[slot]
                            : patch_emitted * (elements[e].area / patch.area);
      }
      Rgb keep_emitted = share_emitted;
      if (count > 0) {
        // Overshooting (omega > 1) shoots more than the unshot power; the excess stays behind as
        // negative unshot power, shot later as negative rays (successive over-relaxation of the
        // Southwell iteration; Feda & Purgathofer 1992).
        const double amount = shot.fraction * options_.overshoot;
        groups_.push_back({e, side, ray_cursor, count, share * (amount / count),
                           share_emitted * (amount / count)});
        ray_cursor += count;
        keep = share * (1 - amount);
        keep_emitted = share_emitted * (1 - amount);
      }
      unshot_[slot] = keep;
      if (track) emitted_unshot_[slot] = keep_emitted;
      remaining += keep;
    }
    patch_unshot_[shot.shooter] = remaining;
  }
  const int64_t total_rays = ray_cursor;

  // Trace in fixed chunks, each with its own random stream, and merge them in order: a pipeline
  // whose last stage deposits chunk k (serially, in ray order, so results do not depend on the
  // thread count) while later chunks are still being traced, instead of after all of them. No
  // chunk starts once the stop flag is raised or the deadline has passed.
  results_.resize(static_cast<size_t>(total_rays));
  const int64_t chunks = (total_rays + kChunk - 1) / kChunk;
  int64_t next_chunk = 0;
  arena().execute([&] {
    tbb::parallel_pipeline(
        static_cast<size_t>(4 * arena().max_concurrency()),
        tbb::make_filter<void, int64_t>(tbb::filter_mode::serial_in_order,
                                        [&](tbb::flow_control& fc) -> int64_t {
                                          if (next_chunk >= chunks || ShouldStop()) fc.stop();
                                          return next_chunk++;
                                        }) &
            tbb::make_filter<int64_t, int64_t>(tbb::filter_mode::parallel,
                                               [&](int64_t c) {
                                                 TraceChunk(c, total_rays,
                                                            results_.data() + c * kChunk);
                                                 return c;
                                               }) &
            tbb::make_filter<int64_t, void>(tbb::filter_mode::serial_in_order, [&](int64_t c) {
              const int64_t end = std::min(total_rays, (c + 1) * kChunk);
              for (int64_t r = c * kChunk; r < end; ++r) {
                const RayGroup& group = groups_[results_[r].group];
                Deposit(results_[r].slot, group.power, group.direct);
              }
            }));
  });
  if (absl::Status s = visibility_.status(); !s.ok()) return s;
  // The input stage stopped after next_chunk - 1 chunks, all of them traced and deposited.
  const int64_t traced = std::min(total_rays, (next_chunk - 1) * kChunk);
  progress_.rays += traced;
  if (traced < total_rays) {
    ReturnUntraced(traced);
    EndStep(/*interrupted=*/true);
    return true;
  }

  progress_.shots += static_cast<int64_t>(shots.size());
  EndStep(/*interrupted=*/false);
  unshot_total = 0;
  for (int s = 0; s < num_shooters; ++s) unshot_total += Magnitude(patch_unshot_[s]);
  progress_.unshot_fraction = unshot_total / emitted_.Sum();
  if (progress_.unshot_fraction <= options_.tolerance) done_ = true;
  return !done_;
}

void ProgressiveSolver::ReturnUntraced(int64_t first_ray) {
  const auto& elements = mesh_.elements();
  for (const RayGroup& g : groups_) {
    const int64_t begin = std::max(first_ray, g.first_ray);
    const int64_t count = g.first_ray + g.count - begin;
    if (count <= 0) continue;
    const int slot = Slot(g.element, g.side);
    const Rgb power = g.power * static_cast<double>(count);
    unshot_[slot] += power;
    patch_unshot_[Slot(elements[g.element].patch, g.side)] += power;
    if (!emitted_unshot_.empty()) emitted_unshot_[slot] += g.direct * static_cast<double>(count);
  }
}

Solution ProgressiveSolver::Final() const {
  Solution sol = NewSolution();
  const auto& elements = mesh_.elements();
  sol.radiosity.assign(exitant_.size(), Rgb());
  for (size_t s = 0; s < exitant_.size(); ++s) {
    if (sides().exists(static_cast<int>(s))) {
      sol.radiosity[s] = exitant_[s] / elements[ElementOfSlot(static_cast<int>(s))].area;
    }
  }
  double magnitude = 0;
  for (const Rgb& u : patch_unshot_) {
    sol.unshot_power += u;
    magnitude += Magnitude(u);
  }
  // Hit counts measure Monte Carlo noise; rows from other estimators have none to speak of.
  if (!estimator_) sol.hits = hits_;
  if (!incident_.empty()) {
    sol.irradiance.assign(incident_.size(), Rgb());
    sol.direct_irradiance.assign(incident_.size(), Rgb());
    for (size_t s = 0; s < incident_.size(); ++s) {
      const double area = elements[ElementOfSlot(static_cast<int>(s))].area;
      sol.irradiance[s] = incident_[s] / area;
      sol.direct_irradiance[s] = direct_in_[s] / area;
    }
  }
  sol.unshot_fraction = magnitude / emitted_.Sum();
  return sol;
}

Solution ProgressiveSolver::Snapshot() const {
  Solution sol = Final();
  if (!options_.ambient || done_) return sol;
  // Ambient term for previews (Cohen, Chen, Wallace & Greenberg 1988, eq. 9-10): the unshot power
  // spread uniformly over the scene and interreflected with the area-mean reflectance,
  //   ambient = (sum_j U_j / A_total) / (1 - rho_mean),  displayed B_i = B_i + rho_i ambient.
  // It approximates light not yet propagated and vanishes as the unshot power does; results
  // (Final) never include it.
  const auto& elements = mesh_.elements();
  double area = 0;
  Rgb rho_area;
  for (size_t s = 0; s < exitant_.size(); ++s) {
    const SideRule& rule = sides()[static_cast<int>(s)];
    if (!rule.exists) continue;
    area += elements[ElementOfSlot(static_cast<int>(s))].area;
    rho_area += rule.reflectance * elements[ElementOfSlot(static_cast<int>(s))].area;
  }
  Rgb ambient;
  for (int c = 0; c < 3; ++c) {
    double rho_mean = rho_area[c] / area;
    ambient[c] = sol.unshot_power[c] / area / std::max(1e-6, 1 - rho_mean);
  }
  for (size_t s = 0; s < exitant_.size(); ++s) {
    const SideRule& rule = sides()[static_cast<int>(s)];
    if (rule.exists) sol.radiosity[s] += rule.reflectance * ambient;
  }
  return sol;
}

}  // namespace radiosity
