// Progressive refinement by Monte Carlo shooting: absorb and re-emit (Shirley's thesis 6.1.3 and
// 6.2; Cohen, Chen, Wallace & Greenberg 1988).
//
// Every element side keeps the power it has received but not yet passed on ("unshot"). A step
// picks the patch sides with the most unshot power (Southwell order; several per step so that the
// rays fill all cores), and each shoots its unshot power as rays of equal power from points of its
// elements, in cosine-distributed directions: the number of rays is proportional to the power, so
// the rays spent over the whole solve are O(N) for N elements (6.2). A ray hitting element side j
// deposits its power there: R_j of it is added to j's unshot power and to its exitance, T_j goes
// to the other side, the rest is absorbed. A ray that hits nothing escapes.
//
// Accuracy per ray (README "Accuracy per second"):
//  - direct light computed (options.direct = "computed"): the first step replaces the emitters'
//    first shot by DirectIrradiance (exact unoccluded factors times visible fractions), kept per
//    element; the emitters it computed have no unshot power after it;
//  - rays from Owen-scrambled Sobol' points (formfactor.sampling = "sobol"): a shot's ray k takes
//    point k of a sequence scrambled for that shot, its element by systematic sampling of k, its
//    position in the element from dimensions 0-1 and its direction from 2-3;
//  - light that has left a reflector received per patch (options.indirect = "patch", Monte Carlo
//    shooting only): a patch side tallies what arrives anywhere on it, reflects it uniformly over
//    its area, and its exitance reaches the elements by interpolation between the patches of the
//    face (bilinear between patch centres, renormalised so each patch keeps its power). As
//    shown (Final), each patch's value is first smoothed by a local plane through its 3 x 3
//    neighbourhood where a chi-square test accepts the plane (SmoothPatchLevel; each face keeps
//    its power). Light straight from an emitter that the direct step did not compute stays per
//    element.
// Each element side's standard error is estimated from the squared powers of what it (or its
// patch) received, and from the direct step's visible-fraction errors (Solution::std_error).
//
// Specular surfaces (README "Specular and glossy surfaces"; transport/specular.h): a ray that
// arrives at a side with specular parts S deposits there as above (S is not absorbed) and goes
// on along the mirror, glossy and transmitted directions, each branch carrying its fraction of
// the ray's power, until what it carries reaches diffuse parts, escapes, or is given up
// (kMaxSpecularBounces, kSpecularCutWeight: booked as absorbed). Only diffuse radiosity is
// stored. The sky's and luminaires' light arriving at a specular part is sent on diffusely, and
// form-factor rows (non-Monte Carlo shooting) absorb it.
//
// With specular surfaces the direct step is a hybrid of zones and images (Shirley 6.3): it
// computes what arrives straight from the emitters and, by the image method, through one ideal
// reflection in a planar mirror (DirectOptions::mirror_images), and deposits the diffuse part
// (1 - S) of it; the emitters still shoot their emission as rays, for what continues
// specularly (or escapes), with rays in proportion to that part of it, but where such a ray
// arrives by a path the step computed (straight, or after one reflection in a mirror whose image
// of its emitter was computed), its diffuse part is dropped and only its specular part goes on. The
// books stay exact: the step's deposits are credited against the emitters' unshot power
// (Solution::unshot_power is less the credit not yet used), and each dropped share uses up the
// credit in proportion to the emission shot, the difference (the rays' sampling error against the
// computed value) booked as escaped: in a closed scene the escaped power is then that small
// difference, of either sign.
//
// Energy is conserved exactly (up to rounding): emitted = absorbed + escaped + unshot at every
// step. Results depend only on the seed: rays are generated in fixed chunks, each with its own
// random stream, and merged in order, whatever the thread count.
#ifndef RADIOSITY_SOLVER_METHODS_PROGRESSIVE_H_
#define RADIOSITY_SOLVER_METHODS_PROGRESSIVE_H_

#include <atomic>
#include <memory>
#include <vector>

#include "solver/methods/solver.h"
#include "solver/transport/direct_irradiance.h"
#include "solver/transport/rng.h"
#include "solver/transport/specular.h"

namespace radiosity {

// Patch-level reception (options.indirect == "patch") carries the light that has left a
// reflector at the resolution of the patches: it is used only when every patch's longer side is
// at most this fraction of the scene's diagonal (the transport of coarser patches is visibly
// biased, README "Accuracy per second"); elsewhere light is received per element.
inline constexpr double kPatchLevelMaxSize = 0.1;
bool PatchesFineEnough(const Mesh& mesh);

class ProgressiveSolver : public SolverBase {
 public:
  ProgressiveSolver(const Scene& scene, const Mesh& mesh, const Visibility& visibility,
                    const SolveOptions& options, const std::atomic<bool>* stop);
  ~ProgressiveSolver() override;

