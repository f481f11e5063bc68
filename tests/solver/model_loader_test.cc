// Models through assimp (solver/input/model_loader.h): glTF written here byte by byte, so that
// what the loader must make of it follows from the glTF 2.0 specification, and the real models
// of Debian's assimp-testmodels.
#include "solver/input/model_loader.h"

#include <OpenImageIO/imageio.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <thread>
#include <vector>

#include "absl/strings/escaping.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "solver/geometry/scene.h"
#include "solver/geometry/sides.h"
#include "solver/geometry/solution.h"
#include "solver/geometry/vec.h"
#include "solver/input/scene_files.h"
#include "solver/util/file_io.h"
#include "tests/testing/test_util.h"
#include "tests/testing/world.h"

namespace radiosity {
namespace {

using ::radiosity::testing::MeshAndSolve;
using ::radiosity::testing::Refused;
using ::radiosity::testing::TempDir;
using ::testing::HasSubstr;
using ::testing::SizeIs;

// A glTF 2.0 asset with one mesh of triangles (positions and optional UVs), one material and the
// nodes given, its buffer inline (a data: URI) or named by `buffer_uri`.
struct Gltf {
  std::vector<float> positions;  // x y z per vertex.
  std::vector<float> uvs;        // u v per vertex, or empty.
  std::vector<uint16_t> indices;
  std::string material = R"({"name": "paint"})";
  std::string nodes = R"([{"name": "part", "mesh": 0}])";
  std::string images;    // JSON array, or empty.
  std::string textures;  // JSON array, or empty.

  std::string Buffer() const {
    std::string bytes(reinterpret_cast<const char*>(positions.data()), 4 * positions.size());
    bytes.append(reinterpret_cast<const char*>(uvs.data()), 4 * uvs.size());
    bytes.append(reinterpret_cast<const char*>(indices.data()), 2 * indices.size());
    while (bytes.size() % 4 != 0) bytes.push_back('\0');
    return bytes;
  }

  // The JSON; `buffer_uri` empty: the buffer inline, base64.
  std::string Json(const std::string& buffer_uri = "", int64_t glb_buffer = -1) const {
    const std::string bytes = Buffer();
    const size_t n = positions.size() / 3;
    float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
    for (size_t v = 0; v < n; ++v) {
      for (int c = 0; c < 3; ++c) {
        lo[c] = std::min(lo[c], positions[3 * v + c]);
        hi[c] = std::max(hi[c], positions[3 * v + c]);
      }
    }
    std::string buffer;
    if (glb_buffer >= 0) {
      buffer = absl::StrCat(R"({"byteLength": )", glb_buffer, "}");
    } else {
      const std::string uri =
          buffer_uri.empty() ? "data:application/octet-stream;base64," + absl::Base64Escape(bytes)
                             : buffer_uri;
      buffer = absl::StrCat(R"({"byteLength": )", bytes.size(), R"(, "uri": ")", uri, R"("})");
    }
    const size_t uv_offset = 4 * positions.size();
    const size_t index_offset = uv_offset + 4 * uvs.size();
    std::string views = absl::StrCat(R"([{"buffer": 0, "byteOffset": 0, "byteLength": )",
                                     4 * positions.size(), "}");
    std::string accessors =
        absl::StrCat(R"([{"bufferView": 0, "componentType": 5126, "count": )", n,
                     R"(, "type": "VEC3", "min": [)", lo[0], ",", lo[1], ",", lo[2],
                     "], \"max\": [", hi[0], ",", hi[1], ",", hi[2], "]}");
    std::string attributes = R"({"POSITION": 0)";
    int next = 1;
    if (!uvs.empty()) {
      absl::StrAppend(&views, R"(, {"buffer": 0, "byteOffset": )", uv_offset, R"(, "byteLength": )",
                      4 * uvs.size(), "}");
      absl::StrAppend(&accessors, R"(, {"bufferView": 1, "componentType": 5126, "count": )", n,
                      R"(, "type": "VEC2"})");
      absl::StrAppend(&attributes, R"(, "TEXCOORD_0": 1)");
      next = 2;
    }
    absl::StrAppend(&views, R"(, {"buffer": 0, "byteOffset": )", index_offset,
                    R"(, "byteLength": )", 2 * indices.size(), "}]");
    absl::StrAppend(&accessors, R"(, {"bufferView": )", next,
                    R"(, "componentType": 5123, "count": )", indices.size(),
                    R"(, "type": "SCALAR"}])");
    attributes += "}";
    std::string json = absl::StrCat(
        R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": )", nodes,
        R"(, "meshes": [{"name": "shape", "primitives": [{"attributes": )", attributes,
        R"(, "indices": )", next, R"(, "material": 0}]}], "materials": [)", material,
        R"(], "buffers": [)", buffer, R"(], "bufferViews": )", views, R"(, "accessors": )",
        accessors);
    if (!images.empty()) absl::StrAppend(&json, R"(, "images": )", images);
    if (!textures.empty()) absl::StrAppend(&json, R"(, "textures": )", textures);
    json += R"(, "extensionsUsed": ["KHR_materials_emissive_strength",)"
            R"( "KHR_materials_transmission"]})";
    return json;
  }

