// The example plug-in (examples/toy_domain, registered like every plug-in) runs the quick method
// comparison through the generic driver (experiments::RunExperiment), as any plug-in would: the
// proof that a domain needs nothing but experiments::Domain. The toy is tuned so that the
// comparison says something: the expert parks in front of the wall after a fast approach, the
// learned policies sometimes overshoot into it, the shield keeps SECURE off it.

#include <gtest/gtest.h>

#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "secure/eval/policy_eval.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"
#include "secure/experiments/ground_truth_study.h"

namespace secure::test {
namespace {

using experiments::ExperimentKind;
using experiments::Profile;

TEST(ToyDomainExperiment, QuickMethodComparisonThroughTheGenericDriver) {
  plugins::RegisterBuiltinDomains(experiments::DomainRegistry::Global());
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

// The ground-truth study (Table 1, `secure cbf table1`) is generic: it runs on any domain with a
// ground truth, here the toy's (its sampler, grid and analytic barrier), and a domain without one
// is refused naming the domains that have one.
TEST(ToyDomainExperiment, GroundTruthStudyRunsOnTheToyDomain) {
  plugins::RegisterBuiltinDomains(experiments::DomainRegistry::Global());
  const experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
  const std::unique_ptr<experiments::Domain> toy = registry.Make("toy-cart", Profile::kQuick);
  experiments::GroundTruthStudyOptions o;
  o.n_safe = o.n_unsafe = 300;
  o.seeds = 2;
  o.trainer = toy->GroundTruthTrainerPreset();
  o.trainer.hidden = {16, 16};
  o.trainer.max_epochs = 60;
  o.trainer.learning_rate = 0.01;
  o.progress = false;
  const experiments::GroundTruthStudyResult r = experiments::RunGroundTruthStudy(*toy, o);
  ASSERT_EQ(r.per_seed.size(), 2u);
  EXPECT_EQ(r.per_seed[0].total(), 41 * 41);  // the toy's validation grid
  EXPECT_NEAR(r.safe_correct.mean + r.over_conservative.mean, 1.0, 1e-12);
  EXPECT_LT(r.over_conservative.mean, 0.2);   // a learned barrier, not a coin
  EXPECT_LT(r.under_conservative.mean, 0.2);
  EXPECT_FALSE(r.paper.has_value());
  EXPECT_EQ(r.Table().find("[paper:"), std::string::npos);
  // Deterministic per seed.
  EXPECT_EQ(experiments::RunGroundTruthStudy(*toy, o).ToJson()["over_conservative"],
            r.ToJson()["over_conservative"]);

  const std::unique_ptr<experiments::Domain> derby = registry.Make("derby", Profile::kQuick);
  try {
    experiments::RunGroundTruthStudy(*derby, o);
    FAIL() << "derby has no ground truth";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("the derby domain has no ground truth"),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("double-integrator"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("toy-cart"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace secure::test
