// The kitchen-cutting plug-in: the MuJoCo model (the shared Panda with a knife), the cut's
// progress, the person's arm and the dangerous test, the demonstrator, the data generators, the
// label check against physics, the shield's model and the domain's options.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>

#include "domains/kitchen_cutting/data.h"
#include "domains/kitchen_cutting/domain.h"
#include "domains/kitchen_cutting/kitchen_cutting.h"
#include "secure/common/error.h"
#include "tests/test_util.h"

namespace secure::domains::kitchen_cutting {
namespace {

// A person who never reaches in: the goal beside the board, starting late.
KitchenCuttingOptions AwayTask() {
  KitchenCuttingOptions o;
  o.human.into_probability = 0.0;
  o.human.start_time = {100.0, 100.0};
  return o;
}

TEST(KitchenCuttingModel, LoadsWithTheKnifeBelowTheHandAndHoldsStill) {
  // The model loads without MuJoCo warnings (the loader fails on any); Step() checks them too.
  KitchenCuttingSim sim(AwayTask());
  Rng rng(1);
  sim.Reset(rng);
  Eigen::VectorXf o(kObservationDim), after(kObservationDim);
  sim.Observe(o);
  // The released neutral posture: tool centre point near (0.093, 0, 0.121); the blade's edge
  // kBladeDrop below it.
  EXPECT_NEAR(o[kEePos], 0.093, 0.01);
  EXPECT_NEAR(o[kEePos + 2], 0.121, 0.01);
  // (The joint noise at reset tilts the hand a little.)
  for (int k = 0; k < 2; ++k) EXPECT_NEAR(o[kBlade + k], o[kEePos + k], 5e-3);
  EXPECT_NEAR(o[kBlade + 2], o[kEePos + 2] - kBladeDrop, 5e-3);
  EXPECT_EQ(o[kStrokes], 0.0f);
  EXPECT_EQ(o[kLifted], 1.0f);
  for (int t = 0; t < 25; ++t) sim.Step(Eigen::Vector3f::Zero());
  sim.Observe(after);
  EXPECT_LT((after.head<3>() - o.head<3>()).norm(), 0.005);
  EXPECT_FALSE(sim.Dangerous());
}

TEST(KitchenCuttingTask, StrokesOverTheLineCountAndTheBladeStopsAtTheBoard) {
  const KitchenCuttingOptions task = AwayTask();
  KitchenCuttingSim sim(task);
  Rng rng(2);
  sim.Reset(rng);
  Eigen::VectorXf o(kObservationDim);
  sim.Observe(o);
  double lowest = 1.0;
  bool down = true;
  for (int t = 0; t < task.max_steps && !sim.Succeeded(); ++t) {
    Eigen::Vector3f a = Eigen::Vector3f::Zero();
    a[0] = static_cast<float>(std::clamp((task.cut_line_x - o[kBlade]) / 0.05, -1.0, 1.0));
    a[1] = static_cast<float>(std::clamp((task.cut_line_y - o[kBlade + 1]) / 0.05, -1.0, 1.0));
    const bool over = std::abs(task.cut_line_x - o[kBlade]) < 0.01;
    if (o[kLifted] > 0.5f) down = true;
    if (o[kLifted] < 0.5f && down) down = false;
    a[2] = over ? (down ? -0.6f : 0.6f) : 0.0f;
    sim.Step(a);
    sim.Observe(o);
    lowest = std::min(lowest, static_cast<double>(o[kBlade + 2]));
  }
  EXPECT_TRUE(sim.Succeeded());
  EXPECT_EQ(sim.strokes(), task.strokes_required);
  EXPECT_FLOAT_EQ(o[kStrokes], 1.0f);
  // The target never goes below the board: the edge stops within a centimetre of it (tracking
  // overshoot; there is no contact force).
  EXPECT_GT(lowest, task.board_top - 0.01);
  EXPECT_LT(lowest, task.board_top + task.stroke_tolerance);
}

TEST(KitchenCuttingTask, StrokesAwayFromTheLineDoNotCount) {
  KitchenCuttingSim sim(AwayTask());
  Rng rng(3);
  sim.Reset(rng);
  // Straight down where the arm starts (x = 0.09, far from the line at 0.30 +- 0.04).
  for (int t = 0; t < 20; ++t) sim.Step(Eigen::Vector3f(0, 0, -1));
  for (int t = 0; t < 10; ++t) sim.Step(Eigen::Vector3f(0, 0, 1));
  for (int t = 0; t < 20; ++t) sim.Step(Eigen::Vector3f(0, 0, -1));
  EXPECT_EQ(sim.strokes(), 0);
}

TEST(KitchenCuttingHuman, ArmPoseKeepsItsSegmentLengthsAndPathsReturnToRest) {
  const HumanArmOptions h;
  const ArmPose p = ArmPoseForWrist(h, Eigen::Vector3d(0.30, 0.0, 0.06));
  EXPECT_NEAR((p.elbow - p.shoulder).norm(), h.upper_arm, 1e-9);
  EXPECT_NEAR((p.wrist - p.elbow).norm(), h.forearm, 1e-9);
  EXPECT_NEAR((p.tip - p.wrist).norm(), h.hand, 1e-9);
  EXPECT_LT(p.elbow.z(), p.shoulder.z());  // the elbow below the shoulder, above the table
  EXPECT_GT(p.elbow.z(), 0.0);
  EXPECT_GT(ArmPoseForWrist(h, Eigen::Vector3d(h.rest[0], h.rest[1], h.rest[2])).elbow.z(), 0.0);
  Rng rng(4);
  int into = 0;
  for (int i = 0; i < 400; ++i) {
    const ReachPath path = DrawReachPath(h, rng);
    into += path.into ? 1 : 0;
    const Eigen::Vector3d rest(h.rest[0], h.rest[1], h.rest[2]);
    EXPECT_NEAR((path.Wrist(h, 0.0) - rest).norm(), 0.0, 1e-12);
    EXPECT_NEAR((path.Wrist(h, path.start + path.travel) - path.goal).norm(), 0.0, 1e-9);
    EXPECT_NEAR((path.Wrist(h, 1e3) - rest).norm(), 0.0, 1e-12);
  }
  EXPECT_NEAR(into / 400.0, h.into_probability, 0.08);
}

TEST(KitchenCuttingHuman, TheBladeOnTheArmIsDangerousAndFarFromItIsNot) {
  const HumanArmOptions h;
  const ArmPose p = ArmPoseForWrist(h, Eigen::Vector3d(0.30, 0.0, 0.06));
  // The edge resting on the forearm's top (over the wrist): inside contact distance.
  const Eigen::Vector3d on_wrist(0.30, 0.0, 0.06 + h.forearm_radius + 0.005);
  EXPECT_LT(EdgeToArmDistance(h, on_wrist, p), 0.02);
  EXPECT_NEAR(EdgeToArmDistance(h, Eigen::Vector3d(0.30, 0.0, 0.06 + h.forearm_radius + 0.1), p),
              0.1, 0.01);
  EXPECT_GT(EdgeToArmDistance(h, Eigen::Vector3d(0.0, -0.3, 0.3), p), 0.2);
}

// The barrier check's unsafe test (c): the blade's edge within contact distance of the arm, both
// as the observation shows them (the shoulder fixed), either side of the threshold; the
// simulator put in the same state agrees.
TEST(KitchenCuttingCheck, TheUnsafeTestIsTheObservedEdgeWithinContactDistanceOfTheArm) {
  const KitchenCuttingDomain domain(experiments::Profile::kQuick);
  const KitchenCuttingOptions& task = domain.options().task;
  const HumanArmOptions& h = task.human;
  const ArmPose arm = ArmPoseForWrist(h, Eigen::Vector3d(0.30, 0.0, 0.06));
  Eigen::VectorXf o = Eigen::VectorXf::Zero(kObservationDim);
  for (int k = 0; k < 3; ++k) {
    o[kWrist + k] = static_cast<float>(arm.wrist[k]);
    o[kElbow + k] = static_cast<float>(arm.elbow[k]);
    o[kHandTip + k] = static_cast<float>(arm.tip[k]);
  }
  o[kLifted] = 1.0f;
  // The edge over the wrist at a height; the hand kBladeDrop above it.
  auto at = [&](double z) {
    Eigen::VectorXf s = o;
    s[kBlade] = 0.30f;
    s[kBlade + 2] = static_cast<float>(z);
    s[kEePos] = 0.30f;
    s[kEePos + 2] = static_cast<float>(z + kBladeDrop);
    return s;
  };
  const double top = 0.06 + h.forearm_radius;  // the forearm's surface over the wrist
  const Eigen::VectorXf near = at(top + task.contact_distance - 0.005);
  const Eigen::VectorXf clear = at(top + task.contact_distance + 0.005);
  const Eigen::Vector3d near_edge(near[kBlade], near[kBlade + 1], near[kBlade + 2]);
  EXPECT_NEAR(ObservedEdgeClearance(task, near), EdgeToArmDistance(h, near_edge, arm), 1e-6);
  EXPECT_LT(ObservedEdgeClearance(task, near), task.contact_distance);
  EXPECT_GT(ObservedEdgeClearance(task, clear), task.contact_distance);
  EXPECT_GT(ObservedEdgeClearance(task, at(top + 0.2)), 0.15);

  data::StateSet set{"two states", ObservationFeatures(), Eigen::MatrixXf(kObservationDim, 2)};
  set.states.col(0) = near;
  set.states.col(1) = clear;
  std::unique_ptr<DynamicsModel> dynamics;
  const cbf::BarrierCheckProblem p =
      domain.MakeCheckProblem(domain.Preset().shield, set, set, &dynamics);
  ASSERT_TRUE(static_cast<bool>(p.is_unsafe));
  EXPECT_TRUE(p.is_unsafe(near));
  EXPECT_FALSE(p.is_unsafe(clear));
  EXPECT_EQ(dynamics->Describe(), KitchenShieldModel(KitchenShieldModelOptions{}).Describe());
  EXPECT_EQ(p.action_lo, Eigen::VectorXf::Constant(kActionDim, -1.0f));
  EXPECT_DOUBLE_EQ(p.dt, domain.Preset().shield.dt);

  // The simulation in those states (the knife by IK, the arm at the observed points) measures the
  // same clearance with the knife's simulated orientation.
  KitchenCuttingSim sim(task);
  Rng rng(3);
  sim.Reset(rng);
  for (const Eigen::VectorXf& s : {near, clear}) {
    EXPECT_LT(sim.SetObservation(s), 0.01);
    EXPECT_NEAR(sim.Clearance(), ObservedEdgeClearance(task, s), 0.004);
  }
  // The region's samples stay above the board (the projection) and are finite.
  Rng region(5);
  Eigen::VectorXf r(kObservationDim);
  for (int i = 0; i < 200; ++i) {
    p.sample_region(region, r);
    ASSERT_TRUE(r.allFinite());
    EXPECT_GE(r[kBlade + 2], task.board_top - 1e-6);
  }
}

TEST(KitchenCuttingEnv, AStrokeOntoTheReachingArmIsDangerousAndEpisodesReplay) {
  KitchenCuttingOptions task;
  task.human.into_probability = 1.0;
  task.human.start_time = {0.0, 0.0};
  task.human.dwell = {2.0, 2.0};
  KitchenCuttingEnv env(task, KitchenShieldModelOptions{});
  Rng rng(5);
  Eigen::VectorXf o(kObservationDim), o2(kObservationDim);
  env.Reset(rng, o);
  // The knife goes over the line high up and waits while the arm reaches over the line, then
  // comes down onto it.
  bool dangerous = false;
  for (int t = 0; t < task.max_steps && !dangerous; ++t) {
    Eigen::VectorXf a(3);
    const float hover = static_cast<float>(std::clamp((0.2 - o[kBlade + 2]) / 0.05, -1.0, 1.0));
    a << static_cast<float>(std::clamp((task.cut_line_x - o[kBlade]) / 0.05, -1.0, 1.0)), 0.0f,
        t < 30 ? hover : -0.3f;
    dangerous = env.Step(a, o).collided;
    if (t < 30) {
      ASSERT_FALSE(dangerous) << t;
    }
  }
  EXPECT_TRUE(dangerous);
  // The same Rng state replays the same episode.
  Rng a_rng(9), b_rng(9);
  env.Reset(a_rng, o);
  KitchenCuttingEnv other(task, KitchenShieldModelOptions{});
  other.Reset(b_rng, o2);
  for (int t = 0; t < 30; ++t) {
    Eigen::VectorXf a = Eigen::VectorXf::Constant(3, 0.3f);
    env.Step(a, o);
    other.Step(a, o2);
  }
  EXPECT_EQ(o, o2);
}

TEST(KitchenCuttingShieldModel, MovesTheKnifeByTheActionAndTheArmAtItsVelocity) {
  KitchenShieldModel model(KitchenShieldModelOptions{});
  Eigen::VectorXf s = Eigen::VectorXf::LinSpaced(kObservationDim, 0.1f, 2.6f);
  Eigen::MatrixXf a(3, 2), next(kObservationDim, 2);
  a << 1.0f, 3.0f, -0.5f, 0.0f, 0.2f, -2.0f;  // the second column clips to (1, 0, -1)
  model.Step(s, a, next);
  for (int c = 0; c < 2; ++c) {
    for (int k = 0; k < 3; ++k) {
      const float ac = std::clamp(a(k, c), -1.0f, 1.0f);
      EXPECT_FLOAT_EQ(next(kEePos + k, c), s[kEePos + k] + 0.05f * ac);
      EXPECT_FLOAT_EQ(next(kBlade + k, c), s[kBlade + k] + 0.05f * ac);
      EXPECT_FLOAT_EQ(next(kEeVel + k, c), 1.25f * ac);
      EXPECT_FLOAT_EQ(next(kWrist + k, c), s[kWrist + k] + 0.04f * s[kWristVel + k]);
      EXPECT_FLOAT_EQ(next(kHandTip + k, c), s[kHandTip + k] + 0.04f * s[kWristVel + k]);
      EXPECT_FLOAT_EQ(next(kElbow + k, c), s[kElbow + k] + 0.04f * s[kElbowVel + k]);
    }
    EXPECT_EQ(next(kStrokes, c), s[kStrokes]);
    EXPECT_EQ(next(kLifted, c), s[kLifted]);
  }
}

TEST(KitchenCuttingData, DemonstrationsFinishSafelyAndSomeWaitForTheArm) {
  const KitchenCuttingDomainOptions d =
      KitchenCuttingDomainOptions::For(experiments::Profile::kQuick);
  KitchenDemonstrationOptions demo = d.demonstrations;
  demo.seed = 11;
  const KitchenDemonstrations demos = GenerateKitchenDemonstrations(d.task, demo);
  ASSERT_GE(demos.trajectories.num_steps(), demo.states);
  EXPECT_GT(demos.into_episodes, 0);  // some reaches went into the workspace, and were survived
  // Every kept episode ends with the cut done (strokes = 1 is observed after the last step only,
  // so the last state shows strokes_required - 1).
  for (long e = 0; e < demos.trajectories.num_episodes(); ++e) {
    const long last = demos.trajectories.episode_begin[e + 1] - 1;
    EXPECT_NEAR(demos.trajectories.states(kStrokes, last),
                float(d.task.strokes_required - 1) / float(d.task.strokes_required), 1e-6);
  }
  // Safe and near-dangerous states: the requested counts, finite; near-dangerous ones are close.
  Rng rng(12);
  const data::StateSet safe = KitchenSafeStates(demos, d.safe, rng);
  std::vector<NearDangerousScenario> kinds;
  const data::StateSet near =
      KitchenNearDangerousStates(d.task, demos, d.near_dangerous, rng, &kinds);
  EXPECT_EQ(safe.size(), d.safe.count);
  EXPECT_EQ(near.size(), d.near_dangerous.count);
  EXPECT_TRUE(near.states.allFinite());
  ASSERT_EQ(static_cast<long>(kinds.size()), near.size());
  for (long i = 0; i < near.size(); ++i) {
    const Eigen::VectorXf o = near.states.col(i);
    ArmPose p;
    p.shoulder = Eigen::Vector3d(d.task.human.shoulder[0], d.task.human.shoulder[1],
                                 d.task.human.shoulder[2]);
    p.wrist = o.segment<3>(kWrist).cast<double>();
    p.elbow = o.segment<3>(kElbow).cast<double>();
    p.tip = o.segment<3>(kHandTip).cast<double>();
    const double clearance =
        EdgeToArmDistance(d.task.human, o.segment<3>(kBlade).cast<double>(), p);
    EXPECT_GE(clearance, d.task.contact_distance - 1e-4);
    EXPECT_LE(clearance, d.near_dangerous.near_distance + 1e-4);
  }
}

TEST(KitchenCuttingData, LabelsHoldAgainstPhysics) {
  // From the safe states the motion continues safely; from the near-dangerous ones it reaches
  // the arm (docs/RESULTS.md has the full table: `secure demos check-labels`).
  KitchenCuttingDomain domain(experiments::Profile::kQuick);
  const std::vector<experiments::LabelCheckRow> rows = domain.CheckLabels(4000, 60);
  ASSERT_EQ(rows.size(), 4u);  // safe, then scenarios (a), (b), (c)
  EXPECT_EQ(rows[0].label, "safe");
  EXPECT_LE(rows[0].DangerousFraction(), 0.05);
  for (size_t r = 1; r < rows.size(); ++r) {
    EXPECT_EQ(rows[r].label, "near-dangerous");
    EXPECT_GE(rows[r].DangerousFraction(), 0.8) << rows[r].set;
  }
}

TEST(KitchenCuttingData, BladeIntoTheRestingArmStatesReachTheArmWhenContinued) {
  // Scenario (c), p_blade: the arm at rest near the edge, the end-effector moving towards it.
  // The default since 2026-12-02: shares 0.4 (a), 0.3 (b), 0.3 (c).
  KitchenCuttingDomain domain(experiments::Profile::kQuick);
  const KitchenCuttingDomainOptions& d = domain.options();
  EXPECT_EQ(d.near_dangerous.ToJson()["p_blade"], 0.3);
  EXPECT_EQ(d.near_dangerous.ToJson()["p_stroke"], 0.4);
  KitchenDemonstrationOptions demo = d.demonstrations;
  demo.seed = 11;
  const KitchenDemonstrations demos = GenerateKitchenDemonstrations(d.task, demo);
  Rng rng(12);
  std::vector<NearDangerousScenario> kinds;
  const data::StateSet near =
      KitchenNearDangerousStates(d.task, demos, d.near_dangerous, rng, &kinds);
  long blade = 0;
  for (long i = 0; i < near.size(); ++i) {
    if (kinds[static_cast<std::size_t>(i)] != NearDangerousScenario::kBlade) continue;
    ++blade;
    const Eigen::VectorXf o = near.states.col(i);
    EXPECT_EQ(o.segment<3>(kWristVel).norm(), 0.0f) << i;
    EXPECT_EQ(o.segment<3>(kElbowVel).norm(), 0.0f) << i;
    const float speed = o.segment<3>(kEeVel).norm();
    EXPECT_GE(speed, d.near_dangerous.blade_speed[0] - 1e-4) << i;
    EXPECT_LE(speed, d.near_dangerous.blade_speed[1] + 1e-4) << i;
    // Moving towards the arm: the edge gets closer to the wrist.
    const Eigen::Vector3f to_wrist = o.segment<3>(kWrist) - o.segment<3>(kBlade);
    EXPECT_GT(o.segment<3>(kEeVel).dot(to_wrist), 0.0f) << i;
  }
  EXPECT_GT(blade, near.size() / 5);
  EXPECT_LT(blade, near.size() / 2);
  // Against physics: continuing the motion reaches the arm.
  const std::vector<experiments::LabelCheckRow> rows = domain.CheckLabels(4000, 60);
  ASSERT_EQ(rows.size(), 4u);
  EXPECT_EQ(rows[3].set, "near-dangerous (blade into the resting arm)");
  EXPECT_GE(rows[3].DangerousFraction(), 0.9);
  // Off (p_blade 0): no state of (c), and no row for it.
  KitchenCuttingDomain off(experiments::Profile::kQuick);
  off.ApplyYaml(YAML::Load("{near_dangerous: {p_stroke: 0.6, p_blade: 0}}"), "test.yaml");
  const std::vector<experiments::LabelCheckRow> off_rows = off.CheckLabels(4000, 20);
  ASSERT_EQ(off_rows.size(), 3u);
  for (const experiments::LabelCheckRow& row : off_rows)
    EXPECT_EQ(row.set.find("resting"), std::string::npos) << row.set;
  // Its share must fit beside the strokes'.
  KitchenCuttingDomain bad(experiments::Profile::kQuick);
  bad.ApplyYaml(YAML::Load("{near_dangerous: {p_stroke: 0.6, p_blade: 0.5}}"), "test.yaml");
  EXPECT_HAS(test::ErrorOf([&] { bad.Validate(); }), "p_blade = 0.5");
}

TEST(KitchenCuttingRender, FramesShowTheSceneAndFollowThePersonsArm) {
  KitchenCuttingEnv env(KitchenCuttingOptions{}, KitchenShieldModelOptions{});
  ASSERT_TRUE(env.CanRender());
  Rng rng(1);
  Eigen::VectorXf o(kObservationDim), before(kObservationDim), after(kObservationDim);
  env.Reset(rng, o);
  Frame first, again;
  env.Render(160, 120, &first);
  ASSERT_EQ(first.width, 160);
  ASSERT_EQ(first.rgb.size(), 160u * 120u * 3u);
  long differing = 0;  // not blank
  for (size_t i = 3; i < first.rgb.size(); i += 3)
    if (first.rgb[i] != first.rgb[0] || first.rgb[i + 1] != first.rgb[1]) ++differing;
  EXPECT_GT(differing, 160 * 120 / 4);
  // Rendering does not change the state; the same state gives the same frame.
  env.sim().Observe(before);
  env.Render(160, 120, &again);
  env.sim().Observe(after);
  EXPECT_EQ(before, after);
  EXPECT_EQ(first.rgb, again.rgb);
  // The same robot state with the person's arm elsewhere (reaching over the board): the frame
  // changes, and comes back with the arm.
  Frame here, there, back;
  env.sim().SetObservation(before);
  env.Render(160, 120, &here);
  Eigen::VectorXf reaching = before;
  const ArmPose p = ArmPoseForWrist(HumanArmOptions{}, Eigen::Vector3d(0.30, 0.0, 0.07));
  for (int k = 0; k < 3; ++k) {
    reaching[kWrist + k] = static_cast<float>(p.wrist[k]);
    reaching[kElbow + k] = static_cast<float>(p.elbow[k]);
    reaching[kHandTip + k] = static_cast<float>(p.tip[k]);
  }
  env.sim().SetObservation(reaching);
  env.Render(160, 120, &there);
  env.sim().SetObservation(before);
  env.Render(160, 120, &back);
  EXPECT_NE(there.rgb, here.rgb);
  EXPECT_EQ(back.rgb, here.rgb);
}

TEST(KitchenCuttingDomain, OptionsRejectBadValuesAndUnknownKeys) {
  KitchenCuttingDomain domain(experiments::Profile::kQuick);
  EXPECT_NO_THROW(domain.Validate());
  EXPECT_THROW(domain.ApplyYaml(YAML::Load("{task: {bogus: 1}}"), "test.yaml"), Error);
  KitchenCuttingDomain bad(experiments::Profile::kQuick);
  bad.ApplyYaml(YAML::Load("{task: {human: {speed: [0.5, 0.1]}}}"), "test.yaml");
  EXPECT_HAS(test::ErrorOf([&] { bad.Validate(); }), "speed");
  KitchenCuttingDomain contact(experiments::Profile::kQuick);
  contact.ApplyYaml(YAML::Load("{task: {contact_distance: -1}}"), "test.yaml");
  EXPECT_THROW(contact.Validate(), Error);
  // The preset is Table 2's barrier and the shield looks one control period ahead.
  const experiments::ExperimentOptions p = KitchenCuttingDomain().Preset();
  EXPECT_EQ(p.flat_barrier.hidden,
            (std::vector<int>{32, 128, 128, 256, 256, 256, 256, 128, 128, 32}));
  EXPECT_EQ(p.flat_barrier.input_features, BarrierFeatures());
  EXPECT_DOUBLE_EQ(p.shield.dt, 0.04);
  EXPECT_EQ(KitchenCuttingDomain().options().demonstrations.states, 2000);
  EXPECT_EQ(KitchenCuttingDomain().options().safe.count, 450);
  EXPECT_EQ(KitchenCuttingDomain().options().near_dangerous.count, 450);
}

// Scenario (d), p_reach: the person's real reach, reach_gap before it touches the blade
// (domains/kitchen_cutting/precursor.h; issue 30 lever 5).
KitchenCuttingDomain ReachDomain(const std::string& yaml) {
  KitchenCuttingDomain d(experiments::Profile::kQuick);
  d.ApplyYaml(YAML::Load(yaml), "test.yaml");
  d.Validate();
  return d;
}

// The near-dangerous states of demonstrations drawn with `demo_seed`, their scenarios in `kinds`.
data::StateSet NearStates(const KitchenCuttingDomainOptions& d, std::uint64_t demo_seed,
                          std::uint64_t seed, std::vector<NearDangerousScenario>* kinds) {
  KitchenDemonstrationOptions demo = d.demonstrations;
  demo.seed = demo_seed;
  const KitchenDemonstrations demos = GenerateKitchenDemonstrations(d.task, demo);
  Rng rng(seed);
  return KitchenNearDangerousStates(d.task, demos, d.near_dangerous, rng, kinds);
}

TEST(KitchenCuttingData, ReachPrecursorStatesComeBeforeContactAndLeadToIt) {
  const KitchenCuttingDomain domain = ReachDomain("{near_dangerous: {p_reach: 0.3}}");
  const KitchenCuttingDomainOptions& d = domain.options();
  EXPECT_EQ(d.near_dangerous.ToJson()["p_reach"], 0.3);
  std::vector<NearDangerousScenario> kinds;
  const data::StateSet near = NearStates(d, 11, 12, &kinds);
  // The peak of a minimum-jerk reach is 1.875 times its mean speed.
  const double peak = 1.875 * d.task.human.speed[1];
  long reach = 0, arm = 0, fast = 0;
  for (long i = 0; i < near.size(); ++i) {
    const NearDangerousScenario k = kinds[static_cast<std::size_t>(i)];
    if (k == NearDangerousScenario::kArm) ++arm;
    if (k != NearDangerousScenario::kReach) continue;
    ++reach;
    const Eigen::VectorXf o = near.states.col(i);
    // Not yet in contact, and the arm moving as a reach does.
    EXPECT_GE(ObservedEdgeClearance(d.task, o), d.task.contact_distance) << i;
    const float speed = o.segment<3>(kWristVel).norm();
    EXPECT_GT(speed, 0.0f) << i;
    EXPECT_LE(speed, peak + 1e-3) << i;
    if (speed > 0.8f) ++fast;
    // The wrist on its way from the rest point into the workspace (towards -y).
    EXPECT_LT(o[kWristVel + 1], 0.0f) << i;
  }
  EXPECT_EQ(arm, 0);  // (d) takes (b)'s whole share here
  EXPECT_GT(reach, near.size() / 5);
  EXPECT_LT(reach, near.size() / 2);
  EXPECT_GT(fast, 0);  // the fast arms the scenario is for
  // Against physics (the label check: the arm moving on at its observed velocity, the knife
  // continuing): continuing leads to contact.
  const std::vector<experiments::LabelCheckRow> rows = domain.CheckLabels(4000, 60);
  ASSERT_EQ(rows.size(), 4u);  // safe, (a), (c), (d): no (b)
  EXPECT_EQ(rows[3].set, "near-dangerous (the person's reach, before contact)");
  EXPECT_GE(rows[3].DangerousFraction(), 0.8);
  // Off by default: no row, no key (the default's files keep their bytes).
  KitchenCuttingDomain off(experiments::Profile::kQuick);
  EXPECT_FALSE(off.options().near_dangerous.ToJson().contains("p_reach"));
  for (const experiments::LabelCheckRow& row : off.CheckLabels(4000, 10))
    EXPECT_EQ(row.set.find("reach"), std::string::npos) << row.set;
}

TEST(KitchenCuttingData, ReachPrecursorStatesAreDeterministicAndTheirGapMatters) {
  const KitchenCuttingDomain domain = ReachDomain("{near_dangerous: {p_reach: 0.3}}");
  const experiments::DomainData a = domain.GenerateData(7), b = domain.GenerateData(7);
  EXPECT_TRUE(a.near_dangerous.states.isApprox(b.near_dangerous.states, 0.0f));
  EXPECT_FALSE(a.near_dangerous.states.isApprox(domain.GenerateData(8).near_dangerous.states));
  // A longer gap puts the arm further from the blade.
  auto mean_clearance = [](const KitchenCuttingDomain& dom) {
    const KitchenCuttingDomainOptions& d = dom.options();
    std::vector<NearDangerousScenario> kinds;
    const data::StateSet near = NearStates(d, 3, 4, &kinds);
    double sum = 0;
    long n = 0;
    for (long i = 0; i < near.size(); ++i)
      if (kinds[static_cast<std::size_t>(i)] == NearDangerousScenario::kReach) {
        sum += ObservedEdgeClearance(d.task, near.states.col(i));
        ++n;
      }
    return n > 0 ? sum / n : -1.0;
  };
  const double near_gap =
      mean_clearance(ReachDomain("{near_dangerous: {p_reach: 0.3, reach_gap: [0.0, 0.04]}}"));
  const double far_gap =
      mean_clearance(ReachDomain("{near_dangerous: {p_reach: 0.3, reach_gap: [0.2, 0.3]}}"));
  EXPECT_GT(near_gap, 0.0);
  EXPECT_GT(far_gap, near_gap + 0.05);
}

TEST(KitchenCuttingData, ReachPrecursorOptionsAreValidated) {
  for (const auto& [yaml, says] :
       {std::pair<std::string, std::string>{"{near_dangerous: {p_reach: 0.5}}", "p_reach = 0.5"},
        {"{near_dangerous: {p_reach: -0.1}}", "p_reach = -0.1"},
        {"{near_dangerous: {p_reach: 0.2, reach_gap: [0.3, 0.1]}}", "reach_gap"},
        {"{near_dangerous: {p_reach: 0.2, reach_gap: [0.0, 2.0]}}", "reach_gap"}}) {
    KitchenCuttingDomain bad(experiments::Profile::kQuick);
    bad.ApplyYaml(YAML::Load(yaml), "test.yaml");
    try {
      bad.Validate();
      ADD_FAILURE() << "expected an error for " << yaml;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace secure::domains::kitchen_cutting
