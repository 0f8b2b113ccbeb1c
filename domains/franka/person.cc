#include "domains/franka/person.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"

namespace secure::domains::franka {

void PersonArmOptions::Validate(const char* o) const {
  for (int k = 0; k < 3; ++k) {
    SECURE_CHECK_FIELD(std::isfinite(shoulder[k]), o, "shoulder", shoulder[k], "finite");
    SECURE_CHECK_FIELD(std::isfinite(rest[k]), o, "rest", rest[k], "finite");
  }
  for (auto [name, v] : {std::pair{"upper_arm", upper_arm}, std::pair{"forearm", forearm},
                         std::pair{"hand", hand}}) {
    SECURE_CHECK_FIELD(std::isfinite(v) && v > 0.01 && v <= 1.0, o, name, v, "in (0.01, 1] m");
  }
  for (auto [name, v] :
       {std::pair{"upper_arm_radius", upper_arm_radius},
        std::pair{"forearm_radius", forearm_radius}, std::pair{"hand_radius", hand_radius}}) {
    SECURE_CHECK_FIELD(std::isfinite(v) && v > 0 && v <= 0.2, o, name, v, "in (0, 0.2] m");
  }
  CheckIntervalField(start_time, o, "start_time", 0, 100);
  CheckIntervalField(speed, o, "speed", 0.01, 5);
  CheckIntervalField(dwell, o, "dwell", 0, 100);
}

void PersonArmOptions::AddFields(YamlFields* fields) {
  fields->Field("shoulder", &shoulder).Field("rest", &rest).Field("hand", &hand);
  fields->Field("upper_arm", &upper_arm).Field("forearm", &forearm);
  fields->Field("upper_arm_radius", &upper_arm_radius).Field("forearm_radius", &forearm_radius);
  fields->Field("hand_radius", &hand_radius).Field("start_time", &start_time);
  fields->Field("speed", &speed).Field("dwell", &dwell);
}

HumanArmGeometry PersonArmOptions::Geometry() const {
  // The elbow out towards the person (+y) and down.
  return {Shoulder(),       upper_arm,      forearm,     hand,
          upper_arm_radius, forearm_radius, hand_radius, Eigen::Vector3d(0, 1, -1)};
}

HumanArmPose ArmPoseForWrist(const PersonArmOptions& p, const Eigen::Vector3d& wrist) {
  return HumanArmPoseForWrist(p.Geometry(), wrist);
}

Eigen::Vector3d PersonReach::Wrist(const PersonArmOptions& p, double t) const {
  const Eigen::Vector3d rest = p.Rest();
  if (t <= start) return rest;
  if (t <= start + travel) return rest + MinJerk((t - start) / travel) * (goal - rest);
  if (t <= start + travel + dwell) return goal;
  return goal + MinJerk((t - start - travel - dwell) / travel) * (rest - goal);
}

void DrawReachTiming(const PersonArmOptions& p, Rng& rng, PersonReach* reach) {
  reach->start = DrawUniform(rng, p.start_time);
  // Minimum jerk covers the distance at mean speed distance / travel.
  reach->travel = std::max(0.05, (reach->goal - p.Rest()).norm() / DrawUniform(rng, p.speed));
  reach->dwell = DrawUniform(rng, p.dwell);
}

PersonArmMotion PersonArmAt(const PersonArmOptions& p, const PersonReach& reach, double t) {
  constexpr double kH = 1e-3;  // s, central differences for the velocities
  PersonArmMotion m;
  m.pose = ArmPoseForWrist(p, reach.Wrist(p, t));
  const HumanArmPose ahead = ArmPoseForWrist(p, reach.Wrist(p, t + kH));
  const HumanArmPose behind = ArmPoseForWrist(p, reach.Wrist(p, std::max(0.0, t - kH)));
  const double span = t + kH - std::max(0.0, t - kH);
  m.wrist_velocity = (ahead.wrist - behind.wrist) / span;
  m.elbow_velocity = (ahead.elbow - behind.elbow) / span;
  return m;
}

}  // namespace secure::domains::franka
