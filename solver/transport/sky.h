// Daylight from outside the scene (`--sky`): a sky dome at infinity over the upper hemisphere
// (about `up`; nothing below the horizon), lighting every element side that sees it.
//
// Models, given the unobstructed horizontal irradiance E_h (W/m^2 per channel; a horizontal
// surface under the open sky receives E_h):
//  - uniform: constant radiance L = E_h / pi;
//  - overcast: the CIE standard overcast sky (Moon & Spencer 1942; CIE S 011/E:2003 sky type 16),
//    L(theta) = L_z (1 + 2 cos theta) / 3 for the zenith angle theta, where integrating
//    L cos theta over the hemisphere gives E_h = 7 pi L_z / 9, so L_z = 9 E_h / (7 pi).
// A vertical surface under the open sky receives E_h / 2 (uniform) and
// E_h (pi / 2 + 4 / 3) / (7 pi / 3) = 0.3961 E_h (overcast).
//
// The irradiance of an element side is H = integral of L(w) V(w) cos(theta_n) dw over its
// hemisphere (V: the ray from a point of the element escapes the scene), estimated from
// `samples` Owen-scrambled Sobol' points per side (position in the element, cosine-distributed
// direction): H = pi x mean of L(w) V(w), with its standard error from the sample variance.
#ifndef RADIOSITY_SOLVER_TRANSPORT_SKY_H_
#define RADIOSITY_SOLVER_TRANSPORT_SKY_H_

#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/vec.h"
#include "solver/transport/visibility.h"
#include "solver/util/bounds.h"
#include "solver/util/stop.h"

namespace radiosity {

struct SkyOptions {
  // "none", "uniform" or "overcast".
  std::string model = "none";
  // E_h: the horizontal irradiance under the open sky, W/m^2 per channel.
  Rgb irradiance;
  // The zenith direction, in scene coordinates (need not be unit length). +y, as in glTF.
  Vec3 up{0, 1, 0};
  // Sobol' points per element side.
  int samples = 256;

  bool enabled() const { return model != "none"; }
  // Radiance arriving from direction `dir` (unit, pointing at the sky), W/(m^2 sr).
  Rgb Radiance(const Vec3& dir) const;
  std::string ToString() const;
};

inline constexpr Bounds kSkySamplesBounds{1, 65536, "[1, 65536]"};

// The elements a computation of light from outside the mesh covers: elements order[first] to
// order[last - 1] (every element, in order, by default).
struct ElementRange {
  const std::vector<int32_t>* order = nullptr;
  size_t first = 0;
  size_t last = static_cast<size_t>(-1);
  size_t size(size_t elements) const { return std::min(last, order ? order->size() : elements) - first; }
  int Element(size_t i) const { return order ? (*order)[first + i] : static_cast<int>(first + i); }
};

// Light received from outside the mesh (a sky, luminaires) by every element side.
struct ElementIrradiance {
  std::vector<Rgb> irradiance;  // Per slot, W/m^2 (zero for sides that do not exist).
  std::vector<Rgb> std_error;   // Per slot.
  int64_t rays = 0;
  bool complete = true;  // False when stopped: the values are then partial.
};

// The sky's irradiance on every existing side of the elements of `range` (`sides_exist(slot)`;
// indexed by slot, zero elsewhere), in the calling thread's task arena. Deterministic for a seed,
// whatever the thread count and the range.
ElementIrradiance SkyIrradiance(const Mesh& mesh, const Visibility& visibility, const SkyOptions& sky,
                          uint64_t seed, const StopToken& stop, const ElementRange& range = {});

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_SKY_H_
