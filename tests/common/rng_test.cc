#include "secure/common/rng.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

#include "secure/common/random_order.h"

namespace secure {
namespace {

std::vector<std::uint64_t> Draw(Rng& rng, int n) {
  std::vector<std::uint64_t> out(n);
  for (auto& v : out) v = rng.NextU64();
  return out;
}

// Pins cross-platform reproducibility: these are the first outputs of xoshiro256++ seeded through
// splitmix64 with seed 0, computed once with this code and checked against an independent
// implementation of the published algorithms. A change here changes every seeded experiment.
TEST(RngTest, FirstRawValuesOfSeedZeroAreGolden) {
  Rng rng(0);
  EXPECT_EQ(rng.NextU64(), 0x53175d61490b23dfULL);
  EXPECT_EQ(rng.NextU64(), 0x61da6f3dc380d507ULL);
  EXPECT_EQ(rng.NextU64(), 0x5c0fdf91ec9a7bfcULL);
  EXPECT_EQ(rng.NextU64(), 0x02eebf8c3bbe5e1aULL);
}

TEST(RngTest, DefaultConstructedEqualsSeedZero) {
  Rng a;
  Rng b(0);
  EXPECT_EQ(Draw(a, 16), Draw(b, 16));
}

TEST(RngTest, SameSeedGivesSameStream) {
  Rng a(12345);
  Rng b(12345);
  EXPECT_EQ(Draw(a, 1000), Draw(b, 1000));
}

TEST(RngTest, ReseedRestartsTheStream) {
  Rng a(7);
  const auto first = Draw(a, 100);
  a.Seed(7);
  EXPECT_EQ(Draw(a, 100), first);
}

TEST(RngTest, ReseedDiscardsTheSpareNormal) {
  Rng a(3);
  const double first = a.Normal();  // leaves a spare
  a.Seed(3);
  EXPECT_EQ(a.Normal(), first);
}

TEST(RngTest, DifferentSeedsGiveDifferentStreams) {
  Rng a(1);
  Rng b(2);
  const auto va = Draw(a, 100);
  const auto vb = Draw(b, 100);
  int equal = 0;
  for (int i = 0; i < 100; ++i) equal += va[i] == vb[i];
  EXPECT_EQ(equal, 0);
}

TEST(RngTest, UniformIsInUnitIntervalWithMeanOneHalf) {
  Rng rng(11);
  constexpr int kN = 100000;
  double sum = 0.0;
  double lo = 1.0, hi = 0.0;
  for (int i = 0; i < kN; ++i) {
    const double u = rng.Uniform();
    ASSERT_GE(u, 0.0);
    ASSERT_LT(u, 1.0);
    sum += u;
    lo = std::min(lo, u);
    hi = std::max(hi, u);
  }
  // Standard error of the mean is sqrt(1/12 / 1e5) ~ 9e-4; 5e-3 is > 5 sigma.
  EXPECT_NEAR(sum / kN, 0.5, 5e-3);
  // The draws cover the interval.
  EXPECT_LT(lo, 1e-3);
  EXPECT_GT(hi, 1.0 - 1e-3);
}

TEST(RngTest, UniformRangeStaysInHalfOpenInterval) {
  Rng rng(5);
  constexpr int kN = 100000;
  double sum = 0.0;
  for (int i = 0; i < kN; ++i) {
    const double u = rng.Uniform(-1.5, 2.5);
    ASSERT_GE(u, -1.5);
    ASSERT_LT(u, 2.5);
    sum += u;
  }
  EXPECT_NEAR(sum / kN, 0.5, 0.02);  // std of the mean ~ 4/sqrt(12e5) ~ 3.7e-3
}

TEST(RngTest, UniformIndexIsInRangeAndRoughlyUniform) {
  Rng rng(99);
  constexpr int kBins = 10;
  constexpr int kN = 100000;
  std::vector<int> counts(kBins, 0);
  for (int i = 0; i < kN; ++i) {
    const std::uint64_t k = rng.UniformIndex(kBins);
    ASSERT_LT(k, static_cast<std::uint64_t>(kBins));
    ++counts[k];
  }
  const double expected = static_cast<double>(kN) / kBins;
  double chi2 = 0.0;
  for (int c : counts) chi2 += (c - expected) * (c - expected) / expected;
  // 9 degrees of freedom: P(chi2 > 40) < 1e-5. A broken index (e.g. always 0 or modulo a wrong
  // n) gives chi2 in the thousands.
  EXPECT_LT(chi2, 40.0);
}

TEST(RngTest, UniformIndexOfOneIsAlwaysZero) {
  Rng rng(4);
  for (int i = 0; i < 1000; ++i) ASSERT_EQ(rng.UniformIndex(1), 0u);
}

TEST(RngTest, UniformIndexReachesTheTopOfALargeRange) {
  // Lemire's method uses the high bits: with n = 2^40 the draws must reach the upper half.
  Rng rng(8);
  const std::uint64_t n = 1ULL << 40;
  bool upper = false, lower = false;
  for (int i = 0; i < 100; ++i) {
    const std::uint64_t k = rng.UniformIndex(n);
    ASSERT_LT(k, n);
    (k >= n / 2 ? upper : lower) = true;
  }
  EXPECT_TRUE(upper);
  EXPECT_TRUE(lower);
}

TEST(RngTest, NormalHasMeanZeroAndUnitVariance) {
  Rng rng(2024);
  constexpr int kN = 100000;
  double sum = 0.0, sum_sq = 0.0;
  int beyond_two_sigma = 0;
  for (int i = 0; i < kN; ++i) {
    const double z = rng.Normal();
    ASSERT_TRUE(std::isfinite(z));
    sum += z;
    sum_sq += z * z;
    beyond_two_sigma += std::abs(z) > 2.0;
  }
  const double mean = sum / kN;
  const double var = sum_sq / kN - mean * mean;
  // Standard errors: mean ~ 3.2e-3, variance ~ 4.5e-3; bounds are > 5 sigma.
  EXPECT_NEAR(mean, 0.0, 0.02);
  EXPECT_NEAR(var, 1.0, 0.03);
  // P(|z| > 2) = 0.0455 for a normal (a uniform with unit variance would give 0).
  EXPECT_NEAR(static_cast<double>(beyond_two_sigma) / kN, 0.0455, 0.004);
}

TEST(RngTest, NormalPairsAreNotIdentical) {
  // Box-Muller returns cos and sin of one draw; returning the same value twice is a bug.
  Rng rng(6);
  int equal = 0;
  for (int i = 0; i < 1000; ++i) equal += rng.Normal() == rng.Normal();
  EXPECT_EQ(equal, 0);
}

TEST(RngTest, NormalIsDeterministicPerSeed) {
  Rng a(17), b(17);
  for (int i = 0; i < 101; ++i) ASSERT_EQ(a.Normal(), b.Normal()) << i;
}

TEST(RngTest, ShuffleIsADeterministicPermutation) {
  std::vector<int> v(1000);
  std::iota(v.begin(), v.end(), 0);
  std::vector<int> a = v, b = v;
  Rng ra(31), rb(31);
  Shuffle(a.begin(), a.end(), ra);
  Shuffle(b.begin(), b.end(), rb);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, v);  // P(identity) = 1/1000!
  std::vector<int> sorted = a;
  std::sort(sorted.begin(), sorted.end());
  EXPECT_EQ(sorted, v);
}

TEST(RngTest, ShuffleDependsOnTheSeed) {
  std::vector<int> a(100), b(100);
  std::iota(a.begin(), a.end(), 0);
  std::iota(b.begin(), b.end(), 0);
  Rng ra(1), rb(2);
  Shuffle(a.begin(), a.end(), ra);
  Shuffle(b.begin(), b.end(), rb);
  EXPECT_NE(a, b);
}

TEST(RngTest, ShuffleMovesEveryPositionUniformly) {
  // Fisher-Yates: element 0 ends at each of 5 positions with probability 1/5. An off-by-one
  // (e.g. UniformIndex(i) instead of i + 1, Sattolo's algorithm) never leaves it in place.
  constexpr int kTrials = 50000;
  std::vector<int> where(5, 0);
  Rng rng(77);
  for (int t = 0; t < kTrials; ++t) {
    std::vector<int> v{0, 1, 2, 3, 4};
    Shuffle(v.begin(), v.end(), rng);
    ++where[std::find(v.begin(), v.end(), 0) - v.begin()];
  }
  for (int p = 0; p < 5; ++p) EXPECT_NEAR(where[p], kTrials / 5, 600) << "position " << p;
}

TEST(RngTest, ShuffleOfEmptyAndSingleRangesIsANoOp) {
  Rng rng(0);
  std::vector<int> empty;
  Shuffle(empty.begin(), empty.end(), rng);
  EXPECT_TRUE(empty.empty());
  std::vector<int> one{42};
  Shuffle(one.begin(), one.end(), rng);
  EXPECT_EQ(one, std::vector<int>{42});
}

TEST(RngTest, RandomPermutationIsTheShuffledIdentity) {
  Rng a(21), b(21);
  std::vector<long> expected(50);
  std::iota(expected.begin(), expected.end(), 0L);
  Shuffle(expected.begin(), expected.end(), b);
  const std::vector<long> p = RandomPermutation(50, a);
  EXPECT_EQ(p, expected);
  EXPECT_EQ(a.NextU64(), b.NextU64());  // the same draws consumed
  EXPECT_TRUE(RandomPermutation(0, a).empty());
}

TEST(RngTest, SortedRandomSubsetIsTheSortedHeadOfThePermutation) {
  Rng a(22), b(22);
  std::vector<long> head = RandomPermutation(40, b);
  head.resize(7);
  std::sort(head.begin(), head.end());
  const std::vector<long> s = SortedRandomSubset(40, 7, a);
  EXPECT_EQ(s, head);
  EXPECT_TRUE(std::is_sorted(s.begin(), s.end()));
  EXPECT_EQ(std::adjacent_find(s.begin(), s.end()), s.end());  // distinct
  EXPECT_GE(s.front(), 0);
  EXPECT_LT(s.back(), 40);
  std::vector<long> all(40);
  std::iota(all.begin(), all.end(), 0L);
  EXPECT_EQ(SortedRandomSubset(40, 40, a), all);
  EXPECT_TRUE(SortedRandomSubset(40, 0, a).empty());
}

TEST(RngTest, SplitGivesADifferentDeterministicStream) {
  Rng parent(10);
  Rng copy(10);
  Rng child = parent.Split();
  Rng child_again = copy.Split();
  const auto child_values = Draw(child, 100);
  EXPECT_EQ(child_values, Draw(child_again, 100));

  // The child differs from the parent's continuation and from a fresh stream of the same seed.
  const auto parent_values = Draw(parent, 100);
  Rng fresh(10);
  const auto fresh_values = Draw(fresh, 100);
  int same_as_parent = 0, same_as_fresh = 0;
  for (int i = 0; i < 100; ++i) {
    same_as_parent += child_values[i] == parent_values[i];
    same_as_fresh += child_values[i] == fresh_values[i];
  }
  EXPECT_EQ(same_as_parent, 0);
  EXPECT_EQ(same_as_fresh, 0);
}

TEST(RngTest, SuccessiveSplitsDiffer) {
  Rng parent(10);
  Rng a = parent.Split();
  Rng b = parent.Split();
  EXPECT_NE(Draw(a, 10), Draw(b, 10));
}

}  // namespace
}  // namespace secure
