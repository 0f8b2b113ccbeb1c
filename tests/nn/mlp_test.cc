#include "secure/nn/mlp.h"
#include "tests/nn/nn_test_util.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "secure/common/error.h"

namespace secure::nn {
namespace {

using secure::test::ErrorOf;
using test::kPandaHidden;
using test::Spec;

// ---------------------------------------------------------------------------------------------
// MlpSpec

TEST(MlpSpecTest, ValidSpecsPass) {
  EXPECT_NO_THROW(Spec(4, {64, 64, 64}).Validate());
  EXPECT_NO_THROW(Spec(3, {}, 2).Validate());  // no hidden layer: a linear model
  EXPECT_NO_THROW(Spec(9, kPandaHidden, 1, Activation::kRelu).Validate());
}

TEST(MlpSpecTest, DefaultSpecIsInvalidBecauseInputDimIsZero) {
  EXPECT_HAS(ErrorOf([] { MlpSpec{}.Validate(); }), "MlpSpec::input_dim = 0");
}

TEST(MlpSpecTest, ValidateNamesTheBadField) {
  EXPECT_HAS(ErrorOf([] { Spec(-3, {8}).Validate(); }), "MlpSpec::input_dim = -3");
  EXPECT_HAS(ErrorOf([] { Spec(4, {8}, 0).Validate(); }), "MlpSpec::output_dim = 0");
  EXPECT_HAS(ErrorOf([] { Spec(4, {8, 0, 8}).Validate(); }), "MlpSpec::hidden[1] = 0");
  EXPECT_HAS(ErrorOf([] { Spec(4, {8, 8, -2}).Validate(); }), "MlpSpec::hidden[2] = -2");
  EXPECT_HAS(ErrorOf([] { Spec(4, {0}).Validate(); }), "must be > 0");
}

TEST(MlpSpecTest, WidthsListInputHiddenAndOutput) {
  EXPECT_EQ(Spec(4, {64, 64, 64}).Widths(), (std::vector<int>{4, 64, 64, 64, 1}));
  EXPECT_EQ(Spec(3, {}, 2).Widths(), (std::vector<int>{3, 2}));
  EXPECT_EQ(Spec(9, kPandaHidden).Widths(),
            (std::vector<int>{9, 32, 128, 128, 256, 256, 256, 256, 128, 128, 32, 1}));
}

TEST(MlpSpecTest, MultiplyAddsPerSampleSumsInTimesOutOverLayers) {
  // 4*64 + 64*64 + 64*64 + 64*1
  EXPECT_EQ(Spec(4, {64, 64, 64}).MultiplyAddsPerSample(), 8512);
  EXPECT_EQ(Spec(3, {}, 2).MultiplyAddsPerSample(), 6);
  // 4*64 + 64*128 + 128*64 + 64*1
  EXPECT_EQ(Spec(4, {64, 128, 64}).MultiplyAddsPerSample(), 16704);
  // 9*32 + 32*128 + 128*128 + 128*256 + 3*256*256 + 256*128 + 128*128 + 128*32 + 32*1
  EXPECT_EQ(Spec(9, kPandaHidden).MultiplyAddsPerSample(), 303424);
  // Asymmetric widths catch in/out mix-ups: 2*3 + 3*5 + 5*7.
  EXPECT_EQ(Spec(2, {3, 5}, 7).MultiplyAddsPerSample(), 56);
}

TEST(MlpSpecTest, EqualityComparesEveryField) {
  const MlpSpec base = Spec(4, {8, 8}, 1, Activation::kTanh);
  EXPECT_TRUE(base == Spec(4, {8, 8}, 1, Activation::kTanh));
  EXPECT_FALSE(base == Spec(5, {8, 8}, 1, Activation::kTanh));
  EXPECT_FALSE(base == Spec(4, {8, 9}, 1, Activation::kTanh));
  EXPECT_FALSE(base == Spec(4, {8}, 1, Activation::kTanh));
  EXPECT_FALSE(base == Spec(4, {8, 8}, 2, Activation::kTanh));
  EXPECT_FALSE(base == Spec(4, {8, 8}, 1, Activation::kRelu));
}

// ---------------------------------------------------------------------------------------------
// MlpParams

TEST(MlpParamsTest, RandomParamsAreValid) {
  EXPECT_NO_THROW(RandomMlpParams(Spec(4, {64, 64, 64}), 1).Validate());
  EXPECT_NO_THROW(RandomMlpParams(Spec(3, {}, 2), 1).Validate());
}

TEST(MlpParamsTest, ValidateCatchesAMissingLayer) {
  MlpParams p = RandomMlpParams(Spec(4, {8, 8}), 1);
  p.layers.pop_back();
  const std::string message = ErrorOf([&] { p.Validate("net.bin"); });
  EXPECT_HAS(message, "net.bin");
  EXPECT_HAS(message, "has 2 layers");
  EXPECT_HAS(message, "needs 3");
}

TEST(MlpParamsTest, ValidateCatchesAnExtraLayer) {
  MlpParams p = RandomMlpParams(Spec(4, {8}), 1);
  p.layers.push_back(p.layers.back());
  EXPECT_HAS(ErrorOf([&] { p.Validate(); }), "has 3 layers");
}

TEST(MlpParamsTest, ValidateCatchesAWrongWeightShape) {
  MlpParams p = RandomMlpParams(Spec(4, {8, 6}), 1);
  p.layers[1].weight = Eigen::MatrixXf::Zero(6, 7);  // expected 6 x 8
  const std::string message = ErrorOf([&] { p.Validate("model.json"); });
  EXPECT_HAS(message, "model.json");
  EXPECT_HAS(message, "layer 1 weight is 6 x 7, expected 6 x 8");
}

TEST(MlpParamsTest, ValidateCatchesATransposedWeight) {
  MlpParams p = RandomMlpParams(Spec(4, {8}), 1);
  p.layers[0].weight.transposeInPlace();  // 4 x 8 instead of 8 x 4
  EXPECT_HAS(ErrorOf([&] { p.Validate(); }), "layer 0 weight is 4 x 8, expected 8 x 4");
}

TEST(MlpParamsTest, ValidateCatchesAWrongBiasSize) {
  MlpParams p = RandomMlpParams(Spec(4, {8, 6}), 1);
  p.layers[2].bias = Eigen::VectorXf::Zero(2);
  EXPECT_HAS(ErrorOf([&] { p.Validate(); }), "layer 2 bias has 2 values, expected 1");
}

TEST(MlpParamsTest, ValidateCatchesNonFiniteWeightsAndBiases) {
  const MlpParams good = RandomMlpParams(Spec(4, {8, 6}), 1);
  {
    MlpParams p = good;
    p.layers[1].weight(3, 2) = std::numeric_limits<float>::quiet_NaN();
    EXPECT_HAS(ErrorOf([&] { p.Validate(); }), "layer 1 has a non-finite");
  }
  {
    MlpParams p = good;
    p.layers[2].weight(0, 5) = std::numeric_limits<float>::infinity();
    EXPECT_HAS(ErrorOf([&] { p.Validate(); }), "layer 2 has a non-finite");
  }
  {
    MlpParams p = good;
    p.layers[0].bias[7] = -std::numeric_limits<float>::infinity();
    EXPECT_HAS(ErrorOf([&] { p.Validate(); }), "layer 0 has a non-finite");
  }
}

TEST(MlpParamsTest, ValidateChecksTheSpecToo) {
  MlpParams p = RandomMlpParams(Spec(4, {8}), 1);
  p.spec.hidden[0] = 0;
  EXPECT_HAS(ErrorOf([&] { p.Validate(); }), "MlpSpec::hidden[0] = 0");
}

TEST(RandomMlpParamsTest, IsDeterministicPerSeed) {
  const MlpSpec spec = Spec(5, {16, 7}, 2);
  const MlpParams a = RandomMlpParams(spec, 42);
  const MlpParams b = RandomMlpParams(spec, 42);
  const MlpParams c = RandomMlpParams(spec, 43);
  EXPECT_TRUE(a.spec == spec);
  ASSERT_EQ(a.layers.size(), 3u);
  for (std::size_t l = 0; l < a.layers.size(); ++l) {
    EXPECT_EQ(a.layers[l].weight, b.layers[l].weight) << "layer " << l;
    EXPECT_EQ(a.layers[l].bias, b.layers[l].bias) << "layer " << l;
    EXPECT_NE(a.layers[l].weight, c.layers[l].weight) << "layer " << l;
  }
}

TEST(RandomMlpParamsTest, UsesGlorotUniformWeightsAndSmallBiases) {
  const MlpSpec spec = Spec(9, {32, 128}, 1);
  const MlpParams p = RandomMlpParams(spec, 3);
  const auto widths = spec.Widths();
  for (std::size_t l = 0; l < p.layers.size(); ++l) {
    const float limit = static_cast<float>(std::sqrt(6.0 / (widths[l] + widths[l + 1])));
    const auto& w = p.layers[l].weight;
    EXPECT_LE(w.cwiseAbs().maxCoeff(), limit) << "layer " << l;
    EXPECT_LE(p.layers[l].bias.cwiseAbs().maxCoeff(), 0.1f) << "layer " << l;
    if (w.size() >= 100) {
      // The weights fill the range (not, say, all zero or all positive).
      EXPECT_GT(w.maxCoeff(), 0.8f * limit) << "layer " << l;
      EXPECT_LT(w.minCoeff(), -0.8f * limit) << "layer " << l;
      EXPECT_NEAR(w.mean(), 0.0f, 0.1f * limit) << "layer " << l;
    }
  }
}

TEST(RandomMlpParamsTest, RejectsAnInvalidSpec) {
  EXPECT_HAS(ErrorOf([] { RandomMlpParams(Spec(4, {8, 0}), 1); }), "MlpSpec::hidden[1] = 0");
}

// ---------------------------------------------------------------------------------------------
// Normalizer

TEST(NormalizerTest, FitGivesMeanAndPopulationStd) {
  Eigen::MatrixXf x(3, 4);
  x << 1, 2, 3, 4,   // mean 2.5, population var 1.25 (sample var would be 5/3)
      7, 7, 7, 7,    // constant: scale 1
      0, 0, 10, 10;  // mean 5, std 5
  const Normalizer n = Normalizer::Fit(x);
  ASSERT_EQ(n.dim(), 3);
  EXPECT_NEAR(n.mean[0], 2.5f, 1e-6f);
  EXPECT_NEAR(n.mean[1], 7.0f, 1e-6f);
  EXPECT_NEAR(n.mean[2], 5.0f, 1e-6f);
  EXPECT_NEAR(n.scale[0], std::sqrt(1.25f), 1e-6f);
  EXPECT_EQ(n.scale[1], 1.0f);
  EXPECT_NEAR(n.scale[2], 5.0f, 1e-6f);
  EXPECT_NO_THROW(n.Validate());
}

TEST(NormalizerTest, FitOfASingleSampleHasUnitScale) {
  Eigen::MatrixXf x(2, 1);
  x << 3, -4;
  const Normalizer n = Normalizer::Fit(x);
  EXPECT_EQ(n.mean, x.col(0));
  EXPECT_EQ(n.scale, Eigen::VectorXf::Ones(2));
}

TEST(NormalizerTest, FitIsAccurateForLargeOffsets) {
  // Values around 1e4 with a spread of 1: a naive float E[x^2] - E[x]^2 loses all digits.
  Eigen::MatrixXf x(1, 1000);
  for (int i = 0; i < 1000; ++i) x(0, i) = 10000.0f + static_cast<float>(i % 2 == 0 ? 1 : -1);
  const Normalizer n = Normalizer::Fit(x);
  EXPECT_NEAR(n.mean[0], 10000.0f, 1e-3f);
  EXPECT_NEAR(n.scale[0], 1.0f, 1e-5f);
}

TEST(NormalizerTest, FitOfNoSamplesThrows) {
  EXPECT_HAS(ErrorOf([] { Normalizer::Fit(Eigen::MatrixXf(3, 0)); }), "no samples");
}

TEST(NormalizerTest, ApplyStandardisesTheFittedData) {
  Eigen::MatrixXf x = Eigen::MatrixXf::Random(4, 500);
  x.row(0) = x.row(0) * 3.0f + Eigen::RowVectorXf::Constant(500, 10.0f);
  x.row(2).setConstant(-2.0f);
  const Normalizer n = Normalizer::Fit(x);
  const Eigen::MatrixXf y = n.Apply(x);
  ASSERT_EQ(y.rows(), 4);
  ASSERT_EQ(y.cols(), 500);
  for (int r : {0, 1, 3}) {
    const Eigen::ArrayXf row = y.row(r).transpose().array();
    EXPECT_NEAR(row.mean(), 0.0f, 1e-5f) << "row " << r;
    EXPECT_NEAR(std::sqrt((row - row.mean()).square().mean()), 1.0f, 1e-5f) << "row " << r;
  }
  EXPECT_EQ(y.row(2), Eigen::RowVectorXf::Zero(500));  // constant feature: shifted, not scaled
}

TEST(NormalizerTest, ApplyComputesXMinusMeanOverScale) {
  Normalizer n;
  n.mean = Eigen::Vector2f(1.0f, -2.0f);
  n.scale = Eigen::Vector2f(2.0f, 0.5f);
  Eigen::MatrixXf x(2, 2);
  x << 5, 1,  //
      0, -3;
  Eigen::MatrixXf expected(2, 2);
  expected << 2, 0,  //
      4, -2;
  EXPECT_EQ(n.Apply(x), expected);
}

TEST(NormalizerTest, ApplyRejectsTheWrongDimension) {
  const Normalizer n = Normalizer::Identity(3);
  EXPECT_HAS(ErrorOf([&] { n.Apply(Eigen::MatrixXf::Zero(4, 2)); }), "4 rows, expected 3");
}

TEST(NormalizerTest, IdentityIsZeroMeanUnitScale) {
  const Normalizer n = Normalizer::Identity(5);
  EXPECT_EQ(n.dim(), 5);
  EXPECT_EQ(n.mean, Eigen::VectorXf::Zero(5));
  EXPECT_EQ(n.scale, Eigen::VectorXf::Ones(5));
  const Eigen::MatrixXf x = Eigen::MatrixXf::Random(5, 3);
  EXPECT_EQ(n.Apply(x), x);
}

TEST(NormalizerTest, ValidateRejectsBadScalesAndMeans) {
  const Normalizer good = Normalizer::Identity(3);
  {
    Normalizer n = good;
    n.scale[1] = 0.0f;
    EXPECT_HAS(ErrorOf([&] { n.Validate("norm"); }), "norm: scale[1] = 0");
  }
  {
    Normalizer n = good;
    n.scale[2] = -1.0f;
    EXPECT_HAS(ErrorOf([&] { n.Validate(); }), "scale[2] = -1");
  }
  {
    Normalizer n = good;
    n.scale[0] = std::numeric_limits<float>::quiet_NaN();
    EXPECT_HAS(ErrorOf([&] { n.Validate(); }), "scale[0]");
  }
  {
    Normalizer n = good;
    n.scale[0] = std::numeric_limits<float>::infinity();
    EXPECT_HAS(ErrorOf([&] { n.Validate(); }), "scale[0]");
  }
  {
    Normalizer n = good;
    n.mean[2] = std::numeric_limits<float>::quiet_NaN();
    EXPECT_HAS(ErrorOf([&] { n.Validate(); }), "mean has a non-finite");
  }
  {
    Normalizer n = good;
    n.scale = Eigen::VectorXf::Ones(2);
    EXPECT_HAS(ErrorOf([&] { n.Validate(); }), "mean has 3 values but scale has 2");
  }
}

// ---------------------------------------------------------------------------------------------
// ReferenceForward (the oracle of the inference and LibTorch tests, so it is pinned by hand)

MlpParams HandNet(Activation activation) {
  // 2 -> 2 -> 1:  z = W1 x + b1,  y = w2 . act(z) + b2.
  MlpParams p{Spec(2, {2}, 1, activation), {}};
  DenseLayer l1{Eigen::MatrixXf(2, 2), Eigen::VectorXf(2)};
  l1.weight << 1, 2,  //
      -1, 0.5;
  l1.bias << 0.5, -1;
  DenseLayer l2{Eigen::MatrixXf(1, 2), Eigen::VectorXf(1)};
  l2.weight << 2, -3;
  l2.bias << 0.25;
  p.layers = {l1, l2};
  return p;
}

TEST(ReferenceForwardTest, MatchesAHandComputedReluNet) {
  const MlpParams p = HandNet(Activation::kRelu);
  Eigen::MatrixXf x(2, 2);
  x << 1, -2,  //
      1, 0;
  // Column 0: z = (1 + 2 + 0.5, -1 + 0.5 - 1) = (3.5, -1.5) -> relu (3.5, 0) -> 7 + 0.25.
  // Column 1: z = (-2 + 0.5, 2 - 1) = (-1.5, 1) -> relu (0, 1) -> -3 + 0.25.
  const Eigen::MatrixXd y = ReferenceForward(p, Normalizer::Identity(2), x);
  ASSERT_EQ(y.rows(), 1);
  ASSERT_EQ(y.cols(), 2);
  EXPECT_DOUBLE_EQ(y(0, 0), 7.25);
  EXPECT_DOUBLE_EQ(y(0, 1), -2.75);
}

TEST(ReferenceForwardTest, MatchesAHandComputedTanhNet) {
  const MlpParams p = HandNet(Activation::kTanh);
  Eigen::MatrixXf x(2, 1);
  x << 1, 1;
  const double expected = 2.0 * std::tanh(3.5) - 3.0 * std::tanh(-1.5) + 0.25;
  EXPECT_NEAR(ReferenceForward(p, Normalizer::Identity(2), x)(0, 0), expected, 1e-12);
}

TEST(ReferenceForwardTest, AppliesTheNormalizerFirst) {
  const MlpParams p = HandNet(Activation::kRelu);
  Normalizer n;
  n.mean = Eigen::Vector2f(1.0f, -1.0f);
  n.scale = Eigen::Vector2f(2.0f, 4.0f);
  Eigen::MatrixXf x(2, 1);
  x << 3, 3;  // normalised: (1, 1), the first column of the relu test
  EXPECT_DOUBLE_EQ(ReferenceForward(p, n, x)(0, 0), 7.25);
}

TEST(ReferenceForwardTest, OutputLayerIsLinear) {
  // A net without hidden layers is affine: negative outputs survive even with relu.
  MlpParams p{Spec(1, {}, 1, Activation::kRelu), {}};
  p.layers.push_back({Eigen::MatrixXf::Constant(1, 1, -2.0f), Eigen::VectorXf::Constant(1, 1.0f)});
  Eigen::MatrixXf x(1, 1);
  x << 3;
  EXPECT_DOUBLE_EQ(ReferenceForward(p, Normalizer::Identity(1), x)(0, 0), -5.0);
}

}  // namespace
}  // namespace secure::nn
