// Replays every input under tests/fuzz/regressions/ (inputs a fuzzer once crashed on) and the
// seed corpus through the fuzzers' entry points: none may crash, hang or leak (the sanitizer CI
// build runs this too).
#include <gtest/gtest.h>

#include <filesystem>

#include "tests/fuzz/fuzz_entry.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

std::vector<std::string> FilesIn(const std::string& dir) {
  std::vector<std::string> out;
  if (!std::filesystem::exists(dir)) return out;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.is_regular_file()) out.push_back(entry.path().string());
  }
  std::sort(out.begin(), out.end());
  return out;
}

TEST(FuzzRegressionTest, ObjInputsNeverCrash) {
  testing::TempDir scratch;
  int n = 0;
  for (const char* dir : {"tests/fuzz/corpus/obj", "tests/fuzz/regressions/obj"}) {
    for (const std::string& file : FilesIn(testing::SourcePath(dir))) {
      SCOPED_TRACE(file);
      fuzz::RunObj(testing::ReadFile(file), scratch.path());
      ++n;
    }
  }
  EXPECT_GE(n, 2);
}

TEST(FuzzRegressionTest, SceneInputsNeverCrash) {
  int n = 0;
  for (const char* dir : {"tests/fuzz/corpus/scene", "tests/fuzz/regressions/scene"}) {
    for (const std::string& file : FilesIn(testing::SourcePath(dir))) {
      SCOPED_TRACE(file);
      fuzz::RunScene(testing::ReadFile(file));
      ++n;
    }
  }
  EXPECT_GE(n, 3);
}

}  // namespace
}  // namespace radiosity
