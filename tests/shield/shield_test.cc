#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <iterator>
#include <limits>
#include <ostream>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "domains/double_integrator/double_integrator.h"
#include "secure/nn/mlp.h"
#include "tests/test_util.h"

namespace secure::shield {

// Readable enum values in failure messages (internal linkage: other test files may add theirs).
static void PrintTo(Status status, std::ostream* os) { *os << ToString(kStatusNames, status); }
static void PrintTo(Fallback fallback, std::ostream* os) {
  *os << ToString(kFallbackNames, fallback);
}

namespace {

using secure::test::ErrorOf;
namespace di = domains::double_integrator;

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

// ------------------------------------------------------------------------------------------------
// Hand-made systems with analytically known safe sets (IntegratorDynamics, FunctionBarrier:
// tests/shield/shield_test_util.h).

using test::BitEqual;
using test::FunctionBarrier;
using test::IndependentG;
using test::IntegratorDynamics;
using test::Vec;

/// Replicates the shield's sampling: `rounds` consecutive rounds of M actions drawn column by
/// column from N(mu, sigma) with the shield's generator (valid while no probe is drawn between
/// the rounds, i.e. for round 1 or for resampling == kNone). `rng` is left after the draws.
Eigen::MatrixXf DrawRounds(Rng& rng, const Eigen::VectorXf& mu, const Eigen::VectorXf& sigma, int m,
                           int rounds = 1) {
  Eigen::MatrixXf samples(mu.size(), static_cast<Eigen::Index>(m) * rounds);
  for (Eigen::Index c = 0; c < samples.cols(); ++c)
    for (Eigen::Index r = 0; r < mu.size(); ++r)
      samples(r, c) = mu[r] + sigma[r] * static_cast<float>(rng.Normal());
  return samples;
}


/// Index of a column of `samples` equal (bit for bit) to `action`, or -1.
int ColumnIndex(const Eigen::MatrixXf& samples, const Eigen::VectorXf& action) {
  for (Eigen::Index c = 0; c < samples.cols(); ++c)
    if (BitEqual(samples.col(c), action)) return static_cast<int>(c);
  return -1;
}

void ExpectSameDecision(const Decision& a, const Decision& b) {
  EXPECT_EQ(a.status, b.status);
  EXPECT_TRUE(BitEqual(a.action, b.action))
      << a.action.transpose() << " vs " << b.action.transpose();
  EXPECT_EQ(std::memcmp(&a.g, &b.g, sizeof(double)), 0) << a.g << " vs " << b.g;
  EXPECT_EQ(a.h, b.h);
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.safe_ratio, b.safe_ratio);
  EXPECT_EQ(a.intervened, b.intervened);
  EXPECT_EQ(a.distance_to_mean, b.distance_to_mean);
  EXPECT_EQ(a.fallback, b.fallback);
}

/// 1-D: x' = x + 0.1 a, h(x) = 1 - x; with dt = 0.1 and alpha = k h,
/// g(a) = -a + k (1 - x), so the safe actions are exactly a <= k (1 - x).
struct HalfLine {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "1 - x",
                          [](const Eigen::Ref<const Eigen::VectorXf>& s) { return 1.0 - s[0]; }};
};

/// HalfLine with a count of the barrier's evaluations (not copyable: the barrier refers to it).
struct CountedHalfLine {
  CountedHalfLine() = default;
  CountedHalfLine(const CountedHalfLine&) = delete;
  CountedHalfLine& operator=(const CountedHalfLine&) = delete;
  long evaluated = 0;
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "1 - x, counted", [this](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            ++evaluated;
                            return 1.0 - s[0];
                          }};
};

/// 1-D: x' = x + 0.1 a, h(x) = x^2 - 1 at x = 0, dt = 0.1, alpha = 0.1 h:
/// g(a) = 0.1 (a^2 - 1), safe iff |a| >= 1 (two disjoint intervals).
struct TwoIntervals {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "x^2 - 1", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            return static_cast<double>(s[0]) * s[0] - 1.0;
                          }};
};

/// 1-D: h(x) = -1 - x^2 everywhere negative; at x = 0 with dt = 0.1, alpha = k h:
/// g(a) = -0.1 a^2 - k < 0 for every a, largest (-k) at a = 0.
struct NowhereSafe {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "-1 - x^2", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            return -1.0 - static_cast<double>(s[0]) * s[0];
                          }};
};

struct DoubleIntegrator {
  di::Dynamics dynamics{0.1};
  domains::double_integrator::GroundTruthBarrier barrier{di::GroundTruth{}};
  domains::double_integrator::GroundTruthBarrier independent{di::GroundTruth{}};  // for re-evaluation
};

// ------------------------------------------------------------------------------------------------
// g computation.

TEST(ShieldTest, EvaluateGMatchesFormulaWithLinearClassK) {
  HalfLine sys;
  ShieldOptions options;
  options.class_k_gain = 2.0;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({0.3f});
  const double h = shield.EvaluateH(state);
  EXPECT_NEAR(h, 0.7, 1e-6);
  Eigen::MatrixXf actions(1, 5);
  actions << -3.0f, 0.0f, 1.4f, 2.0f, 5.0f;
  Eigen::VectorXd g(5);
  shield.EvaluateG(state, h, actions, g);
  for (int i = 0; i < 5; ++i) {
    // (h(x + 0.1 a) - h(x)) / 0.1 + 2 h(x) = -a + 1.4
    EXPECT_NEAR(g[i], -actions(0, i) + 1.4, 1e-5) << "a = " << actions(0, i);
  }
  EXPECT_DOUBLE_EQ(ClassKValue(options, 0.7), 1.4);
  EXPECT_DOUBLE_EQ(ClassKValue(options, -0.5), -1.0);
}

TEST(ShieldTest, EvaluateGMatchesFormulaWithCubicClassK) {
  HalfLine sys;
  ShieldOptions options;
  options.class_k = ClassK::kCubic;
  options.class_k_gain = 3.0;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({0.3f});
  const double h = shield.EvaluateH(state);
  Eigen::MatrixXf actions(1, 4);
  actions << -2.0f, 0.0f, 1.029f, 4.0f;
  Eigen::VectorXd g(4);
  shield.EvaluateG(state, h, actions, g);
  for (int i = 0; i < 4; ++i) {
    // -a + 3 * 0.7^3 = -a + 1.029
    EXPECT_NEAR(g[i], -actions(0, i) + 3.0 * 0.7 * 0.7 * 0.7, 1e-5) << "a = " << actions(0, i);
  }
  EXPECT_DOUBLE_EQ(ClassKValue(options, 0.5), 3.0 * 0.125);
  EXPECT_DOUBLE_EQ(ClassKValue(options, -2.0), -24.0);  // odd: alpha(-h) = -alpha(h)
  EXPECT_DOUBLE_EQ(ClassKValue(options, 0.0), 0.0);
}

TEST(ShieldTest, EvaluateGMatchesGroundTruthFormulaInDouble) {
  DoubleIntegrator sys;
  ShieldOptions options;
  options.class_k_gain = 1.5;
  Shield shield(options, sys.barrier, sys.dynamics);
  const di::GroundTruth truth;
  const double s[4] = {3.0, 2.0, 0.5, -0.3};
  const Eigen::VectorXf state = Vec({3.0f, 2.0f, 0.5f, -0.3f});
  const double h = shield.EvaluateH(state);
  EXPECT_NEAR(h, truth.H(s[0], s[1], s[2], s[3]), 1e-5);
  Eigen::MatrixXf actions(2, 4);
  actions << 0.0f, 1.0f, -2.5f, 4.0f,  //
      0.0f, -1.0f, 3.0f, 4.0f;
  Eigen::VectorXd g(4);
  shield.EvaluateG(state, h, actions, g);
  const double dt = 0.1;
  for (int i = 0; i < 4; ++i) {
    const double ax = actions(0, i), ay = actions(1, i);
    const double x = s[0] + s[2] * dt + 0.5 * ax * dt * dt,
                 y = s[1] + s[3] * dt + 0.5 * ay * dt * dt;
    const double vx = s[2] + ax * dt, vy = s[3] + ay * dt;
    const double h_s = truth.H(s[0], s[1], s[2], s[3]);
    const double expected = (truth.H(x, y, vx, vy) - h_s) / dt + 1.5 * h_s;
    EXPECT_NEAR(g[i], expected, 1e-3) << "column " << i;
  }
}