  // A binary glTF (.glb): the JSON chunk and the buffer (with `extra` appended, e.g. an image
  // the JSON points into with a buffer view).
  std::string Glb(const std::string& json, const std::string& bin) const {
    std::string j = json;
    while (j.size() % 4 != 0) j.push_back(' ');
    std::string b = bin;
    while (b.size() % 4 != 0) b.push_back('\0');
    std::string out = "glTF";
    auto u32 = [&out](uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
    u32(2);
    u32(static_cast<uint32_t>(12 + 8 + j.size() + 8 + b.size()));
    u32(static_cast<uint32_t>(j.size()));
    out += "JSON";
    out += j;
    u32(static_cast<uint32_t>(b.size()));
    out += std::string("BIN\0", 4);
    out += b;
    return out;
  }
};

// Two triangles making the unit square in z = 0, counter-clockwise seen from +z.
Gltf UnitSquare() {
  Gltf g;
  g.positions = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0};
  g.indices = {0, 1, 2, 0, 2, 3};
  return g;
}

double TotalArea(const Scene& scene) {
  double area = 0;
  for (const Face& f : scene.faces) area += PolygonArea(scene, f);
  return area;
}

// The geometric normal of a face (right-hand rule about its vertex order), unit length.
Vec3 FaceNormal(const Scene& scene, const Face& f) {
  const Vec3& a = scene.vertices[f.vertices[0]];
  return Normalize(Cross(scene.vertices[f.vertices[1]] - a, scene.vertices[f.vertices[2]] - a));
}

void ExpectRgbNear(const Rgb& actual, const Rgb& expected, double tolerance) {
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(actual[c], expected[c], tolerance) << "channel " << c;
}

TEST(ModelLoaderTest, GltfNodeTransformsAndMaterialsAsTheSpecificationDefinesThem) {
  TempDir dir;
  Gltf g = UnitSquare();
  g.material = R"({"name": "paint", "doubleSided": true,
      "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.4, 0.2, 1]},
      "emissiveFactor": [1, 0.5, 0.25],
      "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}}})";
  // The parent scales by (2, 3, 1) and moves by (10, 0, 0); the child turns 90 degrees about z.
  g.nodes = R"([{"name": "parent", "children": [1], "scale": [2, 3, 1],
                 "translation": [10, 0, 0]},
                {"name": "part", "mesh": 0, "rotation": [0, 0, 0.70710678, 0.70710678]}])";
  std::vector<std::string> warnings;
  ASSERT_OK_AND_ASSIGN(Scene scene, LoadModel(dir.Write("m.gltf", g.Json()), &warnings));
  ASSERT_THAT(scene.surfaces, SizeIs(1));
  EXPECT_EQ(scene.surfaces[0].name, "part/shape");
  ASSERT_THAT(scene.faces, SizeIs(2));
  // Rotated, the square spans x in [-1, 0] and y in [0, 1]; scaled, x in [-2, 0], y in [0, 3].
  EXPECT_NEAR(TotalArea(scene), 6, 1e-6);
  for (const Vec3& v : scene.vertices) {
    EXPECT_GE(v.x, 8 - 1e-6);
    EXPECT_LE(v.x, 10 + 1e-6);
    EXPECT_GE(v.y, -1e-6);
    EXPECT_LE(v.y, 3 + 1e-6);
  }
  for (const Face& f : scene.faces) EXPECT_NEAR(FaceNormal(scene, f).z, 1, 1e-9);
  const Material& m = scene.materials[scene.surfaces[0].material];
  EXPECT_EQ(m.name, "paint");
  ExpectRgbNear(m.reflectance, Rgb(0.8, 0.4, 0.2), 1e-6);
  ExpectRgbNear(m.emission, Rgb(4, 2, 1), 1e-6);
  EXPECT_TRUE(m.two_sided);
  EXPECT_FALSE(m.Transmits());
  EXPECT_THAT(warnings, ::testing::IsEmpty());
}

