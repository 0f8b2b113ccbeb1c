#include "domains/panda_push/panda_push.h"

#include <mujoco/mujoco.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <mutex>
#include <sstream>

#include "domains/franka/arm_sim.h"
#include "domains/franka/mujoco_model.h"
#include "domains/franka/offscreen_renderer.h"
#include "domains/franka/panda_arm.h"
#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"
#include "secure/dynamics/ensemble.h"
#include "secure/dynamics/learned_environment.h"

namespace secure::domains::panda_push {
// The model text (generated from panda_push.xml by CMake: panda_push_xml.cc).
extern const char kPandaPushXml[];

namespace {

bool Finite(double x) { return std::isfinite(x); }

// The task's model: panda_push.xml with the Panda put in (franka::WithPandaArm), parsed once per
// process.
const mjModel* PandaPushModel() {
  static const franka::MujocoModel model = franka::MujocoModel::FromXml(
      franka::WithPandaArm(kPandaPushXml, "panda_push.xml"), "panda_push.xml");
  return model.get();
}

constexpr bool SameNeutralPosture() {
  for (int i = 0; i < kArmJoints; ++i)
    if (kNeutralJoints[i] != franka::kNeutralJoints[i]) return false;
  return kArmJoints == franka::kArmJoints;
}
static_assert(SameNeutralPosture(), "panda_push.h's neutral posture is the shared arm's");

}  // namespace

const std::vector<std::string>& ObservationFeatures() {
  static const std::vector<std::string> names{
      "ee_x",     "ee_y",     "ee_z",     "ee_vx",      "ee_vy",       "ee_vz",
      "block_x",  "block_y",  "block_z",  "block_roll", "block_pitch", "block_yaw",
      "block_vx", "block_vy", "block_vz", "block_wx",   "block_wy",    "block_wz"};
  return names;
}

const std::vector<std::string>& ActionFeatures() {
  static const std::vector<std::string> names{"act_x", "act_y", "act_z"};
  return names;
}

// ---------------------------------------------------------------------------------------------
// Options

void PandaPushOptions::Validate() const {
  const char* o = "PandaPushOptions";
  ArmTaskOptions::Validate(o);
  SECURE_CHECK_FIELD(
      Finite(initial_joint_noise) && initial_joint_noise >= 0 && initial_joint_noise <= 0.2, o,
      "initial_joint_noise", initial_joint_noise, "in [0, 0.2] rad");
  for (int i = 0; i < 3; ++i) {
    SECURE_CHECK_FIELD(Finite(block_start[i]), o, "block_start", block_start[i], "finite");
    SECURE_CHECK_FIELD(Finite(target[i]), o, "target", target[i], "finite");
  }
  SECURE_CHECK_FIELD(block_start[2] == 0.2, o, "block_start[2]", block_start[2],
                     "0.2 (the block stands on the table: half its height)");
  SECURE_CHECK_FIELD(Finite(success_radius) && success_radius > 0, o, "success_radius",
                     success_radius, "> 0");
  SECURE_CHECK_FIELD(Finite(topple_angle) && topple_angle > 0 && topple_angle < 1.5707963, o,
                     "topple_angle", topple_angle, "in (0, pi/2) rad");
  SECURE_CHECK_FIELD(Finite(table_friction) && table_friction > 0 && table_friction <= 5, o,
                     "table_friction", table_friction, "in (0, 5]");
  SECURE_CHECK_FIELD(Finite(pusher_friction) && pusher_friction > 0 && pusher_friction <= 5, o,
                     "pusher_friction", pusher_friction, "in (0, 5]");
}

YamlFields PandaPushOptions::Fields() {
  YamlFields fields;
  ArmTaskOptions::AddFields(&fields);
  fields.Field("initial_joint_noise", &initial_joint_noise)
      .Field("block_start", &block_start)
      .Field("target", &target)
      .Field("success_radius", &success_radius)
      .Field("topple_angle", &topple_angle)
      .Field("table_friction", &table_friction)
      .Field("pusher_friction", &pusher_friction);
  return fields;
}

SECURE_YAML_JSON_FROM_FIELDS(PandaPushOptions)

// ---------------------------------------------------------------------------------------------
// The simulation

// The model is this simulation's copy (options applied).
struct PandaPushSim::Impl : franka::ArmSim {
  int block_body = -1, block_qpos = -1, block_dof = -1;

