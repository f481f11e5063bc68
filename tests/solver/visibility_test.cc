// What Visibility::Intersect skips (solver/transport/visibility.h): the face a ray leaves from
// and, at a shared edge, its coplanar neighbour (a ray starting on the edge would otherwise hit it
// at t = 0 from behind, and be lost: a closed room's Monte Carlo rows did not sum to 1) and, at a
// convex edge, the face beyond it, and at a concave edge the back of the wall a ray leaves away
// from; but not a wall that meets the face at a corner, however close to it the ray starts, nor
// the back of a face the ray really meets.
#include "solver/transport/visibility.h"

#include <gtest/gtest.h>

#include <cmath>
#include <utility>

#include "solver/geometry/mesh.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

const Material kWhite{"white", Rgb::Gray(0.5), Rgb(), Rgb(), false, 0};

// Two floor tiles [0, 1] x [0, 1] and [1, 2] x [0, 1] (y = 0, facing +y), a ceiling at y = 1
// (facing down) and a wall at x = 0 (facing +x).
Mesh TilesMesh() {
  Scene scene;
  scene.materials.push_back(kWhite);
  testing::AddRect(&scene, "a", 0, {0, 0, 0}, {0, 0, 1}, {1, 0, 0});
  testing::AddRect(&scene, "b", 0, {1, 0, 0}, {0, 0, 1}, {1, 0, 0});
  testing::AddRect(&scene, "ceiling", 0, {0, 1, 0}, {2, 0, 0}, {0, 0, 1});
  testing::AddRect(&scene, "wall", 0, {0, 0, 0}, {0, 1, 0}, {0, 0, 1});
  MeshOptions options;
  options.element_size = 4;  // One element per face.
  absl::StatusOr<Mesh> mesh = Mesh::Build(scene, options);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return mesh.ok() ? *std::move(mesh) : Mesh();
}

// The face whose corners' mean is nearest `centre` (recentred coordinates + the mesh origin).
int FaceAt(const Mesh& mesh, const Vec3& centre) {
  int best = -1;
  double best_d = 1e30;
  for (size_t f = 0; f < mesh.faces().size(); ++f) {
    const auto& p = mesh.faces()[f].p;
    const Vec3 c = (p[0] + p[1] + p[2] + p[3]) * 0.25 + mesh.origin();
    if (Length(c - centre) < best_d) best_d = Length(c - centre), best = static_cast<int>(f);
  }
  return best;
}

TEST(VisibilityTest, ARayFromASharedEdgeSkipsTheCoplanarNeighbourButNotAWall) {
  const Mesh mesh = TilesMesh();
  ASSERT_EQ(mesh.faces().size(), 4u);
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Visibility> vis, Visibility::Build(mesh));
  const int a = FaceAt(mesh, {0.5, 0, 0.5}), b = FaceAt(mesh, {1.5, 0, 0.5});
  const int ceiling = FaceAt(mesh, {1, 1, 0.5}), wall = FaceAt(mesh, {0, 0.5, 0.5});
  ASSERT_TRUE(a != b && a != ceiling && a != wall && b != ceiling && b != wall);
  const Vec3 o = mesh.origin();
  // From points of the edge x = 1 that tile a shares with b, up and away from b, towards it, and
  // straight up: each reaches the ceiling.
  for (double z : {0.25, 0.5, 0.8125}) {
    for (const Vec3& dir : {Vec3{-0.6, 0.8, 0}, Vec3{0.6, 0.8, 0}, Vec3{0, 1, 0.01}}) {
      const Hit hit = vis->Intersect(Vec3{1, 0, z} - o, dir, 0, 1e30, a);
      ASSERT_TRUE(hit.valid()) << z;
      EXPECT_EQ(hit.face, ceiling) << "z " << z << " dir " << dir.x << " " << dir.y;
      EXPECT_NEAR(hit.t, 1 / dir.y, 1e-5);
      EXPECT_TRUE(hit.StrikesFront(dir));
      EXPECT_FALSE(vis->Occluded(Vec3{1, 0, z} - o, dir, 0, 0.9 / dir.y, a));
    }
  }
  // From a point of tile a a hair in front of the wall (rounded to float: on the wall's plane),
  // up and away from it: the ceiling is hit, not the wall's back at t = 0 (a ray lost).
  for (double gap : {1e-9, 1e-8, 3e-8}) {
    for (const Vec3& dir : {Vec3{0.6, 0.8, 0}, Vec3{0.1, 1, 0.2}}) {
      const Hit hit = vis->Intersect(Vec3{gap, 0, 0.5} - o, dir, 0, 1e30, a);
      ASSERT_TRUE(hit.valid()) << gap;
      EXPECT_EQ(hit.face, ceiling) << "gap " << gap << " dir " << dir.x;
      EXPECT_TRUE(hit.StrikesFront(dir)) << gap;
      EXPECT_FALSE(vis->Occluded(Vec3{gap, 0, 0.5} - o, dir, 0, 0.9 / dir.y, a)) << gap;
    }
  }
  // From a point of tile a a hair from the wall, grazing towards it: the wall is hit, at once.
  for (double gap : {1e-9, 1e-7, 1e-5}) {
    const Vec3 dir = Normalize(Vec3{-1, 1e-3, 0});
    const Hit hit = vis->Intersect(Vec3{gap, 0, 0.5} - o, dir, 0, 1e30, a);
    ASSERT_TRUE(hit.valid()) << gap;
    EXPECT_EQ(hit.face, wall) << gap;
    EXPECT_TRUE(hit.StrikesFront(dir));
    EXPECT_LT(hit.t, 1e-4) << gap;
  }
}

