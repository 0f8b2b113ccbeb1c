// The kitchen-cutting labeller (KitchenCuttingDomain::Label): the person's rule that made the
// near-dangerous states (JudgeKitchenState, data.h) answers for any state; its label noise; the
// rows it rejects.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "domains/kitchen_cutting/data.h"
#include "domains/kitchen_cutting/domain.h"
#include "secure/common/error.h"
#include "tests/test_util.h"

namespace secure::domains::kitchen_cutting {
namespace {

// The generator's states with its own labels: every near-dangerous state satisfies a clause of
// the rule (the generator accepts a draw by it), so the labeller calls it near-dangerous; the
// safe states are the careful demonstrator's, which the rule calls safe but for the few where
// the person's arm is moving at the blade while the demonstrator lifts it away (measured on data
// seed 4000, the preset's: 5 of 450, clause (b): the arm at 0.4-0.6 m/s, 0.10-0.12 m from the
// edge; the label check finds about 1 % of the safe states dangerous in physics).
TEST(KitchenLabeller, AgreesWithTheGeneratorsOwnLabels) {
  const KitchenCuttingDomain domain;
  ASSERT_TRUE(domain.HasLabeller());
  EXPECT_NE(domain.LabellerDescription().find("0.3 s"), std::string::npos);
  const experiments::DomainData d = domain.GenerateData(4000);
  const std::vector<int> near = domain.Label(d.near_dangerous.states, 1);
  const std::vector<int> safe = domain.Label(d.safe.states, 1);
  EXPECT_EQ(std::count(near.begin(), near.end(), 0), d.near_dangerous.size());
  EXPECT_GE(std::count(safe.begin(), safe.end(), 1), d.safe.size() - 15);
  // The person always answers.
  EXPECT_EQ(std::count(near.begin(), near.end(), -1) + std::count(safe.begin(), safe.end(), -1), 0);
}

// Scenario (d) (the person's real reach, off by default) is made from the reach's future, which
// the rule cannot see: the labeller calls near-dangerous only those the arm's extrapolation
// catches (measured: 70 of 96 on data seed 4000); (a)-(c) are all caught.
TEST(KitchenLabeller, ReachPrecursorStatesAreOnlyPartlyCaughtByTheRule) {
  KitchenCuttingDomain domain;
  domain.ApplyYaml(YAML::Load("{near_dangerous: {p_reach: 0.3}}"), "test.yaml");
  const KitchenCuttingDomainOptions o = [] {
    KitchenCuttingDomainOptions x;
    x.near_dangerous.p_reach = 0.3;
    return x;
  }();
  KitchenDemonstrationOptions demo = o.demonstrations;
  demo.seed = 4000;
  const KitchenDemonstrations demos = GenerateKitchenDemonstrations(o.task, demo);
  Rng rng(4001);
  KitchenSafeStates(demos, o.safe, rng);  // the draws of GenerateData
  std::vector<NearDangerousScenario> kinds;
  const data::StateSet near =
      KitchenNearDangerousStates(o.task, demos, o.near_dangerous, rng, &kinds);
  const std::vector<int> labels = domain.Label(near.states, 1);
  long reach = 0, reach_caught = 0, others_missed = 0;
  for (std::size_t i = 0; i < kinds.size(); ++i) {
    if (kinds[i] == NearDangerousScenario::kReach) {
      ++reach;
      reach_caught += labels[i] == 0 ? 1 : 0;
    } else {
      others_missed += labels[i] == 0 ? 0 : 1;
    }
  }
  EXPECT_EQ(others_missed, 0);
  EXPECT_GT(reach, 50);
  EXPECT_GT(reach_caught, reach / 2);
  EXPECT_LT(reach_caught, reach);
}

TEST(KitchenLabeller, IsDeterministicPerSeedAndFlipsAtTheConfiguredRate) {
  KitchenCuttingDomain clean(experiments::Profile::kQuick);
  const experiments::DomainData d = clean.GenerateData(7);
  // 20 copies of the 400 states: 8000 answers.
  Eigen::MatrixXf states(kObservationDim, 0);
  for (const data::StateSet* s : {&d.safe, &d.near_dangerous}) {
    Eigen::MatrixXf grown(kObservationDim, states.cols() + 10 * s->size());
    grown << states, s->states.replicate(1, 10);
    states = grown;
  }
  const std::vector<int> truth = clean.Label(states, 3);
  EXPECT_EQ(truth, clean.Label(states, 4));  // no noise: the seed does not matter

  KitchenCuttingDomain noisy(experiments::Profile::kQuick);
  noisy.ApplyYaml(YAML::Load("{near_dangerous: {label_noise: 0.2}}"), "test.yaml");
  EXPECT_EQ(noisy.OptionsJson()["near_dangerous"]["label_noise"], 0.2);
  EXPECT_FALSE(clean.OptionsJson()["near_dangerous"].contains("label_noise"));
  const std::vector<int> a = noisy.Label(states, 3);
  EXPECT_EQ(a, noisy.Label(states, 3));
  const std::vector<int> b = noisy.Label(states, 4);
  EXPECT_NE(a, b);
  long flipped = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) flipped += a[i] != truth[i] ? 1 : 0;
  // Binomial(8000, 0.2): sd 0.0045; the seed is fixed, the band is 4.5 sd wide either side.
  const double rate = double(flipped) / double(truth.size());
  EXPECT_NEAR(rate, 0.2, 0.02);

