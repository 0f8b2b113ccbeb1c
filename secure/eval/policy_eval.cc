#include "secure/eval/policy_eval.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/strings.h"
#include "secure/common/timer.h"
#include "secure/data/data.h"
#include "secure/dynamics/ensemble.h"

namespace secure::eval {

const std::vector<Method>& AllMethods() {
  static const std::vector<Method> methods = {Method::kBc,
                                              Method::kAirl,
                                              Method::kSecure,
                                              Method::kSecureRandomSafe,
                                              Method::kSecureNoResampling,
                                              Method::kBcShield};
  return methods;
}

bool IsShielded(Method method) {
  return method != Method::kBc && method != Method::kAirl && method != Method::kJoint;
}

bool UsesBcPolicy(Method method) { return method == Method::kBc || method == Method::kBcShield; }

bool UsesJointPolicy(Method method) { return method == Method::kJoint; }

shield::ShieldOptions ShieldOptionsFor(Method method, const shield::ShieldOptions& base) {
  shield::ShieldOptions options = base;
  if (method == Method::kSecureRandomSafe) options.aggregation = shield::Aggregation::kRandomSafe;
  if (method == Method::kSecureNoResampling) options.resampling = shield::Resampling::kNone;
  if (method == Method::kSecureMyopic) {
    // alpha(h) = h / dt: g = (h(s+) - h(s)) / dt + h(s) / dt = h(s+) / dt, so g >= 0 is h(s+) >= 0.
    options.class_k = shield::ClassK::kLinear;
    options.class_k_gain = 1.0 / options.dt;
  }
  if (method == Method::kCbfQp) options.proposal = shield::Proposal::kQpOnly;
  if (method == Method::kSecureQp) options.proposal = shield::Proposal::kQp;
  if (method == Method::kFirstSafe) {
    options.aggregation = shield::Aggregation::kFirstSafe;
    options.resampling = shield::Resampling::kNone;  // the policy's own Gaussian, round after round
  }
  if (method == Method::kCbfGrad) options.proposal = shield::Proposal::kRefine;
  return options;
}

std::vector<Method> ParseMethods(const std::string& list) {
  std::vector<Method> methods;
  for (const std::string& name : data::SplitList(list)) {
    const Method method = FromString(kMethodNames, name, "method");
    SECURE_CHECK(std::find(methods.begin(), methods.end(), method) == methods.end(),
                 "method '" << name << "' is listed twice in '" << list << "'");
    methods.push_back(method);
  }
  SECURE_CHECK(!methods.empty(), "methods = '" << list << "': no method given");
  return methods;
}

// ---------------------------------------------------------------------------------------------
nlohmann::json SeedResult::ToJson() const {
  nlohmann::json json = {{"episodes", episodes},
          {"successes", successes},
          {"dangerous", dangerous},
          {"success_rate", success_rate()},
          {"dangerous_rate", dangerous_rate()},
          {"collision_events", collision_events},
          {"steps", steps},
          {"mean_steps_to_goal", mean_steps_to_goal},
          {"decisions", decisions},
          {"interventions", interventions},
          {"interventions_per_episode", interventions_per_episode()},
          {"resampled_decisions", resampled_decisions},
          {"no_safe_action_decisions", no_safe_action_decisions},
          {"invalid_input_decisions", invalid_input_decisions},
          {"mean_iterations", mean_iterations},
          {"latency_us", latency_us.ToJson()},
          {"reference_forward_latency_us", reference_forward_latency_us},
          {"seconds", seconds}};
  // Only where a projection was tried, so that every other method's records keep their bytes.
  if (qp_tried > 0) {
    json["qp_tried"] = qp_tried;
    json["qp_decisions"] = qp_decisions;
    json["qp_rejected"] = qp_rejected;
  }
  if (has_episode_outcomes()) {
    json["dangerous_episodes"] = DangerousEpisodes();
    json["failed_episodes"] = FailedEpisodes();
  }
  return json;
}

std::vector<long> SeedResult::DangerousEpisodes() const {
  std::vector<long> out;
  for (const EpisodeOutcome& e : episode_outcomes)
    if (e.dangerous) out.push_back(e.episode);
  return out;
}

std::vector<long> SeedResult::FailedEpisodes() const {
  std::vector<long> out;
  for (const EpisodeOutcome& e : episode_outcomes)
    if (!e.success) out.push_back(e.episode);
  return out;
}

void EpisodePolicy::Sample(const Eigen::Ref<const Eigen::VectorXf>& observation, Rng& rng,
                           Eigen::Ref<Eigen::VectorXf> action) {
  Mean(observation, action);
  const Eigen::VectorXf& s = sigma();
  for (Eigen::Index i = 0; i < action.size(); ++i)
    action[i] = action[i] + s[i] * static_cast<float>(rng.Normal());
}

EpisodeRunner::EpisodeRunner(domains::Environment& env, EpisodeRunnerOptions options)
    : env_(env),
      options_(options),
      observation_(env.observation_dim()),
      mu_(env.action_dim()),
      action_(env.action_dim()),
      backup_(env.action_dim()) {
  SECURE_CHECK(options_.episode_seed != nullptr,
               "EpisodeRunnerOptions::episode_seed = null, must be a function");
  SECURE_CHECK(options_.first_episode >= 0, "EpisodeRunnerOptions::first_episode = "
                                                << options_.first_episode << ", must be >= 0");
}

std::uint64_t EpisodeSeed(std::uint64_t seed, long episode) {
  // Mixed once more by Rng::Seed (splitmix64), so neighbouring indices give unrelated streams.
  return seed ^ (0x9e3779b97f4a7c15ULL * static_cast<std::uint64_t>(episode + 1));
}

SeedResult EpisodeRunner::Run(policy::PolicyEvaluator& policy, shield::Shield* shield,
                              long episodes, std::uint64_t seed, StepObserver* observer) {
  GaussianEpisodePolicy adapter(policy);
  return Run(adapter, shield, episodes, seed, observer);
}

SeedResult EpisodeRunner::Run(EpisodePolicy& policy, shield::Shield* shield, long episodes,
                              std::uint64_t seed, StepObserver* observer) {
  SECURE_CHECK(episodes > 0, "EpisodeRunner::Run: episodes = " << episodes << ", must be > 0");
  SECURE_CHECK(policy.observation_dim() == env_.observation_dim() &&
                   policy.action_dim() == env_.action_dim(),
               "EpisodeRunner: the policy maps " << policy.observation_dim() << " -> "
                                                 << policy.action_dim()
                                                 << " but the environment has observations of "
                                                 << env_.observation_dim() << " and actions of "
                                                 << env_.action_dim());
  SECURE_CHECK(policy.sigma().size() == env_.action_dim(),
               "EpisodeRunner: the policy's sigma has "
                   << policy.sigma().size() << " values, expected " << env_.action_dim());
  if (shield != nullptr) {
    SECURE_CHECK(shield->state_dim() == env_.observation_dim() &&
                     shield->action_dim() == env_.action_dim(),
                 "EpisodeRunner: the shield takes states of "
                     << shield->state_dim() << " and actions of " << shield->action_dim()
                     << " but the environment has observations of " << env_.observation_dim()
                     << " and actions of " << env_.action_dim());
  }
  const Stopwatch clock;
  SeedResult result;
  result.episodes = episodes;
  std::vector<double> latencies_us;
  latencies_us.reserve(static_cast<std::size_t>(episodes) * 64);
  result.episode_outcomes.reserve(static_cast<std::size_t>(episodes));
  long steps_to_goal_sum = 0;
  long iterations_sum = 0;
  const Eigen::VectorXf& sigma = policy.sigma();
  for (long episode = options_.first_episode; episode < options_.first_episode + episodes;
       ++episode) {
    Rng rng(options_.episode_seed(seed, episode));
    env_.Reset(rng, observation_);
    if (shield != nullptr) shield->Seed(rng.NextU64());
    if (observer != nullptr) observer->OnEpisodeStart(episode, observation_);
    EpisodeOutcome& outcome_of_episode = result.episode_outcomes.emplace_back();
    outcome_of_episode.episode = episode;
    for (int step = 0; step < env_.max_steps(); ++step) {
      const Stopwatch decision_clock;
      const shield::Decision* decision = nullptr;
      if (shield != nullptr) {
        policy.Mean(observation_, mu_);
        if (env_.BackupAction(observation_, backup_)) {
          shield->SetBackupAction(backup_);
        } else {
          shield->ClearBackupAction();
        }
        const shield::Decision& d = shield->Decide(observation_, mu_, sigma);
        latencies_us.push_back(decision_clock.Microseconds());
        action_ = d.action;
        decision = &d;
        ++result.decisions;
        iterations_sum += d.iterations;
        if (d.intervened) ++outcome_of_episode.interventions;
        switch (d.status) {
          case shield::Status::kSafeAfterResampling: ++result.resampled_decisions; break;
          case shield::Status::kNoSafeAction: ++outcome_of_episode.no_safe_action_decisions; break;
          case shield::Status::kInvalidInput: ++result.invalid_input_decisions; break;
          case shield::Status::kSafe: break;
        }
        if (d.qp != shield::QpOutcome::kNotTried) {
          ++result.qp_tried;
          if (d.qp == shield::QpOutcome::kAccepted) {
            ++result.qp_decisions;
          } else {
            ++result.qp_rejected;
          }
        }
      } else {
        policy.Sample(observation_, rng, action_);
        latencies_us.push_back(decision_clock.Microseconds());
      }
      const domains::StepOutcome outcome = env_.Step(action_, observation_);
      ++outcome_of_episode.steps;
      if (observer != nullptr) {
        observer->OnStep(StepView{episode, step, observation_, action_, outcome, decision});
      }
      if (outcome.collided) {
        if (!outcome_of_episode.dangerous) outcome_of_episode.first_dangerous_step = step;
        outcome_of_episode.dangerous = true;
        outcome_of_episode.collision_events += std::max(1, outcome.collisions);
        if (options_.stop_on_collision) break;
      }
      if (outcome.reached_goal) {
        outcome_of_episode.success = true;
        steps_to_goal_sum += step + 1;
        break;
      }
    }
    // The seed's counts are the sums of its episodes'.
    result.steps += outcome_of_episode.steps;
    result.successes += outcome_of_episode.success ? 1 : 0;
    result.dangerous += outcome_of_episode.dangerous ? 1 : 0;
    result.collision_events += outcome_of_episode.collision_events;
    result.interventions += outcome_of_episode.interventions;
    result.no_safe_action_decisions += outcome_of_episode.no_safe_action_decisions;
    if (observer != nullptr) observer->OnEpisodeEnd(episode);
  }
  if (result.successes > 0) {
    result.mean_steps_to_goal = double(steps_to_goal_sum) / double(result.successes);
  }
  if (result.decisions > 0) result.mean_iterations = double(iterations_sum) / double(result.decisions);
  result.latency_us = LatencySummary::Of(std::move(latencies_us));
  result.seconds = clock.Seconds();
  return result;
}

namespace {

// Times SeedResult::reference_forward_latency_us on the first episode's start observation (after
// its Reset, before its first decision: outside every decision's latency, and no extra Reset),
// and passes every call on to `next` (if any).
class ReferenceForwardTimer final : public StepObserver {
 public:
  ReferenceForwardTimer(cbf::Barrier& barrier, StepObserver* next)
      : barrier_(barrier), next_(next) {}

