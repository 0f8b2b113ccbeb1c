// Aggregation::kTopQ: the mean of the safe samples of highest task value Q, re-checked, else the
// one of them nearest that mean (shield.h).
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <string>
#include <vector>

#include "secure/common/rng.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"
#include "tests/test_util.h"

namespace secure::shield {
namespace {

using secure::test::ErrorOf;
using test::FirstRound;
using test::FunctionBarrier;
using test::IntegratorDynamics;
using test::LinearActionValue;
using test::Vec;


// The indices of the `keep` columns of largest `q` among `candidates` (ties by index).
std::vector<int> TopIndices(std::vector<int> candidates, const std::vector<double>& q, int keep) {
  std::stable_sort(candidates.begin(), candidates.end(), [&](int a, int b) { return q[a] > q[b]; });
  candidates.resize(static_cast<std::size_t>(keep));
  std::sort(candidates.begin(), candidates.end());
  return candidates;
}

// 2-D integrator, h = 1 everywhere: every action is safe (g = alpha(1) = 1 > 0). Q = x of the
// next state, so the task prefers large a0.
struct OpenPlane {
  IntegratorDynamics dynamics{2, 0.1};
  FunctionBarrier barrier{2, "1", [](const Eigen::Ref<const Eigen::VectorXf>&) { return 1.0; }};
  LinearActionValue value{Vec({1.0f, 0.0f})};
};

// The top-q shield's decision on the open plane at the origin with mu = 0, sigma = 1, ranked by
// `value`.
Decision DecideAtTheOrigin(OpenPlane& sys, ShieldOptions options, ActionValue* value) {
  options.aggregation = Aggregation::kTopQ;
  Shield shield(options, sys.barrier, sys.dynamics);
  shield.SetActionValue(value);
  const Eigen::VectorXf zero = Vec({0.0f, 0.0f});
  return shield.Decide(zero, zero, Vec({1.0f, 1.0f}));
}

TEST(ShieldTopQTest, AveragesTheSafeSamplesOfHighestQ) {
  OpenPlane sys;
  const Eigen::VectorXf state = Vec({0.0f, 0.0f}), mu = Vec({0.0f, 0.0f}),
                        sigma = Vec({1.0f, 1.0f});
  ShieldOptions options;
  options.seed = 5;
  const Decision d = DecideAtTheOrigin(sys, options, &sys.value);
  ASSERT_EQ(d.status, Status::kSafe) << d.ToJson().dump();
  EXPECT_GE(d.g, 0.0);
  // One Q evaluation of the round's M predicted next states.
  EXPECT_EQ(sys.value.calls, 1);
  EXPECT_EQ(sys.value.columns, options.num_samples);

  const Eigen::MatrixXf samples = FirstRound(options.seed, mu, sigma, options.num_samples);
  std::vector<double> q(options.num_samples);
  for (int i = 0; i < options.num_samples; ++i) q[i] = 0.1 * samples(0, i);  // x' = 0.1 a0
  std::vector<int> all(options.num_samples);
  std::iota(all.begin(), all.end(), 0);
  const int keep = static_cast<int>(std::ceil(0.3 * options.num_samples));  // 20 of 64
  Eigen::Vector2f expected = Eigen::Vector2f::Zero();
  for (int i : TopIndices(all, q, keep)) expected += samples.col(i);
  expected /= static_cast<float>(keep);
  EXPECT_NEAR(d.action[0], expected[0], 1e-5);
  EXPECT_NEAR(d.action[1], expected[1], 1e-5);

  // The mean of all safe samples sits near mu; the top 30 % of N(0, 1) average about 1.16.
  ShieldOptions mean_options = options;
  mean_options.aggregation = Aggregation::kMean;
  Shield mean_shield(mean_options, sys.barrier, sys.dynamics);
  const Decision m = mean_shield.Decide(state, mu, sigma);
  EXPECT_GT(d.action[0], m.action[0] + 0.6)
      << d.action.transpose() << " vs " << m.action.transpose();
}

// 1-D half line: safe iff a <= 1 (x' = x + 0.1 a, h = 1 - x, k = 1, at x = 0). The task wants
// large a, beyond the barrier: top-q moves toward the boundary and stays safe.
TEST(ShieldTopQTest, PrefersTheHigherQSideAndStaysSafeWhereTheBarrierCutsIt) {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "1 - x",
                          [](const Eigen::Ref<const Eigen::VectorXf>& s) { return 1.0 - s[0]; }};
  LinearActionValue value{Vec({1.0f})};
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.5f}), sigma = Vec({1.0f});
  int higher = 0;
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    ShieldOptions options;
    options.seed = seed;
    options.aggregation = Aggregation::kTopQ;
    Shield shield(options, barrier, dynamics);
    shield.SetActionValue(&value);
    const Decision d = shield.Decide(state, mu, sigma);
    ASSERT_TRUE(d.safe()) << d.ToJson().dump();
    EXPECT_GE(d.g, 0.0);
    EXPECT_LE(d.action[0], 1.0f + 1e-6f);  // g >= 0 exactly where a <= 1
    options.aggregation = Aggregation::kMean;
    Shield mean_shield(options, barrier, dynamics);
    const Decision m = mean_shield.Decide(state, mu, sigma);
    if (d.action[0] > m.action[0] + 0.3f) ++higher;
  }
  EXPECT_EQ(higher, 20);
}

