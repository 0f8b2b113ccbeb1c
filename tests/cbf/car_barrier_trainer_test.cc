#include "secure/cbf/car_barrier_trainer.h"
#include "tests/cbf/synthetic_derby_observations.h"
#include "tests/nn/nn_test_util.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <string>
#include <thread>
#include <utility>

#include "domains/derby/domain.h"
#include "secure/cbf/barrier_trainer.h"
#include "secure/cbf/internal/car_barrier_torch.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/nn/torch_mlp.h"

namespace secure::cbf {
namespace {

using secure::test::ErrorOf;

using test::kCars;
using test::kObs;
using test::ObsNames;
using test::Synthetic;

// `o` with the Demolition Derby observation layout (the derby plug-in's; there is no default).
CarBarrierTrainerOptions WithDerbyLayout(CarBarrierTrainerOptions o) {
  o.input.layout = domains::derby::ObstacleLayoutOfObservation();
  return o;
}

CarBarrierTrainerOptions Fast() {
  CarBarrierTrainerOptions o = WithDerbyLayout({});
  o.max_epochs = 15;
  return o;
}

TEST(CarBarrierTrainerTest, LearnsSyntheticDerbyData) {
  CarBarrierTrainingSummary s;
  const CarBarrierNet net =
      TrainCarBarrier(WithDerbyLayout({}), Synthetic(false, 1024, 1), Synthetic(true, 1024, 2), &s);
  std::printf("%s\n%s", s.BriefReport().c_str(), s.FullReport().c_str());
  EXPECT_GE(s.train_accuracy.states.Balanced(), 0.97);
  EXPECT_GE(s.validation_accuracy.states.safe, 0.95);
  EXPECT_GE(s.validation_accuracy.states.near_dangerous, 0.95);
  // Held-out data through the Eigen evaluator.
  const CarBarrierAccuracy test =
      EvaluateCarBarrier(net, Synthetic(false, 1000, 11), Synthetic(true, 1000, 12));
  std::printf("held-out: states safe %.4f nd %.4f, entries safe %.4f danger %.4f\n",
              test.states.safe, test.states.near_dangerous, test.entries.safe,
              test.entries.near_dangerous);
  EXPECT_GE(test.states.safe, 0.95);
  EXPECT_GE(test.states.near_dangerous, 0.95);
  EXPECT_GE(test.entries.safe, 0.97);
  EXPECT_GE(test.entries.near_dangerous, 0.95);
  EXPECT_EQ(net.cap, 0.05);  // the safe margin
  EXPECT_EQ(net.features, ObsNames());
  EXPECT_EQ(net.provenance["summary"]["epochs"], s.epochs);
  EXPECT_GT(s.train_safe_entries, 3 * s.train_safe);  // all in-range cars of all states
  EXPECT_EQ(s.train_danger_entries, s.train_near_dangerous);
}

TEST(CarBarrierTrainerTest, DeterministicForASeedAlsoConcurrently) {
  const auto safe = Synthetic(false, 200, 3), nd = Synthetic(true, 200, 4);
  CarBarrierTrainerOptions o = Fast();
  o.max_epochs = 4;
  CarBarrierNet a, b, c;
  CarBarrierTrainingSummary sa, sb, sc;
  std::thread t1([&] { a = TrainCarBarrier(o, safe, nd, &sa); });
  std::thread t2([&] { b = TrainCarBarrier(o, safe, nd, &sb); });
  t1.join();
  t2.join();
  nn::test::ExpectSameMlp(a.mlp, a.normalizer, b.mlp, b.normalizer);
  EXPECT_EQ(sa.train_loss, sb.train_loss);
  o.seed = 1;
  c = TrainCarBarrier(o, safe, nd, &sc);
  EXPECT_NE(a.mlp.layers[0].weight, c.mlp.layers[0].weight);
}

TEST(CarBarrierTrainerTest, TorchForwardMatchesEigenEvaluatorAndIsDifferentiable) {
  CarBarrierNet net;
  net.input.layout = domains::derby::ObstacleLayoutOfObservation();
  net.input.use_velocity = true;
  net.cap = 0.04;
  net.mlp = nn::RandomMlpParams({5, {64, 128, 64}, 1, nn::Activation::kRelu}, 5);
  net.normalizer = nn::Normalizer::Fit(Eigen::MatrixXf::Random(5, 30));
  data::StateSet mix = Synthetic(false, 100, 6);
  mix.states.rightCols(50) = Synthetic(true, 50, 7).states;
  mix.states.block(4, 90, 48, 5).setConstant(3.0f);  // no car in range: h = cap
  mix.states(9, 97) = std::numeric_limits<float>::quiet_NaN();  // NaN propagates in both

  Eigen::VectorXf h_eigen(100);
  net.MakeEvaluator(64)->Evaluate(mix.states, h_eigen);
  auto model = internal::CarBarrierTorch(net);
  model->Freeze();
  torch::Tensor obs = nn::ToTensor(mix.states).requires_grad_(true);
  const torch::Tensor h = model->forward(obs);
  ASSERT_EQ(h.sizes(), (std::vector<std::int64_t>{100}));
  const Eigen::MatrixXf h_torch = nn::ToEigen(h.detach().unsqueeze(1));
  for (int i = 0; i < 100; ++i) {
    if (i == 97) {
      EXPECT_TRUE(std::isnan(h_torch(0, i)) && std::isnan(h_eigen(i)));
      continue;
    }
    EXPECT_NEAR(h_torch(0, i), h_eigen(i), 1e-5) << "state " << i;
  }
  for (int i = 90; i < 95; ++i) EXPECT_FLOAT_EQ(h_eigen(i), 0.04f);

  // Gradient w.r.t. the observations: finite differences on a state below the cap.
  const torch::Tensor idx = torch::tensor({3, 60}, torch::kLong);
  const torch::Tensor sub = obs.detach().index_select(0, idx).clone().requires_grad_(true);
  model->forward(sub).sum().backward();
  const torch::Tensor grad = sub.grad();
  ASSERT_TRUE(grad.defined());
  EXPECT_GT(grad.abs().sum().item<double>(), 0.0);
  EXPECT_EQ(grad.slice(1, 0, 4).abs().sum().item<double>(), 0.0);  // goal, ego velocity unused
  for (const auto& p : model->parameters()) EXPECT_FALSE(p.grad().defined());
  torch::NoGradGuard no_grad;
  const torch::Tensor hs = model->forward(sub);
  int checked = 0;
  for (int row = 0; row < 2; ++row) {
    if (hs[row].item<float>() >= 0.04f) continue;  // at the cap: no gradient
    for (int f = 4; f < kObs; ++f) {
      const double g = grad[row][f].item<double>();
      if (g == 0.0) continue;
      torch::Tensor plus = sub.detach().clone(), minus = sub.detach().clone();
      plus[row][f] += 1e-3f;
      minus[row][f] -= 1e-3f;
      const double fd =
          (model->forward(plus)[row].item<double>() - model->forward(minus)[row].item<double>()) /
          2e-3;
      EXPECT_NEAR(fd, g, 0.05 * std::abs(g) + 2e-3) << "row " << row << " feature " << f;
      ++checked;
    }
  }
  EXPECT_GT(checked, 0);
}

TEST(CarBarrierTrainerTest, ReleasedConstantsRunOneEpochOf512Updates) {
  CarBarrierTrainingSummary s;
  const CarBarrierNet net =
      TrainCarBarrier(WithDerbyLayout(CarBarrierTrainerOptions::Released()),
                      Synthetic(false, 1024, 8), Synthetic(true, 1024, 9), &s);
  EXPECT_EQ(s.epochs, 1);
  EXPECT_EQ(s.iterations, 512);
  EXPECT_EQ(s.validation_safe, 0);
  EXPECT_DOUBLE_EQ(net.cap, 0.002);
  std::printf("released: %s\n", s.BriefReport().c_str());
}

TEST(CarBarrierTrainerTest, BadInputsNameTheProblem) {
  const auto safe = Synthetic(false, 20, 1), nd = Synthetic(true, 20, 2);
  const CarBarrierTrainerOptions o = Fast();
  CarBarrierTrainingSummary s;
  data::StateSet empty{"empty.csv", ObsNames(), Eigen::MatrixXf(kObs, 0)};
  EXPECT_NE(ErrorOf([&] { TrainCarBarrier(o, empty, nd, &s); }).find("safe states (empty.csv): 0 states"),
            std::string::npos);
  data::StateSet narrow{"narrow.csv", {"a", "b"}, Eigen::MatrixXf::Zero(2, 3)};
  EXPECT_NE(ErrorOf([&] { TrainCarBarrier(o, safe, narrow, &s); })
                .find("near-dangerous states (narrow.csv) have 2 features, the obstacle layout "
                      "needs obs_dim = 52"),
            std::string::npos);
  data::StateSet nan = safe;
  nan.states(9, 5) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_NE(ErrorOf([&] { TrainCarBarrier(o, nan, nd, &s); })
                .find("state 5, feature 'c1dy' (row 9) = nan, must be finite"),
            std::string::npos);
  data::StateSet inf = nd;
  inf.states(0, 3) = std::numeric_limits<float>::infinity();
  EXPECT_NE(ErrorOf([&] { TrainCarBarrier(o, safe, inf, &s); }).find("state 3, feature 'gx'"),
            std::string::npos);
  // Near-dangerous blocks not sorted: the dangerous car is not block 0.
  data::StateSet unsorted = nd;
  unsorted.states.block(4, 7, 4, 1).swap(unsorted.states.block(8, 7, 4, 1));
  EXPECT_NE(ErrorOf([&] { TrainCarBarrier(o, safe, unsorted, &s); })
                .find("state 7: obstacle block 1"),
            std::string::npos);
  // The dangerous car beyond the sensing radius.
  data::StateSet far = nd;
  far.states.block(4, 2, 48, 1).setConstant(2.0f);
  EXPECT_NE(ErrorOf([&] { TrainCarBarrier(o, safe, far, &s); }).find("beyond the sensing radius"),
            std::string::npos);
  // Different feature names.
  data::StateSet renamed = nd;
  renamed.features[0] = "goal_x";
  EXPECT_NE(ErrorOf([&] { TrainCarBarrier(o, safe, renamed, &s); }).find("different feature names"),
            std::string::npos);
  // Options.
  CarBarrierTrainerOptions bad = o;
  bad.batch_size = 0;
  EXPECT_NE(ErrorOf([&] { TrainCarBarrier(bad, safe, nd, &s); })
                .find("CarBarrierTrainerOptions::batch_size = 0, must be > 0"),
            std::string::npos);
  bad = o;
  bad.input.layout.obs_dim = 40;
  EXPECT_NE(ErrorOf([&] { bad.Validate(); }).find("beyond layout.obs_dim = 40"), std::string::npos);
  bad = o;
  bad.cap = -1.0;
  EXPECT_NE(ErrorOf([&] { bad.Validate(); }).find("cap = -1"), std::string::npos);
}

TEST(CarBarrierTrainerTest, TrainingNeedsTheLayout) {
  // No default layout: options without one validate (a domain with a flat barrier carries them
  // unused), but training with them fails, naming the field.
  const auto safe = Synthetic(false, 20, 1), nd = Synthetic(true, 20, 2);
  const CarBarrierTrainerOptions unset;
  EXPECT_FALSE(unset.input.layout.IsSet());
  EXPECT_NO_THROW(unset.Validate());
  CarBarrierTrainingSummary s;
  const std::string e = ErrorOf([&] { TrainCarBarrier(unset, safe, nd, &s); });
  EXPECT_NE(e.find("CarBarrierTrainerOptions::input: layout.obs_dim = 0: the obstacle layout is "
                   "unset and must be given"),
            std::string::npos)
      << e;
  // A partly given layout is checked field by field already by Validate.
  CarBarrierTrainerOptions partial;
  partial.ApplyYaml(YAML::Load("{layout: {num_obstacles: 12}}"), "run.yaml");
  EXPECT_NE(ErrorOf([&] { partial.Validate(); }).find("obs_dim = 0, must be > 0"),
            std::string::npos);
}

TEST(CarBarrierTrainerTest, YamlOptions) {
  CarBarrierTrainerOptions o;
  o.ApplyYaml(YAML::Load("{hidden: [8, 8], use_velocity: true, cap: 0.2, safe_margin: 0.1, "
                         "layout: {num_obstacles: 10}, max_epochs: 3}"),
              "run.yaml");
  EXPECT_EQ(o.hidden, (std::vector<int>{8, 8}));
  EXPECT_TRUE(o.input.use_velocity);
  EXPECT_EQ(o.input.layout.num_obstacles, 10);
  EXPECT_DOUBLE_EQ(o.EffectiveCap(), 0.2);
  o.ApplyYaml(YAML::Load("{cap: null}"), "run.yaml");
  EXPECT_DOUBLE_EQ(o.EffectiveCap(), 0.1);
  EXPECT_TRUE(o.ToJson()["cap"].is_null());
  EXPECT_NE(ErrorOf([&] { o.ApplyYaml(YAML::Load("{epochs: 3}"), "run.yaml"); })
                .find("run.yaml: unknown field 'epochs'"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { o.ApplyYaml(YAML::Load("{layout: {stride: 3}}"), "run.yaml"); })
                .find("unknown field 'layout.stride'"),
            std::string::npos);
}

TEST(CarBarrierTrainerTest, VelocityFeaturesTrainAndCallbackStops) {
  CarBarrierTrainerOptions o = Fast();
  o.input.use_velocity = true;
  o.hidden = {16, 16};
  CarBarrierTrainingSummary s;
  int calls = 0;
  const CarBarrierNet net = TrainCarBarrier(o, Synthetic(false, 100, 1), Synthetic(true, 100, 2), &s,
                                            [&](int, double, double) { return ++calls < 3; });
  EXPECT_EQ(s.epochs, 3);
  EXPECT_EQ(s.stop_reason, "callback");
  EXPECT_EQ(net.mlp.spec.input_dim, 5);
  EXPECT_TRUE(net.input.use_velocity);
}

// ---------------------------------------------------------------------------------------------
// Weights from the options' seed only: LibTorch's global generator plays no part.

// 2-D states: near-dangerous inside the unit disk, safe outside (for the flat trainer).
std::pair<data::StateSet, data::StateSet> DiskSets(int n, std::uint64_t seed) {
  Rng rng(seed);
  data::StateSet safe{"outside", {"px", "py"}, Eigen::MatrixXf(2, n)};
  data::StateSet nd{"inside", {"px", "py"}, Eigen::MatrixXf(2, n)};
  for (int i = 0; i < n; ++i) {
    const double a = rng.Uniform(0, 2 * M_PI), r_in = rng.Uniform(0, 0.9),
                 r_out = rng.Uniform(1.1, 2.0);
    nd.states.col(i) << static_cast<float>(r_in * std::cos(a)),
        static_cast<float>(r_in * std::sin(a));
    safe.states.col(i) << static_cast<float>(r_out * std::sin(a)),
        static_cast<float>(r_out * std::cos(a));
  }
  return {safe, nd};
}

class TrainerGeneratorTest : public secure::test::TempDirTest {
 protected:
  // The model file bytes of a flat barrier (TrainBarrier) and of a per-car barrier.
  std::string FlatBytes(std::uint64_t seed) {
    BarrierTrainerOptions o;
    o.hidden = {16, 16};
    o.max_epochs = 3;
    o.batch_size = 32;
    o.seed = seed;
    const auto [safe, nd] = DiskSets(150, 5);
    const std::string path = PathOf("flat_" + std::to_string(seed) + "_" + Tag() + ".model");
    TrainBarrier(o, safe, nd, nullptr).Save(path);
    return ReadFile(path);
  }
  std::string CarBytes(std::uint64_t seed) {
    CarBarrierTrainerOptions o = Fast();
    o.hidden = {16, 16};
    o.max_epochs = 2;
    o.seed = seed;
    const std::string path = PathOf("car_" + std::to_string(seed) + "_" + Tag() + ".model");
    TrainCarBarrier(o, Synthetic(false, 120, 3), Synthetic(true, 120, 4), nullptr).Save(path);
    return ReadFile(path);
  }

