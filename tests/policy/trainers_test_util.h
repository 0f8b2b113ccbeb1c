#pragma once
// Helpers of the trainer tests (bc_trainer_test.cc, airl_trainer_test.cc, airl_files_test.cc in
// the policy_train_test program): one training thread, bitwise policy equality, a linear expert's
// demonstrations, small BC and AIRL options, and the toy task's success rate.
// Each file: #include "tests/policy/trainers_test_util.h", then `using namespace test;` in
// secure::policy.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <Eigen/Core>

#include "secure/cbf/barrier_net.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/common/strings.h"
#include "secure/nn/mlp.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"
#include "tests/policy/single_thread.h"
#include "tests/policy/toy_env.h"
#include "tests/test_util.h"

namespace secure::policy::test {

using secure::test::ErrorOf;

// The trainers leave thread counts to the caller: one LibTorch and one OpenBLAS thread, as in
// the pipeline.
// (Per file, at start-up.)
[[maybe_unused]] static const bool kOneThread = UseOneTrainingThread();

inline bool BitEqual(const GaussianPolicy& a, const GaussianPolicy& b) {
  if (!(a.mean.spec == b.mean.spec) || a.mean.layers.size() != b.mean.layers.size()) return false;
  for (std::size_t l = 0; l < a.mean.layers.size(); ++l)
    if (a.mean.layers[l].weight != b.mean.layers[l].weight ||
        a.mean.layers[l].bias != b.mean.layers[l].bias)
      return false;
  return a.input.mean == b.input.mean && a.input.scale == b.input.scale && a.log_std == b.log_std;
}

inline std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// Success rate of a policy in the toy task (sampled actions, fixed horizon).
inline double SuccessRate(const GaussianPolicy& pi, int episodes, std::uint64_t seed) {
  PointMassEnv env;
  PolicyEvaluator ev(pi);
  Rng rng(seed);
  Eigen::VectorXf o(2), a(2), next(2);
  int reached = 0;
  for (int e = 0; e < episodes; ++e) {
    env.Reset(rng, o);
    bool hit = false;
    for (int t = 0; t < env.max_steps(); ++t) {
      ev.Sample(o, rng, a);
      hit |= env.Step(a, next).reached_goal;
      o = next;
    }
    reached += hit;
  }
  return static_cast<double>(reached) / episodes;
}

// States uniform in [-2, 2]^2 grouped into episodes; actions from a linear expert with
// per-axis Gaussian noise.
inline const Eigen::Matrix2f kGain = (Eigen::Matrix2f() << -0.8f, 0.3f, 0.2f, -1.1f).finished();
inline const Eigen::Vector2f kOffset(0.5f, -0.25f);
inline const Eigen::Vector2f kNoise(0.3f, 0.1f);

inline data::TrajectorySet LinearDemos(int episodes, int length, std::uint64_t seed) {
  Rng rng(seed);
  data::TrajectorySet d;
  d.source = "linear expert";
  d.state_features = {"x", "y"};
  d.action_features = {"vx", "vy"};
  d.states.resize(2, static_cast<long>(episodes) * length);
  d.actions.resize(2, d.states.cols());
  for (long c = 0; c < d.states.cols(); ++c) {
    if (c % length == 0) d.episode_begin.push_back(c);
    Eigen::VectorXf s(2);  // dynamic size: see gaussian_policy_test.cc
    s << static_cast<float>(rng.Uniform(-2, 2)), static_cast<float>(rng.Uniform(-2, 2));
    d.states.col(c) = s;
    d.actions.col(c) = kGain * s + kOffset;
    for (int i = 0; i < 2; ++i) d.actions(i, c) += kNoise[i] * static_cast<float>(rng.Normal());
  }
  d.episode_begin.push_back(d.states.cols());
  return d;
}

inline BcOptions FastBc() {
  BcOptions o;
  o.hidden = {32, 32};
  o.epochs = 60;
  o.batch_size = 128;
  o.learning_rate = 3e-3;
  o.final_learning_rate = 1e-4;
  return o;
}

// Small AIRL options for tests that need the files, not the learning.
inline AirlOptions SmallAirl() {
  AirlOptions o;
  o.iterations = 6;
  o.steps_per_iteration = 500;  // 10 episodes of 50 steps
  o.minibatch_size = 100;
  o.ppo_epochs = 2;
  o.discriminator_updates = 3;
  o.discriminator_batch = 64;
  o.policy_hidden = {16, 16};
  o.value_hidden = {16, 16};
  o.reward_hidden = {8};
  o.shaping_hidden = {8};
  o.seed = 3;
  return o;
}

}  // namespace secure::policy::test
