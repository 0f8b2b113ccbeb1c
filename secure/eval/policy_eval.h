#pragma once
// The evaluation harness of the paper's Section 6: learned policies run in closed loop, with or
// without the CBF shield, over N episodes per seed and S seeds; per seed the success rate, the
// dangerous rate, the shield's interventions and decision latencies; across seeds mean (std)
// and the paper's statistical tests (Mann–Whitney U, TOST, Kruskal–Wallis + Dunn).
//
// The methods (Table 3 and Figure 9 of the paper):
//   bc                    behaviour cloning, actions sampled from its Gaussian
//   airl                  AIRL, actions sampled from its Gaussian
//   secure                AIRL policy + learned barrier + shield (Algorithms 1 and 2)
//   secure-random-safe    ablation 1: the shield returns one random safe sample, not the mean
//   secure-no-resampling  ablation 2: no adaptive resampling (the policy's own sigma)
//   bc+shield             the BC policy under the same shield
//   secure-myopic         SECURE with the myopic test h(T(s, a)) >= 0 (linear alpha with
//                         alpha dt = 1, the released code's setting; paper Section 4.2, R3)
//   joint                 the joint-optimisation baseline (paper Section 4.1): a policy trained
//                         with the barrier's derivative condition as an extra loss, unshielded
//   cbf-qp                AIRL policy + the CBF-QP filter on the learned barrier (proposal
//                         qp-only: the mean projected onto the linearised CBF half-space and the
//                         action box, checked with the exact g; no sampling)
//   secure-qp             SECURE with the gradient-first shield (proposal qp: the CBF-QP's
//                         projection when its exact g >= 0, else Algorithms 1-2 unchanged)
//   first-safe            AIRL policy + the first-safe sampler (CRABS-style; aggregation
//                         first-safe, resampling none: the policy's draw if safe, else the first
//                         safe draw from the policy's own Gaussian, up to the shield's budget)
//   cbf-grad              AIRL policy + gradient refinement of the mean (MACBF-style; proposal
//                         refine: projected gradient steps on max(0, -g) from the mean, checked
//                         with the exact g; no sampling)
// Unshielded methods sample a ~ N(mu(o), sigma) as the authors' evaluation does; shielded ones
// pass (mu, sigma) to the shield and apply its action.
//
// One episode: Reset(), then up to env.max_steps() steps; it ends early when the goal is
// reached (success). Dangerous = at least one collision in the episode (the number of events is
// kept too); the episode continues after a collision, which is how "at least once" is counted
// (EpisodeRunnerOptions::stop_on_collision ends it at the first one instead, a crash).
//
// The runner is the one episode loop of the project: the methods above run through it with
// their learned Gaussian policies (GaussianEpisodePolicy), and domain harnesses with their own
// EpisodePolicy (e.g. the double integrator's PD controller with fixed noise in
// domains/double_integrator/shield_run.h), counting what they need more with a StepObserver.
//
//   eval::EpisodeRunner runner(env);                       // one per thread
//   eval::SeedResult r = runner.Run(policy, &shield, 100, seed);  // shield = nullptr: unshielded
//   eval::Evaluation ev;  ev.Add(Method::kSecure, r);  ...  ev.Finish();
//   std::cout << ev.Table();  nlohmann::json j = ev.ToJson();
#include <Eigen/Core>
#include <functional>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/common/enum_strings.h"
#include "secure/common/rng.h"
#include "secure/domains/environment.h"
#include "secure/eval/latency.h"
#include "secure/policy/airl_reward.h"
#include "secure/policy/gaussian_policy.h"
#include "secure/shield/shield.h"
#include "secure/stats/statistics.h"

