// The panda-push plug-in: the MuJoCo model, the arm controller, the task's outcomes, the
// demonstrator, the data generators, the label check against physics and the shield's model.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>

#include "domains/panda_push/data.h"
#include "domains/panda_push/domain.h"
#include "domains/panda_push/panda_push.h"
#include "secure/common/error.h"
#include "secure/dynamics/ensemble.h"
#include "secure/nn/mlp.h"
#include "tests/test_util.h"

namespace secure::domains::panda_push {
namespace {

// `episodes` demonstrations without the DART perturbations (dart_brake_rate = dart_noise = 0).
PandaDemonstrationOptions WithoutDart(int episodes) {
  PandaDemonstrationOptions d;
  d.episodes = episodes;
  d.dart_brake_rate = 0.0;
  d.dart_noise = 0.0;
  return d;
}

// Scripted push: descend to `height`, approach, push along +x at `push` (action units) until the
// block reaches the target or topples. Returns the outcome of the last step.
struct PushResult {
  bool success = false, toppled = false;
  int steps = 0;
  double max_tilt = 0;
};
PushResult Push(PandaPushSim& sim, double height, double push) {
  Eigen::VectorXf o(kObservationDim);
  sim.Observe(o);
  PushResult r;
  for (int t = 0; t < sim.options().max_steps; ++t) {
    Eigen::Vector3f a = Eigen::Vector3f::Zero();
    if (o[kEePos + 2] > height + 0.005 && o[kEePos] < 0.2) {
      a[2] = -0.6f;
    } else {
      a[2] = static_cast<float>(std::clamp(0.5 * (height - o[kEePos + 2]) / 0.05, -1.0, 1.0));
      a[0] = o[kBlockPos] - o[kEePos] > 0.11 ? 0.5f : static_cast<float>(push);
    }
    sim.Step(a);
    sim.Observe(o);
    ++r.steps;
    r.max_tilt = std::max(r.max_tilt, sim.BlockTilt());
    if (sim.Toppled()) {
      r.toppled = true;
      break;
    }
    if (sim.Succeeded()) {
      r.success = true;
      break;
    }
  }
  return r;
}

TEST(PandaPushModel, StartsInTheReleasedPoseWithTheBlockUpright) {
  PandaPushSim sim(PandaPushOptions{});
  Eigen::VectorXf o(kObservationDim);
  sim.Observe(o);
  // The released initial end-effector position is about (0.0928, 0, 0.1190) (official-code-facts
  // §2.2); our kinematics from the published DH parameters give the same within 2 mm.
  EXPECT_NEAR(o[kEePos], 0.0928, 0.002);
  EXPECT_NEAR(o[kEePos + 1], 0.0, 0.002);
  EXPECT_NEAR(o[kEePos + 2], 0.119, 0.002);
  EXPECT_NEAR(o[kBlockPos], 0.40, 1e-6);
  EXPECT_NEAR(o[kBlockPos + 2], 0.20, 1e-6);
  EXPECT_NEAR(sim.BlockTilt(), 0.0, 1e-9);
  EXPECT_NEAR(sim.TargetDistance(), 0.15, 1e-6);
  EXPECT_FALSE(sim.Succeeded());
  EXPECT_FALSE(sim.Toppled());
}

TEST(PandaPushModel, HoldingStillKeepsEverythingInPlaceWithoutWarnings) {
  // Step() throws on any MuJoCo warning; the arm holds its pose under gravity.
  PandaPushSim sim(PandaPushOptions{});
  Eigen::VectorXf before(kObservationDim), after(kObservationDim);
  sim.Observe(before);
  for (int t = 0; t < 50; ++t) sim.Step(Eigen::Vector3f::Zero());
  sim.Observe(after);
  EXPECT_LT((after.head<3>() - before.head<3>()).norm(), 0.005);
  EXPECT_LT((after.segment<3>(kBlockPos) - before.segment<3>(kBlockPos)).norm(), 1e-3);
  EXPECT_NEAR(sim.time(), 50 * 0.04, 1e-9);
}

TEST(PandaPushModel, TheEndEffectorTracksTheActionAndPointsDown) {
  PandaPushSim sim(PandaPushOptions{});
  Eigen::VectorXf o(kObservationDim), next(kObservationDim);
  sim.Observe(o);
  // Steps of a = (0.4, 0, -0.4): the target moves 0.02 m each way per step; from rest the
  // controller lags the first step (about 2/3 of it), then keeps up.
  for (int t = 0; t < 4; ++t) sim.Step(Eigen::Vector3f(0.4f, 0.0f, -0.4f));
  sim.Observe(next);
  EXPECT_NEAR(next[kEePos] - o[kEePos], 0.08, 0.012);
  EXPECT_NEAR(next[kEePos + 2] - o[kEePos + 2], -0.08, 0.012);
  EXPECT_NEAR(next[kEePos + 1] - o[kEePos + 1], 0.0, 0.002);
  EXPECT_NEAR(next[kEeVel], 0.5, 0.1);  // 0.02 m per 0.04 s
  // Actions are clipped to [-1, 1]: 5 and 1 give the same step.
  PandaPushSim a(PandaPushOptions{}), b(PandaPushOptions{});
  a.Step(Eigen::Vector3f(5.0f, 0.0f, 0.0f));
  b.Step(Eigen::Vector3f(1.0f, 0.0f, 0.0f));
  Eigen::VectorXf oa(kObservationDim), ob(kObservationDim);
  a.Observe(oa);
  b.Observe(ob);
  EXPECT_EQ(oa, ob);
  EXPECT_THROW(a.Step(Eigen::Vector3f(NAN, 0.0f, 0.0f)), Error);
}

TEST(PandaPushPhysics, ALowCarefulPushReachesTheTargetUpright) {
  PandaPushSim sim(PandaPushOptions{});
  const PushResult r = Push(sim, 0.03, 0.12);
  EXPECT_TRUE(r.success) << "steps " << r.steps << " max tilt " << r.max_tilt;
  EXPECT_LT(r.max_tilt, 0.1);
}

TEST(PandaPushPhysics, PushingTheUpperPartTopplesTheBlock) {
  for (double height : {0.12, 0.2}) {
    PandaPushSim sim(PandaPushOptions{});
    const PushResult r = Push(sim, height, 0.12);
    EXPECT_TRUE(r.toppled) << "height " << height << " max tilt " << r.max_tilt;
    EXPECT_FALSE(r.success);
  }
}

TEST(PandaPushPhysics, LowerTableFrictionLetsTheUpperPushSlideInstead) {
  // The friction is what makes the labels true: on a slippery table the block slides.
  PandaPushOptions o;
  o.table_friction = 0.15;
  PandaPushSim sim(o);
  const PushResult r = Push(sim, 0.12, 0.12);
  EXPECT_FALSE(r.toppled) << "max tilt " << r.max_tilt;
}

TEST(PandaPushSim, SetObservationReproducesTheObservation) {
  PandaPushSim sim(PandaPushOptions{});
  Eigen::VectorXf o(kObservationDim);
  sim.Observe(o);
  Eigen::VectorXf s = o;
  s[kEePos] = 0.3f;
  s[kEePos + 2] = 0.05f;
  s[kEeVel] = 0.1f;
  s[kBlockPos] = 0.42f;
  s[kBlockEuler + 2] = 0.1f;  // yaw
  s[kBlockVel] = 0.05f;
  const double err = sim.SetObservation(s);
  EXPECT_LT(err, 1e-5);
  Eigen::VectorXf back(kObservationDim);
  sim.Observe(back);
  for (int k = 0; k < kObservationDim; ++k)
    EXPECT_NEAR(back[k], s[k], 2e-3) << ObservationFeatures()[k];
  Eigen::VectorXf bad = s;
  bad[3] = INFINITY;
  EXPECT_THROW(sim.SetObservation(bad), Error);
}

TEST(PandaPushEnv, EpisodesAreDeterministicPerRngAndReportOutcomes) {
  PandaPushEnv env(PandaPushOptions{}, PandaPushShieldModelOptions{});
  EXPECT_EQ(env.ObservationFeatures()[kBlockEuler + 1], "block_pitch");
  EXPECT_EQ(env.max_steps(), 150);
  Eigen::VectorXf o1(kObservationDim), o2(kObservationDim);
  Rng r1(5), r2(5), r3(6);
  env.Reset(r1, o1);
  auto clone = env.Clone();
  clone->Reset(r2, o2);
  EXPECT_EQ(o1, o2);
  clone->Reset(r3, o2);
  EXPECT_NE(o1, o2);  // initial joint noise
  EXPECT_THROW(env.Step(Eigen::VectorXf::Zero(2), o1), Error);
}

TEST(PandaPushShieldModel, IsTheReleasedApproximateModel) {
  PandaPushShieldModel model(PandaPushShieldModelOptions{});
  Eigen::VectorXf s = Eigen::VectorXf::Zero(kObservationDim);
  s[kEePos] = 0.33f;
  s[kBlockPos] = 0.41f;  // within contact_range: the block follows
  Eigen::MatrixXf a(3, 2);
  a << 0.5f, 3.0f, 0.0f, 0.0f, -0.2f, 0.0f;
  Eigen::MatrixXf next(kObservationDim, 2);
  model.Step(s, a, next);
  EXPECT_NEAR(next(kEePos, 0), 0.33f + 0.05f * 0.5f, 1e-6);
  EXPECT_NEAR(next(kEeVel, 0), 1.25f * 0.5f, 1e-6);
  EXPECT_NEAR(next(kEePos + 2, 0), -0.05f * 0.2f, 1e-6);
  EXPECT_NEAR(next(kBlockPos, 0), 0.41f + 0.05f * 0.5f, 1e-6);
  EXPECT_NEAR(next(kEePos, 1), 0.33f + 0.05f, 1e-6);  // clipped to 1
  s[kBlockPos] = 0.9f;  // out of range: the block stays
  model.Step(s, a, next);
  EXPECT_EQ(next(kBlockPos, 0), 0.9f);
}

TEST(PandaPushData, DemonstrationsSucceedAndNearDangerousStatesFollowTheirScenarios) {
  PandaDemonstrationOptions d;
  d.episodes = 3;
  d.seed = 11;
  const PandaDemonstrations demos = GeneratePandaDemonstrations(PandaPushOptions{}, d);
  ASSERT_EQ(demos.trajectories.num_episodes(), 3);
  ASSERT_EQ(demos.push_begin.size(), 3u);
  for (long e = 0; e < 3; ++e) {
    EXPECT_GT(demos.push_begin[e], demos.trajectories.episode_begin[e]);
    EXPECT_LT(demos.push_begin[e], demos.trajectories.episode_begin[e + 1]);
  }
  Rng rng(3);
  PandaNearDangerousOptions nd;
  nd.count = 300;
  std::vector<NearDangerousScenario> kinds;
  const data::StateSet set =
      PandaNearDangerousStates(PandaPushOptions{}, demos, nd, LabelCheckOptions{}, rng, &kinds);
  ASSERT_EQ(set.size(), 300);
  ASSERT_EQ(kinds.size(), 300u);
  for (long i = 0; i < set.size(); ++i) {
    const double z = set.states(kEePos + 2, i), vx = set.states(kEeVel, i);
    switch (kinds[i]) {
      case NearDangerousScenario::kUpper:
        EXPECT_GE(z, nd.upper_z.lo - 1e-6);
        break;
      case NearDangerousScenario::kFastX:
        EXPECT_LE(z, nd.low_z_max + 1e-6);
        EXPECT_GE(vx, nd.fast_vx.lo - 1e-6);
        break;
      case NearDangerousScenario::kFastZ:
        EXPECT_LE(set.states(kEeVel + 2, i), -nd.fast_vz.lo + 1e-6);
        break;
      case NearDangerousScenario::kBoth:
        EXPECT_GE(z, nd.upper_z.lo - 1e-6);
        EXPECT_GE(vx, nd.fast_vx.lo - 1e-6);
        break;
    }
  }
  PandaSafeOptions so;
  so.count = 200;
  const data::StateSet safe = PandaSafeStates(demos, so, rng);
  EXPECT_EQ(safe.size(), 200);
  EXPECT_EQ(safe.features, ObservationFeatures());
  so.count = 100000;  // more than 3 demonstrations x 11 copies hold
  EXPECT_THROW(PandaSafeStates(demos, so, rng), Error);
}

TEST(PandaPushData, HoveringSafeStatesLieBehindTheBlockAtAnyHeightAndVelocity) {
  PandaDemonstrationOptions d;
  d.episodes = 2;
  const PandaDemonstrations demos = GeneratePandaDemonstrations(PandaPushOptions{}, d);
  const Eigen::MatrixXf& demo = demos.trajectories.states;
  PandaSafeOptions so;
  so.noisy_copies = 0;
  so.hover_copies = 2;
  so.count = demo.cols() * 3;  // every state: the demonstrations and two hovering copies each
  Rng rng(5);
  const data::StateSet safe = PandaSafeStates(demos, so, rng);
  ASSERT_EQ(safe.size(), demo.cols() * 3);
  long hovering = 0;
  double max_speed = 0, max_z = 0;
  for (long i = 0; i < safe.size(); ++i) {
    const Eigen::VectorXf s = safe.states.col(i);
    bool is_demo = false;
    for (long j = 0; j < demo.cols() && !is_demo; ++j) is_demo = (demo.col(j) == s);
    if (is_demo) continue;
    ++hovering;
    const double gap = s[kBlockPos] - s[kEePos] - 0.08;  // pusher face to block face
    EXPECT_GE(gap, so.hover_gap.lo - 1e-5);
    EXPECT_LE(gap, so.hover_gap.hi + 1e-5);
    EXPECT_GE(s[kEePos + 2], so.hover_z.lo);
    EXPECT_LE(s[kEePos + 2], so.hover_z.hi);
    for (int k = 0; k < 3; ++k) {
      EXPECT_LE(std::abs(s[kEeVel + k]), so.hover_speed);
      max_speed = std::max(max_speed, static_cast<double>(std::abs(s[kEeVel + k])));
    }
    max_z = std::max(max_z, static_cast<double>(s[kEePos + 2]));
  }
  EXPECT_EQ(hovering, demo.cols() * 2);
  EXPECT_GT(max_speed, 0.5 * so.hover_speed);  // the velocities span the range
  EXPECT_GT(max_z, 0.3);                          // so do the heights
  so.hover_copies = -1;
  EXPECT_HAS(test::ErrorOf([&] { PandaSafeStates(demos, so, rng); }), "hover_copies = -1");
}

TEST(PandaPushData, PausedDemonstrationsRestartThePushFromRest) {
  // With pauses the demonstrator lets go of the push key (a_x = 0) for a few steps and then
  // pushes again: states in contact at rest are followed by the push action. Without them
  // (pause_rate 0, the draws of a version without pauses) no demonstrated action is a pause.
  PandaDemonstrationOptions d;
  d.episodes = 3;
  d.action_noise = 0.0;
  const PandaDemonstrations plain = GeneratePandaDemonstrations(PandaPushOptions{}, d);
  d.pause_rate = 0.1;
  const PandaDemonstrations paused = GeneratePandaDemonstrations(PandaPushOptions{}, d);
  auto count_pauses = [](const PandaDemonstrations& demos) {
    long pauses = 0, restarts = 0;
    const Eigen::MatrixXf& s = demos.trajectories.states;
    const Eigen::MatrixXf& a = demos.trajectories.actions;
    for (long i = 0; i + 1 < a.cols(); ++i) {
      if (a(0, i) == 0.0f && a(2, i) > -0.45f) ++pauses;  // not a descent step (a_z <= -0.5)
      const double gap = s(kBlockPos, i + 1) - s(kEePos, i + 1) - 0.08;
      if (a(0, i) == 0.0f && a(0, i + 1) >= 0.08f && gap < 0.01 &&
          std::abs(s(kEeVel, i + 1)) < 0.05)
        ++restarts;
    }
    return std::pair<long, long>(pauses, restarts);
  };
  EXPECT_EQ(count_pauses(plain).first, 0);
  const auto [pauses, restarts] = count_pauses(paused);
  EXPECT_GT(pauses, 5);
  EXPECT_GE(restarts, 1);  // a push starting from rest, in contact
  EXPECT_EQ(paused.trajectories.num_episodes(), 3);  // the paused demonstrations succeed
  d.pause_rate = 0.9;
  EXPECT_HAS(test::ErrorOf([&] { GeneratePandaDemonstrations(PandaPushOptions{}, d); }),
             "pause_rate = 0.9");
}

TEST(PandaPushData, DartBrakesRecordThePushAtStatesSlowedAgainstTheBlock) {
  // DART-style brakes (issue 30 lever 4): the applied a_x is 0 for a few steps while the recorded
  // action stays the demonstrator's push, so the data hold slow states in contact labelled with
  // the push. Without them every slow state in contact is the push's first step.
  PandaDemonstrationOptions d = WithoutDart(3);
  d.action_noise = 0.0;
  const PandaDemonstrations plain = GeneratePandaDemonstrations(PandaPushOptions{}, d);
  d.dart_brake_rate = 0.15;
  d.dart_noise = 0.05;
  const PandaDemonstrations dart = GeneratePandaDemonstrations(PandaPushOptions{}, d);
  // States in contact moving slower than the slowest push (0.08 units x 1.25 m/s per unit)
  // whose recorded a_x is a push; and recorded a_x = 0 never happens after the descent.
  auto slow_pushes = [&](const PandaDemonstrations& demos) {
    long n = 0;
    const Eigen::MatrixXf& s = demos.trajectories.states;
    const Eigen::MatrixXf& a = demos.trajectories.actions;
    for (long e = 0; e < demos.trajectories.num_episodes(); ++e)
      for (long i = demos.push_begin[e] + 2; i < demos.trajectories.episode_begin[e + 1]; ++i) {
        EXPECT_GE(a(0, i), d.push_speed.lo - 1e-6) << "recorded a_x in contact at column " << i;
        if (s(kEeVel, i) < 0.5 * d.push_speed.lo * 1.25) ++n;
      }
    return n;
  };
  EXPECT_EQ(slow_pushes(plain), 0);
  EXPECT_GE(slow_pushes(dart), 3);
  EXPECT_EQ(dart.trajectories.num_episodes(), 3);  // the perturbed demonstrations succeed
  d.dart_brake_rate = 0.6;
  EXPECT_HAS(test::ErrorOf([&] { GeneratePandaDemonstrations(PandaPushOptions{}, d); }),
             "dart_brake_rate = 0.6");
  d.dart_brake_rate = 0;
  d.dart_noise = std::nan("");
  EXPECT_HAS(test::ErrorOf([&] { GeneratePandaDemonstrations(PandaPushOptions{}, d); }),
             "dart_noise = nan");
}

TEST(PandaPushData, PrecursorNearDangerousStatesToppleWhenContinued) {
  // The precursor generator (issue 30 lever 5) keeps only candidates that physics confirms: the
  // label check finds every kept state toppling, against a fraction for the released generator.
  // Some start before contact (the gap), so they are precursors, not pushes in progress.
  PandaDemonstrationOptions d;
  d.episodes = 2;
  d.seed = 4;
  const PandaDemonstrations demos = GeneratePandaDemonstrations(PandaPushOptions{}, d);
  PandaNearDangerousOptions nd;
  nd.count = 30;
  nd.generator = PandaNearDangerousOptions::Generator::kPrecursor;
  nd.precursor_gap = {0.01, 0.04};
  Rng rng(9);
  std::vector<NearDangerousScenario> kinds;
  const data::StateSet near =
      PandaNearDangerousStates(PandaPushOptions{}, demos, nd, LabelCheckOptions{}, rng, &kinds);
  ASSERT_EQ(near.size(), 30);
  ASSERT_EQ(kinds.size(), 30u);
  const LabelCheckResult r = CheckLabels(PandaPushOptions{}, near, LabelCheckOptions{});
  EXPECT_EQ(r.toppled, 30) << r.ToJson().dump();
  long before_contact = 0;
  for (long i = 0; i < near.size(); ++i)
    before_contact += near.states(kBlockPos, i) - near.states(kEePos, i) - 0.08 > 0.005;
  EXPECT_GE(before_contact, 20);
  // Deterministic: the same stream gives the same states.
  Rng again(9);
  EXPECT_EQ(
      PandaNearDangerousStates(PandaPushOptions{}, demos, nd, LabelCheckOptions{}, again).states,
      near.states);
  nd.max_candidates = 5;  // fewer candidates than states asked for
  EXPECT_HAS(test::ErrorOf([&] {
               PandaNearDangerousStates(PandaPushOptions{}, demos, nd, LabelCheckOptions{}, rng);
             }),
             "candidates topple when continued");
}

TEST(PandaPushData, LabelsHoldAgainstPhysics) {
  // The label check on a small sample: near-dangerous states mostly topple when the push
  // continues, the pushing part of the demonstrations does not. Without the DART perturbations:
  // their noise makes some pushing states faster than the push, and continued at that speed a
  // few of them topple (the default data's rate is in docs/RESULTS.md, Panda).
  PandaDemonstrationOptions d = WithoutDart(2);
  d.seed = 4;
  const PandaDemonstrations demos = GeneratePandaDemonstrations(PandaPushOptions{}, d);
  Rng rng(9);
  PandaNearDangerousOptions nd;
  nd.count = 40;
  const data::StateSet near =
      PandaNearDangerousStates(PandaPushOptions{}, demos, nd, LabelCheckOptions{}, rng);
  data::StateSet pushing;
  pushing.features = ObservationFeatures();
  pushing.states = demos.trajectories.states.middleCols(
      demos.push_begin[0] + 1, demos.trajectories.episode_begin[1] - demos.push_begin[0] - 1);
  LabelCheckOptions lc;
  const LabelCheckResult rn = CheckLabels(PandaPushOptions{}, near, lc);
  const LabelCheckResult rs = CheckLabels(PandaPushOptions{}, pushing, lc);
  EXPECT_GT(rn.TopplingFraction(), 0.6) << rn.ToJson().dump();
  EXPECT_LT(rs.TopplingFraction(), 0.1) << rs.ToJson().dump();
}

TEST(PandaPushRolloutModel, PredictsTheEnvironmentsNextObservationExactly) {
  // The privileged model (shield_model.kind = rollout): from the live state, each action's
  // prediction is bit for bit the observation Step writes; the approximate model's is not.
  PandaPushShieldModelOptions rollout;
  rollout.kind = "rollout";
  PandaPushEnv env(PandaPushOptions{}, rollout);
  EXPECT_TRUE(env.ShieldModelIsExact());
  EXPECT_FALSE(PandaPushEnv(PandaPushOptions{}, PandaPushShieldModelOptions{}).ShieldModelIsExact());
  const auto& model = dynamic_cast<const PandaPushRolloutModel&>(env.ShieldModel());
  Rng rng(3);
  Eigen::VectorXf o(kObservationDim), after(kObservationDim);
  env.Reset(rng, o);
  Eigen::MatrixXf actions(3, 3);
  actions << 0.8f, -0.3f, 0.0f,  //
      0.1f, 0.5f, 0.0f,          //
      -0.9f, 0.2f, 0.0f;
  Eigen::MatrixXf next(kObservationDim, 3);
  for (int t = 0; t < 5; ++t) {
    model.Step(o, actions, next);
    const int c = t % 3;
    auto clone = env.Clone();  // a second environment must not disturb the first's model
    env.Step(actions.col(c), after);
    EXPECT_EQ(Eigen::VectorXf(next.col(c)), after) << "step " << t << " action " << c;
    o = after;
  }
  EXPECT_EQ(model.reconstructed_states(), 0);
  // Another observation: the rollout starts from the state SetObservation reconstructs.
  Eigen::VectorXf s = o;
  s[kEePos] += 0.02f;
  model.Step(s, actions, next);
  EXPECT_EQ(model.reconstructed_states(), 1);
  EXPECT_NEAR(next(kEePos, 0), s[kEePos] + 0.05f * 0.8f, 0.02);  // roughly tracked in a period
  // The live state was left alone.
  Eigen::VectorXf live(kObservationDim);
  env.sim().Observe(live);
  EXPECT_EQ(live, o);
}

TEST(PandaPushDomain, OptionsRejectBadValuesAndUnknownKeys) {
  PandaPushDomain domain(experiments::Profile::kQuick);
  EXPECT_NO_THROW(domain.Validate());
  EXPECT_THROW(domain.ApplyYaml(YAML::Load("{task: {no_such_key: 1}}"), "cfg.yaml"), Error);
  domain.ApplyYaml(YAML::Load("{task: {table_friction: -1}}"), "cfg.yaml");
  EXPECT_HAS(test::ErrorOf([&] { domain.Validate(); }), "table_friction");
  PandaPushDomain model(experiments::Profile::kQuick);
  model.ApplyYaml(YAML::Load("{shield_model: {kind: perfect}}"), "cfg.yaml");
  const std::string perfect = test::ErrorOf([&] { model.Validate(); });
  EXPECT_HAS(perfect, "kind");
  EXPECT_HAS(perfect, "perfect");
  PandaPushDomain released(experiments::Profile::kQuick);
  released.ApplyYaml(YAML::Load("{barrier_data: released}"), "cfg.yaml");
  EXPECT_THROW(released.Validate(), Error);  // no released_data_dir
  EXPECT_THROW(released.ApplyYaml(YAML::Load("{barrier_data: other}"), "cfg.yaml"), Error);
}

// The full preset checks each seed in closed loop before deployment (a stalled seed is replaced);
// the quick profile, for tests and smoke runs, does not.
TEST(PandaPushDomain, TheFullPresetRunsTheClosedLoopCheck) {
  const experiments::ExperimentOptions full = PandaPushDomain(experiments::Profile::kFull).Preset();
  EXPECT_TRUE(full.closed_loop.enabled);
  EXPECT_EQ(full.closed_loop.max_candidates, 4);
  EXPECT_EQ(full.closed_loop.episodes, 50);
  EXPECT_FALSE(PandaPushDomain(experiments::Profile::kQuick).Preset().closed_loop.enabled);
}

// The barrier check's unsafe test (c): the block's tilt from upright as the observed Euler
// angles give it, against the topple angle; the simulator's own tilt of the same state agrees.
TEST(PandaPushCheck, TheUnsafeTestIsTheObservedTiltBeyondTheToppleAngle) {
  const PandaPushDomain domain(experiments::Profile::kQuick);
  const double topple = domain.options().task.topple_angle;
  PandaPushSim sim(PandaPushOptions{});
  Eigen::VectorXf o(kObservationDim);
  sim.Observe(o);  // the block upright at its start
  EXPECT_NEAR(ObservedBlockTilt(o), 0.0, 1e-3);
  data::StateSet safe{"upright", ObservationFeatures(), o};
  std::unique_ptr<DynamicsModel> dynamics;
  const cbf::BarrierCheckProblem p =
      domain.MakeCheckProblem(domain.Preset().shield, safe, safe, &dynamics);
  ASSERT_TRUE(static_cast<bool>(p.is_unsafe));
  EXPECT_FALSE(p.is_unsafe(o));
  EXPECT_EQ(dynamics->Describe(), PandaPushShieldModel(PandaPushShieldModelOptions{}).Describe());
  EXPECT_EQ(p.action_lo, Eigen::VectorXf::Constant(kActionDim, -1.0f));
  EXPECT_EQ(p.action_hi, Eigen::VectorXf::Constant(kActionDim, 1.0f));

  // Pitch alone, either side of the threshold; yaw does not tilt.
  Eigen::VectorXf s = o;
  s[kBlockEuler + 1] = static_cast<float>(topple - 0.01);
  EXPECT_NEAR(ObservedBlockTilt(s), topple - 0.01, 1e-6);
  EXPECT_FALSE(p.is_unsafe(s));
  s[kBlockEuler + 1] = static_cast<float>(-(topple + 0.01));
  EXPECT_TRUE(p.is_unsafe(s));
  s[kBlockEuler + 1] = 0.0f;
  s[kBlockEuler + 2] = 1.5f;
  EXPECT_FALSE(p.is_unsafe(s));
  // Roll and pitch 0.3 rad each: neither beyond 0.4, the tilt acos(cos^2 0.3) = 0.422 is.
  s[kBlockEuler] = 0.3f;
  s[kBlockEuler + 1] = 0.3f;
  EXPECT_NEAR(ObservedBlockTilt(s), std::acos(std::cos(0.3) * std::cos(0.3)), 1e-6);
  EXPECT_TRUE(p.is_unsafe(s));
  // The simulator put in that state measures the same tilt.
  sim.SetObservation(s);
  EXPECT_NEAR(sim.BlockTilt(), ObservedBlockTilt(s), 2e-3);
  EXPECT_TRUE(sim.Toppled());
  s[kBlockEuler] = 0.2f;
  s[kBlockEuler + 1] = 0.2f;  // 0.283 rad
  sim.SetObservation(s);
  EXPECT_NEAR(sim.BlockTilt(), ObservedBlockTilt(s), 2e-3);
  EXPECT_FALSE(sim.Toppled());
  EXPECT_FALSE(p.is_unsafe(s));
}

TEST(PandaPushDomain, ReadsTheReleasedData) {
  const std::string dir = std::string(SECURE_SHARED_DIR) + "/data/panda_push";
  Rng rng(1);
  PandaSafeOptions safe;
  safe.count = 500;
  ReleasedPandaData r;
  try {
    r = ReadReleasedPandaData(dir, safe, 1476, rng);
  } catch (const Error& e) {
    GTEST_SKIP() << "the released data is not available: " << e.what();
  }
  EXPECT_EQ(r.demonstrations.num_episodes(), 2);
  EXPECT_EQ(r.demonstrations.num_steps(), 246);
  EXPECT_EQ(r.safe.size(), 500);
  EXPECT_EQ(r.near_dangerous.size(), 1476);
  for (long i = 0; i < r.near_dangerous.size(); ++i)
    EXPECT_FALSE(r.near_dangerous.states.col(i).isZero(0.0f));
  EXPECT_THROW(ReadReleasedPandaData("/nonexistent", safe, 10, rng), Error);
  // Asking for more states than the files hold is an error, not fewer states.
  EXPECT_THROW(ReadReleasedPandaData(dir, safe, 5000, rng), Error);
  const ReleasedPandaFiles files = ReadReleasedPandaFiles(dir);
  EXPECT_EQ(files.near_dangerous.size(), 4380);  // 4381 rows, the all-zero one dropped
}

}  // namespace
}  // namespace secure::domains::panda_push