  void OnEpisodeStart(long episode, const Eigen::VectorXf& observation) override {
    if (us_ == 0.0) Time(observation);
    if (next_ != nullptr) next_->OnEpisodeStart(episode, observation);
  }
  void OnStep(const StepView& step) override {
    if (next_ != nullptr) next_->OnStep(step);
  }
  void OnEpisodeEnd(long episode) override {
    if (next_ != nullptr) next_->OnEpisodeEnd(episode);
  }
  double microseconds() const { return us_; }

 private:
  void Time(const Eigen::VectorXf& observation) {
    const Eigen::MatrixXf states = observation.replicate(1, SeedResult::kReferenceBatch);
    Eigen::VectorXf h(SeedResult::kReferenceBatch);
    barrier_.EvaluateDense(states, h);  // warm: first-call allocations and kernel dispatch
    std::vector<double> us;
    for (int k = 0; k < SeedResult::kReferenceRepeats; ++k) {
      const Stopwatch clock;
      barrier_.EvaluateDense(states, h);
      us.push_back(clock.Microseconds());
    }
    std::nth_element(us.begin(), us.begin() + us.size() / 2, us.end());
    us_ = std::max(us[us.size() / 2], 1e-3);  // never 0: 0 means "not timed"
  }

  cbf::Barrier& barrier_;
  StepObserver* next_;
  double us_ = 0.0;
};

}  // namespace

SeedResult RunMethod(EpisodeRunner& runner, Method method, const SeedModels& models,
                     const shield::ShieldOptions& shield_options, long episodes,
                     std::uint64_t seed, StepObserver* observer) {
  const std::string name = ToString(kMethodNames, method);
  const policy::GaussianPolicy* policy = UsesBcPolicy(method)      ? models.bc
                                         : UsesJointPolicy(method) ? models.joint
                                                                   : models.airl;
  SECURE_CHECK(policy != nullptr, "method '" << name << "' needs a "
                                             << (UsesBcPolicy(method)      ? "BC"
                                                 : UsesJointPolicy(method) ? "joint"
                                                                           : "AIRL")
                                             << " policy, and none was given");
  policy::PolicyEvaluator evaluator(*policy);
  if (!IsShielded(method)) return runner.Run(evaluator, nullptr, episodes, seed, observer);
  SECURE_CHECK(models.make_barrier != nullptr,
               "method '" << name << "' needs a barrier, and none was given");
  const domains::Environment& env = runner.environment();
  // A learned ensemble as the shield model makes the barrier pessimistic over its members
  // (secure/dynamics/README.md); any other model leaves the barrier as it is.
  std::unique_ptr<cbf::Barrier> barrier =
      dynamics::ForShieldModel(models.make_barrier(), env.ShieldModel());
  const shield::ShieldOptions options = ShieldOptionsFor(method, shield_options);
  shield::Shield shield(options, *barrier, env.ShieldModel());
  shield.SetActionBounds(env);
  std::optional<policy::AirlActionValue> value;
  if (options.aggregation == shield::Aggregation::kTopQ) {
    SECURE_CHECK(models.airl_reward != nullptr,
                 "method '" << name
                            << "': shield aggregation top-q needs AIRL's reward model (the task "
                               "value), and none was given");
    SECURE_CHECK(env.ShieldModel().state_dim() == env.observation_dim(),
                 "method '" << name << "': shield aggregation top-q needs a shield model on the "
                            << "observations; " << env.ShieldModel().Describe() << " maps "
                            << env.ShieldModel().state_dim() << "-D states");
    value.emplace(*models.airl_reward, env.ObservationFeatures(),
                  std::max(options.num_samples, options.num_probes));
    shield.SetActionValue(&*value);
  }
  ReferenceForwardTimer timer(*barrier, observer);
  SeedResult result = runner.Run(evaluator, &shield, episodes, seed, &timer);
  result.reference_forward_latency_us = timer.microseconds();
  return result;
}

std::map<Method, SeedResult> EvaluateMethods(const domains::Environment& env,
                                             const std::vector<Method>& methods,
                                             const SeedModels& models,
                                             const shield::ShieldOptions& shield_options,
                                             long episodes, std::uint64_t seed) {
  std::unique_ptr<domains::Environment> local_env = env.Clone();
  EpisodeRunner runner(*local_env);
  std::map<Method, SeedResult> results;
  for (Method method : methods) {
    results[method] = RunMethod(runner, method, models, shield_options, episodes, seed);
  }
  return results;
}

// ---------------------------------------------------------------------------------------------
namespace {

nlohmann::json RateJson(const stats::SampleSummary& summary, const std::vector<double>& per_seed) {
  return {{"mean", summary.mean}, {"std", summary.std}, {"per_seed", per_seed}};
}

template <typename F>
std::vector<double> PerSeed(const MethodSummary& m, F value) {
  std::vector<double> out;
  out.reserve(m.per_seed.size());
  for (const SeedResult& r : m.per_seed) out.push_back(value(r));
  return out;
}

std::vector<double> Successes(const MethodSummary& m) {
  return PerSeed(m, [](const SeedResult& r) { return r.success_rate(); });
}
std::vector<double> Dangers(const MethodSummary& m) {
  return PerSeed(m, [](const SeedResult& r) { return r.dangerous_rate(); });
}

// Mann–Whitney U is undefined when both samples hold one repeated value (e.g. 0 % dangerous for
// both methods on every seed): then the samples do not differ, reported as p = 1.
nlohmann::json MannWhitneyJson(const std::vector<double>& a, const std::vector<double>& b) {
  const bool all_equal =
      std::all_of(a.begin(), a.end(), [&](double v) { return v == a.front(); }) &&
      std::all_of(b.begin(), b.end(), [&](double v) { return v == a.front(); });
  if (all_equal) {
    const double u = 0.5 * double(a.size()) * double(b.size());
    return {{"u", u}, {"p_value", 1.0}, {"method", "all values equal"}};
  }
  return stats::MannWhitneyU(a, b).ToJson();
}

// Undefined figures (a p-value or std that could not be computed) read "n/a" in text tables;
// the JSON document holds null for them.
std::string Percent(double fraction) {
  if (!std::isfinite(fraction)) return "n/a";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%.1f", 100.0 * fraction);
  return buffer;
}

std::string MeanStd(const stats::SampleSummary& s) {
  return Percent(s.mean) + " (" + Percent(s.std) + ")";
}

std::string Number(double value, const char* format = "%.3g") {
  if (!std::isfinite(value)) return "n/a";
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, format, value);
  return buffer;
}

}  // namespace

