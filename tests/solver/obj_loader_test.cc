#include "solver/input/obj_loader.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <ostream>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/vec.h"
#include "solver/util/file_io.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using ::radiosity::testing::SourcePath;
using ::radiosity::testing::TempDir;
using ::testing::AllOf;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::SizeIs;

// Unnormalised normal of a face's first triangle: our front is its counter-clockwise side.
Vec3 FirstTriangleNormal(const Scene& scene, const Face& face) {
  const Vec3& p0 = scene.vertices[face.vertices[0]];
  return Cross(scene.vertices[face.vertices[1]] - p0, scene.vertices[face.vertices[2]] - p0);
}

Vec3 FaceCentroid(const Scene& scene, const Face& face) {
  Vec3 sum;
  for (int v : face.vertices) sum += scene.vertices[v];
  return sum / static_cast<double>(face.vertices.size());
}

int SurfaceIndex(const Scene& scene, const std::string& name) {
  for (size_t i = 0; i < scene.surfaces.size(); ++i) {
    if (scene.surfaces[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

std::vector<const Face*> FacesOf(const Scene& scene, const std::string& surface) {
  int s = SurfaceIndex(scene, surface);
  std::vector<const Face*> out;
  for (const Face& f : scene.faces) {
    if (f.surface == s) out.push_back(&f);
  }
  return out;
}

const Material& MaterialOf(const Scene& scene, const std::string& surface) {
  return scene.materials[scene.surfaces[SurfaceIndex(scene, surface)].material];
}

void ExpectRgbNear(const Rgb& actual, const Rgb& expected, double tolerance) {
  EXPECT_NEAR(actual.r, expected.r, tolerance);
  EXPECT_NEAR(actual.g, expected.g, tolerance);
  EXPECT_NEAR(actual.b, expected.b, tolerance);
}

// ---------------------------------------------------------------------------------------------
// The Cornell box shipped in scenes/.

class CornellBoxTest : public ::testing::Test {
 protected:
  void SetUp() override {
    absl::StatusOr<Scene> loaded = LoadObj(SourcePath("scenes/cornell_box.obj"), &warnings_);
    ASSERT_OK(loaded);
    scene_ = *std::move(loaded);
  }
  Scene scene_;
  std::vector<std::string> warnings_;
};

TEST_F(CornellBoxTest, HasEightSurfacesWithTheExpectedFaceCounts) {
  std::map<std::string, int> faces;
  for (const Face& f : scene_.faces) ++faces[scene_.surfaces[f.surface].name];
  EXPECT_THAT(scene_.surfaces, SizeIs(8));
  EXPECT_EQ(faces, (std::map<std::string, int>{{"light", 1},
                                               {"floor", 1},
                                               {"ceiling", 4},
                                               {"back", 1},
                                               {"green", 1},
                                               {"red", 1},
                                               {"short_block", 5},
                                               {"tall_block", 5}}));
  EXPECT_THAT(warnings_, ::testing::IsEmpty());
  for (const Face& f : scene_.faces) EXPECT_THAT(f.vertices, SizeIs(4)) << f.line;
}

TEST_F(CornellBoxTest, RoomFacesPointIntoTheBoxAndBlockFacesOutwards) {
  const Vec3 box_centre(278, 274, 280);
  int checked = 0;
  for (const char* room : {"light", "floor", "ceiling", "back", "green", "red"}) {
    for (const Face* f : FacesOf(scene_, room)) {
      Vec3 n = FirstTriangleNormal(scene_, *f);
      EXPECT_GT(Dot(n, box_centre - FaceCentroid(scene_, *f)), 0)
          << room << " face at line " << f->line << " faces away from the box centre";
      ++checked;
    }
  }
  for (const char* block : {"short_block", "tall_block"}) {
    std::vector<const Face*> faces = FacesOf(scene_, block);
    Vec3 centroid;
    int n_vertices = 0;
    for (const Face* f : faces) {
      for (int v : f->vertices) {
        centroid += scene_.vertices[v];
        ++n_vertices;
      }
    }
    centroid = centroid / n_vertices;
    for (const Face* f : faces) {
      Vec3 n = FirstTriangleNormal(scene_, *f);
      EXPECT_GT(Dot(n, FaceCentroid(scene_, *f) - centroid), 0)
          << block << " face at line " << f->line << " faces into its block";
      ++checked;
    }
  }
  EXPECT_EQ(checked, 19);
}

TEST_F(CornellBoxTest, CeilingAndLightCoverThePublishedCeilingExactlyOnce) {
  double ceiling = 0, light = 0;
  for (const Face* f : FacesOf(scene_, "ceiling")) ceiling += PolygonArea(scene_, *f);
  for (const Face* f : FacesOf(scene_, "light")) light += PolygonArea(scene_, *f);
  EXPECT_NEAR(light, 130.0 * 105.0, 1e-6);
  // The published ceiling polygon is 556 x 559.2 mm.
  EXPECT_NEAR(ceiling + light, 556.0 * 559.2, 1e-6);
}

TEST_F(CornellBoxTest, MaterialsAreTheStandardStandIns) {
  const Material& light = MaterialOf(scene_, "light");
  ExpectRgbNear(light.emission, Rgb(17, 12, 4) * kPi, 1e-3);
  ExpectRgbNear(light.reflectance, Rgb::Gray(0.78), 1e-12);
  EXPECT_TRUE(light.IsEmitter());
  for (const char* white : {"floor", "ceiling", "back", "short_block", "tall_block"}) {
    ExpectRgbNear(MaterialOf(scene_, white).reflectance, Rgb(0.725, 0.71, 0.68), 1e-12);
    EXPECT_FALSE(MaterialOf(scene_, white).IsEmitter()) << white;
  }
  ExpectRgbNear(MaterialOf(scene_, "red").reflectance, Rgb(0.63, 0.065, 0.05), 1e-12);
  ExpectRgbNear(MaterialOf(scene_, "green").reflectance, Rgb(0.14, 0.45, 0.091), 1e-12);
  // Only the light emits: total power = exitance x 130 x 105 mm^2.
  ExpectRgbNear(EmittedPower(scene_), Rgb(53.407, 37.699, 12.566) * (130.0 * 105.0), 1e-6);
}

TEST_F(CornellBoxTest, RedWallIsKeptNonPlanarAsPublished) {
  std::vector<const Face*> red = FacesOf(scene_, "red");
  ASSERT_THAT(red, SizeIs(1));
  const Face& f = *red[0];
  Vec3 n = Normalize(FirstTriangleNormal(scene_, f));
  double off_plane = Dot(scene_.vertices[f.vertices[3]] - scene_.vertices[f.vertices[0]], n);
  EXPECT_NEAR(std::abs(off_plane), 3.2, 0.05);
}

TEST(TwoSquaresTest, LoadsOpposedBlackSquaresOneEmitting) {
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadObj(SourcePath("tests/data/two_squares.obj"), &warnings);
  ASSERT_OK(scene);
  ASSERT_THAT(scene->surfaces, SizeIs(2));
  ASSERT_THAT(scene->faces, SizeIs(2));
  const Material& emitter = MaterialOf(*scene, "emitter");
  const Material& receiver = MaterialOf(*scene, "receiver");
  EXPECT_EQ(emitter.emission, Rgb(1, 1, 1));
  EXPECT_EQ(emitter.reflectance, Rgb(0, 0, 0));
  EXPECT_EQ(receiver.emission, Rgb(0, 0, 0));
  EXPECT_EQ(receiver.reflectance, Rgb(0, 0, 0));
  const Face& a = *FacesOf(*scene, "emitter")[0];
  const Face& b = *FacesOf(*scene, "receiver")[0];
  EXPECT_DOUBLE_EQ(PolygonArea(*scene, a), 1.0);
  EXPECT_DOUBLE_EQ(PolygonArea(*scene, b), 1.0);
  Vec3 na = Normalize(FirstTriangleNormal(*scene, a));
  Vec3 nb = Normalize(FirstTriangleNormal(*scene, b));
  EXPECT_EQ(na, Vec3(0, 0, 1));
  EXPECT_EQ(nb, Vec3(0, 0, -1));
  // Facing each other at unit distance.
  Vec3 d = FaceCentroid(*scene, b) - FaceCentroid(*scene, a);
  EXPECT_EQ(d, Vec3(0, 0, 1));
}

// ---------------------------------------------------------------------------------------------
// Small scenes written inline.

constexpr char kMtl[] = R"(# test materials
newmtl white
Kd 0.5 0.5 0.5
newmtl lamp
Kd 0.2 0.2 0.2
Ke 1 1 1
)";

// The start of most OBJ files below: the material library and three vertices (lines 1 to 4).
constexpr char kThreeVertices[] = "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\n";

// Writes scene.obj (and scene.mtl unless `mtl` is null) into `dir` and loads it.
absl::StatusOr<Scene> LoadText(const TempDir& dir, const std::string& obj, const char* mtl = kMtl,
                               std::vector<std::string>* warnings = nullptr, bool strict = false) {
  if (mtl != nullptr) dir.Write("scene.mtl", mtl);
  ObjOptions options;
  options.strict = strict;
  return LoadObj(dir.Write("scene.obj", obj), warnings, options);
}

TEST(ObjLoaderTest, QuadsAndPolygonsKeepAllTheirVertices) {
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadText(dir, absl::StrCat(kThreeVertices, R"(v 0 1 0
v 2 0 0
v 3 0 0
v 3.5 1 0
v 2.5 2 0
v 1.8 1 0
g quad
usemtl lamp
f 1 2 3 4
g pentagon
usemtl white
f 5 6 7 8 9
g triangle
usemtl white
f 1 2 3
)"));
  ASSERT_OK(scene);
  ASSERT_THAT(scene->faces, SizeIs(3));
  EXPECT_THAT(scene->faces[0].vertices, ElementsAre(0, 1, 2, 3));
  EXPECT_THAT(scene->faces[1].vertices, ElementsAre(4, 5, 6, 7, 8));
  EXPECT_THAT(scene->faces[2].vertices, ElementsAre(0, 1, 2));
  EXPECT_EQ(scene->surfaces[scene->faces[1].surface].name, "pentagon");
}

TEST(ObjLoaderTest, NegativeIndicesCountBackFromTheLastVertex) {
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadText(dir, R"(mtllib scene.mtl
usemtl lamp
v 9 9 9
v 0 0 0
v 1 0 0
v 1 1 0
f -3 -2 -1
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
f -4 -3 -2 -1
f 2 -5/1 -4//2
)");
  ASSERT_OK(scene);
  ASSERT_THAT(scene->faces, SizeIs(3));
  EXPECT_THAT(scene->faces[0].vertices, ElementsAre(1, 2, 3));
  EXPECT_THAT(scene->faces[1].vertices, ElementsAre(4, 5, 6, 7));
  EXPECT_THAT(scene->faces[2].vertices, ElementsAre(1, 3, 4));
}

TEST(ObjLoaderTest, TextureAndNormalIndicesAreAcceptedAndIgnored) {
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadText(dir, absl::StrCat(kThreeVertices, R"(v 0 1 0
vt 0 0
vt 1 0
vt 1 1
vn 0 0 1
usemtl lamp
s off
f 1/1 2/2 3/3
f 1//1 3//1 4//1
f 1/1/1 2/2/1 3/3/1 4/1/1
l 1 2
p 3
)"));
  ASSERT_OK(scene);
  ASSERT_THAT(scene->faces, SizeIs(3));
  EXPECT_THAT(scene->faces[0].vertices, ElementsAre(0, 1, 2));
  EXPECT_THAT(scene->faces[1].vertices, ElementsAre(0, 2, 3));
  EXPECT_THAT(scene->faces[2].vertices, ElementsAre(0, 1, 2, 3));
}

TEST(ObjLoaderTest, GroupWithSeveralMaterialsBecomesOneSurfacePerMaterial) {
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadText(dir, absl::StrCat(kThreeVertices, R"(v 0 1 0
g wall
usemtl white
f 1 2 3
usemtl lamp
f 1 3 4
usemtl white
f 1 2 4
o floor
usemtl white
f 2 3 4
)"));
  ASSERT_OK(scene);
  ASSERT_THAT(scene->surfaces, SizeIs(3));
  EXPECT_EQ(scene->surfaces[0].name, "wall/white");
  EXPECT_EQ(scene->surfaces[1].name, "wall/lamp");
  EXPECT_EQ(scene->surfaces[2].name, "floor");
  EXPECT_EQ(scene->materials[scene->surfaces[0].material].name, "white");
  EXPECT_EQ(scene->materials[scene->surfaces[1].material].name, "lamp");
  EXPECT_EQ(scene->materials[scene->surfaces[2].material].name, "white");
  // Faces keep their order; both white faces of "wall" are one surface.
  ASSERT_THAT(scene->faces, SizeIs(4));
  EXPECT_EQ(scene->faces[0].surface, 0);
  EXPECT_EQ(scene->faces[1].surface, 1);
  EXPECT_EQ(scene->faces[2].surface, 0);
  EXPECT_EQ(scene->faces[3].surface, 2);
}

TEST(ObjLoaderTest, FacesBeforeAnyGroupGoToASurfaceNamedAfterTheFile) {
  TempDir dir;
  dir.Write("scene.mtl", kMtl);
  absl::StatusOr<Scene> scene = LoadObj(dir.Write("my_room.obj", R"(mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
usemtl lamp
f 1 2 3
)"),
                                        nullptr);
  ASSERT_OK(scene);
  ASSERT_THAT(scene->surfaces, SizeIs(1));
  EXPECT_EQ(scene->surfaces[0].name, "my_room");
  EXPECT_EQ(scene->source, dir.File("my_room.obj"));
}

TEST(ObjLoaderTest, RecordsLinesOfFacesSurfacesAndMaterials) {
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadText(dir, R"(# comment

mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
g tri
usemtl lamp
f 1 2 3
)");
  ASSERT_OK(scene);
  EXPECT_EQ(scene->faces[0].line, 9);
  EXPECT_EQ(scene->surfaces[0].line, 7);
  EXPECT_EQ(scene->materials[0].name, "lamp");
  EXPECT_EQ(scene->materials[0].line, 4);  // newmtl lamp in kMtl
}

TEST(ObjLoaderTest, ReadsAllMaterialKeysAndIgnoresOthers) {
  TempDir dir;
  dir.Write("a.mtl", R"(newmtl gray
Ka 1 1 1
Ks 0.5 0.5 0.5
Ns 10
Ni 1.5
d 1
Tr 0
illum 2
map_Kd texture.png
Kd 0.25
newmtl glass
Kd 0.1 0.2 0.3
Tf 0.5 0.6 0.7
Tr 0.5
two_sided on
)");
  dir.Write("b.mtl", R"(newmtl sheet
Kd 0.4 0.4 0.4
Tf 0.5
d 0.25
two_sided 1
newmtl lamp
Kd 0 0 0
Ke 2 3 4
two_sided off
)");
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadText(dir, R"(mtllib a.mtl b.mtl
v 0 0 0
v 1 0 0
v 1 1 0
g a
usemtl gray
f 1 2 3
g b
usemtl glass
f 1 2 3
g c
usemtl sheet
f 1 2 3
g d
usemtl lamp
f 1 2 3
)",
                                         nullptr, &warnings);
  ASSERT_OK(scene);
  EXPECT_THAT(warnings, ::testing::IsEmpty());
  const Material& gray = MaterialOf(*scene, "a");
  EXPECT_EQ(gray.reflectance, Rgb::Gray(0.25));
  EXPECT_EQ(gray.transmittance, Rgb());
  EXPECT_FALSE(gray.two_sided);
  // As written, and illum 2 makes Ks a glossy lobe of exponent Ns.
  EXPECT_EQ(gray.specular, Rgb::Gray(0.5));
  EXPECT_EQ(gray.shininess, 10);
  EXPECT_EQ(gray.illum, 2);
  EXPECT_EQ(gray.glossy, Rgb::Gray(0.5));
  EXPECT_EQ(gray.glossy_exponent, 10);
  EXPECT_EQ(gray.mirror, Rgb());
  EXPECT_EQ(gray.glass, Rgb());
  // Tr = 1 - d: half the light interacts (reflects Kd of it), half passes, filtered by Tf.
  const Material& glass = MaterialOf(*scene, "b");
  EXPECT_EQ(glass.reflectance, Rgb(0.05, 0.1, 0.15));
  EXPECT_EQ(glass.transmittance, Rgb(0.25, 0.3, 0.35));
  EXPECT_TRUE(glass.two_sided);
  const Material& sheet = MaterialOf(*scene, "c");
  EXPECT_EQ(sheet.reflectance, Rgb::Gray(0.1));
  EXPECT_EQ(sheet.transmittance, Rgb::Gray(0.375));
  EXPECT_TRUE(sheet.two_sided);
  const Material& lamp = MaterialOf(*scene, "d");
  EXPECT_EQ(lamp.emission, Rgb(2, 3, 4));
  EXPECT_FALSE(lamp.two_sided);
}

// docs/guide/specular.md: the MTL mapping.
TEST(ObjLoaderTest, IllumModelsMakeMirrorsGlossyLobesAndGlass) {
  TempDir dir;
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadText(dir, R"(mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
g a
usemtl mirror
f 1 2 3
g b
usemtl exported
f 1 2 3
g c
usemtl window
f 1 2 3
g d
usemtl bad_ni
f 1 2 3
g e
usemtl translucent
f 1 2 3
)",
                                         R"(newmtl mirror
Kd 0.05 0.05 0.05
Ks 0.9 0.8 0.7
illum 3
newmtl exported
Kd 0.8 0.8 0.8
Ks 0.5 0.5 0.5
Ns 250
illum 2
newmtl window
Kd 0.5 0.5 0.5
Tf 0.9 1 0.9
d 0.2
Ni 1.33
illum 4
newmtl bad_ni
Kd 0 0 0
Tr 1
Ni 0
illum 7
newmtl translucent
Kd 0.5 0.5 0.5
d 0.5
illum 2
)",
                                         &warnings);
  ASSERT_OK(scene);
  const Material& mirror = MaterialOf(*scene, "a");
  EXPECT_EQ(mirror.mirror, Rgb(0.9, 0.8, 0.7));
  EXPECT_EQ(mirror.reflectance, Rgb::Gray(0.05));
  // Kd as written; Ks takes what is left of 0.99, with a warning naming the line.
  const Material& exported = MaterialOf(*scene, "b");
  EXPECT_EQ(exported.reflectance, Rgb::Gray(0.8));
  EXPECT_NEAR(exported.glossy.g, 0.19, 1e-12);
  EXPECT_EQ(exported.glossy_exponent, 250);
  EXPECT_THAT(warnings, ::testing::Contains(::testing::HasSubstr(
                            "scene.mtl:5: material 'exported': Ks (0.5, 0.5, 0.5) reduced to "
                            "(0.19, 0.19, 0.19)")));
  // illum 4: the transparent part (1 - d) x Tf is glass of index Ni; no diffuse transmission.
  const Material& window = MaterialOf(*scene, "c");
  EXPECT_NEAR(window.glass.r, 0.72, 1e-12);
  EXPECT_NEAR(window.glass.g, 0.8, 1e-12);
  EXPECT_EQ(window.transmittance, Rgb());
  EXPECT_NEAR(window.reflectance.g, 0.1, 1e-12);
  EXPECT_EQ(window.ior, 1.33);
  EXPECT_FALSE(window.refracts);
  const Material& bad_ni = MaterialOf(*scene, "d");
  EXPECT_EQ(bad_ni.glass, Rgb::Gray(1));
  EXPECT_EQ(bad_ni.ior, 1.5);
  EXPECT_THAT(warnings, ::testing::Contains(::testing::HasSubstr(
                            "material 'bad_ni': Ni 0 is not an index of refraction")));
  // Without a glass illum model the transparent part still transmits diffusely.
  const Material& translucent = MaterialOf(*scene, "e");
  EXPECT_EQ(translucent.transmittance, Rgb::Gray(0.5));
  EXPECT_EQ(translucent.glass, Rgb());
  EXPECT_OK(ValidateScene(*scene));

  // Strict loading refuses Kd + Ks above 0.99 instead of reducing Ks.
  absl::StatusOr<Scene> strict = LoadText(dir, R"(mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
usemtl exported
f 1 2 3
)",
                                          nullptr, nullptr, /*strict=*/true);
  EXPECT_EQ(strict.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(strict.status().message()),
              ::testing::HasSubstr("material 'exported': Kd + Ks (1.3, 1.3, 1.3) is above 0.99"));
}

TEST(ObjLoaderTest, UnknownKeywordIsAWarningNamingTheLine) {
  TempDir dir;
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadText(dir, absl::StrCat(kThreeVertices, R"(frobnicate 1 2
usemtl lamp
f 1 2 3
frobnicate again
)"),
                                         kMtl, &warnings);
  ASSERT_OK(scene);
  ASSERT_THAT(warnings, SizeIs(1));
  EXPECT_THAT(warnings[0],
              AllOf(HasSubstr(dir.File("scene.obj") + ":5:"),
                    HasSubstr("unknown OBJ keyword 'frobnicate'"), HasSubstr("2 lines")));
}

TEST(ObjLoaderTest, AcceptsCrLfLineEndingsAndAByteOrderMark) {
  TempDir dir;
  absl::StatusOr<Scene> scene =
      LoadText(dir,
               "\xEF\xBB\xBFmtllib scene.mtl\r\nv 0 0 0\r\nv 1 0 0\r\nv 1 1 0\r\ng t\r\n"
               "usemtl lamp\r\nf 1 2 3\r\n");
  ASSERT_OK(scene);
  EXPECT_EQ(scene->surfaces[0].name, "t");
  EXPECT_EQ(scene->materials[0].name, "lamp");
  EXPECT_EQ(scene->faces[0].line, 7);
}

TEST(ObjLoaderTest, ParseObjWorksOnTextInMemory) {
  TempDir dir;
  dir.Write("lib.mtl", kMtl);
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene =
      ParseObj("mtllib lib.mtl\nv 0 0 0\nv 2 0 0\nv 0 2 0\nusemtl lamp\nf 1 2 3\n", "memory.obj",
               dir.path(), &warnings);
  ASSERT_OK(scene);
  EXPECT_EQ(scene->source, "memory.obj");
  EXPECT_DOUBLE_EQ(PolygonArea(*scene, scene->faces[0]), 2.0);
}

// ---------------------------------------------------------------------------------------------
// Validation: one case per rule. Each checks that loading fails with INVALID_ARGUMENT (NOT_FOUND
// for a missing file) and that the message names the file, the line (or surface) and the problem.

struct ObjRefusal {
  std::string name;
  std::string obj;             // Text of scene.obj...
  const char* mtl;             // ...and of scene.mtl (kMtl unless the rule is about a material).
  std::string file;            // The file the message names ("scene.obj" or "scene.mtl")...
  std::string where;           // ...followed by this: the line and the problem.
  std::string also_file = "";  // A file whose path the message must also contain, if any...
  std::string also = "";       // ...and more words it must contain, if any.
  absl::StatusCode code = absl::StatusCode::kInvalidArgument;
  bool strict = false;  // Refused only with ObjOptions::strict (else mended with a warning).
};

std::vector<ObjRefusal> ObjRefusals() {
  const std::string v3 = kThreeVertices;
  return {
      {"NanCoordinate", "mtllib scene.mtl\nv 0 0 0\nv 1 nan 0\nv 1 1 0\nusemtl lamp\nf 1 2 3\n",
       kMtl, "scene.obj", ":3: vertex has a NaN or infinite coordinate"},
      {"InfiniteCoordinate",
       "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 -inf\nusemtl lamp\nf 1 2 3\n", kMtl, "scene.obj",
       ":4: vertex has a NaN or infinite coordinate"},
      {"OverflowingCoordinateIsInfinite",
       "mtllib scene.mtl\nv 0 0 1e400\nv 1 0 0\nv 1 1 0\nusemtl lamp\nf 1 2 3\n", kMtl, "scene.obj",
       ":2: vertex has a NaN or infinite coordinate"},
      {"MalformedCoordinate", "mtllib scene.mtl\nv 0 0 0\nv 1 0x 0\nv 1 1\nusemtl lamp\nf 1 2 3\n",
       kMtl, "scene.obj", ":3: vertex coordinate '0x' is not a number"},
      {"VertexWithTooFewCoordinates",
       "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 1 1\nusemtl lamp\nf 1 2 3\n", kMtl, "scene.obj",
       ":4: vertex has 2 coordinates; it needs 3"},
      {"VertexIndexOutOfRange", v3 + "usemtl lamp\nf 1 2 99\n", kMtl, "scene.obj",
       ":6: vertex index 99 is out of range (3 vertices defined so far)"},
      {"VertexIndexDefinedOnlyLaterIsOutOfRange",
       "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nusemtl lamp\nf 1 2 -3\nv 1 1 0\n", kMtl, "scene.obj",
       ":5: vertex index -3 is out of range (2 vertices defined so far)"},
      {"VertexIndexZero", v3 + "usemtl lamp\nf 0 1 2\n", kMtl, "scene.obj",
       ":6: vertex index 0 is invalid"},
      {"FaceWithFewerThanThreeVertices", v3 + "usemtl lamp\nf 1 2\n", kMtl, "scene.obj",
       ":6: face has 2 vertices; a face needs at least 3"},
      {"ReflectanceOfOneOrMore", v3 + "usemtl bright\nf 1 2 3\n",
       "newmtl lamp\nKe 1 1 1\n\nnewmtl bright\nKd 1.2 0.5 0.5\n", "scene.mtl",
       ":5: material 'bright': reflectance (Kd) (1.2, 0.5, 0.5) is outside [0, 1)", "", "",
       absl::StatusCode::kInvalidArgument, true},
      {"ReflectanceExactlyOne", v3 + "usemtl white\nf 1 2 3\n", "newmtl white\nKd 1\nKe 1 1 1\n",
       "scene.mtl", ":2: material 'white': reflectance (Kd) (1, 1, 1) is outside [0, 1)", "", "",
       absl::StatusCode::kInvalidArgument, true},
      {"NegativeReflectance", v3 + "usemtl dark\nf 1 2 3\n",
       "newmtl dark\nKe 1 1 1\nKd 0.5 -0.1 0.5\n", "scene.mtl",
       ":3: material 'dark': reflectance (Kd) (0.5, -0.1, 0.5) is outside [0, 1)"},
      {"DissolveOutsideZeroToOne", v3 + "usemtl glass\nf 1 2 3\n",
       "newmtl glass\nKe 1 1 1\nd 1.5\n", "scene.mtl",
       ":3: material 'glass': 'd 1.5' is outside [0, 1]"},
      {"MalformedDissolve", v3 + "usemtl glass\nf 1 2 3\n", "newmtl glass\nKe 1 1 1\nTr half\n",
       "scene.mtl", ":3: 'Tr' expects a number; 'half' is not one"},
      {"TransmissionFilterAboveOne", v3 + "usemtl glass\nf 1 2 3\n",
       "newmtl glass\nKe 1 1 1\nTf 1.5 1 1\nd 0.5\n", "scene.mtl",
       ":3: material 'glass': transmittance (Tf) (1.5, 1, 1) is outside [0, 1]"},
      {"NegativeEmission", v3 + "usemtl lamp\nf 1 2 3\n",
       "newmtl lamp\nKd 0.5 0.5 0.5\nKe 1 -2 1\n", "scene.mtl",
       ":3: material 'lamp': negative emission (Ke) (1, -2, 1)"},
      {"UnknownMaterial", v3 + "usemtl whtie\nf 1 2 3\n", kMtl, "scene.obj",
       ":5: unknown material 'whtie' (defined: white, lamp)", "", "",
       absl::StatusCode::kInvalidArgument, true},
      {"FaceWithoutMaterial", v3 + "f 1 2 3\n", kMtl, "scene.obj",
       ":5: no material (usemtl) for face", "", "", absl::StatusCode::kInvalidArgument, true},
      {"MissingMaterialLibrary",
       "v 0 0 0\nmtllib nowhere.mtl\nv 1 0 0\nv 1 1 0\nusemtl lamp\nf 1 2 3\n", kMtl, "scene.obj",
       ":2: mtllib 'nowhere.mtl'", "nowhere.mtl", "No such file or directory",
       absl::StatusCode::kNotFound, true},
      {"NoFaces", v3 + "usemtl lamp\n", kMtl, "scene.obj", ": the scene has no faces"},
  };
}

void PrintTo(const ObjRefusal& rule, std::ostream* os) { *os << rule.name; }

class ObjValidationRuleTest : public ::testing::TestWithParam<ObjRefusal> {};

TEST_P(ObjValidationRuleTest, RefusesNamingTheFileTheLineAndTheProblem) {
  const ObjRefusal& rule = GetParam();
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadText(dir, rule.obj, rule.mtl, nullptr, rule.strict);
  ASSERT_FALSE(scene.ok());
  EXPECT_EQ(scene.status().code(), rule.code) << scene.status();
  EXPECT_THAT(scene.status().message(), HasSubstr(dir.File(rule.file) + rule.where));
  if (!rule.also_file.empty()) {
    EXPECT_THAT(scene.status().message(), HasSubstr(dir.File(rule.also_file)));
  }
  if (!rule.also.empty()) {
    EXPECT_THAT(scene.status().message(), HasSubstr(rule.also));
  }
}

std::string RuleName(const ::testing::TestParamInfo<ObjRefusal>& rule) { return rule.param.name; }

INSTANTIATE_TEST_SUITE_P(Rules, ObjValidationRuleTest, ::testing::ValuesIn(ObjRefusals()),
                         RuleName);

TEST(ObjValidationTest, InvalidMaterialThatNoFaceUsesIsNotAnError) {
  TempDir dir;
  absl::StatusOr<Scene> scene =
      LoadText(dir, "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl lamp\nf 1 2 3\n",
               "newmtl unused\nKd 1 1 1\nnewmtl lamp\nKe 1 1 1\n");
  ASSERT_OK(scene);
  ASSERT_THAT(scene->materials, SizeIs(1));
  EXPECT_EQ(scene->materials[0].name, "lamp");
}

TEST(ObjValidationTest, MissingFile) {
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadObj(dir.File("absent.obj"), nullptr);
  ASSERT_FALSE(scene.ok());
  EXPECT_THAT(scene.status().message(),
              AllOf(HasSubstr(dir.File("absent.obj")), HasSubstr("No such file or directory")));
}

TEST(ObjValidationTest, DirectoryInsteadOfFile) {
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadObj(dir.path(), nullptr);
  ASSERT_FALSE(scene.ok());
  EXPECT_THAT(scene.status().message(),
              AllOf(HasSubstr(dir.path() + ": cannot read"), HasSubstr("Is a directory")));
}

TEST(ObjValidationTest, BinaryFileWithNulByte) {
  TempDir dir;
  std::string bytes("v 0 0 0\nv 1", 11);
  bytes += std::string("\0\x01\x02", 3);
  absl::StatusOr<Scene> scene = LoadObj(dir.Write("model.obj", bytes), nullptr);
  ASSERT_FALSE(scene.ok());
  EXPECT_EQ(scene.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(scene.status().message(),
              HasSubstr(dir.File("model.obj") + ": looks binary (NUL byte at offset 11)"));
}

TEST(ObjValidationTest, TextThatIsNotUtf8IsReadAsLatin1WithAWarning) {
  // Older exporters write names in Latin-1 (assimp-testmodels' regr01.mtl: "Terraind\xE6k"); the
  // OBJ and its library agree, so the names still match. Binary files (NUL bytes) stay refused.
  TempDir dir;
  dir.Write("scene.mtl", "newmtl Terraind\xE6k\nKd 0.5\nKe 1 1 1\n");
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadObj(
      dir.Write("model.obj", std::string(kThreeVertices) + "usemtl Terraind\xE6k\nf 1 2 3\n"),
      &warnings);
  ASSERT_OK(scene);
  EXPECT_EQ(scene->materials[0].name, "Terraind\xC3\xA6k");
  ASSERT_THAT(warnings, SizeIs(2));
  EXPECT_THAT(warnings, ::testing::Contains(
                            HasSubstr(dir.File("model.obj") +
                                      ": not UTF-8 (byte 0xE6 at offset 56); read as Latin-1")));
  EXPECT_THAT(warnings, ::testing::Contains(HasSubstr(dir.File("scene.mtl") + ": not UTF-8")));

  // Past the first 64 KiB too (regr01.obj names "Terraind\xE6k" at line 4841): every name and
  // warning is UTF-8.
  warnings.clear();
  std::string padded = std::string(kThreeVertices);
  for (int i = 0; i < 14000; ++i) padded += "# padding\n";
  scene = LoadObj(dir.Write("late.obj", padded + "usemtl Terraind\xE6k\nf 1 2 3\n"), &warnings);
  ASSERT_OK(scene);
  EXPECT_EQ(scene->materials[0].name, "Terraind\xC3\xA6k");
  EXPECT_THAT(warnings, ::testing::Contains(HasSubstr(dir.File("late.obj") + ": not UTF-8")));
}

TEST(ObjValidationTest, ZeroAreaFaceIsDroppedWithAWarning) {
  TempDir dir;
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadText(dir, absl::StrCat(kThreeVertices, R"(v 2 0 0
g good
usemtl lamp
f 1 2 3
g sliver
f 1 2 4
)"),
                                         kMtl, &warnings);
  ASSERT_OK(scene);
  ASSERT_THAT(scene->faces, SizeIs(1));
  EXPECT_EQ(scene->surfaces[scene->faces[0].surface].name, "good");
  ASSERT_THAT(warnings, SizeIs(1));
  EXPECT_THAT(warnings[0], AllOf(HasSubstr(dir.File("scene.obj") + ":10:"),
                                 HasSubstr("surface 'sliver'"), HasSubstr("zero area")));
}

TEST(CheckTextTest, AcceptsUtf8AndReportsTheFirstBadByte) {
  EXPECT_TRUE(CheckText("v 1 2 3 # \xE2\x82\xAC \xF0\x9F\x98\x80\n", "a.obj").ok());
  EXPECT_THAT(CheckText("abc\xC0\xAF", "a.obj").message(),  // Overlong '/'.
              HasSubstr("a.obj: looks binary (invalid UTF-8 at offset 3)"));
  EXPECT_THAT(CheckText("ab\xE2\x82", "a.obj").message(),  // Truncated sequence.
              HasSubstr("a.obj: looks binary (invalid UTF-8 at offset 2)"));
  // Only the first 64 KiB are examined.
  std::string late(70000, 'x');
  late[69000] = '\0';
  EXPECT_TRUE(CheckText(late, "a.obj").ok());
  late[65535] = '\0';
  EXPECT_THAT(CheckText(late, "a.obj").message(), HasSubstr("NUL byte at offset 65535"));
}

TEST(ObjLoaderTest, LoadsALargeGrid) {
  // 300 x 300 quads sharing vertices: every index resolves to the right vertex at scale.
  constexpr int kN = 300;
  std::string obj = "mtllib scene.mtl\nusemtl lamp\n";
  for (int j = 0; j <= kN; ++j) {
    for (int i = 0; i <= kN; ++i) absl::StrAppend(&obj, "v ", i, " ", j, " 0.5\n");
  }
  for (int j = 0; j < kN; ++j) {
    for (int i = 0; i < kN; ++i) {
      int a = j * (kN + 1) + i + 1;
      absl::StrAppend(&obj, "f ", a, " ", a + 1, " ", a + kN + 2, " ", a + kN + 1, "\n");
    }
  }
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadText(dir, obj);
  ASSERT_OK(scene);
  EXPECT_THAT(scene->faces, SizeIs(kN * kN));
  EXPECT_THAT(scene->vertices, SizeIs((kN + 1) * (kN + 1)));
  double area = 0;
  for (const Face& f : scene->faces) area += PolygonArea(*scene, f);
  EXPECT_NEAR(area, kN * kN, 1e-6);
}

}  // namespace
}  // namespace radiosity

// ---------------------------------------------------------------------------------------------
// OBJ/MTL as exporters write it (issue 14): what the strict rules above refuse is mended with one
// warning per cause that names the file and the lines.

namespace radiosity {
namespace {

TEST(ObjExporterTest, FacesWithoutAMaterialTakeTheDefaultGreyWithOneWarningNamingTheLines) {
  TempDir dir;
  std::vector<std::string> warnings;
  // Faces at lines 5-6 and 8 have no usemtl; line 10's has one.
  absl::StatusOr<Scene> scene = LoadText(
      dir,
      std::string(kThreeVertices) + "f 1 2 3\nf 1 3 2\ng other\nf 1 2 3\nusemtl lamp\nf 1 2 3\n",
      kMtl, &warnings);
  ASSERT_OK(scene);
  ASSERT_THAT(scene->faces, SizeIs(4));
  const Material& grey = scene->materials[scene->surfaces[scene->faces[0].surface].material];
  EXPECT_EQ(grey.name, kDefaultMaterialName);
  EXPECT_EQ(grey.reflectance, Rgb::Gray(kDefaultReflectance));
  EXPECT_FALSE(grey.IsEmitter());
  EXPECT_EQ(scene->materials[scene->surfaces[scene->faces[3].surface].material].name, "lamp");
  ASSERT_THAT(warnings, SizeIs(1));
  EXPECT_THAT(warnings[0], AllOf(HasSubstr(dir.File("scene.obj") + ":5-6, 8: no material (usemtl)"),
                                 HasSubstr("3 faces take the default material 'default_grey'")));
}

TEST(ObjExporterTest, UnknownMaterialAndMissingLibraryAreWarningsAndTheDefault) {
  TempDir dir;
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene =
      LoadText(dir,
               "mtllib scene.mtl gone.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nusemtl Default\nf 1 2 3\n"
               "usemtl lamp\nf 1 3 2\n",
               kMtl, &warnings);
  ASSERT_OK(scene);
  EXPECT_EQ(MaterialOf(*scene, "scene/default_grey").reflectance, Rgb::Gray(0.5));
  ASSERT_THAT(warnings, SizeIs(2));
  EXPECT_THAT(warnings[0], AllOf(HasSubstr(dir.File("scene.obj") + ":1: mtllib 'gone.mtl'"),
                                 HasSubstr("skipped")));
  EXPECT_THAT(warnings[1],
              AllOf(HasSubstr(dir.File("scene.obj") + ":6: unknown material 'Default'"),
                    HasSubstr("named at line 5"), HasSubstr("1 face takes the default")));
}

TEST(ObjExporterTest, ReflectanceOfOneIsClampedWithAWarning) {
  TempDir dir;
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene =
      LoadText(dir, std::string(kThreeVertices) + "usemtl white\nf 1 2 3\n",
               "newmtl white\nKd 1 0.5 1.2\nKe 1 1 1\n", &warnings);
  ASSERT_OK(scene);
  EXPECT_EQ(scene->materials[0].reflectance, Rgb(kMaxReflectance, 0.5, kMaxReflectance));
  ASSERT_THAT(warnings, SizeIs(1));
  EXPECT_THAT(warnings[0], AllOf(HasSubstr(dir.File("scene.mtl") + ":2: material 'white'"),
                                 HasSubstr("clamped to (0.99, 0.5, 0.99)")));
}

TEST(ObjExporterTest, TransmissionFilterAloneIsOpaque) {
  // Exporters write `Tf 1 1 1` on opaque materials: Tf is the colour of what `d`/`Tr` let
  // through, not an amount.
  TempDir dir;
  absl::StatusOr<Scene> scene = LoadText(dir, std::string(kThreeVertices) + "usemtl m\nf 1 2 3\n",
                                         "newmtl m\nKd 0.8 0.8 0.8\nTf 1 1 1\nKe 1 1 1\n");
  ASSERT_OK(scene);
  EXPECT_EQ(scene->materials[0].reflectance, Rgb::Gray(0.8));
  EXPECT_EQ(scene->materials[0].transmittance, Rgb());
  EXPECT_FALSE(scene->materials[0].HasBackSide());
}

TEST(ObjExporterTest, LibraryPathsWithDotSlashBackslashesAndSubfoldersResolve) {
  TempDir dir;
  std::filesystem::create_directory(dir.File("mat"));
  dir.Write("mat/sub.mtl", "newmtl sub\nKd 0.3\n");
  dir.Write("scene.mtl", kMtl);
  std::vector<std::string> warnings;
  ObjOptions confined;
  confined.confine_to_directory = true;
  absl::StatusOr<Scene> scene =
      LoadObj(dir.Write("scene.obj",
                        "mtllib ./scene.mtl\nmtllib .\\mat\\sub.mtl\nv 0 0 0\nv 1 0 0\n"
                        "v 1 1 0\nusemtl sub\nf 1 2 3\nusemtl lamp\nf 1 3 2\n"),
              &warnings, confined);
  ASSERT_OK(scene);
  EXPECT_THAT(warnings, ::testing::IsEmpty());
  EXPECT_EQ(MaterialOf(*scene, "scene/sub").reflectance, Rgb::Gray(0.3));
  absl::StatusOr<std::string> text = ReadWholeFile(dir.File("scene.obj"));
  ASSERT_OK(text);
  EXPECT_THAT(ScanMaterialLibraries(*text, dir.path()), ElementsAre("scene.mtl", "mat/sub.mtl"));
}

TEST(ObjExporterTest, Utf16FilesReadAsTheirUtf8Text) {
  const std::string text = std::string(kThreeVertices) + "usemtl lamp\nf 1 2 3\n";
  for (bool little : {true, false}) {
    TempDir dir;
    dir.Write("scene.mtl", kMtl);
    std::string utf16 = little ? "\xFF\xFE" : "\xFE\xFF";
    for (char c : text) {
      utf16 += little ? std::string{c, '\0'} : std::string{'\0', c};
    }
    absl::StatusOr<Scene> scene = LoadObj(dir.Write("scene.obj", utf16), nullptr);
    ASSERT_OK(scene);
    EXPECT_THAT(scene->faces, SizeIs(1));
    EXPECT_TRUE(scene->materials[0].IsEmitter());
  }
}

// `v x y z r g b` (MeshLab, ZBrush, scanners): with ObjOptions::vertex_colors each face takes
// its vertices' mean colour as reflectance, grouped into surfaces by colour; a material's other
// properties stay; faces with an uncoloured vertex keep their material.
TEST(ObjExporterTest, VertexColoursAreReflectanceOnRequest) {
  TempDir dir;
  dir.Write("scene.mtl", "newmtl paint\nKd 0.5 0.5 0.5\nKe 0 0 0\nd 0.9\n");
  const std::string path = dir.Write("scene.obj", R"(mtllib scene.mtl
o wall
v 0 0 0 0.8 0 0
v 1 0 0 0.8 0 0
v 1 1 0 0.2 0 0
v 0 0 1 0 0 0.25
v 1 0 1 0 0 0.25
v 1 1 1 0 0 0.25
v 0 1 1 1
usemtl paint
f 1 2 3
f 4 5 6
f 4 6 7
)");
  ObjOptions options;
  options.vertex_colors = true;
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadObj(path, &warnings, options);
  ASSERT_OK(scene);
  ASSERT_THAT(scene->surfaces, SizeIs(3));
  EXPECT_EQ(scene->surfaces[0].name, "wall#1");
  EXPECT_EQ(scene->surfaces[1].name, "wall#2");
  EXPECT_EQ(scene->surfaces[2].name, "wall");  // Vertex 7 has a weight, not a colour.
  const Material& red = scene->materials[scene->surfaces[0].material];
  const Material& blue = scene->materials[scene->surfaces[1].material];
  EXPECT_EQ(red.name, "paint@wall#1");
  // The colour (rounded to 1/64) times the material's dissolve d, as Kd would be.
  EXPECT_NEAR(red.reflectance.r, 0.6 * 0.9, 0.9 / 128 + 1e-9);
  EXPECT_NEAR(blue.reflectance.b, 0.25 * 0.9, 0.9 / 128 + 1e-9);
  EXPECT_EQ(red.reflectance.g, 0);
  EXPECT_NEAR(red.transmittance.r, 0.1, 1e-9);  // 1 - d, kept.
  EXPECT_NEAR(scene->materials[scene->surfaces[2].material].reflectance.g, 0.45, 1e-9);
  // Without the option the colours are ignored: one surface.
  absl::StatusOr<Scene> plain = LoadObj(path, nullptr);
  ASSERT_OK(plain);
  EXPECT_THAT(plain->surfaces, SizeIs(1));
}

// Every OBJ model of Debian's assimp-testmodels (README's set-up installs it) loads, or is
// refused with a message naming the file and the problem; none crashes.
TEST(ObjExporterTest, EveryAssimpTestModelLoadsOrNamesItsProblem) {
  const std::string root = "/usr/share/assimp/models";
  if (!FileExists(root + "/OBJ/box.obj")) {
    GTEST_SKIP() << root << " is absent: install the Debian package assimp-testmodels";
  }
  // The refusals that are right: files without faces and a malformed number.
  const std::map<std::string, std::string> refused = {
      {"OBJ/point_cloud.obj", "the scene has no faces"},
      {"OBJ/testline.obj", "the scene has no faces"},
      {"OBJ/testpoints.obj", "the scene has no faces"},
      {"OBJ/number_formats.obj", ":11: vertex coordinate '3.1+e2' is not a number"},
      {"invalid/empty.obj", "the scene has no faces"},
      {"invalid/malformed.obj", ":23: vertex index 12 is out of range"},
      {"invalid/malformed2.obj", ":23: face has 0 vertices"},
  };
  int loaded = 0;
  for (const std::string folder : {"OBJ", "invalid"}) {
    for (const auto& entry : std::filesystem::directory_iterator(root + "/" + folder)) {
      const std::string name = entry.path().filename().string();
      if (!absl::EndsWith(name, ".obj")) continue;
      const std::string key = folder + "/" + name, path = root + "/" + key;
      std::vector<std::string> warnings;
      absl::StatusOr<Scene> scene = LoadObj(path, &warnings);
      auto it = refused.find(key);
      if (it == refused.end()) {
        EXPECT_TRUE(scene.ok()) << key << ": " << scene.status();
        if (scene.ok()) ++loaded;
        // Each warning names the model's file or one of its libraries, with a line where the
        // problem has one.
        for (const std::string& w : warnings) {
          EXPECT_THAT(w, ::testing::ContainsRegex("^" + root + "/" + folder + "/[^:]+\\.(obj|mtl)"))
              << key;
        }
      } else {
        ASSERT_FALSE(scene.ok()) << key;
        EXPECT_THAT(scene.status().message(), AllOf(HasSubstr(path), HasSubstr(it->second)));
      }
    }
  }
  EXPECT_GE(loaded, 18);  // Of 25 files, 7 rightly refused.
}

}  // namespace
}  // namespace radiosity
