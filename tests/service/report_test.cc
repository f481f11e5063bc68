// `radiosity report` (client/report.h): sensor statistics against hand-computed values and, end
// to end, against a closed form (inside a closed furnace of reflectance 0.5 emitting 1, every
// point's irradiance is B = 1 / (1 - 0.5) = 2 whatever its direction: min = mean = max = 2,
// U0 = 1); the convergence plot's points and tolerance line; the page's books and tables.
#include "client/report.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <regex>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "nlohmann/json.hpp"
#include "proto/api/exit_codes.h"
#include "proto/api/spec.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using client::SensorGridStats;

TEST(ReportTest, SensorStatisticsPerGrid) {
  // Grey irradiance, so Y(E) = E; two grids.
  const std::string csv =
      "x,y,z,nx,ny,nz,r,g,b,se_r,se_g,se_b,grid\n"
      "0,0,0,0,0,1,100,100,100,1,1,1,desk\n"
      "1,0,0,0,0,1,300,300,300,1,1,1,desk\n"
      "2,0,0,0,0,1,200,200,200,1,1,1,desk\n"
      "0,0,0,0,0,1,50,50,50,1,1,1,floor\n";
  ASSERT_OK_AND_ASSIGN(std::vector<SensorGridStats> grids, client::SensorStatsFromCsv(csv));
  ASSERT_EQ(grids.size(), 2u);
  EXPECT_EQ(grids[0].name, "desk");
  EXPECT_EQ(grids[0].points, 3);
  EXPECT_DOUBLE_EQ(grids[0].min, 100);
  EXPECT_DOUBLE_EQ(grids[0].mean, 200);
  EXPECT_DOUBLE_EQ(grids[0].max, 300);
  EXPECT_DOUBLE_EQ(grids[0].u0, 0.5);
  EXPECT_DOUBLE_EQ(grids[0].min_max, 100.0 / 300);
  EXPECT_EQ(grids[1].name, "floor");
  EXPECT_DOUBLE_EQ(grids[1].u0, 1);
  // Without a grid column every point is in "all"; colour weighs by luminance (Rec. 709 Y).
  ASSERT_OK_AND_ASSIGN(grids, client::SensorStatsFromCsv("x,y,z,nx,ny,nz,r,g,b\n"
                                                         "0,0,0,0,0,1,1,0,0\n"));
  ASSERT_EQ(grids.size(), 1u);
  EXPECT_EQ(grids[0].name, "all");
  EXPECT_NEAR(grids[0].mean, 0.2126, 1e-4);
  absl::Status bad =
      client::SensorStatsFromCsv("x,y,z,nx,ny,nz,r,g,b\n0,0,0,0,0,1,1,x,0\n").status();
  EXPECT_EQ(bad.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.message().find("sensors.csv:2"), std::string::npos) << bad;
}

TEST(ReportTest, ConvergencePlotHasEveryPointAndTheTolerance) {
  const std::string svg = client::ConvergenceSvg({0, 1, 2, 4}, {1, 0.1, 0.01, 0.0005}, 1e-3);
  std::smatch m;
  ASSERT_TRUE(
      std::regex_search(svg, m, std::regex("class=\"convergence\"[^>]*points=\"([^\"]*)\"")))
      << svg;
  const std::string points = m[1];
  EXPECT_EQ(std::count(points.begin(), points.end(), ','), 4) << points;
  EXPECT_NE(svg.find("class=\"tolerance\""), std::string::npos);
  // Four decades and a bit: labels from 1e-4 to 1e0.
  EXPECT_NE(svg.find(">1e-4<"), std::string::npos) << svg;
  EXPECT_NE(svg.find(">1e0<"), std::string::npos) << svg;
  EXPECT_EQ(client::ConvergenceSvg({}, {}, 0).find("polyline"), std::string::npos);
  // The estimated error where it was measured (0: not measured), on the same log scale.
  const std::string both =
      client::ConvergenceSvg({0, 1, 2, 4}, {1, 0.1, 0.01, 0.0005}, 1e-3, {0, 0.05, 0, 2e-5});
  ASSERT_TRUE(std::regex_search(both, m, std::regex("class=\"error\"[^>]*points=\"([^\"]*)\"")))
      << both;
  const std::string error_points = m[1];
  EXPECT_EQ(std::count(error_points.begin(), error_points.end(), ','), 2) << error_points;
  EXPECT_NE(both.find(">1e-5<"), std::string::npos) << both;  // The scale reaches 2e-5.
  EXPECT_EQ(svg.find("class=\"error\""), std::string::npos);  // None measured: no line.
}

