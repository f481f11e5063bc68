#include "solver/output.h"

#include <OpenImageIO/imageio.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <set>
#include <utility>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "absl/strings/string_view.h"

namespace radiosity {

namespace {

constexpr double kPi = 3.14159265358979323846;

// ---------------------------------------------------------------------------------------------
// Camera text.

absl::Status CameraError(absl::string_view message) {
  return absl::InvalidArgumentError(absl::StrCat("camera: ", message));
}

// Parses a finite number; the error names the key and the offending text.
absl::Status ParseNumber(absl::string_view key, absl::string_view text, double* out) {
  if (!absl::SimpleAtod(text, out) || !std::isfinite(*out)) {
    return CameraError(absl::StrCat(key, ": '", text, "' is not a finite number"));
  }
  return absl::OkStatus();
}

absl::Status ParseVec3(absl::string_view key, absl::string_view text, Vec3* out) {
  std::vector<absl::string_view> parts = absl::StrSplit(text, ',');
  if (parts.size() != 3) {
    return CameraError(absl::StrCat(key, " needs three comma-separated numbers (", key,
                                    "=x,y,z), got '", text, "'"));
  }
  double c[3];
  for (int i = 0; i < 3; ++i) {
    absl::Status s = ParseNumber(key, parts[i], &c[i]);
    if (!s.ok()) return s;
  }
  *out = {c[0], c[1], c[2]};
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------------------------
// Interpolation.

// Bilinear interpolation of corner values {c00, c10, c01, c11} at local coordinates (s, t) in
// [0,1]^2: (1-s)(1-t) c00 + s(1-t) c10 + (1-s)t c01 + st c11.
Rgb Bilinear(const std::array<Rgb, 4>& c, double s, double t) {
  return c[0] * ((1 - s) * (1 - t)) + c[1] * (s * (1 - t)) + c[2] * ((1 - s) * t) + c[3] * (s * t);
}

// Element-local coordinates of face parameter point (u, v), clamped to the element's rectangle.
void LocalCoords(const Element& e, double u, double v, double* s, double* t) {
  double du = e.u1 - e.u0, dv = e.v1 - e.v0;
  *s = du > 0 ? std::clamp((u - e.u0) / du, 0.0, 1.0) : 0.5;
  *t = dv > 0 ? std::clamp((v - e.v0) / dv, 0.0, 1.0) : 0.5;
}

// The affine map of one half of a face (mesh.h): evaluating a piece on its own half keeps points
// on the diagonal u + v = 1 exact for both halves of a non-planar quad.
Vec3 EvalOnHalf(const MeshFace& f, int half, double u, double v) {
  return half == 0 ? f.p[0] + u * (f.p[1] - f.p[0]) + v * (f.p[3] - f.p[0])
                   : f.p[2] + (1 - u) * (f.p[3] - f.p[2]) + (1 - v) * (f.p[1] - f.p[2]);
}

Rgb SideRadiosity(const Solution& solution, int element, int side) {
  size_t slot = static_cast<size_t>(Slot(element, side));
  return slot < solution.radiosity.size() ? solution.radiosity[slot] : Rgb{};
}

// Per surface: whether it has a back side of its own (Material::HasBackSide).
std::vector<char> BackSides(const Scene& scene) {
  std::vector<char> back(scene.surfaces.size(), 0);
  for (size_t s = 0; s < scene.surfaces.size(); ++s) {
    int m = scene.surfaces[s].material;
    back[s] =
        m >= 0 && m < static_cast<int>(scene.materials.size()) && scene.materials[m].HasBackSide();
  }
  return back;
}

bool HasBack(const std::vector<char>& back, int surface) {
  return surface >= 0 && surface < static_cast<int>(back.size()) && back[surface];
}

// ---------------------------------------------------------------------------------------------
// Tone mapping (shared by the PNG and the PLY colours).

// Exposure k such that k x (99th percentile of the positive luminances) = 0.9; 1 if none.
double Exposure(std::vector<float>* luminance) {
  std::vector<float>& lum = *luminance;
  lum.erase(std::remove_if(lum.begin(), lum.end(), [](float l) { return !(l > 0); }), lum.end());
  if (lum.empty()) return 1;
  // Nearest-rank percentile: the smallest value with at least 99% of the values at or below it.
  size_t k = static_cast<size_t>(std::ceil(0.99 * static_cast<double>(lum.size()))) - 1;
  k = std::min(k, lum.size() - 1);
  std::nth_element(lum.begin(), lum.begin() + static_cast<std::ptrdiff_t>(k), lum.end());
  double p99 = lum[k];
  return p99 > 0 && std::isfinite(p99) ? 0.9 / p99 : 1;
}

// Linear value (already exposed) to an 8-bit sRGB code: clamp to [0,1], then the sRGB transfer
// function (IEC 61966-2-1): 12.92 c for c <= 0.0031308, else 1.055 c^(1/2.4) - 0.055.
uint8_t ToSrgb8(double c) {
  if (!(c > 0)) return 0;
  if (c >= 1) return 255;
  double s = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1 / 2.4) - 0.055;
  return static_cast<uint8_t>(std::lround(s * 255));
}

// ---------------------------------------------------------------------------------------------
// Text output.

// A file written through a 1 MiB stdio buffer; errors name the path and the system's reason.
class OutputFile {
 public:
  OutputFile(std::string path, std::string what) : path_(std::move(path)), what_(std::move(what)) {}
  ~OutputFile() {
    if (file_ != nullptr) std::fclose(file_);
  }
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  absl::Status Open() {
    file_ = std::fopen(path_.c_str(), "wb");
    if (file_ == nullptr) return Error(errno);
    std::setvbuf(file_, nullptr, _IOFBF, 1 << 20);
    return absl::OkStatus();
  }
  absl::Status Write(absl::string_view text) {
    if (text.empty()) return absl::OkStatus();
    if (std::fwrite(text.data(), 1, text.size(), file_) != text.size()) return Error(errno);
    return absl::OkStatus();
  }
  absl::Status Close() {
    std::FILE* f = file_;
    file_ = nullptr;
    bool failed = std::ferror(f) != 0;
    int err = errno;
    if (std::fclose(f) != 0 && !failed) {
      failed = true;
      err = errno;
    }
    return failed ? Error(err) : absl::OkStatus();
  }

