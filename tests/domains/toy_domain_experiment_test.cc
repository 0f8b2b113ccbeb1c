// The toy domain (tests/toy_domain, registered at run time) runs the quick method comparison
// through the generic driver (experiments::RunExperiment), as any plug-in would: the proof that
// a domain needs nothing but experiments::Domain. The toy is tuned so that the comparison says
// something: the expert parks in front of the wall after a fast approach, the learned policies
// sometimes overshoot into it, the shield keeps SECURE off it.

#include <gtest/gtest.h>

#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "secure/eval/policy_eval.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"
#include "tests/domains/domain_contract_util.h"

namespace secure::test {
namespace {

using experiments::ExperimentKind;
using experiments::Profile;

TEST(ToyDomainExperiment, QuickMethodComparisonThroughTheGenericDriver) {
  ContractDomainNames();  // registers the toy domain
  std::unique_ptr<experiments::Domain> toy =
      experiments::DomainRegistry::Global().Make("toy-cart", Profile::kQuick);
  experiments::ExperimentOptions options = toy->Preset();
  options.verbose = false;
  const experiments::ExperimentResult r =
      experiments::RunExperiment(ExperimentKind::kMethodComparison, *toy, options, nullptr);
  if (std::getenv("SECURE_TOY_VERBOSE")) std::cout << r.Table() << "\n";

  EXPECT_EQ(r.domain, "toy-cart");
  EXPECT_EQ(r.demonstrations, 30);
  EXPECT_EQ(r.safe_states, 600);
  EXPECT_EQ(r.near_dangerous_states, 600);
  ASSERT_EQ(r.evaluations.size(), 1u);
  const auto& methods = r.evaluations[0].second.methods();
  for (eval::Method m : {eval::Method::kBc, eval::Method::kAirl, eval::Method::kSecure}) {
    ASSERT_TRUE(methods.count(m)) << ToString(eval::kMethodNames, m);
    EXPECT_EQ(methods.at(m).per_seed.size(), 2u);
  }
  // Every seed trained BC and AIRL (their summaries are recorded).
  ASSERT_EQ(r.seed_summaries.size(), 2u);
  for (const nlohmann::json& s : r.seed_summaries) {
    EXPECT_TRUE(s.contains("bc")) << s.dump();
    EXPECT_TRUE(s.contains("airl")) << s.dump();
  }
  // The result JSON has every method.
  const nlohmann::json j = r.ToJson();
  for (const char* m : {"bc", "airl", "secure"}) EXPECT_TRUE(j["methods"].contains(m)) << m;

  // The comparison says something: AIRL alone hits the wall in some episodes, SECURE (the same
  // policy under the shield) less often, on every seed, and it still parks.
  const eval::MethodSummary& airl = methods.at(eval::Method::kAirl);
  const eval::MethodSummary& secure = methods.at(eval::Method::kSecure);
  EXPECT_GT(airl.dangerous_rate.mean, 0.1);
  EXPECT_LT(secure.dangerous_rate.mean, airl.dangerous_rate.mean);
  for (std::size_t s = 0; s < secure.per_seed.size(); ++s)
    EXPECT_LT(secure.per_seed[s].dangerous_rate(), airl.per_seed[s].dangerous_rate())
        << "seed " << s;
  EXPECT_LE(secure.dangerous_rate.mean, 0.05);
  EXPECT_GT(secure.success_rate.mean, 0.5);
}

}  // namespace
}  // namespace secure::test
