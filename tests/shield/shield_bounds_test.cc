// The actuator box (Shield::SetActionBounds, ShieldOptions::action_bounds): every decision lies in
// it, samples outside it are clipped or rejected, and Decision::bounded says when it cut in.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <yaml-cpp/yaml.h>

#include "domains/double_integrator/double_integrator.h"
#include "domains/double_integrator/ground_truth_barrier.h"
#include "domains/double_integrator/reach_avoid.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"
#include "tests/test_util.h"

namespace secure::shield {
namespace {

using secure::test::ErrorOf;
using test::BitEqual;
using test::FirstRound;
using test::FunctionBarrier;
using test::IntegratorDynamics;
using test::Vec;
namespace di = domains::double_integrator;

constexpr float kInf = std::numeric_limits<float>::infinity();

bool InBox(const Eigen::VectorXf& a, const Eigen::VectorXf& low, const Eigen::VectorXf& high) {
  return ((a.array() >= low.array()) && (a.array() <= high.array())).all();
}



/// 1-D: x' = x + 0.1 a, h(x) = 1 - x; at x = 0 with dt = 0.1 and k = 1 an action is safe iff
/// a <= 1.
struct HalfLine {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "1 - x",
                          [](const Eigen::Ref<const Eigen::VectorXf>& s) { return 1.0 - s[0]; }};
};

/// 1-D: h(x) = -1 - x^2 < 0 everywhere; at x = 0, g(a) = -0.1 a^2 - 1 < 0, largest at a = 0.
struct NowhereSafe {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "-1 - x^2", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            return -1.0 - static_cast<double>(s[0]) * s[0];
                          }};
};

TEST(ShieldBoundsTest, BuiltinDoubleIntegratorDecisionStaysInsideTheActuatorBox) {
  // Python users met this one: decide([3, 3, 1, 1], mu = [3, 3]) with the double integrator's
  // clipped model returned (-6.80, -6.26) with a box of |a| <= 3.
  const di::GroundTruth truth;
  di::GroundTruthBarrier barrier(truth);
  di::ClippedDoubleIntegrator model(0.1, 3.0);
  const Eigen::VectorXf state = Vec({3.0f, 3.0f, 1.0f, 1.0f}), mu = Vec({3.0f, 3.0f});
  const Eigen::VectorXf sigma = Vec({1.0f, 1.0f});
  const Eigen::VectorXf low = Vec({-3.0f, -3.0f}), high = Vec({3.0f, 3.0f});
  for (ActionBounds mode : {ActionBounds::kClip, ActionBounds::kReject}) {
    SCOPED_TRACE(ToString(kActionBoundsNames, mode));
    int bounded = 0;
    for (std::uint64_t seed = 0; seed < 20; ++seed) {
      ShieldOptions options;
      options.seed = seed;
      options.action_bounds = mode;
      Shield shield(options, barrier, model);
      shield.SetActionBounds(low, high);
      const Decision& d = shield.Decide(state, mu, sigma);
      EXPECT_TRUE(InBox(d.action, low, high)) << d.action.transpose();
      EXPECT_TRUE(d.safe()) << d.ToJson().dump();
      // The condition holds for the action returned, i.e. the one the actuator applies.
      Eigen::MatrixXf column = d.action;
      Eigen::VectorXd g(1);
      shield.EvaluateG(state, shield.EvaluateH(state), column, g);
      EXPECT_EQ(g[0], d.g);
      if (d.bounded) ++bounded;
    }
    EXPECT_GT(bounded, 0);  // mu sits on the box's corner: about half of the draws leave it
  }
}

TEST(ShieldBoundsTest, ClipChecksSamplesAsAppliedAndClipsTheirMean) {
  HalfLine sys;
  const Eigen::VectorXf mu = Vec({0.6f}), sigma = Vec({1.0f});
  const Eigen::VectorXf low = Vec({-0.5f}), high = Vec({0.5f});
  ShieldOptions options;
  options.seed = 7;
  Shield shield(options, sys.barrier, sys.dynamics);
  shield.SetActionBounds(low, high);
  const Decision& d = shield.Decide(Vec({0.0f}), mu, sigma);
  // Every sample is safe as applied (clipped: a <= 0.5 < 1), although some drawn ones exceed 1:
  // one round, the mean of the drawn samples, clipped onto the box.
  const Eigen::MatrixXf samples = FirstRound(options.seed, mu, sigma, options.num_samples);
  ASSERT_GT(samples.maxCoeff(), 1.0f);
  EXPECT_EQ(d.status, Status::kSafe);
  EXPECT_EQ(d.safe_ratio, 1.0);
  EXPECT_TRUE(d.bounded);
  EXPECT_NEAR(d.action[0], std::clamp(samples.rowwise().mean()[0], -0.5f, 0.5f), 1e-6);
  EXPECT_TRUE(InBox(d.action, low, high));
}

