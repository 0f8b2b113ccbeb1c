#pragma once
// A toy task for the policy tests: a 2-D point mass (single integrator) that must reach the
// origin from a random start, with an expert to make demonstrations in memory.
//
//   observation = state = (x, y); action = velocity (vx, vy), clipped to [-1, 1] per axis;
//   x' = x + dt a, dt = 0.1; start at distance U[1.5, 2.5] from the origin in a random
//   direction; success: |p| < 0.25; "collision": leaving the arena |x| or |y| > 3.
//   Horizon 50 steps (the expert needs ~20-25).

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/domains/dynamics.h"
#include "secure/domains/environment.h"

namespace secure::policy::test {

class PointMassModel final : public domains::DynamicsModel {
 public:
  int state_dim() const override { return 2; }
  int action_dim() const override { return 2; }
  std::string Describe() const override { return "point mass"; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override {
    for (Eigen::Index i = 0; i < actions.cols(); ++i)
      next_states.col(i) = state + 0.1f * actions.col(i).cwiseMax(-1.0f).cwiseMin(1.0f);
  }
};

class PointMassEnv final : public domains::Environment {
 public:
  explicit PointMassEnv(int horizon = 50) : horizon_(horizon) {}
  int observation_dim() const override { return 2; }
  int action_dim() const override { return 2; }
  std::vector<std::string> ObservationFeatures() const override { return {"x", "y"}; }
  std::vector<std::string> ActionFeatures() const override { return {"vx", "vy"}; }
  int max_steps() const override { return horizon_; }
  std::string Describe() const override {
    return "toy point mass, horizon " + std::to_string(horizon_);
  }
  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override {
    const double angle = rng.Uniform(0.0, 2.0 * M_PI);
    const double radius = rng.Uniform(1.5, 2.5);
    state_ << static_cast<float>(radius * std::cos(angle)),
        static_cast<float>(radius * std::sin(angle));
    observation = state_;
  }
  domains::StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                            Eigen::Ref<Eigen::VectorXf> observation) override {
    SECURE_CHECK(action.size() == 2 && action.allFinite(), "PointMassEnv: bad action");
    state_ += 0.1f * action.cwiseMax(-1.0f).cwiseMin(1.0f);
    observation = state_;
    domains::StepOutcome out;
    out.reached_goal = state_.norm() < 0.25f;
    out.collided = state_.cwiseAbs().maxCoeff() > 3.0f;
    out.collisions = out.collided ? 1 : 0;
    return out;
  }
  const domains::DynamicsModel& ShieldModel() const override { return model_; }
  void ActionBounds(Eigen::Ref<Eigen::VectorXf> low, Eigen::Ref<Eigen::VectorXf> high) const override {
    low.setConstant(-1.0f);
    high.setConstant(1.0f);
  }
  std::unique_ptr<domains::Environment> Clone() const override {
    return std::make_unique<PointMassEnv>(horizon_);
  }

 private:
  int horizon_;
  Eigen::VectorXf state_ = Eigen::VectorXf::Zero(2);  // dynamic: see gaussian_policy_test.cc
  PointMassModel model_;
};

/// Expert: a = clip(-2 p) + N(0, noise^2) per axis.
inline void ExpertAction(const Eigen::VectorXf& p, double noise, Rng& rng, Eigen::VectorXf& a) {
  for (int i = 0; i < 2; ++i)
    a[i] = std::clamp(-2.0f * p[i], -1.0f, 1.0f) + static_cast<float>(noise * rng.Normal());
}

/// `episodes` fixed-horizon expert episodes in the toy task.
inline data::TrajectorySet ExpertDemos(int episodes, std::uint64_t seed, int horizon = 50,
                                       double noise = 0.1) {
  PointMassEnv env(horizon);
  Rng rng(seed);
  data::TrajectorySet demos;
  demos.source = "toy expert";
  demos.state_features = env.ObservationFeatures();
  demos.action_features = env.ActionFeatures();
  demos.states.resize(2, static_cast<long>(episodes) * horizon);
  demos.actions.resize(2, static_cast<long>(episodes) * horizon);
  Eigen::VectorXf o(2), next(2);
  Eigen::VectorXf a(2);
  long c = 0;
  for (int e = 0; e < episodes; ++e) {
    demos.episode_begin.push_back(c);
    env.Reset(rng, o);
    for (int t = 0; t < horizon; ++t, ++c) {
      ExpertAction(o, noise, rng, a);
      demos.states.col(c) = o;
      demos.actions.col(c) = a;
      env.Step(a, next);
      o = next;
    }
  }
  demos.episode_begin.push_back(c);
  return demos;
}

}  // namespace secure::policy::test