namespace secure::eval {

enum class Method {
  kBc,
  kAirl,
  kSecure,
  kSecureRandomSafe,
  kSecureNoResampling,
  kBcShield,
  kSecureMyopic,
  kJoint,
  kCbfQp,
  kSecureQp,
  kFirstSafe,
  kCbfGrad,
};
inline constexpr EnumTable<Method, 12> kMethodNames{{
    {Method::kBc, "bc"},
    {Method::kAirl, "airl"},
    {Method::kSecure, "secure"},
    {Method::kSecureRandomSafe, "secure-random-safe"},
    {Method::kSecureNoResampling, "secure-no-resampling"},
    {Method::kBcShield, "bc+shield"},
    {Method::kSecureMyopic, "secure-myopic"},
    {Method::kJoint, "joint"},
    {Method::kCbfQp, "cbf-qp"},
    {Method::kSecureQp, "secure-qp"},
    {Method::kFirstSafe, "first-safe"},
    {Method::kCbfGrad, "cbf-grad"},
}};
/// The other safety filters (issue 37), each compared with SECURE in the tables.
inline constexpr Method kOtherFilters[] = {Method::kCbfQp, Method::kSecureQp, Method::kFirstSafe,
                                           Method::kCbfGrad};

/// The methods of the double-integrator pipeline (Table 3 and Figure 9), in table order; the
/// Derby experiments add kSecureMyopic and kJoint.
const std::vector<Method>& AllMethods();
/// Whether the method runs the shield, and which policy it uses.
bool IsShielded(Method method);
bool UsesBcPolicy(Method method);
bool UsesJointPolicy(Method method);
/// The shield options of a method: `base` with the method's ablation applied (aggregation
/// random-safe for kSecureRandomSafe, resampling none for kSecureNoResampling, a linear class-K
/// function with gain 1 / dt for kSecureMyopic).
shield::ShieldOptions ShieldOptionsFor(Method method, const shield::ShieldOptions& base);
/// "bc,airl,secure" -> methods; throws naming the unknown name and listing the valid ones.
std::vector<Method> ParseMethods(const std::string& list);

/// The outcome of one episode (`secure eval --episodes-out`, the experiment's episodes.csv):
/// which episodes of a seed were dangerous or failed, to replay them (`secure render --episode`).
struct EpisodeOutcome {
  long episode = 0;                // its index in the seed's evaluation (`secure render --episode`)
  bool success = false;            // reached the goal
  bool dangerous = false;          // at least one collision (the domain's dangerous event)
  int steps = 0;                   // environment steps
  int first_dangerous_step = -1;   // 0-based index of the first step that collided; -1: none
                                   // (the render's frame first_dangerous_step + 1 shows it)
  long collision_events = 0;
  long interventions = 0;          // decisions whose policy draw had g < 0 (0 unshielded)
  long no_safe_action_decisions = 0;
};

/// The outcome of N episodes of one method with one seed.
struct SeedResult {
  long episodes = 0;
  long successes = 0;         // episodes that reached the goal
  long dangerous = 0;         // episodes with at least one collision
  long collision_events = 0;  // collisions summed over steps and episodes
  long steps = 0;             // environment steps over all episodes
  double mean_steps_to_goal = 0.0;  // over successful episodes (0 if none)
  // Shield statistics (zero for unshielded methods).
  long decisions = 0;
  long interventions = 0;            // decisions whose policy draw had g < 0
  long resampled_decisions = 0;      // kSafeAfterResampling
  long no_safe_action_decisions = 0;
  long invalid_input_decisions = 0;
  double mean_iterations = 0.0;      // sampling rounds per decision
  long qp_tried = 0;      // decisions that tried the CBF-QP projection (proposal qp, qp-only)
  long qp_decisions = 0;  // ... that it made (QpOutcome::kAccepted)
  long qp_rejected = 0;   // ... whose projection had an exact g < 0 (rejected or infeasible)
  LatencySummary latency_us;         // decision latency (shielded) or policy query (unshielded)
  // Shielded methods: one forward of kReferenceBatch states through this seed's barrier with
  // nothing skipped (cbf::Barrier::EvaluateDense: the per-obstacle barrier evaluates every
  // obstacle, in range or not), the median of kReferenceRepeats timed in this process at the
  // start of the first episode, before its first decision (the states: that episode's start
  // observation, repeated). The yardstick of the decision latency (docs/PERFORMANCE.md):
  // latency_us.p50 / reference_forward_latency_us is comparable across machines and loads.
  // Tables print the latency also in these units ("[0.52 / 0.71]").
  double reference_forward_latency_us = 0.0;
  static constexpr int kReferenceBatch = 128;
  static constexpr int kReferenceRepeats = 15;
  double seconds = 0.0;
  // One per episode, in order (episode_outcomes[i].episode = the run's first episode + i); empty
  // for a result read back from a task file written before they were recorded.
  std::vector<EpisodeOutcome> episode_outcomes;

