#include "secure/stats/statistics.h"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <limits>
#include <numeric>
#include <string_view>

#include "secure/common/error.h"

namespace secure::stats {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Checks one sample: at least `min_n` values, all finite. `what` names it in messages, e.g.
// "sample 'a'" or "group 2".
void CheckSample(std::string_view function, std::string_view what,
                 const std::vector<double>& values, std::size_t min_n) {
  SECURE_CHECK(!values.empty(), function << ": " << what << " is empty");
  for (std::size_t k = 0; k < values.size(); ++k)
    SECURE_CHECK(std::isfinite(values[k]), function << ": " << what << " holds a non-finite value ("
                                                    << values[k] << ") at index " << k);
  SECURE_CHECK(values.size() >= min_n, function << ": " << what << " has " << values.size()
                                                << " value" << (values.size() == 1 ? "" : "s")
                                                << ", needs at least " << min_n);
}

// Groups for KruskalWallis / Dunn: at least 2, each non-empty and finite.
void CheckGroups(std::string_view function, const std::vector<std::vector<double>>& groups) {
  SECURE_CHECK(groups.size() >= 2, function << ": " << groups.size() << " group"
                                            << (groups.size() == 1 ? "" : "s")
                                            << " given, needs at least 2");
  for (std::size_t g = 0; g < groups.size(); ++g)
    CheckSample(function, "group " + std::to_string(g), groups[g], 1);
}

// Midranks of `values` and the tie term sum(t^3 - t) over the groups of t equal values.
struct Ranking {
  std::vector<double> ranks;
  double tie_sum = 0;
};

Ranking Rank(const std::vector<double>& values) {
  const std::size_t n = values.size();
  std::vector<std::size_t> order(n);
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t x, std::size_t y) { return values[x] < values[y]; });
  Ranking r;
  r.ranks.resize(n);
  for (std::size_t begin = 0; begin < n;) {
    std::size_t end = begin + 1;  // [begin, end) holds equal values (compared exactly)
    while (end < n && values[order[end]] == values[order[begin]]) ++end;
    const double midrank = 0.5 * static_cast<double>(begin + 1 + end);  // mean of begin+1..end
    for (std::size_t k = begin; k < end; ++k) r.ranks[order[k]] = midrank;
    const double t = static_cast<double>(end - begin);
    r.tie_sum += t * t * t - t;
    begin = end;
  }
  return r;
}

std::vector<double> Pool(const std::vector<std::vector<double>>& groups) {
  std::vector<double> pooled;
  for (const auto& g : groups) pooled.insert(pooled.end(), g.begin(), g.end());
  return pooled;
}

// P(Z >= z) and P(T_df >= t) without cancellation for small tails.
double NormalUpper(double z) {
  return boost::math::cdf(boost::math::complement(boost::math::normal_distribution<double>(), z));
}

// The exact null distribution of U for samples of sizes n1, n2 without ties: counts[u] is the
// number of the C(n1 + n2, n1) orderings with U = u. Uses f(m, n, u) = f(m - 1, n, u - n) +
// f(m, n - 1, u) (the largest value is in the first or the second sample); only additions, so
// every count keeps full relative precision (doubles hold C(100, 50) ~ 1e29 comfortably).
std::vector<double> ExactUCounts(long n1, long n2) {
  // prev[n] = f(m - 1, n, .), cur[n] = f(m, n, .), each of length (m n + 1).
  std::vector<std::vector<double>> prev(n2 + 1), cur(n2 + 1);
  for (long n = 0; n <= n2; ++n) prev[n] = {1.0};  // f(0, n, 0) = 1
  for (long m = 1; m <= n1; ++m) {
    cur[0] = {1.0};  // f(m, 0, 0) = 1
    for (long n = 1; n <= n2; ++n) {
      std::vector<double>& f = cur[n];
      f.assign(static_cast<std::size_t>(m * n + 1), 0.0);
      const std::vector<double>& left = prev[n];  // f(m - 1, n, .), length (m - 1) n + 1
      for (std::size_t u = 0; u < left.size(); ++u) f[u + n] += left[u];
      const std::vector<double>& down = cur[n - 1];  // f(m, n - 1, .), length m (n - 1) + 1
      for (std::size_t u = 0; u < down.size(); ++u) f[u] += down[u];
    }
    std::swap(prev, cur);
  }
  return prev[n2];
}

