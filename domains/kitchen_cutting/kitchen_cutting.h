#pragma once
// Kitchen cutting (paper Section 7.1, Table 3's kitchen row), in simulation: the Panda holds a
// knife (a thin box fixed to the hand, blade down, along world x) and cuts down through a line on
// a cutting board; a person's arm (capsules moved kinematically along a reaching path drawn at
// Reset) shares the space and sometimes reaches into the knife's workspace. MuJoCo physics for
// the arm (domains/franka/: the same Panda, controller and plumbing as panda-push); the model is
// kitchen_cutting.xml, embedded at build time. Every constant is an option (defaults in
// brackets), documented in README.md; the ones that stand for the person are assumptions, not
// measurements of people.
//
//  - action a in [-1, 1]^3 (clipped): the end-effector target is ee + action_scale [0.05] * a
//    (m), tracked as in panda-push (IK + computed torque, 0.04 s, 20 physics steps); the target
//    is kept at or above the height that puts the blade's edge on the board (the blade stops at
//    the board; there is no contact force between knife and board);
//  - the cut: the line on the board at cut_line_x +- cut_line_half_length along x, at
//    cut_line_y. A stroke counts when the blade's edge reaches the board (its centre within
//    stroke_tolerance of the board's top) over the line (edge centre within stroke_tolerance of
//    cut_line_y and its x within cut_line_half_length of cut_line_x) after having been lifted at
//    least lift_height above the board since the last counted stroke (the episode starts
//    lifted). Success: strokes_required [3] strokes;
//  - the person's arm: shoulder fixed, upper arm, forearm and hand as capsules; the wrist
//    follows a minimum-jerk reach from its rest point to a goal, dwells, and returns; the elbow
//    by the two-link arm's inverse kinematics (the elbow out towards the person and down). The goal
//    is in the knife's workspace (over the cut line) with probability into_probability, else beside
//    the board; start time, speed and dwell are drawn per episode;
//  - dangerous: the blade's cutting edge (the knife box's bottom edge) within contact_distance
//    [0.02 m] of an arm capsule's surface;
//  - observation (26): ee position and velocity, the blade edge's centre, the person's wrist,
//    elbow and hand tip positions, wrist and elbow velocities, cut progress (strokes done /
//    required; whether the blade is lifted), ObservationFeatures() names them.
//
// Step() never ends an episode (environment.h); max_steps [200].

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

namespace secure::domains::kitchen_cutting {

constexpr int kObservationDim = 26;
constexpr int kActionDim = 3;
// Observation layout.
constexpr int kEePos = 0, kEeVel = 3, kBlade = 6, kWrist = 9, kElbow = 12, kHandTip = 15,
              kWristVel = 18, kElbowVel = 21, kStrokes = 24, kLifted = 25;

/// "ee_x", ..., "blade_x", ..., "wrist_x", ..., "elbow_x", ..., "hand_x", ..., "wrist_vx", ...,
/// "elbow_vx", ..., "strokes", "lifted".
const std::vector<std::string>& ObservationFeatures();
/// "act_x", "act_y", "act_z".
const std::vector<std::string>& ActionFeatures();

using Vec3 = std::array<double, 3>;
using Interval = std::array<double, 2>;  // [lo, hi], drawn uniformly

/// The person's arm and its reaching paths. ASSUMPTIONS standing in for a person (README.md),
/// not measurements of people. The arm's body and the timing of its reaches are the shared
/// person's (franka::PersonArmOptions, whose defaults are this plug-in's: the shoulder at
/// (0.30, 0.38, 0.38) m, a person standing at the table's +y side; rest (0.30, 0.24, 0.12) m;
/// start_time [0, 1] s, speed [0.3, 0.6] m/s, dwell [0.5, 2] s); where a reach goes is this one's.
struct HumanArmOptions : franka::PersonArmOptions {
  double into_probability = 0.5;  // share of reaches that end over the cut line
  // Wrist goals of a reach into the knife's workspace (over the line) and of one beside it.
  Interval into_x = {0.24, 0.36}, into_y = {-0.04, 0.06}, into_z = {0.05, 0.09};
  Interval away_x = {0.15, 0.45}, away_y = {0.16, 0.26}, away_z = {0.05, 0.10};

  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// max_steps [200], the controller's constants (tracking) and action_scale: franka::ArmTaskOptions.
struct KitchenCuttingOptions : franka::ArmTaskOptions {
  KitchenCuttingOptions() { max_steps = 200; }
  double initial_joint_noise = 0.02;  // rad, uniform per joint at reset
  // The cut (the board's top is at board_top; the knife is fixed by the model: blade 0.16 m
  // long, its edge blade_drop below the tool centre point).
  double board_top = 0.015;
  double cut_line_x = 0.30, cut_line_y = 0.0, cut_line_half_length = 0.04;
  double stroke_tolerance = 0.01;  // m
  double lift_height = 0.04;       // m above the board to re-arm a stroke
  int strokes_required = 3;
  double contact_distance = 0.02;  // m, blade edge to arm surface: dangerous (ASSUMPTION)
  HumanArmOptions human;

  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// The knife (fixed by kitchen_cutting.xml): the blade's edge is kBladeDrop below the tool centre
/// point and kBladeHalfLength long either side along world x (hand pointing down).
constexpr double kBladeDrop = 0.055, kBladeHalfLength = 0.08;

/// The person's arm at one instant: shoulder, elbow, wrist, hand tip (m).
using ArmPose = franka::HumanArmPose;

/// The elbow and hand tip for a wrist position (the wrist pulled into reach if needed).
using franka::ArmPoseForWrist;

/// Distance from the blade's edge (the segment centre +- kBladeHalfLength along x) to the arm's
/// surface (capsule axis distance minus radius; < 0 inside). `edge_centre` is the edge's centre.
double EdgeToArmDistance(const HumanArmOptions& h, const Eigen::Vector3d& edge_centre,
                         const ArmPose& arm);

/// One reaching path (drawn at Reset): over the cut line (`into`) or beside it.
struct ReachPath : franka::PersonReach {
  bool into = false;
};
ReachPath DrawReachPath(const HumanArmOptions& h, Rng& rng);

/// The MuJoCo simulation: model, data, the arm's controller, the person's arm, the cut's
/// progress. Not copyable; one per thread. Allocation-free after construction.
class KitchenCuttingSim {
 public:
  explicit KitchenCuttingSim(const KitchenCuttingOptions& options);
  ~KitchenCuttingSim();
  KitchenCuttingSim(const KitchenCuttingSim&) = delete;
  KitchenCuttingSim& operator=(const KitchenCuttingSim&) = delete;

