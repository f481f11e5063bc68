#include "solver/transport/rng.h"

namespace radiosity {

uint64_t StreamKey(uint64_t seed, uint64_t a, uint64_t b, uint64_t c) {
  return Mix64(Mix64(Mix64(Mix64(seed) ^ a) ^ b) ^ c);
}

}  // namespace radiosity
