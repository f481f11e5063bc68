
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "solver/geometry/interpolation.h"
#include "solver/geometry/mesh.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/solution.h"
#include "solver/input/model_loader.h"
#include "solver/results/camera.h"
#include "solver/results/elements_csv.h"
#include "solver/results/gltf.h"
#include "solver/results/image.h"
#include "solver/results/ply.h"
#include "solver/results/render.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

Material White(bool two_sided = false) {
  Material m;
  m.name = "white";
  m.reflectance = Rgb::Gray(0.5);
  m.two_sided = two_sided;
  return m;
}

// One surface made of one quad, [0,4] x [0,3] in the plane z = 0, facing +z.
Scene MakeQuad() {
  Scene s;
  s.materials.push_back(White());
  s.vertices = {{0, 0, 0}, {4, 0, 0}, {4, 3, 0}, {0, 3, 0}};
  s.surfaces.push_back({"quad", 0, 0});
  Face f;
  f.surface = 0;
  f.vertices = {0, 1, 2, 3};
  s.faces.push_back(f);
  return s;
}

// One triangle (stored by the mesh as a quad with v3 == v2), facing +z.
Scene MakeTriangle() {
  Scene s;
  s.materials.push_back(White());
  s.vertices = {{0, 0, 0}, {3, 0, 0}, {0, 2, 0}};
  s.surfaces.push_back({"tri", 0, 0});
  Face f;
  f.surface = 0;
  f.vertices = {0, 1, 2};
  s.faces.push_back(f);
  return s;
}

struct World {
  Scene scene;
  Mesh mesh;
  std::unique_ptr<Visibility> visibility;
  Solution solution;
};

// Meshes the scene and fills the solution with radiosity(element, side).
std::unique_ptr<World> MakeWorld(Scene scene, double element_size,
                                 const std::function<Rgb(const Element&, int)>& radiosity) {
  auto w = std::make_unique<World>();
  w->scene = std::move(scene);
  MeshOptions options;
  options.element_size = element_size;
  absl::StatusOr<Mesh> mesh = Mesh::Build(w->scene, options);
  EXPECT_TRUE(mesh.ok()) << mesh.status();
  if (!mesh.ok()) return nullptr;
  w->mesh = std::move(*mesh);
  absl::StatusOr<std::unique_ptr<Visibility>> vis = Visibility::Build(w->mesh);
  EXPECT_TRUE(vis.ok()) << vis.status();
  if (!vis.ok()) return nullptr;
  w->visibility = std::move(*vis);
  const auto& elements = w->mesh.elements();
  w->solution.radiosity.resize(2 * elements.size());
  for (size_t e = 0; e < elements.size(); ++e) {
    for (int side = 0; side < 2; ++side) {
      w->solution.radiosity[Slot(static_cast<int>(e), side)] = radiosity(elements[e], side);
    }
  }
  return w;
}

void ExpectRgbNear(const Rgb& actual, const Rgb& expected, double tol, const std::string& what) {
  EXPECT_NEAR(actual.r, expected.r, tol) << what;
  EXPECT_NEAR(actual.g, expected.g, tol) << what;
  EXPECT_NEAR(actual.b, expected.b, tol) << what;
}

Rgb Pixel(const Image& image, int x, int y) {
  const float* p = &image.rgb[3 * (static_cast<size_t>(y) * image.width + x)];
  return {p[0], p[1], p[2]};
}

// ---------------------------------------------------------------------------------------------
// Camera

TEST(CameraTest, ParsesAnySubsetAndKeepsTheRest) {
  Camera base;
  base.up = {0, 0, 1};
  base.look = {5, 0, 0};
  absl::StatusOr<Camera> cam = ParseCamera("  fov=55.5\teye=1,-2,3e1  ", base);
  ASSERT_TRUE(cam.ok()) << cam.status();
  EXPECT_EQ(cam->eye, Vec3(1, -2, 30));
  EXPECT_EQ(cam->look, Vec3(5, 0, 0));
  EXPECT_EQ(cam->up, Vec3(0, 0, 1));
  EXPECT_DOUBLE_EQ(cam->fov, 55.5);

  absl::StatusOr<Camera> same = ParseCamera("", *cam);
  ASSERT_TRUE(same.ok());
  EXPECT_EQ(same->eye, cam->eye);
}

TEST(CameraTest, ToStringRoundTrips) {
  Camera c;
  c.eye = {278.125, 273, -800};
  c.look = {278, 273.5, 0.1};
  c.up = {0.1, 1, 0};
  c.fov = 39.3077;
  absl::StatusOr<Camera> back = ParseCamera(c.ToString(), Camera{});
  ASSERT_TRUE(back.ok()) << back.status() << " for " << c.ToString();
  EXPECT_EQ(back->eye, c.eye);
  EXPECT_EQ(back->look, c.look);
  EXPECT_EQ(back->up, c.up);
  EXPECT_DOUBLE_EQ(back->fov, c.fov);
}

TEST(CameraTest, RejectsBadInputNamingTheKey) {
  struct Case {
    const char* text;
    std::vector<const char*> mentions;
  };
  const Case cases[] = {
      {"eye=1,2", {"eye", "1,2"}},
      {"look=1,2,x", {"look", "'x'"}},
      {"fov=abc", {"fov", "abc"}},
      {"fov=0", {"fov"}},
      {"fov=180", {"fov"}},
      {"fov=nan", {"fov"}},
      {"eye=1,2,inf", {"eye"}},
      {"zoom=2", {"zoom"}},
      {"eye", {"eye", "key=value"}},
      {"fov=30 fov=40", {"fov", "twice"}},
      {"eye=0,0,0 look=0,0,0", {"eye", "look"}},
      {"up=0,0,5", {"up", "parallel"}},  // Default view direction is -z.
      {"up=0,0,0", {"up"}},
  };
  for (const Case& c : cases) {
    absl::StatusOr<Camera> cam = ParseCamera(c.text, Camera{});
    ASSERT_FALSE(cam.ok()) << c.text;
    EXPECT_EQ(cam.status().code(), absl::StatusCode::kInvalidArgument) << c.text;
    for (const char* m : c.mentions) {
      EXPECT_NE(cam.status().message().find(m), absl::string_view::npos)
          << "'" << c.text << "' gave: " << cam.status().message() << " (expected '" << m << "')";
    }
  }
}

