// Writing results: elements.csv, summary.json, mesh.ply, and images rendered from the solution.
#ifndef RADIOSITY_SOLVER_OUTPUT_H_
#define RADIOSITY_SOLVER_OUTPUT_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "solver/mesh.h"
#include "solver/scene.h"
#include "solver/solution.h"
#include "solver/visibility.h"

namespace radiosity {

// A pinhole camera. fov is the vertical field of view in degrees.
struct Camera {
  Vec3 eye{0, 0, 1};
  Vec3 look{0, 0, 0};
  Vec3 up{0, 1, 0};
  double fov = 40;
  std::string ToString() const;
};

// Parses "eye=x,y,z look=x,y,z up=x,y,z fov=deg" (any subset, any order, separated by spaces;
// missing keys keep the values of `base`). Errors name the bad key or number.
absl::StatusOr<Camera> ParseCamera(const std::string& text, const Camera& base);

// A camera that frames the scene's bounding box, looking along +z with +y up (the Cornell box's
// published view direction), from far enough that the whole box is in view.
Camera DefaultCamera(const Mesh& mesh);

// Smoothed radiosity at the corners of every element side, for interpolated shading: for each face
// the values on the lattice of element corners are the area-weighted means of the element sides
// touching them. Indexed like the mesh's elements: corners[Slot(e, side)] = {c00, c10, c01, c11}
// at (u0,v0), (u1,v0), (u0,v1), (u1,v1).
std::vector<std::array<Rgb, 4>> CornerRadiosity(const Mesh& mesh, const Solution& solution);

// An RGB float image, row-major from the top-left pixel.
struct Image {
  int width = 0, height = 0;
  std::vector<float> rgb;  // 3 * width * height, linear radiance (W/m^2/sr).
};

// Renders the solution seen from `camera`: primary rays through Embree, one-sided faces seen from
// behind are skipped (a closed room can be viewed from outside), radiance = interpolated radiosity
// / pi.
Image RenderImage(const Mesh& mesh, const Visibility& visibility, const Solution& solution,
                  const std::vector<std::array<Rgb, 4>>& corners, const Scene& scene,
                  const Camera& camera, int width, int height, int samples_per_pixel = 4);

// Wireframe over a rendered image (same mesh, scene and camera as RenderImage made it with): the
// element each pixel centre sees is found by a primary ray, and pixels whose right or lower
// neighbour sees another element (or the other side, or nothing) are darkened to 15 %, drawing
// element edges and silhouettes one pixel wide. `pieces` (may be empty) maps each element to a
// piece of a coarser subdivision (e.g. the hierarchical solver's receivers): edges are then drawn
// between pieces only. Edges of elements smaller than a pixel merge into dark areas.
void DrawWireframe(const Mesh& mesh, const Visibility& visibility, const Scene& scene,
                   const Camera& camera, const std::vector<int>& pieces, Image* image);

// Writes linear HDR (OpenEXR, half float) and a tone-mapped sRGB PNG (exposure set so that the
// 99th percentile of luminance maps to 0.9). Either path may be empty to skip it.
absl::Status WriteImage(const Image& image, const std::string& exr_path,
                        const std::string& png_path);

// elements.csv: header exactly "surface,element,cx,cy,cz,area,r,g,b", one row per element, front
// side. Surfaces with a back side (two-sided or transmitting) also get their back sides in
// `back_path` (same header), which is not written when no surface has a back side.
absl::Status WriteElementsCsv(const Scene& scene, const Mesh& mesh, const Solution& solution,
                              const std::string& path, const std::string& back_path);

// mesh.ply (ASCII): element polygons with per-vertex colours (interpolated radiosity, tone-mapped
// to 8 bits) and float properties r, g, b holding the linear radiosity itself.
absl::Status WritePly(const Scene& scene, const Mesh& mesh, const Solution& solution,
                      const std::vector<std::array<Rgb, 4>>& corners, const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_OUTPUT_H_
