#include "secure/cbf/query.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>
#include <limits>
#include <numeric>

#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"

namespace secure::cbf {

void QueryOptions::Validate() const {
  SECURE_CHECK_FIELD(k >= 1 && k <= kMaxStates, "QueryOptions", "k", k,
                     "in [1, " << kMaxStates << "]");
  SECURE_CHECK_FIELD(std::isfinite(diversity_radius) && diversity_radius >= 0, "QueryOptions",
                     "diversity_radius", diversity_radius, "finite and >= 0");
}

Eigen::MatrixXf EvaluatePool(const std::vector<Barrier*>& barriers,
                             const Eigen::Ref<const Eigen::MatrixXf>& pool, long chunk) {
  SECURE_CHECK(chunk >= 1, "EvaluatePool: chunk = " << chunk << ", must be >= 1");
  const long n = pool.cols();
  Eigen::MatrixXf values(static_cast<long>(barriers.size()), n);
  Eigen::VectorXf h(std::min(chunk, std::max(n, 1L)));
  for (std::size_t b = 0; b < barriers.size(); ++b) {
    SECURE_CHECK(barriers[b] != nullptr, "EvaluatePool: barrier " << b << " is null");
    SECURE_CHECK(barriers[b]->state_dim() == pool.rows(),
                 "query: barrier " << b << " (" << barriers[b]->Describe() << ") reads "
                                   << barriers[b]->state_dim() << " features, the pool has "
                                   << pool.rows());
    for (long begin = 0; begin < n; begin += chunk) {
      const long m = std::min(chunk, n - begin);
      barriers[b]->Evaluate(pool.middleCols(begin, m), h.head(m));
      values.row(static_cast<long>(b)).segment(begin, m) = h.head(m).transpose();
    }
  }
  return values;
}

Eigen::VectorXf PoolScale(const Eigen::Ref<const Eigen::MatrixXf>& pool) {
  const long n = pool.cols();
  Eigen::VectorXf scale = Eigen::VectorXf::Ones(pool.rows());
  if (n < 2) return scale;
  for (long r = 0; r < pool.rows(); ++r) {
    const double mean = pool.row(r).cast<double>().mean();
    const double var = (pool.row(r).cast<double>().array() - mean).square().sum() / double(n);
    if (var > 0 && std::isfinite(var)) scale(r) = static_cast<float>(std::sqrt(var));
  }
  return scale;
}

namespace {

// Indices of the k largest scores, best first (ties: lower index first).
std::vector<long> TopK(const Eigen::VectorXf& score, long k) {
  std::vector<long> order(static_cast<std::size_t>(score.size()));
  std::iota(order.begin(), order.end(), 0L);
  const auto better = [&score](long a, long b) {
    return score(a) > score(b) || (score(a) == score(b) && a < b);
  };
  if (k < score.size()) {
    std::nth_element(order.begin(), order.begin() + k, order.end(), better);
    order.resize(static_cast<std::size_t>(k));
  }
  std::sort(order.begin(), order.end(), better);
  return order;
}

// All indices by score, best first.
std::vector<long> SortedAll(const Eigen::VectorXf& score) { return TopK(score, score.size()); }

// Greedy batch: in the order given, skipping states closer than `radius` to one taken (distances
// between columns of `normalised`).
std::vector<long> RadiusGreedy(const std::vector<long>& order, const Eigen::MatrixXf& normalised,
                               double radius, long k) {
  std::vector<long> chosen;
  const float r2 = static_cast<float>(radius * radius);
  for (long i : order) {
    bool far = true;
    for (long j : chosen)
      if ((normalised.col(i) - normalised.col(j)).squaredNorm() < r2) {
        far = false;
        break;
      }
    if (far) chosen.push_back(i);
    if (static_cast<long>(chosen.size()) == k) break;
  }
  return chosen;
}

// Farthest-first k-centre from `first`; stops early when the farthest remaining state is closer
// than `radius` to the chosen ones. `score` receives each chosen state's distance to the nearest
// earlier one (the first: its distance to the pool mean).
std::vector<long> KCentre(const Eigen::MatrixXf& normalised, long first, double radius, long k,
                          std::vector<float>* score) {
  const long n = normalised.cols();
  std::vector<long> chosen{first};
  const Eigen::VectorXf mean = normalised.rowwise().mean();
  score->push_back((normalised.col(first) - mean).norm());
  Eigen::VectorXf nearest(n);  // squared distance to the nearest chosen state
  for (long i = 0; i < n; ++i) nearest(i) = (normalised.col(i) - normalised.col(first)).squaredNorm();
  nearest(first) = -1;  // chosen
  const float r2 = static_cast<float>(radius * radius);
  while (static_cast<long>(chosen.size()) < k) {
    long best = -1;
    float best_d = -1;
    for (long i = 0; i < n; ++i)
      if (nearest(i) > best_d) {  // strict: ties to the lower index
        best_d = nearest(i);
        best = i;
      }
    if (best < 0 || best_d < 0) break;
    if (radius > 0 && best_d < r2) break;
    chosen.push_back(best);
    score->push_back(std::sqrt(best_d));
    nearest(best) = -1;
    for (long i = 0; i < n; ++i)
      if (nearest(i) >= 0)
        nearest(i) = std::min(nearest(i), (normalised.col(i) - normalised.col(best)).squaredNorm());
  }
  return chosen;
}

}  // namespace

QueryResult SelectQueriesFromValues(const Eigen::Ref<const Eigen::MatrixXf>& h_values,
                                    const Eigen::Ref<const Eigen::MatrixXf>& pool,
                                    const QueryOptions& options) {
  options.Validate();
  const long n = pool.cols();
  const std::string name = ToString(kQueryStrategyNames, options.strategy);
  SECURE_CHECK(n >= 1 && pool.rows() >= 1, "query: the pool is empty");
  SECURE_CHECK(options.k <= n, "query: k = " << options.k << " exceeds the pool's " << n
                                              << " states");
  SECURE_CHECK(pool.allFinite(), "query: the pool holds a NaN or infinite value");
  SECURE_CHECK(h_values.rows() == 0 || h_values.cols() == n,
               "query: " << h_values.cols() << " h values for a pool of " << n);
  const long barriers = h_values.rows();
  switch (options.strategy) {
    case QueryStrategy::kMargin:
    case QueryStrategy::kShieldRelevant:
      SECURE_CHECK(barriers == 1, "query: strategy " << name << " takes one barrier, got "
                                                     << barriers);
      break;
    case QueryStrategy::kDisagreement:
      SECURE_CHECK(barriers >= 2, "query: strategy disagreement takes an ensemble of at least 2 "
                                  "barriers, got "
                                      << barriers);
      break;
    case QueryStrategy::kDiversity:
    case QueryStrategy::kRandom:
      break;
  }
  SECURE_CHECK(h_values.allFinite(), "query: a barrier gave a NaN or infinite h on the pool");

  Eigen::VectorXf mean_h, spread;
  if (barriers > 0) {
    mean_h = h_values.colwise().mean().transpose();
    spread = ((h_values.rowwise() - mean_h.transpose()).array().square().colwise().sum() /
              float(barriers))
                 .sqrt()
                 .matrix()
                 .transpose();
  }
  Eigen::MatrixXf normalised;
  const bool need_normalised =
      options.strategy == QueryStrategy::kDiversity || options.diversity_radius > 0;
  if (need_normalised) {
    const Eigen::VectorXf scale = PoolScale(pool);
    normalised = pool.array().colwise() / scale.array();
  }

  std::vector<long> chosen;
  std::vector<float> chosen_score;
  Eigen::VectorXf score;
  switch (options.strategy) {
    case QueryStrategy::kMargin:
    case QueryStrategy::kShieldRelevant:
      score = -h_values.row(0).transpose().cwiseAbs();
      break;
    case QueryStrategy::kDisagreement:
      score = spread;
      break;
    case QueryStrategy::kRandom: {
      // A seeded random order of the whole pool (partial Fisher-Yates), scored by its rank.
      std::vector<long> order(static_cast<std::size_t>(n));
      std::iota(order.begin(), order.end(), 0L);
      Rng rng(options.seed ^ 0x0a11'ce0f'0000'0000ULL);
      const long draws = options.diversity_radius > 0 ? n : options.k;
      for (long i = 0; i < std::min(draws, n - 1); ++i) {
        const long j = i + static_cast<long>(rng.UniformIndex(static_cast<std::uint64_t>(n - i)));
        std::swap(order[static_cast<std::size_t>(i)], order[static_cast<std::size_t>(j)]);
      }
      score.setZero(n);
      for (long i = 0; i < n; ++i) score(order[static_cast<std::size_t>(i)]) = float(n - i);
      break;
    }
    case QueryStrategy::kDiversity: {
      Rng rng(options.seed ^ 0xd1e5'0000'0000'0000ULL);
      const long first = static_cast<long>(rng.UniformIndex(static_cast<std::uint64_t>(n)));
      chosen = KCentre(normalised, first, options.diversity_radius, options.k, &chosen_score);
      break;
    }
  }
  if (options.strategy != QueryStrategy::kDiversity) {
    chosen = options.diversity_radius > 0
                 ? RadiusGreedy(SortedAll(score), normalised, options.diversity_radius, options.k)
                 : TopK(score, options.k);
    for (long i : chosen) chosen_score.push_back(score(i));
  }

  QueryResult r;
  r.indices = chosen;
  const long m = static_cast<long>(chosen.size());
  r.score.resize(m);
  r.h.resize(m);
  r.spread.resize(m);
  for (long j = 0; j < m; ++j) {
    const long i = chosen[static_cast<std::size_t>(j)];
    r.score(j) = chosen_score[static_cast<std::size_t>(j)];
    r.h(j) = barriers > 0 ? mean_h(i) : std::numeric_limits<float>::quiet_NaN();
    r.spread(j) = barriers > 0 ? spread(i) : 0.0f;
  }
  return r;
}

QueryResult SelectQueries(const std::vector<Barrier*>& barriers,
                          const Eigen::Ref<const Eigen::MatrixXf>& pool,
                          const QueryOptions& options) {
  options.Validate();
  SECURE_CHECK(pool.cols() >= 1 && pool.rows() >= 1, "query: the pool is empty");
  return SelectQueriesFromValues(EvaluatePool(barriers, pool), pool, options);
}

bool HasLabelColumn(const std::string& path) {
  if (data::IsHdf5Path(path)) return false;
  std::ifstream in(path);
  SECURE_CHECK(in.good(), path << ": cannot open the labelled states");
  std::string header, cell;
  std::getline(in, header);
  std::stringstream cells(header);
  while (std::getline(cells, cell, ',')) {
    while (!cell.empty() && (cell.back() == '\r' || cell.back() == ' ')) cell.pop_back();
    if (cell == kLabelColumn) return true;
  }
  return false;
}

LabelledStates ReadLabelledStates(const std::string& path,
                                  const std::vector<std::string>& features) {
  std::vector<std::string> select = features;
  select.push_back(kLabelColumn);
  const data::NumericTable t = data::ReadCsv(path, select);
  const long d = static_cast<long>(features.size());
  std::vector<long> safe, near;
  LabelledStates r;
  for (long i = 0; i < t.values.cols(); ++i) {
    const double label = t.values(d, i);
    if (label == 1)
      safe.push_back(i);
    else if (label == 0)
      near.push_back(i);
    else if (label == -1)
      ++r.skipped;
    else
      SECURE_THROW(path << ":" << t.lines[static_cast<std::size_t>(i)] << ": label = " << label
                        << ", must be 1 (safe), 0 (near-dangerous) or -1 (not labelled)");
  }
  const auto take = [&](const std::vector<long>& cols, data::StateSet* set, const char* what) {
    set->source = path + " (" + what + ")";
    set->features = features;
    set->states.resize(d, static_cast<long>(cols.size()));
    for (std::size_t j = 0; j < cols.size(); ++j)
      set->states.col(static_cast<long>(j)) = t.values.col(cols[j]).head(d).cast<float>();
  };
  take(safe, &r.safe, "label 1");
  take(near, &r.near_dangerous, "label 0");
  return r;
}

}  // namespace secure::cbf