  // Creates the form-factor estimator when options.formfactor.method is not "montecarlo" (then
  // each shot distributes the patch's power by an estimated row, F_pj, instead of by its own rays).
  absl::Status Init();

  // Checks the stop flag and the deadline between chunks of rays (or rows); a step cut short
  // gives the power of the rays it did not trace back to their shooters.
  absl::StatusOr<bool> Step() override;
  Solution Snapshot() const override;
  Solution Final() const override;
  // The per-slot and per-patch tallies, the pending first steps and what they measured.
  bool SaveState(StateWriter* out) const override;
  absl::Status RestoreState(StateReader* in) override;

  // Rays per step at most (a step is the unit of progress reports and cancellation).
  static constexpr int64_t kMaxRaysPerStep = 1 << 18;
  // Rays per independent random stream.
  static constexpr int kChunk = 4096;

 private:
  // A run of rays from one element side, each carrying `power`.
  struct RayGroup {
    int element;
    int side;
    int64_t first_ray;
    int64_t count;
    Rgb power;
    Rgb direct;  // The part of `power` that is emission never shot before (track_direct).
    int64_t shot_first_ray;  // The first ray of its shot: ray r is point r - shot_first_ray.
    uint64_t shot_key;       // The shot's scramble (sobol) or stream.
    bool element_level;      // Its rays' power is received per element (not per patch).
    // The hybrid direct step computed its emitter's light (the emitter's index in
    // direct_->emitters(), else -1): `direct` (the emission never shot before) is dropped where
    // it arrives by a computed path (Covered).
    int32_t emitter;
  };
  // Where a ray's power went: a slot (element side), or a sink.
  static constexpr int32_t kEscaped = -1;
  static constexpr int32_t kAbsorbedBack = -2;  // Hit the back of a one-sided surface.
  // One arrival of (part of) a ray: `weight` is the fraction of its group's power that arrives
  // (1 straight from the shooter, less after specular bounces).
  struct RayResult {
    int32_t slot;
    int32_t group;
    Rgb weight;
    // kStraight from the shooter; Slot(face, side) of the mirror after exactly one ideal
    // reflection there, by the mirror part of the surface; or kScattered.
    int32_t via;
  };
  static constexpr int32_t kStraight = -1;
  static constexpr int32_t kScattered = -2;
  // Whether the direct step computed the path by which `res` arrived (the hybrid direct step).
  bool Covered(const RayGroup& group, const RayResult& res) const;
  // What Deposit does with the specular part S of what arrives at a side: the ray that brought
  // it carries it on (kTraced), it is absorbed (light not brought by a ray: form-factor rows),
  // or it is sent on diffusely, the glass part from the other side (the sky's and luminaires'
  // light, an approximation: README "Specular and glossy surfaces").
  enum class SpecularPart { kTraced, kAbsorbed, kDiffuse };

  // Traces chunk `chunk`'s rays, appending their arrivals to `out` in ray order.
  void TraceChunk(int64_t chunk, int64_t total_rays, std::vector<RayResult>* out) const;
  // Follows the light leaving specularly from `hit` (of a ray from `origin` along `dir` that
  // arrived with `weight` at slot `slot`), appending each arrival (group `group`) to `out`.
  void FollowSpecular(const Hit& hit, int slot, const Vec3& origin, const Vec3& dir,
                      const Rgb& weight, int32_t group, Rng* rng,
                      std::vector<RayResult>* out) const;
  // Gives rays [first_ray, end of the step) back to their shooters' unshot power (a step cut
  // short).
  void ReturnUntraced(int64_t first_ray);
  // One step shooting with form-factor rows: the shooters within a factor 4 of the largest (at
  // most kRowsPerStep), each row estimated in parallel, deposited in order.
  absl::StatusOr<bool> StepWithRows(double w_max);
  static constexpr int kRowsPerStep = 64;
  // Adds power arriving at a slot (or a sink); `direct` is the part of it straight from an
  // emitter. With patch_level, the power is tallied on the slot's patch side; `ray` marks a
  // ray's arrival (counted in hits_ and in the squared sums of the standard error).
  void Deposit(int slot_hit, const Rgb& power, const Rgb& direct, bool patch_level = false,
               bool ray = true, SpecularPart specular = SpecularPart::kAbsorbed);
  // Ends a step that ran to its end: progress, the unshot fraction, convergence. Returns whether
  // there is more to do.
  bool EndCompleteStep();
  // The first step with a sky or luminaires (options.sky, options.luminaires): their light
  // arriving at every element side that reflects or transmits, which enters the books as emitted
  // power (sky.h, luminaire.h).
  absl::StatusOr<bool> SkyStep();
  // The first step with options.direct == "computed": direct light to every element side.
  absl::StatusOr<bool> DirectStep();
  // Moves patch side `patch_slot`'s patch-level unshot power to its elements by area, before it
  // shoots.
  void SpreadPatchUnshot(int patch_slot);
  // The shape of patch side `patch_slot`'s patch-level exitance over its elements, normalised to
  // an area mean of 1 per channel: InterpolatedShape times openness, shrunk towards the
  // elements' own tallies as far as a chi-square says they disagree with it. Returns the
  // tallies' weight (0: the interpolation, 1: the tallies).
  // `level` holds each patch side's exitant power (patch_level_exitant_ or SmoothPatchLevel's).
  double PatchShape(int patch_slot, const std::vector<Rgb>& level, std::vector<Rgb>* shape) const;
  // Bilinear between the centres of the patches of its face (their exitance per open area),
  // extrapolated linearly beyond the outermost ones, clamped at zero, times each element's
  // openness, normalised.
  void InterpolatedShape(int patch_slot, const std::vector<Rgb>& level,
                         std::vector<Rgb>* shape) const;
  // Per patch side: the exitant power received at the patch level as shown, and its variance.
  // Each patch's value per open area is replaced by a least-squares plane through it and its
  // neighbours on the face (a 3 x 3 window), shrunk back towards its own value as far as a
  // chi-square says the plane misfits; each face side keeps its total.
  void SmoothPatchLevel(std::vector<Rgb>* power, std::vector<Rgb>* variance) const;
  // Whether a contact edge crosses patch side `patch_slot` (one of its elements is partly covered
  // by what rests on it: openness < 1).
  bool CrossedByContact(int patch_slot) const;
  // Per slot: the exitance received at the patch level, interpolated between the patches of each
  // face (see the file comment), and its standard error.
  void InterpolatePatchExitance(std::vector<Rgb>* exitance, std::vector<Rgb>* std_error) const;

