// Tests of the reach-avoid expert (its exact CBF filter), the demonstration generator and the
// safety-demonstration generators.

#include "domains/double_integrator/expert.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/data/data.h"
#include "domains/double_integrator/reach_avoid.h"

namespace secure::domains::double_integrator {
namespace {

using secure::test::ErrorOf;

// One expert episode over the full horizon, with what the tests check.
struct EpisodeRecord {
  int steps_to_goal = 0;  // first step in the goal, 0 = never
  bool collided = false;
  double min_h = std::numeric_limits<double>::infinity();  // ground-truth h over all states
  double max_speed_component = 0.0;
  std::vector<Eigen::Vector4f> states;
};

EpisodeRecord RunExpert(const ReachAvoidOptions& task, const ExpertOptions& options,
                        std::uint64_t seed, bool keep_states = false) {
  ReachAvoidEnv env(task);
  Expert expert(task, options);
  Rng rng(seed);
  Eigen::Vector4f o;
  Eigen::Vector2f a;
  env.Reset(rng, o);
  expert.BeginEpisode(rng);
  EpisodeRecord r;
  r.min_h = task.truth.H(o[0], o[1], o[2], o[3]);
  for (int step = 1; step <= env.max_steps(); ++step) {
    expert.Act(o, rng, a);
    const StepOutcome out = env.Step(a, o);
    if (keep_states) r.states.push_back(o);
    r.collided = r.collided || out.collided;
    if (out.reached_goal && r.steps_to_goal == 0) r.steps_to_goal = step;
    r.min_h = std::min(r.min_h, task.truth.H(o[0], o[1], o[2], o[3]));
    r.max_speed_component =
        std::max({r.max_speed_component, std::abs<double>(o[2]), std::abs<double>(o[3])});
  }
  return r;
}

double NearestRank(std::vector<int> values, double percent) {
  std::sort(values.begin(), values.end());
  const auto rank = static_cast<std::size_t>(std::ceil(percent / 100.0 * values.size() - 1e-9));
  return values[std::max<std::size_t>(rank, 1) - 1];
}

// ---------------------------------------------------------------------------------------------
// Options

TEST(ExpertOptionsTest, ValidateNamesFieldValueAndRule) {
  auto error_of = [](auto&& breaker) {
    ExpertOptions o;
    breaker(o);
    return ErrorOf([&] { Expert(ReachAvoidOptions(), o); });
  };
  EXPECT_HAS(error_of([](ExpertOptions& o) { o.kp = 0; }), "ExpertOptions::kp = 0, must be > 0");
  EXPECT_HAS(error_of([](ExpertOptions& o) { o.gain_spread = 1; }),
             "ExpertOptions::gain_spread = 1, must be in [0, 1)");
  EXPECT_HAS(error_of([](ExpertOptions& o) { o.noise_sigma = -0.1; }),
             "ExpertOptions::noise_sigma = -0.1");
  EXPECT_HAS(error_of([](ExpertOptions& o) { o.cbf_rate = 20; }),
             "ExpertOptions::cbf_rate = 20, must satisfy cbf_rate * dt <= 1");
  EXPECT_HAS(ErrorOf([] {
               ReachAvoidOptions task;
               task.dt = 0;
               Expert(task, ExpertOptions());
             }),
             "ReachAvoidOptions::dt = 0");
  EXPECT_TRUE(ExpertOptions().ToJson().contains("use_filter"));
  DemonstrationOptions demo;
  demo.episodes = 0;
  EXPECT_HAS(ErrorOf([&] { GenerateDemonstrations({}, {}, demo); }),
             "DemonstrationOptions::episodes = 0, must be > 0");
}

// ---------------------------------------------------------------------------------------------
// The filter

TEST(ExpertFilterTest, ReturnsTheNominalActionWhenItIsSafe) {
  const Expert expert(ReachAvoidOptions{});
  // Far from the obstacle, moving away from it: every action in the box is fine.
  const Eigen::Vector4d s(1.0, 1.0, -0.5, -0.2);
  const Eigen::Vector2d nominal(1.25, -2.5);
  FilterInfo info;
  EXPECT_EQ(expert.FilterAction(s, nominal, &info), nominal);
  EXPECT_FALSE(info.modified);
  EXPECT_TRUE(info.feasible);
  EXPECT_GE(info.next_h, info.required);
  // Outside the box: the clipped action.
  EXPECT_EQ(expert.FilterAction(s, Eigen::Vector2d(7.0, -0.5)), Eigen::Vector2d(3.0, -0.5));
}

// The filter's algebra is checked against the task's own obstacle: clearance 0.
ExpertOptions NoClearance() {
  ExpertOptions o;
  o.clearance = 0.0;
  return o;
}

TEST(ExpertFilterTest, BrakesHeadOnApproach) {
  const Expert expert(ReachAvoidOptions{}, NoClearance());
  // On the boundary of the safe set (h = 0): 0.5 left of the obstacle edge, approaching at 0.625:
  // h = (2.5^2 - 4) + 2 * (-2.5 * 0.625) = 2.25 - 3.125 < 0 is unsafe; use v = 0.45 instead:
  // h = 2.25 - 2.25 = 0.
  const Eigen::Vector4d s(2.5, 5.0, 0.45, 0.0);
  ASSERT_NEAR(ReachAvoidOptions().truth.H(s[0], s[1], s[2], s[3]), 0.0, 1e-12);
  FilterInfo info;
  const Eigen::Vector2d a = expert.FilterAction(s, Eigen::Vector2d(3.0, 0.0), &info);
  EXPECT_TRUE(info.modified);
  EXPECT_TRUE(info.feasible);
  EXPECT_LT(a[0], 0.0);          // must decelerate
  EXPECT_NEAR(a[1], 0.0, 1e-9);  // no reason to steer sideways
  EXPECT_GE(expert.NextH(s, a), 0.0);
  // Minimal: the condition is active (h(s') = required + margin).
  EXPECT_NEAR(info.next_h, info.required + expert.options().filter_margin, 1e-9);
}

// Property: over many random safe states and nominal actions, the filtered action is in the box,
// satisfies the exact discrete CBF condition (also after rounding to float, as Act() returns it),
// and no feasible action on a fine grid is closer to the nominal action (the QP is solved
// exactly, not approximately).
TEST(ExpertFilterTest, FilteredActionIsFeasibleAndOptimal) {
  const ReachAvoidOptions task;
  const Expert expert(task, NoClearance());
  const double a_max = task.accel_bound;
  Rng rng(5);
  constexpr int kGrid = 121;  // grid step 0.05
  int modified = 0, infeasible = 0;
  for (int trial = 0; trial < 400; ++trial) {
    // Safe states near the obstacle (where the filter matters): distance in [2, 4], speeds in
    // the task's range.
    Eigen::Vector4d s;
    do {
      const double theta = rng.Uniform(0, 6.283185307179586);
      const double distance = rng.Uniform(2.0, 4.0);
      s << 5 + distance * std::cos(theta), 5 + distance * std::sin(theta), rng.Uniform(-1.5, 1.5),
          rng.Uniform(-1.5, 1.5);
    } while (task.truth.H(s[0], s[1], s[2], s[3]) < 0);
    const Eigen::Vector2d nominal(rng.Uniform(-5, 5), rng.Uniform(-5, 5));
    FilterInfo info;
    const Eigen::Vector2d a = expert.FilterAction(s, nominal, &info);
    ASSERT_LE(a.cwiseAbs().maxCoeff(), a_max);
    if (!info.feasible) {
      ++infeasible;
      continue;
    }
    modified += info.modified;
    const double required = (1.0 - 1.0 * task.dt) * task.truth.H(s[0], s[1], s[2], s[3]);
    ASSERT_GE(expert.NextH(s, a), required) << "trial " << trial;
    ASSERT_GE(expert.NextH(s, a.cast<float>().cast<double>()), required) << "trial " << trial;
    ASSERT_GE(expert.NextH(s, a), 0.0);
    const double best = (a - nominal).norm();
    for (int i = 0; i < kGrid; ++i) {
      for (int j = 0; j < kGrid; ++j) {
        const Eigen::Vector2d g(-a_max + 2 * a_max * i / (kGrid - 1),
                                -a_max + 2 * a_max * j / (kGrid - 1));
        if (expert.NextH(s, g) >= required + expert.options().filter_margin) {
          ASSERT_GE((g - nominal).norm(), best - 1e-9)
              << "trial " << trial << ": grid action (" << g.transpose()
              << ") is feasible and closer than (" << a.transpose() << ")";
        }
      }
    }
  }
  EXPECT_EQ(infeasible, 0);  // from safe states in the task's speed range: always feasible
  EXPECT_GT(modified, 50);   // the property was exercised on active constraints
}

TEST(ExpertFilterTest, InfeasibleStateGetsTheHMaximisingCorner) {
  // The head-on state on the safe set's boundary (h = 0) needs a_x <= -0.35 (see above); with a
  // bound of 0.1 no action meets the condition.
  ReachAvoidOptions weak;
  weak.accel_bound = 0.1;
  const Expert expert(weak);
  const Eigen::Vector4d s(2.5, 5.0, 0.45, 0.2);
  FilterInfo info;
  const Eigen::Vector2d a = expert.FilterAction(s, Eigen::Vector2d(0.05, 0.0), &info);
  EXPECT_FALSE(info.feasible);
  EXPECT_TRUE(info.modified);
  EXPECT_LT(info.next_h, info.required);
  EXPECT_EQ(a, Eigen::Vector2d(-0.1, 0.1));  // brake, and turn the way it already moves
  for (const double x : {-0.1, 0.1})
    for (const double y : {-0.1, 0.1}) EXPECT_GE(info.next_h, expert.NextH(s, {x, y}));
}

TEST(ExpertTest, NominalIsACriticallyDampedSpeedLimitedPd) {
  const ReachAvoidOptions task;
  const Expert expert(task);
  // Near the goal (below the speed limit, obstacle behind): a = kp (g - p) - kd v, kp = 1, kd = 2.
  const Eigen::Vector2d near = expert.Nominal(Eigen::Vector4d(8.0, 8.3, 0.1, -0.2));
  EXPECT_NEAR(near[0], 1.0 * 0.5 - 2.0 * 0.1, 1e-12);
  EXPECT_NEAR(near[1], 1.0 * 0.2 + 2.0 * 0.2, 1e-12);
  // At the goal at rest: nothing to do.
  EXPECT_EQ(expert.Nominal(Eigen::Vector4d(8.5, 8.5, 0, 0)), Eigen::Vector2d::Zero());
  // Far away: the desired velocity is capped at the speed limit, toward the goal.
  ExpertOptions no_detour;
  no_detour.detour_gain = 0;
  const Eigen::Vector2d far = Expert(task, no_detour).Nominal(Eigen::Vector4d(0.5, 8.5, 0.0, 0.5));
  EXPECT_NEAR(far[0], 2.0 * 1.4, 1e-12);
  EXPECT_NEAR(far[1], 2.0 * -0.5, 1e-12);
}

TEST(ExpertTest, NominalDetoursAroundTheObstacleOnTheSideItLeansTo) {
  const ReachAvoidOptions task;
  ExpertOptions no_detour = NoClearance();
  no_detour.detour_gain = 0;
  const Expert expert(task, NoClearance()), plain(task, no_detour);
  // Just in front of the obstacle, a little below the diagonal: the detour pushes toward
  // (+x, -y), the way around below the obstacle, by kd x 0.8 x 1.4 x head_on x exp(-0.05 / 0.5).
  const Eigen::Vector4d below(3.6, 3.5, 0, 0);
  const Eigen::Vector2d extra = expert.Nominal(below) - plain.Nominal(below);
  const Eigen::Vector2d d(-1.4, -1.5), g(4.9, 5.0);
  const double head_on = -d.normalized().dot(g.normalized());
  const double distance = d.norm();
  EXPECT_NEAR(extra.norm(), 2.0 * 0.8 * 1.4 * head_on * std::exp(-(distance - 2.0) / 0.5), 1e-9);
  EXPECT_NEAR(extra.dot(d), 0.0, 1e-9);  // tangential
  EXPECT_GT(extra[0], 0.0);
  EXPECT_LT(extra[1], 0.0);
  // Mirrored state: mirrored detour.
  const Eigen::Vector2d mirrored = expert.Nominal(Eigen::Vector4d(3.5, 3.6, 0, 0)) -
                                   plain.Nominal(Eigen::Vector4d(3.5, 3.6, 0, 0));
  EXPECT_NEAR(mirrored[0], extra[1], 1e-12);
  EXPECT_NEAR(mirrored[1], extra[0], 1e-12);
  // Behind the obstacle (goal not behind it) and far from it: no detour.
  const Eigen::Vector4d past(7.5, 7.0, 0.3, 0.3), away(0.5, 0.5, 0, 0);
  EXPECT_EQ(expert.Nominal(past), plain.Nominal(past));
  EXPECT_NEAR((expert.Nominal(away) - plain.Nominal(away)).norm(), 0.0, 0.01);
}

TEST(ExpertTest, ActRejectsWrongDimensions) {
  Expert expert(ReachAvoidOptions{});
  Rng rng(1);
  Eigen::Vector2f a;
  EXPECT_HAS(ErrorOf([&] { expert.Act(Eigen::Vector3f::Zero(), rng, a); }),
             "state/action have 3/2 entries, expected 4/2");
}

// ---------------------------------------------------------------------------------------------
// Closed loop

TEST(ExpertClosedLoopTest, NeverCollidesStaysSafeAndReachesTheGoal) {
  const ReachAvoidOptions task;
  const ExpertOptions options;
  constexpr int kEpisodes = 300;
  int reached = 0;
  double worst_h = std::numeric_limits<double>::infinity();
  double max_speed = 0.0;
  for (int e = 0; e < kEpisodes; ++e) {
    const EpisodeRecord r = RunExpert(task, options, 1000 + e);
    ASSERT_FALSE(r.collided) << "episode " << e;
    worst_h = std::min(worst_h, r.min_h);
    max_speed = std::max(max_speed, r.max_speed_component);
    reached += r.steps_to_goal > 0;
  }
  EXPECT_GE(worst_h, -1e-6);
  EXPECT_GE(reached, kEpisodes * 99 / 100);
  // Demonstrations stay inside the velocity range the barriers are trained on.
  EXPECT_LT(max_speed, 1.5);
}

TEST(ExpertClosedLoopTest, StaysAtTheGoalAfterReachingIt) {
  const ReachAvoidOptions task;
  const EpisodeRecord r = RunExpert(task, ExpertOptions(), 42, /*keep_states=*/true);
  ASSERT_GT(r.steps_to_goal, 0);
  // From 30 steps (3 s) later on it stays in the goal region, jittering with the noise.
  double worst = 0.0;
  for (std::size_t t = static_cast<std::size_t>(r.steps_to_goal) + 30; t < r.states.size(); ++t)
    worst = std::max(worst, std::hypot(r.states[t][0] - 8.5, r.states[t][1] - 8.5));
  EXPECT_LT(worst, 0.3);
  EXPECT_LT(r.steps_to_goal + 30, static_cast<int>(r.states.size()));
}

TEST(ExpertClosedLoopTest, UnfilteredExpertCollides) {
  ReachAvoidOptions task;
  ExpertOptions options;
  options.use_filter = false;
  int collided = 0;
  for (int e = 0; e < 100; ++e) collided += RunExpert(task, options, 1000 + e).collided;
  EXPECT_GE(collided, 90);  // the task does test safety
}

// The measurements behind the documented constants (reach_avoid.h: max_steps; expert.h), printed
// for the record, and the rule max_steps >= 1.5 x p99 checked.
TEST(ExpertClosedLoopTest, MeasuredStepsToGoalJustifyMaxSteps) {
  const ReachAvoidOptions task;
  ExpertOptions options;
  constexpr int kEpisodes = 1000;
  std::vector<int> steps;
  int unfiltered_collisions = 0;
  ExpertOptions unfiltered = options;
  unfiltered.use_filter = false;
  for (int e = 0; e < kEpisodes; ++e) {
    const EpisodeRecord r = RunExpert(task, options, static_cast<std::uint64_t>(e));
    if (r.steps_to_goal > 0) steps.push_back(r.steps_to_goal);
    unfiltered_collisions += RunExpert(task, unfiltered, static_cast<std::uint64_t>(e)).collided;
  }
  ASSERT_GE(steps.size(), kEpisodes * 99u / 100);
  const double median = NearestRank(steps, 50), p99 = NearestRank(steps, 99);
  const int max = *std::max_element(steps.begin(), steps.end());
  std::printf(
      "[ measured ] expert steps to goal over %d episodes: reached %zu, median %.0f, p99 %.0f, "
      "max %d; unfiltered expert collided in %d (%.1f %%)\n",
      kEpisodes, steps.size(), median, p99, max, unfiltered_collisions,
      100.0 * unfiltered_collisions / kEpisodes);
  EXPECT_GE(task.max_steps, 1.5 * p99);
}

// ---------------------------------------------------------------------------------------------
// Demonstrations

void ExpectConsistent(const Demonstrations& d, const DemonstrationOptions& demo, int horizon) {
  const data::TrajectorySet& t = d.trajectories;
  EXPECT_EQ(t.state_features, StateFeatures());
  EXPECT_EQ(t.action_features, ActionFeatures());
  EXPECT_EQ(t.states.rows(), 4);
  EXPECT_EQ(t.actions.rows(), 2);
  EXPECT_EQ(t.states.cols(), t.actions.cols());
  ASSERT_EQ(t.episode_begin.front(), 0);
  EXPECT_EQ(t.episode_begin.back(), t.num_steps());
  EXPECT_EQ(d.attempted, t.num_episodes() + d.discarded_collisions + d.discarded_no_goal);
  EXPECT_EQ(static_cast<long>(d.steps_to_goal.size()), t.num_episodes());
  for (long k = 0; k < t.num_episodes(); ++k) {
    const long length = t.episode_begin[k + 1] - t.episode_begin[k];
    const int reached = d.steps_to_goal[static_cast<std::size_t>(k)];
    EXPECT_GE(reached, 1);
    EXPECT_LE(reached, horizon);
    EXPECT_EQ(length, demo.stop_at_goal ? reached : horizon) << "episode " << k;
  }
  if (t.num_steps() > 0) {
    EXPECT_LE(t.actions.cwiseAbs().maxCoeff(), 3.0f);
  }
}

TEST(DemonstrationsTest, GeneratesSafeFullHorizonDemonstrationsDeterministically) {
  const ReachAvoidOptions task;
  DemonstrationOptions demo;
  demo.episodes = 20;
  demo.seed = 9;
  const Demonstrations d = GenerateDemonstrations(task, ExpertOptions(), demo);
  ASSERT_EQ(d.trajectories.num_episodes(), 20);
  ExpectConsistent(d, demo, task.max_steps);
  EXPECT_EQ(d.discarded_collisions, 0);
  EXPECT_EQ(d.expert.infeasible, 0);
  EXPECT_GT(d.expert.modified, 0);  // the filter was needed
  EXPECT_GT(d.seconds, 0.0);
  // Every recorded state is safe; each episode starts in the start region and ends at the goal.
  const data::TrajectorySet& t = d.trajectories;
  for (long i = 0; i < t.num_steps(); ++i)
    ASSERT_GE(task.truth.H(t.states(0, i), t.states(1, i), t.states(2, i), t.states(3, i)), 0.0);
  for (long k = 0; k < t.num_episodes(); ++k) {
    const auto first = t.states.col(t.episode_begin[k]);
    const auto last = t.states.col(t.episode_begin[k + 1] - 1);
    EXPECT_GE(first[0], 0.5f);
    EXPECT_LT(first[1], 3.0f);
    EXPECT_LT(std::hypot(last[0] - 8.5f, last[1] - 8.5f), 0.3f) << "episode " << k;
  }
  // Each recorded action, applied to its state, gives the next recorded state.
  ReachAvoidEnv env(task);
  Eigen::Vector4f next;
  for (long i = 0; i + 1 < t.episode_begin[1]; ++i) {
    env.ShieldModel().Step(t.states.col(i), t.actions.col(i), next);
    ASSERT_EQ(next, Eigen::Vector4f(t.states.col(i + 1))) << "step " << i;
  }

  const Demonstrations again = GenerateDemonstrations(task, ExpertOptions(), demo);
  EXPECT_EQ(again.trajectories.states, t.states);
  EXPECT_EQ(again.trajectories.actions, t.actions);
  demo.seed = 10;
  EXPECT_NE(GenerateDemonstrations(task, ExpertOptions(), demo).trajectories.states, t.states);
}

TEST(DemonstrationsTest, DemonstrationsDiffer) {
  DemonstrationOptions demo;
  demo.episodes = 40;
  const Demonstrations d = GenerateDemonstrations({}, {}, demo);
  const data::TrajectorySet& t = d.trajectories;
  // Distinct starts, distinct times to goal, and both sides of the obstacle.
  std::set<float> starts;
  std::set<int> times(d.steps_to_goal.begin(), d.steps_to_goal.end());
  int left = 0, right = 0;  // passing above-left (y > x) or below-right of the diagonal
  for (long k = 0; k < t.num_episodes(); ++k) {
    starts.insert(t.states(0, t.episode_begin[k]));
    double side = 0.0;
    for (long i = t.episode_begin[k]; i < t.episode_begin[k + 1]; ++i) {
      const double along = (t.states(0, i) + t.states(1, i)) / 2.0;
      if (std::abs(along - 5.0) < 0.5) side += t.states(1, i) - t.states(0, i);
    }
    (side > 0 ? left : right)++;
  }
  EXPECT_EQ(starts.size(), 40u);
  EXPECT_GE(times.size(), 10u);
  EXPECT_GE(left, 5);
  EXPECT_GE(right, 5);
}

TEST(DemonstrationsTest, StopAtGoalEndsEpisodesAtTheGoal) {
  DemonstrationOptions demo;
  demo.episodes = 10;
  demo.stop_at_goal = true;
  const Demonstrations d = GenerateDemonstrations({}, {}, demo);
  ExpectConsistent(d, demo, ReachAvoidOptions().max_steps);
  EXPECT_LT(d.trajectories.num_steps(), 10 * 300);
}

TEST(DemonstrationsTest, DiscardsCollidingEpisodesAndReportsTheCounts) {
  ExpertOptions unfiltered;
  unfiltered.use_filter = false;
  DemonstrationOptions demo;
  demo.episodes = 5;
  demo.max_attempts = 30;
  demo.require_all = false;
  const Demonstrations d = GenerateDemonstrations({}, unfiltered, demo);
  ExpectConsistent(d, demo, ReachAvoidOptions().max_steps);
  EXPECT_GT(d.discarded_collisions, 0);
  EXPECT_EQ(d.attempted, d.trajectories.num_episodes() < 5 ? 30 : d.attempted);
  EXPECT_EQ(d.ToJson()["discarded_collisions"], d.discarded_collisions);
  // Kept demonstrations never enter the obstacle.
  const data::TrajectorySet& t = d.trajectories;
  for (long i = 0; i < t.num_steps(); ++i)
    ASSERT_GE(std::hypot(t.states(0, i) - 5.0f, t.states(1, i) - 5.0f), 2.0f);

  demo.require_all = true;
  demo.episodes = 30;
  const std::string message = ErrorOf([&] { GenerateDemonstrations({}, unfiltered, demo); });
  EXPECT_HAS(message, "of DemonstrationOptions::episodes = 30 demonstrations after 30 attempts");
  EXPECT_HAS(message, "collided");
}

TEST(DemonstrationsTest, DiscardsEpisodesThatNeverReachTheGoal) {
  ReachAvoidOptions task;
  task.max_steps = 40;  // far too short to get there
  DemonstrationOptions demo;
  demo.episodes = 3;
  demo.max_attempts = 5;
  demo.require_all = false;
  const Demonstrations d = GenerateDemonstrations(task, {}, demo);
  EXPECT_EQ(d.trajectories.num_episodes(), 0);
  EXPECT_EQ(d.trajectories.num_steps(), 0);
  EXPECT_EQ(d.attempted, 5);
  EXPECT_EQ(d.discarded_no_goal, 5);
  EXPECT_EQ(d.discarded_collisions, 0);
}

class DemonstrationFileTest : public secure::test::TempDirTest {};

TEST_F(DemonstrationFileTest, TrajectoriesAndStateSetsRoundTripThroughCsv) {
  DemonstrationOptions demo;
  demo.episodes = 5;
  const Demonstrations d = GenerateDemonstrations({}, {}, demo);
  const std::string path = PathOf("demos.csv");
  data::WriteTrajectories(path, d.trajectories);
  const data::TrajectorySet back = data::ReadTrajectories(path, StateFeatures(), ActionFeatures());
  EXPECT_EQ(back.states, d.trajectories.states);
  EXPECT_EQ(back.actions, d.trajectories.actions);
  EXPECT_EQ(back.episode_begin, d.trajectories.episode_begin);

  Rng rng(1);
  const data::StateSet nd = GenerateNearDangerous({}, {}, rng);
  data::WriteStateSet(PathOf("nd.csv"), nd);
  EXPECT_EQ(data::ReadStateSet(PathOf("nd.csv"), StateFeatures()).states, nd.states);
}

TEST_F(DemonstrationFileTest, TrajectoriesAndStateSetsRoundTripThroughHdf5) {
  DemonstrationOptions demo;
  demo.episodes = 5;
  const Demonstrations d = GenerateDemonstrations({}, {}, demo);
  Rng rng(1);
  const data::StateSet nd = GenerateNearDangerous({}, {}, rng);
  const std::string path = PathOf("demos.h5");
  data::WriteHdf5(path, &d.trajectories, {{data::kNearDangerousLabel, &nd}});
  const data::TrajectorySet back = data::ReadTrajectories(path, StateFeatures(), ActionFeatures());
  EXPECT_EQ(back.states, d.trajectories.states);
  EXPECT_EQ(back.actions, d.trajectories.actions);
  EXPECT_EQ(back.episode_begin, d.trajectories.episode_begin);
  // Written without a selection, the features come back in order, under their own names.
  const data::TrajectorySet all = data::ReadTrajectories(path, {}, {});
  EXPECT_EQ(all.state_features, StateFeatures());
  EXPECT_EQ(all.action_features, ActionFeatures());
  EXPECT_EQ(data::ReadStateSet(path, StateFeatures(), data::kNearDangerousLabel).states, nd.states);
}

// ---------------------------------------------------------------------------------------------
// Safety demonstrations

TEST(SafeStatesTest, AllOrARandomSubsetOfTheDemonstrationStates) {
  DemonstrationOptions demo;
  demo.episodes = 3;
  const data::TrajectorySet t = GenerateDemonstrations({}, {}, demo).trajectories;
  Rng rng(2);
  const data::StateSet all = SafeStatesFromDemonstrations(t, t.num_steps(), rng);
  EXPECT_EQ(all.states, t.states);
  EXPECT_EQ(all.features, StateFeatures());
  EXPECT_HAS(all.source, "expert demonstrations");

  const data::StateSet some = SafeStatesFromDemonstrations(t, 100, rng);
  ASSERT_EQ(some.size(), 100);
  // Distinct demonstration states, in file order.
  long previous = -1;
  for (long i = 0; i < some.size(); ++i) {
    long found = -1;
    for (long j = previous + 1; j < t.num_steps() && found < 0; ++j)
      if (t.states.col(j) == some.states.col(i)) found = j;
    ASSERT_GE(found, 0) << "state " << i << " is not a later demonstration state";
    previous = found;
  }
  Rng same(2);
  SafeStatesFromDemonstrations(t, t.num_steps(), same);
  EXPECT_EQ(SafeStatesFromDemonstrations(t, 100, same).states, some.states);
  EXPECT_HAS(ErrorOf([&] { SafeStatesFromDemonstrations(t, 0, rng); }), "max_states = 0");
  EXPECT_HAS(ErrorOf([&] { SafeStatesFromDemonstrations(data::TrajectorySet(), 5, rng); }),
             "hold no states");
}

TEST(NearDangerousTest, StatesWrapTheObstacleAndAreUnsafe) {
  const ReachAvoidOptions task;
  const NearDangerousOptions options;
  Rng rng(3);
  const data::StateSet nd = GenerateNearDangerous(task, options, rng);
  ASSERT_EQ(nd.size(), 2000);
  EXPECT_EQ(nd.features, StateFeatures());
  int outside = 0, inside = 0;
  std::set<int> octants;
  for (long i = 0; i < nd.size(); ++i) {
    const auto s = nd.states.col(i);
    ASSERT_LT(task.truth.H(s[0], s[1], s[2], s[3]), 0.0) << "state " << i;
    const double distance = std::hypot(s[0] - 5.0, s[1] - 5.0);
    ASSERT_GE(distance, 2.0 - 1.5 - 1e-5);
    ASSERT_LT(distance, 2.0 + 1.5 + 1e-5);
    ASSERT_GE(s[2], -1.5f);
    ASSERT_LT(s[3], 1.5f);
    (distance >= 2.0 ? outside : inside)++;
    octants.insert(
        static_cast<int>(std::floor((std::atan2(s[1] - 5.0, s[0] - 5.0) + M_PI) / (M_PI / 4))));
  }
  EXPECT_GT(outside, 300);  // outside but about to enter
  EXPECT_GT(inside, 1000);
  EXPECT_GE(octants.size(), 8u);  // all around the obstacle

  Rng same(3);
  EXPECT_EQ(GenerateNearDangerous(task, options, same).states, nd.states);
}

TEST(NearDangerousTest, RejectsBadOptions) {
  Rng rng(1);
  NearDangerousOptions o;
  o.count = 0;
  EXPECT_HAS(ErrorOf([&] { GenerateNearDangerous({}, o, rng); }),
             "NearDangerousOptions::count = 0, must be > 0");
  o = {};
  o.rho_min = 0.4;
  o.rho_max = 0.3;
  EXPECT_HAS(ErrorOf([&] { GenerateNearDangerous({}, o, rng); }),
             "NearDangerousOptions::rho_min, rho_max = 0.4, 0.3");
  o = {};
  o.rho_min = -2.5;
  EXPECT_HAS(ErrorOf([&] { GenerateNearDangerous({}, o, rng); }),
             "NearDangerousOptions::rho_min = -2.5, must be > -radius = -2");
  o = {};
  o.count = 3;
  o.rho_min = 5;
  o.rho_max = 6;  // far out: h < 0 needs speeds beyond the range
  o.velocity_lo = -0.1;
  o.velocity_hi = 0.1;
  EXPECT_HAS(ErrorOf([&] { GenerateNearDangerous({}, o, rng); }), "only 0 of 3 states with h < 0");
}

// Timing of the default generator (printed for the record).
TEST(DemonstrationsTest, HundredDemonstrationsAreFast) {
  const Stopwatch clock;
  const Demonstrations d = GenerateDemonstrations({}, {}, DemonstrationOptions());
  const double seconds = clock.Seconds();
  std::printf("[ measured ] 100 demonstrations (%ld steps, %ld attempts): %.3f s\n",
              d.trajectories.num_steps(), d.attempted, seconds);
  EXPECT_EQ(d.trajectories.num_episodes(), 100);
}

TEST(ExpertTest, KeepsItsClearanceFromTheObstacle) {
  const ReachAvoidOptions task;
  const ExpertOptions options;  // clearance 0.3
  ASSERT_EQ(options.clearance, 0.3);
  DemonstrationOptions demo;
  demo.episodes = 50;
  const Demonstrations d = GenerateDemonstrations(task, options, demo);
  double closest = 1e9;
  for (long i = 0; i < d.trajectories.num_steps(); ++i) {
    const auto s = d.trajectories.states.col(i);
    closest = std::min(closest, std::hypot(double(s[0]) - 5.0, double(s[1]) - 5.0) - 2.0);
  }
  EXPECT_GE(closest, 0.3 - 1e-3);  // h of the enlarged obstacle stays >= 0
  EXPECT_LT(closest, 0.5);          // and the expert does pass close to it
  ExpertOptions bad;
  bad.clearance = -0.1;
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "ExpertOptions::clearance = -0.1");
}

}  // namespace
}  // namespace secure::domains::double_integrator
