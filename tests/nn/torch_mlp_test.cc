#include "secure/nn/torch_mlp.h"
#include "tests/nn/nn_test_util.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <future>
#include <string>
#include <thread>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"
#include "secure/nn/torch_threads.h"

namespace secure::nn {
namespace {

using secure::test::ErrorOf;
using test::Architectures;
using test::Case;
using test::RandomInputs;
using test::Spec;

bool ParamsBitEqual(const MlpParams& a, const MlpParams& b) {
  if (!(a.spec == b.spec) || a.layers.size() != b.layers.size()) return false;
  for (std::size_t l = 0; l < a.layers.size(); ++l) {
    if (a.layers[l].weight.rows() != b.layers[l].weight.rows() ||
        a.layers[l].weight.cols() != b.layers[l].weight.cols() ||
        a.layers[l].bias.size() != b.layers[l].bias.size())
      return false;
    if (a.layers[l].weight != b.layers[l].weight || a.layers[l].bias != b.layers[l].bias)
      return false;
  }
  return true;
}

Eigen::MatrixXf EigenForward(const MlpParams& params, const Eigen::MatrixXf& x) {
  const InferenceMlp mlp(params, Normalizer::Identity(params.spec.input_dim));
  auto ws = mlp.MakeWorkspace(static_cast<int>(x.cols()));
  Eigen::MatrixXf y(params.spec.output_dim, x.cols());
  mlp.Forward(x, ws, y);
  return y;
}

Eigen::MatrixXf TorchForward(TorchMlp& model, const Eigen::MatrixXf& x) {
  torch::NoGradGuard no_grad;
  return ToEigen(model->forward(ToTensor(x)));
}

// The requirement: the Eigen evaluator is numerically equal to the LibTorch forward,
// max abs diff <= 1e-5 on random inputs.
TEST(TorchMlpTest, EigenInferenceEqualsTorchForward) {
  std::uint64_t seed = 1;
  for (const Case& c : Architectures()) {
    SCOPED_TRACE(c.name);
    TorchMlp model(c.spec, seed);
    const MlpParams params = model->ToParams();
    ASSERT_NO_THROW(params.Validate());
    for (int n : {1, 33, 257}) {
      const Eigen::MatrixXf x = RandomInputs(c.spec.input_dim, n, seed++);
      const Eigen::MatrixXf torch_y = TorchForward(model, x);
      const Eigen::MatrixXf eigen_y = EigenForward(params, x);
      ASSERT_EQ(torch_y.rows(), c.spec.output_dim);
      ASSERT_EQ(torch_y.cols(), n);
      EXPECT_LE((torch_y - eigen_y).cwiseAbs().maxCoeff(), 1e-5f) << "batch " << n;
      // And both agree with the double-precision reference.
      const Eigen::MatrixXd ref =
          ReferenceForward(params, Normalizer::Identity(c.spec.input_dim), x);
      EXPECT_LE((torch_y.cast<double>() - ref).cwiseAbs().maxCoeff(), 1e-5) << "batch " << n;
    }
  }
}

TEST(TorchMlpTest, EigenInferenceEqualsTorchForwardForLargeWeightsAndInputs) {
  // Glorot weights and inputs far from the origin: outputs of order 10-100, where a wrong
  // weight layout or activation could hide behind small values.
  std::uint64_t seed = 500;
  for (Activation a : {Activation::kRelu, Activation::kTanh}) {
    const MlpSpec spec = Spec(4, {64, 128, 64}, 1, a);
    const MlpParams params = RandomMlpParams(spec, seed++);
    TorchMlp model(spec);
    model->LoadParams(params);
    const Eigen::MatrixXf x = RandomInputs(4, 129, seed++, 0.0, 10.0);
    const Eigen::MatrixXf torch_y = TorchForward(model, x);
    const Eigen::MatrixXf eigen_y = EigenForward(params, x);
    const Eigen::MatrixXd ref = ReferenceForward(params, Normalizer::Identity(4), x);
    for (int c = 0; c < x.cols(); ++c) {
      const double tol = 1e-5 * std::max(1.0, std::abs(ref(0, c)));
      EXPECT_NEAR(torch_y(0, c), ref(0, c), tol) << c;
      EXPECT_NEAR(eigen_y(0, c), ref(0, c), tol) << c;
    }
  }
}

TEST(TorchMlpTest, TheSeedMakesInitialisationDeterministic) {
  const MlpSpec spec = Spec(4, {64, 64, 64}, 1, Activation::kTanh);
  torch::manual_seed(1);
  TorchMlp a(spec, 123);
  torch::manual_seed(2);  // the global generator plays no part
  TorchMlp b(spec, 123);
  TorchMlp c(spec, 124);
  EXPECT_TRUE(ParamsBitEqual(a->ToParams(), b->ToParams()));
  EXPECT_FALSE(ParamsBitEqual(a->ToParams(), c->ToParams()));
}

// The seeded initialisation reproduces what the trainers used to do — torch::manual_seed(seed),
// then torch::nn::Linear layers — bit for bit, so model files trained before keep their bytes.
TEST(TorchMlpTest, SeededInitialisationEqualsLinearAfterManualSeed) {
  std::vector<Case> cases = Architectures();
  cases.push_back({"one_hidden", Spec(52, {1}, 1, Activation::kRelu)});
  cases.push_back({"wide_input", Spec(300, {7, 5}, 3, Activation::kTanh)});
  for (const Case& c : cases) {
    for (std::uint64_t seed : {0ull, 1ull, 20261129ull, 0xffffffffffffffffull}) {
      SCOPED_TRACE(c.name + " seed " + std::to_string(seed));
      torch::manual_seed(seed);
      MlpParams legacy{c.spec, {}};
      const auto widths = c.spec.Widths();
      for (std::size_t i = 0; i + 1 < widths.size(); ++i) {
        torch::nn::Linear linear(widths[i], widths[i + 1]);
        DenseLayer layer;
        layer.weight = ToEigen(linear->weight.t());  // (out x in)
        layer.bias = ToEigen(linear->bias.unsqueeze(0)).col(0);
        legacy.layers.push_back(std::move(layer));
      }
      EXPECT_TRUE(ParamsBitEqual(TorchMlp(c.spec, seed)->ToParams(), legacy));
    }
  }
}

TEST(TorchMlpTest, ConstructionLeavesTheGlobalGeneratorAlone) {
  torch::manual_seed(42);
  const torch::Tensor expected = torch::rand({16});
  torch::manual_seed(42);
  TorchMlp a(Spec(4, {64, 64}, 1, Activation::kTanh), 7);
  TorchMlp b(Spec(4, {64, 64}, 1, Activation::kTanh));
  TorchMlp c(a->ToParams());
  EXPECT_TRUE(torch::equal(torch::rand({16}), expected));
}

TEST(TorchMlpTest, TheParamsConstructorCopiesTheWeights) {
  const MlpParams params = RandomMlpParams(Spec(3, {6, 5}, 2, Activation::kRelu), 12);
  TorchMlp model(params);
  EXPECT_TRUE(model->spec() == params.spec);
  EXPECT_TRUE(ParamsBitEqual(model->ToParams(), params));
  MlpParams bad = params;
  bad.layers[1].weight(0, 0) = std::nanf("");
  EXPECT_HAS(ErrorOf([&] { TorchMlp invalid(bad); }), "non-finite");
}

TEST(TorchMlpTest, ToParamsHasTheSpecsShapesAndTorchsValues) {
  const MlpSpec spec = Spec(3, {5, 7}, 2, Activation::kRelu);
  TorchMlp model(spec, 9);
  EXPECT_TRUE(model->spec() == spec);
  const MlpParams p = model->ToParams();
  EXPECT_TRUE(p.spec == spec);
  ASSERT_EQ(p.layers.size(), 3u);
  const auto widths = spec.Widths();
  // Registered parameters in order: layer0.weight, layer0.bias, layer1.weight, ...
  const auto named = model->named_parameters();
  for (std::size_t l = 0; l < 3; ++l) {
    ASSERT_EQ(p.layers[l].weight.rows(), widths[l + 1]);
    ASSERT_EQ(p.layers[l].weight.cols(), widths[l]);
    ASSERT_EQ(p.layers[l].bias.size(), widths[l + 1]);
    const torch::Tensor w = named["layer" + std::to_string(l) + ".weight"];
    const torch::Tensor b = named["layer" + std::to_string(l) + ".bias"];
    for (int r = 0; r < widths[l + 1]; ++r) {
      EXPECT_EQ(p.layers[l].bias[r], b[r].item<float>());
      for (int c = 0; c < widths[l]; ++c)
        EXPECT_EQ(p.layers[l].weight(r, c), w[r][c].item<float>()) << l << " " << r << " " << c;
    }
  }
}

TEST(TorchMlpTest, LoadParamsThenToParamsRoundTripsExactly) {
  for (const Case& c : Architectures()) {
    SCOPED_TRACE(c.name);
    const MlpParams params = RandomMlpParams(c.spec, 77);
    TorchMlp model(c.spec);
    model->LoadParams(params);
    EXPECT_TRUE(ParamsBitEqual(model->ToParams(), params));
  }
}

TEST(TorchMlpTest, ToParamsThenLoadParamsIntoAFreshModelGivesTheSameForward) {
  const MlpSpec spec = Spec(4, {64, 64, 64}, 1, Activation::kRelu);
  TorchMlp a(spec, 5);
  TorchMlp b(spec, 6);
  const MlpParams pa = a->ToParams();
  b->LoadParams(pa);
  EXPECT_TRUE(ParamsBitEqual(b->ToParams(), pa));
  const Eigen::MatrixXf x = RandomInputs(4, 50, 8);
  EXPECT_EQ(TorchForward(a, x), TorchForward(b, x));
}

TEST(TorchMlpTest, LoadParamsDoesNotAliasTheSource) {
  const MlpSpec spec = Spec(2, {3}, 1, Activation::kTanh);
  MlpParams params = RandomMlpParams(spec, 1);
  TorchMlp model(spec);
  model->LoadParams(params);
  const MlpParams loaded = model->ToParams();
  params.layers[0].weight.setZero();
  params.layers[0].bias.setZero();
  EXPECT_TRUE(ParamsBitEqual(model->ToParams(), loaded));
}

TEST(TorchMlpTest, LoadParamsWithADifferentArchitectureThrows) {
  TorchMlp model(Spec(4, {64, 64, 64}, 1, Activation::kTanh));
  EXPECT_HAS(ErrorOf([&] {
               model->LoadParams(RandomMlpParams(Spec(4, {64, 64}, 1, Activation::kTanh), 1));
             }),
             "architecture does not match");
  EXPECT_HAS(ErrorOf([&] {
               model->LoadParams(RandomMlpParams(Spec(4, {64, 32, 64}, 1, Activation::kTanh), 1));
             }),
             "architecture does not match");
  EXPECT_HAS(ErrorOf([&] {
               model->LoadParams(RandomMlpParams(Spec(5, {64, 64, 64}, 1, Activation::kTanh), 1));
             }),
             "architecture does not match");
  // Same shapes, different activation: still a different network.
  EXPECT_HAS(ErrorOf([&] {
               model->LoadParams(RandomMlpParams(Spec(4, {64, 64, 64}, 1, Activation::kRelu), 1));
             }),
             "architecture does not match");
}

TEST(TorchMlpTest, FailedLoadParamsLeavesTheWeightsUntouched) {
  const MlpSpec spec = Spec(4, {8, 8}, 1, Activation::kTanh);
  TorchMlp model(spec, 3);
  const MlpParams before = model->ToParams();
  MlpParams bad = RandomMlpParams(spec, 2);
  bad.layers[2].bias[0] = std::nanf("");  // validated before any copy
  EXPECT_HAS(ErrorOf([&] { model->LoadParams(bad); }), "non-finite");
  EXPECT_TRUE(ParamsBitEqual(model->ToParams(), before));
}

TEST(TorchMlpTest, ConstructorRejectsAnInvalidSpec) {
  EXPECT_HAS(ErrorOf([] {
               TorchMlp model(Spec(4, {8, 0}, 1, Activation::kTanh));
             }),
             "MlpSpec::hidden[1] = 0");
}

TEST(TorchMlpTest, ForwardMapsNByInputToNByOutput) {
  TorchMlp model(Spec(5, {8}, 3, Activation::kRelu));
  const torch::Tensor y = model->forward(torch::randn({11, 5}));
  ASSERT_EQ(y.dim(), 2);
  EXPECT_EQ(y.size(0), 11);
  EXPECT_EQ(y.size(1), 3);
}

TEST(TorchMlpTest, ForwardIsDifferentiable) {
  // Training needs gradients through the module: every parameter receives one.
  torch::manual_seed(1);  // the inputs
  TorchMlp model(Spec(4, {16, 16}, 1, Activation::kTanh), 1);
  const torch::Tensor loss = model->forward(torch::randn({32, 4})).pow(2).mean();
  loss.backward();
  const auto params = model->parameters();
  EXPECT_EQ(params.size(), 6u);
  for (const auto& p : params) {
    ASSERT_TRUE(p.grad().defined());
    EXPECT_GT(p.grad().abs().sum().item<float>(), 0.0f);
  }
}

// ---------------------------------------------------------------------------------------------
// ToTensor / ToEigen

TEST(TorchConversionTest, ToTensorIsNByDimWithRowIEqualToColumnI) {
  Eigen::MatrixXf x(3, 4);
  x << 1, 2, 3, 4,  //
      5, 6, 7, 8,   //
      9, 10, 11, 12;
  const torch::Tensor t = ToTensor(x);
  ASSERT_EQ(t.dim(), 2);
  EXPECT_EQ(t.size(0), 4);
  EXPECT_EQ(t.size(1), 3);
  EXPECT_EQ(t.scalar_type(), torch::kFloat32);
  for (int i = 0; i < 4; ++i)
    for (int d = 0; d < 3; ++d) EXPECT_EQ(t[i][d].item<float>(), x(d, i)) << i << " " << d;
}

TEST(TorchConversionTest, ToEigenInvertsToTensor) {
  const Eigen::MatrixXf x = RandomInputs(7, 13, 4);
  EXPECT_EQ(ToEigen(ToTensor(x)), x);
  const torch::Tensor t = torch::randn({6, 9});
  EXPECT_TRUE(torch::equal(ToTensor(ToEigen(t)), t));
  const Eigen::MatrixXf e = ToEigen(t);
  ASSERT_EQ(e.rows(), 9);
  ASSERT_EQ(e.cols(), 6);
  for (int i = 0; i < 6; ++i)
    for (int d = 0; d < 9; ++d) EXPECT_EQ(e(d, i), t[i][d].item<float>());
}

TEST(TorchConversionTest, ToTensorOfABlockCopiesOnlyTheBlock) {
  const Eigen::MatrixXf x = RandomInputs(5, 8, 6);
  const Eigen::MatrixXf block = x.block(1, 2, 3, 4);
  // A block has an outer stride of 5: the conversion must not read the skipped rows.
  const torch::Tensor t = ToTensor(x.block(1, 2, 3, 4));
  ASSERT_EQ(t.size(0), 4);
  ASSERT_EQ(t.size(1), 3);
  EXPECT_EQ(ToEigen(t), block);
}

TEST(TorchConversionTest, ConversionsCopy) {
  Eigen::MatrixXf x = Eigen::MatrixXf::Ones(2, 3);
  const torch::Tensor t = ToTensor(x);
  x.setZero();
  EXPECT_EQ(t.sum().item<float>(), 6.0f);
  torch::Tensor u = torch::ones({3, 2});
  const Eigen::MatrixXf e = ToEigen(u);
  u.zero_();
  EXPECT_EQ(e.sum(), 6.0f);
}

TEST(TorchConversionTest, ToEigenHandlesNonContiguousAndDoubleTensors) {
  const torch::Tensor base = torch::randn({4, 6});
  const torch::Tensor transposed = base.t();  // (6 x 4), not contiguous
  ASSERT_FALSE(transposed.is_contiguous());
  const Eigen::MatrixXf e = ToEigen(transposed);
  ASSERT_EQ(e.rows(), 4);
  ASSERT_EQ(e.cols(), 6);
  for (int i = 0; i < 6; ++i)
    for (int d = 0; d < 4; ++d) EXPECT_EQ(e(d, i), base[d][i].item<float>());
  const torch::Tensor dbl = torch::arange(6, torch::kFloat64).reshape({2, 3});
  Eigen::MatrixXf expected(3, 2);
  expected << 0, 3,  //
      1, 4,          //
      2, 5;
  EXPECT_EQ(ToEigen(dbl), expected);
}

TEST(TorchConversionTest, ToEigenAcceptsATensorThatRequiresGrad) {
  torch::manual_seed(2);  // the inputs
  TorchMlp model(Spec(2, {4}, 1, Activation::kTanh), 2);
  const torch::Tensor y = model->forward(torch::randn({3, 2}));  // requires grad
  ASSERT_TRUE(y.requires_grad());
  const Eigen::MatrixXf e = ToEigen(y);
  EXPECT_EQ(e.rows(), 1);
  EXPECT_EQ(e.cols(), 3);
}

TEST(TorchConversionTest, ToEigenRejectsNon2DTensors) {
  EXPECT_HAS(ErrorOf([] { ToEigen(torch::zeros({5})); }), "tensor has 1 dims, expected 2");
  EXPECT_HAS(ErrorOf([] { ToEigen(torch::zeros({2, 3, 4})); }), "tensor has 3 dims, expected 2");
}

}  // namespace
}  // namespace secure::nn

