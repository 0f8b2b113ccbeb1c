// The coffee-placing labeller (CoffeePlacingDomain::Label): the mean participant judges any
// state by their thresholds and answers with their label noise (ParticipantAnswersUnsafe,
// participants.h), the rule their data were labelled by; the rows it rejects.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <limits>
#include <string>
#include <vector>

#include "domains/coffee_placing/domain.h"
#include "domains/coffee_placing/participants.h"
#include "secure/common/error.h"
#include "tests/test_util.h"

namespace secure::domains::coffee_placing {
namespace {

// The generator's states (safe and unsafe) side by side, and how many answers differ from
// `expected` (1 for the first `safe` columns, 0 after).
Eigen::MatrixXf Both(const experiments::DomainData& d) {
  Eigen::MatrixXf m(kObservationDim, d.safe.size() + d.near_dangerous.size());
  m << d.safe.states, d.near_dangerous.states;
  return m;
}
long Disagreements(const std::vector<int>& labels, long safe) {
  long n = 0;
  for (std::size_t i = 0; i < labels.size(); ++i)
    n += labels[i] != (static_cast<long>(i) < safe ? 1 : 0) ? 1 : 0;
  return n;
}

// Without label noise the labeller gives exactly the generator's labels (one rule); with the
// mean participant's (0.03) both the data's labels and the answers are flipped at that rate.
TEST(CoffeeLabeller, AgreesWithTheGeneratorsOwnLabels) {
  CoffeePlacingDomain exact(experiments::Profile::kQuick);
  exact.ApplyYaml(YAML::Load("{population: {label_noise: [0, 0]}}"), "test.yaml");
  ASSERT_TRUE(exact.HasLabeller());
  const experiments::DomainData d0 = exact.GenerateData(11);
  EXPECT_EQ(Disagreements(exact.Label(Both(d0), 1), d0.safe.size()), 0);

  const CoffeePlacingDomain domain(experiments::Profile::kQuick);
  EXPECT_NE(domain.LabellerDescription().find("0.03"), std::string::npos);
  const experiments::DomainData d = domain.GenerateData(11);
  const long n = d.safe.size() + d.near_dangerous.size();
  const long differ = Disagreements(domain.Label(Both(d), 1), d.safe.size());
  // Two independent flips at 0.03: about 5.8 % of 400 (23); measured 26 with these seeds.
  EXPECT_GE(differ, n * 2 / 100);
  EXPECT_LE(differ, n * 10 / 100);
}

TEST(CoffeeLabeller, IsDeterministicPerSeedAndFlipsAtTheConfiguredRate) {
  CoffeePlacingDomain clean(experiments::Profile::kQuick), noisy(experiments::Profile::kQuick);
  clean.ApplyYaml(YAML::Load("{population: {label_noise: [0, 0]}}"), "test.yaml");
  noisy.ApplyYaml(YAML::Load("{population: {label_noise: [0.2, 0.2]}}"), "test.yaml");
  const Eigen::MatrixXf states = Both(clean.GenerateData(3)).replicate(1, 20);  // 8000
  const std::vector<int> truth = clean.Label(states, 5);
  EXPECT_EQ(truth, clean.Label(states, 6));  // no noise: the seed does not matter
  const std::vector<int> a = noisy.Label(states, 5);
  EXPECT_EQ(a, noisy.Label(states, 5));
  EXPECT_NE(a, noisy.Label(states, 6));
  long flipped = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) flipped += a[i] != truth[i] ? 1 : 0;
  // Binomial(8000, 0.2): sd 0.0045; the seed is fixed, the band is 4.5 sd wide either side.
  EXPECT_NEAR(double(flipped) / double(truth.size()), 0.2, 0.02);
  EXPECT_EQ(std::count(a.begin(), a.end(), -1), 0);  // the person always answers
}

// The person looks at the arm, not at the row's clearance number: a row whose clearance feature
// claims a large distance is still unsafe when the positions put the arm on the cup.
TEST(CoffeeLabeller, JudgesThePositionsAndTheTilt) {
  CoffeePlacingDomain domain(experiments::Profile::kQuick);
  domain.ApplyYaml(YAML::Load("{population: {label_noise: [0, 0]}}"), "test.yaml");
  const experiments::DomainData d = domain.GenerateData(2);
  const std::vector<int> labels = domain.Label(d.safe.states, 0);
  long i = 0;
  while (labels[static_cast<std::size_t>(i)] != 1) ++i;
  const Eigen::VectorXf o = d.safe.states.col(i);
  Eigen::VectorXf tilted = o;
  tilted[kTilt] = 0.3f;  // the mean participant's max tilt is 0.25 rad
  Eigen::VectorXf touching = o;
  for (int k = 0; k < 3; ++k) {
    const float shift = o[kEePos + k] - o[kWrist + k];
    touching[kWrist + k] += shift;
    touching[kHandTip + k] += shift;
    touching[kElbow + k] += shift;
  }
  touching[kClearance] = 1.0f;
  Eigen::MatrixXf m(kObservationDim, 3);
  m << o, tilted, touching;
  EXPECT_EQ(domain.Label(m, 0), (std::vector<int>{1, 0, 0}));
}

TEST(CoffeeLabeller, RejectsRowsItCannotJudge) {
  const CoffeePlacingDomain domain(experiments::Profile::kQuick);
  EXPECT_EQ(test::ErrorOf([&] { domain.Label(Eigen::MatrixXf::Zero(17, 2), 0); }),
            "coffee-placing labeller: states have 17 features, expected 23 (the "
            "observation: ee_x, ..., clearance)");
  Eigen::MatrixXf states = domain.GenerateData(5).safe.states.leftCols(2);
  states(kTilt, 1) = std::numeric_limits<float>::infinity();
  EXPECT_EQ(test::ErrorOf([&] { domain.Label(states, 0); }),
            "coffee-placing labeller: state 1, feature tilt = inf: not finite (the "
            "person cannot judge it)");
}

}  // namespace
}  // namespace secure::domains::coffee_placing
