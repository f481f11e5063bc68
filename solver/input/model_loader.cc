#include "solver/input/model_loader.h"

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>
#include <assimp/DefaultIOSystem.h>
#include <assimp/GltfMaterial.h>
#include <assimp/material.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <algorithm>
#include <array>
#include <assimp/Importer.hpp>
#include <assimp/ProgressHandler.hpp>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <unordered_map>
#include <utility>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "solver/util/file_io.h"

namespace radiosity {
namespace {

constexpr const char* kExtensions[] = {".gltf", ".glb", ".fbx", ".dae", ".3ds", ".ply", ".stl"};

// Largest texture decoded (texels); larger ones are left out with a warning (the factor alone).
constexpr int64_t kMaxTexels = int64_t{1} << 26;
// Texture samples averaged per face.
constexpr int kTextureSamplesPerFace = 16;

// Opens only files inside `dir` (safe relative names), so that a model cannot make the service
// read other files; everything else behaves as assimp's default.
class ConfinedIOSystem : public Assimp::DefaultIOSystem {
 public:
  explicit ConfinedIOSystem(std::string dir) : dir_(std::move(dir)) {}

  bool Exists(const char* file) const override {
    return Allowed(file) && Assimp::DefaultIOSystem::Exists(file);
  }
  Assimp::IOStream* Open(const char* file, const char* mode) override {
    if (!Allowed(file)) return nullptr;
    return Assimp::DefaultIOSystem::Open(file, mode);
  }

 private:
  bool Allowed(const char* file) const {
    std::string name = file == nullptr ? "" : file;
    std::replace(name.begin(), name.end(), '\\', '/');
    if (!dir_.empty() && absl::StartsWith(name, dir_ + "/")) name = name.substr(dir_.size() + 1);
    while (absl::StartsWith(name, "./")) name = name.substr(2);
    return IsSafeRelativeName(name);
  }
  std::string dir_;
};

// Aborts a long import when the caller's stop token fires (assimp checks it between steps).
class StopProgress : public Assimp::ProgressHandler {
 public:
  explicit StopProgress(const StopToken* stop) : stop_(stop) {}
  bool Update(float) override { return stop_ == nullptr || !stop_->ShouldStop(); }

 private:
  const StopToken* stop_;
};

double SrgbToLinear(double c) {
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}

// A decoded texture, linear RGB, for averaging over faces.
struct Texture {
  int width = 0, height = 0;
  std::vector<float> rgb;  // width x height x 3, row 0 at the top (v = 1 in glTF's convention).

  Rgb At(double u, double v) const {
    // Texture coordinates repeat; non-finite ones (hostile files) read texel (0, 0).
    u = std::isfinite(u) ? u - std::floor(u) : 0;
    v = std::isfinite(v) ? v - std::floor(v) : 0;
    const int x = std::clamp(static_cast<int>(u * width), 0, width - 1);
    const int y = std::clamp(static_cast<int>(v * height), 0, height - 1);
    const size_t i = 3 * (static_cast<size_t>(y) * width + x);
    return {rgb[i], rgb[i + 1], rgb[i + 2]};
  }
};

// What assimp 5.2 leaves out of a glTF material: KHR_materials_emissive_strength and
// KHR_materials_ior.
struct GltfMaterial {
  std::string name;
  double emissive_strength = 1;
  double ior = 1.5;
};

// The JSON of a .gltf, or of a .glb's first chunk (glTF 2.0 section 4.4); null when unreadable
// (the importer then reports the problem).
nlohmann::json ReadGltfJson(const std::string& path, bool binary) {
  absl::StatusOr<std::string> bytes = ReadWholeFile(path);
  if (!bytes.ok()) return nullptr;
  absl::string_view text = *bytes;
  if (binary) {
    if (text.size() < 20 || text.substr(0, 4) != "glTF" || text.substr(16, 4) != "JSON") {
      return nullptr;
    }
    uint32_t length = 0;
    std::memcpy(&length, text.data() + 12, 4);
    if (length > text.size() - 20) return nullptr;
    text = text.substr(20, length);
  }
  return nlohmann::json::parse(text.begin(), text.end(), nullptr, /*allow_exceptions=*/false);
}

std::vector<GltfMaterial> ReadGltfMaterials(const std::string& path, bool binary) {
  std::vector<GltfMaterial> out;
  const nlohmann::json doc = ReadGltfJson(path, binary);
  if (!doc.is_object()) return out;
  auto materials = doc.find("materials");
  if (materials == doc.end() || !materials->is_array()) return out;
  for (const nlohmann::json& m : *materials) {
    GltfMaterial material;
    if (m.is_object()) {
      if (auto name = m.find("name"); name != m.end() && name->is_string()) {
        material.name = name->get<std::string>();
      }
      const nlohmann::json::json_pointer strength(
          "/extensions/KHR_materials_emissive_strength/emissiveStrength");
      if (m.contains(strength) && m.at(strength).is_number()) {
        const double v = m.at(strength).get<double>();
        if (std::isfinite(v) && v >= 0) material.emissive_strength = v;
      }
      const nlohmann::json::json_pointer ior("/extensions/KHR_materials_ior/ior");
      if (m.contains(ior) && m.at(ior).is_number()) {
        const double v = m.at(ior).get<double>();
        if (v >= 1 && v <= kMaxIor) material.ior = v;
      }
    }
    out.push_back(material);
  }
  return out;
}

class ModelReader {
 public:
  ModelReader(const std::string& path, std::vector<std::string>* warnings,
              const ModelOptions& options)
      : path_(path), dir_(DirName(path)), warnings_(warnings), options_(options) {}

