#pragma once
// The kitchen-cutting data: the scripted demonstrator, the safe and near-dangerous states, and
// the check of their labels against physics.
//
// Demonstrator (a careful person teaching the cut): from each observation, the blade's edge is
// compared with the person's arm now and extrapolated look_ahead seconds at its velocity:
//   - the arm within caution_distance of the edge: lift the knife straight up (a = (0, 0, 1));
//   - else the arm within caution_distance of the stroke's path (the edge lowered to the board
//     where it is): hold at hover_height above the board (rise to it, never descend);
//   - else cut: move over the line (a_xy = (line - edge_xy) / 0.05, at most travel_speed), at
//     hover_height until over it (within 1 cm), then down-strokes at stroke_speed (a_z < 0) until
//     the stroke counts and up at stroke_speed until the blade is lifted;
// each action component with N(0, action_noise^2) noise, clipped to [-1, 1]. An episode that
// comes dangerous or does not finish the cut is discarded. Episodes are kept until there are at
// least `states` demonstration states (Table 2: 2000).
//
// Safe states: `count` (Table 2: 450) demonstration states drawn without replacement.
//
// Near-dangerous states (`count`, Table 2: 450): demonstration states with the person's arm put
// close to the blade so that continuing the motion reaches it:
//   (a) stroke (p_stroke): the wrist under the blade's edge (x within the blade +- 0.07, y from
//       the edge's plane to 0.08 beyond it, away from the person, so that the forearm passes
//       under the edge; z between the board and the edge), the
//       edge clear of the arm by [contact_distance, near_distance] but the stroke's path (the
//       edge lowered to the board) within contact_distance of it, the end-effector moving down
//       at stroke_vz (the stroke continuing), the arm at rest;
//   (b) arm (the rest): the wrist within near_distance of the edge in a random direction, the
//       edge clear of the arm by [contact_distance, near_distance], the wrist (and the elbow at
//       half the speed) moving towards the edge's centre at arm_speed so that within look_ahead
//       the arm reaches contact_distance (constant velocity); the end-effector as demonstrated;
//   (d) reach (p_reach, off by default): the person's real reach, the state reach_gap before it
//       touches the blade (precursor.h).
// Each draw is rejection-sampled (at most 200 tries per state; a state without an accepted draw
// is skipped); the states are drawn in a random order of demonstration states. Scenarios (a)-(c)
// accept a draw by one clause each of the person's rule (JudgeKitchenState below), which is also
// the domain's labeller (Domain::Label): one rule, one copy of its thresholds.
//
// The person's rule (ASSUMPTION: how the person who made the near-dangerous states judges any
// state): from the observation alone (the blade's edge, the end-effector velocity, the arm's
// wrist, elbow and hand tip and their velocities),
//   - dangerous: the edge within contact_distance of the arm now (ObservedEdgeClearance);
//   - near-dangerous, if any clause holds:
//     (a) StrokeReaches: the end-effector moving down at a stroke's speed (-ee_vz >= the least
//         of stroke_vz, 0.3 m/s: not the hovering knife's drift of a few cm/s) and the stroke's
//         path (the edge lowered to the board; checked halfway and at the board) within
//         contact_distance;
//     (b) ArmReaches: the arm, moved on at its observed velocities (the hand tip with the
//         wrist) for look_ahead, within contact_distance of the edge where it is;
//     (c) BladeReaches: the edge, moved on at the end-effector velocity (10 points over
//         look_ahead, not below the board), within contact_distance of the arm where it is;
//   - else safe.
// Label noise: the labeller flips each answer with probability label_noise (default 0: the
// generator's person labels its states without mistakes, and its states are not flipped).
// Scenario (d) is labelled by the reach's real future, which the rule does not see: its states
// are near-dangerous by the rule only where (b) catches them (measured in the tests).
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "domains/kitchen_cutting/kitchen_cutting.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fwd.h"
#include "secure/data/data.h"

