// The CBF shield (the shield_test program, shield_test.cc): the aggregations and the paper's
// ablations, determinism, a learned BarrierNet, Decision::ToJson.
#include "tests/shield/shield_test_fixtures.h"

namespace secure::shield {
namespace {
using namespace test;  // NOLINT(google-build-using-namespace): the fixtures

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

// The policy-draw tests' loop: for seeds 0..19 a kPolicyDraw shield on `sys` (its barrier and
// dynamics), given to `decide(options, shield)`, which decides, checks and returns whether the
// policy's draw was safe; both kinds of draw must occur.
template <class System, class Decide>
void ForPolicyDrawSeeds(System& sys, const Decide& decide) {
  int safe_draws = 0, unsafe_draws = 0;
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    SCOPED_TRACE("seed " + std::to_string(seed));
    ShieldOptions options;
    options.seed = seed;
    options.aggregation = Aggregation::kPolicyDraw;
    Shield shield(options, sys.barrier, sys.dynamics);
    ++(decide(options, shield) ? safe_draws : unsafe_draws);
  }
  EXPECT_GT(safe_draws, 0);
  EXPECT_GT(unsafe_draws, 0);
}

TEST(ShieldTest, PolicyDrawAggregationReturnsThePolicysSafeDrawElseAlgorithm1) {
  DoubleIntegrator sys;
  // Near the obstacle, so that the policy's draw is safe for some seeds and not for others.
  const Eigen::VectorXf state = Vec({5.0f, 7.3f, 0.0f, -0.6f});
  const Eigen::VectorXf mu = Vec({0.0f, -1.0f}), sigma = Vec({3.0f, 3.0f});
  ForPolicyDrawSeeds(sys, [&](const ShieldOptions& options, Shield& shield) {
    const Decision d = shield.Decide(state, mu, sigma);
    // The policy's draw is the first sample of round 1.
    Rng rng(options.seed);
    const Eigen::MatrixXf samples = DrawRounds(rng, mu, sigma, options.num_samples);
    const double g0 = IndependentG(sys.independent, sys.dynamics, options, state, samples.col(0));
    if (g0 >= 0.0) {
      EXPECT_TRUE(BitEqual(d.action, samples.col(0))) << d.action.transpose();
      EXPECT_EQ(d.status, Status::kSafe);
      EXPECT_EQ(d.iterations, 1);
      EXPECT_FALSE(d.intervened);
      EXPECT_EQ(d.fallback, Fallback::kNone);
      EXPECT_NEAR(d.g, g0, 1e-9 * std::max(1.0, std::abs(g0)));
      EXPECT_NEAR(d.distance_to_mean, (samples.col(0) - mu).norm(), 1e-6);
      return true;
    }
    // An unsafe draw: exactly Algorithm 1's decision (same draws, same seed).
    ShieldOptions mean_options = options;
    mean_options.aggregation = Aggregation::kMean;
    Shield mean_shield(mean_options, sys.barrier, sys.dynamics);
    EXPECT_TRUE(d.intervened);
    ExpectSameDecision(d, mean_shield.Decide(state, mu, sigma));
    return false;
  });
}

TEST(ShieldTest, PolicyDrawEvaluatesOnlyTheDrawWhenItIsSafe) {
  // x' = x + 0.1 a, h = 1 - x at x = 0 with k = 1: the draw a0 ~ N(0, 1) is safe iff a0 <= 1.
  CountedHalfLine sys;
  long& evaluated = sys.evaluated;
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.0f}), sigma = Vec({1.0f});
  ForPolicyDrawSeeds(sys, [&](const ShieldOptions& options, Shield& shield) {
    evaluated = 0;
    const Decision d = shield.Decide(state, mu, sigma);
    Rng rng(options.seed);
    const float a0 = DrawRounds(rng, mu, sigma, options.num_samples)(0, 0);
    if (a0 <= 1.0f) {
      EXPECT_EQ(evaluated, 2);  // h(s) and h(T(s, a0))
      EXPECT_EQ(d.action[0], a0);
      EXPECT_EQ(d.safe_ratio, 1.0);
      return true;
    }
    EXPECT_GE(evaluated, 2 + options.num_samples);  // the draw, then the whole round
    EXPECT_LE(d.action[0], 1.0f);
    return false;
  });
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
