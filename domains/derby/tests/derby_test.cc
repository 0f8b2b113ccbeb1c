// Tests of the Demolition Derby task (domains/derby/derby.h): options, observation layout,
// Euler semantics, collisions, success, determinism, the shield model, bad inputs, allocations.

#include "domains/derby/derby.h"
#include "domains/derby/domain.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <iostream>
#include <limits>
#include <memory>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "tests/malloc_counter.h"
#include "tests/sanitizers.h"
#include "tests/test_util.h"

namespace secure::domains::derby {
namespace {

using secure::test::ErrorOf;

// Far-away cars (beyond any interaction) for constructed scenarios, then the given ones.
Eigen::Matrix2Xf FarCars(int n) {
  Eigen::Matrix2Xf cars(2, n);
  for (int j = 0; j < n; ++j) cars.col(j) = Eigen::Vector2f(10.0f + j, -10.0f);
  return cars;
}

Eigen::Vector2f Block(const Eigen::VectorXf& o, int i, int part) {
  return o.segment<2>(kFirstCarOffset + kCarStride * i + 2 * part);
}

// ---------------------------------------------------------------------------------------------
// Options and names

TEST(DerbyOptionsTest, DefaultsAndValidation) {
  const DerbyOptions o;
  EXPECT_NO_THROW(o.Validate());
  EXPECT_EQ(o.num_cars, 16);
  EXPECT_EQ(o.max_steps, 100);
  EXPECT_EQ(o.dt, 0.1);
  EXPECT_NEAR(o.arena_side, std::sqrt(2.0), 1e-15);
  EXPECT_EQ(o.goal_radius, 0.05);
  EXPECT_EQ(o.collision_radius, 0.07);
  EXPECT_EQ(o.min_separation, 0.105);
  EXPECT_EQ(o.lookahead_steps, 2);
  EXPECT_EQ(o.ToJson()["num_cars"], 16);
  EXPECT_EQ(o.ToJson().size(), 16u);

  DerbyOptions bad;
  bad.num_cars = 5;
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "DerbyOptions::num_cars = 5, must be in [12, 64]");
  bad = {};
  bad.dt = 0;
  EXPECT_HAS(ErrorOf([&] { DerbyEnv env(bad); }), "DerbyOptions::dt = 0");
  bad = {};
  bad.accel_bound = std::nan("");
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "accel_bound = nan");
  bad = {};
  bad.lookahead_steps = 7;
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "lookahead_steps = 7");
  bad = {};
  bad.car_noise = -1;
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "car_noise = -1");
  // Unplaceable cars: a clearance that covers the arena.
  bad = {};
  bad.ego_clearance = 5;
  DerbyEnv crowded(bad);
  Eigen::VectorXf obs(kObservationDim);
  Rng rng(1);
  EXPECT_HAS(ErrorOf([&] { crowded.Reset(rng, obs); }), "no start for car 0");
}

TEST(DerbyOptionsTest, FeatureNames) {
  const auto& f = ObservationFeatures();
  ASSERT_EQ(static_cast<int>(f.size()), kObservationDim);
  EXPECT_EQ(f[0], "goal_dx");
  EXPECT_EQ(f[1], "goal_dy");
  EXPECT_EQ(f[2], "vx");
  EXPECT_EQ(f[3], "vy");
  EXPECT_EQ(f[4], "car0_dx");
  EXPECT_EQ(f[7], "car0_dvy");
  EXPECT_EQ(f[8], "car1_dx");
  EXPECT_EQ(f[51], "car11_dvy");
  EXPECT_EQ(ActionFeatures(), (std::vector<std::string>{"ax", "ay"}));
  DerbyEnv env;
  EXPECT_EQ(env.ObservationFeatures(), f);
  EXPECT_EQ(env.observation_dim(), 52);
  EXPECT_EQ(env.action_dim(), 2);
  EXPECT_EQ(kFirstCarOffset + kCarStride * kObservedCars, kObservationDim);
  EXPECT_HAS(env.Describe(), "16 cars");
}

