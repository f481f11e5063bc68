// Tests of the native scene format (proto/radiosity/v1/scene.proto) and its codec: JSON and
// binary loading, round trips, and one test per validation rule through the JSON path.
#include "solver/input/scene_codec.h"

#include <cmath>
#include <functional>
#include <initializer_list>
#include <ostream>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "google/protobuf/util/json_util.h"
#include "gtest/gtest.h"
#include "solver/input/obj_loader.h"
#include "solver/input/scene_files.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using ::radiosity::testing::MakeClosedBox;
using ::radiosity::testing::SourcePath;
using ::testing::HasSubstr;

// Vector area of a face (Newell): its direction is the front normal, its length the area.
Vec3 VectorArea(const Scene& scene, const Face& face) {
  Vec3 sum;
  const size_t n = face.vertices.size();
  for (size_t k = 0; k < n; ++k) {
    sum += Cross(scene.vertices[face.vertices[k]], scene.vertices[face.vertices[(k + 1) % n]]);
  }
  return sum * 0.5;
}

Vec3 Centroid(const Scene& scene, const Face& face) {
  Vec3 sum;
  for (int v : face.vertices) sum += scene.vertices[v];
  return sum / static_cast<double>(face.vertices.size());
}

// The polygons of a scene as coordinates, per surface name, for comparing scenes whose vertex
// numbering differs.
std::vector<std::pair<std::string, std::vector<Vec3>>> Polygons(const Scene& scene) {
  std::vector<std::pair<std::string, std::vector<Vec3>>> out;
  for (const Face& face : scene.faces) {
    std::vector<Vec3> points;
    for (int v : face.vertices) points.push_back(scene.vertices[v]);
    out.emplace_back(scene.surfaces[face.surface].name, points);
  }
  return out;
}

void ExpectSameMaterials(const Scene& a, const Scene& b) {
  ASSERT_EQ(a.materials.size(), b.materials.size());
  for (size_t i = 0; i < a.materials.size(); ++i) {
    SCOPED_TRACE(a.materials[i].name);
    EXPECT_EQ(a.materials[i].name, b.materials[i].name);
    EXPECT_EQ(a.materials[i].reflectance, b.materials[i].reflectance);
    EXPECT_EQ(a.materials[i].emission, b.materials[i].emission);
    EXPECT_EQ(a.materials[i].transmittance, b.materials[i].transmittance);
    EXPECT_EQ(a.materials[i].two_sided, b.materials[i].two_sided);
    EXPECT_EQ(a.materials[i].mirror, b.materials[i].mirror);
    EXPECT_EQ(a.materials[i].glossy, b.materials[i].glossy);
    EXPECT_EQ(a.materials[i].glossy_exponent, b.materials[i].glossy_exponent);
    EXPECT_EQ(a.materials[i].glass, b.materials[i].glass);
    EXPECT_EQ(a.materials[i].ior, b.materials[i].ior);
    EXPECT_EQ(a.materials[i].refracts, b.materials[i].refracts);
  }
}

void ExpectSameSurfaces(const Scene& a, const Scene& b) {
  ASSERT_EQ(a.surfaces.size(), b.surfaces.size());
  for (size_t i = 0; i < a.surfaces.size(); ++i) {
    EXPECT_EQ(a.surfaces[i].name, b.surfaces[i].name);
    EXPECT_EQ(a.surfaces[i].material, b.surfaces[i].material);
  }
}

// Expects `b` to be `a` exactly: same vertex array, faces, surfaces and materials.
void ExpectSameScene(const Scene& a, const Scene& b) {
  EXPECT_EQ(a.vertices, b.vertices);
  ASSERT_EQ(a.faces.size(), b.faces.size());
  for (size_t f = 0; f < a.faces.size(); ++f) {
    EXPECT_EQ(a.faces[f].surface, b.faces[f].surface) << "face " << f;
    EXPECT_EQ(a.faces[f].vertices, b.faces[f].vertices) << "face " << f;
  }
  ExpectSameSurfaces(a, b);
  ExpectSameMaterials(a, b);
}