  absl::StatusOr<Scene> Read() {
    const std::string ext = Extension(path_);
    if (!IsModelExtension(ext)) {
      return absl::InvalidArgumentError(
          absl::StrCat(path_, ": not a model format (expected ", ModelExtensions(), ")"));
    }
    if (!FileExists(path_)) {
      return absl::NotFoundError(absl::StrCat(path_, ": cannot open: no such file"));
    }
    Assimp::Importer importer;
    if (options_.confine_to_directory) importer.SetIOHandler(new ConfinedIOSystem(dir_));
    importer.SetProgressHandler(new StopProgress(options_.stop));
    importer.SetPropertyBool(AI_CONFIG_FBX_CONVERT_TO_M, true);
    const aiScene* ai =
        importer.ReadFile(path_, aiProcess_Triangulate | aiProcess_JoinIdenticalVertices);
    if (options_.stop != nullptr && options_.stop->ShouldStop()) {
      return absl::CancelledError(absl::StrCat(path_, ": reading the model was stopped"));
    }
    if (ai == nullptr) {
      std::string why = importer.GetErrorString();
      if (why.empty()) why = "unknown error";
      return absl::InvalidArgumentError(
          absl::StrCat(path_, ": cannot read the model (assimp): ", why));
    }
    if (ai->mRootNode == nullptr || ai->mNumMeshes == 0) {
      return absl::InvalidArgumentError(absl::StrCat(path_, ": the model has no meshes"));
    }
    scene_.source = path_;
    ai_ = ai;
    if (ext == ".gltf" || ext == ".glb") gltf_materials_ = ReadGltfMaterials(path_, ext == ".glb");
    materials_.assign(ai->mNumMaterials, {});
    if (absl::Status s = Walk(ai->mRootNode, aiMatrix4x4(), 0); !s.ok()) return s;
    if (dropped_primitives_ > 0) {
      Warn(absl::StrCat(dropped_primitives_,
                        " point or line primitives dropped (only polygons carry light)"));
    }
    if (scene_.faces.empty()) {
      return absl::InvalidArgumentError(absl::StrCat(
          path_, ": the model has no polygons (only points or lines, which carry no light)"));
    }
    if (absl::Status s = ValidateScene(scene_); !s.ok()) return s;
    if (absl::Status s = DropDegenerateFaces(&scene_, warnings_); !s.ok()) return s;
    return std::move(scene_);
  }

 private:
  void Warn(const std::string& what) {
    if (warnings_ != nullptr) warnings_->push_back(absl::StrCat(path_, ": ", what));
  }