TEST(ShieldTest, EvaluateGRejectsBadSizes) {
  HalfLine sys;
  ShieldOptions options;
  options.num_samples = 4;
  options.num_probes = 6;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({0.0f});
  Eigen::MatrixXf seven = Eigen::MatrixXf::Zero(1, 7);
  Eigen::VectorXd g7(7), g2(2);
  EXPECT_HAS(ErrorOf([&] { shield.EvaluateG(state, 1.0, seven, g7); }), "7 actions exceed the 6");
  Eigen::MatrixXf three = Eigen::MatrixXf::Zero(1, 3);
  EXPECT_HAS(ErrorOf([&] { shield.EvaluateG(state, 1.0, three, g2); }),
             "g has 2 entries for 3 actions");
  Eigen::MatrixXf six = Eigen::MatrixXf::Zero(1, 6);  // max(M, N) columns are allowed
  Eigen::VectorXd g6(6);
  shield.EvaluateG(state, 1.0, six, g6);
  EXPECT_NEAR(g6[0], 1.0, 1e-9);  // a = 0: g = alpha(h(s)) with h(s) = 1 given
}

// ------------------------------------------------------------------------------------------------
// Algorithm 1 on the double integrator.

TEST(ShieldTest, FarFromObstacleReturnsMeanOfSafeSamplesWithoutResampling) {
  DoubleIntegrator sys;
  ShieldOptions options;
  options.seed = 7;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({1.0f, 1.0f, 0.0f, 0.0f});
  const Eigen::VectorXf mu = Vec({0.3f, -0.2f}), sigma = Vec({0.5f, 0.5f});
  const Decision d = shield.Decide(state, mu, sigma);

  EXPECT_EQ(d.status, Status::kSafe);
  EXPECT_TRUE(d.safe());
  EXPECT_EQ(d.iterations, 1);
  EXPECT_EQ(d.fallback, Fallback::kNone);
  EXPECT_NEAR(d.h, 28.0, 1e-5);
  EXPECT_GE(d.g, 0.0);
  EXPECT_NEAR(IndependentG(sys.independent, sys.dynamics, options, state, d.action), d.g, 1e-9);
  EXPECT_NEAR(d.distance_to_mean, (d.action - mu).norm(), 1e-6);

  // The same draws outside the shield: all safe here, and the action is their mean.
  Rng rng(options.seed);
  const Eigen::MatrixXf samples = DrawRounds(rng, mu, sigma, options.num_samples);
  Eigen::VectorXf sum = Eigen::VectorXf::Zero(2);
  int num_safe = 0;
  for (int i = 0; i < options.num_samples; ++i) {
    if (IndependentG(sys.independent, sys.dynamics, options, state, samples.col(i)) >= 0) {
      sum += samples.col(i);
      ++num_safe;
    }
  }
  EXPECT_EQ(num_safe, options.num_samples);
  EXPECT_DOUBLE_EQ(d.safe_ratio, 1.0);
  EXPECT_FALSE(d.intervened);  // the first draw is safe
  const Eigen::VectorXf mean = sum / static_cast<float>(num_safe);
  EXPECT_LT((d.action - mean).cwiseAbs().maxCoeff(), 1e-5f)
      << "action " << d.action.transpose() << ", mean of safe samples " << mean.transpose();
  EXPECT_EQ(ColumnIndex(samples, d.action), -1);  // not a single sample
}

TEST(ShieldTest, PolicyDrivingIntoObstacleIsResampledToASafeAction) {
  DoubleIntegrator sys;
  ShieldOptions options;
  options.seed = 3;
  options.max_iterations = 50;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({5.0f, 7.6f, 0.0f, -1.5f});
  const Eigen::VectorXf mu = Vec({0.0f, -5.0f}), sigma = Vec({0.05f, 0.05f});
  const Decision d = shield.Decide(state, mu, sigma);

  EXPECT_EQ(d.status, Status::kSafeAfterResampling) << d.ToJson().dump();
  EXPECT_GT(d.iterations, 1);
  EXPECT_TRUE(d.intervened);
  EXPECT_EQ(d.fallback, Fallback::kNone);
  EXPECT_GT(d.safe_ratio, options.safe_ratio);
  EXPECT_GE(d.g, 0.0);
  EXPECT_TRUE(d.action.allFinite());
  // A fresh shield (and the bare formula) agree that the action is safe.
  Shield fresh(options, sys.independent, sys.dynamics);
  Eigen::MatrixXf column = d.action;
  Eigen::VectorXd g(1);
  fresh.EvaluateG(state, fresh.EvaluateH(state), column, g);
  EXPECT_GE(g[0], 0.0);
  EXPECT_NEAR(g[0], d.g, 1e-9 * std::max(1.0, std::abs(d.g)));
  EXPECT_GE(IndependentG(sys.independent, sys.dynamics, options, state, d.action), 0.0);
  // The policy's mean itself is unsafe; the shield moved away from it (braking: ay > mu_y).
  EXPECT_LT(IndependentG(sys.independent, sys.dynamics, options, state, mu), 0.0);
  EXPECT_GT(d.action[1], mu[1]);
  EXPECT_NEAR(d.distance_to_mean, (d.action - mu).norm(), 1e-6);
}

TEST(ShieldTest, AdaptiveResamplingFindsSafeActionsThatPlainResamplingMisses) {
  // x = 0.9, k = 1: safe iff a <= 0.1. The policy insists on a = 5 with sigma = 0.05 (98 sigma
  // away), so only widening sigma can find a safe action.
  for (std::uint64_t seed = 0; seed < 5; ++seed) {
    HalfLine sys;
    ShieldOptions options;
    options.seed = seed;
    options.max_iterations = 20;
    const Eigen::VectorXf state = Vec({0.9f}), mu = Vec({5.0f}), sigma = Vec({0.05f});

    Shield adaptive(options, sys.barrier, sys.dynamics);
    const Decision a = adaptive.Decide(state, mu, sigma);
    EXPECT_EQ(a.status, Status::kSafeAfterResampling) << "seed " << seed;
    EXPECT_GT(a.iterations, 1);
    EXPECT_LE(a.action[0], 0.1f + 1e-6f);
    EXPECT_GE(a.g, 0.0);
    EXPECT_NEAR(a.g, -a.action[0] + 0.1, 1e-5);

    options.resampling = Resampling::kNone;
    Shield plain(options, sys.barrier, sys.dynamics);
    const Decision p = plain.Decide(state, mu, sigma);
    EXPECT_EQ(p.status, Status::kNoSafeAction) << "seed " << seed;
    EXPECT_EQ(p.iterations, options.max_iterations);
    EXPECT_EQ(p.fallback, Fallback::kRandomSample);
    EXPECT_LT(p.g, 0.0);
    EXPECT_DOUBLE_EQ(p.safe_ratio, 0.0);
    EXPECT_NEAR(p.action[0], 5.0f, 0.5f);  // drawn with the policy's own sigma
  }
}

