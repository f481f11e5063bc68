#include "tests/testing/test_util.h"

#include <sys/wait.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

namespace radiosity::testing {

std::string SourcePath(const std::string& relative) {
  return std::string(RADIOSITY_SOURCE_DIR) + "/" + relative;
}

TempDir::TempDir() {
  std::random_device rd;
  auto base = std::filesystem::temp_directory_path();
  for (;;) {
    auto candidate = base / ("radiosity-test-" + std::to_string(rd()));
    if (std::filesystem::create_directory(candidate)) {
      path_ = candidate.string();
      break;
    }
  }
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::string TempDir::Write(const std::string& name, const std::string& text) const {
  std::string p = File(name);
  std::filesystem::create_directories(std::filesystem::path(p).parent_path());
  std::ofstream(p, std::ios::binary) << text;
  return p;
}

namespace {
std::string ShellQuote(const std::string& s) {
  std::string out = "'";
  for (char c : s) {
    if (c == '\'') {
      out += "'\\''";
    } else {
      out += c;
    }
  }
  return out + "'";
}
}  // namespace

CommandResult RunCli(const std::vector<std::string>& args) {
  std::string cmd = ShellQuote(RADIOSITY_CLI);
  for (const auto& a : args) cmd += " " + ShellQuote(a);
  cmd += " 2>&1";
  CommandResult result;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) return result;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) result.output.append(buf, n);
  int status = pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

namespace {
std::vector<std::string> Split(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : line) {
    if (c == ',') {
      out.push_back(cur);
      cur.clear();
    } else if (c != '\r') {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}
}  // namespace

int Csv::Column(const std::string& name) const {
  for (size_t i = 0; i < header.size(); ++i) {
    if (header[i] == name) return static_cast<int>(i);
  }
  return -1;
}

Csv ReadCsv(const std::string& path) {
  Csv csv;
  std::ifstream in(path);
  std::string line;
  if (std::getline(in, line)) csv.header = Split(line);
  while (std::getline(in, line)) {
    if (!line.empty()) csv.rows.push_back(Split(line));
  }
  return csv;
}

Scene MakeClosedBox(double sx, double sy, double sz, const Material& material) {
  Scene s;
  s.materials.push_back(material);
  // Corners indexed by bits (x, y, z).
  for (int i = 0; i < 8; ++i) {
    s.vertices.push_back({(i & 1) ? sx : 0.0, (i & 2) ? sy : 0.0, (i & 4) ? sz : 0.0});
  }
  // Each side listed counter-clockwise as seen from inside the box.
  struct SideDef {
    const char* name;
    int v[4];
  };
  const SideDef sides[] = {
      {"x0", {0, 2, 6, 4}}, {"x1", {1, 5, 7, 3}}, {"y0", {0, 4, 5, 1}},
      {"y1", {2, 3, 7, 6}}, {"z0", {0, 1, 3, 2}}, {"z1", {4, 6, 7, 5}},
  };
  for (const SideDef& side : sides) {
    s.surfaces.push_back({side.name, 0, 0});
    Face f;
    f.surface = static_cast<int>(s.surfaces.size()) - 1;
    f.vertices.assign(side.v, side.v + 4);
    s.faces.push_back(f);
  }
  return s;
}

void AddRect(Scene* s, const std::string& surface, int material, const Vec3& corner, const Vec3& u,
             const Vec3& v) {
  int index = -1;
  for (size_t i = 0; i < s->surfaces.size(); ++i) {
    if (s->surfaces[i].name == surface) index = static_cast<int>(i);
  }
  if (index < 0) {
    s->surfaces.push_back({surface, material, 0});
    index = static_cast<int>(s->surfaces.size()) - 1;
  }
  int base = static_cast<int>(s->vertices.size());
  for (const Vec3& p : {corner, corner + u, corner + u + v, corner + v}) s->vertices.push_back(p);
  Face f;
  f.surface = index;
  f.vertices = {base, base + 1, base + 2, base + 3};
  s->faces.push_back(f);
}

}  // namespace radiosity::testing
