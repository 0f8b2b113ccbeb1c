// Statistics of within-subject designs (the stats_test program, statistics_test.cc): Friedman,
// Wilcoxon signed-rank, p-value adjustment and pairwise Wilcoxon with Holm's correction.
#include "tests/stats/stats_test_util.h"

namespace secure::stats {
namespace {
using namespace test;  // NOLINT(google-build-using-namespace): the reference samples

// ---------------------------------------------------------------------------------------------
// Within-subject designs. Reference values from SciPy 1.10.1 (Debian's /usr/bin/python3), each
// with the Python expression that produced it, where (in Python)
//   import numpy as np; from scipy import stats
//   T = <kTimes as a list of rows>;  L = <kRatings as a list of rows>
//   col = lambda M, j: [row[j] for row in M]
// The statistics are pinned exactly or to 1e-10 relative, the p-values to 1e-10 relative.

constexpr double kRefTol = 1e-10;

// 12 participants x 4 conditions: completion times (s); no ties within a row, and no two
// |differences| of a pair of columns tie (checked in NumPy).
const std::vector<std::vector<double>> kTimes = {
    {41.2, 38.55, 45.2, 36.94},   {52.33, 47.89, 55.04, 44.7},  {38.76, 39.42, 42.29, 35.15},
    {47.59, 43.96, 49.83, 41.3},  {44.11, 40.3, 46.78, 42.86},  {56.84, 50.13, 58.32, 48.91},
    {39.97, 37.67, 41.57, 38.27}, {50.5, 46.3, 53.61, 45.72},   {43.32, 44.84, 47.96, 40.58},
    {48.65, 42.78, 51.2, 43.43},  {45.98, 41.81, 44.05, 39.79}, {53.1, 49.25, 57.5, 47.04}};
// The same participants: a 1..7 rating. Ties within rows, zero and tied differences.
const std::vector<std::vector<double>> kRatings = {
    {5, 6, 4, 6}, {4, 6, 4, 7}, {5, 5, 3, 6}, {6, 7, 5, 7}, {4, 5, 4, 5}, {3, 5, 3, 6},
    {5, 6, 4, 6}, {4, 4, 2, 5}, {6, 6, 5, 7}, {5, 7, 4, 6}, {4, 5, 3, 5}, {5, 6, 5, 7}};

std::vector<double> Column(const std::vector<std::vector<double>>& m, std::size_t j) {
  std::vector<double> c;
  for (const auto& row : m) c.push_back(row[j]);
  return c;
}

// d_i = ((37 i) mod 101) - 40.25 for i = 1..n: distinct residues, so no zero and no two |d_i|
// tie (that would need two residues summing to 80.5). x_i = i + d_i, y_i = i, all exact.
// Python: x = [i + ((i*37) % 101) - 40.25 for i in range(1, n+1)]; y = list(range(1, n+1))
std::pair<std::vector<double>, std::vector<double>> Generated(int n) {
  std::vector<double> x, y;
  for (int i = 1; i <= n; ++i) {
    x.push_back(i + ((i * 37) % 101) - 40.25);
    y.push_back(i);
  }
  return {x, y};
}

// ---------------------------------------------------------------------------------------------
// Friedman

TEST(FriedmanTest, MatchesScipyWithoutTies) {
  // stats.friedmanchisquare(*np.array(T).T) -> (29.400000000000006, 1.8453028685848766e-06)
  const FriedmanResult r = Friedman(kTimes);
  EXPECT_REL(r.statistic, 29.400000000000006, kRefTol);
  EXPECT_REL(r.p_value, 1.8453028685848766e-06, kRefTol);
  EXPECT_EQ(r.df, 3);
  EXPECT_EQ(r.n, 12);
  EXPECT_EQ(r.k, 4);
  // np.mean([stats.rankdata(row) for row in T], axis=0)
  ASSERT_EQ(r.mean_ranks.size(), 4u);
  EXPECT_DOUBLE_EQ(r.mean_ranks[0], 35.0 / 12.0);
  EXPECT_DOUBLE_EQ(r.mean_ranks[1], 23.0 / 12.0);
  EXPECT_DOUBLE_EQ(r.mean_ranks[2], 47.0 / 12.0);
  EXPECT_DOUBLE_EQ(r.mean_ranks[3], 15.0 / 12.0);
  EXPECT_REL(r.kendall_w, 29.4 / 36.0, kRefTol);
}

TEST(FriedmanTest, MatchesScipyWithTiesWithinRows) {
  // stats.friedmanchisquare(*np.array(L).T) -> (31.805555555555554, 5.751287640924982e-07)
  const FriedmanResult r = Friedman(kRatings);
  EXPECT_REL(r.statistic, 31.805555555555554, kRefTol);
  EXPECT_REL(r.p_value, 5.751287640924982e-07, kRefTol);
  EXPECT_EQ(r.df, 3);
  // np.mean([stats.rankdata(row) for row in L], axis=0)
  EXPECT_DOUBLE_EQ(r.mean_ranks[0], 23.5 / 12.0);
  EXPECT_DOUBLE_EQ(r.mean_ranks[1], 38.0 / 12.0);
  EXPECT_DOUBLE_EQ(r.mean_ranks[2], 14.0 / 12.0);
  EXPECT_DOUBLE_EQ(r.mean_ranks[3], 44.5 / 12.0);
  double sum = 0;
  for (double m : r.mean_ranks) sum += m;
  EXPECT_DOUBLE_EQ(sum, 10.0);  // k (k + 1) / 2
  EXPECT_GT(r.kendall_w, 0.0);
  EXPECT_LE(r.kendall_w, 1.0);
}

TEST(FriedmanTest, ThreeConditionsAndTheSmallestDesign) {
  // stats.friedmanchisquare(*np.array(T)[:, :3].T) -> (18.5, 9.611165206139472e-05)
  std::vector<std::vector<double>> three;
  for (const auto& row : kTimes) three.push_back({row[0], row[1], row[2]});
  const FriedmanResult r = Friedman(three);
  EXPECT_REL(r.statistic, 18.5, kRefTol);
  EXPECT_REL(r.p_value, 9.611165206139472e-05, kRefTol);
  EXPECT_EQ(r.df, 2);
  // stats.friedmanchisquare([1, 2], [2, 1], [3, 3]) -> (3.0, 0.22313016014842982): rows (1, 2, 3)
  // and (2, 1, 3), rank sums 3, 3, 6: 12 / 24 * 54 - 24 = 3; p = exp(-3 / 2).
  const FriedmanResult small = Friedman({{1, 2, 3}, {2, 1, 3}});
  EXPECT_REL(small.statistic, 3.0, kRefTol);
  EXPECT_REL(small.p_value, 0.22313016014842982, kRefTol);
  EXPECT_REL(small.p_value, std::exp(-1.5), 1e-14);
  EXPECT_REL(small.kendall_w, 0.75, kRefTol);
}

TEST(FriedmanTest, AFullyTiedRowIsAllowed) {
  // stats.friedmanchisquare([1, 2, 5], [1, 3, 4], [1, 1, 3])
  //   -> (2.9999999999999996, 0.2231301601484299): row 0 = (1, 1, 1) only adds to the tie term.
  const FriedmanResult r = Friedman({{1, 1, 1}, {2, 3, 1}, {5, 4, 3}});
  EXPECT_REL(r.statistic, 2.9999999999999996, kRefTol);
  EXPECT_REL(r.p_value, 0.2231301601484299, kRefTol);
}

TEST(FriedmanTest, EveryRowTiedThrows) {
  // SciPy: stats.friedmanchisquare([1, 2], [1, 2], [1, 2]) -> (nan, nan) with a warning (0 / 0).
  EXPECT_HAS(ErrorOf([] {
               Friedman({{1, 1, 1}, {2, 2, 2}});
             }),
             "Friedman: in every one of the 2 rows of 'data' all 3 values are the same; the "
             "statistic is undefined (0 / 0)");
}

TEST(FriedmanTest, DoesNotDependOnRowOrColumnOrderOrMonotoneRescaling) {
  const FriedmanResult r = Friedman(kRatings);
  std::vector<std::vector<double>> permuted;  // rows reversed, columns (3, 1, 0, 2), x -> 10 x^3
  for (auto it = kRatings.rbegin(); it != kRatings.rend(); ++it) {
    const auto& row = *it;
    std::vector<double> p;
    for (std::size_t c : {3, 1, 0, 2}) p.push_back(10 * row[c] * row[c] * row[c]);
    permuted.push_back(p);
  }
  const FriedmanResult q = Friedman(permuted);
  EXPECT_NEAR(q.statistic, r.statistic, 1e-12);
  EXPECT_NEAR(q.p_value, r.p_value, 1e-18);
  EXPECT_DOUBLE_EQ(q.mean_ranks[0], r.mean_ranks[3]);
  EXPECT_DOUBLE_EQ(q.mean_ranks[3], r.mean_ranks[2]);
}

TEST(FriedmanTest, NoAgreementGivesZero) {
  // Rows (1, 2, 3), (3, 2, 1): rank sums 4, 4, 4, statistic 0, p = 1, W = 0.
  const FriedmanResult r = Friedman({{1, 2, 3}, {3, 2, 1}});
  EXPECT_EQ(r.statistic, 0.0);
  EXPECT_EQ(r.p_value, 1.0);
  EXPECT_EQ(r.kendall_w, 0.0);
}

TEST(FriedmanTest, ToJsonHasEveryField) {
  const nlohmann::json j = Friedman(kTimes).ToJson();
  EXPECT_REL(j.at("statistic").get<double>(), 29.400000000000006, kRefTol);
  EXPECT_EQ(j.at("df"), 3);
  EXPECT_TRUE(j.at("p_value").is_number());
  EXPECT_EQ(j.at("n"), 12);
  EXPECT_EQ(j.at("k"), 4);
  ASSERT_EQ(j.at("mean_ranks").size(), 4u);
  EXPECT_DOUBLE_EQ(j.at("mean_ranks")[3].get<double>(), 1.25);
  EXPECT_TRUE(j.at("kendall_w").is_number());
}

TEST(FriedmanTest, RejectsBadInput) {
  EXPECT_HAS(ErrorOf([] { Friedman({}); }), "Friedman: 'data' has 0 rows, needs at least 2");
  EXPECT_HAS(ErrorOf([] {
               Friedman({{1, 2, 3}});
             }),
             "Friedman: 'data' has 1 row, needs at least 2 (one row per block");
  EXPECT_HAS(ErrorOf([] {
               Friedman({{1, 2}, {2, 1}});
             }),
             "Friedman: row 0 of 'data' has 2 values, needs at least 3 (one value per condition)");
  EXPECT_HAS(ErrorOf([] {
               Friedman({{1, 2, 3}, {2, 1, 3}, {1, 2}});
             }),
             "Friedman: row 2 of 'data' has 2 values, row 0 has 3");
  EXPECT_HAS(ErrorOf([] {
               Friedman({{1, 2, 3}, {2, 1, 3, 4}});
             }),
             "Friedman: row 1 of 'data' has 4 values, row 0 has 3");
  EXPECT_HAS(ErrorOf([] {
               Friedman({{1, 2, 3}, {2, kNaN, 3}});
             }),
             "Friedman: row 1 of 'data' holds a non-finite value (nan) at column 1");
  EXPECT_HAS(ErrorOf([] {
               Friedman({{1, 2, -kInf}, {2, 1, 3}});
             }),
             "Friedman: row 0 of 'data' holds a non-finite value (-inf) at column 2");
}

// ---------------------------------------------------------------------------------------------
// Wilcoxon signed-rank

// SciPy's method='approx' result for differences that are all negative or zero (W+ = 0), with
// zeros or ties: the zeros dropped, n ranked, W- and the p-value and zstatistic.
struct ScipyAllNegative {
  long zeros, n;
  double w_minus, p, z;
};

// `r` is the asymptotic result `e`: statistic = W+ = 0, rank-biserial -1.
void ExpectAllNegativeApprox(const WilcoxonResult& r, const ScipyAllNegative& e) {
  EXPECT_EQ(r.method, "asymptotic");
  EXPECT_EQ(r.zeros, e.zeros);
  EXPECT_EQ(r.n, e.n);
  EXPECT_EQ(r.statistic, 0.0);
  EXPECT_EQ(r.w_minus, e.w_minus);
  EXPECT_REL(r.p_value, e.p, kRefTol);
  EXPECT_REL(r.z, e.z, kRefTol);
  EXPECT_EQ(r.rank_biserial, -1.0);
}

TEST(WilcoxonTest, SmallExactCaseByHandAndScipy) {
  // d = 1.5, -0.5, 2.5, 3.5, 4.5, 5.5: ranks 2, 1, 3, 4, 5, 6, W- = 1, W+ = 20. Of the 2^6 sign
  // patterns, 2 have W+ >= 20 (W- = 0 or 1): p = 2 * 2 / 64.
  const std::vector<double> x = {2.5, 1.0, 4.5, 5.0, 7.5, 9.0}, y = {1.0, 1.5, 2.0, 1.5, 3.0, 3.5};
  // stats.wilcoxon([2.5, 1.0, 4.5, 5.0, 7.5, 9.0], [1.0, 1.5, 2.0, 1.5, 3.0, 3.5]) -> (1.0, 0.0625)
  const WilcoxonResult r = WilcoxonSignedRank(x, y);
  EXPECT_EQ(r.method, "exact");
  EXPECT_EQ(r.statistic, 1.0);
  EXPECT_EQ(r.w_plus, 20.0);
  EXPECT_EQ(r.w_minus, 1.0);
  EXPECT_EQ(r.n, 6);
  EXPECT_EQ(r.zeros, 0);
  EXPECT_EQ(r.p_value, 0.0625);
  EXPECT_TRUE(std::isnan(r.z));
  EXPECT_DOUBLE_EQ(r.rank_biserial, 19.0 / 21.0);
  // The same with method='approx' -> (1.0, 0.046399461870904594), zstatistic -1.9917411897716448
  const WilcoxonResult a = WilcoxonSignedRank(x, y, WilcoxonMethod::kAsymptotic);
  EXPECT_EQ(a.method, "asymptotic");
  EXPECT_EQ(a.statistic, 1.0);
  EXPECT_REL(a.p_value, 0.046399461870904594, kRefTol);
  EXPECT_REL(a.z, 1.9917411897716448, kRefTol);  // W+ above its mean: positive (SciPy: -|z|)
  // One pair: W+ is 0 or 1 with probability 1/2, p = 1 (stats.wilcoxon([3.0], [1.0]) -> (0, 1)).
  EXPECT_EQ(WilcoxonSignedRank({3.0}, {1.0}).p_value, 1.0);
}

TEST(WilcoxonTest, TwelveParticipantsExactMatchesScipyDefault) {
  const std::vector<double> c0 = Column(kTimes, 0), c1 = Column(kTimes, 1), c3 = Column(kTimes, 3);
  // stats.wilcoxon(col(T, 0), col(T, 1)) -> (3.0, 0.00244140625)
  const WilcoxonResult r01 = WilcoxonSignedRank(c0, c1);
  EXPECT_EQ(r01.method, "exact");
  EXPECT_EQ(r01.statistic, 3.0);
  EXPECT_REL(r01.p_value, 0.00244140625, kRefTol);
  // stats.wilcoxon(col(T, 1), col(T, 3)) -> (13.0, 0.04248046875); W+ = 65, W- = 13
  const WilcoxonResult r13 = WilcoxonSignedRank(c1, c3);
  EXPECT_EQ(r13.statistic, 13.0);
  EXPECT_EQ(r13.w_plus, 65.0);
  EXPECT_REL(r13.p_value, 0.04248046875, kRefTol);
  EXPECT_DOUBLE_EQ(r13.rank_biserial, 52.0 / 78.0);
  // stats.wilcoxon(col(T, 0), col(T, 1), method='approx') -> (3.0, 0.004741768038406972)
  EXPECT_REL(WilcoxonSignedRank(c0, c1, WilcoxonMethod::kAsymptotic).p_value, 0.004741768038406972,
             kRefTol);
}

TEST(WilcoxonTest, ZeroDifferencesAreDroppedAndSwitchToAsymptotic) {
  // d = 0, .05+, .1-, 0, .06+, -.03, .05-, .05+, 0, .05- (x - y in double: 0.55 - 0.50 and
  // 0.70 - 0.65 differ in the last bits, so they do not tie, in SciPy either).
  const std::vector<double> x = {0.61, 0.55, 0.72, 0.48, 0.66, 0.59, 0.70, 0.52, 0.63, 0.58};
  const std::vector<double> y = {0.61, 0.50, 0.62, 0.48, 0.60, 0.62, 0.65, 0.47, 0.63, 0.53};
  // stats.wilcoxon(x, y) -> (1.0, 0.0274336657595771) (warns: zeros, normal approximation)
  const WilcoxonResult r = WilcoxonSignedRank(x, y);
  EXPECT_EQ(r.method, "asymptotic");
  EXPECT_EQ(r.zeros, 3);
  EXPECT_EQ(r.n, 7);
  EXPECT_EQ(r.statistic, 1.0);
  EXPECT_EQ(r.w_plus, 27.0);
  EXPECT_REL(r.p_value, 0.0274336657595771, kRefTol);
  // Zeros and ties: stats.wilcoxon(col(L, 0), col(L, 1)) -> (0.0, 0.005749708623335458),
  // method='approx' gives the same, zstatistic -2.7617238536949698 (W+ = 0, W- = 45, n = 9).
  const WilcoxonResult l = WilcoxonSignedRank(Column(kRatings, 0), Column(kRatings, 1));
  ExpectAllNegativeApprox(l, {3, 9, 45.0, 0.005749708623335458, -2.7617238536949698});
}

TEST(WilcoxonTest, TiesWithoutZerosUseTheNormalApproximationUnlikeScipy110) {
  // col(L, 0) - col(L, 3): 12 negative differences, |d| in {1, 2}: tied. SciPy 1.10's default
  // keeps the exact distribution here: stats.wilcoxon(col(L, 0), col(L, 3)) -> (0.0,
  // 0.00048828125) = 2 / 2^12, as if the ranks were 1..12. kAuto uses the tie-corrected normal
  // approximation: stats.wilcoxon(col(L, 0), col(L, 3), method='approx')
  //   -> (0.0, 0.0013155275236832191), zstatistic -3.2125707287191205
  const WilcoxonResult r = WilcoxonSignedRank(Column(kRatings, 0), Column(kRatings, 3));
  ExpectAllNegativeApprox(r, {0, 12, 78.0, 0.0013155275236832191, -3.2125707287191205});
  // All differences equal: stats.wilcoxon([2, 3, 4, 5, 6], [1, 2, 3, 4, 5]) -> (0.0, 0.0625)
  // (exact), method='approx' -> (0.0, 0.025347318677468252), zstatistic -2.23606797749979.
  const WilcoxonResult equal = WilcoxonSignedRank({2, 3, 4, 5, 6}, {1, 2, 3, 4, 5});
  EXPECT_EQ(equal.method, "asymptotic");
  EXPECT_EQ(equal.statistic, 0.0);
  EXPECT_EQ(equal.w_plus, 15.0);  // five midranks of 3
  EXPECT_REL(equal.p_value, 0.025347318677468252, kRefTol);
  EXPECT_REL(equal.z, 2.23606797749979, kRefTol);
  EXPECT_EQ(equal.rank_biserial, 1.0);
}

TEST(WilcoxonTest, AllDifferencesZeroGiveNoEvidence) {
  // SciPy raises: stats.wilcoxon([1, 2, 3], [1, 2, 3]) -> ValueError("zero_method 'wilcox' and
  // 'pratt' do not work if x - y is zero for all elements."). We return statistic 0, p = 1.
  const WilcoxonResult r = WilcoxonSignedRank({1, 2, 3}, {1, 2, 3});
  EXPECT_EQ(r.method, "asymptotic");
  EXPECT_EQ(r.statistic, 0.0);
  EXPECT_EQ(r.p_value, 1.0);
  EXPECT_EQ(r.n, 0);
  EXPECT_EQ(r.zeros, 3);
  EXPECT_EQ(r.z, 0.0);
  EXPECT_EQ(r.rank_biserial, 0.0);
  EXPECT_EQ(WilcoxonSignedRank({1, 2, 3}, {1, 2, 3}, WilcoxonMethod::kAsymptotic).p_value, 1.0);
  EXPECT_HAS(ErrorOf([] {
               WilcoxonSignedRank({1, 2, 3}, {1, 2, 3}, WilcoxonMethod::kExact);
             }),
             "WilcoxonSignedRank: method = exact, but the differences x - y hold 3 zeros");
}

TEST(WilcoxonTest, ExactUpToFiftyDifferencesThenAsymptotic) {
  // n = 50: stats.wilcoxon(x, y) -> (408.0, 0.02616696817119646); W+ = 867, W- = 408.
  const auto [x50, y50] = Generated(50);
  const WilcoxonResult r50 = WilcoxonSignedRank(x50, y50);
  EXPECT_EQ(r50.method, "exact");
  EXPECT_EQ(r50.statistic, 408.0);
  EXPECT_EQ(r50.w_plus, 867.0);
  EXPECT_REL(r50.p_value, 0.02616696817119646, kRefTol);
  // ... method='approx' -> (408.0, 0.026730738547392646), zstatistic -2.215427455792942
  const WilcoxonResult a50 = WilcoxonSignedRank(x50, y50, WilcoxonMethod::kAsymptotic);
  EXPECT_REL(a50.p_value, 0.026730738547392646, kRefTol);
  EXPECT_REL(a50.z, 2.215427455792942, kRefTol);
  // n = 51: stats.wilcoxon(x, y) -> (413.0, 0.019110588960474614) (normal approximation);
  // method='exact' -> (413.0, 0.018442705457612618).
  const auto [x51, y51] = Generated(51);
  const WilcoxonResult r51 = WilcoxonSignedRank(x51, y51);
  EXPECT_EQ(r51.method, "asymptotic");
  EXPECT_EQ(r51.statistic, 413.0);
  EXPECT_REL(r51.p_value, 0.019110588960474614, kRefTol);
  const WilcoxonResult e51 = WilcoxonSignedRank(x51, y51, WilcoxonMethod::kExact);
  EXPECT_EQ(e51.method, "exact");
  EXPECT_REL(e51.p_value, 0.018442705457612618, kRefTol);
  // n = 60: stats.wilcoxon(x, y) -> (564.0, 0.009768369815048953), zstatistic -2.583922653570905
  // (W+ = 1266); method='exact' -> (564.0, 0.009180933514230011).
  const auto [x60, y60] = Generated(60);
  const WilcoxonResult r60 = WilcoxonSignedRank(x60, y60);
  EXPECT_EQ(r60.method, "asymptotic");
  EXPECT_EQ(r60.statistic, 564.0);
  EXPECT_EQ(r60.w_plus, 1266.0);
  EXPECT_REL(r60.p_value, 0.009768369815048953, kRefTol);
  EXPECT_REL(r60.z, 2.583922653570905, kRefTol);
  EXPECT_REL(WilcoxonSignedRank(x60, y60, WilcoxonMethod::kExact).p_value, 0.009180933514230011,
             kRefTol);
}

TEST(WilcoxonTest, SwappingXAndYMirrorsTheResult) {
  const auto [x50, y50] = Generated(50);
  const std::vector<std::pair<std::vector<double>, std::vector<double>>> cases = {
      {Column(kTimes, 0), Column(kTimes, 2)},
      {Column(kRatings, 1), Column(kRatings, 3)},
      {x50, y50},
      {{2.5, 1.0, 4.5}, {1.0, 1.5, 2.0}}};
  for (const auto& [x, y] : cases) {
    for (WilcoxonMethod m : {WilcoxonMethod::kAuto, WilcoxonMethod::kAsymptotic}) {
      const WilcoxonResult xy = WilcoxonSignedRank(x, y, m), yx = WilcoxonSignedRank(y, x, m);
      EXPECT_EQ(xy.statistic, yx.statistic);
      EXPECT_EQ(xy.w_plus, yx.w_minus);
      EXPECT_EQ(xy.method, yx.method);
      EXPECT_EQ(xy.p_value, yx.p_value);
      EXPECT_EQ(xy.rank_biserial, -yx.rank_biserial);
      if (xy.method == "asymptotic") {
        EXPECT_EQ(xy.z, -yx.z);
      }
      EXPECT_DOUBLE_EQ(xy.w_plus + xy.w_minus, xy.n * (xy.n + 1) / 2.0);
    }
  }
}

TEST(WilcoxonTest, ToJsonWritesNullZForExact) {
  const nlohmann::json exact = WilcoxonSignedRank(Column(kTimes, 0), Column(kTimes, 1)).ToJson();
  EXPECT_TRUE(exact.at("z").is_null());
  EXPECT_EQ(exact.at("method"), "exact");
  EXPECT_EQ(exact.at("statistic").get<double>(), 3.0);
  EXPECT_EQ(exact.at("n"), 12);
  EXPECT_EQ(exact.at("zeros"), 0);
  for (const char* key : {"w_plus", "w_minus", "p_value", "rank_biserial"})
    EXPECT_TRUE(exact.at(key).is_number()) << key;
  const nlohmann::json asym = WilcoxonSignedRank(Column(kRatings, 0), Column(kRatings, 1)).ToJson();
  EXPECT_EQ(asym.at("method"), "asymptotic");
  EXPECT_REL(asym.at("z").get<double>(), -2.7617238536949698, kRefTol);
  EXPECT_EQ(asym.at("zeros"), 3);
}

TEST(WilcoxonTest, RejectsBadInput) {
  EXPECT_HAS(ErrorOf([] { WilcoxonSignedRank({}, {}); }),
             "WilcoxonSignedRank: sample 'x' is empty");
  EXPECT_HAS(ErrorOf([] {
               WilcoxonSignedRank({1, 2}, {1, 2, 3});
             }),
             "WilcoxonSignedRank: sample 'x' has 2 values, sample 'y' has 3; the samples must "
             "be paired");
  EXPECT_HAS(ErrorOf([] {
               WilcoxonSignedRank({1, 2}, {1, kNaN});
             }),
             "WilcoxonSignedRank: sample 'y' holds a non-finite value (nan) at index 1");
  EXPECT_HAS(ErrorOf([] { WilcoxonSignedRank({kInf}, {1}); }),
             "WilcoxonSignedRank: sample 'x' holds a non-finite value (inf) at index 0");
  const std::string tied = ErrorOf(
      [] { WilcoxonSignedRank(Column(kRatings, 0), Column(kRatings, 3), WilcoxonMethod::kExact); });
  EXPECT_HAS(tied, "method = exact, but the differences x - y hold 0 zeros and tied |x - y|");
  EXPECT_HAS(ErrorOf([] {
               WilcoxonSignedRank({1, 2}, {1, 3}, WilcoxonMethod::kExact);
             }),
             "hold 1 zero and no tied |x - y|");
}

TEST(WilcoxonTest, MethodNames) {
  EXPECT_EQ(ToString(kWilcoxonMethodNames, WilcoxonMethod::kAsymptotic), "asymptotic");
  EXPECT_EQ(FromString(kWilcoxonMethodNames, "exact", "method"), WilcoxonMethod::kExact);
  EXPECT_HAS(ErrorOf([] { FromString(kWilcoxonMethodNames, "approx", "method"); }),
             "method = 'approx', must be one of auto, exact, asymptotic");
}

// ---------------------------------------------------------------------------------------------
// AdjustPValues, pairwise Wilcoxon

TEST(AdjustPValuesTest, MatchesDunnsAdjustments) {
  // The unadjusted p-values and Holm's of DunnTest.AdjustmentsOnFourGroups.
  const std::vector<double> p = {0.4326090566376024,    5.8353096542982744e-05,
                                 1.170393826279659e-05, 0.0012179675052207035,
                                 0.0003203085850434399, 0.7161137054671519};
  const std::vector<double> holm = {0.8652181132752048,    0.0002917654827149137,
                                    7.022362957677954e-05, 0.0036539025156621108,
                                    0.0012812343401737596, 0.8652181132752048};
  EXPECT_EQ(AdjustPValues(p, PAdjust::kNone), p);
  const std::vector<double> h = AdjustPValues(p, PAdjust::kHolm);
  const std::vector<double> b = AdjustPValues(p, PAdjust::kBonferroni);
  ASSERT_EQ(h.size(), 6u);
  for (std::size_t k = 0; k < 6; ++k) {
    EXPECT_REL(h[k], holm[k], 1e-14);
    EXPECT_REL(b[k], std::min(1.0, 6 * p[k]), 1e-14);
  }
  const std::vector<std::vector<double>> groups = {kA, kB, kC, kD};
  const DunnResult dunn = Dunn(groups, PAdjust::kHolm);
  std::vector<double> dunn_p;
  for (const DunnPair& pair : dunn.pairs) dunn_p.push_back(pair.p_value);
  const std::vector<double> adjusted = AdjustPValues(dunn_p, PAdjust::kHolm);
  for (std::size_t k = 0; k < 6; ++k) EXPECT_EQ(dunn.pairs[k].p_adjusted, adjusted[k]);
}

TEST(AdjustPValuesTest, EmptyAndBadInput) {
  EXPECT_TRUE(AdjustPValues({}, PAdjust::kHolm).empty());
  EXPECT_EQ(AdjustPValues({0.3}, PAdjust::kHolm), std::vector<double>{0.3});
  EXPECT_HAS(ErrorOf([] {
               AdjustPValues({0.1, 1.5}, PAdjust::kHolm);
             }),
             "AdjustPValues: p_values[1] = 1.5, must be in [0, 1]");
  EXPECT_HAS(ErrorOf([] { AdjustPValues({kNaN}, PAdjust::kNone); }),
             "AdjustPValues: p_values[0] = nan");
  EXPECT_HAS(ErrorOf([] { AdjustPValues({-0.1}, PAdjust::kBonferroni); }),
             "AdjustPValues: p_values[0] = -0.1");
}

// A pair of conditions i < j with SciPy's statistic, p-value and Holm-adjusted p-value.
struct ScipyPair {
  int i, j;
  double statistic, p, holm;
};

// `r` holds the `expected` pairs in order, each by `method`.
void ExpectPairs(const PairwiseWilcoxonResult& r, const std::vector<ScipyPair>& expected,
                 const char* method) {
  ASSERT_EQ(r.pairs.size(), expected.size());
  for (std::size_t k = 0; k < expected.size(); ++k) {
    SCOPED_TRACE(k);
    EXPECT_EQ(r.pairs[k].i, expected[k].i);
    EXPECT_EQ(r.pairs[k].j, expected[k].j);
    EXPECT_EQ(r.pairs[k].method, method);
    EXPECT_EQ(r.pairs[k].statistic, expected[k].statistic);
    EXPECT_REL(r.pairs[k].p_value, expected[k].p, kRefTol);
    EXPECT_REL(r.pairs[k].p_adjusted, expected[k].holm, kRefTol);
  }
}

TEST(PairwiseWilcoxonTest, ExactPairsWithHolmMatchScipy) {
  // Each pair: stats.wilcoxon(col(T, i), col(T, j)) (exact: no zeros, no ties); Holm by its
  // definition on the six p-values (sorted ascending, p_(r) (m - r + 1), running maximum).
  const std::vector<ScipyPair> expected = {
      {0, 1, 3.0, 0.00244140625, 0.00732421875},  {0, 2, 3.0, 0.00244140625, 0.00732421875},
      {0, 3, 0.0, 0.00048828125, 0.0029296875},   {1, 2, 0.0, 0.00048828125, 0.0029296875},
      {1, 3, 13.0, 0.04248046875, 0.04248046875}, {2, 3, 0.0, 0.00048828125, 0.0029296875}};
  const PairwiseWilcoxonResult r = PairwiseWilcoxon(kTimes);
  EXPECT_EQ(r.adjustment, "holm");
  ExpectPairs(r, expected, "exact");
  // Condition 0 is slower than 1 for 10 of 12 participants; 3 is the fastest for everyone.
  EXPECT_GT(r.pairs[0].rank_biserial, 0);
  EXPECT_EQ(r.pairs[2].rank_biserial, 1.0);
  EXPECT_EQ(r.pairs[3].rank_biserial, -1.0);  // 1 vs 2: 2 is slower for everyone
}

TEST(PairwiseWilcoxonTest, RatingsWithZerosAndTiesMatchScipyApprox) {
  // Every pair has zeros or ties: stats.wilcoxon(col(L, i), col(L, j), method='approx'), which
  // for (0,1), (0,2), (1,3) (with zeros) is also SciPy's default; Holm as above.
  const std::vector<ScipyPair> expected = {
      {0, 1, 0.0, 0.005749708623335458, 0.017249125870006373},
      {0, 2, 0.0, 0.00829921599528076, 0.017249125870006373},
      {0, 3, 0.0, 0.0013155275236832191, 0.007893165142099316},
      {1, 2, 0.0, 0.0015321013954196188, 0.007893165142099316},
      {1, 3, 4.0, 0.05878172135535886, 0.05878172135535886},
      {2, 3, 0.0, 0.0016885456987832165, 0.007893165142099316}};
  const PairwiseWilcoxonResult r = PairwiseWilcoxon(kRatings);
  ExpectPairs(r, expected, "asymptotic");
}

TEST(PairwiseWilcoxonTest, AgreesWithSingleTestsAndOtherAdjustments) {
  const PairwiseWilcoxonResult none = PairwiseWilcoxon(kRatings, PAdjust::kNone);
  const PairwiseWilcoxonResult bonferroni = PairwiseWilcoxon(kRatings, PAdjust::kBonferroni);
  const PairwiseWilcoxonResult asym =
      PairwiseWilcoxon(kTimes, PAdjust::kHolm, WilcoxonMethod::kAsymptotic);
  EXPECT_EQ(none.adjustment, "none");
  EXPECT_EQ(bonferroni.adjustment, "bonferroni");
  for (std::size_t k = 0; k < none.pairs.size(); ++k) {
    const WilcoxonPair& p = none.pairs[k];
    const WilcoxonResult w = WilcoxonSignedRank(Column(kRatings, p.i), Column(kRatings, p.j));
    EXPECT_EQ(p.p_value, w.p_value);
    EXPECT_EQ(p.p_adjusted, w.p_value);
    EXPECT_EQ(p.rank_biserial, w.rank_biserial);
    EXPECT_EQ(bonferroni.pairs[k].p_adjusted, std::min(1.0, 6 * w.p_value));
    EXPECT_EQ(asym.pairs[k].method, "asymptotic");
  }
  // stats.wilcoxon(col(T, 0), col(T, 1), method='approx') -> (3.0, 0.004741768038406972)
  EXPECT_REL(asym.pairs[0].p_value, 0.004741768038406972, kRefTol);
  // Two conditions: one pair, adjustments change nothing.
  const PairwiseWilcoxonResult two = PairwiseWilcoxon({{1.0, 2.5}, {2.0, 2.1}, {0.5, 3.0}});
  ASSERT_EQ(two.pairs.size(), 1u);
  EXPECT_EQ(two.pairs[0].p_adjusted, two.pairs[0].p_value);
}

TEST(PairwiseWilcoxonTest, IdenticalConditionsKeepTheTableComplete) {
  std::vector<std::vector<double>> data = kTimes;
  for (auto& row : data) row[3] = row[0];  // condition 3 repeats condition 0
  const PairwiseWilcoxonResult r = PairwiseWilcoxon(data);
  ASSERT_EQ(r.pairs.size(), 6u);
  EXPECT_EQ(r.pairs[2].i, 0);
  EXPECT_EQ(r.pairs[2].j, 3);
  EXPECT_EQ(r.pairs[2].p_value, 1.0);
  EXPECT_EQ(r.pairs[2].p_adjusted, 1.0);
  EXPECT_EQ(r.pairs[2].statistic, 0.0);
}

TEST(PairwiseWilcoxonTest, ToJsonListsThePairs) {
  const nlohmann::json j = PairwiseWilcoxon(kTimes).ToJson();
  EXPECT_EQ(j.at("adjustment"), "holm");
  ASSERT_EQ(j.at("pairs").size(), 6u);
  const nlohmann::json& p = j.at("pairs")[4];
  EXPECT_EQ(p.at("i"), 1);
  EXPECT_EQ(p.at("j"), 3);
  EXPECT_EQ(p.at("statistic").get<double>(), 13.0);
  EXPECT_EQ(p.at("method"), "exact");
  EXPECT_REL(p.at("p_value").get<double>(), 0.04248046875, kRefTol);
  EXPECT_REL(p.at("p_adjusted").get<double>(), 0.04248046875, kRefTol);
  EXPECT_DOUBLE_EQ(p.at("rank_biserial").get<double>(), 52.0 / 78.0);
}

TEST(PairwiseWilcoxonTest, RejectsBadInput) {
  EXPECT_HAS(ErrorOf([] { PairwiseWilcoxon({}); }),
             "PairwiseWilcoxon: 'data' has 0 rows, needs at least 1");
  EXPECT_HAS(ErrorOf([] {
               PairwiseWilcoxon({{1}, {2}});
             }),
             "PairwiseWilcoxon: row 0 of 'data' has 1 value, needs at least 2");
  EXPECT_HAS(ErrorOf([] {
               PairwiseWilcoxon({{1, 2}, {2, 3, 4}});
             }),
             "PairwiseWilcoxon: row 1 of 'data' has 3 values, row 0 has 2");
  EXPECT_HAS(ErrorOf([] {
               PairwiseWilcoxon({{1, 2}, {kNaN, 3}});
             }),
             "PairwiseWilcoxon: row 1 of 'data' holds a non-finite value (nan) at column 0");
}

}  // namespace
}  // namespace secure::stats
