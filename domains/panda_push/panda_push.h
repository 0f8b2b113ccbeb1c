#pragma once
// Panda Arm Push (paper Section 6, Figure 7): a Franka Emika Panda pushes a tall block
// (0.08 x 0.08 x 0.40 m, 1 kg) 0.15 m along the table to a target without toppling it. MuJoCo
// physics (the model is panda_push.xml, our own, embedded in the library at build time).
//
// The task follows the released panda-gym task (/work/shared/reference/official-code-facts.md §2);
// every constant is a PandaPushOptions field (defaults in brackets), documented in README.md:
//  - action a in [-1, 1]^3 (clipped): the end-effector target is ee + action_scale [0.05] * a
//    (m), its z clipped to >= 0, the hand pointing down (tool z = -world z, tool x = world x);
//  - the arm tracks the target: one damped-least-squares IK step on MuJoCo's site Jacobian gives
//    the joint goal, a computed-torque controller (M(q) (kp e + kd de) + bias, natural
//    frequency tracking_omega [40 rad/s], critically damped, the Panda's torque limits) follows
//    the straight joint-space ramp to it over the control period [0.04 s] in `substeps` [20]
//    physics steps;
//  - the observation (18): ee position, ee velocity, block position, block Euler angles (roll,
//    pitch, yaw with R = Rz(yaw) Ry(pitch) Rx(roll), PyBullet's convention), block linear and
//    angular velocity (world frame), ObservationFeatures() names them;
//  - reset: the released neutral posture (0, 0.11, 0, -2.55, 0, 2.6, 0.79) rad plus
//    U(-initial_joint_noise, +initial_joint_noise) [0.02 rad] per joint, so that evaluation
//    episodes differ (the released task is deterministic); the block at block_start
//    [(0.40, 0, 0.20)], upright, at rest; the target at [(0.55, 0, 0.20)];
//  - success: ||block - target|| < success_radius [0.03]; dangerous: the block's tilt from
//    upright (the angle between its z axis and the world's) > topple_angle [0.4 rad] (the
//    released test is |pitch| > 0.4, which misses a block falling sideways);
//  - contacts: block-table friction [0.6], pusher (hand, fingers)-block friction [0.5]. Why 0.6:
//    a tall block pushed at height z above the table at steady speed tips when the push's moment
//    beats gravity's about the front edge, mu m g z > m g w / 2, i.e. above z = w / (2 mu) =
//    0.067 m (w = 0.08); the released near-dangerous "upper part" starts at 0.07 m and the
//    demonstrations push at 0.01-0.04 m. And a block sliding free (pushed fast, then let go)
//    tips forward whenever mu > w / (2 h) = 0.2 (h = 0.2, its centre of mass): the faster it
//    slides, the further it tips. PandaPushLabelCheck (label_check.h) measures both.
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
#include "secure/common/rng.h"
#include "secure/common/yaml_fwd.h"
#include "secure/domains/dynamics.h"
#include "secure/domains/environment.h"

namespace secure::dynamics {
class EnsembleModel;
}  // namespace secure::dynamics

namespace secure::domains::panda_push {

constexpr int kObservationDim = 18;
constexpr int kActionDim = 3;
constexpr int kArmJoints = 7;
// Observation layout.
constexpr int kEePos = 0, kEeVel = 3, kBlockPos = 6, kBlockEuler = 9, kBlockVel = 12,
              kBlockAngVel = 15;

/// "ee_x", "ee_y", "ee_z", "ee_vx", ..., "block_wz" (the released data's column names).
const std::vector<std::string>& ObservationFeatures();
/// "act_x", "act_y", "act_z".
const std::vector<std::string>& ActionFeatures();

/// The released neutral posture of the arm (rad).
inline constexpr std::array<double, kArmJoints> kNeutralJoints = {0.0, 0.11, 0.0, -2.55,
                                                                  0.0, 2.6,  0.79};

/// max_steps [150], the controller's constants (tracking) and action_scale: franka::ArmTaskOptions.
struct PandaPushOptions : franka::ArmTaskOptions {
  double initial_joint_noise = 0.02;  // rad, uniform per joint at reset
  std::array<double, 3> block_start = {0.40, 0.0, 0.20};
  std::array<double, 3> target = {0.55, 0.0, 0.20};
  double success_radius = 0.03;
  double topple_angle = 0.4;     // rad of tilt from upright
  double table_friction = 0.6;   // block-table sliding friction
  double pusher_friction = 0.1;  // block-hand and block-finger sliding friction

