// Pictures of a job's radiosity on the client: the job's scene is downloaded once, meshed with the
// job's mesh options (the mesh is deterministic, so its elements are the server's) and rendered
// from any snapshot or the final result (`radiosity watch --preview-dir`, `radiosity render`).
#ifndef RADIOSITY_CLIENT_PREVIEW_H_
#define RADIOSITY_CLIENT_PREVIEW_H_

#include <memory>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "client/client.h"
#include "solver/mesh.h"
#include "solver/scene.h"
#include "solver/visibility.h"

namespace radiosity::client {

class Previewer {
 public:
  // Downloads the scene of `job` (a solve) into `dir` and builds its mesh and ray-tracing scene.
  static absl::StatusOr<std::unique_ptr<Previewer>> Create(Client& client, const v1::Job& job,
                                                           const std::string& dir);
  int64_t elements() const { return static_cast<int64_t>(mesh_.elements().size()); }
  // Renders packed radiosity ((2 e + side) x 3 + channel) from `camera` (ParseCamera syntax; empty:
  // the default view) and writes the EXR and/or PNG (either path may be empty).
  absl::Status Render(const std::vector<float>& radiosity, const std::string& camera, int width,
                      int height, const std::string& exr_path, const std::string& png_path) const;

 private:
  Previewer() = default;
  Scene scene_;
  Mesh mesh_;
  std::unique_ptr<Visibility> visibility_;
};

}  // namespace radiosity::client

#endif  // RADIOSITY_CLIENT_PREVIEW_H_