TEST(ModelLoaderTest, MirroringTransformKeepsTheFrontOnItsSide) {
  // Mirrored in x, the square's triangles turn clockwise about +z; its front must stay +z, as the
  // glTF specification requires (a negative determinant reverses the winding).
  TempDir dir;
  Gltf g = UnitSquare();
  g.nodes = R"([{"name": "part", "mesh": 0, "scale": [-1, 1, 1]}])";
  ASSERT_OK_AND_ASSIGN(Scene scene, LoadModel(dir.Write("m.gltf", g.Json()), nullptr));
  ASSERT_THAT(scene.faces, SizeIs(2));
  for (const Face& f : scene.faces) EXPECT_NEAR(FaceNormal(scene, f).z, 1, 1e-9);
  EXPECT_NEAR(TotalArea(scene), 1, 1e-9);
}

TEST(ModelLoaderTest, TransmissionAndClampedBaseColour) {
  TempDir dir;
  Gltf g = UnitSquare();
  g.material = R"({"name": "glass",
      "pbrMetallicRoughness": {"baseColorFactor": [1, 0.5, 0.5, 1], "metallicFactor": 0},
      "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.25},
                     "KHR_materials_ior": {"ior": 1.33}}})";
  std::vector<std::string> warnings;
  ASSERT_OK_AND_ASSIGN(Scene scene, LoadModel(dir.Write("m.gltf", g.Json()), &warnings));
  const Material& m = scene.materials[scene.surfaces[0].material];
  // Base colour 1 is clamped to kMaxReflectance; t = 0.25 of it meets thin glass (README
  // "Specular and glossy surfaces"), the rest is reflected diffusely.
  ExpectRgbNear(m.reflectance, Rgb(0.75 * kMaxReflectance, 0.375, 0.375), 1e-6);
  ExpectRgbNear(m.glass, Rgb(0.25 * kMaxReflectance, 0.125, 0.125), 1e-6);
  ExpectRgbNear(m.transmittance, Rgb(), 0);
  EXPECT_FALSE(m.refracts);
  EXPECT_EQ(m.ior, 1.33);
  ASSERT_THAT(warnings, SizeIs(1));
  EXPECT_THAT(warnings[0], HasSubstr("material 'glass': base colour at or above 1 clamped"));
}