TEST(ShieldBoundsTest, ClipIsTheUnboundedDecisionClippedWhereTheModelClips) {
  // The double integrator's shield model clips as its actuator does: g(a) = g(clip(a)), so the
  // box changes no check, and each decision is the unbounded one clipped (same draws, same g).
  const di::GroundTruth truth;
  di::GroundTruthBarrier barrier(truth);
  di::ClippedDoubleIntegrator model(0.1, 3.0);
  const Eigen::VectorXf low = Vec({-3.0f, -3.0f}), high = Vec({3.0f, 3.0f});
  int moved = 0;
  for (Aggregation aggregation :
       {Aggregation::kMean, Aggregation::kPolicyMean, Aggregation::kPolicyDraw,
        Aggregation::kRandomSafe}) {
    for (std::uint64_t seed = 0; seed < 40; ++seed) {
      ShieldOptions options;
      options.seed = seed;
      options.aggregation = aggregation;
      Shield free_shield(options, barrier, model);
      Shield shield(options, barrier, model);
      shield.SetActionBounds(low, high);
      // Near the obstacle (draws beyond the box often unsafe) and far from it (often safe).
      const Eigen::VectorXf state = seed < 20 ? Vec({3.0f + 0.1f * seed, 3.0f, 1.0f, 1.0f})
                                              : Vec({0.5f + 0.05f * seed, 1.0f, 0.0f, 0.0f});
      const Eigen::VectorXf mu = Vec({3.0f, 2.5f}), sigma = Vec({2.0f, 2.0f});
      const Decision free_decision = free_shield.Decide(state, mu, sigma);
      const Decision& d = shield.Decide(state, mu, sigma);
      EXPECT_TRUE(BitEqual(d.action, free_decision.action.cwiseMax(low).cwiseMin(high)))
          << d.action.transpose() << " vs " << free_decision.action.transpose();
      EXPECT_EQ(d.g, free_decision.g);
      EXPECT_EQ(d.status, free_decision.status);
      EXPECT_EQ(d.iterations, free_decision.iterations);
      if (!InBox(free_decision.action, low, high)) ++moved;
    }
  }
  EXPECT_GT(moved, 0);  // the unbounded shield left the box, and the box brought it back
}

TEST(ShieldBoundsTest, RejectCountsSamplesOutsideTheBoxAsUnsafe) {
  HalfLine sys;
  const Eigen::VectorXf mu = Vec({0.0f}), sigma = Vec({1.0f});
  const Eigen::VectorXf low = Vec({-0.5f}), high = Vec({0.5f});
  ShieldOptions options;
  options.seed = 11;
  options.action_bounds = ActionBounds::kReject;
  Shield shield(options, sys.barrier, sys.dynamics);
  shield.SetActionBounds(low, high);
  const Decision& d = shield.Decide(Vec({0.0f}), mu, sigma);
  const Eigen::MatrixXf samples = FirstRound(options.seed, mu, sigma, options.num_samples);
  int inside = 0;
  double sum = 0.0;
  for (Eigen::Index c = 0; c < samples.cols(); ++c) {
    if (std::abs(samples(0, c)) <= 0.5f) {
      ++inside;
      sum += samples(0, c);
    }
  }
  ASSERT_GT(inside, options.safe_ratio * options.num_samples);  // one round is enough
  ASSERT_LT(inside, options.num_samples);
  EXPECT_EQ(d.status, Status::kSafe);
  EXPECT_EQ(d.safe_ratio, static_cast<double>(inside) / options.num_samples);
  EXPECT_TRUE(d.bounded);
  EXPECT_NEAR(d.action[0], sum / inside, 1e-6);  // the mean of the samples inside the box
  EXPECT_TRUE(InBox(d.action, low, high));
}

