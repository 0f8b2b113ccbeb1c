// Behaviour cloning and AIRL (LibTorch): one translation unit for both trainers, so that the
// torch headers are compiled once.
#include <gtest/gtest.h>
#include <torch/torch.h>
#include <yaml-cpp/yaml.h>

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/differentiable_barrier.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/common/strings.h"
#include "secure/nn/mlp.h"
#include "secure/nn/torch_mlp.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"
#include "secure/policy/internal/joint_cbf_term.h"
#include "secure/policy/internal/torch_policy.h"
#include "tests/policy/single_thread.h"
#include "tests/policy/toy_env.h"
#include "tests/test_util.h"

namespace secure::policy {
namespace {

using secure::test::ErrorOf;
using test::ExpertDemos;
using test::PointMassEnv;

// The trainers leave thread counts to the caller: one LibTorch and one OpenBLAS thread, as in
// the pipeline.
const bool kOneThread = test::UseOneTrainingThread();

bool BitEqual(const GaussianPolicy& a, const GaussianPolicy& b) {
  if (!(a.mean.spec == b.mean.spec) || a.mean.layers.size() != b.mean.layers.size()) return false;
  for (std::size_t l = 0; l < a.mean.layers.size(); ++l)
    if (a.mean.layers[l].weight != b.mean.layers[l].weight ||
        a.mean.layers[l].bias != b.mean.layers[l].bias)
      return false;
  return a.input.mean == b.input.mean && a.input.scale == b.input.scale && a.log_std == b.log_std;
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// Success rate of a policy in the toy task (sampled actions, fixed horizon).
double SuccessRate(const GaussianPolicy& pi, int episodes, std::uint64_t seed) {
  PointMassEnv env;
  PolicyEvaluator ev(pi);
  Rng rng(seed);
  Eigen::VectorXf o(2), a(2), next(2);
  int reached = 0;
  for (int e = 0; e < episodes; ++e) {
    env.Reset(rng, o);
    bool hit = false;
    for (int t = 0; t < env.max_steps(); ++t) {
      ev.Sample(o, rng, a);
      hit |= env.Step(a, next).reached_goal;
      o = next;
    }
    reached += hit;
  }
  return static_cast<double>(reached) / episodes;
}

// ---------------------------------------------------------------------------------------------
// Behaviour cloning

// States uniform in [-2, 2]^2 grouped into episodes; actions from a linear expert with
// per-axis Gaussian noise.
const Eigen::Matrix2f kGain = (Eigen::Matrix2f() << -0.8f, 0.3f, 0.2f, -1.1f).finished();
const Eigen::Vector2f kOffset(0.5f, -0.25f);
const Eigen::Vector2f kNoise(0.3f, 0.1f);

data::TrajectorySet LinearDemos(int episodes, int length, std::uint64_t seed) {
  Rng rng(seed);
  data::TrajectorySet d;
  d.source = "linear expert";
  d.state_features = {"x", "y"};
  d.action_features = {"vx", "vy"};
  d.states.resize(2, static_cast<long>(episodes) * length);
  d.actions.resize(2, d.states.cols());
  for (long c = 0; c < d.states.cols(); ++c) {
    if (c % length == 0) d.episode_begin.push_back(c);
    Eigen::VectorXf s(2);  // dynamic size: see gaussian_policy_test.cc
    s << static_cast<float>(rng.Uniform(-2, 2)), static_cast<float>(rng.Uniform(-2, 2));
    d.states.col(c) = s;
    d.actions.col(c) = kGain * s + kOffset;
    for (int i = 0; i < 2; ++i) d.actions(i, c) += kNoise[i] * static_cast<float>(rng.Normal());
  }
  d.episode_begin.push_back(d.states.cols());
  return d;
}

BcOptions FastBc() {
  BcOptions o;
  o.hidden = {32, 32};
  o.epochs = 60;
  o.batch_size = 128;
  o.learning_rate = 3e-3;
  o.final_learning_rate = 1e-4;
  return o;
}

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

TEST(BcTest, TrainingLeavesTheGlobalGeneratorAlone) {
  const data::TrajectorySet demos = LinearDemos(6, 20, 3);
  BcOptions o = FastBc();
  o.epochs = 2;
  torch::manual_seed(77);
  const torch::Tensor expected = torch::rand({32});
  torch::manual_seed(77);
  TrainBc(o, demos, nullptr);
  EXPECT_TRUE(torch::equal(torch::rand({32}), expected));
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

// ---------------------------------------------------------------------------------------------
// AIRL

AirlOptions ToyAirl() {
  AirlOptions o;
  o.iterations = 20;
  o.steps_per_iteration = 2000;  // 40 episodes of 50 steps
  return o;
}

// The first iteration's rollout is the untrained policy's.
struct Recorder {
  std::vector<AirlIterationStats> rows;
  AirlCallback Callback() {
    return [this](const AirlIterationStats& s) {
      rows.push_back(s);
      return true;
    };
  }
};

TEST(AirlTest, LearnsTheToyTaskWithTheLogitDReward) {
  const data::TrajectorySet demos = ExpertDemos(50, 1);
  AirlOptions o = ToyAirl();
  o.reward = AirlReward::kLogitD;
  Recorder rec;
  AirlSummary s;
  const GaussianPolicy pi = TrainAirl(o, demos, PointMassEnv(), nullptr, &s, rec.Callback());
  ASSERT_EQ(rec.rows.size(), 20u);
  const double before = rec.rows.front().success_rate;
  const double after = SuccessRate(pi, 200, 123);
  EXPECT_LE(before, 0.15) << s.BriefReport();
  EXPECT_GE(after, 0.8) << s.BriefReport();
  EXPECT_GE(rec.rows.back().success_rate, 0.8);
  EXPECT_EQ(s.iterations, 20);
  EXPECT_EQ(s.episodes_per_iteration, 40);
  EXPECT_EQ(s.steps_per_iteration, 2000);
  EXPECT_EQ(s.env_steps, 40000);
  EXPECT_EQ(s.expert_transitions, 50 * 49);  // each episode's last row has no successor
  EXPECT_EQ(s.stop_reason, "iterations");
  EXPECT_GT(s.iterations_per_second, 0.0);
  EXPECT_EQ(pi.observation_features, (std::vector<std::string>{"x", "y"}));
  EXPECT_EQ(pi.provenance["options"]["reward"], "logit-d");
  EXPECT_EQ(pi.provenance["summary"]["iterations"], 20);
  for (const auto& row : rec.rows) {
    EXPECT_GT(row.d_expert, 0.0);
    EXPECT_LT(row.d_expert, 1.0);
    EXPECT_TRUE(std::isfinite(row.entropy));
  }
}

TEST(AirlTest, LearnsTheToyTaskWithTheStateReward) {
  const data::TrajectorySet demos = ExpertDemos(50, 1);
  AirlOptions o = ToyAirl();
  o.reward = AirlReward::kStateReward;
  Recorder rec;
  const GaussianPolicy pi = TrainAirl(o, demos, PointMassEnv(), nullptr, nullptr, rec.Callback());
  EXPECT_LE(rec.rows.front().success_rate, 0.15);
  EXPECT_GE(SuccessRate(pi, 200, 123), 0.7);
}

TEST(AirlTest, LogitDRewardIsFMinusLogPi) {
  // Tiny networks with fixed weights; the reward computed by the trainer's torch code against
  // an independent double-precision evaluation.
  const int d = 3, k = 2, n = 5;
  const nn::MlpSpec gspec{d, {4}, 1, nn::Activation::kRelu};
  const nn::MlpSpec pspec{d, {6}, k, nn::Activation::kTanh};
  const nn::MlpParams g = nn::RandomMlpParams(gspec, 1), v = nn::RandomMlpParams(gspec, 2);
  const nn::MlpParams mean = nn::RandomMlpParams(pspec, 3);
  const Eigen::Vector2f log_std(-0.3f, 0.2f);
  const double discount = 0.9;
  Rng rng(4);
  Eigen::MatrixXf s(d, n), s_next(d, n), a(k, n);
  for (int c = 0; c < n; ++c) {
    for (int r = 0; r < d; ++r) s(r, c) = static_cast<float>(rng.Uniform(-1, 1));
    for (int r = 0; r < d; ++r) s_next(r, c) = static_cast<float>(rng.Uniform(-1, 1));
    for (int r = 0; r < k; ++r) a(r, c) = static_cast<float>(rng.Uniform(-2, 2));
  }
  internal::AirlDiscriminator disc(g, v, discount);
  internal::TorchGaussian policy(mean, log_std, -5.0);
  torch::NoGradGuard no_grad;
  const torch::Tensor x = nn::ToTensor(s), xn = nn::ToTensor(s_next), at = nn::ToTensor(a);
  const torch::Tensor f = disc->F(x, xn);
  const torch::Tensor log_pi = policy->LogProb(x, at);
  const torch::Tensor logit =
      internal::AirlPolicyReward(AirlReward::kLogitD, f, disc->G(x), log_pi);
  const torch::Tensor state =
      internal::AirlPolicyReward(AirlReward::kStateReward, f, disc->G(x), log_pi);
  const nn::Normalizer id = nn::Normalizer::Identity(d);
  const Eigen::MatrixXd gs = nn::ReferenceForward(g, id, s);
  const Eigen::MatrixXd vs = nn::ReferenceForward(v, id, s);
  const Eigen::MatrixXd vn = nn::ReferenceForward(v, id, s_next);
  const Eigen::MatrixXd mu = nn::ReferenceForward(mean, id, s);
  for (int c = 0; c < n; ++c) {
    const double f_ref = gs(0, c) + discount * vn(0, c) - vs(0, c);
    const double log_pi_ref = GaussianLogDensity(a.col(c), mu.col(c).cast<float>(), log_std);
    EXPECT_NEAR(f[c].item<double>(), f_ref, 1e-5);
    EXPECT_NEAR(log_pi[c].item<double>(), log_pi_ref, 1e-4);
    EXPECT_NEAR(logit[c].item<double>(), f_ref - log_pi_ref, 1e-4);
    EXPECT_NEAR(state[c].item<double>(), gs(0, c), 1e-5);
    // D = exp(f) / (exp(f) + pi) from its stable logs.
    const double dval = std::exp(f_ref) / (std::exp(f_ref) + std::exp(log_pi_ref));
    EXPECT_NEAR(std::exp(internal::LogD(f, log_pi)[c].item<double>()), dval, 1e-5);
    EXPECT_NEAR(std::exp(internal::Log1mD(f, log_pi)[c].item<double>()), 1 - dval, 1e-5);
  }
  // Stable for extreme logits (no inf or nan).
  const torch::Tensor big = torch::tensor({500.0f, -500.0f});
  const torch::Tensor zero = torch::zeros({2});
  EXPECT_TRUE(torch::isfinite(internal::LogD(big, zero)).all().item<bool>());
  EXPECT_TRUE(torch::isfinite(internal::Log1mD(big, zero)).all().item<bool>());
}

class AirlFileTest : public secure::test::TempDirTest {};

AirlOptions SmallAirl() {
  AirlOptions o;
  o.iterations = 6;
  o.steps_per_iteration = 500;  // 10 episodes of 50 steps
  o.minibatch_size = 100;
  o.ppo_epochs = 2;
  o.discriminator_updates = 3;
  o.discriminator_batch = 64;
  o.policy_hidden = {16, 16};
  o.value_hidden = {16, 16};
  o.reward_hidden = {8};
  o.shaping_hidden = {8};
  o.seed = 3;
  return o;
}

TEST_F(AirlFileTest, ResumeFromACheckpointGivesTheSamePolicyBitwise) {
  const data::TrajectorySet demos = ExpertDemos(10, 2);
  const PointMassEnv env;
  const GaussianPolicy uninterrupted = TrainAirl(SmallAirl(), demos, env, nullptr, nullptr);

  // Stop after 3 iterations with the option, resume to the end.
  AirlOptions o = SmallAirl();
  o.checkpoint_path = PathOf("run/airl.ckpt");
  o.checkpoint_every = 2;
  o.curve_path = PathOf("run/curve.csv");
  o.stop_after_iterations = 3;
  o.resume = true;  // no checkpoint yet: starts afresh
  AirlSummary s;
  TrainAirl(o, demos, env, nullptr, &s);
  EXPECT_FALSE(s.resumed);
  EXPECT_EQ(s.iterations, 3);
  EXPECT_EQ(s.stop_reason, "stop_after_iterations");
  EXPECT_EQ(s.checkpoints_written, 2);  // at 2 and at the stop
  EXPECT_TRUE(std::filesystem::exists(o.checkpoint_path));
  EXPECT_EQ(Lines(ReadFile(o.curve_path)).size(), 4u);

  o.stop_after_iterations = 0;
  const GaussianPolicy resumed = TrainAirl(o, demos, env, nullptr, &s);
  EXPECT_TRUE(s.resumed);
  EXPECT_EQ(s.start_iteration, 3);
  EXPECT_EQ(s.iterations, 6);
  EXPECT_EQ(s.env_steps, 6 * 500);
  EXPECT_TRUE(BitEqual(uninterrupted, resumed));
  // The curve holds every iteration once, in order.
  const auto lines = Lines(ReadFile(o.curve_path));
  ASSERT_EQ(lines.size(), 7u);
  EXPECT_EQ(lines[0], Join(AirlIterationStats::Columns(), ","));
  for (int i = 1; i <= 6; ++i) EXPECT_EQ(lines[i].substr(0, lines[i].find(',')), std::to_string(i));

  // Resuming a finished run returns the same policy without training.
  const GaussianPolicy again = TrainAirl(o, demos, env, nullptr, &s);
  EXPECT_EQ(s.start_iteration, 6);
  EXPECT_TRUE(BitEqual(uninterrupted, again));

  // A callback stop (after iteration 4, between checkpoints) also resumes exactly.
  std::filesystem::remove(o.checkpoint_path);
  TrainAirl(o, demos, env, nullptr, &s,
            [](const AirlIterationStats& stats) { return stats.iteration < 4; });
  EXPECT_EQ(s.stop_reason, "callback");
  EXPECT_EQ(s.iterations, 4);
  EXPECT_TRUE(BitEqual(uninterrupted, TrainAirl(o, demos, env, nullptr, &s)));
  EXPECT_EQ(s.start_iteration, 4);
}

TEST_F(AirlFileTest, IncompatibleOrBrokenCheckpointsAreRejected) {
  const data::TrajectorySet demos = ExpertDemos(10, 2);
  const PointMassEnv env;
  AirlOptions o = SmallAirl();
  o.iterations = 1;
  o.checkpoint_path = PathOf("airl.ckpt");
  TrainAirl(o, demos, env, nullptr, nullptr);
  o.resume = true;
  o.iterations = 2;
  o.gamma = 0.95;
  std::string m = ErrorOf([&] { TrainAirl(o, demos, env, nullptr, nullptr); });
  EXPECT_HAS(m, o.checkpoint_path);
  EXPECT_HAS(m, "AirlOptions::gamma");
  o.gamma = 0.99;
  m = ErrorOf([&] { TrainAirl(o, ExpertDemos(10, 3), env, nullptr, nullptr); });
  EXPECT_HAS(m, "demonstrations_fingerprint");
  m = ErrorOf([&] { TrainAirl(o, demos, PointMassEnv(40), nullptr, nullptr); });
  EXPECT_HAS(m, "environment");
  // A corrupt file names the path.
  std::string bytes = ReadFile(o.checkpoint_path);
  WriteFileAtomically(o.checkpoint_path, bytes.substr(0, bytes.size() / 2));
  m = ErrorOf([&] { TrainAirl(o, demos, env, nullptr, nullptr); });
  EXPECT_HAS(m, o.checkpoint_path);
}

// A checkpoint carries a CRC-32 over its whole content: a flipped byte inside the tensor data
// (which the LibTorch archive itself does not notice) or a truncated file is an error naming the
// file, never a silently different model. So is a checkpoint of an older format version.
TEST_F(AirlFileTest, CorruptTruncatedOrOldCheckpointsAreRejectedNamingTheFile) {
  const data::TrajectorySet demos = ExpertDemos(10, 2);
  const PointMassEnv env;
  AirlOptions o = SmallAirl();
  o.iterations = 2;
  o.checkpoint_path = PathOf("airl.ckpt");
  TrainAirl(o, demos, env, nullptr, nullptr);
  const std::string good = ReadFile(o.checkpoint_path);
  ASSERT_GT(good.size(), 1000u);
  o.resume = true;
  o.iterations = 3;
  auto resume_error = [&](const std::string& bytes) {
    WriteFileAtomically(o.checkpoint_path, bytes);
    return ErrorOf([&] { TrainAirl(o, demos, env, nullptr, nullptr); });
  };

  // One bit of one byte in the middle of the file (tensor data of the archive).
  std::string flipped = good;
  flipped[flipped.size() / 2] = static_cast<char>(flipped[flipped.size() / 2] ^ 0x01);
  std::string m = resume_error(flipped);
  EXPECT_HAS(m, o.checkpoint_path);
  EXPECT_HAS(m, "checksum mismatch");
  EXPECT_HAS(m, "the checkpoint is corrupt");

  // Truncated: the last bytes, or half of the file, missing.
  for (const std::size_t keep : {good.size() - 5, good.size() / 2, std::size_t{10}}) {
    m = resume_error(good.substr(0, keep));
    EXPECT_HAS(m, o.checkpoint_path);
    EXPECT_HAS(m, "truncated");
  }
  m = resume_error("");
  EXPECT_HAS(m, o.checkpoint_path);

  // The trailer's digits themselves damaged.
  std::string trailer = good;
  trailer[trailer.size() - 2] = trailer[trailer.size() - 2] == '0' ? '1' : '0';
  EXPECT_HAS(resume_error(trailer), "checksum mismatch");

  // Version 1 (a bare LibTorch archive, no checksum) and an unknown version: clear errors.
  const std::size_t first_line = good.find('\n');
  ASSERT_NE(first_line, std::string::npos);
  EXPECT_EQ(good.substr(0, first_line), "secure-airl-checkpoint 2");
  const std::size_t trailer_size = std::string("\ncrc32 01234567\n").size();
  const std::string bare =
      good.substr(first_line + 1, good.size() - (first_line + 1) - trailer_size);
  m = resume_error(bare);
  EXPECT_HAS(m, o.checkpoint_path);
  EXPECT_HAS(m, "version 1");
  EXPECT_HAS(m, "reads version 2");
  m = resume_error("secure-airl-checkpoint 3" + good.substr(first_line));
  EXPECT_HAS(m, "version 3");
  m = resume_error("something else entirely\n");
  EXPECT_HAS(m, "not an AIRL checkpoint");

  // The intact file still resumes.
  WriteFileAtomically(o.checkpoint_path, good);
  AirlSummary s;
  TrainAirl(o, demos, env, nullptr, &s);
  EXPECT_TRUE(s.resumed);
  EXPECT_EQ(s.start_iteration, 2);
  EXPECT_EQ(s.iterations, 3);
}

// A run cannot be shortened: resuming a checkpoint with more completed iterations than
// `iterations` is an error; with exactly as many it returns the checkpoint's policy.
TEST_F(AirlFileTest, ResumingWithFewerIterationsThanTheCheckpointIsAnError) {
  const data::TrajectorySet demos = ExpertDemos(10, 2);
  const PointMassEnv env;
  AirlOptions o = SmallAirl();
  o.iterations = 3;
  o.checkpoint_path = PathOf("airl.ckpt");
  const GaussianPolicy trained = TrainAirl(o, demos, env, nullptr, nullptr);
  o.resume = true;
  o.iterations = 2;
  const std::string m = ErrorOf([&] { TrainAirl(o, demos, env, nullptr, nullptr); });
  EXPECT_HAS(m, o.checkpoint_path +
                    ": checkpoint has 3 completed iterations, more than "
                    "iterations = 2");
  o.iterations = 3;
  AirlSummary s;
  EXPECT_TRUE(BitEqual(trained, TrainAirl(o, demos, env, nullptr, &s)));
  EXPECT_EQ(s.start_iteration, 3);
  EXPECT_EQ(s.iterations, 3);
}

// Timing is in the summary (and --json), not in the model file: two identical runs write
// identical model files.
TEST_F(AirlFileTest, IdenticalRunsWriteIdenticalModelFiles) {
  const data::TrajectorySet demos = ExpertDemos(10, 2);
  const PointMassEnv env;
  AirlOptions o = SmallAirl();
  o.iterations = 2;
  AirlSummary s;
  const GaussianPolicy a = TrainAirl(o, demos, env, nullptr, &s);
  const GaussianPolicy b = TrainAirl(o, demos, env, nullptr, nullptr);
  EXPECT_TRUE(s.ToJson().contains("wall_seconds"));
  const nlohmann::json& summary = a.provenance.at("summary");
  for (const char* key : {"wall_seconds", "rollout_seconds", "discriminator_seconds", "ppo_seconds",
                          "iterations_per_second", "env_steps_per_second"})
    EXPECT_FALSE(summary.contains(key)) << key;
  EXPECT_FALSE(summary.at("last").contains("seconds"));
  EXPECT_EQ(summary["iterations"], 2);
  a.Save(PathOf("a.model"));
  b.Save(PathOf("b.model"));
  EXPECT_TRUE(ReadFile(PathOf("a.model")) == ReadFile(PathOf("b.model")));
}

// The trained discriminator's reward g and shaping V, exported for the shield's top-q
// aggregation: the policy's inputs and normaliser, the RL discount, the same bytes for the same
// seed, and a Q that varies with the next state.
TEST_F(AirlFileTest, ExportsTheRewardAndShapingNetworksAsARewardModel) {
  const data::TrajectorySet demos = ExpertDemos(10, 2);
  const PointMassEnv env;
  AirlOptions o = SmallAirl();
  o.gamma = 0.97;
  AirlRewardModel a, b;
  const GaussianPolicy pi = TrainAirl(o, demos, env, nullptr, nullptr, nullptr, &a);
  TrainAirl(o, demos, env, nullptr, nullptr, nullptr, &b);
  EXPECT_EQ(a.discount, 0.97);
  EXPECT_EQ(a.observation_features, pi.observation_features);
  EXPECT_EQ(a.input_features, pi.input_features);
  EXPECT_EQ(a.input.mean, pi.input.mean);
  EXPECT_EQ(a.input.scale, pi.input.scale);
  EXPECT_EQ(a.reward.spec.hidden, o.reward_hidden);
  EXPECT_EQ(a.shaping.spec.hidden, o.shaping_hidden);
  EXPECT_EQ(a.provenance["environment"], env.Describe());
  a.Save(PathOf("a.model"));
  b.Save(PathOf("b.model"));
  EXPECT_EQ(ReadFile(PathOf("a.model")), ReadFile(PathOf("b.model")));
  AirlActionValue value(AirlRewardModel::Load(PathOf("a.model")), env.ObservationFeatures(), 16);
  Eigen::MatrixXf next(2, 16);
  for (int c = 0; c < 16; ++c) next.col(c) << -1.0f + 0.13f * c, 0.5f - 0.07f * c;
  Eigen::VectorXd q(16);
  value.Evaluate(Eigen::Vector2f(0.1f, 0.2f), next, q);
  EXPECT_TRUE(q.allFinite());
  EXPECT_GT(q.maxCoeff() - q.minCoeff(), 1e-6);
}

TEST_F(AirlFileTest, WritesTheLearningCurveEveryIteration) {
  AirlOptions o = SmallAirl();
  o.iterations = 3;
  o.curve_path = PathOf("curve.csv");
  int calls = 0;
  TrainAirl(
      o, ExpertDemos(10, 2), PointMassEnv(), nullptr, nullptr, [&](const AirlIterationStats& s) {
        ++calls;
        // Already on disk when the callback runs.
        EXPECT_EQ(Lines(ReadFile(o.curve_path)).size(), static_cast<std::size_t>(s.iteration + 1));
        return true;
      });
  EXPECT_EQ(calls, 3);
  const auto lines = Lines(ReadFile(o.curve_path));
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[0],
            "iteration,env_steps,episodes,success_rate,collision_rate,mean_collisions,d_expert,"
            "d_policy,discriminator_loss,mean_reward,policy_loss,value_loss,entropy,mean_sigma,"
            "approx_kl,clip_fraction,bc_nll,seconds");
  const auto cells = data::SplitList(lines[3]);
  ASSERT_EQ(cells.size(), AirlIterationStats::Columns().size());
  EXPECT_EQ(cells[0], "3");
  EXPECT_EQ(cells[1], "1500");
  EXPECT_EQ(cells[2], "10");
}

TEST(AirlTest, SameSeedSameResultAlsoInConcurrentThreads) {
  const data::TrajectorySet demos = ExpertDemos(10, 2);
  const PointMassEnv env;
  AirlOptions a = SmallAirl(), b = SmallAirl();
  a.iterations = b.iterations = 3;
  a.seed = 1;
  b.seed = 2;
  const GaussianPolicy seq_a = TrainAirl(a, demos, env, nullptr, nullptr);
  const GaussianPolicy seq_b = TrainAirl(b, demos, env, nullptr, nullptr);
  EXPECT_FALSE(BitEqual(seq_a, seq_b));
  GaussianPolicy par_a, par_b;
  std::thread ta([&] { par_a = TrainAirl(a, demos, env, nullptr, nullptr); });
  std::thread tb([&] { par_b = TrainAirl(b, demos, env, nullptr, nullptr); });
  ta.join();
  tb.join();
  EXPECT_TRUE(BitEqual(seq_a, par_a));
  EXPECT_TRUE(BitEqual(seq_b, par_b));
}

TEST(AirlTest, WarmStartKeepsTheArchitectureAndNormalizer) {
  const data::TrajectorySet demos = ExpertDemos(20, 2);
  BcOptions bc_options = FastBc();
  bc_options.hidden = {24};
  bc_options.epochs = 20;
  const GaussianPolicy bc = TrainBc(bc_options, demos);
  const double bc_success = SuccessRate(bc, 100, 5);
  EXPECT_GE(bc_success, 0.8);
  AirlOptions o = SmallAirl();
  o.iterations = 2;
  AirlSummary s;
  const GaussianPolicy pi = TrainAirl(o, demos, PointMassEnv(), &bc, &s);
  EXPECT_TRUE(s.warm_started);
  EXPECT_EQ(pi.mean.spec, bc.mean.spec);
  EXPECT_EQ(pi.input.mean, bc.input.mean);
  EXPECT_EQ(pi.input.scale, bc.input.scale);
  EXPECT_EQ(pi.provenance["warm_start"], bc.provenance["trainer"]);
  // Two small PPO iterations keep it close to the BC policy.
  EXPECT_GE(SuccessRate(pi, 100, 5), bc_success - 0.2);

  GaussianPolicy wrong = bc;
  wrong.observation_features = {"p", "q"};
  EXPECT_HAS(ErrorOf([&] { TrainAirl(o, demos, PointMassEnv(), &wrong, nullptr); }), "p, q");
}

// AIRL keeps the warm start's input features: its policy, value and discriminator read the same
// rows, and the policy it returns ignores the others.
TEST(AirlTest, AWarmStartOnSomeFeaturesKeepsThem) {
  const data::TrajectorySet demos = ExpertDemos(20, 2);
  BcOptions bc_options = FastBc();
  bc_options.hidden = {24};
  bc_options.epochs = 20;
  bc_options.input_features = {"x"};
  const GaussianPolicy bc = TrainBc(bc_options, demos);
  AirlOptions o = SmallAirl();
  o.iterations = 2;
  const GaussianPolicy pi = TrainAirl(o, demos, PointMassEnv(), &bc, nullptr);
  EXPECT_EQ(pi.input_features, (std::vector<std::string>{"x"}));
  EXPECT_EQ(pi.mean.spec, bc.mean.spec);
  EXPECT_FALSE(BitEqual(pi, bc));  // trained
  PolicyEvaluator ev(pi);
  Eigen::VectorXf o1(2), o2(2), mu1(2), mu2(2);
  o1 << 0.3f, -0.5f;
  o2 << 0.3f, 0.9f;
  ev.Mean(o1, mu1);
  ev.Mean(o2, mu2);
  EXPECT_EQ(mu1, mu2);
}

// The bc_weight term pulls the policy's mean toward the expert's actions: from the same random
// start, a few iterations with it fit the demonstrations far better than pure AIRL, and the
// curve records its NLL (NaN when the term is off).
TEST(AirlTest, BcWeightPullsTheMeanTowardTheExpertActions) {
  const data::TrajectorySet demos = ExpertDemos(20, 2);
  auto action_mse = [&](const GaussianPolicy& pi) {
    PolicyEvaluator ev(pi, static_cast<int>(demos.num_steps()));
    Eigen::MatrixXf mus(demos.actions.rows(), demos.num_steps());
    ev.Means(demos.states, mus);
    return static_cast<double>((mus - demos.actions).squaredNorm()) / mus.size();
  };
  AirlOptions o = SmallAirl();
  o.iterations = 4;
  o.policy_lr = 1e-2;  // 40 Adam steps in all: large steps, so that the terms' pull shows
  Recorder pure, regularised;
  const double mse_pure =
      action_mse(TrainAirl(o, demos, PointMassEnv(), nullptr, nullptr, pure.Callback()));
  o.bc_weight = 10.0;
  const double mse_bc =
      action_mse(TrainAirl(o, demos, PointMassEnv(), nullptr, nullptr, regularised.Callback()));
  EXPECT_LT(mse_bc, 0.5 * mse_pure) << "pure " << mse_pure << ", with bc_weight " << mse_bc;
  for (const auto& row : pure.rows) EXPECT_TRUE(std::isnan(row.bc_nll));
  ASSERT_EQ(regularised.rows.size(), 4u);
  for (const auto& row : regularised.rows) EXPECT_TRUE(std::isfinite(row.bc_nll));
  EXPECT_LT(regularised.rows.back().bc_nll, regularised.rows.front().bc_nll);

  o.bc_weight = -1.0;
  EXPECT_HAS(ErrorOf([&] { TrainAirl(o, demos, PointMassEnv(), nullptr, nullptr); }),
             "AirlOptions::bc_weight = -1");
  AirlOptions y;
  y.ApplyYaml(YAML::Load("{bc_weight: 0.5}"), "airl.yaml");
  EXPECT_EQ(y.bc_weight, 0.5);
  EXPECT_EQ(y.ToJson()["bc_weight"], 0.5);
}

TEST(AirlTest, InvalidInputsAreRejected) {
  const data::TrajectorySet demos = ExpertDemos(4, 2);
  const PointMassEnv env;
  auto error = [&](auto mutate) {
    AirlOptions o = SmallAirl();
    mutate(o);
    return ErrorOf([&] { TrainAirl(o, demos, env, nullptr, nullptr); });
  };
  EXPECT_HAS(error([](AirlOptions& o) { o.iterations = 0; }), "AirlOptions::iterations = 0");
  EXPECT_HAS(error([](AirlOptions& o) { o.clip = 1.5; }),
             "AirlOptions::clip = 1.5, must be in (0, 1)");
  EXPECT_HAS(error([](AirlOptions& o) { o.reward_hidden = {}; }), "AirlOptions::reward_hidden");
  EXPECT_HAS(error([](AirlOptions& o) { o.gae_lambda = -0.1; }), "AirlOptions::gae_lambda");
  EXPECT_HAS(error([](AirlOptions& o) { o.discriminator_discount = 2; }),
             "AirlOptions::discriminator_discount = 2");
  EXPECT_HAS(error([](AirlOptions& o) { o.resume = true; }), "AirlOptions::resume");

  data::TrajectorySet d = demos;
  d.state_features = {"px", "py"};
  std::string m = ErrorOf([&] { TrainAirl(SmallAirl(), d, env, nullptr, nullptr); });
  EXPECT_HAS(m, "px, py");
  EXPECT_HAS(m, "x, y");
  d = demos;
  d.action_features = {"ax", "ay"};
  EXPECT_HAS(ErrorOf([&] { TrainAirl(SmallAirl(), d, env, nullptr, nullptr); }), "ax, ay");
  d = demos;
  d.episode_begin = {0, 1, d.num_steps()};  // a one-row episode has no transition
  EXPECT_HAS(ErrorOf([&] { TrainAirl(SmallAirl(), d, env, nullptr, nullptr); }),
             "episode 0 has 1 rows, at least 2");
  d = demos;
  d.actions(0, 3) = std::numeric_limits<float>::infinity();
  EXPECT_HAS(ErrorOf([&] { TrainAirl(SmallAirl(), d, env, nullptr, nullptr); }),
             "action 3 has a non-finite value");
}

TEST(AirlTest, OptionsYamlAndNames) {
  AirlOptions o;
  o.ApplyYaml(YAML::Load("{reward: state-reward, iterations: 7, policy_hidden: [8], "
                         "discriminator_discount: 1.0, checkpoint_path: x.ckpt, resume: true}"),
              "airl.yaml");
  EXPECT_EQ(o.reward, AirlReward::kStateReward);
  EXPECT_EQ(o.iterations, 7);
  EXPECT_EQ(o.policy_hidden, std::vector<int>{8});
  EXPECT_EQ(o.discriminator_discount, 1.0);
  EXPECT_NO_THROW(o.Validate());
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{reward: gail}"), "airl.yaml"); }),
             "reward = 'gail', must be one of logit-d, state-reward");
  EXPECT_HAS(ErrorOf([&] { o.ApplyYaml(YAML::Load("{gamma_d: 1}"), "airl.yaml"); }),
             "airl.yaml: unknown field 'gamma_d'");
  AirlOptions back;
  back.ApplyYaml(YAML::Load(o.ToJson().dump()), "json");
  EXPECT_EQ(back.ToJson(), o.ToJson());
  EXPECT_EQ(ToString(kAirlRewardNames, AirlReward::kLogitD), "logit-d");
}

// ---------------------------------------------------------------------------------------------
// Joint optimisation (TrainAirlJoint) with a flat BarrierNet

// A flat barrier on the toy task's (x, y): a random tanh MLP with a non-trivial normaliser.
cbf::BarrierNet RandomFlatBarrier() {
  cbf::BarrierNet net;
  net.mlp = nn::RandomMlpParams({2, {8}, 1, nn::Activation::kTanh}, 21);
  net.mlp.layers.back().bias[0] = 0.1f;
  net.normalizer.mean = (Eigen::VectorXf(2) << 0.2f, -0.1f).finished();
  net.normalizer.scale = (Eigen::VectorXf(2) << 1.5f, 0.8f).finished();
  net.features = {"x", "y"};
  return net;
}

// L_cbf of JointCbfOptions from its definition, in double precision through the Eigen
// evaluator of `net` and the toy model T(s, a) = s + 0.1 a (|a| <= 1).
double ReferenceJointLoss(const cbf::BarrierNet& net, const JointCbfOptions& o,
                          const Eigen::MatrixXf& states, const Eigen::MatrixXf& actions) {
  const long n = states.cols();
  const Eigen::MatrixXf next = states + 0.1f * actions;
  Eigen::VectorXf h(n), h_next(n);
  net.MakeEvaluator()->Evaluate(states, h);
  net.MakeEvaluator()->Evaluate(next, h_next);
  double sum = 0.0;
  for (long i = 0; i < n; ++i) {
    const double deriv = double(h_next(i)) - h(i) + o.dt * o.class_k_gain * h(i);
    sum += h(i) >= 0 ? std::max(-deriv, 0.0)
                     : o.unsafe_weight * std::max(-deriv + o.unsafe_margin, 0.0);
  }
  return sum / static_cast<double>(n);
}

TEST(AirlJointTest, TheTermOfAFlatBarrierMatchesItsDefinitionAndFiniteDifferences) {
  const cbf::BarrierNet net = RandomFlatBarrier();
  const std::unique_ptr<cbf::DifferentiableBarrier> barrier = cbf::MakeDifferentiableBarrier(net);
  const test::PointMassModel model;
  JointCbfOptions o;
  o.class_k_gain = 2.0;
  o.unsafe_weight = 3.0;
  o.unsafe_margin = 0.05;
  const int n = 24;
  Rng rng(5);
  Eigen::MatrixXf states(2, n), actions(2, n);
  for (int c = 0; c < n; ++c)
    for (int r = 0; r < 2; ++r) {
      states(r, c) = static_cast<float>(rng.Uniform(-2.5, 2.5));
      actions(r, c) = static_cast<float>(rng.Uniform(-0.9, 0.9));  // inside the action bound
    }
  Eigen::VectorXf h(n);
  net.MakeEvaluator()->Evaluate(states, h);
  ASSERT_GT((h.array() >= 0).count(), 0);  // both branches of the loss are exercised
  ASSERT_GT((h.array() < 0).count(), 0);

  internal::JointCbfTerm term(o, *barrier, model);
  term.Prepare(states, 2);
  // Rows in a permuted order: Loss indexes the prepared rows.
  std::vector<std::int64_t> order(n);
  for (int i = 0; i < n; ++i) order[i] = (7 * i) % n;
  Eigen::MatrixXf permuted_states(2, n), permuted_actions(2, n);
  for (int i = 0; i < n; ++i) {
    permuted_states.col(i) = states.col(order[i]);
    permuted_actions.col(i) = actions.col(order[i]);
  }
  const torch::Tensor idx = internal::IndexTensor(order);
  torch::Tensor a = nn::ToTensor(permuted_actions).requires_grad_(true);
  const torch::Tensor loss = term.Loss(idx, a);
  const double reference = ReferenceJointLoss(net, o, permuted_states, permuted_actions);
  EXPECT_GT(reference, 0.0);
  EXPECT_NEAR(loss.item<double>(), reference, 1e-5);
  EXPECT_NEAR(term.MeanLoss(), loss.item<double>(), 1e-12);

  // d L / d a by autograd against central differences of the definition.
  loss.backward();
  const Eigen::MatrixXf grad = nn::ToEigen(a.grad());
  const float eps = 1e-2f;
  double grad_norm = 0.0;
  for (int i = 0; i < n; ++i)
    for (int k = 0; k < 2; ++k) {
      Eigen::MatrixXf plus = permuted_actions, minus = permuted_actions;
      plus(k, i) += eps;
      minus(k, i) -= eps;
      const double fd = (ReferenceJointLoss(net, o, permuted_states, plus) -
                         ReferenceJointLoss(net, o, permuted_states, minus)) /
                        (2 * eps);
      EXPECT_NEAR(grad(k, i), fd, 1e-4 + 1e-2 * std::abs(fd)) << "row " << i << ", action " << k;
      grad_norm += std::abs(grad(k, i));
    }
  EXPECT_GT(grad_norm, 0.0);
}

// h(s) = 100 tanh(0.01 x) - 5 ~ x - 5: negative everywhere in the arena, so L_cbf (unsafe
// branch) = unsafe_weight * relu(-0.1 a_x - 0.1 (x - 5) + margin) pushes a_x up.
cbf::BarrierNet RightwardFlatBarrier() {
  cbf::BarrierNet net;
  net.mlp.spec = {2, {1}, 1, nn::Activation::kTanh};
  net.mlp.layers = {{(Eigen::MatrixXf(1, 2) << 0.01f, 0.0f).finished(), Eigen::VectorXf::Zero(1)},
                    {Eigen::MatrixXf::Constant(1, 1, 100.0f), Eigen::VectorXf::Constant(1, -5.0f)}};
  net.normalizer = nn::Normalizer::Identity(2);
  net.features = {"x", "y"};
  return net;
}

TEST(AirlJointTest, TrainsWithAFlatBarrierAndTheTermMovesThePolicy) {
  const data::TrajectorySet demos = ExpertDemos(10, 2);
  const PointMassEnv env;
  AirlOptions o = SmallAirl();
  o.iterations = 10;
  o.policy_lr = 3e-3;  // Adam moves the mean ~ lr per step: make the effect visible
  JointCbfOptions joint;
  joint.weight = 10.0;
  AirlSummary airl_summary, joint_summary;
  const GaussianPolicy airl = TrainAirl(o, demos, env, nullptr, &airl_summary);
  const GaussianPolicy with_term = TrainAirlJoint(
      o, joint, RightwardFlatBarrier(), env.ShieldModel(), demos, env, nullptr, &joint_summary);
  EXPECT_EQ(airl_summary.cbf_loss, 0.0);
  EXPECT_TRUE(std::isfinite(joint_summary.cbf_loss));
  EXPECT_GT(joint_summary.cbf_loss, 0.0);
  EXPECT_EQ(with_term.provenance["joint"], joint.ToJson());
  EXPECT_NE(with_term.provenance["trainer"].get<std::string>().find("TrainAirlJoint"),
            std::string::npos);
  // Mean x-action over the demonstration states: the term pushes it up.
  auto mean_ax = [&](const GaussianPolicy& pi) {
    PolicyEvaluator ev(pi, static_cast<int>(demos.num_steps()));
    Eigen::MatrixXf mus(2, demos.num_steps());
    ev.Means(demos.states, mus);
    return mus.row(0).mean();
  };
  EXPECT_GT(mean_ax(with_term), mean_ax(airl) + 1.0)
      << "AIRL " << mean_ax(airl) << ", joint " << mean_ax(with_term);
}

// A flat barrier on some of the observation's features (BarrierTrainerOptions::input_features)
// reads them by name: RightwardFlatBarrier on x alone (its y weight is 0) trains as it does.
TEST(AirlJointTest, AFlatBarrierOnSomeObservationFeaturesReadsThemByName) {
  const data::TrajectorySet demos = ExpertDemos(4, 2);
  const PointMassEnv env;
  AirlOptions o = SmallAirl();
  o.iterations = 2;
  cbf::BarrierNet x_only = RightwardFlatBarrier();
  x_only.mlp.spec.input_dim = 1;
  x_only.mlp.layers[0].weight = Eigen::MatrixXf::Constant(1, 1, 0.01f);
  x_only.normalizer = nn::Normalizer::Identity(1);
  x_only.features = {"x"};
  AirlSummary full_summary, x_summary;
  TrainAirlJoint(o, JointCbfOptions{}, RightwardFlatBarrier(), env.ShieldModel(), demos, env,
                 nullptr, &full_summary);
  TrainAirlJoint(o, JointCbfOptions{}, x_only, env.ShieldModel(), demos, env, nullptr, &x_summary);
  EXPECT_GT(x_summary.cbf_loss, 0.0);
  EXPECT_NEAR(x_summary.cbf_loss, full_summary.cbf_loss, 1e-6 * full_summary.cbf_loss);
}

TEST(AirlJointTest, ABarrierOrModelThatDoesNotFitTheEnvironmentIsRejected) {
  const data::TrajectorySet demos = ExpertDemos(4, 2);
  const PointMassEnv env;
  cbf::BarrierNet wide;
  wide.mlp = nn::RandomMlpParams({3, {4}, 1, nn::Activation::kTanh}, 1);
  wide.normalizer = nn::Normalizer::Identity(3);
  wide.features = {"x", "y", "z"};
  const std::string m = ErrorOf([&] {
    TrainAirlJoint(SmallAirl(), JointCbfOptions{}, wide, env.ShieldModel(), demos, env, nullptr,
                   nullptr);
  });
  EXPECT_HAS(m, "joint optimisation: the barrier (barrier_mlp 3-4-1 tanh");
  EXPECT_HAS(m, "reads 3-D states");
  JointCbfOptions bad;
  bad.weight = -1;
  EXPECT_HAS(ErrorOf([&] {
               TrainAirlJoint(SmallAirl(), bad, RightwardFlatBarrier(), env.ShieldModel(), demos,
                              env, nullptr, nullptr);
             }),
             "JointCbfOptions::weight = -1");
}

}  // namespace
}  // namespace secure::policy