TEST(ShieldTest, AdaptiveResamplingWidensSigmaAlongTheUnsafeDirection) {
  // 2-D integrator, h(x) = 1 - x0 at x = 0, k = 10, dt = 0.1: g = 10 - a0, safe iff a0 <= 10;
  // a1 does not matter. mu = (13, 0), sigma = 0.05: the unsafe direction is +a0, so sigma should
  // grow (mostly) along a0. With random-safe aggregation the returned sample shows the spread:
  // |a1| stays small, while an isotropic widening would give |a1| ~ |a0 - 13| >= 3.
  IntegratorDynamics dynamics(2, 0.1);
  FunctionBarrier barrier(2, "1 - x0",
                          [](const Eigen::Ref<const Eigen::VectorXf>& s) { return 1.0 - s[0]; });
  ShieldOptions options;
  options.class_k_gain = 10.0;
  options.probe_extent = 5.0;
  options.aggregation = Aggregation::kRandomSafe;
  options.max_iterations = 50;
  const Eigen::VectorXf state = Vec({0.0f, 0.0f}), mu = Vec({13.0f, 0.0f});
  const Eigen::VectorXf sigma = Vec({0.05f, 0.05f});
  double sum_a1_sq = 0.0, sum_d0_sq = 0.0;
  const int kSeeds = 20;
  for (int seed = 0; seed < kSeeds; ++seed) {
    options.seed = static_cast<std::uint64_t>(seed);
    Shield shield(options, barrier, dynamics);
    const Decision& d = shield.Decide(state, mu, sigma);
    ASSERT_EQ(d.status, Status::kSafeAfterResampling) << "seed " << seed;
    EXPECT_LE(d.action[0], 10.0f + 1e-5f);
    sum_a1_sq += static_cast<double>(d.action[1]) * d.action[1];
    sum_d0_sq += std::pow(d.action[0] - 13.0, 2);
  }
  const double rms_a1 = std::sqrt(sum_a1_sq / kSeeds), rms_d0 = std::sqrt(sum_d0_sq / kSeeds);
  EXPECT_GE(rms_d0, 3.0);
  EXPECT_LT(rms_a1, 0.35 * rms_d0) << "rms |a1| " << rms_a1 << ", rms |a0 - 13| " << rms_d0;
}

TEST(ShieldTest, UnsafeMeanOfSafeSamplesFallsBackToNearestSafeSample) {
  // Safe actions: |a| >= 1 (two intervals); mu = 0 with a wide sigma: the mean of the safe
  // samples is usually near 0 and unsafe.
  TwoIntervals sys;
  ShieldOptions options;
  options.class_k_gain = 0.1;
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.0f}), sigma = Vec({3.0f});
  int nearest_used = 0, mean_used = 0;
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    options.seed = seed;
    Shield shield(options, sys.barrier, sys.dynamics);
    Shield checker(options, sys.barrier, sys.dynamics);  // independent g (same float path)
    const Decision& d = shield.Decide(state, mu, sigma);
    ASSERT_EQ(d.status, Status::kSafe) << "seed " << seed;
    EXPECT_GE(d.g, 0.0);
    EXPECT_GE(std::abs(d.action[0]), 1.0f - 1e-6f);
    EXPECT_NEAR(d.g, 0.1 * (d.action[0] * d.action[0] - 1.0), 1e-5);

    Rng rng(seed);
    const Eigen::MatrixXf samples = DrawRounds(rng, mu, sigma, options.num_samples);
    Eigen::VectorXd g(options.num_samples);
    checker.EvaluateG(state, checker.EvaluateH(state), samples, g);
    float sum = 0.0f;
    int num_safe = 0;
    for (int i = 0; i < options.num_samples; ++i) {
      if (g[i] >= 0.0) {
        sum += samples(0, i);
        ++num_safe;
      }
    }
    EXPECT_DOUBLE_EQ(d.safe_ratio, static_cast<double>(num_safe) / options.num_samples);
    const float mean = sum / static_cast<float>(num_safe);
    Eigen::MatrixXf mean_column(1, 1);
    mean_column(0, 0) = mean;
    Eigen::VectorXd g_mean(1);
    checker.EvaluateG(state, checker.EvaluateH(state), mean_column, g_mean);
    if (g_mean[0] >= 0.0) {
      ++mean_used;
      EXPECT_NEAR(d.action[0], mean, 1e-5f);
      continue;
    }
    ++nearest_used;
    int nearest = -1;
    for (int i = 0; i < options.num_samples; ++i) {
      if (g[i] >= 0.0 &&
          (nearest < 0 || std::abs(samples(0, i) - mean) < std::abs(samples(0, nearest) - mean)))
        nearest = i;
    }
    ASSERT_GE(nearest, 0);
    EXPECT_EQ(d.action[0], samples(0, nearest)) << "seed " << seed << ", mean " << mean;
    EXPECT_EQ(d.g, g[nearest]);
  }
  EXPECT_GT(nearest_used, 10) << "the mean was unsafe too rarely to test the fallback";
  (void)mean_used;
}

// ------------------------------------------------------------------------------------------------
// No safe action, budgets.

TEST(ShieldTest, NoSafeActionReturnsBestEvaluatedSample) {
  NowhereSafe sys;
  ShieldOptions options;
  options.max_iterations = 5;
  options.seed = 11;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({2.0f}), sigma = Vec({0.5f});
  const Decision d = shield.Decide(state, mu, sigma);
  EXPECT_EQ(d.status, Status::kNoSafeAction);
  EXPECT_FALSE(d.safe());
  EXPECT_EQ(d.fallback, Fallback::kBestSample);
  EXPECT_EQ(d.iterations, options.max_iterations);
  EXPECT_DOUBLE_EQ(d.safe_ratio, 0.0);
  EXPECT_LT(d.g, 0.0);
  EXPECT_TRUE(d.action.allFinite());
  EXPECT_NEAR(d.g, -0.1 * d.action[0] * d.action[0] - 1.0, 1e-5);
  EXPECT_NEAR(IndependentG(sys.barrier, sys.dynamics, options, state, d.action), d.g, 1e-9);
  // At least as good as every sample of the first round (the best over all evaluated actions).
  Rng rng(options.seed);
  const Eigen::MatrixXf first = DrawRounds(rng, mu, sigma, options.num_samples);
  for (int i = 0; i < options.num_samples; ++i)
    EXPECT_GE(d.g, IndependentG(sys.barrier, sys.dynamics, options, state, first.col(i)));
}

TEST(ShieldTest, NoSafeActionPrefersBackupActionOnlyWhenItsGIsLarger) {
  NowhereSafe sys;
  ShieldOptions options;
  options.max_iterations = 4;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({2.0f}), sigma = Vec({0.5f});

  shield.SetBackupAction(Vec({0.0f}));  // g = -1, the global maximum
  const Decision good = shield.Decide(state, mu, sigma);
  EXPECT_EQ(good.status, Status::kNoSafeAction);
  EXPECT_EQ(good.fallback, Fallback::kBackupAction);
  EXPECT_EQ(good.action[0], 0.0f);
  EXPECT_NEAR(good.g, -1.0, 1e-6);
  EXPECT_EQ(good.iterations, options.max_iterations);
  EXPECT_NEAR(good.distance_to_mean, 2.0, 1e-6);

  shield.SetBackupAction(Vec({10.0f}));  // g = -11, worse than any sample near mu
  const Decision bad = shield.Decide(state, mu, sigma);
  EXPECT_EQ(bad.status, Status::kNoSafeAction);
  EXPECT_EQ(bad.fallback, Fallback::kBestSample);
  EXPECT_GT(bad.g, -11.0);
  EXPECT_NE(bad.action[0], 10.0f);

  shield.ClearBackupAction();
  EXPECT_EQ(shield.Decide(state, mu, sigma).fallback, Fallback::kBestSample);
}

