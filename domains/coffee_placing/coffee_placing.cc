#include "domains/coffee_placing/coffee_placing.h"

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

namespace secure::domains::coffee_placing {
// The model text (generated from coffee_placing.xml by CMake: coffee_placing_xml.cc).
extern const char kCoffeePlacingXml[];

namespace {

bool Finite(double x) { return std::isfinite(x); }

const mjModel* CoffeePlacingModel() {
  static const franka::MujocoModel model = franka::MujocoModel::FromXml(
      franka::WithPandaArm(kCoffeePlacingXml, "coffee_placing.xml"), "coffee_placing.xml");
  return model.get();
}

Eigen::Vector3d V(const Vec3& v) { return Eigen::Vector3d(v[0], v[1], v[2]); }

}  // namespace

bool Thresholds::Violated(double clearance, double tilt) const {
  return clearance < comfort_distance || std::abs(tilt) > max_tilt;
}

const std::vector<std::string>& ObservationFeatures() {
  static const std::vector<std::string> names{
      "ee_x",     "ee_y",     "ee_z",     "ee_vx",    "ee_vy",    "ee_vz",    "tilt",     "wrist_x",
      "wrist_y",  "wrist_z",  "elbow_x",  "elbow_y",  "elbow_z",  "hand_x",   "hand_y",   "hand_z",
      "wrist_vx", "wrist_vy", "wrist_vz", "elbow_vx", "elbow_vy", "elbow_vz", "clearance"};
  return names;
}

const std::vector<std::string>& ActionFeatures() {
  static const std::vector<std::string> names{"act_x", "act_y", "act_z", "act_tilt"};
  return names;
}

// ---------------------------------------------------------------------------------------------
// The person's arm, the cup

Eigen::Vector3d CupBottom(const Eigen::Vector3d& ee, double tilt) {
  return ee + Eigen::Vector3d(-kCupDrop * std::sin(tilt), 0.0, -kCupDrop * std::cos(tilt));
}

double Clearance(const PersonOptions& p, const Eigen::Vector3d& ee, double tilt,
                 const ArmPose& arm) {
  return franka::SegmentToArmDistance(p.Geometry(), ee, CupBottom(ee, tilt), arm);
}

double ObservedClearance(const PersonOptions& p, const Eigen::Ref<const Eigen::VectorXf>& o) {
  return Clearance(p, franka::ObservedPoint(o, kEePos), o[kTilt],
                   franka::ReadHumanArm(o, kWrist, p.Shoulder()));
}

BookReach DrawBookReach(const PersonOptions& p, Rng& rng) {
  BookReach r;
  r.book = static_cast<int>(rng.UniformIndex(p.book_x.size()));
  r.goal = Eigen::Vector3d(p.book_x[static_cast<std::size_t>(r.book)],
                           p.book_y + franka::DrawUniform(rng, p.goal_dy), p.goal_z);
  franka::DrawReachTiming(p, rng, &r);
  return r;
}

// ---------------------------------------------------------------------------------------------
// Options

void PersonOptions::Validate() const {
  const char* o = "PersonOptions";
  PersonArmOptions::Validate(o);
  SECURE_CHECK_FIELD(!book_x.empty() && book_x.size() <= 16, o, "book_x", book_x.size() << " books",
                     "1 to 16 books");
  for (double x : book_x)
    SECURE_CHECK_FIELD(Finite(x) && std::abs(x) <= 2, o, "book_x[]", x, "in [-2, 2] m");
  SECURE_CHECK_FIELD(Finite(book_y) && std::abs(book_y) <= 2, o, "book_y", book_y, "in [-2, 2] m");
  CheckIntervalField(goal_dy, o, "goal_dy", -0.5, 0.5);
  SECURE_CHECK_FIELD(Finite(goal_z) && goal_z > 0 && goal_z <= 1, o, "goal_z", goal_z,
                     "in (0, 1] m");
}

YamlFields PersonOptions::Fields() {
  YamlFields fields;
  AddFields(&fields);
  fields.Field("book_x", &book_x)
      .Field("book_y", &book_y)
      .Field("goal_dy", &goal_dy)
      .Field("goal_z", &goal_z);
  return fields;
}

SECURE_YAML_JSON_FROM_FIELDS(PersonOptions)

void CoffeePlacingOptions::Validate() const {
  const char* o = "CoffeePlacingOptions";
  ArmTaskOptions::Validate(o);
  for (int k = 0; k < 3; ++k) {
    SECURE_CHECK_FIELD(Finite(start[k]) && std::abs(start[k]) <= 1, o, "start", start[k],
                       "within 1 m of the origin");
    SECURE_CHECK_FIELD(Finite(target[k]) && std::abs(target[k]) <= 1, o, "target", target[k],
                       "within 1 m of the origin");
  }
  SECURE_CHECK_FIELD(start[2] >= kCupDrop, o, "start", start[2],
                     "high enough for the cup (z >= " << kCupDrop << " m)");
  SECURE_CHECK_FIELD(target[2] == 0.0, o, "target", target[2], "on the table (z = 0)");
  SECURE_CHECK_FIELD(Finite(start_noise) && start_noise >= 0 && start_noise <= 0.1, o,
                     "start_noise", start_noise, "in [0, 0.1] m");
  SECURE_CHECK_FIELD(Finite(target_half_size) && target_half_size > 0 && target_half_size <= 0.2, o,
                     "target_half_size", target_half_size, "in (0, 0.2] m");
  SECURE_CHECK_FIELD(Finite(place_tolerance) && place_tolerance > 0 && place_tolerance <= 0.1, o,
                     "place_tolerance", place_tolerance, "in (0, 0.1] m");
  SECURE_CHECK_FIELD(Finite(upright_tilt) && upright_tilt > 0 && upright_tilt < kMaxTilt, o,
                     "upright_tilt", upright_tilt, "in (0, " << kMaxTilt << ") rad");
  SECURE_CHECK_FIELD(Finite(tilt_scale) && tilt_scale > 0 && tilt_scale <= 0.5, o, "tilt_scale",
                     tilt_scale, "in (0, 0.5] rad");
  SECURE_CHECK_FIELD(Finite(tilt_coupling) && tilt_coupling >= 0 && tilt_coupling <= 5, o,
                     "tilt_coupling", tilt_coupling, "in [0, 5] rad per m/s");
  person.Validate();
}

YamlFields CoffeePlacingOptions::Fields() {
  YamlFields fields;
  ArmTaskOptions::AddFields(&fields);
  fields.Field("start", &start)
      .Field("start_noise", &start_noise)
      .Field("target", &target)
      .Field("target_half_size", &target_half_size)
      .Field("place_tolerance", &place_tolerance)
      .Field("upright_tilt", &upright_tilt)
      .Field("tilt_scale", &tilt_scale)
      .Field("tilt_coupling", &tilt_coupling)
      .Part("person", &person);
  return fields;
}

SECURE_YAML_JSON_FROM_FIELDS(CoffeePlacingOptions)

// ---------------------------------------------------------------------------------------------
// The simulation

struct CoffeePlacingSim::Impl : franka::ArmSim {
  franka::HumanArmCapsules capsules;
  int cup = -1;  // the cup's mocap index