// Checks an n x k matrix of a within-subject design (rows = blocks, columns = conditions): at
// least `min_rows` rows, every row as long as row 0 and at least `min_cols` long, all finite.
void CheckMatrix(std::string_view function, const std::vector<std::vector<double>>& data,
                 std::size_t min_rows, std::size_t min_cols) {
  SECURE_CHECK(data.size() >= min_rows, function << ": 'data' has " << data.size() << " row"
                                                 << (data.size() == 1 ? "" : "s")
                                                 << ", needs at least " << min_rows
                                                 << " (one row per block, e.g. participant)");
  const std::size_t k = data[0].size();
  SECURE_CHECK(k >= min_cols, function << ": row 0 of 'data' has " << k << " value"
                                       << (k == 1 ? "" : "s") << ", needs at least " << min_cols
                                       << " (one value per condition)");
  for (std::size_t b = 0; b < data.size(); ++b) {
    SECURE_CHECK(data[b].size() == k, function << ": row " << b << " of 'data' has "
                                               << data[b].size() << " values, row 0 has " << k
                                               << " (every row needs one value per condition)");
    for (std::size_t c = 0; c < k; ++c)
      SECURE_CHECK(std::isfinite(data[b][c]), function << ": row " << b
                                                       << " of 'data' holds a non-finite value ("
                                                       << data[b][c] << ") at column " << c);
  }
}

