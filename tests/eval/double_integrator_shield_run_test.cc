#include "domains/double_integrator/ground_truth_barrier.h"
#include "domains/double_integrator/shield_run.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/nn/mlp.h"

namespace secure::eval {
namespace {

using secure::test::ErrorOf;

ShieldRunOptions FastOptions(long episodes = 100) {
  ShieldRunOptions options;
  options.episodes = episodes;
  options.seed = 7;
  return options;
}

// The counts that must add up in every run.
void ExpectConsistent(const ShieldRunResult& r) {
  EXPECT_EQ(r.dangerous_episodes + r.success_episodes + r.timeout_episodes, r.episodes);
  EXPECT_GE(r.timeout_episodes, 0);
  EXPECT_LE(r.unsafe_state_episodes, r.episodes);
  EXPECT_LE(r.unsafe_state_steps, r.steps);
  EXPECT_LE(r.steps, r.episodes * r.options.task.max_steps);
  EXPECT_GE(r.steps, r.episodes);
  if (r.shielded) {
    EXPECT_EQ(r.decisions, r.steps);
    EXPECT_EQ(r.latency_us.count, r.decisions);
    EXPECT_LE(r.resampled_decisions + r.no_safe_action_decisions + r.invalid_input_decisions,
              r.decisions);
    EXPECT_LE(r.interventions, r.decisions);
    EXPECT_LE(r.latency_us.p50, r.latency_us.p90);
    EXPECT_LE(r.latency_us.p90, r.latency_us.p99);
    EXPECT_LE(r.latency_us.p99, r.latency_us.max);
  } else {
    EXPECT_EQ(r.decisions, 0);
    EXPECT_EQ(r.latency_us.count, 0);
  }
}

TEST(DoubleIntegratorShieldRunTest, GroundTruthShieldIsSafeAndReachesTheGoal) {
  const ShieldRunOptions options = FastOptions();
  domains::double_integrator::GroundTruthBarrier barrier(options.task.truth);
  const ShieldRunResult r = RunDoubleIntegratorShield(options, barrier);
  ExpectConsistent(r);
  // With the exact model and the true CBF, h(s') >= (1 - k dt) h(s) >= 0 holds at every step.
  EXPECT_EQ(r.dangerous_episodes, 0);
  EXPECT_EQ(r.unsafe_state_episodes, 0);
  EXPECT_EQ(r.unsafe_state_steps, 0);
  EXPECT_EQ(r.no_safe_action_decisions, 0);
  EXPECT_EQ(r.invalid_input_decisions, 0);
  EXPECT_GE(r.success_episodes, 80) << r.Table();
  EXPECT_GT(r.interventions, 0);  // the shield had to act: the goal is behind the obstacle
}

TEST(DoubleIntegratorShieldRunTest, UnshieldedBaselineCollides) {
  const ShieldRunOptions options = FastOptions();
  domains::double_integrator::GroundTruthBarrier barrier(options.task.truth);
  const ShieldRunResult r = RunDoubleIntegratorShield(options, barrier, /*shielded=*/false);
  ExpectConsistent(r);
  // The task tests safety: without the shield most episodes end in the obstacle.
  EXPECT_GE(r.dangerous_episodes, 50) << r.Table();
  EXPECT_GE(r.unsafe_state_episodes, r.dangerous_episodes);
  EXPECT_EQ(r.barrier, "none");
}

TEST(DoubleIntegratorShieldRunTest, SameSeedSameResult) {
  ShieldRunOptions options = FastOptions(30);
  domains::double_integrator::GroundTruthBarrier barrier(options.task.truth);
  auto without_timing = [](const ShieldRunResult& r) {
    nlohmann::json j = r.ToJson();
    j.erase("latency_us");
    j.erase("seconds");
    return j;
  };
  const nlohmann::json a = without_timing(RunDoubleIntegratorShield(options, barrier));
  const nlohmann::json b = without_timing(RunDoubleIntegratorShield(options, barrier));
  EXPECT_EQ(a, b);
  options.seed = 8;
  const nlohmann::json c = without_timing(RunDoubleIntegratorShield(options, barrier));
  EXPECT_NE(a["steps"], c["steps"]);
  // The unshielded baseline too.
  options.seed = 7;
  EXPECT_EQ(without_timing(RunDoubleIntegratorShield(options, barrier, false)),
            without_timing(RunDoubleIntegratorShield(options, barrier, false)));
}

TEST(DoubleIntegratorShieldRunTest, JsonHasTheDocumentedKeys) {
  const ShieldRunOptions options = FastOptions(3);
  domains::double_integrator::GroundTruthBarrier barrier(options.task.truth);
  const ShieldRunResult r = RunDoubleIntegratorShield(options, barrier);
  const nlohmann::json j = r.ToJson();
  for (const char* key :
       {"episodes", "dangerous_episodes", "success_episodes", "timeout_episodes",
        "unsafe_state_episodes", "unsafe_state_steps", "steps", "decisions", "interventions",
        "mean_interventions_per_episode", "no_safe_action_decisions", "invalid_input_decisions",
        "latency_us", "seconds", "options", "barrier", "shielded"})
    EXPECT_TRUE(j.contains(key)) << key;
  for (const char* key : {"p50", "p90", "p99", "max"})
    EXPECT_TRUE(j["latency_us"].contains(key)) << key;
  EXPECT_EQ(j["episodes"], 3);
  EXPECT_EQ(j["options"]["shield"]["num_samples"], 64);
  const std::string table = r.Table();
  EXPECT_HAS(table, "| metric | value |");
  EXPECT_HAS(table, "dangerous");
  EXPECT_HAS(table, "latency");
}

TEST(DoubleIntegratorShieldRunTest, ValidateNamesTheField) {
  const ShieldRunOptions good;
  good.Validate();
  auto error_with = [&](auto mutate) {
    ShieldRunOptions o = good;
    mutate(o);
    return ErrorOf([&] { o.Validate(); });
  };
  EXPECT_HAS(error_with([](ShieldRunOptions& o) { o.episodes = 0; }),
             "ShieldRunOptions::episodes = 0, must be > 0");
  EXPECT_HAS(error_with([](ShieldRunOptions& o) { o.task.max_steps = -1; }),
             "ReachAvoidOptions::max_steps = -1");
  EXPECT_HAS(error_with([](ShieldRunOptions& o) { o.task.goal_x = o.task.goal_y = 5.5; }),
             "ReachAvoidOptions::goal = (5.5, 5.5)");
  EXPECT_HAS(error_with([](ShieldRunOptions& o) { o.task.start_hi = 0.0; }),
             "ReachAvoidOptions::start_lo, start_hi");
  EXPECT_HAS(error_with([](ShieldRunOptions& o) { o.policy_sigma = -0.1; }),
             "ShieldRunOptions::policy_sigma = -0.1");
  EXPECT_HAS(error_with([](ShieldRunOptions& o) { o.task.accel_bound = 0; }),
             "ReachAvoidOptions::accel_bound = 0");
  EXPECT_HAS(error_with([](ShieldRunOptions& o) { o.task.truth.radius = -2; }),
             "ReachAvoidOptions::truth.radius = -2");
  EXPECT_HAS(error_with([](ShieldRunOptions& o) { o.task.dt = 0.05; }),
             "ShieldRunOptions::shield.dt = 0.1, must be equal to task.dt = 0.05");
  EXPECT_HAS(error_with([](ShieldRunOptions& o) { o.shield.num_samples = 0; }),
             "ShieldOptions::num_samples = 0");
  // RunDoubleIntegratorShield validates too.
  ShieldRunOptions bad = good;
  bad.kp = 0;
  domains::double_integrator::GroundTruthBarrier barrier(good.task.truth);
  EXPECT_HAS(ErrorOf([&] { RunDoubleIntegratorShield(bad, barrier); }), "ShieldRunOptions::kp");
}

TEST(DoubleIntegratorShieldRunTest, ImpossibleSizesAreRejectedByValidate) {
  ShieldRunOptions o;
  o.episodes = 2147483648L;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }),
             "ShieldRunOptions::episodes = 2147483648, must be in [1, 1000000]");
  o = ShieldRunOptions{};
  o.shield.num_samples = 2000000000;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }),
             "ShieldOptions::num_samples = 2000000000, must be in [1, 1000000]");
  o = ShieldRunOptions{};
  o.shield.num_probes = 1000001;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "ShieldOptions::num_probes = 1000001");
}

