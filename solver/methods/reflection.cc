#include "solver/methods/reflection.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "solver/transport/rng.h"
#include "solver/transport/sampling.h"
#include "tbb/blocked_range.h"
#include "tbb/parallel_for.h"

namespace radiosity {

namespace {

// Distinguishes the packets' random streams from every other stream of a seed.
constexpr uint64_t kReflectionStream = 0x5245464c45435431ULL;  // "REFLECT1"

}  // namespace

ReflectionSolver::ReflectionSolver(const Scene& scene, const Mesh& mesh,
                                   const Visibility& visibility, const SolveOptions& options,
                                   const std::atomic<bool>* stop)
    : SolverBase(scene, mesh, visibility, options, stop, "reflection"), specular_(scene) {
  const size_t n = mesh.elements().size();
  emitted_slot_ = EmittedPerSlot();
  incident_.assign(2 * n, Rgb());
  // Packets per emitting side in proportion to its power (at least one, so every emitter is
  // sampled); each carries its side's power / count: about emitted / (rays_per_element x N).
  const double target = options.rays_per_element * static_cast<double>(n);
  const double total = emitted_.Sum();
  for (size_t s = 0; s < 2 * n; ++s) {
    const double w = emitted_slot_[s].Sum();
    if (!(w > 0)) continue;
    const int64_t count = std::max<int64_t>(1, std::llround(target * w / total));
    emitters_.push_back({static_cast<int>(s), planned_, count, emitted_slot_[s] / count});
    planned_ += count;
  }
  // Packet p runs as planned packet (p x stride_) mod planned_, a stride coprime to planned_
  // near its golden section: any run of consecutive packets visits the emitters in proportion
  // to their packets, so a solve stopped early has sampled every emitter alike.
  stride_ = std::max<int64_t>(1, std::llround(0.6180339887498949 * static_cast<double>(planned_)));
  while (std::gcd(stride_, std::max<int64_t>(1, planned_)) != 1) ++stride_;
  progress_.unshot_fraction = 1;
}

ReflectionSolver::~ReflectionSolver() = default;

void ReflectionSolver::TraceChunk(int64_t chunk, int64_t begin, int64_t end,
                                  ChunkResult* out) const {
  // Keyed by the chunk's place among all planned packets, so the packets do not depend on how
  // they are grouped into steps or threads.
  Rng rng(StreamKey(options_.seed, kReflectionStream, static_cast<uint64_t>(chunk)));
  out->arrivals.clear();
  out->emitted = out->absorbed = out->escaped = Rgb();
  out->rays = 0;
  const auto& faces = mesh_.faces();
  for (int64_t p = begin; p < end; ++p) {
    // A packet may bounce thousands of times near R + T = 1: check often.
    if ((p - begin) % kStopCheck == 0 && ShouldStop()) return;
    const int64_t planned = static_cast<int64_t>(
        (static_cast<unsigned __int128>(p) * static_cast<uint64_t>(stride_)) %
        static_cast<uint64_t>(planned_));
    const size_t g = static_cast<size_t>(
        std::upper_bound(emitters_.begin(), emitters_.end(), planned,
                         [](int64_t q, const Emitter& em) { return q < em.first; }) -
        emitters_.begin() - 1);
    Rgb power = emitters_[g].power;
    out->emitted += power;
    int element = ElementOfSlot(emitters_[g].slot);
    int side = SideOfSlot(emitters_[g].slot);
    // A packet that left specularly goes on from where it arrived (origin, dir, face).
    bool specular = false;
    int specular_run = 0;  // Specular bounces in a row.
    Vec3 origin, dir;
    int face = 0;
    for (int bounce = 1;; ++bounce) {
      if (!specular) {
        // Leave from a uniform point of the element (zonal: its radiosity is uniform over it).
        int half = 0;
        const double r1 = rng.Uniform(), r2 = rng.Uniform(), r3 = rng.Uniform();
        origin = mesh_.SampleElement(element, r1, r2, r3, &half, &face);
        const Vec3 normal = side == 0 ? faces[face].normal[half] : -faces[face].normal[half];
        const double r4 = rng.Uniform(), r5 = rng.Uniform();
        dir = CosineDirection(normal, r4, r5);
      }
      const Hit hit = visibility_.Intersect(origin, dir, 0, 1e30, face);
      out->rays += 1;
      if (!hit.valid()) {
        out->escaped += power;
        break;
      }
      const MeshFace& f = faces[hit.face];
      const int e = mesh_.FindElement(hit.face, hit.u, hit.v);
      const bool front = Dot(dir, f.normal[f.Half(hit.u, hit.v)]) < 0;
      const int k = Slot(e, front ? 0 : 1);
      if (e < 0 || !sides().exists(k)) {  // The back of a one-sided surface absorbs everything.
        out->absorbed += power;
        break;
      }
      out->arrivals.push_back({k, power});
      // What the side absorbs of it, in expectation per channel (the packet's fate below is
      // decided on the channel sum, so its own power at termination would bias the channels).
      const SideRule& rule = sides()[k];
      const Rgb reflected = rule.reflectance * power;
      const Rgb transmitted = rule.transmittance * power;
      // Specular branches (transport/specular.h): their weights sum to S_k.
      SpecularBranch branches[3];
      int num_branches = 0;
      Rgb carried;
      if (rule.Specular()) {
        Vec3 n = Normalize(Vec3(hit.ng[0], hit.ng[1], hit.ng[2]));
        if (!front) n = -n;
        const double g1 = rng.Uniform(), g2 = rng.Uniform();
        num_branches =
            ScatterSpecular(specular_.Rule(f.surface, front ? 0 : 1), dir, n, g1, g2, branches);
        int kept = 0;
        for (int b = 0; b < num_branches; ++b) {
          branches[b].weight = branches[b].weight * power;
          carried += branches[b].weight;
          // A branch that carries nothing of this packet's colours is never chosen.
          if (branches[b].weight.Sum() > 0) branches[kept++] = branches[b];
        }
        num_branches = kept;
      }
      out->absorbed += power - reflected - transmitted - carried;
      // Russian roulette keeping the packet's channel sum: continue with the probability of the
      // fraction of its power R_k (or T_k, or a specular branch) passes on, reweighting the
      // channels by R_k / p_R.
      const double sum = power.Sum();
      const double p_r = reflected.Sum() / sum, p_t = transmitted.Sum() / sum;
      const double p_s = carried.Sum() / sum;
      double xi = rng.Uniform();
      if (xi >= p_r + p_t + p_s) break;
      // Truncated: what it still carries counts as absorbed (kMaxSpecularBounces specular
      // bounces in a row, as the progressive solver gives up a branch).
      if (bounce >= kMaxBounces || (xi >= p_r + p_t && specular_run >= kMaxSpecularBounces)) {
        out->absorbed += reflected + transmitted + carried;
        break;
      }
      specular = false;
      specular_run = xi >= p_r + p_t ? specular_run + 1 : 0;
      if (xi < p_r) {
        power = reflected * (sum / reflected.Sum());
        side = SideOfSlot(k);
      } else if (xi < p_r + p_t) {
        power = transmitted * (sum / transmitted.Sum());
        side = SideOfSlot(OtherSide(k));
      } else {
        // One branch, chosen in proportion to its channel sum.
        xi -= p_r + p_t;
        int b = 0;
        while (b + 1 < num_branches && xi >= branches[b].weight.Sum() / sum) {
          xi -= branches[b].weight.Sum() / sum;
          ++b;
        }
        power = branches[b].weight * (sum / branches[b].weight.Sum());
        specular = true;
        origin = origin + dir * static_cast<double>(hit.t);
        dir = branches[b].dir;
        face = hit.face;
      }
      element = e;
    }
  }
}

bool ReflectionSolver::SaveState(StateWriter* out) const {
  SaveBase(out);
  out->Put("reflection.planned", planned_);
  out->Put("reflection.next_packet", next_packet_);
  out->Put("reflection.emitted_so_far", emitted_so_far_);
  out->PutVector("reflection.incident", incident_);
  return true;
}

absl::Status ReflectionSolver::RestoreState(StateReader* in) {
  if (absl::Status st = RestoreBase(in); !st.ok()) return st;
  int64_t planned = 0;
  if (absl::Status st = in->Get("reflection.planned", &planned); !st.ok()) return st;
  if (planned != planned_) {
    return absl::FailedPreconditionError("the state plans another number of packets");
  }
  for (absl::Status st : {in->Get("reflection.next_packet", &next_packet_),
                          in->Get("reflection.emitted_so_far", &emitted_so_far_),
                          in->GetVector("reflection.incident", &incident_)}) {
    if (!st.ok()) return st;
  }
  return in->Finish();
}

absl::StatusOr<bool> ReflectionSolver::Step() {
  if (next_packet_ >= planned_) return false;
  int64_t count = std::min(kPacketsPerStep, planned_ - next_packet_);
  // Near the ray budget, only the whole chunks it is expected to pay for.
  if (options_.max_rays > 0 && progress_.rays > 0) {
    const double rays_per_packet = static_cast<double>(progress_.rays) / next_packet_;
    const double left = static_cast<double>(options_.max_rays - progress_.rays) / rays_per_packet;
    const int64_t chunks = std::max<int64_t>(1, static_cast<int64_t>(std::ceil(left / kChunk)));
    count = std::min(count, chunks * kChunk);
  }
  // Steps start on chunk boundaries (kPacketsPerStep is a multiple of kChunk).
  const int64_t first_chunk = next_packet_ / kChunk;
  const int64_t chunks = (count + kChunk - 1) / kChunk;
  chunks_.resize(static_cast<size_t>(chunks));
  const int64_t end = next_packet_ + count;
  arena().execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<int64_t>(0, chunks, 1), [&](const tbb::blocked_range<int64_t>& range) {
          for (int64_t c = range.begin(); c < range.end(); ++c) {
            const int64_t begin = next_packet_ + c * kChunk;
            TraceChunk(first_chunk + c, begin, std::min(end, begin + kChunk), &chunks_[c]);
          }
        });
  });
  if (absl::Status s = visibility_.status(); !s.ok()) return s;
  if (ShouldStop()) {  // Some chunks are incomplete: the step is dropped.
    EndStep(/*interrupted=*/true);
    return true;
  }
  // Merge in order: the sums do not depend on the thread count.
  for (const ChunkResult& chunk : chunks_) {
    for (const Arrival& a : chunk.arrivals) incident_[a.slot] += a.power;
    emitted_so_far_ += chunk.emitted;
    absorbed_ += chunk.absorbed;
    escaped_ += chunk.escaped;
    progress_.rays += chunk.rays;
  }
  next_packet_ = end;
  progress_.shots = next_packet_;
  progress_.unshot_fraction = std::max(0.0, (emitted_ - emitted_so_far_).Sum() / emitted_.Sum());
  if (next_packet_ >= planned_) progress_.unshot_fraction = 0;
  EndStep(/*interrupted=*/false);
  return next_packet_ < planned_;
}