// The exact null distribution of the signed-rank statistic W+ for n untied, non-zero
// differences: pmf[w] = P(W+ = w), w = 0..n (n + 1) / 2, each of the 2^n sign patterns equally
// likely. Built rank by rank (rank r is positive or negative with probability 1/2), as SciPy's
// _get_wilcoxon_distr; every value is a multiple of 2^-n, exact in double for n <= 50.
std::vector<double> SignedRankPmf(long n) {
  std::vector<double> pmf = {1.0};
  for (long r = 1; r <= n; ++r) {
    std::vector<double> next(pmf.size() + static_cast<std::size_t>(r), 0.0);
    for (std::size_t w = 0; w < pmf.size(); ++w) {
      next[w] += 0.5 * pmf[w];                                // rank r negative
      next[w + static_cast<std::size_t>(r)] += 0.5 * pmf[w];  // rank r positive
    }
    pmf = std::move(next);
  }
  return pmf;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

nlohmann::json SampleSummary::ToJson() const {
  return {{"n", n}, {"mean", mean}, {"std", std}, {"min", min}, {"max", max}};
}

SampleSummary Summarize(const std::vector<double>& values) {
  CheckSample("Summarize", "sample 'values'", values, 1);
  SampleSummary s;
  s.n = static_cast<long>(values.size());
  s.mean = std::accumulate(values.begin(), values.end(), 0.0) / static_cast<double>(s.n);
  double ss = 0;  // two-pass: sum of squared deviations from the mean
  for (double v : values) ss += (v - s.mean) * (v - s.mean);
  s.std = s.n > 1 ? std::sqrt(ss / static_cast<double>(s.n - 1)) : 0.0;
  const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
  s.min = *lo;
  s.max = *hi;
  return s;
}

std::vector<double> Midranks(const std::vector<double>& values) {
  for (std::size_t k = 0; k < values.size(); ++k)
    SECURE_CHECK(std::isfinite(values[k]), "Midranks: sample 'values' holds a non-finite value ("
                                               << values[k] << ") at index " << k);
  return Rank(values).ranks;
}

// ---------------------------------------------------------------------------------------------

nlohmann::json RankTestResult::WithRankTestFields(nlohmann::json fields) const {
  fields["p_value"] = p_value;
  fields["method"] = method;
  fields["z"] = std::isfinite(z) ? nlohmann::json(z) : nlohmann::json(nullptr);
  fields["rank_biserial"] = rank_biserial;
  return fields;
}

nlohmann::json MannWhitneyResult::ToJson() const { return WithRankTestFields({{"u", u}}); }

MannWhitneyResult MannWhitneyU(const std::vector<double>& a, const std::vector<double>& b,
                               MannWhitneyMethod method) {
  CheckSample("MannWhitneyU", "sample 'a'", a, 1);
  CheckSample("MannWhitneyU", "sample 'b'", b, 1);
  const long n1 = static_cast<long>(a.size()), n2 = static_cast<long>(b.size());
  const double n = static_cast<double>(n1 + n2);
  const double n1n2 = static_cast<double>(n1) * static_cast<double>(n2);

  std::vector<double> pooled = a;
  pooled.insert(pooled.end(), b.begin(), b.end());
  const Ranking r = Rank(pooled);
  const double rank_sum_a = std::accumulate(r.ranks.begin(), r.ranks.begin() + n1, 0.0);
  // U = R_a - n1 (n1 + 1) / 2: an integer or a half-integer, exact in double.
  MannWhitneyResult result;
  result.u = rank_sum_a - 0.5 * static_cast<double>(n1) * static_cast<double>(n1 + 1);
  result.rank_biserial = 2.0 * result.u / n1n2 - 1.0;

  const bool ties = r.tie_sum > 0;
  SECURE_CHECK(method != MannWhitneyMethod::kExact || !ties,
               "MannWhitneyU: method = exact, but the pooled samples hold tied values; the exact "
               "distribution of U assumes none (use asymptotic or auto)");
  const bool exact = method == MannWhitneyMethod::kExact ||
                     (method == MannWhitneyMethod::kAuto && !ties &&
                      n1 <= kMannWhitneyExactMaxSize && n2 <= kMannWhitneyExactMaxSize);

  if (exact) {
    result.method = "exact";
    result.z = kNaN;
    const std::vector<double> counts = ExactUCounts(n1, n2);
    const long u = std::lround(result.u);  // no ties: U is an integer
    // Both tails summed from their own end, so a tiny tail is not 1 minus nearly 1.
    double total = 0, lower = 0, upper = 0;
    for (long k = 0; k < static_cast<long>(counts.size()); ++k) {
      total += counts[k];
      if (k <= u) lower += counts[k];
      if (k >= u) upper += counts[k];
    }
    result.p_value = std::min(1.0, 2.0 * std::min(lower, upper) / total);
    return result;
  }

  result.method = "asymptotic";
  if (r.tie_sum == n * n * n - n) {  // every value the same: no ordering information at all
    result.z = 0;
    result.p_value = 1;
    return result;
  }
  const double sigma = std::sqrt(n1n2 / 12.0 * ((n + 1.0) - r.tie_sum / (n * (n - 1.0))));
  const double d = result.u - 0.5 * n1n2;
  const double corrected = std::max(std::abs(d) - 0.5, 0.0);  // continuity correction
  result.z = std::copysign(corrected / sigma, d);
  result.p_value = std::min(1.0, 2.0 * NormalUpper(corrected / sigma));
  return result;
}

// ---------------------------------------------------------------------------------------------

bool TostResult::equivalent(double alpha) const {
  SECURE_CHECK(alpha > 0 && alpha < 1,
               "TostResult::equivalent: alpha = " << alpha << ", must be in (0, 1)");
  return p_value < alpha;
}

nlohmann::json TostResult::ToJson() const {
  const auto finite = [](double v) {
    return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr);
  };
  return {{"difference", difference},
          {"bound", bound},
          {"se", se},
          {"df", finite(df)},
          {"t_lower", finite(t_lower)},
          {"p_lower", p_lower},
          {"t_upper", finite(t_upper)},
          {"p_upper", p_upper},
          {"p_value", p_value}};
}

