#include "solver/methods/progressive.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>

#include "solver/geometry/plane_fit.h"
#include "solver/geometry/rect_sampler.h"
#include "solver/transport/openness.h"
#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "solver/transport/sobol.h"
#include "tbb/parallel_for.h"
#include "tbb/parallel_pipeline.h"

namespace radiosity {

namespace {

// Magnitude of a (possibly negative, with overshooting) unshot power, for ranking and budgets.
double Magnitude(const Rgb& c) { return std::fabs(c.r) + std::fabs(c.g) + std::fabs(c.b); }

Rgb Sqrt(const Rgb& c) { return Rgb(std::sqrt(c.r), std::sqrt(c.g), std::sqrt(c.b)); }

}  // namespace

bool PatchesFineEnough(const Mesh& mesh) {
  double largest = 0;
  for (const MeshFace& f : mesh.faces()) {
    largest = std::max({largest, f.len_u / f.pu, f.len_v / f.pv});
  }
  return largest <= kPatchLevelMaxSize * mesh.scale();
}

namespace {}  // namespace

ProgressiveSolver::ProgressiveSolver(const Scene& scene, const Mesh& mesh,
                                     const Visibility& visibility, const SolveOptions& options,
                                     const std::atomic<bool>* stop)
    : SolverBase(scene, mesh, visibility, options, stop, "progressive"), specular_(scene) {
  const auto& elements = mesh.elements();
  const size_t n = elements.size();
  unshot_.assign(2 * n, Rgb());
  exitant_.assign(2 * n, Rgb());
  hits_.assign(2 * n, 0.0);
  sequence_used_.assign(2 * n, 0);
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

  const size_t patch_slots = 2 * mesh.patches().size();
  sobol_ = options.formfactor.sampling != "random";
  patch_level_ = options.formfactor.method == "montecarlo" && options.indirect == "patch" &&
                 PatchesFineEnough(mesh);
  element_sq_.assign(2 * n, Rgb());
  if (patch_level_) {
    patch_level_unshot_.assign(patch_slots, Rgb());
    patch_level_exitant_.assign(patch_slots, Rgb());
    patch_level_sq_.assign(patch_slots, Rgb());
    tally_exitant_.assign(2 * n, Rgb());
    tally_sq_.assign(2 * n, Rgb());
  }
  // Direct light from agglomerated emitters is shot: computing it costs receivers x emitting faces
  // quadratures, and a tessellated lamp has many faces.
  bool agglomerated_emitter = false;
  for (int e = 0; e < static_cast<int>(n) && mesh.agglomerated(); ++e) {
    agglomerated_emitter =
        agglomerated_emitter || (elements[e].num_members > 0 &&
                                 (sides().at(e, kFront).Emits() || sides().at(e, kBack).Emits()));
  }
  if (options.direct == "computed" && !agglomerated_emitter) {
    DirectOptions d;
    d.shadow_rays = options.direct_shadow_rays;
    d.max_shadow_rays = std::min(65536, 16 * options.direct_shadow_rays);
    d.seed = options.seed;
    // With specular surfaces, the hybrid direct step (see the header): images in planar mirrors
    // too (form-factor rows absorb the specular parts instead).
    hybrid_ = mesh.sides().any_specular() && options.formfactor.method == "montecarlo";
    d.mirror_images = hybrid_;
    direct_ = std::make_unique<DirectIrradiance>(mesh, visibility, d, static_cast<int64_t>(n));
    if (direct_->emitters().empty()) {
      direct_.reset();
      hybrid_ = false;
    } else {
      // The emission's part of the unshot power is followed (as with track_direct): rays carry
      // it as RayGroup::direct.
      if (emitted_unshot_.empty()) emitted_unshot_ = unshot_;
      direct_left_ = true;
      direct_done_.assign(n, 0);
      held_.assign(2 * n, Rgb());
      placeholder_sq_.assign(2 * n, Rgb());
      direct_std_error_.assign(2 * n, Rgb());
      if (options.track_direct) held_straight_.assign(2 * n, Rgb());
    }
  }
  sky_pending_ = options.sky.enabled() || !options.luminaires.empty();
  progress_.direct_fraction = direct_ || sky_pending_ ? 0 : 1;
  // Light straight from an emitter the direct step does not compute is received per element, as
  // its shadows are sharp; but from an agglomerated (tessellated) emitter it is received per
  // patch like reflected light, PatchShape's chi-square falling back to the elements' tallies
  // where a shadow edge crosses a patch: such a lamp lights much of the scene, and per element
  // its light would carry the noise of each element's own few rays.
  element_level_shooter_.assign(patch_slots, 0);
  for (int p = 0; p < static_cast<int>(mesh.patches().size()); ++p) {
    const Patch& patch = mesh.patches()[p];
    if (patch.num_elements == 0) continue;
    for (int side : {kFront, kBack}) {
      if (sides().at(patch.first_element, side).Emits() &&
          !(direct_ && direct_->Computes(patch.face, side)) &&
          elements[patch.first_element].num_members == 0) {
        element_level_shooter_[Slot(p, side)] = 1;
      }
    }
  }
}

bool ProgressiveSolver::SaveState(StateWriter* out) const {
  SaveBase(out);
  out->Put("progressive.flags", std::array<bool, 6>{direct_left_, sky_pending_, sobol_,
                                                    patch_level_, done_, last_was_block_});
  out->Put("progressive.ray_power", ray_power_);
  out->Put("progressive.direct_next", direct_next_);
  out->Put("progressive.sky_next", sky_next_);
  out->PutVector("progressive.sky_face_power", sky_face_power_);
  out->PutVector("progressive.sky_face_area", sky_face_area_);
  out->PutVector("progressive.unshot", unshot_);
  out->PutVector("progressive.exitant", exitant_);
  out->PutVector("progressive.hits", hits_);
  out->PutVector("progressive.patch_unshot", patch_unshot_);
  out->PutVector("progressive.emitted_unshot", emitted_unshot_);
  out->PutVector("progressive.incident", incident_);
  out->PutVector("progressive.direct_in", direct_in_);
  out->PutVector("progressive.direct_std_error", direct_std_error_);
  out->PutVector("progressive.sky_std_error", sky_std_error_);
  out->PutVector("progressive.patch_level_unshot", patch_level_unshot_);
  out->PutVector("progressive.patch_level_exitant", patch_level_exitant_);
  out->PutVector("progressive.patch_level_sq", patch_level_sq_);
  out->PutVector("progressive.tally_exitant", tally_exitant_);
  out->PutVector("progressive.tally_sq", tally_sq_);
  out->PutVector("progressive.openness", openness_);
  out->PutVector("progressive.patch_open_area", patch_open_area_);
  out->PutVector("progressive.element_sq", element_sq_);
  out->PutVector("progressive.element_level_shooter", element_level_shooter_);
  out->PutVector("progressive.direct_order", direct_order_);
  out->PutVector("progressive.direct_done", direct_done_);
  out->PutVector("progressive.held", held_);
  out->PutVector("progressive.placeholder_sq", placeholder_sq_);
  out->PutVector("progressive.held_straight", held_straight_);
  out->PutVector("progressive.sequence_used", sequence_used_);
  out->Put("progressive.arrived", arrived_);
  out->Put("progressive.loan", loan_);
  out->Put("progressive.direct_absorbed", direct_absorbed_);
  out->Put("progressive.shot_rays", shot_rays_);
  out->Put("progressive.sent_on", sent_on_);
  return true;
}

absl::Status ProgressiveSolver::RestoreState(StateReader* in) {
  if (absl::Status st = RestoreBase(in); !st.ok()) return st;
  std::array<bool, 6> flags{};
  if (absl::Status st = in->Get("progressive.flags", &flags); !st.ok()) return st;
  // What the constructor derived from the options and the mesh must agree.
  if (flags[2] != sobol_ || flags[3] != patch_level_ || (flags[0] && !direct_left_) ||
      (flags[1] && !sky_pending_)) {
    return absl::FailedPreconditionError("the state is of other solve options");
  }
  direct_left_ = flags[0];
  sky_pending_ = flags[1];
  done_ = flags[4];
  last_was_block_ = flags[5];
  for (absl::Status st : {
           in->Get("progressive.ray_power", &ray_power_),
           in->Get("progressive.direct_next", &direct_next_),
           in->Get("progressive.sky_next", &sky_next_),
           in->GetAnyVector("progressive.sky_face_power", &sky_face_power_),
           in->GetAnyVector("progressive.sky_face_area", &sky_face_area_),
           in->GetVector("progressive.unshot", &unshot_),
           in->GetVector("progressive.exitant", &exitant_),
           in->GetVector("progressive.hits", &hits_),
           in->GetVector("progressive.patch_unshot", &patch_unshot_),
           in->GetVector("progressive.emitted_unshot", &emitted_unshot_),
           in->GetVector("progressive.incident", &incident_),
           in->GetVector("progressive.direct_in", &direct_in_),
           in->GetVector("progressive.direct_std_error", &direct_std_error_),
           in->GetAnyVector("progressive.sky_std_error", &sky_std_error_),
           in->GetVector("progressive.patch_level_unshot", &patch_level_unshot_),
           in->GetVector("progressive.patch_level_exitant", &patch_level_exitant_),
           in->GetVector("progressive.patch_level_sq", &patch_level_sq_),
           in->GetVector("progressive.tally_exitant", &tally_exitant_),
           in->GetVector("progressive.tally_sq", &tally_sq_),
           in->GetAnyVector("progressive.openness", &openness_),
           in->GetAnyVector("progressive.patch_open_area", &patch_open_area_),
           in->GetVector("progressive.element_sq", &element_sq_),
           in->GetVector("progressive.element_level_shooter", &element_level_shooter_),
           in->GetAnyVector("progressive.direct_order", &direct_order_),
           in->GetVector("progressive.direct_done", &direct_done_),
           in->GetVector("progressive.held", &held_),
           in->GetVector("progressive.placeholder_sq", &placeholder_sq_),
           in->GetVector("progressive.held_straight", &held_straight_),
           in->GetVector("progressive.sequence_used", &sequence_used_),
           in->Get("progressive.arrived", &arrived_),
           in->Get("progressive.loan", &loan_),
           in->Get("progressive.direct_absorbed", &direct_absorbed_),
           in->Get("progressive.shot_rays", &shot_rays_),
           in->Get("progressive.sent_on", &sent_on_),
       }) {
    if (!st.ok()) return st;
  }
  const size_t slots = unshot_.size(), patch_slots = patch_unshot_.size();
  if (!(openness_.empty() || openness_.size() == slots) ||
      !(patch_open_area_.empty() || patch_open_area_.size() == patch_slots) ||
      !(sky_std_error_.empty() || sky_std_error_.size() == slots) || direct_next_ < 0 ||
      direct_next_ > static_cast<int64_t>(direct_order_.size())) {
    return absl::FailedPreconditionError("the state's measured tallies are of another mesh");
  }
  for (int32_t e : direct_order_) {
    if (e < 0 || static_cast<size_t>(e) >= direct_done_.size()) {
      return absl::DataLossError("the state's direct-step order names no element of the mesh");
    }
  }
  direct_ahead_.clear();
  return in->Finish();
}

bool ProgressiveSolver::DirectBlockDue() const {
  if (!direct_left_) return false;
  // Alternate with shooting steps while there is anything to shoot.
  return !last_was_block_ || UnshotMagnitude() <= options_.tolerance * emitted_.Sum();
}

std::vector<int32_t> ProgressiveSolver::DirectOrder() const {
  const auto& elements = mesh_.elements();
  std::vector<std::pair<double, int32_t>> keyed;
  for (int e = 0; e < static_cast<int>(elements.size()); ++e) {
    // Elements that neither reflect nor transmit come last, and only to record their irradiance
    // (track_direct): their light goes no further.
    const bool receives = sides().at(e, kFront).Receives() || sides().at(e, kBack).Receives();
    if (!receives && incident_.empty()) continue;
    // The placeholder's relative variance (of luminance-like sums); one where nothing arrived.
    double value = 0, variance = 0;
    for (int side : {kFront, kBack}) {
      value += held_[Slot(e, side)].Sum();
      variance += placeholder_sq_[Slot(e, side)].Sum();
    }
    keyed.push_back({!receives ? -1.0 : value > 0 ? variance / (value * value) : 1.0, e});
  }
  std::stable_sort(keyed.begin(), keyed.end(),
                   [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<int32_t> order(keyed.size());
  for (size_t i = 0; i < keyed.size(); ++i) order[i] = keyed[i].second;
  return order;
}

absl::StatusOr<bool> ProgressiveSolver::DirectBlock() {
  last_was_block_ = true;
  if (direct_order_.empty() && direct_next_ == 0) direct_order_ = DirectOrder();
  const int64_t total = static_cast<int64_t>(direct_order_.size());
  // Enough chunks computed ahead for this block: in batches of one chunk per thread, then two
  // (how many are computed ahead never changes which are applied). The batch stays small because
  // the cost of elements varies by orders of magnitude down the order: a ceiling behind its lamps
  // costs nothing, the walls below them 10 ms each, and a batch doubled on the cheap ones would
  // hold the stream for seconds.
  int64_t work = 0, ahead = 0;
  for (const DirectChunk& c : direct_ahead_) {
    if (work >= kDirectBlockWork) break;
    work += c.work;
    ++ahead;
  }
  size_t batch = static_cast<size_t>(arena().max_concurrency());
  while (work < kDirectBlockWork) {
    const int64_t first = direct_next_ + static_cast<int64_t>(direct_ahead_.size()) * kDirectChunk;
    if (first >= total) break;
    const size_t count = static_cast<size_t>(
        std::min<int64_t>(total - first, static_cast<int64_t>(batch) * kDirectChunk));
    DirectElements d;
    arena().execute(
        [&] { d = direct_->ForElementList(direct_order_.data() + first, count, stop_token()); });
    if (absl::Status s = visibility_.status(); !s.ok()) return s;
    if (!d.complete) {  // Nothing of this block was applied yet: the step is simply not done.
      EndStep(/*interrupted=*/true);
      return true;
    }
    // Split into chunks, each with its work (shadow rays and quadrature evaluations): the work
    // decides where a block ends, so that does not depend on the threads.
    for (size_t c = 0; c < count; c += kDirectChunk) {
      const size_t m = std::min<size_t>(kDirectChunk, count - c);
      DirectChunk chunk;
      auto slice = [&](const std::vector<Rgb>& v) {
        return v.empty() ? std::vector<Rgb>()
                         : std::vector<Rgb>(v.begin() + 2 * c, v.begin() + 2 * (c + m));
      };
      chunk.values.irradiance = slice(d.irradiance);
      chunk.values.std_error = slice(d.std_error);
      chunk.values.via_mirrors = slice(d.via_mirrors);
      for (size_t i = c; i < c + m; ++i) {
        chunk.work += d.work[i];
        chunk.rays += d.element_rays[i];
      }
      chunk.work = std::max<int64_t>(1, chunk.work);
      direct_ahead_.push_back(std::move(chunk));
      if (work < kDirectBlockWork) {
        work += direct_ahead_.back().work;
        ++ahead;
      }
    }
    batch = 2 * static_cast<size_t>(arena().max_concurrency());
  }
  // Apply the block's chunks in order.
  for (int64_t c = 0; c < ahead; ++c) {
    const DirectElements& v = direct_ahead_[static_cast<size_t>(c)].values;
    // The rays of chunks computed ahead count once applied: a checkpoint drops the chunks
    // computed ahead (they are computed again after a restart), so that progress and a ray
    // budget do not depend on when it was taken.
    progress_.rays += direct_ahead_[static_cast<size_t>(c)].rays;
    const size_t m = v.irradiance.size() / 2;
    for (size_t i = 0; i < m; ++i) {
      const Rgb none[2];
      ApplyDirect(direct_order_[static_cast<size_t>(direct_next_)], &v.irradiance[2 * i],
                  &v.std_error[2 * i], v.via_mirrors.empty() ? none : &v.via_mirrors[2 * i]);
      ++direct_next_;
    }
  }
  direct_ahead_.erase(direct_ahead_.begin(), direct_ahead_.begin() + ahead);
  direct_left_ = direct_next_ < total;
  progress_.shots += 1;
  return EndCompleteStep();
}

void ProgressiveSolver::ApplyDirect(int e, const Rgb h[2], const Rgb se[2], const Rgb m[2]) {
  const double area = mesh_.elements()[e].area;
  for (int side : {kFront, kBack}) {
    const int slot = Slot(e, side);
    if (!sides().exists(slot)) {  // Its light is absorbed either way.
      direct_absorbed_ += h[side] * area;
      continue;
    }
    const Rgb delta = h[side] * area - held_[slot];
    held_[slot] = h[side] * area;
    Rgb straight;
    if (!held_straight_.empty()) {
      straight = (h[side] - m[side]) * area - held_straight_[slot];
      held_straight_[slot] = (h[side] - m[side]) * area;
    }
    // The rays carry the specular part of what arrived on; rows absorb it.
    Deposit(slot, delta, straight, /*patch_level=*/false, /*ray=*/false,
            hybrid_ ? SpecularPart::kTraced : SpecularPart::kAbsorbed);
    loan_ += hybrid_ ? delta - sides()[slot].specular * delta : delta;
    placeholder_sq_[slot] = Rgb();
    direct_std_error_[slot] = se[side];
  }
  direct_done_[static_cast<size_t>(e)] = 1;
}

double ProgressiveSolver::ProjectedRays() const {
  const double nominal = options_.rays_per_element * static_cast<double>(mesh_.elements().size());
  if (static_cast<double>(shot_rays_) < nominal || !(arrived_.Sum() > 0)) return shot_rays_;
  // The unshot power and all its bounces, at the reflectance measured so far.
  const double rho = std::min(sent_on_.Sum() / arrived_.Sum(), 1 - 1e-9);
  return static_cast<double>(shot_rays_) + UnshotMagnitude() / ray_power_ / (1 - rho);
}

void ProgressiveSolver::CountSentOn(int slot, const Rgb& power) {
  arrived_ += power;
  if (slot >= 0) sent_on_ += (sides()[slot].reflectance + sides()[slot].transmittance) * power;
}

void ProgressiveSolver::DepositCovered(int slot, const Rgb& emission, bool straight, bool ray) {
  const SpecularPart specular = ray ? SpecularPart::kTraced : SpecularPart::kAbsorbed;
  if (slot < 0) {  // Escaped, or absorbed at the back of a face.
    Deposit(slot, emission, straight ? emission : Rgb(), false, ray, specular);
    return;
  }
  if (direct_done_[static_cast<size_t>(ElementOfSlot(slot))]) {
    loan_ -= ray ? emission - sides()[slot].specular * emission : emission;
    return;
  }
  held_[slot] += emission;
  if (straight && !held_straight_.empty()) held_straight_[slot] += emission;
  if (ray) hits_[slot] += 1;
  // Its standard error is the placeholder's own until the block replaces it.
  const Rgb r = sides()[slot].reflectance * emission;
  const Rgb t = sides()[slot].transmittance * emission;
  placeholder_sq_[slot] += r * r;
  placeholder_sq_[OtherSide(slot)] += t * t;
  Deposit(slot, emission, straight ? emission : Rgb(), /*patch_level=*/false, /*ray=*/false,
          specular);
}

std::vector<int32_t> ProgressiveSolver::StrideOrder(size_t n) {
  // Element k at position (k x stride) mod n, a stride coprime to n near its golden section.
  std::vector<int32_t> order(n);
  uint64_t stride =
      std::max<uint64_t>(1, std::llround(0.6180339887498949 * static_cast<double>(n)));
  while (n > 1 && std::gcd(stride, static_cast<uint64_t>(n)) != 1) ++stride;
  for (size_t k = 0; k < n; ++k) {
    order[static_cast<size_t>((static_cast<unsigned __int128>(k) * stride) % n)] =
        static_cast<int32_t>(k);
  }
  return order;
}

absl::StatusOr<bool> ProgressiveSolver::SkyStep() {
  const auto& elements = mesh_.elements();
  const size_t n = elements.size();
  if (sky_order_.size() != n) sky_order_ = StrideOrder(n);
  // A block of about kMaxRaysPerStep sample rays.
  const int64_t per_element =
      2 * ((options_.sky.enabled() ? options_.sky.samples : 0) +
           options_.luminaire_samples * static_cast<int64_t>(options_.luminaires.size()));
  const size_t block = static_cast<size_t>(
      std::clamp<int64_t>(kMaxRaysPerStep / std::max<int64_t>(1, per_element), 16, 1 << 20));
  const ElementRange range{&sky_order_, static_cast<size_t>(sky_next_),
                           std::min(n, static_cast<size_t>(sky_next_) + block)};
  ElementIrradiance sky, lum;
  arena().execute([&] {
    sky = SkyIrradiance(mesh_, visibility_, options_.sky, options_.seed, stop_token(), range);
    if (sky.complete) {
      lum = LuminaireIrradiance(mesh_, visibility_, options_.luminaires, options_.luminaire_samples,
                                options_.seed, stop_token(), range);
    }
  });
  if (absl::Status s = visibility_.status(); !s.ok()) return s;
  if (!sky.complete || !lum.complete) {  // Nothing of the block was deposited: it is not done.
    EndStep(/*interrupted=*/true);
    return true;
  }
  if (sky_std_error_.empty()) sky_std_error_.assign(2 * n, Rgb());
  if (sky_face_power_.empty()) {
    sky_face_power_.assign(2 * mesh_.faces().size(), Rgb());
    sky_face_area_.assign(2 * mesh_.faces().size(), 0.0);
  }
  // What reaches a side that reflects or transmits enters the scene: the books count it as
  // emitted. Light the sky sends onto absorbing sides, or past the scene, is not counted.
  Rgb arrived;
  for (size_t i = 0; i < range.size(n); ++i) {
    const int e = range.Element(i);
    for (int side : {kFront, kBack}) {
      const int s = Slot(e, side);
      // One table: the sky's light and the luminaires', their standard errors in quadrature.
      const Rgb h = sky.irradiance[s] + lum.irradiance[s];
      for (int c = 0; c < 3; ++c) {
        sky_std_error_[s][c] = std::hypot(sky.std_error[s][c], lum.std_error[s][c]);
      }
      sky_face_power_[Slot(elements[e].face, side)] += h * elements[e].area;
      sky_face_area_[Slot(elements[e].face, side)] += elements[e].area;
      if (!sides().exists(s) || !(sides()[s].Receives() || sides()[s].Specular())) continue;
      const Rgb power = h * elements[e].area;
      if (power.IsZero()) continue;
      arrived += power;
      Deposit(s, power, power, /*patch_level=*/false, /*ray=*/false, SpecularPart::kDiffuse);
    }
  }
  emitted_ += arrived;
  progress_.rays += sky.rays + lum.rays;
  progress_.shots += 1;
  sky_next_ = static_cast<int64_t>(range.last);
  sky_pending_ = static_cast<size_t>(sky_next_) < n;
  // Rays carry equal power: the emitted power now includes the sky's.
  ray_power_ = emitted_.Sum() / (options_.rays_per_element * static_cast<double>(n));
  if (!sky_pending_ && !(emitted_.Sum() > 0)) {  // Neither emitters nor sky light on anything
                                                 // that reflects.
    EndStep(/*interrupted=*/false);
    progress_.unshot_fraction = 0;
    done_ = true;
    return false;
  }
  return EndCompleteStep();
}

void ProgressiveSolver::SpreadPatchUnshot(int patch_slot) {
  if (patch_level_unshot_.empty() || patch_level_unshot_[patch_slot].IsZero()) return;
  const Patch& patch = mesh_.patches()[PatchOfSlot(patch_slot)];
  const int side = SideOfSlot(patch_slot);
  const Rgb u = patch_level_unshot_[patch_slot];
  // Over the elements as its exitance is shown (PatchShape), so the light leaves from where it
  // is.
  std::vector<Rgb> shape;
  PatchShape(patch_slot, patch_level_exitant_, &shape);
  for (int k = 0; k < patch.num_elements; ++k) {
    const int e = patch.first_element + k;
    unshot_[Slot(e, side)] += u * shape[k] * (mesh_.elements()[e].area / patch.area);
  }
  patch_level_unshot_[patch_slot] = Rgb();
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
    // A computed emitter's emission is the placeholder of its computed light (DepositCovered).
    const bool covered = direct_ && direct_->Computes(patch.face, side);
    for (size_t k = 0; k < rows[i].slots.size(); ++k) {
      const int slot = sides().exists(rows[i].slots[k]) ? rows[i].slots[k] : kAbsorbedBack;
      const double f = rows[i].f[k] * scale;
      if (covered) {
        DepositCovered(slot, direct * f, /*straight=*/true, /*ray=*/false);
        Deposit(slot, (power - direct) * f, Rgb());
      } else {
        Deposit(slot, power * f, direct * f);
      }
      CountSentOn(slot, (power - direct) * f);
    }
    escaped_ += power * (1 - sum * scale);
    progress_.rays += rows[i].rays;
  }
  progress_.shots += static_cast<int64_t>(shooters.size());
  return EndCompleteStep();
}

void ProgressiveSolver::TraceChunk(int64_t chunk, int64_t total_rays,
                                   std::vector<RayResult>* out) const {
  out->clear();
  Rng rng(StreamKey(options_.seed, static_cast<uint64_t>(progress_.step),
                    static_cast<uint64_t>(chunk)));
  const int64_t begin = chunk * kChunk;
  const int64_t end = std::min(total_rays, begin + kChunk);
  // The group holding ray `begin`: groups are sorted by first_ray.
  auto it = std::upper_bound(groups_.begin(), groups_.end(), begin,
                             [](int64_t r, const RayGroup& g) { return r < g.first_ray; });
  int g = static_cast<int>(it - groups_.begin()) - 1;
  const auto& faces = mesh_.faces();
  uint64_t key = 0;
  OwenSobol seq(0);
  for (int64_t r = begin; r < end; ++r) {
    while (r >= groups_[g].first_ray + groups_[g].count) ++g;
    const RayGroup& group = groups_[g];
    int half = 0, source_face = 0;
    Vec3 origin, dir;
    if (sobol_) {
      if (group.sequence_key != key) {
        key = group.sequence_key;
        seq = OwenSobol(key);
      }
      double d[4];
      seq.GetPoint(static_cast<uint32_t>(group.sequence_first + (r - group.first_ray)), 0, 4, d);
      // An element on one half of its face maps (u, v) affinely (Mesh::SampleElement takes them
      // as r2, r3 there); one across the diagonal goes through its pieces.
      const Element& el = mesh_.elements()[group.element];
      const bool one_half =
          el.num_members == 0 && (double{el.u1} + el.v1 <= 1.0 ||
                                  (double{el.u0} + el.v0 >= 1.0 && !faces[el.face].triangle));
      origin = one_half ? mesh_.SampleElement(group.element, 0.0, d[0], d[1], &half, &source_face)
                        : SampleElementArea(mesh_, group.element, d[0], d[1], &half, &source_face);
      Vec3 normal = faces[source_face].normal[half];
      if (group.side == 1) normal = -normal;
      dir = CosineDirection(normal, d[2], d[3]);
    } else {
      double r1 = rng.Uniform(), r2 = rng.Uniform(), r3 = rng.Uniform();
      origin = mesh_.SampleElement(group.element, r1, r2, r3, &half, &source_face);
      Vec3 normal = faces[source_face].normal[half];
      if (group.side == 1) normal = -normal;
      dir = CosineDirection(normal, rng.Uniform(), rng.Uniform());
    }
    // The shooting face is skipped (a planar face cannot see itself; the slight fold of a
    // non-planar quad is neglected), so rays start exactly on the surface.
    Hit hit = visibility_.Intersect(origin, dir, 0, 1e30, source_face);
    if (!hit.valid()) {
      out->push_back({kEscaped, g, Rgb::Gray(1), kStraight});
      continue;
    }
    const int e = mesh_.FindElement(hit.face, hit.u, hit.v);
    const int slot = Slot(e, hit.StrikesFront(dir) ? 0 : 1);
    const bool exists = e >= 0 && sides().exists(slot);
    out->push_back({exists ? slot : kAbsorbedBack, g, Rgb::Gray(1), kStraight});
    if (exists && sides()[slot].Specular()) {
      FollowSpecular(hit, slot, origin, dir, Rgb::Gray(1), g, &rng, out);
    }
  }
}

void ProgressiveSolver::FollowSpecular(const Hit& first_hit, int first_slot, const Vec3& origin,
                                       const Vec3& dir, const Rgb& weight, int32_t group, Rng* rng,
                                       std::vector<RayResult>* out) const {
  struct Pending {
    Hit hit;
    int slot;
    Vec3 origin, dir;
    Rgb weight;
    int bounces;
  };
  std::vector<Pending> stack{{first_hit, first_slot, origin, dir, weight, 0}};
  int segments = 0;
  while (!stack.empty()) {
    const Pending at = stack.back();
    stack.pop_back();
    const SideRule& rule = sides()[at.slot];
    const Rgb leaving = at.weight * rule.specular;
    // The weight a deposit books as carried on is given up here (books: absorbed).
    if (at.bounces >= kMaxSpecularBounces || leaving.Max() < kSpecularCutWeight ||
        segments >= kMaxSpecularSegments) {
      out->push_back({kAbsorbedBack, group, leaving, kScattered});
      continue;
    }
    const int side = SideOfSlot(at.slot);
    const MeshFace& face = mesh_.faces()[at.hit.face];
    const SpecularRule& spec = specular_.Rule(face.surface, side);
    Vec3 n = Normalize(Vec3(at.hit.ng[0], at.hit.ng[1], at.hit.ng[2]));
    if (side == kBack) n = -n;
    const Vec3 p = at.origin + at.dir * static_cast<double>(at.hit.t);
    const double r1 = spec.glossy.IsZero() ? 0 : rng->Uniform();
    const double r2 = spec.glossy.IsZero() ? 0 : rng->Uniform();
    SpecularBranch branches[3];
    const int count = ScatterSpecular(spec, at.dir, n, r1, r2, branches);
    for (int k = 0; k < count; ++k) {
      const Rgb w = at.weight * branches[k].weight;
      const Vec3& d = branches[k].dir;
      ++segments;
      const Hit hit = visibility_.Intersect(p, d, 0, 1e30, at.hit.face);
      if (!hit.valid()) {
        out->push_back({kEscaped, group, w, kScattered});
        continue;
      }
      const int e = mesh_.FindElement(hit.face, hit.u, hit.v);
      const int slot = Slot(e, hit.StrikesFront(d) ? 0 : 1);
      const bool exists = e >= 0 && sides().exists(slot);
      const int arrival = exists ? slot : kAbsorbedBack;
      if (at.bounces == 0 && branches[k].mirror_direction && !spec.mirror.IsZero()) {
        // One ideal reflection, straight from the shooter: the mirror part's arrival is apart
        // (the hybrid direct step may have computed it as an image: Covered).
        const Rgb image = at.weight * spec.mirror;
        out->push_back({arrival, group, image, Slot(at.hit.face, side)});
        if (!(w - image).IsZero()) out->push_back({arrival, group, w - image, kScattered});
      } else {
        out->push_back({arrival, group, w, kScattered});
      }
      if (exists && sides()[slot].Specular()) {
        stack.push_back({hit, slot, p, d, w, at.bounces + 1});
      }
    }
  }
}

void ProgressiveSolver::Deposit(int slot, const Rgb& power, const Rgb& direct, bool patch_level,
                                bool ray, SpecularPart specular) {
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
  if (ray) hits_[slot] += 1;
  if (!incident_.empty()) {
    incident_[slot] += power;
    direct_in_[slot] += direct;
  }
  const SideRule& rule = sides()[slot];
  Rgb reflected = rule.reflectance * power;
  Rgb transmitted = rule.transmittance * power;
  // The specular part: carried on by the ray (its later arrivals), or sent on diffusely.
  Rgb carried;
  if (specular == SpecularPart::kTraced) carried = rule.specular * power;
  if (specular == SpecularPart::kDiffuse && rule.Specular()) {
    reflected += (rule.specular - rule.glass) * power;
    transmitted += rule.glass * power;
  }
  // Power `out` leaving side `to` (an element slot) of what arrived.
  auto leave = [&](int to, const Rgb& out) {
    const int patch_slot = Slot(patch, SideOfSlot(to));
    patch_unshot_[patch_slot] += out;
    if (patch_level) {
      patch_level_unshot_[patch_slot] += out;
      patch_level_exitant_[patch_slot] += out;
      patch_level_sq_[patch_slot] += out * out;
      tally_exitant_[to] += out;
      tally_sq_[to] += out * out;
    } else {
      unshot_[to] += out;
      exitant_[to] += out;
      if (ray) element_sq_[to] += out * out;
    }
  };
  leave(slot, reflected);
  if (!transmitted.IsZero()) leave(OtherSide(slot), transmitted);
  absorbed_ += power - reflected - transmitted - carried;
}

absl::StatusOr<bool> ProgressiveSolver::Step() {
  if (done_) return false;
  if (openness_.empty()) {
    // Before any light arrives: how open each element side is (openness.h), so that enclosed
    // elements get none of the light shared out at the patch level, and the estimate of light
    // not yet shot (CompleteUnshot) reaches only the open part of a partly covered element.
    int64_t rays = 0;
    std::vector<float> openness;
    arena().execute([&] {
      // Stratified probes only: the uncovered fraction of each element's area.
      openness = MeasureOpenness(mesh_, visibility_, options_.seed, stop_token(), &rays,
                                 OpennessProbes{/*corners=*/true, /*points=*/16,
                                                /*refine_points=*/256});
    });
    progress_.rays += rays;
    if (absl::Status s = visibility_.status(); !s.ok()) return s;
    if (openness.empty()) {
      EndStep(/*interrupted=*/true);
      return true;
    }
    openness_ = std::move(openness);
    const auto& patches = mesh_.patches();
    patch_open_area_.assign(2 * patches.size(), 0.0);
    for (int p = 0; p < static_cast<int>(patches.size()) && patch_level_; ++p) {
      for (int e = patches[p].first_element; e < patches[p].first_element + patches[p].num_elements;
           ++e) {
        for (int side : {kFront, kBack}) {
          patch_open_area_[Slot(p, side)] += openness_[Slot(e, side)] * mesh_.elements()[e].area;
        }
      }
    }
  }
  if (sky_pending_) return SkyStep();
  if (DirectBlockDue()) return DirectBlock();
  last_was_block_ = false;
  const auto& patches = mesh_.patches();
  const auto& elements = mesh_.elements();
  const int num_shooters = static_cast<int>(patch_unshot_.size());

  // A step holds kMaxRaysPerStep rays at most (fewer when the ray budget is nearly spent).
  double w_max = 0;
  for (int s = 0; s < num_shooters; ++s) w_max = std::max(w_max, Magnitude(patch_unshot_[s]));
  progress_.unshot_fraction = UnshotMagnitude() / emitted_.Sum();
  if (progress_.unshot_fraction <= options_.tolerance || w_max <= 0) {
    if (direct_left_) return DirectBlock();
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
  // Every shooter shoots the same fraction of its unshot power (all of it when the step has
  // room), so that after any step each has sent the same share of what it holds, the emitters
  // of their emission alike: the light not yet shot, which Final completes by estimates
  // (CompleteUnshot), is then spread as the light already shot is. In Southwell's order of
  // power one region would be lit before another, and a small lamp after the first bounces of
  // large ones. The rays are the same in all (in proportion to the power shot, Shirley 6.2).
  std::vector<std::pair<int, double>> holding;
  double rays_needed = 0;
  for (int s = 0; s < num_shooters; ++s) {
    const double w = Magnitude(patch_unshot_[s]);
    if (!(w > 0)) continue;
    holding.push_back({s, w});
    rays_needed += std::max(1.0, std::round(options_.overshoot * w / ray_power_));
  }
  const double fraction = std::min(1.0, static_cast<double>(cap) / std::max(1.0, rays_needed));
  for (const auto& [shooter, w] : holding) {
    if (step_rays >= cap) break;
    const int64_t n = std::max<int64_t>(1, std::llround(options_.overshoot * w / ray_power_));
    const int64_t take =
        std::min({n, cap - step_rays,
                  std::max<int64_t>(1, std::llround(fraction * static_cast<double>(n)))});
    shots.push_back({shooter, take, take == n ? 1.0 : static_cast<double>(take) / n});
    step_rays += take;
  }

  // Spread each shot over the shooter's elements by systematic sampling of their weights (unshot
  // power, or area for the uniform substructuring of the chapter), so every ray carries the same
  // share of its element's power and the power shot is exactly the power removed.
  groups_.clear();
  int64_t ray_cursor = 0;
  for (const Shot& shot : shots) {
    const int p = PatchOfSlot(shot.shooter), side = SideOfSlot(shot.shooter);
    const Patch& patch = patches[p];
    SpreadPatchUnshot(shot.shooter);
    const bool element_level = !patch_level_ || element_level_shooter_[shot.shooter] != 0;
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
        const int emitter = direct_ ? direct_->EmitterIndex(elements[e].face, side) : -1;
        // A computed emitter's emission arriving by a computed path is kept per element
        // (DepositCovered); what goes on specularly is sharp light, received per element too.
        const bool element_rays =
            element_level || (hybrid_ && emitter >= 0 && !share_emitted.IsZero());
        // The side's rays continue its own sequence across shots: the rays a side ever shoots
        // are one stratified set, however many shots they take.
        groups_.push_back({e, side, ray_cursor, count, share * (amount / count),
                           share_emitted * (amount / count), sequence_used_[slot],
                           StreamKey(options_.seed, static_cast<uint64_t>(slot), 3ULL << 40),
                           element_rays, emitter});
        sequence_used_[slot] += count;
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
  const int64_t chunks = (total_rays + kChunk - 1) / kChunk;
  if (chunk_results_.size() < static_cast<size_t>(chunks)) chunk_results_.resize(chunks);
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
                                                 TraceChunk(c, total_rays, &chunk_results_[c]);
                                                 return c;
                                               }) &
            tbb::make_filter<int64_t, void>(tbb::filter_mode::serial_in_order, [&](int64_t c) {
              // Light after a specular bounce is not "straight from an emitter" (what
              // re-gathering recomputes, adaptive.h).
              for (const RayResult& res : chunk_results_[c]) {
                const RayGroup& group = groups_[res.group];
                Rgb power = group.power * res.weight;
                Rgb direct = res.via == kStraight ? group.direct * res.weight : Rgb();
                if (Covered(group, res)) {
                  // The direct step computes this path: the emission's part is a placeholder or
                  // dropped.
                  const Rgb emission = group.direct * res.weight;
                  DepositCovered(res.slot, emission, res.via == kStraight, /*ray=*/true);
                  power -= emission;
                  direct = Rgb();
                }
                Deposit(res.slot, power, direct, !group.element_level, /*ray=*/true,
                        SpecularPart::kTraced);
                CountSentOn(res.slot, (group.power - group.direct) * res.weight);
              }
              // Bounded memory: a ray of many specular branches makes a long list.
              if (chunk_results_[c].capacity() > 4 * static_cast<size_t>(kChunk)) {
                std::vector<RayResult>().swap(chunk_results_[c]);
              }
            }));
  });
  if (absl::Status s = visibility_.status(); !s.ok()) return s;
  // The input stage stopped after next_chunk - 1 chunks, all of them traced and deposited.
  const int64_t traced = std::min(total_rays, (next_chunk - 1) * kChunk);
  progress_.rays += traced;
  shot_rays_ += traced;
  if (traced < total_rays) {
    ReturnUntraced(traced);
    EndStep(/*interrupted=*/true);
    return true;
  }

  progress_.shots += static_cast<int64_t>(shots.size());
  return EndCompleteStep();
}