  absl::Status Walk(const aiNode* node, const aiMatrix4x4& parent, int depth) {
    if (depth > 1000) {
      return absl::InvalidArgumentError(
          absl::StrCat(path_, ": the node hierarchy is deeper than 1000"));
    }
    if (options_.stop != nullptr && options_.stop->ShouldStop()) {
      return absl::CancelledError(absl::StrCat(path_, ": reading the model was stopped"));
    }
    const aiMatrix4x4 transform = parent * node->mTransformation;
    for (unsigned i = 0; i < node->mNumMeshes; ++i) {
      if (node->mMeshes[i] >= ai_->mNumMeshes) {
        return absl::InvalidArgumentError(absl::StrCat(path_, ": node '", node->mName.C_Str(),
                                                       "' names mesh ", node->mMeshes[i], " of ",
                                                       ai_->mNumMeshes));
      }
      if (absl::Status s = AddMesh(node, *ai_->mMeshes[node->mMeshes[i]], transform); !s.ok()) {
        return s;
      }
    }
    for (unsigned i = 0; i < node->mNumChildren; ++i) {
      if (absl::Status s = Walk(node->mChildren[i], transform, depth + 1); !s.ok()) return s;
    }
    return absl::OkStatus();
  }

  // A name for a surface that no other surface has.
  std::string UniqueSurfaceName(std::string name) {
    if (name.empty()) name = "mesh";
    std::string unique = name;
    for (int k = 2; !surface_names_.insert(unique).second; ++k) unique = absl::StrCat(name, "#", k);
    return unique;
  }

  // What the model's material `index` is, converted once.
  struct MaterialInfo {
    bool converted = false;
    int scene_index = -1;  // Into scene_.materials: the material with the base colour, once used.
    Rgb base;              // Linear base colour (before clamping).
    Rgb emission;
    double transmission = 0;  // KHR_materials_transmission: the dielectric part's glass.
    double metallic = 0;      // glTF metallic-roughness.
    double roughness = 1;
    double ior = 1.5;
    double opacity = 1;
    bool two_sided = false;
    std::string name;
    const Texture* texture = nullptr;  // Base-colour texture, if it could be read.
    unsigned uv_channel = 0;
  };

  MaterialInfo& MaterialOf(unsigned index) {
    MaterialInfo& info = materials_[index];
    if (info.converted) return info;
    info.converted = true;
    const aiMaterial& m = *ai_->mMaterials[index];
    aiString name;
    info.name = m.Get(AI_MATKEY_NAME, name) == AI_SUCCESS && name.length > 0
                    ? std::string(name.C_Str())
                    : absl::StrCat("material", index);
    aiColor4D color(1, 1, 1, 1);
    if (m.Get(AI_MATKEY_BASE_COLOR, color) != AI_SUCCESS &&
        m.Get(AI_MATKEY_COLOR_DIFFUSE, color) != AI_SUCCESS) {
      color = aiColor4D(kDefaultReflectance, kDefaultReflectance, kDefaultReflectance, 1);
    }
    info.base = Rgb(color.r, color.g, color.b);
    aiColor3D emissive(0, 0, 0);
    if (m.Get(AI_MATKEY_COLOR_EMISSIVE, emissive) == AI_SUCCESS) {
      float strength = 1;
      if (m.Get(AI_MATKEY_EMISSIVE_INTENSITY, strength) != AI_SUCCESS &&
          index < gltf_materials_.size() &&
          (gltf_materials_[index].name.empty() || gltf_materials_[index].name == info.name)) {
        strength = static_cast<float>(gltf_materials_[index].emissive_strength);
      }
      info.emission = Rgb(emissive.r, emissive.g, emissive.b) * strength;
    }
    float t = 0;
    if (m.Get(AI_MATKEY_TRANSMISSION_FACTOR, t) == AI_SUCCESS) {
      info.transmission = std::clamp(static_cast<double>(t), 0.0, 1.0);
    }
    float metallic = 0, roughness = 1, ior = 1.5f;
    if (m.Get(AI_MATKEY_METALLIC_FACTOR, metallic) == AI_SUCCESS && std::isfinite(metallic)) {
      info.metallic = std::clamp(static_cast<double>(metallic), 0.0, 1.0);
    }
    if (m.Get(AI_MATKEY_ROUGHNESS_FACTOR, roughness) == AI_SUCCESS && std::isfinite(roughness)) {
      info.roughness = std::clamp(static_cast<double>(roughness), 0.0, 1.0);
    }
    if (m.Get(AI_MATKEY_REFRACTI, ior) == AI_SUCCESS && ior >= 1 && ior <= kMaxIor) {
      info.ior = ior;
    }
    if (index < gltf_materials_.size() &&
        (gltf_materials_[index].name.empty() || gltf_materials_[index].name == info.name)) {
      info.ior = gltf_materials_[index].ior;
    }
    float opacity = 1;
    // glTF's alpha is coverage, and ignored when alphaMode is OPAQUE (the default), though
    // assimp 5.2 reports it as opacity.
    aiString alpha_mode;
    const bool opaque = m.Get(AI_MATKEY_GLTF_ALPHAMODE, alpha_mode) == AI_SUCCESS &&
                        std::string(alpha_mode.C_Str()) == "OPAQUE";
    if (!opaque && m.Get(AI_MATKEY_OPACITY, opacity) == AI_SUCCESS && opacity >= 0 && opacity < 1) {
      info.opacity = opacity;
    }
    int two_sided = 0;
    info.two_sided = m.Get(AI_MATKEY_TWOSIDED, two_sided) == AI_SUCCESS && two_sided != 0;

    for (aiTextureType type : {aiTextureType_BASE_COLOR, aiTextureType_DIFFUSE}) {
      aiString file;
      unsigned uv = 0;
      if (m.GetTextureCount(type) == 0 ||
          m.GetTexture(type, 0, &file, nullptr, &uv) != AI_SUCCESS) {
        continue;
      }
      info.texture = LoadTexture(file.C_Str(), info.name);
      info.uv_channel = uv;
      break;
    }
    if (!std::isfinite(info.base.Sum()) || !std::isfinite(info.emission.Sum())) {
      Warn(absl::StrCat("material '", info.name,
                        "': a colour is not finite; the default grey is used"));
      info.base = Rgb::Gray(kDefaultReflectance);
      info.emission = Rgb();
    }
    for (int c = 0; c < 3; ++c) {
      info.base[c] = std::max(0.0, info.base[c]);
      info.emission[c] = std::max(0.0, info.emission[c]);
    }
    return info;
  }