namespace {

// The two one-sided t-tests of a difference with standard error `se` on `df` degrees of freedom.
// se = 0 means the difference is exact (see TostWelch's comment).
TostResult TostOf(double difference, double se, double df, double bound) {
  TostResult r;
  r.difference = difference;
  r.bound = bound;
  r.se = se;
  if (r.se == 0) {
    r.df = kInf;
    const bool above_lower = r.difference > -bound, below_upper = r.difference < bound;
    r.t_lower = above_lower ? kInf : -kInf;
    r.p_lower = above_lower ? 0.0 : 1.0;
    r.t_upper = below_upper ? -kInf : kInf;
    r.p_upper = below_upper ? 0.0 : 1.0;
  } else {
    r.df = df;
    const boost::math::students_t_distribution<double> t(r.df);
    r.t_lower = (r.difference + bound) / r.se;
    r.p_lower = boost::math::cdf(boost::math::complement(t, r.t_lower));
    r.t_upper = (r.difference - bound) / r.se;
    r.p_upper = boost::math::cdf(t, r.t_upper);
  }
  r.p_value = std::max(r.p_lower, r.p_upper);
  return r;
}

}  // namespace

TostResult TostWelch(const std::vector<double>& a, const std::vector<double>& b, double bound) {
  SECURE_CHECK(std::isfinite(bound) && bound > 0,
               "TostWelch: bound = " << bound << ", must be > 0 and finite");
  CheckSample("TostWelch", "sample 'a'", a, 2);
  CheckSample("TostWelch", "sample 'b'", b, 2);
  const SampleSummary sa = Summarize(a), sb = Summarize(b);
  const double va = sa.std * sa.std / static_cast<double>(sa.n);  // squared standard errors
  const double vb = sb.std * sb.std / static_cast<double>(sb.n);
  const double se = std::sqrt(va + vb);
  const double df =
      se == 0
          ? kInf
          : (va + vb) * (va + vb) /
                (va * va / static_cast<double>(sa.n - 1) + vb * vb / static_cast<double>(sb.n - 1));
  return TostOf(sa.mean - sb.mean, se, df, bound);
}

TostResult TostPaired(const std::vector<double>& a, const std::vector<double>& b, double bound) {
  SECURE_CHECK(std::isfinite(bound) && bound > 0,
               "TostPaired: bound = " << bound << ", must be > 0 and finite");
  CheckSample("TostPaired", "sample 'a'", a, 2);
  CheckSample("TostPaired", "sample 'b'", b, 2);
  SECURE_CHECK(a.size() == b.size(), "TostPaired: samples 'a' and 'b' have " << a.size() << " and "
                                                                             << b.size()
                                                                             << " values, must be "
                                                                                "paired");
  std::vector<double> d(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) d[i] = a[i] - b[i];
  const SampleSummary sd = Summarize(d);
  const double n = static_cast<double>(sd.n);
  return TostOf(sd.mean, sd.std / std::sqrt(n), n - 1, bound);
}

// ---------------------------------------------------------------------------------------------

nlohmann::json KruskalWallisResult::ToJson() const {
  return {{"h", h}, {"df", df}, {"p_value", p_value}};
}

KruskalWallisResult KruskalWallis(const std::vector<std::vector<double>>& groups) {
  CheckGroups("KruskalWallis", groups);
  const Ranking r = Rank(Pool(groups));
  const double n = static_cast<double>(r.ranks.size());
  SECURE_CHECK(r.tie_sum < n * n * n - n, "KruskalWallis: all "
                                              << r.ranks.size()
                                              << " values are the same; H is undefined (0 / 0)");
  double sum = 0;  // sum over groups of R_g^2 / n_g
  std::size_t offset = 0;
  for (const auto& g : groups) {
    const double rank_sum =
        std::accumulate(r.ranks.begin() + offset, r.ranks.begin() + offset + g.size(), 0.0);
    sum += rank_sum * rank_sum / static_cast<double>(g.size());
    offset += g.size();
  }
  KruskalWallisResult result;
  result.h = (12.0 / (n * (n + 1.0)) * sum - 3.0 * (n + 1.0)) / (1.0 - r.tie_sum / (n * n * n - n));
  result.h = std::max(result.h, 0.0);  // rounding can leave -1e-15 when all mean ranks agree
  result.df = static_cast<int>(groups.size()) - 1;
  result.p_value = boost::math::cdf(
      boost::math::complement(boost::math::chi_squared_distribution<double>(result.df), result.h));
  return result;
}