// docs/guide/specular.md: metallic-roughness. A smooth metal is a glossy lobe of
// exponent 2 / roughness^4 - 2, a very smooth one a mirror; glTF's defaults (metallic 1,
// roughness 1) a rough metal, reflecting diffusely.
TEST(ModelLoaderTest, MetallicRoughnessMakesGlossyLobesAndMirrors) {
  struct Case {
    const char* pbr;
    Rgb diffuse, glossy, mirror;
    double exponent;
  };
  const Case cases[] = {
      {R"("baseColorFactor": [0.8, 0.6, 0.4, 1], "metallicFactor": 1, "roughnessFactor": 0.5)",
       Rgb(), Rgb(0.8, 0.6, 0.4), Rgb(), 2 / std::pow(0.5, 4) - 2},
      {R"("baseColorFactor": [0.8, 0.6, 0.4, 1], "metallicFactor": 0.5, "roughnessFactor": 0.01)",
       Rgb(0.4, 0.3, 0.2), Rgb(), Rgb(0.4, 0.3, 0.2), 0},
      {R"("baseColorFactor": [0.8, 0.6, 0.4, 1])", Rgb(0.8, 0.6, 0.4), Rgb(), Rgb(), 0},
  };
  for (const Case& c : cases) {
    TempDir dir;
    Gltf g = UnitSquare();
    g.material = absl::StrCat(R"({"name": "metal", "pbrMetallicRoughness": {)", c.pbr, "}}");
    std::vector<std::string> warnings;
    ASSERT_OK_AND_ASSIGN(Scene scene, LoadModel(dir.Write("m.gltf", g.Json()), &warnings));
    const Material& m = scene.materials[scene.surfaces[0].material];
    ExpectRgbNear(m.reflectance, c.diffuse, 1e-6);
    ExpectRgbNear(m.glossy, c.glossy, 1e-6);
    ExpectRgbNear(m.mirror, c.mirror, 1e-6);
    EXPECT_NEAR(m.glossy_exponent, c.exponent, 1e-3) << c.pbr;
    EXPECT_OK(ValidateScene(scene));
  }
}

// Writes a `width` x 1 PNG of sRGB byte colours `texels` (r g b per texel).
std::string WritePng(const std::string& path, int width, const std::vector<uint8_t>& texels) {
  std::unique_ptr<OIIO::ImageOutput> out = OIIO::ImageOutput::create(path);
  EXPECT_NE(out, nullptr);
  OIIO::ImageSpec spec(width, 1, 3, OIIO::TypeDesc::UINT8);
  EXPECT_TRUE(out->open(path, spec));
  EXPECT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, texels.data()));
  out->close();
  return path;
}

// A texture of two texels, red and mid green (sRGB 128, linear 0.2158605); the square's first
// triangle maps inside the red texel, its second inside the green one.
Gltf TexturedSquare() {
  Gltf g = UnitSquare();
  // Separate vertices per triangle so each triangle has its own UVs.
  g.positions = {0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 0, 0, 1, 1, 0, 0, 1, 0};
  g.uvs = {0.1f, 0.2f, 0.4f, 0.2f, 0.4f, 0.8f, 0.6f, 0.2f, 0.9f, 0.8f, 0.6f, 0.8f};
  g.indices = {0, 1, 2, 3, 4, 5};
  g.material = R"({"name": "print", "pbrMetallicRoughness": {
      "baseColorFactor": [0.5, 0.5, 0.5, 1], "baseColorTexture": {"index": 0}}})";
  g.textures = R"([{"source": 0}])";
  return g;
}

void ExpectTwoTexelColours(const Scene& scene) {
  ASSERT_THAT(scene.surfaces, SizeIs(2));
  std::vector<Rgb> colours;
  for (const Surface& s : scene.surfaces) {
    colours.push_back(scene.materials[s.material].reflectance);
    EXPECT_TRUE(absl::StartsWith(s.name, "part/shape#")) << s.name;
  }
  std::sort(colours.begin(), colours.end(), [](const Rgb& a, const Rgb& b) { return a.r < b.r; });
  // Factor 0.5 times the linear texel, rounded to kTextureColorStep.
  ExpectRgbNear(colours[0], Rgb(0, 0.5 * 0.2158605, 0), kTextureColorStep / 2 + 1e-9);
  ExpectRgbNear(colours[1], Rgb(0.5, 0, 0), kTextureColorStep / 2 + 1e-9);
}

