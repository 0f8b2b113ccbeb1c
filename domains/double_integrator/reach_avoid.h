#pragma once
// The double-integrator reach-avoid task: drive a point mass with bounded acceleration from the
// lower-left corner of the box to a goal behind a circular obstacle, without touching it. The
// task the SECURE pipeline is run on end to end in this domain (demonstrations from the expert in
// expert.h, BC/AIRL policies, the learned barrier, the shield, the evaluation).
//
// The task (every constant is a ReachAvoidOptions field, defaults in brackets):
//  - state s = (x, y, vx, vy) (StateFeatures()), action a = (ax, ay) (ActionFeatures()); the goal
//    is fixed, so the observation is the state itself;
//  - start: position uniform in [start_lo, start_hi)^2 [0.5, 3), velocity components uniform in
//    [-start_speed, start_speed] [0.1], redrawn until ||p - p_o|| >= r + start_clearance [0.5]
//    and the ground-truth h(s) >= 0 (the default square never redraws);
//  - obstacle p_o = (5, 5), r = 2, and the ground-truth CBF with gamma = 1 (GroundTruth);
//  - goal (8.5, 8.5), on the far side of the obstacle on the diagonal through its centre, so
//    that every straight line from the start square to the goal passes within 0.91 of the centre
//    (a goal-seeking policy that ignores the obstacle collides);
//  - transition: each action component clipped to [-accel_bound, accel_bound] [3], then the
//    exact zero-order-hold step with dt [0.1] (ClippedDoubleIntegrator; ShieldModel() is the
//    same map, so a shield sees exactly the next state that will happen);
//  - success: ||p - goal|| < goal_radius [0.3] at some step; dangerous: ||p - p_o|| < r at some
//    step (a physical collision; the episode is dangerous if it happens at least once);
//  - max_steps [300] = 30 s. Measured (expert_test.cc, MeasuredStepsToGoalJustifyMaxSteps: 1000
//    episodes of the default Expert, seeds 0..999): steps to the goal median 126, 99th
//    percentile 175, maximum 189, all 1000 reached. 300 = 1.7 x p99 (>= 1.5 x p99, checked by
//    that test) leaves room for slower learned policies and shield detours; `secure shield run`
//    (shield_run.h) runs in this task too (ShieldRunOptions::task), so the two runs compare.
//  - backup action (the shield's fallback): braking, a = clip(-brake_gain v) [10 = 1 / dt: stops
//    in one step whenever the bound allows].
//
// Step() never ends an episode (see environment.h): it reports reached_goal and collided for the
// new state, and the caller decides whether to stop.
//
// Usage:
//   ReachAvoidEnv env;                         // the defaults above
//   Rng rng(seed);
//   Eigen::VectorXf o(env.observation_dim()), a(env.action_dim());
//   env.Reset(rng, o);
//   for (int t = 0; t < env.max_steps(); ++t) {
//     policy(o, a);
//     const StepOutcome out = env.Step(a, o);
//     if (out.collided) ...; if (out.reached_goal) break;
//   }

#include <Eigen/Core>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "domains/double_integrator/double_integrator.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fwd.h"
#include "secure/domains/environment.h"

namespace secure::domains::double_integrator {

/// Names of the action features, as used in CSV files and model files: "ax", "ay".
const std::vector<std::string>& ActionFeatures();

struct ReachAvoidOptions {
  // The obstacle (5, 5), r = 2, and the ground-truth CBF (gamma = 1), the project's defaults
  // that the learned barriers are trained for.
  GroundTruth truth;

  // The goal: on the diagonal behind the obstacle as seen from the start square, inside the
  // box [0, 10)^2, 4.95 from the obstacle centre (2.95 clear of it).
  double goal_x = 8.5;
  double goal_y = 8.5;
  // Reached when ||p - goal|| < goal_radius: small against the obstacle and the distances
  // travelled, large against the jitter of a noisy policy (sigma dt^2 / 2 per step).
  double goal_radius = 0.3;

