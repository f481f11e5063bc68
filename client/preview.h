// Pictures of a job's radiosity on the client: the job's scene is downloaded once and meshed as
// the job's first mesh (the mesh is deterministic, so its elements are the server's) and rendered
// from any snapshot or the final result (`radiosity watch --preview-dir`, `radiosity render`).
// When the server announces a refined mesh (WatchJob include_mesh), the previewer rebuilds it from
// the first mesh and the announced element rectangles, so snapshots of every refinement pass
// render without restarting.
#ifndef RADIOSITY_CLIENT_PREVIEW_H_
#define RADIOSITY_CLIENT_PREVIEW_H_

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/client.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/results/false_color.h"
#include "solver/transport/gather.h"
#include "solver/transport/visibility.h"

namespace radiosity::client {

class Previewer {
 public:
  // Downloads the scene of `job` (a solve) into `dir` and builds its first mesh (the one RunJob
  // starts from: with adaptive refinement, a sixteenth of the element budget) and ray-tracing
  // scene.
  static absl::StatusOr<std::unique_ptr<Previewer>> Create(Client& client, const v1::Job& job,
                                                           const std::string& dir);
  int64_t elements() const { return static_cast<int64_t>(mesh_.elements().size()); }
  // Version of the announced mesh in use (0: the first mesh, built locally, no announcement).
  int64_t mesh_version() const { return mesh_version_; }
  // Switches to an announced mesh: splits the first mesh's leaves to the announced rectangles
  // (MeshFromElementRects), checks every element's surface, centroid and area against the
  // announcement (the traced faces, hence the ray-tracing scene, are the same). FAILED_PRECONDITION
  // when the announcement is not a refinement of the local first mesh (the previewer keeps its
  // previous mesh then).
  absl::Status UseMesh(const MeshGeometry& geometry);
  // Renders packed radiosity ((2 e + side) x 3 + channel, e in the server's element order) from
  // `camera` (ParseCamera syntax; empty: the default view) and writes the EXR and/or PNG (either
  // path may be empty). With `wireframe`, element edges are drawn over the shading
  // (DrawWireframe). With `false_color` (PNG only), the PNG shows radiosity on that scale with a
  // legend (FalseColorImage) instead of the tone-mapped shading. `samples_per_pixel` rays per
  // pixel; with `gather`, a final gather at the diffuse points the rays reach (RenderOptions::
  // gather) instead of interpolation; `progress` hears the fraction of rows done.
  absl::Status Render(const std::vector<float>& radiosity, const std::string& camera, int width,
                      int height, const std::string& exr_path, const std::string& png_path,
                      bool wireframe = false, const FalseColorRange* false_color = nullptr,
                      int samples_per_pixel = 4, const GatherOptions* gather = nullptr,
                      const std::function<void(double)>& progress = {}) const;

 private:
  Previewer() = default;
  Scene scene_;
  Mesh first_;                      // The job's first mesh.
  MeshOptions first_options_;       // Its options.
  double agglomerate_degrees_ = 0;  // The job's.
  Mesh mesh_;                       // The mesh in use.
  // Element of mesh_ for each of the server's elements (empty: the same numbering).
  std::vector<int> local_;
  int64_t mesh_version_ = 0;
  std::unique_ptr<Visibility> visibility_;
};

}  // namespace radiosity::client

#endif  // RADIOSITY_CLIENT_PREVIEW_H_