TEST(DerbyOptionsTest, ObstacleLayoutOfObservationPointsAtTheCarBlocks) {
  // The per-car barrier's layout comes from the plug-in (cbf has no default).
  const cbf::ObstacleLayout l = ObstacleLayoutOfObservation();
  EXPECT_NO_THROW(l.Validate());
  EXPECT_EQ(l.obs_dim, kObservationDim);
  EXPECT_EQ(l.num_obstacles, kObservedCars);
  const auto& f = ObservationFeatures();
  for (int i = 0; i < kObservedCars; ++i) {
    const std::string car = "car" + std::to_string(i);
    EXPECT_EQ(f[l.PositionIndex(i)], car + "_dx");
    EXPECT_EQ(f[l.PositionIndex(i) + 1], car + "_dy");
    EXPECT_EQ(f[l.VelocityIndex(i)], car + "_dvx");
    EXPECT_EQ(f[l.VelocityIndex(i) + 1], car + "_dvy");
  }
  // Both profiles' presets train the per-car barrier on it.
  for (const auto profile : {experiments::Profile::kFull, experiments::Profile::kQuick})
    EXPECT_TRUE(DerbyDomain(profile).Preset().per_obstacle_barrier.input.layout == l);
}

// ---------------------------------------------------------------------------------------------
// Observation

TEST(DerbyEnvTest, ObservationIsEgoRelativeAndSortedByDistance) {
  DerbyEnv env;
  Eigen::Matrix2Xf cars = FarCars(16);
  Eigen::Matrix2Xf vel = Eigen::Matrix2Xf::Zero(2, 16);
  const Eigen::Vector2f p(0.5f, 0.5f), v(0.1f, -0.2f), goal(1.4f, 1.3f);
  cars.col(7) = p + Eigen::Vector2f(0.3f, 0.0f);   // distance 0.3
  cars.col(3) = p + Eigen::Vector2f(0.0f, -0.2f);  // 0.2: nearest
  cars.col(9) = p + Eigen::Vector2f(0.0f, 0.3f);   // 0.3: tie with car 7, after it (index)
  cars.col(12) = p + Eigen::Vector2f(-0.3f, 0.4f);  // 0.5
  vel.col(3) = Eigen::Vector2f(0.5f, 0.25f);
  Eigen::VectorXf o(kObservationDim);
  env.SetScenario(Eigen::Vector4f(p.x(), p.y(), v.x(), v.y()), goal, cars, vel, o);
  EXPECT_TRUE(o.segment<2>(0).isApprox(goal - p));
  EXPECT_EQ(Eigen::Vector2f(o.segment<2>(2)), v);
  EXPECT_EQ(env.ObservedCars()[0], 3);
  EXPECT_EQ(env.ObservedCars()[1], 7);
  EXPECT_EQ(env.ObservedCars()[2], 9);
  EXPECT_EQ(env.ObservedCars()[3], 12);
  EXPECT_TRUE(Block(o, 0, 0).isApprox(Eigen::Vector2f(0.0f, -0.2f)));
  EXPECT_TRUE(Block(o, 0, 1).isApprox(Eigen::Vector2f(0.5f, 0.25f) - v));
  EXPECT_TRUE(Block(o, 3, 0).isApprox(Eigen::Vector2f(-0.3f, 0.4f)));
  EXPECT_TRUE(Block(o, 3, 1).isApprox(-v));
  // The far cars follow in index order (their distances increase with the index) and 4 of the
  // 16 cars are not observed.
  for (int i = 1; i < kObservedCars; ++i)
    EXPECT_LE(Block(o, i - 1, 0).squaredNorm(), Block(o, i, 0).squaredNorm());
  EXPECT_EQ(env.ObservedCars()[4], 0);
  EXPECT_EQ(env.ObservedCars()[11], 10);
}

