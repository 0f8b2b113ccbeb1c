#include "domains/franka/arm_sim.h"

namespace secure::domains::franka {

MujocoModel TaskModel(const mjModel* base, const ArmTracking& tracking) {
  MujocoModel m = MujocoModel::Copy(base);
  m.get()->opt.timestep = tracking.control_period / tracking.substeps;
  return m;
}

std::array<double, kArmJoints> NoisyNeutralJoints(double noise, Rng& rng) {
  std::array<double, kArmJoints> q = kNeutralJoints;
  for (double& v : q) v += noise * (2.0 * rng.Uniform() - 1.0);
  return q;
}

void StepTool(PandaArm& arm, const mjModel* m, mjData* d, const ArmTaskOptions& task,
              const Eigen::Vector3d& a, double min_z, const char* who) {
  const Eigen::Map<const Eigen::Vector3d> ee(d->site_xpos + 3 * arm.tcp());
  Eigen::Vector3d target = ee + task.action_scale * a;
  target.z() = std::max(target.z(), min_z);
  arm.Track(m, d, target, task.tracking);
  CheckWarnings(d, who, "a step");
}

void CheckObservationSize(Eigen::Index size, int dim, const char* who) {
  SECURE_CHECK(size == dim, who << ": observation has " << size << " entries, expected " << dim);
}

void CheckObservation(const Eigen::Ref<const Eigen::VectorXf>& o,
                      const std::vector<std::string>& features, const char* who) {
  CheckObservationSize(o.size(), static_cast<int>(features.size()), who);
  for (Eigen::Index k = 0; k < o.size(); ++k) {
    SECURE_CHECK(std::isfinite(o[k]),
                 who << ": observation " << features[k] << " = " << o[k] << " is not finite");
  }
}

void ObserveTool(const mjModel* m, mjData* d, int tcp, int ee_pos, int ee_vel,
                 Eigen::Ref<Eigen::VectorXf> o) {
  mjtNum v[6];
  mj_objectVelocity(m, d, mjOBJ_SITE, tcp, v, 0);
  for (int k = 0; k < 3; ++k) {
    o[ee_pos + k] = static_cast<float>(d->site_xpos[3 * tcp + k]);
    o[ee_vel + k] = static_cast<float>(v[3 + k]);
  }
}

double PlaceObservedTool(PandaArm& arm, const mjModel* m, mjData* d,
                         const Eigen::Ref<const Eigen::VectorXf>& o, int ee_pos, int ee_vel) {
  const double error =
      arm.PlaceTool(m, d, Eigen::Vector3d(o[ee_pos], o[ee_pos + 1], o[ee_pos + 2]));
  arm.SetToolVelocity(m, d, Eigen::Vector3d(o[ee_vel], o[ee_vel + 1], o[ee_vel + 2]));
  return error;
}

}  // namespace secure::domains::franka
