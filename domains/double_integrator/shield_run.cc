#include "domains/double_integrator/shield_run.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>
#include <vector>

#include "domains/double_integrator/reach_avoid.h"
#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"

namespace secure::eval {
namespace {

namespace di = domains::double_integrator;

// Episode i's stream: the seed and the index mixed (Rng::Seed runs splitmix64 over the result).
// Not eval::EpisodeSeed: this run's published figures were measured with these streams.
std::uint64_t ShieldRunEpisodeSeed(std::uint64_t seed, long episode) {
  return seed ^ (0xd1b54a32d192ed03ULL * static_cast<std::uint64_t>(episode + 1));
}

// Counts, per step of the runner, what SeedResult does not: the ground-truth unsafe states and
// the decisions that fell back to the braking backup action.
class GroundTruthCounter final : public StepObserver {
 public:
  GroundTruthCounter(const di::ReachAvoidEnv& env, ShieldRunResult& result, long record = 0)
      : env_(env), truth_(env.options().truth), result_(result), record_(record) {}
  // The recorded states (4 x n).
  Eigen::MatrixXf Visited() const {
    return Eigen::Map<const Eigen::MatrixXf>(visited_.data(), 4,
                                             static_cast<long>(visited_.size() / 4));
  }
  void OnEpisodeStart(long, const Eigen::VectorXf&) override { left_safe_set_ = false; }
  void OnStep(const StepView& step) override {
    const Eigen::Vector4f& s = env_.state();
    if (static_cast<long>(visited_.size()) < 4 * record_) visited_.insert(visited_.end(), s.data(), s.data() + 4);
    if (truth_.H(s[0], s[1], s[2], s[3]) < 0.0) {
      ++result_.unsafe_state_steps;
      left_safe_set_ = true;
    }
    if (step.decision != nullptr && step.decision->fallback == shield::Fallback::kBackupAction)
      ++result_.backup_action_decisions;
  }
  void OnEpisodeEnd(long) override {
    if (left_safe_set_) ++result_.unsafe_state_episodes;
  }