  std::unique_ptr<FormFactorEstimator> estimator_;  // Only for non-Monte Carlo shooting.

  // Per slot (Slot(element, side)).
  std::vector<Rgb> unshot_;
  std::vector<Rgb> exitant_;       // Emitted + reflected + transmitted power that left the side.
  std::vector<double> hits_;       // Rays arrived per slot (a float would stop at 2^24).
  std::vector<Rgb> patch_unshot_;  // Per patch side: 2 * patch + side.
  // track_direct only (else empty), per slot: the part of unshot_ that is emission never shot,
  // the power that arrived, and the part of that straight from an emitter. Every operation on
  // unshot_ is linear, so the emission's part follows it exactly (overshooting included).
  std::vector<Rgb> emitted_unshot_, incident_, direct_in_;

  // Computed direct light (options.direct == "computed"): pending until the first step.
  std::unique_ptr<DirectIrradiance> direct_;
  bool direct_pending_ = false;
  // The hybrid direct step (specular surfaces; see the file comment), per computed emitter
  // (direct_->emitters() order): the credit of what it deposited, the part of it not yet set
  // against shot emission, and the emission it was computed for.
  bool hybrid_ = false;
  std::vector<Rgb> credit_, credit_left_, credit_emission_;
  // Sets emitter k's credit for `power` of its emission shot (negative: given back) against the
  // escaped power.
  void UseCredit(int k, const Rgb& power);
  // The unshot power's magnitude (per channel sums of absolute values), less the credit not yet
  // used: what is left to propagate.
  double UnshotMagnitude() const;
  std::vector<Rgb> direct_std_error_;  // Per slot: the direct irradiance's standard error.
  bool sky_pending_ = false;           // A sky or luminaires: SkyStep not yet done.
  std::vector<Rgb> sky_std_error_;     // Per slot: their irradiance's standard error.
  bool sobol_ = true;                  // formfactor.sampling == "sobol".
  bool patch_level_ = false;           // options.indirect == "patch" with Monte Carlo shooting.
  // Per patch side (patch_level_): unshot power received at the patch level (spread over the
  // elements when the patch shoots), the power that left the patch side from it, and the sum of
  // the squares of its parts (per channel, for the standard error).
  std::vector<Rgb> patch_level_unshot_, patch_level_exitant_, patch_level_sq_;
  // Per slot (patch_level_): the same tallies as each element would have kept, for the test of
  // PatchShape and for patches that fail it.
  std::vector<Rgb> tally_exitant_, tally_sq_;
  // patch_level_: per slot, how open the side is (openness.h; measured in the first step), and
  // per patch side, its area weighted by openness.
  std::vector<float> openness_;
  std::vector<double> patch_open_area_;
  // Per slot: the sum of the squares of the exitant parts received per element.
  std::vector<Rgb> element_sq_;
  // Per patch side: its rays are received per element (emitters the direct step left out).
  std::vector<uint8_t> element_level_shooter_;

  double ray_power_ = 0;  // Scalar (channel sum) power one ray carries.
  std::vector<RayGroup> groups_;
  std::vector<std::vector<RayResult>> chunk_results_;  // Per chunk of the step's rays.
  SpecularTable specular_;  // Per surface side: its specular parts (transport/specular.h).
  bool done_ = false;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_PROGRESSIVE_H_
