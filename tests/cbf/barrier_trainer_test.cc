#include "secure/cbf/barrier_trainer.h"
#include "tests/nn/nn_test_util.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/nn/torch_threads.h"

namespace secure::cbf {
namespace {

// Two classes in 2-D separated by the circle |p| = 1: inside is near-dangerous.
data::StateSet Disk(bool inside, int n, std::uint64_t seed) {
  Rng rng(seed);
  data::StateSet set{inside ? "inside" : "outside", {"px", "py"}, Eigen::MatrixXf(2, n)};
  int have = 0;
  while (have < n) {
    const double x = rng.Uniform(-2, 2), y = rng.Uniform(-2, 2);
    const double r = std::hypot(x, y);
    if ((inside && r < 0.9) || (!inside && r > 1.1)) {
      set.states(0, have) = static_cast<float>(x);
      set.states(1, have) = static_cast<float>(y);
      ++have;
    }
  }
  return set;
}

BarrierTrainerOptions Fast() {
  BarrierTrainerOptions o;
  o.hidden = {16, 16};
  o.max_epochs = 60;
  o.batch_size = 64;
  o.learning_rate = 1e-2;
  o.final_learning_rate = 1e-3;
  return o;
}

using secure::test::ErrorOf;

TEST(BarrierTrainerTest, LearnsASeparableProblem) {
  BarrierTrainingSummary summary;
  const BarrierNet net = TrainBarrier(Fast(), Disk(false, 300, 1), Disk(true, 200, 2), &summary);
  EXPECT_GE(summary.train_accuracy.Balanced(), 0.98);
  EXPECT_GE(summary.validation_accuracy.Balanced(), 0.95);
  // Fresh data from the same distribution.
  auto barrier = net.MakeEvaluator();
  const ClassAccuracy test =
      EvaluateAccuracy(*barrier, Disk(false, 500, 11).states, Disk(true, 500, 12).states);
  EXPECT_GE(test.safe, 0.95);
  EXPECT_GE(test.near_dangerous, 0.95);
  EXPECT_EQ(net.features, (std::vector<std::string>{"px", "py"}));
}

// `threads` reaches both LibTorch and OpenBLAS while training, and both counts are the caller's
// again afterwards (the trainer once set LibTorch's count only).
TEST(BarrierTrainerTest, ThreadsOptionHoldsForTrainingAndIsRestored) {
  ASSERT_GT(nn::BlasThreads(), 0) << "this build's BLAS is not OpenBLAS (scripts/setup.sh)";
  nn::SetTorchThreads(2);
  BarrierTrainerOptions options = Fast();
  options.threads = 1;
  int torch_inside = -1, blas_inside = -1;
  BarrierTrainingSummary summary;
  TrainBarrier(options, Disk(false, 100, 1), Disk(true, 100, 2), &summary,
               [&](int, double, double) {
                 torch_inside = nn::TorchThreads();
                 blas_inside = nn::BlasThreads();
                 return true;
               });
  EXPECT_EQ(torch_inside, 1);
  EXPECT_EQ(blas_inside, 1);
  EXPECT_EQ(nn::TorchThreads(), 2);
  EXPECT_EQ(nn::BlasThreads(), 2);
  nn::SetTorchThreads(1);
}

TEST(BarrierTrainerTest, SummaryCountsAndProvenance) {
  BarrierTrainerOptions o = Fast();
  o.validation_fraction = 0.2;
  BarrierTrainingSummary s;
  const BarrierNet net = TrainBarrier(o, Disk(false, 100, 1), Disk(true, 50, 2), &s);
  EXPECT_EQ(s.validation_safe, 20);
  EXPECT_EQ(s.validation_near_dangerous, 10);
  EXPECT_EQ(s.train_safe, 80);
  EXPECT_EQ(s.train_near_dangerous, 40);
  EXPECT_EQ(s.epochs, 60);
  EXPECT_EQ(s.iterations, 60 * 2);  // 120 training states, batches of 64
  EXPECT_GE(s.best_epoch, 1);
  EXPECT_LE(s.best_epoch, 60);
  EXPECT_EQ(s.stop_reason, "max_epochs");
  EXPECT_GT(s.wall_seconds, 0.0);
  EXPECT_EQ(net.provenance["options"]["hidden"], nlohmann::json({16, 16}));
  EXPECT_EQ(net.provenance["safe_states"]["count"], 100);
  EXPECT_FALSE(s.BriefReport().empty());
  EXPECT_NE(s.FullReport().find("validation"), std::string::npos);
}

TEST(BarrierTrainerTest, SameSeedSameWeightsOtherSeedOtherWeights) {
  const auto safe = Disk(false, 120, 1);
  const auto nd = Disk(true, 80, 2);
  BarrierTrainerOptions o = Fast();
  o.max_epochs = 5;
  const BarrierNet a = TrainBarrier(o, safe, nd, nullptr);
  const BarrierNet b = TrainBarrier(o, safe, nd, nullptr);
  o.seed = 1;
  const BarrierNet c = TrainBarrier(o, safe, nd, nullptr);
  nn::test::ExpectSameMlp(a.mlp, a.normalizer, b.mlp, b.normalizer);
  EXPECT_NE(a.mlp.layers[0].weight, c.mlp.layers[0].weight);
}

// even_batches (YAML key, JSON only when set): the same optimiser steps, cut into near-equal
// minibatches (130 states in batches of 64: 44, 43, 43 instead of 64, 64, 2), so other weights.
TEST(BarrierTrainerTest, EvenBatchesKeepTheStepsAndChangeTheMinibatches) {
  const auto safe = Disk(false, 80, 1);
  const auto nd = Disk(true, 50, 2);
  BarrierTrainerOptions o = Fast();
  o.max_epochs = 5;
  o.validation_fraction = 0.0;
  EXPECT_FALSE(o.ToJson().contains("even_batches"));  // earlier files keep their bytes
  BarrierTrainingSummary plain_summary, even_summary;
  const BarrierNet plain = TrainBarrier(o, safe, nd, &plain_summary);
  o.ApplyYaml(YAML::Load("{even_batches: true}"), "cfg.yaml");
  ASSERT_TRUE(o.even_batches);
  EXPECT_EQ(o.ToJson()["even_batches"], true);
  const BarrierNet even = TrainBarrier(o, safe, nd, &even_summary);
  EXPECT_EQ(plain_summary.iterations, 5 * 3);
  EXPECT_EQ(even_summary.iterations, 5 * 3);
  EXPECT_NE(plain.mlp.layers[0].weight, even.mlp.layers[0].weight);
  EXPECT_EQ(even.provenance["options"]["even_batches"], true);
}

TEST(BarrierTrainerTest, EarlyStoppingAndCallbackStop) {
  BarrierTrainerOptions o = Fast();
  o.max_epochs = 500;
  o.patience = 5;
  BarrierTrainingSummary s;
  TrainBarrier(o, Disk(false, 100, 1), Disk(true, 100, 2), &s);
  EXPECT_EQ(s.stop_reason, "early_stopping");
  EXPECT_LT(s.epochs, 500);
  EXPECT_EQ(s.epochs - s.best_epoch, 5);

  o.patience = 0;
  int calls = 0;
  TrainBarrier(o, Disk(false, 100, 1), Disk(true, 100, 2), &s,
               [&](int epoch, double, double) { return ++calls < 3; });
  EXPECT_EQ(calls, 3);
  EXPECT_EQ(s.epochs, 3);
  EXPECT_EQ(s.stop_reason, "callback");
}

TEST(BarrierTrainerTest, RejectsBadData) {
  const auto safe = Disk(false, 10, 1);
  data::StateSet empty{"empty.csv", {"px", "py"}, Eigen::MatrixXf(2, 0)};
  std::string msg = ErrorOf([&] { TrainBarrier(Fast(), safe, empty, nullptr); });
  EXPECT_NE(msg.find("near-dangerous"), std::string::npos) << msg;
  EXPECT_NE(msg.find("empty.csv"), std::string::npos) << msg;

  data::StateSet other{"other.csv", {"px", "vx"}, Eigen::MatrixXf::Zero(2, 3)};
  msg = ErrorOf([&] { TrainBarrier(Fast(), safe, other, nullptr); });
  EXPECT_NE(msg.find("different features"), std::string::npos) << msg;

  data::StateSet nan = Disk(true, 10, 2);
  nan.states(1, 4) = std::numeric_limits<float>::quiet_NaN();
  msg = ErrorOf([&] { TrainBarrier(Fast(), safe, nan, nullptr); });
  EXPECT_FALSE(msg.empty());
}

TEST(BarrierTrainerOptionsTest, ValidateNamesFieldValueAndRule) {
  BarrierTrainerOptions o;
  o.batch_size = 0;
  EXPECT_EQ(ErrorOf([&] { o.Validate(); }), "BarrierTrainerOptions::batch_size = 0, must be > 0");
  o = {};
  o.hidden = {64, 0};
  EXPECT_EQ(ErrorOf([&] { o.Validate(); }), "BarrierTrainerOptions::hidden[1] = 0, must be > 0");
  o = {};
  o.validation_fraction = 1.0;
  EXPECT_NE(ErrorOf([&] { o.Validate(); }).find("validation_fraction = 1"), std::string::npos);
  o = {};
  o.learning_rate = std::nan("");
  EXPECT_NE(ErrorOf([&] { o.Validate(); }).find("learning_rate = nan"), std::string::npos);
  EXPECT_NO_THROW(BarrierTrainerOptions{}.Validate());
}

TEST(BarrierTrainerOptionsTest, ValidateBoundsTheLayerWidth) {
  BarrierTrainerOptions o;
  o.hidden = {64, 2000000000};
  EXPECT_EQ(ErrorOf([&] { o.Validate(); }),
            "BarrierTrainerOptions::hidden[1] = 2000000000, must be in [1, 10000]");
  o.hidden = {10000};
  EXPECT_NO_THROW(o.Validate());
}

TEST(BarrierTrainerTest, ReportsSayThereWasNoValidationSplit) {
  BarrierTrainerOptions o = Fast();
  o.validation_fraction = 0.0;
  BarrierTrainingSummary s;
  TrainBarrier(o, Disk(false, 40, 1), Disk(true, 40, 2), &s);
  ASSERT_EQ(s.validation_safe + s.validation_near_dangerous, 0);
  EXPECT_HAS(s.FullReport(), "| validation | 0 | 0 | n/a | n/a (no held-out states) |");
  EXPECT_HAS(s.BriefReport(), "val acc n/a (no held-out states)");
  EXPECT_TRUE(s.ToJson()["validation_accuracy"].is_null());
  o.validation_fraction = 0.25;
  TrainBarrier(o, Disk(false, 40, 1), Disk(true, 40, 2), &s);
  EXPECT_TRUE(s.ToJson()["validation_accuracy"]["safe"].is_number());
  EXPECT_EQ(s.FullReport().find("n/a"), std::string::npos) << s.FullReport();
}

TEST(BarrierTrainerOptionsTest, YamlOverridesAndRejectsUnknownKeys) {
  BarrierTrainerOptions o;
  o.ApplyYaml(YAML::Load("{hidden: [8, 4], activation: relu, max_epochs: 7, safe_margin: 0.5}"),
              "cfg.yaml");
  EXPECT_EQ(o.hidden, (std::vector<int>{8, 4}));
  EXPECT_EQ(o.activation, nn::Activation::kRelu);
  EXPECT_EQ(o.max_epochs, 7);
  EXPECT_DOUBLE_EQ(o.safe_margin, 0.5);
  EXPECT_EQ(o.batch_size, BarrierTrainerOptions{}.batch_size);  // untouched
  std::string msg = ErrorOf([&] { o.ApplyYaml(YAML::Load("{max_epoch: 3}"), "cfg.yaml"); });
  EXPECT_NE(msg.find("cfg.yaml: unknown field 'max_epoch'"), std::string::npos) << msg;
  msg = ErrorOf([&] { o.ApplyYaml(YAML::Load("{batch_size: many}"), "cfg.yaml"); });
  EXPECT_NE(msg.find("'batch_size'"), std::string::npos) << msg;
  EXPECT_NE(msg.find("many"), std::string::npos) << msg;
  msg = ErrorOf([&] { o.ApplyYaml(YAML::Load("{activation: sigmoid}"), "cfg.yaml"); });
  EXPECT_NE(msg.find("sigmoid"), std::string::npos) << msg;
}

// `set` (px, py) inside wider states: (noise, py, junk, px), the extra rows random.
data::StateSet Widen(const data::StateSet& set, std::uint64_t seed) {
  Rng rng(seed);
  data::StateSet wide{set.source, {"noise", "py", "junk", "px"}, Eigen::MatrixXf(4, set.size())};
  for (long j = 0; j < set.size(); ++j) {
    wide.states(0, j) = static_cast<float>(rng.Uniform(-5, 5));
    wide.states(1, j) = set.states(1, j);
    wide.states(2, j) = static_cast<float>(rng.Uniform(100, 200));
    wide.states(3, j) = set.states(0, j);
  }
  return wide;
}

TEST(BarrierTrainerTest, InputFeaturesSelectAndOrderTheColumns) {
  const auto safe = Disk(false, 120, 1), nd = Disk(true, 80, 2);
  const auto wide_safe = Widen(safe, 3), wide_nd = Widen(nd, 4);
  BarrierTrainerOptions o = Fast();
  o.max_epochs = 5;
  const BarrierNet reference = TrainBarrier(o, safe, nd, nullptr);
  o.input_features = {"px", "py"};
  BarrierTrainingSummary summary;
  const BarrierNet net = TrainBarrier(o, wide_safe, wide_nd, &summary);
  EXPECT_EQ(net.features, (std::vector<std::string>{"px", "py"}));
  EXPECT_EQ(net.state_dim(), 2);
  EXPECT_EQ(net.provenance["options"]["input_features"], nlohmann::json({"px", "py"}));
  // Training on the selected columns is training on those data: the same weights.
  nn::test::ExpectSameMlp(net.mlp, net.normalizer, reference.mlp, reference.normalizer);
  // On the wide states, h equals h on the projected states exactly.
  Eigen::VectorXf h_wide(wide_safe.size()), h_projected(safe.size());
  const std::unique_ptr<Barrier> wide = net.MakeEvaluatorFor(wide_safe.features, "wide states");
  EXPECT_EQ(wide->state_dim(), 4);
  wide->Evaluate(wide_safe.states, h_wide);
  net.MakeEvaluator()->Evaluate(safe.states, h_projected);
  EXPECT_EQ(h_wide, h_projected);

  // The order given is the model's order: (py, px) reads the rows swapped.
  o.input_features = {"py", "px"};
  const BarrierNet swapped = TrainBarrier(o, wide_safe, wide_nd, nullptr);
  EXPECT_EQ(swapped.features, (std::vector<std::string>{"py", "px"}));
  EXPECT_EQ(swapped.normalizer.mean[0], reference.normalizer.mean[1]);
  EXPECT_EQ(swapped.normalizer.mean[1], reference.normalizer.mean[0]);
  // All features in the data's order: the same as no selection.
  o.input_features = wide_safe.features;
  EXPECT_EQ(TrainBarrier(o, wide_safe, wide_nd, nullptr).features, wide_safe.features);
}

TEST(BarrierTrainerTest, AnInputFeatureMissingFromTheDataIsNamed) {
  BarrierTrainerOptions o = Fast();
  o.input_features = {"px", "vz"};
  const std::string msg = ErrorOf([&] {
    TrainBarrier(o, Widen(Disk(false, 10, 1), 3), Widen(Disk(true, 10, 2), 4), nullptr);
  });
  EXPECT_HAS(msg, "(outside) has 4 features (noise, py, junk, px), without 'vz'");
  EXPECT_HAS(msg, "BarrierTrainerOptions::input_features reads (2: px, vz)");
}

// Only the selected columns must be finite: a NaN in a column the barrier does not read is fine.
TEST(BarrierTrainerTest, OnlyTheSelectedColumnsAreChecked) {
  BarrierTrainerOptions o = Fast();
  o.max_epochs = 2;
  o.input_features = {"px", "py"};
  data::StateSet safe = Widen(Disk(false, 20, 1), 3);
  safe.states(2, 5) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NO_THROW(TrainBarrier(o, safe, Widen(Disk(true, 20, 2), 4), nullptr));
  o.input_features = {"junk", "px"};
  EXPECT_THROW(TrainBarrier(o, safe, Widen(Disk(true, 20, 2), 4), nullptr), Error);
}

TEST(BarrierTrainerOptionsTest, InputFeaturesInYamlJsonAndValidate) {
  BarrierTrainerOptions o;
  EXPECT_TRUE(o.input_features.empty());
  EXPECT_EQ(o.ToJson()["input_features"], nlohmann::json::array());
  o.ApplyYaml(YAML::Load("{input_features: [ee_x, ee_y, block_z]}"), "cfg.yaml");
  EXPECT_EQ(o.input_features, (std::vector<std::string>{"ee_x", "ee_y", "block_z"}));
  EXPECT_EQ(o.ToJson()["input_features"], nlohmann::json({"ee_x", "ee_y", "block_z"}));
  EXPECT_NO_THROW(o.Validate());
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{input_features: ee_x}"), "cfg.yaml"); }),
             "cfg.yaml: field 'input_features' must be a list of feature names");
  o.input_features = {"ee_x", "ee_y", "ee_x"};
  EXPECT_EQ(ErrorOf([&] { o.Validate(); }),
            "BarrierTrainerOptions::input_features[2] = 'ee_x', must be a name not given before "
            "(it is also input_features[0])");
  o.input_features = {"ee_x", ""};
  EXPECT_EQ(ErrorOf([&] { o.Validate(); }),
            "BarrierTrainerOptions::input_features[1] = '', must be a non-empty feature name");
}

// Two runs with the same seed and data write byte-identical model files: no wall-clock time in
// the file (it stays in the summary the caller gets, i.e. the run record).
class BarrierTrainerFileTest : public secure::test::TempDirTest {};

TEST_F(BarrierTrainerFileTest, SameSeedGivesByteIdenticalModelFiles) {
  const auto safe = Disk(false, 60, 1);
  const auto nd = Disk(true, 40, 2);
  BarrierTrainerOptions o = Fast();
  o.max_epochs = 3;
  BarrierTrainingSummary sa, sb;
  TrainBarrier(o, safe, nd, &sa).Save(PathOf("a.model"));
  TrainBarrier(o, safe, nd, &sb).Save(PathOf("b.model"));
  const std::string a = ReadFile(PathOf("a.model")), b = ReadFile(PathOf("b.model"));
  EXPECT_TRUE(a == b) << "model files of two same-seed runs differ";
  const BarrierNet loaded = BarrierNet::Load(PathOf("a.model"));
  EXPECT_FALSE(loaded.provenance["summary"].contains("wall_seconds"));
  EXPECT_EQ(loaded.provenance["summary"]["epochs"], 3);
  EXPECT_GT(sa.wall_seconds, 0.0);  // the caller still gets the timing
  EXPECT_TRUE(sa.ToJson().contains("wall_seconds"));
}

// ensemble = K: K members, member k trained with EnsembleMemberSeed(seed, k); member 0 is the
// barrier of ensemble = 1 (the same path reproducing itself: bitwise).
TEST_F(BarrierTrainerFileTest, EnsembleOfThreeHasDistinctMembersAndMemberZeroIsTheSingleOne) {
  const auto safe = Disk(false, 80, 1);
  const auto nd = Disk(true, 60, 2);
  BarrierTrainerOptions o = Fast();
  o.max_epochs = 5;
  o.seed = 17;
  BarrierTrainingSummary single_summary, summary;
  const BarrierNet single = TrainBarrier(o, safe, nd, &single_summary);
  EXPECT_EQ(single.members(), 1);
  EXPECT_FALSE(single.provenance["options"].contains("ensemble"));
  EXPECT_FALSE(single_summary.ToJson().contains("members"));
  o.ensemble = 3;
  int epochs_seen = 0;
  const BarrierNet net = TrainBarrier(o, safe, nd, &summary, [&](int, double, double) {
    ++epochs_seen;
    return true;
  });
  ASSERT_EQ(net.members(), 3);
  EXPECT_EQ(epochs_seen, 15);  // every member's epochs
  EXPECT_EQ(summary.members, 3);
  EXPECT_NE(summary.BriefReport().find("(member 0 of 3)"), std::string::npos);
  EXPECT_EQ(net.provenance["options"]["ensemble"], 3);
  EXPECT_EQ(net.provenance["member_summaries"].size(), 3u);
  for (std::size_t l = 0; l < single.mlp.layers.size(); ++l)
    EXPECT_EQ(net.mlp.layers[l].weight, single.mlp.layers[l].weight) << "layer " << l;
  EXPECT_EQ(net.normalizer.mean, single.normalizer.mean);
  for (int a = 0; a < 3; ++a)
    for (int b = a + 1; b < 3; ++b)
      EXPECT_NE(net.Member(a).mlp.layers[0].weight, net.Member(b).mlp.layers[0].weight)
          << "members " << a << " and " << b;
  EXPECT_EQ(EnsembleMemberSeed(17, 0), 17u);
  EXPECT_NE(EnsembleMemberSeed(17, 1), EnsembleMemberSeed(17, 2));
  // h is the least member's.
  const Eigen::MatrixXf states = Disk(false, 30, 5).states;
  Eigen::VectorXf h(30), h0(30);
  net.MakeEvaluator()->Evaluate(states, h);
  single.MakeEvaluator()->Evaluate(states, h0);
  EXPECT_TRUE((h.array() <= h0.array()).all());
  // Deterministic bytes.
  net.Save(PathOf("e1.model"));
  TrainBarrier(o, safe, nd, nullptr).Save(PathOf("e2.model"));
  EXPECT_TRUE(ReadFile(PathOf("e1.model")) == ReadFile(PathOf("e2.model")));
  EXPECT_EQ(BarrierNet::Load(PathOf("e1.model")).members(), 3);
}

TEST(BarrierTrainerOptionsTest, EnsembleInYamlJsonAndValidate) {
  BarrierTrainerOptions o;
  EXPECT_EQ(o.ensemble, 1);
  o.ApplyYaml(YAML::Load("{ensemble: 3}"), "cfg.yaml");
  EXPECT_EQ(o.ensemble, 3);
  EXPECT_EQ(o.ToJson()["ensemble"], 3);
  o.ensemble = 0;
  EXPECT_EQ(ErrorOf([&] { o.Validate(); }),
            "BarrierTrainerOptions::ensemble = 0, must be in [1, 64]");
  o.ensemble = 65;
  EXPECT_THROW(o.Validate(), Error);
}

}  // namespace
}  // namespace secure::cbf