  /// Whether episode_outcomes holds every episode.
  bool has_episode_outcomes() const {
    return episodes > 0 && episode_outcomes.size() == static_cast<std::size_t>(episodes);
  }
  /// The indices of the episodes that were dangerous / did not reach the goal (empty without
  /// episode_outcomes).
  std::vector<long> DangerousEpisodes() const;
  std::vector<long> FailedEpisodes() const;

  double success_rate() const { return episodes ? double(successes) / double(episodes) : 0.0; }
  double dangerous_rate() const { return episodes ? double(dangerous) / double(episodes) : 0.0; }
  double interventions_per_episode() const {
    return episodes ? double(interventions) / double(episodes) : 0.0;
  }
  /// The counts, rates and latencies; with episode_outcomes also "dangerous_episodes" and
  /// "failed_episodes" (the indices: DangerousEpisodes(), FailedEpisodes()).
  nlohmann::json ToJson() const;
};

/// The random stream of episode `episode` of an evaluation with `seed`.
std::uint64_t EpisodeSeed(std::uint64_t seed, long episode);

/// The evaluation seed of a training seed: the stream EvaluateMethods() draws the evaluation
/// episodes from, distinct from every stream the training of `training_seed` uses (those are
/// derived from the training seed itself), so a seed's evaluation episodes are fresh start states
/// and noise. training_seed ^ 0x5ec07e5eed5 (the value `secure demo`, `secure eval` and the
/// experiments have always used; changing it changes every published evaluation figure).
constexpr std::uint64_t EvaluationSeed(std::uint64_t training_seed) {
  return training_seed ^ 0x5ec07e5eed5ULL;
}

/// What the episode runner asks of a policy: a Gaussian N(mu(o), diag(sigma^2)) over actions.
/// Unshielded runs apply a sample of it; shielded runs pass (mu(o), sigma) to the shield.
/// Implementations must not allocate in Mean() or Sample() (they are called every step).
class EpisodePolicy {
 public:
  virtual ~EpisodePolicy() = default;
  virtual int observation_dim() const = 0;
  virtual int action_dim() const = 0;
  /// mu = mu(observation) (action_dim values).
  virtual void Mean(const Eigen::Ref<const Eigen::VectorXf>& observation,
                    Eigen::Ref<Eigen::VectorXf> mu) = 0;
  /// The per-axis standard deviation (action_dim values), the same for every observation.
  virtual const Eigen::VectorXf& sigma() const = 0;
  /// a ~ N(mu(o), sigma): by default action = Mean(o), then action[i] += sigma[i] * eps_i with
  /// one rng.Normal() per action dimension, in order.
  virtual void Sample(const Eigen::Ref<const Eigen::VectorXf>& observation, Rng& rng,
                      Eigen::Ref<Eigen::VectorXf> action);
};

/// A learned Gaussian policy (policy::PolicyEvaluator) as an EpisodePolicy: Mean() and Sample()
/// are the evaluator's own.
class GaussianEpisodePolicy final : public EpisodePolicy {
 public:
  /// `evaluator` must outlive this object.
  explicit GaussianEpisodePolicy(policy::PolicyEvaluator& evaluator) : evaluator_(evaluator) {}
  int observation_dim() const override { return evaluator_.observation_dim(); }
  int action_dim() const override { return evaluator_.action_dim(); }
  void Mean(const Eigen::Ref<const Eigen::VectorXf>& observation,
            Eigen::Ref<Eigen::VectorXf> mu) override {
    evaluator_.Mean(observation, mu);
  }
  const Eigen::VectorXf& sigma() const override { return evaluator_.sigma(); }
  void Sample(const Eigen::Ref<const Eigen::VectorXf>& observation, Rng& rng,
              Eigen::Ref<Eigen::VectorXf> action) override {
    evaluator_.Sample(observation, rng, action);
  }

