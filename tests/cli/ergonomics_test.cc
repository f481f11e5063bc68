// CLI ergonomics: `radiosity --version`, and the bash completion script of `radiosity completion
// bash` run in bash: commands from `--help` complete, each command's flags (as its `--help` lists
// them) complete after `-`, global flags complete anywhere.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "nlohmann/json.hpp"
#include "proto/api/exit_codes.h"
#include "tests/testing/test_util.h"

namespace radiosity {
namespace {

using testing::RunCli;

TEST(CliErgonomicsTest, VersionNamesTheProgramAndItsLibraries) {
  testing::CommandResult r = RunCli({"--version"});
  EXPECT_EQ(r.exit_code, kExitOk) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex(R"(^radiosity \d+\.\d+\.\d+ \(gRPC \d)")))
      << r.output;
}

// The words bash completes for `words` (the last one being completed), with the script loaded.
std::set<std::string> Complete(const std::string& script, const std::string& words) {
  testing::TempDir dir;
  const std::string path = dir.Write("completion.bash", script);
  const std::string command = "bash -c 'source " + path + "; COMP_WORDS=(" + words +
                              "); COMP_CWORD=$((${#COMP_WORDS[@]} - 1)); "
                              "_radiosity_complete; printf \"%s\\n\" \"${COMPREPLY[@]}\"' 2>&1";
  std::string output;
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return {};
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) output.append(buffer, n);
  pclose(pipe);
  std::set<std::string> out;
  for (absl::string_view line : absl::StrSplit(output, '\n', absl::SkipEmpty())) {
    out.emplace(line);
  }
  return out;
}

// Long flags in a --help text.
std::set<std::string> FlagsOf(const std::string& help) {
  std::set<std::string> flags;
  std::regex flag(R"((^|[ ,])(--[a-z][a-z0-9-]*))");
  for (const std::string& line : std::vector<std::string>(absl::StrSplit(help, '\n'))) {
    for (std::sregex_iterator it(line.begin(), line.end(), flag), end; it != end; ++it) {
      flags.insert((*it)[2]);
    }
  }
  return flags;
}

TEST(CliErgonomicsTest, BashCompletionKnowsEveryCommandAndFlag) {
  testing::CommandResult script = RunCli({"completion", "bash"});
  ASSERT_EQ(script.exit_code, kExitOk) << script.output;
  ASSERT_NE(script.output.find("complete -o filenames -F _radiosity_complete radiosity"),
            std::string::npos)
      << script.output;

  // The commands `radiosity --help` lists under "Subcommands:".
  testing::CommandResult help = RunCli({"--help"});
  std::vector<std::string> commands;
  const size_t at = help.output.find("Subcommands:");
  ASSERT_NE(at, std::string::npos) << help.output;
  std::regex command_line(R"(^  ([a-z]+) )");
  for (const std::string& line :
       std::vector<std::string>(absl::StrSplit(help.output.substr(at), '\n'))) {
    std::smatch m;
    if (std::regex_search(line, m, command_line)) commands.push_back(m[1]);
  }
  ASSERT_GE(commands.size(), 10u) << help.output;
  const std::set<std::string> all = Complete(script.output, "radiosity \"\"");
  for (const std::string& c : commands) EXPECT_TRUE(all.count(c)) << c;
  EXPECT_EQ(Complete(script.output, "radiosity vie"), std::set<std::string>{"viewfactor"});

  // Each command's own long flags, as its --help shows them in the option column.
  for (const std::string& c : {std::string("solve"), std::string("render"), std::string("jobs")}) {
    testing::CommandResult sub = RunCli({c, "--help"});
    std::set<std::string> wanted;
    for (const std::string& line : std::vector<std::string>(absl::StrSplit(sub.output, '\n'))) {
      if (line.rfind("  -", 0) != 0) continue;  // Option lines start with two spaces and a dash.
      const std::string column = line.substr(0, line.find("  ", 2));
      for (const std::string& f : FlagsOf(column)) wanted.insert(f);
    }
    ASSERT_FALSE(wanted.empty()) << sub.output;
    const std::set<std::string> got = Complete(script.output, "radiosity " + c + " --");
    for (const std::string& f : wanted) EXPECT_TRUE(got.count(f)) << c << " " << f;
    EXPECT_TRUE(got.count("--server")) << "global flags complete after a command";
  }
  EXPECT_EQ(Complete(script.output, "radiosity render job --false"),
            std::set<std::string>{"--false-color"});
  EXPECT_EQ(Complete(script.output, "radiosity --serv"), std::set<std::string>{"--server"});
}