// A small valid scene: materials "white" (emitting) and "red"; surfaces "floor" (a unit square at
// z = 0 facing +z) and "wall" (a unit square at y = 1 facing -y), each with 4 vertices and one
// face.
void SetColor(radiosity::v1::Color* color, double r, double g, double b) {
  color->set_r(r);
  color->set_g(g);
  color->set_b(b);
}

// Adds a surface of four vertices (x, y, z each) and the one face through them in order.
void AddQuad(radiosity::v1::Scene* msg, const std::string& name, const std::string& material,
             std::initializer_list<double> vertices) {
  radiosity::v1::Surface* surface = msg->add_surfaces();
  surface->set_name(name);
  surface->set_material(material);
  for (double v : vertices) surface->add_vertices(v);
  radiosity::v1::Face* face = surface->add_faces();
  for (uint32_t i : {0, 1, 2, 3}) face->add_indices(i);
}

radiosity::v1::Scene ValidScene() {
  radiosity::v1::Scene msg;
  msg.set_name("valid");
  radiosity::v1::Material* white = msg.add_materials();
  white->set_name("white");
  SetColor(white->mutable_reflectance(), 0.8, 0.8, 0.8);
  white->mutable_emission()->set_r(2);
  radiosity::v1::Material* red = msg.add_materials();
  red->set_name("red");
  SetColor(red->mutable_reflectance(), 0.6, 0.1, 0.1);

  AddQuad(&msg, "floor", "white", {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0});
  AddQuad(&msg, "wall", "red", {0, 1, 0, 1, 1, 0, 1, 1, 1, 0, 1, 1});
  return msg;
}

std::string ToJson(const radiosity::v1::Scene& msg) {
  std::string json;
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = true;
  EXPECT_TRUE(google::protobuf::util::MessageToJsonString(msg, &json, options).ok());
  return json;
}

class SceneCodecTest : public ::testing::Test {
 protected:
  // Writes `text` to <tmp>/scene.json and loads it.
  absl::StatusOr<Scene> LoadJsonText(const std::string& text) {
    return LoadSceneFile(dir_.Write("scene.json", text), &warnings_);
  }
  absl::StatusOr<Scene> LoadJson(const radiosity::v1::Scene& msg) {
    return LoadJsonText(ToJson(msg));
  }
  // Loads `msg` through JSON, expects an InvalidArgument error and returns its message.
  std::string JsonError(const radiosity::v1::Scene& msg) { return ErrorOf(LoadJson(msg)); }
  std::string ErrorOf(const absl::StatusOr<Scene>& result) {
    EXPECT_FALSE(result.ok()) << "loaded unexpectedly: " << result->ToString();
    if (result.ok()) return "";
    EXPECT_EQ(result.status().code(), absl::StatusCode::kInvalidArgument) << result.status();
    return std::string(result.status().message());
  }
  std::string JsonPath() const { return dir_.File("scene.json"); }

  testing::TempDir dir_;
  std::vector<std::string> warnings_;
};

TEST_F(SceneCodecTest, LoadsFurnaceJson) {
  absl::StatusOr<Scene> scene = LoadSceneFile(SourcePath("scenes/furnace.json"), &warnings_);
  ASSERT_TRUE(scene.ok()) << scene.status();
  EXPECT_THAT(warnings_, ::testing::IsEmpty());
  EXPECT_EQ(scene->source, SourcePath("scenes/furnace.json"));
  ASSERT_EQ(scene->surfaces.size(), 6u);
  ASSERT_EQ(scene->faces.size(), 6u);
  ASSERT_EQ(scene->materials.size(), 1u);
  EXPECT_EQ(scene->materials[0].reflectance, Rgb::Gray(0.5));
  EXPECT_EQ(scene->materials[0].emission, Rgb::Gray(1));
  EXPECT_EQ(scene->materials[0].transmittance, Rgb());
  EXPECT_FALSE(scene->materials[0].two_sided);

  double total_area = 0;
  const Vec3 center(0.5, 0.5, 0.5);
  std::vector<int> faces_per_surface(6, 0);
  for (size_t f = 0; f < scene->faces.size(); ++f) {
    const Face& face = scene->faces[f];
    SCOPED_TRACE(scene->DescribeFace(static_cast<int>(f)));
    EXPECT_EQ(face.vertices.size(), 4u);
    EXPECT_EQ(scene->surfaces[face.surface].material, 0);
    ++faces_per_surface[face.surface];
    const double area = PolygonArea(*scene, face);
    EXPECT_NEAR(area, 1.0, 1e-12);
    total_area += area;
    // Inward: the front normal points from the face towards the cube's center.
    const Vec3 normal = Normalize(VectorArea(*scene, face));
    const Vec3 to_center = Normalize(center - Centroid(*scene, face));
    EXPECT_NEAR(Dot(normal, to_center), 1.0, 1e-12);
  }
  EXPECT_NEAR(total_area, 6.0, 1e-12);
  EXPECT_EQ(faces_per_surface, std::vector<int>(6, 1));
}