  // Adds a material named `name` with diffuse colour `color` and the rest of `info`.
  int AddMaterial(const std::string& name, const MaterialInfo& info, Rgb color) {
    Material out;
    out.name = name;
    for (int k = 2; !material_names_.insert(out.name).second; ++k) {
      out.name = absl::StrCat(name, "#", k);
    }
    bool clamped = false;
    for (int c = 0; c < 3; ++c) {
      if (color[c] > kMaxReflectance) {
        color[c] = kMaxReflectance;
        clamped = true;
      }
    }
    if (clamped && !clamped_warned_.count(info.name)) {
      clamped_warned_.insert(info.name);
      Warn(absl::StrCat("material '", info.name, "': base colour at or above 1 clamped to ",
                        kMaxReflectance));
    }
    // docs/guide/specular.md: the dielectric part (1 - metallic) reflects the base
    // colour diffusely and passes `transmission` of it as thin glass; the metallic part reflects
    // it into a glossy lobe of Phong exponent 2 / roughness^4 - 2 (Walter et al. 2007's
    // alpha = roughness^2), as a mirror when that exceeds kMirrorExponent, diffusely below 1.
    const double dielectric = info.opacity * (1 - info.metallic);
    const double metal = info.opacity * info.metallic;
    out.reflectance = color * (dielectric * (1 - info.transmission));
    out.glass = color * (dielectric * info.transmission);
    out.ior = info.ior;
    if (metal > 0) {
      const double a2 = std::pow(info.roughness, 4);
      const double exponent = a2 > 0 ? 2 / a2 - 2 : std::numeric_limits<double>::infinity();
      if (exponent > kMirrorExponent) {
        out.mirror = color * metal;
      } else if (exponent >= 1) {
        out.glossy = color * metal;
        out.glossy_exponent = exponent;
      } else {
        out.reflectance += color * metal;
      }
    }
    out.transmittance = Rgb::Gray(1 - info.opacity);
    for (int c = 0; c < 3; ++c) {  // The parts sum to at most 1 by construction; guard rounding.
      const double rest = out.reflectance[c] + out.glass[c] + out.mirror[c] + out.glossy[c];
      out.transmittance[c] = std::clamp(out.transmittance[c], 0.0, std::max(0.0, 1 - rest));
    }
    out.emission = info.emission;
    out.two_sided = info.two_sided;
    scene_.materials.push_back(out);
    return static_cast<int>(scene_.materials.size()) - 1;
  }

