#pragma once
// Statistics for comparing methods over seeds (the paper's Section 6 runs every method with 10
// seeds): summaries, the Mann–Whitney U test, a TOST equivalence test (two one-sided Welch
// t-tests), the Kruskal–Wallis H test and Dunn's post-hoc test; and, for within-subject designs
// (the same participants under every condition), the Friedman test, the Wilcoxon signed-rank test
// and pairwise Wilcoxon post-hoc tests. Results are plain structs with documented fields and
// ToJson(), so the evaluation harness can store them next to its metrics.
//
//   using namespace secure::stats;
//   const std::vector<double> secure_rate = {...}, bc_rate = {...};   // one value per seed
//   const SampleSummary s = Summarize(secure_rate);                   // mean ± std (ddof = 1)
//   const MannWhitneyResult mw = MannWhitneyU(secure_rate, bc_rate);  // do they differ?
//   const TostResult tost = TostWelch(secure_rate, bc_rate, 0.05);    // are they within ±0.05?
//   if (tost.equivalent()) ...
//   const DunnResult dunn = Dunn({secure_rate, bc_rate, airl_rate});  // which pairs differ?
//
//   // Within-subject: one row per participant, one column per condition.
//   const std::vector<std::vector<double>> times = {{41.2, 38.5, 45.1, 36.9}, ...};
//   const FriedmanResult f = Friedman(times);                      // do the conditions differ?
//   const PairwiseWilcoxonResult post = PairwiseWilcoxon(times);   // which pairs (Holm)?
//
// Conventions (chosen to match SciPy, so numbers can be checked against scipy.stats):
//   - Ranks are 1-based, and tied values get the average of the ranks they span (midranks).
//     Values are compared exactly: 0.47 in one sample ties 0.47 in another.
//   - All p-values are two-sided, except the two one-sided p-values inside TostResult.
//   - Distributions (normal, Student's t, chi-squared) come from Boost.Math; upper tails are
//     computed as complements, so small p-values keep their relative precision.
//   - Bad input throws secure::Error naming the function, the argument and the value: empty
//     samples, non-finite values, too few values, bound <= 0, fewer than 2 groups, unpaired
//     samples or rows of different lengths, and all-values-tied inputs where a statistic is
//     undefined (see each function).

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/common/enum_strings.h"

namespace secure::stats {

// ---------------------------------------------------------------------------------------------
// Summaries and ranks

struct SampleSummary {
  long n = 0;       // number of values
  double mean = 0;  // arithmetic mean
  double std = 0;   // sample standard deviation (ddof = 1); 0 for n = 1
  double min = 0;   // smallest value
  double max = 0;   // largest value
  nlohmann::json ToJson() const;
};

/// n, mean, std (ddof = 1), min and max of `values` (at least one value, all finite).
SampleSummary Summarize(const std::vector<double>& values);

/// 1-based ranks of `values` with midranks for ties (scipy.stats.rankdata's "average"), e.g.
/// {3, 1, 3, 2} -> {3.5, 1, 3.5, 2}. Values must be finite; an empty input gives an empty result.
std::vector<double> Midranks(const std::vector<double>& values);

// ---------------------------------------------------------------------------------------------
// Mann–Whitney U (Wilcoxon rank-sum) test, two-sided

enum class MannWhitneyMethod {
  kAuto,        // exact if the pooled values hold no ties and both samples have <= 50 values,
                // else asymptotic. (SciPy's own "auto" uses a different size limit: pass the
                // method explicitly to reproduce a SciPy call exactly.)
  kExact,       // the exact null distribution of U; requires that no two pooled values tie
  kAsymptotic,  // normal approximation, tie-corrected variance, continuity correction 0.5
};
inline constexpr EnumTable<MannWhitneyMethod, 3> kMannWhitneyMethodNames{{
    {MannWhitneyMethod::kAuto, "auto"},
    {MannWhitneyMethod::kExact, "exact"},
    {MannWhitneyMethod::kAsymptotic, "asymptotic"},
}};

/// The samples at which kAuto still uses the exact distribution (both samples at most this big).
inline constexpr long kMannWhitneyExactMaxSize = 50;

/// What the two rank tests (Mann–Whitney U, Wilcoxon signed-rank) report alike; each result
/// adds its statistic and says what its z and rank_biserial measure.
struct RankTestResult {
  double p_value = 1;  // two-sided
  std::string method;  // the method used: "exact" or "asymptotic" (never "auto")
  // Asymptotic only: the standard score of the statistic. NaN for the exact method (null in
  // JSON).
  double z = 0;
  // Effect size in [-1, 1]: 0 for no tendency.
  double rank_biserial = 0;

