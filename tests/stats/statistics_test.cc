#include "secure/stats/statistics.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "tests/test_util.h"

namespace secure::stats {
namespace {

using secure::test::ErrorOf;

// Reference values in this file were computed with SciPy 1.10 (scipy.stats.mannwhitneyu,
// kruskal, rankdata, t, norm); Dunn and TOST by their textbook formulas on top of those.
const std::vector<double> kA = {0.49, 0.55, 0.42, 0.51, 0.47, 0.58, 0.44, 0.53, 0.50, 0.46};
const std::vector<double> kB = {0.47, 0.52, 0.41, 0.45, 0.49, 0.43, 0.50, 0.48, 0.39, 0.46};
const std::vector<double> kC = {0.31, 0.36, 0.29, 0.40, 0.33, 0.27, 0.35, 0.30, 0.38, 0.32};
const std::vector<double> kD = {0.28, 0.33, 0.30, 0.35, 0.31, 0.29, 0.34, 0.32, 0.36, 0.30};

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

// |actual - expected| <= rel * |expected|, printed with both values.
#define EXPECT_REL(actual, expected, rel) \
  EXPECT_NEAR((actual), (expected), (rel)*std::abs(static_cast<double>(expected)))

constexpr double kStatTol = 1e-6;  // statistics: relative
constexpr double kPTol = 1e-5;     // p-values: relative

// ---------------------------------------------------------------------------------------------
// Summarize, Midranks

TEST(SummarizeTest, MeanStdWithDdofOneMinMax) {
  const SampleSummary s = Summarize(kA);
  EXPECT_EQ(s.n, 10);
  EXPECT_REL(s.mean, 0.495, 1e-12);
  EXPECT_REL(s.std, 0.049721446300587654, 1e-12);  // numpy std(ddof=1)
  EXPECT_EQ(s.min, 0.42);
  EXPECT_EQ(s.max, 0.58);
  // Hand-computable: {1, 2, 3, 4}: mean 2.5, squared deviations 5, ddof 1 -> var 5/3.
  const SampleSummary t = Summarize({4, 1, 3, 2});
  EXPECT_DOUBLE_EQ(t.mean, 2.5);
  EXPECT_DOUBLE_EQ(t.std, std::sqrt(5.0 / 3.0));
  EXPECT_EQ(t.min, 1);
  EXPECT_EQ(t.max, 4);
}

TEST(SummarizeTest, OneValueHasZeroStd) {
  const SampleSummary s = Summarize({3.25});
  EXPECT_EQ(s.n, 1);
  EXPECT_EQ(s.mean, 3.25);
  EXPECT_EQ(s.std, 0.0);
  EXPECT_EQ(s.min, 3.25);
  EXPECT_EQ(s.max, 3.25);
}

TEST(SummarizeTest, LargeOffsetDoesNotLoseTheSpread) {
  // A naive sum-of-squares formula cancels catastrophically here; the two-pass one does not.
  const SampleSummary s = Summarize({1e9 + 1, 1e9 + 2, 1e9 + 3});
  EXPECT_DOUBLE_EQ(s.std, 1.0);
}

TEST(SummarizeTest, ToJsonHasEveryField) {
  const nlohmann::json j = Summarize({1, 2, 3}).ToJson();
  EXPECT_EQ(j.at("n"), 3);
  EXPECT_DOUBLE_EQ(j.at("mean").get<double>(), 2.0);
  EXPECT_DOUBLE_EQ(j.at("std").get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(j.at("min").get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(j.at("max").get<double>(), 3.0);
}

TEST(SummarizeTest, RejectsEmptyAndNonFinite) {
  EXPECT_HAS(ErrorOf([] { Summarize({}); }), "Summarize: sample 'values' is empty");
  const std::string nan = ErrorOf([] { Summarize({1, kNaN}); });
  EXPECT_HAS(nan, "Summarize: sample 'values' holds a non-finite value (nan) at index 1");
  EXPECT_HAS(ErrorOf([] { Summarize({kInf}); }), "non-finite value (inf) at index 0");
}

TEST(MidranksTest, AveragesTies) {
  EXPECT_EQ(Midranks({3, 1, 3, 2}), (std::vector<double>{3.5, 1, 3.5, 2}));
  EXPECT_EQ(Midranks({5, 5, 5}), (std::vector<double>{2, 2, 2}));
  EXPECT_EQ(Midranks({}), std::vector<double>{});
  EXPECT_EQ(Midranks({-1, 0.5, -7}), (std::vector<double>{2, 3, 1}));
  EXPECT_HAS(ErrorOf([] { Midranks({1, -kInf}); }), "Midranks: sample 'values' holds a non-finite");
}

TEST(MidranksTest, DecimalLiteralsFromDifferentSamplesTie) {
  // 0.47, 0.49, 0.50 and 0.46 occur in both a and b: the same literals, so exact ties.
  std::vector<double> pooled = kA;
  pooled.insert(pooled.end(), kB.begin(), kB.end());
  const std::vector<double> r = Midranks(pooled);
  EXPECT_EQ(r[4], r[10]);  // 0.47
  EXPECT_EQ(r[0], r[14]);  // 0.49
  EXPECT_EQ(r[8], r[16]);  // 0.50
  EXPECT_EQ(r[9], r[19]);  // 0.46
  double sum = 0;
  for (double v : r) sum += v;
  EXPECT_DOUBLE_EQ(sum, 20.0 * 21.0 / 2.0);
}

// ---------------------------------------------------------------------------------------------
// Mann–Whitney U

TEST(MannWhitneyTest, AsymptoticWithTiesMatchesScipy) {
  // a and b share tied values, so auto uses the asymptotic method.
  for (MannWhitneyMethod m : {MannWhitneyMethod::kAuto, MannWhitneyMethod::kAsymptotic}) {
    const MannWhitneyResult r = MannWhitneyU(kA, kB, m);
    EXPECT_EQ(r.method, "asymptotic");
    EXPECT_EQ(r.u, 70.0);
    EXPECT_REL(r.p_value, 0.1398679114797594, kPTol);
    EXPECT_GT(r.z, 0);  // a tends to be larger
    EXPECT_DOUBLE_EQ(r.rank_biserial, 2.0 * 70.0 / 100.0 - 1.0);
  }
}

TEST(MannWhitneyTest, ExactMatchesScipy) {
  for (MannWhitneyMethod m : {MannWhitneyMethod::kAuto, MannWhitneyMethod::kExact}) {
    const MannWhitneyResult r = MannWhitneyU(kA, kC, m);
    EXPECT_EQ(r.method, "exact");
    EXPECT_EQ(r.u, 100.0);
    EXPECT_REL(r.p_value, 1.082508822446903e-05, kPTol);
    EXPECT_TRUE(std::isnan(r.z));
    EXPECT_EQ(r.rank_biserial, 1.0);
  }
  const MannWhitneyResult bc = MannWhitneyU(kB, kC, MannWhitneyMethod::kExact);
  EXPECT_EQ(bc.u, 99.0);
  EXPECT_REL(bc.p_value, 2.165017644893806e-05, kPTol);
  // The asymptotic p-values for the same samples, from SciPy.
  EXPECT_REL(MannWhitneyU(kA, kC, MannWhitneyMethod::kAsymptotic).p_value, 0.00018267179110955002,
             kPTol);
  EXPECT_REL(MannWhitneyU(kB, kC, MannWhitneyMethod::kAsymptotic).p_value, 0.00024612812790522973,
             kPTol);
}

TEST(MannWhitneyTest, TinyHandComputableExactCases) {
  // {1,2} vs {3,4}: U = 0; of the C(4,2) = 6 orderings one has U = 0, so p = 2 * 1/6.
  const MannWhitneyResult r = MannWhitneyU({1, 2}, {3, 4}, MannWhitneyMethod::kExact);
  EXPECT_EQ(r.u, 0.0);
  EXPECT_NEAR(r.p_value, 1.0 / 3.0, 1e-14);
  EXPECT_EQ(r.rank_biserial, -1.0);
  // U distribution for (2, 2): counts 1,1,2,1,1 for U = 0..4. U = 2 is the median: p = 1.
  EXPECT_EQ(MannWhitneyU({1, 4}, {2, 3}, MannWhitneyMethod::kExact).p_value, 1.0);
  // U = 1: P(U <= 1) = 2/6, p = 2/3.
  EXPECT_NEAR(MannWhitneyU({1, 3}, {2, 4}, MannWhitneyMethod::kExact).p_value, 2.0 / 3.0, 1e-14);
  // 5 vs 6 fully separated: p = 2 / C(11, 5) = 2 / 462 (SciPy: 0.004329004329004329).
  EXPECT_NEAR(MannWhitneyU({1, 2, 3, 4, 5}, {6, 7, 8, 9, 10, 11}).p_value, 2.0 / 462.0, 1e-15);
  // One value each: U is 0 or 1 with probability 1/2: p = 1.
  EXPECT_EQ(MannWhitneyU({1}, {2}).p_value, 1.0);
}

TEST(MannWhitneyTest, LargerExactAndAsymptoticMatchScipyAndAgree) {
  // 40 vs 45 values, no ties (SciPy: exact 0.0836190556018177, asymptotic 0.08361490563366317).
  const std::vector<double> x = {
      0.345584,  0.821618,  0.330437,  -1.303157, 0.905356,  0.446375,  -0.536953, 0.581118,
      0.364572,  0.294132,  0.028422,  0.546713,  -0.736454, -0.16291,  -0.482119, 0.598846,
      0.039722,  -0.292457, -0.781908, -0.257192, 0.008142,  -0.275603, 1.294064,  1.006724,
      -2.711162, -1.889013, -0.174772, -0.42219,  0.213643,  0.217322,  2.117839,  -1.112021,
      -0.377605, 2.042772,  0.646703,  0.663063,  -0.514006, -1.648075, 0.167465,  0.109014};
  const std::vector<double> y = {
      -0.727352, -0.183227, 0.427956,  -0.444752, 0.40173,   0.595483,  0.535586,  -0.006292,
      1.093748,  1.391167,  0.820848,  -0.31823,  1.231652,  -0.00144,  1.379161,  -0.571787,
      1.414467,  0.479937,  -0.748749, 0.186101,  0.554102,  0.772791,  -0.482188, -0.607373,
      0.699585,  0.03325,   0.735506,  1.25952,   -1.148787, 0.754388,  1.724647,  0.202473,
      -0.310815, 1.252244,  0.753447,  1.395883,  0.154784,  -0.981818, 0.389989,  0.054172,
      1.275324,  0.693633,  -1.130849, -0.695163, 1.383789};
  const MannWhitneyResult exact = MannWhitneyU(x, y);
  EXPECT_EQ(exact.method, "exact");
  EXPECT_EQ(exact.u, 703.0);
  EXPECT_REL(exact.p_value, 0.0836190556018177, kPTol);
  const MannWhitneyResult asym = MannWhitneyU(x, y, MannWhitneyMethod::kAsymptotic);
  EXPECT_EQ(asym.u, 703.0);
  EXPECT_REL(asym.p_value, 0.08361490563366317, kPTol);
  EXPECT_LT(asym.z, 0);
  // Moderate n: the two methods agree to a few percent.
  EXPECT_NEAR(asym.p_value, exact.p_value, 0.05 * exact.p_value);
  // Above the auto limit (51 values) auto switches to asymptotic.
  std::vector<double> x51 = x;
  for (int k = 0; k < 11; ++k) x51.push_back(10.0 + k);
  EXPECT_EQ(MannWhitneyU(x51, y).method, "asymptotic");
  EXPECT_EQ(MannWhitneyU(x51, y, MannWhitneyMethod::kExact).method, "exact");
}

TEST(MannWhitneyTest, SwappingTheSamplesMirrorsU) {
  const std::vector<std::pair<std::vector<double>, std::vector<double>>> cases = {
      {kA, kB}, {kA, kC}, {kB, kC}, {{1, 2, 3}, {3, 4, 5}}, {{0.5}, {0.1, 0.9, 0.3}}};
  for (const auto& [a, b] : cases) {
    for (MannWhitneyMethod m : {MannWhitneyMethod::kAuto, MannWhitneyMethod::kAsymptotic}) {
      const MannWhitneyResult ab = MannWhitneyU(a, b, m), ba = MannWhitneyU(b, a, m);
      EXPECT_EQ(ab.u + ba.u, static_cast<double>(a.size() * b.size()));
      EXPECT_EQ(ab.method, ba.method);
      EXPECT_NEAR(ab.p_value, ba.p_value, 1e-14);
      EXPECT_NEAR(ab.rank_biserial, -ba.rank_biserial, 1e-14);
      if (ab.method == "asymptotic") {
        EXPECT_NEAR(ab.z, -ba.z, 1e-14);
      }
    }
  }
}

TEST(MannWhitneyTest, TiesCountHalf) {
  // {1,2,3} vs {3,4,5}: pairs x > y: none; one tie (3, 3): U = 0.5 (SciPy p = 0.12118327283746319).
  const MannWhitneyResult r = MannWhitneyU({1, 2, 3}, {3, 4, 5});
  EXPECT_EQ(r.u, 0.5);
  EXPECT_EQ(r.method, "asymptotic");
  EXPECT_REL(r.p_value, 0.12118327283746319, kPTol);
}

TEST(MannWhitneyTest, AllValuesTiedGiveScipysAnswer) {
  const MannWhitneyResult r = MannWhitneyU({1, 1, 1}, {1, 1});
  EXPECT_EQ(r.u, 3.0);  // SciPy: statistic 3.0, p 1.0
  EXPECT_EQ(r.p_value, 1.0);
  EXPECT_EQ(r.method, "asymptotic");
  EXPECT_EQ(r.z, 0.0);
  EXPECT_EQ(r.rank_biserial, 0.0);
}

TEST(MannWhitneyTest, ToJsonWritesNullZForExact) {
  const nlohmann::json exact = MannWhitneyU({1, 2}, {3, 4}).ToJson();
  EXPECT_TRUE(exact.at("z").is_null());
  EXPECT_EQ(exact.at("method"), "exact");
  EXPECT_DOUBLE_EQ(exact.at("u").get<double>(), 0.0);
  EXPECT_NEAR(exact.at("p_value").get<double>(), 1.0 / 3.0, 1e-14);
  EXPECT_DOUBLE_EQ(exact.at("rank_biserial").get<double>(), -1.0);
  const nlohmann::json asym = MannWhitneyU(kA, kB).ToJson();
  EXPECT_TRUE(asym.at("z").is_number());
}

TEST(MannWhitneyTest, RejectsBadInput) {
  EXPECT_HAS(ErrorOf([] { MannWhitneyU({}, {1}); }), "MannWhitneyU: sample 'a' is empty");
  EXPECT_HAS(ErrorOf([] { MannWhitneyU({1}, {}); }), "MannWhitneyU: sample 'b' is empty");
  EXPECT_HAS(ErrorOf([] {
               MannWhitneyU({1, kNaN}, {2});
             }),
             "MannWhitneyU: sample 'a' holds a non-finite value (nan) at index 1");
  EXPECT_HAS(ErrorOf([] {
               MannWhitneyU({1}, {2, 3, -kInf});
             }),
             "MannWhitneyU: sample 'b' holds a non-finite value (-inf) at index 2");
  const std::string tied = ErrorOf([] { MannWhitneyU(kA, kB, MannWhitneyMethod::kExact); });
  EXPECT_HAS(tied, "MannWhitneyU: method = exact");
  EXPECT_HAS(tied, "tied values");
}

TEST(MannWhitneyTest, MethodNames) {
  EXPECT_EQ(ToString(kMannWhitneyMethodNames, MannWhitneyMethod::kAsymptotic), "asymptotic");
  EXPECT_EQ(FromString(kMannWhitneyMethodNames, "exact", "method"), MannWhitneyMethod::kExact);
  EXPECT_HAS(ErrorOf([] { FromString(kMannWhitneyMethodNames, "fast", "method"); }),
             "method = 'fast', must be one of auto, exact, asymptotic");
}

// ---------------------------------------------------------------------------------------------
// TOST

TEST(TostWelchTest, EquivalentPairMatchesReference) {
  const TostResult r = TostWelch(kA, kB, 0.10);
  EXPECT_REL(r.difference, 0.035, 1e-12);
  EXPECT_EQ(r.bound, 0.10);
  EXPECT_REL(r.se, 0.020344259359556173, kStatTol);
  EXPECT_REL(r.df, 17.34302577901224, kStatTol);
  EXPECT_REL(r.t_lower, 6.635778556204226, kStatTol);
  EXPECT_REL(r.p_lower, 1.901630205436652e-06, kPTol);
  EXPECT_REL(r.t_upper, -3.195004490024259, kStatTol);
  EXPECT_REL(r.p_upper, 0.002600589461937522, kPTol);
  EXPECT_REL(r.p_value, 0.002600589461937522, kPTol);
  EXPECT_TRUE(r.equivalent());
  EXPECT_TRUE(r.equivalent(0.01));
  EXPECT_FALSE(r.equivalent(0.001));
}

TEST(TostWelchTest, DifferentPairIsNotEquivalent) {
  const TostResult r = TostWelch(kA, kC, 0.10);
  EXPECT_REL(r.difference, 0.164, 1e-12);
  EXPECT_REL(r.df, 17.401829685423518, kStatTol);
  EXPECT_REL(r.t_upper, 3.133676022324724, kStatTol);
  EXPECT_REL(r.p_lower, 1.1797176056136503e-10, kPTol);
  EXPECT_REL(r.p_value, 0.9970394826991223, kPTol);
  EXPECT_FALSE(r.equivalent());
  // A tight bound: a - b is no longer shown equivalent.
  const TostResult tight = TostWelch(kA, kB, 0.03);
  EXPECT_REL(tight.p_lower, 0.002600589461937534, kPTol);
  EXPECT_REL(tight.p_value, 0.5956272159297584, kPTol);
  EXPECT_FALSE(tight.equivalent());
}

TEST(TostWelchTest, SwappingTheSamplesSwapsTheTails) {
  const TostResult ab = TostWelch(kA, kB, 0.1), ba = TostWelch(kB, kA, 0.1);
  EXPECT_NEAR(ab.difference, -ba.difference, 1e-15);
  EXPECT_NEAR(ab.df, ba.df, 1e-12);
  EXPECT_NEAR(ab.p_lower, ba.p_upper, 1e-15);
  EXPECT_NEAR(ab.p_upper, ba.p_lower, 1e-15);
  EXPECT_NEAR(ab.p_value, ba.p_value, 1e-15);
}

TEST(TostWelchTest, BothSamplesConstantIsExact) {
  const TostResult in = TostWelch({1, 1, 1}, {1.05, 1.05}, 0.1);
  EXPECT_EQ(in.se, 0.0);
  EXPECT_EQ(in.df, kInf);
  EXPECT_EQ(in.p_lower, 0.0);
  EXPECT_EQ(in.p_upper, 0.0);
  EXPECT_EQ(in.p_value, 0.0);
  EXPECT_EQ(in.t_lower, kInf);
  EXPECT_EQ(in.t_upper, -kInf);
  EXPECT_TRUE(in.equivalent());
  const TostResult out = TostWelch({1, 1}, {1.5, 1.5}, 0.1);  // difference -0.5
  EXPECT_EQ(out.p_lower, 1.0);
  EXPECT_EQ(out.p_upper, 0.0);
  EXPECT_EQ(out.p_value, 1.0);
  EXPECT_EQ(out.t_lower, -kInf);
  EXPECT_FALSE(out.equivalent());
  const TostResult above = TostWelch({2, 2}, {1, 1}, 0.1);  // difference +1
  EXPECT_EQ(above.p_lower, 0.0);
  EXPECT_EQ(above.p_upper, 1.0);
  EXPECT_EQ(above.t_upper, kInf);
  EXPECT_FALSE(above.equivalent());
  // JSON: the infinities become null, nothing is NaN.
  const nlohmann::json j = in.ToJson();
  EXPECT_TRUE(j.at("df").is_null());
  EXPECT_TRUE(j.at("t_lower").is_null());
  EXPECT_EQ(j.at("p_value").get<double>(), 0.0);
}

TEST(TostWelchTest, OneConstantSampleUsesTheOthersVariance) {
  // b constant: se^2 = var(a) / n_a, df = n_a - 1.
  const std::vector<double> a = {1.0, 2.0, 3.0, 4.0};
  const TostResult r = TostWelch(a, {2.5, 2.5, 2.5}, 1.0);
  EXPECT_DOUBLE_EQ(r.difference, 0.0);
  EXPECT_DOUBLE_EQ(r.se, std::sqrt(5.0 / 3.0 / 4.0));
  EXPECT_DOUBLE_EQ(r.df, 3.0);
  EXPECT_TRUE(std::isfinite(r.p_value));
  EXPECT_DOUBLE_EQ(r.p_lower, r.p_upper);  // symmetric about 0
}

TEST(TostPairedTest, IsTheOneSampleTestOfTheDifferences) {
  // Paired values with a large shared per-seed effect (the seeds' models) and a small,
  // consistent difference: Welch sees the seed spread, the paired test only the differences.
  const std::vector<double> seed_effect = {0.2, 0.9, 0.5, 0.05, 0.7, 0.35, 0.8, 0.6, 0.1, 0.45};
  const std::vector<double> shift = {0.01, -0.02, 0.0,    0.015, -0.01,
                                     0.02, 0.005, -0.005, 0.0,   0.01};
  std::vector<double> a, b, d;
  for (std::size_t i = 0; i < seed_effect.size(); ++i) {
    a.push_back(seed_effect[i] + shift[i]);
    b.push_back(seed_effect[i]);
    d.push_back(a.back() - b.back());
  }
  const TostResult paired = TostPaired(a, b, 0.02);
  // The one-sample test of d against 0 is TostWelch with a constant second sample.
  const TostResult one_sample = TostWelch(d, std::vector<double>(d.size(), 0.0), 0.02);
  EXPECT_NEAR(paired.difference, 0.0025, 1e-15);
  EXPECT_DOUBLE_EQ(paired.df, 9.0);
  EXPECT_NEAR(paired.se, one_sample.se, 1e-15);
  EXPECT_NEAR(paired.p_lower, one_sample.p_lower, 1e-12);
  EXPECT_NEAR(paired.p_upper, one_sample.p_upper, 1e-12);
  EXPECT_TRUE(paired.equivalent());
  EXPECT_FALSE(TostWelch(a, b, 0.02).equivalent());  // the seed spread hides the equivalence
}

TEST(TostPairedTest, MatchesTheStudentTQuantile) {
  // d = {-1, 1} * c + m with n = 2 has std = c * sqrt(2), se = c, df = 1. With bound - m = c *
  // 6.313751514675 (t_{0.95, 1}) the upper test sits at p = 0.05.
  const double c = 0.01, m = 0.003, bound = m + c * 6.313751514675043;
  const TostResult r = TostPaired({m - c, m + c}, {0.0, 0.0}, bound);
  EXPECT_DOUBLE_EQ(r.df, 1.0);
  EXPECT_NEAR(r.se, c, 1e-15);
  EXPECT_NEAR(r.p_upper, 0.05, 1e-9);
  EXPECT_LT(r.p_lower, 0.05);
  EXPECT_NEAR(r.p_value, 0.05, 1e-9);
}

TEST(TostPairedTest, EqualDifferencesAreExactAndBadInputIsNamed) {
  const TostResult same = TostPaired({0.5, 0.7, 0.9}, {0.49, 0.69, 0.89}, 0.02);
  EXPECT_EQ(same.se, 0.0);
  EXPECT_EQ(same.p_value, 0.0);
  EXPECT_FALSE(TostPaired({0.5, 0.7}, {0.4, 0.6}, 0.02).equivalent());
  EXPECT_HAS(ErrorOf([] {
               TostPaired({1, 2, 3}, {1, 2}, 0.1);
             }),
             "TostPaired: samples 'a' and 'b' have 3 and 2 values, must be paired");
  EXPECT_HAS(ErrorOf([] { TostPaired({1, 2}, {1, 2}, 0.0); }), "TostPaired: bound = 0");
  EXPECT_HAS(ErrorOf([] { TostPaired({1}, {1}, 0.1); }), "TostPaired: sample 'a'");
}

TEST(TostWelchTest, ToJsonHasEveryField) {
  const nlohmann::json j = TostWelch(kA, kB, 0.1).ToJson();
  for (const char* key :
       {"difference", "bound", "se", "df", "t_lower", "p_lower", "t_upper", "p_upper", "p_value"})
    EXPECT_TRUE(j.at(key).is_number()) << key;
}

TEST(TostWelchTest, RejectsBadInput) {
  EXPECT_HAS(ErrorOf([] { TostWelch(kA, kB, -0.1); }), "TostWelch: bound = -0.1, must be > 0");
  EXPECT_HAS(ErrorOf([] { TostWelch(kA, kB, 0.0); }), "TostWelch: bound = 0, must be > 0");
  EXPECT_HAS(ErrorOf([] { TostWelch(kA, kB, kNaN); }), "TostWelch: bound = nan");
  EXPECT_HAS(ErrorOf([] { TostWelch(kA, kB, kInf); }), "TostWelch: bound = inf");
  EXPECT_HAS(ErrorOf([] { TostWelch({}, kB, 0.1); }), "TostWelch: sample 'a' is empty");
  EXPECT_HAS(ErrorOf([] { TostWelch(kA, {0.5}, 0.1); }),
             "TostWelch: sample 'b' has 1 value, needs at least 2");
  EXPECT_HAS(ErrorOf([] {
               TostWelch({1, kInf}, kB, 0.1);
             }),
             "TostWelch: sample 'a' holds a non-finite value (inf) at index 1");
  const TostResult r = TostWelch(kA, kB, 0.1);
  EXPECT_HAS(ErrorOf([&] { r.equivalent(0.0); }),
             "TostResult::equivalent: alpha = 0, must be in (0, 1)");
  EXPECT_HAS(ErrorOf([&] { r.equivalent(1.5); }), "alpha = 1.5");
}

// ---------------------------------------------------------------------------------------------
// Kruskal–Wallis

TEST(KruskalWallisTest, MatchesScipy) {
  const KruskalWallisResult r = KruskalWallis({kA, kB, kC});
  EXPECT_REL(r.h, 20.072055221554226, kStatTol);
  EXPECT_EQ(r.df, 2);
  EXPECT_REL(r.p_value, 4.379339238390723e-05, kPTol);
  const KruskalWallisResult four = KruskalWallis({kA, kB, kC, kD});
  EXPECT_REL(four.h, 29.762502348299826, kStatTol);
  EXPECT_EQ(four.df, 3);
  EXPECT_REL(four.p_value, 1.5482761316463795e-06, kPTol);
}

TEST(KruskalWallisTest, DoesNotDependOnGroupOrder) {
  const KruskalWallisResult abc = KruskalWallis({kA, kB, kC});
  const KruskalWallisResult cab = KruskalWallis({kC, kA, kB});
  EXPECT_NEAR(abc.h, cab.h, 1e-12);
  EXPECT_NEAR(abc.p_value, cab.p_value, 1e-15);
}

TEST(KruskalWallisTest, TwoGroupsWithoutTiesIsZSquaredOfMannWhitney) {
  // For two groups, uncorrected H = z^2 of the Mann-Whitney normal approximation (no continuity
  // correction): here a vs c with U = 100, mu = 50, sigma^2 = 100 * 21 / 12.
  const KruskalWallisResult r = KruskalWallis({kA, kC});
  EXPECT_NEAR(r.h, 50.0 * 50.0 / (100.0 * 21.0 / 12.0), 1e-10);
  EXPECT_EQ(r.df, 1);
}

TEST(KruskalWallisTest, IdenticalDistributionsGiveHZero) {
  const KruskalWallisResult r = KruskalWallis({{1, 4}, {2, 3}});  // equal mean ranks
  EXPECT_EQ(r.h, 0.0);
  EXPECT_EQ(r.p_value, 1.0);
  const nlohmann::json j = r.ToJson();
  EXPECT_EQ(j.at("df"), 1);
  EXPECT_EQ(j.at("h").get<double>(), 0.0);
  EXPECT_EQ(j.at("p_value").get<double>(), 1.0);
}

TEST(KruskalWallisTest, RejectsBadInput) {
  EXPECT_HAS(ErrorOf([] { KruskalWallis({}); }), "KruskalWallis: 0 groups given, needs at least 2");
  EXPECT_HAS(ErrorOf([] { KruskalWallis({kA}); }),
             "KruskalWallis: 1 group given, needs at least 2");
  EXPECT_HAS(ErrorOf([] { KruskalWallis({kA, {}, kC}); }), "KruskalWallis: group 1 is empty");
  EXPECT_HAS(ErrorOf([] {
               KruskalWallis({kA, kB, {0.3, kNaN}});
             }),
             "KruskalWallis: group 2 holds a non-finite value (nan) at index 1");
  EXPECT_HAS(ErrorOf([] {
               KruskalWallis({{2, 2}, {2}, {2, 2, 2}});
             }),
             "KruskalWallis: all 6 values are the same; H is undefined");
}

// ---------------------------------------------------------------------------------------------
// Dunn

TEST(DunnTest, ThreeGroupsMatchReferenceInPairOrder) {
  const DunnResult r = Dunn({kA, kB, kC});
  EXPECT_EQ(r.adjustment, "bonferroni");
  ASSERT_EQ(r.pairs.size(), 3u);
  EXPECT_EQ(r.pairs[0].i, 0);
  EXPECT_EQ(r.pairs[0].j, 1);
  EXPECT_EQ(r.pairs[1].i, 0);
  EXPECT_EQ(r.pairs[1].j, 2);
  EXPECT_EQ(r.pairs[2].i, 1);
  EXPECT_EQ(r.pairs[2].j, 2);
  EXPECT_REL(r.pairs[0].z, 1.0418647106326402, kStatTol);
  EXPECT_REL(r.pairs[0].p_value, 0.2974744072709399, kPTol);
  EXPECT_REL(r.pairs[0].p_adjusted, 0.8924232218128197, kPTol);
  EXPECT_REL(r.pairs[1].z, 4.294515514558929, kStatTol);
  EXPECT_REL(r.pairs[1].p_value, 1.7507523876665816e-05, kPTol);
  EXPECT_REL(r.pairs[1].p_adjusted, 3 * 1.7507523876665816e-05, kPTol);
  EXPECT_REL(r.pairs[2].z, 3.25265080392629, kStatTol);
  EXPECT_REL(r.pairs[2].p_value, 0.0011433390847228637, kPTol);
  EXPECT_REL(r.pairs[2].p_adjusted, 0.003430017254168591, kPTol);
}

TEST(DunnTest, ReversedGroupsFlipTheSignOfZ) {
  const DunnResult r = Dunn({kC, kB, kA});  // pairs (0,1) = c-b, (0,2) = c-a, (1,2) = b-a
  EXPECT_REL(r.pairs[0].z, -3.25265080392629, kStatTol);
  EXPECT_REL(r.pairs[1].z, -4.294515514558929, kStatTol);
  EXPECT_REL(r.pairs[2].z, -1.0418647106326402, kStatTol);
}

TEST(DunnTest, AdjustmentsOnFourGroups) {
  // Unadjusted p of the 6 pairs (0,1) (0,2) (0,3) (1,2) (1,3) (2,3), and Holm from the reference.
  const std::vector<double> p = {0.4326090566376024,    5.8353096542982744e-05,
                                 1.170393826279659e-05, 0.0012179675052207035,
                                 0.0003203085850434399, 0.7161137054671519};
  const std::vector<double> holm = {0.8652181132752048,    0.0002917654827149137,
                                    7.022362957677954e-05, 0.0036539025156621108,
                                    0.0012812343401737596, 0.8652181132752048};
  const std::vector<std::vector<double>> groups = {kA, kB, kC, kD};
  const DunnResult none = Dunn(groups, PAdjust::kNone);
  const DunnResult bonferroni = Dunn(groups, PAdjust::kBonferroni);
  const DunnResult holm_result = Dunn(groups, PAdjust::kHolm);
  EXPECT_EQ(none.adjustment, "none");
  EXPECT_EQ(holm_result.adjustment, "holm");
  ASSERT_EQ(none.pairs.size(), 6u);
  for (std::size_t k = 0; k < 6; ++k) {
    SCOPED_TRACE(k);
    EXPECT_REL(none.pairs[k].p_value, p[k], kPTol);
    EXPECT_EQ(none.pairs[k].p_adjusted, none.pairs[k].p_value);
    EXPECT_REL(bonferroni.pairs[k].p_adjusted, std::min(1.0, 6 * p[k]), kPTol);
    EXPECT_REL(holm_result.pairs[k].p_adjusted, holm[k], kPTol);
    EXPECT_LE(holm_result.pairs[k].p_adjusted, bonferroni.pairs[k].p_adjusted);
    EXPECT_GE(holm_result.pairs[k].p_adjusted, holm_result.pairs[k].p_value);
  }
  EXPECT_EQ(bonferroni.pairs[5].p_adjusted, 1.0);  // 6 * 0.716 capped
}

TEST(DunnTest, ToJsonListsThePairs) {
  const nlohmann::json j = Dunn({kA, kB, kC}).ToJson();
  EXPECT_EQ(j.at("adjustment"), "bonferroni");
  ASSERT_EQ(j.at("pairs").size(), 3u);
  EXPECT_EQ(j.at("pairs")[2].at("i"), 1);
  EXPECT_EQ(j.at("pairs")[2].at("j"), 2);
  EXPECT_TRUE(j.at("pairs")[2].at("z").is_number());
  EXPECT_TRUE(j.at("pairs")[2].at("p_value").is_number());
  EXPECT_TRUE(j.at("pairs")[2].at("p_adjusted").is_number());
  EXPECT_EQ(ToString(kPAdjustNames, PAdjust::kHolm), "holm");
  EXPECT_EQ(FromString(kPAdjustNames, "none", "adjust"), PAdjust::kNone);
}

TEST(DunnTest, RejectsBadInput) {
  EXPECT_HAS(ErrorOf([] { Dunn({kA}); }), "Dunn: 1 group given, needs at least 2");
  EXPECT_HAS(ErrorOf([] { Dunn({{}, kA}); }), "Dunn: group 0 is empty");
  EXPECT_HAS(ErrorOf([] {
               Dunn({kA, {kInf}});
             }),
             "Dunn: group 1 holds a non-finite value (inf) at index 0");
  EXPECT_HAS(ErrorOf([] { Dunn({{0.5}, {0.5, 0.5}}); }), "Dunn: all 3 values are the same");
}

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
  EXPECT_EQ(l.method, "asymptotic");
  EXPECT_EQ(l.zeros, 3);
  EXPECT_EQ(l.n, 9);
  EXPECT_EQ(l.statistic, 0.0);
  EXPECT_EQ(l.w_minus, 45.0);
  EXPECT_REL(l.p_value, 0.005749708623335458, kRefTol);
  EXPECT_REL(l.z, -2.7617238536949698, kRefTol);
  EXPECT_EQ(l.rank_biserial, -1.0);
}

TEST(WilcoxonTest, TiesWithoutZerosUseTheNormalApproximationUnlikeScipy110) {
  // col(L, 0) - col(L, 3): 12 negative differences, |d| in {1, 2}: tied. SciPy 1.10's default
  // keeps the exact distribution here: stats.wilcoxon(col(L, 0), col(L, 3)) -> (0.0,
  // 0.00048828125) = 2 / 2^12, as if the ranks were 1..12. kAuto uses the tie-corrected normal
  // approximation: stats.wilcoxon(col(L, 0), col(L, 3), method='approx')
  //   -> (0.0, 0.0013155275236832191), zstatistic -3.2125707287191205
  const WilcoxonResult r = WilcoxonSignedRank(Column(kRatings, 0), Column(kRatings, 3));
  EXPECT_EQ(r.method, "asymptotic");
  EXPECT_EQ(r.zeros, 0);
  EXPECT_EQ(r.n, 12);
  EXPECT_EQ(r.statistic, 0.0);
  EXPECT_EQ(r.w_minus, 78.0);
  EXPECT_REL(r.p_value, 0.0013155275236832191, kRefTol);
  EXPECT_REL(r.z, -3.2125707287191205, kRefTol);
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

TEST(PairwiseWilcoxonTest, ExactPairsWithHolmMatchScipy) {
  // Each pair: stats.wilcoxon(col(T, i), col(T, j)) (exact: no zeros, no ties); Holm by its
  // definition on the six p-values (sorted ascending, p_(r) (m - r + 1), running maximum).
  struct Row {
    int i, j;
    double statistic, p, holm;
  };
  const std::vector<Row> expected = {
      {0, 1, 3.0, 0.00244140625, 0.00732421875},  {0, 2, 3.0, 0.00244140625, 0.00732421875},
      {0, 3, 0.0, 0.00048828125, 0.0029296875},   {1, 2, 0.0, 0.00048828125, 0.0029296875},
      {1, 3, 13.0, 0.04248046875, 0.04248046875}, {2, 3, 0.0, 0.00048828125, 0.0029296875}};
  const PairwiseWilcoxonResult r = PairwiseWilcoxon(kTimes);
  EXPECT_EQ(r.adjustment, "holm");
  ASSERT_EQ(r.pairs.size(), expected.size());
  for (std::size_t k = 0; k < expected.size(); ++k) {
    SCOPED_TRACE(k);
    EXPECT_EQ(r.pairs[k].i, expected[k].i);
    EXPECT_EQ(r.pairs[k].j, expected[k].j);
    EXPECT_EQ(r.pairs[k].method, "exact");
    EXPECT_EQ(r.pairs[k].statistic, expected[k].statistic);
    EXPECT_REL(r.pairs[k].p_value, expected[k].p, kRefTol);
    EXPECT_REL(r.pairs[k].p_adjusted, expected[k].holm, kRefTol);
  }
  // Condition 0 is slower than 1 for 10 of 12 participants; 3 is the fastest for everyone.
  EXPECT_GT(r.pairs[0].rank_biserial, 0);
  EXPECT_EQ(r.pairs[2].rank_biserial, 1.0);
  EXPECT_EQ(r.pairs[3].rank_biserial, -1.0);  // 1 vs 2: 2 is slower for everyone
}

TEST(PairwiseWilcoxonTest, RatingsWithZerosAndTiesMatchScipyApprox) {
  // Every pair has zeros or ties: stats.wilcoxon(col(L, i), col(L, j), method='approx'), which
  // for (0,1), (0,2), (1,3) (with zeros) is also SciPy's default; Holm as above.
  struct Row {
    int i, j;
    double statistic, p, holm;
  };
  const std::vector<Row> expected = {{0, 1, 0.0, 0.005749708623335458, 0.017249125870006373},
                                     {0, 2, 0.0, 0.00829921599528076, 0.017249125870006373},
                                     {0, 3, 0.0, 0.0013155275236832191, 0.007893165142099316},
                                     {1, 2, 0.0, 0.0015321013954196188, 0.007893165142099316},
                                     {1, 3, 4.0, 0.05878172135535886, 0.05878172135535886},
                                     {2, 3, 0.0, 0.0016885456987832165, 0.007893165142099316}};
  const PairwiseWilcoxonResult r = PairwiseWilcoxon(kRatings);
  ASSERT_EQ(r.pairs.size(), expected.size());
  for (std::size_t k = 0; k < expected.size(); ++k) {
    SCOPED_TRACE(k);
    EXPECT_EQ(r.pairs[k].i, expected[k].i);
    EXPECT_EQ(r.pairs[k].j, expected[k].j);
    EXPECT_EQ(r.pairs[k].method, "asymptotic");
    EXPECT_EQ(r.pairs[k].statistic, expected[k].statistic);
    EXPECT_REL(r.pairs[k].p_value, expected[k].p, kRefTol);
    EXPECT_REL(r.pairs[k].p_adjusted, expected[k].holm, kRefTol);
  }
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