  const Texture* LoadTexture(const std::string& file, const std::string& material) {
    auto it = textures_.find(file);
    if (it != textures_.end()) return it->second.get();
    std::unique_ptr<Texture> texture;
    std::string why;
    const aiTexture* embedded = ai_->GetEmbeddedTexture(file.c_str());
    if (embedded != nullptr) {
      texture = DecodeEmbedded(*embedded, &why);
    } else {
      std::string name = file;
      std::replace(name.begin(), name.end(), '\\', '/');
      while (absl::StartsWith(name, "./")) name = name.substr(2);
      if (options_.confine_to_directory && !IsSafeRelativeName(name)) {
        why = "not a file inside the model's directory";
      } else {
        const std::string local =
            !name.empty() && name.front() == '/' ? name : JoinPath(dir_, name);
        if (name.empty() || !FileExists(local)) {
          why = "no such file";
        } else {
          texture = DecodeFile(local, nullptr, &why);
        }
      }
    }
    if (texture == nullptr) {
      Warn(absl::StrCat("material '", material, "': texture '", file, "' left out (", why,
                        "); its colour factor alone is used"));
    }
    const Texture* result = texture.get();
    textures_[file] = std::move(texture);
    return result;
  }

  std::unique_ptr<Texture> DecodeEmbedded(const aiTexture& t, std::string* why) {
    if (t.mHeight == 0) {  // Compressed (PNG, JPEG, ...): mWidth bytes.
      std::string hint = t.achFormatHint;
      if (hint.empty()) hint = "png";
      OIIO::Filesystem::IOMemReader reader(t.pcData, t.mWidth);
      return DecodeFile(absl::StrCat("embedded.", hint), &reader, why);
    }
    if (t.mWidth == 0 || t.pcData == nullptr ||
        static_cast<int64_t>(t.mWidth) * t.mHeight > kMaxTexels) {
      *why = "empty or too large";
      return nullptr;
    }
    auto texture = std::make_unique<Texture>();
    texture->width = static_cast<int>(t.mWidth);
    texture->height = static_cast<int>(t.mHeight);
    texture->rgb.resize(3 * static_cast<size_t>(t.mWidth) * t.mHeight);
    for (size_t i = 0; i < static_cast<size_t>(t.mWidth) * t.mHeight; ++i) {
      texture->rgb[3 * i] = static_cast<float>(SrgbToLinear(t.pcData[i].r / 255.0));
      texture->rgb[3 * i + 1] = static_cast<float>(SrgbToLinear(t.pcData[i].g / 255.0));
      texture->rgb[3 * i + 2] = static_cast<float>(SrgbToLinear(t.pcData[i].b / 255.0));
    }
    return texture;
  }