 protected:
  /// `fields` (the test's own) with p_value, method, z and rank_biserial added.
  nlohmann::json WithRankTestFields(nlohmann::json fields) const;
};

/// z: the continuity-corrected standard score of U, signed as U - n_a n_b / 2 (positive when a
/// tends to be larger). rank_biserial: 2U / (n_a n_b) - 1, +1 if every value of a exceeds every
/// value of b, -1 if every value of b exceeds every value of a.
struct MannWhitneyResult : RankTestResult {
  // U of the first sample (SciPy's convention): the number of pairs (x in a, y in b) with x > y,
  // plus half the number of tied pairs. U(a, b) + U(b, a) = n_a n_b.
  double u = 0;
  nlohmann::json ToJson() const;
};

/// Two-sided Mann–Whitney U test of whether the values of `a` tend to be larger or smaller than
/// those of `b`. Both samples need at least one value, all finite.
///   exact:      p = min(1, 2 min(P(U <= u), P(U >= u))) under the exact null distribution of U
///               (computed by dynamic programming over sample sizes; cost O((n_a n_b)^2 / 4)).
///   asymptotic: z = sign(d) max(|d| - 0.5, 0) / sigma with d = u - n_a n_b / 2 and the tie-
///               corrected sigma^2 = n_a n_b / 12 ((N + 1) - sum(t^3 - t) / (N (N - 1))); p = 2
///               P(Z >= |z|), which equals SciPy's asymptotic p-value.
/// If every pooled value is the same, nothing can be ranked: the result is SciPy's, U =
/// n_a n_b / 2, p = 1 (asymptotic, z = 0). kExact with tied values throws.
MannWhitneyResult MannWhitneyU(const std::vector<double>& a, const std::vector<double>& b,
                               MannWhitneyMethod method = MannWhitneyMethod::kAuto);

// ---------------------------------------------------------------------------------------------
// TOST equivalence tests: Welch's t (independent samples) and paired t

struct TostResult {
  double difference = 0;  // mean(a) - mean(b)
  double bound = 0;       // equivalence margin: H1 is -bound < difference < bound
  double se = 0;          // standard error of the difference: sqrt(var_a / n_a + var_b / n_b)
                          // (Welch), std(a - b) / sqrt(n) (paired)
  double df = 0;          // Welch–Satterthwaite degrees of freedom, n - 1 if paired (+inf if
                          // se = 0)
  double t_lower = 0;     // (difference + bound) / se, tests H0: difference <= -bound
  double p_lower = 1;     // P(T >= t_lower)
  double t_upper = 0;     // (difference - bound) / se, tests H0: difference >= +bound
  double p_upper = 1;     // P(T <= t_upper)
  double p_value = 1;     // max(p_lower, p_upper): the TOST p-value