TEST(ShieldBoundsTest, PolicyMeanOutsideTheBoxIsCheckedAndReturnedClipped) {
  HalfLine sys;
  const Eigen::VectorXf sigma = Vec({0.3f});
  ShieldOptions options;
  options.aggregation = Aggregation::kPolicyMean;
  {
    // mu = 0.8 is safe but outside [-0.5, 0.5]: the actuator would apply 0.5, which is safe.
    Shield shield(options, sys.barrier, sys.dynamics);
    shield.SetActionBounds(Vec({-0.5f}), Vec({0.5f}));
    const Decision& d = shield.Decide(Vec({0.0f}), Vec({0.8f}), sigma);
    EXPECT_EQ(d.status, Status::kSafe);
    EXPECT_EQ(d.action[0], 0.5f);
    EXPECT_TRUE(d.bounded);
    EXPECT_FALSE(d.intervened);  // the box, not the barrier, moved it
    EXPECT_NEAR(d.distance_to_mean, 0.3, 1e-6);
  }
  {
    // mu = 2 in a box of [-3, 3] is unsafe (a <= 1): Algorithm 1 decides, inside the box.
    Shield shield(options, sys.barrier, sys.dynamics);
    shield.SetActionBounds(Vec({-3.0f}), Vec({3.0f}));
    const Decision& d = shield.Decide(Vec({0.0f}), Vec({2.0f}), Vec({1.0f}));
    EXPECT_TRUE(d.safe());
    EXPECT_TRUE(d.intervened);
    EXPECT_LE(d.action[0], 1.0f);
    EXPECT_GE(d.action[0], -3.0f);
  }
}

TEST(ShieldBoundsTest, PolicyDrawOutsideTheBoxIsNeverReturnedUnderReject) {
  HalfLine sys;
  const Eigen::VectorXf mu = Vec({0.0f}), sigma = Vec({1.0f});
  ShieldOptions options;
  options.aggregation = Aggregation::kPolicyDraw;
  options.action_bounds = ActionBounds::kReject;
  int outside_draws = 0;
  for (std::uint64_t seed = 0; seed < 40; ++seed) {
    options.seed = seed;
    Shield shield(options, sys.barrier, sys.dynamics);
    shield.SetActionBounds(Vec({-0.5f}), Vec({0.5f}));
    const Decision& d = shield.Decide(Vec({0.0f}), mu, sigma);
    const float draw = FirstRound(seed, mu, sigma, 1)(0, 0);
    if (std::abs(draw) > 0.5f) {
      ++outside_draws;
      EXPECT_NE(d.action[0], draw);
      EXPECT_TRUE(d.bounded);
    } else {
      EXPECT_EQ(d.action[0], draw);  // a safe draw inside the box is the decision
      EXPECT_FALSE(d.bounded);
    }
    EXPECT_LE(std::abs(d.action[0]), 0.5f);
  }
  EXPECT_GT(outside_draws, 0);
}

TEST(ShieldBoundsTest, FallbacksStayInTheBox) {
  NowhereSafe sys;
  // The largest g is at a = 0, outside the box [0.5, 1]: the fallback is the best action inside.
  const Eigen::VectorXf low = Vec({0.5f}), high = Vec({1.0f});
  for (ActionBounds mode : {ActionBounds::kClip, ActionBounds::kReject}) {
    for (Resampling resampling : {Resampling::kAdaptive, Resampling::kNone}) {
      for (float mu : {-3.0f, 0.0f, 0.7f}) {
        SCOPED_TRACE(std::string(ToString(kActionBoundsNames, mode)) + " " +
                     ToString(kResamplingNames, resampling) + " mu " + std::to_string(mu));
        ShieldOptions options;
        options.action_bounds = mode;
        options.resampling = resampling;
        options.max_iterations = 3;
        Shield shield(options, sys.barrier, sys.dynamics);
        shield.SetActionBounds(low, high);
        const Decision& d = shield.Decide(Vec({0.0f}), Vec({mu}), Vec({0.1f}));
        EXPECT_EQ(d.status, Status::kNoSafeAction);
        EXPECT_TRUE(InBox(d.action, low, high)) << d.action.transpose();
        EXPECT_TRUE(std::isfinite(d.g));
        // Its g is that of the action returned.
        Eigen::MatrixXf column = d.action;
        Eigen::VectorXd g(1);
        shield.EvaluateG(Vec({0.0f}), d.h, column, g);
        EXPECT_EQ(g[0], d.g);
      }
    }
  }
}

