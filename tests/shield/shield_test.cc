// The CBF shield (Algorithm 1, Algorithm 2): g, the decision on hand-made systems and the
// double integrator, no safe action and budgets. Also in the shield_test program:
// shield_robustness_test.cc (invalid input, NaN barriers, misuse), shield_ablation_test.cc
// (aggregations, ablations, determinism, a learned barrier, JSON).
#include "tests/shield/shield_test_fixtures.h"

namespace secure::shield {
namespace {
using namespace test;  // NOLINT(google-build-using-namespace): the fixtures

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

}  // namespace
}  // namespace secure::shield
