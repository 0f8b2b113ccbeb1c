#pragma once
// Adversarial inverse reinforcement learning (AIRL; Fu et al. 2018; paper Section 3) with a PPO
// generator: the AIRL baseline of Table 3 and the policy SECURE shields.
//
// Discriminator (state-only, as released): a reward g(s) and a shaping term V(s), MLPs on
// normalised observations, give
//     f(s, s') = g(s) + gamma_D V(s') - V(s),      D(s, a, s') = exp(f) / (exp(f) + pi(a|s)),
// computed stably as log D = f - logaddexp(f, log pi), log(1 - D) = log pi - logaddexp(f, log pi),
// with log pi the *current* policy's Gaussian log-density of the taken action. It minimises the
// cross-entropy with expert transitions labelled 1 and the latest rollout's labelled 0 (Adam,
// `discriminator_updates` minibatches of `discriminator_batch` expert + as many policy
// transitions per iteration, drawn uniformly with replacement, as the authors' code does).
// Expert transitions (s, a, s') are consecutive rows of one demonstration episode; each
// episode's last row has no successor and is dropped (the released code pads s' with zeros
// instead, a defect).
//
// gamma_D (discriminator_discount) defaults to the RL discount 0.99, as in AIRL's derivation;
// the released code used 1.0 (official-code-facts.md §5.1) — set it to 1 to reproduce that.
//
// Policy reward (AirlReward):
//   kLogitD       log D - log(1 - D) = f - log pi(a|s)   (the paper's r_theta)
//   kStateReward  g(s)                                   (what the released code optimised;
//                                                         the default)
// The default is g(s) because with a state-only f the -log pi term of the logit-d reward is an
// entropy bonus of weight 1 that the discriminator can hardly counter when one action barely
// changes the next state (dt = 0.1): on the double-integrator reach-avoid task sigma then grows
// from a cold start, e.g. 1 -> 2.2 after 60 iterations and 4.9 after 150 with 10 discriminator
// updates per iteration, while with g(s) it shrinks as the policy learns; see README.md.
//
// Generator: PPO with a clipped surrogate, GAE(gamma, lambda), a separate value network,
// advantage normalisation, optional entropy bonus and gradient-norm clipping. Each iteration
// rolls out ceil(steps_per_iteration / H) fixed-horizon episodes of H = env.max_steps() steps
// (never stopped at the goal or a collision, so that no termination bias enters the reward; the
// value is bootstrapped at the horizon as a time-limit truncation; with absorbing_goal the goal
// is an absorbing state the episode stays in). Rollouts run the policy
// with Eigen (PolicyEvaluator) on all episodes in lock-step; rewards, advantages and updates
// are batched LibTorch computations. Rewards are divided by a running standard deviation of the
// discounted return (`normalize_rewards`, as in common PPO implementations) so that the value
// network sees targets of order 1 whatever the discriminator's scale.
//
// Determinism: weights are initialised from secure::Rng (nn::RandomMlpParams; the policy mean's
// output layer is scaled by 0.01 and its bias zeroed, as is common for PPO), and all noise,
// episode starts and minibatch orders are drawn from per-iteration secure::Rng streams that are
// a pure function of (seed, iteration). LibTorch's global generator is never used, and the
// trainer does not call torch::set_num_threads: the caller sets the intra-op thread count once,
// and OpenBLAS's (which LibTorch uses for matrix products here and which set_num_threads does not
// reach: openblas_set_num_threads(1) or OPENBLAS_NUM_THREADS=1; otherwise concurrent trainers
// slow each other down ~10x, README.md "Threads"). The same seed, data, environment and thread
// counts give bitwise-identical policies, also when several trainers run concurrently in
// different std::threads.
//
// Checkpoints: `checkpoint_path` is one file (a format line, a LibTorch archive and a CRC-32
// trailer over the whole content; docs/FILE_FORMATS.md) holding the policy, value, reward and
// shaping networks, the three Adam states, the normaliser, the reward statistics, the iteration
// counter and the learning-curve rows so far; the RNG state needs no storage (it is derived
// from seed and iteration). It is written atomically (temporary file + rename) every
// `checkpoint_every` iterations and when training stops. With `resume`, training continues from
// an existing checkpoint (a missing one starts afresh); the result is bitwise identical to an
// uninterrupted run. Resuming checks the checksum and format version, that the options that
// shape training (everything except iterations, verbose, curve/checkpoint paths and cadence,
// resume and stop_after_iterations) and the demonstrations and environment match, and that the
// checkpoint has at most `iterations` completed iterations (as many: its policy is returned).
//
// The returned policy's provenance records the summary without timing (identical runs give
// identical model files); AirlSummary keeps the timing.
//
//   policy::AirlOptions options;                  // documented defaults
//   options.checkpoint_path = "run/airl.ckpt";
//   policy::AirlSummary summary;
//   policy::GaussianPolicy pi =
//       policy::TrainAirl(options, demos, env, /*warm_start=*/nullptr, &summary);
//   std::cerr << summary.BriefReport() << "\n";

