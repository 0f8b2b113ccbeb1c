#pragma once
// The expert demonstrator of the double-integrator reach-avoid task (reach_avoid.h) and the
// generators of SECURE's three data sets from it: task demonstrations (trajectories, for BC and
// AIRL), safe states (S_s, the demonstration states) and near-dangerous states (S_nd, states that
// "wrap" the obstacle, paper Section 4.1). Everything here is deterministic for a given seed.
//
// The expert. One step at state s = (p, v):
//  1. nominal goal controller, a critically damped PD with a speed limit and a detour:
//       a_pd = kd (v_des - v),  v_des = sat_{speed_limit}((kp / kd) (goal - p)) + detour,
//     kd = 2 sqrt(kp) (sat: scales the vector down to the norm limit). Below the speed limit and
//     away from the obstacle this is exactly a = kp (goal - p) - kd v; the limit keeps every
//     velocity component inside the range [-1.5, 1.5) the barriers are trained and validated on.
//     The detour (ExpertOptions::detour_gain) bends the desired velocity around the obstacle
//     when the goal lies behind it. At the goal the PD holds the agent there.
//  2. exploration: a_nom = a_pd + N(0, noise_sigma^2 I), a fresh draw every step;
//  3. safety filter (CBF-QP on the ground-truth CBF h of GroundTruth, exact, see below):
//       a = argmin ||a - a_nom||^2  s.t.  h(T(s, a)) >= (1 - k dt) h(s) + margin,  |a_i| <= a_max,
//     T the exact zero-order-hold step, k = cbf_rate. With k dt <= 1 and h(s) >= 0 this keeps
//     h(s') >= 0: the expert never leaves the ground-truth safe set. h >= 0 alone does not
//     exclude the obstacle (inside it, moving outward fast, h >= 0), but b = |p - p_o|^2 - r^2
//     obeys db/dt >= -gamma b on the safe set, so b >= 0 persists in continuous time; at the
//     sampled states the tests check it (0 collisions). The filter works on the obstacle
//     enlarged by `clearance` (0.3), so the expert keeps that distance (tested).
//     use_filter = false skips the filter (a = clip(a_nom)): the unfiltered baseline, which
//     drives into the obstacle (the straight path passes it within 0.91 of its centre).
//
// Variation between demonstrations (so that they differ, yet stay imitable: smooth and mostly a
// function of the state): per episode (BeginEpisode), kp is scaled by U[1 - gain_spread,
// 1 + gain_spread] and the speed limit by U[1 - speed_spread, 1]; per step, the noise of 2.
// Together with the random start states this gives demonstrations passing the obstacle on both
// sides (the side the start leans to), at different speeds. noise_sigma = 0.2 is 7 % of the
// bound: visible jitter that still leaves the action mostly a function of the state, and small
// enough that the PD holds the agent within about 0.03 (std) of the goal once there.
//
// The filter, exactly. With e = d + v dt (d = p - p_o, c = dt^2 / 2),
//   h(T(s, a)) = h0 + g.a + q |a|^2,  h0 = gamma (|e|^2 - r^2) + 2 e.v,
//   g = (2 gamma c + 2 dt) e + 2 c v,  q = gamma c^2 + 2 c dt > 0,
// a convex quadratic with isotropic curvature, so the constraint excludes an open disc
// |a - a_c| < R (a_c = -g / (2q)) and the feasible set is the box minus that disc. The minimiser
// of ||a - a_nom||^2 over it is clip(a_nom) if that is feasible; otherwise it lies on the boundary
// and is one of finitely many candidates, all enumerated: the radial projection of a_nom onto
// the circle, the projections of a_nom onto the four box edges, the circle's intersections with
// the edges, and the corners; the closest feasible one wins (every candidate is verified by
// evaluating h at the exact next state). `margin` (1e-3) is a safety allowance for the float
// arithmetic of the environment (measured over 1000 episodes: the float step moves h(s') by at
// most 1.3e-5 from the exact value).
// Feasibility: the condition can be met from every safe state of the task. In continuous time,
// with k = gamma and a pointing away from the obstacle (d.a = a_max |d|_1 >= a_max |d|),
//   dh/dt + k h = 4 gamma d.v + 2 |v|^2 + 2 d.a + gamma^2 b >= 2 |d| (a_max - 2 gamma |v|) >= 0
// for b >= 0 and |v| <= a_max / (2 gamma) = 1.5 (the expert's speed limit is 1.4); the discrete
// condition adds the positive q |a|^2. The property test finds no infeasible safe state near the
// obstacle with velocity components up to 1.5 either (speeds up to 2.1).
// Should the disc nevertheless cover the box, the filter returns the corner
// that maximises h(s') (the maximum of a convex function over a box is at a vertex) and the
// episode is discarded if it collides. FilterInfo and Expert::stats() count such steps.
//
// Usage:
//   ReachAvoidOptions task;  ExpertOptions expert;  DemonstrationOptions demo;  demo.seed = 1;
//   Demonstrations d = GenerateDemonstrations(task, expert, demo);
//   data::WriteTrajectories("demos.csv", d.trajectories);
//   Rng rng(2);
//   data::WriteStateSet("safe.csv", SafeStatesFromDemonstrations(d.trajectories, 1000, rng));
//   data::WriteStateSet("near_dangerous.csv", GenerateNearDangerous(task, {}, rng));

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/domains/filtering_expert.h"
#include "domains/double_integrator/double_integrator.h"
#include "domains/double_integrator/reach_avoid.h"