  explicit Impl(franka::MujocoModel m) : ArmSim(std::move(m), "panda-push") {}
};

PandaPushSim::PandaPushSim(const PandaPushOptions& options)
    : options_((options.Validate(), options)) {
  franka::MujocoModel m = franka::TaskModel(PandaPushModel(), options_.tracking);
  mjModel* raw = m.get();
  for (int p = 0; p < raw->npair; ++p) {
    const std::string name = mj_id2name(raw, mjOBJ_PAIR, p) ? mj_id2name(raw, mjOBJ_PAIR, p) : "";
    if (name == "block_table") {
      raw->pair_friction[5 * p] = raw->pair_friction[5 * p + 1] = options_.table_friction;
    } else if (name.rfind("block_", 0) == 0) {
      raw->pair_friction[5 * p] = raw->pair_friction[5 * p + 1] = options_.pusher_friction;
    }
  }
  impl_ = std::make_unique<Impl>(std::move(m));
  Impl& s = *impl_;
  const mjModel* mm = s.model.get();
  auto id = [&](mjtObj type, const char* name) {
    const int i = mj_name2id(mm, type, name);
    SECURE_CHECK(i >= 0, "the Panda model has no " << name);
    return i;
  };
  s.block_body = id(mjOBJ_BODY, "block");
  const int block_joint = id(mjOBJ_JOINT, "block");
  s.block_qpos = mm->jnt_qposadr[block_joint];
  s.block_dof = mm->jnt_dofadr[block_joint];
  ResetTo(kNeutralJoints);
}

PandaPushSim::~PandaPushSim() = default;

const void* PandaPushSim::model() const { return impl_->model.get(); }
void* PandaPushSim::data() const { return impl_->data.get(); }
double PandaPushSim::time() const { return impl_->data.get()->time; }

void PandaPushSim::ResetTo(const std::array<double, kArmJoints>& joints) {
  Impl& s = *impl_;
  const mjModel* m = s.model.get();
  mjData* d = s.data.get();
  mj_resetData(m, d);
  s.arm.SetJoints(d, joints);
  for (int k = 0; k < 3; ++k) d->qpos[s.block_qpos + k] = options_.block_start[k];
  d->qpos[s.block_qpos + 3] = 1.0;
  for (int k = 4; k < 7; ++k) d->qpos[s.block_qpos + k] = 0.0;
  franka::UpdateKinematics(m, d);
}

void PandaPushSim::Reset(Rng& rng) {
  ResetTo(franka::NoisyNeutralJoints(options_.initial_joint_noise, rng));
}

void PandaPushSim::Step(const Eigen::Ref<const Eigen::Vector3f>& action) {
  Impl& s = *impl_;
  const mjModel* m = s.model.get();
  mjData* d = s.data.get();
  const Eigen::Vector3d a = franka::ClipAction<3>(action, "panda-push");
  // The end-effector target (kinematics are current: every public call leaves them so), kept
  // above the table, tracked for one control period.
  franka::StepTool(s.arm, m, d, options_, a, 0.0, "panda-push");
}

void PandaPushSim::Observe(Eigen::Ref<Eigen::VectorXf> o) const {
  franka::CheckObservationSize(o.size(), kObservationDim, "panda-push");
  const Impl& s = *impl_;
  const mjModel* m = s.model.get();
  mjData* d = s.data.get();
  franka::ObserveTool(m, d, s.arm.tcp(), kEePos, kEeVel, o);
  mjtNum v[6];
  for (int k = 0; k < 3; ++k) o[kBlockPos + k] = static_cast<float>(d->xpos[3 * s.block_body + k]);
  const mjtNum* r = d->xmat + 9 * s.block_body;  // row-major
  o[kBlockEuler + 0] = static_cast<float>(std::atan2(r[7], r[8]));
  o[kBlockEuler + 1] = static_cast<float>(std::asin(std::clamp(-r[6], -1.0, 1.0)));
  o[kBlockEuler + 2] = static_cast<float>(std::atan2(r[3], r[0]));
  mj_objectVelocity(m, d, mjOBJ_BODY, s.block_body, v, 0);
  for (int k = 0; k < 3; ++k) o[kBlockVel + k] = static_cast<float>(v[3 + k]);
  for (int k = 0; k < 3; ++k) o[kBlockAngVel + k] = static_cast<float>(v[k]);
}

double PandaPushSim::SetObservation(const Eigen::Ref<const Eigen::VectorXf>& o) {
  franka::CheckObservation(o, ObservationFeatures(), "panda-push");
  Impl& s = *impl_;
  const mjModel* m = s.model.get();
  mjData* d = s.data.get();
  ResetTo(kNeutralJoints);
  // The arm: IK from the neutral posture to the end-effector position, hand down, with the joint
  // velocities that give the end-effector velocity (no rotation).
  const double error = franka::PlaceObservedTool(s.arm, m, d, o, kEePos, kEeVel);
  // The block: R = Rz(yaw) Ry(pitch) Rx(roll).
  for (int k = 0; k < 3; ++k) d->qpos[s.block_qpos + k] = o[kBlockPos + k];
  const Eigen::Quaterniond q = Eigen::AngleAxisd(o[kBlockEuler + 2], Eigen::Vector3d::UnitZ()) *
                               Eigen::AngleAxisd(o[kBlockEuler + 1], Eigen::Vector3d::UnitY()) *
                               Eigen::AngleAxisd(o[kBlockEuler + 0], Eigen::Vector3d::UnitX());
  d->qpos[s.block_qpos + 3] = q.w();
  d->qpos[s.block_qpos + 4] = q.x();
  d->qpos[s.block_qpos + 5] = q.y();
  d->qpos[s.block_qpos + 6] = q.z();
  // Free joint: linear velocity in the world frame, angular velocity in the body frame.
  const Eigen::Vector3d w_world(o[kBlockAngVel], o[kBlockAngVel + 1], o[kBlockAngVel + 2]);
  const Eigen::Vector3d w_body = q.toRotationMatrix().transpose() * w_world;
  for (int k = 0; k < 3; ++k) {
    d->qvel[s.block_dof + k] = o[kBlockVel + k];
    d->qvel[s.block_dof + 3 + k] = w_body[k];
  }
  franka::UpdateKinematics(m, d);
  return error;
}

void PandaPushSim::CopyStateFrom(const PandaPushSim& other) {
  if (&other == this) return;
  const mjModel* m = impl_->model.get();
  const mjModel* o = other.impl_->model.get();
  // mj_copyData needs the same sizes; the options' physical constants (friction, timestep)
  // must agree too, which the constructor's callers ensure (one options struct).
  SECURE_CHECK(
      m->nbuffer == o->nbuffer && m->nstack == o->nstack && m->opt.timestep == o->opt.timestep,
      "panda-push: CopyStateFrom needs two simulations of the same model and options");
  mj_copyData(impl_->data.get(), m, other.impl_->data.get());
}

double PandaPushSim::BlockTilt() const {
  const mjData* d = impl_->data.get();
  return std::acos(std::clamp(d->xmat[9 * impl_->block_body + 8], -1.0, 1.0));
}

double PandaPushSim::TargetDistance() const {
  const mjData* d = impl_->data.get();
  const mjtNum* p = d->xpos + 3 * impl_->block_body;
  double sum = 0;
  for (int k = 0; k < 3; ++k) sum += (p[k] - options_.target[k]) * (p[k] - options_.target[k]);
  return std::sqrt(sum);
}

// ---------------------------------------------------------------------------------------------
// The shield's model

void PandaPushShieldModelOptions::Validate() const {
  const char* o = "PandaPushShieldModelOptions";
  SECURE_CHECK_FIELD(kind == "approximate" || kind == "rollout" || kind == "learned", o, "kind",
                     kind, "approximate, rollout or learned");
  SECURE_CHECK_FIELD(kind == "learned" || path.empty(), o, "path", path,
                     "empty unless kind = learned");
  SECURE_CHECK_FIELD(kind != "learned" || !path.empty(), o, "path", "''",
                     "a learned dynamics model file (`secure dynamics train`) with kind = learned");
  EndEffectorGains::Validate(o);
  SECURE_CHECK_FIELD(Finite(contact_range) && contact_range >= 0, o, "contact_range", contact_range,
                     ">= 0");
}

YamlFields PandaPushShieldModelOptions::Fields() {
  YamlFields fields;
  fields.Field("kind", &kind);
  AddFields(&fields);
  fields.Field("contact_range", &contact_range).Field("path", &path);
  return fields;
}

nlohmann::json PandaPushShieldModelOptions::ToJson() const {
  nlohmann::json j = TableJson(*this);
  if (kind != "learned") j.erase("path");  // a model file only for kind = learned
  return j;
}

void PandaPushShieldModelOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  Fields().Apply(node, source);
}