void ProgressiveSolver::WriteOffComputedEmission() {
  // Once every element's direct light is computed, the computed emitters' emission not yet shot,
  // U, would only repay the loan where it lands (DepositCovered), be absorbed where a side does
  // not exist, or escape: rays that change no radiosity, half of a Cornell box's. It is booked at
  // once instead, by the computed light: of the emitters' whole emission E, the computed
  // irradiance put A_n on sides that do not exist, so U A_n / E is absorbed there, and the rest
  // of U repays the loan; what the loan has left (U's escaping share, and the rays' sampling
  // error) SettleLoan books as escaped. Only where the computed light covers every element
  // (elements that neither reflect nor transmit are otherwise left out of the blocks), and not
  // with mirrors (hybrid_), whose rays carry a specular part of the emission on.
  if (hybrid_ || direct_left_ || emitted_unshot_.empty() ||
      direct_order_.size() != mesh_.elements().size()) {
    return;
  }
  const auto& elements = mesh_.elements();
  Rgb unshot, total;
  for (int slot = 0; slot < static_cast<int>(emitted_unshot_.size()); ++slot) {
    const int e = ElementOfSlot(slot);
    if (!direct_->Computes(elements[e].face, SideOfSlot(slot))) continue;
    unshot += emitted_unshot_[slot];
    total += sides()[slot].exitance * elements[e].area;
  }
  if (unshot.IsZero()) return;
  for (int slot = 0; slot < static_cast<int>(emitted_unshot_.size()); ++slot) {
    const Rgb r = emitted_unshot_[slot];
    const int e = ElementOfSlot(slot);
    if (r.IsZero() || !direct_->Computes(elements[e].face, SideOfSlot(slot))) continue;
    unshot_[slot] -= r;
    patch_unshot_[Slot(elements[e].patch, SideOfSlot(slot))] -= r;
    emitted_unshot_[slot] = Rgb();
  }
  Rgb absorbed;
  for (int c = 0; c < 3; ++c) {
    absorbed[c] = total[c] > 0 ? unshot[c] * direct_absorbed_[c] / total[c] : 0;
  }
  absorbed_ += absorbed;
  loan_ -= unshot - absorbed;
}

