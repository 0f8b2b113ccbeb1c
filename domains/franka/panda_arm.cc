// GCC 12 reports false -Wmaybe-uninitialized inside Eigen's AVX-512 packet code for the small
// double products below (Eigen 3.4); the whole translation unit is quiet about it.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include "domains/franka/panda_arm.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

#include "secure/common/error.h"

namespace secure::domains::franka {

// The arm's text (generated from panda_arm.xml by CMake: panda_arm_xml.cc).
extern const char kPandaArmXml[];

namespace {

// The tool frame's target orientation: z down, x along world x (rotation by pi about x; the
// released IK target quaternion (x, y, z, w) = (1, 0, 0, 0)).
const Eigen::Matrix3d& TargetRotation() {
  static const Eigen::Matrix3d r = Eigen::Vector3d(1, -1, -1).asDiagonal();
  return r;
}

// Damped least squares: dq = J^T (J J^T + lambda^2 I)^-1 e, plus a null-space pull towards the
// neutral posture (so the redundant elbow does not drift over an episode).
Eigen::Matrix<double, kArmJoints, 1> IkStep(const Eigen::Matrix<double, 6, kArmJoints>& j,
                                            const Eigen::Matrix<double, 6, 1>& error,
                                            const Eigen::Matrix<double, kArmJoints, 1>& posture,
                                            double lambda) {
  const Eigen::Matrix<double, 6, 6> jjt =
      j * j.transpose() + lambda * lambda * Eigen::Matrix<double, 6, 6>::Identity();
  const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> solver(jjt);
  // J^T A^-1 = (A^-1 J)^T, A symmetric.
  const Eigen::Matrix<double, kArmJoints, 6> pinv = solver.solve(j).transpose();
  const Eigen::Matrix<double, kArmJoints, kArmJoints> null =
      Eigen::Matrix<double, kArmJoints, kArmJoints>::Identity() - pinv * j;
  return pinv * error + null * posture;
}

// The tool site's Jacobian (6 x 7, arm columns) at the current kinematics.
void ToolJacobian(const mjModel* m, mjData* d, int site, std::vector<mjtNum>& jacp,
                  std::vector<mjtNum>& jacr, Eigen::Matrix<double, 6, kArmJoints>* j) {
  mj_jacSite(m, d, jacp.data(), jacr.data(), site);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < kArmJoints; ++c) {
      (*j)(r, c) = jacp[r * m->nv + c];
      (*j)(r + 3, c) = jacr[r * m->nv + c];
    }
  }
}

// Position and orientation error of the tool site towards `target` (orientation: TargetRotation).
Eigen::Matrix<double, 6, 1> ToolError(const mjData* d, int site, const Eigen::Vector3d& target) {
  Eigen::Matrix<double, 6, 1> e;
  const Eigen::Map<const Eigen::Vector3d> p(d->site_xpos + 3 * site);
  const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> r(d->site_xmat + 9 * site);
  e.head<3>() = target - p;
  // Small-angle rotation vector from r to the target: 0.5 sum_i r_i x t_i over the columns.
  const Eigen::Matrix3d& t = TargetRotation();
  e.tail<3>() =
      0.5 * (r.col(0).cross(t.col(0)) + r.col(1).cross(t.col(1)) + r.col(2).cross(t.col(2)));
  return e;
}

// Replaces the one occurrence of `marker` in `text`.
void ReplaceOnce(std::string& text, const std::string& marker, const std::string& with,
                 const std::string& name) {
  const size_t at = text.find(marker);
  SECURE_CHECK(at != std::string::npos && text.find(marker, at + 1) == std::string::npos,
               name << ": the model must contain " << marker << " exactly once");
  text.replace(at, marker.size(), with);
}

}  // namespace

std::string WithPandaArm(const std::string& xml, const std::string& name) {
  const std::string arm = kPandaArmXml;
  const std::string split = "<!-- @ACTUATORS@";
  const size_t motors = arm.find(split);
  SECURE_CHECK(motors != std::string::npos, "panda_arm.xml: no " << split << " marker");
  std::string bodies = arm.substr(0, motors);
  const std::string actuators = "<actuator>\n" + arm.substr(motors) + "</actuator>\n";
  const std::string open = "<panda_arm>", close = "</panda_arm>";
  const size_t begin = xml.find(open);
  const size_t end = xml.find(close);
  SECURE_CHECK(begin != std::string::npos && end != std::string::npos && begin < end,
               name << ": the model must contain " << open << "TOOL" << close);
  const std::string tool = xml.substr(begin + open.size(), end - begin - open.size());
  ReplaceOnce(bodies, "@TOOL@", tool, "panda_arm.xml");
  std::string result = xml;
  result.replace(begin, end + close.size() - begin, bodies);
  ReplaceOnce(result, "<panda_arm_actuators/>", actuators, name);
  return result;
}

void UpdateKinematics(const mjModel* m, mjData* d) {
  mj_kinematics(m, d);
  mj_comPos(m, d);
  mj_comVel(m, d);
}

