// Active label queries (secure/cbf/query.h): every strategy returns k distinct pool states,
// margin the smallest |h|, disagreement the largest spread, diversity no two states closer than
// its radius.
#include "secure/cbf/query.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <numeric>
#include <set>

#include "secure/cbf/barrier_net.h"
#include "secure/common/rng.h"
#include "tests/test_util.h"

namespace secure::cbf {
namespace {

using secure::test::ErrorOf;

// h(s) = f(s) per column.
class FunctionBarrier final : public Barrier {
 public:
  FunctionBarrier(int dim, std::function<float(const Eigen::VectorXf&)> f)
      : dim_(dim), f_(std::move(f)) {}
  int state_dim() const override { return dim_; }
  std::string Describe() const override { return "function"; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    for (long i = 0; i < states.cols(); ++i) h(i) = f_(states.col(i));
  }

 private:
  int dim_;
  std::function<float(const Eigen::VectorXf&)> f_;
};

Eigen::MatrixXf Pool(long n, int dim, std::uint64_t seed) {
  Rng rng(seed);
  Eigen::MatrixXf p(dim, n);
  for (long i = 0; i < n; ++i)
    for (int r = 0; r < dim; ++r) p(r, i) = static_cast<float>(rng.Uniform(-3.0, 3.0));
  return p;
}

void ExpectDistinct(const QueryResult& r, long k, long n) {
  ASSERT_EQ(static_cast<long>(r.indices.size()), k);
  const std::set<long> unique(r.indices.begin(), r.indices.end());
  EXPECT_EQ(static_cast<long>(unique.size()), k);
  for (long i : r.indices) {
    EXPECT_GE(i, 0);
    EXPECT_LT(i, n);
  }
}

TEST(QueryTest, EveryStrategyReturnsKDistinctPoolStates) {
  const Eigen::MatrixXf pool = Pool(2000, 4, 1);
  FunctionBarrier a(4, [](const Eigen::VectorXf& s) { return s(0) - 0.5f * s(1); });
  FunctionBarrier b(4, [](const Eigen::VectorXf& s) { return s(0) + 0.3f * s(2); });
  FunctionBarrier c(4, [](const Eigen::VectorXf& s) { return 1.1f * s(0); });
  for (const auto& [strategy, name] : kQueryStrategyNames) {
    for (long k : {1L, 50L, 2000L}) {
      QueryOptions o;
      o.strategy = strategy;
      o.k = k;
      o.seed = 7;
      std::vector<Barrier*> barriers{&a};
      if (strategy == QueryStrategy::kDisagreement) barriers = {&a, &b, &c};
      SCOPED_TRACE(std::string(name) + " k=" + std::to_string(k));
      const QueryResult r = SelectQueries(barriers, pool, o);
      ExpectDistinct(r, k, pool.cols());
      EXPECT_EQ(r.score.size(), k);
      EXPECT_TRUE(r.h.allFinite());
      // Deterministic: the same call gives the same indices.
      EXPECT_EQ(SelectQueries(barriers, pool, o).indices, r.indices);
    }
  }
}

TEST(QueryTest, MarginPicksTheSmallestAbsoluteH) {
  const Eigen::MatrixXf pool = Pool(5000, 3, 2);
  FunctionBarrier bar(3, [](const Eigen::VectorXf& s) { return s(0) * s(0) - 1.0f + 0.1f * s(2); });
  QueryOptions o;
  o.k = 40;
  const QueryResult r = SelectQueries({&bar}, pool, o);
  Eigen::VectorXf h(pool.cols());
  bar.Evaluate(pool, h);
  std::vector<long> order(static_cast<std::size_t>(pool.cols()));
  std::iota(order.begin(), order.end(), 0L);
  std::stable_sort(order.begin(), order.end(),
                   [&](long x, long y) { return std::abs(h(x)) < std::abs(h(y)); });
  order.resize(40);
  EXPECT_EQ(r.indices, order);  // best first, the same order
  for (long j = 1; j < 40; ++j) EXPECT_LE(std::abs(r.h(j - 1)), std::abs(r.h(j)));
  // shield-relevant is margin on the pool it is given.
  o.strategy = QueryStrategy::kShieldRelevant;
  EXPECT_EQ(SelectQueries({&bar}, pool, o).indices, order);
}

TEST(QueryTest, DisagreementPicksTheLargestSpread) {
  // Barrier b is h_b = s0 + b * s1: the ensemble's spread is |s1| * std(b), largest at large |s1|
  // whatever s0 (which makes h near 0 elsewhere: margin would pick other states).
  const Eigen::MatrixXf pool = Pool(3000, 2, 3);
  std::vector<FunctionBarrier> ensemble;
  for (int b = 0; b < 5; ++b)
    ensemble.emplace_back(2, [b](const Eigen::VectorXf& s) { return s(0) + float(b) * s(1); });
  std::vector<Barrier*> ptrs;
  for (auto& e : ensemble) ptrs.push_back(&e);
  QueryOptions o;
  o.strategy = QueryStrategy::kDisagreement;
  o.k = 25;
  const QueryResult r = SelectQueries(ptrs, pool, o);
  std::vector<long> order(static_cast<std::size_t>(pool.cols()));
  std::iota(order.begin(), order.end(), 0L);
  std::stable_sort(order.begin(), order.end(),
                   [&](long x, long y) { return std::abs(pool(1, x)) > std::abs(pool(1, y)); });
  order.resize(25);
  EXPECT_EQ(std::set<long>(r.indices.begin(), r.indices.end()),
            std::set<long>(order.begin(), order.end()));
  const float std_b = std::sqrt(2.0f);  // population std of {0, 1, 2, 3, 4}
  for (long j = 0; j < 25; ++j)
    EXPECT_NEAR(r.spread(j), std::abs(pool(1, r.indices[static_cast<std::size_t>(j)])) * std_b,
                1e-4f);
  // One barrier is not an ensemble.
  EXPECT_NE(ErrorOf([&] { SelectQueries({ptrs[0]}, pool, o); }).find("at least 2"),
            std::string::npos);
}

double MinPairDistance(const Eigen::MatrixXf& pool, const std::vector<long>& idx) {
  const Eigen::VectorXf scale = PoolScale(pool);
  double best = 1e30;
  for (std::size_t i = 0; i < idx.size(); ++i)
    for (std::size_t j = 0; j < i; ++j)
      best = std::min<double>(
          best, ((pool.col(idx[i]) - pool.col(idx[j])).array() / scale.array()).matrix().norm());
  return best;
}

TEST(QueryTest, DiversityNeverReturnsTwoStatesCloserThanItsRadius) {
  // A pool with clusters of near-copies: without a radius margin takes copies of one state.
  Eigen::MatrixXf pool = Pool(4000, 3, 4);
  pool.leftCols(500).colwise() = pool.col(0);
  pool.leftCols(500) += 1e-3f * Pool(500, 3, 5);
  FunctionBarrier near(3, [&](const Eigen::VectorXf& s) { return (s - pool.col(0)).norm(); });
  for (double radius : {0.2, 0.5, 1.0}) {
    for (const auto& [strategy, name] : kQueryStrategyNames) {
      if (strategy == QueryStrategy::kDisagreement) continue;
      QueryOptions o;
      o.strategy = strategy;
      o.k = 30;
      o.diversity_radius = radius;
      SCOPED_TRACE(std::string(name) + " radius " + std::to_string(radius));
      const QueryResult r = SelectQueries({&near}, pool, o);
      EXPECT_GE(MinPairDistance(pool, r.indices), radius);
      EXPECT_EQ(r.indices.size(), 30u);  // the pool has room for 30 at these radii
      const std::set<long> unique(r.indices.begin(), r.indices.end());
      EXPECT_EQ(unique.size(), r.indices.size());
    }
  }
  // Margin alone piles into the cluster around pool.col(0) (h = distance to it).
  QueryOptions o;
  o.k = 30;
  EXPECT_LT(MinPairDistance(pool, SelectQueries({&near}, pool, o).indices), 0.01);
  // A radius too large for k states gives fewer, all still far apart.
  o.strategy = QueryStrategy::kDiversity;
  o.diversity_radius = 3.0;
  const QueryResult few = SelectQueries({}, pool, o);
  EXPECT_LT(few.indices.size(), 30u);
  EXPECT_GE(few.indices.size(), 2u);
  EXPECT_GE(MinPairDistance(pool, few.indices), 3.0);
}

TEST(QueryTest, KCentreSpreadsOverThePool) {
  // Farthest-first on a pool of 4 tight clusters takes one state from each cluster first.
  Eigen::MatrixXf pool = 0.01f * Pool(400, 2, 6);
  for (long i = 0; i < 400; ++i) pool.col(i) += Eigen::Vector2f(float(i % 4 / 2) * 10, float(i % 2) * 10);
  QueryOptions o;
  o.strategy = QueryStrategy::kDiversity;
  o.k = 4;
  const QueryResult r = SelectQueries({}, pool, o);
  std::set<long> clusters;
  for (long i : r.indices) clusters.insert(i % 4);
  EXPECT_EQ(clusters.size(), 4u);
}

TEST(QueryTest, RandomIsSeeded) {
  const Eigen::MatrixXf pool = Pool(1000, 2, 8);
  QueryOptions o;
  o.strategy = QueryStrategy::kRandom;
  o.k = 20;
  o.seed = 1;
  const auto a = SelectQueries({}, pool, o).indices;
  EXPECT_EQ(SelectQueries({}, pool, o).indices, a);
  o.seed = 2;
  EXPECT_NE(SelectQueries({}, pool, o).indices, a);
}

TEST(QueryTest, BadInputNamesTheProblem) {
  const Eigen::MatrixXf pool = Pool(10, 2, 9);
  FunctionBarrier bar(2, [](const Eigen::VectorXf& s) { return s(0); });
  FunctionBarrier wide(3, [](const Eigen::VectorXf& s) { return s(0); });
  QueryOptions o;
  o.k = 11;
  EXPECT_NE(ErrorOf([&] { SelectQueries({&bar}, pool, o); }).find("k = 11 exceeds the pool's 10"),
            std::string::npos);
  o.k = 0;
  EXPECT_NE(ErrorOf([&] { SelectQueries({&bar}, pool, o); }).find("QueryOptions::k = 0"),
            std::string::npos);
  o.k = 2;
  EXPECT_NE(ErrorOf([&] { SelectQueries({}, pool, o); }).find("margin takes one barrier"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { SelectQueries({&wide}, pool, o); }).find("reads 3 features"),
            std::string::npos);
  o.diversity_radius = -1;
  EXPECT_NE(ErrorOf([&] { SelectQueries({&bar}, pool, o); }).find("diversity_radius = -1"),
            std::string::npos);
}

TEST(QueryTest, BarrierNetEnsembleOnAPool) {
  // Real networks through EvaluatePool (chunked): the chunk size changes no h.
  std::vector<BarrierNet> nets;
  for (int s = 0; s < 3; ++s) {
    BarrierNet net;
    net.mlp = nn::RandomMlpParams(nn::MlpSpec{4, {16, 16}, 1, nn::Activation::kTanh}, 10 + s);
    net.normalizer = nn::Normalizer::Fit(Pool(100, 4, 11));
    net.features = {"a", "b", "c", "d"};
    nets.push_back(net);
  }
  std::vector<std::unique_ptr<Barrier>> evaluators;
  std::vector<Barrier*> ptrs;
  for (const BarrierNet& n : nets) {
    evaluators.push_back(n.MakeEvaluator());
    ptrs.push_back(evaluators.back().get());
  }
  const Eigen::MatrixXf pool = Pool(10000, 4, 12);
  const Eigen::MatrixXf a = EvaluatePool(ptrs, pool, 4096), b = EvaluatePool(ptrs, pool, 333);
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-5f);
  QueryOptions o;
  o.strategy = QueryStrategy::kDisagreement;
  o.k = 100;
  ExpectDistinct(SelectQueries(ptrs, pool, o), 100, 10000);
}

}  // namespace
}  // namespace secure::cbf