std::string PandaPushShieldModel::Describe() const {
  std::ostringstream s;
  s << "panda-push approximate model (ee += " << options_.position_gain
    << " a, ee_vel = " << options_.velocity_gain << " a, block follows within "
    << options_.contact_range << " m)";
  return s.str();
}

int PandaPushShieldModel::Carried(const Eigen::Ref<const Eigen::VectorXf>& state) const {
  const bool pushing =
      std::abs(state[kEePos] - state[kBlockPos]) < static_cast<float>(options_.contact_range);
  return pushing ? kBlockPos : -1;
}

PandaPushRolloutModel::PandaPushRolloutModel(const PandaPushSim& live)
    : live_(live),
      start_(std::make_unique<PandaPushSim>(live.options())),
      work_(std::make_unique<PandaPushSim>(live.options())),
      live_observation_(kObservationDim) {}

PandaPushRolloutModel::~PandaPushRolloutModel() = default;

std::string PandaPushRolloutModel::Describe() const {
  return "panda-push rollout model (privileged: one simulated control period per action, from "
         "the simulator's state)";
}

void PandaPushRolloutModel::DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
                                   const Eigen::Ref<const Eigen::MatrixXf>& actions,
                                   Eigen::Ref<Eigen::MatrixXf> next) const {
  live_.Observe(live_observation_);
  const PandaPushSim* from = &live_;
  if (!(state.array() == live_observation_.array()).all()) {
    start_->SetObservation(state);
    from = start_.get();
    ++reconstructed_;
  }
  for (Eigen::Index c = 0; c < actions.cols(); ++c) {
    work_->CopyStateFrom(*from);
    work_->Step(Eigen::Vector3f(actions(0, c), actions(1, c), actions(2, c)));
    work_->Observe(next.col(c));
  }
}