PandaArm::PandaArm(const mjModel* m, const char* who) {
  auto id = [&](mjtObj type, const char* name) {
    const int i = mj_name2id(m, type, name);
    SECURE_CHECK(i >= 0, who << ": the Panda model has no " << name);
    return i;
  };
  tcp_ = id(mjOBJ_SITE, "tcp");
  for (int i = 0; i < kArmJoints; ++i) {
    const std::string name = "joint" + std::to_string(i + 1);
    const int j = id(mjOBJ_JOINT, name.c_str());
    qpos_[i] = m->jnt_qposadr[j];
    dof_[i] = m->jnt_dofadr[j];
    lower_[i] = m->jnt_range[2 * j];
    upper_[i] = m->jnt_range[2 * j + 1];
    SECURE_CHECK(dof_[i] == i, who << ": the Panda model's arm joints must come first");
  }
  jacp_.assign(3 * m->nv, 0.0);
  jacr_.assign(3 * m->nv, 0.0);
  force_in_.assign(m->nv, 0.0);
  force_out_.assign(m->nv, 0.0);
}

void PandaArm::SetJoints(mjData* d, const std::array<double, kArmJoints>& q) const {
  for (int i = 0; i < kArmJoints; ++i) d->qpos[qpos_[i]] = q[i];
}

void PandaArm::Track(const mjModel* m, mjData* d, const Eigen::Vector3d& target,
                     const ArmTracking& tracking) {
  Eigen::Matrix<double, 6, kArmJoints> j;
  ToolJacobian(m, d, tcp_, jacp_, jacr_, &j);
  Eigen::Matrix<double, kArmJoints, 1> q0, posture;
  for (int i = 0; i < kArmJoints; ++i) {
    q0[i] = d->qpos[qpos_[i]];
    posture[i] = 0.1 * (kNeutralJoints[i] - q0[i]);
  }
  Eigen::Matrix<double, kArmJoints, 1> dq =
      IkStep(j, ToolError(d, tcp_, target), posture, tracking.ik_damping);
  for (int i = 0; i < kArmJoints; ++i) {
    // Stay 0.01 rad inside the joint limits.
    dq[i] = std::clamp(q0[i] + dq[i], lower_[i] + 0.01, upper_[i] - 0.01) - q0[i];
  }
  // Computed-torque tracking of the ramp q0 -> q0 + dq over the period.
  const double kp = tracking.tracking_omega * tracking.tracking_omega;
  const double kd = 2.0 * tracking.tracking_omega;
  const Eigen::Matrix<double, kArmJoints, 1> qd_ref = dq / tracking.control_period;
  for (int k = 1; k <= tracking.substeps; ++k) {
    mj_step1(m, d);
    const double f = static_cast<double>(k) / tracking.substeps;
    std::fill(force_in_.begin(), force_in_.end(), 0.0);
    for (int i = 0; i < kArmJoints; ++i) {
      const double e = q0[i] + f * dq[i] - d->qpos[qpos_[i]];
      const double ed = qd_ref[i] - d->qvel[dof_[i]];
      force_in_[dof_[i]] = kp * e + kd * ed;
    }
    mj_mulM(m, d, force_out_.data(), force_in_.data());
    for (int i = 0; i < kArmJoints; ++i) {
      const int dof = dof_[i];
      d->ctrl[i] = force_out_[dof] + d->qfrc_bias[dof] - d->qfrc_passive[dof];
    }
    mj_step2(m, d);
  }
  UpdateKinematics(m, d);
}

double PandaArm::PlaceTool(const mjModel* m, mjData* d, const Eigen::Vector3d& target) {
  Eigen::Matrix<double, 6, kArmJoints> j;
  Eigen::Matrix<double, 6, 1> e;
  for (int it = 0; it < 200; ++it) {
    e = ToolError(d, tcp_, target);
    if (e.norm() < 1e-7) break;
    ToolJacobian(m, d, tcp_, jacp_, jacr_, &j);
    Eigen::Matrix<double, kArmJoints, 1> posture;
    for (int i = 0; i < kArmJoints; ++i) posture[i] = 0.1 * (kNeutralJoints[i] - d->qpos[qpos_[i]]);
    const Eigen::Matrix<double, kArmJoints, 1> dq = IkStep(j, e, posture, 1e-3);
    for (int i = 0; i < kArmJoints; ++i) {
      double& q = d->qpos[qpos_[i]];
      q = std::clamp(q + dq[i], lower_[i] + 0.01, upper_[i] - 0.01);
    }
    UpdateKinematics(m, d);
  }
  e = ToolError(d, tcp_, target);
  return e.head<3>().norm();
}

void PandaArm::SetToolVelocity(const mjModel* m, mjData* d, const Eigen::Vector3d& v) {
  Eigen::Matrix<double, 6, kArmJoints> j;
  ToolJacobian(m, d, tcp_, jacp_, jacr_, &j);
  Eigen::Matrix<double, 6, 1> twist = Eigen::Matrix<double, 6, 1>::Zero();
  twist.head<3>() = v;
  const Eigen::Matrix<double, kArmJoints, 1> qd =
      IkStep(j, twist, Eigen::Matrix<double, kArmJoints, 1>::Zero(), 1e-3);
  for (int i = 0; i < kArmJoints; ++i) d->qvel[dof_[i]] = qd[i];
}

}  // namespace secure::domains::franka
