// The barriers' analytic gradients (Barrier::EvaluateGradient, InferenceMlp::ForwardGradient)
// against central finite differences and against LibTorch autograd (DifferentiableBarrier), on
// every barrier kind: the flat MLP (tanh and ReLU, 0 to 3 hidden layers), the same on wider
// states (SelectRows), the per-car network's capped minimum (positions only and with
// velocities), and the finite-difference default of any other barrier.
//
// Tolerances. MLP against differences of the double-precision reference forward (step 1e-4):
// 1e-4 + 1e-3 |g| (float arithmetic of the analytic path). Against autograd (float32 both):
// 1e-5 + 1e-4 |g|. Per-car barrier against float differences (step 1e-3) of its evaluator:
// 2e-3 + 1e-2 |g| where the active car and the cap do not change within the step. The
// finite-difference default against a known gradient: 1e-3 + 1e-3 |g|.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include "domains/derby/domain.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/cbf/differentiable_barrier.h"
#include "secure/common/rng.h"
#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"
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

BarrierNet FlatNet(int dim, std::vector<int> hidden, nn::Activation act, std::uint64_t seed) {
  BarrierNet net;
  net.mlp = nn::RandomMlpParams({dim, std::move(hidden), 1, act}, seed);
  net.normalizer = nn::Normalizer::Fit(UniformStates(dim, 60, -3, 5, seed + 100));
  for (int i = 0; i < dim; ++i) net.features.push_back("f" + std::to_string(i));
  return net;
}

// d h / d s by autograd through the LibTorch forward of the same model.
Eigen::MatrixXf Autograd(const DifferentiableBarrier& h, const Eigen::MatrixXf& states,
                         Eigen::VectorXf* values) {
  torch::Tensor x = nn::ToTensor(states).requires_grad_(true);
  const torch::Tensor v = h.Forward(x);
  values->resize(states.cols());
  for (Eigen::Index i = 0; i < states.cols(); ++i) (*values)[i] = v[i].item<float>();
  v.sum().backward();
  return nn::ToEigen(x.grad());
}

struct NetCase {
  int dim;
  std::vector<int> hidden;
  nn::Activation activation;
};

class MlpGradientTest : public ::testing::TestWithParam<NetCase> {};

TEST_P(MlpGradientTest, MatchesReferenceDifferencesAndAutograd) {
  const NetCase& c = GetParam();
  const BarrierNet net = FlatNet(c.dim, c.hidden, c.activation, 7 + c.hidden.size());
  // 150 states: more than one gradient chunk (64), so the chunking is covered too.
  const int n = 150;
  const Eigen::MatrixXf states = UniformStates(c.dim, n, -3, 5, 21);
  std::unique_ptr<Barrier> evaluator = net.MakeEvaluator();
  EXPECT_TRUE(evaluator->analytic_gradient());
  Eigen::VectorXf h(n), h_plain(n);
  Eigen::MatrixXf grad(c.dim, n);
  evaluator->EvaluateGradient(states, h, grad);
  evaluator->Evaluate(states, h_plain);
  for (int i = 0; i < n; ++i) EXPECT_NEAR(h[i], h_plain[i], 1e-5 + 1e-5 * std::abs(h_plain[i]));

  // Central differences of the double-precision reference forward, step 1e-4.
  const double step = 1e-4;
  for (int r = 0; r < c.dim; ++r) {
    Eigen::MatrixXf plus = states, minus = states;
    // Float states: difference what is represented.
    plus.row(r).array() += static_cast<float>(step);
    minus.row(r).array() -= static_cast<float>(step);
    const Eigen::MatrixXd hp = nn::ReferenceForward(net.mlp, net.normalizer, plus);
    const Eigen::MatrixXd hm = nn::ReferenceForward(net.mlp, net.normalizer, minus);
    for (int i = 0; i < n; ++i) {
      const double width = double(plus(r, i)) - double(minus(r, i));
      const double fd = (hp(0, i) - hm(0, i)) / width;
      // ReLU: a kink within the step makes the difference meaningless there; skip it (rare).
      if (c.activation == nn::Activation::kRelu) {
        const Eigen::MatrixXd hc = nn::ReferenceForward(net.mlp, net.normalizer, states.col(i));
        if (std::abs((hp(0, i) - hc(0, 0)) - (hc(0, 0) - hm(0, i))) > 1e-9) continue;
      }
      EXPECT_NEAR(grad(r, i), fd, 1e-4 + 1e-3 * std::abs(fd)) << "row " << r << ", state " << i;
    }
  }
  // Autograd through LibTorch.
  Eigen::VectorXf h_torch;
  const Eigen::MatrixXf grad_torch = Autograd(*MakeDifferentiableBarrier(net), states, &h_torch);
  for (int i = 0; i < n; ++i) {
    EXPECT_NEAR(h[i], h_torch[i], 1e-5 + 1e-5 * std::abs(h_torch[i]));
    for (int r = 0; r < c.dim; ++r)
      EXPECT_NEAR(grad(r, i), grad_torch(r, i), 1e-5 + 1e-4 * std::abs(grad_torch(r, i)))
          << "row " << r << ", state " << i;
  }
  EXPECT_GT(grad.cwiseAbs().sum(), 0.0f);
}

