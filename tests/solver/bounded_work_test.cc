// Bounded work before and after the solve (issue 15): polygons beyond kMaxFaceVertices are refused
// at load naming the line, and the steps around a solve (reading an OBJ, meshing, the ray-tracing
// structure, rendering) stop at the stop flag or the deadline, so that no input can keep a job
// from being cancelled. The solvers' own loops are tests/solver/cancel_test.cc.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "solver/geometry/interpolation.h"
#include "solver/geometry/mesh.h"
#include "solver/input/obj_loader.h"
#include "solver/pipeline/job.h"
#include "solver/results/camera.h"
#include "solver/results/render.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using testing::AddRect;
using testing::BuildMesh;
using testing::TempDir;

TEST(BoundedWorkTest, AFaceOfMoreVerticesThanTheLimitIsRefusedNamingItsLine) {
  const int n = static_cast<int>(kMaxFaceVertices);
  std::vector<std::string> warnings;
  ASSERT_OK_AND_ASSIGN(Scene at_limit,
                       ParseObj(testing::RegularPolygonObj(n), "gon.obj", "", &warnings, {}));
  EXPECT_EQ(at_limit.faces.size(), 1u);
  absl::StatusOr<Scene> over =
      ParseObj(testing::RegularPolygonObj(n + 1), "gon.obj", "", &warnings, {});
  ASSERT_FALSE(over.ok());
  EXPECT_EQ(over.status().code(), absl::StatusCode::kInvalidArgument);
  // The face is on the line after the n + 1 vertices.
  EXPECT_NE(over.status().message().find(absl::StrCat("gon.obj:", n + 2, ": ")), std::string::npos)
      << over.status();
  EXPECT_NE(over.status().message().find(absl::StrCat("has ", n + 1, " vertices")),
            std::string::npos)
      << over.status();
  EXPECT_NE(over.status().message().find(absl::StrCat("at most ", n)), std::string::npos);
}

// A grid of 2 x cells^2 triangles in the unit square, one grey surface, lit by a small quad above.
Scene TriangleGrid(int cells) {
  Scene scene;
  Material grey;
  grey.name = "grey";
  grey.reflectance = Rgb::Gray(0.5);
  Material light;
  light.name = "light";
  light.emission = Rgb::Gray(1);
  scene.materials = {grey, light};
  scene.surfaces.push_back({"floor", 0});
  for (int j = 0; j <= cells; ++j) {
    for (int i = 0; i <= cells; ++i) {
      scene.vertices.push_back({static_cast<double>(i) / cells, static_cast<double>(j) / cells, 0});
    }
  }
  auto at = [&](int i, int j) { return j * (cells + 1) + i; };
  for (int j = 0; j < cells; ++j) {
    for (int i = 0; i < cells; ++i) {
      scene.faces.push_back({0, {at(i, j), at(i + 1, j), at(i + 1, j + 1)}});
      scene.faces.push_back({0, {at(i, j), at(i + 1, j + 1), at(i, j + 1)}});
    }
  }
  AddRect(&scene, "lamp", 1, {0.4, 0.6, 1}, {0.2, 0, 0}, {0, -0.2, 0});
  return scene;
}

TEST(BoundedWorkTest, MeshingStopsAtTheFlagAndAtTheDeadline) {
  const Scene scene = TriangleGrid(100);
  MeshOptions options;
  options.max_elements = 1000;
  options.agglomerate_degrees = 10;
  std::atomic<bool> flag{true};
  const StopToken raised(&flag, 0);
  absl::StatusOr<Mesh> cancelled = Mesh::Build(scene, options, &raised);
  ASSERT_FALSE(cancelled.ok());
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled) << cancelled.status();
  EXPECT_NE(cancelled.status().message().find("meshing"), std::string::npos);
  // A deadline already passed (a nanosecond from now, the clock read after).
  const StopToken deadline(nullptr, 1e-9);
  absl::StatusOr<Mesh> late = Mesh::Build(scene, options, &deadline);
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.status().code(), absl::StatusCode::kDeadlineExceeded) << late.status();
  // Neither stopped: the same mesh as without a token.
  flag = false;
  ASSERT_OK_AND_ASSIGN(Mesh with_token, Mesh::Build(scene, options, &raised));
  ASSERT_OK_AND_ASSIGN(Mesh without, Mesh::Build(scene, options));
  EXPECT_EQ(with_token.elements().size(), without.elements().size());
}