namespace secure::domains::double_integrator {

struct ExpertOptions {
  // Nominal controller: proportional gain (kd = 2 sqrt(kp) = 2, critically damped) and the
  // speed limit of the desired velocity (norm), which keeps every velocity component below the
  // range [-1.5, 1.5) of the state box. kp = 1 rather than the 0.25 of eval's ShieldRunOptions:
  // with the speed limit doing the far-field work, the gain only shapes the arrival, and 0.25
  // arrives slowly (median 148 instead of 111 steps, with the detour below).
  double kp = 1.0;
  double speed_limit = 1.4;
  // Per-episode variation: kp x U[1 - gain_spread, 1 + gain_spread], speed_limit x
  // U[1 - speed_spread, 1]. speed_spread = 0.5 (speeds 0.7 to 1.4) rather than 0.2: slower
  // demonstrations put safe states at low speeds near the obstacle, where the learned barrier
  // otherwise has no data.
  // Detour: near the obstacle, when the goal lies behind it, the desired velocity gains a
  // tangential component of detour_gain x speed_limit x head_on x exp(-(|d| - r) / detour_range)
  // (head_on = max(0, -cos) of the angle between the goal direction and the direction to the
  // obstacle centre) toward the side the goal direction already leans to. Without it the expert
  // stalls in front of the obstacle whenever it approaches head-on (the min-norm CBF-QP has an
  // undesired equilibrium there, where the filtered action is 0): measured over 1000 episodes,
  // 1.2 % never reach the goal within 300 steps and the median is 143 steps (kp = 1). It is part
  // of the nominal controller, and the unfiltered expert still always collides (it acts only
  // within about detour_range of the boundary, too late without the filter). 0 disables it.
  double detour_gain = 0.8;
  double detour_range = 0.5;
  double gain_spread = 0.2;
  double speed_spread = 0.5;
  // Per-step Gaussian noise on the nominal action (before the filter), per axis.
  double noise_sigma = 0.2;

  // The safety filter: enforce h(s') >= (1 - cbf_rate dt) h(s) + filter_margin. cbf_rate = 1 is
  // the shield's default alpha(h) = 1.0 h (with dt = 0.1: h may shrink by 10 % per step) and
  // gamma of the ground truth (the feasibility argument above); cbf_rate dt must be in (0, 1].
  bool use_filter = true;
  double cbf_rate = 1.0;
  double filter_margin = 1e-3;
  // The filter (and the detour) use the ground-truth CBF of an obstacle enlarged by this much:
  // the expert keeps a clearance, as a person demonstrating would. Without one (0) it grazes the
  // obstacle at 0.03, its demonstration states then lie among the near-dangerous ones, and a
  // barrier learned from them cannot tell grazing from entering: measured, a shield with such a
  // barrier let 6-12 % of AIRL's episodes touch the obstacle.
  double clearance = 0.3;

