// libFuzzer target: models through assimp (glTF, FBX, Collada, 3DS, PLY, STL) and meshing
// (tests/fuzz/run.sh).
#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <string>

#include "tests/fuzz/fuzz_entry.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string scratch = [] {
    char dir[] = "/tmp/radiosity-fuzz-XXXXXX";
    return std::string(mkdtemp(dir));
  }();
  radiosity::fuzz::RunModel(std::string(reinterpret_cast<const char*>(data), size), scratch);
  return 0;
}