 private:
  static std::string Tag() {
    return std::to_string(std::hash<std::thread::id>{}(std::this_thread::get_id()));
  }
};

// The two trainers used to seed the global generator under two different mutexes, so one's
// initialisation could draw from the other's seed. Now each run alone and both runs together
// on two threads give the same model file bytes.
TEST_F(TrainerGeneratorTest, ConcurrentFlatAndPerCarTrainingsGiveTheSoloBytes) {
  const std::string flat = FlatBytes(11), car = CarBytes(12);
  for (int round = 0; round < 4; ++round) {
    SCOPED_TRACE(round);
    std::string flat_2, car_2;
    std::thread t1([&] { flat_2 = FlatBytes(11); });
    std::thread t2([&] { car_2 = CarBytes(12); });
    t1.join();
    t2.join();
    EXPECT_TRUE(flat_2 == flat);
    EXPECT_TRUE(car_2 == car);
  }
  EXPECT_FALSE(FlatBytes(13) == flat);  // and the seed matters
  EXPECT_FALSE(CarBytes(13) == car);
}

TEST_F(TrainerGeneratorTest, TrainingLeavesTheGlobalGeneratorAlone) {
  torch::manual_seed(2024);
  const torch::Tensor expected = torch::rand({32});
  torch::manual_seed(2024);
  FlatBytes(3);
  CarBytes(4);
  EXPECT_TRUE(torch::equal(torch::rand({32}), expected));
}

class CarBarrierTrainerFileTest : public secure::test::TempDirTest {};

TEST_F(CarBarrierTrainerFileTest, SameSeedGivesByteIdenticalModelFiles) {
  const auto safe = Synthetic(false, 60, 3), nd = Synthetic(true, 60, 4);
  CarBarrierTrainerOptions o = Fast();
  o.max_epochs = 2;
  CarBarrierTrainingSummary sa, sb;
  TrainCarBarrier(o, safe, nd, &sa).Save(PathOf("a.model"));
  TrainCarBarrier(o, safe, nd, &sb).Save(PathOf("b.model"));
  EXPECT_TRUE(ReadFile(PathOf("a.model")) == ReadFile(PathOf("b.model")))
      << "model files of two same-seed runs differ";
  const CarBarrierNet loaded = CarBarrierNet::Load(PathOf("a.model"));
  EXPECT_FALSE(loaded.provenance["summary"].contains("wall_seconds"));
  EXPECT_TRUE(sa.ToJson().contains("wall_seconds"));
}

}  // namespace
}  // namespace secure::cbf
