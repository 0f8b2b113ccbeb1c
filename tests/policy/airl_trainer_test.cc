// AIRL and the joint policy (AIRL + the CBF term) (LibTorch; the policy_train_test program): the
// one file of the program that includes the torch headers (15 s per translation unit), so the
// tests that reach LibTorch directly are here: AIRL's reward terms, the joint CBF term, and
// BC's use of the global generator.
#include <torch/torch.h>

#include "secure/cbf/differentiable_barrier.h"
#include "secure/nn/torch_mlp.h"
#include "secure/policy/internal/joint_cbf_term.h"
#include "secure/policy/internal/torch_policy.h"
#include "tests/policy/trainers_test_util.h"

namespace secure::policy {
namespace {
using namespace test;  // NOLINT(google-build-using-namespace): the trainer tests' helpers

// ---------------------------------------------------------------------------------------------
// Behaviour cloning and the global generator (here for the torch headers).

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