TEST(ShieldTest, TimeBudgetStopsTheLoopEarly) {
  NowhereSafe sys;
  ShieldOptions options;
  options.max_iterations = 1000000;
  options.time_budget_us = 1.0;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Decision& d = shield.Decide(Vec({0.0f}), Vec({2.0f}), Vec({0.5f}));
  EXPECT_EQ(d.status, Status::kNoSafeAction);
  EXPECT_GE(d.iterations, 1);
  EXPECT_LE(d.iterations, 3) << "a 1 us budget should stop after the first round or so";
  EXPECT_LT(d.seconds, 0.5);
  EXPECT_TRUE(d.action.allFinite());
}

TEST(ShieldTest, ZeroTimeBudgetMeansIterationsOnly) {
  NowhereSafe sys;
  ShieldOptions options;
  options.max_iterations = 7;
  options.time_budget_us = 0.0;
  Shield shield(options, sys.barrier, sys.dynamics);
  EXPECT_EQ(shield.Decide(Vec({0.0f}), Vec({2.0f}), Vec({0.5f})).iterations, 7);
}

// ------------------------------------------------------------------------------------------------
// Invalid input and NaN barriers.

TEST(ShieldTest, NonFiniteOrNegativeInputsGiveInvalidInputAndAFiniteAction) {
  DoubleIntegrator sys;
  ShieldOptions options;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({1.0f, 1.0f, 0.0f, 0.0f});
  const Eigen::VectorXf mu = Vec({0.1f, 0.1f}), sigma = Vec({0.5f, 0.5f});
  struct Case {
    const char* what;
    Eigen::VectorXf state, mu, sigma;
  };
  const std::vector<Case> cases = {
      {"NaN state", Vec({1.0f, kNan, 0.0f, 0.0f}), mu, sigma},
      {"Inf state", Vec({1.0f, 1.0f, -kInf, 0.0f}), mu, sigma},
      {"NaN mu", state, Vec({kNan, 0.0f}), sigma},
      {"Inf mu", state, Vec({0.0f, kInf}), sigma},
      {"NaN sigma", state, mu, Vec({0.5f, kNan})},
      {"Inf sigma", state, mu, Vec({kInf, 0.5f})},
      {"negative sigma", state, mu, Vec({0.5f, -0.01f})},
  };
  for (bool with_backup : {false, true}) {
    if (with_backup) shield.SetBackupAction(Vec({-1.0f, 2.0f}));
    for (const Case& c : cases) {
      SCOPED_TRACE(std::string(c.what) + (with_backup ? ", with backup" : ", no backup"));
      const Decision& d = shield.Decide(c.state, c.mu, c.sigma);
      EXPECT_EQ(d.status, Status::kInvalidInput);
      EXPECT_FALSE(d.safe());
      EXPECT_TRUE(d.action.allFinite());
      EXPECT_EQ(d.action.size(), 2);
      if (with_backup) {
        EXPECT_TRUE(BitEqual(d.action, Vec({-1.0f, 2.0f})));
      } else {
        EXPECT_TRUE(d.action.isZero(0.0f));
      }
      EXPECT_TRUE(std::isnan(d.g));
      EXPECT_EQ(d.iterations, 0);
      EXPECT_EQ(d.ToJson()["status"], "invalid_input");
    }
  }
  // Zero sigma is valid (the policy is deterministic).
  shield.ClearBackupAction();
  EXPECT_EQ(shield.Decide(state, mu, Vec({0.0f, 0.0f})).status, Status::kSafe);
}

TEST(ShieldTest, NanBarrierAtTheStateGivesInvalidInput) {
  IntegratorDynamics dynamics(1, 0.1);
  FunctionBarrier barrier(1, "NaN beyond 5", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
    return s[0] > 5.0f ? std::numeric_limits<double>::quiet_NaN() : 1.0;
  });
  ShieldOptions options;
  Shield shield(options, barrier, dynamics);
  const Decision& d = shield.Decide(Vec({6.0f}), Vec({0.0f}), Vec({1.0f}));
  EXPECT_EQ(d.status, Status::kInvalidInput);
  EXPECT_EQ(d.action[0], 0.0f);
  EXPECT_TRUE(std::isnan(d.h));
  shield.SetBackupAction(Vec({-0.5f}));
  const Decision& b = shield.Decide(Vec({6.0f}), Vec({0.0f}), Vec({1.0f}));
  EXPECT_EQ(b.status, Status::kInvalidInput);
  EXPECT_EQ(b.action[0], -0.5f);
}

TEST(ShieldTest, SamplesWithNanNextBarrierNeverCountAsSafe) {
  // h(x) = 1 - x for x < 0.05, NaN beyond. At x = 0 with k = 1: g = 1 - a for a < 0.5 (all safe),
  // NaN for a >= 0.5. mu = 0.5, sigma = 1: about half the samples have a NaN g.
  IntegratorDynamics dynamics(1, 0.1);
  FunctionBarrier barrier(
      1, "1 - x, NaN beyond 0.05", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
        return s[0] < 0.05f ? 1.0 - s[0] : std::numeric_limits<double>::quiet_NaN();
      });
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.5f}), sigma = Vec({1.0f});
  for (Aggregation aggregation : {Aggregation::kMean, Aggregation::kRandomSafe}) {
    for (std::uint64_t seed = 0; seed < 10; ++seed) {
      ShieldOptions options;
      options.seed = seed;
      options.aggregation = aggregation;
      Shield shield(options, barrier, dynamics);
      const Decision& d = shield.Decide(state, mu, sigma);
      SCOPED_TRACE("seed " + std::to_string(seed) + ", " +
                   ToString(kAggregationNames, aggregation));
      ASSERT_TRUE(d.safe());
      EXPECT_EQ(d.iterations, 1);
      EXPECT_LT(0.1f * d.action[0], 0.05f);
      EXPECT_GE(d.g, 0.0);
      EXPECT_FALSE(std::isnan(d.g));
      // The safe ratio counts only the finite-g samples.
      Rng rng(seed);
      const Eigen::MatrixXf samples = DrawRounds(rng, mu, sigma, options.num_samples);
      int finite = 0;
      for (int i = 0; i < options.num_samples; ++i)
        if (0.0f + 0.1f * samples(0, i) < 0.05f) ++finite;
      EXPECT_LT(finite, options.num_samples);
      EXPECT_DOUBLE_EQ(d.safe_ratio, static_cast<double>(finite) / options.num_samples);
    }
  }
}

TEST(ShieldTest, AllNanNextBarrierGivesNoSafeActionWithAFiniteAction) {
  IntegratorDynamics dynamics(1, 0.1);
  FunctionBarrier barrier(1, "finite only at 0", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
    return s[0] == 0.0f ? 1.0 : std::numeric_limits<double>::quiet_NaN();
  });
  ShieldOptions options;
  options.max_iterations = 3;
  Shield shield(options, barrier, dynamics);
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({1.0f}), sigma = Vec({0.3f});
  const Decision d = shield.Decide(state, mu, sigma);
  EXPECT_EQ(d.status, Status::kNoSafeAction);
  EXPECT_FALSE(d.g >= 0.0);
  EXPECT_TRUE(d.action.allFinite());
  // A backup with a finite (here: safe) g wins over actions whose g is unknown.
  shield.SetBackupAction(Vec({0.0f}));
  const Decision b = shield.Decide(state, mu, sigma);
  EXPECT_EQ(b.fallback, Fallback::kBackupAction);
  EXPECT_EQ(b.action[0], 0.0f);
  EXPECT_NEAR(b.g, 1.0, 1e-9);  // g(0) = alpha(h(0)) = 1
  EXPECT_TRUE(b.safe());
}

