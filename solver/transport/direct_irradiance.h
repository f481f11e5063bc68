// Direct light computed, not sampled (Shirley's thesis 6.2.1: "only use the elements for direct
// lighting"): the irradiance that every element side, or a free point, receives straight from
// the emitters.
//
// For a receiver i and an emitting face P of exitance M (its emitting side's polygons),
//   H_i = M F_{i->P} V_{i,P},
// where F_{i->P} is the unoccluded form factor, integrated over the receiver by adaptive
// quadrature of Lambert's contour formula to a stated tolerance (area_to_polygon.h; exact for a
// point receiver), and V_{i,P} is the visible fraction, weighted by the kernel:
//   V = sum_k w_k v_k / sum_k w_k,  w_k = cos(theta_x) cos(theta_y) / r^2,
// from shadow rays between pairs (x_k, y_k) of points on the receiver and on the emitter taken
// from one Owen-scrambled Sobol' sequence per pair (4-D: stratified on both areas at once). Where
// every ray arrives the estimate is exactly 1 and has no variance (correlated sampling: the
// variance lives only in penumbrae) unless a corner of the element disagrees; where some are
// blocked, or all (a small visible part would otherwise be lost whole), max_shadow_rays are
// traced. Its standard error is the ratio estimator's,
//   se(V) = sqrt(sum_k w_k^2 (v_k - V)^2) / sum_k w_k  (Cochran 1977, 6.3),
// an independent-sampling formula, so an upper bound for the stratified points; or, with
// DirectOptions::replicates > 1, the spread of independently scrambled replicates' estimates.
//
// Planar mirrors (DirectOptions::mirror_images): every emitting face in front of a mirror plane
// (the planar faces with an ideal mirror part, grouped by plane and reflectance: a mirror
// modelled as many faces is one plane) also lights a receiver through it as its image, reflected
// about the plane with exitance times the mirror's reflectance (the image method; Shirley 6.3).
// The image's unoccluded factor is Lambert's (the point-to-polygon formula, or its quadrature
// over an element) and its visible fraction is found by the same shadow rays, each of which must
// meet a face of the plane on its reflecting side and then reach the real emitter. Only the part
// of an emitter in front of the plane has an image; planes smaller than kMinMirrorPlaneArea (a
// curved mirror's facets) make none. Images count against max_pairs like emitters; those left
// out are the caller's to shoot (ComputesImage).
//
// Many emitters: the emitting faces are taken brightest first while receivers x faces stays
// within max_pairs; the rest are left to the caller (the progressive solver shoots them as rays).
// Per receiver, faces whose unoccluded contribution is below 1e-3 of the receiver's total get
// only min_shadow_rays.
#ifndef RADIOSITY_SOLVER_TRANSPORT_DIRECT_IRRADIANCE_H_
#define RADIOSITY_SOLVER_TRANSPORT_DIRECT_IRRADIANCE_H_

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/vec.h"
#include "solver/transport/area_to_polygon.h"
#include "solver/transport/visibility.h"
#include "solver/util/stop.h"

namespace radiosity {

struct DirectOptions {
  // Shadow rays per receiver and emitting face, and where they disagree (a penumbra), up to this
  // many in all.
  int shadow_rays = 16;
  int max_shadow_rays = 256;
  // Shadow rays for faces contributing under 1e-3 of a receiver's unoccluded direct light.
  int min_shadow_rays = 4;
  QuadratureOptions quadrature;
  // Shadow rays come from this many independently scrambled sequences, in turn: 1, the most
  // accurate estimate, with the independent-sampling standard error (an upper bound); more, an
  // honest standard error from their spread at some cost in accuracy (sensors take 8).
  int replicates = 1;
  // Cost bound: receivers x emitting faces computed (the brightest faces first).
  int64_t max_pairs = 50'000'000;
  uint64_t seed = 1;
  // Light arriving by one reflection in a planar mirror, by the image method (see the file
  // comment), for at most kMaxMirrorImages emitter-mirror pairs.
  bool mirror_images = false;
};

inline constexpr int kMaxMirrorImages = 4096;
// Mirror planes smaller than this fraction of the square of the scene's diagonal make no images.
inline constexpr double kMinMirrorPlaneArea = 1e-3;
inline constexpr int64_t kMaxMirrorPairsExamined = 1 << 24;

// One emitting side of a mesh face.
struct DirectEmitter {
  int face = -1;
  int side = 0;
  Rgb exitance;
  double area = 0;
  Rgb power;                           // exitance x area.
  std::vector<SpacePolygon> polygons;  // Its halves, with the emitting side's normal.
  // An image (mirror_images): `face` seen in mirror plane `via` (an index of the planes that
  // BuildMirrorImages groups the mirror faces into), which passes through `plane_point` with
  // unit normal `plane_normal` (towards the reflecting side); `polygons` are reflected and
  // `exitance` includes the mirror's reflectance.
  int via = -1;
  Vec3 plane_point, plane_normal;
};

// The direct light of element sides: of every element (ForElements, indexed by slot), or of a
// list of elements (ForElementList, indexed by 2 x the element's position in the list + side).
struct DirectElements {
  std::vector<Rgb> irradiance;  // W/m^2 (also for sides that do not exist).
  std::vector<Rgb> std_error;   // The standard error of irradiance.
  // The part of irradiance that arrives through mirrors (DirectOptions::mirror_images; empty
  // without).
  std::vector<Rgb> via_mirrors;
  // Per element: some emitter is partly visible from it (a penumbra or a contact shadow).
  std::vector<uint8_t> penumbra;
  // Per element: its shadow rays and quadrature evaluations, and its shadow rays alone
  // (ForElementList only).
  std::vector<int64_t> work;
  std::vector<int64_t> element_rays;
  int64_t rays = 0;         // Shadow rays traced.
  int64_t evaluations = 0;  // Point-to-polygon evaluations of the quadrature.
  bool complete = true;     // False when stopped: the values are then partial.
};

class DirectIrradiance {
 public:
  DirectIrradiance(const Mesh& mesh, const Visibility& visibility, const DirectOptions& options,
                   int64_t receivers);

