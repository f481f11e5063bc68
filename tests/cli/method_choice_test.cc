// The default method, "auto" (ChooseMethod): hierarchical radiosity on bright scenes of few
// polygons, progressive refinement elsewhere. The albedo it decides on is checked against sums done
// here by hand, the decision against its documented thresholds, and what the chosen method
// returns against the furnace's closed form B = E / (1 - rho) (Shirley, eq. 6.2 with
// sum_j F_ij = 1), through the library and through the CLI.
#include "solver/methods/method_choice.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <string>

#include "proto/api/exit_codes.h"
#include "solver/geometry/mesh.h"
#include "solver/input/scene_files.h"
#include "solver/methods/solver.h"
#include "solver/transport/visibility.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using testing::ReadFile;
using testing::SourcePath;

using testing::BuildMesh;

TEST(MethodChoiceTest, MeanAlbedoIsTheAreaWeightedLargestChannel) {
  // A 2 x 1 x 1 box: the two 1 x 1 ends (x0, x1) have area 1 each, the four sides area 2 each.
  Scene s = testing::MakeClosedBox(2, 1, 1, {"side", Rgb(0.8, 0.6, 0.2), Rgb(), Rgb(), false, 0});
  s.materials.push_back({"end", Rgb(0.2, 0.9, 0.1), Rgb::Gray(1), Rgb(), false, 0});
  for (Surface& surface : s.surfaces) {
    if (surface.name == "x0" || surface.name == "x1") surface.material = 1;
  }
  ASSERT_OK_AND_ASSIGN(const Mesh mesh, BuildMesh(s, 0.25));
  // Per channel: (8 x side + 2 x end) / 10; red 0.68, green 0.66, blue 0.18.
  EXPECT_NEAR(MeanAlbedo(mesh), (8 * 0.8 + 2 * 0.2) / 10, 1e-12);
}

TEST(MethodChoiceTest, TransmissionAndTwoSidedBacksCount) {
  // A closed unit box (R = 0.5, area 6) with a two-sided transmitting panel inside (R = 0.3,
  // T = 0.6, area 0.25, both sides exist): the panel's sides count twice, with R + T each.
  Scene s =
      testing::MakeClosedBox(1, 1, 1, {"wall", Rgb::Gray(0.5), Rgb::Gray(1), Rgb(), false, 0});
  s.materials.push_back({"panel", Rgb::Gray(0.3), Rgb(), Rgb::Gray(0.6), true, 0});
  testing::AddRect(&s, "panel", 1, {0.25, 0.25, 0.5}, {0.5, 0, 0}, {0, 0.5, 0});
  ASSERT_OK_AND_ASSIGN(const Mesh mesh, BuildMesh(s, 0.25));
  EXPECT_NEAR(MeanAlbedo(mesh), (6 * 0.5 + 2 * 0.25 * 0.9) / (6 + 2 * 0.25), 1e-12);
}

TEST(MethodChoiceTest, BrightFewPolygonScenesGetHierarchicalOthersProgressive) {
  const Material bright{"wall", Rgb::Gray(0.95), Rgb::Gray(1), Rgb(), false, 0};
  Scene furnace = testing::MakeClosedBox(1, 1, 1, bright);
  ASSERT_OK_AND_ASSIGN(const Mesh furnace_mesh, BuildMesh(furnace, 0.25));
  MethodChoice c = ChooseMethod(furnace_mesh);
  EXPECT_EQ(c.method, "hierarchical") << c.ToString();
  EXPECT_NE(c.reason.find("6 faces"), std::string::npos) << c.reason;

  // Just below the albedo threshold.
  Scene dim = testing::MakeClosedBox(
      1, 1, 1, {"wall", Rgb::Gray(kAutoMinAlbedo - 0.01), Rgb::Gray(1), Rgb(), false, 0});
  ASSERT_OK_AND_ASSIGN(const Mesh dim_mesh, BuildMesh(dim, 0.25));
  c = ChooseMethod(dim_mesh);
  EXPECT_EQ(c.method, "progressive") << c.ToString();
  EXPECT_NE(c.reason.find("mean albedo"), std::string::npos) << c.reason;

  // Bright but of more faces than the cap: the furnace plus small floating tiles.
  Scene cluttered = furnace;
  for (int i = 0; i <= kAutoMaxFaces; ++i) {
    const double x = 0.05 + 0.9 * (i % 15) / 15, y = 0.05 + 0.9 * (i / 15) / 15.0;
    testing::AddRect(&cluttered, "tiles", 0, {x, y, 0.5}, {0.02, 0, 0}, {0, 0.02, 0});
  }
  ASSERT_OK_AND_ASSIGN(const Mesh cluttered_mesh, BuildMesh(cluttered, 0.25));
  ASSERT_GT(static_cast<int64_t>(cluttered_mesh.faces().size()), kAutoMaxFaces);
  c = ChooseMethod(cluttered_mesh);
  EXPECT_EQ(c.method, "progressive") << c.ToString();
  EXPECT_NE(c.reason.find("faces"), std::string::npos) << c.reason;

  // The Cornell box as published is not bright (white 0.7 at most).
  auto cornell = LoadSceneFile(SourcePath("scenes/cornell_box.obj"), nullptr);
  ASSERT_TRUE(cornell.ok()) << cornell.status();
  MeshOptions mo;
  mo.max_elements = 200;
  auto cornell_mesh = Mesh::Build(*cornell, mo);
  ASSERT_TRUE(cornell_mesh.ok());
  c = ChooseMethod(*cornell_mesh);
  EXPECT_EQ(c.method, "progressive") << c.ToString();
  EXPECT_LT(c.mean_albedo, 0.8);
}

