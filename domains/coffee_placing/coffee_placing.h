#pragma once
// Coffee placing (paper Section 7.2, the user study's task), in simulation: the Panda carries a cup
// from a start point to a target square on the table and puts it down upright, while a person's
// arm (capsules moved kinematically) reaches for one of four books lying beside the robot's path
// (book and timing drawn per episode). MuJoCo physics for the arm (domains/franka/: the same
// Panda, controller and plumbing as panda-push and kitchen-cutting; the person's arm is
// domains/franka/human_arm.h, shared with kitchen-cutting). The model is coffee_placing.xml,
// embedded at build time. Every constant is an option (defaults in brackets), documented in
// README.md; the ones that stand for people are assumptions, not measurements of people.
//
//  - action a in [-1, 1]^4 (clipped): a[0..2] move the end-effector target by action_scale [0.05]
//    * a (m), tracked as in panda-push (IK + computed torque, 0.04 s, 20 physics steps; the
//    target is kept at or above the height that puts the cup's bottom on the table); a[3] is the
//    cup's tilt rate: tilt += tilt_scale [0.1 rad] * a[3] per control period;
//  - the cup's tilt (rad, about world y: the cup tips along x, the direction of travel) is a state
//    of the simulation, not a joint: the hand holds the cup in a compliant grip, so a change of
//    the hand's x velocity over a control period tilts it by tilt_coupling [0.5 rad per m/s]
//    (tilt += tilt_coupling * (vx_new - vx_old)), and a[3] turns it back; |tilt| <= 1.2 rad;
//  - success: the cup put down upright on the target square (the cup's bottom within
//    target_half_size of the square's centre in x and y, within place_tolerance of the table,
//    |tilt| <= upright_tilt);
//  - the person judges the robot by two thresholds (Thresholds): the clearance (the distance
//    from the robot's hand-and-cup segment, the tool centre point to the cup's bottom, to the
//    arm's capsules' surface) must stay >= comfort_distance, and |tilt| <= max_tilt. A step
//    where either fails is a violation: StepOutcome::collided (the environment's dangerous
//    event) for the thresholds the environment was made with;
//  - observation (23): ee position and velocity, tilt, the person's wrist, elbow and hand tip
//    positions, wrist and elbow velocities, clearance. ObservationFeatures() names them.
//
// Step() never ends an episode (environment.h); max_steps [150].

#include <Eigen/Core>
#include <array>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "domains/franka/arm_environment.h"
#include "domains/franka/arm_shield_model.h"
#include "domains/franka/arm_tracking.h"
#include "domains/franka/human_arm.h"
#include "domains/franka/person.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fwd.h"
#include "secure/domains/dynamics.h"
#include "secure/domains/environment.h"

namespace secure::domains::coffee_placing {

constexpr int kObservationDim = 23;
constexpr int kActionDim = 4;
// Observation layout.
constexpr int kEePos = 0, kEeVel = 3, kTilt = 6, kWrist = 7, kElbow = 10, kHandTip = 13,
              kWristVel = 16, kElbowVel = 19, kClearance = 22;
/// The cup (fixed by coffee_placing.xml): its bottom is kCupDrop below the tool centre point when
/// upright.
constexpr double kCupDrop = 0.09;
constexpr double kMaxTilt = 1.2;  // rad, the tilt's physical bound

/// "ee_x", ..., "ee_vx", ..., "tilt", "wrist_x", ..., "elbow_x", ..., "hand_x", ...,
/// "wrist_vx", ..., "elbow_vx", ..., "clearance".
const std::vector<std::string>& ObservationFeatures();
/// "act_x", "act_y", "act_z", "act_tilt".
const std::vector<std::string>& ActionFeatures();

using Vec3 = std::array<double, 3>;
using Interval = std::array<double, 2>;  // [lo, hi], drawn uniformly

/// A person's comfort thresholds: what they judge a violation.
struct Thresholds {
  double comfort_distance = 0.15;  // m, clearance below it is a violation
  double max_tilt = 0.25;          // rad, |tilt| above it is a violation
  bool Violated(double clearance, double tilt) const;
};

/// The person's arm and its reaches for the books. ASSUMPTIONS standing in for a person
/// (README.md), not measurements of people. The arm's body and the timing of its reaches are the
/// shared person's (franka::PersonArmOptions), with this plug-in's defaults for the shoulder
/// (a person at the table's +y side), the rest point and the dwell; where a reach goes (a book)
/// is this one's.
struct PersonOptions : franka::PersonArmOptions {
  std::vector<double> book_x = {0.00, 0.11, 0.22, 0.33};  // the four books' centres (m)
  double book_y = -0.04;                                  // m, the row of books
  Interval goal_dy = {-0.02, 0.03};  // the wrist's goal: the book's centre + this in y
  double goal_z = 0.08;              // m, the wrist above the book