TEST(DerbyEnvTest, ResetPlacesCarsAsDocumented) {
  DerbyEnv env;
  const DerbyOptions& o = env.options();
  Eigen::VectorXf obs(kObservationDim);
  Rng rng(3);
  for (int episode = 0; episode < 200; ++episode) {
    env.Reset(rng, obs);
    const Eigen::Vector2f p = env.ego_position();
    ASSERT_LE(p.cwiseAbs().maxCoeff(), o.start_jitter);
    ASSERT_LE((env.goal().array() - static_cast<float>(o.arena_side)).abs().maxCoeff(),
              o.goal_jitter + 1e-6);
    ASSERT_EQ(env.ego_velocity(), Eigen::Vector2f::Zero());
    const auto cars = env.CarPositions(0);
    ASSERT_EQ(env.CarVelocities(0), Eigen::Matrix2Xf::Zero(2, 16));
    for (int j = 0; j < 16; ++j) {
      ASSERT_GE(cars.col(j).minCoeff(), 0.0f);
      ASSERT_LE(cars.col(j).maxCoeff(), static_cast<float>(o.arena_side));
      ASSERT_GT((cars.col(j) - p).norm(), o.ego_clearance - 1e-6);
      ASSERT_GT((cars.col(j) - env.goal()).norm(), o.ego_clearance - 1e-6);
      ASSERT_GT((env.car_goals().col(j) - env.goal()).norm(), o.ego_clearance - 1e-6);
      ASSERT_LE((env.car_goals().col(j) - cars.col(j)).cwiseAbs().maxCoeff(),
                o.car_goal_offset + 1e-6);
      for (int k = 0; k < j; ++k) {
        ASSERT_GT((cars.col(j) - cars.col(k)).norm(), o.min_separation - 1e-6);
        ASSERT_GT((env.car_goals().col(j) - env.car_goals().col(k)).norm(),
                  o.min_separation - 1e-6);
      }
    }
    Eigen::VectorXf want(kObservationDim);
    BuildObservation(p, env.ego_velocity(), env.goal(), cars, env.CarVelocities(0), want);
    ASSERT_EQ(obs, want);
  }
}

TEST(DerbyEnvTest, CarsFollowTheirDampedControllerAndKeepMoving) {
  DerbyEnv env;
  Eigen::VectorXf obs(kObservationDim);
  Rng rng(4);
  double speed_sum = 0, last_second_sum = 0, max_speed = 0;
  long count = 0, last_count = 0;
  const int episodes = 200;
  for (int e = 0; e < episodes; ++e) {
    env.Reset(rng, obs);
    for (int f = 1; f <= env.max_steps(); ++f) {
      // Explicit Euler: p(f) = p(f - 1) + v(f - 1) dt.
      const Eigen::Matrix2Xf step = env.CarPositions(f - 1) + env.CarVelocities(f - 1) * 0.1f;
      ASSERT_TRUE(env.CarPositions(f).isApprox(step, 1e-5f));
      for (int j = 0; j < 16; ++j) {
        const double s = env.CarVelocities(f).col(j).norm();
        speed_sum += s;
        max_speed = std::max(max_speed, s);
        ++count;
        if (f > env.max_steps() - 10) {
          last_second_sum += s;
          ++last_count;
        }
      }
    }
  }
  const double mean = speed_sum / count, last = last_second_sum / last_count;
  std::cout << "[derby cars] mean speed " << mean << ", last second " << last << ", max "
            << max_speed << "\n";
  EXPECT_GT(mean, 0.15);
  EXPECT_GT(last, 0.08);  // still moving at the end of the episode
  EXPECT_LT(max_speed, 2.0);
}

// ---------------------------------------------------------------------------------------------
// Dynamics, collisions, success

TEST(DerbyEnvTest, ExplicitEulerUsesTheOldVelocityAndClips) {
  DerbyEnv env;
  Eigen::VectorXf o(kObservationDim);
  const Eigen::Vector4f ego(0.2f, 0.3f, 0.5f, -0.4f);
  env.SetScenario(ego, Eigen::Vector2f(1, 1), FarCars(16), Eigen::Matrix2Xf::Zero(2, 16), o);
  env.Step(Eigen::Vector2f(1.0f, 2.0f), o);
  EXPECT_TRUE(env.ego_position().isApprox(Eigen::Vector2f(0.2f + 0.05f, 0.3f - 0.04f)));
  EXPECT_TRUE(env.ego_velocity().isApprox(Eigen::Vector2f(0.5f + 0.1f, -0.4f + 0.2f)));
  EXPECT_TRUE(o.segment<2>(2).isApprox(env.ego_velocity()));
  // Clipped to +-3 per axis.
  env.Step(Eigen::Vector2f(10.0f, -100.0f), o);
  EXPECT_TRUE(env.ego_position().isApprox(Eigen::Vector2f(0.25f + 0.06f, 0.26f - 0.02f)));
  EXPECT_TRUE(env.ego_velocity().isApprox(Eigen::Vector2f(0.6f + 0.3f, -0.2f - 0.3f)));
  EXPECT_EQ(env.step_index(), 2);
}

