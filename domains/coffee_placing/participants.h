#pragma once
// The simulated participants of the coffee-placing user study (paper Section 7.2) and their data.
// ASSUMPTIONS standing in for people (README.md, "The participants"), not measurements of
// people.
//
// A participant has
//   - thresholds (Thresholds): a comfort distance between the robot's hand-and-cup and their arm,
//     and a maximum cup tilt. Participant i's value of each is mean + spread * half_range * u_i
//     with u_i ~ U(-1, 1) drawn from the population seed (the same u_i at every spread, so a
//     sweep over the spread changes only how far apart the participants are);
//   - a demonstration style: the margin they keep on top of their comfort distance (caution),
//     the hand's top speed (travel_speed), how fast they change it (ramp: the largest change of
//     an action component per step, a drawn factor times their max tilt: who minds the tilt
//     moves gently), their action noise; and a label noise (the fraction of
//     states they label the wrong way).
//
// Demonstrations (Table 2: about 2000 states per participant; the participant's scripted
// demonstrator, whole episodes kept until there are at least `states`): from each observation,
//   - the arm (now, or extrapolated look_ahead seconds at its velocity) within comfort + caution
//     of the hand-and-cup: back away from it (-y, and up) at travel speed;
//   - else the arm within comfort + caution of the straight path to the point above the target
//     (hover_height): hold (no motion);
//   - else go to that point at travel speed (a = offset / 0.05, at most travel_speed per axis),
//     then down onto the target at descend_speed;
//   - the tilt action turns the tilt back, the tilt this action's change of x velocity causes
//     included: a_tilt = -(tilt + coupling * (velocity_gain * a_x - vx)) / tilt_scale;
//   - every component moves at most `ramp` from the action the current velocity shows (v /
//     velocity_gain), then N(0, noise^2) noise, clipped to [-1, 1].
// An episode with a violation of the participant's own thresholds, or that does not put the cup
// down, is discarded.
//
// Labelled states (Table 2: 2500 safe + 2500 unsafe per participant): demonstration states with
// the person's arm moved (p = arm_probability: the wrist put within arm_radius of the hand, in a
// random direction, the arm moving at up to arm_speed in a random direction) and / or the cup's
// tilt redrawn (p = tilt_probability: U(-tilt_range, tilt_range)); the clearance recomputed;
// labelled by the participant's thresholds (a violation: unsafe), then flipped with the
// participant's label noise; drawn until both classes are full. The judgement and the flip are
// ParticipantAnswersUnsafe, which is also the domain's labeller (Domain::Label, the mean
// participant): one rule, one copy of the thresholds.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "domains/coffee_placing/coffee_placing.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fwd.h"
#include "secure/data/data.h"

namespace secure::domains::coffee_placing {

/// One participant (ASSUMPTIONS).
struct Participant {
  int index = 0;
  Thresholds thresholds;
  double caution = 0.035;      // m kept on top of the comfort distance when demonstrating
  double travel_speed = 0.6;   // max |a| per axis moving
  double ramp = 0.15;          // max change of an action component per step
  double action_noise = 0.04;  // std of the demonstration noise per component
  double label_noise = 0.03;   // fraction of labels flipped
  nlohmann::json ToJson() const;
};

/// Where the participants' constants are drawn from (ASSUMPTIONS, README.md).
struct PopulationRanges {
  double comfort_mean = 0.15, comfort_half_range = 0.07;  // m: [0.08, 0.22] at spread 1
  double tilt_mean = 0.25, tilt_half_range = 0.12;        // rad: [0.13, 0.37] at spread 1
  Interval caution = {0.02, 0.05};
  Interval travel_speed = {0.25, 0.5};
  Interval ramp = {0.4, 0.8};  // per rad of max tilt: ramp = this * max_tilt
  Interval action_noise = {0.02, 0.06};
  Interval label_noise = {0.0, 0.06};

  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// Participant `index` of the population drawn from `seed` with the thresholds' spread scaled by
/// `spread` (>= 0; 0: every participant has the mean thresholds). Deterministic; independent of
/// how many participants there are.
Participant DrawParticipant(const PopulationRanges& ranges, std::uint64_t seed, int index,
                            double spread);
/// The mean participant: every constant at the middle of its range (the domain's default
/// participant for the ordinary experiments).
Participant MeanParticipant(const PopulationRanges& ranges);

struct CoffeeDemonstrationOptions {
  long states = 2000;           // at least this many demonstration states (whole episodes)
  int max_attempts = 2000;      // episodes tried before giving up
  double look_ahead = 0.3;      // s the arm is extrapolated
  double hover_height = 0.20;   // m, the tool centre point above the table while carrying
  double descend_speed = 0.5;   // |a_z| putting the cup down
  double velocity_gain = 1.25;  // the hand's velocity per unit action (m/s)

  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

struct CoffeeLabelOptions {
  long safe = 2500, unsafe = 2500;  // Table 2
  double arm_probability = 0.7;
  double arm_radius = 0.35;  // m
  double arm_speed = 0.5;    // m/s
  double tilt_probability = 0.5;
  double tilt_range = 0.6;  // rad

  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

struct CoffeeDemonstrations {
  data::TrajectorySet trajectories;
  long discarded_violating = 0, discarded_failed = 0;
};

/// The participant's demonstrator's action for an observation (noise-free).
Eigen::Vector4f DemonstratorAction(const CoffeePlacingOptions& task,
                                   const CoffeeDemonstrationOptions& options,
                                   const Participant& participant,
                                   const Eigen::Ref<const Eigen::VectorXf>& observation);

/// @throws secure::Error if the states are not reached within max_attempts.
CoffeeDemonstrations GenerateCoffeeDemonstrations(const CoffeePlacingOptions& task,
                                                  const CoffeeDemonstrationOptions& options,
                                                  const Participant& participant,
                                                  std::uint64_t seed);

/// The participant's judgement of an observation (kObservationDim values): a violation of their
/// thresholds (Thresholds::Violated) by the clearance recomputed from the observation's
/// positions (ObservedClearance, rounded to float as the observation's clearance feature is;
/// the row's own clearance feature is not read) and the tilt. True: unsafe.
bool ParticipantJudgesUnsafe(const PersonOptions& person, const Thresholds& thresholds,
                             const Eigen::Ref<const Eigen::VectorXf>& observation);
/// The participant's answer: the judgement flipped with probability participant.label_noise
/// (one uniform from `rng`, drawn whatever the judgement). True: unsafe.
bool ParticipantAnswersUnsafe(const PersonOptions& person, const Participant& participant,
                              const Eigen::Ref<const Eigen::VectorXf>& observation, Rng& rng);

/// The participant's labelled states (safe, unsafe) from the demonstration states.
/// @throws secure::Error if the classes cannot be filled.
void CoffeeLabelledStates(const CoffeePlacingOptions& task, const CoffeeLabelOptions& options,
                          const Participant& participant, const data::TrajectorySet& demos,
                          Rng& rng, data::StateSet* safe, data::StateSet* unsafe);

}  // namespace secure::domains::coffee_placing
