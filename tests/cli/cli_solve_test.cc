// `radiosity solve` end to end: the files it writes, their contracts, and determinism.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "proto/api/exit_codes.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using testing::ReadFile;
using testing::RunSolve;
using testing::TempDir;

std::string CornellBox() { return testing::SourcePath("scenes/cornell_box.obj"); }

// Solves the Cornell box into `dir` with `flags`; the solve must succeed.
void SolveCornellBox(const TempDir& dir, const std::vector<std::string>& flags) {
  testing::CommandResult r = RunSolve(CornellBox(), dir.path(), flags);
  ASSERT_EQ(r.exit_code, kExitOk) << r.output;
}

TEST(CliSolveTest, WritesEveryOutputWithItsContract) {
  TempDir dir;
  ASSERT_NO_FATAL_FAILURE(SolveCornellBox(dir, {"--max-elements", "600", "--rays-per-element",
                                                "200", "--width", "64", "--height", "64"}));
  auto csv = testing::ReadCsv(dir.File("elements.csv"));
  const std::vector<std::string> header = {"surface", "element", "cx", "cy", "cz",
                                           "area",    "r",       "g",  "b"};
  EXPECT_EQ(csv.header, header);
  ASSERT_GT(csv.rows.size(), 100u);
  ASSERT_LE(csv.rows.size(), 600u);
  // Areas sum to the scene's area: the box's surfaces and blocks (published dimensions, mm^2).
  double area = 0, light_b = 0;
  for (const auto& row : csv.rows) {
    area += std::stod(row[5]);
    if (row[0] == "light") light_b = std::stod(row[6]);
  }
  EXPECT_GT(area, 5 * 550.0 * 550.0);
  EXPECT_LT(area, 5 * 560.0 * 560.0 + 2 * 170.0 * 170.0 * 5 + 300000);
  // The light's radiosity is at least its emission Ke (53.407 in red).
  EXPECT_GE(light_b, 53.407);
  std::string summary = ReadFile(dir.File("summary.json"));
  for (const char* key :
       {"\"elements\"", "\"patches\"", "\"rays\"", "\"seconds\"", "\"unshot_fraction\"",
        "\"emitted_power\"", "\"absorbed_power\"", "\"escaped_power\"", "\"seed\"", "\"method\""}) {
    EXPECT_NE(summary.find(key), std::string::npos) << key << " missing from " << summary;
  }
  EXPECT_EQ(ReadFile(dir.File("mesh.ply")).rfind("ply\nformat ascii 1.0\n", 0), 0u);
  EXPECT_GT(std::filesystem::file_size(dir.File("image.exr")), 1000u);
  EXPECT_EQ(ReadFile(dir.File("image.png")).substr(1, 3), "PNG");
  EXPECT_FALSE(std::filesystem::exists(dir.File("elements_back.csv")));
}

TEST(CliSolveTest, ErrorsAndSensorsFilesKeepTheirContracts) {
  // elements_error.csv: header exactly "surface,element,r,g,b", the rows of elements.csv in the
  // same order, positive finite standard errors; sensors.csv: the nine columns it always had,
  // then se_r, se_g, se_b; summary.json: the errors' RMS.
  TempDir dir;
  const std::string sensors = dir.File("points.txt");
  {
    std::ofstream out(sensors);
    out << "278 0.1 280 0 1 0\n100 200 300 1 0 0\n";
  }
  ASSERT_NO_FATAL_FAILURE(
      SolveCornellBox(dir, {"--max-elements", "600", "--rays-per-element", "200", "--width", "16",
                            "--height", "16", "--sensors", sensors, "--sensor-samples", "256"}));
  const auto elements = testing::ReadCsv(dir.File("elements.csv"));
  const auto errors = testing::ReadCsv(dir.File("elements_error.csv"));
  EXPECT_EQ(errors.header, (std::vector<std::string>{"surface", "element", "r", "g", "b"}));
  ASSERT_EQ(errors.rows.size(), elements.rows.size());
  int positive = 0;
  for (size_t i = 0; i < errors.rows.size(); ++i) {
    EXPECT_EQ(errors.rows[i][0], elements.rows[i][0]) << i;
    EXPECT_EQ(errors.rows[i][1], elements.rows[i][1]) << i;
    const double se = std::stod(errors.rows[i][3]);
    EXPECT_TRUE(std::isfinite(se) && se >= 0) << i;
    positive += se > 0;
  }
  EXPECT_GT(positive, static_cast<int>(errors.rows.size()) / 2);
  const auto sensed = testing::ReadCsv(dir.File("sensors.csv"));
  EXPECT_EQ(sensed.header, (std::vector<std::string>{"x", "y", "z", "nx", "ny", "nz", "r", "g", "b",
                                                     "se_r", "se_g", "se_b"}));
  ASSERT_EQ(sensed.rows.size(), 2u);
  // The floor point under the light: lit, with an error far below its value.
  EXPECT_GT(std::stod(sensed.rows[0][6]), 0);
  EXPECT_LT(std::stod(sensed.rows[0][9]), 0.05 * std::stod(sensed.rows[0][6]));
  const std::string summary = ReadFile(dir.File("summary.json"));
  EXPECT_NE(summary.find("\"std_error_rms\": ["), std::string::npos) << summary;
  EXPECT_NE(summary.find("\"std_error_rms_relative\": 0."), std::string::npos) << summary;
}

