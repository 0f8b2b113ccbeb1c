// The coffee-placing plug-in: the MuJoCo model (the shared Panda carrying a cup), the cup's tilt,
// the person's reach for a book, the thresholds and the violation test, the participants (their
// draws, demonstrations and labels), the shield's model, the population and the domain's options.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>

#include "domains/coffee_placing/coffee_placing.h"
#include "domains/coffee_placing/domain.h"
#include "domains/coffee_placing/participants.h"
#include "secure/common/error.h"

namespace secure::domains::coffee_placing {
namespace {

// A person who never reaches (the reach starts after the episode).
CoffeePlacingOptions StillPerson() {
  CoffeePlacingOptions o;
  o.person.start_time = {100.0, 100.0};
  return o;
}

TEST(CoffeePlacingModel, LoadsWithTheCupAtTheStartAndHoldsStill) {
  // The model loads without MuJoCo warnings (the loader fails on any); Step() checks them too.
  CoffeePlacingSim sim(StillPerson());
  Rng rng(1);
  sim.Reset(rng);
  Eigen::VectorXf o(kObservationDim), after(kObservationDim);
  sim.Observe(o);
  const CoffeePlacingOptions& t = sim.options();
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(o[kEePos + k], t.start[k], t.start_noise + 0.005);
  EXPECT_EQ(o[kTilt], 0.0f);
  EXPECT_GT(o[kClearance], 0.25);  // the arm at rest, far from the cup
  for (int step = 0; step < 25; ++step) sim.Step(Eigen::Vector4f::Zero());
  sim.Observe(after);
  EXPECT_LT((after.head<3>() - o.head<3>()).norm(), 0.01);
  EXPECT_LT(std::abs(after[kTilt]), 0.05);
  EXPECT_FALSE(sim.Placed());
}

TEST(CoffeePlacingTask, TheTiltActionTurnsTheCupAndAcceleratingTiltsIt) {
  CoffeePlacingSim sim(StillPerson());
  Rng rng(2);
  sim.Reset(rng);
  sim.Step(Eigen::Vector4f(0, 0, 0, 1));
  EXPECT_NEAR(sim.tilt(), sim.options().tilt_scale, 0.02);
  sim.Step(Eigen::Vector4f(0, 0, 0, -1));
  EXPECT_NEAR(sim.tilt(), 0.0, 0.02);
  // A sudden start along -x tilts the cup by about coupling * delta vx (negative).
  sim.Step(Eigen::Vector4f(-1, 0, 0, 0));
  EXPECT_LT(sim.tilt(), -0.2);
}

TEST(CoffeePlacingTask, CarryingTheCupDownOntoTheSquareSucceeds) {
  const CoffeePlacingOptions task = StillPerson();
  CoffeePlacingEnv env(task, CoffeeShieldModelOptions{}, Thresholds{});
  Rng rng(3);
  Eigen::VectorXf o(kObservationDim);
  env.Reset(rng, o);
  const Participant careful = MeanParticipant(PopulationRanges{});
  bool placed = false, violated = false;
  for (int t = 0; t < task.max_steps && !placed; ++t) {
    const Eigen::Vector4f a = DemonstratorAction(task, CoffeeDemonstrationOptions{}, careful, o);
    const StepOutcome r = env.Step(a, o);
    placed = r.reached_goal;
    violated = violated || r.collided;
  }
  EXPECT_TRUE(placed);
  EXPECT_FALSE(violated);
  EXPECT_NEAR(o[kEePos], task.target[0], task.target_half_size);
  EXPECT_NEAR(o[kEePos + 1], task.target[1], task.target_half_size);
}

TEST(CoffeePlacingThresholds, AViolationOfDistanceOrTiltIsDetected) {
  const Thresholds t{0.15, 0.25};
  EXPECT_FALSE(t.Violated(0.2, 0.1));
  EXPECT_TRUE(t.Violated(0.1, 0.1));   // too close
  EXPECT_TRUE(t.Violated(0.2, 0.3));   // tilted too far
  EXPECT_TRUE(t.Violated(0.2, -0.3));  // either way
  // In the environment: the cup tilted beyond the threshold is a violation (collided).
  CoffeePlacingEnv env(StillPerson(), CoffeeShieldModelOptions{}, t);
  Rng rng(4);
  Eigen::VectorXf o(kObservationDim);
  env.Reset(rng, o);
  EXPECT_FALSE(env.Step(Eigen::Vector4f(0, 0, 0, 1), o).collided);  // 0.1 rad
  EXPECT_FALSE(env.Step(Eigen::Vector4f(0, 0, 0, 1), o).collided);  // 0.2 rad
  EXPECT_TRUE(env.Step(Eigen::Vector4f(0, 0, 0, 1), o).collided);   // 0.3 rad
  // And the hand next to the person's arm: the arm's wrist put on the cup's path.
  const PersonOptions p;
  const ArmPose arm = ArmPoseForWrist(p, Eigen::Vector3d(0.17, -0.12, 0.15));
  EXPECT_LT(Clearance(p, Eigen::Vector3d(0.17, -0.18, 0.2), 0.0, arm), t.comfort_distance);
  EXPECT_TRUE(t.Violated(Clearance(p, Eigen::Vector3d(0.17, -0.18, 0.2), 0.0, arm), 0.0));
}

TEST(CoffeePlacingPerson, ReachesGoForABookAndComeBack) {
  const PersonOptions p;
  Rng rng(5);
  for (int i = 0; i < 20; ++i) {
    const BookReach r = DrawBookReach(p, rng);
    ASSERT_GE(r.book, 0);
    ASSERT_LT(r.book, 4);
    EXPECT_NEAR(r.goal.x(), p.book_x[static_cast<std::size_t>(r.book)], 1e-12);
    EXPECT_LT((r.Wrist(p, r.start + r.travel + 0.5 * r.dwell) - r.goal).norm(), 1e-9);
    EXPECT_LT((r.Wrist(p, r.start + 2 * r.travel + r.dwell + 1) -
               Eigen::Vector3d(p.rest[0], p.rest[1], p.rest[2]))
                  .norm(),
              1e-9);
  }
}

TEST(CoffeePlacingParticipants, DeterministicFromTheSeedAndWithinTheDocumentedRanges) {
  const PopulationRanges r;
  for (int i = 0; i < 12; ++i) {
    const Participant a = DrawParticipant(r, 7, i, 1.0), b = DrawParticipant(r, 7, i, 1.0);
    EXPECT_EQ(a.ToJson(), b.ToJson());
    EXPECT_GE(a.thresholds.comfort_distance, 0.08);
    EXPECT_LE(a.thresholds.comfort_distance, 0.22);
    EXPECT_GE(a.thresholds.max_tilt, 0.13);
    EXPECT_LE(a.thresholds.max_tilt, 0.37);
    EXPECT_GE(a.caution, r.caution[0]);
    EXPECT_LE(a.caution, r.caution[1]);
    EXPECT_GE(a.label_noise, r.label_noise[0]);
    EXPECT_LE(a.label_noise, r.label_noise[1]);
    // Spread 0: every participant has the mean thresholds; other constants unchanged.
    const Participant z = DrawParticipant(r, 7, i, 0.0);
    EXPECT_EQ(z.thresholds.comfort_distance, r.comfort_mean);
    EXPECT_EQ(z.thresholds.max_tilt, r.tilt_mean);
    EXPECT_EQ(z.caution, a.caution);
    // Half the spread: half as far from the mean.
    const Participant h = DrawParticipant(r, 7, i, 0.5);
    EXPECT_NEAR(h.thresholds.comfort_distance - r.comfort_mean,
                0.5 * (a.thresholds.comfort_distance - r.comfort_mean), 1e-12);
  }
  EXPECT_NE(DrawParticipant(r, 7, 0, 1.0).ToJson(), DrawParticipant(r, 8, 0, 1.0).ToJson());
  EXPECT_NE(DrawParticipant(r, 7, 0, 1.0).ToJson(), DrawParticipant(r, 7, 1, 1.0).ToJson());
  EXPECT_THROW(DrawParticipant(r, 7, 0, -0.1), Error);
}

TEST(CoffeePlacingData, DemonstrationsMostlyPlaceTheCupWithinTheParticipantsThresholds) {
  const CoffeePlacingDomainOptions o =
      CoffeePlacingDomainOptions::For(experiments::Profile::kQuick);
  for (int i = 0; i < 3; ++i) {
    const Participant p = DrawParticipant(o.population, 11, i, 1.0);
    const CoffeeDemonstrations d =
        GenerateCoffeeDemonstrations(o.task, o.demonstrations, p, 100 + i);
    const long kept = d.trajectories.num_episodes();
    const long tried = kept + d.discarded_violating + d.discarded_failed;
    EXPECT_GE(d.trajectories.num_steps(), o.demonstrations.states);
    // Most of the scripted demonstrator's episodes put the cup down without a violation of the
    // participant's own thresholds.
    EXPECT_GT(double(kept) / double(tried), 0.5)
        << "participant " << i << ": " << kept << " kept, " << d.discarded_violating
        << " violated, " << d.discarded_failed << " failed";
    // Every kept state keeps the participant's thresholds.
    for (long c = 0; c < d.trajectories.num_steps(); ++c) {
      const Eigen::VectorXf s = d.trajectories.states.col(c);
      ASSERT_FALSE(p.thresholds.Violated(s[kClearance], s[kTilt])) << "state " << c;
    }
  }
}

TEST(CoffeePlacingData, AParticipantsLabelsFollowTheirThresholds) {
  const CoffeePlacingDomainOptions o =
      CoffeePlacingDomainOptions::For(experiments::Profile::kQuick);
  const Participant p = DrawParticipant(o.population, 12, 3, 1.0);
  const experiments::DomainData d = ParticipantData(o, p, 200);
  ASSERT_EQ(d.safe.size(), o.labels.safe);
  ASSERT_EQ(d.near_dangerous.size(), o.labels.unsafe);
  long agree = 0;
  for (long c = 0; c < d.safe.size(); ++c) {
    const Eigen::VectorXf s = d.safe.states.col(c);
    EXPECT_NEAR(s[kClearance], ObservedClearance(o.task.person, s), 1e-5);
    agree += !p.thresholds.Violated(s[kClearance], s[kTilt]);
  }
  for (long c = 0; c < d.near_dangerous.size(); ++c) {
    const Eigen::VectorXf s = d.near_dangerous.states.col(c);
    agree += p.thresholds.Violated(s[kClearance], s[kTilt]);
  }
  const double n = double(d.safe.size() + d.near_dangerous.size());
  // All but the flipped ones (label noise, plus a binomial allowance).
  EXPECT_GE(agree / n, 1.0 - p.label_noise - 0.04) << "label noise " << p.label_noise;
  // Another participant with other thresholds labels the same states differently somewhere.
  const Participant q = DrawParticipant(o.population, 12, 4, 1.0);
  long differ = 0;
  for (long c = 0; c < d.safe.size(); ++c) {
    const Eigen::VectorXf s = d.safe.states.col(c);
    differ += p.thresholds.Violated(s[kClearance], s[kTilt]) !=
              q.thresholds.Violated(s[kClearance], s[kTilt]);
  }
  EXPECT_GT(differ, 0);
}

TEST(CoffeePlacingShieldModel, MovesTheHandByTheActionTiltsAndRecomputesTheClearance) {
  const CoffeePlacingOptions task;
  CoffeeShieldModel model(CoffeeShieldModelOptions{}, task);
  CoffeePlacingSim sim(task);
  Rng rng(6);
  sim.Reset(rng);
  Eigen::VectorXf o(kObservationDim);
  sim.Observe(o);
  o[kWristVel] = 0.5f;
  Eigen::MatrixXf actions(kActionDim, 1);
  actions << -1, 0, 0, 0.5;
  Eigen::MatrixXf next(kObservationDim, 1);
  model.Step(o, actions, next);
  EXPECT_NEAR(next(kEePos, 0), o[kEePos] - 0.05, 1e-6);
  EXPECT_NEAR(next(kEeVel, 0), -1.25, 1e-6);
  EXPECT_NEAR(next(kTilt, 0), o[kTilt] + 0.05 + task.tilt_coupling * (-1.25 - o[kEeVel]), 1e-5);
  EXPECT_NEAR(next(kWrist, 0), o[kWrist] + 0.04 * 0.5, 1e-6);
  EXPECT_NEAR(next(kClearance, 0), ObservedClearance(task.person, next.col(0)), 1e-6);
}

// The barrier check's unsafe test (c): a violation of the mean participant's thresholds, from the
// observation's positions and tilt; the region keeps the clearance feature consistent with them.
TEST(CoffeePlacingCheck, TheUnsafeTestIsAViolationOfTheMeanParticipantsThresholds) {
  const CoffeePlacingDomain domain(experiments::Profile::kQuick);
  const Thresholds mean = MeanParticipant(domain.options().population).thresholds;
  CoffeePlacingSim sim(StillPerson());
  Rng rng(7);
  sim.Reset(rng);
  Eigen::VectorXf o(kObservationDim);
  sim.Observe(o);  // the person at rest, far from the cup, which is upright
  ASSERT_GT(o[kClearance], mean.comfort_distance);
  data::StateSet set{"one state", ObservationFeatures(), o};
  std::unique_ptr<DynamicsModel> dynamics;
  const cbf::BarrierCheckProblem p =
      domain.MakeCheckProblem(domain.Preset().shield, set, set, &dynamics);
  ASSERT_TRUE(static_cast<bool>(p.is_unsafe));
  EXPECT_EQ(p.action_lo.size(), kActionDim);
  EXPECT_FALSE(p.is_unsafe(o));
  Eigen::VectorXf s = o;
  s[kTilt] = static_cast<float>(mean.max_tilt + 0.01);
  EXPECT_TRUE(p.is_unsafe(s));
  s[kTilt] = static_cast<float>(mean.max_tilt - 0.01);
  EXPECT_FALSE(p.is_unsafe(s));
  // The arm moved next to the hand: judged by the positions, not by the stale clearance feature.
  const ArmPose arm =
      ArmPoseForWrist(domain.options().task.person,
                      Eigen::Vector3d(o[kEePos], o[kEePos + 1] + 0.08, o[kEePos + 2]));
  for (int k = 0; k < 3; ++k) {
    s[kWrist + k] = static_cast<float>(arm.wrist[k]);
    s[kElbow + k] = static_cast<float>(arm.elbow[k]);
    s[kHandTip + k] = static_cast<float>(arm.tip[k]);
  }
  ASSERT_LT(ObservedClearance(domain.options().task.person, s), mean.comfort_distance);
  EXPECT_TRUE(p.is_unsafe(s));
  ASSERT_TRUE(static_cast<bool>(p.project));
  p.project(s);
  EXPECT_NEAR(s[kClearance], ObservedClearance(domain.options().task.person, s), 1e-6);
  Rng region(8);
  Eigen::VectorXf r(kObservationDim);
  for (int i = 0; i < 100; ++i) {
    p.sample_region(region, r);
    EXPECT_NEAR(r[kClearance], ObservedClearance(domain.options().task.person, r), 1e-5);
    EXPECT_LE(std::abs(r[kTilt]), kMaxTilt);
  }
}

TEST(CoffeePlacingPopulation, EnvironmentsJudgeByTheParticipantsThresholds) {
  const CoffeePlacingDomain domain(experiments::Profile::kQuick);
  experiments::PopulationOptions po;
  po.participants = 4;
  po.seed = 3;
  const std::unique_ptr<experiments::Population> pop = domain.MakePopulation(po);
  ASSERT_EQ(pop->size(), 4);
  const auto& cp = static_cast<const CoffeePopulation&>(*pop);
  for (int p = 0; p < 4; ++p) {
    const std::unique_ptr<Environment> env = pop->MakeEnvironment(p);
    const auto& ce = static_cast<const CoffeePlacingEnv&>(*env);
    EXPECT_EQ(ce.thresholds().comfort_distance, cp.participant(p).thresholds.comfort_distance);
    EXPECT_EQ(pop->Participant(p)["max_tilt"].get<double>(), cp.participant(p).thresholds.max_tilt);
    Eigen::VectorXf o = Eigen::VectorXf::Zero(kObservationDim);
    o[kClearance] = 1.0f;
    EXPECT_TRUE(pop->HeldWithMargin(p, o));
    o[kClearance] = static_cast<float>(cp.participant(p).thresholds.comfort_distance + 0.01);
    EXPECT_FALSE(pop->HeldWithMargin(p, o));  // held, but not with margin
  }
  ASSERT_TRUE(pop->PaperReference().has_value());
  EXPECT_EQ(pop->PaperReference()->rows.size(), 3u);
  po.threshold_spread = 2.0;
  EXPECT_THROW(domain.MakePopulation(po), Error);
}

TEST(CoffeePlacingDomain, OptionsRejectBadValuesAndUnknownKeys) {
  CoffeePlacingDomain domain(experiments::Profile::kQuick);
  EXPECT_NO_THROW(domain.Validate());
  EXPECT_THROW(domain.ApplyYaml(YAML::Load("{nonsense: 1}"), "t.yaml"), Error);
  CoffeePlacingDomain bad(experiments::Profile::kQuick);
  bad.ApplyYaml(YAML::Load("{task: {tilt_scale: 0}}"), "t.yaml");
  EXPECT_THROW(bad.Validate(), Error);
  domain.ApplyYaml(YAML::Load("{population: {comfort_mean: 0.2}, margin_tilt: 0.1}"), "t.yaml");
  EXPECT_EQ(domain.options().population.comfort_mean, 0.2);
  EXPECT_EQ(domain.OptionsJson()["margin_tilt"].get<double>(), 0.1);
}

}  // namespace
}  // namespace secure::domains::coffee_placing