TEST(CameraTest, DefaultCameraFramesTheBoxFromMinusZ) {
  // A Cornell-box-sized room, shifted so that the recentring matters.
  Scene scene = testing::MakeClosedBox(556, 549, 560, White());
  for (Vec3& v : scene.vertices) v += Vec3(1000, -50, 20);
  auto w = MakeWorld(scene, 100, [](const Element&, int) { return Rgb{}; });
  ASSERT_NE(w, nullptr);
  Camera c = DefaultCamera(w->mesh);
  const Vec3 centre(1278, 274.5 - 50, 300);
  EXPECT_NEAR(c.look.x, centre.x, 1e-9);
  EXPECT_NEAR(c.look.y, centre.y, 1e-9);
  EXPECT_NEAR(c.look.z, centre.z, 1e-9);
  EXPECT_NEAR(c.eye.x, centre.x, 1e-9);
  EXPECT_NEAR(c.eye.y, centre.y, 1e-9);
  // 278 / tan(20 deg) + 280 in front of the centre.
  EXPECT_NEAR(c.eye.z, centre.z - (278 / std::tan(20 * kPi / 180) + 280), 1e-6);
  EXPECT_NEAR(c.eye.z - 20, -764, 1);
  EXPECT_EQ(c.up, Vec3(0, 1, 0));
  EXPECT_DOUBLE_EQ(c.fov, 40);
}

// ---------------------------------------------------------------------------------------------
// CornerRadiosity

TEST(CornerRadiosityTest, ConstantFieldIsConstantEverywhere) {
  for (Scene scene : {testing::MakeClosedBox(3, 2, 1.5, White()), MakeTriangle(), MakeQuad()}) {
    const Rgb front(0.25, 1.5, 7), back(0, 0, 0.125);
    auto w = MakeWorld(scene, 0.3, [&](const Element&, int side) { return side ? back : front; });
    ASSERT_NE(w, nullptr);
    auto corners = CornerRadiosity(w->mesh, w->solution);
    ASSERT_EQ(corners.size(), 2 * w->mesh.elements().size());
    for (size_t e = 0; e < w->mesh.elements().size(); ++e) {
      for (int c = 0; c < 4; ++c) {
        ExpectRgbNear(corners[Slot(e, 0)][c], front, 1e-12, "front");
        ExpectRgbNear(corners[Slot(e, 1)][c], back, 1e-12, "back");
      }
    }
  }
}

TEST(CornerRadiosityTest, LinearFieldIsExactAtInteriorCorners) {
  // B(x, y) linear in the centroid; on a uniform lattice the four elements around an interior
  // corner have equal areas and centroids symmetric about it, so their mean is B(corner).
  auto field = [](const Vec3& p) { return Rgb(1 + 2 * p.x, 3 - p.y, p.x + 0.5 * p.y); };
  auto w = MakeWorld(MakeQuad(), 0.25,
                     [&](const Element& e, int side) { return side ? Rgb{} : field(e.centroid); });
  ASSERT_NE(w, nullptr);
  ASSERT_GT(w->mesh.elements().size(), 100u);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  const MeshFace& f = w->mesh.faces()[0];
  int interior = 0;
  for (size_t e = 0; e < w->mesh.elements().size(); ++e) {
    const Element& el = w->mesh.elements()[e];
    for (int c = 0; c < 4; ++c) {
      const double u = (c & 1) ? el.u1 : el.u0, v = (c & 2) ? el.v1 : el.v0;
      if (u <= 0 || u >= 1 || v <= 0 || v >= 1) continue;
      ++interior;
      Vec3 p = f.Eval(u, v) + w->mesh.origin();
      ExpectRgbNear(corners[Slot(e, 0)][c], field(p), 1e-5, "interior corner");
    }
  }
  EXPECT_GT(interior, 300);
}

TEST(CornerRadiosityTest, AveragesByArea) {
  // Two elements of a 2 x 1 quad: the shared corners take the area-weighted mean.
  Scene s = MakeQuad();
  s.vertices = {{0, 0, 0}, {2, 0, 0}, {2, 1, 0}, {0, 1, 0}};
  auto w = MakeWorld(
      s, 1, [](const Element& e, int) { return e.centroid.x < 1 ? Rgb::Gray(1) : Rgb::Gray(3); });
  ASSERT_NE(w, nullptr);
  ASSERT_EQ(w->mesh.elements().size(), 2u);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  const int left = w->mesh.elements()[0].centroid.x < 1 ? 0 : 1;
  const auto& lc = corners[Slot(left, 0)];
  EXPECT_DOUBLE_EQ(lc[0].r, 1);  // (u0, v0): only the left element.
  EXPECT_DOUBLE_EQ(lc[2].r, 1);
  EXPECT_DOUBLE_EQ(lc[1].r, 2);  // Shared edge: (1 + 3) / 2.
  EXPECT_DOUBLE_EQ(lc[3].r, 2);
  EXPECT_DOUBLE_EQ(corners[Slot(1 - left, 0)][0].r, 2);
  EXPECT_DOUBLE_EQ(corners[Slot(1 - left, 0)][1].r, 3);
}