  /// Throws secure::Error naming the field ("ExpertOptions::kp = -1, must be > 0").
  void Validate() const;
  nlohmann::json ToJson() const;
};

/// What the filter did at one state.
struct FilterInfo {
  double h = 0.0;         // ground-truth h(s)
  double required = 0.0;  // (1 - k dt) h(s): the condition is h(s') >= required
  double next_h = 0.0;    // h(s') for the returned action
  bool modified = false;  // the result differs from clip(nominal)
  bool feasible = true;   // some action in the box satisfies the condition (with the margin)
};

/// Counts over the Act() calls since construction or the last ResetStats() (infeasible: the
/// h-maximising corner was used).
using ExpertStats = domains::ExpertFilterStats;

class Expert {
 public:
  /// @throws secure::Error if the options are invalid, or cbf_rate * task.dt is not in (0, 1].
  Expert(const ReachAvoidOptions& task, const ExpertOptions& options = {});

  /// Draws this episode's gain and speed limit from `rng` (see the header comment). Before the
  /// first call the expert uses the nominal kp and speed_limit.
  void BeginEpisode(Rng& rng);
  /// The expert's action at `state` (4 values): nominal + noise from `rng`, filtered (unless
  /// use_filter is false), inside the box [-a_max, a_max]^2. Allocates nothing.
  /// @throws secure::Error on a wrong dimension.
  void Act(const Eigen::Ref<const Eigen::VectorXf>& state, Rng& rng,
           Eigen::Ref<Eigen::VectorXf> action);

  /// The noise-free nominal action (PD with this episode's parameters; not clipped).
  Eigen::Vector2d Nominal(const Eigen::Vector4d& state) const;
  /// The safety filter alone: the action in the box closest to `nominal` with
  /// h(s') >= (1 - k dt) h(s) + margin (see the header comment). Works with any options'
  /// use_filter.
  Eigen::Vector2d FilterAction(const Eigen::Vector4d& state, const Eigen::Vector2d& nominal,
                               FilterInfo* info = nullptr) const;
  /// h(T(state, action)) for the exact step (no clipping), in double precision.
  double NextH(const Eigen::Vector4d& state, const Eigen::Vector2d& action) const;

  const ExpertOptions& options() const { return options_; }
  const ReachAvoidOptions& task() const { return task_; }
  double episode_kp() const { return kp_; }
  double episode_speed_limit() const { return speed_limit_; }
  const ExpertStats& stats() const { return stats_; }
  void ResetStats() { stats_ = {}; }

 private:
  ReachAvoidOptions task_;
  ExpertOptions options_;
  GroundTruth guard_;  // task_.truth with the radius enlarged by options_.clearance
  double kp_;
  double speed_limit_;
  ExpertStats stats_;
};

// ---------------------------------------------------------------------------------------------
// Task demonstrations

struct DemonstrationOptions {
  // Kept demonstrations (the paper's Table 2 has 52612 task-demo states for its first domain;
  // 100 episodes x 300 steps = 30000 states here, enough for BC and AIRL on a 4-D task, and
  // generated in well under a second).
  long episodes = 100;
  // false (default): every demonstration runs env.max_steps() steps, the expert holding at the
  // goal after reaching it, because adversarial IRL uses fixed-horizon episodes (no termination
  // bias in the learned reward). true: an episode ends at the step that reaches the goal (the
  // goal state itself is not recorded: it has no action).
  bool stop_at_goal = false;
  // Attempts before giving up (0: 10 x episodes + 10). An attempt is discarded if it collides
  // (the paper filters out colliding trajectories) or never reaches the goal within max_steps
  // (the expert is meant to demonstrate the task, not a failure at it).
  long max_attempts = 0;
  // If true (default), kept < episodes after max_attempts is an error naming the counts; if
  // false, the demonstrations kept so far are returned (the counts say how many).
  bool require_all = true;
  // Attempt i draws its start state, episode parameters and noise from its own stream derived
  // from (seed, i).
  std::uint64_t seed = 0;

  void Validate() const;
  nlohmann::json ToJson() const;
};

/// The counts (attempted, discarded_collisions: entered the obstacle at least once,
/// discarded_no_goal, steps_to_goal, expert, seconds): ExpertDemonstrationCounts.
struct Demonstrations : ExpertDemonstrationCounts {
  // State features StateFeatures(), action features ActionFeatures(); the action recorded at
  // each state is the action the environment applied (after clipping).
  data::TrajectorySet trajectories;

