// The scene validation rules seen through the CLI: `radiosity solve <scene>` must refuse bad input
// with exit code kExitInput and an error naming the file and the problem.
#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "absl/strings/numbers.h"
#include "absl/strings/str_split.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "proto/api/exit_codes.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using ::radiosity::testing::CommandResult;
using ::radiosity::testing::RunSolve;
using ::radiosity::testing::TempDir;
using ::testing::AllOf;
using ::testing::HasSubstr;

// Materials shared by the cases; every scene that gets past the loader has an emitter, so the only
// thing wrong with each is the rule under test.
constexpr char kMtl[] = R"(newmtl white
Kd 0.5 0.5 0.5
newmtl lamp
Kd 0.2 0.2 0.2
Ke 1 1 1
)";

// A valid scene (a lit triangle facing a white one) up to the face lines.
constexpr char kVertices[] = R"(mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 0 1
v 0 1 1
v 1 1 1
)";

struct BadScene {
  std::string name;  // Test name.
  std::string obj;   // scene.obj
  std::string mtl;   // scene.mtl
  // Which file the message must name ("scene.obj" or "scene.mtl") and what else it must say.
  std::string file;
  std::vector<std::string> words;
};

std::vector<BadScene> BadScenes() {
  const std::string v = kVertices;
  const std::string faces = "g lamp\nusemtl lamp\nf 1 2 3\ng wall\nusemtl white\nf 4 5 6\n";
  return {
      {"NanCoordinate",
       v + "v 1 nan 0\n" + faces,
       kMtl,
       "scene.obj:8:",
       {"NaN or infinite coordinate"}},
      {"InfiniteCoordinate",
       v + "v inf 0 0\n" + faces,
       kMtl,
       "scene.obj:8:",
       {"NaN or infinite coordinate"}},
      {"VertexIndexOutOfRange",
       v + "usemtl lamp\nf 1 2 99\n",
       kMtl,
       "scene.obj:9:",
       {"vertex index 99 is out of range", "6 vertices"}},
      {"ReflectanceOfOne",
       v + "usemtl white\nf 1 2 3\nusemtl lamp\nf 4 5 6\n",
       "newmtl white\nKd 1 1 1\nnewmtl lamp\nKe 1 1 1\n",
       "scene.mtl:2:",
       {"'white'", "reflectance (Kd)", "outside [0, 1)"}},
      {"NegativeReflectance",
       v + "usemtl white\nf 1 2 3\nusemtl lamp\nf 4 5 6\n",
       "newmtl white\nKd 0.5 -0.5 0.5\nnewmtl lamp\nKe 1 1 1\n",
       "scene.mtl:2:",
       {"'white'", "reflectance (Kd)", "outside [0, 1)"}},
      {"DissolveAboveOne",
       v + "usemtl lamp\nf 1 2 3\nusemtl glass\nf 4 5 6\n",
       std::string(kMtl) + "newmtl glass\nKd 0.7 0.7 0.7\nd 2\n",
       "scene.mtl:8:",
       {"'glass'", "'d 2' is outside [0, 1]"}},
      {"NegativeEmission",
       v + "usemtl lamp\nf 1 2 3\n",
       "newmtl lamp\nKd 0.5\nKe -1 1 1\n",
       "scene.mtl:3:",
       {"'lamp'", "negative emission (Ke)"}},
      {"UnknownMaterial",
       v + "usemtl lamp\nf 1 2 3\nusemtl chrome\nf 4 5 6\n",
       kMtl,
       "scene.obj:10:",
       {"unknown material 'chrome'", "white, lamp"}},
      {"FaceWithoutMaterial",
       v + "f 1 2 3\n",
       kMtl,
       "scene.obj:8:",
       {"no material (usemtl) for face"}},
      {"FaceWithTwoVertices",
       v + "usemtl lamp\nf 1 2\n",
       kMtl,
       "scene.obj:9:",
       {"face has 2 vertices"}},
      {"NoFaces", v + "usemtl lamp\n", kMtl, "scene.obj", {"no faces"}},
      {"MissingMaterialLibrary",
       "mtllib other.mtl\n" + v.substr(v.find('\n') + 1) + faces,
       kMtl,
       "scene.obj:1:",
       {"other.mtl", "No such file or directory"}},
      {"BinaryFile",
       std::string("v 0 0 0\n\0\0\x7f", 11),
       kMtl,
       "scene.obj",
       {"looks binary", "NUL byte at offset 8"}},
  };
}

class CliRuleTest : public ::testing::TestWithParam<BadScene> {};

TEST_P(CliRuleTest, ExitsWithInputErrorNamingFileAndProblem) {
  const BadScene& bad = GetParam();
  TempDir dir;
  dir.Write("scene.mtl", bad.mtl);
  std::string obj = dir.Write("scene.obj", bad.obj);
  // --strict: what exporters commonly write (no usemtl, unknown names, missing libraries,
  // Kd >= 1) is refused too, as it is mended without it (below).
  CommandResult result = RunSolve(obj, dir.File("out"), {"--strict"});
  EXPECT_EQ(result.exit_code, kExitInput) << result.output;
  EXPECT_THAT(result.output, HasSubstr("radiosity: error:"));
  EXPECT_THAT(result.output, HasSubstr(dir.File(bad.file)));
  for (const std::string& word : bad.words) EXPECT_THAT(result.output, HasSubstr(word));
}