  // Decodes an image file (or, with `proxy`, bytes in memory named like a file of their format).
  std::unique_ptr<Texture> DecodeFile(const std::string& name, OIIO::Filesystem::IOProxy* proxy,
                                      std::string* why) {
    // Only the image formats models use: OpenImageIO would otherwise hand the bytes to any of its
    // decoders (video, camera raw ...) by the name's extension.
    static const std::set<std::string> kImageFormats = {".png", ".jpg", ".jpeg", ".tga",
                                                        ".bmp", ".hdr", ".exr"};
    const std::string ext = Extension(name);
    if (kImageFormats.count(ext) == 0) {
      *why = absl::StrCat("'", ext, "' is not an image format read here (png, jpeg, tga, bmp, ",
                          "hdr, exr)");
      return nullptr;
    }
    std::unique_ptr<OIIO::ImageInput> in = OIIO::ImageInput::open(name, nullptr, proxy);
    if (!in) {
      *why = OIIO::geterror();
      if (why->empty()) *why = "unreadable image";
      return nullptr;
    }
    const std::string format = in->format_name();
    if (format != "png" && format != "jpeg" && format != "targa" && format != "bmp" &&
        format != "hdr" && format != "openexr") {
      *why = absl::StrCat("decoded as '", format, "', not an image format read here");
      return nullptr;
    }
    const OIIO::ImageSpec& spec = in->spec();
    if (spec.width <= 0 || spec.height <= 0 || spec.nchannels <= 0 ||
        static_cast<int64_t>(spec.width) * spec.height > kMaxTexels) {
      *why = absl::StrFormat("%d x %d texels: too large or empty", spec.width, spec.height);
      return nullptr;
    }
    std::vector<float> pixels(static_cast<size_t>(spec.width) * spec.height * spec.nchannels);
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, pixels.data())) {
      *why = in->geterror();
      return nullptr;
    }
    const bool linear = spec.get_string_attribute("oiio:ColorSpace") == "Linear" ||
                        spec.format.basetype == OIIO::TypeDesc::FLOAT ||
                        spec.format.basetype == OIIO::TypeDesc::HALF;
    auto texture = std::make_unique<Texture>();
    texture->width = spec.width;
    texture->height = spec.height;
    texture->rgb.resize(3 * static_cast<size_t>(spec.width) * spec.height);
    for (size_t i = 0; i < static_cast<size_t>(spec.width) * spec.height; ++i) {
      for (int c = 0; c < 3; ++c) {
        // Grey (1 channel) and grey + alpha (2): the grey for every colour channel.
        const float v = pixels[i * spec.nchannels + (spec.nchannels < 3 ? 0 : c)];
        texture->rgb[3 * i + c] = linear ? v : static_cast<float>(SrgbToLinear(v));
      }
    }
    return texture;
  }

  absl::Status AddMesh(const aiNode* node, const aiMesh& mesh, const aiMatrix4x4& transform) {
    if ((mesh.mPrimitiveTypes & (aiPrimitiveType_TRIANGLE | aiPrimitiveType_POLYGON)) == 0) {
      dropped_primitives_ += mesh.mNumFaces;
      return absl::OkStatus();
    }
    if (mesh.mNumFaces == 0 || mesh.mNumVertices == 0 || mesh.mVertices == nullptr ||
        mesh.mFaces == nullptr) {
      return absl::OkStatus();  // An empty mesh (an empty STL solid): nothing to add.
    }
    if (mesh.mMaterialIndex >= ai_->mNumMaterials) {
      return absl::InvalidArgumentError(
          absl::StrCat(path_, ": mesh '", mesh.mName.C_Str(), "' has no material"));
    }
    MaterialInfo& material = MaterialOf(mesh.mMaterialIndex);
    std::string name = node->mName.length > 0 ? node->mName.C_Str() : "";
    if (mesh.mName.length > 0 && mesh.mName.C_Str() != name) {
      name = name.empty() ? mesh.mName.C_Str() : absl::StrCat(name, "/", mesh.mName.C_Str());
    }
    if (name.empty()) name = "mesh";

    for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
      const aiFace& face = mesh.mFaces[f];
      for (unsigned i = 0; i < face.mNumIndices; ++i) {
        if (face.mIndices[i] >= mesh.mNumVertices) {
          return absl::InvalidArgumentError(absl::StrFormat(
              "%s: mesh '%s' face %u: vertex index %u is out of range (%u vertices)", path_, name,
              f, face.mIndices[i], mesh.mNumVertices));
        }
      }
    }
    if (scene_.vertices.size() + mesh.mNumVertices > static_cast<size_t>(INT32_MAX)) {
      return absl::ResourceExhaustedError(absl::StrCat(path_, ": more than 2^31 vertices"));
    }

    // Vertices, transformed; a mirroring transform reverses the winding.
    const int base = static_cast<int>(scene_.vertices.size());
    for (unsigned v = 0; v < mesh.mNumVertices; ++v) {
      const aiVector3D p = transform * mesh.mVertices[v];
      scene_.vertices.emplace_back(p.x, p.y, p.z);
    }
    const bool mirrored = transform.Determinant() < 0;

