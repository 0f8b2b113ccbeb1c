// Tests of the Demolition Derby expert (privileged CBF-QP filter) and the generators of
// demonstrations, safe states and near-dangerous states (domains/derby/expert.h).

#include "domains/derby/expert.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <set>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "tests/test_util.h"

namespace secure::domains::derby {
namespace {

using secure::test::ErrorOf;

// 200 demonstrations, shared by the tests below (about 0.2 s).
const DerbyDemonstrations& Demos() {
  static const DerbyDemonstrations demos = [] {
    DerbyDemonstrationOptions demo;
    demo.episodes = 200;
    demo.seed = 7;
    return GenerateDerbyDemonstrations(DerbyOptions{}, DerbyExpertOptions{}, demo);
  }();
  return demos;
}

TEST(DerbyExpertTest, OptionsValidate) {
  EXPECT_NO_THROW(DerbyExpertOptions{}.Validate());
  DerbyExpertOptions o;
  o.kp = -1;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "DerbyExpertOptions::kp = -1");
  o = {};
  o.clearance = std::nan("");
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "clearance = nan");
  o = {};
  o.cbf_rate = 20;  // 20 * 0.1 > 1
  EXPECT_HAS(ErrorOf([&] { DerbyExpert(DerbyOptions{}, o); }), "cbf_rate = 20");
  DerbyDemonstrationOptions d;
  d.episodes = 0;
  EXPECT_HAS(ErrorOf([&] { d.Validate(); }), "episodes = 0");
  EXPECT_EQ(DerbyExpertOptions{}.ToJson()["kd"], DerbyExpertOptions{}.kd);
}

TEST(DerbyExpertTest, NominalIsPdBelowTheSpeedLimit) {
  const DerbyExpert expert(DerbyOptions{});
  const Eigen::Vector2d p(1.0, 1.1), v(0.1, -0.2), g(1.2, 1.0);
  const Eigen::Vector2d a = expert.Nominal(p, v, g);
  const Eigen::Vector2d want = -3.0 * (p - g) - 3.0 * v;
  EXPECT_NEAR(a.x(), want.x(), 1e-12);
  EXPECT_NEAR(a.y(), want.y(), 1e-12);
  // Far away the desired speed saturates at speed_limit: at v = v_des the action is 0.
  const Eigen::Vector2d far(-10.0, 0.0);
  const Eigen::Vector2d at_limit(1.0, 0.0);
  EXPECT_NEAR(expert.Nominal(far, at_limit, Eigen::Vector2d::Zero()).norm(), 0.0, 1e-12);
}

TEST(DerbyExpertTest, FilterStopsAHeadOnApproach) {
  // One car straight ahead on the ego's path, others far away: the unfiltered nominal drives
  // into it, the filter brakes in time.
  DerbyOptions task;
  task.num_cars = 12;
  DerbyEnv env(task);
  Eigen::Matrix2Xf cars(2, 12), vel = Eigen::Matrix2Xf::Zero(2, 12);
  for (int j = 0; j < 12; ++j) cars.col(j) = Eigen::Vector2f(-5.0f - j, -5.0f);
  cars.col(0) = Eigen::Vector2f(0.5f, 0.0f);
  Eigen::VectorXf o(kObservationDim);
  Eigen::Vector2f a;
  for (bool filter : {true, false}) {
    env.SetScenario(Eigen::Vector4f(0, 0, 0.8f, 0), Eigen::Vector2f(1.0f, 0.0f), cars, vel, o);
    DerbyExpertOptions options;
    options.noise_sigma = 0;
    options.use_filter = filter;
    DerbyExpert expert(task, options);
    Rng rng(1);
    float closest = 1e9f;
    for (int t = 0; t < 30; ++t) {
      expert.Act(env, rng, a);
      env.Step(a, o);
      closest = std::min(closest, env.NearestCarDistance());
    }
    if (filter) {
      EXPECT_GT(closest, task.collision_radius + 0.02) << "the filter let the ego hit the car";
    } else {
      EXPECT_LE(closest, task.collision_radius) << "the unfiltered nominal should hit the car";
    }
  }
}

