// Randomised quasi-Monte Carlo points: Owen-scrambled Sobol' points with a scrambled index
// ("shuffled scrambled Sobol'", Burley 2020), keyed per stream like Rng so that the numbers are a
// pure function of (seed, index, dimension) and never depend on which thread asks.
//
// Sobol' points (Sobol' 1967). Dimension j's point number i, as a 32-bit binary fraction, is the
// XOR of the direction numbers v_{j,k} selected by the set bits k of i (digital construction,
// Bratley & Fox 1988 "Algorithm 659", ACM TOMS 14(1)):
//   x_j(i) = XOR_{k : bit k of i is 1} v_{j,k}.
// Dimension 0 has v_{0,k} = 2^-(k+1), the van der Corput sequence (the bits of i reversed). The
// other dimensions take their direction numbers from Joe & Kuo (2008), "Constructing Sobol'
// sequences with better two-dimensional projections", SIAM J. Sci. Comput. 30(5), table
// new-joe-kuo-6.21201: dimension j >= 1 is row d = j + 1 of that table, with primitive polynomial
// x^s + a_1 x^{s-1} + ... + a_{s-1} x + 1 (a packs a_1..a_{s-1}, high bit first), initial values
// m_1..m_s, v_k = m_k / 2^k for k <= s, and for k > s
//   v_k = a_1 v_{k-1} ^ a_2 v_{k-2} ^ ... ^ a_{s-1} v_{k-s+1} ^ v_{k-s} ^ (v_{k-s} / 2^s).
// The points form a (t,s)-sequence in base 2: every aligned block of 2^m points,
// indices [c 2^m, (c+1) 2^m), is a (t,m,s)-net (Niederreiter 1992, "Random Number Generation
// and Quasi-Monte Carlo Methods", ch. 4). Each dimension alone is a (0,1)-sequence (the first 2^m
// points put one point in each interval [k/2^m, (k+1)/2^m)), and dimensions 0 and 1 together are
// a (0,2)-sequence.
//
// Owen scrambling (Owen 1995, "Randomly permuted (t,m,s)-nets and (t,s)-sequences", in Monte
// Carlo and Quasi-Monte Carlo Methods in Scientific Computing, LNS 106): a nested uniform scramble
// flips digit k of a coordinate by a random bit that depends only on digits 1..k-1, so it maps
// every elementary interval onto an elementary interval of the same size and keeps every net
// property, while making each point uniform on [0,1)^s and the estimate unbiased; for smooth
// integrands its variance is O(N^-3 (log N)^(s-1)) (Owen 1997, "Scrambled net variance for
// integrals of smooth functions", Ann. Statist. 25(4)). In base 2 Laine & Karras (2011,
// "Stratified sampling for stochastic transparency", EGSR) observed that a hash built from
// additions, multiplications by constants and x ^= x * even lets each bit depend only on the
// bits below it; applied to the bit-reversed value it is an Owen scramble (Burley 2020,
// "Practical Hash-based Owen Scrambling", JCGT 9(4)). The hash used here is Vegdahl's (2021,
// "Building a Better LK Hash", psychopath.io): Burley's structure with better-mixing steps and
// constants.
//
// Shuffled scrambled Sobol' (Burley 2020): the index, read as the binary fraction index 2^-32, is
// Owen-scrambled too, with a seed of its own, before the Sobol' point is looked up; then each
// dimension is Owen-scrambled with its own seed. An Owen scramble of the index bits maps every
// aligned block of 2^m indices onto an aligned block of 2^m indices, so indices 0..2^m-1 give the
// points of one aligned block of the Sobol' sequence: a digitally shifted copy of its first 2^m
// points, whose shift the dimension scrambles absorb. Every prefix of 2^m indices keeps the
// stratification and the t-values of the unscrambled first 2^m points, and different seeds give
// independent, decorrelated sequences.
#ifndef RADIOSITY_SOLVER_TRANSPORT_SOBOL_H_
#define RADIOSITY_SOLVER_TRANSPORT_SOBOL_H_

#include <cstdint>

namespace radiosity {

// Number of Sobol' dimensions: van der Corput, then rows d = 2..32 of new-joe-kuo-6.21201.
inline constexpr int kSobolDimensions = 32;

// Point number `index` of the unscrambled Sobol' sequence in dimension `dim`, as the 32 bits of
// a binary fraction (the value is SobolBits(index, dim) * 2^-32). Dimension 0 is the van der
// Corput sequence. Requires 0 <= dim < kSobolDimensions.
uint32_t SobolBits(uint32_t index, int dim);

// Base-2 nested uniform (Owen) scramble of the 32-bit binary fraction x: bit 31 - k (digit k + 1)
// is flipped by a hash of the seed and of the bits above it, so values that share their top k
// bits map to values that share their top k bits, and every aligned block of 2^k values maps
// onto an aligned block. A bijection of the 32-bit integers for each seed. Burley 2020 with
// Vegdahl's 2021 hash.
uint32_t NestedUniformScramble(uint32_t x, uint32_t seed);

// Owen-scrambled, index-shuffled Sobol' points keyed by a 64-bit seed (e.g. StreamKey(...) of a
// stream), cheap to construct (a few hashes, no tables). Thread-safe: Get is a const pure
// function.
class OwenSobol {
 public:
  explicit OwenSobol(uint64_t seed);

  // Coordinate `dim` of point number `index`, in [0, 1) (never 1.0). The top 32 bits are the
  // scrambled Sobol' digits; the 21 bits below 2^-32 are hashed from the seed, the dimension
  // and those 32 digits, as a nested uniform scramble would fill the digits past the last
  // nonzero one, so values are not all multiples of 2^-32. Requires 0 <= dim <
  // kSobolDimensions.
  double Get(uint32_t index, int dim) const;

  // The top 32 bits of Get(index, dim), as a binary fraction.
  uint32_t GetBits(uint32_t index, int dim) const;

  // Coordinates first_dim .. first_dim + count - 1 of point `index`: the values of Get, with the
  // index scrambled once for all of them.
  void GetPoint(uint32_t index, int first_dim, int count, double* out) const;

 private:
  uint64_t DimHash(int dim) const;
  double Value(uint32_t bits, uint64_t dim_hash) const;

  static constexpr int kCachedDimensions = 8;
  uint64_t key_;         // Hashed seed; the per-dimension seeds are hashed from it.
  uint32_t index_seed_;  // Seed of the index scramble.
  uint64_t dim_hash_[kCachedDimensions];  // DimensionHash of the first dimensions.
};

}  // namespace radiosity

#endif  // RADIOSITY_SOLVER_TRANSPORT_SOBOL_H_