TEST(ModelLoaderTest, TextureIsAveragedOverEachFaceFromAFile) {
  TempDir dir;
  WritePng(dir.File("tex.png"), 2, {255, 0, 0, 0, 128, 0});
  Gltf g = TexturedSquare();
  g.images = R"([{"uri": "tex.png"}])";
  const std::string path = dir.Write("m.gltf", g.Json());
  ASSERT_OK_AND_ASSIGN(Scene scene, LoadModel(path, nullptr));
  ExpectTwoTexelColours(scene);
  ASSERT_OK_AND_ASSIGN(std::vector<std::string> deps, ModelDependencies(path));
  EXPECT_EQ(deps, std::vector<std::string>({"tex.png"}));
}

TEST(ModelLoaderTest, TextureIsAveragedOverEachFaceFromABinaryGltf) {
  TempDir dir;
  const std::string png =
      ReadWholeFile(WritePng(dir.File("tex.png"), 2, {255, 0, 0, 0, 128, 0})).value();
  Gltf g = TexturedSquare();
  const std::string buffer = g.Buffer();
  std::string json = g.Json("", static_cast<int64_t>(buffer.size() + png.size()));
  // The image is a buffer view after the geometry.
  json.insert(json.rfind(']', json.find("\"accessors\"")),
              absl::StrCat(R"(, {"buffer": 0, "byteOffset": )", buffer.size(),
                           R"(, "byteLength": )", png.size(), "}"));
  const int image_view = g.uvs.empty() ? 2 : 3;
  json.insert(json.size() - 1, absl::StrCat(R"(, "images": [{"bufferView": )", image_view,
                                            R"(, "mimeType": "image/png"}])"));
  std::filesystem::remove(dir.File("tex.png"));
  ASSERT_OK_AND_ASSIGN(Scene scene,
                       LoadModel(dir.Write("m.glb", g.Glb(json, buffer + png)), nullptr));
  ExpectTwoTexelColours(scene);
}

TEST(ModelLoaderTest, MissingTextureLeavesTheFactorWithAWarning) {
  TempDir dir;
  Gltf g = TexturedSquare();
  g.images = R"([{"uri": "gone.png"}])";
  std::vector<std::string> warnings;
  const std::string path = dir.Write("m.gltf", g.Json());
  ASSERT_OK_AND_ASSIGN(Scene scene, LoadModel(path, &warnings));
  ASSERT_THAT(scene.surfaces, SizeIs(1));
  ExpectRgbNear(scene.materials[scene.surfaces[0].material].reflectance, Rgb::Gray(0.5), 1e-6);
  ASSERT_THAT(warnings, SizeIs(1));
  EXPECT_THAT(warnings[0], AllOf(HasSubstr(path), HasSubstr("texture 'gone.png' left out")));
}

TEST(ModelLoaderTest, VertexColoursAreReflectanceOnRequest) {
  // ASCII PLY: two triangles, one red-ish, one blue-ish (vertex colours averaged per face).
  const std::string path = testing::SourcePath("tests/data/vertex_colours.ply");
  ModelOptions options;
  options.vertex_colors = true;
  ASSERT_OK_AND_ASSIGN(Scene coloured, LoadModel(path, nullptr, options));
  ASSERT_THAT(coloured.surfaces, SizeIs(2));
  std::vector<Rgb> colours;
  for (const Surface& s : coloured.surfaces) {
    colours.push_back(coloured.materials[s.material].reflectance);
  }
  std::sort(colours.begin(), colours.end(), [](const Rgb& a, const Rgb& b) { return a.r < b.r; });
  ExpectRgbNear(colours[0], Rgb(0, 0, 0.2), kTextureColorStep / 2 + 1e-9);
  ExpectRgbNear(colours[1], Rgb((0.8 + 0.8 + 0.4) / 3, 0, 0), kTextureColorStep / 2 + 1e-9);
  ASSERT_OK_AND_ASSIGN(Scene plain, LoadModel(path, nullptr));
  EXPECT_THAT(plain.surfaces, SizeIs(1));
}