// Two safe intervals |a| >= 1 (TwoIntervals of shield_test.cc) and a constant Q: the top set is
// the first ceil(0.3 #safe) safe samples in index order; their mean is re-checked and, where it
// falls between the intervals, replaced by the one of them nearest to it.
TEST(ShieldTopQTest, AnUnsafeMeanFallsBackToTheNearestSampleOfTheTopSet) {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "x^2 - 1", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            return static_cast<double>(s[0]) * s[0] - 1.0;
                          }};
  LinearActionValue value{Vec({0.0f})};
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.0f}), sigma = Vec({2.0f});
  int fallbacks = 0;
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    ShieldOptions options;
    options.seed = seed;
    options.class_k_gain = 0.1;
    options.aggregation = Aggregation::kTopQ;
    Shield shield(options, barrier, dynamics);
    shield.SetActionValue(&value);
    const Decision d = shield.Decide(state, mu, sigma);
    ASSERT_EQ(d.iterations, 1) << d.ToJson().dump();
    ASSERT_TRUE(d.safe());
    EXPECT_GE(std::abs(d.action[0]), 1.0f - 1e-6f);
    const Eigen::MatrixXf samples = FirstRound(seed, mu, sigma, options.num_samples);
    std::vector<int> safe;
    for (int i = 0; i < options.num_samples; ++i)
      if (std::abs(samples(0, i)) >= 1.0f) safe.push_back(i);
    const int keep = static_cast<int>(std::ceil(0.3 * static_cast<double>(safe.size())));
    safe.resize(static_cast<std::size_t>(keep));  // constant Q: ties by index
    float mean = 0.0f;
    for (int i : safe) mean += samples(0, i);
    mean /= static_cast<float>(keep);
    if (std::abs(mean) >= 1.0f) {
      EXPECT_NEAR(d.action[0], mean, 1e-5);
    } else {
      ++fallbacks;
      int nearest = safe.front();
      for (int i : safe)
        if (std::abs(samples(0, i) - mean) < std::abs(samples(0, nearest) - mean)) nearest = i;
      // FirstRound re-derives the draws in this file's own code (its float arithmetic may be
      // contracted differently from the shield's): equal to within float rounding.
      EXPECT_NEAR(d.action[0], samples(0, nearest), 1e-6f);
    }
  }
  EXPECT_GT(fallbacks, 0);
}

TEST(ShieldTopQTest, FractionOneIsAlgorithmOnesMean) {
  OpenPlane sys;
  const Eigen::VectorXf state = Vec({0.2f, -0.1f}), mu = Vec({0.3f, 0.1f}),
                        sigma = Vec({0.7f, 1.2f});
  for (std::uint64_t seed = 0; seed < 5; ++seed) {
    ShieldOptions options;
    options.seed = seed;
    options.aggregation = Aggregation::kTopQ;
    options.top_q_fraction = 1.0;
    Shield top(options, sys.barrier, sys.dynamics);
    top.SetActionValue(&sys.value);
    options.aggregation = Aggregation::kMean;
    Shield mean(options, sys.barrier, sys.dynamics);
    const Decision a = top.Decide(state, mu, sigma), b = mean.Decide(state, mu, sigma);
    // The same code sums the same samples in the same order.
    EXPECT_EQ(a.action, b.action) << "seed " << seed;
    EXPECT_EQ(a.g, b.g);
  }
}

// A NaN Q ranks below every number: here every sample with a0 > 0 has Q = NaN, so the top set
// (the largest Q) is the samples just below 0.
TEST(ShieldTopQTest, ANanQRanksLast) {
  class NanAbove final : public ActionValue {
   public:
    void Evaluate(const Eigen::Ref<const Eigen::VectorXf>&,
                  const Eigen::Ref<const Eigen::MatrixXf>& next,
                  Eigen::Ref<Eigen::VectorXd> q) override {
      for (Eigen::Index i = 0; i < next.cols(); ++i)
        q[i] = next(0, i) > 0 ? std::numeric_limits<double>::quiet_NaN() : next(0, i);
    }
    std::string Describe() const override { return "NaN above 0"; }
  } value;
  OpenPlane sys;
  ShieldOptions options;
  options.top_q_fraction = 0.2;
  const Decision d = DecideAtTheOrigin(sys, options, &value);
  ASSERT_TRUE(d.safe());
  EXPECT_LE(d.action[0], 0.0f);
  EXPECT_GT(d.action[0], -0.6f);
}

TEST(ShieldTopQTest, NeedsATaskValueAndAValidFraction) {
  OpenPlane sys;
  ShieldOptions options;
  options.aggregation = Aggregation::kTopQ;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf v = Vec({0.0f, 0.0f}), sigma = Vec({1.0f, 1.0f});
  EXPECT_HAS(ErrorOf([&] { shield.Decide(v, v, sigma); }),
             "aggregation = top-q needs a task value (Shield::SetActionValue)");
  shield.SetActionValue(&sys.value);
  EXPECT_TRUE(shield.Decide(v, v, sigma).safe());

  for (double bad : {0.0, -0.1, 1.5, std::nan("")}) {
    ShieldOptions o;
    o.top_q_fraction = bad;
    EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "ShieldOptions::top_q_fraction = ");
    EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "must be in (0, 1]");
  }
}

TEST(ShieldTopQTest, OptionsJsonAndYaml) {
  ShieldOptions options;
  EXPECT_FALSE(options.ToJson().contains("top_q_fraction"));  // other shields keep their identity
  options.ApplyYaml(YAML::Load("{aggregation: top-q, top_q_fraction: 0.5}"), "test.yaml");
  EXPECT_EQ(options.aggregation, Aggregation::kTopQ);
  EXPECT_EQ(options.top_q_fraction, 0.5);
  EXPECT_EQ(options.ToJson()["aggregation"], "top-q");
  EXPECT_EQ(options.ToJson()["top_q_fraction"], 0.5);
  EXPECT_HAS(ErrorOf([&] { options.ApplyYaml(YAML::Load("{top_q_fraction: many}"), "test.yaml"); }),
             "top_q_fraction");
}

}  // namespace
}  // namespace secure::shield