  /// Counts and options (not the trajectories).
  nlohmann::json ToJson() const;
};

/// Runs the expert in ReachAvoidEnv(task) until demo.episodes demonstrations are kept.
/// @throws secure::Error if an options struct is invalid, or (require_all) fewer than
///   demo.episodes demonstrations are kept after max_attempts (the message gives the counts).
Demonstrations GenerateDemonstrations(const ReachAvoidOptions& task, const ExpertOptions& expert,
                                      const DemonstrationOptions& demo);

// ---------------------------------------------------------------------------------------------
// Safety demonstrations

/// The demonstrations cut at the first state in the goal (inclusive): the states the expert
/// passes through on its way, without the (many, nearly identical) states of holding at the goal
/// that full-horizon demonstrations end with. Used for the safe-state set.
data::TrajectorySet UntilGoal(const Demonstrations& demonstrations);

/// The safe-state set S_s = the demonstration states: all of them if max_states >=
/// num_steps(), else a uniformly random subset of max_states (without replacement, kept in file
/// order). @throws secure::Error unless max_states > 0 and the set has states.
data::StateSet SafeStatesFromDemonstrations(const data::TrajectorySet& trajectories,
                                            long max_states, Rng& rng);

/// Safe-state augmentation (the authors augment their Panda safe states with noisy copies):
/// `copies` copies of every state with its velocity scaled by lambda ~ U[0, 1) — the same
/// place, moving slower in the same direction. Slowing down keeps a safe state safe: outside
/// the obstacle (b >= 0), h = gamma b + lambda 2 (p - p_o).v is >= 0 for every lambda in [0, 1]
/// when it is at lambda = 1. Without these, demonstrations (always moving near the obstacle)
/// leave h undetermined for slow states there, and a learned h then ranked coasting toward the
/// obstacle above braking (measured: the shield's no-safe-action fallbacks coasted into it).
/// @throws secure::Error if copies < 0 or the set's features are not the double integrator's.
data::StateSet WithSlowedCopies(const data::StateSet& safe, int copies, Rng& rng);

/// The near-dangerous set S_nd: states that wrap the obstacle, as a user would demonstrate
/// them (paper Section 4.1; not a ground-truth labelling of the whole box). Each state:
///   angle theta ~ U[0, 2 pi), rho ~ U[rho_min, rho_max),
///   p = p_o + (r + rho) (cos theta, sin theta),  v ~ U[velocity_lo, velocity_hi)^2,
/// kept only if the ground-truth h(s) < 0 (inside the obstacle, or about to enter it unless it
/// brakes), until `count` states are kept. The defaults: a band from 1.5 inside the boundary to
/// 1.5 outside it, velocities over the state box's range. Why so wide: the unsafe set of a
/// velocity-dependent barrier reaches as far out as the agent needs to stop (h < 0 at distance
/// rho outside the edge whenever the approach speed exceeds about rho, so up to 1.5 at the top
/// speed), and a learned h is only pinned down where there are data. Measured with
/// `secure shield run` (300 noisy PD episodes): a narrow band (-0.1, 0.3) let the learned
/// barrier stay positive on slow approaches it had no data for, and 5-18 % of the shielded
/// episodes entered the obstacle; with this band and the demonstration states up to the goal
/// (UntilGoal) as the safe set, 0 % on 4 of 5 seeds. (The released code's Demolition Derby band,
/// rho in {0.01, ..., 0.14}, is for a position-only barrier.)
struct NearDangerousOptions {
  long count = 2000;
  double rho_min = -1.5;
  double rho_max = 1.5;
  double velocity_lo = -1.5;
  double velocity_hi = 1.5;

  /// rho_min > -r and rho_min < rho_max are checked against the task's radius in
  /// GenerateNearDangerous; here: count > 0, finite values, lo < hi.
  void Validate() const;
  nlohmann::json ToJson() const;
};

/// @throws secure::Error if the options are invalid, rho_min <= -r, or the band holds (almost)
///   no state with h < 0 (gives up after 1000 draws per requested state).
data::StateSet GenerateNearDangerous(const ReachAvoidOptions& task,
                                     const NearDangerousOptions& options, Rng& rng);

}  // namespace secure::domains::double_integrator
