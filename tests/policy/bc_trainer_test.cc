// Behaviour cloning (the policy_train_test program): accuracy, validation split, files,
// determinism, options and bad input. BcTest.TrainingLeavesTheGlobalGeneratorAlone is in
// airl_trainer_test.cc, the one file of the program that includes the torch headers.
#include "tests/policy/trainers_test_util.h"

namespace secure::policy {
namespace {
using namespace test;  // NOLINT(google-build-using-namespace): the trainer tests' helpers

TEST(BcTest, RecoversALinearExpertAndItsNoise) {
  const data::TrajectorySet demos = LinearDemos(40, 100, 1);
  BcOptions o = FastBc();
  o.epochs = 150;
  BcSummary s;
  const GaussianPolicy pi = TrainBc(o, demos, &s);
  // The mean recovers the noise-free expert on fresh states.
  PolicyEvaluator ev(pi);
  Rng rng(99);
  double mse = 0.0;
  const int n = 2000;
  Eigen::VectorXf mu(2);
  for (int i = 0; i < n; ++i) {
    Eigen::VectorXf st(2);
    st << static_cast<float>(rng.Uniform(-1.8, 1.8)), static_cast<float>(rng.Uniform(-1.8, 1.8));
    ev.Mean(st, mu);
    mse += (mu - (kGain * st + kOffset)).squaredNorm() / 2.0;
  }
  mse /= n;
  EXPECT_LT(mse, 0.003) << s.BriefReport();
  // sigma is the demonstrator's noise (maximum likelihood), within 20 %.
  ASSERT_EQ(s.sigma.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(s.sigma[i], kNoise[i], 0.2 * kNoise[i]) << "axis " << i << ": " << s.BriefReport();
    EXPECT_FLOAT_EQ(static_cast<float>(s.sigma[i]), std::exp(pi.log_std[i]));
  }
  // The NLL of N(a; K s + b, noise^2) per pair is sum_i log(noise_i sqrt(2 pi e)).
  const double optimum = std::log(kNoise[0] * std::sqrt(2 * M_PI * M_E)) +
                         std::log(kNoise[1] * std::sqrt(2 * M_PI * M_E));
  EXPECT_NEAR(s.validation_nll, optimum, 0.1);
  EXPECT_EQ(pi.observation_features, demos.state_features);
  EXPECT_EQ(pi.action_features, demos.action_features);
  EXPECT_EQ(pi.provenance["options"]["epochs"], 150);
  EXPECT_EQ(pi.provenance["demonstrations"]["episodes"], 40);
}

TEST(BcTest, HoldsOutWholeEpisodesForValidation) {
  const data::TrajectorySet demos = LinearDemos(20, 30, 2);
  BcOptions o = FastBc();
  o.epochs = 5;
  o.validation_fraction = 0.25;
  BcSummary s;
  TrainBc(o, demos, &s);
  EXPECT_EQ(s.validation_episodes, 5);
  EXPECT_EQ(s.train_episodes, 15);
  EXPECT_EQ(s.validation_pairs, 5 * 30);
  EXPECT_EQ(s.train_pairs, 15 * 30);
  EXPECT_EQ(s.epochs, 5);
  EXPECT_EQ(s.optimizer_steps, 5 * 4);  // 450 pairs in batches of 128
  EXPECT_GE(s.best_epoch, 1);
  EXPECT_TRUE(std::isfinite(s.validation_nll));

  // A small fraction still holds out one episode; zero holds out none (the last epoch is kept).
  o.validation_fraction = 0.01;
  TrainBc(o, demos, &s);
  EXPECT_EQ(s.validation_episodes, 1);
  o.validation_fraction = 0.0;
  TrainBc(o, demos, &s);
  EXPECT_EQ(s.validation_episodes, 0);
  EXPECT_EQ(s.validation_pairs, 0);
  EXPECT_TRUE(std::isnan(s.validation_nll));
  EXPECT_EQ(s.best_epoch, 5);
  EXPECT_TRUE(s.ToJson()["validation_nll"].is_null());
  EXPECT_FALSE(s.BriefReport().empty());
}

class BcFileTest : public secure::test::TempDirTest {};

// Issue 34: bc.model recorded the curve's path, so one experiment under two --out names gave
// different model bytes.
TEST_F(BcFileTest, TheModelsBytesDoNotDependOnWhereTheCurveGoes) {
  BcOptions o = FastBc();
  o.epochs = 3;
  std::string bytes[2];
  for (int k = 0; k < 2; ++k) {
    o.curve_path = PathOf(k == 0 ? "a/curve.csv" : "somewhere/else/curve.csv");
    o.verbose = k == 1;
    TrainBc(o, LinearDemos(10, 20, 3), nullptr).Save(PathOf("m" + std::to_string(k)));
    bytes[k] = ReadFile(PathOf("m" + std::to_string(k)));
  }
  EXPECT_TRUE(bytes[0] == bytes[1]);
  EXPECT_EQ(bytes[0].find("curve"), std::string::npos);
}

TEST_F(BcFileTest, WritesTheLearningCurve) {
  BcOptions o = FastBc();
  o.epochs = 7;
  o.curve_path = PathOf("curve.csv");
  TrainBc(o, LinearDemos(10, 20, 3), nullptr);
  const auto lines = Lines(ReadFile(o.curve_path));
  ASSERT_EQ(lines.size(), 8u);
  EXPECT_EQ(lines[0], "epoch,train_nll,validation_nll,action_mse,seconds");
  for (int e = 1; e <= 7; ++e) {
    const auto cells = data::SplitList(lines[e]);
    ASSERT_EQ(cells.size(), 5u) << lines[e];
    EXPECT_EQ(cells[0], std::to_string(e));
    for (int c = 1; c < 5; ++c) EXPECT_TRUE(std::isfinite(std::stod(cells[c]))) << lines[e];
  }
  // Without validation the validation cell is empty.
  o.validation_fraction = 0;
  TrainBc(o, LinearDemos(10, 20, 3), nullptr);
  EXPECT_NE(Lines(ReadFile(o.curve_path))[1].find(",,"), std::string::npos);

  // The trained policy saves and loads.
  const GaussianPolicy pi = TrainBc(o, LinearDemos(10, 20, 3), nullptr);
  pi.Save(PathOf("bc.model"));
  EXPECT_TRUE(BitEqual(pi, GaussianPolicy::Load(PathOf("bc.model"))));
}

TEST(BcTest, DeterministicForASeed) {
  const data::TrajectorySet demos = LinearDemos(10, 40, 4);
  BcOptions o = FastBc();
  o.epochs = 5;
  const GaussianPolicy a = TrainBc(o, demos);
  const GaussianPolicy b = TrainBc(o, demos);
  EXPECT_TRUE(BitEqual(a, b));
  o.seed = 1;
  EXPECT_FALSE(BitEqual(a, TrainBc(o, demos)));
}

TEST(BcTest, InvalidOptionsAreRejectedNamingTheField) {
  const data::TrajectorySet demos = LinearDemos(4, 10, 5);
  auto error = [&](auto mutate) {
    BcOptions o = FastBc();
    mutate(o);
    return ErrorOf([&] { TrainBc(o, demos); });
  };
  EXPECT_HAS(error([](BcOptions& o) { o.epochs = 0; }), "BcOptions::epochs = 0, must be > 0");
  EXPECT_HAS(error([](BcOptions& o) { o.hidden = {8, 0}; }), "BcOptions::hidden[1] = 0");
  EXPECT_HAS(error([](BcOptions& o) { o.batch_size = -3; }), "BcOptions::batch_size = -3");
  EXPECT_HAS(error([](BcOptions& o) { o.validation_fraction = 1.0; }),
             "BcOptions::validation_fraction = 1");
  EXPECT_HAS(error([](BcOptions& o) { o.final_learning_rate = 1.0; }),
             "BcOptions::final_learning_rate = 1, must be in (0, learning_rate]");
  EXPECT_HAS(error([](BcOptions& o) { o.learning_rate = std::nan(""); }),
             "BcOptions::learning_rate = nan");
}

// The linear expert's action depends on x and y; a policy that reads x alone learns the best
// it can from x, E[a | x] = K[:, 0] x + b (y is uniform with mean 0), and ignores y.
TEST(BcTest, APolicyOnSomeFeaturesLearnsFromThemAndIgnoresTheOthers) {
  const data::TrajectorySet demos = LinearDemos(40, 100, 1);
  BcOptions o = FastBc();
  o.epochs = 150;
  o.input_features = {"x"};
  const GaussianPolicy pi = TrainBc(o, demos);
  EXPECT_EQ(pi.observation_features, demos.state_features);
  EXPECT_EQ(pi.input_features, (std::vector<std::string>{"x"}));
  EXPECT_EQ(pi.input_dim(), 1);
  EXPECT_EQ(pi.provenance["options"]["input_features"], nlohmann::json({"x"}));
  PolicyEvaluator ev(pi);
  Rng rng(99);
  double mse = 0.0;
  const int n = 1000;
  Eigen::VectorXf st(2), mu(2), mu_other_y(2);
  for (int i = 0; i < n; ++i) {
    st << static_cast<float>(rng.Uniform(-1.8, 1.8)), static_cast<float>(rng.Uniform(-1.8, 1.8));
    ev.Mean(st, mu);
    mse += (mu - (kGain.col(0) * st[0] + kOffset)).squaredNorm() / 2.0;
    st[1] = -st[1];
    ev.Mean(st, mu_other_y);
    EXPECT_EQ(mu, mu_other_y);
  }
  EXPECT_LT(mse / n, 0.003);
  // Listing every feature, in any order, is the default: the same model, bit for bit.
  o.input_features = {"y", "x"};
  const GaussianPolicy all = TrainBc(o, demos);
  o.input_features.clear();
  EXPECT_TRUE(BitEqual(all, TrainBc(o, demos)));
  EXPECT_TRUE(all.input_features.empty());
}

TEST(BcTest, UnknownOrRepeatedInputFeaturesAreRejected) {
  const data::TrajectorySet demos = LinearDemos(4, 10, 5);
  BcOptions o = FastBc();
  o.input_features = {"x", "speed"};
  EXPECT_HAS(ErrorOf([&] { TrainBc(o, demos); }),
             "BcOptions::input_features = 'speed', must be a state feature of the demonstrations "
             "(x, y)");
  o.input_features = {"x", "x"};
  EXPECT_HAS(ErrorOf([&] { TrainBc(o, demos); }), "BcOptions::input_features[1] = 'x'");
  BcOptions y;
  y.ApplyYaml(YAML::Load("{input_features: [x]}"), "bc.yaml");
  EXPECT_EQ(y.input_features, (std::vector<std::string>{"x"}));
  EXPECT_HAS(ErrorOf([&] { y.ApplyYaml(YAML::Load("{input_features: x}"), "bc.yaml"); }),
             "bc.yaml: field 'input_features' must be a list of names");
}

TEST(BcTest, InvalidDataIsRejected) {
  data::TrajectorySet d = LinearDemos(3, 10, 6);
  d.states(1, 17) = std::nanf("");
  std::string m = ErrorOf([&] { TrainBc(FastBc(), d); });
  EXPECT_HAS(m, "linear expert");
  EXPECT_HAS(m, "state 17 has a non-finite value");

  d = LinearDemos(3, 10, 6);
  d.action_features = {"vx"};
  EXPECT_HAS(ErrorOf([&] { TrainBc(FastBc(), d); }), "actions have 2 rows for 1 action features");

  data::TrajectorySet empty;
  empty.source = "empty.csv";
  empty.state_features = {"x"};
  empty.action_features = {"u"};
  empty.states.resize(1, 0);
  empty.actions.resize(1, 0);
  empty.episode_begin = {0};
  EXPECT_HAS(ErrorOf([&] { TrainBc(FastBc(), empty); }), "empty.csv");
}

TEST(BcTest, OptionsYaml) {
  BcOptions o;
  o.ApplyYaml(YAML::Load("{hidden: [16, 8], activation: relu, epochs: 12, learning_rate: 0.01, "
                         "seed: 7, curve_path: c.csv, min_log_std: -3}"),
              "bc.yaml");
  EXPECT_EQ(o.hidden, (std::vector<int>{16, 8}));
  EXPECT_EQ(o.activation, nn::Activation::kRelu);
  EXPECT_EQ(o.epochs, 12);
  EXPECT_EQ(o.seed, 7u);
  EXPECT_EQ(o.curve_path, "c.csv");
  EXPECT_EQ(o.ToJson()["min_log_std"], -3.0);
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{epoch: 3}"), "bc.yaml"); }),
             "bc.yaml: unknown field 'epoch'");
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{epochs: many}"), "bc.yaml"); }),
             "field 'epochs' has value 'many'");
  // ToJson round-trips through ApplyYaml.
  BcOptions back;
  back.ApplyYaml(YAML::Load(o.ToJson().dump()), "json");
  EXPECT_EQ(back.ToJson(), o.ToJson());
}

}  // namespace
}  // namespace secure::policy