  // The emitting faces computed directly, brightest first.
  const std::vector<DirectEmitter>& emitters() const { return emitters_; }
  // Whether side `side` of mesh face `face` is among them, and its index in emitters() (-1: not).
  bool Computes(int face, int side) const { return EmitterIndex(face, side) >= 0; }
  int EmitterIndex(int face, int side) const;
  // The emitting faces left out by max_pairs.
  int64_t skipped() const { return skipped_; }
  // The images of emitters in mirror planes (DirectOptions::mirror_images), and whether side
  // `side` of emitting face `face` is computed as seen by one reflection in side `via_side` of
  // mesh face `via`.
  const std::vector<DirectEmitter>& images() const { return images_; }
  bool ComputesImage(int face, int side, int via, int via_side) const;

  // Every element side's direct irradiance, in parallel (in the caller's task arena); checks
  // `stop` per element and then returns what it has with complete = false.
  DirectElements ForElements(const StopToken& stop) const;
  // The same for the `count` elements listed at `elements`, in the caller's task arena; the
  // values do not depend on the list (each element's rays are keyed by the element).
  DirectElements ForElementList(const int* elements, size_t count, const StopToken& stop) const;

  // One element's (both sides, added to irradiance[2], variance[2], and the part through mirrors
  // to via_mirrors[2] when given); returns the shadow rays. Checks `stop` every 64 emitting
  // faces; once it stops, the values are partial.
  int64_t ForElement(int element, Rgb irradiance[2], Rgb variance[2], bool* penumbra,
                     int64_t* evaluations, const StopToken& stop = StopToken(),
                     Rgb* via_mirrors = nullptr) const;

  // At a free point x (mesh coordinates) with unit normal n, such as a sensor: the irradiance and
  // its standard error. `stream` keys the shadow rays.
  // Checks `stop` every 64 emitting faces; once it stops, the value is partial.
  Rgb AtPoint(const Vec3& x, const Vec3& n, uint64_t stream, Rgb* std_error, int64_t* rays,
              const StopToken& stop = StopToken()) const;

  std::string ToString() const;

 private:
  // images_ and image_keys_ (mirror_images), while receivers x polygons stays within max_pairs.
  void BuildMirrorImages(int64_t receivers, int64_t pairs);
  // Emitter k of emitters_ followed by images_.
  const DirectEmitter& Source(size_t k) const {
    return k < emitters_.size() ? emitters_[k] : images_[k - emitters_.size()];
  }
  size_t NumSources() const { return emitters_.size() + images_.size(); }

  const Mesh& mesh_;
  const Visibility& visibility_;
  DirectOptions options_;
  std::vector<DirectEmitter> emitters_;
  std::vector<int32_t> computes_;  // Per face slot Slot(face, side): 1 + its emitters_ index, or 0.
  std::vector<DirectEmitter> images_;
  // Sorted (Slot(face, side), mirror plane) of images_.
  std::vector<std::pair<int, int>> image_keys_;
  // Per face slot (Slot(face, side)): its mirror plane, or -1 (mirror_images); per mirror plane,
  // the bounding box (lo, hi) of its faces.
  std::vector<int> mirror_plane_;
  std::vector<std::array<Vec3, 2>> mirror_box_;
  // Whether the segments from the receiver's polygons to image `em` can cross its mirror plane
  // within the box of the plane's faces (false: the image is not seen from there at all).
  bool ApertureOverlaps(const std::vector<SpacePolygon>& receiver, const DirectEmitter& em) const;
  int replicates_ = 1;
  int64_t skipped_ = 0;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_DIRECT_IRRADIANCE_H_
