#pragma once
// What the Franka plug-ins' approximate shield models share (panda-push, kitchen-cutting,
// coffee-placing), declared, validated, read and written once: the end effector's gains (the
// tool centre point moves position_gain * a per control period and its velocity becomes
// velocity_gain * a, a being the action's first three components clipped to [-1, 1]: measured on
// the simulator, domains/panda_push/README.md) and, for the plug-ins with a person, how far ahead
// the person's arm is extrapolated (dt, one control period). Each plug-in's model adds what else
// moves (panda-push's block, kitchen-cutting's blade, coffee-placing's tilt and clearance). The
// models themselves derive from EndEffectorModel (their options validated and kept, their
// dimensions). MuJoCo-free, so the plug-ins' public headers may include it.
#include <Eigen/Core>
#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>
#include "secure/common/yaml_fwd.h"
#include "secure/domains/dynamics.h"

namespace secure::domains::franka {

struct EndEffectorGains {
  double position_gain = 0.05;  // m per unit action per control period
  double velocity_gain = 1.25;  // m/s per unit action

  /// @throws secure::Error "owner::field = value, must be ..." for the first field out of range.
  void Validate(const char* owner) const;
  /// Adds the gains' keys to the field table of the plug-in's shield-model options (which reads
  /// and writes them).
  void AddFields(YamlFields* fields);

  /// Column c of the model's prediction, from `state`: `next` = state, then the end effector
  /// (position at ee_pos, velocity at ee_vel) stepped by column c of `actions`, and the position
  /// at `carried` (3 values that move with the hand; none if < 0) moved as the end effector.
  void Step(const Eigen::Ref<const Eigen::VectorXf>& state,
            const Eigen::Ref<const Eigen::MatrixXf>& actions, Eigen::Index c, int ee_pos,
            int ee_vel, int carried, Eigen::Ref<Eigen::MatrixXf> next) const {
    const float pg = static_cast<float>(position_gain);
    const float vg = static_cast<float>(velocity_gain);
    next.col(c) = state;
    for (int k = 0; k < 3; ++k) {
      const float a = std::clamp(actions(k, c), -1.0f, 1.0f);
      next(ee_pos + k, c) += pg * a;
      next(ee_vel + k, c) = vg * a;
      if (carried >= 0) next(carried + k, c) += pg * a;
    }
  }
};

/// The approximate model's options of a plug-in with a person: the end effector's gains, and the
/// person's arm moved on at its observed velocities for dt (the plug-in checks dt = its control
/// period).
struct PersonShieldModelOptions : EndEffectorGains {
  double dt = 0.04;  // s

  /// @throws secure::Error naming `owner`, the field, value and rule.
  void Validate(const char* owner) const;
  /// The plug-in's domain options' check that dt is the task's control period: @throws
  /// secure::Error "owner::shield_model.dt = value, must be the control period (... s)".
  void CheckControlPeriod(const char* owner, double control_period) const;
  /// The field table (position_gain, velocity_gain, dt): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  /// Keys: position_gain, velocity_gain, dt. Does not validate.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// A Franka plug-in's approximate shield model: `Options` (an EndEffectorGains with Validate())
/// validated at construction and kept in options_, the model's dimensions (the plug-in's
/// observation and action), and its step: per action column c, the end effector (position at
/// kEePos, velocity at kEeVel) by options_.Step, with the position at Carried(state) moved with
/// the hand, then what else the plug-in's model moves (StepOthers). The plug-in adds Describe and
/// those two.
template <typename Options, int kStateDim, int kActionDim, int kEePos, int kEeVel>
class EndEffectorModel : public DynamicsModel {
 public:
  /// @throws secure::Error from options.Validate().
  explicit EndEffectorModel(const Options& options) : options_((options.Validate(), options)) {}
  int state_dim() const override { return kStateDim; }
  int action_dim() const override { return kActionDim; }

 protected:
  /// Where 3 values that move with the hand start in `state` (e.g. a blade; -1: none). Once per
  /// DoStep.
  virtual int Carried(const Eigen::Ref<const Eigen::VectorXf>& state) const {
    (void)state;
    return -1;
  }
  /// Column c of `next` after the end effector's part: what else the model moves from `state`
  /// under column c of `actions` (nothing by default).
  virtual void StepOthers(const Eigen::Ref<const Eigen::VectorXf>& state,
                          const Eigen::Ref<const Eigen::MatrixXf>& actions, Eigen::Index c,
                          Eigen::Ref<Eigen::MatrixXf> next) const {
    (void)state, (void)actions, (void)c, (void)next;
  }

  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next) const final {
    const int carried = Carried(state);
    for (Eigen::Index c = 0; c < actions.cols(); ++c) {
      options_.Step(state, actions, c, kEePos, kEeVel, carried, next);
      StepOthers(state, actions, c, next);
    }
  }

  Options options_;
};

}  // namespace secure::domains::franka