 private:
  absl::Status Error(int err) const {
    // Exit code 1 (exit_codes.h): an I/O failure writing results.
    return absl::InternalError(absl::StrCat(path_, ": cannot write ", what_, ": ",
                                            err != 0 ? std::strerror(err) : "I/O error"));
  }

  std::string path_, what_;
  std::FILE* file_ = nullptr;
};

// Appends %.9g of v (std::to_chars with a precision is specified as printf's %.*g).
void AppendG9(std::string* out, double v) {
  char buf[40];
  auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 9);
  out->append(buf, r.ptr);
}

// Appends the shortest text that reads back as the same float.
void AppendFloat(std::string* out, float v) {
  char buf[40];
  auto r = std::to_chars(buf, buf + sizeof buf, v);
  out->append(buf, r.ptr);
}

void AppendInt(std::string* out, int64_t v) {
  char buf[24];
  auto r = std::to_chars(buf, buf + sizeof buf, v);
  out->append(buf, r.ptr);
}

// Items per block of parallel text formatting.
constexpr int64_t kBlock = 4096;

// Formats items [0, n) in blocks of kBlock, in parallel, and writes them in order.
// format(begin, end, &text) appends the text of items [begin, end). Batches bound the memory.
template <typename Format>
absl::Status WriteBlocks(OutputFile* file, int64_t n, const Format& format) {
  constexpr int64_t kBatch = 64;
  const int64_t blocks = (n + kBlock - 1) / kBlock;
  std::vector<std::string> text(static_cast<size_t>(std::min(blocks, kBatch)));
  for (int64_t b0 = 0; b0 < blocks; b0 += kBatch) {
    const int64_t b1 = std::min(blocks, b0 + kBatch);
    tbb::parallel_for(b0, b1, [&](int64_t b) {
      std::string& s = text[static_cast<size_t>(b - b0)];
      s.clear();
      format(b * kBlock, std::min(n, (b + 1) * kBlock), &s);
    });
    for (int64_t b = b0; b < b1; ++b) {
      absl::Status st = file->Write(text[static_cast<size_t>(b - b0)]);
      if (!st.ok()) return st;
    }
  }
  return absl::OkStatus();
}

// A CSV field: quoted (RFC 4180) only when it contains a separator, a quote or a line break.
std::string CsvField(const std::string& s) {
  if (s.find_first_of(",\"\r\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

absl::Status WriteCsvSide(const Mesh& mesh, const Solution& solution,
                          const std::vector<std::string>& names, const std::vector<char>& back,
                          int side, const std::string& path) {
  OutputFile file(path, side == 0 ? "elements CSV" : "back-side elements CSV");
  absl::Status st = file.Open();
  if (!st.ok()) return st;
  st = file.Write("surface,element,cx,cy,cz,area,r,g,b\n");
  if (!st.ok()) return st;
  const auto& elements = mesh.elements();
  st = WriteBlocks(
      &file, static_cast<int64_t>(elements.size()),
      [&](int64_t begin, int64_t end, std::string* out) {
        for (int64_t i = begin; i < end; ++i) {
          const Element& e = elements[i];
          if (side == 1 && !HasBack(back, e.surface)) continue;
          Rgb b = SideRadiosity(solution, static_cast<int>(i), side);
          out->append(e.surface >= 0 && e.surface < static_cast<int>(names.size())
                          ? names[e.surface]
                          : std::string("?"));
          out->push_back(',');
          AppendInt(out, e.index_in_surface);
          for (double x : {e.centroid.x, e.centroid.y, e.centroid.z, e.area, b.r, b.g, b.b}) {
            out->push_back(',');
            AppendG9(out, x);
          }
          out->push_back('\n');
        }
      });
  if (!st.ok()) return st;
  return file.Close();
}

// Deterministic per-pixel random numbers: SplitMix64 (Steele, Lea & Flood 2014).
class PixelRng {
 public:
  PixelRng(uint64_t x, uint64_t y) : state_(0x5EED5EED12345678ull ^ (x << 32) ^ y) { Next(); }
  uint64_t Next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1).
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }

 private:
  uint64_t state_;
};

}  // namespace

// ---------------------------------------------------------------------------------------------
// Camera.

std::string Camera::ToString() const {
  return absl::StrFormat("eye=%.9g,%.9g,%.9g look=%.9g,%.9g,%.9g up=%.9g,%.9g,%.9g fov=%.9g", eye.x,
                         eye.y, eye.z, look.x, look.y, look.z, up.x, up.y, up.z, fov);
}

absl::StatusOr<Camera> ParseCamera(const std::string& text, const Camera& base) {
  Camera camera = base;
  std::set<std::string> seen;
  for (absl::string_view token :
       absl::StrSplit(text, absl::ByAnyChar(" \t\r\n"), absl::SkipEmpty())) {
    size_t eq = token.find('=');
    if (eq == absl::string_view::npos) {
      return CameraError(
          absl::StrCat("expected key=value, got '", token, "' (keys: eye, look, up, fov)"));
    }
    absl::string_view key = token.substr(0, eq), value = token.substr(eq + 1);
    if (key != "eye" && key != "look" && key != "up" && key != "fov") {
      return CameraError(
          absl::StrCat("unknown key '", key, "' in '", token, "' (keys: eye, look, up, fov)"));
    }
    if (!seen.insert(std::string(key)).second) {
      return CameraError(absl::StrCat("key '", key, "' is given twice"));
    }
    absl::Status st;
    if (key == "fov") {
      st = ParseNumber(key, value, &camera.fov);
      if (st.ok() && !(camera.fov > 0 && camera.fov < 180)) {
        return CameraError(absl::StrCat("fov must be in (0, 180) degrees, got '", value, "'"));
      }
    } else {
      st = ParseVec3(key, value,
                     key == "eye"    ? &camera.eye
                     : key == "look" ? &camera.look
                                     : &camera.up);
    }
    if (!st.ok()) return st;
  }
  // The view must be well defined: a direction, and an up vector not along it.
  Vec3 dir = camera.look - camera.eye;
  if (!(Length(dir) > 0)) {
    return CameraError(absl::StrCat("eye and look are the same point ", camera.eye.ToString()));
  }
  if (!(Length(camera.up) > 0)) return CameraError("up must be a nonzero vector");
  if (Length(Cross(Normalize(dir), Normalize(camera.up))) < 1e-9) {
    return CameraError(absl::StrCat("up ", camera.up.ToString(),
                                    " is parallel to the view direction look - eye ",
                                    dir.ToString()));
  }
  return camera;
}

Camera DefaultCamera(const Mesh& mesh) {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  Vec3 lo{kInf, kInf, kInf}, hi{-kInf, -kInf, -kInf};
  for (const MeshFace& f : mesh.faces()) {
    for (const Vec3& p : f.p) {
      lo = Min(lo, p);
      hi = Max(hi, p);
    }
  }
  if (mesh.faces().empty()) lo = hi = Vec3{};
  const Vec3 half = (hi - lo) * 0.5;
  const Vec3 centre = (lo + hi) * 0.5 + mesh.origin();
  Camera camera;
  camera.fov = 40;
  camera.up = {0, 1, 0};
  camera.look = centre;
  // The near face of the box (half extents hx, hy at depth hz before the centre) fills a square
  // view of half-angle fov/2 at distance max(hx, hy) / tan(fov/2); the centre is hz further on.
  const double tan_half = std::tan(0.5 * camera.fov * kPi / 180);
  double distance = std::max(half.x, half.y) / tan_half + half.z;
  if (!(distance > 0)) distance = 1;
  camera.eye = centre - Vec3{0, 0, distance};
  return camera;
}

// ---------------------------------------------------------------------------------------------
// Corner radiosity.

std::vector<std::array<Rgb, 4>> CornerRadiosity(const Mesh& mesh, const Solution& solution) {
  const auto& elements = mesh.elements();
  const int64_t n = static_cast<int64_t>(elements.size());
  std::vector<std::array<Rgb, 4>> corners(static_cast<size_t>(2 * n));
  if (n == 0) return corners;

  // One entry per element corner, keyed by (face, round(u 2^20), round(v 2^20)); sorting groups
  // the corners that coincide on the face's lattice.
  struct Entry {
    uint64_t uv;
    int32_t face;
    int32_t index;  // 4 * element + corner (corner: 0 = (u0,v0), 1 = (u1,v0), 2 = (u0,v1), 3).
    bool operator<(const Entry& o) const {
      return face != o.face ? face < o.face : (uv != o.uv ? uv < o.uv : index < o.index);
    }
  };
  auto quantise = [](double x) { return static_cast<uint64_t>(std::llround(x * 1048576.0)); };
  std::vector<Entry> entries(static_cast<size_t>(4 * n));
  tbb::parallel_for(tbb::blocked_range<int64_t>(0, n), [&](const tbb::blocked_range<int64_t>& r) {
    for (int64_t e = r.begin(); e != r.end(); ++e) {
      const Element& el = elements[e];
      const double us[2] = {el.u0, el.u1}, vs[2] = {el.v0, el.v1};
      for (int c = 0; c < 4; ++c) {
        Entry& en = entries[static_cast<size_t>(4 * e + c)];
        en.uv = (quantise(us[c & 1]) << 32) | quantise(vs[c >> 1]);
        en.face = el.face;
        en.index = static_cast<int32_t>(4 * e + c);
      }
    }
  });
  tbb::parallel_sort(entries.begin(), entries.end());

  // Each group: B(corner) = sum(A_e B_e) / sum(A_e) over the element sides touching it, front
  // and back separately.
  const size_t total = entries.size();
  for (size_t i = 0; i < total;) {
    size_t j = i;
    double w = 0;
    Rgb front, back;
    for (; j < total && entries[j].face == entries[i].face && entries[j].uv == entries[i].uv; ++j) {
      int e = entries[j].index / 4;
      double a = elements[e].area;
      w += a;
      front += SideRadiosity(solution, e, 0) * a;
      back += SideRadiosity(solution, e, 1) * a;
    }
    if (w > 0) {
      front = front / w;
      back = back / w;
    } else {
      // Zero-area sides only (not made by Mesh::Build): a plain mean.
      front = back = Rgb{};
      for (size_t k = i; k < j; ++k) {
        front += SideRadiosity(solution, entries[k].index / 4, 0);
        back += SideRadiosity(solution, entries[k].index / 4, 1);
      }
      front = front / static_cast<double>(j - i);
      back = back / static_cast<double>(j - i);
    }
    for (size_t k = i; k < j; ++k) {
      int e = entries[k].index / 4, c = entries[k].index % 4;
      corners[Slot(e, 0)][c] = front;
      corners[Slot(e, 1)][c] = back;
    }
    i = j;
  }

  // T-vertices of an adaptively refined mesh: a corner of smaller elements lying inside the edge
  // of a larger neighbour (its midpoint, as refinement keeps neighbours within 2:1) takes the
  // value interpolated along that edge, so shading is continuous across the edge (no cracks).
  // Larger elements first, so that chains of constraints resolve from the coarsest edge down.
  std::vector<int32_t> order(static_cast<size_t>(n));
  for (int64_t e = 0; e < n; ++e) order[e] = static_cast<int32_t>(e);
  std::sort(order.begin(), order.end(), [&](int32_t a, int32_t b) {
    double sa = (elements[a].u1 - elements[a].u0) + (elements[a].v1 - elements[a].v0);
    double sb = (elements[b].u1 - elements[b].u0) + (elements[b].v1 - elements[b].v0);
    return sa != sb ? sa > sb : a < b;
  });
  // Edges as (corner a, corner b) in the 0=(u0,v0), 1=(u1,v0), 2=(u0,v1), 3=(u1,v1) numbering.
  static constexpr int kEdges[4][2] = {{0, 1}, {2, 3}, {0, 2}, {1, 3}};
  // A T-vertex's edge may end at another T-vertex (of a larger edge): repeat until nothing
  // changes, which takes at most as many passes as the quadtrees are deep.
  for (int pass = 0; pass < 64; ++pass) {
    bool changed = false;
    for (int32_t e : order) {
      const Element& el = elements[e];
      const double us[2] = {el.u0, el.u1}, vs[2] = {el.v0, el.v1};
      for (const auto& edge : kEdges) {
        double um = 0.5 * (us[edge[0] & 1] + us[edge[1] & 1]);
        double vm = 0.5 * (vs[edge[0] >> 1] + vs[edge[1] >> 1]);
        Entry key{(quantise(um) << 32) | quantise(vm), el.face, -1};
        auto it = std::lower_bound(entries.begin(), entries.end(), key);
        if (it == entries.end() || it->face != el.face || it->uv != key.uv) continue;
        for (int side = 0; side < 2; ++side) {
          const auto& c = corners[Slot(e, side)];
          Rgb mid = (c[edge[0]] + c[edge[1]]) * 0.5;
          for (auto k = it; k != entries.end() && k->face == el.face && k->uv == key.uv; ++k) {
            Rgb& value = corners[Slot(k->index / 4, side)][k->index % 4];
            if (!(value == mid)) {
              value = mid;
              changed = true;
            }
          }
        }
      }
    }
    if (!changed) break;
  }
  return corners;
}

// ---------------------------------------------------------------------------------------------
// Rendering.

namespace {

// Primary rays of a pinhole camera: orthonormal (right, up, forward); the image plane at distance
// 1 spans tan(fov/2) vertically and tan(fov/2) x width/height horizontally.
struct PrimaryRays {
  PrimaryRays(const Mesh& mesh, const Camera& camera, int width, int height)
      : eye(camera.eye - mesh.origin()), forward(Normalize(camera.look - camera.eye)) {
    right = Normalize(Cross(forward, camera.up));
    if (!(Length(right) > 0)) {
      Vec3 b;
      OrthonormalBasis(forward, &right, &b);
    }
    up = Cross(right, forward);
    tan_y = std::tan(0.5 * camera.fov * kPi / 180);
    tan_x = tan_y * width / height;
    w = width;
    h = height;
  }
  // Unit direction through image position (x + jx, y + jy) (pixels from the top left).
  Vec3 Direction(double x, double y) const {
    // Normalised device coordinates in [-1, 1], +y up.
    const double px = 2 * x / w - 1;
    const double py = 1 - 2 * y / h;
    return Normalize(forward + right * (px * tan_x) + up * (py * tan_y));
  }
  Vec3 eye, forward, right, up;
  double tan_x = 0, tan_y = 0;
  int w = 1, h = 1;
};

// The first element side seen along a primary ray from `eye`, skipping the backs of one-sided
// surfaces (up to 16 of them): its slot, or -1; (u, v) of the hit on its face.
int VisibleSlot(const Mesh& mesh, const Visibility& visibility, const std::vector<char>& back,
                const Vec3& eye, const Vec3& dir, size_t slots, double* u, double* v) {
  const double eps = visibility.epsilon();
  double tnear = 0;
  int skipped = -1;
  for (int pass = 0; pass <= 16; ++pass) {
    Hit hit =
        visibility.Intersect(eye, dir, tnear, std::numeric_limits<double>::infinity(), skipped);
    if (!hit.valid()) return -1;
    const MeshFace& f = mesh.faces()[hit.face];
    const int side = Dot(dir, f.normal[f.Half(hit.u, hit.v)]) < 0 ? 0 : 1;
    const int e = mesh.FindElement(hit.face, hit.u, hit.v);
    if (e >= 0 && (side == 0 || HasBack(back, f.surface)) &&
        static_cast<size_t>(Slot(e, side)) < slots) {
      *u = hit.u;
      *v = hit.v;
      return Slot(e, side);
    }
    // Past the hit by the scene epsilon, and by more than float rounding of t; the face just
    // skipped is also ignored outright.
    tnear = hit.t + std::max(eps, 1e-6 * hit.t);
    skipped = hit.face;
  }
  return -1;
}

}  // namespace

Image RenderImage(const Mesh& mesh, const Visibility& visibility, const Solution& solution,
                  const std::vector<std::array<Rgb, 4>>& corners, const Scene& scene,
                  const Camera& camera, int width, int height, int samples_per_pixel) {
  Image image;
  if (width <= 0 || height <= 0) return image;
  image.width = width;
  image.height = height;
  image.rgb.assign(3 * static_cast<size_t>(width) * height, 0.0f);
  const int spp = std::max(1, samples_per_pixel);
  const std::vector<char> back = BackSides(scene);
  const PrimaryRays rays(mesh, camera, width, height);
  // Stratified jitter on a g x g grid, and plain random positions for the remaining samples.
  const int grid = static_cast<int>(std::sqrt(static_cast<double>(spp)));
  const auto& elements = mesh.elements();

  // Radiance along a primary ray (unit dir): L = B / pi for a diffuse surface.
  auto trace = [&](const Vec3& dir) -> Rgb {
    double u, v;
    const int slot = VisibleSlot(mesh, visibility, back, rays.eye, dir, corners.size(), &u, &v);
    if (slot < 0) return {};
    double s, t;
    LocalCoords(elements[slot >> 1], u, v, &s, &t);
    return Bilinear(corners[slot], s, t) / kPi;
  };

  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int x = 0; x < width; ++x) {
        PixelRng rng(static_cast<uint64_t>(x), static_cast<uint64_t>(y));
        Rgb sum;
        for (int k = 0; k < spp; ++k) {
          double jx, jy;
          if (k < grid * grid) {
            jx = (k % grid + rng.Uniform()) / grid;
            jy = (k / grid + rng.Uniform()) / grid;
          } else {
            jx = rng.Uniform();
            jy = rng.Uniform();
          }
          sum += trace(rays.Direction(x + jx, y + jy));
        }
        sum = sum / spp;
        float* out = &image.rgb[3 * (static_cast<size_t>(y) * width + x)];
        out[0] = static_cast<float>(sum.r);
        out[1] = static_cast<float>(sum.g);
        out[2] = static_cast<float>(sum.b);
      }
    }
  });
  return image;
}