// A closed cube of glTF triangles facing inwards, every wall emitting E and reflecting rho: the
// furnace, whose radiosity is E / (1 - rho) everywhere.
TEST(ModelLoaderTest, GltfFurnaceSolvesToItsClosedForm) {
  TempDir dir;
  Gltf g;
  g.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1};
  // Two triangles per wall, wound so that their fronts face the inside (corner bits x, y, z).
  g.indices = {0, 3, 2, 0, 1, 3, 4, 7, 5, 4, 6, 7, 0, 5, 1, 0, 4, 5,
               2, 7, 6, 2, 3, 7, 0, 6, 4, 0, 2, 6, 1, 7, 3, 1, 5, 7};
  g.material = R"({"name": "wall", "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]},
      "emissiveFactor": [1, 1, 1]})";
  ASSERT_OK_AND_ASSIGN(Scene scene, LoadModel(dir.Write("furnace.gltf", g.Json()), nullptr));
  ASSERT_THAT(scene.faces, SizeIs(12));
  for (const Face& f : scene.faces) {
    // Fronts face the cube's centre.
    const Vec3& a = scene.vertices[f.vertices[0]];
    EXPECT_GT(Dot(FaceNormal(scene, f), Vec3(0.5, 0.5, 0.5) - a), 0);
  }
  ASSERT_OK_AND_ASSIGN(testing::SolvedWorld solved, MeshAndSolve(scene, 0.1, SolveOptions()));
  // Triangles are meshed in their parameter square, so small pieces lie along each diagonal and
  // carry more noise than a quad's elements: every element is held to its own standard error,
  // the whole to its area-weighted mean and RMS.
  const Mesh& mesh = *solved.world->mesh;
  const Solution& solution = solved.run.solution;
  ASSERT_EQ(solution.std_error.size(), solution.radiosity.size());
  double area = 0, mean = 0, squares = 0;
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    const int slot = Slot(static_cast<int>(e), kFront);
    const double b = solution.radiosity[slot].r, se = solution.std_error[slot].r;
    EXPECT_LT(std::abs(b - 2), 4.5 * se + 1e-3) << "element " << e;
    area += mesh.elements()[e].area;
    mean += mesh.elements()[e].area * b;
    squares += (b / 2 - 1) * (b / 2 - 1);
  }
  EXPECT_NEAR(mean / area, 2, 2 * 0.002);
  EXPECT_LT(std::sqrt(squares / static_cast<double>(mesh.elements().size())), 0.015);
}

TEST(ModelLoaderTest, ConfinedReaderOpensNothingOutsideTheModelsDirectory) {
  TempDir dir;
  std::filesystem::create_directory(dir.File("inside"));
  Gltf g = UnitSquare();
  dir.Write("outside.bin", g.Buffer());
  const std::string path = dir.Write("inside/m.gltf", g.Json("../outside.bin"));
  ModelOptions confined;
  confined.confine_to_directory = true;
  EXPECT_TRUE(Refused(LoadModel(path, nullptr, confined), absl::StatusCode::kInvalidArgument,
                      {path, "outside.bin"}));
  EXPECT_OK(LoadModel(path, nullptr));  // Unconfined (the CLI's own files), it is read.
  // Its dependencies name only files inside the directory.
  ASSERT_OK_AND_ASSIGN(std::vector<std::string> deps, ModelDependencies(path));
  EXPECT_THAT(deps, ::testing::IsEmpty());
}

