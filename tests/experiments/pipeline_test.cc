// The SECURE pipeline (`secure demo`: the method comparison with every method) end to end on the
// double integrator's tiny profile: structure of the result, determinism, independence from the
// number of worker threads, and that the shield does its job.
#include "domains/double_integrator/domain.h"
#include "secure/experiments/experiment.h"

#include <gtest/gtest.h>

#include <yaml-cpp/yaml.h>
#include <limits>
#include <sstream>

#include "secure/common/atomic_file.h"
#include "secure/policy/airl_reward.h"
#include "tests/json_util.h"
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
  std::ostringstream dt_error;  // the field and both values
  dt_error << "ExperimentOptions::shield.dt = 0.05, must be the control period of the "
              "double-integrator environment ("
           << TinyDomain().options().task.dt << " s)";
  EXPECT_HAS(ErrorOf([&] { CheckExperimentOptions(TinyDomain(), o); }), dt_error.str());
  EXPECT_HAS(ErrorOf([&] { RunTiny(o); }), "ExperimentOptions::shield.dt = 0.05");
  o = Tiny();
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{policy: {epochs: 3}}"), "x.yaml"); }),
             "unknown section 'policy'");
  o.ApplyYaml(YAML::Load("{bc: {epochs: 3}, airl: {iterations: 2}, barrier: {max_epochs: 7}}"),
              "x.yaml");
  EXPECT_EQ(o.bc.epochs, 3);
  EXPECT_EQ(o.airl.iterations, 2);
  EXPECT_EQ(o.flat_barrier.max_epochs, 7);  // `barrier` is the preset's kind: flat here
  // The shield's options through `shield:` (enums by name), over the preset's.
  o.ApplyYaml(YAML::Load("{shield: {num_samples: 32, class_k: cubic, class_k_gain: 3, "
                         "aggregation: random-safe, resampling: none}}"),
              "x.yaml");
  EXPECT_EQ(o.shield.num_samples, 32);
  EXPECT_EQ(o.shield.class_k, shield::ClassK::kCubic);
  EXPECT_EQ(o.shield.class_k_gain, 3.0);
  EXPECT_EQ(o.shield.aggregation, shield::Aggregation::kRandomSafe);
  EXPECT_EQ(o.shield.resampling, shield::Resampling::kNone);
  EXPECT_EQ(o.shield.dt, Tiny().shield.dt);  // keys not given keep the preset's value
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{shield: {class_k: quadratic}}"), "x.yaml"); }),
             "x.yaml [shield] [class_k] = 'quadratic', must be one of linear, cubic");
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{shield: {samples: 8}}"), "x.yaml"); }),
             "x.yaml [shield]: unknown key 'samples'");
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{shield: {num_samples: many}}"), "x.yaml"); }),
             "num_samples");
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

using test::WithoutTimings;

class TopQPipelineTest : public test::TempDirTest {};

// The shield's top-q aggregation ranks actions by the AIRL reward model the seed trained: the
// experiment writes it beside airl.model, and SECURE's decisions use it (a different action
// stream from the mean's on the same episodes).
TEST_F(TopQPipelineTest, SecureWithTopQUsesTheSeedsAirlRewardModel) {
  ExperimentOptions o = Tiny();
  o.seeds = 1;
  o.methods = {eval::Method::kAirl, eval::Method::kSecure};
  o.output_dir = PathOf("mean");
  const nlohmann::json mean = RunTiny(o).ToJson();
  o.output_dir = PathOf("top-q");
  o.ApplyYaml(YAML::Load("{shield: {aggregation: top-q, top_q_fraction: 0.25}}"), "x.yaml");
  const nlohmann::json top = RunTiny(o).ToJson();
  const policy::AirlRewardModel reward =
      policy::AirlRewardModel::Load(PathOf("top-q/seed-0/airl_reward.model"));
  EXPECT_EQ(reward.observation_features, TinyDomain().MakeEnvironment()->ObservationFeatures());
  EXPECT_EQ(ReadFile(PathOf("mean/seed-0/airl_reward.model")),
            ReadFile(PathOf("top-q/seed-0/airl_reward.model")));  // the same AIRL run
  EXPECT_EQ(top["experiment"]["options"]["shield"]["aggregation"], "top-q");
  EXPECT_EQ(top["experiment"]["options"]["shield"]["top_q_fraction"], 0.25);
  // What the episodes did (not their timing).
  const auto counts = [](const nlohmann::json& seed) {
    nlohmann::json c;
    for (const char* key : {"steps", "successes", "dangerous", "collision_events", "interventions",
                            "resampled_decisions", "mean_iterations"})
      c[key] = seed[key];
    return c;
  };
  EXPECT_EQ(counts(mean["methods"]["airl"]["seeds"][0]),
            counts(top["methods"]["airl"]["seeds"][0]));
  const nlohmann::json& seed0 = top["methods"]["secure"]["seeds"][0];
  EXPECT_EQ(seed0["decisions"], seed0["steps"]);
  EXPECT_NE(counts(mean["methods"]["secure"]["seeds"][0]), counts(seed0));
}