std::vector<double> AdjustPValues(const std::vector<double>& p_values, PAdjust adjust) {
  for (std::size_t k = 0; k < p_values.size(); ++k)
    SECURE_CHECK(p_values[k] >= 0 && p_values[k] <= 1,
                 "AdjustPValues: p_values[" << k << "] = " << p_values[k] << ", must be in [0, 1]");
  const double m = static_cast<double>(p_values.size());
  std::vector<double> adjusted(p_values.size());
  switch (adjust) {
    case PAdjust::kNone:
      adjusted = p_values;
      break;
    case PAdjust::kBonferroni:
      for (std::size_t k = 0; k < p_values.size(); ++k)
        adjusted[k] = std::min(1.0, p_values[k] * m);
      break;
    case PAdjust::kHolm: {
      std::vector<std::size_t> order(p_values.size());
      std::iota(order.begin(), order.end(), std::size_t{0});
      std::stable_sort(order.begin(), order.end(),
                       [&](std::size_t x, std::size_t y) { return p_values[x] < p_values[y]; });
      double running = 0;
      for (std::size_t rank = 0; rank < order.size(); ++rank) {
        const double p = p_values[order[rank]];
        running = std::max(running, std::min(1.0, p * (m - static_cast<double>(rank))));
        adjusted[order[rank]] = running;
      }
      break;
    }
  }
  return adjusted;
}

nlohmann::json DunnPair::ToJson() const {
  return {{"i", i}, {"j", j}, {"z", z}, {"p_value", p_value}, {"p_adjusted", p_adjusted}};
}

nlohmann::json DunnResult::ToJson() const {
  nlohmann::json list = nlohmann::json::array();
  for (const DunnPair& p : pairs) list.push_back(p.ToJson());
  return {{"adjustment", adjustment}, {"pairs", list}};
}

DunnResult Dunn(const std::vector<std::vector<double>>& groups, PAdjust adjust) {
  CheckGroups("Dunn", groups);
  const Ranking r = Rank(Pool(groups));
  const double n = static_cast<double>(r.ranks.size());
  SECURE_CHECK(
      r.tie_sum < n * n * n - n,
      "Dunn: all " << r.ranks.size() << " values are the same; z is undefined (standard error 0)");
  std::vector<double> mean_rank;
  std::size_t offset = 0;
  for (const auto& g : groups) {
    mean_rank.push_back(
        std::accumulate(r.ranks.begin() + offset, r.ranks.begin() + offset + g.size(), 0.0) /
        static_cast<double>(g.size()));
    offset += g.size();
  }
  const double variance = n * (n + 1.0) / 12.0 - r.tie_sum / (12.0 * (n - 1.0));

  DunnResult result;
  result.adjustment = ToString(kPAdjustNames, adjust);
  const int k = static_cast<int>(groups.size());
  for (int i = 0; i < k; ++i) {
    for (int j = i + 1; j < k; ++j) {
      DunnPair p;
      p.i = i;
      p.j = j;
      const double se = std::sqrt(variance * (1.0 / static_cast<double>(groups[i].size()) +
                                              1.0 / static_cast<double>(groups[j].size())));
      p.z = (mean_rank[i] - mean_rank[j]) / se;
      p.p_value = std::min(1.0, 2.0 * NormalUpper(std::abs(p.z)));
      result.pairs.push_back(p);
    }
  }

  std::vector<double> p_values;
  for (const DunnPair& p : result.pairs) p_values.push_back(p.p_value);
  const std::vector<double> adjusted = AdjustPValues(p_values, adjust);
  for (std::size_t k = 0; k < adjusted.size(); ++k) result.pairs[k].p_adjusted = adjusted[k];
  return result;
}

