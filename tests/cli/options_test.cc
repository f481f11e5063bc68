// The CLI's options through the method registry and the solver's one validation (the table of
// methods in docs/guide/methods.md is `radiosity methods`'s output, kept so by
// tests/docs/check_docs.py): an option the method ignores is a warning
// (on stderr and in summary.json), an estimator the method cannot use and an out-of-range value
// are usage errors naming the flag.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "proto/api/exit_codes.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using testing::ReadFile;
using testing::RunCli;
using testing::SourcePath;
using testing::TempDir;

std::vector<std::string> Solve(const TempDir& dir, std::vector<std::string> extra) {
  std::vector<std::string> args = {"solve",
                                   SourcePath("scenes/cornell_box.obj"),
                                   "--out",
                                   dir.path(),
                                   "--max-elements",
                                   "150",
                                   "--rays-per-element",
                                   "50",
                                   "--width",
                                   "16",
                                   "--height",
                                   "16"};
  args.insert(args.end(), extra.begin(), extra.end());
  return args;
}

TEST(CliOptionsTest, AnIgnoredOptionIsAWarningOnStderrAndInTheSummary) {
  TempDir dir;
  testing::CommandResult r = RunCli(Solve(dir, {"--method", "jacobi", "--overshoot", "1.5"}));
  ASSERT_EQ(r.exit_code, kExitOk) << r.output;
  EXPECT_THAT(r.output,
              HasSubstr("radiosity: warning: --overshoot is ignored by --method jacobi\n"));
  EXPECT_THAT(ReadFile(dir.File("summary.json")),
              HasSubstr("\"warnings\": [\"--overshoot is ignored by --method jacobi\"]"));

  TempDir quiet;
  r = RunCli(Solve(quiet, {"--method", "jacobi"}));
  ASSERT_EQ(r.exit_code, kExitOk) << r.output;
  EXPECT_THAT(r.output, Not(HasSubstr("warning")));
}

TEST(CliOptionsTest, AutoReportsWhatTheMethodItChoseIgnores) {
  // The Cornell box is dim: auto runs progressive, which does not read --max-matrix-mb.
  TempDir dir;
  testing::CommandResult r = RunCli(Solve(dir, {"--max-matrix-mb", "100"}));
  ASSERT_EQ(r.exit_code, kExitOk) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--max-matrix-mb is ignored by --method progressive"));
  EXPECT_THAT(ReadFile(dir.File("summary.json")),
              HasSubstr("--max-matrix-mb is ignored by --method progressive"));
}

TEST(CliOptionsTest, MeaninglessCombinationsAndBadValuesAreUsageErrorsNamingTheFlag) {
  struct Case {
    std::vector<std::string> extra;
    std::string message;
  };
  const std::vector<Case> cases = {
      {{"--method", "reflection", "--formfactor", "analytic"},
       "--formfactor: 'analytic' does not apply to --method 'reflection'"},
      {{"--refine-passes", "0"}, "--refine-passes: 0 is outside [1, 64]"},
      {{"--hemicube-resolution", "65", "--formfactor", "hemicube"},
       "--hemicube-resolution: 65 is not even"},
      {{"--method", "bogus"}, "--method: 'bogus' is not one of auto, progressive"},
      {{"--refine-light-samples", "0"}, "--refine-light-samples: 0 is outside [1, 4096]"},
  };
  for (const Case& c : cases) {
    TempDir dir;
    testing::CommandResult r = RunCli(Solve(dir, c.extra));
    EXPECT_EQ(r.exit_code, kExitUsage) << c.extra[0] << ": " << r.output;
    EXPECT_THAT(r.output, HasSubstr("radiosity: error: " + c.message));
  }
  TempDir dir;
  testing::CommandResult r =
      RunCli({"viewfactor", SourcePath("scenes/furnace.json"), "--shadow-rays", "5000"});
  EXPECT_EQ(r.exit_code, kExitUsage) << r.output;
  EXPECT_THAT(r.output, HasSubstr("--shadow-rays: 5000 is outside [1, 4096]"));
}

}  // namespace
}  // namespace radiosity
