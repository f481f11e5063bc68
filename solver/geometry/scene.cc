#include "solver/geometry/scene.h"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <unordered_map>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"

namespace radiosity {

std::string Material::ToString() const {
  return absl::StrCat(
      "Material{", name, " Kd=", reflectance.ToString(), " Ke=", emission.ToString(),
      " Tf=", transmittance.ToString(), two_sided ? " two-sided" : "",
      mirror.IsZero() ? "" : absl::StrCat(" mirror=", mirror.ToString()),
      glossy.IsZero() ? "" : absl::StrCat(" glossy=", glossy.ToString(), "^", glossy_exponent),
      glass.IsZero() ? ""
                     : absl::StrCat(" glass=", glass.ToString(), " ior=", ior,
                                    refracts ? " refracts" : " thin"),
      "}");
}

std::string Surface::ToString() const {
  return absl::StrCat("Surface{", name, " material=", material, "}");
}

std::string Scene::Where(int line) const {
  if (source.empty()) return "";
  if (line > 0) return absl::StrCat(source, ":", line, ": ");
  return absl::StrCat(source, ": ");
}

std::string Scene::DescribeFace(int f) const {
  const Face& face = faces[f];
  int index_in_surface = 0;
  for (int i = 0; i < f; ++i) index_in_surface += faces[i].surface == face.surface;
  std::string name = face.surface >= 0 && face.surface < static_cast<int>(surfaces.size())
                         ? surfaces[face.surface].name
                         : "?";
  return absl::StrCat("surface '", name, "' face ", index_in_surface);
}

std::string Scene::ToString() const {
  return absl::StrCat("Scene{", source.empty() ? "<memory>" : source, ": ", vertices.size(),
                      " vertices, ", faces.size(), " faces, ", surfaces.size(), " surfaces, ",
                      materials.size(), " materials}");
}

namespace {
std::string Channels(const Rgb& c) { return absl::StrFormat("(%g, %g, %g)", c.r, c.g, c.b); }
}  // namespace

absl::Status ValidateSpecularParts(const Material& m, const std::string& where) {
  const std::pair<const char*, const Rgb*> parts[] = {
      {"mirror", &m.mirror}, {"glossy", &m.glossy}, {"glass", &m.glass}};
  for (const auto& [field, rgb] : parts) {
    if (!rgb->IsFinite() || rgb->Min() < 0 || rgb->Max() > 1) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, field, " ", Channels(*rgb), " is outside [0, 1]"));
    }
  }
  const Rgb sum = m.reflectance + m.transmittance + m.mirror + m.glossy + m.glass;
  if (sum.Max() > 1 + 1e-12) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, "reflectance + transmittance + mirror + glossy + glass ", Channels(sum),
                     " is above 1 (a surface cannot send on more light than arrives)"));
  }
  if (!m.glossy.IsZero() && !(m.glossy_exponent >= 1 && m.glossy_exponent <= kMaxGlossyExponent)) {
    return absl::InvalidArgumentError(absl::StrCat(where, "glossy exponent ", m.glossy_exponent,
                                                   " is outside [1, ", kMaxGlossyExponent,
                                                   "] (use mirror for a sharper reflection)"));
  }
  if (!m.glass.IsZero() && !(m.ior >= 1 && m.ior <= kMaxIor)) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, "index of refraction ", m.ior, " is outside [1, ", kMaxIor, "]"));
  }
  return absl::OkStatus();
}

namespace {

// Validates one material; `where` prefixes the message.
absl::Status ValidateMaterial(const Scene& scene, const Material& m) {
  std::string where = absl::StrCat(scene.Where(m.line), "material '", m.name, "': ");
  if (!m.reflectance.IsFinite() || !m.emission.IsFinite() || !m.transmittance.IsFinite()) {
    return absl::InvalidArgumentError(absl::StrCat(where, "NaN or infinite value"));
  }
  for (int c = 0; c < 3; ++c) {
    if (m.reflectance[c] < 0 || m.reflectance[c] >= 1) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "reflectance (Kd) ", Channels(m.reflectance), " is outside [0, 1)"));
    }
    if (m.transmittance[c] < 0 || m.transmittance[c] > 1) {
      return absl::InvalidArgumentError(absl::StrCat(
          where, "transmittance (Tf) ", Channels(m.transmittance), " is outside [0, 1]"));
    }
    if (m.reflectance[c] + m.transmittance[c] > 1) {
      return absl::InvalidArgumentError(absl::StrCat(where, "reflectance + transmittance ",
                                                     Channels(m.reflectance + m.transmittance),
                                                     " is above 1"));
    }
    if (m.emission[c] < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, "negative emission (Ke) ", Channels(m.emission)));
    }
  }
  return ValidateSpecularParts(m, where);
}

}  // namespace

