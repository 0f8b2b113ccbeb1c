#pragma once
// The panda-push data: the scripted demonstrator, the safe and near-dangerous state generators,
// the authors' released data, and the check of the labels against physics.
//
// Demonstrator (in the style of the released keyboard teleoperation, official-code-facts.md
// §2.6): descend to a push height h ~ U(push_height) at a_z ~ -U(descend_speed); approach along
// +x at a_x ~ U(approach_speed), easing off linearly to the push speed a_x ~ U(push_speed) over
// the last approach_gap metres before the pusher touches the block; then push along +x at that
// speed holding the height (a_z = (h - z) / 0.05 * 0.5) and the line (a_y = -5 (ee_y - block_y)),
// each action component with N(0, action_noise^2) noise, until the block reaches the target;
// with DART perturbations (dart_noise, dart_brake_rate) the applied action differs from the
// recorded one (below).
// The push starts (push_begin) at the first state within 5 mm of contact. Episodes that topple
// the block or miss the target are discarded.
//
// Near-dangerous states (the released generator, §2.7, in this simulator's units and without
// its bug that copies unmodified states into the unsafe set): the pushing part of each
// demonstration (from its first push step) is processed `copies` times; each copy draws one
// scenario, every state then draws its own values:
//   (a) upper part (p_upper):  ee_x -= back_off; ee_z ~ U(upper_z);
//   (b) too fast   (p_fast):   ee_x -= back_off; ee_z ~ U(0, low_z_max); and with probability
//                              fast_x_share ee_vx ~ U(fast_vx), otherwise ee_vz ~ U(fast_vz);
//   (c) both       (the rest): ee_x -= back_off; ee_z ~ U(upper_z); ee_vx ~ U(fast_vx).
// `count` states are drawn from the result without replacement.
//
// Safe states: the demonstration states, each also copied `noisy_copies` times with the released
// noise (ee_x += U(-0.01, 0), ee_y += U(-0.005, 0.005), ee_z += U(-0.001, 0.001), every ee and
// block velocity component += U(-0.001, 0.001)); `count` drawn without replacement.
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "domains/panda_push/panda_push.h"
#include "secure/common/enum_strings.h"
#include "secure/common/rng.h"
#include "secure/common/yaml_fwd.h"
#include "secure/data/data.h"

