// The SECURE pipeline (`secure demo`: the method comparison with every method) end to end on the
// double integrator's tiny profile: structure of the result, determinism, independence from the
// number of worker threads, and that the shield does its job.
#include "domains/double_integrator/domain.h"
#include "secure/experiments/experiment.h"

#include <gtest/gtest.h>

#include <yaml-cpp/yaml.h>
#include <limits>

#include "tests/test_util.h"

namespace secure::experiments {
namespace {

using test::ErrorOf;

const domains::double_integrator::DoubleIntegratorDomain& TinyDomain() {
  static const domains::double_integrator::DoubleIntegratorDomain domain = [] {
    domains::double_integrator::DoubleIntegratorDomain d(Profile::kQuick);
    d.mutable_options().demonstrations.episodes = 20;
    return d;
  }();
  return domain;
}

ExperimentOptions Tiny() {
  ExperimentOptions o = TinyDomain().Preset();
  o.methods = eval::AllMethods();
  o.episodes = 8;
  o.airl.iterations = 3;
  o.flat_barrier.max_epochs = 30;
  o.verbose = false;
  return o;
}

ExperimentResult RunTiny(const ExperimentOptions& o) {
  return RunExperiment(ExperimentKind::kMethodComparison, TinyDomain(), o, nullptr);
}

TEST(PipelineTest, RunsEveryMethodOverSeedsAndDoesNotDependOnTheWorkerCount) {
  ExperimentOptions one = Tiny();
  one.threads = 1;
  ExperimentOptions two = Tiny();
  two.threads = 2;
  const ExperimentResult a = RunTiny(one);
  const ExperimentResult b = RunTiny(two);
  const nlohmann::json ja = a.ToJson(), jb = b.ToJson();
  for (eval::Method m : eval::AllMethods()) {
    const std::string name = ToString(eval::kMethodNames, m);
    ASSERT_TRUE(ja["methods"].contains(name)) << name;
    for (const char* metric : {"success_rate", "dangerous_rate"}) {
      const nlohmann::json& r = ja["methods"][name][metric];
      ASSERT_EQ(r["per_seed"].size(), 2u) << name;
      for (const auto& v : r["per_seed"]) {
        EXPECT_GE(v.get<double>(), 0.0);
        EXPECT_LE(v.get<double>(), 1.0);
      }
      EXPECT_EQ(r, jb["methods"][name][metric]) << name << " " << metric;
    }
    EXPECT_EQ(ja["methods"][name]["interventions_per_episode"],
              jb["methods"][name]["interventions_per_episode"]);
  }
  EXPECT_TRUE(ja["comparisons"].contains("secure_vs_airl"));
  EXPECT_TRUE(ja["comparisons"].contains("ablations"));
  EXPECT_EQ(ja["experiment"]["seeds"].size(), 2u);
  EXPECT_EQ(ja["experiment"]["domain"], "double-integrator");
  EXPECT_EQ(a.demonstrations, 20);
  EXPECT_GT(a.safe_states, a.demonstrations);  // states of the demonstrations, plus copies
  EXPECT_EQ(a.near_dangerous_states, TinyDomain().options().near_dangerous.count);
  // The shield does its job: SECURE (AIRL under the shield) is dangerous less often than AIRL
  // alone, over both seeds, and never more often than AIRL on any seed.
  const nlohmann::json& airl_danger = ja["methods"]["airl"]["dangerous_rate"];
  const nlohmann::json& secure_danger = ja["methods"]["secure"]["dangerous_rate"];
  EXPECT_LE(secure_danger["mean"].get<double>(), airl_danger["mean"].get<double>());
  for (std::size_t i = 0; i < 2; ++i)
    EXPECT_LE(secure_danger["per_seed"][i].get<double>(),
              airl_danger["per_seed"][i].get<double>());
  // Unshielded methods make no shield decisions; shielded ones decide every step.
  const nlohmann::json& seed0 = ja["methods"]["secure"]["seeds"][0];
  EXPECT_EQ(seed0["decisions"], seed0["steps"]);
  EXPECT_EQ(ja["methods"]["airl"]["seeds"][0]["decisions"], 0);
}

// A flat barrier on some of the observation's features (flat_barrier.input_features, here in
// another order): the shield and the joint policy read them by name. (The double integrator has
// no barrier check in experiments; `cbf check` on such a barrier is in cli_test.)
TEST(PipelineTest, AFlatBarrierOnSomeObservationFeaturesRunsEveryStage) {
  ExperimentOptions o = Tiny();
  o.seeds = 1;
  o.methods = {eval::Method::kAirl, eval::Method::kSecure, eval::Method::kJoint};
  o.ApplyYaml(YAML::Load("{flat_barrier: {input_features: [vy, x, y]}}"), "x.yaml");
  EXPECT_EQ(o.ToJson()["flat_barrier"]["input_features"], nlohmann::json({"vy", "x", "y"}));
  const nlohmann::json j = RunTiny(o).ToJson();
  for (const char* name : {"secure", "joint"}) {
    const double danger = j.at("methods").at(name).at("dangerous_rate").at("mean");
    EXPECT_GE(danger, 0.0) << name;
    EXPECT_LE(danger, 1.0) << name;
  }
  const nlohmann::json& seed0 = j.at("methods").at("secure").at("seeds").at(0);
  EXPECT_EQ(seed0.at("decisions"), seed0.at("steps"));

  o.ApplyYaml(YAML::Load("{flat_barrier: {input_features: [x, speed]}}"), "x.yaml");
  EXPECT_HAS(ErrorOf([&] { RunTiny(o); }), "without 'speed'");
}

TEST(PipelineTest, OptionsAreValidated) {
  ExperimentOptions o = Tiny();
  o.seeds = 0;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "ExperimentOptions::seeds = 0");
  o = Tiny();
  o.episodes = 2147483648L;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }),
             "ExperimentOptions::episodes = 2147483648, must be in [1, 1000000]");
  o = Tiny();
  o.seeds = 10001;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }),
             "ExperimentOptions::seeds = 10001, must be in [1, 10000]");
  o = Tiny();
  o.evaluation.tost_bound = std::numeric_limits<double>::infinity();
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "ExperimentOptions::evaluation.tost_bound = inf");
  o = Tiny();
  o.shield.dt = 0.05;
  EXPECT_HAS(ErrorOf([&] { TinyDomain().CheckExperiment(o); }),
             "ExperimentOptions::shield.dt = 0.05");
  EXPECT_HAS(ErrorOf([&] { RunTiny(o); }), "ExperimentOptions::shield.dt = 0.05");
  o = Tiny();
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{policy: {epochs: 3}}"), "x.yaml"); }),
             "unknown section 'policy'");
  o.ApplyYaml(YAML::Load("{bc: {epochs: 3}, airl: {iterations: 2}, barrier: {max_epochs: 7}}"),
              "x.yaml");
  EXPECT_EQ(o.bc.epochs, 3);
  EXPECT_EQ(o.airl.iterations, 2);
  EXPECT_EQ(o.flat_barrier.max_epochs, 7);  // `barrier` is the preset's kind: flat here
  // The domain's own options through `domain:`, only when the domain is given.
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{domain: {safe_states: 5}}"), "x.yaml"); }),
             "unknown section 'domain'");
  domains::double_integrator::DoubleIntegratorDomain d(Profile::kQuick);
  o.ApplyYaml(YAML::Load("{domain: {safe_states: 5, near_dangerous: {count: 9}}}"), "x.yaml", &d);
  EXPECT_EQ(d.options().safe_states, 5);
  EXPECT_EQ(d.options().near_dangerous.count, 9);
  EXPECT_HAS(ErrorOf([&] { d.ApplyYaml(YAML::Load("{near_dangerous: {rho: 1}}"), "x.yaml"); }),
             "unknown key 'rho'");
}

}  // namespace
}  // namespace secure::experiments