TEST(DerbyExpertTest, DemonstrationsAreSafeAndMostlyKept) {
  const DerbyDemonstrations& d = Demos();
  const data::TrajectorySet& t = d.trajectories;
  ASSERT_EQ(t.num_episodes(), 200);
  EXPECT_EQ(t.num_steps(), 200 * 100);
  EXPECT_EQ(t.states.rows(), kObservationDim);
  EXPECT_EQ(t.actions.rows(), kActionDim);
  EXPECT_EQ(t.state_features, ObservationFeatures());
  const double kept_fraction = 200.0 / static_cast<double>(d.attempted);
  std::cout << "[derby expert] " << d.ToJson().dump() << "\n";
  EXPECT_GE(kept_fraction, 0.9);
  EXPECT_GT(d.min_car_distance, DerbyOptions{}.collision_radius);
  EXPECT_EQ(static_cast<long>(d.attempts.size()), 200);
  EXPECT_EQ(d.attempted, 200 + d.discarded_collisions + d.discarded_no_goal);
  // Replaying the kept episodes with the recorded actions: 0 collisions, every goal reached.
  DerbyEnv env;
  Eigen::VectorXf o(kObservationDim);
  for (long e = 0; e < t.num_episodes(); e += 20) {
    Rng rng = DerbyAttemptRng(d.seed, d.attempts[static_cast<std::size_t>(e)]);
    env.Reset(rng, o);
    const long begin = t.episode_begin[static_cast<std::size_t>(e)];
    ASSERT_TRUE(o.isApprox(t.states.col(begin))) << "episode " << e;
    int collisions = 0;
    bool reached = false;
    for (long i = begin; i < t.episode_begin[static_cast<std::size_t>(e) + 1]; ++i) {
      const StepOutcome out = env.Step(t.actions.col(i), o);
      collisions += out.collisions;
      reached = reached || out.reached_goal;
      if (i + 1 < t.episode_begin[static_cast<std::size_t>(e) + 1]) {
        ASSERT_TRUE(o.isApprox(t.states.col(i + 1), 1e-5f));
      }
    }
    EXPECT_EQ(collisions, 0) << "episode " << e;
    EXPECT_TRUE(reached) << "episode " << e;
  }
  // Actions inside the bound; demonstrations differ.
  EXPECT_LE(t.actions.cwiseAbs().maxCoeff(), 3.0f);
  EXPECT_NE(t.states.col(t.episode_begin[0] + 30), t.states.col(t.episode_begin[1] + 30));
}

TEST(DerbyExpertTest, UnfilteredNominalCollidesMore) {
  DerbyDemonstrationOptions demo;
  demo.episodes = 200;
  demo.seed = 7;
  demo.require_all = false;
  demo.max_attempts = 200;
  DerbyExpertOptions unfiltered;
  unfiltered.use_filter = false;
  const DerbyDemonstrations without = GenerateDerbyDemonstrations({}, unfiltered, demo);
  const DerbyDemonstrations with = GenerateDerbyDemonstrations({}, {}, demo);
  std::cout << "[derby expert] 200 attempts, collided with filter " << with.discarded_collisions
            << ", without " << without.discarded_collisions << "\n";
  EXPECT_EQ(with.attempted, 200);
  EXPECT_GE(without.discarded_collisions, 5 * std::max<long>(1, with.discarded_collisions));
  EXPECT_GE(without.discarded_collisions, 40);
}

TEST(DerbyExpertTest, DemonstrationsAreDeterministic) {
  DerbyDemonstrationOptions demo;
  demo.episodes = 5;
  demo.seed = 3;
  const DerbyDemonstrations a = GenerateDerbyDemonstrations({}, {}, demo);
  const DerbyDemonstrations b = GenerateDerbyDemonstrations({}, {}, demo);
  EXPECT_EQ(a.trajectories.states, b.trajectories.states);
  EXPECT_EQ(a.trajectories.actions, b.trajectories.actions);
  EXPECT_EQ(a.attempts, b.attempts);
  demo.seed = 4;
  const DerbyDemonstrations c = GenerateDerbyDemonstrations({}, {}, demo);
  EXPECT_NE(a.trajectories.states, c.trajectories.states);
}

TEST(DerbyExpertTest, SafeStatesAreDemonstrationObservations) {
  const data::TrajectorySet& t = Demos().trajectories;
  Rng rng(5);
  const data::StateSet safe = SafeStatesFromDemonstrations(t, 1024, rng);
  ASSERT_EQ(safe.size(), 1024);
  EXPECT_EQ(safe.features, ObservationFeatures());
  // Each is a column of the demonstrations, all distinct columns (without replacement).
  std::set<long> columns;
  for (long i = 0; i < safe.size(); ++i) {
    long found = -1;
    for (long c = 0; c < t.num_steps() && found < 0; ++c)
      if (t.states.col(c) == safe.states.col(i)) found = c;
    ASSERT_GE(found, 0) << "safe state " << i << " is not a demonstration state";
    columns.insert(found);
  }
  EXPECT_GT(static_cast<long>(columns.size()), 1000);  // (a few demonstration states repeat)
  // More than the set holds: every state, plus a random rest.
  data::TrajectorySet small = t;
  small.states = t.states.leftCols(10);
  const data::StateSet all = SafeStatesFromDemonstrations(small, 25, rng);
  EXPECT_EQ(all.size(), 25);
  EXPECT_EQ(all.states.leftCols(10), small.states);
  EXPECT_HAS(ErrorOf([&] { SafeStatesFromDemonstrations(t, 0, rng); }), "count = 0");
}

class DerbyDataFileTest : public secure::test::TempDirTest {};

