#pragma once
// The closed-loop check of the CBF shield on the double integrator: episodes in which a noisy
// goal-seeking policy must pass an obstacle, with or without the shield in the loop.
//
// The task. Start states are drawn in the lower-left square [0.5, 3)^2 (at rest up to a small
// velocity), the goal (8.5, 8.5) lies behind the obstacle (5, 5), r = 2 as seen from there, and
// the nominal policy is a PD controller straight at the goal: a = kp (g - p) - kd v, clipped to
// the acceleration bound, with Gaussian exploration N(a, sigma^2 I). Every straight line from the
// start square to the goal passes within 0.91 of the obstacle centre, so without a shield the
// policy drives into the obstacle; with a correct barrier the shield must steer it around.
//
// The episodes run in the reach-avoid task (domains::double_integrator::ReachAvoidEnv, whose
// options ShieldRunOptions::task holds: obstacle and ground truth, goal, start distribution, dt,
// acceleration bound, braking backup action, max_steps) through the project's one episode loop,
// eval::EpisodeRunner: the PD controller with fixed noise is an eval::EpisodePolicy, and a step
// observer counts what the runner does not (ground-truth unsafe states, braking fallbacks).
//
// One step: mu = PD(s); the shield returns a = Decide(s, mu, sigma) (unshielded: a ~ N(mu,
// sigma)); the environment clips a to [-a_max, a_max]^2 and applies the exact zero-order-hold
// dynamics. The shield's model T is that same environment map (clip + exact step,
// ReachAvoidEnv::ShieldModel(), domains::double_integrator::ClippedDoubleIntegrator), so with
// the ground-truth barrier the checked next state is the one that happens: h(s') >= (1 - k dt)
// h(s) >= 0 for the linear class-K alpha(h) = k h.
//
// An episode ends when the agent reaches the goal (success), enters the obstacle (a crash:
// ||p - p_o|| < r; EpisodeRunnerOptions::stop_on_collision), or after max_steps (timeout). Two
// safety counts are kept apart:
//  - dangerous: the obstacle was entered (the physical failure the shield must prevent);
//  - left the safe set: some state had ground-truth h(s) < 0 (the CBF's safe set is smaller than
//    "outside the obstacle": h < 0 also flags states that will enter it unless they brake).
// Episode i draws from its own stream (seed ^ (0xd1b54a32d192ed03 (i + 1)), mixed by Rng), the
// streams this run's published figures were measured with (EpisodeRunnerOptions::episode_seed).
//
// Usage:
//   eval::ShieldRunOptions options;  // the defaults below
//   domains::double_integrator::GroundTruthBarrier barrier(options.task.truth);
//   eval::ShieldRunResult r = eval::RunDoubleIntegratorShield(options, barrier);
//   std::cout << r.Table();

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "domains/double_integrator/ground_truth_barrier.h"
#include "domains/double_integrator/reach_avoid.h"
#include "secure/cbf/barrier.h"
#include "secure/eval/latency.h"
#include "secure/eval/policy_eval.h"
#include "secure/shield/shield.h"

namespace secure::eval {

struct ShieldRunOptions {
  // The task, with ReachAvoidOptions' defaults: obstacle (5, 5), r = 2, gamma = 1 (the ground
  // truth used to count unsafe states, which the learned barriers are trained for); goal
  // (8.5, 8.5) behind the obstacle as seen from the start square, radius 0.3; starts in
  // [0.5, 3)^2, speed <= 0.1, 0.5 clear of the obstacle; dt = 0.1 (the shield must look ahead
  // exactly one step: shield.dt == task.dt is checked); acceleration bound 3 per component,
  // applied by the environment (it clips every action, also the shield's) and by the PD policy
  // (3 gives enough authority to brake from the speeds the PD reaches, |v| <= 1.5, within the
  // ground-truth CBF's margin, so a safe action exists); the shield's backup action braking,
  // a = clip(-brake_gain v), brake_gain 10 = 1 / dt; max_steps 300 = 30 s (the unobstructed PD
  // reaches the goal in about 11 s, so a detour fits and a stalled agent times out).
  domains::double_integrator::ReachAvoidOptions task;

  long episodes = 1000;

  // PD gains: critically damped (kd = 2 sqrt(kp)), so no overshoot at the goal; kp = 0.25
  // keeps the peak speed at about 1.5 per component, inside the velocity range [-1.5, 1.5) the
  // barriers are trained and validated on (a learned h is meaningless far outside it).
  double kp = 0.25;
  double kd = 1.0;
  // Exploration noise of the policy, per axis (the sigma passed to the shield): 10 % of the
  // acceleration bound, enough to break the symmetry of a head-on approach, and the source of
  // the baseline's spread.
  double policy_sigma = 0.3;

