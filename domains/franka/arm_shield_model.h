#pragma once
// What the Franka plug-ins' approximate shield models share (panda-push, kitchen-cutting,
// coffee-placing), declared, validated, read and written once: the end effector's gains (the
// tool centre point moves position_gain * a per control period and its velocity becomes
// velocity_gain * a, a being the action's first three components clipped to [-1, 1]: measured on
// the simulator, domains/panda_push/README.md) and, for the plug-ins with a person, how far ahead
// the person's arm is extrapolated (dt, one control period). Each plug-in's model adds what else
// moves (panda-push's block, kitchen-cutting's blade, coffee-placing's tilt and clearance).
// MuJoCo-free, so the plug-ins' public headers may include it.
#include <Eigen/Core>
#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>
#include "secure/common/yaml_fwd.h"

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

}  // namespace secure::domains::franka