// A backup action whose g is NaN (h(T(s, backup)) is NaN) must not replace a best sample with a
// finite g: the backup competes on g, and g is NaN only for invalid input.
TEST(ShieldTest, BackupWithNanGDoesNotReplaceABestSampleWithFiniteG) {
  IntegratorDynamics dynamics(1, 0.1);
  FunctionBarrier barrier(
      1, "-1 - x^2 for |x| <= 0.5, NaN beyond", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
        return std::abs(s[0]) <= 0.5f ? -1.0 - static_cast<double>(s[0]) * s[0]
                                      : std::numeric_limits<double>::quiet_NaN();
      });
  ShieldOptions options;
  options.max_iterations = 2;
  Shield shield(options, barrier, dynamics);
  shield.SetBackupAction(Vec({10.0f}));  // x' = 1: h is NaN, so g(backup) is NaN
  const Decision& d = shield.Decide(Vec({0.0f}), Vec({0.0f}), Vec({0.5f}));
  EXPECT_EQ(d.status, Status::kNoSafeAction);
  EXPECT_EQ(d.fallback, Fallback::kBestSample) << d.ToJson().dump();
  EXPECT_FALSE(std::isnan(d.g)) << "g is NaN for a " << ToString(kStatusNames, d.status)
                                << " decision";
  EXPECT_LT(d.g, 0.0);
}

// ------------------------------------------------------------------------------------------------
// Ablations.

TEST(ShieldTest, RandomSafeAggregationReturnsOneOfTheSafeSamples) {
  DoubleIntegrator sys;
  // Near the obstacle, so that only part of the samples are safe.
  const Eigen::VectorXf state = Vec({5.0f, 7.3f, 0.0f, -0.6f});
  const Eigen::VectorXf mu = Vec({0.0f, -1.0f}), sigma = Vec({3.0f, 3.0f});
  std::set<std::pair<float, float>> chosen;
  int partially_safe = 0;
  for (std::uint64_t seed = 0; seed < 10; ++seed) {
    ShieldOptions options;
    options.seed = seed;
    options.aggregation = Aggregation::kRandomSafe;
    Shield shield(options, sys.barrier, sys.dynamics);
    const Decision& d = shield.Decide(state, mu, sigma);
    SCOPED_TRACE("seed " + std::to_string(seed));
    ASSERT_EQ(d.iterations, 1) << d.ToJson().dump();
    ASSERT_EQ(d.status, Status::kSafe);
    Rng rng(seed);
    const Eigen::MatrixXf samples = DrawRounds(rng, mu, sigma, options.num_samples);
    const int column = ColumnIndex(samples, d.action);
    ASSERT_GE(column, 0) << "the action " << d.action.transpose() << " is not a sample";
    const double g = IndependentG(sys.independent, sys.dynamics, options, state, d.action);
    EXPECT_GE(g, 0.0);
    // IndependentG re-derives g with its own single-column evaluation and formula (not the
    // shield's batched EvaluateG loop): -march=native may contract it into FMAs differently.
    EXPECT_NEAR(d.g, g, 1e-9 * std::max(1.0, std::abs(g)));
    EXPECT_NEAR(d.distance_to_mean, (samples.col(column) - mu).norm(), 1e-6);
    if (d.safe_ratio < 1.0) ++partially_safe;
    chosen.insert({d.action[0], d.action[1]});
  }
  EXPECT_GT(partially_safe, 0);
  EXPECT_GT(chosen.size(), 5u);  // different seeds, different choices
}

TEST(ShieldTest, PolicyDrawAggregationReturnsThePolicysSafeDrawElseAlgorithm1) {
  DoubleIntegrator sys;
  // Near the obstacle, so that the policy's draw is safe for some seeds and not for others.
  const Eigen::VectorXf state = Vec({5.0f, 7.3f, 0.0f, -0.6f});
  const Eigen::VectorXf mu = Vec({0.0f, -1.0f}), sigma = Vec({3.0f, 3.0f});
  int safe_draws = 0, unsafe_draws = 0;
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    ShieldOptions options;
    options.seed = seed;
    options.aggregation = Aggregation::kPolicyDraw;
    Shield shield(options, sys.barrier, sys.dynamics);
    const Decision d = shield.Decide(state, mu, sigma);
    // The policy's draw is the first sample of round 1.
    Rng rng(seed);
    const Eigen::MatrixXf samples = DrawRounds(rng, mu, sigma, options.num_samples);
    const double g0 = IndependentG(sys.independent, sys.dynamics, options, state, samples.col(0));
    if (g0 >= 0.0) {
      ++safe_draws;
      EXPECT_TRUE(BitEqual(d.action, samples.col(0))) << d.action.transpose();
      EXPECT_EQ(d.status, Status::kSafe);
      EXPECT_EQ(d.iterations, 1);
      EXPECT_FALSE(d.intervened);
      EXPECT_EQ(d.fallback, Fallback::kNone);
      EXPECT_NEAR(d.g, g0, 1e-9 * std::max(1.0, std::abs(g0)));
      EXPECT_NEAR(d.distance_to_mean, (samples.col(0) - mu).norm(), 1e-6);
    } else {
      // An unsafe draw: exactly Algorithm 1's decision (same draws, same seed).
      ++unsafe_draws;
      ShieldOptions mean_options = options;
      mean_options.aggregation = Aggregation::kMean;
      Shield mean_shield(mean_options, sys.barrier, sys.dynamics);
      EXPECT_TRUE(d.intervened);
      ExpectSameDecision(d, mean_shield.Decide(state, mu, sigma));
    }
  }
  EXPECT_GT(safe_draws, 0);
  EXPECT_GT(unsafe_draws, 0);
}

TEST(ShieldTest, PolicyDrawEvaluatesOnlyTheDrawWhenItIsSafe) {
  // x' = x + 0.1 a, h = 1 - x at x = 0 with k = 1: the draw a0 ~ N(0, 1) is safe iff a0 <= 1.
  CountedHalfLine sys;
  long& evaluated = sys.evaluated;
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.0f}), sigma = Vec({1.0f});
  int safe_draws = 0, unsafe_draws = 0;
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    ShieldOptions options;
    options.seed = seed;
    options.aggregation = Aggregation::kPolicyDraw;
    Shield shield(options, sys.barrier, sys.dynamics);
    evaluated = 0;
    const Decision d = shield.Decide(state, mu, sigma);
    Rng rng(seed);
    const float a0 = DrawRounds(rng, mu, sigma, options.num_samples)(0, 0);
    if (a0 <= 1.0f) {
      ++safe_draws;
      EXPECT_EQ(evaluated, 2);  // h(s) and h(T(s, a0))
      EXPECT_EQ(d.action[0], a0);
      EXPECT_EQ(d.safe_ratio, 1.0);
    } else {
      ++unsafe_draws;
      EXPECT_GE(evaluated, 2 + options.num_samples);  // the draw, then the whole round
      EXPECT_LE(d.action[0], 1.0f);
    }
  }
  EXPECT_GT(safe_draws, 0);
  EXPECT_GT(unsafe_draws, 0);
}