TEST(BoundedWorkTest, TheRayTracingStructureStopsAtTheFlag) {
  ASSERT_OK_AND_ASSIGN(Mesh mesh, BuildMesh(TriangleGrid(60), 0.05));
  std::atomic<bool> flag{true};
  const StopToken raised(&flag, 0);
  absl::StatusOr<std::unique_ptr<Visibility>> cancelled = Visibility::Build(mesh, nullptr, &raised);
  ASSERT_FALSE(cancelled.ok());
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled) << cancelled.status();
  flag = false;
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Visibility> built,
                       Visibility::Build(mesh, nullptr, &raised));
  // (The flag was raised before the build: Embree's progress callback cancelled it.)
  // It traces: straight down from above the middle of the grid, a hit on the floor at z = 0.
  const Vec3 from = Vec3{0.5, 0.5, 0.5} - mesh.origin();
  Hit hit = built->Intersect(from, {0, 0, -1}, 0, 10);
  ASSERT_TRUE(hit.valid());
  EXPECT_NEAR(hit.t, 0.5, 1e-5);
}

TEST(BoundedWorkTest, RenderingStopsAtTheFlagWithAnEmptyImage) {
  const Scene scene = TriangleGrid(10);
  ASSERT_OK_AND_ASSIGN(Mesh mesh, BuildMesh(scene, 0.1));
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Visibility> vis, Visibility::Build(mesh));
  Solution solution;
  solution.radiosity.assign(2 * mesh.elements().size(), Rgb::Gray(1));
  const auto corners = CornerRadiosity(mesh, solution);
  const Camera camera = DefaultCamera(mesh);
  std::atomic<bool> flag{true};
  const StopToken raised(&flag, 0);
  Image stopped = RenderImage(mesh, *vis, solution, corners, camera, 32, 24, 1, &raised);
  EXPECT_EQ(stopped.width, 0);
  EXPECT_TRUE(stopped.rgb.empty());
  flag = false;
  Image image = RenderImage(mesh, *vis, solution, corners, camera, 32, 24, 1, &raised);
  EXPECT_EQ(image.width, 32);
  EXPECT_EQ(image.rgb.size(), 3u * 32 * 24);
}

// max_seconds covers meshing: a limit that passes before the mesh of 200 000 triangles is built
// fails the job naming the option (there is nothing to solve on), and a cancel before it is
// CANCELLED.
TEST(BoundedWorkTest, AJobsTimeLimitCoversMeshing) {
  const Scene scene = TriangleGrid(316);
  TempDir dir;
  JobSpec spec;
  spec.mesh.max_elements = 1000;
  spec.mesh.agglomerate_degrees = 10;
  spec.solve.max_seconds = 1e-3;
  absl::StatusOr<JobResult> late = RunJob(scene, spec, dir.path(), nullptr, {});
  ASSERT_FALSE(late.ok());
  EXPECT_EQ(late.status().code(), absl::StatusCode::kDeadlineExceeded) << late.status();
  EXPECT_NE(late.status().message().find("--max-seconds 0.001 passed before the mesh was ready"),
            std::string::npos)
      << late.status();
  spec.solve.max_seconds = 0;
  std::atomic<bool> flag{true};
  absl::StatusOr<JobResult> cancelled = RunJob(scene, spec, dir.path(), &flag, {});
  ASSERT_FALSE(cancelled.ok());
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled) << cancelled.status();
}

}  // namespace
}  // namespace radiosity