 private:
  policy::PolicyEvaluator& evaluator_;
};

/// One step as the runner reports it to a StepObserver, after env.Step(). The references are
/// valid only during the call.
struct StepView {
  long episode = 0;                    // 0-based
  int step = 0;                        // 0-based index of the step within the episode
  const Eigen::VectorXf& observation;  // after the step
  const Eigen::VectorXf& action;       // the action passed to env.Step()
  const domains::StepOutcome& outcome;
  const shield::Decision* decision = nullptr;  // the shield's decision; null unshielded
};

/// Watches a run step by step, e.g. to count what SeedResult does not (states outside a
/// reference safe set, the shield's fallbacks). Called on the runner's thread; an exception it
/// throws propagates out of Run().
class StepObserver {
 public:
  virtual ~StepObserver() = default;
  /// After Reset(): `observation` is the start observation.
  virtual void OnEpisodeStart(long /*episode*/, const Eigen::VectorXf& /*observation*/) {}
  virtual void OnStep(const StepView& step) = 0;
  /// After the episode's last step (goal, collision with stop_on_collision, or max_steps).
  virtual void OnEpisodeEnd(long /*episode*/) {}
};

struct EpisodeRunnerOptions {
  // End an episode at its first collision (a crash), as a physical run would. Off by default:
  // the paper's evaluation continues after a collision and counts the episode as dangerous if
  // one happened at least once (collision_events counts every step with one).
  bool stop_on_collision = false;
  // The stream of episode i of a run with seed s is episode_seed(s, i). EpisodeSeed by default;
  // a harness with published figures may keep the streams it was measured with.
  std::uint64_t (*episode_seed)(std::uint64_t seed, long episode) = &EpisodeSeed;
  // The index of the first episode Run() plays: a run of N episodes plays episodes
  // first_episode, ..., first_episode + N - 1 (each from its own stream episode_seed(seed, i),
  // and so reported to the observer), so one episode of an evaluation can be replayed alone
  // (`secure render`). 0 by default: the evaluation's episodes.
  long first_episode = 0;
};

/// Runs episodes in one environment (not thread-safe; one runner per thread).
class EpisodeRunner {
 public:
  /// `env` must outlive the runner.
  explicit EpisodeRunner(domains::Environment& env, EpisodeRunnerOptions options = {});

  /// `episodes` episodes of `policy`, shielded by `shield` if non-null (its Decide() is used with
  /// the policy's mu and sigma; its backup action is set per step from env.BackupAction()).
  /// Episode i draws everything (its start first, then policy noise and the shield's samples)
  /// from its own stream options.episode_seed(seed, i) (EpisodeSeed by default): every method
  /// sees the same start states for the same seed (common random numbers), and any episode can
  /// be replayed alone. `observer`, if non-null, sees every episode start, step and end.
  /// latency_us: per step, the time from the observation to the action (policy mean + backup
  /// action + Decide shielded; the policy's sample unshielded). No allocation per step beyond
  /// the latency record (reserved up front).
  /// @throws secure::Error if the policy's or shield's dimensions disagree with the environment.
  SeedResult Run(EpisodePolicy& policy, shield::Shield* shield, long episodes, std::uint64_t seed,
                 StepObserver* observer = nullptr);
  /// The same with a learned policy (GaussianEpisodePolicy).
  SeedResult Run(policy::PolicyEvaluator& policy, shield::Shield* shield, long episodes,
                 std::uint64_t seed, StepObserver* observer = nullptr);

