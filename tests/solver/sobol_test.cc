// Owen-scrambled Sobol' points (solver/transport/sobol.h): the unscrambled sequence against
// values from SciPy's independent implementation (scipy.stats.qmc.Sobol, the same Joe-Kuo table),
// exact stratification and (t,m,2)-net properties before and after scrambling (t counted by
// brute force and from the rank of the generator matrices), integration error against plain
// Monte Carlo's analytic standard error and its rate in N, unbiasedness over seeds, uniformity
// over seeds, determinism across objects and threads, and the range [0, 1).
#include "solver/transport/sobol.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <set>
#include <thread>
#include <utility>
#include <vector>

#include "solver/transport/rng.h"

namespace radiosity {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kMaxLog2Points = 12;

// The 32 digits of point `index` in dimension `dim` of some point set.
using PointFn = std::function<uint32_t(uint32_t index, int dim)>;

PointFn Unscrambled() {
  return [](uint32_t index, int dim) { return SobolBits(index, dim); };
}

// The top 32 digits of the scrambled double (exact: scaling by 2^32 is exact and the value is
// below 1).
PointFn Scrambled(uint64_t seed) {
  return [sampler = OwenSobol(seed)](uint32_t index, int dim) {
    return static_cast<uint32_t>(sampler.Get(index, dim) * 4294967296.0);
  };
}

std::vector<std::pair<const char*, PointFn>> PointSets() {
  return {{"unscrambled", Unscrambled()},
          {"seed 1", Scrambled(1)},
          {"seed 0xdeadbeef", Scrambled(0xdeadbeef)},
          {"seed StreamKey(7, 3)", Scrambled(StreamKey(7, 3))}};
}

// First `bits` digits of x (0 when bits == 0).
uint32_t Leading(uint32_t x, int bits) { return bits == 0 ? 0u : x >> (32 - bits); }

// Whether points 0..2^m-1 of dimensions (a, b) put exactly 2^t points in every elementary
// interval [i/2^p, (i+1)/2^p) x [j/2^q, (j+1)/2^q) with p + q = m - t: a (t,m,2)-net.
bool IsNet(const std::vector<uint32_t>& xa, const std::vector<uint32_t>& xb, int m, int t) {
  for (int p = 0; p <= m - t; ++p) {
    const int q = m - t - p;
    std::vector<uint32_t> count(size_t{1} << (m - t), 0);
    for (size_t i = 0; i < (size_t{1} << m); ++i) {
      ++count[(Leading(xa[i], p) << q) | Leading(xb[i], q)];
    }
    for (uint32_t c : count) {
      if (c != (1u << t)) return false;
    }
  }
  return true;
}

std::vector<uint32_t> Column(const PointFn& point, int m, int dim) {
  std::vector<uint32_t> x(size_t{1} << m);
  for (uint32_t i = 0; i < x.size(); ++i) x[i] = point(i, dim);
  return x;
}

// Smallest t for which the first 2^m points of dimensions (a, b) are a (t,m,2)-net, by counting.
int BruteForceT(const PointFn& point, int m, int a, int b) {
  const std::vector<uint32_t> xa = Column(point, m, a), xb = Column(point, m, b);
  for (int t = 0; t < m; ++t) {
    if (IsNet(xa, xb, m, t)) return t;
  }
  return m;
}

// Whether the GF(2) vectors are linearly independent.
bool Independent(const std::vector<uint32_t>& rows) {
  std::array<uint32_t, 32> basis{};  // basis[b]: a vector whose leading bit is b
  for (uint32_t v : rows) {
    for (int b = 31; b >= 0; --b) {
      if (!((v >> b) & 1u)) continue;
      if (basis[b] == 0) {
        basis[b] = v;
        break;
      }
      v ^= basis[b];
    }
    if (v == 0) return false;  // reduced to zero: a combination of the rows before it
  }
  return true;
}

// Row r (digit r + 1) of the m x m generator matrix of dimension d, as a mask over the index
// bits: point i's digit r + 1 is the parity of (row & i).
uint32_t GeneratorRow(int d, int r, int m) {
  uint32_t row = 0;
  for (int j = 0; j < m; ++j) {
    if ((SobolBits(1u << j, d) >> (31 - r)) & 1u) row |= 1u << j;
  }
  return row;
}

// t of the first 2^m points of dimensions (a, b) from the generator matrices: the points are a
// (t,m,2)-net iff, for every p + q = m - t, the first p rows of C_a and the first q rows of C_b
// are linearly independent (Niederreiter 1992, ch. 4).
int GeneratorMatrixT(int m, int a, int b) {
  for (int k = m; k >= 0; --k) {
    bool all_independent = true;
    for (int p = 0; p <= k && all_independent; ++p) {
      std::vector<uint32_t> rows;
      for (int r = 0; r < p; ++r) rows.push_back(GeneratorRow(a, r, m));
      for (int r = 0; r < k - p; ++r) rows.push_back(GeneratorRow(b, r, m));
      all_independent = Independent(rows);
    }
    if (all_independent) return m - k;
  }
  return m;
}

// FNV-1a over the 32 direction numbers of a dimension (the points at indices 2^k).
uint64_t DirectionChecksum(int dim) {
  uint64_t h = 0xcbf29ce484222325ULL;
  for (int k = 0; k < 32; ++k) {
    h ^= SobolBits(1u << k, dim);
    h *= 0x100000001b3ULL;
  }
  return h;
}

TEST(SobolTest, MatchesSciPyReference) {
  // scipy.stats.qmc.Sobol(d=32, scramble=False, bits=32) (SciPy 1.10, new-joe-kuo-6.21201),
  // reordered from its Gray-code order to index order.
  const double first_points[4][8] = {{0.0, 0.5, 0.25, 0.75, 0.125, 0.625, 0.375, 0.875},
                                     {0.0, 0.5, 0.75, 0.25, 0.625, 0.125, 0.375, 0.875},
                                     {0.0, 0.5, 0.75, 0.25, 0.375, 0.875, 0.625, 0.125},
                                     {0.0, 0.5, 0.75, 0.25, 0.125, 0.625, 0.875, 0.375}};
  for (int d = 0; d < 4; ++d) {
    for (uint32_t i = 0; i < 8; ++i) {
      EXPECT_EQ(SobolBits(i, d) * 0x1.0p-32, first_points[d][i]) << "dim " << d << " index " << i;
    }
  }
  EXPECT_EQ(SobolBits(0xffffffffu, 31), 0x8391ef09u);
  EXPECT_EQ(SobolBits(0x12345678u, 17), 0x9c156028u);
  // FNV-1a of each dimension's direction numbers (SciPy's Sobol()._sv rows).
  const uint64_t checksums[kSobolDimensions] = {
      0x0853bbd496535fd0ULL, 0xdaf135459ed3ad6aULL, 0x2f0f56d931d40e88ULL, 0xb0c6dc56d416c966ULL,
      0x664e6e11c69e8cf4ULL, 0xd02a65ed54e131a2ULL, 0x4650a59f6363ddeeULL, 0xd6120619a8cd0890ULL,
      0xdba77dd93fb19ec0ULL, 0x1b5b9148b0643938ULL, 0x1151ee3bb2dd1b84ULL, 0x51732a925b53bf74ULL,
      0x34b37b435bd6d8daULL, 0x1f9e20557106fa06ULL, 0x6edfa601f748394cULL, 0x817b0e200dd0a888ULL,
      0xca07728b51d5734eULL, 0x6a1a52e0f4511f30ULL, 0xedacdf3623a24baaULL, 0x51256bfc39d3df82ULL,
      0x3b34cc60055ba030ULL, 0xa376231bc14fbbb0ULL, 0x93ce7d4c8257a2c8ULL, 0x90775e382986d83cULL,
      0xf79b4c889698f414ULL, 0x4f1a4550bb21c256ULL, 0x242f93f61860bc56ULL, 0xc6c804b866b5eff8ULL,
      0xccae9b16e82c53b8ULL, 0xebc1f5363bebcb0cULL, 0x52a7c007f6cb2744ULL, 0x5425d16210141d2aULL};
  for (int d = 0; d < kSobolDimensions; ++d) {
    EXPECT_EQ(DirectionChecksum(d), checksums[d]) << "dim " << d;
  }
}

TEST(SobolTest, EveryDimensionIsStratified) {
  for (const auto& [name, point] : PointSets()) {
    for (int d = 0; d < kSobolDimensions; ++d) {
      const std::vector<uint32_t> x = Column(point, kMaxLog2Points, d);
      for (int m = 1; m <= kMaxLog2Points; ++m) {
        std::vector<int> count(size_t{1} << m, 0);
        for (size_t i = 0; i < (size_t{1} << m); ++i) ++count[Leading(x[i], m)];
        for (size_t k = 0; k < count.size(); ++k) {
          ASSERT_EQ(count[k], 1) << name << ", dim " << d << ", m " << m << ", interval " << k;
        }
      }
    }
  }
}

TEST(SobolTest, FirstTwoDimensionsAreZeroMTwoNets) {
  for (const auto& [name, point] : PointSets()) {
    const std::vector<uint32_t> x0 = Column(point, kMaxLog2Points, 0);
    const std::vector<uint32_t> x1 = Column(point, kMaxLog2Points, 1);
    for (int m = 1; m <= kMaxLog2Points; ++m) {
      EXPECT_TRUE(IsNet(x0, x1, m, 0)) << name << ", m " << m;
    }
  }
}

TEST(SobolTest, PairTValuesMatchGeneratorMatricesAndSurviveScrambling) {
  const std::pair<int, int> pairs[] = {{0, 1},  {2, 3},   {1, 4}, {0, 5},  {3, 7},
                                       {5, 12}, {14, 15}, {8, 9}, {20, 31}};
  for (const auto& [a, b] : pairs) {
    for (int m = 2; m <= kMaxLog2Points; ++m) {
      const int t = BruteForceT(Unscrambled(), m, a, b);
      ASSERT_EQ(t, GeneratorMatrixT(m, a, b)) << "dims " << a << "," << b << ", m " << m;
      if (a == 0 && b == 1) {
        ASSERT_EQ(t, 0);
      }
      for (const auto& [name, point] : PointSets()) {
        ASSERT_EQ(BruteForceT(point, m, a, b), t)
            << name << ", dims " << a << "," << b << ", m " << m;
      }
      if (m == kMaxLog2Points) {
        std::printf("[ sobol    ] t of dims (%d,%d), 2^%d points: %d\n", a, b, m, t);
      }
    }
  }
}

TEST(SobolTest, NestedUniformScrambleMapsAlignedBlocksToAlignedBlocks) {
  for (uint32_t seed : {0u, 1u, 0x9e3779b9u, 0xffffffffu}) {
    // Top k output digits depend on the top k input digits only, bijectively.
    for (int k : {1, 5, 16}) {
      std::set<uint32_t> images;
      for (uint32_t prefix = 0; prefix < (1u << k); ++prefix) {
        const uint32_t base = prefix << (32 - k);
        const uint32_t image = NestedUniformScramble(base, seed) >> (32 - k);
        images.insert(image);
        for (uint32_t low : {1u, 0x1234u, (1u << (32 - k)) - 1}) {
          ASSERT_EQ(NestedUniformScramble(base | low, seed) >> (32 - k), image)
              << "seed " << seed << ", k " << k << ", prefix " << prefix;
        }
      }
      EXPECT_EQ(images.size(), size_t{1} << k) << "seed " << seed << ", k " << k;
    }
  }
  EXPECT_NE(NestedUniformScramble(0, 1), NestedUniformScramble(0, 2));
}

double SineFactor(double x) { return 0.5 * kPi * std::sin(kPi * x); }
double LinearFactor(double x) { return 1.0 + 0.5 * (x - 0.5); }
double ExpFactor(double x) { return std::exp(-x) / (1.0 - std::exp(-1.0)); }

// f(x) = prod_{d in dims} factor(x_d), each factor integrating to 1 on [0, 1), so that the
// integral is 1 and the variance is (int factor^2)^5 - 1.
struct Integrand {
  const char* name;
  std::array<int, 5> dims;
  double (*factor)(double);
  double factor_second_moment;
};

// int (pi/2 sin(pi x))^2 = pi^2/8; int (1 + (x - 1/2)/2)^2 = 1 + 1/48;
// int (e^-x / (1 - 1/e))^2 = (1 - e^-2) / (2 (1 - 1/e)^2).
const double kExpSecondMoment = (1.0 - std::exp(-2.0)) / (2.0 * std::pow(1.0 - std::exp(-1.0), 2));
const Integrand kSine04 = {
    "prod pi/2 sin(pi x), dims 0-4", {0, 1, 2, 3, 4}, SineFactor, kPi* kPi / 8};
const Integrand kLinear04 = {
    "prod 1 + (x - 1/2)/2, dims 0-4", {0, 1, 2, 3, 4}, LinearFactor, 1.0 + 1.0 / 48};
const Integrand kExp04 = {
    "prod e^-x / (1 - 1/e), dims 0-4", {0, 1, 2, 3, 4}, ExpFactor, kExpSecondMoment};
const Integrand kExp1115 = {
    "prod e^-x / (1 - 1/e), dims 11-15", {11, 12, 13, 14, 15}, ExpFactor, kExpSecondMoment};
const Integrand kLinear2731 = {
    "prod 1 + (x - 1/2)/2, dims 27-31", {27, 28, 29, 30, 31}, LinearFactor, 1.0 + 1.0 / 48};

struct Estimates {
  double rms_error;               // over the seeds, against the exact integral 1
  double mean;                    // of the estimates
  double standard_error_of_mean;  // from their spread
};

// Estimates of the integral of f by the first n points of 64 independently seeded sequences.
Estimates Integrate(const Integrand& f, uint32_t n) {
  constexpr int kSeeds = 64;
  std::vector<double> estimates;
  for (int s = 0; s < kSeeds; ++s) {
    const OwenSobol sampler(StreamKey(2024, s));
    double total = 0;
    for (uint32_t i = 0; i < n; ++i) {
      double value = 1;
      for (int d : f.dims) value *= f.factor(sampler.Get(i, d));
      total += value;
    }
    estimates.push_back(total / n);
  }
  double sum = 0, sum_squared_error = 0;
  for (double e : estimates) {
    sum += e;
    sum_squared_error += (e - 1.0) * (e - 1.0);
  }
  const double mean = sum / kSeeds;
  double spread = 0;
  for (double e : estimates) spread += (e - mean) * (e - mean);
  return {std::sqrt(sum_squared_error / kSeeds), mean, std::sqrt(spread / (kSeeds - 1) / kSeeds)};
}

TEST(SobolTest, OwenScrambledIntegrationBeatsMonteCarloUnbiased) {
  constexpr uint32_t kPoints = 4096;
  for (const Integrand* f : {&kSine04, &kLinear04, &kExp04, &kExp1115, &kLinear2731}) {
    // Plain Monte Carlo's standard error with kPoints independent uniform points.
    const double mc_standard_error =
        std::sqrt((std::pow(f->factor_second_moment, 5) - 1.0) / kPoints);
    const Estimates e = Integrate(*f, kPoints);
    std::printf(
        "[ sobol    ] %s: N=%u, RMS error over 64 seeds %.3g, MC standard error %.3g "
        "(ratio %.1f); mean - 1 = %.3g = %.2f standard errors\n",
        f->name, kPoints, e.rms_error, mc_standard_error, mc_standard_error / e.rms_error,
        e.mean - 1.0, (e.mean - 1.0) / e.standard_error_of_mean);
    EXPECT_LT(10 * e.rms_error, mc_standard_error) << f->name;
    EXPECT_GT(e.standard_error_of_mean, 0) << f->name << ": the seeds must scramble";
    EXPECT_LT(std::abs(e.mean - 1.0), 4 * e.standard_error_of_mean) << f->name;
  }
}

TEST(SobolTest, OwenScrambledErrorFallsFasterThanOneOverN) {
  // Owen (1997): O(N^-3/2 (log N)^2) RMS error for smooth integrands in 5 dimensions; plain
  // Monte Carlo's falls as N^-1/2, and even N^-1 would give only a factor 16 for 16 times the
  // points.
  for (const Integrand* f : {&kLinear04, &kExp04}) {
    const double coarse = Integrate(*f, 1024).rms_error;
    const double fine = Integrate(*f, 16384).rms_error;
    std::printf("[ sobol    ] %s: RMS error %.3g at N=1024, %.3g at N=16384 (ratio %.1f)\n",
                f->name, coarse, fine, coarse / fine);
    EXPECT_GT(coarse / fine, 16.0) << f->name;
  }
}

TEST(SobolOwenTest, SameSeedSameNumbersOnEveryObjectAndThread) {
  constexpr uint32_t kPoints = 1024;
  const uint64_t seed = StreamKey(11, 22, 33);
  auto table = [&](const OwenSobol& sampler) {
    std::vector<double> values;
    for (uint32_t i = 0; i < kPoints; ++i) {
      for (int d = 0; d < kSobolDimensions; ++d) values.push_back(sampler.Get(i * 7919u, d));
    }
    return values;
  };
  const std::vector<double> reference = table(OwenSobol(seed));
  EXPECT_EQ(table(OwenSobol(seed)), reference);

  const OwenSobol shared(seed);
  std::vector<std::vector<double>> per_thread(4);
  std::vector<std::thread> threads;
  for (size_t t = 0; t < per_thread.size(); ++t) {
    threads.emplace_back(
        [&, t] { per_thread[t] = t % 2 == 0 ? table(shared) : table(OwenSobol(seed)); });
  }
  for (std::thread& thread : threads) thread.join();
  for (const std::vector<double>& values : per_thread) EXPECT_EQ(values, reference);

  const std::vector<double> other = table(OwenSobol(seed + 1));
  int same = 0;
  for (size_t k = 0; k < reference.size(); ++k) same += other[k] == reference[k];
  EXPECT_EQ(same, 0);
}

TEST(SobolOwenTest, ScrambledPointsAreUniformOverSeeds) {
  // One point under 4096 seeds: each coordinate uniform, and the pair (dims 0, 1) too.
  constexpr int kSeeds = 4096;
  for (uint32_t index : {0u, 1u, 777u}) {
    std::vector<int> bins(16, 0), pair_bins(64, 0);
    for (int s = 0; s < kSeeds; ++s) {
      const OwenSobol sampler(StreamKey(99, s));
      ++bins[static_cast<int>(sampler.Get(index, 5) * 16)];
      ++pair_bins[static_cast<int>(sampler.Get(index, 0) * 8) * 8 +
                  static_cast<int>(sampler.Get(index, 1) * 8)];
    }
    auto chi_square = [](const std::vector<int>& counts, double expected) {
      double chi2 = 0;
      for (int c : counts) chi2 += (c - expected) * (c - expected) / expected;
      return chi2;
    };
    // 99.99th percentiles of chi-square with 15 and 63 degrees of freedom: 44.3 and 113.5.
    EXPECT_LT(chi_square(bins, kSeeds / 16.0), 44.3) << "index " << index;
    EXPECT_LT(chi_square(pair_bins, kSeeds / 64.0), 113.5) << "index " << index;
  }
}

TEST(SobolOwenTest, DimensionsAreScrambledIndependently) {
  // Points 0..3 of a dimension put one point in each quarter of [0, 1). An Owen scramble applies
  // one of 8 equally likely nested permutations of the quarters (flip digit 1, then digit 2
  // depending on digit 1), so two dimensions with independent scrambles show the same quarter
  // pattern with probability 1/8, or 0 when their unscrambled patterns are not related by such a
  // permutation. Dimensions sharing one scramble agree more often: dimensions 2 and 3 share their
  // first two direction numbers, and agree whenever their points' digital shifts do (1/4).
  constexpr int kSeeds = 4096;
  std::vector<std::vector<int>> agree(kSobolDimensions, std::vector<int>(kSobolDimensions, 0));
  for (int s = 0; s < kSeeds; ++s) {
    const OwenSobol sampler(StreamKey(77, s));
    uint32_t pattern[kSobolDimensions];
    for (int d = 0; d < kSobolDimensions; ++d) {
      pattern[d] = 0;
      for (uint32_t i = 0; i < 4; ++i) pattern[d] |= (sampler.GetBits(i, d) >> 30) << (2 * i);
    }
    for (int a = 0; a < kSobolDimensions; ++a) {
      for (int b = a + 1; b < kSobolDimensions; ++b) agree[a][b] += pattern[a] == pattern[b];
    }
  }
  // 1/8 + 6.7 standard deviations of a frequency over 4096 seeds.
  for (int a = 0; a < kSobolDimensions; ++a) {
    for (int b = a + 1; b < kSobolDimensions; ++b) {
      EXPECT_LT(agree[a][b], 0.16 * kSeeds) << "dims " << a << ", " << b;
    }
  }
}

TEST(SobolOwenTest, IndexIsShuffledPerSeed) {
  // Unshuffled, points 0 and 2 of dimension 0 (van der Corput: 0 and 1/4) share their first
  // digit under any Owen scramble, so they lie in the same half of [0, 1). Under an Owen scramble
  // of the index, the last index bit is flipped by a hash of the bits above it, which differ for
  // indices 0 and 2, so the two points lie in the same half for half of the seeds.
  constexpr int kSeeds = 4096;
  int same_half = 0;
  for (int s = 0; s < kSeeds; ++s) {
    const OwenSobol sampler(StreamKey(31, s));
    same_half += (sampler.Get(0, 0) < 0.5) == (sampler.Get(2, 0) < 0.5);
  }
  // 1/2 within 6.4 standard deviations.
  EXPECT_NEAR(same_half, kSeeds / 2, 0.05 * kSeeds);
}

TEST(SobolOwenTest, ValuesInUnitIntervalWithLowBitsFilled) {
  int filled = 0, total = 0;
  for (uint64_t seed = 0; seed < 64; ++seed) {
    const OwenSobol sampler(StreamKey(5, seed));
    for (uint32_t index : {0u, 1u, 2u, 4095u, 4096u, 0x7fffffffu, 0xfffffffeu, 0xffffffffu}) {
      for (int d = 0; d < kSobolDimensions; ++d) {
        const double x = sampler.Get(index, d);
        ASSERT_GE(x, 0.0);
        ASSERT_LT(x, 1.0);
        const double scaled = x * 4294967296.0;
        ASSERT_EQ(static_cast<uint32_t>(scaled), sampler.GetBits(index, d));
        filled += scaled != std::floor(scaled);
        ++total;
      }
    }
  }
  // Each of the 21 bits below 2^-32 is hashed: all are zero with probability 2^-21.
  EXPECT_GE(filled, total - 1);
}

}  // namespace
}  // namespace radiosity