  const KitchenCuttingOptions& options() const { return options_; }

  /// Neutral posture + noise, a new reaching path, no strokes yet (lifted).
  void Reset(Rng& rng);
  /// One control period. @throws secure::Error on a non-finite action or a MuJoCo warning.
  void Step(const Eigen::Ref<const Eigen::Vector3f>& action);
  void Observe(Eigen::Ref<Eigen::VectorXf> observation) const;

  /// For the label check: the arm put by IK at the observation's end-effector position and
  /// velocity, the person's wrist and elbow at the observation's positions, moving on at the
  /// observation's velocities (constant-velocity extrapolation, replacing the reaching path),
  /// the progress features as given. Returns the remaining end-effector error (m).
  double SetObservation(const Eigen::Ref<const Eigen::VectorXf>& observation);

  /// Edge-to-arm distance now (m).
  double Clearance() const;
  bool Dangerous() const { return Clearance() < options_.contact_distance; }
  int strokes() const { return strokes_; }
  bool Succeeded() const { return strokes_ >= options_.strokes_required; }
  const ReachPath& path() const { return path_; }
  double time() const;
  const void* model() const;
  void* data() const;

 private:
  void UpdateHuman();  // the arm pose (and its mocap bodies) at the current time
  void UpdateProgress();
  struct Impl;
  std::unique_ptr<Impl> impl_;
  KitchenCuttingOptions options_;
  ReachPath path_;
  bool extrapolate_ = false;  // SetObservation: constant-velocity arm instead of the path
  Eigen::Vector3d wrist0_, elbow0_, wrist_v_, elbow_v_;
  double t0_ = 0;
  ArmPose arm_;
  Eigen::Vector3d wrist_vel_, elbow_vel_;
  int strokes_ = 0;
  bool lifted_ = true;
};

/// The shield's one-step model (approximate): ee += position_gain * a; ee_vel = velocity_gain *
/// a; blade edge += position_gain * a; the person's wrist, elbow and hand tip move on at the
/// observed wrist and elbow velocities for one control period (the tip with the wrist);
/// progress unchanged. It ignores the arm's dynamics, the board (the blade's floor) and the
/// person's acceleration.
/// The options (position_gain, velocity_gain, dt) are the shared franka::PersonShieldModelOptions.
struct KitchenShieldModelOptions : franka::PersonShieldModelOptions {
  void Validate() const { PersonShieldModelOptions::Validate("KitchenShieldModelOptions"); }
};

class KitchenShieldModel final
    : public franka::EndEffectorModel<KitchenShieldModelOptions, kObservationDim, kActionDim,
                                      kEePos, kEeVel> {
 public:
  using EndEffectorModel::EndEffectorModel;
  std::string Describe() const override;

 protected:
  /// The blade, fixed to the hand.
  int Carried(const Eigen::Ref<const Eigen::VectorXf>&) const override { return kBlade; }
  /// The person's arm extrapolated for dt.
  void StepOthers(const Eigen::Ref<const Eigen::VectorXf>& state,
                  const Eigen::Ref<const Eigen::MatrixXf>& actions, Eigen::Index c,
                  Eigen::Ref<Eigen::MatrixXf> next) const override;
};

/// The task as an Environment (franka::ArmEnvironment: Render() draws offscreen with MuJoCo's
/// renderer, OSMesa, from the robot's right, the person's arm at the back).
class KitchenCuttingEnv final
    : public franka::ArmEnvironment<KitchenCuttingSim, kObservationDim, kActionDim> {
 public:
  KitchenCuttingEnv(const KitchenCuttingOptions& options,
                    const KitchenShieldModelOptions& shield_model);
  ~KitchenCuttingEnv() override;

  std::vector<std::string> ObservationFeatures() const override;
  std::vector<std::string> ActionFeatures() const override;
  std::string Describe() const override;
  const DynamicsModel& ShieldModel() const override { return shield_model_; }
  /// Lifting the knife straight up: a = (0, 0, 1).
  bool BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                    Eigen::Ref<Eigen::VectorXf> action) const override;
  std::unique_ptr<Environment> Clone() const override;

 private:
  bool Reached() const override { return sim_.Succeeded(); }
  bool Dangerous() const override { return sim_.Dangerous(); }

  KitchenShieldModelOptions shield_model_options_;
  KitchenShieldModel shield_model_;
};

}  // namespace secure::domains::kitchen_cutting
