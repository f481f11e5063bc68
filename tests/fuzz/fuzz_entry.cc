#include "tests/fuzz/fuzz_entry.h"

#include <google/protobuf/util/json_util.h>

#include <fstream>
#include <iterator>
#include <vector>

#include "radiosity/v1/scene.pb.h"
#include "solver/geometry/mesh.h"
#include "solver/input/model_loader.h"
#include "solver/input/obj_loader.h"
#include "solver/input/scene_codec.h"

namespace radiosity::fuzz {

namespace {

void MeshIt(const absl::StatusOr<Scene>& scene) {
  if (!scene.ok()) return;
  MeshOptions options;
  options.max_elements = 256;
  absl::StatusOr<Mesh> mesh = Mesh::Build(*scene, options);
  if (!mesh.ok()) return;
  // Every element found again from its own parameter rectangle's centre.
  for (const Element& e : mesh->elements()) {
    (void)mesh->FindElement(e.face, 0.5 * (e.u0 + e.u1), 0.5 * (e.v0 + e.v1));
  }
}

}  // namespace

void RunObj(const std::string& input, const std::string& scratch_dir) {
  std::string obj = input, mtl;
  const std::string marker = "\n#MTL\n";
  if (size_t at = input.find(marker); at != std::string::npos) {
    obj = input.substr(0, at + 1);
    mtl = input.substr(at + marker.size());
  }
  std::ofstream(scratch_dir + "/f.mtl", std::ios::binary | std::ios::trunc) << mtl;
  std::vector<std::string> warnings;
  MeshIt(ParseObj(obj, "fuzz.obj", scratch_dir, &warnings));
}

void RunScene(const std::string& input) {
  radiosity::v1::Scene msg;
  if (msg.ParseFromString(input)) MeshIt(SceneFromProto(msg, "fuzz.pb", nullptr));
  radiosity::v1::Scene json_msg;
  if (CheckText(input, "fuzz.json").ok() &&
      google::protobuf::util::JsonStringToMessage(input, &json_msg).ok()) {
    MeshIt(SceneFromProto(json_msg, "fuzz.json", nullptr));
  }
}

void RunModel(const std::string& input, const std::string& scratch_dir) {
  if (input.empty()) return;
  constexpr size_t kCount = std::size(kModelFuzzExtensions);
  const std::string path =
      scratch_dir + "/f" + kModelFuzzExtensions[static_cast<unsigned char>(input[0]) % kCount];
  std::ofstream(path, std::ios::binary | std::ios::trunc) << input.substr(1);
  ModelOptions options;
  options.confine_to_directory = true;
  options.vertex_colors = (static_cast<unsigned char>(input[0]) / kCount) % 2 == 1;
  std::vector<std::string> warnings;
  MeshIt(LoadModel(path, &warnings, options));
}

}  // namespace radiosity::fuzz
