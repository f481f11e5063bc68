#include "solver/input/scene_codec.h"

#include <algorithm>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <map>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/strip.h"
#include "google/protobuf/util/json_util.h"
#include "solver/input/obj_loader.h"
#include "solver/util/file_io.h"

namespace radiosity {
namespace {

// The most material names listed in an "unknown material" message.
constexpr int kMaxListedMaterials = 20;

// "source: " or "" when there is no source.
std::string Prefix(const std::string& source) {
  return source.empty() ? std::string() : absl::StrCat(source, ": ");
}

std::string Label(const char* list, int index, const std::string& name) {
  return absl::StrCat(list, "[", index, "] ('", name, "')");
}

Rgb ToRgb(const radiosity::v1::Color& c) { return {c.r(), c.g(), c.b()}; }

void FromRgb(const Rgb& rgb, radiosity::v1::Color* c) {
  c->set_r(rgb.r);
  c->set_g(rgb.g);
  c->set_b(rgb.b);
}

// Checks one material's colors against docs/guide/scenes.md; `where` is "source: materials[i]
// ('name')".
absl::Status CheckMaterial(const radiosity::v1::Material& m, const std::string& where) {
  static constexpr const char* kChannel[] = {"r", "g", "b"};
  const Rgb kd = ToRgb(m.reflectance());
  const Rgb ke = ToRgb(m.emission());
  const Rgb tf = ToRgb(m.transmittance());
  const std::pair<const char*, const Rgb*> colors[] = {
      {"reflectance", &kd}, {"emission", &ke}, {"transmittance", &tf}};
  for (const auto& [field, rgb] : colors) {
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite((*rgb)[c])) {
        return absl::InvalidArgumentError(absl::StrCat(where, ".", field, ".", kChannel[c], ": ",
                                                       (*rgb)[c], " is not a finite number"));
      }
    }
  }
  for (int c = 0; c < 3; ++c) {
    std::string ch = kChannel[c];
    if (kd[c] < 0 || kd[c] >= 1) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ".reflectance.", ch, ": ", kd[c], " is outside [0, 1)"));
    }
    if (ke[c] < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ".emission.", ch, ": ", ke[c], " is negative"));
    }
    if (tf[c] < 0 || tf[c] > 1) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ".transmittance.", ch, ": ", tf[c], " is outside [0, 1]"));
    }
    if (kd[c] + tf[c] > 1) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": reflectance.", ch,
                                                     " + transmittance.", ch, " = ", kd[c], " + ",
                                                     tf[c], " = ", kd[c] + tf[c], " is above 1"));
    }
  }
  return absl::OkStatus();
}

std::string DefinedMaterials(const radiosity::v1::Scene& msg) {
  if (msg.materials_size() == 0) return "no materials are defined";
  std::vector<std::string> names;
  for (int i = 0; i < msg.materials_size() && i < kMaxListedMaterials; ++i) {
    names.push_back(absl::StrCat("'", msg.materials(i).name(), "'"));
  }
  std::string list = absl::StrJoin(names, ", ");
  if (msg.materials_size() > kMaxListedMaterials) {
    absl::StrAppend(&list, " and ", msg.materials_size() - kMaxListedMaterials, " more");
  }
  return absl::StrCat("defined: ", list);
}

// Rewrites an error of the protobuf JSON parser (3.21) in our style, naming the file.
// Syntax errors come as "<message>\n<up to 40 characters of context>\n<spaces>^"; the context is
// located in `text` to find the line and column (left out when it is not found exactly once).
// Type errors come as "(field.path): <message>" and become "file: field.path: <message>".
std::string FormatJsonError(const std::string& path, const std::string& text,
                            const std::string& error) {
  const size_t first_newline = error.find('\n');
  const size_t last_newline = error.rfind('\n');
  if (first_newline != std::string::npos && last_newline > first_newline) {
    const std::string message = error.substr(0, first_newline);
    const std::string context = error.substr(first_newline + 1, last_newline - first_newline - 1);
    const std::string caret = error.substr(last_newline + 1);
    const size_t found = context.empty() ? std::string::npos : text.find(context);
    const size_t offset = found + caret.size() - 1;  // Of the character the caret points at.
    if (caret.empty() || found == std::string::npos ||
        text.find(context, found + 1) != std::string::npos || caret.back() != '^' ||
        offset > text.size()) {
      return absl::StrCat(path, ": invalid JSON: ", message);
    }
    const size_t line = 1 + std::count(text.begin(), text.begin() + offset, '\n');
    const size_t column = line == 1 ? offset + 1 : offset - text.rfind('\n', offset - 1);
    return absl::StrCat(path, ":", line, ":", column, ": invalid JSON: ", message);
  }
  if (error.size() > 1 && error[0] == '(') {
    const size_t close = error.find("): ");
    if (close != std::string::npos) {
      return absl::StrCat(path, ": ", error.substr(1, close - 1), ": ", error.substr(close + 3));
    }
  }
  return absl::StrCat(path, ": not a valid JSON Scene message: ", absl::StripPrefix(error, ": "));
}

}  // namespace