// Every --json line of every command has the keys docs/guide/cli.md gives it (and no
// command writes anything else on stdout).
std::vector<nlohmann::json> JsonLines(const testing::CommandResult& r) {
  std::vector<nlohmann::json> out;
  for (const std::string& line : std::vector<std::string>(absl::StrSplit(r.output, '\n'))) {
    if (line.empty() || line[0] != '{') continue;
    out.push_back(nlohmann::json::parse(line, nullptr, false));
    EXPECT_FALSE(out.back().is_discarded()) << line;
  }
  return out;
}

::testing::AssertionResult HasKeys(const nlohmann::json& j,
                                   std::initializer_list<const char*> keys) {
  for (const char* k : keys) {
    if (!j.contains(k)) return ::testing::AssertionFailure() << j.dump() << " lacks " << k;
  }
  return ::testing::AssertionSuccess();
}

// Whether `part` is `whole` with some elements left out.
bool IsSubsequence(const std::vector<std::string>& part, const std::vector<std::string>& whole) {
  size_t j = 0;
  for (const std::string& x : part) {
    while (j < whole.size() && whole[j] != x) ++j;
    if (j == whole.size()) return false;
    ++j;
  }
  return true;
}

// A closed box's Monte Carlo view factors with closure enforced: the report says what it was
// before, --row-sums writes every row (summing to 1 now), --out FILE.mtx the Matrix Market file.
TEST(CliErgonomicsTest, ViewFactorsEnforcedWithRowSumsAndMatrixMarket) {
  testing::TempDir dir;
  testing::CommandResult r =
      RunCli({"viewfactor", testing::SourcePath("scenes/furnace.json"), "--method", "montecarlo",
              "--rays-per-surface", "20000", "--enforce", "closure", "--row-sums",
              dir.File("rows.csv"), "--out", dir.File("vf.mtx")});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, ::testing::HasSubstr("before --enforce closure: max reciprocity error"));
  const testing::Csv rows = testing::ReadCsv(dir.File("rows.csv"));
  ASSERT_EQ(rows.header, (std::vector<std::string>{"surface", "area", "row_sum"}));
  ASSERT_EQ(rows.rows.size(), 6u);
  for (const auto& row : rows.rows) {
    EXPECT_NEAR(std::strtod(row[1].c_str(), nullptr), 1, 1e-9) << row[0];
    EXPECT_NEAR(std::strtod(row[2].c_str(), nullptr), 1, 1e-9) << row[0];
  }
  const std::string mtx = testing::ReadFile(dir.File("vf.mtx"));
  EXPECT_EQ(mtx.rfind("%%MatrixMarket matrix coordinate real general\n", 0), 0u) << mtx;
  EXPECT_THAT(mtx, ::testing::HasSubstr("\n6 6 30\n"));
}

// --from x1,z0: the CSV holds those rows only, line for line as the whole matrix's (same seed),
// --row-sums and --check report those rows; an unknown name is refused, naming it and the flag.
TEST(CliErgonomicsTest, ViewFactorsFromSomeSurfacesOnly) {
  testing::TempDir dir;
  const std::vector<std::string> base = {
      "viewfactor",         testing::SourcePath("scenes/furnace.json"),
      "--method",           "montecarlo",
      "--rays-per-surface", "20000"};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> args = base;
    args.insert(args.end(), extra.begin(), extra.end());
    return RunCli(args);
  };
  testing::CommandResult all = with({"--out", dir.File("all.csv")});
  ASSERT_EQ(all.exit_code, 0) << all.output;
  testing::CommandResult some = with({"--from", "x1,z0", "--out", dir.File("some.csv"),
                                      "--row-sums", dir.File("rows.csv"), "--check"});
  ASSERT_EQ(some.exit_code, 0) << some.output;
  const testing::Csv whole = testing::ReadCsv(dir.File("all.csv"));
  const testing::Csv part = testing::ReadCsv(dir.File("some.csv"));
  ASSERT_EQ(part.header, whole.header);
  std::vector<std::vector<std::string>> expected;
  for (const auto& row : whole.rows) {
    if (row[0] == "x1" || row[0] == "z0") expected.push_back(row);
  }
  EXPECT_EQ(expected.size(), 10u);
  EXPECT_EQ(part.rows, expected);
  const testing::Csv rows = testing::ReadCsv(dir.File("rows.csv"));
  ASSERT_EQ(rows.rows.size(), 2u);
  EXPECT_EQ(rows.rows[0][0], "x1");
  EXPECT_EQ(rows.rows[1][0], "z0");
  EXPECT_THAT(some.output, ::testing::HasSubstr("x1: sum of F = 1.000000"));
  EXPECT_THAT(some.output, ::testing::Not(::testing::HasSubstr("y0: sum of F")));
  testing::CommandResult bad = with({"--from", "x1,nope", "--out", dir.File("bad.csv")});
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_THAT(bad.output, ::testing::HasSubstr("no surface named 'nope'"));
  EXPECT_THAT(bad.output, ::testing::HasSubstr("--from"));
}

