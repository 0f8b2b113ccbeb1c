// Tests of the reach-avoid task (ReachAvoidEnv, its options) and ClippedDoubleIntegrator.

#include "domains/double_integrator/reach_avoid.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"

namespace secure::domains::double_integrator {
namespace {

using secure::test::ErrorOf;

// ---------------------------------------------------------------------------------------------
// ClippedDoubleIntegrator

TEST(ClippedDoubleIntegratorTest, ClipsThenStepsExactly) {
  const ClippedDoubleIntegrator env(0.1, 3.0);
  const Dynamics exact(0.1);
  const Eigen::Vector4f s(1.0f, 2.0f, 0.5f, -0.5f);
  // 150 columns: more than one internal chunk.
  Eigen::MatrixXf actions = Eigen::MatrixXf::Random(2, 150) * 6.0f;
  Eigen::MatrixXf clipped = actions.cwiseMax(-3.0f).cwiseMin(3.0f);
  Eigen::MatrixXf got(4, 150), want(4, 150);
  env.Step(s, actions, got);
  exact.Step(s, clipped, want);
  EXPECT_EQ(got, want);
  EXPECT_NE(clipped, actions);  // some were clipped
  EXPECT_HAS(env.Describe(), "clipped");
  EXPECT_EQ(env.dt(), 0.1);
  EXPECT_EQ(env.accel_bound(), 3.0);
  EXPECT_HAS(ErrorOf([] { ClippedDoubleIntegrator(0.1, 0.0); }), "accel_bound = 0");
  EXPECT_HAS(ErrorOf([] { ClippedDoubleIntegrator(-1.0, 3.0); }), "dt = -1");
}

// ---------------------------------------------------------------------------------------------
// ReachAvoidOptions

TEST(ReachAvoidOptionsTest, DefaultsAreTheDocumentedTask) {
  const ReachAvoidOptions o;
  EXPECT_NO_THROW(o.Validate());
  EXPECT_EQ(o.truth.obstacle_x, 5.0);
  EXPECT_EQ(o.truth.radius, 2.0);
  EXPECT_EQ(o.goal_x, 8.5);
  EXPECT_EQ(o.goal_y, 8.5);
  EXPECT_EQ(o.goal_radius, 0.3);
  EXPECT_EQ(o.start_lo, 0.5);
  EXPECT_EQ(o.start_hi, 3.0);
  EXPECT_EQ(o.dt, 0.1);
  EXPECT_EQ(o.accel_bound, 3.0);
  EXPECT_EQ(o.max_steps, 300);
  // Every straight line from the start square to the goal passes the obstacle within 0.91 of its
  // centre: the corners (0.5, 3) and (3, 0.5) are the worst, at distance 2.5 / sqrt(2) * ...
  // computed here as the distance of the centre from the segment (0.5, 3) -> (8.5, 8.5).
  const Eigen::Vector2d a(0.5, 3.0), b(8.5, 8.5), c(5.0, 5.0);
  const double t = (c - a).dot(b - a) / (b - a).squaredNorm();
  EXPECT_LT((a + t * (b - a) - c).norm(), 0.91);
}

TEST(ReachAvoidOptionsTest, ValidateNamesFieldValueAndRule) {
  auto error_of = [](auto&& breaker) {
    ReachAvoidOptions o;
    breaker(o);
    return ErrorOf([&] { o.Validate(); });
  };
  EXPECT_HAS(error_of([](ReachAvoidOptions& o) { o.goal_radius = 0; }),
             "ReachAvoidOptions::goal_radius = 0, must be > 0");
  EXPECT_HAS(error_of([](ReachAvoidOptions& o) { o.max_steps = -3; }),
             "ReachAvoidOptions::max_steps = -3, must be > 0");
  EXPECT_HAS(error_of([](ReachAvoidOptions& o) { o.dt = std::nan(""); }),
             "ReachAvoidOptions::dt = nan");
  EXPECT_HAS(error_of([](ReachAvoidOptions& o) { o.accel_bound = -1; }),
             "ReachAvoidOptions::accel_bound = -1");
  EXPECT_HAS(error_of([](ReachAvoidOptions& o) { o.start_hi = 0.5; }),
             "ReachAvoidOptions::start_lo, start_hi = 0.5, 0.5");
  EXPECT_HAS(error_of([](ReachAvoidOptions& o) { o.truth.radius = 0; }),
             "ReachAvoidOptions::truth.radius = 0");
  EXPECT_HAS(error_of([](ReachAvoidOptions& o) { o.goal_x = o.goal_y = 6.0; }),
             "ReachAvoidOptions::goal = (6, 6), must be at least radius + goal_radius");
  EXPECT_HAS(ErrorOf([] {
               ReachAvoidOptions o;
               o.brake_gain = -1;
               ReachAvoidEnv env(o);
             }),
             "brake_gain = -1");
}

TEST(ReachAvoidOptionsTest, JsonAndYamlUseTheSameKeys) {
  ReachAvoidOptions o;
  const nlohmann::json j = o.ToJson();
  for (const char* key :
       {"obstacle", "radius", "gamma", "goal", "goal_radius", "start_region", "start_speed",
        "start_clearance", "dt", "accel_bound", "brake_gain", "max_steps"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["goal"], nlohmann::json({8.5, 8.5}));

  // The JSON of the defaults, read as YAML, reproduces the defaults; overrides apply.
  ReachAvoidOptions back;
  back.max_steps = 1;
  back.ApplyYaml(YAML::Load(j.dump()), "j");
  EXPECT_EQ(back.ToJson(), j);
  back.ApplyYaml(YAML::Load("{goal: [7, 8], max_steps: 50, radius: 1.5, start_region: [1, 2]}"),
                 "y");
  EXPECT_EQ(back.goal_x, 7.0);
  EXPECT_EQ(back.goal_y, 8.0);
  EXPECT_EQ(back.max_steps, 50);
  EXPECT_EQ(back.truth.radius, 1.5);
  EXPECT_EQ(back.start_lo, 1.0);
  EXPECT_EQ(back.start_hi, 2.0);

  EXPECT_HAS(ErrorOf([&] { back.ApplyYaml(YAML::Load("{goal_radious: 1}"), "cfg.yaml"); }),
             "cfg.yaml: unknown field 'goal_radious'");
  EXPECT_HAS(ErrorOf([&] { back.ApplyYaml(YAML::Load("{max_steps: lots}"), "cfg.yaml"); }),
             "cfg.yaml: field 'max_steps' has value 'lots', which is not a valid integer");
  EXPECT_HAS(ErrorOf([&] { back.ApplyYaml(YAML::Load("{goal: 3}"), "cfg.yaml"); }),
             "field 'goal' has value '3', must be a list of two numbers");
  EXPECT_HAS(ErrorOf([&] { back.ApplyYaml(YAML::Load("[1, 2]"), "cfg.yaml"); }),
             "expected a mapping");
}

// ---------------------------------------------------------------------------------------------
// ReachAvoidEnv

TEST(ReachAvoidEnvTest, DescribesItselfWithFeatureNames) {
  const ReachAvoidEnv env;
  EXPECT_EQ(env.observation_dim(), 4);
  EXPECT_EQ(env.action_dim(), 2);
  EXPECT_EQ(env.ObservationFeatures(), (std::vector<std::string>{"x", "y", "vx", "vy"}));
  EXPECT_EQ(env.ActionFeatures(), (std::vector<std::string>{"ax", "ay"}));
  EXPECT_EQ(env.max_steps(), 300);
  EXPECT_HAS(env.Describe(), "goal (8.5, 8.5)");
  EXPECT_HAS(env.Describe(), "obstacle (5, 5) r 2");
}

TEST(ReachAvoidEnvTest, ResetDrawsSafeStartsSpreadOverTheStartRegion) {
  ReachAvoidEnv env;
  const ReachAvoidOptions& o = env.options();
  Rng rng(3);
  Eigen::VectorXf s(4);
  Eigen::Vector4f lo = Eigen::Vector4f::Constant(1e9f), hi = -lo;
  for (int i = 0; i < 3000; ++i) {
    env.Reset(rng, s);
    EXPECT_EQ(Eigen::Vector4f(s), env.state());
    ASSERT_GE(s[0], 0.5f);
    ASSERT_LT(s[0], 3.0f);
    ASSERT_GE(s[1], 0.5f);
    ASSERT_LT(s[1], 3.0f);
    ASSERT_LE(std::abs(s[2]), 0.1f);
    ASSERT_LE(std::abs(s[3]), 0.1f);
    ASSERT_GE(o.truth.H(s[0], s[1], s[2], s[3]), 0.0);
    ASSERT_GE(std::hypot(s[0] - 5.0, s[1] - 5.0), 2.5);
    lo = lo.cwiseMin(Eigen::Vector4f(s));
    hi = hi.cwiseMax(Eigen::Vector4f(s));
  }
  // Uniform: the extremes come close to the region's edges.
  EXPECT_LT(lo[0], 0.55f);
  EXPECT_GT(hi[0], 2.95f);
  EXPECT_LT(lo[1], 0.55f);
  EXPECT_GT(hi[1], 2.95f);
  EXPECT_LT(lo[2], -0.09f);
  EXPECT_GT(hi[3], 0.09f);
}

TEST(ReachAvoidEnvTest, StartsRespectTheClearance) {
  // A start region reaching into the obstacle: every start is redrawn until clear.
  ReachAvoidOptions o;
  o.start_lo = 2.0;
  o.start_hi = 5.0;
  o.start_clearance = 0.3;
  Rng rng(4);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector4f s = DrawStartState(o, rng);
    ASSERT_GE(std::hypot(s[0] - 5.0, s[1] - 5.0), 2.3);
    ASSERT_GE(o.truth.H(s[0], s[1], s[2], s[3]), 0.0);
  }
  o.start_lo = 4.0;
  o.start_hi = 6.0;  // entirely inside the obstacle
  EXPECT_HAS(ErrorOf([&] { DrawStartState(o, rng); }), "no start state in [4, 6)^2");
}

TEST(ReachAvoidEnvTest, StepClipsThenStepsExactly) {
  ReachAvoidEnv env;
  const Eigen::Vector4f s(1.0f, 2.0f, 0.5f, -0.5f);
  env.SetState(s);
  Eigen::VectorXf o(4);
  const Eigen::Vector2f action(10.0f, -0.5f);
  env.Step(action, o);
  // x: 1 + 0.05 + 3 * 0.005; vx: 0.5 + 0.3 (clipped to 3); y: 2 - 0.05 - 0.0025; vy: -0.55.
  EXPECT_NEAR(o[0], 1.065, 1e-6);
  EXPECT_NEAR(o[1], 1.9475, 1e-6);
  EXPECT_NEAR(o[2], 0.8, 1e-6);
  EXPECT_NEAR(o[3], -0.55, 1e-6);
  // Bit-identical to the shield's model.
  Eigen::Vector4f want;
  env.ShieldModel().Step(s, action, want);
  EXPECT_EQ(Eigen::Vector4f(o), want);
  EXPECT_EQ(env.state(), want);
  EXPECT_HAS(env.ShieldModel().Describe(), "clipped to [-3, 3]");
}

TEST(ReachAvoidEnvTest, FlagsGoalAndCollisionOfTheNewState) {
  ReachAvoidEnv env;
  Eigen::VectorXf o(4);
  const Eigen::Vector2f zero(0.0f, 0.0f);

  env.SetState(Eigen::Vector4f(8.5f, 8.3f, 0.0f, 0.0f));  // 0.2 from the goal, at rest
  StepOutcome out = env.Step(zero, o);
  EXPECT_TRUE(out.reached_goal);
  EXPECT_FALSE(out.collided);
  EXPECT_EQ(out.collisions, 0);

  env.SetState(Eigen::Vector4f(8.5f, 8.1f, 0.0f, 0.0f));  // 0.4 from the goal
  EXPECT_FALSE(env.Step(zero, o).reached_goal);
  // Moving 1.5 per second toward the goal: 8.1 + 0.15 = 8.25, now 0.25 from it.
  env.SetState(Eigen::Vector4f(8.5f, 8.1f, 0.0f, 1.5f));
  EXPECT_TRUE(env.Step(zero, o).reached_goal);

  // 0.05 outside the obstacle, moving in at 1: the new state is 0.05 inside.
  env.SetState(Eigen::Vector4f(5.0f, 2.95f, 0.0f, 1.0f));
  out = env.Step(zero, o);
  EXPECT_TRUE(out.collided);
  EXPECT_EQ(out.collisions, 1);
  EXPECT_FALSE(out.reached_goal);
  // The next step still inside: collided, but no new collision (the contact goes on).
  out = env.Step(zero, o);
  EXPECT_TRUE(out.collided);
  EXPECT_EQ(out.collisions, 0);
  // Still inside and moving out: every step inside is flagged; SetState inside the obstacle is a
  // contact under way, so no new collision either.
  env.SetState(Eigen::Vector4f(5.0f, 3.1f, 0.0f, -0.5f));
  out = env.Step(zero, o);
  EXPECT_TRUE(out.collided);
  EXPECT_EQ(out.collisions, 0);
  // Braking down and out (y 3.05 -> 2.985), then pushed back up: the re-entry is a new collision.
  const Eigen::Vector2f down(0.0f, -3.0f), up(0.0f, 3.0f);
  EXPECT_FALSE(env.Step(down, o).collided);
  int steps = 0, collisions = 0;
  for (; steps < 20 && !(out = env.Step(up, o)).collided; ++steps) collisions += out.collisions;
  ASSERT_LT(steps, 20);
  EXPECT_EQ(collisions, 0);
  EXPECT_EQ(out.collisions, 1);
  // Touching is not colliding (strict <), and Step() does not end anything: stepping continues.
  env.SetState(Eigen::Vector4f(5.0f, 7.0f, 0.0f, 0.0f));
  EXPECT_FALSE(env.Step(zero, o).collided);
  EXPECT_FALSE(env.Step(zero, o).collided);
  EXPECT_TRUE(env.InObstacle(5.0, 3.01));
  EXPECT_FALSE(env.InObstacle(5.0, 2.99));
  EXPECT_TRUE(env.InGoal(8.7, 8.5));
  EXPECT_FALSE(env.InGoal(8.81, 8.5));
}

TEST(ReachAvoidEnvTest, StepRejectsBadInputClearly) {
  ReachAvoidEnv env;
  Eigen::VectorXf o(4);
  EXPECT_HAS(ErrorOf([&] { env.Step(Eigen::Vector2f::Zero(), o); }), "before Reset");
  Rng rng(1);
  env.Reset(rng, o);
  EXPECT_HAS(ErrorOf([&] { env.Step(Eigen::Vector3f::Zero(), o); }),
             "action has 3 entries, expected 2");
  EXPECT_HAS(ErrorOf([&] {
               Eigen::VectorXf small(3);
               env.Step(Eigen::Vector2f::Zero(), small);
             }),
             "observation has 3 entries, expected 4");
  const Eigen::Vector4f before = env.state();
  EXPECT_HAS(
      ErrorOf([&] { env.Step(Eigen::Vector2f(0.0f, std::numeric_limits<float>::quiet_NaN()), o); }),
      "action component ay = nan, must be finite");
  EXPECT_HAS(
      ErrorOf([&] { env.Step(Eigen::Vector2f(std::numeric_limits<float>::infinity(), 0.0f), o); }),
      "action component ax = inf");
  EXPECT_EQ(env.state(), before);  // a rejected step changes nothing
  EXPECT_HAS(ErrorOf([&] { env.SetState(Eigen::Vector4f(0, 0, NAN, 0)); }),
             "state component vx = nan");
  EXPECT_HAS(ErrorOf([&] {
               Eigen::VectorXf small(2);
               env.Reset(rng, small);
             }),
             "observation has 2 entries, expected 4");
}

// A random-action episode; returns the observations.
std::vector<Eigen::Vector4f> RandomEpisode(Environment& env, std::uint64_t seed) {
  Rng rng(seed);
  Eigen::VectorXf o(4);
  env.Reset(rng, o);
  std::vector<Eigen::Vector4f> states{o};
  Eigen::Vector2f a;
  for (int t = 0; t < 50; ++t) {
    a = Eigen::Vector2f(static_cast<float>(rng.Normal() * 2), static_cast<float>(rng.Normal() * 2));
    env.Step(a, o);
    states.emplace_back(o);
  }
  return states;
}

TEST(ReachAvoidEnvTest, EpisodesAreReplayedFromTheSameRngAndCloneIsIndependent) {
  ReachAvoidEnv env;
  const std::vector<Eigen::Vector4f> first = RandomEpisode(env, 11);
  EXPECT_EQ(RandomEpisode(env, 11), first);
  EXPECT_NE(RandomEpisode(env, 12), first);

  ReachAvoidOptions o;
  o.max_steps = 77;
  const ReachAvoidEnv original(o);
  std::unique_ptr<Environment> clone = original.Clone();
  EXPECT_EQ(clone->max_steps(), 77);
  EXPECT_EQ(clone->Describe(), original.Describe());
  EXPECT_EQ(RandomEpisode(*clone, 11), RandomEpisode(env, 11));
}

TEST(ReachAvoidEnvTest, BackupActionBrakes) {
  const ReachAvoidEnv env;
  Eigen::Vector2f a;
  ASSERT_TRUE(env.BackupAction(Eigen::Vector4f(1, 1, 0.2f, -1.0f), a));
  EXPECT_FLOAT_EQ(a[0], -2.0f);  // -10 * 0.2
  EXPECT_FLOAT_EQ(a[1], 3.0f);   // -10 * -1, clipped to the bound
  // From rest the brake does nothing; after braking from a slow speed the agent stops.
  ReachAvoidEnv stepper;
  stepper.SetState(Eigen::Vector4f(1, 1, 0.2f, -0.25f));
  ASSERT_TRUE(stepper.BackupAction(stepper.state(), a));
  Eigen::VectorXf o(4);
  stepper.Step(a, o);
  EXPECT_NEAR(o[2], 0.0f, 1e-6f);
  EXPECT_NEAR(o[3], 0.0f, 1e-6f);
}

}  // namespace
}  // namespace secure::domains::double_integrator