absl::StatusOr<Scene> SceneFromProto(const radiosity::v1::Scene& msg, const std::string& source,
                                     std::vector<std::string>* warnings) {
  const std::string prefix = Prefix(source);
  Scene scene;
  scene.source = source;

  // Materials: unique non-empty names, physically valid colors.
  std::map<std::string, int> material_index;
  for (int i = 0; i < msg.materials_size(); ++i) {
    const radiosity::v1::Material& m = msg.materials(i);
    const std::string where = absl::StrCat(prefix, Label("materials", i, m.name()));
    if (m.name().empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat(prefix, "materials[", i, "].name: a material needs a non-empty name"));
    }
    auto [it, inserted] = material_index.emplace(m.name(), i);
    if (!inserted) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ".name: duplicate material name (also materials[", it->second, "])"));
    }
    if (absl::Status s = CheckMaterial(m, where); !s.ok()) return s;
    Material& out = scene.materials.emplace_back();
    out.name = m.name();
    out.reflectance = ToRgb(m.reflectance());
    out.emission = ToRgb(m.emission());
    out.transmittance = ToRgb(m.transmittance());
    out.two_sided = m.two_sided();
    out.mirror = ToRgb(m.mirror());
    out.glossy = ToRgb(m.glossy());
    out.glossy_exponent = m.glossy_exponent();
    out.glass = ToRgb(m.glass());
    out.ior = m.ior() == 0 ? 1.5 : m.ior();
    out.refracts = m.refracts();
    if (absl::Status s = ValidateSpecularParts(out, absl::StrCat(where, ": ")); !s.ok()) return s;
  }

  // Surfaces: unique non-empty names, a known material, finite vertices, indices in range.
  std::map<std::string, int> surface_index;
  for (int i = 0; i < msg.surfaces_size(); ++i) {
    const radiosity::v1::Surface& s = msg.surfaces(i);
    const std::string where = absl::StrCat(prefix, Label("surfaces", i, s.name()));
    if (s.name().empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat(prefix, "surfaces[", i, "].name: a surface needs a non-empty name"));
    }
    auto [it, inserted] = surface_index.emplace(s.name(), i);
    if (!inserted) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ".name: duplicate surface name (also surfaces[", it->second, "])"));
    }
    if (s.material().empty()) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ".material: no material given (", DefinedMaterials(msg), ")"));
    }
    auto material = material_index.find(s.material());
    if (material == material_index.end()) {
      return absl::InvalidArgumentError(absl::StrCat(
          where, ".material: unknown material '", s.material(), "' (", DefinedMaterials(msg), ")"));
    }
    if (s.vertices_size() % 3 != 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ".vertices: ", s.vertices_size(),
                       " numbers is not a multiple of 3 (vertices are packed x, y, z triples)"));
    }
    for (int k = 0; k < s.vertices_size(); ++k) {
      if (!std::isfinite(s.vertices(k))) {
        return absl::InvalidArgumentError(absl::StrCat(
            where, ".vertices[", k, "]: ", s.vertices(k), " (", std::string(1, "xyz"[k % 3]),
            " of vertex ", k / 3, ") is not a finite number"));
      }
    }
    const int64_t num_vertices = s.vertices_size() / 3;
    if (static_cast<int64_t>(scene.vertices.size()) + num_vertices > INT_MAX) {
      return absl::InvalidArgumentError(absl::StrCat(where, ".vertices: too many vertices"));
    }
    if (s.faces_size() == 0 && warnings != nullptr) {
      warnings->push_back(absl::StrCat(where, ": the surface has no faces"));
    }
    const int offset = static_cast<int>(scene.vertices.size());
    const int surface = static_cast<int>(scene.surfaces.size());
    for (int f = 0; f < s.faces_size(); ++f) {
      const radiosity::v1::Face& face = s.faces(f);
      if (face.indices_size() < 3) {
        return absl::InvalidArgumentError(absl::StrCat(
            where, ".faces[", f, "].indices: ", face.indices_size(),
            face.indices_size() == 1 ? " index" : " indices", "; a face needs at least 3"));
      }
      Face& out = scene.faces.emplace_back();
      out.surface = surface;
      out.vertices.reserve(face.indices_size());
      for (int k = 0; k < face.indices_size(); ++k) {
        const uint32_t index = face.indices(k);
        if (index >= num_vertices) {
          return absl::InvalidArgumentError(
              absl::StrCat(where, ".faces[", f, "].indices[", k, "]: vertex index ", index,
                           " is out of range (surface has ", num_vertices, " vertices)"));
        }
        out.vertices.push_back(offset + static_cast<int>(index));
      }
    }
    for (int k = 0; k + 2 < s.vertices_size(); k += 3) {
      scene.vertices.push_back({s.vertices(k), s.vertices(k + 1), s.vertices(k + 2)});
    }
    scene.surfaces.push_back({s.name(), material->second, 0});
  }
  if (scene.faces.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(prefix, "surfaces: the scene has no faces (it needs at least one)"));
  }

  if (absl::Status s = ValidateScene(scene); !s.ok()) return s;
  if (absl::Status s = DropDegenerateFaces(&scene, warnings); !s.ok()) return s;
  return scene;
}