TEST(ShieldTest, PolicyMeanAggregationReturnsASafeMeanElseAlgorithm1) {
  DoubleIntegrator sys;
  // Near the obstacle, moving towards it: the policy's mean is safe for some means and not for
  // others (the same state, seeds and draws for every mean).
  const Eigen::VectorXf state = Vec({5.0f, 7.3f, 0.0f, -0.6f});
  const Eigen::VectorXf sigma = Vec({3.0f, 3.0f});
  int safe_means = 0, unsafe_means = 0;
  for (int k = 0; k <= 12; ++k) {
    const Eigen::VectorXf mu = Vec({0.0f, -3.0f + 0.5f * static_cast<float>(k)});
    SCOPED_TRACE("mu " + std::to_string(mu[1]));
    ShieldOptions options;
    options.seed = static_cast<std::uint64_t>(k);
    options.aggregation = Aggregation::kPolicyMean;
    Shield shield(options, sys.barrier, sys.dynamics);
    const Decision d = shield.Decide(state, mu, sigma);
    const double g_mu = IndependentG(sys.independent, sys.dynamics, options, state, mu);
    // A mean within float rounding of g = 0 could go either way in the shield's own evaluation.
    if (std::abs(g_mu) < 1e-6) continue;
    if (g_mu > 0.0) {
      ++safe_means;
      EXPECT_TRUE(BitEqual(d.action, mu)) << d.action.transpose();
      EXPECT_EQ(d.status, Status::kSafe);
      EXPECT_EQ(d.iterations, 1);
      EXPECT_FALSE(d.intervened);
      EXPECT_EQ(d.fallback, Fallback::kNone);
      EXPECT_EQ(d.distance_to_mean, 0.0);
      EXPECT_NEAR(d.g, g_mu, 1e-9 * std::max(1.0, std::abs(g_mu)));
    } else {
      // An unsafe mean: exactly Algorithm 1's decision (same draws, same seed), and always an
      // intervention (kMean's `intervened` says whether its first draw was unsafe instead).
      ++unsafe_means;
      ShieldOptions mean_options = options;
      mean_options.aggregation = Aggregation::kMean;
      Shield mean_shield(mean_options, sys.barrier, sys.dynamics);
      EXPECT_TRUE(d.intervened);
      Decision algorithm1 = mean_shield.Decide(state, mu, sigma);
      algorithm1.intervened = true;
      ExpectSameDecision(d, algorithm1);
      EXPECT_GE(d.g, 0.0);
    }
  }
  EXPECT_GT(safe_means, 0);
  EXPECT_GT(unsafe_means, 0);
}

TEST(ShieldTest, PolicyMeanEvaluatesOnlyTheMeanWhenItIsSafe) {
  // x' = x + 0.1 a, h = 1 - x at x = 0 with k = 1: an action is safe iff a <= 1.
  CountedHalfLine sys;
  long& evaluated = sys.evaluated;
  const Eigen::VectorXf state = Vec({0.0f}), sigma = Vec({1.0f});
  ShieldOptions options;
  options.aggregation = Aggregation::kPolicyMean;
  Shield shield(options, sys.barrier, sys.dynamics);

  evaluated = 0;
  const Decision safe = shield.Decide(state, Vec({0.9f}), sigma);
  EXPECT_EQ(evaluated, 2);  // h(s) and h(T(s, mu))
  EXPECT_EQ(safe.action[0], 0.9f);
  EXPECT_EQ(safe.safe_ratio, 1.0);
  EXPECT_FALSE(safe.intervened);

  // Unsafe mean: the whole round is scored, and the returned action is safe and not the mean.
  evaluated = 0;
  const Decision shielded = shield.Decide(state, Vec({1.5f}), sigma);
  EXPECT_GE(evaluated, 2 + options.num_samples);
  EXPECT_LE(shielded.action[0], 1.0f);
  EXPECT_TRUE(shielded.intervened);
  EXPECT_NE(shielded.status, Status::kNoSafeAction);
}

TEST(ShieldTest, RandomSafeWithSameSamplesCanPickDifferentSamples) {
  // The pick is uniform among the safe samples: its rank among them varies with the seed (it is
  // not, e.g., always the first or the last safe sample).
  HalfLine sys;  // x = 0, k = 1: safe iff a <= 1
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.0f}), sigma = Vec({1.0f});
  std::set<int> picked;
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    ShieldOptions options;
    options.seed = seed;
    options.aggregation = Aggregation::kRandomSafe;
    Shield shield(options, sys.barrier, sys.dynamics);
    const Decision& d = shield.Decide(state, mu, sigma);
    Rng rng(seed);
    const Eigen::MatrixXf samples = DrawRounds(rng, mu, sigma, options.num_samples);
    const int column = ColumnIndex(samples, d.action);
    ASSERT_GE(column, 0);
    EXPECT_LE(samples(0, column), 1.0f + 1e-6f);
    int safe_rank = 0;  // rank of the pick among the safe samples
    for (int i = 0; i < column; ++i)
      if (samples(0, i) <= 1.0f) ++safe_rank;
    picked.insert(safe_rank);
  }
  EXPECT_GT(picked.size(), 5u);
}

TEST(ShieldTest, NoResamplingAblationReturnsARandomSampleOfTheLastRound) {
  HalfLine sys;  // x = 0.9: safe iff a <= 0.1
  ShieldOptions options;
  options.resampling = Resampling::kNone;
  options.max_iterations = 6;
  options.seed = 5;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({0.9f}), mu = Vec({5.0f}), sigma = Vec({0.05f});
  const Decision d = shield.Decide(state, mu, sigma);
  EXPECT_EQ(d.status, Status::kNoSafeAction);
  EXPECT_EQ(d.fallback, Fallback::kRandomSample);
  EXPECT_EQ(d.iterations, 6);
  // Without probes the rounds are consecutive draws of the same N(mu, sigma) (sigma never
  // widened); the pick follows them.
  Rng rng(options.seed);
  const Eigen::MatrixXf all = DrawRounds(rng, mu, sigma, options.num_samples, 6);
  const Eigen::MatrixXf last = all.rightCols(options.num_samples);
  const int pick = static_cast<int>(rng.UniformIndex(options.num_samples));
  EXPECT_EQ(d.action[0], last(0, pick));
  EXPECT_LT((last.array() - 5.0f).abs().maxCoeff(), 0.5f);  // every round used sigma = 0.05
  EXPECT_NEAR(d.g, -d.action[0] + 0.1, 1e-5);
}

TEST(ShieldTest, NoResamplingAblationWithEnoughSafeSamplesAggregatesAsUsual) {
  DoubleIntegrator sys;
  const Eigen::VectorXf state = Vec({1.0f, 1.0f, 0.0f, 0.0f});
  const Eigen::VectorXf mu = Vec({0.3f, -0.2f}), sigma = Vec({0.5f, 0.5f});
  ShieldOptions options;
  options.seed = 21;
  Shield adaptive(options, sys.barrier, sys.dynamics);
  const Decision a = adaptive.Decide(state, mu, sigma);
  options.resampling = Resampling::kNone;
  Shield none(options, sys.barrier, sys.dynamics);
  const Decision n = none.Decide(state, mu, sigma);
  EXPECT_EQ(a.iterations, 1);
  ExpectSameDecision(a, n);
}

// kSafeAfterResampling means "found after one or more resampling rounds": with resampling = none
// and max_iterations = 1 there is no resampling round, so a safe random pick at the limit is kSafe.
TEST(ShieldTest, NoResamplingSingleRoundSafePickIsReportedSafe) {
  HalfLine sys;  // x = 0, k = 1: safe iff a <= 1
  ShieldOptions options;
  options.resampling = Resampling::kNone;
  options.max_iterations = 1;
  options.safe_ratio = 0.95;  // ~84% safe: not enough, so the ablation picks at random
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.0f}), sigma = Vec({1.0f});
  bool checked = false;
  for (std::uint64_t seed = 0; seed < 10 && !checked; ++seed) {
    options.seed = seed;
    Shield shield(options, sys.barrier, sys.dynamics);
    const Decision& d = shield.Decide(state, mu, sigma);
    ASSERT_EQ(d.iterations, 1);
    ASSERT_EQ(d.fallback, Fallback::kRandomSample);
    if (d.g < 0.0) continue;  // find a seed whose random pick is safe
    checked = true;
    EXPECT_GE(d.g, 0.0);
    EXPECT_EQ(d.status, Status::kSafe)
        << "seed " << seed << ": no resampling round happened (iterations = 1); "
        << d.ToJson().dump();
  }
  EXPECT_TRUE(checked);
}