TEST_F(SceneCodecTest, LoadsTwoSquaresJson) {
  absl::StatusOr<Scene> scene =
      LoadSceneFile(SourcePath("tests/data/two_squares.json"), &warnings_);
  ASSERT_TRUE(scene.ok()) << scene.status();
  EXPECT_THAT(warnings_, ::testing::IsEmpty());
  ASSERT_EQ(scene->surfaces.size(), 2u);
  ASSERT_EQ(scene->faces.size(), 2u);
  EXPECT_EQ(scene->surfaces[0].name, "emitter");
  EXPECT_EQ(scene->surfaces[1].name, "receiver");
  const Material& emitter = scene->materials[scene->surfaces[0].material];
  const Material& receiver = scene->materials[scene->surfaces[1].material];
  EXPECT_EQ(emitter.emission, Rgb::Gray(1));
  EXPECT_EQ(emitter.reflectance, Rgb());
  EXPECT_EQ(receiver.emission, Rgb());
  EXPECT_EQ(receiver.reflectance, Rgb());

  const Vec3 a0 = VectorArea(*scene, scene->faces[0]);
  const Vec3 a1 = VectorArea(*scene, scene->faces[1]);
  EXPECT_EQ(scene->faces[0].surface, 0);
  EXPECT_EQ(a0, Vec3(0, 0, 1));   // At z = 0, facing +z, area 1.
  EXPECT_EQ(a1, Vec3(0, 0, -1));  // At z = 1, facing -z, area 1.
  EXPECT_EQ(Centroid(*scene, scene->faces[0]), Vec3(0.5, 0.5, 0));
  EXPECT_EQ(Centroid(*scene, scene->faces[1]), Vec3(0.5, 0.5, 1));
}