namespace secure::domains::panda_push {
namespace {

// Pixels that look like the block (red) in a frame.
long RedPixels(const Frame& f) {
  long n = 0;
  for (size_t i = 0; i + 2 < f.rgb.size(); i += 3)
    if (f.rgb[i] > 120 && f.rgb[i + 1] < 90 && f.rgb[i + 2] < 90) ++n;
  return n;
}

TEST(PandaPushRender, FramesShowTheSceneWithTheBlock) {
  PandaPushEnv env(PandaPushOptions{}, PandaPushShieldModelOptions{});
  ASSERT_TRUE(env.CanRender());
  Rng rng(1);
  Eigen::VectorXf o(kObservationDim);
  env.Reset(rng, o);
  Frame first, again;
  env.Render(160, 120, &first);
  ASSERT_EQ(first.width, 160);
  ASSERT_EQ(first.height, 120);
  ASSERT_EQ(first.rgb.size(), 160u * 120u * 3u);
  // Not blank: many distinct colours, and the red block covers a visible patch.
  long differing = 0;
  for (size_t i = 3; i < first.rgb.size(); i += 3)
    if (first.rgb[i] != first.rgb[0] || first.rgb[i + 1] != first.rgb[1]) ++differing;
  EXPECT_GT(differing, 160 * 120 / 4);
  EXPECT_GT(RedPixels(first), 100);
  // Rendering does not change the state; the same state gives the same frame.
  Eigen::VectorXf before(kObservationDim), after(kObservationDim);
  env.sim().Observe(before);
  env.Render(160, 120, &again);
  env.sim().Observe(after);
  EXPECT_EQ(before, after);
  EXPECT_EQ(first.rgb, again.rgb);
  // The frame follows the state: a toppled block looks different.
  Eigen::VectorXf tipped = before;
  tipped[kBlockEuler + 1] = 1.3f;
  tipped[kBlockPos + 2] = 0.06f;
  env.sim().SetObservation(tipped);
  Frame toppled;
  env.Render(160, 120, &toppled);
  EXPECT_NE(toppled.rgb, first.rgb);
  EXPECT_GT(RedPixels(toppled), 50);
  EXPECT_THROW(env.Render(4000, 120, &toppled), Error);
  EXPECT_THROW(env.Render(0, 120, &toppled), Error);
}

}  // namespace
}  // namespace secure::domains::panda_push