class ShardedPipelineTest : public test::TempDirTest {};

// The sensitivity kind (several barrier-data variants per seed, its own table) run whole and as
// three shards of one directory: the merged result is the unsharded one; a rerun reuses every
// task file; a task file of another experiment is refused, naming the file and the difference.
TEST_F(ShardedPipelineTest, ShardsMergeToTheUnshardedResultAndTaskFilesAreReused) {
  ExperimentOptions o = Tiny();
  o.methods = {eval::Method::kSecure};
  o.seeds = 4;
  o.data_fractions = {1.0, 0.5};
  o.imbalance_ratios = {1};
  o.label_noise = {0.0, 0.3};
  o.output_dir = PathOf("full");
  const ExperimentKind kind = ExperimentKind::kSensitivity;
  const ExperimentResult whole = RunExperiment(kind, TinyDomain(), o, nullptr);
  ASSERT_EQ(whole.variants.size(), 3u);
  for (int k = 0; k < 3; ++k) {
    ExperimentOptions shard = o;
    shard.output_dir = PathOf("run");
    shard.shard = k;
    shard.shards = 3;
    const ShardReport report = RunExperimentShard(kind, TinyDomain(), shard, nullptr);
    EXPECT_EQ(report.computed.size(), k == 0 ? 2u : 1u);
    EXPECT_TRUE(report.reused.empty());
  }
  EXPECT_FALSE(std::filesystem::exists(PathOf("run/result.json")));
  const ExperimentResult merged = MergeExperiment({PathOf("run")});
  // (Compared as text: a NaN in a summary -- an accuracy without held-out states -- is null in a
  // task file, and NaN != NaN.)
  EXPECT_EQ(WithoutTimings(merged.ToJson()).dump(), WithoutTimings(whole.ToJson()).dump());
  EXPECT_EQ(merged.Table(), whole.Table());  // the sensitivity table has no timing column
  // result.json of the unsharded run: the in-memory result's document.
  EXPECT_EQ(ReadFile(PathOf("full/result.json")), whole.ToJson().dump(2) + "\n");

  // A rerun (with other threads: not part of the experiment) reuses every seed: the same
  // result, seed timings included.
  ExperimentOptions again = o;
  again.threads = 1;
  nlohmann::json rerun = RunExperiment(kind, TinyDomain(), again, nullptr).ToJson();
  nlohmann::json first = whole.ToJson();
  EXPECT_EQ(rerun["experiment"]["seeds"].dump(), first["experiment"]["seeds"].dump());
  rerun["experiment"]["options"].erase("threads");
  first["experiment"]["options"].erase("threads");
  EXPECT_EQ(WithoutTimings(rerun).dump(), WithoutTimings(first).dump());

  // Another experiment into the same directory: refused before anything is written.
  again.episodes = 9;
  EXPECT_HAS(ErrorOf([&] { RunExperiment(kind, TinyDomain(), again, nullptr); }),
             PathOf("full") +
                 "/seed-0/task.json: the task of a different experiment "
                 "(options.episodes: 8 vs 9");
  // Merge: a seed missing, a directory of another experiment.
  std::filesystem::remove(PathOf("run/seed-3/task.json"));
  EXPECT_HAS(ErrorOf([&] { MergeExperiment({PathOf("run")}); }),
             "1 of 4 seeds have no task file (seed 3)");
  EXPECT_HAS(ErrorOf([&] {
               MergeExperiment({PathOf("run"), PathOf("full")});
             }),
             "seed 0 is there twice");

  // Shard options.
  ExperimentOptions bad = o;
  bad.shards = 2;
  bad.shard = 2;
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "ExperimentOptions::shard = 2");
  bad.shard = 1;
  bad.output_dir.clear();
  EXPECT_HAS(ErrorOf([&] { RunExperimentShard(kind, TinyDomain(), bad, nullptr); }),
             "ExperimentOptions::output_dir");
  bad.output_dir = PathOf("full");
  EXPECT_HAS(ErrorOf([&] { RunExperiment(kind, TinyDomain(), bad, nullptr); }),
             "use RunExperimentShard");
}

}  // namespace
}  // namespace secure::experiments