  const EpisodeRunnerOptions& options() const { return options_; }
  /// The environment the runner steps.
  domains::Environment& environment() const { return env_; }

 private:
  domains::Environment& env_;
  EpisodeRunnerOptions options_;
  Eigen::VectorXf observation_, mu_, action_, backup_;
};

/// What one seed's evaluation needs: the policies (any may be null when no listed method uses
/// it) and a barrier factory (one evaluator per shield; null when no method is shielded).
struct SeedModels {
  const policy::GaussianPolicy* bc = nullptr;
  const policy::GaussianPolicy* airl = nullptr;
  const policy::GaussianPolicy* joint = nullptr;
  std::function<std::unique_ptr<cbf::Barrier>()> make_barrier;
  // AIRL's reward and shaping networks: the task value of a shield with aggregation = top-q
  // (null when no shielded method aggregates so).
  const policy::AirlRewardModel* airl_reward = nullptr;
};

/// Runs `method` in `runner` for `episodes` episodes with evaluation seed `seed`, exactly as
/// EvaluateMethods() runs each of its methods: a PolicyEvaluator of the method's policy, and for a
/// shielded method a shield with ShieldOptionsFor(method, shield_options) over a barrier from
/// models.make_barrier() and the runner's environment's ShieldModel(); with aggregation = top-q
/// its task value is policy::AirlActionValue of models.airl_reward. `observer` as in
/// EpisodeRunner::Run(). @throws secure::Error if the method's model is missing.
SeedResult RunMethod(EpisodeRunner& runner, Method method, const SeedModels& models,
                     const shield::ShieldOptions& shield_options, long episodes,
                     std::uint64_t seed, StepObserver* observer = nullptr);

/// Runs every method of `methods` for `episodes` episodes with evaluation seed `seed` in a clone
/// of `env` (RunMethod for each). Shielded methods use ShieldOptionsFor(method, shield_options) and the environment's
/// ShieldModel(). @throws secure::Error if a method's model is missing.
std::map<Method, SeedResult> EvaluateMethods(const domains::Environment& env,
                                             const std::vector<Method>& methods,
                                             const SeedModels& models,
                                             const shield::ShieldOptions& shield_options,
                                             long episodes, std::uint64_t seed);

/// Per-method results over seeds, and the comparisons of the paper.
struct MethodSummary {
  std::vector<SeedResult> per_seed;
  stats::SampleSummary success_rate;
  stats::SampleSummary dangerous_rate;
  stats::SampleSummary interventions_per_episode;
  nlohmann::json ToJson() const;
};

struct EvaluationOptions {
  // TOST equivalence bound for SECURE vs AIRL success rates, as a fraction (the paper: 10
  // points).
  double tost_bound = 0.10;
  double alpha = 0.05;  // significance level used in the table's verdicts
};

class Evaluation {
 public:
  explicit Evaluation(EvaluationOptions options = {}) : options_(options) {}
  /// Adds one seed's result of `method` (seeds in order).
  void Add(Method method, const SeedResult& result);
  /// Computes the summaries and tests. Needs the same number of seeds for every method.
  void Finish();

  const std::map<Method, MethodSummary>& methods() const { return methods_; }
  /// {"methods": {name: {"success_rate": {"mean","std","per_seed"}, "dangerous_rate": {...},
  ///   "interventions_per_episode": {...}, "seeds": [SeedResult...]}},
  ///  "comparisons": {"secure_vs_airl": {...}, "ablations": {...}}, "options": {...}}
  /// Rates are fractions in [0, 1].
  nlohmann::json ToJson() const;
  /// A Table-3-style Markdown table (percent, mean (std)) plus the tests.
  std::string Table() const;

 private:
  EvaluationOptions options_;
  std::map<Method, MethodSummary> methods_;
  nlohmann::json comparisons_ = nlohmann::json::object();
  bool finished_ = false;
};

}  // namespace secure::eval