// Radiative exchange between concentric cubes (a convex body in an enclosure): the net power
// is sigma A1 (T1^4 - T2^4) / (1/eps1 + (A1/A2) (1/eps2 - 1)); Monte Carlo factors with closure
// enforced make F_12 = 1 and F_21 = A1/A2 exact.
TEST(CliErgonomicsTest, ViewFactorsWithRadiativeExchange) {
  testing::TempDir dir;
  std::string obj;
  for (double r : {1.0, 2.0}) {
    for (int i = 0; i < 8; ++i) {
      obj += absl::StrFormat("v %g %g %g\n", (i & 1) ? r : -r, (i & 2) ? r : -r, (i & 4) ? r : -r);
    }
  }
  // Each side counter-clockwise seen from outside (the inner cube faces out).
  const int sides[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  obj += "g inner\n";
  for (const auto& s : sides)
    obj += absl::StrFormat("f %d %d %d %d\n", s[0] + 1, s[1] + 1, s[2] + 1, s[3] + 1);
  obj += "g outer\n";
  for (const auto& s : sides)
    obj += absl::StrFormat("f %d %d %d %d\n", s[3] + 9, s[2] + 9, s[1] + 9, s[0] + 9);
  const std::string scene = dir.Write("cubes.obj", obj);
  const std::string thermal =
      dir.Write("thermal.csv", "surface,emissivity,temperature\ninner,0.7,800\n*,0.25,300\n");
  testing::CommandResult r =
      RunCli({"viewfactor", scene, "--method", "montecarlo", "--rays-per-surface", "20000",
              "--enforce", "closure", "--thermal", thermal, "--exchange", dir.File("ex.csv"),
              "--gebhart", dir.File("gebhart.csv"), "--out", dir.File("vf.csv")});
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_THAT(r.output, ::testing::HasSubstr("radiative exchange"));
  const testing::Csv ex = testing::ReadCsv(dir.File("ex.csv"));
  ASSERT_EQ(ex.header,
            (std::vector<std::string>{"surface", "area", "emissivity", "temperature", "emitted_W",
                                      "absorbed_W", "net_W", "net_W_per_m2", "to_environment_W"}));
  ASSERT_EQ(ex.rows.size(), 2u);
  const double sigma = 5.670374419e-8, a1 = 24, a2 = 96;
  const double q = sigma * a1 * (std::pow(800.0, 4) - std::pow(300.0, 4)) /
                   (1 / 0.7 + (a1 / a2) * (1 / 0.25 - 1));
  EXPECT_NEAR(std::strtod(ex.rows[0][6].c_str(), nullptr), q, 1e-8 * q);
  EXPECT_NEAR(std::strtod(ex.rows[1][6].c_str(), nullptr), -q, 1e-8 * q);
  EXPECT_EQ(ex.rows[1][2], "0.25");  // The default row.
  const testing::Csv g = testing::ReadCsv(dir.File("gebhart.csv"));
  ASSERT_EQ(g.header, (std::vector<std::string>{"from", "to", "gebhart", "net_W"}));
  EXPECT_EQ(g.rows.size(), 4u);

  // A surface left without thermal data fails the job, naming it.
  const std::string partial =
      dir.Write("partial.csv", "surface,emissivity,temperature\ninner,0.7,800\n");
  r = RunCli({"viewfactor", scene, "--method", "montecarlo", "--thermal", partial, "--out",
              dir.File("vf2.csv")});
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.output, ::testing::HasSubstr("surface 'outer' has no emissivity and temperature"));
}