 private:
  const di::ReachAvoidEnv& env_;
  const di::GroundTruth& truth_;
  ShieldRunResult& result_;
  long record_ = 0;
  std::vector<float> visited_;
  bool left_safe_set_ = false;
};

}  // namespace

// ---------------------------------------------------------------------------------------------
PdEpisodePolicy::PdEpisodePolicy(const ShieldRunOptions& options)
    : kp_(options.kp),
      kd_(options.kd),
      goal_x_(options.task.goal_x),
      goal_y_(options.task.goal_y),
      a_max_(options.task.accel_bound),
      sigma_(Eigen::VectorXf::Constant(2, static_cast<float>(options.policy_sigma))) {}

void PdEpisodePolicy::Mean(const Eigen::Ref<const Eigen::VectorXf>& s,
                           Eigen::Ref<Eigen::VectorXf> mu) {
  SECURE_CHECK(s.size() == 4 && mu.size() == 2, "PdEpisodePolicy::Mean: observation/mu have "
                                                    << s.size() << "/" << mu.size()
                                                    << " entries, expected 4/2");
  mu[0] = static_cast<float>(std::clamp(kp_ * (goal_x_ - s[0]) - kd_ * s[2], -a_max_, a_max_));
  mu[1] = static_cast<float>(std::clamp(kp_ * (goal_y_ - s[1]) - kd_ * s[3], -a_max_, a_max_));
}

// ---------------------------------------------------------------------------------------------
void ShieldRunOptions::Validate() const {
  task.Validate();
  SECURE_CHECK_FIELD(episodes > 0, "ShieldRunOptions", "episodes", episodes, "> 0");
  SECURE_CHECK_FIELD(episodes <= kMaxEpisodes, "ShieldRunOptions", "episodes", episodes,
                     "in [1, " << kMaxEpisodes << "]");
  SECURE_CHECK_FIELD(std::isfinite(kp) && kp > 0, "ShieldRunOptions", "kp", kp, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(kd) && kd >= 0, "ShieldRunOptions", "kd", kd, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(policy_sigma) && policy_sigma >= 0, "ShieldRunOptions",
                     "policy_sigma", policy_sigma, ">= 0");
  shield.Validate();
  SECURE_CHECK_FIELD(record_states >= 0 && record_states <= kMaxStates, "ShieldRunOptions",
                     "record_states", record_states, "in [0, " << kMaxStates << "]");
  SECURE_CHECK_FIELD(
      shield.dt == task.dt, "ShieldRunOptions", "shield.dt", shield.dt,
      "equal to task.dt = " << task.dt << " (the shield looks one environment step ahead)");
}

nlohmann::json ShieldRunOptions::ToJson() const {
  nlohmann::json j = task.ToJson();
  j["episodes"] = episodes;
  j["kp"] = kp;
  j["kd"] = kd;
  j["policy_sigma"] = policy_sigma;
  j["shield"] = shield.ToJson();
  j["seed"] = seed;
  return j;
}

// ---------------------------------------------------------------------------------------------
nlohmann::json ShieldRunResult::ToJson() const {
  return {{"shielded", shielded},
          {"barrier", barrier},
          {"episodes", episodes},
          {"dangerous_episodes", dangerous_episodes},
          {"success_episodes", success_episodes},
          {"timeout_episodes", timeout_episodes},
          {"unsafe_state_episodes", unsafe_state_episodes},
          {"unsafe_state_steps", unsafe_state_steps},
          {"steps", steps},
          {"mean_steps_to_goal", mean_steps_to_goal},
          {"decisions", decisions},
          {"interventions", interventions},
          {"mean_interventions_per_episode", mean_interventions_per_episode},
          {"resampled_decisions", resampled_decisions},
          {"no_safe_action_decisions", no_safe_action_decisions},
          {"invalid_input_decisions", invalid_input_decisions},
          {"backup_action_decisions", backup_action_decisions},
          {"latency_us", latency_us.ToJson()},
          {"seconds", seconds},
          {"options", options.ToJson()}};
}

std::string ShieldRunResult::Table() const {
  const double n = static_cast<double>(std::max(episodes, 1L));
  auto row = [](std::ostringstream& out, const char* name, const std::string& value) {
    out << "| " << name << " | " << value << " |\n";
  };
  auto count = [&](long c) {
    char buf[64];
    std::snprintf(buf, sizeof(buf), "%ld (%.1f %%)", c, 100.0 * static_cast<double>(c) / n);
    return std::string(buf);
  };
  auto number = [](const char* format, double v) {
    if (!std::isfinite(v)) return std::string("n/a");  // undefined; JSON holds null
    char buf[64];
    std::snprintf(buf, sizeof(buf), format, v);
    return std::string(buf);
  };
  std::ostringstream out;
  out << (shielded ? "Shielded" : "Unshielded") << " double integrator, barrier: " << barrier
      << "\n\n| metric | value |\n|---|---:|\n";
  row(out, "episodes", std::to_string(episodes));
  row(out, "dangerous (entered the obstacle)", count(dangerous_episodes));
  row(out, "success (reached the goal)", count(success_episodes));
  row(out, "timeout", count(timeout_episodes));
  row(out, "left the safe set (ground-truth h < 0)", count(unsafe_state_episodes));
  row(out, "steps with ground-truth h < 0", std::to_string(unsafe_state_steps));
  row(out, "steps", std::to_string(steps));
  row(out, "mean steps to goal",
      success_episodes > 0 ? number("%.1f", mean_steps_to_goal) : "n/a (no successful episode)");
  if (shielded) {
    row(out, "decisions", std::to_string(decisions));
    row(out, "interventions per episode", number("%.2f", mean_interventions_per_episode));
    row(out, "decisions after resampling", std::to_string(resampled_decisions));
    row(out, "no-safe-action decisions", std::to_string(no_safe_action_decisions));
    row(out, "invalid-input decisions", std::to_string(invalid_input_decisions));
    row(out, "backup (braking) fallbacks", std::to_string(backup_action_decisions));
    row(out, "latency p50 / p90 / p99 / max (µs)",
        number("%.1f", latency_us.p50) + " / " + number("%.1f", latency_us.p90) + " / " +
            number("%.1f", latency_us.p99) + " / " + number("%.1f", latency_us.max));
  }
  row(out, "wall time (s)", number("%.2f", seconds));
  return out.str();
}

// ---------------------------------------------------------------------------------------------
ShieldRunResult RunDoubleIntegratorShield(const ShieldRunOptions& options, cbf::Barrier& barrier,
                                          bool shielded) {
  options.Validate();
  const Stopwatch clock;
  di::ReachAvoidEnv env(options.task);
  std::optional<shield::Shield> shield;
  if (shielded) {
    shield.emplace(options.shield, barrier, env.ShieldModel());
    shield->SetActionBounds(env);
  }
  PdEpisodePolicy policy(options);

  ShieldRunResult result;
  result.shielded = shielded;
  result.barrier = shielded ? barrier.Describe() : "none";
  result.options = options;
  GroundTruthCounter counter(env, result, options.record_states);
  EpisodeRunnerOptions runner_options;
  runner_options.stop_on_collision = true;  // entering the obstacle is a crash
  runner_options.episode_seed = &ShieldRunEpisodeSeed;
  EpisodeRunner runner(env, runner_options);
  const SeedResult r =
      runner.Run(policy, shielded ? &*shield : nullptr, options.episodes, options.seed, &counter);

  result.episodes = r.episodes;
  result.dangerous_episodes = r.dangerous;
  result.success_episodes = r.successes;
  result.timeout_episodes = r.episodes - r.dangerous - r.successes;
  result.steps = r.steps;
  result.mean_steps_to_goal = r.mean_steps_to_goal;
  result.decisions = r.decisions;
  result.interventions = r.interventions;
  result.mean_interventions_per_episode = r.interventions_per_episode();
  result.resampled_decisions = r.resampled_decisions;
  result.no_safe_action_decisions = r.no_safe_action_decisions;
  result.invalid_input_decisions = r.invalid_input_decisions;
  // Unshielded there is no decision to time (the runner times the policy's sample).
  if (shielded) result.latency_us = r.latency_us;
  result.visited = counter.Visited();
  result.seconds = clock.Seconds();
  return result;
}

}  // namespace secure::eval