TEST(DerbyEnvTest, CollisionsCountRisingEdgesOfAnyCarContact) {
  DerbyEnv env;
  Eigen::VectorXf o(kObservationDim);
  Eigen::Matrix2Xf cars = FarCars(16), vel = Eigen::Matrix2Xf::Zero(2, 16);
  // Car 2 crosses the parked ego at 0.5 m/s: x = -0.3 + 0.05 t, in contact (|x| <= 0.07) at
  // t = 5, 6, 7. Car 5 (and car 6 together with it) cross later: x = -0.6 + 0.05 t, contact at
  // t = 11, 12, 13; two cars at once are one event.
  cars.col(2) = Eigen::Vector2f(-0.3f, 0.0f);
  vel.col(2) = Eigen::Vector2f(0.5f, 0.0f);
  cars.col(5) = Eigen::Vector2f(-0.6f, 0.01f);
  vel.col(5) = Eigen::Vector2f(0.5f, 0.0f);
  cars.col(6) = Eigen::Vector2f(-0.6f, -0.01f);
  vel.col(6) = Eigen::Vector2f(0.5f, 0.0f);
  env.SetScenario(Eigen::Vector4f::Zero(), Eigen::Vector2f(1, 1), cars, vel, o);
  int total = 0;
  std::vector<int> contact_steps, edge_steps;
  for (int t = 1; t <= 20; ++t) {
    const StepOutcome out = env.Step(Eigen::Vector2f::Zero(), o);
    EXPECT_LE(out.collisions, out.collided ? 1 : 0);
    if (out.collided) contact_steps.push_back(t);
    if (out.collisions) edge_steps.push_back(t);
    total += out.collisions;
  }
  EXPECT_EQ(contact_steps, (std::vector<int>{5, 6, 7, 11, 12, 13}));
  EXPECT_EQ(edge_steps, (std::vector<int>{5, 11}));
  EXPECT_EQ(total, 2);
  // The boundary: in contact at distance <= collision_radius.
  for (float d : {0.069f, 0.071f}) {
    Eigen::Matrix2Xf one = FarCars(16);
    one.col(15) = Eigen::Vector2f(d, 0.0f);
    env.SetScenario(Eigen::Vector4f::Zero(), Eigen::Vector2f(1, 1), one,
                    Eigen::Matrix2Xf::Zero(2, 16), o);
    EXPECT_EQ(env.Step(Eigen::Vector2f::Zero(), o).collided, d < 0.07f) << d;
  }
}

TEST(DerbyEnvTest, SuccessRadius) {
  DerbyEnv env;
  Eigen::VectorXf o(kObservationDim);
  for (float d : {0.049f, 0.051f}) {
    env.SetScenario(Eigen::Vector4f::Zero(), Eigen::Vector2f(d, 0.0f), FarCars(16),
                    Eigen::Matrix2Xf::Zero(2, 16), o);
    const StepOutcome out = env.Step(Eigen::Vector2f::Zero(), o);
    EXPECT_EQ(out.reached_goal, d < 0.05f) << d;
    EXPECT_FALSE(out.collided);
  }
}

TEST(DerbyEnvTest, EpisodesReplayExactlyFromTheSameRng) {
  DerbyEnv a, b;
  Eigen::VectorXf oa(kObservationDim), ob(kObservationDim);
  Rng ra(42), rb(42), actions_a(9), actions_b(9);
  a.Reset(ra, oa);
  b.Reset(rb, ob);
  ASSERT_EQ(oa, ob);
  for (int t = 0; t < a.max_steps(); ++t) {
    const Eigen::Vector2f act_a(actions_a.Normal(), actions_a.Normal());
    const Eigen::Vector2f act_b(actions_b.Normal(), actions_b.Normal());
    const StepOutcome x = a.Step(act_a, oa), y = b.Step(act_b, ob);
    ASSERT_EQ(oa, ob) << "step " << t;
    ASSERT_EQ(x.collided, y.collided);
    ASSERT_EQ(x.collisions, y.collisions);
  }
  Rng other(43);
  b.Reset(other, ob);
  Rng again(42);
  a.Reset(again, oa);
  EXPECT_NE(oa, ob);
}

TEST(DerbyEnvTest, ClonesAreIndependent) {
  DerbyEnv env;
  Eigen::VectorXf o(kObservationDim), reference(kObservationDim), oc(kObservationDim);
  Rng r1(5);
  env.Reset(r1, o);
  std::unique_ptr<Environment> clone = env.Clone();
  Rng r2(6);
  clone->Reset(r2, oc);
  clone->Step(Eigen::Vector2f(1, 1), oc);
  EXPECT_NE(o, oc);
  // The original continues as if the clone did not exist.
  DerbyEnv fresh;
  Rng r3(5);
  fresh.Reset(r3, reference);
  env.Step(Eigen::Vector2f(0.5f, 0.5f), o);
  fresh.Step(Eigen::Vector2f(0.5f, 0.5f), reference);
  EXPECT_EQ(o, reference);
  EXPECT_EQ(clone->observation_dim(), 52);
}