TEST(ReportTest, GridNamesOnTheWireAreCheckedByField) {
  v1::SolveSpec spec;
  for (const char* grid : {"", "desk-1", "a,b"}) {
    v1::SensorPoint* p = spec.add_sensors();
    p->mutable_normal()->set_z(1);
    p->set_grid(grid);
  }
  absl::Status refused = service::ToJobSpec(spec).status();
  EXPECT_EQ(refused.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.message().find("solve.sensors[2].grid: grid name 'a,b'"), std::string::npos)
      << refused;
  spec.mutable_sensors()->RemoveLast();
  ASSERT_OK_AND_ASSIGN(JobSpec parsed, service::ToJobSpec(spec));
  ASSERT_EQ(parsed.sensors.size(), 2u);
  EXPECT_EQ(parsed.sensors[0].grid, "");
  EXPECT_EQ(parsed.sensors[1].grid, "desk-1");
  EXPECT_EQ(service::ToSolveSpec(parsed, 1).sensors(1).grid(), "desk-1");
}

class ReportCliTest : public service::testing::ServiceTest {
 protected:
  // `radiosity --json report` of the newest job into `out`: its JSON line.
  void ReportNewestJob(const std::string& out, nlohmann::json* line) {
    auto listed = testing::RunCli({"--server", address(), "jobs"});
    std::smatch m;
    ASSERT_TRUE(std::regex_search(listed.output, m, std::regex("jobs/[0-9a-f]+"))) << listed.output;
    auto report = testing::RunCli({"--server", address(), "--json", "report", m[0], "--out", out});
    ASSERT_EQ(report.exit_code, kExitOk) << report.output;
    for (const std::string& l : std::vector<std::string>(absl::StrSplit(report.output, '\n'))) {
      if (!l.empty() && l[0] == '{') *line = nlohmann::json::parse(l, nullptr, false);
    }
    ASSERT_TRUE(line->contains("sensor_grids")) << report.output;
  }
};

TEST_F(ReportCliTest, FurnaceSensorsReadTheClosedForm) {
  testing::TempDir dir;
  const std::string sensors = dir.Write("sensors.txt",
                                        "# inside the unit furnace, facing every way\n"
                                        "# grid: up\n"
                                        "0.5 0.5 0.5 0 0 1\n0.2 0.3 0.4 0 0 1\n"
                                        "# grid: other\n"
                                        "0.5 0.5 0.5 0 0 -1\n0.8 0.7 0.1 0 1 0\n"
                                        "0.1 0.1 0.1 1 1 1\n");
  auto solved = testing::RunCli(
      {"--server", address(), "solve", testing::SourcePath("scenes/furnace.json"), "--max-elements",
       "600", "--sensors", sensors, "--out", dir.File("solve"), "--width", "32", "--height", "32"});
  ASSERT_EQ(solved.exit_code, kExitOk) << solved.output;
  nlohmann::json line;
  ASSERT_NO_FATAL_FAILURE(ReportNewestJob(dir.File("report"), &line));
  ASSERT_EQ(line["sensor_grids"].size(), 2u) << line.dump();
  EXPECT_EQ(line["sensor_grids"][0]["grid"], "up");
  EXPECT_EQ(line["sensor_grids"][0]["points"].get<int>(), 2);
  EXPECT_EQ(line["sensor_grids"][1]["grid"], "other");
  EXPECT_EQ(line["sensor_grids"][1]["points"].get<int>(), 3);
  for (const auto& grid : line["sensor_grids"]) {
    EXPECT_NEAR(grid["mean"].get<double>(), 2.0, 0.02);
    EXPECT_NEAR(grid["min"].get<double>(), 2.0, 0.03);
    EXPECT_NEAR(grid["max"].get<double>(), 2.0, 0.03);
    EXPECT_NEAR(grid["u0"].get<double>(), 1.0, 0.02);
  }

  const std::string html = testing::ReadFile(dir.File("report/report.html"));
  EXPECT_NE(html.find("<img src=\"image.png\""), std::string::npos);
  EXPECT_EQ(testing::ReadFile(dir.File("report/image.png")).substr(1, 3), "PNG");
  EXPECT_NE(html.find("class=\"convergence\""), std::string::npos);
  EXPECT_NE(html.find("<table id=\"books\">"), std::string::npos);
  EXPECT_NE(html.find("<table id=\"sensors\">"), std::string::npos);
  // The books show the summary's emitted power (6 faces of area 1 emitting 1: 6 W a channel).
  EXPECT_NE(html.find("<td>emitted</td><td>6</td><td>6</td><td>6</td>"), std::string::npos) << html;

  // A job that is not a solve, or not there, is refused.
  auto missing =
      testing::RunCli({"--server", address(), "report", "jobs/000000000000", "--out", dir.path()});
  EXPECT_EQ(missing.exit_code, kExitServer) << missing.output;
}