    // Per-face colours from a texture or vertex colours, when there are any.
    const bool use_vertex_colors = options_.vertex_colors && mesh.HasVertexColors(0);
    const bool use_texture = !use_vertex_colors && material.texture != nullptr &&
                             mesh.HasTextureCoords(material.uv_channel);
    std::vector<Rgb> face_color;
    if (use_vertex_colors || use_texture) {
      face_color.reserve(mesh.mNumFaces);
      for (unsigned f = 0; f < mesh.mNumFaces; ++f) {
        Rgb c = use_vertex_colors ? VertexColor(mesh, mesh.mFaces[f])
                                  : TextureColor(mesh, mesh.mFaces[f], material);
        // Float colours may be anything: non-finite or negative ones are black, the rest are
        // clamped to reflectances (kMaxReflectance) when the materials are made.
        for (int ch = 0; ch < 3; ++ch)
          c[ch] = std::isfinite(c[ch]) ? std::clamp(c[ch], 0.0, 1.0) : 0;
        face_color.push_back(c);
      }
    }
    // Groups of faces by rounded colour: one surface each (a single group without colours).
    std::map<std::array<int64_t, 3>, std::vector<unsigned>> groups;
    double step = kTextureColorStep;
    if (face_color.empty()) {
      std::vector<unsigned>& all = groups[{0, 0, 0}];
      for (unsigned f = 0; f < mesh.mNumFaces; ++f) all.push_back(f);
    } else {
      step = ColorGroupingStep(face_color);
      for (unsigned f = 0; f < mesh.mNumFaces; ++f)
        groups[ColorKey(face_color[f], step)].push_back(f);
      if (step != kTextureColorStep) {
        Warn(absl::StrFormat(
            "mesh '%s': face colours rounded to steps of 1/%d to keep %d surfaces or fewer", name,
            static_cast<int>(std::lround(1 / step)), kMaxColorGroups));
      }
    }
    int k = 0;
    for (const auto& [key, faces] : groups) {
      Surface surface;
      int material_index = material.scene_index;
      if (!face_color.empty()) {
        ++k;
        surface.name = UniqueSurfaceName(groups.size() == 1 ? name : absl::StrCat(name, "#", k));
        const Rgb color(key[0] * step, key[1] * step, key[2] * step);
        material_index =
            AddMaterial(absl::StrCat(material.name, "@", surface.name), material, color);
      } else {
        surface.name = UniqueSurfaceName(name);
        if (material.scene_index < 0) {
          material.scene_index = AddMaterial(material.name, material, material.base);
        }
        material_index = material.scene_index;
      }
      surface.material = material_index;
      scene_.surfaces.push_back(surface);
      const int s = static_cast<int>(scene_.surfaces.size()) - 1;
      for (unsigned f : faces) {
        const aiFace& face = mesh.mFaces[f];
        if (face.mNumIndices < 3) {
          ++dropped_primitives_;
          continue;
        }
        Face out;
        out.surface = s;
        out.vertices.reserve(face.mNumIndices);
        for (unsigned i = 0; i < face.mNumIndices; ++i) {
          out.vertices.push_back(base + static_cast<int>(face.mIndices[i]));
        }
        if (mirrored) std::reverse(out.vertices.begin(), out.vertices.end());
        scene_.faces.push_back(std::move(out));
      }
    }
    return absl::OkStatus();
  }

  Rgb VertexColor(const aiMesh& mesh, const aiFace& face) const {
    Rgb sum;
    for (unsigned i = 0; i < face.mNumIndices; ++i) {
      const aiColor4D& c = mesh.mColors[0][face.mIndices[i]];
      sum += Rgb(c.r, c.g, c.b);
    }
    return face.mNumIndices > 0 ? sum / face.mNumIndices : sum;
  }

  // The base colour averaged over a triangle: the factor times the texture at
  // kTextureSamplesPerFace stratified points of the face's UV triangle.
  Rgb TextureColor(const aiMesh& mesh, const aiFace& face, const MaterialInfo& material) const {
    if (face.mNumIndices < 3) return material.base;
    const aiVector3D* uv = mesh.mTextureCoords[material.uv_channel];
    const aiVector3D& a = uv[face.mIndices[0]];
    const aiVector3D& b = uv[face.mIndices[1]];
    const aiVector3D& c = uv[face.mIndices[2]];
    Rgb sum;
    const int n = 4;  // n x n strata of the unit square, mapped area-uniformly to the triangle.
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        // An area-uniform point a + s (b - a) + t (c - a) (Shirley 1990): s = sqrt(r1)(1 - r2),
        // t = sqrt(r1) r2.
        const double r1 = (i + 0.5) / n, r2 = (j + 0.5) / n;
        const double s = std::sqrt(r1) * (1 - r2), t = std::sqrt(r1) * r2;
        const double u = a.x + s * (b.x - a.x) + t * (c.x - a.x);
        const double v = a.y + s * (b.y - a.y) + t * (c.y - a.y);
        // Image rows run downwards; texture v runs upwards (assimp flips glTF's convention).
        sum += material.texture->At(u, 1 - v);
      }
    }
    static_assert(n * n == kTextureSamplesPerFace);
    return material.base * (sum / kTextureSamplesPerFace);
  }

  const std::string path_;
  const std::string dir_;
  std::vector<std::string>* warnings_;
  const ModelOptions options_;
  const aiScene* ai_ = nullptr;
  Scene scene_;
  std::vector<MaterialInfo> materials_;
  std::vector<GltfMaterial> gltf_materials_;
  std::set<std::string> surface_names_;
  std::set<std::string> material_names_;
  std::set<std::string> clamped_warned_;
  std::unordered_map<std::string, std::unique_ptr<Texture>> textures_;
  int64_t dropped_primitives_ = 0;
};

}  // namespace

