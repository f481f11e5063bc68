// The native scene format: conversion between the scene message (radiosity.v1.Scene,
// proto/radiosity/v1/scene.proto) and the solver's scene model, and its JSON and binary encodings.
#ifndef RADIOSITY_SOLVER_INPUT_SCENE_CODEC_H_
#define RADIOSITY_SOLVER_INPUT_SCENE_CODEC_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "radiosity/v1/scene.pb.h"
#include "solver/geometry/scene.h"

namespace radiosity {

// Converts a Scene message to the solver's model. Each surface's vertices are appended to the
// global vertex array and its face indices offset accordingly. Checks the message first, with
// errors naming `source` and the field path, e.g.
//   "scene.json: surfaces[2] ('floor').faces[5].indices[3]: vertex index 7 is out of range
//    (surface has 4 vertices)",
// then runs ValidateScene and DropDegenerateFaces (zero-area faces are dropped with a warning
// appended to `warnings`, which may be null). `source` becomes Scene::source.
absl::StatusOr<Scene> SceneFromProto(const radiosity::v1::Scene& msg, const std::string& source,
                                     std::vector<std::string>* warnings = nullptr);

// Converts the solver's model to a Scene message. Every surface gets its own vertex list: the
// vertices its faces use, in the order of their global indices (vertices shared between surfaces
// are duplicated; vertices no face uses are left out). Materials are referenced by name, so
// material and surface names must be unique and non-empty for the result to load back.
radiosity::v1::Scene SceneToProto(const Scene& scene);

// Reads a native scene: `bytes` in the protobuf JSON mapping (json) or binary. Errors name `path`
// (and for JSON the line and column); the result is SceneFromProto's.
absl::StatusOr<Scene> ParseNativeScene(const std::string& bytes, bool json, const std::string& path,
                                       std::vector<std::string>* warnings);

// The native encoding of `scene`: JSON (indented, snake_case field names) or binary.
absl::StatusOr<std::string> EncodeNativeScene(const Scene& scene, bool json,
                                              const std::string& path);

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_INPUT_SCENE_CODEC_H_
