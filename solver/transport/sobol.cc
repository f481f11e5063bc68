#include "solver/transport/sobol.h"

#include <cassert>
#include <cstdint>

#include "solver/transport/rng.h"

namespace radiosity {
namespace {

// A row of Joe & Kuo's new-joe-kuo-6.21201: degree s of the primitive polynomial, its inner
// coefficients a (a_1..a_{s-1}, a_1 the high bit) and the initial values m_1..m_s.
struct JoeKuoRow {
  int s;
  uint32_t a;
  uint32_t m[7];
};

// Rows d = 2..32 of new-joe-kuo-6.21201 (row d = 1, the van der Corput dimension, has no entry).
constexpr JoeKuoRow kJoeKuo[kSobolDimensions - 1] = {
    {1, 0, {1}},                         // d = 2
    {2, 1, {1, 3}},                      // d = 3
    {3, 1, {1, 3, 1}},                   // d = 4
    {3, 2, {1, 1, 1}},                   // d = 5
    {4, 1, {1, 1, 3, 3}},                // d = 6
    {4, 4, {1, 3, 5, 13}},               // d = 7
    {5, 2, {1, 1, 5, 5, 17}},            // d = 8
    {5, 4, {1, 1, 5, 5, 5}},             // d = 9
    {5, 7, {1, 1, 7, 11, 19}},           // d = 10
    {5, 11, {1, 1, 5, 1, 1}},            // d = 11
    {5, 13, {1, 1, 1, 3, 11}},           // d = 12
    {5, 14, {1, 3, 5, 5, 31}},           // d = 13
    {6, 1, {1, 3, 3, 9, 7, 49}},         // d = 14
    {6, 13, {1, 1, 1, 15, 21, 21}},      // d = 15
    {6, 16, {1, 3, 1, 13, 27, 49}},      // d = 16
    {6, 19, {1, 1, 1, 15, 7, 5}},        // d = 17
    {6, 22, {1, 3, 1, 15, 13, 25}},      // d = 18
    {6, 25, {1, 1, 5, 5, 19, 61}},       // d = 19
    {7, 1, {1, 3, 7, 11, 23, 15, 103}},  // d = 20
    {7, 4, {1, 3, 7, 13, 13, 15, 69}},   // d = 21
    {7, 7, {1, 1, 3, 13, 7, 35, 63}},    // d = 22
    {7, 8, {1, 3, 5, 9, 1, 25, 53}},     // d = 23
    {7, 14, {1, 3, 1, 13, 9, 35, 107}},  // d = 24
    {7, 19, {1, 3, 1, 5, 27, 61, 31}},   // d = 25
    {7, 21, {1, 1, 5, 11, 19, 41, 61}},  // d = 26
    {7, 28, {1, 3, 5, 3, 3, 13, 69}},    // d = 27
    {7, 31, {1, 1, 7, 13, 1, 19, 1}},    // d = 28
    {7, 32, {1, 3, 7, 5, 13, 19, 59}},   // d = 29
    {7, 37, {1, 1, 3, 9, 25, 29, 41}},   // d = 30
    {7, 41, {1, 3, 5, 13, 23, 1, 55}},   // d = 31
    {7, 42, {1, 3, 7, 3, 13, 59, 17}},   // d = 32
};

// Plain arrays rather than std::array keep the compile-time evaluation within Clang's default
// step limit.
struct DirectionTable {
  uint32_t v[kSobolDimensions][32];
};

// v[j][k] is the direction number v_{k+1} of dimension j as a 32-bit binary fraction (sobol.h).
constexpr DirectionTable MakeDirections() {
  DirectionTable table{};
  auto& v = table.v;
  for (int k = 0; k < 32; ++k) v[0][k] = 1u << (31 - k);
  for (int j = 1; j < kSobolDimensions; ++j) {
    const JoeKuoRow& row = kJoeKuo[j - 1];
    const int s = row.s;
    for (int k = 0; k < 32; ++k) {
      if (k < s) {
        v[j][k] = row.m[k] << (31 - k);
        continue;
      }
      uint32_t x = v[j][k - s] ^ (v[j][k - s] >> s);
      for (int i = 1; i < s; ++i) {
        if ((row.a >> (s - 1 - i)) & 1u) x ^= v[j][k - i];
      }
      v[j][k] = x;
    }
  }
  return table;
}

// Byte tables of the bit-reversed direction numbers: kReversedByteTable[j][b][byte] is the XOR of
// ReverseBits(v[j][31 - k]) over the set bits k - 8 b of the byte, for k in [8 b, 8 b + 8). XOR-ing
// one entry per byte of ReverseBits(i) gives ReverseBits(SobolBits(i, j)): four loads instead of a
// loop over the set bits of i (a scrambled index has about 16 of them).
struct ByteTable {
  uint32_t t[kSobolDimensions][4][256];
};

constexpr uint32_t ReverseBits(uint32_t x) {
  x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
  x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
  return (x >> 16) | (x << 16);
}

constexpr ByteTable MakeReversedByteTable(const DirectionTable& directions) {
  ByteTable table{};
  const auto& v = directions.v;
  auto& t = table.t;
  for (int j = 0; j < kSobolDimensions; ++j) {
    for (int b = 0; b < 4; ++b) {
      // Bytes in [2^bit, 2^(bit+1)) are those below 2^bit with bit `bit` added.
      for (int bit = 0; bit < 8; ++bit) {
        const uint32_t reversed = ReverseBits(v[j][31 - (8 * b + bit)]);
        const uint32_t low = 1u << bit;
        for (uint32_t byte = low; byte < 2 * low; ++byte) {
          t[j][b][byte] = t[j][b][byte - low] ^ reversed;
        }
      }
    }
  }
  return table;
}

constexpr ByteTable kReversedByteTable = MakeReversedByteTable(MakeDirections());

// ReverseBits(SobolBits(i, dim)) from reversed_index = ReverseBits(i).
inline uint32_t ReversedSobol(uint32_t reversed_index, int dim) {
  const auto& t = kReversedByteTable.t[dim];
  return t[0][reversed_index & 0xffu] ^ t[1][(reversed_index >> 8) & 0xffu] ^
         t[2][(reversed_index >> 16) & 0xffu] ^ t[3][reversed_index >> 24];
}

// Laine-Karras style permutation of a bit-reversed value: every step (adding the seed,
// multiplying by an odd number, x ^= x * even) leaves bit k as itself XOR a function of the
// bits below it. Constants from Vegdahl 2021.
inline uint32_t LaineKarrasPermutation(uint32_t x, uint32_t seed) {
  x ^= x * 0x3d20adeau;
  x += seed;
  x *= (seed >> 16) | 1u;
  x ^= x * 0x05526c56u;
  x ^= x * 0x53a22864u;
  return x;
}

constexpr uint64_t kGolden = 0x9e3779b97f4a7c15ULL;
constexpr uint64_t kSobolStreamTag = 0x536f626f6c4f7765ULL;  // "SobolOwe"

// Per-dimension hash of the key: its low 32 bits seed the dimension's scramble, all 64 bits key the
// digits below 2^-32.
inline uint64_t DimensionHash(uint64_t key, int dim) {
  return Mix64(key + static_cast<uint64_t>(dim + 1) * kGolden);
}

// Bit-reversed Owen-scrambled index; bit k of it is bit 31 - k of the shuffled index.
inline uint32_t ScrambledReversedIndex(uint32_t index, uint32_t index_seed) {
  return LaineKarrasPermutation(ReverseBits(index), index_seed);
}

inline uint32_t ScrambledPoint(uint32_t reversed_index, uint64_t dim_hash, int dim) {
  assert(dim >= 0 && dim < kSobolDimensions);
  // Bit-reversed Sobol' point of the shuffled index.
  const uint32_t reversed_point = ReversedSobol(reversed_index, dim);
  return ReverseBits(LaineKarrasPermutation(reversed_point, static_cast<uint32_t>(dim_hash)));
}

inline uint32_t ScrambledBits(uint32_t index, uint32_t index_seed, uint64_t dim_hash, int dim) {
  return ScrambledPoint(ScrambledReversedIndex(index, index_seed), dim_hash, dim);
}

}  // namespace

uint32_t SobolBits(uint32_t index, int dim) {
  assert(dim >= 0 && dim < kSobolDimensions);
  return ReverseBits(ReversedSobol(ReverseBits(index), dim));
}

uint32_t NestedUniformScramble(uint32_t x, uint32_t seed) {
  return ReverseBits(LaineKarrasPermutation(ReverseBits(x), seed));
}

OwenSobol::OwenSobol(uint64_t seed)
    : key_(StreamKey(seed, kSobolStreamTag)), index_seed_(static_cast<uint32_t>(Mix64(key_))) {
  for (int d = 0; d < kCachedDimensions; ++d) dim_hash_[d] = DimensionHash(key_, d);
}

uint64_t OwenSobol::DimHash(int dim) const {
  return dim < kCachedDimensions ? dim_hash_[dim] : DimensionHash(key_, dim);
}

double OwenSobol::Value(uint32_t bits, uint64_t dim_hash) const {
  // Digits 33..53: a hash of the dimension's key and of the point's first 32 scrambled digits
  // (a nested uniform scramble draws each deeper digit from the node its prefix reaches).
  const uint64_t low = Mix64(dim_hash ^ (static_cast<uint64_t>(bits) << 32 | bits)) >> 43;
  return static_cast<double>(static_cast<uint64_t>(bits) << 21 | low) * 0x1.0p-53;
}

uint32_t OwenSobol::GetBits(uint32_t index, int dim) const {
  return ScrambledBits(index, index_seed_, DimHash(dim), dim);
}

double OwenSobol::Get(uint32_t index, int dim) const {
  const uint64_t dim_hash = DimHash(dim);
  return Value(ScrambledBits(index, index_seed_, dim_hash, dim), dim_hash);
}

void OwenSobol::GetPoint(uint32_t index, int first_dim, int count, double* out) const {
  const uint32_t reversed_index = ScrambledReversedIndex(index, index_seed_);
  for (int k = 0; k < count; ++k) {
    const int dim = first_dim + k;
    const uint64_t dim_hash = DimHash(dim);
    out[k] = Value(ScrambledPoint(reversed_index, dim_hash, dim), dim_hash);
  }
}

}  // namespace radiosity