  /// True if both one-sided tests reject at level alpha (p_value < alpha), alpha in (0, 1).
  bool equivalent(double alpha = 0.05) const;
  nlohmann::json ToJson() const;  // infinite values are written as null
};

/// Two one-sided Welch t-tests (TOST) for the equivalence of mean(a) and mean(b) within ±bound
/// (in the metric's units, bound > 0). Each sample needs at least 2 values, all finite.
/// If both samples have zero variance the difference is known exactly: se = 0, df = +inf,
/// p_lower = 0 if difference > -bound else 1, p_upper = 0 if difference < bound else 1, and the
/// t statistics are +inf or -inf accordingly (so p_value = 0 iff |difference| < bound).
/// If only one sample has zero variance, Welch's formulas hold as they are.
TostResult TostWelch(const std::vector<double>& a, const std::vector<double>& b, double bound);

/// Paired TOST: two one-sided t-tests on the differences d_i = a_i - b_i of paired values (the
/// same seeds and episodes under two settings), df = n - 1, se = std(d) / sqrt(n). Both samples
/// need the same number of values, at least 2, all finite. If every difference is the same, it is
/// exact: the zero-variance rule of TostWelch applies.
TostResult TostPaired(const std::vector<double>& a, const std::vector<double>& b, double bound);

// ---------------------------------------------------------------------------------------------
// Kruskal–Wallis H test and Dunn's post-hoc test

struct KruskalWallisResult {
  double h = 0;        // H statistic, tie-corrected (divided by 1 - sum(t^3 - t) / (N^3 - N))
  int df = 0;          // number of groups - 1
  double p_value = 1;  // P(chi^2_df >= h)
  nlohmann::json ToJson() const;
};

/// Kruskal–Wallis H test of whether the groups (numbered from 0) come from the same distribution.
/// At least 2 groups, each with at least one value, all finite. Like SciPy, throws if every value
/// is the same (H is 0 / 0 then).
KruskalWallisResult KruskalWallis(const std::vector<std::vector<double>>& groups);

/// How Dunn's p-values are adjusted for the number of pairs m.
enum class PAdjust {
  kBonferroni,  // min(1, p m)
  kHolm,  // step-down Holm–Bonferroni: sort p ascending, p_(k) (m - k + 1), running maximum,
          // capped at 1 (k 1-based); never larger than Bonferroni
  kNone,  // p unchanged
};
inline constexpr EnumTable<PAdjust, 3> kPAdjustNames{{
    {PAdjust::kBonferroni, "bonferroni"},
    {PAdjust::kHolm, "holm"},
    {PAdjust::kNone, "none"},
}};

/// The p-values of m simultaneous tests adjusted for multiplicity, in the input order (Dunn and
/// PairwiseWilcoxon use this). Each p-value must be in [0, 1]; an empty input gives an empty
/// result. Holm's ties keep their input order (a stable sort), which does not change the result.
std::vector<double> AdjustPValues(const std::vector<double>& p_values, PAdjust adjust);

struct DunnPair {
  int i = 0;              // first group (i < j)
  int j = 0;              // second group
  double z = 0;           // (mean rank of i - mean rank of j) / se
  double p_value = 1;     // two-sided, unadjusted
  double p_adjusted = 1;  // after DunnResult::adjustment
  nlohmann::json ToJson() const;
};

struct DunnResult {
  std::vector<DunnPair> pairs;            // every pair i < j, ordered (0,1), (0,2), ..., (1,2), ...
  std::string adjustment = "bonferroni";  // name of the PAdjust used
  nlohmann::json ToJson() const;
};

/// Dunn's test for every pair of groups, on the ranks of the pooled values, tie-corrected:
/// se = sqrt((N (N + 1) / 12 - sum(t^3 - t) / (12 (N - 1))) (1 / n_i + 1 / n_j)). Same input
/// rules as KruskalWallis, including the error when every value is the same (se = 0).
DunnResult Dunn(const std::vector<std::vector<double>>& groups,
                PAdjust adjust = PAdjust::kBonferroni);

// ---------------------------------------------------------------------------------------------
// Within-subject designs: Friedman, Wilcoxon signed-rank, pairwise Wilcoxon
//
// The data of a within-subject design is an n x k matrix: one row per block (participant, seed,
// scenario), one column per condition, data[b][c] the measurement of block b under condition c.

struct FriedmanResult {
  // Friedman's chi-square statistic, tie-corrected as scipy.stats.friedmanchisquare: with R_c the
  // sum over blocks of condition c's within-block midrank,
  //   (12 / (n k (k + 1)) sum_c R_c^2 - 3 n (k + 1)) / (1 - sum(t^3 - t) / (n (k^3 - k))),
  // the tie term summed over the groups of t equal values within each block.
  double statistic = 0;
  int df = 0;                      // k - 1
  double p_value = 1;              // P(chi^2_df >= statistic): the asymptotic p-value, as SciPy's
  long n = 0;                      // blocks (rows)
  int k = 0;                       // conditions (columns)
  std::vector<double> mean_ranks;  // per condition: its mean within-block rank, in [1, k]
  // Kendall's coefficient of concordance W = statistic / (n (k - 1)) in [0, 1] (tie-corrected):
  // 0 for no agreement between blocks on the order of the conditions, 1 for complete agreement.
  double kendall_w = 0;
  nlohmann::json ToJson() const;
};

/// Friedman test of whether k related conditions differ, on `data` (n x k, rows = blocks): at
/// least 2 rows and 3 columns, every row the same length, all values finite. Ranks are taken
/// within each row (midranks for ties, values compared exactly). A row whose values are all equal
/// is allowed (it counts in n and in the tie term, as in SciPy); if every row is like that, the
/// statistic is 0 / 0 and Friedman throws (SciPy returns NaN).
FriedmanResult Friedman(const std::vector<std::vector<double>>& data);

enum class WilcoxonMethod {
  kAuto,        // exact if there are no zero differences, no tied |differences| and at most
                // kWilcoxonExactMaxSize of them, else asymptotic (R's wilcox.test rule). SciPy
                // 1.10's "auto" differs only with ties: see WilcoxonSignedRank.
  kExact,       // the exact null distribution of W+; requires no zeros and no ties
  kAsymptotic,  // normal approximation, tie-corrected variance, no continuity correction
};
inline constexpr EnumTable<WilcoxonMethod, 3> kWilcoxonMethodNames{{
    {WilcoxonMethod::kAuto, "auto"},
    {WilcoxonMethod::kExact, "exact"},
    {WilcoxonMethod::kAsymptotic, "asymptotic"},
}};

/// The number of differences up to which kAuto still uses the exact distribution.
inline constexpr long kWilcoxonExactMaxSize = 50;

/// z: (w_plus - n (n + 1) / 4) / sigma, positive when x tends to be larger (SciPy reports
/// -|z|). rank_biserial: the matched-pairs rank-biserial correlation (w_plus - w_minus) /
/// (w_plus + w_minus), +1 if every non-zero difference is positive, -1 if every one is negative;
/// 0 if n = 0.
struct WilcoxonResult : RankTestResult {
  double statistic = 0;  // min(w_plus, w_minus): SciPy's two-sided statistic
  double w_plus = 0;     // sum of the midranks of |d| over the positive differences d = x - y
  double w_minus = 0;    // ... over the negative ones; w_plus + w_minus = n (n + 1) / 2
  long n = 0;            // non-zero differences: the ones ranked
  long zeros = 0;        // zero differences (x = y exactly), dropped before ranking
  nlohmann::json ToJson() const;
};

/// Two-sided Wilcoxon signed-rank test of whether the paired differences d = x - y are symmetric
/// about 0, with SciPy's defaults (zero_method = "wilcox", correction = False). x and y need the
/// same number (>= 1) of values, all finite. Zero differences are dropped; the remaining n are
/// ranked by |d| (midranks, compared exactly: x - y is computed in double, so 0.55 - 0.50 and
/// 0.70 - 0.65 need not tie, exactly as in SciPy).
///   exact:      p = min(1, 2 min(P(W+ <= w_plus), P(W+ >= w_plus))) under the exact null
///               distribution of W+ (each of the 2^n sign patterns equally likely; O(n^3)).
///   asymptotic: sigma^2 = n (n + 1) (2 n + 1) / 24 - sum(t^3 - t) / 48 (tie groups of |d|),
///               z = (w_plus - n (n + 1) / 4) / sigma, p = 2 P(Z >= |z|): scipy.stats.wilcoxon(x,
///               y, method="approx") exactly.
/// kAuto equals scipy.stats.wilcoxon(x, y) (SciPy 1.10: exact iff len(x) <= 50 and no zero
/// differences) whenever the non-zero |d| hold no ties. With ties SciPy 1.10 still uses the
/// exact distribution, which assumes untied ranks 1..n, and truncates a half-integer W+ to an
/// integer; kAuto uses the tie-corrected normal approximation instead (as R's wilcox.test does).
/// If every difference is 0 (x = y), SciPy raises; here the result is statistic 0, p = 1
/// (asymptotic, z = 0, n = 0): the samples show no difference, and a pairwise post-hoc table
/// stays complete. kExact throws on zeros or ties.
WilcoxonResult WilcoxonSignedRank(const std::vector<double>& x, const std::vector<double>& y,
                                  WilcoxonMethod method = WilcoxonMethod::kAuto);

struct WilcoxonPair {
  int i = 0;                 // first condition (column; i < j)
  int j = 0;                 // second condition
  double statistic = 0;      // WilcoxonSignedRank(column i, column j).statistic
  double rank_biserial = 0;  // ... .rank_biserial: positive when condition i tends to be larger
  std::string method;        // ... .method: "exact" or "asymptotic"
  double p_value = 1;        // two-sided, unadjusted
  double p_adjusted = 1;     // after PairwiseWilcoxonResult::adjustment over all pairs
  nlohmann::json ToJson() const;
};

struct PairwiseWilcoxonResult {
  std::vector<WilcoxonPair> pairs;  // every pair i < j, ordered (0,1), (0,2), ..., (1,2), ...
  std::string adjustment = "holm";  // name of the PAdjust used
  nlohmann::json ToJson() const;
};

/// Post-hoc Wilcoxon signed-rank tests between every pair of conditions (columns) of `data`
/// (n x k, rows = blocks: at least 1 row and 2 columns, every row the same length, all values
/// finite), p-values adjusted over the k (k - 1) / 2 pairs by AdjustPValues.
PairwiseWilcoxonResult PairwiseWilcoxon(const std::vector<std::vector<double>>& data,
                                        PAdjust adjust = PAdjust::kHolm,
                                        WilcoxonMethod method = WilcoxonMethod::kAuto);

}  // namespace secure::stats