// A square [0,4]^2 in z = 0 written as two triangles sharing the diagonal from (0,0) to (4,4):
// with `hypotenuses`, both take it as their hypotenuse (u + v = 1), otherwise as a leg (the u
// axis of one, the v axis of the other). `lift` raises (0,4) off the plane (a crease).
Scene MakeSquareOfTwoTriangles(bool hypotenuses, double lift = 0) {
  Scene s;
  s.materials.push_back(White());
  s.vertices = {{0, 0, 0}, {4, 0, 0}, {4, 4, 0}, {0, 4, lift}};
  s.surfaces.push_back({"square", 0, 0});
  const std::vector<std::vector<int>> faces =
      hypotenuses ? std::vector<std::vector<int>>{{1, 2, 0}, {3, 0, 2}}
                  : std::vector<std::vector<int>>{{0, 1, 2}, {0, 2, 3}};
  for (const auto& vertices : faces) {
    Face f;
    f.surface = 0;
    f.vertices = vertices;
    s.faces.push_back(f);
  }
  return s;
}

// (u, v) of point x (recentred) in triangle face f: x = p0 + u (p1 - p0) + v (p2 - p0).
std::pair<double, double> TriangleUv(const MeshFace& f, const Vec3& x) {
  const Vec3 a = f.p[1] - f.p[0], b = f.p[2] - f.p[0], d = x - f.p[0];
  const double aa = Dot(a, a), ab = Dot(a, b), bb = Dot(b, b), det = aa * bb - ab * ab;
  return {(bb * Dot(d, a) - ab * Dot(d, b)) / det, (aa * Dot(d, b) - ab * Dot(d, a)) / det};
}

// Faces of one surface split into several elements shade as one surface where their element
// corners meet. Two triangles sharing a leg (a quad split along its diagonal) have the same
// lattice along it, and read the same value everywhere along it (not only at lattice points); a
// crease beyond the shading bound (1 degree when not agglomerated) stays sharp. Sharing their
// hypotenuses, which their lattices cross at different points, they agree at the shared vertices.
TEST(CornerRadiosityTest, SplitFacesOfOneSurfaceAreContinuousWhereTheirCornersMeet) {
  auto field = [](const Vec3& p) { return Rgb(1 + p.x + 2 * p.y, 2 - 0.25 * p.x, 1 + p.z); };
  for (const double lift : {0.0, 1.0}) {
    for (const bool hypotenuses : {false, true}) {
      SCOPED_TRACE(::testing::Message() << "hypotenuses=" << hypotenuses << " lift=" << lift);
      auto w = MakeWorld(MakeSquareOfTwoTriangles(hypotenuses, lift), 0.3,
                         [&](const Element& e, int) { return field(e.centroid); });
      ASSERT_NE(w, nullptr);
      const Mesh& mesh = w->mesh;
      ASSERT_EQ(mesh.faces().size(), 2u);
      ASSERT_GT(mesh.elements().size(), 100u);
      const auto corners = CornerRadiosity(mesh, w->solution);
      // The largest difference between the two faces' readings at point (4s, 4s, 0).
      auto jump = [&](double s) {
        const Vec3 x = Vec3(4 * s, 4 * s, 0) - mesh.origin();
        Rgb read[2];
        for (int face = 0; face < 2; ++face) {
          auto [u, v] = TriangleUv(mesh.faces()[face], x);
          EXPECT_TRUE(u >= -1e-9 && v >= -1e-9 && u + v <= 1 + 1e-9) << "off face " << face;
          u = std::clamp(u, 0.0, 1.0);
          v = std::clamp(v, 0.0, 1.0 - u);
          const int e = mesh.FindElement(face, u, v);
          EXPECT_GE(e, 0);
          if (e < 0) return 1e300;
          read[face] = InterpolatedRadiosity(mesh, corners, e, 0, face, u, v);
        }
        return std::fabs(read[0].r - read[1].r) + std::fabs(read[0].g - read[1].g);
      };
      double along = 0;  // Off the lattice: 101 points.
      for (int k = 0; k < 101; ++k) along = std::max(along, jump((k + 0.5) / 101));
      const double at_vertices = std::max(jump(0), jump(1));
      if (lift > 0) {
        // Each triangle keeps its own elements' values: the fold's two sides differ by about the
        // field's change between the centroids on either side of the edge.
        EXPECT_GT(along, 0.05);
        EXPECT_GT(at_vertices, 0.05);
      } else {
        EXPECT_LT(at_vertices, 1e-9);
        if (!hypotenuses) {
          EXPECT_LT(along, 1e-9);
        }
      }
    }
  }
}

// A disk of 200 triangles around one vertex (a cylinder's cap), each triangle one element: at the
// centre every face reads the mean of all (equal areas), although so many faces meet there that
// the faces blend by the surface's mean normal rather than pairwise.
TEST(CornerRadiosityTest, AFanOfManyFacesBlendsAtItsCentre) {
  constexpr int kFaces = 200;
  Scene s;
  s.materials.push_back(White());
  s.surfaces.push_back({"cap", 0, 0});
  s.vertices.push_back({0, 0, 0});
  for (int k = 0; k < kFaces; ++k) {
    const double a = 2 * kPi * k / kFaces;
    s.vertices.push_back({std::cos(a), std::sin(a), 0});
  }
  for (int k = 0; k < kFaces; ++k) {
    Face f;
    f.surface = 0;
    f.vertices = {0, 1 + k, 1 + (k + 1) % kFaces};
    s.faces.push_back(f);
  }
  auto w = MakeWorld(s, 10, [](const Element& e, int side) {
    return side ? Rgb{} : Rgb::Gray(1 + e.centroid.x + 0.5 * e.centroid.y * e.centroid.y);
  });
  ASSERT_NE(w, nullptr);
  ASSERT_EQ(w->mesh.elements().size(), static_cast<size_t>(kFaces));
  double mean = 0;
  for (int e = 0; e < kFaces; ++e) mean += w->solution.radiosity[Slot(e, 0)].r / kFaces;
  const auto corners = CornerRadiosity(w->mesh, w->solution);
  for (int e = 0; e < kFaces; ++e) {
    const int face = w->mesh.elements()[e].face;
    // The centre is p0 of every face: (u, v) = (0, 0).
    EXPECT_NEAR(InterpolatedRadiosity(w->mesh, corners, e, 0, face, 0, 0).r, mean, 1e-9);
  }
}