INSTANTIATE_TEST_SUITE_P(
    EveryActivationAndDepth, MlpGradientTest,
    ::testing::Values(NetCase{3, {}, nn::Activation::kTanh},
                      NetCase{4, {16}, nn::Activation::kTanh},
                      NetCase{4, {16}, nn::Activation::kRelu},
                      NetCase{5, {32, 16}, nn::Activation::kTanh},
                      NetCase{5, {32, 16}, nn::Activation::kRelu},
                      NetCase{9, {64, 128, 64}, nn::Activation::kRelu},
                      NetCase{9, {64, 64, 64}, nn::Activation::kTanh}),
    // Test names that say the net ("in5_32_16_relu"), not gtest's bytes of the struct.
    [](const ::testing::TestParamInfo<NetCase>& info) {
      std::string name = "in" + std::to_string(info.param.dim);
      for (int h : info.param.hidden) name += "_" + std::to_string(h);
      return name + (info.param.activation == nn::Activation::kTanh ? "_tanh" : "_relu");
    });

TEST(InferenceMlpGradientTest, OneStateEqualsItsColumnOfABatchAndChecksShapes) {
  const BarrierNet net = FlatNet(4, {16, 16}, nn::Activation::kTanh, 3);
  const nn::InferenceMlp mlp(net.mlp, net.normalizer);
  nn::InferenceMlp::GradientWorkspace ws = mlp.MakeGradientWorkspace(8);
  const Eigen::MatrixXf states = UniformStates(4, 8, -2, 2, 5);
  Eigen::VectorXf h(8), h1(1);
  Eigen::MatrixXf g(4, 8), g1(4, 1);
  mlp.ForwardGradient(states, ws, h, g);
  for (int i = 0; i < 8; ++i) {
    mlp.ForwardGradient(states.col(i), ws, h1, g1);
    EXPECT_NEAR(h1[0], h[i], 1e-6);
    EXPECT_TRUE(g1.col(0).isApprox(g.col(i), 1e-6f));
  }
  Eigen::VectorXf h9(9);
  Eigen::MatrixXf g9(4, 9);
  EXPECT_HAS(ErrorOf([&] { mlp.ForwardGradient(UniformStates(4, 9, 0, 1, 1), ws, h9, g9); }),
             "exceeds the gradient workspace's max_batch 8");
  EXPECT_HAS(ErrorOf([&] { mlp.ForwardGradient(UniformStates(3, 2, 0, 1, 1), ws, h9, g9); }),
             "inputs have 3 rows, expected 4");
  const nn::InferenceMlp two(nn::RandomMlpParams({3, {4}, 2, nn::Activation::kTanh}, 1),
                             nn::Normalizer::Identity(3));
  nn::InferenceMlp::GradientWorkspace ws2 = two.MakeGradientWorkspace(2);
  Eigen::VectorXf v2(1);
  Eigen::MatrixXf gr2(3, 1);
  EXPECT_HAS(ErrorOf([&] { two.ForwardGradient(UniformStates(3, 1, 0, 1, 1), ws2, v2, gr2); }),
             "the network has 2 outputs; the gradient needs exactly 1");
}