// ------------------------------------------------------------------------------------------------
// Determinism.

// The default sampler (i.i.d. normals) is pinned: these decisions were recorded before
// ShieldOptions::sampler existed (commit 63d30f0, GCC 12, AVX-512), so the draws of every existing
// result are unchanged. Each row: the state (0 far, 1 heading into the obstacle), then the action,
// g, iterations. Consecutive decisions of one shield continue its stream. Compared to a relative
// 1e-4, not bit for bit: another compiler or instruction set rounds the barrier's arithmetic
// differently (clang's build differs in the last bits of row 3), while a changed draw moves an
// action by the order of sigma.
struct PinnedDecision {
  int state;
  float a0, a1;
  double g;
  int iterations;
};

TEST(ShieldTest, IidSamplerDecisionsAreUnchanged) {
  static const PinnedDecision kPinned[] = {
      {0, 0x1.644684p-3f, -0x1.1321f2p-3f, 0x1.3f2d28p+4, 1},
      {1, -0x1.751a64p+0f, 0x1.a12612p+1f, 0x1.096a34p+3, 14},
      {1, 0x1.523442p-1f, 0x1.f00fc8p+1f, 0x1.6cd8a8p+3, 19},
      {0, 0x1.104f8ep-3f, -0x1.565678p-3f, 0x1.4900c8p+4, 1},
      {1, -0x1.c8a7b4p-2f, 0x1.617b34p+2f, 0x1.3c9ae5p+4, 15},
      {0, 0x1.3e8422p-2f, -0x1.d87228p-4f, 0x1.2a6e74p+4, 1},
  };
  DoubleIntegrator sys;
  const Eigen::VectorXf states[2] = {Vec({1.0f, 1.0f, 0.3f, 0.2f}), Vec({5.0f, 7.6f, 0.0f, -1.5f})};
  const Eigen::VectorXf mus[2] = {Vec({0.2f, -0.1f}), Vec({0.0f, -5.0f})};
  const Eigen::VectorXf sigmas[2] = {Vec({0.5f, 0.5f}), Vec({0.05f, 0.05f})};
  ShieldOptions options;
  options.seed = 99;
  options.max_iterations = 50;
  ASSERT_EQ(options.sampler, Sampler::kIid);  // the default
  Shield shield(options, sys.barrier, sys.dynamics);
  std::string recorded;
  bool same = true;
  const int order[] = {0, 1, 1, 0, 1, 0};
  for (int i = 0; i < 6; ++i) {
    const int k = order[i];
    const Decision& d = shield.Decide(states[k], mus[k], sigmas[k]);
    char line[160];
    std::snprintf(line, sizeof line, "{%d, %af, %af, %a, %d},\n", k, d.action[0], d.action[1], d.g,
                  d.iterations);
    recorded += line;
    if (i >= static_cast<int>(std::size(kPinned))) {
      same = false;
      continue;
    }
    const PinnedDecision& p = kPinned[i];
    const auto close = [](double a, double b) {
      return std::abs(a - b) <= 1e-4 * std::max(1.0, std::abs(b));
    };
    same = same && p.state == k && close(d.action[0], p.a0) && close(d.action[1], p.a1) &&
           close(d.g, p.g) && p.iterations == d.iterations;
  }
  EXPECT_TRUE(same) << "recorded:\n" << recorded;
}

TEST(ShieldTest, SameSeedGivesIdenticalDecisions) {
  DoubleIntegrator sys;
  const Eigen::VectorXf state = Vec({5.0f, 7.6f, 0.0f, -1.5f});
  const Eigen::VectorXf mu = Vec({0.0f, -5.0f}), sigma = Vec({0.05f, 0.05f});
  ShieldOptions options;
  options.seed = 99;
  options.max_iterations = 50;
  Shield first(options, sys.barrier, sys.dynamics);
  Shield second(options, sys.independent, sys.dynamics);
  const Decision a = first.Decide(state, mu, sigma);
  const Decision b = second.Decide(state, mu, sigma);
  EXPECT_GT(a.iterations, 1);  // the resampling path, probes included
  ExpectSameDecision(a, b);

  // Seed() on a used shield restarts the stream.
  first.Decide(state, mu, sigma);
  first.Seed(99);
  ExpectSameDecision(a, first.Decide(state, mu, sigma));

  // Another seed: another action.
  first.Seed(100);
  const Decision c = first.Decide(state, mu, sigma);
  EXPECT_FALSE(BitEqual(a.action, c.action));
  options.seed = 100;
  Shield third(options, sys.barrier, sys.dynamics);
  ExpectSameDecision(c, third.Decide(state, mu, sigma));

  // Consecutive decisions of one shield continue the stream (they differ).
  const Decision d = third.Decide(state, mu, sigma);
  EXPECT_FALSE(BitEqual(c.action, d.action));
}

// ------------------------------------------------------------------------------------------------
// Misuse.

TEST(ShieldTest, OptionsValidateNamesFieldValueAndRule) {
  const auto message = [](auto mutate) {
    ShieldOptions options;
    mutate(options);
    return ErrorOf([&] { options.Validate(); });
  };
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_samples = 0; }),
             "ShieldOptions::num_samples = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_samples = -3; }),
             "ShieldOptions::num_samples = -3, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_samples = 2000000000; }),
             "ShieldOptions::num_samples = 2000000000, must be in [1, 1000000]");
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_probes = 1000001; }),
             "ShieldOptions::num_probes = 1000001, must be in [1, 1000000]");
  EXPECT_HAS(message([](ShieldOptions& o) { o.safe_ratio = 1.0; }),
             "ShieldOptions::safe_ratio = 1, must be in [0, 1)");
  EXPECT_HAS(message([](ShieldOptions& o) { o.safe_ratio = -0.5; }),
             "ShieldOptions::safe_ratio = -0.5, must be in [0, 1)");
  EXPECT_HAS(message([](ShieldOptions& o) { o.safe_ratio = std::nan(""); }),
             "ShieldOptions::safe_ratio = nan");
  EXPECT_HAS(message([](ShieldOptions& o) { o.dt = 0.0; }), "ShieldOptions::dt = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.dt = std::numeric_limits<double>::infinity(); }),
             "ShieldOptions::dt = inf, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.class_k_gain = 0.0; }),
             "ShieldOptions::class_k_gain = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.class_k_gain = -1.0; }),
             "ShieldOptions::class_k_gain = -1, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_probes = 0; }),
             "ShieldOptions::num_probes = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.probe_extent = 0.0; }),
             "ShieldOptions::probe_extent = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.sigma_step = -0.5; }),
             "ShieldOptions::sigma_step = -0.5, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.max_iterations = 0; }),
             "ShieldOptions::max_iterations = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.time_budget_us = -1.0; }),
             "ShieldOptions::time_budget_us = -1, must be >= 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.time_budget_us = std::nan(""); }),
             "ShieldOptions::time_budget_us = nan");

  ShieldOptions fine;
  fine.safe_ratio = 0.0;
  fine.max_iterations = 1;
  fine.num_samples = 1;
  fine.num_probes = 1;
  fine.Validate();  // boundaries that are allowed

  // The constructor validates.
  HalfLine sys;
  ShieldOptions bad;
  bad.num_probes = 0;
  EXPECT_HAS(ErrorOf([&] { Shield shield(bad, sys.barrier, sys.dynamics); }),
             "ShieldOptions::num_probes = 0, must be > 0");
}