// ---------------------------------------------------------------------------------------------

nlohmann::json FriedmanResult::ToJson() const {
  return {{"statistic", statistic},
          {"df", df},
          {"p_value", p_value},
          {"n", n},
          {"k", k},
          {"mean_ranks", mean_ranks},
          {"kendall_w", kendall_w}};
}

FriedmanResult Friedman(const std::vector<std::vector<double>>& data) {
  CheckMatrix("Friedman", data, 2, 3);
  const std::size_t rows = data.size(), cols = data[0].size();
  const double n = static_cast<double>(rows), k = static_cast<double>(cols);
  std::vector<double> rank_sums(cols, 0.0);
  double tie_sum = 0;  // sum over rows of sum(t^3 - t)
  for (const auto& row : data) {
    const Ranking r = Rank(row);
    for (std::size_t c = 0; c < cols; ++c) rank_sums[c] += r.ranks[c];
    tie_sum += r.tie_sum;
  }
  // Integers (or sums of them) in double: the comparison is exact.
  SECURE_CHECK(tie_sum < n * (k * k * k - k), "Friedman: in every one of the "
                                                  << rows << " rows of 'data' all " << cols
                                                  << " values are the same; the statistic is "
                                                     "undefined (0 / 0)");
  double sum_sq = 0;
  for (double r : rank_sums) sum_sq += r * r;
  FriedmanResult result;
  result.n = static_cast<long>(rows);
  result.k = static_cast<int>(cols);
  result.df = result.k - 1;
  const double correction = 1.0 - tie_sum / (n * (k * k * k - k));
  result.statistic = (12.0 / (k * n * (k + 1.0)) * sum_sq - 3.0 * n * (k + 1.0)) / correction;
  result.statistic = std::max(result.statistic, 0.0);  // rounding near "all mean ranks equal"
  result.p_value = boost::math::cdf(boost::math::complement(
      boost::math::chi_squared_distribution<double>(result.df), result.statistic));
  for (double r : rank_sums) result.mean_ranks.push_back(r / n);
  result.kendall_w = std::min(1.0, result.statistic / (n * (k - 1.0)));
  return result;
}

// ---------------------------------------------------------------------------------------------

nlohmann::json WilcoxonResult::ToJson() const {
  return WithRankTestFields({{"statistic", statistic},
                             {"w_plus", w_plus},
                             {"w_minus", w_minus},
                             {"n", n},
                             {"zeros", zeros}});
}