radiosity::v1::Scene SceneToProto(const Scene& scene) {
  radiosity::v1::Scene msg;
  if (!scene.source.empty()) msg.set_name(std::filesystem::path(scene.source).stem().string());
  for (const Material& m : scene.materials) {
    radiosity::v1::Material* out = msg.add_materials();
    out->set_name(m.name);
    FromRgb(m.reflectance, out->mutable_reflectance());
    FromRgb(m.emission, out->mutable_emission());
    FromRgb(m.transmittance, out->mutable_transmittance());
    out->set_two_sided(m.two_sided);
    if (m.IsSpecular()) {
      FromRgb(m.mirror, out->mutable_mirror());
      FromRgb(m.glossy, out->mutable_glossy());
      out->set_glossy_exponent(m.glossy_exponent);
      FromRgb(m.glass, out->mutable_glass());
      out->set_ior(m.ior);
      out->set_refracts(m.refracts);
    }
  }

  const int num_surfaces = static_cast<int>(scene.surfaces.size());
  const int num_vertices = static_cast<int>(scene.vertices.size());
  std::vector<std::vector<int>> faces_of(num_surfaces);
  for (size_t f = 0; f < scene.faces.size(); ++f) {
    const int s = scene.faces[f].surface;
    if (s >= 0 && s < num_surfaces) faces_of[s].push_back(static_cast<int>(f));
  }
  // local[v] is the index of global vertex v in the current surface's list, or -1.
  std::vector<int> local(num_vertices, -1);
  for (int s = 0; s < num_surfaces; ++s) {
    const Surface& surface = scene.surfaces[s];
    radiosity::v1::Surface* out = msg.add_surfaces();
    out->set_name(surface.name);
    if (surface.material >= 0 && surface.material < static_cast<int>(scene.materials.size())) {
      out->set_material(scene.materials[surface.material].name);
    }
    std::vector<int> used;
    for (int f : faces_of[s]) {
      for (int v : scene.faces[f].vertices) {
        if (v >= 0 && v < num_vertices) used.push_back(v);
      }
    }
    std::sort(used.begin(), used.end());
    used.erase(std::unique(used.begin(), used.end()), used.end());
    out->mutable_vertices()->Reserve(3 * static_cast<int>(used.size()));
    for (size_t k = 0; k < used.size(); ++k) {
      local[used[k]] = static_cast<int>(k);
      const Vec3& p = scene.vertices[used[k]];
      out->add_vertices(p.x);
      out->add_vertices(p.y);
      out->add_vertices(p.z);
    }
    for (int f : faces_of[s]) {
      radiosity::v1::Face* face = out->add_faces();
      for (int v : scene.faces[f].vertices) {
        // An out-of-range index (only in an invalid scene) maps past the end, so it stays invalid.
        const size_t index =
            v >= 0 && v < num_vertices ? static_cast<size_t>(local[v]) : used.size();
        face->add_indices(static_cast<uint32_t>(index));
      }
    }
    for (int v : used) local[v] = -1;
  }
  return msg;
}

absl::StatusOr<Scene> ParseNativeScene(const std::string& bytes, bool json, const std::string& path,
                                       std::vector<std::string>* warnings) {
  radiosity::v1::Scene msg;
  if (json) {
    if (absl::Status s = CheckText(bytes, path); !s.ok()) return s;
    google::protobuf::util::JsonParseOptions options;
    options.ignore_unknown_fields = false;
    const auto status = google::protobuf::util::JsonStringToMessage(bytes, &msg, options);
    if (!status.ok()) {
      const auto message = status.message();
      return absl::InvalidArgumentError(
          FormatJsonError(path, bytes, std::string(message.data(), message.size())));
    }
  } else if (!msg.ParseFromString(bytes)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a valid binary Scene message"));
  }
  return SceneFromProto(msg, path, warnings);
}

absl::StatusOr<std::string> EncodeNativeScene(const Scene& scene, bool json,
                                              const std::string& path) {
  const radiosity::v1::Scene msg = SceneToProto(scene);
  std::string bytes;
  if (json) {
    google::protobuf::util::JsonPrintOptions options;
    options.add_whitespace = true;
    options.always_print_primitive_fields = true;
    options.preserve_proto_field_names = true;
    const auto status = google::protobuf::util::MessageToJsonString(msg, &bytes, options);
    if (!status.ok()) {
      const auto message = status.message();
      return absl::InternalError(absl::StrCat(path, ": cannot encode the scene as JSON: ",
                                              std::string(message.data(), message.size())));
    }
  } else if (!msg.SerializeToString(&bytes)) {
    return absl::InternalError(absl::StrCat(path, ": cannot encode the scene (too large?)"));
  }
  return bytes;
}

}  // namespace radiosity