nlohmann::json MethodSummary::ToJson() const {
  nlohmann::json seeds = nlohmann::json::array();
  for (const SeedResult& r : per_seed) seeds.push_back(r.ToJson());
  return {{"success_rate", RateJson(success_rate, Successes(*this))},
          {"dangerous_rate", RateJson(dangerous_rate, Dangers(*this))},
          {"interventions_per_episode",
           RateJson(interventions_per_episode,
                    PerSeed(*this, [](const SeedResult& r) { return r.interventions_per_episode(); }))},
          {"seeds", std::move(seeds)}};
}

void Evaluation::Add(Method method, const SeedResult& result) {
  SECURE_CHECK(!finished_, "Evaluation::Add after Finish()");
  methods_[method].per_seed.push_back(result);
}

void Evaluation::Finish() {
  SECURE_CHECK(!methods_.empty(), "Evaluation::Finish: no results were added");
  const std::size_t seeds = methods_.begin()->second.per_seed.size();
  for (auto& [method, summary] : methods_) {
    SECURE_CHECK(summary.per_seed.size() == seeds,
                 "Evaluation::Finish: method '" << ToString(kMethodNames, method) << "' has "
                                                << summary.per_seed.size() << " seeds, '"
                                                << ToString(kMethodNames, methods_.begin()->first)
                                                << "' has " << seeds);
    summary.success_rate = stats::Summarize(Successes(summary));
    summary.dangerous_rate = stats::Summarize(Dangers(summary));
    summary.interventions_per_episode = stats::Summarize(
        PerSeed(summary, [](const SeedResult& r) { return r.interventions_per_episode(); }));
  }
  comparisons_ = nlohmann::json::object();
  const auto secure = methods_.find(Method::kSecure);
  const auto airl = methods_.find(Method::kAirl);
  if (secure != methods_.end() && airl != methods_.end() && seeds >= 2) {
    const std::vector<double> s_success = Successes(secure->second);
    const std::vector<double> a_success = Successes(airl->second);
    comparisons_["secure_vs_airl"] = {
        {"success_mann_whitney", MannWhitneyJson(s_success, a_success)},
        {"dangerous_mann_whitney",
         MannWhitneyJson(Dangers(secure->second), Dangers(airl->second))},
        {"success_tost", stats::TostWelch(s_success, a_success, options_.tost_bound).ToJson()},
    };
  }
  // The other safety filters (issue 37) against SECURE: the same tests as SECURE vs AIRL.
  for (Method m : kOtherFilters) {
    const auto other = methods_.find(m);
    if (secure == methods_.end() || other == methods_.end() || seeds < 2) continue;
    const std::vector<double> o_success = Successes(other->second);
    const std::vector<double> s_success = Successes(secure->second);
    comparisons_[std::string(ToString(kMethodNames, m)) + "_vs_secure"] = {
        {"success_mann_whitney", MannWhitneyJson(o_success, s_success)},
        {"dangerous_mann_whitney", MannWhitneyJson(Dangers(other->second), Dangers(secure->second))},
        {"success_tost", stats::TostWelch(o_success, s_success, options_.tost_bound).ToJson()},
    };
  }
  // Figure 9: SECURE and its two ablations, Kruskal–Wallis and Dunn on each metric.
  std::vector<Method> group_methods;
  for (Method m : {Method::kSecure, Method::kSecureRandomSafe, Method::kSecureNoResampling}) {
    if (methods_.count(m) != 0) group_methods.push_back(m);
  }
  if (group_methods.size() >= 2 && seeds >= 2) {
    nlohmann::json ablations = {{"methods", nlohmann::json::array()}};
    for (Method m : group_methods) ablations["methods"].push_back(ToString(kMethodNames, m));
    for (const char* metric : {"success_rate", "dangerous_rate"}) {
      std::vector<std::vector<double>> groups;
      for (Method m : group_methods) {
        groups.push_back(std::string(metric) == "success_rate" ? Successes(methods_.at(m))
                                                               : Dangers(methods_.at(m)));
      }
      std::vector<double> all;
      for (const auto& g : groups) all.insert(all.end(), g.begin(), g.end());
      if (std::all_of(all.begin(), all.end(), [&](double v) { return v == all.front(); })) {
        ablations[metric] = {{"note", "all values equal; no test"}};
        continue;
      }
      ablations[metric] = {{"kruskal_wallis", stats::KruskalWallis(groups).ToJson()},
                           {"dunn", stats::Dunn(groups).ToJson()}};
    }
    comparisons_["ablations"] = std::move(ablations);
  }
  finished_ = true;
}