  KitchenCuttingDomain bad;
  bad.ApplyYaml(YAML::Load("{near_dangerous: {label_noise: 0.7}}"), "test.yaml");
  EXPECT_THROW(bad.Validate(), Error);
  EXPECT_THROW(bad.Label(states.leftCols(1), 0), Error);
}

TEST(KitchenLabeller, JudgesEachClauseOfTheRule) {
  const KitchenCuttingOptions task;
  const KitchenCuttingDomain domain(experiments::Profile::kQuick);
  const experiments::DomainData d = domain.GenerateData(5);
  // A safe demonstration state the rule calls safe; then the arm put where the edge is: dangerous.
  const std::vector<int> labels = domain.Label(d.safe.states, 0);
  long i = 0;
  while (labels[static_cast<std::size_t>(i)] != 1) ++i;
  Eigen::VectorXf o = d.safe.states.col(i);
  EXPECT_EQ(JudgeKitchenState(task, KitchenNearDangerousOptions{}, o), KitchenJudgement::kSafe);
  Eigen::VectorXf touching = o;
  for (int k = 0; k < 3; ++k) {
    const float shift = o[kBlade + k] - o[kWrist + k];
    touching[kWrist + k] += shift;
    touching[kHandTip + k] += shift;
  }
  EXPECT_EQ(JudgeKitchenState(task, KitchenNearDangerousOptions{}, touching),
            KitchenJudgement::kDangerous);
  EXPECT_EQ(domain.Label(touching, 0), std::vector<int>{0});
  // Clause (b): the arm moving so that its wrist is at the edge after look_ahead (0.3 s).
  Eigen::VectorXf moving = o;
  for (int k = 0; k < 3; ++k) {
    moving[kWristVel + k] = (o[kBlade + k] - o[kWrist + k]) / 0.3f;
    moving[kElbowVel + k] = moving[kWristVel + k];
  }
  EXPECT_EQ(JudgeKitchenState(task, KitchenNearDangerousOptions{}, moving),
            KitchenJudgement::kNearDangerous);
  // Clause (c): the knife moving at the resting arm instead.
  Eigen::VectorXf knife = o;
  for (int k = 0; k < 3; ++k) knife[kEeVel + k] = (o[kWrist + k] - o[kBlade + k]) / 0.3f;
  EXPECT_EQ(JudgeKitchenState(task, KitchenNearDangerousOptions{}, knife),
            KitchenJudgement::kNearDangerous);
}

TEST(KitchenLabeller, RejectsRowsItCannotJudge) {
  const KitchenCuttingDomain domain(experiments::Profile::kQuick);
  const Eigen::MatrixXf narrow = Eigen::MatrixXf::Zero(21, 2);
  EXPECT_EQ(test::ErrorOf([&] { domain.Label(narrow, 0); }),
            "kitchen-cutting labeller: states have 21 features, expected 26 (the "
            "observation: ee_x, ..., lifted)");
  Eigen::MatrixXf states = domain.GenerateData(5).safe.states.leftCols(3);
  states(kWrist, 2) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(test::ErrorOf([&] { domain.Label(states, 0); }),
            "kitchen-cutting labeller: state 2, feature wrist_x = nan: not finite "
            "(the person cannot judge it)");
}

}  // namespace
}  // namespace secure::domains::kitchen_cutting