INSTANTIATE_TEST_SUITE_P(Rules, CliRuleTest, ::testing::ValuesIn(BadScenes()),
                         [](const ::testing::TestParamInfo<BadScene>& param_info) {
                           return param_info.param.name;
                         });

TEST(CliValidationTest, WithoutStrictExportersHabitsAreMendedWithWarnings) {
  // A face without usemtl, an unknown material and Kd 1: the solve runs, and each is a warning
  // naming the file and line.
  TempDir dir;
  dir.Write("scene.mtl", std::string(kMtl) + "newmtl paper\nKd 1 1 1\n");
  std::string obj = dir.Write(
      "scene.obj",
      std::string(kVertices) +
          "f 4 5 6\nusemtl lamp\nf 1 2 3\nusemtl chrome\nf 4 6 5\nusemtl paper\nf 4 5 6\n");
  CommandResult result = RunSolve(obj, dir.File("out"), {"--max-elements", "50"});
  EXPECT_EQ(result.exit_code, 0) << result.output;
  EXPECT_THAT(
      result.output,
      AllOf(HasSubstr("radiosity: warning: " + dir.File("scene.obj") +
                      ":8: no material (usemtl): 1 face takes the default material"),
            HasSubstr(dir.File("scene.obj") + ":12: unknown material 'chrome'"),
            HasSubstr(dir.File("scene.mtl") + ":7: material 'paper': Kd (1, 1, 1) clamped")));
  EXPECT_FALSE(::radiosity::testing::ReadFile(dir.File("out/elements.csv")).empty());
}

TEST(CliValidationTest, SceneWithoutEmitterIsAnInputErrorNamingEmit) {
  TempDir dir;
  dir.Write("scene.mtl", kMtl);
  std::string obj =
      dir.Write("scene.obj", std::string(kVertices) + "usemtl white\nf 1 2 3\nf 4 5 6\n");
  CommandResult result = RunSolve(obj, dir.File("out"), {});
  EXPECT_EQ(result.exit_code, kExitInput) << result.output;
  EXPECT_THAT(result.output, AllOf(HasSubstr("radiosity: error:"), HasSubstr("no emitter"),
                                   HasSubstr("--emit NAME=R,G,B")));
  // --emit lights it: the face that emits reports its power in the summary (exitance x area).
  result = RunSolve(obj, dir.File("out"), {"--emit", "white=2,2,2", "--max-elements", "50"});
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_THAT(::radiosity::testing::ReadFile(dir.File("out/summary.json")),
              HasSubstr("\"emitted_power\": [2, 2, 2]"));
  // A name that is neither a material nor a surface, and a malformed value, are refused.
  result = RunSolve(obj, dir.File("out"), {"--emit", "lamp=1"});
  EXPECT_EQ(result.exit_code, kExitUsage) << result.output;
  EXPECT_THAT(result.output, HasSubstr("no material or surface is named 'lamp'"));
  result = RunSolve(obj, dir.File("out"), {"--emit", "white=bright"});
  EXPECT_EQ(result.exit_code, kExitUsage) << result.output;
  EXPECT_THAT(result.output, HasSubstr("--emit 'white=bright'"));
  // So does a sky (the message names it too); auto then runs progressive refinement.
  EXPECT_THAT(RunSolve(obj, dir.File("out"), {}).output, HasSubstr("--sky uniform=E"));
  result = RunSolve(obj, dir.File("out"),
                    {"--sky", "overcast=100", "--sky-up", "0,0,1", "--max-elements", "50"});
  ASSERT_EQ(result.exit_code, 0) << result.output;
  const std::string summary = ::radiosity::testing::ReadFile(dir.File("out/summary.json"));
  EXPECT_THAT(summary, HasSubstr("\"method\": \"progressive\""));
  EXPECT_THAT(summary, HasSubstr("--sky"));
  for (const char* bad : {"overcast", "cloudy=3", "uniform=-1"}) {
    result = RunSolve(obj, dir.File("out"), {"--sky", bad});
    EXPECT_EQ(result.exit_code, kExitUsage) << bad << ": " << result.output;
    EXPECT_THAT(result.output, HasSubstr("--sky")) << bad;
  }
  result = RunSolve(obj, dir.File("out"), {"--sky", "uniform=1", "--method", "jacobi"});
  EXPECT_EQ(result.exit_code, kExitUsage) << result.output;
  EXPECT_THAT(result.output,
              HasSubstr("--sky: light from outside applies to --method progressive"));
}

