#pragma once
// The Franka Emika Panda shared by the Franka plug-ins (panda-push, kitchen-cutting): its MJCF
// (panda_arm.xml, embedded at build time) and its controller, the released end-effector action
// tracked by one damped-least-squares IK step and computed-torque control (the README of
// domains/panda_push/, "Control"). Internal to the plug-ins' sources: it includes MuJoCo's
// headers.
#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <array>
#include <string>
#include <vector>

#include "domains/franka/arm_tracking.h"

namespace secure::domains::franka {

constexpr int kArmJoints = 7;

/// The released neutral posture of the arm (rad).
inline constexpr std::array<double, kArmJoints> kNeutralJoints = {0.0, 0.11, 0.0, -2.55,
                                                                  0.0, 2.6,  0.79};

/// A domain's MJCF with the Panda put in: `<panda_arm>TOOL</panda_arm>` becomes the arm's body
/// chain (panda_arm.xml) with TOOL (the domain's geoms and sites on the hand; it must define the
/// site "tcp", the tool centre point 0.1034 m below the hand) inside the hand body, and
/// `<panda_arm_actuators/>` becomes the seven torque motors. @throws secure::Error naming `name`
/// if either marker is missing.
std::string WithPandaArm(const std::string& xml, const std::string& name);

/// Positions and velocities of every body and site from qpos, qvel (no collision, no forces).
void UpdateKinematics(const mjModel* m, mjData* d);

/// The Panda in a model made by WithPandaArm: its joints (joint1..joint7, the model's first
/// degrees of freedom), limits and tool site "tcp"; scratch sized once. Allocation-free after
/// construction. The tool's orientation target is always "hand pointing down, tool x = world x".
class PandaArm {
 public:
  /// @throws secure::Error naming `who` if the model lacks a joint or the site, or the arm's
  /// joints are not its first degrees of freedom.
  PandaArm(const mjModel* m, const char* who);

  /// Sets the arm's joint positions (velocities untouched; kinematics not updated).
  void SetJoints(mjData* d, const std::array<double, kArmJoints>& q) const;
  /// One control period towards the tool target `target` (world, m): one damped-least-squares
  /// IK step (position and orientation, a null-space pull to the neutral posture, 0.01 rad inside
  /// the joint limits) gives the joint goal; computed torque follows the straight joint ramp to
  /// it over `tracking.substeps` physics steps (mj_step1 / mj_step2). Leaves the kinematics
  /// current. Kinematics must be current on entry.
  void Track(const mjModel* m, mjData* d, const Eigen::Vector3d& target,
             const ArmTracking& tracking);
  /// Moves the arm (positions only) by IK from its current posture to put the tool at `target`,
  /// hand down (200 iterations at most); kinematics current afterwards. Returns the remaining
  /// position error (m).
  double PlaceTool(const mjModel* m, mjData* d, const Eigen::Vector3d& target);
  /// Sets the joint velocities that give the tool the linear velocity `v` (no rotation), by
  /// damped least squares at the current kinematics.
  void SetToolVelocity(const mjModel* m, mjData* d, const Eigen::Vector3d& v);

  int tcp() const { return tcp_; }

 private:
  int tcp_ = -1;
  int qpos_[kArmJoints], dof_[kArmJoints];
  double lower_[kArmJoints], upper_[kArmJoints];
  std::vector<mjtNum> jacp_, jacr_, force_in_, force_out_;
};

}  // namespace secure::domains::franka