void DrawWireframe(const Mesh& mesh, const Visibility& visibility, const Scene& scene,
                   const Camera& camera, const std::vector<int>& pieces, Image* image) {
  const int width = image->width, height = image->height;
  if (width <= 0 || height <= 0 || image->rgb.size() != 3 * static_cast<size_t>(width) * height) {
    return;
  }
  const std::vector<char> back = BackSides(scene);
  const PrimaryRays rays(mesh, camera, width, height);
  const size_t slots = 2 * mesh.elements().size();
  // What each pixel centre sees: the piece (or element) and the side, -1 for nothing.
  std::vector<int64_t> id(static_cast<size_t>(width) * height, -1);
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int y = rows.begin(); y != rows.end(); ++y) {
      for (int x = 0; x < width; ++x) {
        double u, v;
        const int slot = VisibleSlot(mesh, visibility, back, rays.eye,
                                     rays.Direction(x + 0.5, y + 0.5), slots, &u, &v);
        if (slot < 0) continue;
        const int e = slot >> 1;
        const int64_t piece =
            static_cast<size_t>(e) < pieces.size() && pieces[e] >= 0 ? pieces[e] : e;
        id[static_cast<size_t>(y) * width + x] = 2 * piece + (slot & 1);
      }
    }
  });
  // An edge pixel sees a different piece than its right or lower neighbour: darkened, so the
  // lines stay visible over bright and mid-tone shading alike.
  constexpr float kLine = 0.15f;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const size_t i = static_cast<size_t>(y) * width + x;
      const bool edge = (x + 1 < width && id[i + 1] != id[i]) ||
                        (y + 1 < height && id[i + width] != id[i]);
      if (!edge || id[i] < 0) continue;
      for (int c = 0; c < 3; ++c) image->rgb[3 * i + c] *= kLine;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Images.