  // Start positions uniform in [start_lo, start_hi)^2, the lower-left corner of the box, at
  // least 0.83 from the obstacle boundary.
  double start_lo = 0.5;
  double start_hi = 3.0;
  // Start velocity components uniform in [-start_speed, start_speed]: almost at rest, so that
  // episodes differ in more than position but start deep inside the safe set.
  double start_speed = 0.1;
  // Start states satisfy ||p - p_o|| >= r + start_clearance and h(s) >= 0 (rejection sampling).
  double start_clearance = 0.5;

  // Control period, the paper's dt.
  double dt = 0.1;
  // Per-component acceleration bound, applied by clipping every action: enough authority to
  // brake from the speeds of the task (|v| <= 1.5 per component) within the ground-truth CBF's
  // margin, so a safe action exists from every safe state (see expert.h).
  double accel_bound = 3.0;
  // The backup (braking) action a = clip(-brake_gain v).
  double brake_gain = 10.0;
  // The step limit (see the header comment for the measurement behind it).
  int max_steps = 300;

  /// Throws secure::Error naming the field, value and rule
  /// ("ReachAvoidOptions::goal_radius = 0, must be > 0").
  void Validate() const;
  /// Keys: obstacle [x, y], radius, gamma, goal [x, y], goal_radius, start_region [lo, hi],
  /// start_speed, start_clearance, dt, accel_bound, brake_gain, max_steps.
  nlohmann::json ToJson() const;
  /// Overrides the fields present in `node`, a mapping with the keys of ToJson(); unknown keys
  /// and values of the wrong type are errors naming `source` and the key. Does not validate.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// A start state as Reset() draws it (see ReachAvoidOptions), from `rng`.
/// @throws secure::Error if 10000 draws find no admissible start (options that leave none).
Eigen::Vector4f DrawStartState(const ReachAvoidOptions& options, Rng& rng);

class ReachAvoidEnv final : public Environment {
 public:
  /// @throws secure::Error if the options are invalid.
  explicit ReachAvoidEnv(const ReachAvoidOptions& options = {});

  int observation_dim() const override { return kStateDim; }
  int action_dim() const override { return kActionDim; }
  std::vector<std::string> ObservationFeatures() const override { return StateFeatures(); }
  std::vector<std::string> ActionFeatures() const override;
  int max_steps() const override { return options_.max_steps; }
  std::string Describe() const override;

  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override;
  /// @throws secure::Error before the first Reset()/SetState(), on a wrong action or observation
  ///   dimension, or a non-finite action (naming the component and value).
  StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                   Eigen::Ref<Eigen::VectorXf> observation) override;

  const DynamicsModel& ShieldModel() const override { return model_; }
  /// The shield model is the environment's own clipped step on the state (= observation).
  bool ShieldModelIsExact() const override { return true; }
  /// Braking: clip(-brake_gain v) per component. Always available.
  bool BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                    Eigen::Ref<Eigen::VectorXf> action) const override;
  std::unique_ptr<Environment> Clone() const override;
  /// [-accel_bound, accel_bound] per component (the clip of Step()).
  void ActionBounds(Eigen::Ref<Eigen::VectorXf> low,
                    Eigen::Ref<Eigen::VectorXf> high) const override {
    low.setConstant(-static_cast<float>(options_.accel_bound));
    high.setConstant(static_cast<float>(options_.accel_bound));
  }
  double control_period() const override { return options_.dt; }

  const ReachAvoidOptions& options() const { return options_; }
  /// The current state (valid after Reset() or SetState()).
  const Eigen::Vector4f& state() const { return state_; }
  /// Puts the system into `state` (4 finite values), e.g. to replay or test a situation. A state
  /// inside the obstacle counts as a contact already under way (the next step inside reports
  /// collided, with collisions = 0).
  void SetState(const Eigen::Ref<const Eigen::VectorXf>& state);

  /// ||p - goal|| < goal_radius.
  bool InGoal(double x, double y) const;
  /// ||p - p_o|| < r: a collision.
  bool InObstacle(double x, double y) const;

 private:
  ReachAvoidOptions options_;
  ClippedDoubleIntegrator model_;
  Eigen::Vector4f state_ = Eigen::Vector4f::Zero();
  Eigen::Vector4f next_ = Eigen::Vector4f::Zero();
  bool in_obstacle_ = false;  // the current state is inside the obstacle (StepOutcome.collisions)
  bool started_ = false;
};

}  // namespace secure::domains::double_integrator