  Impl(franka::MujocoModel m, const franka::HumanArmCapsules& c)
      : ArmSim(std::move(m), "coffee-placing"), capsules(c) {}
};

CoffeePlacingSim::CoffeePlacingSim(const CoffeePlacingOptions& options)
    : options_((options.Validate(), options)) {
  franka::MujocoModel m = franka::TaskModel(CoffeePlacingModel(), options_.tracking);
  mjModel* raw = m.get();
  const franka::HumanArmCapsules capsules(raw, options_.person.Geometry(), "coffee-placing");
  const int cup_body = mj_name2id(raw, mjOBJ_BODY, "cup");
  SECURE_CHECK(cup_body >= 0 && raw->body_mocapid[cup_body] >= 0,
               "coffee-placing: no cup mocap body in the model");
  const int cup = raw->body_mocapid[cup_body];
  impl_ = std::make_unique<Impl>(std::move(m), capsules);
  impl_->cup = cup;
  Rng rng(0);
  Reset(rng);
}

CoffeePlacingSim::~CoffeePlacingSim() = default;

const void* CoffeePlacingSim::model() const { return impl_->model.get(); }
void* CoffeePlacingSim::data() const { return impl_->data.get(); }

void CoffeePlacingSim::UpdateScene() {
  const PersonOptions& p = options_.person;
  mjData* d = impl_->data.get();
  const double t = d->time;
  const franka::PersonArmMotion motion = franka::PersonArmAt(p, reach_, t);
  arm_ = motion.pose;
  wrist_vel_ = motion.wrist_velocity;
  elbow_vel_ = motion.elbow_velocity;
  // The cup: its top at the tool centre point, tilted about y.
  const Eigen::Map<const Eigen::Vector3d> ee(d->site_xpos + 3 * impl_->arm.tcp());
  const Eigen::Vector3d centre = 0.5 * (ee + CupBottom(ee, tilt_));
  const int c = impl_->cup;
  for (int i = 0; i < 3; ++i) d->mocap_pos[3 * c + i] = centre[i];
  d->mocap_quat[4 * c] = std::cos(0.5 * tilt_);
  d->mocap_quat[4 * c + 1] = 0;
  d->mocap_quat[4 * c + 2] = std::sin(0.5 * tilt_);
  d->mocap_quat[4 * c + 3] = 0;
  clearance_ = Clearance(p, ee, tilt_, arm_);
  impl_->capsules.Pose(impl_->model.get(), d, arm_);  // (mj_kinematics: the cup too)
}

void CoffeePlacingSim::Reset(Rng& rng) {
  const mjModel* m = impl_->model.get();
  mjData* d = impl_->data.get();
  mj_resetData(m, d);
  impl_->arm.SetJoints(d, franka::kNeutralJoints);
  franka::UpdateKinematics(m, d);
  Eigen::Vector3d start = V(options_.start);
  for (int k = 0; k < 3; ++k) start[k] += options_.start_noise * (2.0 * rng.Uniform() - 1.0);
  impl_->arm.PlaceTool(m, d, start);
  franka::UpdateKinematics(m, d);
  tilt_ = 0;
  reach_ = DrawBookReach(options_.person, rng);
  UpdateScene();
}

void CoffeePlacingSim::Step(const Eigen::Ref<const Eigen::Vector4f>& action) {
  const mjModel* m = impl_->model.get();
  mjData* d = impl_->data.get();
  const Eigen::Vector4d a = franka::ClipAction<4>(action, "coffee-placing");
  mjtNum v[6];
  mj_objectVelocity(m, d, mjOBJ_SITE, impl_->arm.tcp(), v, 0);
  const double vx_before = v[3];
  // The cup stops at the table.
  franka::StepTool(impl_->arm, m, d, options_, a.head<3>(), options_.target[2] + kCupDrop,
                   "coffee-placing");
  mj_objectVelocity(m, d, mjOBJ_SITE, impl_->arm.tcp(), v, 0);
  tilt_ =
      std::clamp(tilt_ + options_.tilt_scale * a[3] + options_.tilt_coupling * (v[3] - vx_before),
                 -kMaxTilt, kMaxTilt);
  UpdateScene();
}

bool CoffeePlacingSim::Placed() const {
  const mjData* d = impl_->data.get();
  const Eigen::Map<const Eigen::Vector3d> ee(d->site_xpos + 3 * impl_->arm.tcp());
  const Eigen::Vector3d bottom = CupBottom(ee, tilt_);
  const CoffeePlacingOptions& o = options_;
  return std::abs(bottom.x() - o.target[0]) <= o.target_half_size &&
         std::abs(bottom.y() - o.target[1]) <= o.target_half_size &&
         bottom.z() - o.target[2] <= o.place_tolerance && std::abs(tilt_) <= o.upright_tilt;
}

void CoffeePlacingSim::Observe(Eigen::Ref<Eigen::VectorXf> o) const {
  franka::CheckObservationSize(o.size(), kObservationDim, "coffee-placing");
  franka::ObserveTool(impl_->model.get(), impl_->data.get(), impl_->arm.tcp(), kEePos, kEeVel, o);
  franka::WriteHumanArm(arm_, wrist_vel_, elbow_vel_, kWrist, o);
  o[kTilt] = static_cast<float>(tilt_);
  o[kClearance] = static_cast<float>(clearance_);
}

// ---------------------------------------------------------------------------------------------
// The shield's model

std::string CoffeeShieldModel::Describe() const {
  std::ostringstream s;
  s << "coffee-placing approximate model (ee += " << options_.position_gain
    << " a, ee_vel = " << options_.velocity_gain << " a, tilt += " << task_.tilt_scale
    << " a_tilt + " << task_.tilt_coupling << " dvx, the person's arm at constant velocity for "
    << options_.dt << " s, clearance recomputed)";
  return s.str();
}

void CoffeeShieldModel::StepOthers(const Eigen::Ref<const Eigen::VectorXf>& state,
                                   const Eigen::Ref<const Eigen::MatrixXf>& actions, Eigen::Index c,
                                   Eigen::Ref<Eigen::MatrixXf> next) const {
  franka::ExtrapolateHumanArm(state, kWrist, static_cast<float>(options_.dt), next.col(c));
  const float at = std::clamp(actions(3, c), -1.0f, 1.0f);
  const float tilt = state[kTilt] + static_cast<float>(task_.tilt_scale) * at +
                     static_cast<float>(task_.tilt_coupling) * (next(kEeVel, c) - state[kEeVel]);
  next(kTilt, c) = std::clamp(tilt, static_cast<float>(-kMaxTilt), static_cast<float>(kMaxTilt));
  next(kClearance, c) = static_cast<float>(ObservedClearance(task_.person, next.col(c)));
}

// ---------------------------------------------------------------------------------------------
// The environment

namespace {
// The camera of `secure render`, from the robot's right (-y), a little above: the person's arm
// reaching in from the back.
constexpr franka::CameraView kCoffeePlacingView{{0.25, 0.0, 0.12}, 1.5, 60, -30};
}  // namespace

CoffeePlacingEnv::CoffeePlacingEnv(const CoffeePlacingOptions& options,
                                   const CoffeeShieldModelOptions& shield_model,
                                   const Thresholds& thresholds)
    : ArmEnvironment(options, "coffee-placing", kCoffeePlacingView),
      shield_model_options_(shield_model),
      shield_model_(shield_model, options),
      thresholds_(thresholds) {}

std::vector<std::string> CoffeePlacingEnv::ObservationFeatures() const {
  return coffee_placing::ObservationFeatures();
}
std::vector<std::string> CoffeePlacingEnv::ActionFeatures() const {
  return coffee_placing::ActionFeatures();
}

std::string CoffeePlacingEnv::Describe() const {
  const CoffeePlacingOptions& o = sim_.options();
  std::ostringstream s;
  s << "Coffee placing (MuJoCo " << mj_versionString()
    << "): the Panda carries a cup to a target square and puts it down upright while a simulated "
       "person reaches for one of "
    << o.person.book_x.size() << " books beside its path; a violation: the hand-and-cup within "
    << thresholds_.comfort_distance << " m of the arm or the cup tilted beyond "
    << thresholds_.max_tilt << " rad; " << o.max_steps << " steps of " << o.tracking.control_period
    << " s";
  return s.str();
}

bool CoffeePlacingEnv::BackupAction(const Eigen::Ref<const Eigen::VectorXf>& o,
                                    Eigen::Ref<Eigen::VectorXf> action) const {
  const CoffeePlacingOptions& t = sim_.options();
  action.setZero();
  // Stopping changes the x velocity by -vx: turn the tilt and that back.
  const double tilt = o[kTilt] - t.tilt_coupling * o[kEeVel];
  action[3] = static_cast<float>(std::clamp(-tilt / t.tilt_scale, -1.0, 1.0));
  return true;
}

CoffeePlacingEnv::~CoffeePlacingEnv() = default;

std::unique_ptr<Environment> CoffeePlacingEnv::Clone() const {
  return std::make_unique<CoffeePlacingEnv>(sim_.options(), shield_model_options_, thresholds_);
}

}  // namespace secure::domains::coffee_placing