  /// @throws secure::Error naming the field, value and rule.
  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  /// Keys: the field names above (block_start and target as 3-sequences). Does not validate.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// The MuJoCo simulation of the task: model, data, controller. Not copyable; one per thread.
/// Allocation-free after construction (Reset, Step, Observe, SetObservation).
class PandaPushSim {
 public:
  /// Loads the embedded model and applies `options` (validated). @throws secure::Error on a
  /// MuJoCo error or warning.
  explicit PandaPushSim(const PandaPushOptions& options);
  ~PandaPushSim();
  PandaPushSim(const PandaPushSim&) = delete;
  PandaPushSim& operator=(const PandaPushSim&) = delete;

  const PandaPushOptions& options() const { return options_; }

  /// The arm at `joints` at rest, the block at its start, at rest.
  void ResetTo(const std::array<double, kArmJoints>& joints);
  /// ResetTo(neutral + noise from rng).
  void Reset(Rng& rng);
  /// One control period with action `a` (clipped to [-1, 1]^3). @throws secure::Error on a
  /// non-finite action or on a MuJoCo warning (e.g. the contact buffer overflowed).
  void Step(const Eigen::Ref<const Eigen::Vector3f>& action);
  /// The 18-D observation of the current state.
  void Observe(Eigen::Ref<Eigen::VectorXf> observation) const;
  /// Puts the simulation in the state an observation describes: the arm by IK at the end-effector
  /// position (hand pointing down) with the joint velocities that give the end-effector velocity,
  /// the block at its position, orientation and velocities. Returns the remaining end-effector
  /// position error (m; small unless the position is out of reach).
  double SetObservation(const Eigen::Ref<const Eigen::VectorXf>& observation);

  /// Puts this simulation in `other`'s exact state: MuJoCo's whole mjData (positions,
  /// velocities, warm starts, derived quantities); the controller keeps no state of its own.
  /// Both must be built from the same options. @throws secure::Error if their models' sizes
  /// or timesteps differ.
  void CopyStateFrom(const PandaPushSim& other);

  /// The block's tilt from upright (rad).
  double BlockTilt() const;
  /// The block's distance to the target (m).
  double TargetDistance() const;
  /// Within success_radius of the target and not toppled (a block falling over passes through
  /// the target region; the released test does not exclude it).
  bool Succeeded() const { return TargetDistance() < options_.success_radius && !Toppled(); }
  bool Toppled() const { return BlockTilt() > options_.topple_angle; }
  /// Simulated time since the last reset (s).
  double time() const;