namespace secure::domains::panda_push {

/// A closed interval [lo, hi] to draw from uniformly.
struct Range {
  double lo = 0, hi = 0;
};

struct PandaDemonstrationOptions {
  // Kept demonstrations. The paper learns from 2 teleoperated ones (246 states); our scripted ones
  // are shorter (about 45 steps) and BC/AIRL from 6 of them drifted off the block (AIRL 55 %
  // success); 20 (about 900 states) gave AIRL 90-95 % (docs/RESULTS.md).
  int episodes = 20;
  int max_attempts = 100;  // episodes tried before giving up
  Range push_height = {0.02, 0.035};  // m, the end-effector height while pushing
  Range descend_speed = {0.5, 0.9};   // -a_z while descending
  Range approach_speed = {0.4, 0.7};  // a_x while approaching
  Range push_speed = {0.08, 0.15};    // a_x while pushing
  // m: the approach speed eases to the push speed over this gap. 0.2 (was 0.1): the demonstrations
  // then reach the block slowly, so that no safe state lies 1-2 cm from contact at approach speed,
  // next to the "too fast" near-dangerous states; the shield then brakes a fast approach
  // (docs/RESULTS.md, Panda: 10 seeds x 100, dangerous 13.6 -> 5.7 %).
  double approach_gap = 0.2;
  double action_noise = 0.02;         // sd of the per-component action noise
  // Pauses (a keyboard user letting go of the push key; not in the paper): after the descent,
  // at each step with probability pause_rate a_x is 0 for U(pause_steps) steps (rounded), then the push
  // resumes, from rest. Without them every demonstrated state in contact is moving, and a policy
  // that learned a_x ~ the current velocity cannot start again once the shield has braked it to
  // a stop (docs/RESULTS.md, Panda). 0: none (the draws are then those of a version without it).
  double pause_rate = 0.0;
  Range pause_steps = {2, 6};
  // DART-style perturbations (Laskey et al. 2017; not in the paper; issue 30 lever 4): the
  // *applied* action differs from the *recorded* one, which stays the demonstrator's corrective
  // action at the perturbed state. After the descent every applied component gets
  // N(0, dart_noise^2); once in contact, at each step with probability dart_brake_rate a brake of
  // U(dart_brake_steps) steps (rounded) starts in which the applied a_x is 0 while the recorded
  // a_x is the push. The data then hold states slowed or stopped against the block labelled with
  // the push, which a policy whose a_x tracks the current velocity never sees (the stall of
  // docs/RESULTS.md, Panda). 0.1 and 0.1 since 2026-12-02 (were 0 and 0, the paper's data;
  // docs/RESULTS.md, Panda, "Demonstrations that teach recovery"); brake rate 0.2 since
  // 2026-12-03: at 0.1 the policies' *mean* still stopped short of the target on some seeds
  // (docs/RESULTS.md, Panda, "The policy's mean"). 0 and 0: none (the draws are then those of a
  // version without it).
  double dart_noise = 0.1;
  double dart_brake_rate = 0.2;
  Range dart_brake_steps = {2, 6};
  std::uint64_t seed = 0;

  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

struct PandaDemonstrations {
  data::TrajectorySet trajectories;  // observations and actions, one episode per demonstration
  std::vector<long> push_begin;      // per episode: the column of its first push step
  long discarded_toppled = 0, discarded_failed = 0;
};

/// @throws secure::Error if fewer than options.episodes succeed within max_attempts.
PandaDemonstrations GeneratePandaDemonstrations(const PandaPushOptions& task,
                                                const PandaDemonstrationOptions& options);

struct PandaSafeOptions {
  long count = 1476;      // Table 2
  int noisy_copies = 10;  // the released noisy copies per demonstration state (0: none)
  // Hovering copies per demonstration state (0: none; not in the paper): the arm behind the
  // block, its face hover_gap away along x, at a height ~ U(hover_z), ee_y += U(-0.05, 0.05),
  // moving in any direction (each ee velocity component ~ U(-hover_speed, hover_speed)); the
  // block as in the state. They teach the barrier that away from the block the arm's height and
  // velocity do not matter: without them it extrapolates in the velocity features, and the
  // shield picks the never-seen velocities it rates safest (docs/RESULTS.md, Panda). The gap is
  // more than one step at full speed (0.05 m), so the arm can still stop short of the block.
  // 3 by default (was 0, the paper's data): docs/RESULTS.md, Panda.
  int hover_copies = 3;
  Range hover_gap = {0.06, 0.25};  // m, from the pusher's face to the block's face
  Range hover_z = {0.0, 0.5};      // m
  double hover_speed = 1.0;        // m/s
  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

struct PandaNearDangerousOptions {
  long count = 1476;  // Table 2
  int copies = 10;
  double p_upper = 0.3, p_fast = 0.4;  // the rest: both
  double fast_x_share = 1.0;           // of the fast scenario: fast along x (else along z)
  Range upper_z = {0.07, 0.399};       // m
  double low_z_max = 0.069;            // m
  // m/s. The demonstrations push at 0.1-0.19 m/s; continuing a push topples the block from
  // 0.3 m/s on (label check: 7 % at 0.2-0.3, 37 % at 0.3-0.4, 89 % at 0.4-0.6, 99 % above), and
  // a pusher arriving at 0.36 m/s knocks it over (seen in SECURE episodes with 0.6 here).
  Range fast_vx = {0.35, 1.25};
  Range fast_vz = {0.3, 1.25};         // m/s (downwards)
  double back_off = 0.002;             // m
  // The generator (issue 30 lever 5). kReleased: the scenarios above, labelled by construction.
  // kPrecursor: paper Eq. 2's near-dangerous states, states a trajectory into a topple passes
  // before it topples. Each candidate is a scenario above started a further U(precursor_gap)
  // behind (so before contact as well as in it), and is kept only if physics confirms that
  // continuing its motion topples the block (the label check's continuation, CheckLabels; the
  // candidates start from demonstration states, where the block stands upright). Candidates are
  // drawn until `count` are kept, at most max_candidates (else an error).
  enum class Generator { kReleased, kPrecursor };
  Generator generator = Generator::kReleased;
  Range precursor_gap = {0.0, 0.05};  // m
  long max_candidates = 20000;
  void Validate() const;
  /// The field table (the YAML keys and JSON fields): ApplyYaml and ToJson.
  YamlFields Fields();
  nlohmann::json ToJson() const;
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

/// The continuation of CheckLabels (below) and of the kPrecursor generator.
struct LabelCheckOptions {
  double push_distance = 0.1;  // m
  double stop_seconds = 0.2;
  double push_seconds = 1.0;
  double hold_seconds = 1.0;
  double velocity_gain = 1.25;  // m/s per unit action (PandaPushShieldModelOptions)
  long max_states = 300;        // per set, the first ones (sets are already shuffled)
};

inline constexpr EnumTable<PandaNearDangerousOptions::Generator, 2> kNearDangerousGeneratorNames{{
    {PandaNearDangerousOptions::Generator::kReleased, "released"},
    {PandaNearDangerousOptions::Generator::kPrecursor, "precursor"},
}};

/// The scenario of each generated near-dangerous state.
enum class NearDangerousScenario { kUpper, kFastX, kFastZ, kBoth };
const char* ScenarioName(NearDangerousScenario s);

/// Safe states from the demonstrations (observations), their noisy copies and hovering copies.
data::StateSet PandaSafeStates(const PandaDemonstrations& demos, const PandaSafeOptions& options,
                               Rng& rng);
/// Near-dangerous states from the pushing part of the demonstrations; `scenarios` (if not null)
/// receives each state's scenario. `task` and `continuation` (its velocity_gain and durations)
/// are the physics of the kPrecursor generator's check (unused by kReleased).
data::StateSet PandaNearDangerousStates(const PandaPushOptions& task,
                                        const PandaDemonstrations& demos,
                                        const PandaNearDangerousOptions& options,
                                        const LabelCheckOptions& continuation, Rng& rng,
                                        std::vector<NearDangerousScenario>* scenarios = nullptr);

/// The authors' released data (official-code-facts.md §2.6-2.7): task_demos.csv (2
/// demonstrations, 246 states) and near_dangerous_states.csv (4381 states) in `dir`, read by
/// feature name. Safe states: the released demonstration states with `safe.noisy_copies` noisy
/// copies, `safe.count` drawn; near-dangerous: `near_count` drawn from the released file (its
/// all-zero row dropped; its unmodified rows kept, as released).
/// @throws secure::Error naming the file on a missing file or column, or if a count exceeds the
///   states there are.
struct ReleasedPandaData {
  data::TrajectorySet demonstrations;
  data::StateSet safe, near_dangerous;
};
/// The released files as they are: the demonstrations and every near-dangerous state but the
/// all-zero row (no sampling, no copies).
struct ReleasedPandaFiles {
  data::TrajectorySet demonstrations;
  data::StateSet near_dangerous;
};
ReleasedPandaFiles ReadReleasedPandaFiles(const std::string& dir);
ReleasedPandaData ReadReleasedPandaData(const std::string& dir, const PandaSafeOptions& safe,
                                        long near_count, Rng& rng);

struct LabelCheckResult {
  long states = 0, toppled = 0, unreachable = 0;
  double TopplingFraction() const {
    return states > unreachable ? double(toppled) / double(states - unreachable) : 0.0;
  }
  nlohmann::json ToJson() const;
};

/// The labels against physics: from each state, the simulation is put in that state
/// (PandaPushSim::SetObservation), the push continues at the state's own end-effector velocity
/// (a = v / velocity_gain, clipped) until the end-effector has moved push_distance or
/// push_seconds have passed, then the push ends as a careful demonstrator ends one: the action
/// ramps down to zero over stop_seconds and the arm holds still for hold_seconds. (Every push
/// ends somewhere; a fast push that ends lets the block slide on alone, and a tall block sliding
/// on a table with friction above w / 2h = 0.2 tips forward.) The state "topples" if the block's
/// tilt exceeds the topple angle at any step. States the arm cannot reach (IK error > 0.01 m) are
/// counted apart. Checks `set` (observations). Deterministic.
LabelCheckResult CheckLabels(const PandaPushOptions& task, const data::StateSet& set,
                             const LabelCheckOptions& options);

/// Per state, what CheckLabels' continuation gives: 0 (near-dangerous) if it topples the block,
/// 1 (safe) if the block stays up, -1 if the arm cannot reach the state. Every column of `states`
/// (observations; options.max_states is not applied). Deterministic.
std::vector<int> LabelStates(const PandaPushOptions& task,
                             const Eigen::Ref<const Eigen::MatrixXf>& states,
                             const LabelCheckOptions& options);

}  // namespace secure::domains::panda_push