TEST(CliErgonomicsTest, JsonLinesAreTheDocumentedOnes) {
  testing::TempDir dir;
  const std::vector<std::string> base = {"--data-dir", dir.File("data"), "--json"};
  auto run = [&](std::vector<std::string> args) {
    args.insert(args.begin(), base.begin(), base.end());
    return RunCli(args);
  };
  const std::string furnace = testing::SourcePath("scenes/furnace.json");
  auto r = run({"upload", furnace});
  ASSERT_EQ(r.exit_code, kExitOk) << r.output;
  auto lines = JsonLines(r);
  ASSERT_EQ(lines.size(), 1u) << r.output;
  EXPECT_TRUE(HasKeys(lines[0], {"name", "files", "faces"}));

  r = run({"solve", furnace, "--max-elements", "100", "--out", dir.File("out"), "--width", "16",
           "--height", "16"});
  ASSERT_EQ(r.exit_code, kExitOk) << r.output;
  lines = JsonLines(r);
  ASSERT_GE(lines.size(), 3u) << r.output;
  EXPECT_EQ(lines.front()["event"], "job");
  EXPECT_TRUE(HasKeys(lines.front(), {"job"}));
  const std::string job = lines.front()["job"]["name"];
  EXPECT_EQ(lines.back()["event"], "result");
  EXPECT_TRUE(HasKeys(lines.back(), {"job", "out"}));
  // The phases in their order, meshing and writing each from 0 to 1 without going back, writing
  // naming result files in the order the result lists them.
  const std::vector<std::string> phases = {"meshing", "solving", "writing"};
  std::vector<std::string> seen_phases;
  std::vector<std::string> items;
  double fraction = 0;
  for (size_t i = 1; i + 1 < lines.size(); ++i) {
    SCOPED_TRACE(lines[i].dump());
    EXPECT_EQ(lines[i]["event"], "snapshot");
    EXPECT_TRUE(HasKeys(lines[i], {"job", "sequence", "state", "rays", "unshot_fraction",
                                   "elapsed_seconds", "resync", "final", "elements", "mesh_version",
                                   "phase", "phase_fraction", "phase_item"}));
    const std::string phase = lines[i]["phase"];
    if (lines[i]["final"] == true) break;
    if (seen_phases.empty() || seen_phases.back() != phase) {
      seen_phases.push_back(phase);
      fraction = 0;
    }
    const double f = lines[i]["phase_fraction"];
    EXPECT_GE(f, fraction);
    EXPECT_LE(f, 1);
    fraction = f;
    const std::string item = lines[i]["phase_item"];
    if (phase == "writing" && !item.empty() && (items.empty() || items.back() != item)) {
      items.push_back(item);
    }
    if (phase != "writing") {
      EXPECT_EQ(item, "");
    }
  }
  EXPECT_EQ(lines[lines.size() - 2]["final"], true);
  // Every file written is named, in the order of the job's result files (image.png stands for
  // both images).
  std::vector<std::string> results;
  for (const auto& f : lines.back()["job"]["results"]) {
    const std::string name = f["name"];
    if (name != "image.exr") results.push_back(name);
  }
  ASSERT_GE(results.size(), 5u);
  bool gap = false;  // A reader slower than the job skips snapshots (latest wins), and says so.
  for (size_t i = 1; i + 1 < lines.size(); ++i) gap = gap || lines[i]["resync"] == true;
  if (!gap) {
    EXPECT_EQ(seen_phases, phases);
    EXPECT_EQ(fraction, 1);  // Writing's end.
    EXPECT_EQ(items, results);
  } else {
    EXPECT_TRUE(IsSubsequence(seen_phases, phases)) << absl::StrJoin(seen_phases, ",");
    EXPECT_TRUE(IsSubsequence(items, results)) << absl::StrJoin(items, ",");
  }

  r = run({"watch", job});
  lines = JsonLines(r);
  ASSERT_FALSE(lines.empty()) << r.output;
  EXPECT_EQ(lines.back()["event"], "snapshot");
  EXPECT_EQ(lines.back()["state"], "SUCCEEDED");
  for (const auto& [command, keys] :
       std::vector<std::pair<std::vector<std::string>, std::vector<const char*>>>{
           {{"jobs"}, {"name", "state"}},
           {{"scenes"}, {"name", "files"}},
           {{"get", job, "--out", dir.File("got")}, {"job", "out", "files"}},
           {{"render", job, "--out", dir.File("r.png"), "--width", "8", "--height", "8"},
            {"job", "out"}},
           {{"render", job, "--out", dir.File("g.png"), "--width", "8", "--height", "8",
             "--final-gather", "16", "--samples-per-pixel", "1"},
            {"job", "out"}},
           {{"report", job, "--out", dir.File("report")}, {"job", "out", "files", "sensor_grids"}},
           {{"viewfactor", furnace, "--method", "analytic"}, {"job", "result", "csv"}},
           {{"health"}, {"service", "serving"}},
           {{"cancel", job}, {"error", "exit_code"}},  // It has ended: FAILED_PRECONDITION.
       }) {
    r = run(command);
    SCOPED_TRACE(command[0] + ": " + r.output);
    lines = JsonLines(r);
    ASSERT_FALSE(lines.empty());
    for (const nlohmann::json& line : lines) {
      for (const char* k : keys) EXPECT_TRUE(line.contains(k)) << line.dump() << " lacks " << k;
    }
    if (command[0] == "cancel") {
      EXPECT_EQ(lines[0]["error"]["code"], "FAILED_PRECONDITION");
      EXPECT_EQ(lines[0]["exit_code"].get<int>(), r.exit_code);
    } else {
      EXPECT_EQ(r.exit_code, kExitOk);
    }
  }
}

}  // namespace
}  // namespace radiosity
