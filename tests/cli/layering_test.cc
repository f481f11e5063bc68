// The architecture of docs/design/architecture.md holds in the source: every #include of a project
// header goes down the layers, never up or sideways, and the solver's test binary links no gRPC.
//
//   solver/util <- geometry <- transport <- methods <- results <- pipeline;  input <- geometry
//   proto/api (what server and clients share) <- server <- client
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

namespace fs = std::filesystem;
using testing::ReadFile;
using testing::SourcePath;

// The project folders a source folder may include headers from (a folder always may include its
// own). Generated protobuf headers ("radiosity/v1/...") are checked separately.
const std::map<std::string, std::set<std::string>>& Allowed() {
  static const auto* allowed = new std::map<std::string, std::set<std::string>>{
      {"solver/util", {}},
      {"solver/geometry", {"solver/util"}},
      {"solver/transport", {"solver/util", "solver/geometry"}},
      {"solver/methods", {"solver/util", "solver/geometry", "solver/transport"}},
      {"solver/results", {"solver/util", "solver/geometry", "solver/transport", "solver/methods"}},
      {"solver/pipeline",
       {"solver/util", "solver/geometry", "solver/transport", "solver/methods", "solver/results"}},
      {"solver/input", {"solver/util", "solver/geometry"}},
  };
  return *allowed;
}

struct Include {
  std::string file;
  int line;
  std::string header;
};

// The quoted #includes of every .h and .cc below `dir` (relative to the source tree).
std::vector<Include> IncludesBelow(const std::string& dir) {
  static const std::regex kInclude(R"re(^\s*#\s*include\s+"([^"]+)")re");
  std::vector<Include> out;
  for (const auto& entry : fs::recursive_directory_iterator(SourcePath(dir))) {
    const std::string ext = entry.path().extension().string();
    if (!entry.is_regular_file() || (ext != ".h" && ext != ".cc")) continue;
    const std::string file = fs::relative(entry.path(), SourcePath("")).string();
    const std::string text = ReadFile(entry.path().string());
    int line = 0;
    size_t start = 0;
    while (start < text.size()) {
      size_t end = text.find('\n', start);
      if (end == std::string::npos) end = text.size();
      ++line;
      std::smatch m;
      const std::string l = text.substr(start, end - start);
      if (std::regex_search(l, m, kInclude)) out.push_back({file, line, m[1]});
      start = end + 1;
    }
  }
  return out;
}

// "solver/methods" for "solver/methods/progressive.h"; the top folder for other project headers;
// "" for headers that are not the project's (absl/..., tbb/...).
std::string FolderOf(const std::string& header) {
  for (const char* top : {"solver/", "proto/", "server/", "client/", "tests/", "bench/"}) {
    if (header.rfind(top, 0) != 0) continue;
    if (std::string(top) == "solver/" || std::string(top) == "proto/") {
      const size_t second = header.find('/', std::string(top).size());
      return second == std::string::npos ? header : header.substr(0, second);
    }
    return std::string(top, std::string(top).size() - 1);
  }
  return "";
}

TEST(LayeringTest, SolverLayersIncludeOnlyTheLayersBelowThem) {
  std::vector<Include> includes = IncludesBelow("solver");
  ASSERT_GT(includes.size(), 100u);
  int checked = 0;
  for (const Include& inc : includes) {
    const std::string from = FolderOf(inc.file);
    const auto rule = Allowed().find(from);
    ASSERT_NE(rule, Allowed().end()) << inc.file << " is in no known layer";
    // The native scene format reads the scene message; nothing in solver/ sees the service.
    if (inc.header.rfind("radiosity/v1/", 0) == 0) {
      EXPECT_TRUE(from == "solver/input" && inc.header == "radiosity/v1/scene.pb.h")
          << inc.file << ":" << inc.line << " includes " << inc.header;
      continue;
    }
    const std::string to = FolderOf(inc.header);
    if (to.empty()) continue;
    ++checked;
    EXPECT_TRUE(to == from || rule->second.count(to) > 0)
        << inc.file << ":" << inc.line << " (" << from << ") includes " << inc.header << " (" << to
        << "), which is not below it";
  }
  EXPECT_GT(checked, 100);
}

TEST(LayeringTest, SharedApiCodeAndTheServerDoNotReachUp) {
  for (const auto& [dir, forbidden] : std::vector<std::pair<std::string, std::set<std::string>>>{
           {"proto", {"server", "client", "tests", "bench"}},
           {"server", {"client", "tests", "bench"}},
           {"client", {"tests", "bench"}}}) {
    for (const Include& inc : IncludesBelow(dir)) {
      const std::string to = FolderOf(inc.header);
      const std::string top = to.substr(0, to.find('/'));
      EXPECT_EQ(forbidden.count(top), 0u)
          << inc.file << ":" << inc.line << " includes " << inc.header;
    }
  }
  // The CLI starts the service in-process through its one public entry point, and speaks to it
  // only through the API.
  for (const Include& inc : IncludesBelow("client")) {
    if (FolderOf(inc.header) != "server") continue;
    EXPECT_EQ(inc.header, "server/server.h") << inc.file << ":" << inc.line;
  }
}

TEST(LayeringTest, SolverTestsIncludeNothingOfTheService) {
  for (const Include& inc : IncludesBelow("tests/solver")) {
    const std::string to = FolderOf(inc.header);
    EXPECT_TRUE(to != "server" && to != "client" &&
                (to != "proto/api" || inc.header == "proto/api/exit_codes.h") &&
                inc.header.rfind("radiosity/v1/service", 0) != 0)
        << inc.file << ":" << inc.line << " includes " << inc.header;
  }
}

TEST(LayeringTest, SolverTestBinaryLinksNoGrpc) {
  std::FILE* pipe = ::popen(("ldd '" + std::string(RADIOSITY_SOLVER_TESTS_BIN) + "'").c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string out;
  char buffer[4096];
  size_t n;
  while ((n = std::fread(buffer, 1, sizeof buffer, pipe)) > 0) out.append(buffer, n);
  ASSERT_EQ(::pclose(pipe), 0) << out;
  ASSERT_NE(out.find("libembree"), std::string::npos) << out;  // ldd did list the libraries.
  EXPECT_EQ(out.find("libgrpc"), std::string::npos) << out;
}

}  // namespace
}  // namespace radiosity
