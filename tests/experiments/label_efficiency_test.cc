// The label-efficiency driver's shield-relevant strategy (RunLabelEfficiency, issue 35): a round
// whose shielded run visited fewer than k states asks by margin over the pool instead, and the
// curve and the table say how often; a domain without a shield run rejects the strategy.
#include <gtest/gtest.h>

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

}  // namespace
}  // namespace secure::experiments
