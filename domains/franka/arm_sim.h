#pragma once
// What the Franka plug-ins' MuJoCo simulations (panda-push, kitchen-cutting, coffee-placing) do
// alike around the arm, written once: the model copy with the controller's physics step, the
// model/data/arm triple, the noisy neutral posture, the action's check and clip, one control
// period towards the end-effector target, the tool's position and velocity in an observation and
// back (IK), and the observation's checks. Each simulation adds what is its task's (the block,
// the knife, the cup, the person). Internal to the plug-ins' sources: it includes MuJoCo's
// headers.
#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "domains/franka/arm_tracking.h"
#include "domains/franka/mujoco_model.h"
#include "domains/franka/panda_arm.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"

namespace secure::domains::franka {

/// A copy of the task's model `base` with the physics step tracking.control_period /
/// tracking.substeps (the plug-in may adjust the copy further before making ArmSim of it).
MujocoModel TaskModel(const mjModel* base, const ArmTracking& tracking);

/// A task simulation's model, its data (made after the model's last adjustment) and the arm
/// (`who` names the plug-in in errors).
struct ArmSim {
  MujocoModel model;
  MujocoData data;
  PandaArm arm;

  ArmSim(MujocoModel m, const char* who)
      : model(std::move(m)), data(model), arm(model.get(), who) {}
};

/// The neutral posture with each joint moved by noise * U(-1, 1), drawn in joint order.
std::array<double, kArmJoints> NoisyNeutralJoints(double noise, Rng& rng);

/// `action` with every component checked finite ("who: action[k] = v is not finite") and
/// clipped to [-1, 1].
template <int N>
Eigen::Matrix<double, N, 1> ClipAction(const Eigen::Ref<const Eigen::Matrix<float, N, 1>>& action,
                                       const char* who) {
  Eigen::Matrix<double, N, 1> a;
  for (int k = 0; k < N; ++k) {
    SECURE_CHECK(std::isfinite(action[k]),
                 who << ": action[" << k << "] = " << action[k] << " is not finite");
    a[k] = std::clamp(static_cast<double>(action[k]), -1.0, 1.0);
  }
  return a;
}

/// One control period towards the end-effector target ee + task.action_scale * a, its height
/// kept at or above min_z (what the tool stops at), tracked by the arm; then MuJoCo's warnings
/// ("who: MuJoCo warning during a step"). Kinematics must be current on entry (they are after).
void StepTool(PandaArm& arm, const mjModel* m, mjData* d, const ArmTaskOptions& task,
              const Eigen::Vector3d& a, double min_z, const char* who);

/// @throws secure::Error "who: observation has n entries, expected dim" unless size == dim.
void CheckObservationSize(Eigen::Index size, int dim, const char* who);
/// The size check, then every value finite ("who: observation NAME = v is not finite", the
/// name from `features`, one per value).
void CheckObservation(const Eigen::Ref<const Eigen::VectorXf>& o,
                      const std::vector<std::string>& features, const char* who);

/// Writes the tool centre point's position to o[ee_pos, ee_pos + 3) and its linear velocity to
/// o[ee_vel, ee_vel + 3).
void ObserveTool(const mjModel* m, mjData* d, int tcp, int ee_pos, int ee_vel,
                 Eigen::Ref<Eigen::VectorXf> o);

/// The arm moved by IK from its present posture to put the tool at the observation's position
/// (o[ee_pos, +3)), with the joint velocities that give it the observed velocity (o[ee_vel, +3));
/// returns the remaining position error (m).
double PlaceObservedTool(PandaArm& arm, const mjModel* m, mjData* d,
                         const Eigen::Ref<const Eigen::VectorXf>& o, int ee_pos, int ee_vel);

}  // namespace secure::domains::franka