WilcoxonResult WilcoxonSignedRank(const std::vector<double>& x, const std::vector<double>& y,
                                  WilcoxonMethod method) {
  CheckSample("WilcoxonSignedRank", "sample 'x'", x, 1);
  CheckSample("WilcoxonSignedRank", "sample 'y'", y, 1);
  SECURE_CHECK(x.size() == y.size(), "WilcoxonSignedRank: sample 'x' has "
                                         << x.size() << " values, sample 'y' has " << y.size()
                                         << "; the samples must be paired (the same length)");
  WilcoxonResult result;
  std::vector<double> d, magnitude;  // the non-zero differences and their |d|
  for (std::size_t k = 0; k < x.size(); ++k) {
    const double diff = x[k] - y[k];
    if (diff == 0) {
      ++result.zeros;
    } else {
      d.push_back(diff);
      magnitude.push_back(std::abs(diff));
    }
  }
  result.n = static_cast<long>(d.size());
  const Ranking r = Rank(magnitude);
  for (std::size_t k = 0; k < d.size(); ++k)
    (d[k] > 0 ? result.w_plus : result.w_minus) += r.ranks[k];
  result.statistic = std::min(result.w_plus, result.w_minus);

  const bool ties = r.tie_sum > 0;
  SECURE_CHECK(method != WilcoxonMethod::kExact || (result.zeros == 0 && !ties),
               "WilcoxonSignedRank: method = exact, but the differences x - y hold "
                   << result.zeros << " zero" << (result.zeros == 1 ? "" : "s") << " and "
                   << (ties ? "" : "no ") << "tied |x - y|; the exact distribution assumes "
                   << "neither (use asymptotic or auto)");
  const bool exact =
      method == WilcoxonMethod::kExact || (method == WilcoxonMethod::kAuto && result.zeros == 0 &&
                                           !ties && result.n <= kWilcoxonExactMaxSize);
  if (result.n > 0) {
    result.rank_biserial = (result.w_plus - result.w_minus) / (result.w_plus + result.w_minus);
  }

  if (exact) {
    result.method = "exact";
    result.z = kNaN;
    const std::vector<double> pmf = SignedRankPmf(result.n);
    const long w = std::lround(result.w_plus);  // no ties: an integer
    // Both tails summed from their own end, so a tiny tail is not 1 minus nearly 1.
    double lower = 0, upper = 0;
    for (long v = 0; v <= w; ++v) lower += pmf[v];
    for (long v = static_cast<long>(pmf.size()) - 1; v >= w; --v) upper += pmf[v];
    result.p_value = std::min(1.0, 2.0 * std::min(lower, upper));
    return result;
  }

  result.method = "asymptotic";
  if (result.n == 0) {  // x = y: no difference to rank (SciPy raises here)
    result.z = 0;
    result.p_value = 1;
    return result;
  }
  const double n = static_cast<double>(result.n);
  const double sigma = std::sqrt(n * (n + 1.0) * (2.0 * n + 1.0) / 24.0 - r.tie_sum / 48.0);
  result.z = (result.w_plus - n * (n + 1.0) / 4.0) / sigma;
  result.p_value = std::min(1.0, 2.0 * NormalUpper(std::abs(result.z)));
  return result;
}

nlohmann::json WilcoxonPair::ToJson() const {
  return {{"i", i},
          {"j", j},
          {"statistic", statistic},
          {"rank_biserial", rank_biserial},
          {"method", method},
          {"p_value", p_value},
          {"p_adjusted", p_adjusted}};
}

nlohmann::json PairwiseWilcoxonResult::ToJson() const {
  nlohmann::json list = nlohmann::json::array();
  for (const WilcoxonPair& p : pairs) list.push_back(p.ToJson());
  return {{"adjustment", adjustment}, {"pairs", list}};
}

PairwiseWilcoxonResult PairwiseWilcoxon(const std::vector<std::vector<double>>& data,
                                        PAdjust adjust, WilcoxonMethod method) {
  CheckMatrix("PairwiseWilcoxon", data, 1, 2);
  const int k = static_cast<int>(data[0].size());
  std::vector<std::vector<double>> columns(k);
  for (const auto& row : data)
    for (int c = 0; c < k; ++c) columns[c].push_back(row[c]);

  PairwiseWilcoxonResult result;
  result.adjustment = ToString(kPAdjustNames, adjust);
  std::vector<double> p_values;
  for (int i = 0; i < k; ++i) {
    for (int j = i + 1; j < k; ++j) {
      const WilcoxonResult w = WilcoxonSignedRank(columns[i], columns[j], method);
      WilcoxonPair p;
      p.i = i;
      p.j = j;
      p.statistic = w.statistic;
      p.rank_biserial = w.rank_biserial;
      p.method = w.method;
      p.p_value = w.p_value;
      result.pairs.push_back(p);
      p_values.push_back(w.p_value);
    }
  }
  const std::vector<double> adjusted = AdjustPValues(p_values, adjust);
  for (std::size_t m = 0; m < adjusted.size(); ++m) result.pairs[m].p_adjusted = adjusted[m];
  return result;
}

}  // namespace secure::stats
