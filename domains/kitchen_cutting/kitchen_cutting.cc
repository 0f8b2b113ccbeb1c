#include "domains/kitchen_cutting/kitchen_cutting.h"

#include <mujoco/mujoco.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <sstream>

#include "domains/franka/arm_sim.h"
#include "domains/franka/human_arm.h"
#include "domains/franka/mujoco_model.h"
#include "domains/franka/offscreen_renderer.h"
#include "domains/franka/panda_arm.h"
#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/yaml_fields.h"

namespace secure::domains::kitchen_cutting {
// The model text (generated from kitchen_cutting.xml by CMake: kitchen_cutting_xml.cc).
extern const char kKitchenCuttingXml[];

namespace {

bool Finite(double x) { return std::isfinite(x); }

const mjModel* KitchenCuttingModel() {
  static const franka::MujocoModel model = franka::MujocoModel::FromXml(
      franka::WithPandaArm(kKitchenCuttingXml, "kitchen_cutting.xml"), "kitchen_cutting.xml");
  return model.get();
}

double EdgeDistance(const HumanArmOptions& h, const Eigen::Vector3d& centre,
                    const Eigen::Vector3d& axis, const ArmPose& arm) {
  const Eigen::Vector3d a = centre - kBladeHalfLength * axis, b = centre + kBladeHalfLength * axis;
  return franka::SegmentToArmDistance(h.Geometry(), a, b, arm);
}

}  // namespace

const std::vector<std::string>& ObservationFeatures() {
  static const std::vector<std::string> names{
      "ee_x",     "ee_y",     "ee_z",     "ee_vx",   "ee_vy",    "ee_vz",    "blade_x",
      "blade_y",  "blade_z",  "wrist_x",  "wrist_y", "wrist_z",  "elbow_x",  "elbow_y",
      "elbow_z",  "hand_x",   "hand_y",   "hand_z",  "wrist_vx", "wrist_vy", "wrist_vz",
      "elbow_vx", "elbow_vy", "elbow_vz", "strokes", "lifted"};
  return names;
}

const std::vector<std::string>& ActionFeatures() {
  static const std::vector<std::string> names{"act_x", "act_y", "act_z"};
  return names;
}

// ---------------------------------------------------------------------------------------------
// The person's arm

double EdgeToArmDistance(const HumanArmOptions& h, const Eigen::Vector3d& edge_centre,
                         const ArmPose& arm) {
  return EdgeDistance(h, edge_centre, Eigen::Vector3d::UnitX(), arm);
}

ReachPath DrawReachPath(const HumanArmOptions& h, Rng& rng) {
  ReachPath p;
  p.into = rng.Uniform() < h.into_probability;
  const Interval& x = p.into ? h.into_x : h.away_x;
  const Interval& y = p.into ? h.into_y : h.away_y;
  const Interval& z = p.into ? h.into_z : h.away_z;
  p.goal.x() = franka::DrawUniform(rng, x);
  p.goal.y() = franka::DrawUniform(rng, y);
  p.goal.z() = franka::DrawUniform(rng, z);
  franka::DrawReachTiming(h, rng, &p);
  return p;
}

// ---------------------------------------------------------------------------------------------
// Options

void HumanArmOptions::Validate() const {
  const char* o = "HumanArmOptions";
  PersonArmOptions::Validate(o);
  SECURE_CHECK_FIELD(Finite(into_probability) && into_probability >= 0 && into_probability <= 1, o,
                     "into_probability", into_probability, "in [0, 1]");
  CheckIntervalField(into_x, o, "into_x", -2, 2);
  CheckIntervalField(into_y, o, "into_y", -2, 2);
  CheckIntervalField(into_z, o, "into_z", 0, 2);
  CheckIntervalField(away_x, o, "away_x", -2, 2);
  CheckIntervalField(away_y, o, "away_y", -2, 2);
  CheckIntervalField(away_z, o, "away_z", 0, 2);
}

YamlFields HumanArmOptions::Fields() {
  YamlFields fields;
  AddFields(&fields);
  fields.Field("into_probability", &into_probability)
      .Field("into_x", &into_x)
      .Field("into_y", &into_y)
      .Field("into_z", &into_z)
      .Field("away_x", &away_x)
      .Field("away_y", &away_y)
      .Field("away_z", &away_z);
  return fields;
}

SECURE_YAML_JSON_FROM_FIELDS(HumanArmOptions)

void KitchenCuttingOptions::Validate() const {
  const char* o = "KitchenCuttingOptions";
  ArmTaskOptions::Validate(o);
  SECURE_CHECK_FIELD(
      Finite(initial_joint_noise) && initial_joint_noise >= 0 && initial_joint_noise <= 0.2, o,
      "initial_joint_noise", initial_joint_noise, "in [0, 0.2] rad");
  SECURE_CHECK_FIELD(board_top == 0.015, o, "board_top", board_top,
                     "0.015 (the board in kitchen_cutting.xml)");
  SECURE_CHECK_FIELD(Finite(cut_line_x) && Finite(cut_line_y), o, "cut_line_x", cut_line_x,
                     "finite (and cut_line_y)");
  SECURE_CHECK_FIELD(Finite(cut_line_half_length) && cut_line_half_length > 0, o,
                     "cut_line_half_length", cut_line_half_length, "> 0");
  SECURE_CHECK_FIELD(Finite(stroke_tolerance) && stroke_tolerance > 0 && stroke_tolerance < 0.05, o,
                     "stroke_tolerance", stroke_tolerance, "in (0, 0.05) m");
  SECURE_CHECK_FIELD(Finite(lift_height) && lift_height > stroke_tolerance && lift_height <= 0.3, o,
                     "lift_height", lift_height, "in (stroke_tolerance, 0.3] m");
  SECURE_CHECK_FIELD(strokes_required >= 1 && strokes_required <= 20, o, "strokes_required",
                     strokes_required, "in [1, 20]");
  SECURE_CHECK_FIELD(Finite(contact_distance) && contact_distance >= 0 && contact_distance < 0.2, o,
                     "contact_distance", contact_distance, "in [0, 0.2) m");
  human.Validate();
}

YamlFields KitchenCuttingOptions::Fields() {
  YamlFields fields;
  ArmTaskOptions::AddFields(&fields);
  fields.Field("initial_joint_noise", &initial_joint_noise)
      .Field("board_top", &board_top)
      .Field("cut_line_x", &cut_line_x)
      .Field("cut_line_y", &cut_line_y)
      .Field("cut_line_half_length", &cut_line_half_length)
      .Field("stroke_tolerance", &stroke_tolerance)
      .Field("lift_height", &lift_height)
      .Field("strokes_required", &strokes_required)
      .Field("contact_distance", &contact_distance)
      .Part("human", &human);
  return fields;
}

SECURE_YAML_JSON_FROM_FIELDS(KitchenCuttingOptions)

// ---------------------------------------------------------------------------------------------
// The simulation

struct KitchenCuttingSim::Impl : franka::ArmSim {
  franka::HumanArmCapsules capsules;  // the person's arm (upper arm, forearm, hand)
  int blade = -1, knife = -1;