// ---------------------------------------------------------------------------------------------
// RenderImage

TEST(RenderImageTest, ClosedBoxSeenFromOutsideShowsItsInterior) {
  const double b = 1.75;
  auto w = MakeWorld(testing::MakeClosedBox(556, 549, 560, White()), 60,
                     [&](const Element&, int side) { return side ? Rgb{} : Rgb::Gray(b); });
  ASSERT_NE(w, nullptr);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  Camera cam = DefaultCamera(w->mesh);
  Image image = RenderImage(w->mesh, *w->visibility, w->solution, corners, cam, 64, 48,
                            /*samples_per_pixel=*/1);
  ASSERT_EQ(image.width, 64);
  ASSERT_EQ(image.height, 48);
  ASSERT_EQ(image.rgb.size(), 3u * 64 * 48);
  int hits = 0;
  for (int y = 0; y < image.height; ++y) {
    for (int x = 0; x < image.width; ++x) {
      Rgb p = Pixel(image, x, y);
      if (p.IsZero()) continue;
      ++hits;
      ExpectRgbNear(p, Rgb::Gray(b / kPi), 1e-6, "hit pixel");
    }
  }
  // The box fills the view vertically, and 4:3 of it horizontally.
  EXPECT_GT(hits, 64 * 48 * 0.6);
  ExpectRgbNear(Pixel(image, 32, 24), Rgb::Gray(b / kPi), 1e-6, "centre");
  ExpectRgbNear(Pixel(image, 0, 24), Rgb{}, 0, "left of the box");
  ExpectRgbNear(Pixel(image, 63, 24), Rgb{}, 0, "right of the box");
  EXPECT_TRUE(w->visibility->status().ok());
}

TEST(RenderImageTest, SeesTheRightWallsTheRightWayUp) {
  // Distinct radiosity per wall: MakeClosedBox's surfaces are x0, x1, y0, y1, z0, z1.
  const double wall[6] = {1, 2, 3, 4, 5, 6};
  auto w = MakeWorld(
      testing::MakeClosedBox(2, 2, 2, White()), 0.25,
      [&](const Element& e, int side) { return side ? Rgb{} : Rgb::Gray(wall[e.surface]); });
  ASSERT_NE(w, nullptr);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  Camera cam = DefaultCamera(w->mesh);
  Image image = RenderImage(w->mesh, *w->visibility, w->solution, corners, cam, 64, 64, 4);
  auto at = [&](int x, int y) { return Pixel(image, x, y).r * kPi; };
  // Looking along +z with +y up, +x is to the left. The near wall z0 is seen from behind and
  // skipped; the far wall z1 fills the centre.
  EXPECT_NEAR(at(32, 32), wall[5], 1e-5);
  EXPECT_NEAR(at(4, 32), wall[1], 1e-5);   // Left: x1.
  EXPECT_NEAR(at(59, 32), wall[0], 1e-5);  // Right: x0.
  EXPECT_NEAR(at(32, 4), wall[3], 1e-5);   // Top: ceiling y1.
  EXPECT_NEAR(at(32, 59), wall[2], 1e-5);  // Bottom: floor y0.

  // Deterministic.
  Image again = RenderImage(w->mesh, *w->visibility, w->solution, corners, cam, 64, 64, 4);
  EXPECT_EQ(image.rgb, again.rgb);
}

TEST(RenderImageTest, TwoSidedSurfacesShowTheirBackSide) {
  const Rgb front(1, 1, 1), back(0.5, 2, 4);
  auto w = MakeWorld(testing::MakeClosedBox(2, 2, 2, White(/*two_sided=*/true)), 0.5,
                     [&](const Element&, int side) { return side ? back : front; });
  ASSERT_NE(w, nullptr);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  Image image =
      RenderImage(w->mesh, *w->visibility, w->solution, corners, DefaultCamera(w->mesh), 16, 16, 2);
  ExpectRgbNear(Pixel(image, 8, 8), back / kPi, 1e-6, "back of the near wall");
}