std::array<int64_t, 3> ColorKey(const Rgb& color, double step) {
  return {std::llround(color.r / step), std::llround(color.g / step), std::llround(color.b / step)};
}

double ColorGroupingStep(const std::vector<Rgb>& colors) {
  for (double step = kTextureColorStep;; step *= 2) {
    std::set<std::array<int64_t, 3>> keys;
    for (const Rgb& c : colors) {
      keys.insert(ColorKey(c, step));
      if (static_cast<int>(keys.size()) > kMaxColorGroups) break;
    }
    // Colours in [0, 1] give at most 8 keys once the step reaches 2, so this ends.
    if (static_cast<int>(keys.size()) <= kMaxColorGroups) return step;
  }
}

bool IsModelExtension(const std::string& extension) {
  for (const char* e : kExtensions) {
    if (extension == e) return true;
  }
  return false;
}

std::string ModelExtensions() { return absl::StrJoin(kExtensions, ", "); }

absl::StatusOr<Scene> LoadModelInChild(const std::string& path, std::vector<std::string>* warnings,
                                       const ModelOptions& options);  // model_import.cc

void UseOneDecodingThread() { OIIO::attribute("threads", 1); }

absl::StatusOr<Scene> LoadModelInProcess(const std::string& path,
                                         std::vector<std::string>* warnings,
                                         const ModelOptions& options) {
  return ModelReader(path, warnings, options).Read();
}

absl::StatusOr<Scene> LoadModel(const std::string& path, std::vector<std::string>* warnings,
                                const ModelOptions& options) {
  if (!options.importer.empty()) return LoadModelInChild(path, warnings, options);
  return LoadModelInProcess(path, warnings, options);
}

absl::StatusOr<std::vector<std::string>> ModelDependencies(const std::string& path) {
  std::vector<std::string> files;
  if (Extension(path) != ".gltf") return files;
  absl::StatusOr<std::string> text = ReadWholeFile(path);
  if (!text.ok()) return text.status();
  nlohmann::json doc = nlohmann::json::parse(*text, nullptr, /*allow_exceptions=*/false);
  if (doc.is_discarded() || !doc.is_object()) return files;  // The loader reports the error.
  const std::string dir = DirName(path);
  for (const char* key : {"buffers", "images"}) {
    auto list = doc.find(key);
    if (list == doc.end() || !list->is_array()) continue;
    for (const nlohmann::json& item : *list) {
      if (!item.is_object()) continue;
      auto uri = item.find("uri");
      if (uri == item.end() || !uri->is_string()) continue;
      std::string name = uri->get<std::string>();
      if (absl::StartsWith(name, "data:")) continue;
      while (absl::StartsWith(name, "./")) name = name.substr(2);
      // Percent-encoded names (RFC 3986) are left to the loader: only plain names are uploaded.
      if (!IsSafeRelativeName(name) || !FileExists(JoinPath(dir, name))) continue;
      if (std::find(files.begin(), files.end(), name) == files.end()) files.push_back(name);
    }
  }
  return files;
}

}  // namespace radiosity