// A box's top [0, 1] x [0, 1] (y = 0, facing +y) and its side at x = 1 (facing +x, down to
// y = -1): a convex edge. A fin standing on the top at x = 0.5 faces -x (its back towards +x), and
// a ceiling at y = 1 faces down.
Mesh ConvexEdgeMesh() {
  Scene scene;
  scene.materials.push_back(kWhite);
  testing::AddRect(&scene, "top", 0, {0, 0, 0}, {0, 0, 1}, {1, 0, 0});
  testing::AddRect(&scene, "side", 0, {1, 0, 0}, {0, 0, 1}, {0, -1, 0});
  testing::AddRect(&scene, "fin", 0, {0.5, 0, 0}, {0, 0, 1}, {0, 0.5, 0});
  testing::AddRect(&scene, "ceiling", 0, {-1, 1, 0}, {3, 0, 0}, {0, 0, 1});
  MeshOptions options;
  options.element_size = 8;  // One element per face.
  absl::StatusOr<Mesh> mesh = Mesh::Build(scene, options);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  return mesh.ok() ? *std::move(mesh) : Mesh();
}

// Rays leaving the top at its convex edge with the side start (rounded to float) on the side's
// plane, and hit it from behind at t ~ 0 unless that is skipped (a ray lost); the back of a face
// the ray really meets, on its side of the top's plane, is still hit: the fin from a point of
// the top beside it, the side from the top's back beside the edge.
TEST(VisibilityTest, ARayFromAConvexEdgeSkipsTheFaceBeyondItButNotAFinBesideIt) {
  const Mesh mesh = ConvexEdgeMesh();
  ASSERT_EQ(mesh.faces().size(), 4u);
  ASSERT_OK_AND_ASSIGN(std::unique_ptr<Visibility> vis, Visibility::Build(mesh));
  const int top = FaceAt(mesh, {0.5, 0, 0.5}), side = FaceAt(mesh, {1, -0.5, 0.5});
  const int fin = FaceAt(mesh, {0.5, 0.25, 0.5}), ceiling = FaceAt(mesh, {0.5, 1, 0.5});
  ASSERT_TRUE(top != side && top != fin && top != ceiling && side != fin && fin != ceiling);
  const Vec3 o = mesh.origin();
  int lost = 0;
  for (int k = 0; k < 64; ++k) {
    const double z = (k + 0.5) / 64;
    for (const Vec3& dir : {Vec3{0.6, 0.8, 0}, Vec3{0.1, 1, 0}, Vec3{0.9, 1, 0}}) {
      const Hit hit = vis->Intersect(Vec3{1, 0, z} - o, dir, 0, 1e30, top);
      if (!hit.valid() || hit.face != ceiling) {
        ++lost;
        continue;
      }
      EXPECT_NEAR(hit.t, 1 / dir.y, 1e-5);
      EXPECT_TRUE(hit.StrikesFront(dir));
      EXPECT_FALSE(vis->Occluded(Vec3{1, 0, z} - o, dir, 0, 0.9 / dir.y, top));
    }
  }
  EXPECT_EQ(lost, 0);
  // From the top's back a hair inside the edge, down and towards the side (as a ray leaving a
  // two-sided face inside a closed box): the side is on the ray's side of the top's plane, and
  // its back is hit at once.
  for (double gap : {1e-9, 1e-7, 1e-5}) {
    const Vec3 dir{0.6, -0.8, 0};
    const Hit hit = vis->Intersect(Vec3{1 - gap, 0, 0.5} - o, dir, 0, 1e30, top);
    ASSERT_TRUE(hit.valid()) << gap;
    EXPECT_EQ(hit.face, side) << gap;
    EXPECT_FALSE(hit.StrikesFront(dir)) << gap;
    EXPECT_LT(hit.t, 1e-4) << gap;
  }
  // From the top beside the fin's back, towards it: the fin is hit from behind, however close.
  for (double gap : {1e-9, 1e-7, 1e-4, 1e-3, 0.1}) {
    const Vec3 dir = Normalize(Vec3{-1, 0.2, 0});
    const Hit hit = vis->Intersect(Vec3{0.5 + gap, 0, 0.5} - o, dir, 0, 1e30, top);
    ASSERT_TRUE(hit.valid()) << gap;
    EXPECT_EQ(hit.face, fin) << gap;
    EXPECT_FALSE(hit.StrikesFront(dir)) << gap;
    EXPECT_TRUE(vis->Occluded(Vec3{0.5 + gap, 0, 0.5} - o, dir, 0, 1, top)) << gap;
  }
}

}  // namespace
}  // namespace radiosity