void ProgressiveSolver::SettleLoan() {
  if (loan_.IsZero()) return;
  for (size_t slot = 0; slot < emitted_unshot_.size(); ++slot) {
    if (!emitted_unshot_[slot].IsZero() &&
        direct_->Computes(mesh_.elements()[ElementOfSlot(static_cast<int>(slot))].face,
                          SideOfSlot(static_cast<int>(slot)))) {
      return;
    }
  }
  // What is left is the rays' sampling error against the computed light: it left the scene.
  escaped_ += loan_ * -1.0;
  loan_ = Rgb();
}

bool ProgressiveSolver::EndCompleteStep() {
  EndStep(/*interrupted=*/false);
  // Both the sky's blocks and the direct light's count towards the direct fraction.
  const double n = static_cast<double>(mesh_.elements().size());
  const double sky = !sky_pending_ ? 1 : static_cast<double>(sky_next_) / n;
  const double direct = !direct_left_           ? 1
                        : direct_order_.empty() ? 0
                                                : static_cast<double>(direct_next_) /
                                                      static_cast<double>(direct_order_.size());
  progress_.direct_fraction = (options_.sky.enabled() || !options_.luminaires.empty()) && direct_
                                  ? 0.5 * (sky + direct)
                              : direct_ ? direct
                                        : sky;
  if (direct_) {
    WriteOffComputedEmission();
    SettleLoan();
  }
  progress_.unshot_fraction = emitted_.Sum() > 0 ? UnshotMagnitude() / emitted_.Sum() : 1;
  if (progress_.unshot_fraction <= options_.tolerance && !direct_left_ && !sky_pending_) {
    done_ = true;
  } else if (!direct_left_ && !sky_pending_ &&
             ProjectedRays() > kStallBounces * options_.rays_per_element *
                                   static_cast<double>(mesh_.elements().size())) {
    done_ = stalled_ = true;  // Its bound: see kStallBounces.
  }
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

double ProgressiveSolver::UnshotMagnitude() const {
  double magnitude = 0;
  for (const Rgb& u : patch_unshot_) magnitude += Magnitude(u);
  return std::max(0.0, magnitude - loan_.Sum());
}

bool ProgressiveSolver::Covered(const RayGroup& group, const RayResult& res) const {
  if (group.emitter < 0) return false;
  if (res.via == kStraight) return res.slot != kEscaped;
  if (res.via < 0) return false;
  return direct_->ComputesImage(mesh_.elements()[group.element].face, group.side,
                                ElementOfSlot(res.via), SideOfSlot(res.via));
}

void ProgressiveSolver::InterpolatedShape(int patch_slot, const std::vector<Rgb>& level,
                                          std::vector<Rgb>* shape) const {
  const auto& elements = mesh_.elements();
  const auto& patches = mesh_.patches();
  const int p = PatchOfSlot(patch_slot), side = SideOfSlot(patch_slot);
  const Patch& patch = patches[p];
  const MeshFace& f = mesh_.faces()[patch.face];
  shape->assign(static_cast<size_t>(patch.num_elements), Rgb::Gray(1));
  if (!(patch_open_area_[patch_slot] > 0)) return;
  // Each patch's exitance per open area (a patch with none taking this one's).
  auto per_open_area = [&](int q) {
    return level[Slot(q, side)] / patch_open_area_[Slot(q, side)];
  };
  const Rgb own = per_open_area(p);
  auto value = [&](int pi, int pj) {
    const int q = f.first_patch + pj * f.pu + pi;
    return patch_open_area_[Slot(q, side)] > 0 ? per_open_area(q) : own;
  };
  // The centres of the two patches around coordinate c along an axis of `cells` patches (the
  // outermost pair beyond the outermost centres: linear extrapolation).
  auto axis = [](double c, int cells, int* i0, double* t) {
    if (cells == 1) {
      *i0 = 0;
      *t = 0;
      return;
    }
    const double g = c * cells - 0.5;
    *i0 = std::clamp(static_cast<int>(std::floor(g)), 0, cells - 2);
    *t = g - *i0;
  };
  for (int k = 0; k < patch.num_elements; ++k) {
    const Element& el = elements[patch.first_element + k];
    int i0, j0;
    double tu, tv;
    axis(0.5 * (double{el.u0} + el.u1), f.pu, &i0, &tu);
    axis(0.5 * (double{el.v0} + el.v1), f.pv, &j0, &tv);
    const int i1 = std::min(i0 + 1, f.pu - 1), j1 = std::min(j0 + 1, f.pv - 1);
    const Rgb x = value(i0, j0) * ((1 - tu) * (1 - tv)) + value(i1, j0) * (tu * (1 - tv)) +
                  value(i0, j1) * ((1 - tu) * tv) + value(i1, j1) * (tu * tv);
    (*shape)[k] = Rgb(std::max(0.0, x.r), std::max(0.0, x.g), std::max(0.0, x.b));
  }
}

double ProgressiveSolver::PatchShape(int patch_slot, const std::vector<Rgb>& level,
                                     std::vector<Rgb>* shape) const {
  const auto& elements = mesh_.elements();
  const Patch& patch = mesh_.patches()[PatchOfSlot(patch_slot)];
  const int side = SideOfSlot(patch_slot);
  const Rgb total = level[patch_slot];
  const int n = patch.num_elements;
  shape->assign(static_cast<size_t>(n), Rgb::Gray(1));
  if (!(patch.area > 0) || !(total.Sum() > 0)) return true;
  auto slot_of = [&](int k) { return Slot(patch.first_element + k, side); };
  auto area_of = [&](int k) { return elements[patch.first_element + k].area; };
  // Power per element: the interpolated shape times the element's openness (the uncovered
  // fraction of its area: none for the part of it a block rests on), sharing the patch's total.
  std::vector<Rgb> raw, part(static_cast<size_t>(n));
  InterpolatedShape(patch_slot, level, &raw);
  Rgb weight;
  for (int k = 0; k < n; ++k) {
    raw[k] *= openness_[slot_of(k)];
    weight += raw[k] * area_of(k);
  }
  for (int k = 0; k < n; ++k) {
    for (int c = 0; c < 3; ++c) {
      part[k][c] =
          total[c] * (weight[c] > 0 ? raw[k][c] * area_of(k) / weight[c] : area_of(k) / patch.area);
    }
  }
  // Pearson's chi-square of the elements' own tallies against those shares (each tally's
  // variance estimated by its sum of squared parts; channel sums). A patch whose light varies
  // across it faster than the interpolation (a contact shadow, a corner) fails, and all its
  // elements keep their own tallies: unbiased, only noisier.
  double chi2 = 0;
  int dof = 0;
  for (int k = 0; k < n; ++k) {
    const Rgb& q = tally_sq_[slot_of(k)];
    const double sd = std::sqrt(q.r) + std::sqrt(q.g) + std::sqrt(q.b);
    if (!(sd > 0)) continue;
    const double d = tally_exitant_[slot_of(k)].Sum() - part[k].Sum();
    chi2 += d * d / (sd * sd);
    ++dof;
  }
  // The tallies' weight, by positive-part James-Stein shrinkage towards the interpolation
  // (James & Stein 1961; Efron & Morris 1973): w = 1 - (dof - 2) / chi2, clamped to [0, 1]. Where
  // the interpolation fits (chi2 near its dof) the patch takes it; where the light varies faster,
  // the elements move towards their own tallies, as far as the evidence says. Both share the
  // patch's power, so the blend keeps it.
  const double threshold = dof + 3 * std::sqrt(2.0 * dof);
  double w = dof == 0 || !(chi2 > threshold) ? 0.0 : 1 - threshold / chi2;
  // A patch that a contact edge crosses (an element partly covered by what rests on it) keeps
  // the elements' own tallies: the contact shadow of indirect light is sharper than any
  // interpolation between patch centres, and too few elements misfit for the test to see it
  // (measured on the Cornell box: the floor elements beside the blocks were 30-40 % too bright).
  if (CrossedByContact(patch_slot)) w = 1;
  for (int k = 0; k < n; ++k) {
    const Rgb p = part[k] * (1 - w) + tally_exitant_[slot_of(k)] * w;
    for (int c = 0; c < 3; ++c) {
      (*shape)[k][c] = total[c] > 0 ? p[c] / area_of(k) / (total[c] / patch.area) : 1.0;
    }
  }
  return w;
}

bool ProgressiveSolver::CrossedByContact(int patch_slot) const {
  const Patch& patch = mesh_.patches()[PatchOfSlot(patch_slot)];
  for (int k = 0; k < patch.num_elements; ++k) {
    if (openness_[Slot(patch.first_element + k, SideOfSlot(patch_slot))] < 1) return true;
  }
  return false;
}

void ProgressiveSolver::SmoothPatchLevel(std::vector<Rgb>* power,
                                         std::vector<Rgb>* variance) const {
  *power = patch_level_exitant_;
  *variance = patch_level_sq_;
  // A patch that a contact edge crosses keeps its elements' own tallies (PatchShape), and is no
  // neighbour of the others either: its light changes faster than a plane.
  std::vector<FitPoint> points;
  std::vector<int> members;
  std::vector<double> hat;
  std::vector<Rgb> value, value_var;
  for (const MeshFace& f : mesh_.faces()) {
    const int count = f.pu * f.pv;
    if (count < 2) continue;
    for (int side : {kFront, kBack}) {
      std::vector<uint8_t> usable(static_cast<size_t>(count), 0);
      for (int i = 0; i < count; ++i) {
        const int ps = Slot(f.first_patch + i, side);
        usable[i] = patch_open_area_[ps] > 0 && !CrossedByContact(ps);
      }
      std::vector<Rgb> smoothed(static_cast<size_t>(count)), smoothed_var(smoothed.size());
      Rgb before, after;
      for (int pj = 0; pj < f.pv; ++pj) {
        for (int pi = 0; pi < f.pu; ++pi) {
          const int index = pj * f.pu + pi;
          if (!usable[index]) continue;
          // The 3 x 3 window around the patch, moved inwards at the face's borders.
          const int i0 = std::clamp(pi - 1, 0, std::max(0, f.pu - 3));
          const int j0 = std::clamp(pj - 1, 0, std::max(0, f.pv - 3));
          points.clear();
          members.clear();
          value.clear();
          value_var.clear();
          int own = -1;
          for (int j = j0; j <= std::min(f.pv - 1, j0 + 2); ++j) {
            for (int i = i0; i <= std::min(f.pu - 1, i0 + 2); ++i) {
              if (!usable[j * f.pu + i]) continue;
              if (j * f.pu + i == index) own = static_cast<int>(members.size());
              const int ps = Slot(f.first_patch + j * f.pu + i, side);
              const double a = patch_open_area_[ps];
              points.push_back({static_cast<double>(i), static_cast<double>(j), a});
              members.push_back(ps);
              value.push_back(patch_level_exitant_[ps] / a);
              value_var.push_back(patch_level_sq_[ps] / (a * a));
            }
          }
          const int n = static_cast<int>(members.size());
          const int dof = n - PlaneFitHat(points, &hat);
          // Pearson's chi-square of the values against the plane (channel sums, as PatchShape),
          // and the values' weight by positive-part James-Stein shrinkage, here with the plain
          // threshold chi2 = dof: where the plane fits no worse than noise would, the patch takes
          // it (a 3 x 3 plane has a ninth of a value's variance at its centre); where it misfits,
          // the patch keeps its own value in proportion. (The tallies' variance estimate is
          // that of independent rays, above the Sobol' shooting's true variance, so the test
          // leans towards the plane; on the Cornell box a threshold of dof + 3 sqrt(2 dof), as
          // PatchShape's, let smooth curvature through and cost 4-7 % of the RMS error.)
          double chi2 = 0;
          for (int m = 0; m < n; ++m) {
            Rgb fit;
            for (int j = 0; j < n; ++j) fit += value[j] * hat[static_cast<size_t>(m) * n + j];
            const Rgb& q = value_var[m];
            const double sd = std::sqrt(q.r) + std::sqrt(q.g) + std::sqrt(q.b);
            const double d = (value[m] - fit).Sum();
            if (sd > 0) chi2 += d * d / (sd * sd);
          }
          const double w = dof <= 0 ? 1.0 : !(chi2 > dof) ? 0.0 : 1 - dof / chi2;
          Rgb v, var;
          for (int j = 0; j < n; ++j) {
            const double c = (1 - w) * hat[static_cast<size_t>(own) * n + j] + (j == own ? w : 0);
            v += value[j] * c;
            var += value_var[j] * (c * c);
          }
          const double a = patch_open_area_[members[own]];
          smoothed[index] = Rgb(std::max(0.0, v.r), std::max(0.0, v.g), std::max(0.0, v.b)) * a;
          smoothed_var[index] = var * (a * a);
          before += patch_level_exitant_[members[own]];
          after += smoothed[index];
        }
      }
      // The face side keeps the power it received.
      Rgb scale = Rgb::Gray(1);
      for (int c = 0; c < 3; ++c) {
        if (after[c] > 0) scale[c] = before[c] / after[c];
      }
      for (int index = 0; index < count; ++index) {
        if (!usable[index]) continue;
        const int ps = Slot(f.first_patch + index, side);
        (*power)[ps] = smoothed[index] * scale;
        (*variance)[ps] = smoothed_var[index] * scale * scale;
      }
    }
  }
}

void ProgressiveSolver::InterpolatePatchExitance(std::vector<Rgb>* exitance,
                                                 std::vector<Rgb>* std_error) const {
  const auto& patches = mesh_.patches();
  exitance->assign(exitant_.size(), Rgb());
  std_error->assign(exitant_.size(), Rgb());
  std::vector<Rgb> level, level_variance, shape;
  SmoothPatchLevel(&level, &level_variance);
  for (int p = 0; p < static_cast<int>(patches.size()); ++p) {
    const Patch& patch = patches[p];
    if (patch.num_elements == 0 || !(patch.area > 0)) continue;
    for (int side : {kFront, kBack}) {
      const int ps = Slot(p, side);
      if (level[ps].IsZero()) continue;
      const Rgb own = level[ps] / patch.area;
      const Rgb se = Sqrt(level_variance[ps]) / patch.area;
      const double w = PatchShape(ps, level, &shape);
      for (int k = 0; k < patch.num_elements; ++k) {
        const int slot = Slot(patch.first_element + k, side);
        (*exitance)[slot] = own * shape[k];
        // The blend's: the patch's error (which the interpolation carries) and the tally's.
        const Rgb tally = Sqrt(tally_sq_[slot]) / mesh_.elements()[patch.first_element + k].area;
        (*std_error)[slot] = Sqrt(se * se * ((1 - w) * (1 - w)) + tally * tally * (w * w));
      }
    }
  }
}

Solution ProgressiveSolver::Final() const {
  Solution sol = NewSolution();
  const auto& elements = mesh_.elements();
  sol.radiosity.assign(exitant_.size(), Rgb());
  std::vector<Rgb> variance(exitant_.size());
  for (size_t s = 0; s < exitant_.size(); ++s) {
    const int slot = static_cast<int>(s);
    if (!sides().exists(slot)) continue;
    const double area = elements[ElementOfSlot(slot)].area;
    sol.radiosity[s] = exitant_[s] / area;
    variance[s] = element_sq_[s] / (area * area);
    if (!placeholder_sq_.empty()) variance[s] += placeholder_sq_[s] / (area * area);
    // The standard errors of light received once, straight from its source (the emitters'
    // computed direct light, the sky), carried into what leaves this side.
    for (const std::vector<Rgb>* received : {&direct_std_error_, &sky_std_error_}) {
      if (received->empty()) continue;
      const SideRule& rule = sides()[slot];
      const SideRule& other = sides()[OtherSide(slot)];
      const Rgb a = rule.reflectance * (*received)[s];
      const Rgb b = other.transmittance * (*received)[OtherSide(slot)];
      variance[s] += a * a + b * b;
    }
  }
  // Stopped before the first step measured how open the elements are, no light has reached the
  // patch level yet (and there is nothing to interpolate).
  if (patch_level_ && !patch_open_area_.empty()) {
    std::vector<Rgb> exitance, se;
    InterpolatePatchExitance(&exitance, &se);
    for (size_t s = 0; s < exitant_.size(); ++s) {
      if (!sides().exists(static_cast<int>(s))) continue;
      sol.radiosity[s] += exitance[s];
      variance[s] += se[s] * se[s];
    }
  }
  if (!estimator_) {
    sol.std_error.resize(variance.size());
    for (size_t s = 0; s < variance.size(); ++s) sol.std_error[s] = Sqrt(variance[s]);
  }
  // Less the computed direct light delivered ahead of the emission still to shoot (loan_).
  for (const Rgb& u : patch_unshot_) sol.unshot_power += u;
  sol.unshot_power -= loan_;
  const double magnitude = UnshotMagnitude();
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
  // Nothing emitted: a sky not yet received (all still to do), or one that lit nothing.
  sol.unshot_fraction = emitted_.Sum() > 0 ? magnitude / emitted_.Sum() : (sky_pending_ ? 1 : 0);
  if (!done_ || stalled_) CompleteUnshot(&sol);
  return sol;
}

Rgb ProgressiveSolver::CompletePendingSky(Solution* sol) const {
  Rgb spread;
  if (!sky_pending_ || sky_face_area_.empty()) return spread;
  const auto& elements = mesh_.elements();
  std::vector<uint8_t> done(elements.size(), 0);
  for (int64_t i = 0; i < sky_next_; ++i) done[static_cast<size_t>(sky_order_[i])] = 1;
  for (size_t e = 0; e < elements.size(); ++e) {
    if (done[e]) continue;
    for (int side : {kFront, kBack}) {
      const int slot = Slot(static_cast<int>(e), side);
      const int fs = Slot(elements[e].face, side);
      if (!sides().exists(slot) || !(sky_face_area_[fs] > 0)) continue;
      const Rgb h = sky_face_power_[fs] / sky_face_area_[fs];
      const Rgb reflected = (sides()[slot].reflectance + sides()[slot].specular) * h;
      sol->radiosity[slot] += reflected;
      spread += reflected * elements[e].area;
      if (sides().exists(OtherSide(slot))) {
        sol->radiosity[OtherSide(slot)] += sides()[slot].transmittance * h;
        spread += sides()[slot].transmittance * h * elements[e].area;
      }
    }
  }
  return spread;
}

void ProgressiveSolver::CompleteUnshot(Solution* sol) const {
  // Sky and luminaire light on the elements whose blocks are still to come: the mean of what
  // their face's computed elements received (the blocks are spread over the whole mesh).
  const Rgb sky_spread = CompletePendingSky(sol);
  // What surfaces have sent on of the power that arrived from shots (the ambient's reflectance).
  Rgb sent_on;
  for (int c = 0; c < 3; ++c) {
    sent_on[c] = arrived_[c] > 0 ? sent_on_[c] / arrived_[c] : 0;
  }
  const Rgb* rho = arrived_.Sum() > 0 ? &sent_on : nullptr;
  // Light not yet shot reaches only the open part of an element a block partly covers.
  const std::vector<float>* open = openness_.empty() ? nullptr : &openness_;
  auto open_of = [&](int slot) {
    return open != nullptr ? static_cast<double>(openness_[slot]) : 1.0;
  };
  if (!direct_) {
    const Rgb spread = sol->unshot_power + sky_spread;
    AddAmbient(sol, &spread, rho, open);
    return;
  }
  // The computed emitters' emission not yet shot, and the share of it shot (every emitter shoots
  // the same fraction a step).
  const auto& elements = mesh_.elements();
  Rgb unshot, total;
  for (size_t slot = 0; slot < emitted_unshot_.size(); ++slot) {
    const int e = ElementOfSlot(static_cast<int>(slot));
    if (!direct_->Computes(elements[e].face, SideOfSlot(static_cast<int>(slot)))) continue;
    unshot += emitted_unshot_[slot];
    total += sides()[static_cast<int>(slot)].exitance * elements[e].area;
  }
  const double shot = total.Sum() > 0 ? std::clamp(1 - unshot.Sum() / total.Sum(), 0.0, 1.0) : 1;
  // Each placeholder's direct light, estimated from what it holds, P (the rays' estimate of
  // `shot` of it), shrunk towards its face's mean, mu (the face's placeholders scaled by
  // 1 / shot; before anything is shot, the emission spread over the scene's area), as a
  // Gamma-Poisson posterior mean with the weight of kPriorShare of the emission's rays:
  // D = (P + b mu A) / (shot + b). Early the face's mean dominates (an element's own noise,
  // scaled by 1 / shot, would be large); as the emission is shot, its own rays do. What it sends
  // on of D - P joins the power the ambient term spreads, instead of the emission not yet shot.
  constexpr double kPriorShare = 0.05;
  double area = 0;
  std::vector<Rgb> face_power(2 * mesh_.faces().size());
  std::vector<double> face_area(2 * mesh_.faces().size(), 0.0);
  for (int slot = 0; slot < static_cast<int>(2 * elements.size()); ++slot) {
    if (!sides().exists(slot)) continue;
    const Element& el = elements[ElementOfSlot(slot)];
    area += el.area * open_of(slot);
    if (direct_done_[ElementOfSlot(slot)]) continue;
    face_power[Slot(el.face, SideOfSlot(slot))] += held_[slot];
    face_area[Slot(el.face, SideOfSlot(slot))] += el.area * open_of(slot);
  }
  const Rgb uniform = area > 0 ? total / area : Rgb();
  Rgb spread = sol->unshot_power + loan_ - unshot + sky_spread;
  for (size_t e = 0; e < elements.size() && shot < 1; ++e) {
    if (direct_done_[e] > 0) continue;
    for (int side : {kFront, kBack}) {
      const int slot = Slot(static_cast<int>(e), side);
      if (!sides().exists(slot)) continue;
      const int fs = Slot(elements[e].face, side);
      const Rgb mu = !(shot > 0)         ? uniform
                     : face_area[fs] > 0 ? face_power[fs] / (shot * face_area[fs])
                                         : Rgb();  // A face no light reaches.
      const Rgb d = (held_[slot] + mu * (kPriorShare * elements[e].area * open_of(slot))) /
                    (shot + kPriorShare);
      const Rgb rest = d - held_[slot];
      const Rgb reflected = sides()[slot].reflectance * rest;
      const Rgb transmitted = sides()[slot].transmittance * rest;
      sol->radiosity[slot] += reflected / elements[e].area;
      spread += reflected;
      if (sides().exists(OtherSide(slot))) {
        sol->radiosity[OtherSide(slot)] += transmitted / elements[e].area;
        spread += transmitted;
      }
    }
  }
  AddAmbient(sol, &spread, rho, open);
}

Solution ProgressiveSolver::Snapshot() const { return Final(); }

}  // namespace radiosity