TEST(MethodChoiceTest, AutoSolvesABrightFurnaceToItsClosedForm) {
  const double rho = 0.95;
  Scene s =
      testing::MakeClosedBox(1, 1, 1, {"wall", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), false, 0});
  ASSERT_OK_AND_ASSIGN(const Mesh mesh, BuildMesh(s, 0.25));
  auto vis = Visibility::Build(mesh);
  ASSERT_TRUE(vis.ok()) << vis.status();
  SolveOptions opt;
  opt.method = "auto";
  auto solver = CreateSolver(s, mesh, **vis, opt, nullptr);
  ASSERT_TRUE(solver.ok()) << solver.status();
  auto reason = RunSolver(**solver, opt, nullptr, nullptr);
  ASSERT_TRUE(reason.ok()) << reason.status();
  EXPECT_EQ(*reason, StopReason::kConverged);
  const Solution sol = (*solver)->Final();
  EXPECT_EQ(sol.method, "hierarchical");
  const double expected = 1 / (1 - rho);
  for (size_t e = 0; e < mesh.elements().size(); ++e) {
    EXPECT_NEAR(sol.radiosity[2 * e].Luminance(), expected, 0.01 * expected) << "element " << e;
  }
}

// Through the CLI, with no --method: the bright furnace runs hierarchical (said on the progress
// line and in summary.json) and every element meets the closed form; the Cornell box runs
// progressive.
TEST(MethodChoiceTest, TheCliDefaultIsAutoAndSaysWhatItChose) {
  testing::TempDir dir;
  std::string scene = ReadFile(SourcePath("scenes/furnace.json"));
  for (size_t at = 0; (at = scene.find("0.5", at)) != std::string::npos;) {
    scene.replace(at, 3, "0.95");
    at += 4;
  }
  ASSERT_NE(scene.find("\"r\": 0.95"), std::string::npos);
  const std::string path = dir.Write("bright.json", scene);
  auto r = testing::RunSolve(path, dir.File("out"),
                             {"--element-size", "0.25", "--width", "16", "--height", "16"});
  ASSERT_EQ(r.exit_code, kExitOk) << r.output;
  EXPECT_NE(r.output.find("method hierarchical (auto: mean albedo 0.95 >= 0.9"), std::string::npos)
      << r.output;
  const std::string summary = ReadFile(dir.File("out/summary.json"));
  EXPECT_NE(summary.find("\"method\": \"hierarchical\""), std::string::npos) << summary;
  EXPECT_NE(summary.find("\"method_requested\": \"auto\""), std::string::npos) << summary;
  auto csv = testing::ReadCsv(dir.File("out/elements.csv"));
  ASSERT_EQ(csv.rows.size(), 96u);
  for (const auto& row : csv.rows) {
    for (int c = 6; c < 9; ++c) EXPECT_NEAR(std::stod(row[c]), 20, 0.2) << row[0] << " " << row[1];
  }

  auto cornell = testing::RunSolve(
      SourcePath("scenes/cornell_box.obj"), dir.File("cornell"),
      {"--max-elements", "200", "--rays-per-element", "100", "--width", "16", "--height", "16"});
  ASSERT_EQ(cornell.exit_code, kExitOk) << cornell.output;
  EXPECT_NE(ReadFile(dir.File("cornell/summary.json")).find("\"method\": \"progressive\""),
            std::string::npos);
}

}  // namespace
}  // namespace radiosity