#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/enum_strings.h"
#include "secure/data/data.h"
#include "secure/domains/dynamics.h"
#include "secure/domains/environment.h"
#include "secure/policy/airl_reward.h"
#include "secure/policy/gaussian_policy.h"

namespace YAML {
class Node;
}

namespace secure::cbf {
class DifferentiableBarrier;  // secure/cbf/differentiable_barrier.h (LibTorch; secure::cbf_train)
}

namespace secure::policy {

enum class AirlReward {
  kLogitD,       // log D - log(1 - D) = f(s, s') - log pi(a|s): the paper
  kStateReward,  // g(s): the released code
};
inline constexpr EnumTable<AirlReward, 2> kAirlRewardNames{{
    {AirlReward::kLogitD, "logit-d"},
    {AirlReward::kStateReward, "state-reward"},
}};

struct AirlOptions {
  // Networks. The policy mean and the value network use tanh; g and V use ReLU (as released).
  std::vector<int> policy_hidden = {64, 64};   // ignored with a warm start (its net is kept)
  std::vector<int> value_hidden = {64, 64};    // PPO baseline
  std::vector<int> reward_hidden = {32, 32};   // g(s)
  std::vector<int> shaping_hidden = {32, 32};  // V(s)
  double init_log_std = 0.0;                   // initial log sigma (ignored with a warm start)
  double min_log_std = -5.0;                   // lower clamp of log sigma

  // Schedule.
  int iterations = 100;            // rollout + discriminator + PPO rounds
  int steps_per_iteration = 4000;  // environment steps per iteration, rounded up to whole
                                   // episodes of env.max_steps()

  // PPO generator.
  double gamma = 0.99;            // RL discount
  double gae_lambda = 0.95;       // GAE lambda
  double clip = 0.2;              // surrogate ratio clip epsilon
  int ppo_epochs = 5;             // passes over each rollout
  int minibatch_size = 500;       // transitions per PPO minibatch
  double policy_lr = 3e-4;        // Adam, policy mean and log sigma
  double value_lr = 1e-3;         // Adam, value network
  double entropy_coef = 0.0;      // entropy bonus (the released code: none)
  // Behaviour-cloning regulariser: bc_weight x the mean negative log-likelihood of a minibatch
  // of expert pairs (as many as the PPO minibatch, drawn afresh) is added to every PPO policy
  // loss, as in GAIL/AIRL + BC (Jena et al. 2020) and DAPG (Rajeswaran et al. 2018). 0 (the
  // released code): pure AIRL. It keeps the expert's action where the learned reward is flat,
  // e.g. the final approach to a goal (docs/RESULTS.md, Demolition Derby).
  double bc_weight = 0.0;
  double max_grad_norm = 0.5;     // gradient-norm clip per network (0: off)
  bool normalize_rewards = true;  // divide rewards by the running std of discounted returns
  // The goal as an absorbing state (issue 30 lever 3; Kostrikov et al. 2019, DAC; the released
  // environment ends an episode at success). Once a rollout episode reaches the goal, its
  // remaining steps record the goal observation frozen (next = current, no physics), with the
  // policy's sampled actions, and PPO is rewarded there with the learned reward of the goal
  // state. The discriminator sees only the transitions up to the goal: the demonstrations end at
  // the goal, so frozen transitions have no expert counterpart and would be learned as the
  // policy's signature. false: fixed-horizon episodes that keep running past the goal.
  bool absorbing_goal = false;

  // Discriminator.
  double discriminator_lr = 1e-3;        // Adam
  int discriminator_updates = 20;        // minibatch updates per iteration (released: 10 x 32)
  int discriminator_batch = 256;         // expert (and as many policy) transitions per update
  double discriminator_discount = 0.99;  // gamma_D in f = g(s) + gamma_D V(s') - V(s)
  AirlReward reward = AirlReward::kStateReward;  // see the header comment

