// Random numbers for the Monte Carlo estimators: PCG32 (O'Neill 2014), seeded per independent
// stream so results do not depend on how work is split between threads.
#ifndef RADIOSITY_SOLVER_TRANSPORT_RNG_H_
#define RADIOSITY_SOLVER_TRANSPORT_RNG_H_

#include <cstdint>

namespace radiosity {

// SplitMix64 (Steele et al. 2014): mixes a 64-bit value into a well-distributed one.
inline uint64_t Mix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// Stream key of (seed, a, b, c): distinct keys give independent streams.
uint64_t StreamKey(uint64_t seed, uint64_t a, uint64_t b = 0, uint64_t c = 0);

class Rng {
 public:
  explicit Rng(uint64_t stream_key) : state_(0), inc_((Mix64(stream_key) << 1u) | 1u) {
    Next();
    state_ += Mix64(stream_key ^ 0x5851f42d4c957f2dULL);
    Next();
  }

  uint32_t Next() {
    uint64_t old = state_;
    state_ = old * 6364136223846793005ULL + inc_;
    uint32_t xorshifted = static_cast<uint32_t>(((old >> 18u) ^ old) >> 27u);
    uint32_t rot = static_cast<uint32_t>(old >> 59u);
    return (xorshifted >> rot) | (xorshifted << ((~rot + 1u) & 31));
  }

  // Uniform double in [0, 1) with 53 random bits.
  double Uniform() {
    uint64_t hi = Next(), lo = Next();
    return static_cast<double>(((hi << 32) | lo) >> 11) * 0x1.0p-53;
  }

 private:
  uint64_t state_;
  uint64_t inc_;
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_RNG_H_