TEST_F(SceneCodecTest, SurfaceIndicesAreLocalAndOffset) {
  absl::StatusOr<Scene> scene = LoadJson(ValidScene());
  ASSERT_TRUE(scene.ok()) << scene.status();
  ASSERT_EQ(scene->vertices.size(), 8u);
  ASSERT_EQ(scene->faces.size(), 2u);
  EXPECT_EQ(scene->faces[0].vertices, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(scene->faces[1].vertices, (std::vector<int>{4, 5, 6, 7}));
  EXPECT_EQ(scene->faces[1].surface, 1);
  EXPECT_EQ(scene->surfaces[1].material, 1);
  EXPECT_EQ(scene->vertices[4], Vec3(0, 1, 0));
}

TEST_F(SceneCodecTest, BinaryRoundTrip) {
  absl::StatusOr<Scene> original = LoadSceneFile(SourcePath("scenes/furnace.json"), &warnings_);
  ASSERT_TRUE(original.ok()) << original.status();
  const radiosity::v1::Scene msg = SceneToProto(*original);
  EXPECT_EQ(msg.name(), "furnace");
  ASSERT_EQ(msg.surfaces_size(), 6);
  EXPECT_EQ(msg.surfaces(0).vertices_size(), 12);

  const std::string path = dir_.File("furnace.pb");
  ASSERT_TRUE(SaveSceneFile(*original, path).ok());
  absl::StatusOr<Scene> loaded = LoadSceneFile(path, &warnings_);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  EXPECT_THAT(warnings_, ::testing::IsEmpty());
  EXPECT_EQ(loaded->source, path);
  ExpectSameScene(*original, *loaded);

  // .binpb is the same format.
  const std::string binpb = dir_.File("furnace.binpb");
  ASSERT_TRUE(SaveSceneFile(*original, binpb).ok());
  absl::StatusOr<Scene> loaded2 = LoadSceneFile(binpb, &warnings_);
  ASSERT_TRUE(loaded2.ok()) << loaded2.status();
  ExpectSameScene(*original, *loaded2);
}

TEST_F(SceneCodecTest, JsonRoundTrip) {
  absl::StatusOr<Scene> original = LoadJson(ValidScene());
  ASSERT_TRUE(original.ok()) << original.status();
  const std::string path = dir_.File("copy.json");
  ASSERT_TRUE(SaveSceneFile(*original, path).ok());
  EXPECT_THAT(testing::ReadFile(path), HasSubstr("\"two_sided\": false"));
  absl::StatusOr<Scene> loaded = LoadSceneFile(path, &warnings_);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ExpectSameScene(*original, *loaded);
}

TEST_F(SceneCodecTest, RoundTripOfSharedVerticesAndAllMaterialFields) {
  // MakeClosedBox shares its 8 corners between the sides; SceneToProto gives each surface its own
  // copies, so compare polygons by coordinates. Values that are not short decimals check that the
  // JSON encoding keeps doubles exactly.
  Material m;
  m.name = "glass";
  m.reflectance = {0.1, 0.2, 1.0 / 3};
  m.transmittance = {0.7, 0.6, 0.5};
  m.emission = {0, 1e-3, 12.5};
  m.two_sided = true;
  m.transmittance = {0.3, 0.2, 0.1};
  m.mirror = {0.1, 0, 0};
  m.glossy = {0.1, 0.1, 0.1};
  m.glossy_exponent = 33.5;
  m.glass = {0.2, 0.3, 0.1};
  m.ior = 1.333;
  m.refracts = true;
  Scene box = MakeClosedBox(2, 3.25, 1e-1 / 3, m);
  box.source = "box.obj";
  for (const char* file : {"box.json", "box.pb"}) {
    SCOPED_TRACE(file);
    const std::string path = dir_.File(file);
    ASSERT_TRUE(SaveSceneFile(box, path).ok());
    absl::StatusOr<Scene> loaded = LoadSceneFile(path, &warnings_);
    ASSERT_TRUE(loaded.ok()) << loaded.status();
    EXPECT_EQ(loaded->vertices.size(), 24u);
    EXPECT_EQ(Polygons(*loaded), Polygons(box));
    ExpectSameSurfaces(box, *loaded);
    ExpectSameMaterials(box, *loaded);
  }
  EXPECT_EQ(SceneToProto(box).name(), "box");
}

// docs/guide/specular.md: the parts are checked with the material named.
TEST_F(SceneCodecTest, SpecularPartsAreChecked) {
  radiosity::v1::Scene msg = ValidScene();
  SetColor(msg.mutable_materials(1)->mutable_mirror(), 0.5, 0.5, 0.5);
  EXPECT_THAT(JsonError(msg),
              ::testing::HasSubstr("materials[1] ('red'): reflectance + transmittance + mirror + "
                                   "glossy + glass (1.1, 0.6, 0.6) is above 1"));
  msg = ValidScene();
  SetColor(msg.mutable_materials(1)->mutable_glossy(), 0.2, 0.2, 0.2);
  EXPECT_THAT(JsonError(msg), ::testing::HasSubstr("materials[1] ('red'): glossy exponent 0"));
  msg.mutable_materials(1)->set_glossy_exponent(40);
  SetColor(msg.mutable_materials(1)->mutable_glass(), 0.1, 0.1, 0.1);
  ASSERT_OK_AND_ASSIGN(Scene scene, LoadJson(msg));
  EXPECT_EQ(scene.materials[1].ior, 1.5);  // Unset: 1.5.
  EXPECT_TRUE(scene.materials[1].IsSpecular());
  EXPECT_TRUE(scene.materials[1].HasBackSide());  // Glass passes light from either side.
}

TEST_F(SceneCodecTest, ExtensionIsCaseInsensitive) {
  Material gray;
  gray.name = "gray";
  gray.reflectance = Rgb::Gray(0.5);
  const std::string path = dir_.File("SCENE.JSON");
  ASSERT_TRUE(SaveSceneFile(MakeClosedBox(1, 1, 1, gray), path).ok());
  EXPECT_TRUE(LoadSceneFile(path, &warnings_).ok());
}

TEST_F(SceneCodecTest, DropsZeroAreaFacesWithWarning) {
  radiosity::v1::Scene msg = ValidScene();
  radiosity::v1::Face* sliver = msg.mutable_surfaces(0)->add_faces();
  for (uint32_t i : {0, 1, 0}) sliver->add_indices(i);
  absl::StatusOr<Scene> scene = LoadJson(msg);
  ASSERT_TRUE(scene.ok()) << scene.status();
  EXPECT_EQ(scene->faces.size(), 2u);
  ASSERT_EQ(warnings_.size(), 1u);
  EXPECT_THAT(warnings_[0], HasSubstr(JsonPath() + ": surface 'floor' face 1 has zero area"));
}

TEST_F(SceneCodecTest, DispatchesObjToLoadObj) {
  dir_.Write("tri.mtl", "newmtl white\nKd 0.5 0.5 0.5\nKe 1 1 1\n");
  const std::string path =
      dir_.Write("tri.obj", "mtllib tri.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl white\nf 1 2 3\n");
  std::vector<std::string> direct_warnings;
  absl::StatusOr<Scene> direct = LoadObj(path, &direct_warnings);
  absl::StatusOr<Scene> dispatched = LoadSceneFile(path, &warnings_);
  ASSERT_EQ(direct.status(), dispatched.status());
  EXPECT_EQ(direct_warnings, warnings_);
  if (direct.ok()) ExpectSameScene(*direct, *dispatched);
}

// --- Validation, one rule per case, through the JSON path. ---

// A validation rule of the native format: how it breaks ValidScene(), and what the message (after
// the file's path) must say.
struct SceneRule {
  std::string name;
  std::function<void(radiosity::v1::Scene*)> mutate;
  std::string message;
};

void PrintTo(const SceneRule& rule, std::ostream* os) { *os << rule.name; }

std::vector<SceneRule> SceneRules() {
  return {
      // Index 4 would be valid in the global array (8 vertices) but not in the surface's own list.
      {"OutOfRangeIndex",
       [](radiosity::v1::Scene* m) { m->mutable_surfaces(1)->mutable_faces(0)->set_indices(3, 4); },
       ": surfaces[1] ('wall').faces[0].indices[3]: vertex index 4 is out of range (surface has 4 "
       "vertices)"},
      {"VerticesNotMultipleOfThree",
       [](radiosity::v1::Scene* m) { m->mutable_surfaces(0)->add_vertices(5); },
       ": surfaces[0] ('floor').vertices: 13 numbers is not a multiple of 3"},
      {"UnknownMaterial",
       [](radiosity::v1::Scene* m) { m->mutable_surfaces(1)->set_material("blue"); },
       ": surfaces[1] ('wall').material: unknown material 'blue' (defined: 'white', 'red')"},
      {"MissingMaterial", [](radiosity::v1::Scene* m) { m->mutable_surfaces(0)->clear_material(); },
       ": surfaces[0] ('floor').material: no material given"},
      {"ReflectanceOfOne",
       [](radiosity::v1::Scene* m) { m->mutable_materials(1)->mutable_reflectance()->set_g(1.0); },
       ": materials[1] ('red').reflectance.g: 1 is outside [0, 1)"},
      {"ReflectancePlusTransmittanceAboveOne",
       [](radiosity::v1::Scene* m) {
         m->mutable_materials(1)->mutable_transmittance()->set_r(0.5);  // 0.6 + 0.5
       },
       ": materials[1] ('red'): reflectance.r + transmittance.r = 0.6 + 0.5 = 1.1 is above 1"},
      {"NegativeEmission",
       [](radiosity::v1::Scene* m) { m->mutable_materials(0)->mutable_emission()->set_b(-0.25); },
       ": materials[0] ('white').emission.b: -0.25 is negative"},
      {"SceneWithoutFaces",
       [](radiosity::v1::Scene* m) {
         m->mutable_surfaces(0)->clear_faces();
         m->mutable_surfaces(1)->clear_faces();
       },
       ": surfaces: the scene has no faces"},
      {"FaceWithTwoIndices",
       [](radiosity::v1::Scene* m) {
         m->mutable_surfaces(1)->mutable_faces(0)->mutable_indices()->Truncate(2);
       },
       ": surfaces[1] ('wall').faces[0].indices: 2 indices; a face needs at least 3"},
      {"DuplicateMaterialName",
       [](radiosity::v1::Scene* m) { m->mutable_materials(1)->set_name("white"); },
       ": materials[1] ('white').name: duplicate material name (also materials[0])"},
      {"DuplicateSurfaceName",
       [](radiosity::v1::Scene* m) { m->mutable_surfaces(1)->set_name("floor"); },
       ": surfaces[1] ('floor').name: duplicate surface name (also surfaces[0])"},
      {"EmptySurfaceName", [](radiosity::v1::Scene* m) { m->mutable_surfaces(1)->clear_name(); },
       ": surfaces[1].name: a surface needs a non-empty name"},
      {"EmptyMaterialName", [](radiosity::v1::Scene* m) { m->mutable_materials(0)->clear_name(); },
       ": materials[0].name: a material needs a non-empty name"},
  };
}

class SceneCodecRuleTest : public SceneCodecTest,
                           public ::testing::WithParamInterface<SceneRule> {};

TEST_P(SceneCodecRuleTest, RejectsNamingTheFieldAndTheProblem) {
  radiosity::v1::Scene msg = ValidScene();
  GetParam().mutate(&msg);
  EXPECT_THAT(JsonError(msg), HasSubstr(JsonPath() + GetParam().message));
}

std::string RuleName(const ::testing::TestParamInfo<SceneRule>& rule) { return rule.param.name; }

INSTANTIATE_TEST_SUITE_P(Rules, SceneCodecRuleTest, ::testing::ValuesIn(SceneRules()), RuleName);

TEST_F(SceneCodecTest, RejectsNanCoordinate) {
  // The protobuf JSON mapping accepts "NaN" for a double; our validation must not.
  const std::string text = R"({
    "materials": [{"name": "white", "reflectance": {"r": 0.5, "g": 0.5, "b": 0.5}}],
    "surfaces": [{
      "name": "floor", "material": "white",
      "vertices": [0, 0, 0,  1, 0, 0,  1, "NaN", 0],
      "faces": [{"indices": [0, 1, 2]}]
    }]
  })";
  EXPECT_THAT(ErrorOf(LoadJsonText(text)),
              HasSubstr(JsonPath() + ": surfaces[0] ('floor').vertices[7]: nan (y of vertex 2) "
                                     "is not a finite number"));
}