  PersonOptions() {
    shoulder = {0.17, 0.48, 0.40};  // m
    rest = {0.17, 0.28, 0.15};      // m
    dwell = {0.5, 1.5};             // s
  }
  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// max_steps [150], the controller's constants (tracking) and action_scale: franka::ArmTaskOptions.
struct CoffeePlacingOptions : franka::ArmTaskOptions {
  Vec3 start = {0.32, -0.18, 0.22};  // the tool centre point at reset (m)
  double start_noise = 0.02;         // m, uniform per axis at reset
  Vec3 target = {0.02, -0.18, 0.0};  // the target square's centre on the table (m)
  double target_half_size = 0.03;    // m
  double place_tolerance = 0.01;     // m, the cup's bottom above the table
  double upright_tilt = 0.1;         // rad, |tilt| when put down
  double tilt_scale = 0.1;           // rad per unit a[3] per control period
  double tilt_coupling = 0.5;        // rad per m/s change of the hand's x velocity
  PersonOptions person;

  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// The person's arm at one instant: shoulder, elbow, wrist, hand tip (m).
using ArmPose = franka::HumanArmPose;
/// The elbow and hand tip for a wrist position.
using franka::ArmPoseForWrist;
/// The cup's bottom for a tool centre point and tilt.
Eigen::Vector3d CupBottom(const Eigen::Vector3d& ee, double tilt);
/// The clearance: the hand-and-cup segment (ee to the cup's bottom) to the arm's surface (m).
double Clearance(const PersonOptions& p, const Eigen::Vector3d& ee, double tilt,
                 const ArmPose& arm);
/// The clearance of an observation's hand and arm (the observation's own positions).
double ObservedClearance(const PersonOptions& p, const Eigen::Ref<const Eigen::VectorXf>& o);

/// One reach for a book (drawn at Reset).
struct BookReach : franka::PersonReach {
  int book = 0;
};
BookReach DrawBookReach(const PersonOptions& p, Rng& rng);

/// The MuJoCo simulation: model, data, the arm's controller, the cup's tilt, the person's arm.
/// Not copyable; one per thread. Allocation-free after construction.
class CoffeePlacingSim {
 public:
  explicit CoffeePlacingSim(const CoffeePlacingOptions& options);
  ~CoffeePlacingSim();
  CoffeePlacingSim(const CoffeePlacingSim&) = delete;
  CoffeePlacingSim& operator=(const CoffeePlacingSim&) = delete;

  const CoffeePlacingOptions& options() const { return options_; }
  /// The tool at the start (+ noise) by IK, at rest, the cup upright, a new reach.
  void Reset(Rng& rng);
  /// One control period. @throws secure::Error on a non-finite action or a MuJoCo warning.
  void Step(const Eigen::Ref<const Eigen::Vector4f>& action);
  void Observe(Eigen::Ref<Eigen::VectorXf> observation) const;

  double clearance() const { return clearance_; }
  double tilt() const { return tilt_; }
  bool Placed() const;
  const BookReach& reach() const { return reach_; }
  const void* model() const;
  void* data() const;

 private:
  void UpdateScene();  // the person's arm, the cup's mocap body, the clearance
  struct Impl;
  std::unique_ptr<Impl> impl_;
  CoffeePlacingOptions options_;
  BookReach reach_;
  ArmPose arm_;
  Eigen::Vector3d wrist_vel_, elbow_vel_;
  double tilt_ = 0, clearance_ = 1;
};

/// The shield's one-step model (approximate): ee += position_gain * a[0..2]; ee_vel =
/// velocity_gain * a[0..2]; tilt += tilt_scale * a[3] + tilt_coupling * (velocity_gain * a[0] -
/// ee_vx); the person's wrist, elbow and hand tip move on at the observed wrist and elbow
/// velocities for dt (the tip with the wrist); the clearance recomputed from the predicted
/// positions. It ignores the arm's dynamics, the table and the person's acceleration.
/// The options (position_gain, velocity_gain, dt) are the shared franka::PersonShieldModelOptions.
struct CoffeeShieldModelOptions : franka::PersonShieldModelOptions {
  void Validate() const { PersonShieldModelOptions::Validate("CoffeeShieldModelOptions"); }
};

class CoffeeShieldModel final
    : public franka::EndEffectorModel<CoffeeShieldModelOptions, kObservationDim, kActionDim, kEePos,
                                      kEeVel> {
 public:
  CoffeeShieldModel(const CoffeeShieldModelOptions& options, const CoffeePlacingOptions& task)
      : EndEffectorModel(options), task_(task) {}
  std::string Describe() const override;

 protected:
  /// The person's arm extrapolated for dt, the tilt, the clearance recomputed.
  void StepOthers(const Eigen::Ref<const Eigen::VectorXf>& state,
                  const Eigen::Ref<const Eigen::MatrixXf>& actions, Eigen::Index c,
                  Eigen::Ref<Eigen::MatrixXf> next) const override;

 private:
  CoffeePlacingOptions task_;
};

/// The task as an Environment, judged by `thresholds` (collided = a violation of them).
class CoffeePlacingEnv final
    : public franka::ArmEnvironment<CoffeePlacingSim, kObservationDim, kActionDim> {
 public:
  CoffeePlacingEnv(const CoffeePlacingOptions& options,
                   const CoffeeShieldModelOptions& shield_model, const Thresholds& thresholds);
  ~CoffeePlacingEnv() override;

  std::vector<std::string> ObservationFeatures() const override;
  std::vector<std::string> ActionFeatures() const override;
  std::string Describe() const override;
  const DynamicsModel& ShieldModel() const override { return shield_model_; }
  /// Stop and level the cup: a = (0, 0, 0, turn the tilt back, the stop's own tilt included).
  bool BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                    Eigen::Ref<Eigen::VectorXf> action) const override;
  std::unique_ptr<Environment> Clone() const override;

  const Thresholds& thresholds() const { return thresholds_; }

 private:
  bool Reached() const override { return sim_.Placed(); }
  bool Dangerous() const override { return thresholds_.Violated(sim_.clearance(), sim_.tilt()); }

  CoffeeShieldModelOptions shield_model_options_;
  CoffeeShieldModel shield_model_;
  Thresholds thresholds_;
};

}  // namespace secure::domains::coffee_placing