absl::Status ValidateScene(const Scene& scene) {
  for (const Material& m : scene.materials) {
    if (absl::Status s = ValidateMaterial(scene, m); !s.ok()) return s;
  }
  for (size_t i = 0; i < scene.vertices.size(); ++i) {
    if (!IsFinite(scene.vertices[i])) {
      return absl::InvalidArgumentError(absl::StrCat(scene.Where(0), "vertex ", i + 1,
                                                     " has a NaN or infinite coordinate ",
                                                     scene.vertices[i].ToString()));
    }
  }
  for (const Surface& s : scene.surfaces) {
    if (s.material < 0 || s.material >= static_cast<int>(scene.materials.size())) {
      return absl::InvalidArgumentError(
          absl::StrCat(scene.Where(s.line), "surface '", s.name, "' has no material"));
    }
  }
  if (scene.faces.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(scene.Where(0), "the scene has no faces"));
  }
  const int nv = static_cast<int>(scene.vertices.size());
  for (size_t f = 0; f < scene.faces.size(); ++f) {
    const Face& face = scene.faces[f];
    if (face.surface < 0 || face.surface >= static_cast<int>(scene.surfaces.size())) {
      return absl::InvalidArgumentError(
          absl::StrCat(scene.Where(face.line), "face ", f, " belongs to no surface"));
    }
    if (face.vertices.size() < 3) {
      return absl::InvalidArgumentError(absl::StrCat(scene.Where(face.line), scene.DescribeFace(f),
                                                     " has ", face.vertices.size(),
                                                     " vertices; a face needs at least 3"));
    }
    // A polygon is traced as a fan of pieces that all meet at its first vertex: beyond a few
    // thousand vertices their bounds all overlap there, and each ray tests most of them.
    if (face.vertices.size() > kMaxFaceVertices) {
      return absl::InvalidArgumentError(absl::StrCat(
          scene.Where(face.line), scene.DescribeFace(f), " has ", face.vertices.size(),
          " vertices; a face may have at most ", kMaxFaceVertices,
          " (split larger polygons into several faces, or triangulate them on export)"));
    }
    for (int v : face.vertices) {
      if (v < 0 || v >= nv) {
        return absl::InvalidArgumentError(
            absl::StrCat(scene.Where(face.line), scene.DescribeFace(f), ": vertex index ", v + 1,
                         " is out of range (the scene has ", nv, " vertices)"));
      }
    }
  }
  return absl::OkStatus();
}

double PolygonArea(const Scene& scene, const Face& face) {
  // Vector area of a polygon: 1/2 sum_k p_k x p_{k+1}, taken relative to the first vertex so that
  // coordinates far from the origin do not cancel catastrophically.
  Vec3 area;
  const Vec3& p0 = scene.vertices[face.vertices[0]];
  for (size_t k = 1; k + 1 < face.vertices.size(); ++k) {
    area += Cross(scene.vertices[face.vertices[k]] - p0, scene.vertices[face.vertices[k + 1]] - p0);
  }
  return 0.5 * Length(area);
}

absl::Status DropDegenerateFaces(Scene* scene, std::vector<std::string>* warnings) {
  double largest = 0;
  std::vector<double> areas(scene->faces.size());
  for (size_t f = 0; f < scene->faces.size(); ++f) {
    areas[f] = PolygonArea(*scene, scene->faces[f]);
    largest = std::max(largest, areas[f]);
  }
  std::vector<Face> kept;
  kept.reserve(scene->faces.size());
  // Index of each face within its surface, counted as we go (DescribeFace's numbering, without
  // its O(faces) count per call: a file of millions of degenerate faces stays linear).
  std::vector<int> in_surface(scene->surfaces.size(), 0);
  int64_t dropped = 0;
  for (size_t f = 0; f < scene->faces.size(); ++f) {
    const int surface = scene->faces[f].surface;
    const bool known = surface >= 0 && surface < static_cast<int>(in_surface.size());
    const int index = known ? in_surface[surface]++ : 0;
    // Relative 1e-15: scenes may legitimately span 1e12 in area; only rounding noise is dropped.
    if (!(areas[f] > 1e-15 * largest)) {
      if (warnings && ++dropped <= kMaxDroppedFaceWarnings) {
        warnings->push_back(absl::StrCat(scene->Where(scene->faces[f].line), "surface '",
                                         known ? scene->surfaces[surface].name : "?", "' face ",
                                         index, " has zero area and was dropped"));
      }
      continue;
    }
    kept.push_back(std::move(scene->faces[f]));
  }
  if (warnings && dropped > kMaxDroppedFaceWarnings) {
    warnings->push_back(absl::StrCat(scene->Where(0), dropped - kMaxDroppedFaceWarnings,
                                     " more faces of zero area were dropped"));
  }
  scene->faces = std::move(kept);
  if (scene->faces.empty()) {
    return absl::InvalidArgumentError(
        absl::StrCat(scene->Where(0), "the scene has no faces of non-zero area"));
  }
  return absl::OkStatus();
}

