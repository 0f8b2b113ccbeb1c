#pragma once
// The Panda controller's constants (panda_arm.h's Track), embedded in the Franka plug-ins' task
// options (PandaPushOptions, KitchenCuttingOptions, CoffeePlacingOptions::tracking): declared,
// validated and read once here. Their YAML keys and JSON fields stay at the top level of the
// plug-in's task options (control_period, substeps, tracking_omega, ik_damping). MuJoCo-free, so
// the plug-ins' public headers may include it.
#include <nlohmann/json.hpp>

namespace secure {
class YamlFields;
}  // namespace secure

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

}  // namespace secure::domains::franka