TEST_F(SceneCodecTest, RejectsInfiniteColor) {
  const std::string text = R"({
    "materials": [{"name": "sun", "emission": {"r": "Infinity"}}],
    "surfaces": [{"name": "s", "material": "sun", "vertices": [0,0,0, 1,0,0, 0,1,0],
                  "faces": [{"indices": [0, 1, 2]}]}]
  })";
  EXPECT_THAT(ErrorOf(LoadJsonText(text)),
              HasSubstr(JsonPath() + ": materials[0] ('sun').emission.r: inf is not a finite"));
}

TEST_F(SceneCodecTest, WarnsAboutSurfaceWithoutFaces) {
  radiosity::v1::Scene msg = ValidScene();
  msg.mutable_surfaces(1)->clear_faces();
  ASSERT_TRUE(LoadJson(msg).ok());
  ASSERT_EQ(warnings_.size(), 1u);
  EXPECT_EQ(warnings_[0], JsonPath() + ": surfaces[1] ('wall'): the surface has no faces");
}

TEST_F(SceneCodecTest, RejectsMalformedJson) {
  // A syntax error is located by line and column.
  const std::string missing_comma = R"({"name": "x",
  "materials": [
    {"name": "m" "reflectance": {}}
  ]
})";
  EXPECT_THAT(ErrorOf(LoadJsonText(missing_comma)),
              HasSubstr(JsonPath() + ":3:18: invalid JSON: "));
  EXPECT_THAT(ErrorOf(LoadJsonText(R"({"name": "x", "surfaces": [{"name": )")),
              HasSubstr(JsonPath() + ": invalid JSON: "));
  // A value of the wrong type is reported with its field path.
  EXPECT_THAT(ErrorOf(LoadJsonText(R"({"surfaces": [{"name": "a", "vertices": [1, 2, "q"]}]})")),
              HasSubstr(JsonPath() + ": surfaces[0].vertices[2]: "));
  EXPECT_THAT(ErrorOf(LoadJsonText("[1, 2]")),
              HasSubstr(JsonPath() + ": not a valid JSON Scene message: "));
}