TEST(DoubleIntegratorShieldRunTest, TableSaysNotApplicableWithoutASuccess) {
  ShieldRunOptions o;
  o.episodes = 2;
  o.task.max_steps = 3;  // too short to reach the goal
  domains::double_integrator::GroundTruthBarrier barrier(o.task.truth);
  const ShieldRunResult r = RunDoubleIntegratorShield(o, barrier);
  ASSERT_EQ(r.success_episodes, 0);
  EXPECT_HAS(r.Table(), "| mean steps to goal | n/a (no successful episode) |");
  EXPECT_EQ(r.Table().find("nan"), std::string::npos) << r.Table();
}

TEST(DoubleIntegratorShieldRunTest, StartRegionWithoutSafeStatesIsAnError) {
  ShieldRunOptions options = FastOptions(1);
  options.task.start_lo = 4.5;  // entirely inside the obstacle
  options.task.start_hi = 5.5;
  domains::double_integrator::GroundTruthBarrier barrier(options.task.truth);
  EXPECT_HAS(ErrorOf([&] { RunDoubleIntegratorShield(options, barrier); }), "no start state");
}

TEST(DoubleIntegratorShieldRunTest, RandomLearnedBarrierRunsAndCountsAddUp) {
  // An untrained network: not a CBF at all, so no safety claim, only a well-formed run.
  cbf::BarrierNet net;
  net.mlp = nn::RandomMlpParams(nn::MlpSpec{4, {16, 16}, 1, nn::Activation::kTanh}, 11);
  Eigen::MatrixXf samples = Eigen::MatrixXf::Random(4, 100);
  samples.topRows(2) = (samples.topRows(2).array() + 1.0f) * 5.0f;  // x, y in [0, 10]
  samples.bottomRows(2) *= 1.5f;
  net.normalizer = nn::Normalizer::Fit(samples);
  net.features = domains::double_integrator::StateFeatures();
  net.Validate();
  const auto barrier = net.MakeEvaluator();
  const ShieldRunOptions options = FastOptions(20);
  const ShieldRunResult r = RunDoubleIntegratorShield(options, *barrier);
  ExpectConsistent(r);
  EXPECT_EQ(r.episodes, 20);
  EXPECT_EQ(r.invalid_input_decisions, 0);
  EXPECT_HAS(r.barrier, "barrier_mlp");
}