// ScopedTorchThreads sets both pools for its scope and puts both previous counts back.
TEST(ScopedTorchThreadsTest, SetsAndRestoresLibTorchsAndOpenBlassCounts) {
  ASSERT_GT(secure::nn::BlasThreads(), 0) << "this build's BLAS is not OpenBLAS (scripts/setup.sh)";
  secure::nn::SetTorchThreads(2);
  {
    const secure::nn::ScopedTorchThreads scoped(1);
    EXPECT_EQ(secure::nn::TorchThreads(), 1);
    EXPECT_EQ(secure::nn::BlasThreads(), 1);
  }
  EXPECT_EQ(secure::nn::TorchThreads(), 2);
  EXPECT_EQ(secure::nn::BlasThreads(), 2);
  secure::nn::SetTorchThreads(1);
}

// Scopes on two threads share OpenBLAS's process-wide count: the first to leave does not put the
// count back under the one still running, the last one does, and another count asked while a
// scope holds one is an error.
TEST(ScopedTorchThreadsTest, ConcurrentScopesHoldOpenBlassCountUntilTheLastLeaves) {
  ASSERT_GT(secure::nn::BlasThreads(), 0) << "this build's BLAS is not OpenBLAS (scripts/setup.sh)";
  secure::nn::SetTorchThreads(2);
  std::promise<void> entered, first_left;
  int blas_after_first_left = -1;
  std::thread other;
  {
    const secure::nn::ScopedTorchThreads first(1);
    other = std::thread([&] {
      const secure::nn::ScopedTorchThreads second(1);
      entered.set_value();
      first_left.get_future().wait();
      blas_after_first_left = secure::nn::BlasThreads();
    });
    entered.get_future().wait();
    EXPECT_THROW(secure::nn::ScopedTorchThreads(3), secure::Error);
    EXPECT_EQ(secure::nn::BlasThreads(), 1);
  }
  first_left.set_value();
  other.join();
  EXPECT_EQ(blas_after_first_left, 1);
  EXPECT_EQ(secure::nn::BlasThreads(), 2);
  EXPECT_EQ(secure::nn::TorchThreads(), 2);
  secure::nn::SetTorchThreads(1);
}