namespace {

absl::Status WriteOiio(const std::string& path, const OIIO::ImageSpec& spec, OIIO::TypeDesc type,
                       const void* data) {
  auto out = OIIO::ImageOutput::create(path);
  if (!out) {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": cannot write image: ", OIIO::geterror()));
  }
  if (!out->open(path, spec)) {
    return absl::InternalError(absl::StrCat(path, ": cannot write image: ", out->geterror()));
  }
  if (!out->write_image(type, data)) {
    std::string message = out->geterror();
    out->close();
    return absl::InternalError(absl::StrCat(path, ": cannot write image: ", message));
  }
  if (!out->close()) {
    return absl::InternalError(absl::StrCat(path, ": cannot write image: ", out->geterror()));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status WriteImage(const Image& image, const std::string& exr_path,
                        const std::string& png_path) {
  const size_t pixels = static_cast<size_t>(std::max(0, image.width)) * std::max(0, image.height);
  if (image.width <= 0 || image.height <= 0 || image.rgb.size() != 3 * pixels) {
    return absl::InvalidArgumentError(absl::StrFormat("cannot write a %dx%d image with %d values",
                                                      image.width, image.height, image.rgb.size()));
  }
  if (!exr_path.empty()) {
    OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::HALF);
    spec.attribute("oiio:ColorSpace", "Linear");
    spec.attribute("compression", "zip");
    absl::Status st = WriteOiio(exr_path, spec, OIIO::TypeDesc::FLOAT, image.rgb.data());
    if (!st.ok()) return st;
  }
  if (!png_path.empty()) {
    std::vector<float> lum(pixels);
    for (size_t i = 0; i < pixels; ++i) {
      lum[i] = static_cast<float>(
          Rgb(image.rgb[3 * i], image.rgb[3 * i + 1], image.rgb[3 * i + 2]).Luminance());
    }
    const double exposure = Exposure(&lum);
    std::vector<uint8_t> bytes(3 * pixels);
    for (size_t i = 0; i < 3 * pixels; ++i) bytes[i] = ToSrgb8(exposure * image.rgb[i]);
    OIIO::ImageSpec spec(image.width, image.height, 3, OIIO::TypeDesc::UINT8);
    spec.attribute("oiio:ColorSpace", "sRGB");
    absl::Status st = WriteOiio(png_path, spec, OIIO::TypeDesc::UINT8, bytes.data());
    if (!st.ok()) return st;
  }
  return absl::OkStatus();
}

