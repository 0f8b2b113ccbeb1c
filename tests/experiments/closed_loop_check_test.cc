// The closed-loop check before deployment with model selection (ClosedLoopCheckOptions), on
// Derby's tiny profile: a passing first candidate changes no number, failing candidates are
// replaced and recorded, the evaluated models are the selected candidate's, and a seed that no
// candidate passes is reported as failed.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <string>

#include "domains/derby/domain.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/atomic_file.h"
#include "secure/data/data.h"
#include "secure/eval/policy_eval.h"
#include "secure/experiments/experiment.h"
#include "secure/policy/gaussian_policy.h"
#include "tests/experiments/tiny_derby.h"
#include "tests/test_util.h"

namespace secure::experiments {
namespace {

using test::ErrorOf;

const domains::derby::DerbyDomain& TinyDomain() { return test::TinyDerby(); }

ExperimentOptions Tiny() {
  ExperimentOptions o = test::TinyDerbyOptions();
  o.seeds = 1;
  o.episodes = 6;
  o.check_enabled = false;
  o.methods = {eval::Method::kAirl, eval::Method::kSecure};
  return o;
}

std::string Scratch(const std::string& name) {
  const std::string dir = ::testing::TempDir() + "/closed_loop_" + name;
  std::filesystem::remove_all(dir);
  return dir;
}

TEST(ClosedLoopCheck, APassingFirstCandidateChangesNoNumber) {
  const ExperimentOptions off = Tiny();
  ExperimentOptions on = off;
  on.closed_loop.enabled = true;
  on.closed_loop.episodes = 5;
  on.closed_loop.min_success = 0.0;  // every candidate passes
  on.closed_loop.max_dangerous = 1.0;
  const ExperimentResult a = RunExperiment(ExperimentKind::kMethodComparison, TinyDomain(), off, nullptr);
  const ExperimentResult b = RunExperiment(ExperimentKind::kMethodComparison, TinyDomain(), on, nullptr);
  const nlohmann::json ja = a.ToJson(), jb = b.ToJson();
  for (const char* name : {"airl", "secure"})
    for (const char* key : {"successes", "dangerous", "collision_events", "steps", "interventions"})
      EXPECT_EQ(ja["methods"][name]["seeds"][0][key], jb["methods"][name]["seeds"][0][key])
          << name << " " << key;
  // Off: nothing of the check anywhere, so earlier results keep their bytes.
  EXPECT_FALSE(ja["experiment"]["options"].contains("closed_loop"));
  EXPECT_FALSE(ja["experiment"]["seeds"][0].contains("closed_loop"));
  EXPECT_EQ(a.Table().find("Closed-loop check"), std::string::npos);
  const nlohmann::json& c = jb["experiment"]["seeds"][0]["closed_loop"];
  ASSERT_TRUE(c.is_object()) << jb["experiment"]["seeds"][0].dump();
  EXPECT_EQ(c["verdict"], "pass");
  EXPECT_EQ(c["selected"], 0);
  ASSERT_EQ(c["candidates"].size(), 1u);
  EXPECT_EQ(c["candidates"][0]["training_seed"], 0u);
  EXPECT_EQ(c["candidates"][0]["episodes"], 5);
  EXPECT_TRUE(jb["experiment"]["options"].contains("closed_loop"));
  EXPECT_NE(b.Table().find("Closed-loop check per seed"), std::string::npos) << b.Table();
  EXPECT_NE(b.Table().find("0 of 1 seeds evaluated with a replacement candidate; 0 failed"),
            std::string::npos)
      << b.Table();
}

TEST(ClosedLoopCheck, FailingCandidatesAreReplacedAndTheSelectedOneIsEvaluated) {
  ExperimentOptions o = Tiny();
  o.closed_loop.enabled = true;
  o.closed_loop.episodes = 5;
  o.closed_loop.min_success = 1.0;  // 100 % and no dangerous episode: rarely met after 1 AIRL iteration
  o.closed_loop.max_dangerous = 0.0;
  o.closed_loop.max_candidates = 3;
  o.output_dir = Scratch("replace");
  const ExperimentResult r = RunExperiment(ExperimentKind::kMethodComparison, TinyDomain(), o, nullptr);
  const nlohmann::json j = r.ToJson();
  const nlohmann::json& c = j["experiment"]["seeds"][0]["closed_loop"];
  ASSERT_TRUE(c.is_object());
  const nlohmann::json& candidates = c["candidates"];
  ASSERT_GE(candidates.size(), 1u);
  ASSERT_LE(candidates.size(), 3u);
  // Candidates stop at the first that passes; all before it failed.
  for (std::size_t k = 0; k + 1 < candidates.size(); ++k)
    EXPECT_FALSE(candidates[k]["passed"].get<bool>()) << k;
  const bool last_passed = candidates.back()["passed"].get<bool>();
  EXPECT_TRUE(last_passed || candidates.size() == 3u);
  EXPECT_EQ(c["verdict"], last_passed ? "pass" : "failed");
  // Each candidate trained from its own initialisation.
  for (std::size_t k = 0; k < candidates.size(); ++k)
    EXPECT_EQ(candidates[k]["training_seed"].get<std::uint64_t>(),
              CandidateSeed(0, static_cast<int>(k)));
  // The selected candidate: the best by (failed criteria, success - dangerous).
  const std::size_t selected = c["selected"].get<std::size_t>();
  ASSERT_LT(selected, candidates.size());
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    const int fk = static_cast<int>(candidates[k]["failed_criteria"].size());
    const int fs = static_cast<int>(candidates[selected]["failed_criteria"].size());
    EXPECT_LE(fs, fk) << k;
  }
  // The models under the usual names are the selected candidate's, bit for bit, and the
  // evaluation's AIRL row is that policy on the seed's evaluation episodes.
  const std::string chosen = o.output_dir + "/seed-0/candidate-" + std::to_string(selected);
  EXPECT_EQ(ReadFile(o.output_dir + "/seed-0/airl.model"), ReadFile(chosen + "/airl.model"));
  EXPECT_EQ(ReadFile(o.output_dir + "/seed-0/barrier.model"), ReadFile(chosen + "/barrier.model"));
  EXPECT_EQ(ReadFile(o.output_dir + "/seed-0/airl_curve.csv"), ReadFile(chosen + "/airl_curve.csv"));
  for (std::size_t k = 0; k < candidates.size(); ++k) {
    if (k == selected) continue;
    EXPECT_NE(ReadFile(o.output_dir + "/seed-0/candidate-" + std::to_string(k) + "/airl.model"),
              ReadFile(chosen + "/airl.model"))
        << k;
  }
  const policy::GaussianPolicy airl = policy::GaussianPolicy::Load(chosen + "/airl.model");
  eval::SeedModels models;
  models.airl = &airl;
  const std::unique_ptr<domains::Environment> env = TinyDomain().MakeEnvironment();
  const eval::SeedResult again = eval::EvaluateMethods(*env, {eval::Method::kAirl}, models, o.shield,
                                                       o.episodes, eval::EvaluationSeed(0))
                                     .at(eval::Method::kAirl);
  const nlohmann::json& evaluated = j["methods"]["airl"]["seeds"][0];
  EXPECT_EQ(evaluated["successes"], again.successes);
  EXPECT_EQ(evaluated["dangerous"], again.dangerous);
  EXPECT_EQ(evaluated["collision_events"], again.collision_events);
  EXPECT_NE(r.Table().find(last_passed ? "| pass |" : "| **failed** |"), std::string::npos)
      << r.Table();
  std::filesystem::remove_all(o.output_dir);
}

// Records, for one replayed episode, the observation each step started from and whether it was
// dangerous.
class StepRecorder final : public eval::StepObserver {
 public:
  void OnEpisodeStart(long, const Eigen::VectorXf& observation) override {
    before.push_back(observation);
  }
  void OnStep(const eval::StepView& step) override {
    dangerous.push_back(step.outcome.collided);
    before.push_back(step.observation);
  }
  std::vector<Eigen::VectorXf> before;  // before[t]: the observation step t started from
  std::vector<bool> dangerous;
};

TEST(ClosedLoopCheck, RepairAddsTheStatesBeforeDangerousStepsWhichReproduceWhenReplayed) {
  ExperimentOptions o = Tiny();
  o.closed_loop.enabled = true;
  o.closed_loop.episodes = 12;
  o.closed_loop.min_success = 0.0;
  o.closed_loop.max_dangerous = 0.0;  // any dangerous episode fails the candidate
  o.closed_loop.max_candidates = 1;
  o.closed_loop.repair_rounds = 1;
  o.closed_loop.repair_lookback = 2;
  // A myopic shield (alpha dt >> 1: any next h >= -(alpha dt - 1) h(s) is admitted) lets the
  // tiny policy collide.
  o.shield.class_k_gain = 1000.0;
  o.output_dir = Scratch("repair");
  const ExperimentResult r =
      RunExperiment(ExperimentKind::kMethodComparison, TinyDomain(), o, nullptr);
  const nlohmann::json j = r.ToJson();
  EXPECT_EQ(j["experiment"]["options"]["closed_loop"]["repair_rounds"], 1);
  const nlohmann::json& candidate = j["experiment"]["seeds"][0]["closed_loop"]["candidates"][0];
  ASSERT_TRUE(candidate.contains("repairs"))
      << "the tiny AIRL policy under the shield was expected to have a dangerous check episode: "
      << candidate.dump();
  const nlohmann::json& repair = candidate["repairs"][0];
  EXPECT_GT(candidate["unrepaired"]["dangerous_rate"].get<double>(), 0.0);
  const long added = repair["counterexamples"].get<long>();
  EXPECT_GT(added, 0);
  EXPECT_EQ(repair["near_dangerous_states"].get<long>(),
            static_cast<long>(TinyDomain().options().near_dangerous.count) + added);
  // The record's verdict is the repaired candidate's.
  EXPECT_EQ(candidate["dangerous_rate"], repair["dangerous_rate"]);
  EXPECT_EQ(candidate["passed"], repair["passed"]);
  EXPECT_NE(r.Table().find("| repairs (dangerous % before) |"), std::string::npos) << r.Table();
  EXPECT_NE(r.Table().find("1 with a repaired barrier"), std::string::npos) << r.Table();

  // The evaluated barrier is the repaired one.
  const std::string files = o.output_dir + "/seed-0/candidate-0";
  EXPECT_EQ(ReadFile(o.output_dir + "/seed-0/barrier.model"),
            ReadFile(files + "/barrier_repair_1.model"));
  EXPECT_NE(ReadFile(files + "/barrier.model"), ReadFile(files + "/barrier_repair_1.model"));

  // Every counterexample reproduces when its episode is replayed alone with the unrepaired
  // candidate: the episode passes through that observation at that step, and the step that ends
  // an episode's run of counterexamples is its first dangerous one.
  const std::unique_ptr<domains::Environment> env = TinyDomain().MakeEnvironment();
  std::vector<std::string> columns = {"episode", "step"};
  for (const std::string& f : env->ObservationFeatures()) columns.push_back(f);
  const data::NumericTable table = data::ReadCsv(files + "/counterexamples_1.csv", columns);
  ASSERT_EQ(table.values.cols(), added);
  const policy::GaussianPolicy airl = policy::GaussianPolicy::Load(files + "/airl.model");
  const cbf::CarBarrierNet barrier = cbf::CarBarrierNet::Load(files + "/barrier.model");
  eval::SeedModels models;
  models.airl = &airl;
  models.make_barrier = [&] { return barrier.MakeEvaluator(256); };
  long replayed = 0;
  for (Eigen::Index i = 0; i < table.values.cols(); ++i) {
    const long episode = static_cast<long>(table.values(0, i));
    const int step = static_cast<int>(table.values(1, i));
    const bool last = i + 1 == table.values.cols() || table.values(0, i + 1) != episode;
    eval::EpisodeRunnerOptions ro;
    ro.first_episode = episode;
    eval::EpisodeRunner runner(*env, ro);
    StepRecorder recorder;
    eval::RunMethod(runner, eval::Method::kSecure, models, o.shield, 1, ClosedLoopCheckSeed(0),
                    &recorder);
    ASSERT_LT(static_cast<std::size_t>(step), recorder.dangerous.size()) << i;
    const Eigen::VectorXf state = table.values.col(i).tail(env->observation_dim()).cast<float>();
    EXPECT_LE((recorder.before[static_cast<std::size_t>(step)] - state).cwiseAbs().maxCoeff(),
              1e-5f * (1.0f + state.cwiseAbs().maxCoeff()))
        << "counterexample " << i << " (episode " << episode << ", step " << step << ")";
    for (int t = 0; t < step; ++t)
      EXPECT_FALSE(recorder.dangerous[static_cast<std::size_t>(t)]) << i << " step " << t;
    if (last) {
      EXPECT_TRUE(recorder.dangerous[static_cast<std::size_t>(step)]) << i;
      ++replayed;
    }
  }
  EXPECT_GT(replayed, 0);
  std::filesystem::remove_all(o.output_dir);
}

// A flat barrier ensemble (BarrierTrainerOptions::ensemble) through the check and its repair:
// the candidate's barrier and the repaired one are ensembles of 2, the repair retrains both
// members on the augmented labels, and the evaluated barrier is the repaired ensemble.
TEST(ClosedLoopCheck, RepairRetrainsEveryMemberOfABarrierEnsemble) {
  ExperimentOptions o = Tiny();
  o.barrier_kind = BarrierKind::kFlat;
  o.flat_barrier.hidden = {16, 16};
  o.flat_barrier.max_epochs = 5;
  o.flat_barrier.ensemble = 2;
  o.closed_loop.enabled = true;
  o.closed_loop.episodes = 12;
  o.closed_loop.min_success = 0.0;
  o.closed_loop.max_dangerous = 0.0;
  o.closed_loop.max_candidates = 1;
  o.closed_loop.repair_rounds = 1;
  o.shield.class_k_gain = 1000.0;  // myopic: the tiny policy collides (the repair test above)
  o.output_dir = Scratch("ensemble");
  const ExperimentResult r =
      RunExperiment(ExperimentKind::kMethodComparison, TinyDomain(), o, nullptr);
  const nlohmann::json j = r.ToJson();
  const nlohmann::json& candidate = j["experiment"]["seeds"][0]["closed_loop"]["candidates"][0];
  EXPECT_EQ(candidate["barrier"]["members"], 2) << candidate.dump();
  ASSERT_TRUE(candidate.contains("repairs")) << candidate.dump();
  EXPECT_EQ(candidate["repairs"][0]["barrier"]["members"], 2);
  const std::string files = o.output_dir + "/seed-0/candidate-0";
  const cbf::BarrierNet before = cbf::BarrierNet::Load(files + "/barrier.model");
  const cbf::BarrierNet after = cbf::BarrierNet::Load(files + "/barrier_repair_1.model");
  ASSERT_EQ(before.members(), 2);
  ASSERT_EQ(after.members(), 2);
  for (int k = 0; k < 2; ++k)
    EXPECT_NE(before.Member(k).mlp.layers[0].weight, after.Member(k).mlp.layers[0].weight) << k;
  EXPECT_EQ(ReadFile(o.output_dir + "/seed-0/barrier.model"),
            ReadFile(files + "/barrier_repair_1.model"));
  std::filesystem::remove_all(o.output_dir);
}

TEST(ClosedLoopCheck, OptionsFromYamlAndValidation) {
  ExperimentOptions o = Tiny();
  o.ApplyYaml(YAML::Load("{closed_loop: {enabled: true, episodes: 20, min_success: 0.9, "
                         "max_dangerous: 0.01, max_candidates: 5, repair_rounds: 2, "
                         "repair_lookback: 4}}"),
              "cfg.yaml");
  EXPECT_TRUE(o.closed_loop.enabled);
  EXPECT_EQ(o.closed_loop.episodes, 20);
  EXPECT_EQ(o.closed_loop.min_success, 0.9);
  EXPECT_EQ(o.closed_loop.max_dangerous, 0.01);
  EXPECT_EQ(o.closed_loop.max_candidates, 5);
  EXPECT_EQ(o.closed_loop.repair_rounds, 2);
  EXPECT_EQ(o.closed_loop.repair_lookback, 4);
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{closed_loop: {rounds: 2}}"), "cfg.yaml"); }),
             "unknown key 'rounds'");
  ExperimentOptions bad = Tiny();
  bad.closed_loop.max_candidates = 0;
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "ClosedLoopCheckOptions::max_candidates = 0");
  bad = Tiny();
  bad.closed_loop.repair_rounds = -1;
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "ClosedLoopCheckOptions::repair_rounds = -1");
  bad = Tiny();
  bad.closed_loop.repair_lookback = 0;
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "ClosedLoopCheckOptions::repair_lookback = 0");
  bad = Tiny();
  bad.closed_loop.min_success = 1.5;
  EXPECT_HAS(ErrorOf([&] { bad.Validate(); }), "ClosedLoopCheckOptions::min_success = 1.5");
  bad = Tiny();
  bad.closed_loop.enabled = true;
  bad.methods = {eval::Method::kBc};
  EXPECT_HAS(ErrorOf([&] { RunExperiment(ExperimentKind::kMethodComparison, TinyDomain(), bad, nullptr); }),
             "the methods must include AIRL and a shielded method");
  // Distinct streams and seeds.
  EXPECT_NE(ClosedLoopCheckSeed(3), eval::EvaluationSeed(3));
  EXPECT_EQ(CandidateSeed(7, 0), 7u);
  EXPECT_NE(CandidateSeed(7, 1), CandidateSeed(8, 0));
}

TEST(ClosedLoopCheck, TheSensitivityStudysVariantsTrainWithTheSelectedCandidatesSeed) {
  ExperimentOptions o = Tiny();
  o.methods = {};
  o.data_fractions = {1.0, 0.5};
  o.imbalance_ratios = {1};
  o.label_noise = {0.0};
  o.closed_loop.enabled = true;
  o.closed_loop.episodes = 5;
  o.closed_loop.min_success = 1.0;
  o.closed_loop.max_dangerous = 0.0;
  o.closed_loop.max_candidates = 2;
  const nlohmann::json j =
      RunExperiment(ExperimentKind::kSensitivity, TinyDomain(), o, nullptr).ToJson();
  const nlohmann::json& seed = j["experiment"]["seeds"][0];
  const int selected = seed["closed_loop"]["selected"].get<int>();
  for (const auto& [name, record] : seed["barriers"].items())
    EXPECT_EQ(record["training_seed"].get<std::uint64_t>(), CandidateSeed(0, selected)) << name;
  EXPECT_EQ(seed["barriers"].size(), 2u);
}

}  // namespace
}  // namespace secure::experiments
