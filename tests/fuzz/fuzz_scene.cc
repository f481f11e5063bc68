// libFuzzer target: the native Scene reader (binary and JSON) and meshing (tests/fuzz/run.sh).
#include <cstdint>
#include <string>

#include "tests/fuzz/fuzz_entry.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  radiosity::fuzz::RunScene(std::string(reinterpret_cast<const char*>(data), size));
  return 0;
}