Rgb EmittedPower(const Scene& scene) {
  Rgb total;
  for (const Face& face : scene.faces) {
    const Material& m = scene.materials[scene.surfaces[face.surface].material];
    if (!m.IsEmitter()) continue;
    total += m.emission * (PolygonArea(scene, face) * (m.two_sided ? 2.0 : 1.0));
  }
  return total;
}

std::string EmitOverride::ToString() const {
  return absl::StrFormat("%s=%g,%g,%g", name, exitance.r, exitance.g, exitance.b);
}

absl::Status ApplyEmitOverrides(const std::vector<EmitOverride>& emit, Scene* scene) {
  if (emit.empty()) return absl::OkStatus();
  // Indexes by name, so that many overrides on a scene of many surfaces stay linear.
  std::unordered_map<std::string, std::vector<int>> materials_named, surfaces_named;
  for (size_t k = 0; k < scene->materials.size(); ++k) {
    materials_named[scene->materials[k].name].push_back(static_cast<int>(k));
  }
  for (size_t k = 0; k < scene->surfaces.size(); ++k) {
    surfaces_named[scene->surfaces[k].name].push_back(static_cast<int>(k));
  }
  for (const EmitOverride& e : emit) {
    if (!e.exitance.IsFinite() || e.exitance.Min() < 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("emit ", e.ToString(), ": the exitance must be finite and >= 0"));
    }
    bool found = false;
    if (auto it = materials_named.find(e.name); it != materials_named.end()) {
      for (int k : it->second) scene->materials[k].emission = e.exitance;
      continue;
    }
    if (auto it = surfaces_named.find(e.name); it != surfaces_named.end()) {
      found = true;
      for (int i : it->second) {
        Surface& surface = scene->surfaces[i];
        // The surface's own emitting copy, made by an earlier override or now.
        const std::string copy_name =
            absl::StrCat(scene->materials[surface.material].name, "@", surface.name);
        if (absl::EndsWith(scene->materials[surface.material].name, "@" + surface.name)) {
          scene->materials[surface.material].emission = e.exitance;
          continue;
        }
        std::vector<int>& copies = materials_named[copy_name];
        if (copies.empty()) {
          Material copy = scene->materials[surface.material];
          copy.name = copy_name;
          copies.push_back(static_cast<int>(scene->materials.size()));
          scene->materials.push_back(std::move(copy));
        }
        scene->materials[copies[0]].emission = e.exitance;
        surface.material = copies[0];
      }
    }
    if (!found) {
      constexpr size_t kShown = 12;
      std::vector<std::string> materials, surfaces;
      for (size_t k = 0; k < scene->materials.size() && k < kShown; ++k) {
        materials.push_back(scene->materials[k].name);
      }
      for (size_t k = 0; k < scene->surfaces.size() && k < kShown; ++k) {
        surfaces.push_back(scene->surfaces[k].name);
      }
      auto more = [](size_t n) {
        return n > kShown ? absl::StrCat(" and ", n - kShown, " more") : "";
      };
      return absl::InvalidArgumentError(absl::StrCat(
          "emit ", e.ToString(), ": no material or surface is named '", e.name,
          "' (materials: ", absl::StrJoin(materials, ", "), more(scene->materials.size()),
          "; surfaces: ", absl::StrJoin(surfaces, ", "), more(scene->surfaces.size()), ")"));
    }
  }
  return absl::OkStatus();
}

}  // namespace radiosity
