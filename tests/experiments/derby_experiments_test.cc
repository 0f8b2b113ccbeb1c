// The Demolition Derby experiments on tiny profiles: the result structure of each experiment,
// independence from the number of worker threads, and the barrier-data variants of the
// sensitivity study.
#include "domains/derby/domain.h"
#include "secure/experiments/experiment.h"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <set>

#include "tests/experiments/tiny_derby.h"
#include "tests/test_util.h"

namespace secure::experiments {
namespace {

using test::ErrorOf;

const domains::derby::DerbyDomain& TinyDomain() { return test::TinyDerby(); }

ExperimentOptions Tiny() { return test::TinyDerbyOptions(); }

ExperimentResult RunTiny(ExperimentKind kind, const ExperimentOptions& o) {
  return RunExperiment(kind, TinyDomain(), o, nullptr);
}

void ExpectRates(const nlohmann::json& methods, const std::string& name, std::size_t seeds) {
  ASSERT_TRUE(methods.contains(name)) << name;
  for (const char* metric : {"success_rate", "dangerous_rate"}) {
    const nlohmann::json& r = methods[name][metric];
    ASSERT_EQ(r["per_seed"].size(), seeds) << name;
    for (const auto& v : r["per_seed"]) {
      EXPECT_GE(v.get<double>(), 0.0) << name;
      EXPECT_LE(v.get<double>(), 1.0) << name;
    }
  }
}

TEST(DerbyExperimentsTest, Table3RunsBcAirlSecureAndDoesNotDependOnTheWorkerCount) {
  ExperimentOptions one = Tiny();
  one.threads = 1;
  ExperimentOptions two = Tiny();
  two.threads = 2;
  const ExperimentResult a = RunTiny(ExperimentKind::kMethodComparison, one);
  const ExperimentResult b = RunTiny(ExperimentKind::kMethodComparison, two);
  const nlohmann::json ja = a.ToJson(), jb = b.ToJson();
  EXPECT_EQ(ja["methods"].size(), 3u);
  for (const char* name : {"bc", "airl", "secure"}) {
    ExpectRates(ja["methods"], name, 2);
    for (const char* metric : {"success_rate", "dangerous_rate", "interventions_per_episode"})
      EXPECT_EQ(ja["methods"][name][metric], jb["methods"][name][metric]) << name << metric;
  }
  EXPECT_TRUE(ja["comparisons"].contains("secure_vs_airl"));
  EXPECT_EQ(ja["experiment"]["kind"], "method-comparison");
  EXPECT_EQ(ja["experiment"]["domain"], "derby");
  EXPECT_EQ(a.demonstrations, 12);
  EXPECT_EQ(a.safe_states, 200);
  EXPECT_EQ(a.near_dangerous_states, 200);
  // SECURE decides every step; the shield statistics are recorded.
  const nlohmann::json& seed0 = ja["methods"]["secure"]["seeds"][0];
  EXPECT_EQ(seed0["decisions"], seed0["steps"]);
  EXPECT_GT(seed0["latency_us"]["p50"].get<double>(), 0.0);
  EXPECT_NE(a.Table().find("| secure |"), std::string::npos);
}

TEST(DerbyExperimentsTest, AblationAndJointExperimentsRunTheirMethods) {
  ExperimentOptions o = Tiny();
  o.seeds = 2;
  const nlohmann::json ablation = RunTiny(ExperimentKind::kAblation, o).ToJson();
  for (const char* name : {"secure", "secure-random-safe", "secure-no-resampling", "secure-myopic"})
    ExpectRates(ablation["methods"], name, 2);
  EXPECT_TRUE(ablation["comparisons"].contains("ablations"));
  EXPECT_EQ(ablation["comparisons"]["ablations"]["methods"].size(), 3u);

  o.seeds = 1;
  const ExperimentResult joint = RunTiny(ExperimentKind::kJoint, o);
  const nlohmann::json jj = joint.ToJson();
  for (const char* name : {"airl", "secure", "joint"}) ExpectRates(jj["methods"], name, 1);
  EXPECT_EQ(jj["methods"]["joint"]["seeds"][0]["decisions"], 0);  // unshielded
  EXPECT_TRUE(jj["experiment"]["seeds"][0].contains("joint"));
}

TEST(DerbyExperimentsTest, SensitivityEvaluatesSecureOncePerDataVariant) {
  ExperimentOptions o = Tiny();
  o.seeds = 1;
  o.data_fractions = {1.0, 0.1};
  o.imbalance_ratios = {1, 4};
  o.label_noise = {0.0, 0.5};
  const ExperimentResult r = RunTiny(ExperimentKind::kSensitivity, o);
  ASSERT_EQ(r.evaluations.size(), 4u);  // baseline, data 10%, imbalance 1:4, label noise 50%
  const nlohmann::json j = r.ToJson();
  for (const char* name : {"baseline", "data 10%", "imbalance 1:4", "label noise 50%"}) {
    ASSERT_TRUE(j["variants"].contains(name)) << name;
    ExpectRates(j["variants"][name]["methods"], "secure", 1);
  }
  const nlohmann::json& barriers = j["experiment"]["seeds"][0]["barriers"];
  EXPECT_EQ(barriers["data 10%"]["safe_states"], 20);
  EXPECT_EQ(barriers["data 10%"]["near_dangerous_states"], 20);
  EXPECT_EQ(barriers["imbalance 1:4"]["near_dangerous_states"], 50);
  EXPECT_EQ(barriers["label noise 50%"]["safe_states"], 200);
  EXPECT_NE(r.Table().find("| imbalance 1:4 | 200 : 50 |"), std::string::npos) << r.Table();
}

TEST(DerbyExperimentsTest, BarrierCheckIsRecordedPerSeedAndChangesNoNumber) {
  ExperimentOptions off = Tiny();
  off.seeds = 1;
  off.check_enabled = false;
  ExperimentOptions on = off;
  on.check_enabled = true;
  on.check.region_samples = 100;
  on.check.near_samples = 100;
  on.check_held_out = 50;
  const ExperimentResult a = RunTiny(ExperimentKind::kMethodComparison, off);
  const ExperimentResult b = RunTiny(ExperimentKind::kMethodComparison, on);
  const nlohmann::json ja = a.ToJson(), jb = b.ToJson();
  // The check draws from its own streams only: every number is unchanged.
  for (const char* name : {"bc", "airl", "secure"})
    for (const char* metric : {"success_rate", "dangerous_rate", "interventions_per_episode"})
      EXPECT_EQ(ja["methods"][name][metric], jb["methods"][name][metric]) << name << metric;
  EXPECT_EQ(ja["methods"]["secure"]["seeds"][0]["collision_events"],
            jb["methods"]["secure"]["seeds"][0]["collision_events"]);
  EXPECT_FALSE(ja["experiment"]["seeds"][0].contains("check"));
  EXPECT_EQ(a.Table().find("Barrier check"), std::string::npos);
  const nlohmann::json& check = jb["experiment"]["seeds"][0]["check"];
  ASSERT_TRUE(check.is_object());
  EXPECT_TRUE(check["verdict"] == "pass" || check["verdict"] == "flagged");
  EXPECT_EQ(check["kinds"]["no_safe_action"]["threshold"], 0.01);
  EXPECT_EQ(check["accuracy"]["held_out_near_dangerous"], 50);
  EXPECT_EQ(check["kinds"]["near_dangerous"]["checked"], 100);
  EXPECT_EQ(jb["experiment"]["seeds"][0]["barriers"]["baseline"]["check"], check);
  EXPECT_NE(b.Table().find("Barrier check per seed"), std::string::npos) << b.Table();
  EXPECT_NE(b.Table().find("| 0 | "), std::string::npos) << b.Table();

  // Thresholds 0 flag any counterexample; `augment` then retrains once with them.
  ExperimentOptions augment = on;
  augment.check.thresholds.no_safe_action = 0;
  augment.check.thresholds.near_dangerous = 0;
  augment.check.thresholds.unsafe = 0;
  augment.check.thresholds.min_accuracy_safe = 1;
  augment.check.thresholds.min_accuracy_near_dangerous = 1;
  augment.augment_flagged = true;
  const nlohmann::json jc = RunTiny(ExperimentKind::kMethodComparison, augment).ToJson();
  const nlohmann::json& seed = jc["experiment"]["seeds"][0];
  ASSERT_TRUE(seed["check"]["flagged"].get<bool>()) << seed["check"].dump();
  if (seed["check"]["kinds"]["unsafe"]["examples"].get<long>() +
          seed["check"]["kinds"]["near_dangerous"]["examples"].get<long>() +
          seed["check"]["kinds"]["no_safe_action"]["examples"].get<long>() >
      0) {
    const nlohmann::json& aug = seed["barriers"]["baseline"]["augmented"];
    EXPECT_GT(aug["added_near_dangerous_states"].get<long>(), 0);
    EXPECT_TRUE(seed.contains("check_augmented"));
  }
  // BC and AIRL do not depend on the barrier.
  EXPECT_EQ(jc["methods"]["airl"]["dangerous_rate"], jb["methods"]["airl"]["dangerous_rate"]);
}

TEST(DerbyExperimentsTest, CheckOptionsFromYaml) {
  ExperimentOptions o = Tiny();
  o.ApplyYaml(YAML::Load("{check: {enabled: false, held_out: 32, augment: true, "
                         "region_samples: 10, thresholds: {unsafe: 0.5}}}"),
              "x.yaml");
  EXPECT_FALSE(o.check_enabled);
  EXPECT_EQ(o.check_held_out, 32);
  EXPECT_TRUE(o.augment_flagged);
  EXPECT_EQ(o.check.region_samples, 10);
  EXPECT_DOUBLE_EQ(o.check.thresholds.unsafe, 0.5);
  EXPECT_NE(
      ErrorOf([&] { o.ApplyYaml(YAML::Load("{check: {bogus: 1}}"), "x.yaml"); }).find("bogus"),
      std::string::npos);
  o.check.thresholds.near_dangerous = std::nan("");
  EXPECT_NE(ErrorOf([&] { o.Validate(); }).find("near_dangerous = nan"), std::string::npos);
}

data::StateSet Numbered(long n, float offset) {
  data::StateSet s;
  s.features = {"id"};
  s.states.resize(1, n);
  for (long i = 0; i < n; ++i) s.states(0, i) = offset + static_cast<float>(i);
  return s;
}

TEST(DerbyExperimentsTest, BarrierDataVariantsKeepFlipAndValidate) {
  const std::vector<BarrierDataVariant> variants =
      SensitivityVariants({1.0, 0.1, 0.01}, {1, 2, 4, 8}, {0.0, 0.1, 0.3, 0.5});
  std::vector<std::string> names;
  for (const auto& v : variants) names.push_back(v.name);
  EXPECT_EQ(names, (std::vector<std::string>{"baseline", "data 10%", "data 1%", "imbalance 1:2",
                                             "imbalance 1:4", "imbalance 1:8", "label noise 10%",
                                             "label noise 30%", "label noise 50%"}));

  // Label noise: 30 % of each class moves to the other; nothing is lost or duplicated.
  data::StateSet safe = Numbered(100, 0), nd = Numbered(50, 1000);
  ApplyBarrierDataVariant({"noise", 1.0, 1, 0.3}, 7, &safe, &nd);
  EXPECT_EQ(safe.size(), 100 - 30 + 15);
  EXPECT_EQ(nd.size(), 50 - 15 + 30);
  std::set<float> all;
  long safe_from_nd = 0, nd_from_safe = 0;
  for (long i = 0; i < safe.size(); ++i) {
    all.insert(safe.states(0, i));
    safe_from_nd += safe.states(0, i) >= 1000;
  }
  for (long i = 0; i < nd.size(); ++i) {
    all.insert(nd.states(0, i));
    nd_from_safe += nd.states(0, i) < 1000;
  }
  EXPECT_EQ(all.size(), 150u);
  EXPECT_EQ(safe_from_nd, 15);
  EXPECT_EQ(nd_from_safe, 30);

  // Deterministic for a seed, different across seeds.
  data::StateSet s1 = Numbered(100, 0), n1 = Numbered(50, 1000);
  data::StateSet s2 = Numbered(100, 0), n2 = Numbered(50, 1000);
  data::StateSet s3 = Numbered(100, 0), n3 = Numbered(50, 1000);
  ApplyBarrierDataVariant({"size", 0.1, 1, 0.0}, 1, &s1, &n1);
  ApplyBarrierDataVariant({"size", 0.1, 1, 0.0}, 1, &s2, &n2);
  ApplyBarrierDataVariant({"size", 0.1, 1, 0.0}, 2, &s3, &n3);
  EXPECT_EQ(s1.size(), 10);
  EXPECT_EQ(n1.size(), 5);
  EXPECT_EQ(s1.states, s2.states);
  EXPECT_NE(s1.states, s3.states);

  // Imbalance 1:8 keeps every safe state and 1/8 of the near-dangerous ones.
  data::StateSet s4 = Numbered(80, 0), n4 = Numbered(80, 1000);
  ApplyBarrierDataVariant({"imbalance", 1.0, 8, 0.0}, 3, &s4, &n4);
  EXPECT_EQ(s4.size(), 80);
  EXPECT_EQ(n4.size(), 10);

  EXPECT_HAS(ErrorOf([&] { ApplyBarrierDataVariant({"bad", 0.0, 1, 0.0}, 1, &s4, &n4); }),
             "data_fraction = 0");
  EXPECT_HAS(ErrorOf([&] { ApplyBarrierDataVariant({"bad", 1.0, 0, 0.0}, 1, &s4, &n4); }),
             "imbalance = 0");
  EXPECT_HAS(ErrorOf([&] { ApplyBarrierDataVariant({"bad", 1.0, 1, 1.0}, 1, &s4, &n4); }),
             "label_noise = 1");
}

TEST(DerbyExperimentsTest, OptionsAreValidated) {
  ExperimentOptions o = Tiny();
  o.seeds = 0;
  EXPECT_HAS(ErrorOf([&] { RunTiny(ExperimentKind::kMethodComparison, o); }),
             "ExperimentOptions::seeds = 0");
  o = Tiny();
  o.label_noise = {0.0, 1.5};
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "label_noise[] = 1.5");
  o = Tiny();
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{policy: {}}"), "cfg.yaml"); }),
             "cfg.yaml: unknown section 'policy'");
}

TEST(DerbyExperimentsTest, JointSectionSetsTheCbfWeight) {
  ExperimentOptions o = Tiny();
  o.ApplyYaml(YAML::Load("{joint: {weight: 25, class_k_gain: 2}, airl: {iterations: 3}}"),
              "cfg.yaml");
  EXPECT_EQ(o.joint.weight, 25.0);
  EXPECT_EQ(o.joint.class_k_gain, 2.0);
  EXPECT_EQ(o.joint.dt, policy::JointCbfOptions{}.dt);  // untouched fields keep their defaults
  EXPECT_EQ(o.airl.iterations, 3);
  EXPECT_EQ(o.ToJson()["joint"]["weight"], 25.0);
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{joint: {cbf_weight: 3}}"), "cfg.yaml"); }),
             "unknown field 'cbf_weight'");
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{joint: {weight: heavy}}"), "cfg.yaml"); }),
             "weight");
  o.ApplyYaml(YAML::Load("{joint: {weight: -1}}"), "cfg.yaml");
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "JointCbfOptions::weight = -1");
}

}  // namespace
}  // namespace secure::experiments
