// Replays every input under tests/fuzz/regressions/ (inputs a fuzzer once crashed on) and the
// seed corpus under tests/fuzz/corpus/ through the fuzzers' entry points: none may crash, hang or
// leak (the sanitizer CI build runs this too). Both folders of each fuzzer must exist (the
// regression folders are kept in git by a README, which is not an input) and the seed corpus must
// not be empty: a replay of nothing passes nothing.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "tests/fuzz/fuzz_entry.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

// The inputs in `dir` (relative to the source tree), sorted: its regular files but the README
// that keeps the folder in git. A missing folder is a test failure.
void InputsIn(const std::string& dir, std::vector<std::string>* inputs) {
  const std::string path = testing::SourcePath(dir);
  ASSERT_TRUE(std::filesystem::is_directory(path)) << path << " is missing";
  for (const auto& entry : std::filesystem::directory_iterator(path)) {
    if (entry.is_regular_file() && entry.path().filename() != "README") {
      inputs->push_back(entry.path().string());
    }
  }
  std::sort(inputs->begin(), inputs->end());
}

// Runs every input of one fuzzer (its seed corpus, then its regressions) through `run`; *count is
// how many ran.
void Replay(const std::string& fuzzer, const std::function<void(const std::string&)>& run,
            int* count) {
  std::vector<std::string> seeds, regressions;
  ASSERT_NO_FATAL_FAILURE(InputsIn("tests/fuzz/corpus/" + fuzzer, &seeds));
  ASSERT_NO_FATAL_FAILURE(InputsIn("tests/fuzz/regressions/" + fuzzer, &regressions));
  ASSERT_FALSE(seeds.empty()) << "the seed corpus tests/fuzz/corpus/" << fuzzer << " is empty";
  seeds.insert(seeds.end(), regressions.begin(), regressions.end());
  for (const std::string& file : seeds) {
    SCOPED_TRACE(file);
    run(testing::ReadFile(file));
    ++*count;
  }
}

TEST(FuzzRegressionTest, ObjInputsNeverCrash) {
  testing::TempDir scratch;
  int n = 0;
  ASSERT_NO_FATAL_FAILURE(Replay(
      "obj", [&](const std::string& input) { fuzz::RunObj(input, scratch.path()); }, &n));
  EXPECT_GE(n, 2);
}

TEST(FuzzRegressionTest, SceneInputsNeverCrash) {
  int n = 0;
  ASSERT_NO_FATAL_FAILURE(Replay("scene", fuzz::RunScene, &n));
  EXPECT_GE(n, 3);
}

TEST(FuzzRegressionTest, ModelInputsNeverCrash) {
  testing::TempDir scratch;
  int n = 0;
  ASSERT_NO_FATAL_FAILURE(Replay(
      "model", [&](const std::string& input) { fuzz::RunModel(input, scratch.path()); }, &n));
  EXPECT_GE(n, 30);
}

}  // namespace
}  // namespace radiosity
