// deploy/ kept in step with the README (there is no Docker engine here, so the files are checked
// as text): the Dockerfile installs exactly deploy/packages.txt (what the quick start's demo
// installs; its test installs deploy/packages-test.txt too) and builds without the tests, is
// multi-stage on Debian bookworm and runs as a non-root user, its runtime stage has
// a package for every shared library the binaries link, and the server flags used by the
// Dockerfile and compose.yaml are flags radiosity-server accepts.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "absl/strings/match.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using testing::ReadFile;
using testing::SourcePath;

std::vector<std::string> Lines(const std::string& text) { return absl::StrSplit(text, '\n'); }

// Non-comment, non-blank lines of deploy/packages.txt (or another list).
std::vector<std::string> PackagesTxt(const std::string& file = "deploy/packages.txt") {
  std::vector<std::string> packages;
  for (const std::string& line : Lines(ReadFile(SourcePath(file)))) {
    std::string p(absl::StripAsciiWhitespace(line));
    if (!p.empty() && p[0] != '#') packages.push_back(p);
  }
  return packages;
}

// The package lines ("    name \") between "# BEGIN <block>" and "# END <block>".
std::vector<std::string> DockerfileBlock(const std::string& block) {
  static const std::regex kPackage(R"(^\s+([a-z0-9][a-z0-9+.\-]*)\s*\\?\s*$)");
  std::vector<std::string> packages;
  bool inside = false;
  for (const std::string& line : Lines(ReadFile(SourcePath("deploy/Dockerfile")))) {
    if (absl::StartsWith(line, "# BEGIN " + block)) inside = true;
    if (absl::StartsWith(line, "# END " + block)) inside = false;
    std::smatch m;
    if (inside && std::regex_match(line, m, kPackage)) packages.push_back(m[1]);
  }
  return packages;
}

std::string Shell(const std::string& command) {
  std::string out;
  FILE* pipe = popen((command + " 2>/dev/null").c_str(), "r");
  if (!pipe) return out;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof buffer, pipe)) > 0) out.append(buffer, n);
  pclose(pipe);
  return out;
}

TEST(DeployTest, DockerfileInstallsExactlyPackagesTxt) {
  std::vector<std::string> expected = PackagesTxt();
  ASSERT_GT(expected.size(), 5u);
  EXPECT_EQ(DockerfileBlock("packages.txt"), expected);
  std::set<std::string> unique(expected.begin(), expected.end());
  EXPECT_EQ(unique.size(), expected.size()) << "packages.txt lists a package twice";
  // The quick start reads the same file.
  EXPECT_NE(ReadFile(SourcePath("deploy/quickstart.sh")).find("deploy/packages.txt"),
            std::string::npos);
}

// The tests' packages add to the programs' (none twice); the Dockerfile, which installs only the
// programs', configures without the tests (whose GoogleTest it lacks).
TEST(DeployTest, TestPackagesAddToThePrograms) {
  const std::vector<std::string> programs = PackagesTxt(),
                                 tests = PackagesTxt("deploy/packages-test.txt");
  ASSERT_GT(tests.size(), 5u);
  std::set<std::string> all(programs.begin(), programs.end());
  for (const std::string& p : tests) EXPECT_TRUE(all.insert(p).second) << p << " is listed twice";
  EXPECT_NE(std::find(tests.begin(), tests.end(), "libgtest-dev"), tests.end());
  EXPECT_NE(ReadFile(SourcePath("deploy/quickstart.sh")).find("deploy/packages-test.txt"),
            std::string::npos);
  EXPECT_NE(ReadFile(SourcePath("deploy/Dockerfile")).find("-DRADIOSITY_TESTS=OFF"),
            std::string::npos);
}

TEST(DeployTest, MultiStageBookwormRunningAsNonRoot) {
  const std::string dockerfile = ReadFile(SourcePath("deploy/Dockerfile"));
  std::vector<std::string> stages;
  std::string user;  // USER of the last stage.
  for (const std::string& line : Lines(dockerfile)) {
    if (absl::StartsWith(line, "FROM ")) {
      stages.push_back(line);
      user.clear();
    }
    if (absl::StartsWith(line, "USER "))
      user = std::string(absl::StripAsciiWhitespace(line.substr(5)));
  }
  ASSERT_GE(stages.size(), 2u);
  for (const std::string& s : stages) EXPECT_TRUE(absl::StartsWith(s, "FROM debian:bookworm")) << s;
  EXPECT_FALSE(user.empty());
  EXPECT_NE(user, "root");
  EXPECT_NE(user, "0");
  EXPECT_NE(dockerfile.find("COPY --from=build"), std::string::npos);
  const std::string compose = ReadFile(SourcePath("deploy/compose.yaml"));
  EXPECT_NE(compose.find("dockerfile: deploy/Dockerfile"), std::string::npos);
  EXPECT_NE(compose.find("services:"), std::string::npos);
}

