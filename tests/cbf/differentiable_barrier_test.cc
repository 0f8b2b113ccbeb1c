#include "secure/cbf/differentiable_barrier.h"

#include <gtest/gtest.h>

#include "domains/derby/domain.h"
#include "secure/common/rng.h"
#include "secure/nn/torch_mlp.h"
#include "tests/nn/nn_test_util.h"
#include "tests/test_util.h"

namespace secure::cbf {
namespace {

using secure::test::ErrorOf;

// (dim x n) states, uniform in [lo, hi) per row, seeded (the nn tests' RandomInputs).
Eigen::MatrixXf UniformStates(int dim, int n, double lo, double hi, std::uint64_t seed) {
  return nn::test::RandomInputs(dim, n, seed, lo, hi);
}

BarrierNet FlatNet() {
  BarrierNet net;
  net.mlp = nn::RandomMlpParams({3, {8, 8}, 1, nn::Activation::kTanh}, 11);
  net.normalizer.mean = (Eigen::VectorXf(3) << 0.5f, -1.0f, 0.25f).finished();
  net.normalizer.scale = (Eigen::VectorXf(3) << 2.0f, 0.5f, 1.5f).finished();
  net.features = {"a", "b", "c"};
  return net;
}

// On wider states whose rows hold the net's features among others, by name: the values of the
// Eigen evaluator for the same states, and no gradient to the rows it does not read.
TEST(DifferentiableBarrierTest, FlatForWiderStatesPicksItsFeaturesByName) {
  const BarrierNet net = FlatNet();  // a, b, c
  const std::vector<std::string> wide = {"c", "x", "a", "b", "y"};
  const std::unique_ptr<DifferentiableBarrier> h =
      MakeDifferentiableBarrierFor(net, wide, "the wide states");
  EXPECT_EQ(h->state_dim(), 5);
  EXPECT_NE(h->Describe().find("on 3 of 5 state rows"), std::string::npos) << h->Describe();
  const Eigen::MatrixXf states = UniformStates(5, 40, -2, 2, 13);
  Eigen::VectorXf h_eigen(40);
  net.MakeEvaluatorFor(wide, "the wide states")->Evaluate(states, h_eigen);
  torch::Tensor x = nn::ToTensor(states).requires_grad_(true);
  const torch::Tensor values = h->Forward(x);
  for (int i = 0; i < 40; ++i) EXPECT_NEAR(values[i].item<double>(), h_eigen(i), 1e-5);
  values.sum().backward();
  const Eigen::MatrixXf grad = nn::ToEigen(x.grad());
  EXPECT_EQ(grad.row(1).cwiseAbs().maxCoeff(), 0.0f);  // x
  EXPECT_EQ(grad.row(4).cwiseAbs().maxCoeff(), 0.0f);  // y
  EXPECT_GT(grad.row(0).cwiseAbs().maxCoeff(), 0.0f);  // c

  EXPECT_EQ(MakeDifferentiableBarrierFor(net, net.features, "s")->Describe(),
            MakeDifferentiableBarrier(net)->Describe());
  EXPECT_HAS(ErrorOf([&] { MakeDifferentiableBarrierFor(net, {"a", "c"}, "two.csv", "m"); }),
             "two.csv has 2 features (a, c), without 'b', which m reads (3: a, b, c)");
}

TEST(DifferentiableBarrierTest, FlatMatchesItsEvaluatorAndFiniteDifferences) {
  const BarrierNet net = FlatNet();
  const std::unique_ptr<DifferentiableBarrier> h = MakeDifferentiableBarrier(net);
  EXPECT_EQ(h->state_dim(), 3);
  EXPECT_NE(h->Describe().find("barrier_mlp 3-8-8-1 tanh"), std::string::npos) << h->Describe();

  const Eigen::MatrixXf states = UniformStates(3, 40, -2, 2, 12);
  Eigen::VectorXf h_eigen(40);
  net.MakeEvaluator()->Evaluate(states, h_eigen);
  torch::Tensor x = nn::ToTensor(states).requires_grad_(true);
  const torch::Tensor values = h->Forward(x);
  ASSERT_EQ(values.sizes(), (std::vector<std::int64_t>{40}));
  for (int i = 0; i < 40; ++i) EXPECT_NEAR(values[i].item<double>(), h_eigen(i), 1e-5);

  // d h / d s by autograd against central differences (each row's h depends on its row only).
  values.sum().backward();
  const Eigen::MatrixXf grad = nn::ToEigen(x.grad());
  const float eps = 1e-2f;
  for (int r = 0; r < 3; ++r) {
    Eigen::MatrixXf plus = states, minus = states;
    plus.row(r).array() += eps;
    minus.row(r).array() -= eps;
    Eigen::VectorXf hp(40), hm(40);
    net.MakeEvaluator()->Evaluate(plus, hp);
    net.MakeEvaluator()->Evaluate(minus, hm);
    for (int i = 0; i < 40; ++i)
      EXPECT_NEAR(grad(r, i), (hp(i) - hm(i)) / (2 * eps), 2e-3 + 1e-2 * std::abs(grad(r, i)))
          << "row " << r << ", state " << i;
  }
  EXPECT_GT(grad.cwiseAbs().sum(), 0.0f);
}

TEST(DifferentiableBarrierTest, CarMatchesItsEvaluatorAndPassesGradientsToTheStates) {
  CarBarrierNet net;
  net.input.layout = domains::derby::ObstacleLayoutOfObservation();
  net.input.use_velocity = true;
  net.cap = 0.04;
  net.mlp = nn::RandomMlpParams({5, {16, 16}, 1, nn::Activation::kRelu}, 5);
  net.normalizer = nn::Normalizer::Fit(Eigen::MatrixXf::Random(5, 30));
  const std::unique_ptr<DifferentiableBarrier> h = MakeDifferentiableBarrier(net);
  EXPECT_EQ(h->state_dim(), net.state_dim());
  EXPECT_EQ(h->Describe(), net.Describe() + " (differentiable)");

  const Eigen::MatrixXf states = UniformStates(net.state_dim(), 30, -0.6, 0.6, 13);
  Eigen::VectorXf h_eigen(30);
  net.MakeEvaluator()->Evaluate(states, h_eigen);
  torch::Tensor x = nn::ToTensor(states).requires_grad_(true);
  const torch::Tensor values = h->Forward(x);
  ASSERT_EQ(values.sizes(), (std::vector<std::int64_t>{30}));
  for (int i = 0; i < 30; ++i) EXPECT_NEAR(values[i].item<double>(), h_eigen(i), 1e-5);
  values.sum().backward();
  ASSERT_TRUE(x.grad().defined());
  EXPECT_GT(x.grad().abs().sum().item<double>(), 0.0);
}

TEST(DifferentiableBarrierTest, WrongShapesAndInvalidNetsAreRejected) {
  const std::unique_ptr<DifferentiableBarrier> h = MakeDifferentiableBarrier(FlatNet());
  EXPECT_HAS(ErrorOf([&] { h->Forward(torch::zeros({4, 2})); }), "expected [N, 3]");
  EXPECT_HAS(ErrorOf([&] { h->Forward(torch::zeros({4, 3}, torch::kFloat64)); }), "float32");
  BarrierNet bad = FlatNet();
  bad.normalizer = nn::Normalizer::Identity(2);
  EXPECT_HAS(ErrorOf([&] { MakeDifferentiableBarrier(bad); }), "normalizer");
}

// An ensemble: the minimum over its members, as MinBarrier; the gradient is the arg-min
// member's (MinBarrier's analytic gradient).
TEST(DifferentiableBarrierTest, EnsembleIsTheMinimumWithTheArgMinMembersGradient) {
  BarrierNet net = FlatNet();
  for (unsigned long long seed : {21ULL, 22ULL}) {
    BarrierMember m;
    m.mlp = nn::RandomMlpParams({3, {8, 8}, 1, nn::Activation::kTanh}, seed);
    m.normalizer = nn::Normalizer::Identity(3);
    net.more_members.push_back(m);
  }
  const std::unique_ptr<DifferentiableBarrier> h = MakeDifferentiableBarrier(net);
  EXPECT_NE(h->Describe().find("min of 3 barrier_mlp 3-8-8-1 tanh"), std::string::npos)
      << h->Describe();
  const Eigen::MatrixXf states = UniformStates(3, 40, -2, 2, 14);
  Eigen::VectorXf h_eigen(40);
  Eigen::MatrixXf g_eigen(3, 40);
  net.MakeEvaluator()->EvaluateGradient(states, h_eigen, g_eigen);
  torch::Tensor x = nn::ToTensor(states).requires_grad_(true);
  const torch::Tensor values = h->Forward(x);
  values.sum().backward();
  const Eigen::MatrixXf grad = nn::ToEigen(x.grad());
  for (int i = 0; i < 40; ++i) {
    EXPECT_NEAR(values[i].item<double>(), h_eigen(i), 1e-5);
    for (int r = 0; r < 3; ++r) EXPECT_NEAR(grad(r, i), g_eigen(r, i), 1e-4) << i << ", " << r;
  }
}

}  // namespace
}  // namespace secure::cbf