  Impl(franka::MujocoModel m, const franka::HumanArmCapsules& c)
      : ArmSim(std::move(m), "kitchen-cutting"), capsules(c) {}
};

KitchenCuttingSim::KitchenCuttingSim(const KitchenCuttingOptions& options)
    : options_((options.Validate(), options)) {
  franka::MujocoModel m = franka::TaskModel(KitchenCuttingModel(), options_.tracking);
  mjModel* raw = m.get();
  // The person's capsules take the options' sizes (each runs along its body's z from 0 to L).
  const franka::HumanArmCapsules capsules(raw, options_.human.Geometry(), "kitchen-cutting");
  impl_ = std::make_unique<Impl>(std::move(m), capsules);
  const mjModel* mm = impl_->model.get();
  impl_->blade = mj_name2id(mm, mjOBJ_SITE, "blade");
  impl_->knife = mj_name2id(mm, mjOBJ_GEOM, "knife");
  SECURE_CHECK(impl_->blade >= 0 && impl_->knife >= 0, "kitchen-cutting: no knife in the model");
  Rng rng(0);
  Reset(rng);
}

KitchenCuttingSim::~KitchenCuttingSim() = default;

const void* KitchenCuttingSim::model() const { return impl_->model.get(); }
void* KitchenCuttingSim::data() const { return impl_->data.get(); }
double KitchenCuttingSim::time() const { return impl_->data.get()->time; }

void KitchenCuttingSim::UpdateHuman() {
  const HumanArmOptions& h = options_.human;
  const double t = impl_->data.get()->time;
  if (extrapolate_) {
    const double s = t - t0_;
    arm_.shoulder = h.Shoulder();
    arm_.wrist = wrist0_ + s * wrist_v_;
    arm_.elbow = elbow0_ + s * elbow_v_;
    const Eigen::Vector3d fore = arm_.wrist - arm_.elbow;
    arm_.tip = arm_.wrist + h.hand * (fore.norm() > 1e-9 ? Eigen::Vector3d(fore.normalized())
                                                         : Eigen::Vector3d(0, -1, 0));
    wrist_vel_ = wrist_v_;
    elbow_vel_ = elbow_v_;
  } else {
    const franka::PersonArmMotion motion = franka::PersonArmAt(h, path_, t);
    arm_ = motion.pose;
    wrist_vel_ = motion.wrist_velocity;
    elbow_vel_ = motion.elbow_velocity;
  }
  // The capsules (for the picture; the dangerous test uses arm_).
  impl_->capsules.Pose(impl_->model.get(), impl_->data.get(), arm_);
}

void KitchenCuttingSim::UpdateProgress() {
  const mjData* d = impl_->data.get();
  const mjtNum* edge = d->site_xpos + 3 * impl_->blade;
  const KitchenCuttingOptions& o = options_;
  if (edge[2] >= o.board_top + o.lift_height) lifted_ = true;
  if (lifted_ && edge[2] <= o.board_top + o.stroke_tolerance &&
      std::abs(edge[1] - o.cut_line_y) <= o.stroke_tolerance &&
      std::abs(edge[0] - o.cut_line_x) <= o.cut_line_half_length) {
    ++strokes_;
    lifted_ = false;
  }
}

void KitchenCuttingSim::Reset(Rng& rng) {
  const mjModel* m = impl_->model.get();
  mjData* d = impl_->data.get();
  mj_resetData(m, d);
  impl_->arm.SetJoints(d, franka::NoisyNeutralJoints(options_.initial_joint_noise, rng));
  franka::UpdateKinematics(m, d);
  path_ = DrawReachPath(options_.human, rng);
  extrapolate_ = false;
  strokes_ = 0;
  lifted_ = true;
  UpdateHuman();
}

void KitchenCuttingSim::Step(const Eigen::Ref<const Eigen::Vector3f>& action) {
  const mjModel* m = impl_->model.get();
  mjData* d = impl_->data.get();
  const Eigen::Vector3d a = franka::ClipAction<3>(action, "kitchen-cutting");
  // The blade stops at the board.
  franka::StepTool(impl_->arm, m, d, options_, a, options_.board_top + kBladeDrop,
                   "kitchen-cutting");
  UpdateHuman();
  UpdateProgress();
}

void KitchenCuttingSim::Observe(Eigen::Ref<Eigen::VectorXf> o) const {
  franka::CheckObservationSize(o.size(), kObservationDim, "kitchen-cutting");
  const mjData* d = impl_->data.get();
  franka::ObserveTool(impl_->model.get(), impl_->data.get(), impl_->arm.tcp(), kEePos, kEeVel, o);
  for (int k = 0; k < 3; ++k)
    o[kBlade + k] = static_cast<float>(d->site_xpos[3 * impl_->blade + k]);
  franka::WriteHumanArm(arm_, wrist_vel_, elbow_vel_, kWrist, o);
  o[kStrokes] = static_cast<float>(strokes_) / static_cast<float>(options_.strokes_required);
  o[kLifted] = lifted_ ? 1.0f : 0.0f;
}

double KitchenCuttingSim::SetObservation(const Eigen::Ref<const Eigen::VectorXf>& o) {
  franka::CheckObservation(o, ObservationFeatures(), "kitchen-cutting");
  const mjModel* m = impl_->model.get();
  mjData* d = impl_->data.get();
  mj_resetData(m, d);
  impl_->arm.SetJoints(d, franka::kNeutralJoints);
  franka::UpdateKinematics(m, d);
  const double error = franka::PlaceObservedTool(impl_->arm, m, d, o, kEePos, kEeVel);
  franka::UpdateKinematics(m, d);
  extrapolate_ = true;
  t0_ = d->time;
  for (int k = 0; k < 3; ++k) {
    wrist0_[k] = o[kWrist + k];
    elbow0_[k] = o[kElbow + k];
    wrist_v_[k] = o[kWristVel + k];
    elbow_v_[k] = o[kElbowVel + k];
  }
  strokes_ = static_cast<int>(std::lround(o[kStrokes] * options_.strokes_required));
  lifted_ = o[kLifted] > 0.5f;
  UpdateHuman();
  return error;
}

double KitchenCuttingSim::Clearance() const {
  const mjData* d = impl_->data.get();
  const Eigen::Map<const Eigen::Vector3d> centre(d->site_xpos + 3 * impl_->blade);
  // The blade's axis: the knife box's x axis (row-major xmat: column 0).
  const mjtNum* r = d->geom_xmat + 9 * impl_->knife;
  const Eigen::Vector3d axis(r[0], r[3], r[6]);
  return EdgeDistance(options_.human, centre, axis, arm_);
}

// ---------------------------------------------------------------------------------------------
// The shield's model

std::string KitchenShieldModel::Describe() const {
  std::ostringstream s;
  s << "kitchen-cutting approximate model (ee and blade += " << options_.position_gain
    << " a, ee_vel = " << options_.velocity_gain << " a, the person's arm at constant velocity for "
    << options_.dt << " s)";
  return s.str();
}

void KitchenShieldModel::StepOthers(const Eigen::Ref<const Eigen::VectorXf>& state,
                                    const Eigen::Ref<const Eigen::MatrixXf>&, Eigen::Index c,
                                    Eigen::Ref<Eigen::MatrixXf> next) const {
  franka::ExtrapolateHumanArm(state, kWrist, static_cast<float>(options_.dt), next.col(c));
}

// ---------------------------------------------------------------------------------------------
// The environment

namespace {
// The camera of `secure render`, looking at the board from the robot's right (-y), a little
// above: the arm at the left, the person's arm reaching in from the back.
constexpr franka::CameraView kKitchenCuttingView{{0.15, 0.05, 0.15}, 1.4, 60, -25};
}  // namespace

KitchenCuttingEnv::KitchenCuttingEnv(const KitchenCuttingOptions& options,
                                     const KitchenShieldModelOptions& shield_model)
    : ArmEnvironment(options, "kitchen-cutting", kKitchenCuttingView),
      shield_model_options_(shield_model),
      shield_model_(shield_model) {}

std::vector<std::string> KitchenCuttingEnv::ObservationFeatures() const {
  return kitchen_cutting::ObservationFeatures();
}
std::vector<std::string> KitchenCuttingEnv::ActionFeatures() const {
  return kitchen_cutting::ActionFeatures();
}

std::string KitchenCuttingEnv::Describe() const {
  const KitchenCuttingOptions& o = sim_.options();
  std::ostringstream s;
  s << "Kitchen cutting (MuJoCo " << mj_versionString() << "): the Panda cuts "
    << o.strokes_required << " strokes through a line on a board while a simulated person's arm "
    << "reaches (into the knife's workspace with p = " << o.human.into_probability
    << "); dangerous: the blade's edge within " << o.contact_distance << " m of the arm; "
    << o.max_steps << " steps of " << o.tracking.control_period << " s";
  return s.str();
}

bool KitchenCuttingEnv::BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                                     Eigen::Ref<Eigen::VectorXf> action) const {
  action.setZero();
  action[2] = 1.0f;
  return true;
}

KitchenCuttingEnv::~KitchenCuttingEnv() = default;

std::unique_ptr<Environment> KitchenCuttingEnv::Clone() const {
  return std::make_unique<KitchenCuttingEnv>(sim_.options(), shield_model_options_);
}

}  // namespace secure::domains::kitchen_cutting