TEST(DeployTest, ServerFlagsInDeployFilesExist) {
  const std::string help = Shell(std::string(RADIOSITY_SERVER_BIN) + " --help");
  ASSERT_NE(help.find("--listen"), std::string::npos) << help;
  static const std::regex kFlag(R"((--[a-z][a-z0-9-]*))");
  for (const char* file : {"deploy/Dockerfile", "deploy/compose.yaml"}) {
    const std::string text = ReadFile(SourcePath(file));
    // The server's arguments: the CMD line of the Dockerfile, the command list of compose.yaml.
    std::string args;
    for (const std::string& line : Lines(text)) {
      if (absl::StartsWith(line, "CMD ") ||
          absl::StartsWith(absl::StripLeadingAsciiWhitespace(line), "- --")) {
        args += line + "\n";
      }
    }
    ASSERT_FALSE(args.empty()) << file;
    for (std::sregex_iterator it(args.begin(), args.end(), kFlag), end; it != end; ++it) {
      EXPECT_NE(help.find((*it)[1].str()), std::string::npos) << file << ": " << (*it)[1];
    }
  }
  // The health check is a real CLI command.
  EXPECT_NE(Shell(std::string(RADIOSITY_CLI) + " --help").find("health"), std::string::npos);
}

TEST(DeployTest, RuntimeStageHasAPackageForEverySharedLibrary) {
  if (Shell("command -v dpkg-query && command -v ldd && command -v readelf").empty()) {
    GTEST_SKIP() << "needs dpkg-query, ldd and readelf (Debian)";
  }
  std::vector<std::string> runtime = DockerfileBlock("runtime packages");
  ASSERT_FALSE(runtime.empty());
  std::set<std::string> available(runtime.begin(), runtime.end());
  // In every debian:bookworm image (Priority: required).
  for (const char* base : {"libc6", "libgcc-s1", "libstdc++6", "zlib1g"}) available.insert(base);
  // soname -> path (as ldd prints it) for the libraries the binaries name directly (NEEDED).
  std::map<std::string, std::string> needed;
  static const std::regex kNeeded(R"(\(NEEDED\).*\[(.+)\])");
  for (const char* binary : {RADIOSITY_SERVER_BIN, RADIOSITY_CLI, RADIOSITY_IMPORT_BIN}) {
    const std::string ldd = Shell(std::string("ldd ") + binary);
    for (const std::string& line : Lines(Shell(std::string("readelf -d ") + binary))) {
      std::smatch m;
      if (!std::regex_search(line, m, kNeeded)) continue;
      const std::string soname = m[1];
      // "\tlibfoo.so.1 => /usr/lib/x86_64-linux-gnu/libfoo.so.1 (0x...)"
      size_t at = ldd.find("\t" + soname + " => ");
      ASSERT_NE(at, std::string::npos) << soname;
      at += soname.size() + 5;
      needed[soname] = ldd.substr(at, ldd.find(' ', at) - at);
    }
  }
  ASSERT_FALSE(needed.empty());
  for (const auto& [soname, path] : needed) {
    if (absl::StartsWith(soname, "libasan") || absl::StartsWith(soname, "libubsan") ||
        absl::StartsWith(soname, "libtsan")) {
      GTEST_SKIP() << "a sanitizer build links its runtimes; the image builds without them";
    }
  }
  // Their packages, in one dpkg query ("package:arch: /path" a line). dpkg knows a file by the
  // path its package installed it at: with merged /usr, /lib/... and /usr/lib/... are the same.
  std::string paths;
  for (const auto& [soname, path] : needed) {
    paths += " " + path;
    if (absl::StartsWith(path, "/usr/lib/")) paths += " " + path.substr(4);
    if (absl::StartsWith(path, "/lib/")) paths += " /usr" + path;
  }
  std::map<std::string, std::string> owner;  // path -> package
  for (const std::string& line : Lines(Shell("dpkg-query -S" + paths))) {
    size_t colon = line.find(": ");
    if (colon == std::string::npos) continue;
    std::string package = line.substr(0, line.find(':'));
    std::string path = line.substr(colon + 2);
    owner[path] = package;
    if (absl::StartsWith(path, "/usr/lib/")) owner[path.substr(4)] = package;
    if (absl::StartsWith(path, "/lib/")) owner["/usr" + path] = package;
  }
  for (const auto& [soname, path] : needed) {
    auto it = owner.find(path);
    ASSERT_NE(it, owner.end()) << soname << " at " << path << " belongs to no package";
    EXPECT_TRUE(available.count(it->second))
        << soname << " comes from " << it->second << ", missing from the runtime stage";
  }
}

}  // namespace
}  // namespace radiosity