TEST(DoubleIntegratorShieldRunTest, BarrierOfTheWrongDimensionIsAnError) {
  cbf::BarrierNet net;
  net.mlp = nn::RandomMlpParams(nn::MlpSpec{3, {4}, 1, nn::Activation::kTanh}, 1);
  net.normalizer = nn::Normalizer::Identity(3);
  net.features = {"a", "b", "c"};
  const auto barrier = net.MakeEvaluator();
  EXPECT_HAS(ErrorOf([&] { RunDoubleIntegratorShield(FastOptions(1), *barrier); }),
             "3-dimensional states");
  // Unshielded, the barrier is not used.
  EXPECT_EQ(RunDoubleIntegratorShield(FastOptions(1), *barrier, false).episodes, 1);
}

// The counts of the hand-written episode loop this run had before it ran on eval::EpisodeRunner
// (the same episodes: the same streams, start states, policy, crash rule and counting), with the
// actuator box ignored as it was then; and with the box (action_bounds = clip, the default since
// 2026-12-03): the same counts, since the double integrator's shield model clips as its actuator
// does (the box changes no check, and the environment clipped the decisions before).
TEST(DoubleIntegratorShieldRunTest, ResultsOfTheFormerEpisodeLoopArePinned) {
  ShieldRunOptions options = FastOptions();
  domains::double_integrator::GroundTruthBarrier barrier(options.task.truth);
  for (shield::ActionBounds bounds : {shield::ActionBounds::kIgnore, shield::ActionBounds::kClip}) {
    SCOPED_TRACE(ToString(shield::kActionBoundsNames, bounds));
    options.shield.action_bounds = bounds;
    const ShieldRunResult s = RunDoubleIntegratorShield(options, barrier);
    EXPECT_EQ(s.success_episodes, 100);
    EXPECT_EQ(s.steps, 18486);
    EXPECT_EQ(s.interventions, 9643);
    EXPECT_EQ(s.resampled_decisions, 8999);
  }
  const ShieldRunResult u = RunDoubleIntegratorShield(options, barrier, /*shielded=*/false);
  EXPECT_EQ(u.dangerous_episodes, 100);  // every episode ends at its crash
  EXPECT_EQ(u.steps, 2010);
  EXPECT_EQ(u.unsafe_state_steps, 1187);
  EXPECT_EQ(u.unsafe_state_episodes, 100);
}

