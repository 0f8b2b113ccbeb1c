#pragma once
// The simulated person the Franka plug-ins with people share (kitchen-cutting, coffee-placing),
// declared, validated, read and written once: the arm's body (a fixed shoulder, segment lengths,
// capsule radii), the wrist's rest point and the timing of a reach (start, mean speed, dwell),
// the reach's profile (minimum jerk out, dwell, minimum jerk back) and the arm's pose and
// velocities on it. Where a reach goes is the plug-in's (kitchen-cutting: over the cut line or
// beside it; coffee-placing: one of the books), and so are the defaults of the body and the
// timing. Every value is an ASSUMPTION standing in for a person (the plug-ins' READMEs). It
// declares MuJoCo's types only (human_arm.h), so the plug-ins' headers may include it.
#include <Eigen/Core>
#include <array>
#include <nlohmann/json.hpp>

#include "domains/franka/human_arm.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fwd.h"

namespace secure::domains::franka {

/// The person's arm and the timing of its reaches. The plug-in's person options derive from it
/// (their YAML keys and JSON fields sit at the same level as the plug-in's own).
struct PersonArmOptions {
  std::array<double, 3> shoulder = {0.30, 0.38, 0.38};   // m, fixed
  double upper_arm = 0.30, forearm = 0.27, hand = 0.08;  // segment lengths (m)
  double upper_arm_radius = 0.045, forearm_radius = 0.035, hand_radius = 0.03;  // m
  std::array<double, 3> rest = {0.30, 0.24, 0.12};  // the wrist's rest point (m)
  std::array<double, 2> start_time = {0.0, 1.0};    // s after reset the reach begins
  std::array<double, 2> speed = {0.3, 0.6};         // m/s, the wrist's mean speed (minimum jerk)
  std::array<double, 2> dwell = {0.5, 2.0};         // s at the goal before returning

  /// The body (shoulder, rest, lengths, radii), then the timing. @throws secure::Error
  /// "owner::field = value, must be ..." for the first field out of range.
  void Validate(const char* owner) const;
  /// Adds the fields' keys to the field table of the plug-in's person options (which reads and
  /// writes them).
  void AddFields(YamlFields* fields);
  /// The arm as human_arm.h sees it (the elbow out towards the person, +y, and down).
  HumanArmGeometry Geometry() const;
  Eigen::Vector3d Shoulder() const { return {shoulder[0], shoulder[1], shoulder[2]}; }
  Eigen::Vector3d Rest() const { return {rest[0], rest[1], rest[2]}; }
};

/// The elbow and hand tip for a wrist position (the wrist pulled into reach if needed).
HumanArmPose ArmPoseForWrist(const PersonArmOptions& p, const Eigen::Vector3d& wrist);

/// One reach of the wrist: from the rest point to `goal` in `travel` s (minimum jerk), `dwell` s
/// there, and back the same way; it begins `start` s after reset.
struct PersonReach {
  Eigen::Vector3d goal = Eigen::Vector3d::Zero();
  double start = 0, travel = 1, dwell = 0;
  /// The wrist at time t (s since reset).
  Eigen::Vector3d Wrist(const PersonArmOptions& p, double t) const;
};

/// Draws the timing of a reach whose goal is set: the start, the travel time (the distance at a
/// drawn mean speed, at least 0.05 s) and the dwell, in this order from `rng`.
void DrawReachTiming(const PersonArmOptions& p, Rng& rng, PersonReach* reach);

/// The arm at time t on `reach`, with the wrist's and the elbow's velocities (central
/// differences over 1 ms, one-sided at t < 1 ms).
struct PersonArmMotion {
  HumanArmPose pose;
  Eigen::Vector3d wrist_velocity, elbow_velocity;
};
PersonArmMotion PersonArmAt(const PersonArmOptions& p, const PersonReach& reach, double t);

/// A value drawn uniformly from [r[0], r[1]].
inline double DrawUniform(Rng& rng, const std::array<double, 2>& r) {
  return r[0] + (r[1] - r[0]) * rng.Uniform();
}

}  // namespace secure::domains::franka
