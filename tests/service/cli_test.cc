// The `radiosity` CLI against a real server on 127.0.0.1 (`--server`, before or after the command):
// solve, upload, jobs --json, watch with previews, get, render, cancel, viewfactor, and the exit
// codes of bad input and of an unreachable server.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "google/protobuf/util/json_util.h"
#include "proto/api/exit_codes.h"
#include "radiosity/v1/service.pb.h"
#include "server/server.h"
#include "solver/results/false_color.h"
#include "tests/service/fixture.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using testing::ReadCsv;
using testing::ReadFile;
using testing::RunCli;
using testing::SourcePath;
using testing::TempDir;

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  for (absl::string_view l : absl::StrSplit(text, '\n', absl::SkipEmpty())) lines.emplace_back(l);
  return lines;
}

// Width and height from a PNG's IHDR chunk.
std::pair<int, int> PngSize(const std::string& png) {
  if (png.size() < 24 || png.substr(1, 3) != "PNG") return {0, 0};
  auto be32 = [&](size_t at) {
    return (static_cast<unsigned char>(png[at]) << 24) |
           (static_cast<unsigned char>(png[at + 1]) << 16) |
           (static_cast<unsigned char>(png[at + 2]) << 8) | static_cast<unsigned char>(png[at + 3]);
  };
  return {static_cast<int>(be32(16)), static_cast<int>(be32(20))};
}

class ServiceCliTest : public service::testing::ServiceTest {
 protected:
  void SetUp() override {
    ASSERT_NO_FATAL_FAILURE(ServiceTest::SetUp());
    address_ = address();
  }
  // Only the stdout lines that are JSON objects (stderr is merged by RunCli).
  static std::vector<v1::Job> JobLines(const std::string& output) {
    std::vector<v1::Job> jobs;
    for (const std::string& line : Lines(output)) {
      if (line.empty() || line[0] != '{') continue;
      v1::Job job;
      if (google::protobuf::util::JsonStringToMessage(line, &job).ok() && !job.name().empty()) {
        jobs.push_back(job);
      }
    }
    return jobs;
  }

  std::string address_;
};

TEST_F(ServiceCliTest, SolveWatchGetRenderAndListThroughTheServer) {
  TempDir a, b, local;
  const std::vector<std::string> common = {SourcePath("scenes/cornell_box.obj"),
                                           "--max-elements",
                                           "500",
                                           "--rays-per-element",
                                           "300",
                                           "--seed",
                                           "3",
                                           "--width",
                                           "24",
                                           "--height",
                                           "16",
                                           "--threads",
                                           "1"};
  std::vector<std::string> before = {"--server", address_, "solve"};
  before.insert(before.end(), common.begin(), common.end());
  before.insert(before.end(), {"--out", a.path()});
  std::vector<std::string> after = {"solve"};
  after.insert(after.end(), common.begin(), common.end());
  after.insert(after.end(), {"--out", b.path(), "--server", address_});
  std::vector<std::string> embedded = {"solve"};
  embedded.insert(embedded.end(), common.begin(), common.end());
  embedded.insert(embedded.end(), {"--out", local.path()});
  auto r1 = RunCli(before);
  ASSERT_EQ(r1.exit_code, kExitOk) << r1.output;
  EXPECT_NE(r1.output.find("converged after"), std::string::npos) << r1.output;
  auto r2 = RunCli(after);
  ASSERT_EQ(r2.exit_code, kExitOk) << r2.output;
  auto r3 = RunCli(embedded);
  ASSERT_EQ(r3.exit_code, kExitOk) << r3.output;
  const std::string csv = ReadFile(a.File("elements.csv"));
  ASSERT_FALSE(csv.empty());
  EXPECT_EQ(csv, ReadFile(b.File("elements.csv")));
  EXPECT_EQ(csv, ReadFile(local.File("elements.csv")));
  EXPECT_EQ(
      ReadCsv(a.File("elements.csv")).header,
      (std::vector<std::string>{"surface", "element", "cx", "cy", "cz", "area", "r", "g", "b"}));
  for (const char* f : {"summary.json", "mesh.ply", "image.exr", "image.png"}) {
    EXPECT_TRUE(std::filesystem::exists(a.File(f))) << f;
  }

  // Both remote solves are jobs on the server; the scene was uploaded once.
  auto listed = RunCli({"--server", address_, "--json", "jobs"});
  ASSERT_EQ(listed.exit_code, kExitOk) << listed.output;
  std::vector<v1::Job> jobs = JobLines(listed.output);
  ASSERT_EQ(jobs.size(), 2u) << listed.output;
  EXPECT_EQ(jobs[0].scene(), jobs[1].scene());
  EXPECT_EQ(jobs[0].state(), v1::JOB_STATE_SUCCEEDED);
  const std::string job = jobs[0].name();

  // watch (ended job: its final snapshot) with previews, get, render.
  TempDir previews, got, picture;
  auto watched = RunCli({"watch", job, "--server", address_, "--preview-dir", previews.path(),
                         "--preview-width", "20", "--preview-height", "10"});
  ASSERT_EQ(watched.exit_code, kExitOk) << watched.output;
  int pngs = 0;
  for (const auto& entry : std::filesystem::directory_iterator(previews.path())) {
    if (entry.path().extension() == ".png") {
      ++pngs;
      EXPECT_EQ(PngSize(ReadFile(entry.path().string())), std::make_pair(20, 10));
    }
  }
  EXPECT_EQ(pngs, 1);
  auto fetched = RunCli({"--server", address_, "get", job, "--out", got.path()});
  ASSERT_EQ(fetched.exit_code, kExitOk) << fetched.output;
  EXPECT_EQ(ReadFile(got.File("elements.csv")), csv);
  auto rendered =
      RunCli({"--server", address_, "render", job, "--out", picture.File("side.png"), "--camera",
              "eye=278,273,-300 fov=60", "--width", "32", "--height", "24"});
  ASSERT_EQ(rendered.exit_code, kExitOk) << rendered.output;
  EXPECT_EQ(PngSize(ReadFile(picture.File("side.png"))), std::make_pair(32, 24));
  // In false colour: the legend to the right; a range that is not MIN < MAX is a usage error.
  auto false_color =
      RunCli({"--server", address_, "render", job, "--out", picture.File("false.png"),
              "--false-color", "0:40", "--width", "32", "--height", "24"});
  ASSERT_EQ(false_color.exit_code, kExitOk) << false_color.output;
  EXPECT_EQ(PngSize(ReadFile(picture.File("false.png"))),
            std::make_pair(32 + FalseColorLegendWidth(24), 24));
  auto bad_range = RunCli({"--server", address_, "render", job, "--out", picture.File("bad.png"),
                           "--false-color", "40:0"});
  EXPECT_EQ(bad_range.exit_code, kExitUsage) << bad_range.output;
  EXPECT_NE(bad_range.output.find("--false-color '40:0': MIN must be below MAX"), std::string::npos)
      << bad_range.output;

  // Cancelling an ended job is refused by the server: exit code 4.
  auto cancelled = RunCli({"--server", address_, "cancel", job});
  EXPECT_EQ(cancelled.exit_code, kExitServer) << cancelled.output;
  auto missing = RunCli({"--server", address_, "get", "jobs/nosuchjob", "--out", got.path()});
  EXPECT_EQ(missing.exit_code, kExitServer) << missing.output;
}

