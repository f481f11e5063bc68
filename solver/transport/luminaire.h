// Luminaires: light from photometric files (photometry.h), placed in the scene by position and
// orientation. A luminaire is not geometry: rays from the scene pass through it, and its light
// reaches a receiver only directly, computed (not shot as rays):
//
//   E(x) = I(omega) cos(theta_x) / d^2 x V(x, y)                       (inverse-square law)
//
// for a point luminaire at y (omega the direction from y to x, d = |x - y|, theta_x the angle at
// the receiver, V the shadow ray). A luminaire whose file gives a luminous opening (LM-63 width
// and length, EULUMDAT luminous area; a rectangle, or a disc) is an area luminaire: every point
// of the opening emits the same distribution, scaled by 1/area, and E is the mean over points of
// it (Owen-scrambled Sobol' points, as for every element: IES LM-63-2019 annex D's near field).
//
// Units are photometric: candela in, lux (lm/m^2) out, for a scene modelled in metres. The solver
// is linear, so the lumens a luminaire sends enter the same books as the W of emitting surfaces;
// a scene should use one or the other.
#ifndef RADIOSITY_SOLVER_TRANSPORT_LUMINAIRE_H_
#define RADIOSITY_SOLVER_TRANSPORT_LUMINAIRE_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/photometry.h"
#include "solver/geometry/vec.h"
#include "solver/transport/sky.h"
#include "solver/transport/visibility.h"
#include "solver/util/bounds.h"
#include "solver/util/stop.h"

namespace radiosity {

struct Luminaire {
  // The photometric file, a name among the scene's files (.ies or .ldt).
  std::string file;
  // Where its photometric centre is, scene coordinates (metres).
  Vec3 position;
  // The direction of gamma = 0 (the nadir of a downlight; need not be unit length).
  Vec3 aim{0, -1, 0};
  // The direction of the C0 plane (projected perpendicular to `aim`); C90 is a quarter turn
  // counterclockwise from it seen from behind the luminaire (from above a downlight), as in
  // LM-63. When parallel to `aim`, +z is taken (or +x for an aim along z).
  Vec3 c0{1, 0, 0};
  // Multiplies the file's candela (a dimming, maintenance or lumen-scaling factor).
  double multiplier = 1;
  // The light's colour, scaled to luminance 1: the luminance-weighted result is photometric.
  Rgb color{1, 1, 1};
  // The parsed file (set by the pipeline from the scene's files; null until then).
  std::shared_ptr<const Photometry> photometry;

  // Intensity per channel toward the unit direction `dir` (from the luminaire), cd.
  Rgb Intensity(const Vec3& dir) const;
  // Flux, lm per channel (Photometry::flux x multiplier x colour).
  Rgb Flux() const;
  // A point of the luminous opening for (u1, u2) in [0, 1)^2, uniform by area (the position
  // itself for a point luminaire).
  Vec3 OpeningPoint(double u1, double u2) const;
  bool IsArea() const;
  std::string ToString() const;
};

// Points per receiver (element side, sensor) and area luminaire; a point luminaire needs one per
// point of the receiver.
inline constexpr int kDefaultLuminaireSamples = 64;
inline constexpr Bounds kLuminaireSamplesBounds{1, 65536, "[1, 65536]"};
inline constexpr size_t kMaxLuminaires = 10'000;

// The direct light of all `luminaires` (positions in scene coordinates) on every existing side of
// the elements of `range`: the mean of E over `samples` Sobol' points of the element (and of the
// opening), with its standard error from the sample variance. Runs in the calling thread's task
// arena; deterministic for a seed, whatever the range.
ElementIrradiance LuminaireIrradiance(const Mesh& mesh, const Visibility& visibility,
                                      const std::vector<Luminaire>& luminaires, int samples,
                                      uint64_t seed, const StopToken& stop,
                                      const ElementRange& range = {});

// The direct light of all `luminaires` at point `x` (mesh coordinates: scene - mesh.origin()) with
// unit normal `n`: exact for point luminaires (one shadow ray each), the mean over `samples`
// points of the opening for area ones. Adds the standard error's square to *variance and the rays
// to *rays.
Rgb LuminaireIrradianceAt(const Mesh& mesh, const Visibility& visibility,
                          const std::vector<Luminaire>& luminaires, const Vec3& x, const Vec3& n,
                          int samples, uint64_t stream, Rgb* variance, int64_t* rays);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_LUMINAIRE_H_