TEST(RenderImageTest, InterpolatesCornerValues) {
  // A linear field on a quad facing the camera renders as that field / pi at interior points.
  auto field = [](const Vec3& p) { return Rgb(1 + p.x, 1 + p.y, 2); };
  auto w = MakeWorld(MakeQuad(), 0.5,
                     [&](const Element& e, int side) { return side ? Rgb{} : field(e.centroid); });
  ASSERT_NE(w, nullptr);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  // Looking down -z at the quad's centre from z = 10, with +y up (then +x is to the right).
  Camera cam;
  cam.eye = {2, 1.5, 10};
  cam.look = {2, 1.5, 0};
  cam.fov = 10;
  Image image = RenderImage(w->mesh, *w->visibility, w->solution, corners, cam, 33, 33, 1);
  // The pixel centres are jittered by up to half a pixel: tan(5 deg) * 10 / 16.5 per pixel.
  const double pixel = std::tan(5 * kPi / 180) * 10 / 16.5;
  for (int y = 8; y <= 24; y += 8) {
    for (int x = 8; x <= 24; x += 8) {
      Vec3 p(2 + (x + 0.5 - 16.5) * pixel, 1.5 - (y + 0.5 - 16.5) * pixel, 0);
      Rgb expected = field(p) / kPi;
      Rgb got = Pixel(image, x, y);
      EXPECT_NEAR(got.r, expected.r, pixel / kPi) << x << "," << y;
      EXPECT_NEAR(got.g, expected.g, pixel / kPi) << x << "," << y;
      EXPECT_NEAR(got.b, 2 / kPi, 1e-6);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// WriteImage

TEST(WriteImageTest, ExrReadsBackAndPngIsToneMapped) {
  testing::TempDir dir;
  Image image;
  image.width = 7;
  image.height = 5;
  image.rgb.resize(3 * 7 * 5);
  for (size_t i = 0; i < image.rgb.size(); ++i) image.rgb[i] = 0.01f * i * i + 0.5f * (i % 3);
  const std::string exr = dir.File("out.exr"), png = dir.File("out.png");
  ASSERT_TRUE(WriteImage(image, exr, png).ok());

  auto in = OIIO::ImageInput::open(exr);
  ASSERT_TRUE(in) << OIIO::geterror();
  const OIIO::ImageSpec& spec = in->spec();
  EXPECT_EQ(spec.width, 7);
  EXPECT_EQ(spec.height, 5);
  EXPECT_EQ(spec.nchannels, 3);
  EXPECT_EQ(spec.format, OIIO::TypeDesc::HALF);
  std::vector<float> back(image.rgb.size());
  ASSERT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, back.data())) << in->geterror();
  in->close();
  for (size_t i = 0; i < back.size(); ++i) {
    EXPECT_NEAR(back[i], image.rgb[i], 1e-3 * std::fabs(image.rgb[i]) + 1e-7) << i;
  }

  auto pin = OIIO::ImageInput::open(png);
  ASSERT_TRUE(pin) << OIIO::geterror();
  EXPECT_EQ(pin->spec().width, 7);
  EXPECT_EQ(pin->spec().height, 5);
  EXPECT_EQ(pin->spec().nchannels, 3);
  EXPECT_EQ(pin->spec().format, OIIO::TypeDesc::UINT8);
  pin->close();
}

TEST(WriteImageTest, PngExposureMapsThe99thPercentileTo09) {
  testing::TempDir dir;
  // 200 gray pixels at 3.7, one black, one very bright (above the 99th percentile).
  Image image;
  image.width = 202;
  image.height = 1;
  image.rgb.assign(3 * 202, 3.7f);
  for (int c = 0; c < 3; ++c) {
    image.rgb[c] = 0;
    image.rgb[3 + c] = 1000;
  }
  const std::string png = dir.File("gray.png");
  ASSERT_TRUE(WriteImage(image, "", png).ok());
  auto in = OIIO::ImageInput::open(png);
  ASSERT_TRUE(in) << OIIO::geterror();
  std::vector<uint8_t> px(3 * 202);
  ASSERT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, px.data()));
  // sRGB(0.9) = 1.055 * 0.9^(1/2.4) - 0.055 = 0.95464 -> 243.
  const int expected =
      static_cast<int>(std::lround(255 * (1.055 * std::pow(0.9, 1 / 2.4) - 0.055)));
  EXPECT_EQ(expected, 243);
  EXPECT_EQ(px[0], 0);    // Black stays black.
  EXPECT_EQ(px[3], 255);  // Clamped.
  for (int i = 2; i < 202; ++i) EXPECT_EQ(px[3 * i], expected) << i;
}

TEST(WriteImageTest, ErrorsNameThePath) {
  Image image;
  image.width = image.height = 2;
  image.rgb.assign(12, 1.0f);
  const std::string bad = "/nonexistent-radiosity-dir/out.exr";
  absl::Status st = WriteImage(image, bad, "");
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find(bad), absl::string_view::npos) << st;

  testing::TempDir dir;
  const std::string unknown = dir.File("out.notanimageformat");
  st = WriteImage(image, "", unknown);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find(unknown), absl::string_view::npos) << st;

  EXPECT_FALSE(WriteImage(Image{}, dir.File("empty.exr"), "").ok());
}

// ---------------------------------------------------------------------------------------------
// WriteElementsCsv

TEST(ElementsCsvTest, OneRowPerElementWithExactHeaderAndAreas) {
  testing::TempDir dir;
  auto w =
      MakeWorld(testing::MakeClosedBox(3, 2, 1.5, White()), 0.2, [](const Element& e, int side) {
        return side ? Rgb{} : Rgb(e.centroid.x, 1.0 / 3, e.index_in_surface);
      });
  ASSERT_NE(w, nullptr);
  const std::string path = dir.File("elements.csv"), back = dir.File("elements_back.csv");
  absl::Status st = WriteElementsCsv(w->scene, w->mesh, w->solution, path, back);
  ASSERT_TRUE(st.ok()) << st;
  const std::string text = testing::ReadFile(path);
  EXPECT_EQ(text.substr(0, text.find('\n')), "surface,element,cx,cy,cz,area,r,g,b");
  testing::Csv csv = testing::ReadCsv(path);
  ASSERT_EQ(csv.rows.size(), w->mesh.elements().size());
  std::map<std::string, double> area;
  for (size_t i = 0; i < csv.rows.size(); ++i) {
    const auto& row = csv.rows[i];
    ASSERT_EQ(row.size(), 9u);
    const Element& e = w->mesh.elements()[i];
    EXPECT_EQ(row[0], w->scene.surfaces[e.surface].name);
    EXPECT_EQ(std::stoi(row[1]), e.index_in_surface);
    EXPECT_NEAR(std::stod(row[2]), e.centroid.x, 1e-7);
    EXPECT_NEAR(std::stod(row[7]), 1.0 / 3, 1e-9);  // %.9g.
    EXPECT_EQ(std::stod(row[8]), e.index_in_surface);
    area[row[0]] += std::stod(row[5]);
  }
  EXPECT_NEAR(area["x0"], 2 * 1.5, 1e-6);
  EXPECT_NEAR(area["x1"], 2 * 1.5, 1e-6);
  EXPECT_NEAR(area["y0"], 3 * 1.5, 1e-6);
  EXPECT_NEAR(area["y1"], 3 * 1.5, 1e-6);
  EXPECT_NEAR(area["z0"], 3 * 2, 1e-6);
  EXPECT_NEAR(area["z1"], 3 * 2, 1e-6);
  // No surface has a back side: no back file.
  EXPECT_FALSE(std::ifstream(back).good());
}

