// The SECURE pipeline end to end on a tiny profile: structure of the result, determinism, and
// independence from the number of worker threads.
#include "secure/experiments/double_integrator_pipeline.h"

#include <gtest/gtest.h>

#include <yaml-cpp/yaml.h>
#include <limits>

#include "tests/test_util.h"

namespace secure::experiments {
namespace {

using test::ErrorOf;

PipelineOptions Tiny() {
  PipelineOptions o = PipelineOptions::Quick();
  o.episodes = 8;
  o.demonstrations.episodes = 20;
  o.airl.iterations = 3;
  o.barrier.max_epochs = 30;
  o.verbose = false;
  return o;
}

TEST(PipelineTest, RunsEveryMethodOverSeedsAndDoesNotDependOnTheWorkerCount) {
  PipelineOptions one = Tiny();
  one.threads = 1;
  PipelineOptions two = Tiny();
  two.threads = 2;
  const PipelineResult a = RunDoubleIntegratorPipeline(one, nullptr);
  const PipelineResult b = RunDoubleIntegratorPipeline(two, nullptr);
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
  EXPECT_EQ(ja["pipeline"]["timings"].size(), 2u);
  EXPECT_EQ(a.demonstrations, 20);
  EXPECT_GT(a.safe_states, a.demonstrations);  // states of the demonstrations, plus copies
  EXPECT_EQ(a.near_dangerous_states, one.near_dangerous.count);
  // Unshielded methods make no shield decisions; shielded ones decide every step.
  const nlohmann::json& seed0 = ja["methods"]["secure"]["seeds"][0];
  EXPECT_EQ(seed0["decisions"], seed0["steps"]);
  EXPECT_EQ(ja["methods"]["airl"]["seeds"][0]["decisions"], 0);
}

TEST(PipelineTest, OptionsAreValidated) {
  PipelineOptions o = Tiny();
  o.seeds = 0;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "PipelineOptions::seeds = 0");
  o = Tiny();
  o.episodes = 2147483648L;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }),
             "PipelineOptions::episodes = 2147483648, must be in [1, 1000000]");
  o = Tiny();
  o.seeds = 10001;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }),
             "PipelineOptions::seeds = 10001, must be in [1, 10000]");
  o = Tiny();
  o.evaluation.tost_bound = std::numeric_limits<double>::infinity();
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "PipelineOptions::evaluation.tost_bound = inf");
  o = Tiny();
  o.shield.dt = 0.05;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "PipelineOptions::shield.dt = 0.05");
  o = Tiny();
  o.methods.clear();
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "methods");
  o = Tiny();
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{policy: {epochs: 3}}"), "x.yaml"); }),
             "unknown section 'policy'");
  o.ApplyYaml(YAML::Load("{bc: {epochs: 3}, airl: {iterations: 2}}"), "x.yaml");
  EXPECT_EQ(o.bc.epochs, 3);
  EXPECT_EQ(o.airl.iterations, 2);
}

}  // namespace
}  // namespace secure::experiments