// A model without emitters lit by a luminaire from a photometric file elsewhere on disk: the file
// is uploaded with the scene (OBJ or native), and sensors read I cos^3(theta) / h^2 in lux.
TEST(CliValidationTest, LuminairesLightAModelWithoutEmitters) {
  TempDir dir;
  dir.Write("floor.mtl", "newmtl white\nKd 0.5 0.5 0.5\n");
  const std::string obj =
      dir.Write("floor.obj",
                "mtllib floor.mtl\nv -5 0 -5\nv -5 0 5\nv 5 0 5\nv 5 0 -5\nusemtl white\n"
                "f 1 2 3 4\n");
  const std::string json =
      dir.Write("floor.json",
                R"({"materials": [{"name": "white", "reflectance": {"r": 0.5, "g": 0.5, "b": 0.5}}],
          "surfaces": [{"name": "floor", "material": "white",
                        "vertices": [-5, 0, -5, -5, 0, 5, 5, 0, 5, 5, 0, -5],
                        "faces": [{"indices": [0, 1, 2, 3]}]}]})");
  std::filesystem::create_directories(dir.File("lamps"));
  dir.Write("lamps/iso.ies",
            "IESNA:LM-63-2002\n[TEST] isotropic\nTILT=NONE\n1 -1 1 2 1 1 2 0 0 0\n1 1 0\n0 180\n"
            "0\n1000 1000\n");
  dir.Write("lamps/bad.ies",
            "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 2 1 1 2 0 0 0\n1 1 0\n0 180\n0\n1000 x\n");
  const std::string sensors = dir.Write("s.txt", "0 0 0 0 1 0\n2 0 1 0 1 0\n-3 0 4 0 1 0\n");
  for (const std::string& scene : {obj, json}) {
    SCOPED_TRACE(scene);
    CommandResult result = RunSolve(scene, dir.File("out"),
                                    {"--luminaire", dir.File("lamps/iso.ies") + " at=0,3,0",
                                     "--sensors", sensors, "--max-elements", "400"});
    ASSERT_EQ(result.exit_code, 0) << result.output;
    EXPECT_THAT(result.output, HasSubstr("--luminaire"));  // auto: why progressive.
    const std::string csv = ::radiosity::testing::ReadFile(dir.File("out/sensors.csv"));
    std::vector<std::string> rows = absl::StrSplit(csv, '\n', absl::SkipEmpty());
    ASSERT_EQ(rows.size(), 4u) << csv;
    for (int i = 1; i <= 3; ++i) {
      std::vector<std::string> cells = absl::StrSplit(rows[i], ',');
      double x, z, e;
      ASSERT_TRUE(absl::SimpleAtod(cells[0], &x) && absl::SimpleAtod(cells[2], &z) &&
                  absl::SimpleAtod(cells[7], &e))
          << rows[i];
      const double d = std::sqrt(9 + x * x + z * z);
      EXPECT_NEAR(e, 1000 * 3 / (d * d * d), 1e-6 * e) << rows[i];
    }
  }
  // A bad file is named with its line before anything is uploaded; so are bad placements.
  CommandResult result =
      RunSolve(obj, dir.File("out"), {"--luminaire", dir.File("lamps/bad.ies") + " at=0,3,0"});
  EXPECT_EQ(result.exit_code, kExitInput) << result.output;
  EXPECT_THAT(result.output, HasSubstr("bad.ies:7: 'x' is not a number"));
  result = RunSolve(obj, dir.File("out"), {"--luminaire", dir.File("lamps/iso.ies")});
  EXPECT_EQ(result.exit_code, kExitUsage) << result.output;
  EXPECT_THAT(result.output, HasSubstr("no position at=X,Y,Z"));
  result = RunSolve(obj, dir.File("out"),
                    {"--luminaire", dir.File("lamps/iso.ies") + " at=0,3,0 aim=0,0,0"});
  EXPECT_EQ(result.exit_code, kExitUsage) << result.output;
  EXPECT_THAT(result.output, HasSubstr("aim (0, 0, 0) is not a direction"));
  result = RunSolve(obj, dir.File("out"),
                    {"--luminaire", dir.File("lamps/iso.ies") + " at=0,3,0", "--method", "jacobi"});
  EXPECT_EQ(result.exit_code, kExitUsage) << result.output;
  EXPECT_THAT(result.output,
              HasSubstr("--luminaire: luminaires shoot first in --method progressive"));
}

TEST(CliValidationTest, MissingSceneFileIsAnInputError) {
  TempDir dir;
  CommandResult result = RunSolve(dir.File("absent.obj"), dir.File("out"), {});
  EXPECT_EQ(result.exit_code, kExitInput) << result.output;
  EXPECT_THAT(result.output,
              AllOf(HasSubstr(dir.File("absent.obj")), HasSubstr("No such file or directory")));
}

TEST(CliValidationTest, SolveWithoutSceneIsAUsageError) {
  CommandResult result = ::radiosity::testing::RunCli({"solve"});
  EXPECT_EQ(result.exit_code, kExitUsage) << result.output;
}

}  // namespace
}  // namespace radiosity