TEST(ElementsCsvTest, BackSidesGoToTheirOwnFile) {
  testing::TempDir dir;
  Scene scene = testing::MakeClosedBox(1, 1, 1, White());
  scene.materials.push_back(White(/*two_sided=*/true));
  scene.surfaces[2].material = 1;  // y0 is two-sided.
  auto w = MakeWorld(scene, 0.25, [](const Element&, int side) { return Rgb::Gray(side ? 9 : 1); });
  ASSERT_NE(w, nullptr);
  const std::string path = dir.File("elements.csv"), back = dir.File("elements_back.csv");
  ASSERT_TRUE(WriteElementsCsv(w->scene, w->mesh, w->solution, path, back).ok());
  testing::Csv csv = testing::ReadCsv(back);
  EXPECT_EQ(csv.header, testing::ReadCsv(path).header);
  ASSERT_EQ(csv.rows.size(), 16u);
  for (const auto& row : csv.rows) {
    EXPECT_EQ(row[0], "y0");
    EXPECT_EQ(row[6], "9");
  }
}

TEST(ElementsCsvTest, UnwritablePathFailsNamingIt) {
  auto w = MakeWorld(MakeQuad(), 1, [](const Element&, int) { return Rgb{}; });
  ASSERT_NE(w, nullptr);
  const std::string bad = "/nonexistent-radiosity-dir/elements.csv";
  absl::Status st = WriteElementsCsv(w->scene, w->mesh, w->solution, bad, "");
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find(bad), absl::string_view::npos) << st;
}

// ---------------------------------------------------------------------------------------------
// WritePly

struct Ply {
  int64_t vertices = -1, faces = -1;
  std::vector<std::string> header;
  std::vector<std::vector<double>> vertex_rows;
  std::vector<std::vector<int64_t>> face_rows;
};

Ply ReadPly(const std::string& path) {
  Ply ply;
  std::ifstream in(path);
  std::string line;
  while (std::getline(in, line)) {
    ply.header.push_back(line);
    std::istringstream ls(line);
    std::string a, b;
    ls >> a >> b;
    if (a == "element" && b == "vertex") ls >> ply.vertices;
    if (a == "element" && b == "face") ls >> ply.faces;
    if (line == "end_header") break;
  }
  for (int64_t i = 0; i < ply.vertices && std::getline(in, line); ++i) {
    std::istringstream ls(line);
    std::vector<double> row;
    double x;
    while (ls >> x) row.push_back(x);
    ply.vertex_rows.push_back(row);
  }
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::vector<int64_t> row;
    int64_t x;
    while (ls >> x) row.push_back(x);
    ply.face_rows.push_back(row);
  }
  return ply;
}

// Total area of the PLY's polygons (fan triangulation) and how many face the given normal.
double PlyArea(const Ply& ply, const Vec3& normal, double* facing_area) {
  double total = 0;
  *facing_area = 0;
  for (const auto& f : ply.face_rows) {
    auto p = [&](int k) {
      const auto& r = ply.vertex_rows[f[1 + k]];
      return Vec3(r[0], r[1], r[2]);
    };
    Vec3 area_vector;
    for (int k = 1; k + 1 < f[0]; ++k) area_vector += 0.5 * Cross(p(k) - p(0), p(k + 1) - p(0));
    total += Length(area_vector);
    if (Dot(area_vector, normal) > 0) *facing_area += Length(area_vector);
  }
  return total;
}