TEST_F(SceneCodecTest, RejectsUnknownJsonField) {
  EXPECT_THAT(ErrorOf(LoadJsonText(R"({"name": "x", "surfacez": []})")),
              ::testing::AllOf(HasSubstr(JsonPath() + ": not a valid JSON Scene message: "),
                               HasSubstr("surfacez")));
}

TEST_F(SceneCodecTest, RejectsBinaryGarbageAsJson) {
  static constexpr char kPng[] = "\x89PNG\r\n\x1a\n\0\0\0\rIHDR\xff\xfe";
  const std::string garbage(kPng, sizeof kPng - 1);
  absl::StatusOr<Scene> result = LoadJsonText(garbage);
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(std::string(result.status().message()), HasSubstr(JsonPath()));
  EXPECT_THAT(std::string(result.status().message()), ::testing::Not(HasSubstr("JSON")));
}

TEST_F(SceneCodecTest, RejectsInvalidBinary) {
  // Field 1 (name), length 16, but only 3 bytes follow.
  const std::string path = dir_.Write("scene.pb", std::string("\x0a\x10"
                                                              "abc"));
  EXPECT_EQ(ErrorOf(LoadSceneFile(path, &warnings_)), path + ": not a valid binary Scene message");
}

TEST_F(SceneCodecTest, RejectsUnknownExtension) {
  const std::string path = dir_.Write("scene.xyz", "1 2 3\n");
  EXPECT_EQ(ErrorOf(LoadSceneFile(path, &warnings_)),
            path +
                ": unknown scene format '.xyz' (expected .obj, .json, .pb or a model: .gltf, "
                ".glb, .fbx, .dae, .3ds, .ply, .stl)");
  absl::Status saved = SaveSceneFile(MakeClosedBox(1, 1, 1, Material{}), dir_.File("out.obj"));
  EXPECT_EQ(saved.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_THAT(std::string(saved.message()), HasSubstr("out.obj: unknown scene format '.obj'"));
}

TEST_F(SceneCodecTest, ReportsMissingFile) {
  const std::string path = dir_.File("missing.json");
  absl::StatusOr<Scene> result = LoadSceneFile(path, &warnings_);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), absl::StatusCode::kNotFound);
  EXPECT_EQ(result.status().message(), path + ": cannot open: No such file or directory");
}

TEST_F(SceneCodecTest, ReportsUnwritableFile) {
  const std::string path = dir_.File("no/such/dir/scene.pb");
  absl::Status status = SaveSceneFile(MakeClosedBox(1, 1, 1, Material{}), path);
  ASSERT_FALSE(status.ok());
  EXPECT_THAT(std::string(status.message()), HasSubstr(path + ": cannot open for writing: "));
}

TEST_F(SceneCodecTest, MessagesWithoutSourceHaveNoPrefix) {
  radiosity::v1::Scene msg = ValidScene();
  msg.mutable_surfaces(0)->set_material("blue");
  absl::StatusOr<Scene> result = SceneFromProto(msg, "");
  ASSERT_FALSE(result.ok());
  EXPECT_THAT(std::string(result.status().message()),
              ::testing::StartsWith("surfaces[0] ('floor').material: unknown material 'blue'"));
}

}  // namespace
}  // namespace radiosity