// ---------------------------------------------------------------------------------------------
// elements.csv

absl::Status WriteElementsCsv(const Scene& scene, const Mesh& mesh, const Solution& solution,
                              const std::string& path, const std::string& back_path) {
  std::vector<std::string> names;
  names.reserve(scene.surfaces.size());
  for (const Surface& s : scene.surfaces) names.push_back(CsvField(s.name));
  const std::vector<char> back = BackSides(scene);
  absl::Status st = WriteCsvSide(mesh, solution, names, back, 0, path);
  if (!st.ok()) return st;
  bool any_back = false;
  for (const Element& e : mesh.elements()) {
    if (HasBack(back, e.surface)) {
      any_back = true;
      break;
    }
  }
  if (!any_back || back_path.empty()) return absl::OkStatus();
  return WriteCsvSide(mesh, solution, names, back, 1, back_path);
}

// ---------------------------------------------------------------------------------------------
// mesh.ply

absl::Status WritePly(const Scene& scene, const Mesh& mesh, const Solution& solution,
                      const std::vector<std::array<Rgb, 4>>& corners, const std::string& path) {
  const auto& elements = mesh.elements();
  const auto& faces = mesh.faces();
  const int64_t n = static_cast<int64_t>(elements.size());
  if (corners.size() < static_cast<size_t>(2 * n)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: cannot write PLY: %d corner sets for %d elements", path, corners.size(), n));
  }
  const std::vector<char> back = BackSides(scene);
  const Vec3 origin = mesh.origin();

  // Calls emit(position in scene coordinates, s, t) for each vertex of the element's polygon
  // pieces, in order, where (s, t) are the element-local coordinates for Bilinear; returns the
  // piece count.
  auto for_each_vertex = [&](int64_t i, std::array<ElementPiece, 2>* pieces, auto&& emit) {
    const Element& e = elements[i];
    const MeshFace& f = faces[e.face];
    const int np = mesh.Pieces(static_cast<int>(i), pieces);
    for (int k = 0; k < np; ++k) {
      const ElementPiece& pc = (*pieces)[k];
      for (int j = 0; j < pc.n; ++j) {
        const double u = pc.uv[2 * j], v = pc.uv[2 * j + 1];
        double s, t;
        LocalCoords(e, u, v, &s, &t);
        emit(EvalOnHalf(f, pc.half, u, v) + origin, s, t);
      }
    }
    return np;
  };
  auto sides_of = [&](int64_t i) { return HasBack(back, elements[i].surface) ? 2 : 1; };

  // Pass 1: vertex and face counts per block of elements (the blocks of WriteBlocks), for the
  // header and the face indices.
  const int64_t blocks = (n + kBlock - 1) / kBlock;
  std::vector<int64_t> vertex_start(static_cast<size_t>(blocks + 1), 0);
  std::vector<int64_t> face_start(static_cast<size_t>(blocks + 1), 0);
  tbb::parallel_for(int64_t{0}, blocks, [&](int64_t b) {
    std::array<ElementPiece, 2> pieces;
    int64_t nv = 0, nf = 0;
    for (int64_t i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i) {
      int np = mesh.Pieces(static_cast<int>(i), &pieces);
      int verts = 0;
      for (int k = 0; k < np; ++k) verts += pieces[k].n;
      nv += static_cast<int64_t>(verts) * sides_of(i);
      nf += static_cast<int64_t>(np) * sides_of(i);
    }
    vertex_start[b + 1] = nv;
    face_start[b + 1] = nf;
  });
  for (int64_t b = 0; b < blocks; ++b) {
    vertex_start[b + 1] += vertex_start[b];
    face_start[b + 1] += face_start[b];
  }
  const int64_t num_vertices = vertex_start[blocks], num_faces = face_start[blocks];

  // Pass 2: exposure from the luminance of all vertex values, as for the PNG.
  std::vector<float> lum(static_cast<size_t>(num_vertices));
  tbb::parallel_for(int64_t{0}, blocks, [&](int64_t b) {
    std::array<ElementPiece, 2> pieces;
    int64_t next = vertex_start[b];
    for (int64_t i = b * kBlock; i < std::min(n, (b + 1) * kBlock); ++i) {
      for (int side = 0; side < sides_of(i); ++side) {
        const auto& c = corners[Slot(static_cast<int>(i), side)];
        for_each_vertex(i, &pieces, [&](const Vec3&, double s, double t) {
          lum[next++] = static_cast<float>(Bilinear(c, s, t).Luminance());
        });
      }
    }
  });
  const double exposure = Exposure(&lum);
  lum = std::vector<float>();

  OutputFile file(path, "PLY mesh");
  absl::Status st = file.Open();
  if (!st.ok()) return st;
  st = file.Write(absl::StrCat(
      "ply\nformat ascii 1.0\n"
      "comment radiosity mesh: one polygon per element side, coordinates in scene units\n"
      "comment red green blue: tone-mapped sRGB; r g b: linear radiosity (W/m^2 per channel)\n"
      "element vertex ",
      num_vertices,
      "\nproperty float x\nproperty float y\nproperty float z\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\n"
      "property float r\nproperty float g\nproperty float b\n"
      "element face ",
      num_faces, "\nproperty list uchar int vertex_indices\nend_header\n"));
  if (!st.ok()) return st;

  // Vertices: per element, the front side's vertices, then the back side's (same positions).
  st = WriteBlocks(&file, n, [&](int64_t begin, int64_t end, std::string* out) {
    std::array<ElementPiece, 2> pieces;
    for (int64_t i = begin; i < end; ++i) {
      for (int side = 0; side < sides_of(i); ++side) {
        const auto& c = corners[Slot(static_cast<int>(i), side)];
        for_each_vertex(i, &pieces, [&](const Vec3& p, double s, double t) {
          const Rgb b = Bilinear(c, s, t);
          AppendFloat(out, static_cast<float>(p.x));
          out->push_back(' ');
          AppendFloat(out, static_cast<float>(p.y));
          out->push_back(' ');
          AppendFloat(out, static_cast<float>(p.z));
          for (int ch = 0; ch < 3; ++ch) {
            out->push_back(' ');
            AppendInt(out, ToSrgb8(exposure * b[ch]));
          }
          for (int ch = 0; ch < 3; ++ch) {
            out->push_back(' ');
            AppendFloat(out, static_cast<float>(b[ch]));
          }
          out->push_back('\n');
        });
      }
    }
  });
  if (!st.ok()) return st;

  // Faces: front pieces counter-clockwise about the normal (mesh.h's maps preserve the (u, v)
  // orientation on both halves), back pieces reversed.
  st = WriteBlocks(&file, n, [&](int64_t begin, int64_t end, std::string* out) {
    std::array<ElementPiece, 2> pieces;
    int64_t next = vertex_start[begin / kBlock];
    for (int64_t i = begin; i < end; ++i) {
      const int np = mesh.Pieces(static_cast<int>(i), &pieces);
      for (int side = 0; side < sides_of(i); ++side) {
        for (int k = 0; k < np; ++k) {
          const int m = pieces[k].n;
          AppendInt(out, m);
          for (int j = 0; j < m; ++j) {
            out->push_back(' ');
            AppendInt(out, next + (side == 0 ? j : m - 1 - j));
          }
          out->push_back('\n');
          next += m;
        }
      }
    }
  });
  if (!st.ok()) return st;
  return file.Close();
}

}  // namespace radiosity
