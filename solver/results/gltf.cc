#include "solver/results/gltf.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>

#include "absl/strings/str_format.h"
#include "solver/results/element_polygons.h"
#include "solver/results/text_writer.h"
#include "solver/results/tone_map.h"

namespace radiosity {
namespace {

constexpr int kFloat = 5126, kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;

template <typename T>
void Append(std::string* out, const std::vector<T>& values) {
  out->append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
  while (out->size() % 4 != 0) out->push_back('\0');
}

void AppendU32(std::string* out, uint32_t v) { out->append(reinterpret_cast<const char*>(&v), 4); }

}  // namespace

absl::Status WriteGlb(const Mesh& mesh, const std::vector<std::array<Rgb, 4>>& corners,
                      const std::string& path) {
  const int64_t n = static_cast<int64_t>(mesh.elements().size());
  if (corners.size() < static_cast<size_t>(2 * n)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: cannot write glTF: %d corner sets for %d elements", path, corners.size(), n));
  }
  std::vector<float> positions, radiosity;
  std::vector<uint32_t> indices;
  std::vector<int> sizes;
  for (int64_t i = 0; i < n; ++i) {
    sizes.clear();
    ElementPieceSizes(mesh, i, &sizes);
    for (int side = 0; side < DrawnSides(mesh, i); ++side) {
      const size_t first = positions.size() / 3;
      ForEachElementVertex(mesh, i, [&](const Vec3& p, int face, double u, double v) {
        const Rgb b = InterpolatedRadiosity(mesh, corners, static_cast<int>(i), side, face, u, v);
        positions.insert(positions.end(), {static_cast<float>(p.x), static_cast<float>(p.y),
                                           static_cast<float>(p.z)});
        radiosity.insert(radiosity.end(), {static_cast<float>(b.r), static_cast<float>(b.g),
                                           static_cast<float>(b.b)});
      });
      // Each piece a fan of triangles; the back's winding reversed.
      size_t start = first;
      for (const int m : sizes) {
        for (int j = 1; j + 1 < m; ++j) {
          const uint32_t a = static_cast<uint32_t>(start), b = static_cast<uint32_t>(start + j),
                         d = static_cast<uint32_t>(start + j + 1);
          if (side == kFront) {
            indices.insert(indices.end(), {a, b, d});
          } else {
            indices.insert(indices.end(), {a, d, b});
          }
        }
        start += static_cast<size_t>(m);
      }
    }
    if (positions.size() / 3 > std::numeric_limits<uint32_t>::max()) {
      return absl::ResourceExhaustedError(
          absl::StrFormat("%s: more than 2^32 vertices for one glTF mesh", path));
    }
  }
  const size_t vertices = positions.size() / 3;
  std::vector<float> luminance(vertices);
  for (size_t v = 0; v < vertices; ++v) {
    luminance[v] = static_cast<float>(
        Rgb(radiosity[3 * v], radiosity[3 * v + 1], radiosity[3 * v + 2]).Luminance());
  }
  const double exposure = Exposure(&luminance);
  luminance = std::vector<float>();
  std::vector<float> colors(radiosity.size());
  for (size_t k = 0; k < radiosity.size(); ++k) {
    colors[k] = static_cast<float>(std::clamp(exposure * radiosity[k], 0.0, 1.0));
  }
  float lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
  for (size_t v = 0; v < vertices; ++v) {
    for (int a = 0; a < 3; ++a) {
      const float x = positions[3 * v + a];
      lo[a] = v == 0 ? x : std::min(lo[a], x);
      hi[a] = v == 0 ? x : std::max(hi[a], x);
    }
  }

  std::string bin;
  nlohmann::json views = nlohmann::json::array(), accessors = nlohmann::json::array();
  auto add_view = [&](const auto& values, int target) {
    const size_t offset = bin.size();
    Append(&bin, values);
    views.push_back({{"buffer", 0},
                     {"byteOffset", offset},
                     {"byteLength", values.size() * sizeof(values[0])},
                     {"target", target}});
    return views.size() - 1;
  };
  nlohmann::json position = {{"bufferView", add_view(positions, kArrayBuffer)},
                             {"componentType", kFloat},
                             {"count", vertices},
                             {"type", "VEC3"},
                             {"min", {lo[0], lo[1], lo[2]}},
                             {"max", {hi[0], hi[1], hi[2]}}};
  accessors.push_back(position);
  accessors.push_back({{"bufferView", add_view(colors, kArrayBuffer)},
                       {"componentType", kFloat},
                       {"count", vertices},
                       {"type", "VEC3"}});
  accessors.push_back({{"bufferView", add_view(radiosity, kArrayBuffer)},
                       {"componentType", kFloat},
                       {"count", vertices},
                       {"type", "VEC3"}});
  accessors.push_back({{"bufferView", add_view(indices, kElementArrayBuffer)},
                       {"componentType", kUnsignedInt},
                       {"count", indices.size()},
                       {"type", "SCALAR"}});
  nlohmann::json doc;
  doc["asset"]["version"] = "2.0";
  doc["asset"]["generator"] = "radiosity";
  doc["asset"]["extras"]["radiosity_exposure"] = exposure;
  doc["asset"]["extras"]["radiosity_units"] =
      "_RADIOSITY: W/m^2 per channel (per square scene unit); COLOR_0: _RADIOSITY x "
      "radiosity_exposure, clamped to [0, 1], linear";
  doc["extensionsUsed"] = nlohmann::json::array({"KHR_materials_unlit"});
  doc["scene"] = 0;
  doc["scenes"] = nlohmann::json::array({{{"nodes", nlohmann::json::array({0})}}});
  nlohmann::json node;
  node["name"] = "radiosity";
  node["mesh"] = 0;
  doc["nodes"] = nlohmann::json::array({node});
  nlohmann::json material;
  material["name"] = "baked light";
  material["pbrMetallicRoughness"]["baseColorFactor"] = nlohmann::json::array({1, 1, 1, 1});
  material["pbrMetallicRoughness"]["metallicFactor"] = 0;
  material["extensions"]["KHR_materials_unlit"] = nlohmann::json::object();
  doc["materials"] = nlohmann::json::array({material});
  nlohmann::json primitive;
  primitive["attributes"]["POSITION"] = 0;
  primitive["attributes"]["COLOR_0"] = 1;
  primitive["attributes"]["_RADIOSITY"] = 2;
  primitive["indices"] = 3;
  primitive["material"] = 0;
  primitive["mode"] = 4;
  nlohmann::json gltf_mesh;
  gltf_mesh["name"] = "radiosity";
  gltf_mesh["primitives"] = nlohmann::json::array({primitive});
  doc["meshes"] = nlohmann::json::array({gltf_mesh});
  nlohmann::json buffer;
  buffer["byteLength"] = bin.size();
  doc["buffers"] = nlohmann::json::array({buffer});
  doc["bufferViews"] = views;
  doc["accessors"] = accessors;
  std::string json = doc.dump();
  while (json.size() % 4 != 0) json.push_back(' ');
  const uint64_t total = 12 + 8 + json.size() + 8 + bin.size();
  if (total > std::numeric_limits<uint32_t>::max()) {
    return absl::ResourceExhaustedError(
        absl::StrFormat("%s: %d bytes exceed binary glTF's 4 GiB", path, total));
  }
  std::string header = "glTF";
  AppendU32(&header, 2);
  AppendU32(&header, static_cast<uint32_t>(total));
  AppendU32(&header, static_cast<uint32_t>(json.size()));
  header += "JSON";

  OutputFile file(path, "binary glTF mesh");
  absl::Status st = file.Open();
  if (!st.ok()) return st;
  std::string bin_header;
  AppendU32(&bin_header, static_cast<uint32_t>(bin.size()));
  bin_header += std::string("BIN\0", 4);
  for (const std::string* part : {&header, &json, &bin_header, &bin}) {
    st = file.Write(*part);
    if (!st.ok()) return st;
  }
  return file.Close();
}

}  // namespace radiosity
