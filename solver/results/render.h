// Rendering a solution: primary rays through Embree from a camera, and a wireframe over it.
#ifndef RADIOSITY_SOLVER_RESULTS_RENDER_H_
#define RADIOSITY_SOLVER_RESULTS_RENDER_H_

#include <array>
#include <functional>
#include <vector>

#include "solver/geometry/mesh.h"
#include "solver/geometry/solution.h"
#include "solver/results/camera.h"
#include "solver/results/image.h"
#include "solver/transport/gather.h"
#include "solver/transport/specular.h"
#include "solver/transport/visibility.h"
#include "solver/util/stop.h"

namespace radiosity {

// Renders the solution seen from `camera`: primary rays through Embree, element sides that do not
// exist (one-sided faces seen from behind) are skipped (a closed room can be viewed from outside),
// radiance = interpolated radiosity (CornerRadiosity) / pi. `stop` (may be null) is checked
// for every row: once it stops, the image returned is empty (width and height 0).
//
// The view pass of specular surfaces (docs/guide/specular.md): with `specular`
// (the scene's SpecularTable; may be null), a ray that arrives at a side with specular parts
// adds, to that side's diffuse radiance, the radiance along its mirror, glossy (one sample per
// visit) and transmitted directions times their weights, up to kMaxViewBounces deep and
// kMaxViewSegments rays per sample. Without specular surfaces the image is the same as without
// `specular`.
inline constexpr int kMaxViewBounces = 8;
inline constexpr int kMaxViewSegments = 64;
Image RenderImage(const Mesh& mesh, const Visibility& visibility, const Solution& solution,
                  const std::vector<std::array<Rgb, 4>>& corners, const Camera& camera, int width,
                  int height, int samples_per_pixel = 4, const StopToken* stop = nullptr,
                  const SpecularTable* specular = nullptr);

struct RenderOptions {
  int samples_per_pixel = 4;
  const StopToken* stop = nullptr;          // Checked for every row (may be null).
  const SpecularTable* specular = nullptr;  // The view pass through specular parts (above).
  // The final gather (docs/guide/specular.md): where a ray arrives at a diffuse
  // part, its radiance is (E + R H + T' H') / pi with the irradiance H (and the other side's H',
  // where that side transmits) gathered at the point by `gather` (direct light computed, the
  // solution's radiosity gathered for the rest), not interpolated between elements: shadows as
  // sharp as the geometry, no mesh in the image. Null: interpolation.
  const PointGather* gather = nullptr;
  // Called with the fraction of rows done, from the rendering threads (must be thread-safe).
  std::function<void(double)> progress;
};
Image RenderImage(const Mesh& mesh, const Visibility& visibility, const Solution& solution,
                  const std::vector<std::array<Rgb, 4>>& corners, const Camera& camera, int width,
                  int height, const RenderOptions& options);

// Wireframe over a rendered image (same mesh and camera as RenderImage made it with): the element
// each pixel centre sees is found by a primary ray, and pixels whose right or lower neighbour sees
// another element (or the other side, or nothing) are darkened to 15 %, drawing element edges and
// silhouettes one pixel wide. `pieces` (may be empty) maps each element to a piece of a coarser
// subdivision (e.g. the hierarchical solver's receivers): edges are then drawn between pieces
// only. Edges of elements smaller than a pixel merge into dark areas.
void DrawWireframe(const Mesh& mesh, const Visibility& visibility, const Camera& camera,
                   const std::vector<int>& pieces, Image* image);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_RESULTS_RENDER_H_