TEST(DoubleIntegratorShieldRunTest, OptionsJsonKeepsItsKeys) {
  const nlohmann::json j = ShieldRunOptions{}.ToJson();
  for (const char* key :
       {"obstacle", "radius", "gamma", "goal", "goal_radius", "start_region", "start_speed",
        "start_clearance", "episodes", "max_steps", "dt", "accel_bound", "kp", "kd", "policy_sigma",
        "brake_gain", "shield", "seed"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j.size(), 18u) << j.dump();
  EXPECT_EQ(j["max_steps"], 300);
  EXPECT_EQ(j["episodes"], 1000);
}

TEST(DoubleIntegratorShieldRunTest, PdPolicyIsClippedWithFixedSigma) {
  ShieldRunOptions o;
  o.policy_sigma = 0.2;
  PdEpisodePolicy pd(o);
  Eigen::VectorXf mu(2);
  pd.Mean(Eigen::Vector4f(8.5f, 6.5f, 0.0f, 1.0f), mu);
  EXPECT_FLOAT_EQ(mu[0], 0.0f);                 // at the goal's x, at rest
  EXPECT_FLOAT_EQ(mu[1], 0.25f * 2.0f - 1.0f);  // kp (g - p) - kd v
  pd.Mean(Eigen::Vector4f(-100.0f, 8.5f, 0.0f, 0.0f), mu);
  EXPECT_FLOAT_EQ(mu[0], 3.0f);  // clipped to the acceleration bound
  EXPECT_EQ(pd.sigma(), Eigen::VectorXf::Constant(2, 0.2f));
  EXPECT_HAS(ErrorOf([&] { pd.Mean(Eigen::VectorXf::Zero(3), mu); }), "expected 4/2");
}

TEST(LatencySummaryTest, NearestRank) {
  std::vector<double> values;
  for (int i = 100; i >= 1; --i) values.push_back(i);  // unsorted on purpose
  const LatencySummary s = LatencySummary::Of(values);
  EXPECT_EQ(s.count, 100);
  EXPECT_EQ(s.p50, 50);
  EXPECT_EQ(s.p90, 90);
  EXPECT_EQ(s.p99, 99);
  EXPECT_EQ(s.max, 100);
  EXPECT_DOUBLE_EQ(s.mean, 50.5);
  const std::vector<double> four{1, 2, 3, 4};
  EXPECT_EQ(NearestRankPercentile(four, 50), 2);
  EXPECT_EQ(NearestRankPercentile(four, 51), 3);
  EXPECT_EQ(NearestRankPercentile(four, 90), 4);
  EXPECT_EQ(NearestRankPercentile({7.0}, 1), 7);
  EXPECT_EQ(LatencySummary::Of({}).count, 0);
  EXPECT_EQ(LatencySummary::Of({}).p99, 0);
  EXPECT_HAS(ErrorOf([] { NearestRankPercentile({}, 50); }), "no values");
  EXPECT_HAS(ErrorOf([&] { NearestRankPercentile(four, 0); }), "percent = 0");
}

}  // namespace
}  // namespace secure::eval