TEST(DerbyEnvTest, BadInputsThrowNamingTheProblem) {
  DerbyEnv env;
  Eigen::VectorXf o(kObservationDim), short_obs(10);
  EXPECT_HAS(ErrorOf([&] { env.Step(Eigen::Vector2f::Zero(), o); }), "before Reset");
  Rng rng(1);
  EXPECT_HAS(ErrorOf([&] { env.Reset(rng, short_obs); }), "observation has 10 entries");
  env.Reset(rng, o);
  EXPECT_HAS(ErrorOf([&] { env.Step(Eigen::Vector3f::Zero(), o); }),
             "action has 3 entries, expected 2");
  EXPECT_HAS(ErrorOf([&] { env.Step(Eigen::Vector2f(0.0f, std::nanf("")), o); }),
             "action component ay = nan");
  EXPECT_HAS(ErrorOf([&] {
               env.Step(Eigen::Vector2f(std::numeric_limits<float>::infinity(), 0.0f), o);
             }),
             "action component ax = inf");
  EXPECT_HAS(ErrorOf([&] { env.Step(Eigen::Vector2f::Zero(), short_obs); }),
             "observation has 10 entries");
  EXPECT_HAS(ErrorOf([&] { env.CarPositions(env.num_frames()); }), "frame 105 outside [0, 105)");
  // The trajectories end max_steps + kLookaheadFrames steps after Reset.
  for (int t = 0; t < env.max_steps() + kLookaheadFrames; ++t) env.Step(Eigen::Vector2f::Zero(), o);
  EXPECT_HAS(ErrorOf([&] { env.Step(Eigen::Vector2f::Zero(), o); }),
             "past the generated car trajectories");
  EXPECT_HAS(ErrorOf([&] {
               env.SetScenario(Eigen::Vector4f::Zero(), Eigen::Vector2f::Zero(), FarCars(12),
                               Eigen::Matrix2Xf::Zero(2, 12), o);
             }),
             "expected 16 (num_cars)");
  Eigen::VectorXf a(2);
  EXPECT_HAS(ErrorOf([&] { env.BackupAction(short_obs, a); }), "expected 52/2");
}

TEST(DerbyEnvTest, BackupActionBrakes) {
  DerbyEnv env;
  Eigen::VectorXf o = Eigen::VectorXf::Zero(kObservationDim);
  Eigen::VectorXf a(2);
  o[2] = 0.1f;
  o[3] = -0.9f;
  ASSERT_TRUE(env.BackupAction(o, a));
  EXPECT_NEAR(a[0], -1.0f, 1e-6);
  EXPECT_NEAR(a[1], 3.0f, 1e-6);  // 9 clipped to the bound
}

// ---------------------------------------------------------------------------------------------
// The shield model

TEST(DerbyShieldModelTest, ExactUnderConstantVelocityCars) {
  DerbyEnv env;
  const DynamicsModel& model = env.ShieldModel();
  EXPECT_EQ(model.state_dim(), 52);
  EXPECT_EQ(model.action_dim(), 2);
  EXPECT_HAS(model.Describe(), "held 2 steps");
  Rng rng(8);
  Eigen::VectorXf o(kObservationDim), after(kObservationDim);
  for (int trial = 0; trial < 20; ++trial) {
    Eigen::Matrix2Xf cars(2, 16), vel(2, 16);
    for (int j = 0; j < 16; ++j) {
      cars.col(j) = Eigen::Vector2f(rng.Uniform(0, 1.4), rng.Uniform(0, 1.4));
      vel.col(j) = Eigen::Vector2f(rng.Uniform(-0.5, 0.5), rng.Uniform(-0.5, 0.5));
    }
    const Eigen::Vector4f ego(rng.Uniform(0, 1.4), rng.Uniform(0, 1.4), rng.Uniform(-1, 1),
                              rng.Uniform(-1, 1));
    const Eigen::Vector2f goal(1.4f, 1.4f);
    Eigen::MatrixXf actions(2, 3);
    actions << rng.Uniform(-3, 3), 5.0f, -0.5f, rng.Uniform(-3, 3), -7.0f, 0.25f;
    Eigen::MatrixXf predicted(kObservationDim, 3);
    env.SetScenario(ego, goal, cars, vel, o);
    model.Step(o, actions, predicted);
    for (int m = 0; m < 3; ++m) {
      env.SetScenario(ego, goal, cars, vel, o);
      const std::array<int, kObservedCars> blocks = env.ObservedCars();
      env.Step(actions.col(m), after);
      env.Step(actions.col(m), after);
      // Same layout and block order as the input: block i is still car blocks[i].
      Eigen::VectorXf want(kObservationDim);
      want.segment<2>(0) = env.goal() - env.ego_position();
      want.segment<2>(2) = env.ego_velocity();
      for (int i = 0; i < kObservedCars; ++i) {
        const int j = blocks[static_cast<std::size_t>(i)];
        want.segment<2>(kFirstCarOffset + kCarStride * i) =
            env.CarPositions().col(j) - env.ego_position();
        want.segment<2>(kFirstCarOffset + kCarStride * i + 2) =
            env.CarVelocities().col(j) - env.ego_velocity();
      }
      ASSERT_LE((predicted.col(m) - want).cwiseAbs().maxCoeff(), 2e-6f)
          << "trial " << trial << " action " << m;
    }
  }
}