  // Run control.
  std::uint64_t seed = 0;
  bool verbose = false;           // one status line per ~2 s (and the last) on stderr
  std::string curve_path;         // CSV learning curve, one row per iteration, rewritten
                                  // atomically every iteration (survives a kill; see resume)
  std::string checkpoint_path;    // checkpoint file ("" : none)
  int checkpoint_every = 10;      // iterations between checkpoints (also written at the end)
  bool resume = false;            // continue from checkpoint_path if it exists (else start
                                  // afresh); more completed iterations than `iterations`: error
  int stop_after_iterations = 0;  // > 0: stop once the iteration counter reaches this (for
                                  // splitting a run; a checkpoint is written)

  /// Throws secure::Error naming the field, value and rule.
  void Validate() const;
  /// Reads fields from a YAML mapping; unknown keys are an error naming the key and `source`.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
};

/// What one iteration did (rollout statistics are of the rollout *before* that iteration's
/// updates).
struct AirlIterationStats {
  int iteration = 0;                // 1-based
  long env_steps = 0;               // cumulative environment steps
  int episodes = 0;                 // rollout episodes this iteration
  double success_rate = 0.0;        // fraction of episodes in which reached_goal happened
  double collision_rate = 0.0;      // fraction of episodes with at least one collision
  double mean_collisions = 0.0;     // collision events per episode
  double d_expert = 0.0;            // mean D on expert transitions (a fixed random subset of
                                    // up to 2048; after this iteration's discriminator update)
  double d_policy = 0.0;            // mean D on this rollout's transitions (after this update)
  double discriminator_loss = 0.0;  // mean cross-entropy over this iteration's updates
  double mean_reward = 0.0;         // mean policy reward per step (before normalisation)
  double policy_loss = 0.0;         // mean clipped-surrogate loss over the PPO minibatches
  double value_loss = 0.0;          // mean squared error of the value network
  double entropy = 0.0;             // Gaussian entropy of the policy after the update (nats)
  double mean_sigma = 0.0;          // mean exp(log_std) after the update
  double approx_kl = 0.0;           // mean (ratio - 1) - log ratio of the last PPO epoch
  double clip_fraction = 0.0;       // fraction of clipped ratios in the last PPO epoch
  double bc_nll = 0.0;              // mean expert NLL of the bc_weight term (NaN if bc_weight 0)
  double seconds = 0.0;             // cumulative wall-clock seconds of training

  /// The learning-curve CSV columns, in order, and this row's values.
  static std::vector<std::string> Columns();
  std::vector<double> Values() const;
  nlohmann::json ToJson() const;
};

struct AirlSummary {
  int iterations = 0;       // iterations completed in total (including resumed ones)
  int start_iteration = 0;  // iterations already done when this call started (resume)
  long env_steps = 0;       // cumulative
  int episodes_per_iteration = 0;
  int steps_per_iteration = 0;  // episodes_per_iteration * horizon
  int horizon = 0;              // env.max_steps()
  long expert_transitions = 0;
  bool warm_started = false;
  bool resumed = false;
  int checkpoints_written = 0;
  std::string stop_reason;  // "iterations", "stop_after_iterations", "callback"
  AirlIterationStats last;  // the last iteration's statistics
  // Timing of this call (not of resumed-from runs).
  double wall_seconds = 0.0;
  double rollout_seconds = 0.0, discriminator_seconds = 0.0, ppo_seconds = 0.0;
  double iterations_per_second = 0.0;
  double env_steps_per_second = 0.0;  // environment steps trained on per wall-clock second
  double cbf_loss = 0.0;  // TrainAirlJoint: mean L_cbf of the last iteration (0 for TrainAirl)