TEST(ModelLoaderTest, StoppedReadIsCancelled) {
  TempDir dir;
  std::atomic<bool> stop{true};
  StopToken token(&stop, 0);
  ModelOptions options;
  options.stop = &token;
  EXPECT_EQ(LoadModel(dir.Write("m.gltf", UnitSquare().Json()), nullptr, options).status().code(),
            absl::StatusCode::kCancelled);
}

TEST(ModelLoaderTest, GarbageIsRefusedWithTheFileNamed) {
  TempDir dir;
  for (const char* name : {"a.gltf", "a.glb", "a.fbx", "a.dae", "a.3ds", "a.ply", "a.stl"}) {
    const std::string path = dir.Write(name, std::string("\x01\x02garbage\xff", 10));
    absl::StatusOr<Scene> scene = LoadSceneFile(path, nullptr);
    ASSERT_FALSE(scene.ok()) << name;
    EXPECT_THAT(std::string(scene.status().message()), HasSubstr(path)) << name;
  }
}

// The importer in a child process (ModelOptions::importer, radiosity-import beside this test):
// the same scene as in process; a file that hangs assimp (found by fuzz_model) is refused at the
// wall-clock limit, and a stop kills it at once; a crash is an error naming the file.
ModelOptions InChild() {
  ModelOptions options;
  options.importer = ModelImporter();
  options.confine_to_directory = true;
  return options;
}

TEST(ModelImportTest, ChildReadsTheSameSceneAndWarnings) {
  ASSERT_FALSE(ModelImporter().empty()) << "radiosity-import is not beside the test binary";
  TempDir dir;
  Gltf g = TexturedSquare();
  g.images = R"([{"uri": "gone.png"}])";
  const std::string path = dir.Write("m.gltf", g.Json());
  std::vector<std::string> here_warnings, child_warnings;
  ASSERT_OK_AND_ASSIGN(Scene here, LoadModel(path, &here_warnings));
  ASSERT_OK_AND_ASSIGN(Scene child, LoadModel(path, &child_warnings, InChild()));
  EXPECT_EQ(child.ToString(), here.ToString());
  EXPECT_EQ(child.vertices, here.vertices);
  EXPECT_EQ(child_warnings, here_warnings);
  // Errors keep their code and message.
  const std::string bad = dir.Write("bad.gltf", "{\"asset\": 7}");
  absl::Status here_error = LoadModel(bad, nullptr).status();
  absl::Status child_error = LoadModel(bad, nullptr, InChild()).status();
  EXPECT_EQ(child_error, here_error);
  EXPECT_THAT(std::string(child_error.message()), HasSubstr(bad));
}

TEST(ModelImportTest, HangingImporterIsStoppedAtItsLimitOrOnStop) {
  const std::string path = testing::SourcePath("tests/data/hostile/hangs_assimp.ply");
  ModelOptions options = InChild();
  options.import_seconds = 1;
  absl::StatusOr<Scene> scene = LoadModel(path, nullptr, options);
  EXPECT_TRUE(Refused(scene, absl::StatusCode::kInvalidArgument, {path, "took longer than 1 s"}));

  std::atomic<bool> stop{false};
  StopToken token(&stop, 0);
  options.import_seconds = 600;
  options.stop = &token;
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    stop = true;
  });
  scene = LoadModel(path, nullptr, options);
  stopper.join();
  EXPECT_EQ(scene.status().code(), absl::StatusCode::kCancelled) << scene.status();
}

TEST(ModelImportTest, CrashingImporterIsAnErrorNamingTheFile) {
  TempDir dir;
  const std::string crash = dir.Write("crash.sh", "#!/bin/sh\nkill -SEGV $$\n");
  std::filesystem::permissions(crash, std::filesystem::perms::owner_all);
  ModelOptions options = InChild();
  options.importer = crash;
  const std::string path = dir.Write("m.gltf", UnitSquare().Json());
  EXPECT_TRUE(Refused(LoadModel(path, nullptr, options), absl::StatusCode::kInvalidArgument,
                      {path, "died of signal 11"}));
}