TEST(PlyTest, HeaderCountsMatchTheBodyAndPolygonsCoverTheSurfaces) {
  testing::TempDir dir;
  auto w = MakeWorld(MakeTriangle(), 0.3,
                     [](const Element&, int side) { return side ? Rgb{} : Rgb(0.5, 1, 2); });
  ASSERT_NE(w, nullptr);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  const std::string path = dir.File("mesh.ply");
  absl::Status st = WritePly(w->mesh, w->solution, corners, path);
  ASSERT_TRUE(st.ok()) << st;
  Ply ply = ReadPly(path);
  const double exposure = 0.9 / Rgb(0.5, 1, 2).Luminance();
  auto srgb8 = [](double c) { return std::lround(255 * (1.055 * std::pow(c, 1 / 2.4) - 0.055)); };
  const double red = srgb8(0.5 * exposure), green = srgb8(exposure);
  ASSERT_GE(ply.header.size(), 3u);
  EXPECT_EQ(ply.header[0], "ply");
  EXPECT_EQ(ply.header[1], "format ascii 1.0");
  EXPECT_EQ(ply.header.back(), "end_header");
  ASSERT_GT(ply.vertices, 0);
  ASSERT_GE(ply.faces, static_cast<int64_t>(w->mesh.elements().size()));
  ASSERT_EQ(static_cast<int64_t>(ply.vertex_rows.size()), ply.vertices);
  ASSERT_EQ(static_cast<int64_t>(ply.face_rows.size()), ply.faces);
  for (const auto& v : ply.vertex_rows) {
    ASSERT_EQ(v.size(), 9u);
    EXPECT_NEAR(v[6], 0.5, 1e-6);
    EXPECT_NEAR(v[7], 1, 1e-6);
    EXPECT_NEAR(v[8], 2, 1e-6);
    // Tone mapping: every vertex has the same value, whose luminance maps to 0.9; blue clamps.
    EXPECT_EQ(v[3], red);
    EXPECT_EQ(v[4], green);
    EXPECT_EQ(v[5], 255);
  }
  int64_t used = 0;
  for (const auto& f : ply.face_rows) {
    ASSERT_GE(f.size(), 4u);
    ASSERT_EQ(static_cast<int64_t>(f.size()), f[0] + 1);
    for (size_t k = 1; k < f.size(); ++k) {
      ASSERT_GE(f[k], 0);
      ASSERT_LT(f[k], ply.vertices);
    }
    used += f[0];
  }
  EXPECT_EQ(used, ply.vertices);  // Vertices are not shared.
  double facing;
  EXPECT_NEAR(PlyArea(ply, Vec3(0, 0, 1), &facing), 3.0, 1e-5);  // The triangle's area.
  EXPECT_NEAR(facing, 3.0, 1e-5);  // Counter-clockwise about the front normal.
}

TEST(PlyTest, BackSidesAreDuplicatedWithReversedWinding) {
  testing::TempDir dir;
  Scene scene = testing::MakeClosedBox(1, 1, 1, White());
  scene.materials.push_back(White(/*two_sided=*/true));
  scene.surfaces[4].material = 1;  // z0 (facing +z) is two-sided.
  auto w = MakeWorld(scene, 0.25, [](const Element&, int side) { return Rgb::Gray(side ? 3 : 1); });
  ASSERT_NE(w, nullptr);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  const std::string path = dir.File("mesh.ply");
  ASSERT_TRUE(WritePly(w->mesh, w->solution, corners, path).ok());
  Ply ply = ReadPly(path);
  ASSERT_EQ(static_cast<int64_t>(ply.face_rows.size()), ply.faces);
  ASSERT_EQ(static_cast<int64_t>(ply.vertex_rows.size()), ply.vertices);
  // Elements straddling a face's diagonal are two pieces (two polygons).
  int64_t faces = 0, back_vertices_expected = 0;
  for (size_t e = 0; e < w->mesh.elements().size(); ++e) {
    std::array<ElementPiece, 2> pieces;
    int np = w->mesh.Pieces(static_cast<int>(e), &pieces);
    bool two = w->mesh.elements()[e].surface == 4;
    faces += np * (two ? 2 : 1);
    for (int k = 0; two && k < np; ++k) back_vertices_expected += pieces[k].n;
  }
  EXPECT_GT(faces, 7 * 16);
  EXPECT_EQ(ply.faces, faces);
  double facing_minus_z;
  EXPECT_NEAR(PlyArea(ply, Vec3(0, 0, -1), &facing_minus_z), 7.0, 1e-5);
  // z1's front and z0's back face -z.
  EXPECT_NEAR(facing_minus_z, 2.0, 1e-5);
  int back_vertices = 0;
  for (const auto& v : ply.vertex_rows) back_vertices += v[6] == 3;
  EXPECT_EQ(back_vertices, back_vertices_expected);
}

TEST(PlyTest, UnwritablePathFailsNamingIt) {
  auto w = MakeWorld(MakeQuad(), 1, [](const Element&, int) { return Rgb{}; });
  ASSERT_NE(w, nullptr);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  const std::string bad = "/nonexistent-radiosity-dir/mesh.ply";
  absl::Status st = WritePly(w->mesh, w->solution, corners, bad);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find(bad), absl::string_view::npos) << st;
}

// A binary glTF read back by the container layout of the glTF 2.0 specification (section 4.4):
// its JSON and its buffer.
struct Glb {
  nlohmann::json json;
  std::string bin;
  // Accessor `a` as floats (FLOAT) or as indices (UNSIGNED_INT), from its buffer view.
  template <typename T>
  std::vector<T> Accessor(int a) const {
    const nlohmann::json& acc = json["accessors"][a];
    const nlohmann::json& view = json["bufferViews"][acc["bufferView"].get<int>()];
    const size_t offset = view["byteOffset"].get<size_t>(), length = view["byteLength"];
    std::vector<T> out(length / sizeof(T));
    std::memcpy(out.data(), bin.data() + offset, length);
    return out;
  }
};

Glb ReadGlb(const std::string& path) {
  const std::string bytes = testing::ReadFile(path);
  Glb g;
  auto u32 = [&](size_t at) {
    uint32_t v = 0;
    std::memcpy(&v, bytes.data() + at, 4);
    return v;
  };
  EXPECT_GE(bytes.size(), 28u);
  if (bytes.size() < 28) return g;
  EXPECT_EQ(bytes.substr(0, 4), "glTF");
  EXPECT_EQ(u32(4), 2u);
  EXPECT_EQ(u32(8), bytes.size());
  const uint32_t json_length = u32(12);
  EXPECT_EQ(bytes.substr(16, 4), "JSON");
  EXPECT_EQ(json_length % 4, 0u);
  g.json = nlohmann::json::parse(bytes.substr(20, json_length));
  const size_t bin_at = 20 + json_length;
  EXPECT_EQ(bytes.substr(bin_at + 4, 4), std::string("BIN\0", 4));
  g.bin = bytes.substr(bin_at + 8, u32(bin_at));
  return g;
}

