#pragma once
// The simulated person's arm shared by the Franka plug-ins with people (kitchen-cutting,
// coffee-placing): a fixed shoulder, upper arm, forearm and hand as capsules; the elbow from the
// two-link arm's inverse kinematics for a wrist position; distances from a segment (a blade, a
// hand holding a cup) to the capsules' surfaces; the minimum-jerk profile of a reach; and the
// capsules as three mocap bodies of a MuJoCo model (for the pictures). Every constant is the
// plug-in's (an assumption standing in for a person, documented in its README). Internal to the
// plug-ins' sources (it includes MuJoCo's headers).
#include <mujoco/mujoco.h>

#include <Eigen/Core>
#include <array>

namespace secure::domains::franka {

/// The arm's fixed geometry (m).
struct HumanArmGeometry {
  Eigen::Vector3d shoulder = Eigen::Vector3d::Zero();
  double upper_arm = 0.30, forearm = 0.27, hand = 0.08;                         // segment lengths
  double upper_arm_radius = 0.045, forearm_radius = 0.035, hand_radius = 0.03;  // capsule radii
  // The elbow points along this direction (made orthogonal to the shoulder-wrist line).
  Eigen::Vector3d elbow_out = Eigen::Vector3d(0, 1, -1);
};

/// The arm at one instant: shoulder, elbow, wrist, hand tip (m).
struct HumanArmPose {
  Eigen::Vector3d shoulder, elbow, wrist, tip;
};

/// The elbow and hand tip for a wrist position (the wrist pulled into reach if needed).
HumanArmPose HumanArmPoseForWrist(const HumanArmGeometry& g, const Eigen::Vector3d& wrist);

/// The closest distance between segments p1-q1 and p2-q2 (Ericson, Real-Time Collision Detection
/// 5.1.9; a degenerate segment is a point).
double SegmentDistance(const Eigen::Vector3d& p1, const Eigen::Vector3d& q1,
                       const Eigen::Vector3d& p2, const Eigen::Vector3d& q2);

/// Distance from segment a-b to the arm's surface: the minimum over the upper arm, forearm and
/// hand capsules of the axis distance minus the radius (< 0 inside).
double SegmentToArmDistance(const HumanArmGeometry& g, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b, const HumanArmPose& arm);

/// Minimum jerk from 0 to 1 over tau in [0, 1] (clamped).
double MinJerk(double tau);

/// The arm's three capsules in a model: geoms and mocap bodies named "upper_arm", "forearm" and
/// "person_hand", each capsule along its body's z from 0 to its length.
class HumanArmCapsules {
 public:
  /// Sets the capsules' sizes in `model` (before mjData is made) from `g`. @throws secure::Error
  /// naming `who` if a geom or mocap body is missing.
  HumanArmCapsules(mjModel* model, const HumanArmGeometry& g, const char* who);
  /// Puts the capsules at `pose` and recomputes the kinematics (mj_kinematics).
  void Pose(const mjModel* m, mjData* d, const HumanArmPose& pose) const;

 private:
  std::array<int, 3> mocap_{{-1, -1, -1}};
};

}  // namespace secure::domains::franka