  std::string BriefReport() const;  // one line
  nlohmann::json ToJson() const;
};

/// Called after every iteration; return false to stop (a checkpoint is written if configured).
using AirlCallback = std::function<bool(const AirlIterationStats&)>;

/// Trains a Gaussian policy with AIRL on `demos` in `env` (cloned inside; `env` is not used
/// after the call returns, nor modified). `warm_start` (may be null), e.g. a BC policy: its
/// architecture, normaliser and log sigma are the starting point; otherwise the observation
/// normaliser is fitted on the demonstration states. The demonstrations' state/action features
/// must equal env.ObservationFeatures()/ActionFeatures(), be finite, and every episode needs >= 2
/// rows. The returned policy's provenance records options, data, environment and summary
/// (without timing). `reward_model`, if non-null, receives the trained discriminator's reward
/// g and shaping V (airl_reward.h: the task value of the shield's top-q aggregation).
/// @throws secure::Error on invalid options, data, warm start or an incompatible checkpoint.
GaussianPolicy TrainAirl(const AirlOptions& options, const data::TrajectorySet& demos,
                         const domains::Environment& env, const GaussianPolicy* warm_start,
                         AirlSummary* summary, const AirlCallback& callback = nullptr,
                         AirlRewardModel* reward_model = nullptr);

/// The joint-optimisation baseline of the paper (Section 4.1; official-code-facts.md §8.1,
/// variant A): instead of a shield, the barrier's derivative condition is an extra term of the
/// policy's loss, L = PPO surrogate + weight * L_cbf, with the barrier frozen:
///
///   deriv(s, a) = h(T(s, a)) - h(s) + dt * alpha * h(s),    a = mu(s) + sigma * eps (reparameterised)
///   L_cbf = mean over the PPO minibatch of  max(-deriv, 0)                        if h(s) >= 0
///                                           unsafe_weight * max(-deriv + unsafe_margin, 0)  else
///
/// T is the shield's dynamics model, linearised in the action around a = 0 per state (exact for
/// models affine in the action, as Demolition Derby's within the action bound).
struct JointCbfOptions {
  double weight = 1.0;           // cbf_weight (the released driver script is missing: [ND])
  double class_k_gain = 1.0;     // alpha (released: ALPHA_CBF = 1)
  double dt = 0.1;               // dt in deriv (released: TIME_STEP = 0.1)
  double unsafe_weight = 2.0;    // released: 2
  double unsafe_margin = 1e-3;   // released: 1e-3

  /// Throws secure::Error naming the field, value and rule.
  void Validate() const;
  /// Reads the fields above (keys as in ToJson()) from a YAML mapping; unknown keys and values
  /// of the wrong type are errors naming the key and `source`. Does not validate.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
};

/// TrainAirl with the JointCbfOptions term in every PPO minibatch (the returned summary's
/// `cbf_loss` is the last iteration's mean L_cbf). `barrier` is any differentiable barrier
/// (cbf::MakeDifferentiableBarrier of a BarrierNet or CarBarrierNet, or another implementation;
/// it must outlive the call) and must read the environment's observations (its state_dim equals
/// the observation dimension); `model` must map them (its state_dim and action_dim equal the
/// environment's).
/// @throws secure::Error as TrainAirl, or on a model or barrier that does not fit the environment.
GaussianPolicy TrainAirlJoint(const AirlOptions& options, const JointCbfOptions& joint,
                              const cbf::DifferentiableBarrier& barrier,
                              const domains::DynamicsModel& model,
                              const data::TrajectorySet& demos, const domains::Environment& env,
                              const GaussianPolicy* warm_start, AirlSummary* summary,
                              const AirlCallback& callback = nullptr);

/// The same with a learned barrier model (made differentiable inside, so that the caller needs
/// no LibTorch header): the per-car CarBarrierNet (Demolition Derby) or the flat BarrierNet (an
/// MLP on the observation; one whose features are all among the environment's observation
/// features reads them by name, as BarrierNet::MakeEvaluatorFor). Throws also on an invalid
/// `barrier`.
GaussianPolicy TrainAirlJoint(const AirlOptions& options, const JointCbfOptions& joint,
                              const cbf::CarBarrierNet& barrier,
                              const domains::DynamicsModel& model,
                              const data::TrajectorySet& demos, const domains::Environment& env,
                              const GaussianPolicy* warm_start, AirlSummary* summary,
                              const AirlCallback& callback = nullptr);
GaussianPolicy TrainAirlJoint(const AirlOptions& options, const JointCbfOptions& joint,
                              const cbf::BarrierNet& barrier, const domains::DynamicsModel& model,
                              const data::TrajectorySet& demos, const domains::Environment& env,
                              const GaussianPolicy* warm_start, AirlSummary* summary,
                              const AirlCallback& callback = nullptr);

}  // namespace secure::policy