// shield_model: {kind: learned, path: FILE}: the environment's shield model is the learned
// ensemble (secure/dynamics); a model of other features, or no path, is refused naming the file.
class PandaPushLearnedModel : public secure::test::TempDirTest {};
TEST_F(PandaPushLearnedModel, TheConfigSelectsALearnedEnsemble) {
  using namespace secure;
  namespace pp = secure::domains::panda_push;
  dynamics::EnsembleDynamics e;
  e.state_features = pp::ObservationFeatures();
  e.action_features = pp::ActionFeatures();
  const int in = pp::kObservationDim + pp::kActionDim;
  for (int k = 0; k < 2; ++k)
    e.members.push_back(nn::RandomMlpParams(
        nn::MlpSpec{in, {8}, pp::kObservationDim, nn::Activation::kTanh}, 3 + k));
  e.input = nn::Normalizer::Identity(in);
  e.delta = nn::Normalizer::Identity(pp::kObservationDim);
  const std::string path = PathOf("panda.model");
  e.Save(path);
  pp::PandaPushShieldModelOptions options;
  options.kind = "learned";
  options.path = path;
  const pp::PandaPushEnv env(pp::PandaPushOptions{}, options);
  EXPECT_HAS(env.ShieldModel().Describe(), "ensemble of 2");
  EXPECT_FALSE(env.ShieldModelIsExact());
  EXPECT_HAS(env.Clone()->ShieldModel().Describe(), "ensemble of 2");
  EXPECT_EQ(options.ToJson()["path"], path);

  e.state_features.back() = "other";
  e.Save(PathOf("other.model"));
  options.path = PathOf("other.model");
  EXPECT_HAS(test::ErrorOf([&] { pp::PandaPushEnv bad(pp::PandaPushOptions{}, options); }),
             "other.model: the learned dynamics predicts 18 features");
  options.path.clear();
  EXPECT_HAS(test::ErrorOf([&] { options.Validate(); }), "PandaPushShieldModelOptions::path");
}