TEST(CliSolveTest, SameSeedSameElementsWhateverTheThreadCount) {
  TempDir one, two;
  const std::vector<std::string> common = {
      "--max-elements", "800", "--rays-per-element", "300", "--seed", "7",
      "--width",        "16",  "--height",           "16"};
  auto a = common, b = common;
  a.insert(a.end(), {"--threads", "1"});
  b.insert(b.end(), {"--threads", "2"});
  ASSERT_NO_FATAL_FAILURE(SolveCornellBox(one, a));
  ASSERT_NO_FATAL_FAILURE(SolveCornellBox(two, b));
  std::string ea = ReadFile(one.File("elements.csv")), eb = ReadFile(two.File("elements.csv"));
  ASSERT_FALSE(ea.empty());
  EXPECT_EQ(ea, eb);
}

TEST(CliSolveTest, StopsOnTheRayBudget) {
  // The budget exceeds the direct step's shadow rays (traced first, and counted): the shooting
  // that follows stops exactly at it.
  TempDir dir;
  ASSERT_NO_FATAL_FAILURE(
      SolveCornellBox(dir, {"--max-elements", "500", "--max-rays", "200000", "--tolerance", "1e-9",
                            "--width", "16", "--height", "16"}));
  std::string summary = ReadFile(dir.File("summary.json"));
  EXPECT_NE(summary.find("\"rays\": 200000,"), std::string::npos) << summary;
  EXPECT_NE(summary.find("\"stop_reason\": \"max_rays\""), std::string::npos) << summary;
}

// Hierarchical radiosity reports its links and their memory (issue 7); the links of a closed
// scene stay far below the N^2 pairs of the full matrix (Hanrahan et al. 1991, sec. 4).
TEST(CliSolveTest, HierarchicalSummaryReportsLinksAndMemory) {
  TempDir dir;
  ASSERT_NO_FATAL_FAILURE(SolveCornellBox(dir, {"--method", "hierarchical", "--max-elements",
                                                "1000", "--width", "16", "--height", "16"}));
  std::string summary = ReadFile(dir.File("summary.json"));
  auto number = [&](const std::string& key) -> double {
    size_t at = summary.find("\"" + key + "\": ");
    if (at == std::string::npos) return -1;
    return std::stod(summary.substr(at + key.size() + 4));
  };
  const double elements = number("elements"), links = number("links");
  const double bytes = number("link_memory_bytes");
  ASSERT_GT(elements, 100) << summary;
  EXPECT_GT(links, elements) << summary;  // Every element gathers over at least one link.
  EXPECT_LT(links, 0.5 * elements * elements) << summary;
  EXPECT_GT(bytes, links * 8) << summary;  // A link holds at least its source and form factor.
}

TEST(CliSolveTest, BadOptionsAreUsageErrors) {
  TempDir dir;
  for (auto extra : std::vector<std::vector<std::string>>{{"--tolerance", "2"},
                                                          {"--element-size", "-1"},
                                                          {"--bogus"},
                                                          {"--element-size", "1e-9"}}) {
    auto r = RunSolve(CornellBox(), dir.path(), extra);
    EXPECT_EQ(r.exit_code, kExitUsage) << extra[0] << ": " << r.output;
  }
}

}  // namespace
}  // namespace radiosity