namespace secure::domains::kitchen_cutting {

struct KitchenDemonstrationOptions {
  long states = 2000;                  // at least this many demonstration states (whole episodes)
  int max_attempts = 2000;             // episodes tried before giving up
  Interval stroke_speed = {0.3, 0.6};  // |a_z| of a stroke (down and up), per episode
  Interval travel_speed = {0.6, 1.0};  // max |a_x|, |a_y| moving over the line, per episode
  double caution_distance = 0.10;      // m (ASSUMPTION: how close a careful person lets it come)
  double look_ahead = 0.3;             // s the arm is extrapolated
  double hover_height = 0.08;          // m of the edge above the board while waiting
  double action_noise = 0.02;
  std::uint64_t seed = 0;

  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

struct KitchenDemonstrations {
  data::TrajectorySet trajectories;
  long discarded_dangerous = 0, discarded_failed = 0;
  long into_episodes = 0;  // kept episodes whose reach went into the knife's workspace
};

/// @throws secure::Error if the states are not reached within max_attempts.
KitchenDemonstrations GenerateKitchenDemonstrations(const KitchenCuttingOptions& task,
                                                    const KitchenDemonstrationOptions& options);

/// The demonstrator's action for an observation (deterministic part; the noise is added by
/// GenerateKitchenDemonstrations). `stroke_speed`, `travel_speed` as drawn for the episode.
Eigen::Vector3f DemonstratorAction(const KitchenCuttingOptions& task,
                                   const KitchenDemonstrationOptions& options,
                                   const Eigen::Ref<const Eigen::VectorXf>& observation,
                                   double stroke_speed, double travel_speed);

struct KitchenSafeOptions {
  long count = 450;  // Table 2
  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

struct KitchenNearDangerousOptions {
  long count = 450;  // Table 2
  // The shares of the scenarios: (a) p_stroke, (c) p_blade, (b) the rest. Until 2026-12-02
  // p_stroke = 0.6 and no (c); (c) took the dangerous rate of SECURE from 5.8 to 2.6 % over 20
  // seeds (docs/RESULTS.md, "Kitchen cutting").
  double p_stroke = 0.4;
  double near_distance = 0.06;      // m, the edge's clearance from the arm at most
  Interval stroke_vz = {0.3, 1.0};  // m/s downwards
  Interval arm_speed = {0.2, 0.6};  // m/s
  double look_ahead = 0.3;          // s
  // (c) the blade moving into an arm at rest (the person holding the food, or dwelling): the
  // share of all states (drawn from the non-stroke share; 0 with p_stroke 0.6: the data of
  // earlier releases).
  double p_blade = 0.3;
  Interval blade_speed = {0.2, 1.0};  // m/s, the end-effector's speed towards the arm
  // (d) the person's real reach, reach_gap s before contact (precursor.h): the share of all
  // states (drawn from (b)'s share; 0: the data of earlier releases).
  double p_reach = 0.0;
  Interval reach_gap = {0.0, 0.2};  // s before the first contact
  // The labeller's share of wrong answers (JudgeKitchenState's answer flipped; not applied to
  // the generated states). 0: the generator's person.
  double label_noise = 0.0;
  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson (which writes p_reach
  /// and reach_gap only with p_reach > 0, label_noise only when > 0).
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

enum class NearDangerousScenario { kStroke, kArm, kBlade, kReach };
const char* ScenarioName(NearDangerousScenario s);

data::StateSet KitchenSafeStates(const KitchenDemonstrations& demos,
                                 const KitchenSafeOptions& options, Rng& rng);
/// @throws secure::Error if fewer than options.count states could be made.
data::StateSet KitchenNearDangerousStates(const KitchenCuttingOptions& task,
                                          const KitchenDemonstrations& demos,
                                          const KitchenNearDangerousOptions& options, Rng& rng,
                                          std::vector<NearDangerousScenario>* scenarios = nullptr);

/// The person's judgement of a state (the rule above).
enum class KitchenJudgement { kSafe, kNearDangerous, kDangerous };
/// The clauses of the rule, on the edge (its centre) and the arm in world coordinates.
/// (a) the end-effector moving down at `ee_vz` (< 0, -ee_vz >= stroke_vz[0]) and the stroke's
/// path within contact.
bool StrokeReaches(const KitchenCuttingOptions& task, const KitchenNearDangerousOptions& rule,
                   const Eigen::Vector3d& edge, double ee_vz, const ArmPose& arm);
/// (b) the arm moved on for `look_ahead` s (wrist and hand tip at `wrist_velocity`, elbow at
/// `elbow_velocity`) within contact of the edge.
bool ArmReaches(const KitchenCuttingOptions& task, const Eigen::Vector3d& edge, const ArmPose& arm,
                const Eigen::Vector3d& wrist_velocity, const Eigen::Vector3d& elbow_velocity,
                double look_ahead);
/// (c) the edge moved on at `ee_velocity` (10 points over `look_ahead` s, at or above the board)
/// within contact of the arm.
bool BladeReaches(const KitchenCuttingOptions& task, const Eigen::Vector3d& edge,
                  const Eigen::Vector3d& ee_velocity, const ArmPose& arm, double look_ahead);
/// The rule on an observation (kObservationDim values), with `rule`'s look_ahead and stroke_vz.
KitchenJudgement JudgeKitchenState(const KitchenCuttingOptions& task,
                                   const KitchenNearDangerousOptions& rule,
                                   const Eigen::Ref<const Eigen::VectorXf>& observation);

/// The labels against physics: the simulation is put in each state
/// (KitchenCuttingSim::SetObservation: the arm by IK, the person's arm moving on at its observed
/// velocity), the end-effector continues at its own velocity (a = v / velocity_gain, clipped) for
/// continue_seconds, then holds still (a = 0) for hold_seconds; the state leads to danger if the
/// edge comes within contact_distance of the arm at any step (or starts there). States the arm
/// cannot reach (IK error > 0.01 m) are counted apart.
struct KitchenLabelCheckOptions {
  double continue_seconds = 0.3;
  double hold_seconds = 0.2;
  double velocity_gain = 1.25;
  long max_states = 300;
};
struct KitchenLabelCheckResult {
  long states = 0, dangerous = 0, unreachable = 0;
};
KitchenLabelCheckResult CheckKitchenLabels(const KitchenCuttingOptions& task,
                                           const data::StateSet& set,
                                           const KitchenLabelCheckOptions& options);

}  // namespace secure::domains::kitchen_cutting