  // The shield (defaults: M = 64, rho0 = 0.1, alpha(h) = 1.0 h with 1.0 * dt = 0.1 < 1, dt =
  // 0.1). shield.seed is not used: each episode re-seeds the shield from its own stream.
  shield::ShieldOptions shield;

  // Everything random (start states, the shield's samples, the unshielded policy's noise) flows
  // from this seed; episode i uses its own stream derived from (seed, i).
  std::uint64_t seed = 0;

  // Keep the state of every step, up to this many, in ShieldRunResult::visited (0: none; the
  // shield-relevant label queries' pool). Not in ToJson: it changes no number.
  long record_states = 0;

  /// Throws secure::Error naming the field ("ShieldRunOptions::episodes = 0, must be > 0";
  /// the task's fields as "ReachAvoidOptions::goal_radius = 0, must be > 0").
  void Validate() const;
  /// The task's keys (ReachAvoidOptions::ToJson) and episodes, kp, kd, policy_sigma, shield,
  /// seed.
  nlohmann::json ToJson() const;
};

/// The nominal policy of the run: a = clip(kp (g - p) - kd v) per axis (bound accel_bound,
/// goal task.goal), with fixed noise sigma = policy_sigma per axis. No allocation per call.
class PdEpisodePolicy final : public EpisodePolicy {
 public:
  explicit PdEpisodePolicy(const ShieldRunOptions& options);
  int observation_dim() const override { return 4; }
  int action_dim() const override { return 2; }
  void Mean(const Eigen::Ref<const Eigen::VectorXf>& observation,
            Eigen::Ref<Eigen::VectorXf> mu) override;
  const Eigen::VectorXf& sigma() const override { return sigma_; }

 private:
  double kp_, kd_, goal_x_, goal_y_, a_max_;
  Eigen::VectorXf sigma_;
};

struct ShieldRunResult {
  bool shielded = true;
  Eigen::MatrixXf visited;  // (4 x n) the first options.record_states states the run visited
  std::string barrier;  // Describe() of the barrier, or "none" unshielded

  long episodes = 0;
  long dangerous_episodes = 0;      // entered the obstacle (the episode ends there)
  long success_episodes = 0;        // reached the goal without entering the obstacle
  long timeout_episodes = 0;        // neither within max_steps
  long unsafe_state_episodes = 0;   // some state had ground-truth h < 0
  long unsafe_state_steps = 0;      // states with ground-truth h < 0, over all episodes
  long steps = 0;                   // environment steps, over all episodes
  double mean_steps_to_goal = 0.0;  // over the successful episodes (0 if none)

  // Shield decisions (all 0 unshielded).
  long decisions = 0;
  long interventions = 0;  // decisions whose policy draw had g < 0
  double mean_interventions_per_episode = 0.0;
  long resampled_decisions = 0;       // status kSafeAfterResampling
  long no_safe_action_decisions = 0;  // status kNoSafeAction
  long invalid_input_decisions = 0;   // status kInvalidInput
  long backup_action_decisions = 0;   // the fallback was the braking backup action
  LatencySummary latency_us;  // per decision: PD mean + backup action + Decide (empty unshielded)

  double seconds = 0.0;  // wall time of the run
  ShieldRunOptions options;

  /// Keys: shielded, barrier, episodes, dangerous_episodes, success_episodes, timeout_episodes,
  /// unsafe_state_episodes, unsafe_state_steps, steps, mean_steps_to_goal, decisions,
  /// interventions, mean_interventions_per_episode, resampled_decisions,
  /// no_safe_action_decisions, invalid_input_decisions, backup_action_decisions, latency_us
  /// {count, p50, p90, p99, max, mean}, seconds, options.
  nlohmann::json ToJson() const;
  /// A Markdown table of the counts and latencies.
  std::string Table() const;
};

/// Runs options.episodes episodes with eval::EpisodeRunner in a ReachAvoidEnv(options.task).
/// shielded: each action comes from a Shield over `barrier` and the environment model; else
/// from N(mu, sigma) directly (the unshielded baseline; `barrier`
/// is not evaluated). Deterministic per options.seed apart from latencies (and, with a
/// shield time budget, the decisions that budget cuts short).
/// @throws secure::Error if the options are invalid or `barrier` does not take 4-D states.
ShieldRunResult RunDoubleIntegratorShield(const ShieldRunOptions& options, cbf::Barrier& barrier,
                                          bool shielded = true);

}  // namespace secure::eval