// A wider state than the model reads: the model's rows get its gradient, the others 0.
TEST(BarrierGradientTest, SelectRowsScattersTheInnerGradient) {
  const BarrierNet net = FlatNet(3, {8, 8}, nn::Activation::kTanh, 4);  // f0, f1, f2
  const std::vector<std::string> wide = {"f2", "x", "f0", "f1", "y"};
  std::unique_ptr<Barrier> h = net.MakeEvaluatorFor(wide, "wide", "m", 16);
  EXPECT_TRUE(h->analytic_gradient());
  const Eigen::MatrixXf states = UniformStates(5, 40, -2, 2, 8);  // chunks of 16
  Eigen::VectorXf values(40);
  Eigen::MatrixXf grad(5, 40);
  h->EvaluateGradient(states, values, grad);
  Eigen::MatrixXf narrow(3, 40);
  narrow.row(0) = states.row(2);
  narrow.row(1) = states.row(3);
  narrow.row(2) = states.row(0);
  Eigen::VectorXf values_n(40);
  Eigen::MatrixXf grad_n(3, 40);
  net.MakeEvaluator()->EvaluateGradient(narrow, values_n, grad_n);
  EXPECT_EQ(grad.row(1).cwiseAbs().maxCoeff(), 0.0f);
  EXPECT_EQ(grad.row(4).cwiseAbs().maxCoeff(), 0.0f);
  EXPECT_TRUE(grad.row(2).isApprox(grad_n.row(0)));
  EXPECT_TRUE(grad.row(3).isApprox(grad_n.row(1)));
  EXPECT_TRUE(grad.row(0).isApprox(grad_n.row(2)));
  EXPECT_TRUE(values.isApprox(values_n));
  Eigen::VectorXf h_torch;
  const Eigen::MatrixXf grad_torch =
      Autograd(*MakeDifferentiableBarrierFor(net, wide, "wide"), states, &h_torch);
  EXPECT_TRUE(grad.isApprox(grad_torch, 1e-4f)) << (grad - grad_torch).cwiseAbs().maxCoeff();
  Eigen::MatrixXf wrong(4, 40);
  EXPECT_HAS(ErrorOf([&] { h->EvaluateGradient(states, values, wrong); }),
             "gradients are 4 x 40, expected 5 x 40");
}

CarBarrierNet CarNet(bool velocity, nn::Activation act, std::uint64_t seed) {
  CarBarrierNet net;
  net.input.layout = domains::derby::ObstacleLayoutOfObservation();
  net.input.use_velocity = velocity;
  net.cap = 0.3;
  const int f = net.input.feature_dim();
  net.mlp = nn::RandomMlpParams({f, {16, 16}, 1, act}, seed);
  net.normalizer = nn::Normalizer::Fit(UniformStates(f, 40, -1, 1, seed));
  return net;
}

class CarGradientTest : public ::testing::TestWithParam<std::tuple<bool, nn::Activation>> {};