  /// For rendering: the MuJoCo model and data (opaque here so that users of this header do not
  /// need MuJoCo's headers).
  const void* model() const;
  void* data() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  PandaPushOptions options_;
};

/// The shield's one-step model (the released approximate model, official-code-facts.md §2.8,
/// with its gains as options): s' = s except
///   ee_pos += position_gain * a;  ee_vel = velocity_gain * a;
///   if |ee_x - block_x| < contact_range: block_pos += position_gain * a (all three axes).
/// Approximate: it ignores the arm's dynamics, the block's rotation and whether the pusher
/// actually touches the block. The released gains (0.033, 0.2) were fitted to panda-gym; ours
/// (the defaults) are measured on this simulator (README.md): the arm tracks the target within
/// one period, so the end-effector moves action_scale * a = 0.05 a per step and at 1.25 a m/s.
/// The action is clipped to [-1, 1] first (the environment clips it too; the released model
/// does not).
///
/// `kind: rollout` replaces it with PandaPushRolloutModel (below), privileged and exact: an upper
/// bound on what a perfect model gives the shield, at the cost of one simulated control period
/// per sampled action (the gains then play no part).
/// The gains (position_gain, velocity_gain) are the shared franka::EndEffectorGains.
struct PandaPushShieldModelOptions : franka::EndEffectorGains {
  std::string kind = "approximate";  // approximate | rollout | learned
  std::string path;                  // kind = learned: a `secure dynamics train` model file
  double contact_range = 0.15;
  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson (which writes path
  /// only for kind = learned).
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

class PandaPushShieldModel final
    : public franka::EndEffectorModel<PandaPushShieldModelOptions, kObservationDim, kActionDim,
                                      kEePos, kEeVel> {
 public:
  using EndEffectorModel::EndEffectorModel;
  std::string Describe() const override;

 protected:
  /// The block while pushing (|ee_x - block_x| < contact_range), else none.
  int Carried(const Eigen::Ref<const Eigen::VectorXf>& state) const override;
};

/// The privileged one-step model: each sampled action is simulated in MuJoCo for one control
/// period, and its next observation is the model's prediction. From the live simulation's own
/// observation (the shield's case: it decides at the state the environment is in) the rollout
/// starts from the live simulation's exact state, so the prediction is exactly the observation
/// Step(a) will write. From any other observation it starts from the state SetObservation
/// reconstructs (arm by IK, block placed; the arm's joint velocities and the contacts' warm
/// starts are then approximations). Privileged: it reads the simulator's state, which a real
/// robot's shield cannot; cost ~ one environment step per action. Not thread-safe (scratch
/// simulations); each environment (one per thread) owns its own.
class PandaPushRolloutModel final : public DynamicsModel {
 public:
  /// `live` must outlive the model.
  explicit PandaPushRolloutModel(const PandaPushSim& live);
  ~PandaPushRolloutModel() override;
  int state_dim() const override { return kObservationDim; }
  int action_dim() const override { return kActionDim; }
  std::string Describe() const override;
  /// How many predictions started from a reconstructed (not the live) state, since construction.
  long reconstructed_states() const { return reconstructed_; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override;

 private:
  const PandaPushSim& live_;
  std::unique_ptr<PandaPushSim> start_;  // a reconstructed start state
  std::unique_ptr<PandaPushSim> work_;   // each action's rollout
  mutable Eigen::VectorXf live_observation_;
  mutable long reconstructed_ = 0;
};

/// The task as an Environment (franka::ArmEnvironment: Render() draws offscreen with MuJoCo's
/// renderer, OSMesa, from the side).
class PandaPushEnv final
    : public franka::ArmEnvironment<PandaPushSim, kObservationDim, kActionDim> {
 public:
  PandaPushEnv(const PandaPushOptions& options, const PandaPushShieldModelOptions& shield_model);
  ~PandaPushEnv() override;

  std::vector<std::string> ObservationFeatures() const override;
  std::vector<std::string> ActionFeatures() const override;
  std::string Describe() const override;

  /// The approximate model, or with shield_model.kind = rollout the privileged rollout model.
  const DynamicsModel& ShieldModel() const override;
  /// True with the rollout model (exact from every observation the environment is in).
  bool ShieldModelIsExact() const override { return rollout_model_ != nullptr; }
  /// Holding still: a = 0 (the end-effector target stays where it is).
  bool BackupAction(const Eigen::Ref<const Eigen::VectorXf>& observation,
                    Eigen::Ref<Eigen::VectorXf> action) const override;
  std::unique_ptr<Environment> Clone() const override;

 private:
  bool Reached() const override { return sim_.Succeeded(); }
  bool Dangerous() const override { return sim_.Toppled(); }

  PandaPushShieldModelOptions shield_model_options_;
  PandaPushShieldModel shield_model_;
  std::unique_ptr<PandaPushRolloutModel> rollout_model_;    // kind = rollout
  std::unique_ptr<dynamics::EnsembleModel> learned_model_;  // kind = learned
};

}  // namespace secure::domains::panda_push