// Derby's demonstrations and safety demonstrations through one HDF5 file (robomimic's layout)
// and through CSV: the same matrices, bit for bit.
TEST_F(DerbyDataFileTest, DemonstrationsRoundTripThroughHdf5AsThroughCsv) {
  DerbyDemonstrationOptions demo;
  demo.episodes = 4;
  demo.seed = 3;
  const DerbyDemonstrations d = GenerateDerbyDemonstrations({}, {}, demo);
  Rng rng(5);
  const data::StateSet safe = SafeStatesFromDemonstrations(d.trajectories, 100, rng);
  DerbyNearDangerousOptions options;
  options.count = 100;
  const data::StateSet nd = GenerateDerbyNearDangerous({}, d, options, rng);
  const std::string h5 = PathOf("derby.h5"), csv = PathOf("demos.csv");
  data::WriteHdf5(h5, &d.trajectories,
                  {{data::kSafeLabel, &safe}, {data::kNearDangerousLabel, &nd}});
  data::WriteTrajectories(csv, d.trajectories);
  for (const std::string& path : {h5, csv}) {
    SCOPED_TRACE(path);
    const data::TrajectorySet back =
        data::ReadTrajectories(path, ObservationFeatures(), ActionFeatures());
    EXPECT_EQ(back.states, d.trajectories.states);
    EXPECT_EQ(back.actions, d.trajectories.actions);
    EXPECT_EQ(back.episode_begin, d.trajectories.episode_begin);
  }
  EXPECT_EQ(data::ReadStateSet(h5, ObservationFeatures(), data::kSafeLabel).states, safe.states);
  EXPECT_EQ(data::ReadStateSet(h5, ObservationFeatures(), data::kNearDangerousLabel).states,
            nd.states);
}

TEST(DerbyExpertTest, NearDangerousStatesFollowTheReleasedScheme) {
  const DerbyDemonstrations& d = Demos();
  DerbyNearDangerousOptions options;
  options.count = 3000;
  Rng rng(11);
  const data::StateSet nd = GenerateDerbyNearDangerous({}, d, options, rng);
  ASSERT_EQ(nd.size(), 3000);
  EXPECT_EQ(nd.features, ObservationFeatures());
  // Block 0 is the dangerous car: the nearest, within 0.14; blocks are sorted by distance.
  std::map<double, long> by_rho;  // the smallest rho compatible with each offset
  for (long i = 0; i < nd.size(); ++i) {
    const auto s = nd.states.col(i);
    const float d0 = s.segment<2>(kFirstCarOffset).norm();
    ASSERT_LE(d0, 0.14f + 1e-5f) << "state " << i;
    for (int k = 1; k < kObservedCars; ++k)
      ASSERT_LE(d0, s.segment<2>(kFirstCarOffset + kCarStride * k).norm()) << "state " << i;
    // |u_i| rho / sqrt(2) <= rho per axis: the smallest rho compatible with the offset.
    const float m = s.segment<2>(kFirstCarOffset).cwiseAbs().maxCoeff() * std::sqrt(2.0f);
    for (double rho : options.rho)
      if (m <= rho + 1e-6) {
        ++by_rho[rho];
        break;
      }
  }
  // With u ~ U(-1, 1)^2, max_i |offset_i| sqrt(2) = rho max |u_i| exceeds 0.07 only for rho in
  // {0.10, 0.12, 0.14} (probabilities .2, .1, .1), with P(max |u_i| > 0.07 / rho) =
  // 1 - (0.07 / rho)^2: 0.2 x 0.51 + 0.1 x 0.660 + 0.1 x 0.75 = 0.243.
  long beyond = 0;
  for (long i = 0; i < nd.size(); ++i)
    if (nd.states.col(i).segment<2>(kFirstCarOffset).cwiseAbs().maxCoeff() > 0.07f / std::sqrt(2.0f))
      ++beyond;
  const double fraction = static_cast<double>(beyond) / static_cast<double>(nd.size());
  EXPECT_NEAR(fraction, 0.2 * (1 - 0.49) + 0.1 * (1 - 0.3403) + 0.1 * (1 - 0.25), 0.04);
  // max |offset_i| sqrt(2) <= 0.01: always for rho = 0.01 (probability 0.2), else with
  // P = (0.01 / rho)^2: 0.2 + 0.2 / 9 + 0.2 / 49 + 0.2 / 100 + 0.1 / 144 + 0.1 / 196 = 0.2295.
  EXPECT_NEAR(static_cast<double>(by_rho[0.01]) / static_cast<double>(nd.size()), 0.2295, 0.03);
  // Velocities are demonstration velocities (|v| within the expert's range).
  EXPECT_LE(nd.states.row(2).cwiseAbs().maxCoeff(), 2.0f);
  // Deterministic.
  Rng again(11);
  EXPECT_EQ(GenerateDerbyNearDangerous({}, d, options, again).states, nd.states);
  // Bad options.
  options.probabilities = {0.5, 0.5};
  EXPECT_HAS(ErrorOf([&] { GenerateDerbyNearDangerous({}, d, options, rng); }),
             "rho has 6 values and probabilities 2");
  options = {};
  options.probabilities[0] = 0.3;
  EXPECT_HAS(ErrorOf([&] { options.Validate(); }), "sum to 1.1");
  options = {};
  options.nearest = 13;
  EXPECT_HAS(ErrorOf([&] { options.Validate(); }), "nearest = 13");
}

}  // namespace
}  // namespace secure::domains::derby