TEST(ShieldTest, OptionsToJsonHasEveryField) {
  ShieldOptions options;
  options.class_k = ClassK::kCubic;
  options.aggregation = Aggregation::kRandomSafe;
  options.resampling = Resampling::kNone;
  options.seed = 42;
  const nlohmann::json j = options.ToJson();
  EXPECT_EQ(j["num_samples"], 64);
  EXPECT_EQ(j["safe_ratio"], 0.1);
  EXPECT_EQ(j["class_k"], "cubic");
  EXPECT_EQ(j["aggregation"], "random-safe");
  EXPECT_EQ(j["resampling"], "none");
  EXPECT_EQ(j["seed"], 42u);
  for (const char* key : {"dt", "class_k_gain", "num_probes", "probe_extent", "sigma_step",
                          "max_iterations", "time_budget_us"})
    EXPECT_TRUE(j.contains(key)) << key;
}

TEST(ShieldTest, ConstructorRejectsBarrierOfAnotherStateDimension) {
  di::Dynamics dynamics(0.1);
  FunctionBarrier barrier(1, "one-dimensional barrier",
                          [](const Eigen::Ref<const Eigen::VectorXf>&) { return 1.0; });
  const std::string message = ErrorOf([&] { Shield shield(ShieldOptions{}, barrier, dynamics); });
  EXPECT_HAS(message, "one-dimensional barrier");
  EXPECT_HAS(message, "1-dimensional");
  EXPECT_HAS(message, dynamics.Describe());
  EXPECT_HAS(message, "produces 4");
}

TEST(ShieldTest, DecideThrowsOnWrongDimensions) {
  DoubleIntegrator sys;
  Shield shield(ShieldOptions{}, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({1.0f, 1.0f, 0.0f, 0.0f}), two = Vec({0.0f, 0.0f});
  EXPECT_HAS(ErrorOf([&] {
               shield.Decide(Vec({1.0f, 1.0f, 0.0f}), two, two);
             }),
             "state has 3 values, expected 4");
  EXPECT_HAS(ErrorOf([&] { shield.Decide(state, Vec({0.0f}), two); }),
             "mu has 1 values, expected 2");
  EXPECT_HAS(ErrorOf([&] {
               shield.Decide(state, two, Vec({1.0f, 1.0f, 1.0f}));
             }),
             "sigma has 3 values, expected 2");
  // Dimension errors win over bad numbers (misuse is reported, not hidden as invalid input).
  EXPECT_HAS(ErrorOf([&] { shield.Decide(Vec({kNan}), two, two); }), "state has 1 values");
  // The shield still works afterwards.
  EXPECT_EQ(shield.Decide(state, two, Vec({0.1f, 0.1f})).status, Status::kSafe);
}

TEST(ShieldTest, SetBackupActionRejectsNonFiniteOrWrongSize) {
  DoubleIntegrator sys;
  Shield shield(ShieldOptions{}, sys.barrier, sys.dynamics);
  EXPECT_HAS(ErrorOf([&] { shield.SetBackupAction(Vec({0.0f, kNan})); }), "non-finite");
  EXPECT_HAS(ErrorOf([&] { shield.SetBackupAction(Vec({kInf, 0.0f})); }), "non-finite");
  EXPECT_HAS(ErrorOf([&] {
               shield.SetBackupAction(Vec({0.0f, 0.0f, 0.0f}));
             }),
             "backup action has 3 values, expected 2");
  // A rejected backup is not installed: invalid input still returns zeros.
  const Decision& d =
      shield.Decide(Vec({kNan, 0.0f, 0.0f, 0.0f}), Vec({1.0f, 1.0f}), Vec({1.0f, 1.0f}));
  EXPECT_EQ(d.status, Status::kInvalidInput);
  EXPECT_TRUE(d.action.isZero(0.0f));
}

// ------------------------------------------------------------------------------------------------
// Learned barrier, JSON.

TEST(ShieldTest, WorksWithALearnedBarrierNet) {
  cbf::BarrierNet net;
  net.mlp = nn::RandomMlpParams(nn::MlpSpec{4, {16}, 1, nn::Activation::kTanh}, 17);
  net.normalizer = nn::Normalizer::Identity(4);
  net.features = di::StateFeatures();
  const auto evaluator = net.MakeEvaluator();
  const auto independent = net.MakeEvaluator();
  di::Dynamics dynamics(0.1);
  ShieldOptions options;
  options.seed = 5;
  Shield shield(options, *evaluator, dynamics);
  Shield checker(options, *independent, dynamics);
  Rng rng(1234);
  int safe = 0, resampled = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::VectorXf state = Vec(
        {static_cast<float>(rng.Uniform(0, 10)), static_cast<float>(rng.Uniform(0, 10)),
         static_cast<float>(rng.Uniform(-1.5, 1.5)), static_cast<float>(rng.Uniform(-1.5, 1.5))});
    const Eigen::VectorXf mu =
        Vec({static_cast<float>(rng.Uniform(-5, 5)), static_cast<float>(rng.Uniform(-5, 5))});
    const Eigen::VectorXf sigma = Vec({0.3f, 0.3f});
    const Decision& d = shield.Decide(state, mu, sigma);
    ASSERT_NE(d.status, Status::kInvalidInput);
    ASSERT_TRUE(d.action.allFinite());
    Eigen::MatrixXf column = d.action;
    Eigen::VectorXd g(1);
    checker.EvaluateG(state, checker.EvaluateH(state), column, g);
    EXPECT_NEAR(g[0], d.g, 1e-6 * std::max(1.0, std::abs(d.g)));
    if (d.safe()) {
      ++safe;
      EXPECT_GE(g[0], 0.0) << "trial " << trial;
      if (d.status == Status::kSafeAfterResampling) ++resampled;
    } else {
      EXPECT_LT(d.g, 0.0);
    }
  }
  EXPECT_GT(safe, 0);
  (void)resampled;
}

TEST(ShieldTest, DecisionToJsonHasEveryField) {
  NowhereSafe sys;
  ShieldOptions options;
  options.max_iterations = 2;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Decision& d = shield.Decide(Vec({0.0f}), Vec({2.0f}), Vec({0.5f}));
  const nlohmann::json j = d.ToJson();
  EXPECT_EQ(j["status"], "no_safe_action");
  EXPECT_EQ(j["fallback"], "best_sample");
  ASSERT_TRUE(j["action"].is_array());
  ASSERT_EQ(j["action"].size(), 1u);
  EXPECT_FLOAT_EQ(j["action"][0].get<float>(), d.action[0]);
  EXPECT_DOUBLE_EQ(j["g"].get<double>(), d.g);
  EXPECT_DOUBLE_EQ(j["h"].get<double>(), -1.0);
  EXPECT_EQ(j["iterations"], 2);
  EXPECT_DOUBLE_EQ(j["safe_ratio"].get<double>(), 0.0);
  EXPECT_EQ(j["intervened"], true);
  EXPECT_DOUBLE_EQ(j["distance_to_mean"].get<double>(), d.distance_to_mean);
  EXPECT_TRUE(j["seconds"].is_number());
  EXPECT_EQ(j["bounded"], false);  // no box
  EXPECT_EQ(j.size(), 11u);

  HalfLine half;
  Shield safe_shield(ShieldOptions{}, half.barrier, half.dynamics);
  const nlohmann::json s = safe_shield.Decide(Vec({0.0f}), Vec({-1.0f}), Vec({0.1f})).ToJson();
  EXPECT_EQ(s["status"], "safe");
  EXPECT_EQ(s["fallback"], "none");
  EXPECT_EQ(s["intervened"], false);
}

}  // namespace
}  // namespace secure::shield