// ---------------------------------------------------------------------------------------------
// The environment

namespace {
// The camera of `secure render`, seen from the side (-y), slightly above the table: the arm at
// the left, the block and the target at the right.
constexpr franka::CameraView kPandaPushView{{0.12, 0.0, 0.3}, 2.0, 75, -15};
}  // namespace

PandaPushEnv::PandaPushEnv(const PandaPushOptions& options,
                           const PandaPushShieldModelOptions& shield_model)
    : ArmEnvironment(options, "panda-push", kPandaPushView),
      shield_model_options_(shield_model),
      shield_model_(shield_model) {
  if (shield_model.kind == "rollout")
    rollout_model_ = std::make_unique<PandaPushRolloutModel>(sim_);
  if (shield_model.kind == "learned") {
    // A learned ensemble (secure/dynamics): the evaluation pairs it with a barrier pessimistic
    // over its members (dynamics::ForShieldModel).
    auto model = std::make_shared<const dynamics::EnsembleDynamics>(
        dynamics::EnsembleDynamics::Load(shield_model.path));
    dynamics::CheckModelFeatures(*model, panda_push::ObservationFeatures(),
                                 panda_push::ActionFeatures(), shield_model.path);
    learned_model_ = std::make_unique<dynamics::EnsembleModel>(std::move(model));
  }
}

const DynamicsModel& PandaPushEnv::ShieldModel() const {
  if (rollout_model_ != nullptr) return *rollout_model_;
  if (learned_model_ != nullptr) return *learned_model_;
  return shield_model_;
}

PandaPushEnv::~PandaPushEnv() = default;

std::vector<std::string> PandaPushEnv::ObservationFeatures() const {
  return panda_push::ObservationFeatures();
}
std::vector<std::string> PandaPushEnv::ActionFeatures() const {
  return panda_push::ActionFeatures();
}

std::string PandaPushEnv::Describe() const {
  const PandaPushOptions& o = sim_.options();
  std::ostringstream s;
  s << "Panda Arm Push (MuJoCo " << mj_versionString() << "): push a 0.08 x 0.08 x 0.40 m, 1 kg "
    << "block from (" << o.block_start[0] << ", " << o.block_start[1] << ") to within "
    << o.success_radius << " m of (" << o.target[0] << ", " << o.target[1]
    << ") without tilting it past " << o.topple_angle << " rad; " << o.max_steps << " steps of "
    << o.tracking.control_period << " s, friction table " << o.table_friction << ", pusher "
    << o.pusher_friction;
  return s.str();
}

bool PandaPushEnv::BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                                Eigen::Ref<Eigen::VectorXf> action) const {
  action.setZero();
  return true;
}

std::unique_ptr<Environment> PandaPushEnv::Clone() const {
  return std::make_unique<PandaPushEnv>(sim_.options(), shield_model_options_);
}

}  // namespace secure::domains::panda_push
