// AIRL's rollout collection (secure/policy/internal/airl_rollout.h; no LibTorch): fixed-horizon
// episodes, and with absorbing_goal the goal as an absorbing state.
#include "secure/policy/internal/airl_rollout.h"

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <vector>

#include "tests/policy/toy_env.h"

namespace secure::policy {
namespace {

// The toy point mass, counting the Step() calls of every clone in one shared counter.
class CountingEnv final : public domains::Environment {
 public:
  explicit CountingEnv(std::shared_ptr<long> steps) : steps_(std::move(steps)) {}
  int observation_dim() const override { return env_.observation_dim(); }
  int action_dim() const override { return env_.action_dim(); }
  std::vector<std::string> ObservationFeatures() const override {
    return env_.ObservationFeatures();
  }
  std::vector<std::string> ActionFeatures() const override { return env_.ActionFeatures(); }
  int max_steps() const override { return env_.max_steps(); }
  std::string Describe() const override { return "counting " + env_.Describe(); }
  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override {
    env_.Reset(rng, observation);
  }
  domains::StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                            Eigen::Ref<Eigen::VectorXf> observation) override {
    ++*steps_;
    return env_.Step(action, observation);
  }
  const domains::DynamicsModel& ShieldModel() const override { return env_.ShieldModel(); }
  void ActionBounds(Eigen::Ref<Eigen::VectorXf> low, Eigen::Ref<Eigen::VectorXf> high) const override {
    env_.ActionBounds(low, high);
  }
  std::unique_ptr<domains::Environment> Clone() const override {
    return std::make_unique<CountingEnv>(steps_);
  }

 private:
  std::shared_ptr<long> steps_;
  test::PointMassEnv env_;
};

// A linear policy a = -2 p with a small sigma: it reaches the goal (|p| < 0.25) in ~15 steps.
GaussianPolicy HomingPolicy() {
  GaussianPolicy p;
  nn::MlpSpec spec;
  spec.input_dim = 2;
  spec.output_dim = 2;
  p.mean.spec = spec;
  p.mean.layers.resize(1);
  p.mean.layers[0].weight = -2.0f * Eigen::MatrixXf::Identity(2, 2);
  p.mean.layers[0].bias = Eigen::VectorXf::Zero(2);
  p.input.mean = Eigen::VectorXf::Zero(2);
  p.input.scale = Eigen::VectorXf::Ones(2);
  p.log_std = Eigen::VectorXf::Constant(2, std::log(0.05f));
  p.observation_features = {"x", "y"};
  p.action_features = {"vx", "vy"};
  return p;
}

struct Rollout {
  internal::RolloutBuffer buffer;
  AirlIterationStats stats;
  long env_steps = 0;
};

Rollout Collect(bool absorbing_goal, int episodes, int horizon) {
  auto steps = std::make_shared<long>(0);
  std::vector<std::unique_ptr<domains::Environment>> envs;
  for (int e = 0; e < episodes; ++e) envs.push_back(std::make_unique<CountingEnv>(steps));
  Rollout r;
  r.buffer.Resize(2, 2, static_cast<long>(episodes) * horizon);
  Rng rng(7);
  internal::CollectRollout(HomingPolicy(), envs, horizon, absorbing_goal, rng, r.buffer, r.stats);
  r.env_steps = *steps;
  return r;
}

TEST(AirlRollout, FixedHorizonEpisodesStepEveryColumn) {
  const Rollout r = Collect(false, 4, 50);
  EXPECT_EQ(r.env_steps, 200);
  ASSERT_EQ(r.buffer.live.size(), 200u);
  for (long c = 0; c < 200; ++c) EXPECT_EQ(r.buffer.live[c], c);
  EXPECT_EQ(r.stats.success_rate, 1.0);
  // Past the goal the point mass keeps moving (the policy's noise): no column is frozen.
  long frozen = 0;
  for (long c = 0; c < 200; ++c) frozen += r.buffer.obs.col(c) == r.buffer.next_obs.col(c);
  EXPECT_EQ(frozen, 0);
}

TEST(AirlRollout, AbsorbingGoalRecordsTheGoalObservationAndNoPostGoalPhysics) {
  const int episodes = 4, horizon = 50;
  const Rollout r = Collect(true, episodes, horizon);
  EXPECT_EQ(r.stats.success_rate, 1.0);
  long live = 0;
  for (int e = 0; e < episodes; ++e) {
    // The step that reached the goal: the first whose next observation lies in the goal.
    int goal_step = -1;
    for (int t = 0; t < horizon && goal_step < 0; ++t)
      if (r.buffer.next_obs.col(static_cast<long>(e) * horizon + t).norm() < 0.25f) goal_step = t;
    ASSERT_GE(goal_step, 1) << "episode " << e;
    ASSERT_LT(goal_step, horizon - 1) << "episode " << e;
    const Eigen::VectorXf goal = r.buffer.next_obs.col(static_cast<long>(e) * horizon + goal_step);
    for (int t = goal_step + 1; t < horizon; ++t) {
      const long c = static_cast<long>(e) * horizon + t;
      EXPECT_EQ(r.buffer.obs.col(c), goal) << "episode " << e << " step " << t;
      EXPECT_EQ(r.buffer.next_obs.col(c), goal) << "episode " << e << " step " << t;
      EXPECT_TRUE(r.buffer.actions.col(c).allFinite());
    }
    // The live columns: the episode's steps up to and including the one that reached the goal.
    for (int t = 0; t <= goal_step; ++t, ++live)
      EXPECT_EQ(r.buffer.live[live], static_cast<long>(e) * horizon + t);
  }
  EXPECT_EQ(static_cast<long>(r.buffer.live.size()), live);
  // No physics after the goal: the environment stepped exactly the live columns.
  EXPECT_EQ(r.env_steps, live);
  EXPECT_LT(live, episodes * horizon / 2);
}

}  // namespace
}  // namespace secure::policy
