#include "domains/franka/human_arm.h"

#include <mujoco/mujoco.h>

#include <algorithm>
#include <cmath>

#include "secure/common/error.h"

namespace secure::domains::franka {

HumanArmPose HumanArmPoseForWrist(const HumanArmGeometry& g, const Eigen::Vector3d& wrist) {
  HumanArmPose p;
  p.shoulder = g.shoulder;
  const double l1 = g.upper_arm, l2 = g.forearm;
  const Eigen::Vector3d sw = wrist - p.shoulder;
  double d = sw.norm();
  const Eigen::Vector3d u = d > 1e-9 ? Eigen::Vector3d(sw / d) : Eigen::Vector3d(0, -1, 0);
  d = std::clamp(d, std::abs(l1 - l2) + 1e-3, l1 + l2 - 1e-3);
  p.wrist = p.shoulder + d * u;
  const double along = (l1 * l1 - l2 * l2 + d * d) / (2 * d);
  const double across = std::sqrt(std::max(0.0, l1 * l1 - along * along));
  // The elbow out along elbow_out, orthogonal to the shoulder-wrist line.
  const Eigen::Vector3d out = g.elbow_out.normalized();
  Eigen::Vector3d n = out - out.dot(u) * u;
  if (n.norm() < 1e-6) n = Eigen::Vector3d(1, 0, 0) - u.x() * u;
  n.normalize();
  p.elbow = p.shoulder + along * u + across * n;
  const Eigen::Vector3d fore = (p.wrist - p.elbow).normalized();
  p.tip = p.wrist + g.hand * fore;
  return p;
}

namespace {
// Offsets within the arm's block.
constexpr int kWrist = 0, kElbow = 3, kTip = 6, kWristVel = 9, kElbowVel = 12;
}  // namespace

void WriteHumanArm(const HumanArmPose& pose, const Eigen::Vector3d& wrist_velocity,
                   const Eigen::Vector3d& elbow_velocity, int offset,
                   Eigen::Ref<Eigen::VectorXf> o) {
  for (int k = 0; k < 3; ++k) {
    o[offset + kWrist + k] = static_cast<float>(pose.wrist[k]);
    o[offset + kElbow + k] = static_cast<float>(pose.elbow[k]);
    o[offset + kTip + k] = static_cast<float>(pose.tip[k]);
    o[offset + kWristVel + k] = static_cast<float>(wrist_velocity[k]);
    o[offset + kElbowVel + k] = static_cast<float>(elbow_velocity[k]);
  }
}

HumanArmPose ReadHumanArm(const Eigen::Ref<const Eigen::VectorXf>& o, int offset,
                          const Eigen::Vector3d& shoulder, double ahead) {
  HumanArmPose p;
  p.shoulder = shoulder;
  p.wrist = ObservedPoint(o, offset + kWrist) + ahead * ObservedPoint(o, offset + kWristVel);
  p.elbow = ObservedPoint(o, offset + kElbow) + ahead * ObservedPoint(o, offset + kElbowVel);
  p.tip = ObservedPoint(o, offset + kTip) + ahead * ObservedPoint(o, offset + kWristVel);
  return p;
}

void ExtrapolateHumanArm(const Eigen::Ref<const Eigen::VectorXf>& state, int offset, float dt,
                         Eigen::Ref<Eigen::VectorXf> next) {
  for (int k = 0; k < 3; ++k) {
    next[offset + kWrist + k] += dt * state[offset + kWristVel + k];
    next[offset + kTip + k] += dt * state[offset + kWristVel + k];
    next[offset + kElbow + k] += dt * state[offset + kElbowVel + k];
  }
}

double SegmentDistance(const Eigen::Vector3d& p1, const Eigen::Vector3d& q1,
                       const Eigen::Vector3d& p2, const Eigen::Vector3d& q2) {
  const Eigen::Vector3d d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  constexpr double kEps = 1e-12;
  double s = 0, t = 0;
  if (a <= kEps && e <= kEps) return r.norm();
  if (a <= kEps) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= kEps) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2), denom = a * e - b * b;
      s = denom > kEps ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1) {
        t = 1;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  return ((p1 + s * d1) - (p2 + t * d2)).norm();
}

double SegmentToArmDistance(const HumanArmGeometry& g, const Eigen::Vector3d& a,
                            const Eigen::Vector3d& b, const HumanArmPose& arm) {
  return std::min({SegmentDistance(a, b, arm.shoulder, arm.elbow) - g.upper_arm_radius,
                   SegmentDistance(a, b, arm.elbow, arm.wrist) - g.forearm_radius,
                   SegmentDistance(a, b, arm.wrist, arm.tip) - g.hand_radius});
}

double MinJerk(double tau) {
  tau = std::clamp(tau, 0.0, 1.0);
  return tau * tau * tau * (10.0 + tau * (-15.0 + 6.0 * tau));
}

HumanArmCapsules::HumanArmCapsules(mjModel* raw, const HumanArmGeometry& g, const char* who) {
  auto id = [&](mjtObj type, const char* name) {
    const int i = mj_name2id(raw, type, name);
    SECURE_CHECK(i >= 0, "the " << who << " model has no " << name);
    return i;
  };
  const char* names[3] = {"upper_arm", "forearm", "person_hand"};
  const double lengths[3] = {g.upper_arm, g.forearm, g.hand};
  const double radii[3] = {g.upper_arm_radius, g.forearm_radius, g.hand_radius};
  for (int k = 0; k < 3; ++k) {
    const int geom = id(mjOBJ_GEOM, names[k]);
    raw->geom_size[3 * geom] = radii[k];
    raw->geom_size[3 * geom + 1] = lengths[k] / 2;
    raw->geom_pos[3 * geom + 2] = lengths[k] / 2;
    mocap_[k] = raw->body_mocapid[id(mjOBJ_BODY, names[k])];
    SECURE_CHECK(mocap_[k] >= 0, who << ": body " << names[k] << " is not a mocap body");
  }
}

void HumanArmCapsules::Pose(const mjModel* m, mjData* d, const HumanArmPose& pose) const {
  const Eigen::Vector3d from[3] = {pose.shoulder, pose.elbow, pose.wrist};
  const Eigen::Vector3d to[3] = {pose.elbow, pose.wrist, pose.tip};
  for (int k = 0; k < 3; ++k) {
    const int b = mocap_[k];
    for (int i = 0; i < 3; ++i) d->mocap_pos[3 * b + i] = from[k][i];
    mjtNum dir[3] = {to[k].x() - from[k].x(), to[k].y() - from[k].y(), to[k].z() - from[k].z()};
    mju_quatZ2Vec(d->mocap_quat + 4 * b, dir);
  }
  // The capsules' frames follow (positions of the other bodies are recomputed unchanged).
  mj_kinematics(m, d);
}

}  // namespace secure::domains::franka
