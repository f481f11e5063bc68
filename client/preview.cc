#include "client/preview.h"

#include "absl/strings/str_cat.h"
#include "proto/scene_codec.h"
#include "server/spec.h"
#include "solver/output.h"
#include "solver/solution.h"

namespace radiosity::client {

absl::StatusOr<std::unique_ptr<Previewer>> Previewer::Create(Client& client, const v1::Job& job,
                                                             const std::string& dir) {
  if (!job.has_solve()) {
    return absl::FailedPreconditionError(absl::StrCat(job.name(), " is not a solve"));
  }
  absl::StatusOr<JobSpec> spec = service::ToJobSpec(job.solve());
  if (!spec.ok()) return spec.status();
  absl::StatusOr<std::string> main = client.DownloadScene(job.scene(), dir);
  if (!main.ok()) return main.status();
  std::unique_ptr<Previewer> p(new Previewer());
  absl::StatusOr<Scene> scene = LoadSceneFile(*main, nullptr);
  if (!scene.ok()) return scene.status();
  p->scene_ = *std::move(scene);
  absl::StatusOr<Mesh> mesh = Mesh::Build(p->scene_, spec->mesh);
  if (!mesh.ok()) return mesh.status();
  p->mesh_ = *std::move(mesh);
  absl::StatusOr<std::unique_ptr<Visibility>> visibility = Visibility::Build(p->mesh_);
  if (!visibility.ok()) return visibility.status();
  p->visibility_ = *std::move(visibility);
  return p;
}

absl::Status Previewer::Render(const std::vector<float>& radiosity, const std::string& camera_text,
                               int width, int height, const std::string& exr_path,
                               const std::string& png_path) const {
  const size_t slots = 2 * mesh_.elements().size();
  if (radiosity.size() != 3 * slots) {
    return absl::FailedPreconditionError(absl::StrCat("the snapshot has ", radiosity.size() / 6,
                                                      " elements but the local mesh has ",
                                                      mesh_.elements().size()));
  }
  Solution solution;
  solution.radiosity.resize(slots);
  for (size_t i = 0; i < slots; ++i) {
    solution.radiosity[i] = Rgb{radiosity[3 * i], radiosity[3 * i + 1], radiosity[3 * i + 2]};
  }
  Camera camera = DefaultCamera(mesh_);
  if (!camera_text.empty()) {
    absl::StatusOr<Camera> parsed = ParseCamera(camera_text, camera);
    if (!parsed.ok()) return absl::InvalidArgumentError(parsed.status().message());
    camera = *parsed;
  }
  auto corners = CornerRadiosity(mesh_, solution);
  Image image = RenderImage(mesh_, *visibility_, solution, corners, scene_, camera, width, height);
  return WriteImage(image, exr_path, png_path);
}

}  // namespace radiosity::client
