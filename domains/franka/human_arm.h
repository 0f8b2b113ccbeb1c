#pragma once
// The simulated person's arm shared by the Franka plug-ins with people (kitchen-cutting,
// coffee-placing): a fixed shoulder, upper arm, forearm and hand as capsules; the elbow from the
// two-link arm's inverse kinematics for a wrist position; distances from a segment (a blade, a
// hand holding a cup) to the capsules' surfaces; the minimum-jerk profile of a reach; and the
// capsules as three mocap bodies of a MuJoCo model (for the pictures). Every constant is the
// plug-in's (an assumption standing in for a person, documented in its README). It declares
// MuJoCo's model and data types only, so the plug-ins' headers may include it.
#include <Eigen/Core>
#include <array>

struct mjModel_;
struct mjData_;
typedef struct mjModel_ mjModel;  // as MuJoCo's headers declare them
typedef struct mjData_ mjData;

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

/// The 3 observation features from `offset` (a position or a velocity) as a point.
inline Eigen::Vector3d ObservedPoint(const Eigen::Ref<const Eigen::VectorXf>& o, int offset) {
  return Eigen::Vector3d(o[offset], o[offset + 1], o[offset + 2]);
}
/// The arm in an observation: kHumanArmFeatures features from an offset, the wrist, elbow and
/// hand tip (m), then the wrist's and the elbow's velocity (m/s), 3 each (the layout
/// kitchen-cutting and coffee-placing share).
inline constexpr int kHumanArmFeatures = 15;
/// Writes `pose` (not its shoulder) and the velocities into o[offset, offset + 15).
void WriteHumanArm(const HumanArmPose& pose, const Eigen::Vector3d& wrist_velocity,
                   const Eigen::Vector3d& elbow_velocity, int offset,
                   Eigen::Ref<Eigen::VectorXf> o);
/// The arm an observation shows, moved `ahead` seconds at its velocities (the hand tip with the
/// wrist); the shoulder is fixed and not observed.
HumanArmPose ReadHumanArm(const Eigen::Ref<const Eigen::VectorXf>& o, int offset,
                          const Eigen::Vector3d& shoulder, double ahead = 0.0);
/// The shield models' guess of the arm one step later: next's wrist, elbow and hand tip = the
/// state's moved dt at the state's velocities (the hand tip with the wrist); the velocities and
/// every other feature of `next` are left as they are.
void ExtrapolateHumanArm(const Eigen::Ref<const Eigen::VectorXf>& state, int offset, float dt,
                         Eigen::Ref<Eigen::VectorXf> next);

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