TEST(DerbyShieldModelTest, EgoPartMatchesTheEnvAndClips) {
  // With the cars' real (accelerating) motion the ego part is still exact.
  DerbyEnv env;
  Rng rng(2);
  Eigen::VectorXf o(kObservationDim), after(kObservationDim);
  env.Reset(rng, o);
  for (int t = 0; t < 10; ++t) env.Step(Eigen::Vector2f(1.0f, 0.5f), o);
  const Eigen::Vector2f a(2.0f, -1.0f);
  Eigen::MatrixXf predicted(kObservationDim, 1);
  env.ShieldModel().Step(o, a, predicted);
  env.Step(a, after);
  env.Step(a, after);
  EXPECT_LE((predicted.col(0).head<4>() - after.head<4>()).cwiseAbs().maxCoeff(), 2e-6f);
  // Clipping: 10 acts as 3.
  Eigen::MatrixXf big(2, 2), out(kObservationDim, 2);
  big << 10.0f, 3.0f, -10.0f, -3.0f;
  env.ShieldModel().Step(o, big, out);
  EXPECT_EQ(out.col(0), out.col(1));
  // One-step model: the position does not depend on the action (explicit Euler).
  DerbyShieldModel one(0.1, 3.0, 1);
  Eigen::MatrixXf two(2, 2), next(kObservationDim, 2);
  two << 1.0f, -2.0f, 0.5f, 3.0f;
  one.Step(o, two, next);
  EXPECT_EQ(next.col(0).head<2>(), next.col(1).head<2>());
  EXPECT_NE(next.col(0).segment<2>(2), next.col(1).segment<2>(2));
  // Dimensions and constructor arguments.
  Eigen::MatrixXf wrong(kObservationDim, 3);
  EXPECT_HAS(ErrorOf([&] { env.ShieldModel().Step(o, big, wrong); }), "expected 52 x 2");
  EXPECT_HAS(ErrorOf([&] { env.ShieldModel().Step(o.head(4), big, out); }),
             "state has 4 values, expected 52");
  EXPECT_HAS(ErrorOf([] { DerbyShieldModel(0.1, 3.0, 0); }), "lookahead_steps = 0");
}

// ---------------------------------------------------------------------------------------------
// Allocations

TEST(DerbyEnvTest, ResetStepAndModelDoNotAllocate) {
  if (SECURE_TEST_ASAN) GTEST_SKIP() << "counts calls of a replaced malloc: not under ASan";
  DerbyEnv env;
  Eigen::VectorXf o(kObservationDim);
  Eigen::Vector2f a(0.3f, 0.2f);
  Eigen::MatrixXf actions = Eigen::MatrixXf::Random(2, 64), next(kObservationDim, 64);
  Rng rng(1);
  env.Reset(rng, o);
  test::BeginCountingMalloc();
  env.Reset(rng, o);
  for (int t = 0; t < 50; ++t) env.Step(a, o);
  env.ShieldModel().Step(o, actions, next);
  const long calls = test::EndCountingMalloc();
  EXPECT_EQ(calls, 0);
}

}  // namespace
}  // namespace secure::domains::derby