nlohmann::json Evaluation::ToJson() const {
  SECURE_CHECK(finished_, "Evaluation::ToJson before Finish()");
  nlohmann::json methods = nlohmann::json::object();
  for (const auto& [method, summary] : methods_) {
    methods[ToString(kMethodNames, method)] = summary.ToJson();
  }
  return {{"methods", std::move(methods)},
          {"comparisons", comparisons_},
          {"options", {{"tost_bound", options_.tost_bound}, {"alpha", options_.alpha}}}};
}

std::string Evaluation::Table() const {
  SECURE_CHECK(finished_, "Evaluation::Table before Finish()");
  std::ostringstream out;
  const std::size_t seeds = methods_.begin()->second.per_seed.size();
  const long episodes = methods_.begin()->second.per_seed.front().episodes;
  out << "Success and dangerous rate, % mean (std) over " << seeds << " seeds x " << episodes
      << " episodes\n\n";
  out << "| method | success % | dangerous % | interventions / episode | sampling rounds / "
         "decision | no-safe-action | decision p50 / p99 (us) [in forwards of 128] |\n";
  out << "|---|---|---|---|---|---|---|\n";
  for (const auto& [method, s] : methods_) {
    long no_safe = 0, decisions = 0;
    double rounds = 0.0;
    std::vector<double> p50, p99;
    for (const SeedResult& r : s.per_seed) {
      no_safe += r.no_safe_action_decisions;
      decisions += r.decisions;
      rounds += r.mean_iterations * double(r.decisions);
      p50.push_back(r.latency_us.p50);
      p99.push_back(r.latency_us.p99);
    }
    std::sort(p50.begin(), p50.end());
    std::sort(p99.begin(), p99.end());
    const bool shielded = IsShielded(method);
    // A shielded method's latency also in units of its seeds' reference forward (SeedResult).
    std::vector<double> p50_ref, p99_ref;
    for (const SeedResult& r : s.per_seed) {
      if (!shielded || r.reference_forward_latency_us <= 0) continue;
      p50_ref.push_back(r.latency_us.p50 / r.reference_forward_latency_us);
      p99_ref.push_back(r.latency_us.p99 / r.reference_forward_latency_us);
    }
    std::sort(p50_ref.begin(), p50_ref.end());
    std::sort(p99_ref.begin(), p99_ref.end());
    out << "| " << ToString(kMethodNames, method) << " | " << MeanStd(s.success_rate) << " | "
        << MeanStd(s.dangerous_rate) << " | "
        << (shielded ? Number(s.interventions_per_episode.mean, "%.2f") : "-") << " | "
        << (shielded && decisions > 0 ? Number(rounds / double(decisions), "%.2f") : "-") << " | "
        << (shielded ? std::to_string(no_safe) : "-") << " | "
        << Number(p50[p50.size() / 2], "%.1f") << " / " << Number(p99[p99.size() / 2], "%.1f")
        << (p50_ref.empty() ? std::string()
                            : " [" + Number(p50_ref[p50_ref.size() / 2], "%.2f") + " / " +
                                  Number(p99_ref[p99_ref.size() / 2], "%.2f") + "]")
        << " |\n";
  }
  if (comparisons_.contains("secure_vs_airl")) {
    const nlohmann::json& c = comparisons_["secure_vs_airl"];
    const nlohmann::json& tost = c["success_tost"];
    out << "\nSECURE vs AIRL: success Mann-Whitney U = " << Number(c["success_mann_whitney"]["u"].get<double>())
        << ", p = " << Number(c["success_mann_whitney"]["p_value"].get<double>())
        << "; dangerous Mann-Whitney U = " << Number(c["dangerous_mann_whitney"]["u"].get<double>())
        << ", p = " << Number(c["dangerous_mann_whitney"]["p_value"].get<double>())
        << "; success TOST (bound " << Percent(options_.tost_bound)
        << " points): difference " << Percent(tost["difference"].get<double>()) << " points, ";
    if (!(tost["se"].get<double>() > 0)) {
      // Both methods' success is the same on every seed (e.g. 0 % against 0 %): the test's
      // standard error is 0 and its p-value says nothing about equivalence.
      out << "not informative: each method's success is constant over the seeds ("
          << Percent(methods_.at(Method::kSecure).success_rate.mean) << " % and "
          << Percent(methods_.at(Method::kAirl).success_rate.mean) << " %)\n";
    } else {
      out << "p = " << Number(tost["p_value"].get<double>()) << " ("
          << (tost["p_value"].get<double>() < options_.alpha ? "equivalent"
                                                             : "not shown equivalent")
          << " at alpha " << options_.alpha << ")\n";
    }
  }
  for (Method m : kOtherFilters) {
    const std::string name = ToString(kMethodNames, m);
    if (!comparisons_.contains(name + "_vs_secure")) continue;
    const nlohmann::json& c = comparisons_[name + "_vs_secure"];
    const nlohmann::json& tost = c["success_tost"];
    long tried = 0, decided = 0;
    for (const SeedResult& r : methods_.at(m).per_seed) {
      tried += r.qp_tried;
      decided += r.qp_decisions;
    }
    out << "\n" << name << " vs SECURE: dangerous Mann-Whitney U = "
        << Number(c["dangerous_mann_whitney"]["u"].get<double>())
        << ", p = " << Number(c["dangerous_mann_whitney"]["p_value"].get<double>())
        << "; success TOST (bound " << Percent(options_.tost_bound) << " points): ";
    if (!(tost["se"].get<double>() > 0)) {
      // Success constant over the seeds on both sides (e.g. 100 % and 100 %): no test.
      out << "not informative (each method's success is constant over the seeds)";
    } else {
      out << "difference " << Percent(tost["difference"].get<double>())
          << " points, p = " << Number(tost["p_value"].get<double>()) << " ("
          << (tost["p_value"].get<double>() < options_.alpha ? "equivalent"
                                                             : "not shown equivalent")
          << " at alpha " << options_.alpha << ")";
    }
    if (tried > 0) {
      out << "; the " << (m == Method::kCbfGrad ? "gradient refinement" : "CBF-QP projection")
          << " decided " << decided << " of " << tried << " decisions";
    }
    out << "\n";
  }
  if (comparisons_.contains("ablations")) {
    const nlohmann::json& a = comparisons_["ablations"];
    for (const char* metric : {"success_rate", "dangerous_rate"}) {
      if (!a.contains(metric)) continue;
      out << "\nAblations, " << metric << ": ";
      if (!a[metric].contains("kruskal_wallis")) {
        out << a[metric]["note"].get<std::string>() << "\n";
        continue;
      }
      const nlohmann::json& kw = a[metric]["kruskal_wallis"];
      out << "Kruskal-Wallis H = " << Number(kw["h"].get<double>())
          << ", p = " << Number(kw["p_value"].get<double>()) << "; Dunn (Bonferroni):";
      for (const nlohmann::json& pair : a[metric]["dunn"]["pairs"]) {
        const int i = pair["i"].get<int>(), j = pair["j"].get<int>();
        out << " " << a["methods"][i].get<std::string>() << " vs "
            << a["methods"][j].get<std::string>()
            << " p = " << Number(pair["p_adjusted"].get<double>()) << ";";
      }
      out << "\n";
    }
  }
  return out.str();
}

}  // namespace secure::eval
