#include "domains/double_integrator/expert.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include "secure/common/error.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/random_order.h"
#include "secure/common/timer.h"
#include "secure/domains/demonstrations.h"

namespace secure::domains::double_integrator {
namespace {

constexpr double kTwoPi = 6.283185307179586;

}  // namespace

// ---------------------------------------------------------------------------------------------
// Options

void ExpertOptions::Validate() const {
  SECURE_CHECK_FIELD(std::isfinite(kp) && kp > 0, "ExpertOptions", "kp", kp, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(speed_limit) && speed_limit > 0, "ExpertOptions", "speed_limit",
                     speed_limit, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(detour_gain) && detour_gain >= 0, "ExpertOptions", "detour_gain",
                     detour_gain, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(detour_range) && detour_range > 0, "ExpertOptions",
                     "detour_range", detour_range, "> 0");
  SECURE_CHECK_FIELD(std::isfinite(gain_spread) && gain_spread >= 0 && gain_spread < 1,
                     "ExpertOptions", "gain_spread", gain_spread, "in [0, 1)");
  SECURE_CHECK_FIELD(std::isfinite(speed_spread) && speed_spread >= 0 && speed_spread < 1,
                     "ExpertOptions", "speed_spread", speed_spread, "in [0, 1)");
  SECURE_CHECK_FIELD(std::isfinite(noise_sigma) && noise_sigma >= 0, "ExpertOptions", "noise_sigma",
                     noise_sigma, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(cbf_rate) && cbf_rate > 0, "ExpertOptions", "cbf_rate", cbf_rate,
                     "> 0");
  SECURE_CHECK_FIELD(std::isfinite(filter_margin) && filter_margin >= 0, "ExpertOptions",
                     "filter_margin", filter_margin, ">= 0");
  SECURE_CHECK_FIELD(std::isfinite(clearance) && clearance >= 0, "ExpertOptions", "clearance",
                     clearance, ">= 0");
}

nlohmann::json ExpertOptions::ToJson() const {
  return {{"kp", kp},
          {"speed_limit", speed_limit},
          {"detour_gain", detour_gain},
          {"detour_range", detour_range},
          {"gain_spread", gain_spread},
          {"speed_spread", speed_spread},
          {"noise_sigma", noise_sigma},
          {"use_filter", use_filter},
          {"cbf_rate", cbf_rate},
          {"filter_margin", filter_margin},
          {"clearance", clearance}};
}

void DemonstrationOptions::Validate() const {
  SECURE_CHECK_FIELD(episodes > 0, "DemonstrationOptions", "episodes", episodes, "> 0");
  SECURE_CHECK_FIELD(episodes <= kMaxEpisodes, "DemonstrationOptions", "episodes", episodes,
                     "in [1, " << kMaxEpisodes << "]");
  SECURE_CHECK_FIELD(max_attempts >= 0, "DemonstrationOptions", "max_attempts", max_attempts,
                     ">= 0 (0: 10 x episodes + 10)");
}

nlohmann::json DemonstrationOptions::ToJson() const {
  return {{"episodes", episodes},
          {"stop_at_goal", stop_at_goal},
          {"max_attempts", max_attempts},
          {"require_all", require_all},
          {"seed", seed}};
}

void NearDangerousOptions::Validate() const {
  SECURE_CHECK_FIELD(count > 0, "NearDangerousOptions", "count", count, "> 0");
  SECURE_CHECK_FIELD(count <= kMaxStates, "NearDangerousOptions", "count", count,
                     "in [1, " << kMaxStates << "]");
  SECURE_CHECK_FIELD(std::isfinite(rho_min) && std::isfinite(rho_max) && rho_min < rho_max,
                     "NearDangerousOptions", "rho_min, rho_max", rho_min << ", " << rho_max,
                     "finite with rho_min < rho_max");
  SECURE_CHECK_FIELD(
      std::isfinite(velocity_lo) && std::isfinite(velocity_hi) && velocity_lo < velocity_hi,
      "NearDangerousOptions", "velocity_lo, velocity_hi", velocity_lo << ", " << velocity_hi,
      "finite with velocity_lo < velocity_hi");
}

nlohmann::json NearDangerousOptions::ToJson() const {
  return {{"count", count}, {"rho", {rho_min, rho_max}}, {"velocity", {velocity_lo, velocity_hi}}};
}

// ---------------------------------------------------------------------------------------------
// Expert

Expert::Expert(const ReachAvoidOptions& task, const ExpertOptions& options)
    : task_(task), options_(options), kp_(options.kp), speed_limit_(options.speed_limit) {
  task_.Validate();
  options_.Validate();
  guard_ = task_.truth;
  guard_.radius += options_.clearance;
  const double k_dt = options_.cbf_rate * task_.dt;
  SECURE_CHECK(k_dt <= 1.0, "ExpertOptions::cbf_rate = "
                                << options_.cbf_rate << ", must satisfy cbf_rate * dt <= 1 (dt = "
                                << task_.dt << ", cbf_rate * dt = " << k_dt << ")");
}

void Expert::BeginEpisode(Rng& rng) {
  kp_ = options_.kp * rng.Uniform(1.0 - options_.gain_spread, 1.0 + options_.gain_spread);
  speed_limit_ = options_.speed_limit * rng.Uniform(1.0 - options_.speed_spread, 1.0);
}

Eigen::Vector2d Expert::Nominal(const Eigen::Vector4d& s) const {
  const double kd = 2.0 * std::sqrt(kp_);
  Eigen::Vector2d v_des((kp_ / kd) * (task_.goal_x - s[0]), (kp_ / kd) * (task_.goal_y - s[1]));
  const double speed = v_des.norm();
  if (speed > speed_limit_) v_des *= speed_limit_ / speed;
  if (options_.detour_gain > 0 && speed > 0) {
    const GroundTruth& t = guard_;
    Eigen::Vector2d d(s[0] - t.obstacle_x, s[1] - t.obstacle_y);
    const double distance = d.norm();
    if (distance > 0) {
      d /= distance;
      const Eigen::Vector2d goal_direction = v_des / v_des.norm();
      const double head_on = std::max(0.0, -d.dot(goal_direction));
      Eigen::Vector2d tangent = goal_direction - goal_direction.dot(d) * d;
      const double tangent_norm = tangent.norm();
      tangent = tangent_norm > 1e-12 ? Eigen::Vector2d(tangent / tangent_norm)
                                     : Eigen::Vector2d(-d[1], d[0]);
      v_des += options_.detour_gain * speed_limit_ * head_on *
               std::exp(-std::max(0.0, distance - t.radius) / options_.detour_range) * tangent;
    }
  }
  return kd * (v_des - s.tail<2>());
}

double Expert::NextH(const Eigen::Vector4d& s, const Eigen::Vector2d& a) const {
  const double dt = task_.dt;
  const double c = 0.5 * dt * dt;
  return guard_.H(s[0] + s[2] * dt + a[0] * c, s[1] + s[3] * dt + a[1] * c, s[2] + a[0] * dt,
                       s[3] + a[1] * dt);
}

Eigen::Vector2d Expert::FilterAction(const Eigen::Vector4d& s, const Eigen::Vector2d& nominal,
                                     FilterInfo* info) const {
  const GroundTruth& t = guard_;
  const double dt = task_.dt;
  const double a_max = task_.accel_bound;
  const double h = t.H(s[0], s[1], s[2], s[3]);
  const double required = (1.0 - options_.cbf_rate * dt) * h;
  const double target = required + options_.filter_margin;
  // Candidates computed on the boundary meet the target up to rounding; accept them with a
  // tolerance far below the margin.
  const double tolerance = 1e-9 * std::max(1.0, std::abs(target));
  auto feasible = [&](const Eigen::Vector2d& a) { return NextH(s, a) >= target - tolerance; };
  auto finish = [&](const Eigen::Vector2d& a, bool modified, bool is_feasible) {
    if (info != nullptr) {
      info->h = h;
      info->required = required;
      info->next_h = NextH(s, a);
      info->modified = modified;
      info->feasible = is_feasible;
    }
    return a;
  };

  const Eigen::Vector2d clipped = nominal.cwiseMax(-a_max).cwiseMin(a_max);
  if (feasible(clipped)) return finish(clipped, false, true);

  // h(T(s, a)) = h0 + g.a + q |a|^2 (see the header comment).
  const double gamma = t.gamma;
  const double c = 0.5 * dt * dt;
  const Eigen::Vector2d d(s[0] - t.obstacle_x, s[1] - t.obstacle_y);
  const Eigen::Vector2d v = s.tail<2>();
  const Eigen::Vector2d e = d + v * dt;
  const double h0 = gamma * (e.squaredNorm() - t.radius * t.radius) + 2.0 * e.dot(v);
  const Eigen::Vector2d g = (2.0 * gamma * c + 2.0 * dt) * e + 2.0 * c * v;
  const double q = gamma * c * c + 2.0 * c * dt;

  Eigen::Vector2d best = clipped;
  double best_distance = std::numeric_limits<double>::infinity();
  auto consider = [&](Eigen::Vector2d a) {
    a = a.cwiseMax(-a_max).cwiseMin(a_max);  // candidates within rounding of the box
    if (!feasible(a)) return;
    const double distance = (a - nominal).squaredNorm();
    if (distance < best_distance) {
      best_distance = distance;
      best = a;
    }
  };
  auto in_box = [&](const Eigen::Vector2d& a) {
    const double slack = 1e-12 * a_max;
    return std::abs(a[0]) <= a_max + slack && std::abs(a[1]) <= a_max + slack;
  };

  // The radial projection of the nominal action onto the circle |a - a_c| = R.
  const Eigen::Vector2d centre = -g / (2.0 * q);
  const double radius_squared = (target - h0) / q + g.squaredNorm() / (4.0 * q * q);
  if (radius_squared > 0) {
    const Eigen::Vector2d w = nominal - centre;
    const double w_norm = w.norm();
    if (w_norm > 0) {
      const Eigen::Vector2d a = centre + std::sqrt(radius_squared) / w_norm * w;
      if (in_box(a)) consider(a);
    }
  }
  // Each box edge a_i = +-a_max: the projection of the nominal action, and the roots of
  // q t^2 + g_j t + (h0 + g_i x + q x^2 - target) = 0 in t = a_j (stable quadratic formula).
  for (int i = 0; i < 2; ++i) {
    const int j = 1 - i;
    for (const double x : {-a_max, a_max}) {
      Eigen::Vector2d a;
      a[i] = x;
      a[j] = std::clamp(nominal[j], -a_max, a_max);
      consider(a);  // also a corner when nominal[j] is outside the bound
      const double c0 = h0 + g[i] * x + q * x * x - target;
      const double discriminant = g[j] * g[j] - 4.0 * q * c0;
      if (discriminant < 0) continue;
      const double sq = std::sqrt(discriminant);
      const double m = -0.5 * (g[j] + (g[j] >= 0 ? sq : -sq));
      for (const double root : {m / q, m != 0.0 ? c0 / m : 0.0}) {
        if (std::abs(root) <= a_max) {
          a[j] = root;
          consider(a);
        }
      }
    }
  }
  // The corners (covered above when the nominal action lies outside the box; cheap to add).
  for (const double x : {-a_max, a_max})
    for (const double y : {-a_max, a_max}) consider(Eigen::Vector2d(x, y));

  if (std::isfinite(best_distance)) return finish(best, true, true);

  // No action meets the condition: the corner with the largest h(s') (h(s') is convex in a).
  Eigen::Vector2d argmax(a_max, a_max);
  double max_h = -std::numeric_limits<double>::infinity();
  for (const double x : {-a_max, a_max}) {
    for (const double y : {-a_max, a_max}) {
      const double next_h = NextH(s, Eigen::Vector2d(x, y));
      if (next_h > max_h) {
        max_h = next_h;
        argmax = Eigen::Vector2d(x, y);
      }
    }
  }
  return finish(argmax, true, false);
}

void Expert::Act(const Eigen::Ref<const Eigen::VectorXf>& state, Rng& rng,
                 Eigen::Ref<Eigen::VectorXf> action) {
  SECURE_CHECK(state.size() == kStateDim && action.size() == kActionDim,
               "Expert::Act: state/action have " << state.size() << "/" << action.size()
                                                 << " entries, expected 4/2");
  const Eigen::Vector4d s = state.cast<double>();
  const Eigen::Vector2d a = NoisyFilteredAction<FilterInfo>(
      Nominal(s), options_.noise_sigma, options_.use_filter, task_.accel_bound, rng, stats_,
      [&](const Eigen::Vector2d& noisy, FilterInfo* info) { return FilterAction(s, noisy, info); });
  action[0] = static_cast<float>(a[0]);
  action[1] = static_cast<float>(a[1]);
}

// ---------------------------------------------------------------------------------------------
// Demonstrations

nlohmann::json Demonstrations::ToJson() const {
  return {{"episodes", trajectories.num_episodes()},
          {"steps", trajectories.num_steps()},
          {"attempted", attempted},
          {"discarded_collisions", discarded_collisions},
          {"discarded_no_goal", discarded_no_goal},
          {"expert_steps", expert.steps},
          {"expert_modified", expert.modified},
          {"expert_infeasible", expert.infeasible},
          {"seconds", seconds}};
}

Demonstrations GenerateDemonstrations(const ReachAvoidOptions& task,
                                      const ExpertOptions& expert_options,
                                      const DemonstrationOptions& demo) {
  demo.Validate();
  const Stopwatch clock;
  ReachAvoidEnv env(task);
  Expert expert(task, expert_options);
  const long max_attempts = demo.max_attempts > 0 ? demo.max_attempts : 10 * demo.episodes + 10;
  const int horizon = env.max_steps();

  Demonstrations out;
  DemonstrationCollector collector("expert demonstrations (seed " + std::to_string(demo.seed) + ")",
                                   StateFeatures(), ActionFeatures());
  Eigen::Vector4f observation;
  Eigen::Vector2f action, applied;
  const AttemptPlan plan{"GenerateDemonstrations", "DemonstrationOptions::episodes", demo.episodes,
                         max_attempts, demo.require_all};
  KeepReachingEpisodes(
      plan, collector, out,
      [&](long attempt) {
        // Attempt i's stream (AttemptRng: the seed and the index mixed).
        Rng rng = AttemptRng(demo.seed, attempt);
        env.Reset(rng, observation);
        expert.BeginEpisode(rng);
        return RecordEpisode(
            env, collector, horizon, demo.stop_at_goal, observation, action, applied,
            [&](const Eigen::Vector4f& o, Eigen::Vector2f& a, Eigen::Vector2f& recorded) {
              expert.Act(o, rng, a);
              // The action the environment applies: the clipped one (the expert's is inside the
              // box).
              recorded = a.cwiseMax(-static_cast<float>(task.accel_bound))
                             .cwiseMin(static_cast<float>(task.accel_bound));
            },
            [](const StepOutcome&) {});
      },
      [](long) {});
  out.expert = expert.stats();
  out.trajectories = collector.Finish();
  out.seconds = clock.Seconds();
  return out;
}

// ---------------------------------------------------------------------------------------------
// Safety demonstrations

data::TrajectorySet UntilGoal(const Demonstrations& demonstrations) {
  const data::TrajectorySet& t = demonstrations.trajectories;
  SECURE_CHECK(static_cast<long>(demonstrations.steps_to_goal.size()) == t.num_episodes(),
               "UntilGoal: " << demonstrations.steps_to_goal.size() << " steps_to_goal for "
                             << t.num_episodes() << " demonstrations");
  std::vector<long> keep;
  data::TrajectorySet out;
  out.source = t.source + " [until the goal]";
  out.state_features = t.state_features;
  out.action_features = t.action_features;
  out.episode_begin.push_back(0);
  for (long e = 0; e < t.num_episodes(); ++e) {
    const long begin = t.episode_begin[static_cast<std::size_t>(e)];
    const long end = t.episode_begin[static_cast<std::size_t>(e) + 1];
    const long length = std::min<long>(end - begin, demonstrations.steps_to_goal[e] + 1);
    for (long i = begin; i < begin + length; ++i) keep.push_back(i);
    out.episode_begin.push_back(static_cast<long>(keep.size()));
  }
  out.states = data::SelectColumns(t.states, keep);
  out.actions = data::SelectColumns(t.actions, keep);
  return out;
}

data::StateSet SafeStatesFromDemonstrations(const data::TrajectorySet& trajectories,
                                            long max_states, Rng& rng) {
  SECURE_CHECK(max_states > 0,
               "SafeStatesFromDemonstrations: max_states = " << max_states << ", must be > 0");
  const long n = trajectories.num_steps();
  SECURE_CHECK(n > 0, "SafeStatesFromDemonstrations: the demonstrations (" << trajectories.source
                                                                           << ") hold no states");
  data::StateSet set;
  set.source = trajectories.source + " [states]";
  set.features = trajectories.state_features;
  if (max_states >= n) {
    set.states = trajectories.states;
    return set;
  }
  set.states = data::SelectColumns(trajectories.states, SortedRandomSubset(n, max_states, rng));
  return set;
}

data::StateSet WithSlowedCopies(const data::StateSet& safe, int copies, Rng& rng) {
  SECURE_CHECK(copies >= 0, "WithSlowedCopies: copies = " << copies << ", must be >= 0");
  SECURE_CHECK(safe.features == StateFeatures(),
               "WithSlowedCopies: " << safe.source
                                    << " does not have the double integrator's features x, y, "
                                       "vx, vy");
  data::StateSet out = safe;
  if (copies == 0) return out;
  const long n = safe.size();
  out.source = safe.source + " + " + std::to_string(copies) + " slowed copies";
  out.states.resize(kStateDim, n * (1 + copies));
  out.states.leftCols(n) = safe.states;
  for (int c = 1; c <= copies; ++c) {
    for (long i = 0; i < n; ++i) {
      const float lambda = static_cast<float>(rng.Uniform());
      auto column = out.states.col(c * n + i);
      column = safe.states.col(i);
      column.tail<2>() *= lambda;
    }
  }
  return out;
}

data::StateSet GenerateNearDangerous(const ReachAvoidOptions& task,
                                     const NearDangerousOptions& options, Rng& rng) {
  task.Validate();
  options.Validate();
  const GroundTruth& t = task.truth;
  SECURE_CHECK_FIELD(options.rho_min > -t.radius, "NearDangerousOptions", "rho_min",
                     options.rho_min, "> -radius = " << -t.radius);
  data::StateSet set;
  set.source = "near-dangerous states (generated)";
  set.features = StateFeatures();
  set.states.resize(kStateDim, options.count);
  const long max_draws = 1000 * options.count + 1000;
  long kept = 0, draws = 0;
  while (kept < options.count) {
    SECURE_CHECK(draws < max_draws, "GenerateNearDangerous: only "
                                        << kept << " of " << options.count
                                        << " states with h < 0 in " << max_draws
                                        << " draws from the band rho in [" << options.rho_min
                                        << ", " << options.rho_max << ")");
    ++draws;
    const double theta = rng.Uniform(0.0, kTwoPi);
    const double distance = t.radius + rng.Uniform(options.rho_min, options.rho_max);
    Eigen::Vector4f s;
    s[0] = static_cast<float>(t.obstacle_x + distance * std::cos(theta));
    s[1] = static_cast<float>(t.obstacle_y + distance * std::sin(theta));
    s[2] = static_cast<float>(rng.Uniform(options.velocity_lo, options.velocity_hi));
    s[3] = static_cast<float>(rng.Uniform(options.velocity_lo, options.velocity_hi));
    // Label the float state that is stored.
    if (t.H(s[0], s[1], s[2], s[3]) < 0.0) {
      for (int d = 0; d < kStateDim; ++d) set.states(d, kept) = s[d];
      ++kept;
    }
  }
  return set;
}

}  // namespace secure::domains::double_integrator
