#pragma once
// The Panda controller's constants (panda_arm.h's Track), embedded in the Franka plug-ins' task
// options (PandaPushOptions, KitchenCuttingOptions, CoffeePlacingOptions::tracking), and the
// task options' part they share around it (ArmTaskOptions: the episode length, the controller,
// the action's scale): declared, validated and read once here. Their YAML keys and JSON fields
// stay at the top level of the plug-in's task options (control_period, substeps, tracking_omega,
// ik_damping, max_steps, action_scale). MuJoCo-free, so the plug-ins' public headers may include
// it.
#include <nlohmann/json.hpp>
#include "secure/common/yaml_fwd.h"

namespace secure::domains::franka {

/// The controller's constants (domains/panda_push/README.md, "Control").
struct ArmTracking {
  double control_period = 0.04;  // s per control step (one Step())
  int substeps = 20;             // physics steps per control step (timestep 2 ms)
  double tracking_omega = 40.0;  // rad/s, natural frequency of the computed-torque controller
  double ik_damping = 0.02;      // damped least squares lambda (m / rad)

  /// @throws secure::Error "owner::field = value, must be ..." for the first field out of range.
  void Validate(const char* owner) const;
  /// Adds the four keys to the field table of the plug-in's task options (which reads and writes
  /// them).
  void AddFields(YamlFields* fields);
};

/// The part of a Franka plug-in's task options that every plug-in has (its task options derive
/// from it; a plug-in with another episode length sets max_steps in its constructor).
struct ArmTaskOptions {
  int max_steps = 150;
  // control_period (s per Step()), substeps, tracking_omega, ik_damping: the controller's
  // constants (YAML keys and JSON fields at the task options' level).
  ArmTracking tracking;
  double action_scale = 0.05;  // m of end-effector target offset per unit action

  /// max_steps, the tracking fields, action_scale, in this order. @throws secure::Error
  /// "owner::field = value, must be ..." for the first field out of range.
  void Validate(const char* owner) const;
  /// Adds the tracking fields' keys, max_steps and action_scale to the field table of the
  /// plug-in's task options (which reads and writes them).
  void AddFields(YamlFields* fields);
};

}  // namespace secure::domains::franka
