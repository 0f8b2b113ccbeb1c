// Statistics between groups (the stats_test program): Summarize, Midranks, Mann-Whitney, TOST,
// Kruskal-Wallis, Dunn, against SciPy reference values. Within-subject designs (Friedman,
// Wilcoxon, p-value adjustment): within_subject_test.cc.
#include "tests/stats/stats_test_util.h"

namespace secure::stats {
namespace {
using namespace test;  // NOLINT(google-build-using-namespace): the reference samples

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

}  // namespace
}  // namespace secure::stats
