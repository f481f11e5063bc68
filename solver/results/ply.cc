#include "solver/results/ply.h"

#include <algorithm>
#include <cstdint>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "solver/geometry/interpolation.h"
#include "solver/results/element_polygons.h"
#include "solver/results/text_writer.h"
#include "solver/results/tone_map.h"

namespace radiosity {

absl::Status WritePly(const Mesh& mesh, const Solution& solution,
                      const std::vector<std::array<Rgb, 4>>& corners, const std::string& path) {
  const auto& elements = mesh.elements();
  const int64_t n = static_cast<int64_t>(elements.size());
  if (corners.size() < static_cast<size_t>(2 * n)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: cannot write PLY: %d corner sets for %d elements", path, corners.size(), n));
  }
  auto sides_of = [&](int64_t i) { return DrawnSides(mesh, i); };

  // Pass 1: vertex and face counts per block of elements (the blocks of WriteBlocks), for the
  // header and the face indices.
  const int64_t blocks = (n + kTextBlock - 1) / kTextBlock;
  std::vector<int64_t> vertex_start(static_cast<size_t>(blocks + 1), 0);
  std::vector<int64_t> face_start(static_cast<size_t>(blocks + 1), 0);
  tbb::parallel_for(int64_t{0}, blocks, [&](int64_t b) {
    std::vector<int> sizes;
    int64_t nv = 0, nf = 0;
    for (int64_t i = b * kTextBlock; i < std::min(n, (b + 1) * kTextBlock); ++i) {
      sizes.clear();
      ElementPieceSizes(mesh, i, &sizes);
      int verts = 0;
      for (const int m : sizes) verts += m;
      nv += static_cast<int64_t>(verts) * sides_of(i);
      nf += static_cast<int64_t>(sizes.size()) * sides_of(i);
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
    int64_t next = vertex_start[b];
    for (int64_t i = b * kTextBlock; i < std::min(n, (b + 1) * kTextBlock); ++i) {
      for (int side = 0; side < sides_of(i); ++side) {
        ForEachElementVertex(mesh, i, [&](const Vec3&, int face, double u, double v) {
          lum[next++] = static_cast<float>(
              InterpolatedRadiosity(mesh, corners, static_cast<int>(i), side, face, u, v)
                  .Luminance());
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
    for (int64_t i = begin; i < end; ++i) {
      for (int side = 0; side < sides_of(i); ++side) {
        ForEachElementVertex(mesh, i, [&](const Vec3& p, int face, double u, double v) {
          const Rgb b = InterpolatedRadiosity(mesh, corners, static_cast<int>(i), side, face, u, v);
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
    std::vector<int> sizes;
    int64_t next = vertex_start[begin / kTextBlock];
    for (int64_t i = begin; i < end; ++i) {
      sizes.clear();
      ElementPieceSizes(mesh, i, &sizes);
      for (int side = 0; side < sides_of(i); ++side) {
        for (const int m : sizes) {
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