TEST(ShieldBoundsTest, UnboundedComponentsAreLeftAlone) {
  HalfLine sys;
  ShieldOptions options;
  options.seed = 3;
  Shield free_shield(options, sys.barrier, sys.dynamics);
  const Decision free_decision = free_shield.Decide(Vec({0.0f}), Vec({-2.0f}), Vec({1.0f}));
  Shield shield(options, sys.barrier, sys.dynamics);
  shield.SetActionBounds(Vec({-kInf}), Vec({kInf}));
  const Decision& d = shield.Decide(Vec({0.0f}), Vec({-2.0f}), Vec({1.0f}));
  EXPECT_TRUE(BitEqual(d.action, free_decision.action));
  EXPECT_FALSE(d.bounded);
}

TEST(ShieldBoundsTest, IgnoreDecidesAsWithoutABox) {
  HalfLine sys;
  for (Aggregation aggregation : {Aggregation::kMean, Aggregation::kPolicyMean}) {
    ShieldOptions options;
    options.seed = 5;
    options.aggregation = aggregation;
    options.action_bounds = ActionBounds::kIgnore;
    Shield free_shield(options, sys.barrier, sys.dynamics);
    const Decision free_decision = free_shield.Decide(Vec({0.0f}), Vec({0.8f}), Vec({1.0f}));
    Shield shield(options, sys.barrier, sys.dynamics);
    shield.SetActionBounds(Vec({-0.5f}), Vec({0.5f}));
    EXPECT_FALSE(shield.bounds_active());
    const Decision& d = shield.Decide(Vec({0.0f}), Vec({0.8f}), Vec({1.0f}));
    EXPECT_TRUE(BitEqual(d.action, free_decision.action));
    EXPECT_EQ(d.g, free_decision.g);
    EXPECT_FALSE(d.bounded);
  }
}

TEST(ShieldBoundsTest, SetActionBoundsRejectsBadBoxesAndBackupsOutside) {
  HalfLine sys;
  Shield shield(ShieldOptions{}, sys.barrier, sys.dynamics);
  EXPECT_HAS(ErrorOf([&] { shield.SetActionBounds(Vec({-1.0f, -1.0f}), Vec({1.0f, 1.0f})); }),
             "action bounds have 2 and 2 values, expected 1");
  EXPECT_HAS(ErrorOf([&] { shield.SetActionBounds(Vec({1.0f}), Vec({-1.0f})); }),
             "action bounds [1, -1] of action 0: need low <= high");
  EXPECT_HAS(ErrorOf([&] {
               shield.SetActionBounds(Vec({std::numeric_limits<float>::quiet_NaN()}), Vec({1.0f}));
             }),
             "no NaN");
  shield.SetBackupAction(Vec({2.0f}));
  EXPECT_HAS(ErrorOf([&] { shield.SetActionBounds(Vec({-1.0f}), Vec({1.0f})); }),
             "the backup action[0] = 2 lies outside the action bounds [-1, 1]");
  shield.ClearBackupAction();
  shield.SetActionBounds(Vec({-1.0f}), Vec({1.0f}));
  EXPECT_HAS(ErrorOf([&] { shield.SetBackupAction(Vec({-1.5f})); }),
             "backup action[0] = -1.5 lies outside the action bounds [-1, 1]");
  shield.SetBackupAction(Vec({1.0f}));  // on the boundary: inside
  EXPECT_TRUE(shield.has_action_bounds());
}

TEST(ShieldBoundsTest, EnvironmentGivesItsActuatorBox) {
  di::ReachAvoidOptions task;
  task.accel_bound = 2.5;
  di::ReachAvoidEnv env(task);
  di::GroundTruthBarrier barrier{di::GroundTruth{}};
  Shield shield(ShieldOptions{}, barrier, env.ShieldModel());
  shield.SetActionBounds(env);
  EXPECT_EQ(shield.action_low(), Vec({-2.5f, -2.5f}));
  EXPECT_EQ(shield.action_high(), Vec({2.5f, 2.5f}));
}

TEST(ShieldBoundsTest, OptionRoundTripsThroughYamlAndJson) {
  ShieldOptions options;
  EXPECT_EQ(options.ToJson()["action_bounds"], "clip");
  options.ApplyYaml(YAML::Load("{action_bounds: reject}"), "test.yaml");
  EXPECT_EQ(options.action_bounds, ActionBounds::kReject);
  EXPECT_EQ(options.ToJson()["action_bounds"], "reject");
  EXPECT_HAS(ErrorOf([&] { options.ApplyYaml(YAML::Load("{action_bounds: wrap}"), "test.yaml"); }),
             "action_bounds");
}

}  // namespace
}  // namespace secure::shield