TEST_F(ServiceCliTest, DetachThenWatchAndJsonLines) {
  TempDir out;
  auto submitted = RunCli({"--server", address_, "solve", SourcePath("scenes/furnace.json"),
                           "--detach", "--max-rays", "30000", "--width", "8", "--height", "8"});
  ASSERT_EQ(submitted.exit_code, kExitOk) << submitted.output;
  std::vector<std::string> lines = Lines(submitted.output);
  ASSERT_FALSE(lines.empty());
  const std::string job = lines.back();
  ASSERT_EQ(job.rfind("jobs/", 0), 0u) << submitted.output;
  auto watched = RunCli({"--server", address_, "--json", "watch", job});
  ASSERT_EQ(watched.exit_code, kExitOk) << watched.output;
  int snapshots = 0;
  bool final_seen = false;
  for (const std::string& line : Lines(watched.output)) {
    if (line.rfind("{\"event\":\"snapshot\"", 0) != 0) continue;
    ++snapshots;
    final_seen |= line.find("\"final\":true") != std::string::npos;
  }
  EXPECT_GE(snapshots, 1);
  EXPECT_TRUE(final_seen) << watched.output;
  auto fetched = RunCli({"--server", address_, "--json", "get", job, "--out", out.path()});
  ASSERT_EQ(fetched.exit_code, kExitOk) << fetched.output;
  EXPECT_NE(ReadFile(out.File("summary.json")).find("\"stop_reason\": \"max_rays\""),
            std::string::npos);
}

TEST_F(ServiceCliTest, ExitCodesForBadInputAndUnreachableServer) {
  TempDir dir;
  dir.Write("scene.mtl", "newmtl lamp\nKd 0.5 0.5 0.5\nKe 1 1 1\n");
  std::string obj =
      dir.Write("scene.obj", "mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nusemtl lamp\nf 1 2 7\n");
  auto bad = RunCli({"--server", address_, "solve", obj, "--out", dir.File("out")});
  EXPECT_EQ(bad.exit_code, kExitInput) << bad.output;
  EXPECT_NE(bad.output.find(obj + ":5:"), std::string::npos) << bad.output;
  auto usage = RunCli({"--server", address_, "solve", SourcePath("scenes/furnace.json"), "--out",
                       dir.File("out"), "--element-size", "1e-9"});
  EXPECT_EQ(usage.exit_code, kExitUsage) << usage.output;
  auto json = RunCli({"--server", address_, "--json", "upload", obj});
  EXPECT_EQ(json.exit_code, kExitInput);
  EXPECT_NE(json.output.find("{\"error\":{\"code\":\"INVALID_ARGUMENT\""), std::string::npos)
      << json.output;
  // Nothing listens on port 1 of the loopback interface.
  auto unreachable = RunCli({"--server", "127.0.0.1:1", "--timeout", "5", "jobs"});
  EXPECT_EQ(unreachable.exit_code, kExitServer) << unreachable.output;
  auto health = RunCli({"--server", address_, "health"});
  EXPECT_EQ(health.exit_code, kExitOk) << health.output;
}

TEST_F(ServiceCliTest, ViewFactorBetweenOpposedSquares) {
  TempDir dir;
  auto r = RunCli({"--server", address_, "viewfactor", SourcePath("tests/data/two_squares.obj"),
                   "--method", "analytic", "--out", dir.File("f.csv"), "--check"});
  ASSERT_EQ(r.exit_code, kExitOk) << r.output;
  auto csv = ReadCsv(dir.File("f.csv"));
  ASSERT_EQ(csv.header, (std::vector<std::string>{"from", "to", "F"}));
  std::map<std::pair<std::string, std::string>, double> f;
  for (const auto& row : csv.rows) f[{row[0], row[1]}] = std::stod(row[2]);
  // Howell's catalogue C-11: directly opposed unit squares at unit distance.
  EXPECT_NEAR((f[{"emitter", "receiver"}]), 0.199824895698, 1e-4);
  EXPECT_NEAR((f[{"receiver", "emitter"}]), 0.199824895698, 1e-4);
  EXPECT_NE(r.output.find("reciprocity"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace radiosity