TEST_P(CarGradientTest, TheActiveCarsGradientMatchesAutogradAndDifferences) {
  const auto [velocity, act] = GetParam();
  const CarBarrierNet net = CarNet(velocity, act, 5);
  const int dim = net.state_dim(), n = 100;  // more than one gradient chunk
  const Eigen::MatrixXf states = UniformStates(dim, n, -0.7, 0.7, 13);
  std::unique_ptr<Barrier> evaluator = net.MakeEvaluator(32);
  EXPECT_TRUE(evaluator->analytic_gradient());
  Eigen::VectorXf h(n), h_plain(n);
  Eigen::MatrixXf grad(dim, n);
  evaluator->EvaluateGradient(states, h, grad);
  evaluator->Evaluate(states, h_plain);
  EXPECT_EQ(h, h_plain);  // the same forward picks the active car
  int at_cap = 0, below = 0;
  for (int i = 0; i < n; ++i) {
    if (h[i] == static_cast<float>(net.cap)) {
      ++at_cap;
      EXPECT_EQ(grad.col(i).cwiseAbs().maxCoeff(), 0.0f) << "state " << i;
    } else {
      ++below;
    }
  }
  EXPECT_GT(below, 10);

  Eigen::VectorXf h_torch;
  const Eigen::MatrixXf grad_torch = Autograd(*MakeDifferentiableBarrier(net), states, &h_torch);
  for (int i = 0; i < n; ++i)
    for (int r = 0; r < dim; ++r)
      EXPECT_NEAR(grad(r, i), grad_torch(r, i), 1e-5 + 1e-4 * std::abs(grad_torch(r, i)))
          << "row " << r << ", state " << i;

  // Central differences where the active entry stays the same within the step: every other
  // in-range car's h_j and the cap at least 1e-2 above, and no car within 1e-2 of the sensing
  // radius.
  const float step = 1e-3f;
  const Eigen::MatrixXf entries = net.EntryValues(states);
  int checked = 0;
  for (int i = 0; i < n; ++i) {
    std::vector<float> v(entries.col(i).data(), entries.col(i).data() + entries.rows());
    v.push_back(static_cast<float>(net.cap));
    std::sort(v.begin(), v.end());
    if (v[1] - v[0] < 1e-2f) continue;
    bool near_radius = false;
    for (int j = 0; j < net.input.layout.num_obstacles; ++j) {
      const int p = net.input.layout.PositionIndex(j);
      const float d = std::hypot(states(p, i), states(p + 1, i));
      near_radius = near_radius || std::abs(d - static_cast<float>(net.input.sensing_radius)) < 2e-2f;
    }
    if (near_radius) continue;
    for (int r = 0; r < dim; ++r) {
      Eigen::MatrixXf pm(dim, 2);
      pm.col(0) = states.col(i);
      pm.col(1) = states.col(i);
      pm(r, 0) += step;
      pm(r, 1) -= step;
      Eigen::VectorXf hpm(2);
      evaluator->Evaluate(pm, hpm);
      const float fd = (hpm[0] - hpm[1]) / (pm(r, 0) - pm(r, 1));
      if (act == nn::Activation::kRelu) {
        // A ReLU kink within the step: skip (the one-sided differences disagree).
        Eigen::VectorXf hc(1);
        evaluator->Evaluate(states.col(i), hc);
        if (std::abs((hpm[0] - hc[0]) - (hc[0] - hpm[1])) > 1e-5f) continue;
      }
      EXPECT_NEAR(grad(r, i), fd, 2e-3 + 1e-2 * std::abs(fd)) << "row " << r << ", state " << i;
    }
    ++checked;
  }
  EXPECT_GT(checked, 10);
}

INSTANTIATE_TEST_SUITE_P(PositionsAndVelocities, CarGradientTest,
                         ::testing::Combine(::testing::Bool(),
                                            ::testing::Values(nn::Activation::kTanh,
                                                              nn::Activation::kRelu)));

// Any other barrier: central differences of Evaluate, against the known gradient.
class Quadratic final : public Barrier {
 public:
  int state_dim() const override { return 3; }
  std::string Describe() const override { return "quadratic"; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    for (Eigen::Index i = 0; i < states.cols(); ++i) {
      const auto s = states.col(i);
      h[i] = 4.0f - s[0] * s[0] - 2.0f * s[1] * s[1] + 0.5f * s[0] * s[2];
    }
  }
};

TEST(BarrierGradientTest, AnyOtherBarrierGetsCentralDifferences) {
  Quadratic q;
  EXPECT_FALSE(q.analytic_gradient());
  const Eigen::MatrixXf states = UniformStates(3, 20, -3, 3, 2);
  Eigen::VectorXf h(20), h_plain(20);
  Eigen::MatrixXf grad(3, 20);
  q.EvaluateGradient(states, h, grad);
  q.Evaluate(states, h_plain);
  EXPECT_EQ(h, h_plain);
  for (int i = 0; i < 20; ++i) {
    const auto s = states.col(i);
    const Eigen::Vector3f exact(-2 * s[0] + 0.5f * s[2], -4 * s[1], 0.5f * s[0]);
    for (int r = 0; r < 3; ++r)
      EXPECT_NEAR(grad(r, i), exact[r], 1e-3 + 1e-3 * std::abs(exact[r])) << r << ", " << i;
  }
}

}  // namespace
}  // namespace secure::cbf
