#include "domains/derby/expert.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>

#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/common/random_order.h"
#include "secure/common/timer.h"
#include "secure/domains/demonstrations.h"

namespace secure::domains::derby {
namespace {

bool Finite(double x) { return std::isfinite(x); }

double SignedSqrt(double x) { return x >= 0 ? std::sqrt(x) : -std::sqrt(-x); }

// A half-plane g.a >= b (|g| = 1 for the car constraints and the box edges).
struct HalfPlane {
  Eigen::Vector2d g;
  double b;
};

constexpr int kMaxLines = kMaxCars + 4;
constexpr double kFeasibleTolerance = 1e-9;

}  // namespace

// ---------------------------------------------------------------------------------------------
// Options

void DerbyExpertOptions::Validate() const {
  SECURE_CHECK_FIELD(Finite(kp) && kp > 0, "DerbyExpertOptions", "kp", kp, "> 0");
  SECURE_CHECK_FIELD(Finite(kd) && kd > 0, "DerbyExpertOptions", "kd", kd, "> 0");
  SECURE_CHECK_FIELD(Finite(speed_limit) && speed_limit > 0, "DerbyExpertOptions", "speed_limit",
                     speed_limit, "> 0");
  SECURE_CHECK_FIELD(Finite(gain_spread) && gain_spread >= 0 && gain_spread < 1,
                     "DerbyExpertOptions", "gain_spread", gain_spread, "in [0, 1)");
  SECURE_CHECK_FIELD(Finite(speed_spread) && speed_spread >= 0 && speed_spread < 1,
                     "DerbyExpertOptions", "speed_spread", speed_spread, "in [0, 1)");
  SECURE_CHECK_FIELD(Finite(noise_sigma) && noise_sigma >= 0, "DerbyExpertOptions", "noise_sigma",
                     noise_sigma, ">= 0");
  SECURE_CHECK_FIELD(Finite(braking_accel) && braking_accel > 0, "DerbyExpertOptions",
                     "braking_accel", braking_accel, "> 0");
  SECURE_CHECK_FIELD(Finite(clearance) && clearance >= 0, "DerbyExpertOptions", "clearance",
                     clearance, ">= 0");
  SECURE_CHECK_FIELD(Finite(cbf_rate) && cbf_rate > 0, "DerbyExpertOptions", "cbf_rate", cbf_rate,
                     "> 0");
  SECURE_CHECK_FIELD(Finite(filter_margin) && filter_margin >= 0, "DerbyExpertOptions",
                     "filter_margin", filter_margin, ">= 0");
}

nlohmann::json DerbyExpertOptions::ToJson() const {
  return {{"kp", kp},
          {"kd", kd},
          {"speed_limit", speed_limit},
          {"gain_spread", gain_spread},
          {"speed_spread", speed_spread},
          {"noise_sigma", noise_sigma},
          {"use_filter", use_filter},
          {"braking_accel", braking_accel},
          {"clearance", clearance},
          {"cbf_rate", cbf_rate},
          {"filter_margin", filter_margin}};
}

void DerbyDemonstrationOptions::Validate() const {
  SECURE_CHECK_FIELD(episodes > 0, "DerbyDemonstrationOptions", "episodes", episodes, "> 0");
  SECURE_CHECK_FIELD(max_attempts >= 0, "DerbyDemonstrationOptions", "max_attempts", max_attempts,
                     ">= 0");
}

nlohmann::json DerbyDemonstrationOptions::ToJson() const {
  return {{"episodes", episodes},
          {"max_attempts", max_attempts},
          {"require_all", require_all},
          {"seed", seed}};
}

nlohmann::json DerbyDemonstrations::ToJson() const {
  const long kept = trajectories.num_episodes();
  std::vector<int> sorted = steps_to_goal;
  std::sort(sorted.begin(), sorted.end());
  const double median = sorted.empty() ? 0.0 : sorted[sorted.size() / 2];
  return {{"kept", kept},
          {"attempted", attempted},
          {"discarded_collisions", discarded_collisions},
          {"discarded_no_goal", discarded_no_goal},
          {"kept_fraction", attempted > 0 ? static_cast<double>(kept) / attempted : 0.0},
          {"steps_to_goal_median", median},
          {"steps", trajectories.num_steps()},
          {"min_car_distance", min_car_distance},
          {"expert_steps", expert.steps},
          {"expert_modified", expert.modified},
          {"expert_infeasible", expert.infeasible},
          {"seed", seed},
          {"seconds", seconds}};
}

void DerbyNearDangerousOptions::Validate() const {
  SECURE_CHECK_FIELD(count > 0, "DerbyNearDangerousOptions", "count", count, "> 0");
  SECURE_CHECK(!rho.empty() && rho.size() == probabilities.size(),
               "DerbyNearDangerousOptions::rho has " << rho.size() << " values and probabilities "
                                                     << probabilities.size()
                                                     << ", must be as many, at least one");
  double sum = 0.0;
  for (std::size_t i = 0; i < rho.size(); ++i) {
    SECURE_CHECK_FIELD(Finite(rho[i]) && rho[i] > 0, "DerbyNearDangerousOptions",
                       "rho[" << i << "]", rho[i], "> 0");
    SECURE_CHECK_FIELD(Finite(probabilities[i]) && probabilities[i] >= 0,
                       "DerbyNearDangerousOptions", "probabilities[" << i << "]", probabilities[i],
                       ">= 0");
    sum += probabilities[i];
  }
  SECURE_CHECK(std::abs(sum - 1.0) <= 1e-6, "DerbyNearDangerousOptions::probabilities sum to "
                                                << sum << ", must sum to 1");
  SECURE_CHECK_FIELD(nearest >= 1 && nearest <= kObservedCars, "DerbyNearDangerousOptions",
                     "nearest", nearest, "in [1, " << kObservedCars << "]");
  SECURE_CHECK_FIELD(max_redraws >= 1, "DerbyNearDangerousOptions", "max_redraws", max_redraws,
                     ">= 1");
}

nlohmann::json DerbyNearDangerousOptions::ToJson() const {
  return {{"count", count},
          {"rho", rho},
          {"probabilities", probabilities},
          {"nearest", nearest},
          {"max_redraws", max_redraws}};
}

// ---------------------------------------------------------------------------------------------
// DerbyExpert

DerbyExpert::DerbyExpert(const DerbyOptions& task, const DerbyExpertOptions& options)
    : task_((task.Validate(), task)),
      options_((options.Validate(), options)),
      kp_(options.kp),
      kd_(options.kd),
      speed_limit_(options.speed_limit) {
  const double k_dt = options.cbf_rate * task.dt;
  SECURE_CHECK(k_dt > 0 && k_dt <= 1, "DerbyExpertOptions::cbf_rate = "
                                          << options.cbf_rate << ": cbf_rate * dt = " << k_dt
                                          << ", must be in (0, 1]");
}

void DerbyExpert::BeginEpisode(Rng& rng) {
  const double gain = rng.Uniform(1.0 - options_.gain_spread, 1.0 + options_.gain_spread);
  kp_ = options_.kp * gain;
  kd_ = options_.kd * std::sqrt(gain);
  speed_limit_ = options_.speed_limit * rng.Uniform(1.0 - options_.speed_spread, 1.0);
}

Eigen::Vector2d DerbyExpert::Nominal(const Eigen::Vector2d& p, const Eigen::Vector2d& v,
                                     const Eigen::Vector2d& goal) const {
  Eigen::Vector2d v_des = (kp_ / kd_) * (goal - p);
  const double speed = v_des.norm();
  if (speed > speed_limit_) v_des *= speed_limit_ / speed;
  return kd_ * (v_des - v);
}

double DerbyExpert::PairBarrier(const Eigen::Vector2d& dp, const Eigen::Vector2d& dv) const {
  const double d = dp.norm();
  const double safe = task_.collision_radius + options_.clearance;
  const double approach = d > 1e-12 ? dp.dot(dv) / d : 0.0;
  return SignedSqrt(2.0 * options_.braking_accel * (d - safe)) + approach;
}

Eigen::Vector2d DerbyExpert::FilterAction(const DerbyEnv& env, const Eigen::Vector2d& nominal,
                                          DerbyFilterInfo* info) const {
  const int t = env.step_index();
  SECURE_CHECK(t + 1 < env.num_frames(), "DerbyExpert: no car frame after step " << t);
  const double dt = task_.dt;
  const double bound = task_.accel_bound;
  const double safe = task_.collision_radius + options_.clearance;
  const double decay = 1.0 - options_.cbf_rate * dt;
  const Eigen::Vector2d p = env.ego_position().cast<double>();
  const Eigen::Vector2d v = env.ego_velocity().cast<double>();
  const auto q0 = env.CarPositions(t);
  const auto w0 = env.CarVelocities(t);
  const auto q1 = env.CarPositions(t + 1);
  const auto w1 = env.CarVelocities(t + 1);
  const Eigen::Vector2d p_next = p + v * dt;  // independent of the action (explicit Euler)

  std::array<HalfPlane, kMaxLines> lines;
  int m = 0;  // car constraints in lines[0, m)
  double min_h = std::numeric_limits<double>::infinity();
  for (int j = 0; j < env.num_cars(); ++j) {
    const Eigen::Vector2d dp0 = p - q0.col(j).cast<double>();
    const Eigen::Vector2d dv0 = v - w0.col(j).cast<double>();
    const double h0 = PairBarrier(dp0, dv0);
    min_h = std::min(min_h, h0);
    const Eigen::Vector2d dp1 = p_next - q1.col(j).cast<double>();
    const double d1 = dp1.norm();
    Eigen::Vector2d n = d1 > 1e-12 ? Eigen::Vector2d(dp1 / d1) : Eigen::Vector2d(1.0, 0.0);
    // h(dp1, v + a dt - w1) = S + n.(v - w1) + dt n.a >= decay h0 + margin.
    const double rest = SignedSqrt(2.0 * options_.braking_accel * (d1 - safe)) +
                        n.dot(v - w1.col(j).cast<double>());
    const double b = (decay * h0 + options_.filter_margin - rest) / dt;
    if (-bound * n.cwiseAbs().sum() >= b) continue;  // the whole box satisfies it
    lines[m++] = {n, b};
  }
  const int num_constraints = m;
  int num_lines = m;
  lines[num_lines++] = {Eigen::Vector2d(1, 0), -bound};
  lines[num_lines++] = {Eigen::Vector2d(-1, 0), -bound};
  lines[num_lines++] = {Eigen::Vector2d(0, 1), -bound};
  lines[num_lines++] = {Eigen::Vector2d(0, -1), -bound};

  auto feasible = [&](const Eigen::Vector2d& a) {
    for (int i = 0; i < num_lines; ++i)
      if (lines[i].g.dot(a) < lines[i].b - kFeasibleTolerance) return false;
    return true;
  };
  const Eigen::Vector2d clipped = nominal.cwiseMax(-bound).cwiseMin(bound);
  Eigen::Vector2d best = clipped;
  bool found = feasible(clipped);
  if (!found) {
    double best_d2 = std::numeric_limits<double>::infinity();
    auto consider = [&](const Eigen::Vector2d& a) {
      const double d2 = (a - nominal).squaredNorm();
      if (d2 < best_d2 && feasible(a)) {
        best_d2 = d2;
        best = a;
        found = true;
      }
    };
    for (int i = 0; i < num_lines; ++i) {
      const HalfPlane& l = lines[i];
      consider(nominal + (l.b - l.g.dot(nominal)) / l.g.squaredNorm() * l.g);
    }
    for (int i = 0; i < num_lines; ++i) {
      for (int k = i + 1; k < num_lines; ++k) {
        const Eigen::Vector2d& g1 = lines[i].g;
        const Eigen::Vector2d& g2 = lines[k].g;
        const double det = g1.x() * g2.y() - g1.y() * g2.x();
        if (std::abs(det) < 1e-12) continue;
        const Eigen::Vector2d a((lines[i].b * g2.y() - lines[k].b * g1.y()) / det,
                                (g1.x() * lines[k].b - g2.x() * lines[i].b) / det);
        consider(a);
      }
    }
  }
  bool feasible_box = found;
  if (!found) {
    // Maximise the worst constraint value over the box: grid, then two local refinements.
    auto worst = [&](const Eigen::Vector2d& a) {
      double w = std::numeric_limits<double>::infinity();
      for (int i = 0; i < num_constraints; ++i) w = std::min(w, lines[i].g.dot(a) - lines[i].b);
      return w;
    };
    constexpr int kGrid = 41;
    double best_w = -std::numeric_limits<double>::infinity();
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    double half = bound;
    for (int level = 0; level < 3; ++level) {
      const Eigen::Vector2d c = centre;
      for (int ix = 0; ix < kGrid; ++ix) {
        for (int iy = 0; iy < kGrid; ++iy) {
          const Eigen::Vector2d a =
              (c + half * Eigen::Vector2d(2.0 * ix / (kGrid - 1) - 1.0, 2.0 * iy / (kGrid - 1) - 1.0))
                  .cwiseMax(-bound)
                  .cwiseMin(bound);
          const double w = worst(a);
          if (w > best_w) {
            best_w = w;
            centre = a;
          }
        }
      }
      half *= 2.0 / (kGrid - 1);
    }
    best = centre;
  }
  best = best.cwiseMax(-bound).cwiseMin(bound);
  if (info != nullptr) {
    info->constraints = num_constraints;
    info->modified = best != clipped;
    info->feasible = feasible_box;
    info->min_h = min_h;
  }
  return best;
}

void DerbyExpert::Act(const DerbyEnv& env, Rng& rng, Eigen::Ref<Eigen::VectorXf> action) {
  SECURE_CHECK(action.size() == kActionDim,
               "DerbyExpert::Act: action has " << action.size() << " entries, expected 2");
  const DerbyOptions& o = env.options();
  SECURE_CHECK(o.num_cars == task_.num_cars && o.dt == task_.dt &&
                   o.accel_bound == task_.accel_bound &&
                   o.collision_radius == task_.collision_radius,
               "DerbyExpert::Act: the env's options differ from the expert's task ("
                   << o.ToJson().dump() << " vs " << task_.ToJson().dump() << ")");
  const Eigen::Vector2d p = env.ego_position().cast<double>();
  const Eigen::Vector2d v = env.ego_velocity().cast<double>();
  const Eigen::Vector2d a = NoisyFilteredAction<DerbyFilterInfo>(
      Nominal(p, v, env.goal().cast<double>()), options_.noise_sigma, options_.use_filter,
      task_.accel_bound, rng, stats_,
      [&](const Eigen::Vector2d& noisy, DerbyFilterInfo* info) {
        return FilterAction(env, noisy, info);
      });
  action = a.cast<float>();
}

// ---------------------------------------------------------------------------------------------
// Demonstrations

Rng DerbyAttemptRng(std::uint64_t seed, long attempt) {
  return AttemptRng(seed, attempt, 0x5eedde4b7ULL);
}

DerbyDemonstrations GenerateDerbyDemonstrations(const DerbyOptions& task,
                                                const DerbyExpertOptions& expert_options,
                                                const DerbyDemonstrationOptions& demo) {
  demo.Validate();
  const Stopwatch clock;
  DerbyEnv env(task);
  DerbyExpert expert(task, expert_options);
  const long max_attempts = demo.max_attempts > 0 ? demo.max_attempts : 2 * demo.episodes + 10;
  const int horizon = env.max_steps();

  DerbyDemonstrations out;
  out.seed = demo.seed;
  DemonstrationCollector collector(
      "derby expert demonstrations (seed " + std::to_string(demo.seed) + ")", ObservationFeatures(),
      ActionFeatures(), demo.episodes * horizon);
  Eigen::VectorXf observation(kObservationDim);
  Eigen::Vector2f action, applied;
  const float bound = static_cast<float>(task.accel_bound);
  double min_distance = std::numeric_limits<double>::infinity();
  double episode_min = 0.0;
  const AttemptPlan plan{"GenerateDerbyDemonstrations", "DerbyDemonstrationOptions::episodes",
                         demo.episodes, max_attempts, demo.require_all};
  const long kept = KeepReachingEpisodes(
      plan, collector, out,
      [&](long attempt) {
        Rng rng = DerbyAttemptRng(demo.seed, attempt);
        env.Reset(rng, observation);
        expert.BeginEpisode(rng);
        episode_min = env.NearestCarDistance();
        return RecordEpisode(
            env, collector, horizon, /*stop_at_goal=*/false, observation, action, applied,
            [&](const Eigen::VectorXf&, Eigen::Vector2f& a, Eigen::Vector2f& recorded) {
              expert.Act(env, rng, a);
              // The applied action (the expert's is in the box).
              for (int i = 0; i < kActionDim; ++i) recorded[i] = std::clamp(a[i], -bound, bound);
            },
            [&](const StepOutcome&) {
              episode_min = std::min<double>(episode_min, env.NearestCarDistance());
            });
      },
      [&](long attempt) {
        min_distance = std::min(min_distance, episode_min);
        out.attempts.push_back(attempt);
      });
  out.expert = expert.stats();
  out.min_car_distance = kept > 0 ? min_distance : 0.0;
  out.trajectories = collector.Finish();
  out.seconds = clock.Seconds();
  return out;
}

// ---------------------------------------------------------------------------------------------
// Safety demonstrations

data::StateSet SafeStatesFromDemonstrations(const data::TrajectorySet& trajectories, long count,
                                            Rng& rng) {
  SECURE_CHECK(count > 0, "SafeStatesFromDemonstrations: count = " << count << ", must be > 0");
  const long n = trajectories.num_steps();
  SECURE_CHECK(n > 0, "SafeStatesFromDemonstrations: the demonstrations (" << trajectories.source
                                                                           << ") hold no states");
  data::StateSet set;
  set.source = trajectories.source + " [safe states]";
  set.features = trajectories.state_features;
  std::vector<long> picked;
  picked.reserve(static_cast<std::size_t>(count));
  for (long r = 0; r < count / n; ++r)
    for (long i = 0; i < n; ++i) picked.push_back(i);
  const long rest = count - static_cast<long>(picked.size());
  if (rest > 0) {
    const std::vector<long> subset = SortedRandomSubset(n, rest, rng);
    picked.insert(picked.end(), subset.begin(), subset.end());
  }
  set.states = data::SelectColumns(trajectories.states, picked);
  return set;
}

data::StateSet GenerateDerbyNearDangerous(const DerbyOptions& task,
                                          const DerbyDemonstrations& demonstrations,
                                          const DerbyNearDangerousOptions& options, Rng& rng) {
  options.Validate();
  const data::TrajectorySet& t = demonstrations.trajectories;
  const long episodes = t.num_episodes();
  SECURE_CHECK(episodes > 0 && t.num_steps() > 0 &&
                   static_cast<long>(demonstrations.attempts.size()) == episodes,
               "GenerateDerbyNearDangerous: the demonstrations hold "
                   << episodes << " episodes, " << t.num_steps() << " steps and "
                   << demonstrations.attempts.size()
                   << " attempt indices; need at least one episode and one index per episode");
  SECURE_CHECK(t.states.rows() == kObservationDim,
               "GenerateDerbyNearDangerous: demonstration states have "
                   << t.states.rows() << " rows, expected " << kObservationDim);
  DerbyEnv env(task);
  Eigen::VectorXf scratch(kObservationDim), placed(kObservationDim);
  std::vector<double> cumulative(options.probabilities.size());
  std::partial_sum(options.probabilities.begin(), options.probabilities.end(),
                   cumulative.begin());

  data::StateSet out;
  out.source = "derby near-dangerous states (" + t.source + ")";
  out.features = ObservationFeatures();
  out.states.resize(kObservationDim, options.count);
  long made = 0;
  long loaded_episode = -1;
  const long max_frames = 100 * options.count;
  const float inv_sqrt2 = static_cast<float>(1.0 / std::sqrt(2.0));
  for (long tries = 0; made < options.count; ++tries) {
    SECURE_CHECK(tries < max_frames, "GenerateDerbyNearDangerous: made only "
                                         << made << " of " << options.count << " states after "
                                         << max_frames << " frames");
    const long column = static_cast<long>(rng.UniformIndex(static_cast<std::uint64_t>(t.num_steps())));
    const long episode = static_cast<long>(
        std::upper_bound(t.episode_begin.begin(), t.episode_begin.end(), column) -
        t.episode_begin.begin() - 1);
    const int frame = static_cast<int>(column - t.episode_begin[static_cast<std::size_t>(episode)]);
    if (episode != loaded_episode) {
      Rng world = DerbyAttemptRng(demonstrations.seed,
                                  demonstrations.attempts[static_cast<std::size_t>(episode)]);
      env.Reset(world, scratch);
      loaded_episode = episode;
    }
    SECURE_CHECK(frame < env.num_frames(), "GenerateDerbyNearDangerous: frame "
                                               << frame << " of episode " << episode
                                               << " is past the task's " << env.num_frames()
                                               << " frames (other task options?)");
    const Eigen::Vector2f goal = env.goal();
    const Eigen::Vector2f p = goal - t.states.col(column).head<2>();
    const Eigen::Vector2f v = t.states.col(column).segment<2>(2);
    const auto cars_p = env.CarPositions(frame);
    const auto cars_v = env.CarVelocities(frame);
    std::array<int, kObservedCars> nearest;
    BuildObservation(p, v, goal, cars_p, cars_v, scratch, &nearest);
    for (int k = 0; k < options.nearest && made < options.count; ++k) {
      const int j = nearest[static_cast<std::size_t>(k)];
      const double r = rng.Uniform();
      std::size_t which = 0;
      while (which + 1 < cumulative.size() && r >= cumulative[which]) ++which;
      const float rho = static_cast<float>(options.rho[which]);
      for (int draw = 0; draw < options.max_redraws; ++draw) {
        const float u1 = static_cast<float>(rng.Uniform(-1.0, 1.0));
        const float u2 = static_cast<float>(rng.Uniform(-1.0, 1.0));
        const Eigen::Vector2f ego = cars_p.col(j) + Eigen::Vector2f(u1, u2) * (rho * inv_sqrt2);
        std::array<int, kObservedCars> order;
        BuildObservation(ego, v, goal, cars_p, cars_v, placed, &order);
        if (order[0] == j) {
          out.states.col(made++) = placed;
          break;
        }
      }
    }
  }
  return out;
}

}  // namespace secure::domains::derby
