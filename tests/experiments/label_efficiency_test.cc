// The label-efficiency driver's shield-relevant strategy (RunLabelEfficiency, issue 35): a round
// whose shielded run visited fewer than k states asks by margin over the pool instead, and the
// curve and the table say how often; a domain without a shield run rejects the strategy.
#include <gtest/gtest.h>

#include <limits>
#include <memory>
#include <string>

#include "secure/experiments/domain.h"
#include "secure/experiments/label_efficiency.h"
#include "tests/test_util.h"

namespace secure::experiments {
namespace {

using test::ErrorOf;

std::unique_ptr<Domain> Make(const std::string& name) {
  DomainRegistry& registry = DomainRegistry::Global();
  plugins::RegisterBuiltinDomains(registry);  // as the CLI does (idempotent)
  return registry.Make(name, Profile::kQuick);
}

LabelEfficiencyOptions OneRound(const Domain& domain) {
  LabelEfficiencyOptions o = LabelEfficiencyOptions::For(domain, Profile::kQuick);
  o.strategies = {cbf::QueryStrategy::kShieldRelevant};
  o.seeds = 1;
  o.rounds = 1;
  o.final_episodes = 2;
  o.verbose = false;
  return o;
}

TEST(LabelEfficiencyTest, ShieldRelevantCountsTheRoundsMarginAskedInstead) {
  const std::unique_ptr<Domain> d = Make("double-integrator");
  ASSERT_TRUE(d->HasShieldRun());
  LabelEfficiencyOptions o = OneRound(*d);
  // Enough visited states: the shielded run's states are the pool, no round falls back.
  const LabelEfficiencyResult visited = RunLabelEfficiency(*d, o, nullptr);
  ASSERT_EQ(visited.curves.size(), 1u);
  EXPECT_EQ(visited.curves[0].margin_rounds, 0);
  EXPECT_EQ(visited.curves[0].ToJson()["margin_rounds"], 0);
  EXPECT_EQ(visited.Table().find("asked by margin"), std::string::npos);
  // Fewer visited states kept than k: the round asks by margin over the pool, and says so.
  o.shield_pool_states = o.k - 1;
  const LabelEfficiencyResult fell_back = RunLabelEfficiency(*d, o, nullptr);
  const LabelEfficiencyCurve& c = fell_back.curves[0];
  EXPECT_EQ(c.margin_rounds, 1);
  EXPECT_EQ(LabelEfficiencyCurve::FromJson(c.ToJson()).margin_rounds, 1);
  EXPECT_NE(fell_back.Table().find("shield-relevant: 1 of 1 query rounds asked by margin"),
            std::string::npos)
      << fell_back.Table();
  // The rounds still asked k states each.
  ASSERT_EQ(c.points.size(), 2u);
  EXPECT_EQ(c.points[1].labels - c.points[0].labels, o.k);
}

TEST(LabelEfficiencyTest, ShieldRelevantNeedsADomainWithAShieldRun) {
  const std::unique_ptr<Domain> d = Make("derby");
  ASSERT_FALSE(d->HasShieldRun());
  EXPECT_HAS(ErrorOf([&] { RunLabelEfficiency(*d, OneRound(*d), nullptr); }),
             "the derby domain has no shield run");
  // Other strategies' curves carry no such count.
  LabelEfficiencyCurve margin;
  margin.strategy = "margin";
  EXPECT_FALSE(margin.ToJson().contains("margin_rounds"));
}

// k_growth: round r asks round(k · g^r) states, so the labels double with g = 2; the schedule
// is checked against the pool before any training, and the options' JSON (the task identity)
// carries k_growth only where it is not 1.
TEST(LabelEfficiencyTest, GrowingRoundsAskKTimesGrowthToTheRound) {
  const std::unique_ptr<Domain> d = Make("double-integrator");
  LabelEfficiencyOptions o = LabelEfficiencyOptions::For(*d, Profile::kQuick);
  o.strategies = {cbf::QueryStrategy::kRandom, cbf::QueryStrategy::kMargin};
  o.seeds = 1;
  o.initial_labels = 10;
  o.k = 10;
  o.rounds = 3;
  o.final_episodes = 2;
  o.verbose = false;
  EXPECT_FALSE(o.ToJson().contains("k_growth"));
  o.k_growth = 2;
  EXPECT_EQ(o.QueriesIn(0), 10);
  EXPECT_EQ(o.QueriesIn(2), 40);
  EXPECT_EQ(o.LabelsAtTheEnd(), 10 + 10 + 20 + 40);
  EXPECT_EQ(o.ToJson()["k_growth"], 2.0);
  const LabelEfficiencyResult r = RunLabelEfficiency(*d, o, nullptr);
  ASSERT_EQ(r.curves.size(), 2u);
  for (const LabelEfficiencyCurve& c : r.curves) {
    ASSERT_EQ(c.points.size(), 4u) << c.strategy;
    EXPECT_EQ(c.points[0].labels, 10) << c.strategy;  // both classes among the first 10
    EXPECT_EQ(c.points[1].labels, 20) << c.strategy;
    EXPECT_EQ(c.points[2].labels, 40) << c.strategy;
    EXPECT_EQ(c.points[3].labels, 80) << c.strategy;
  }
  // 1.5: 10, 15, 22.5 -> 23 (rounded half away from zero).
  o.k_growth = 1.5;
  EXPECT_EQ(o.QueriesIn(2), 23);
  EXPECT_EQ(o.LabelsAtTheEnd(), 10 + 10 + 15 + 23);
  // Bad schedules: one line naming the field and value.
  o.k_growth = 0.5;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "k_growth = 0.5");
  o.k_growth = std::numeric_limits<double>::quiet_NaN();
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "k_growth = nan");
  o.k_growth = 10;
  o.rounds = 6;  // 10 + 10 (1 + 10 + ... + 10^5) labels: more than the pool
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "<= pool (" + std::to_string(o.pool) + ")");
}

}  // namespace
}  // namespace secure::experiments
