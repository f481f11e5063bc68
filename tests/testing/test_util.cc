#include "tests/testing/test_util.h"

#include <sys/wait.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>

#include "absl/strings/str_cat.h"

namespace radiosity::testing {

::testing::AssertionResult Refused(const absl::Status& status, absl::StatusCode code,
                                   std::initializer_list<std::string> words) {
  if (status.code() != code) {
    return ::testing::AssertionFailure()
           << "expected " << absl::StatusCodeToString(code) << ", got " << status;
  }
  for (const std::string& w : words) {
    if (status.message().find(w) == absl::string_view::npos) {
      return ::testing::AssertionFailure()
             << "message '" << status.message() << "' lacks '" << w << "'";
    }
  }
  return ::testing::AssertionSuccess();
}

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

CommandResult RunSolve(const std::string& scene, const std::string& out,
                       const std::vector<std::string>& flags) {
  std::vector<std::string> args = {"solve", scene, "--out", out};
  args.insert(args.end(), flags.begin(), flags.end());
  return RunCli(args);
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

absl::StatusOr<Mesh> BuildMesh(const Scene& scene, double element_size) {
  MeshOptions options;
  options.element_size = element_size;
  return Mesh::Build(scene, options);
}

// An icosphere of unit radius (20 x 4^subdivisions triangles) facing inward: triangles whose
// centroid has z > 1 - 2 cap are the lamp (exitance 1, reflectance 0), the rest the coating.
// Sets *f to the lamp's share of the area.
Scene IntegratingSphere(int subdivisions, double cap, double rho, double* f) {
  const double t = (1 + std::sqrt(5.0)) / 2;
  std::vector<Vec3> v = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (Vec3& p : v) p = Normalize(p);
  std::vector<std::array<int, 3>> tris = {
      {0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      auto key = std::minmax(a, b);
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back(Normalize((v[a] + v[b]) * 0.5));
      return mid[key] = static_cast<int>(v.size()) - 1;
    };
    std::vector<std::array<int, 3>> next;
    for (const auto& [a, b, c] : tris) {
      const int ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
      next.insert(next.end(), {{a, ab, ca}, {b, bc, ab}, {c, ca, bc}, {ab, bc, ca}});
    }
    tris = std::move(next);
  }
  Scene scene;
  scene.vertices = v;
  Material lamp;
  lamp.name = "lamp";
  lamp.emission = Rgb::Gray(1);
  Material coating;
  coating.name = "coating";
  coating.reflectance = Rgb::Gray(rho);
  scene.materials = {lamp, coating};
  scene.surfaces = {{"lamp", 0, 0}, {"coating", 1, 0}};
  double lamp_area = 0, area = 0;
  for (auto [a, b, c] : tris) {
    const Vec3 n = Cross(v[b] - v[a], v[c] - v[a]);
    const Vec3 centroid = (v[a] + v[b] + v[c]) / 3.0;
    if (Dot(n, centroid) > 0) std::swap(b, c);  // Front towards the centre.
    Face face;
    face.vertices = {a, b, c};
    face.surface = centroid.z > 1 - 2 * cap ? 0 : 1;
    area += 0.5 * Length(n);
    if (face.surface == 0) lamp_area += 0.5 * Length(n);
    scene.faces.push_back(face);
  }
  *f = lamp_area / area;
  return scene;
}

Scene ConcentricIcospheres(int subdivisions) {
  double unused = 0;
  const Scene unit = IntegratingSphere(subdivisions, 0, 0.5, &unused);  // Faces inward.
  Scene scene;
  scene.materials.push_back({"black", Rgb(), Rgb(), Rgb(), false, 0});
  scene.surfaces = {{"inner", 0, 0}, {"outer", 0, 0}};
  for (int s = 0; s < 2; ++s) {
    const double r = s == 0 ? 1.0 : 2.0;
    const int base = static_cast<int>(scene.vertices.size());
    for (const Vec3& p : unit.vertices) scene.vertices.push_back(p * r);
    for (const Face& f : unit.faces) {
      Face g;
      g.surface = s;
      for (int v : f.vertices) g.vertices.push_back(base + v);
      if (s == 0) std::swap(g.vertices[1], g.vertices[2]);  // The inner one faces out.
      scene.faces.push_back(g);
    }
  }
  return scene;
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

void AddPolygon(Scene* s, const std::string& surface, int material,
                const std::vector<Vec3>& corners) {
  s->surfaces.push_back({surface, material, 0});
  Face f;
  f.surface = static_cast<int>(s->surfaces.size()) - 1;
  for (const Vec3& p : corners) {
    f.vertices.push_back(static_cast<int>(s->vertices.size()));
    s->vertices.push_back(p);
  }
  s->faces.push_back(f);
}

std::string RegularPolygonObj(int n) {
  std::string text;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * kPi * i / n;
    absl::StrAppend(&text, "v ", std::cos(a), " ", std::sin(a), " 0\n");
  }
  text += "f";
  for (int i = 1; i <= n; ++i) absl::StrAppend(&text, " ", i);
  return text + "\n";
}

Scene PolygonScene(const std::vector<std::pair<std::string, std::vector<Vec3>>>& polygons) {
  Scene s;
  s.materials.push_back({"black", Rgb(), Rgb(), Rgb(), false, 0});
  for (const auto& [name, corners] : polygons) AddPolygon(&s, name, 0, corners);
  return s;
}

Scene OpposedRectanglesScene(double a, double b, double c) {
  return PolygonScene({{"bottom", {{0, 0, 0}, {a, 0, 0}, {a, b, 0}, {0, b, 0}}},
                       {"top", {{0, 0, c}, {0, b, c}, {a, b, c}, {a, 0, c}}}});
}

Scene HalfBlockedSquaresScene() {
  return PolygonScene({{"bottom", {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}}},
                       {"top", {{0, 0, 1}, {0, 1, 1}, {1, 1, 1}, {1, 0, 1}}},
                       {"wall", {{0.5, -1, 0}, {0.5, 2, 0}, {0.5, 2, 1}, {0.5, -1, 1}}}});
}

Scene CornerBlockFurnace(double rho) {
  Scene s;
  s.materials.push_back({"furnace", Rgb::Gray(rho), Rgb::Gray(1), Rgb(), false, 0});
  const double L = 4;
  auto add = [&](const std::string& surface, const Vec3& corner, const Vec3& u, const Vec3& v) {
    AddRect(&s, surface, 0, corner, u, v);
  };
  // Floor y = 0 facing +y, minus [0,1]x[0,1] in (x, z): two pieces.
  add("floor", {1, 0, 0}, {0, 0, 1}, {L - 1, 0, 0});
  add("floor", {0, 0, 1}, {0, 0, L - 1}, {L, 0, 0});
  // Wall x = 0 facing +x, minus [0,1]x[0,1] in (y, z).
  add("wall_x0", {0, 1, 0}, {0, L - 1, 0}, {0, 0, 1});
  add("wall_x0", {0, 0, 1}, {0, L, 0}, {0, 0, L - 1});
  // Wall z = 0 facing +z, minus [0,1]x[0,1] in (x, y).
  add("wall_z0", {1, 0, 0}, {L - 1, 0, 0}, {0, 1, 0});
  add("wall_z0", {0, 1, 0}, {L, 0, 0}, {0, L - 1, 0});
  // The other three sides, whole.
  add("ceiling", {0, L, 0}, {L, 0, 0}, {0, 0, L});
  add("wall_x4", {L, 0, 0}, {0, 0, L}, {0, L, 0});
  add("wall_z4", {0, 0, L}, {0, L, 0}, {L, 0, 0});
  // The block's room-facing faces.
  add("block", {0, 1, 0}, {0, 0, 1}, {1, 0, 0});  // top, +y
  add("block", {1, 0, 0}, {0, 1, 0}, {0, 0, 1});  // x = 1, +x
  add("block", {0, 0, 1}, {1, 0, 0}, {0, 1, 0});  // z = 1, +z
  return s;
}

double OpposedRectangles(double a, double b, double c) {
  const double x = a / c, y = b / c, x2 = x * x, y2 = y * y;
  return 2 / (kPi * x * y) *
         (std::log(std::sqrt((1 + x2) * (1 + y2) / (1 + x2 + y2))) +
          x * std::sqrt(1 + y2) * std::atan(x / std::sqrt(1 + y2)) +
          y * std::sqrt(1 + x2) * std::atan(y / std::sqrt(1 + x2)) - x * std::atan(x) -
          y * std::atan(y));
}

double PerpendicularRectangles(double l, double w, double h) {
  const double W = w / l, H = h / l, W2 = W * W, H2 = H * H, r = std::sqrt(W2 + H2);
  return 1 / (kPi * W) *
         (W * std::atan(1 / W) + H * std::atan(1 / H) - r * std::atan(1 / r) +
          0.25 * (std::log((1 + W2) * (1 + H2) / (1 + W2 + H2)) +
                  W2 * std::log(W2 * (1 + W2 + H2) / ((1 + W2) * (W2 + H2))) +
                  H2 * std::log(H2 * (1 + H2 + W2) / ((1 + H2) * (H2 + W2)))));
}

double ParallelRectangles(double x1, double x2, double y1, double y2, double xi1, double xi2,
                          double eta1, double eta2, double c) {
  // B(x, y) with x = x_i - xi_l, y = y_j - eta_k: the corner function of the superposition.
  auto b = [c](double x, double y) {
    const double z2 = c * c;
    double v = -0.5 * z2 * std::log(x * x + y * y + z2);
    const double sx = std::sqrt(x * x + z2), sy = std::sqrt(y * y + z2);
    v += y * sx * std::atan(y / sx) + x * sy * std::atan(x / sy);
    return v;
  };
  const double xs[2] = {x1, x2}, ys[2] = {y1, y2}, xis[2] = {xi1, xi2}, etas[2] = {eta1, eta2};
  double sum = 0;
  for (int i = 0; i < 2; ++i) {
    for (int j = 0; j < 2; ++j) {
      for (int k = 0; k < 2; ++k) {
        for (int l = 0; l < 2; ++l) {
          const double sign = ((i + j + k + l) % 2 == 0) ? 1.0 : -1.0;
          sum += sign * b(xs[i] - xis[l], ys[j] - etas[k]);
        }
      }
    }
  }
  return sum / (2 * kPi * (x2 - x1) * (y2 - y1));
}

double PointUnderCorner(double a, double b, double c) {
  const double x = a / c, y = b / c;
  return 1 / (2 * kPi) *
         (x / std::sqrt(1 + x * x) * std::atan(y / std::sqrt(1 + x * x)) +
          y / std::sqrt(1 + y * y) * std::atan(x / std::sqrt(1 + y * y)));
}

double CoaxialDisks(double r1, double r2, double h) {
  const double R1 = r1 / h, R2 = r2 / h, S = 1 + (1 + R2 * R2) / (R1 * R1);
  return 0.5 * (S - std::sqrt(S * S - 4 * (R2 / R1) * (R2 / R1)));
}

}  // namespace radiosity::testing
