#include "client/preview.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "proto/api/spec.h"
#include "solver/geometry/interpolation.h"
#include "solver/geometry/solution.h"
#include "solver/input/scene_files.h"
#include "solver/methods/adaptive.h"
#include "solver/methods/method_choice.h"
#include "solver/results/camera.h"
#include "solver/results/image.h"
#include "solver/results/render.h"

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
  // The first mesh of RunJob (solver/job.cc): adaptive runs start from a sixteenth of the budget
  // and mesh every face. Whether a job that may agglomerate did is known from its announcement
  // (UseMesh builds the other kind then).
  MeshOptions first = spec->mesh;
  if (spec->refine.tolerance > 0 || !TakesAgglomeratedMesh(spec->solve)) {
    first.agglomerate_degrees = 0;
  }
  if (spec->refine.tolerance > 0 && first.element_size == 0) {
    first.max_elements = std::max<int64_t>(1, spec->mesh.max_elements / 16);
  }
  p->first_options_ = first;
  p->agglomerate_degrees_ = spec->mesh.agglomerate_degrees;
  absl::StatusOr<Mesh> mesh = Mesh::Build(p->scene_, first);
  if (!mesh.ok()) return mesh.status();
  p->first_ = *std::move(mesh);
  p->mesh_ = p->first_;
  absl::StatusOr<std::unique_ptr<Visibility>> visibility = Visibility::Build(p->mesh_);
  if (!visibility.ok()) return visibility.status();
  p->visibility_ = *std::move(visibility);
  return p;
}

absl::Status Previewer::UseMesh(const MeshGeometry& g) {
  const int64_t n = g.elements();
  auto mismatch = [&](const std::string& what) {
    return absl::FailedPreconditionError(
        absl::StrCat("the server's mesh version ", g.version, " (", n,
                     " elements) is not a refinement of the mesh built here (",
                     first_.elements().size(), " elements): ", what));
  };
  if (g.faces != static_cast<int64_t>(first_.faces().size())) {
    return mismatch(absl::StrCat(g.faces, " faces there, ", first_.faces().size(), " here"));
  }
  // A job that could agglomerate may have meshed every face ("auto" resolved to another method),
  // and the other way round: build the kind announced.
  const bool agglomerated =
      std::any_of(g.member_count.begin(), g.member_count.end(), [](int32_t c) { return c > 0; });
  if (agglomerated != first_.agglomerated()) {
    MeshOptions options = first_options_;
    options.agglomerate_degrees = agglomerated ? agglomerate_degrees_ : 0;
    absl::StatusOr<Mesh> rebuilt = Mesh::Build(scene_, options);
    if (!rebuilt.ok()) return rebuilt.status();
    first_ = *std::move(rebuilt);
  }
  std::vector<int> local;
  absl::StatusOr<Mesh> mesh;
  if (agglomerated) {
    // Never refined: the announced mesh is the first one, element for element.
    if (n != static_cast<int64_t>(first_.elements().size())) {
      return mismatch(
          absl::StrCat(n, " agglomerated elements there, ", first_.elements().size(), " here"));
    }
    mesh = first_;
    local.resize(static_cast<size_t>(n));
    for (int64_t i = 0; i < n; ++i) local[i] = static_cast<int>(i);
  } else {
    std::vector<ElementRect> rects(static_cast<size_t>(n));
    for (int64_t i = 0; i < n; ++i) {
      rects[i] = {g.face[i], g.uv[4 * i], g.uv[4 * i + 1], g.uv[4 * i + 2], g.uv[4 * i + 3]};
    }
    mesh = MeshFromElementRects(scene_, first_, rects, &local);
  }
  if (!mesh.ok()) return mismatch(std::string(mesh.status().message()));
  // The rebuilt elements must be the announced ones: same surface, centroid and area (the
  // announcement rounds them to float).
  const double tolerance = 1e-5 * std::max(mesh->scale(), 1e-300);
  for (int64_t i = 0; i < n; ++i) {
    const Element& e = mesh->elements()[local[i]];
    const Vec3 c{g.origin[0] + g.centroid[3 * i], g.origin[1] + g.centroid[3 * i + 1],
                 g.origin[2] + g.centroid[3 * i + 2]};
    if (e.surface != g.surface[i] || Length(e.centroid - c) > tolerance ||
        std::fabs(e.area - g.area[i]) > 1e-5 * std::max<double>(e.area, g.area[i])) {
      return mismatch(absl::StrFormat(
          "element %d: surface %d, centroid (%g, %g, %g), area %g there; surface %d, centroid "
          "(%g, %g, %g), area %g here",
          i, g.surface[i], c.x, c.y, c.z, g.area[i], e.surface, e.centroid.x, e.centroid.y,
          e.centroid.z, e.area));
    }
  }
  // Neither refinement nor agglomeration changes the traced faces, so the ray-tracing scene stays
  // as it is.
  mesh_ = *std::move(mesh);
  bool identity = true;
  for (int64_t i = 0; i < n && identity; ++i) identity = local[i] == i;
  local_ = identity ? std::vector<int>() : std::move(local);
  mesh_version_ = g.version;
  return absl::OkStatus();
}

absl::Status Previewer::Render(const std::vector<float>& radiosity, const std::string& camera_text,
                               int width, int height, const std::string& exr_path,
                               const std::string& png_path, bool wireframe,
                               const FalseColorRange* false_color, int samples_per_pixel,
                               const GatherOptions* gather,
                               const std::function<void(double)>& progress) const {
  const size_t slots = 2 * mesh_.elements().size();
  if (radiosity.size() != 3 * slots) {
    return absl::FailedPreconditionError(absl::StrCat("the snapshot has ", radiosity.size() / 6,
                                                      " elements but the local mesh has ",
                                                      mesh_.elements().size()));
  }
  Solution solution;
  solution.radiosity.resize(slots);
  for (size_t i = 0; i < slots; ++i) {
    // Server element i / 2 is local element local_[i / 2].
    const size_t slot = local_.empty() ? i : 2 * static_cast<size_t>(local_[i / 2]) + i % 2;
    solution.radiosity[slot] = Rgb{radiosity[3 * i], radiosity[3 * i + 1], radiosity[3 * i + 2]};
  }
  Camera camera = DefaultCamera(mesh_);
  if (!camera_text.empty()) {
    absl::StatusOr<Camera> parsed = ParseCamera(camera_text, camera);
    if (!parsed.ok()) return absl::InvalidArgumentError(parsed.status().message());
    camera = *parsed;
  }
  auto corners = CornerRadiosity(mesh_, solution);
  const SpecularTable specular(scene_);
  RenderOptions options;
  options.samples_per_pixel = samples_per_pixel;
  options.specular = &specular;
  std::unique_ptr<PointGather> point_gather;
  if (gather != nullptr) {
    point_gather = std::make_unique<PointGather>(scene_, mesh_, *visibility_, solution, *gather,
                                                 static_cast<int64_t>(width) * height);
    options.gather = point_gather.get();
  }
  options.progress = progress;
  Image image = RenderImage(mesh_, *visibility_, solution, corners, camera, width, height, options);
  if (wireframe) DrawWireframe(mesh_, *visibility_, camera, {}, &image);
  if (false_color != nullptr) {
    if (!exr_path.empty() || png_path.empty()) {
      return absl::InvalidArgumentError("--false-color writes a PNG (--out FILE.png)");
    }
    return WritePng8(FalseColorImage(image, *false_color), png_path);
  }
  return WriteImage(image, exr_path, png_path);
}

}  // namespace radiosity::client
