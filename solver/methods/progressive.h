// Progressive refinement by Monte Carlo shooting: absorb and re-emit (Shirley's thesis 6.1.3 and
// 6.2; Cohen, Chen, Wallace & Greenberg 1988).
//
// Every element side keeps the power it has received but not yet passed on ("unshot"). A step
// has every patch side shoot the same fraction of its unshot power (all of it once the step has
// room for that; at most kMaxRaysPerStep rays a step), as rays of equal power from points of its
// elements, in cosine-distributed directions: the number of rays is proportional to the power, so
// the rays spent over the whole solve are O(N) for N elements (6.2), and whatever the order.
// Shooting the same fraction everywhere (rather than the largest unshot power first, Southwell's
// order) keeps what is not yet shot spread as what is shot, which the estimate of the unshot
// light's effect (Final) assumes. A ray hitting element side j deposits its power there: R_j of
// it is added to j's unshot power and to its exitance, T_j goes to the other side, the rest is
// absorbed. A ray that hits nothing escapes.
//
// Accuracy per ray (bench/REPORT.md):
//  - direct light computed (options.direct = "computed"), without a silent step: the emitters
//    shoot their emission as rays like every other patch, and what arrives straight from a
//    computed emitter (or through a mirror image it computes) is kept per element side as a
//    placeholder. In steps that alternate with shooting steps, blocks of receiving elements (the
//    noisiest placeholders first) get DirectIrradiance's value (exact unoccluded factors times
//    visible fractions), which replaces the placeholder: the difference is deposited (its
//    reflected part joins the unshot power) as a loan against the emission still to shoot
//    (loan_), which what arrives by a computed path at a computed side later repays (it is
//    dropped), so the books balance after every block. After any step every side's direct light is
//    either computed or the rays' unbiased estimate of the emission shot so far;
//  - rays from Owen-scrambled Sobol' points (formfactor.sampling = "sobol"): a shot's rays are
//    spread over its elements by systematic sampling, and an element side's k-th ray ever takes
//    point k of a sequence scrambled for that side (its rays over all shots are one stratified
//    set), its position in the element from dimensions 0-1 and its direction from 2-3;
//  - light that has left a reflector received per patch (options.indirect = "patch", Monte Carlo
//    shooting only): a patch side tallies what arrives anywhere on it, reflects it uniformly over
//    its area, and its exitance reaches the elements by interpolation between the patches of the
//    face (bilinear between patch centres, renormalised so each patch keeps its power). As
//    shown (Final), each patch's value is first smoothed by a local plane through its 3 x 3
//    neighbourhood where a chi-square test accepts the plane (SmoothPatchLevel; each face keeps
//    its power). Light straight from an emitter stays per element.
// Before convergence (previews, and a solve stopped by a deadline, a cancel or a ray budget) the
// solution is a complete estimate (CompleteUnshot): each placeholder side's direct light is
// estimated from the share of the emission shot, and what is left unshot is spread by Cohen et
// al.'s ambient term with the reflectance the shots have measured (SolverBase::AddAmbient).
// Each element side's standard error is estimated from the squared powers of what it (or its
// patch) received, and from the direct step's visible-fraction errors (Solution::std_error).
//
// Specular surfaces (docs/guide/specular.md; transport/specular.h): a ray that
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
// (1 - S) of it; the emitters' rays go on along specular directions from where they arrive
// (what arrives by a computed path is a placeholder, or dropped, only for its diffuse part).
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
// biased, bench/REPORT.md); elsewhere light is received per element.
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
  bool Stalled() const override { return stalled_; }
  // Its bound: a solve whose rays, shot and still to shoot (ProjectedRays), would exceed
  // kStallBounces x rays_per_element an element stops as stalled (a closed scene of mean
  // reflectance above about 1 - 1 / kStallBounces, where the rays grow like 1 / (1 - rho)).
  static constexpr double kStallBounces = 2000;
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
    // Sobol' sampling: ray r is point sequence_first + (r - first_ray) of the side's sequence,
    // scrambled by sequence_key.
    uint32_t sequence_first;
    uint64_t sequence_key;
    bool element_level;  // Its rays' power is received per element (not per patch).
    // The direct step computes its emitter's light (the emitter's index in direct_->emitters(),
    // else -1): `direct` (the emission never shot before) arriving by a computed path (Covered)
    // is a placeholder or dropped (DepositCovered).
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
  // Whether the direct step computes the path by which `res` arrived.
  bool Covered(const RayGroup& group, const RayResult& res) const;
  // What Deposit does with the specular part S of what arrives at a side: the ray that brought
  // it carries it on (kTraced), it is absorbed (light not brought by a ray: form-factor rows),
  // or it is sent on diffusely, the glass part from the other side (the sky's and luminaires'
  // light, an approximation: docs/guide/specular.md).
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
  // The first steps with a sky or luminaires (options.sky, options.luminaires): their light
  // arriving at the element sides that reflect or transmit, a block of elements (about
  // kMaxRaysPerStep rays) a step, which enters the books as emitted power (sky.h,
  // luminaire.h). Until every block is done, Final estimates the rest (CompleteUnshot).
  absl::StatusOr<bool> SkyStep();
  // The computed direct light (see the file comment): whether a block is due now, and one block
  // of receiving elements (whole chunks of kDirectChunk elements in direct_order_, until their
  // shadow rays and quadrature evaluations reach kDirectBlockWork).
  bool DirectBlockDue() const;
  absl::StatusOr<bool> DirectBlock();
  static constexpr int kDirectChunk = 16;
  static constexpr int64_t kDirectBlockWork = int64_t{1} << 18;
  // The receiving elements (a side that reflects or transmits), noisiest placeholder first.
  std::vector<int32_t> DirectOrder() const;
  // `emission` of a computed emitter's shot arriving at `slot` by a computed path (`straight`:
  // not through a mirror): the slot's placeholder until its direct light is computed, dropped
  // (escaped) after. `ray`: brought by a ray (its specular part goes on with it), else by a row.
  void DepositCovered(int slot, const Rgb& emission, bool straight, bool ray);
  // Replaces the direct light element `e` holds by its computed direct light h (and its standard
  // error se, and the part through mirrors m) per side.
  void ApplyDirect(int e, const Rgb h[2], const Rgb se[2], const Rgb m[2]);
  // Completes a solution stopped before convergence (SolverBase::AddAmbient, with the reflectance
  // the shots have measured): a placeholder's side also gets the rest of its direct light, in
  // proportion to the share of the computed emitters' emission shot, and only what it sends on
  // of that rest spreads as ambient.
  void CompleteUnshot(Solution* sol) const;
  // The rays shot so far and those the unshot power and all its bounces will need, at the
  // reflectance the shots have measured (once the rays of one pass over the elements are shot).
  double ProjectedRays() const;
  // Books power arriving from a shot at `slot` (or a sink), and what the side sends on of it.
  void CountSentOn(int slot, const Rgb& power);
  Rgb arrived_, sent_on_;
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
  std::vector<Rgb> exitant_;  // Emitted + reflected + transmitted power that left the side.
  std::vector<double> hits_;  // Rays arrived per slot (a float would stop at 2^24).
  std::vector<uint32_t> sequence_used_;  // Per slot: points of its Sobol' sequence used.
  std::vector<Rgb> patch_unshot_;        // Per patch side: 2 * patch + side.
  // track_direct only (else empty), per slot: the part of unshot_ that is emission never shot,
  // the power that arrived, and the part of that straight from an emitter. Every operation on
  // unshot_ is linear, so the emission's part follows it exactly (overshooting included).
  std::vector<Rgb> emitted_unshot_, incident_, direct_in_;

  // Computed direct light (options.direct == "computed"): the emitters it computes, the
  // receiving elements in the order its blocks take them and how many are done (direct_next_),
  // per element whether it is computed, and per slot the direct power it holds (the
  // placeholder, then the computed value), the sum of squares of what left the side from the
  // placeholder, and the straight part of what it holds (track_direct).
  std::unique_ptr<DirectIrradiance> direct_;
  bool hybrid_ = false;  // With specular surfaces and rays: images in mirrors (see the header).
  std::vector<int32_t> direct_order_;
  int64_t direct_next_ = 0;
  bool direct_left_ = false;    // Receivers not yet computed (direct_order_ may not exist yet).
  bool last_was_block_ = true;  // Blocks and shooting steps alternate, shooting first.
  std::vector<uint8_t> direct_done_;
  std::vector<Rgb> held_, placeholder_sq_, held_straight_;
  // Computed ahead of the block that applies them (not part of the state): chunks of
  // direct_order_ from direct_next_ on, each with its values and its work.
  struct DirectChunk {
    DirectElements values;
    int64_t work = 0;
    int64_t rays = 0;  // Counted in progress when the chunk is applied, not when computed ahead.
  };
  // The computed direct light on element sides that do not exist (absorbed there), W.
  Rgb direct_absorbed_;
  std::vector<DirectChunk> direct_ahead_;
  // The computed direct light deposited ahead of the emission that brings it (a block's value
  // less its placeholder), less what arrived of that emission since (dropped): the unshot
  // power is less it, so the books balance. Once the computed emitters have shot all their
  // emission, what is left of it (the rays' sampling error) is booked as escaped (SettleLoan).
  Rgb loan_;
  // With every element's direct light computed, books the computed emitters' emission not yet
  // shot (absorbed, loan repaid) instead of shooting it.
  void WriteOffComputedEmission();
  void SettleLoan();
  // The unshot power's magnitude (per channel sums of absolute values), less the loan: what is
  // left to propagate.
  double UnshotMagnitude() const;
  std::vector<Rgb> direct_std_error_;  // Per slot: the direct irradiance's standard error.
  // A sky or luminaires: elements whose light from them is not yet computed (SkyStep takes
  // them in blocks, in sky_order_ from sky_next_ on).
  bool sky_pending_ = false;
  std::vector<int32_t> sky_order_;
  int64_t sky_next_ = 0;
  // The elements 0 .. n - 1 in a stride order (each stretch of it spread over the whole mesh).
  static std::vector<int32_t> StrideOrder(size_t n);
  std::vector<Rgb> sky_std_error_;  // Per slot: their irradiance's standard error.
  // Per face side: the power and area of its elements whose sky light is computed.
  std::vector<Rgb> sky_face_power_;
  std::vector<double> sky_face_area_;
  // Adds the estimated sky and luminaire light of the elements still to compute to *sol (see
  // CompleteUnshot); returns what they send on of it.
  Rgb CompletePendingSky(Solution* sol) const;
  bool sobol_ = true;         // formfactor.sampling == "sobol".
  bool patch_level_ = false;  // options.indirect == "patch" with Monte Carlo shooting.
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
  bool stalled_ = false;
  int64_t shot_rays_ = 0;  // Rays shot (not the direct step's shadow rays).
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_METHODS_PROGRESSIVE_H_