Solution ReflectionSolver::Snapshot() const {
  Solution sol = NewSolution();
  const auto& elements = mesh_.elements();
  sol.radiosity.assign(incident_.size(), Rgb());
  // Stopped early, the packets traced are a sample of all planned (interleaved over the
  // emitters): their tallies scaled to all of them are the estimate of the whole answer.
  const double scale =
      next_packet_ > 0 && next_packet_ < planned_
          ? static_cast<double>(planned_) / static_cast<double>(next_packet_)
          : 1.0;
  for (int s = 0; s < static_cast<int>(incident_.size()); ++s) {
    const SideRule& rule = sides()[s];
    if (!rule.exists) continue;
    // B = E + (R H + T' H') / A: the expected exitance given the tallied arrivals.
    sol.radiosity[s] = (emitted_slot_[s] + (rule.reflectance * incident_[s] +
                                            sides()[OtherSide(s)].transmittance *
                                                incident_[OtherSide(s)]) *
                                               scale) /
                       elements[ElementOfSlot(s)].area;
  }
  // Nothing traced yet: the emission's light as an ambient term.
  if (next_packet_ == 0 && planned_ > 0) AddAmbient(&sol);
  sol.unshot_power = next_packet_ >= planned_ ? Rgb() : emitted_ - emitted_so_far_;
  return sol;
}

}  // namespace radiosity