TEST(GltfTest, BakedLightReadsBackAsTheSpecificationAndAssimpSeeIt) {
  testing::TempDir dir;
  Scene scene = testing::MakeClosedBox(1, 1, 1, White());
  scene.materials.push_back(White(/*two_sided=*/true));
  scene.surfaces[4].material = 1;  // z0 (facing +z) is two-sided: its back is drawn too.
  auto w = MakeWorld(scene, 0.25, [](const Element&, int side) { return Rgb::Gray(side ? 3 : 1); });
  ASSERT_NE(w, nullptr);
  auto corners = CornerRadiosity(w->mesh, w->solution);
  const std::string path = dir.File("mesh.glb");
  ASSERT_OK(WriteGlb(w->mesh, corners, path));
  const Glb g = ReadGlb(path);
  ASSERT_FALSE(g.json.is_null());
  EXPECT_EQ(g.json["asset"]["version"], "2.0");
  const nlohmann::json& attributes = g.json["meshes"][0]["primitives"][0]["attributes"];
  const std::vector<float> position = g.Accessor<float>(attributes["POSITION"].get<int>());
  const std::vector<float> colour = g.Accessor<float>(attributes["COLOR_0"].get<int>());
  const std::vector<float> radiosity = g.Accessor<float>(attributes["_RADIOSITY"].get<int>());
  const std::vector<uint32_t> index =
      g.Accessor<uint32_t>(g.json["meshes"][0]["primitives"][0]["indices"].get<int>());
  const size_t vertices = position.size() / 3;
  ASSERT_EQ(colour.size(), 3 * vertices);
  ASSERT_EQ(radiosity.size(), 3 * vertices);
  ASSERT_EQ(index.size() % 3, 0u);
  EXPECT_EQ(g.json["accessors"][0]["count"].get<size_t>(), vertices);
  // COLOR_0 is the radiosity times the recorded exposure, clamped to [0, 1].
  const double exposure = g.json["asset"]["extras"]["radiosity_exposure"].get<double>();
  for (size_t k = 0; k < radiosity.size(); ++k) {
    ASSERT_TRUE(radiosity[k] == 1 || radiosity[k] == 3) << radiosity[k];
    EXPECT_FLOAT_EQ(colour[k], std::min(1.0, exposure * radiosity[k]));
  }
  // Triangles: 6 unit walls facing inwards, and z0's back (radiosity 3) facing -z.
  auto p = [&](uint32_t v) {
    return Vec3(position[3 * v], position[3 * v + 1], position[3 * v + 2]);
  };
  double inward = 0, back = 0;
  for (size_t t = 0; t < index.size(); t += 3) {
    ASSERT_LT(index[t + 2], vertices);
    const Vec3 a = p(index[t]);
    const Vec3 area = 0.5 * Cross(p(index[t + 1]) - a, p(index[t + 2]) - a);
    if (radiosity[3 * index[t]] == 3) {
      EXPECT_LT(area.z, 0);
      back += Length(area);
    } else {
      if (Dot(area, Vec3(0.5, 0.5, 0.5) - a) > 0) inward += Length(area);
    }
  }
  EXPECT_NEAR(inward, 6, 1e-5);
  EXPECT_NEAR(back, 1, 1e-5);
  // A reader that is not ours (assimp) reads it: one mesh of these triangles.
  std::vector<std::string> warnings;
  ASSERT_OK_AND_ASSIGN(Scene read, LoadModel(path, &warnings));
  EXPECT_EQ(read.faces.size(), index.size() / 3);
  double area = 0;
  for (const Face& f : read.faces) area += PolygonArea(read, f);
  EXPECT_NEAR(area, 7, 1e-4);
}

TEST(GltfTest, UnwritablePathFailsNamingIt) {
  auto w = MakeWorld(MakeQuad(), 1, [](const Element&, int) { return Rgb{}; });
  ASSERT_NE(w, nullptr);
  const std::string bad = "/nonexistent-radiosity-dir/mesh.glb";
  absl::Status st = WriteGlb(w->mesh, CornerRadiosity(w->mesh, w->solution), bad);
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find(bad), absl::string_view::npos) << st;
}

// A million elements: run with --gtest_also_run_disabled_tests to time the output stages.
TEST(OutputBenchmark, DISABLED_MillionElements) {
  testing::TempDir dir;
  auto t0 = std::chrono::steady_clock::now();
  auto w =
      MakeWorld(testing::MakeClosedBox(1, 1, 1, White()), 1.0 / 408,
                [](const Element& e, int side) { return side ? Rgb{} : Rgb(e.centroid.x, 1, 2); });
  ASSERT_NE(w, nullptr);
  auto lap = [&](const char* what) {
    auto t = std::chrono::steady_clock::now();
    std::printf("%-10s %.3f s\n", what, std::chrono::duration<double>(t - t0).count());
    t0 = t;
  };
  std::printf("%zu elements\n", w->mesh.elements().size());
  lap("mesh");
  auto corners = CornerRadiosity(w->mesh, w->solution);
  lap("corners");
  Image image = RenderImage(w->mesh, *w->visibility, w->solution, corners, DefaultCamera(w->mesh),
                            512, 512, 4);
  lap("render");
  ASSERT_TRUE(WriteImage(image, dir.File("a.exr"), dir.File("a.png")).ok());
  lap("images");
  ASSERT_TRUE(WriteElementsCsv(w->scene, w->mesh, w->solution, dir.File("e.csv"), "").ok());
  lap("csv");
  ASSERT_TRUE(WritePly(w->mesh, w->solution, corners, dir.File("m.ply")).ok());
  lap("ply");
}

}  // namespace
}  // namespace radiosity
