#include "domains/double_integrator/shield_run.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>

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
Rng EpisodeRng(std::uint64_t seed, long episode) {
  return Rng(seed ^ (0xd1b54a32d192ed03ULL * static_cast<std::uint64_t>(episode + 1)));
}

float Clip(double value, double bound) {
  return static_cast<float>(std::clamp(value, -bound, bound));
}

// A start state: the reach-avoid task's start distribution with this run's start region.
Eigen::Vector4f DrawStart(const ShieldRunOptions& o, Rng& rng) {
  di::ReachAvoidOptions task;
  task.truth = o.truth;
  task.start_lo = o.start_lo;
  task.start_hi = o.start_hi;
  task.start_speed = o.start_speed;
  task.start_clearance = o.start_clearance;
  return di::DrawStartState(task, rng);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
void ShieldRunOptions::Validate() const {
  const di::GroundTruth& t = truth;
  SECURE_CHECK_FIELD(std::isfinite(t.obstacle_x) && std::isfinite(t.obstacle_y), "ShieldRunOptions",
                     "truth.obstacle", "(" << t.obstacle_x << ", " << t.obstacle_y << ")",
                     "finite");
  SECURE_CHECK_FIELD(std::isfinite(t.radius) && t.radius > 0, "ShieldRunOptions", "truth.radius",
                     t.radius, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(t.gamma) && t.gamma > 0, "ShieldRunOptions", "truth.gamma",
                     t.gamma, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(goal_radius) && goal_radius > 0, "ShieldRunOptions",
                     "goal_radius", goal_radius, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(goal_x) && std::isfinite(goal_y), "ShieldRunOptions", "goal",
                     "(" << goal_x << ", " << goal_y << ")", "finite");
  const double goal_distance = std::hypot(goal_x - t.obstacle_x, goal_y - t.obstacle_y);
  SECURE_CHECK_FIELD(goal_distance >= t.radius + goal_radius, "ShieldRunOptions", "goal",
                     "(" << goal_x << ", " << goal_y << ")",
                     "at least radius + goal_radius = " << t.radius + goal_radius
                                                        << " from the obstacle centre (is "
                                                        << goal_distance << ")");
  SECURE_CHECK_FIELD(std::isfinite(start_lo) && std::isfinite(start_hi) && start_lo < start_hi,
                     "ShieldRunOptions", "start_lo, start_hi", start_lo << ", " << start_hi,
                     "finite with start_lo < start_hi");
  SECURE_CHECK_FIELD(std::isfinite(start_speed) && start_speed >= 0, "ShieldRunOptions",
                     "start_speed", start_speed, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(start_clearance) && start_clearance >= 0, "ShieldRunOptions",
                     "start_clearance", start_clearance, ">= 0");
  SECURE_CHECK_FIELD(episodes > 0, "ShieldRunOptions", "episodes", episodes, "> 0");
  SECURE_CHECK_FIELD(episodes <= kMaxEpisodes, "ShieldRunOptions", "episodes", episodes,
                     "in [1, " << kMaxEpisodes << "]");
  SECURE_CHECK_FIELD(max_steps > 0, "ShieldRunOptions", "max_steps", max_steps, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(dt) && dt > 0, "ShieldRunOptions", "dt", dt, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(accel_bound) && accel_bound > 0, "ShieldRunOptions",
                     "accel_bound", accel_bound, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(kp) && kp > 0, "ShieldRunOptions", "kp", kp, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(kd) && kd >= 0, "ShieldRunOptions", "kd", kd, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(policy_sigma) && policy_sigma >= 0, "ShieldRunOptions",
                     "policy_sigma", policy_sigma, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(brake_gain) && brake_gain >= 0, "ShieldRunOptions", "brake_gain",
                     brake_gain, ">= 0");
  shield.Validate();
  SECURE_CHECK_FIELD(shield.dt == dt, "ShieldRunOptions", "shield.dt", shield.dt,
                     "equal to dt = " << dt << " (the shield looks one environment step ahead)");
}

nlohmann::json ShieldRunOptions::ToJson() const {
  return {{"obstacle", {truth.obstacle_x, truth.obstacle_y}},
          {"radius", truth.radius},
          {"gamma", truth.gamma},
          {"goal", {goal_x, goal_y}},
          {"goal_radius", goal_radius},
          {"start_region", {start_lo, start_hi}},
          {"start_speed", start_speed},
          {"start_clearance", start_clearance},
          {"episodes", episodes},
          {"max_steps", max_steps},
          {"dt", dt},
          {"accel_bound", accel_bound},
          {"kp", kp},
          {"kd", kd},
          {"policy_sigma", policy_sigma},
          {"brake_gain", brake_gain},
          {"shield", shield.ToJson()},
          {"seed", seed}};
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
  const di::GroundTruth& truth = options.truth;
  const di::ClippedDoubleIntegrator environment(options.dt, options.accel_bound);
  std::optional<shield::Shield> shield;
  if (shielded) shield.emplace(options.shield, barrier, environment);

  ShieldRunResult result;
  result.shielded = shielded;
  result.barrier = shielded ? barrier.Describe() : "none";
  result.options = options;
  result.episodes = options.episodes;
  std::vector<double> latencies_us;
  if (shielded) latencies_us.reserve(static_cast<std::size_t>(options.episodes) * 128);
  long steps_to_goal = 0;

  const double a_max = options.accel_bound;
  const Eigen::Vector2f sigma = Eigen::Vector2f::Constant(static_cast<float>(options.policy_sigma));
  Eigen::Vector2f mu, brake;
  Eigen::Matrix<float, 2, 1> action;
  Eigen::Matrix<float, 4, 1> next;
  for (long episode = 0; episode < options.episodes; ++episode) {
    Rng rng = EpisodeRng(options.seed, episode);
    Eigen::Vector4f s = DrawStart(options, rng);
    if (shielded) shield->Seed(rng.NextU64());
    bool left_safe_set = false;
    for (int step = 1; step <= options.max_steps; ++step) {
      // The nominal policy: PD toward the goal, clipped to the bound.
      mu[0] = Clip(options.kp * (options.goal_x - s[0]) - options.kd * s[2], a_max);
      mu[1] = Clip(options.kp * (options.goal_y - s[1]) - options.kd * s[3], a_max);
      if (shielded) {
        brake[0] = Clip(-options.brake_gain * s[2], a_max);
        brake[1] = Clip(-options.brake_gain * s[3], a_max);
        shield->SetBackupAction(brake);
        const shield::Decision& d = shield->Decide(s, mu, sigma);
        ++result.decisions;
        latencies_us.push_back(d.seconds * 1e6);
        if (d.intervened) ++result.interventions;
        if (d.status == shield::Status::kSafeAfterResampling) ++result.resampled_decisions;
        if (d.status == shield::Status::kNoSafeAction) ++result.no_safe_action_decisions;
        if (d.status == shield::Status::kInvalidInput) ++result.invalid_input_decisions;
        if (d.fallback == shield::Fallback::kBackupAction) ++result.backup_action_decisions;
        action = d.action;
      } else {
        for (int i = 0; i < 2; ++i) action[i] = mu[i] + sigma[i] * static_cast<float>(rng.Normal());
      }
      environment.Step(s, action, next);  // clips the action
      s = next;
      ++result.steps;

      if (truth.H(s[0], s[1], s[2], s[3]) < 0.0) {
        ++result.unsafe_state_steps;
        left_safe_set = true;
      }
      if (std::hypot(s[0] - truth.obstacle_x, s[1] - truth.obstacle_y) < truth.radius) {
        ++result.dangerous_episodes;  // a crash ends the episode
        break;
      }
      if (std::hypot(s[0] - options.goal_x, s[1] - options.goal_y) < options.goal_radius) {
        ++result.success_episodes;
        steps_to_goal += step;
        break;
      }
    }
    if (left_safe_set) ++result.unsafe_state_episodes;
  }
  result.timeout_episodes = result.episodes - result.dangerous_episodes - result.success_episodes;
  result.mean_interventions_per_episode =
      static_cast<double>(result.interventions) / static_cast<double>(result.episodes);
  if (result.success_episodes > 0)
    result.mean_steps_to_goal =
        static_cast<double>(steps_to_goal) / static_cast<double>(result.success_episodes);
  result.latency_us = LatencySummary::Of(std::move(latencies_us));
  result.seconds = clock.Seconds();
  return result;
}

}  // namespace secure::eval