// Lighting engineers' numbers in lux: a grid of desk points under a 1000 cd isotropic luminaire
// 3 m above them, whose minimum, mean, maximum and uniformity the report gives as the closed form
// E = I cos^3(theta) / h^2 at each point does.
TEST_F(ReportCliTest, LuminaireGridStatisticsAreInLuxAndReadTheClosedForm) {
  testing::TempDir dir;
  dir.Write("floor.json",
            R"({"materials": [{"name": "grey", "reflectance": {"r": 0.5, "g": 0.5, "b": 0.5}}],
                "surfaces": [{"name": "floor", "material": "grey",
                              "vertices": [-5, 0, -5, -5, 0, 5, 5, 0, 5, 5, 0, -5],
                              "faces": [{"indices": [0, 1, 2, 3]}]}]})");
  dir.Write("lamp.ies",
            "IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 2 1 1 2 0 0 0\n1 1 0\n0 180\n0\n1000 1000\n");
  std::string points = "# grid: desk\n";
  std::vector<double> expected;
  for (int i = 0; i < 4; ++i) {
    for (int k = 0; k < 3; ++k) {
      const double x = 0.5 * i, z = 0.7 * k - 0.7, d2 = 9 + x * x + z * z;
      absl::StrAppend(&points, x, " 0 ", z, " 0 1 0\n");
      expected.push_back(1000 * 3 / (d2 * std::sqrt(d2)));
    }
  }
  const std::string sensors = dir.Write("desk.txt", points);
  auto solved =
      testing::RunCli({"--server", address(), "solve", dir.File("floor.json"), "--luminaire",
                       dir.File("lamp.ies") + " at=0,3,0", "--sensors", sensors, "--max-elements",
                       "400", "--out", dir.File("solve"), "--width", "32", "--height", "32"});
  ASSERT_EQ(solved.exit_code, kExitOk) << solved.output;
  nlohmann::json line;
  ASSERT_NO_FATAL_FAILURE(ReportNewestJob(dir.File("report"), &line));
  const auto& grid = line["sensor_grids"][0];
  const double lo = *std::min_element(expected.begin(), expected.end());
  const double hi = *std::max_element(expected.begin(), expected.end());
  double mean = 0;
  for (double e : expected) mean += e / expected.size();
  EXPECT_NEAR(grid["min"].get<double>(), lo, 1e-6 * lo);
  EXPECT_NEAR(grid["max"].get<double>(), hi, 1e-6 * hi);
  EXPECT_NEAR(grid["mean"].get<double>(), mean, 1e-6 * mean);
  EXPECT_NEAR(grid["u0"].get<double>(), lo / mean, 1e-6);
  const std::string html = testing::ReadFile(dir.File("report/report.html"));
  EXPECT_NE(html.find("Illuminance in lux"), std::string::npos) << html;
  const std::string summary = testing::ReadFile(dir.File("solve/summary.json"));
  EXPECT_NE(summary.find("\"luminaires\": [{\"file\": \"lamp.ies\""), std::string::npos) << summary;
}

}  // namespace
}  // namespace radiosity
