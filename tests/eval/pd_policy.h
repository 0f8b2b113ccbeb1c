#pragma once
// The linear PD policy the evaluation tests run on the double-integrator reach-avoid task.
#include <cmath>

#include "domains/double_integrator/reach_avoid.h"
#include "secure/policy/gaussian_policy.h"

namespace secure::test {

// A linear policy: the PD controller a = kp (goal - p) - kd v straight at the goal (through the
// obstacle), with the given noise.
inline policy::GaussianPolicy PdPolicy(const domains::double_integrator::ReachAvoidOptions& task,
                                       double sigma) {
  namespace di = domains::double_integrator;
  policy::GaussianPolicy p;
  p.mean.spec.input_dim = 4;
  p.mean.spec.output_dim = 2;
  nn::DenseLayer layer;
  const float kp = 0.25f, kd = 1.0f;
  layer.weight = Eigen::MatrixXf::Zero(2, 4);
  layer.weight(0, 0) = -kp;
  layer.weight(1, 1) = -kp;
  layer.weight(0, 2) = -kd;
  layer.weight(1, 3) = -kd;
  layer.bias =
      Eigen::Vector2f(kp * static_cast<float>(task.goal_x), kp * static_cast<float>(task.goal_y));
  p.mean.layers.push_back(layer);
  p.input = nn::Normalizer::Identity(4);
  p.log_std = Eigen::VectorXf::Constant(2, static_cast<float>(std::log(sigma)));
  p.observation_features = di::StateFeatures();
  const di::ReachAvoidEnv env(task);
  p.action_features = env.ActionFeatures();
  p.Validate();
  return p;
}

// The double integrator's reach-avoid task (default options), its environment and the PD policy
// above with noise `sigma`: the evaluation tests' usual setup.
struct PdOnReachAvoid {
  explicit PdOnReachAvoid(double sigma) : env(task), pd(PdPolicy(task, sigma)) {}
  const domains::double_integrator::ReachAvoidOptions task;
  domains::double_integrator::ReachAvoidEnv env;
  const policy::GaussianPolicy pd;
};

}  // namespace secure::test
