// The code paths the fuzzers drive, shared with the regression test that replays every input a
// fuzzer ever crashed on (tests/fuzz_regression_test.cc).
#ifndef RADIOSITY_TESTS_FUZZ_FUZZ_ENTRY_H_
#define RADIOSITY_TESTS_FUZZ_FUZZ_ENTRY_H_

#include <string>

namespace radiosity::fuzz {

// OBJ input, optionally followed by a line "#MTL" and the text of the MTL file it may name as
// "mtllib f.mtl". Loads it, and meshes what loads (at most 256 elements).
void RunObj(const std::string& input, const std::string& scratch_dir);

// A native Scene: tried as binary protobuf and as its JSON mapping; meshes what loads.
void RunScene(const std::string& input);

// A model read through assimp: the first byte picks the format (modulo the count of
// kModelFuzzExtensions), the rest is the file, written into `scratch_dir` and read confined to
// it; meshes what loads.
inline constexpr const char* kModelFuzzExtensions[] = {".glb", ".gltf", ".fbx", ".dae",
                                                       ".3ds", ".ply",  ".stl"};
void RunModel(const std::string& input, const std::string& scratch_dir);

}  // namespace radiosity::fuzz

#endif  // RADIOSITY_TESTS_FUZZ_FUZZ_ENTRY_H_