// Every model of the formats read through assimp in Debian's assimp-testmodels loads, or is
// refused with a message that names the file and the problem; none crashes or hangs.
TEST(ModelLoaderTest, EveryAssimpTestModelLoadsOrNamesItsProblem) {
  const std::string root = "/usr/share/assimp/models";
  if (!FileExists(root + "/glTF2/BoxTextured-glTF/BoxTextured.gltf")) {
    GTEST_SKIP() << root << " is absent: install the Debian package assimp-testmodels";
  }
  // The refusals that are right: broken files, files without polygons, non-finite coordinates.
  const std::map<std::string, std::string> refused = {
      {"Collada/cube_UTF16LE.dae", "malformed XML"},
      {"Collada/library_animation_clips.dae", "as a real number"},
      {"FBX/transparentTest.fbx", "block offset is out of range"},
      {"PLY/issue623.ply", "no polygons"},
      {"PLY/points.ply", "no polygons"},
      {"PLY/pond.0.ply", "no polygons"},
      {"glTF2/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb", "NaN or infinite coordinate"},
      {"glTF2/IndexOutOfRange/AllIndicesOutOfRange.gltf", "has no faces"},
      {"glTF2/MissingBin/BoxTextured.gltf", "could not open referenced file"},
      {"glTF2/RecursiveNodes/RecursiveNodes.gltf", "recursive ref"},
      {"glTF2/SchemaFailures/sceneWrongType.gltf", "was not of type"},
      {"glTF2/TestNoRootNode/NoScene.gltf", "No scene"},
      {"glTF2/TestNoRootNode/SceneWithoutNodes.gltf", "no meshes"},
      {"glTF2/issue_3269/texcoord_crash.gltf", "Invalid attribute"},
      {"glTF2/wrongTypes/badArray.gltf", "was not of type"},
      {"glTF2/wrongTypes/badExtension.gltf", "was not of type"},
      {"glTF2/wrongTypes/badNumber.gltf", "was not of type"},
      {"glTF2/wrongTypes/badObject.gltf", "was not of type"},
      {"glTF2/wrongTypes/badString.gltf", "was not of type"},
      {"glTF2/wrongTypes/badUint.gltf", "was not of type"},
  };
  int loaded = 0, models = 0;
  for (const std::string folder : {"glTF2", "FBX", "Collada", "3DS", "PLY", "STL"}) {
    for (const auto& entry : std::filesystem::recursive_directory_iterator(root + "/" + folder)) {
      const std::string path = entry.path().string();
      if (!IsModelExtension(Extension(path))) continue;
      const std::string key = path.substr(root.size() + 1);
      ++models;
      std::vector<std::string> warnings;
      absl::StatusOr<Scene> scene = LoadSceneFile(path, &warnings);
      auto it = refused.find(key);
      // The glTF asset generator's primitive-mode files of points and lines only.
      bool lines_only = false;
      for (const char* mode : {"00", "01", "02", "03", "07", "08", "09", "10"}) {
        lines_only |= absl::EndsWith(key, absl::StrCat("Mesh_PrimitiveMode_", mode, ".gltf"));
      }
      if (it == refused.end() && !lines_only) {
        EXPECT_TRUE(scene.ok()) << key << ": " << scene.status();
        if (scene.ok()) ++loaded;
        for (const std::string& w : warnings) EXPECT_TRUE(absl::StartsWith(w, path)) << w;
      } else {
        ASSERT_FALSE(scene.ok()) << key;
        EXPECT_THAT(std::string(scene.status().message()),
                    AllOf(HasSubstr(path), HasSubstr(lines_only ? "no polygons" : it->second)));
      }
    }
  }
  EXPECT_GE(models, 115);
  EXPECT_GE(loaded, 87);  // Of 115 files, 28 rightly refused.
}

}  // namespace
}  // namespace radiosity
