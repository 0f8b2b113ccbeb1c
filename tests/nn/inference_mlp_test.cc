#include "secure/nn/inference_mlp.h"
#include "tests/nn/nn_test_util.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/nn/mlp.h"

namespace secure::nn {
namespace {

using secure::test::ErrorOf;
using test::Architectures;
using test::Case;
using test::kPandaHidden;
using test::RandomInputs;
using test::Spec;

// A non-trivial normaliser: per-feature means in [-5, 5] and scales in [10^-max_log10_scale,
// 10^max_log10_scale] (log-uniform).
Normalizer RandomNormalizer(int dim, std::uint64_t seed, double max_log10_scale) {
  Rng rng(seed);
  Normalizer n;
  n.mean.resize(dim);
  n.scale.resize(dim);
  for (int i = 0; i < dim; ++i) {
    n.mean[i] = static_cast<float>(rng.Uniform(-5.0, 5.0));
    n.scale[i] = static_cast<float>(std::pow(10.0, rng.Uniform(-max_log10_scale, max_log10_scale)));
  }
  return n;
}

// Scales from 0.05 to 20: |mean| / scale up to 100, a hard case for folding in float.
Normalizer SkewedNormalizer(int dim, std::uint64_t seed) {
  return RandomNormalizer(dim, seed, 1.3);
}
// Scales from 0.5 to 2 (the double integrator's fitted normaliser is mean (5, 5, 0, 0), scale
// (2.9, 2.9, 0.87, 0.87)).
Normalizer ModerateNormalizer(int dim, std::uint64_t seed) {
  return RandomNormalizer(dim, seed, 0.3);
}

// Max over entries of |got - ref| / max(1, |ref|).
double MaxScaledError(const Eigen::MatrixXf& got, const Eigen::MatrixXd& ref) {
  EXPECT_EQ(got.rows(), ref.rows());
  EXPECT_EQ(got.cols(), ref.cols());
  double worst = 0.0;
  for (Eigen::Index c = 0; c < ref.cols(); ++c)
    for (Eigen::Index r = 0; r < ref.rows(); ++r)
      worst = std::max(worst, std::abs(static_cast<double>(got(r, c)) - ref(r, c)) /
                                  std::max(1.0, std::abs(ref(r, c))));
  return worst;
}

Eigen::MatrixXf Forward(const InferenceMlp& mlp, const Eigen::MatrixXf& x, int max_batch) {
  auto ws = mlp.MakeWorkspace(max_batch);
  Eigen::MatrixXf y(mlp.output_dim(), x.cols());
  mlp.Forward(x, ws, y);
  return y;
}

TEST(InferenceMlpTest, MatchesReferenceForwardForAllArchitecturesAndBatchSizes) {
  std::uint64_t seed = 1;
  for (const Case& c : Architectures()) {
    SCOPED_TRACE(c.name);
    const MlpParams params = RandomMlpParams(c.spec, seed++);
    const Normalizer identity = Normalizer::Identity(c.spec.input_dim);
    const InferenceMlp mlp(params, identity);
    EXPECT_EQ(mlp.input_dim(), c.spec.input_dim);
    EXPECT_EQ(mlp.output_dim(), c.spec.output_dim);
    EXPECT_TRUE(mlp.spec() == c.spec);
    auto ws = mlp.MakeWorkspace(256);
    for (int n : {1, 7, 64, 129, 256}) {
      SCOPED_TRACE("batch " + std::to_string(n));
      const Eigen::MatrixXf x = RandomInputs(c.spec.input_dim, n, seed++);
      Eigen::MatrixXf y(c.spec.output_dim, n);
      mlp.Forward(x, ws, y);
      const Eigen::MatrixXd ref = ReferenceForward(params, identity, x);
      EXPECT_LE(MaxScaledError(y, ref), 1e-5);
    }
  }
}

// Both matrix-product backends against the double reference: shapes with a row remainder
// (widths not a multiple of the 64-row kernel block), every column tail (1..63 after 64-column
// blocks), and inputs that are a strided block of a larger matrix.
TEST(InferenceMlpTest, BothBackendsMatchTheReference) {
  std::uint64_t seed = 700;
  std::vector<Case> cases = Architectures();
  for (Activation a : {Activation::kRelu, Activation::kTanh})
    cases.push_back({"row_remainder_" + ToString(kActivationNames, a),
                     Spec(6, {100, 200, 70}, 2, a)});
  for (const Case& c : cases) {
    for (MatmulBackend backend : {MatmulBackend::kEigen, MatmulBackend::kAuto}) {
      SCOPED_TRACE(c.name + " " + ToString(kMatmulBackendNames, backend));
      const MlpParams params = RandomMlpParams(c.spec, seed++);
      const Normalizer norm = ModerateNormalizer(c.spec.input_dim, seed++);
      const InferenceMlp mlp(params, norm, backend);
      EXPECT_NE(mlp.backend(), MatmulBackend::kAuto);
      auto ws = mlp.MakeWorkspace(200);
      for (int n : {1, 2, 3, 31, 63, 64, 65, 127, 128, 200}) {
        SCOPED_TRACE("batch " + std::to_string(n));
        const Eigen::MatrixXf big = RandomInputs(c.spec.input_dim + 3, n + 2, seed++);
        const Eigen::MatrixXf x = big.block(1, 1, c.spec.input_dim, n);
        const Eigen::MatrixXd ref = ReferenceForward(params, norm, x);
        Eigen::MatrixXf y(c.spec.output_dim, n), y_strided(c.spec.output_dim, n);
        mlp.Forward(x, ws, y);
        EXPECT_LE(MaxScaledError(y, ref), 1e-5);
        mlp.Forward(big.block(1, 1, c.spec.input_dim, n), ws, y_strided);  // outer stride != rows
        EXPECT_EQ(y, y_strided);
      }
    }
  }
}

#if defined(__x86_64__)
TEST(InferenceMlpTest, DefaultBackendIsLibxsmmOnX86) {
  const MlpParams params = RandomMlpParams(Spec(4, {64, 64}, 1, Activation::kTanh), 3);
  // A forced run (tests/dispatch: SECURE_MATMUL_BACKEND) replaces the default.
  const MatmulBackend expected = InferenceMlp::ForcedBackend() == MatmulBackend::kEigen
                                     ? MatmulBackend::kEigen
                                     : MatmulBackend::kLibxsmm;
  EXPECT_EQ(InferenceMlp(params, Normalizer::Identity(4)).backend(), expected);
  EXPECT_EQ(InferenceMlp(params, Normalizer::Identity(4), MatmulBackend::kLibxsmm).backend(),
            MatmulBackend::kLibxsmm);
  EXPECT_EQ(InferenceMlp(params, Normalizer::Identity(4), MatmulBackend::kEigen).backend(),
            MatmulBackend::kEigen);
}
#endif

TEST(InferenceMlpTest, BackendsAgreeOnTheShieldShapes) {
  // The two backends sum in different orders, so they agree to float rounding, not bitwise.
  for (const MlpSpec& spec : {Spec(4, {64, 64}, 1, Activation::kTanh),
                              Spec(3, {64, 128, 64}, 1, Activation::kRelu),
                              Spec(9, kPandaHidden, 1, Activation::kTanh)}) {
    const MlpParams params = RandomMlpParams(spec, 11);
    const InferenceMlp fast(params, Normalizer::Identity(spec.input_dim));
    const InferenceMlp eigen(params, Normalizer::Identity(spec.input_dim), MatmulBackend::kEigen);
    const Eigen::MatrixXf x = RandomInputs(spec.input_dim, 780, 12);
    EXPECT_LE(MaxScaledError(Forward(fast, x, 780), Forward(eigen, x, 780).cast<double>()), 1e-5);
  }
}

TEST(InferenceMlpTest, ForwardRejectsAWorkspaceOfAnotherBackend) {
  const MlpParams params = RandomMlpParams(Spec(4, {8}, 1, Activation::kRelu), 1);
  const InferenceMlp eigen(params, Normalizer::Identity(4), MatmulBackend::kEigen);
  const InferenceMlp fast(params, Normalizer::Identity(4));
  if (fast.backend() != MatmulBackend::kLibxsmm) GTEST_SKIP() << "no LIBXSMM code for this CPU";
  auto ws = eigen.MakeWorkspace(4);
  Eigen::MatrixXf y(1, 4);
  EXPECT_HAS(ErrorOf([&] { fast.Forward(Eigen::MatrixXf::Zero(4, 4), ws, y); }),
             "workspace was made by a model with another backend");
}

TEST(InferenceMlpTest, BatchExactlyMaxBatchMatchesReference) {
  for (Activation a : {Activation::kRelu, Activation::kTanh}) {
    const MlpParams params = RandomMlpParams(Spec(4, {64, 64, 64}, 1, a), 5);
    const Normalizer identity = Normalizer::Identity(4);
    const InferenceMlp mlp(params, identity);
    for (int n : {1, 7, 64, 129}) {
      const Eigen::MatrixXf x = RandomInputs(4, n, 100 + n);
      EXPECT_LE(MaxScaledError(Forward(mlp, x, n), ReferenceForward(params, identity, x)), 1e-5)
          << "batch " << n;
    }
  }
}

TEST(InferenceMlpTest, FoldedNormalizerMatchesNormalizingTheInputs) {
  std::uint64_t seed = 300;
  for (const Case& c : Architectures()) {
    for (bool skewed : {false, true}) {
      SCOPED_TRACE(c.name + (skewed ? " skewed" : " moderate") + " normalizer");
      const int d = c.spec.input_dim;
      const MlpParams params = RandomMlpParams(c.spec, seed++);
      const Normalizer norm = skewed ? SkewedNormalizer(d, seed++) : ModerateNormalizer(d, seed++);
      const InferenceMlp folded(params, norm);
      const InferenceMlp plain(params, Normalizer::Identity(d));
      auto ws = folded.MakeWorkspace(129);
      for (int n : {1, 7, 64, 129}) {
        SCOPED_TRACE("batch " + std::to_string(n));
        // Inputs on the normaliser's scale: mean +- 2 scale.
        Eigen::MatrixXf x = RandomInputs(d, n, seed++, -2.0f, 2.0f);
        for (int r = 0; r < d; ++r)
          x.row(r) = x.row(r) * norm.scale[r] + Eigen::RowVectorXf::Constant(n, norm.mean[r]);
        Eigen::MatrixXf y(c.spec.output_dim, n);
        folded.Forward(x, ws, y);
        // Against the double reference with the normaliser...
        const Eigen::MatrixXd ref = ReferenceForward(params, norm, x);
        EXPECT_LE(MaxScaledError(y, ref), 1e-5);
        // ...and against normalising explicitly, then running an identity-normalised network.
        Eigen::MatrixXf y_plain(c.spec.output_dim, n);
        plain.Forward(norm.Apply(x), ws, y_plain);
        EXPECT_LE(MaxScaledError(y, y_plain.cast<double>()), 1e-5);
        // The normaliser matters: ignoring it gives a clearly different answer.
        if (n >= 7) {
          plain.Forward(x, ws, y_plain);
          EXPECT_GT(MaxScaledError(y_plain, ref), 1e-3);
        }
      }
    }
  }
}

TEST(InferenceMlpTest, FittedNormalizerIsFolded) {
  const MlpSpec spec = Spec(4, {64, 64, 64}, 1, Activation::kTanh);
  const MlpParams params = RandomMlpParams(spec, 9);
  Eigen::MatrixXf data = RandomInputs(4, 1000, 10, 0.0f, 10.0f);
  data.row(3).setConstant(0.5f);  // constant feature: scale 1
  const Normalizer norm = Normalizer::Fit(data);
  const InferenceMlp mlp(params, norm);
  const Eigen::MatrixXf x = data.leftCols(64);
  EXPECT_LE(MaxScaledError(Forward(mlp, x, 64), ReferenceForward(params, norm, x)), 1e-5);
}

TEST(InferenceMlpTest, ConstructionDoesNotAlterTheParams) {
  const MlpSpec spec = Spec(3, {8}, 1, Activation::kRelu);
  const MlpParams params = RandomMlpParams(spec, 4);
  const MlpParams copy = params;
  const InferenceMlp mlp(params, SkewedNormalizer(3, 1));
  EXPECT_EQ(params.layers[0].weight, copy.layers[0].weight);
  EXPECT_EQ(params.layers[0].bias, copy.layers[0].bias);
}

// Largest |value of a column evaluated alone, in pairs or in a sub-batch - value of the same
// column inside one batch of 129|, for inputs on the normaliser's scale (mean +- 2 scale).
double MaxBatchCompositionDiff(const MlpSpec& spec, std::uint64_t seed) {
  const int d = spec.input_dim;
  const MlpParams params = RandomMlpParams(spec, seed);
  const Normalizer norm = ModerateNormalizer(d, seed + 1);
  Eigen::MatrixXf x = RandomInputs(d, 129, seed + 2, -2.0f, 2.0f);
  for (int r = 0; r < d; ++r)
    x.row(r) = x.row(r) * norm.scale[r] + Eigen::RowVectorXf::Constant(129, norm.mean[r]);
  const InferenceMlp mlp(params, norm);
  const Eigen::MatrixXf batch = Forward(mlp, x, 129);
  auto ws = mlp.MakeWorkspace(129);
  double worst = 0.0;
  Eigen::MatrixXf one(1, 1), two(1, 2), middle(1, 50);
  for (int c = 0; c < 129; ++c) {
    mlp.Forward(x.col(c), ws, one);
    worst = std::max(worst, static_cast<double>(std::abs(one(0, 0) - batch(0, c))));
  }
  for (int c = 0; c + 1 < 129; c += 2) {
    mlp.Forward(x.middleCols(c, 2), ws, two);
    for (int k = 0; k < 2; ++k)
      worst = std::max(worst, static_cast<double>(std::abs(two(0, k) - batch(0, c + k))));
  }
  mlp.Forward(x.middleCols(40, 50), ws, middle);
  for (int c = 0; c < 50; ++c)
    worst = std::max(worst, static_cast<double>(std::abs(middle(0, c) - batch(0, 40 + c))));
  return worst;
}

TEST(InferenceMlpTest, ColumnAloneEqualsColumnInsideABatch) {
  for (Activation a : {Activation::kRelu, Activation::kTanh}) {
    SCOPED_TRACE(ToString(kActivationNames, a));
    for (std::uint64_t seed : {1, 4, 7}) {
      EXPECT_LE(MaxBatchCompositionDiff(Spec(4, {64, 64, 64}, 1, a), seed), 1e-6) << "DI net";
      EXPECT_LE(MaxBatchCompositionDiff(Spec(4, {64, 128, 64}, 1, a), seed), 1e-6) << "Derby";
      EXPECT_LE(MaxBatchCompositionDiff(Spec(5, {3, 40, 7}, 1, a), seed), 1e-6) << "narrow";
    }
  }
  for (std::uint64_t seed : {1, 4, 7})
    EXPECT_LE(MaxBatchCompositionDiff(Spec(9, kPandaHidden, 1, Activation::kRelu), seed), 1e-6)
        << "Panda relu";
}

TEST(InferenceMlpTest, DeepTanhNetIsBatchIndependentWithinFloatRounding) {
  // The 12-layer tanh Panda net: Eigen's kernel and per-column summation order depend on the
  // batch size and the column's position (GEMV for one column, GEMM micro-kernels for full and
  // tail blocks), so a column may differ in its last bits with the batch around it (measured up
  // to 1.2e-6 at |h| ~ 1 through 12 tanh layers) — but never by more than float rounding allows.
  for (std::uint64_t seed : {1, 4, 7})
    EXPECT_LE(MaxBatchCompositionDiff(Spec(9, kPandaHidden, 1, Activation::kTanh), seed), 1e-5);
}

TEST(InferenceMlpTest, WorkspaceIsReusableAcrossBatchSizes) {
  // A large batch followed by a small one: stale activations in the workspace must not leak in.
  const MlpSpec spec = Spec(4, {64, 128, 64}, 1, Activation::kRelu);
  const MlpParams params = RandomMlpParams(spec, 31);
  const Normalizer identity = Normalizer::Identity(4);
  const InferenceMlp mlp(params, identity);
  auto ws = mlp.MakeWorkspace(200);
  for (int n : {200, 3, 150, 1, 200}) {
    const Eigen::MatrixXf x = RandomInputs(4, n, 1000 + n);
    Eigen::MatrixXf y(1, n);
    mlp.Forward(x, ws, y);
    EXPECT_LE(MaxScaledError(y, ReferenceForward(params, identity, x)), 1e-5) << "batch " << n;
  }
}

TEST(InferenceMlpTest, OneModelServesSeveralWorkspaces) {
  const MlpParams params = RandomMlpParams(Spec(4, {16, 16}, 2, Activation::kTanh), 41);
  const InferenceMlp mlp(params, Normalizer::Identity(4));
  auto ws_a = mlp.MakeWorkspace(10);
  auto ws_b = mlp.MakeWorkspace(3);
  EXPECT_EQ(ws_a.max_batch(), 10);
  EXPECT_EQ(ws_b.max_batch(), 3);
  const Eigen::MatrixXf x = RandomInputs(4, 3, 42);
  Eigen::MatrixXf ya(2, 3), yb(2, 3);
  mlp.Forward(x, ws_a, ya);
  mlp.Forward(x, ws_b, yb);
  EXPECT_EQ(ya, yb);
}

TEST(InferenceMlpTest, OutputsMayBeABlockOfALargerMatrix) {
  const MlpParams params = RandomMlpParams(Spec(4, {16}, 2, Activation::kTanh), 51);
  const Normalizer identity = Normalizer::Identity(4);
  const InferenceMlp mlp(params, identity);
  const Eigen::MatrixXf x = RandomInputs(4, 5, 52);
  Eigen::MatrixXf big = Eigen::MatrixXf::Constant(4, 9, 123.0f);
  auto ws = mlp.MakeWorkspace(5);
  mlp.Forward(x, ws, big.block(1, 2, 2, 5));
  EXPECT_LE(MaxScaledError(big.block(1, 2, 2, 5), ReferenceForward(params, identity, x)), 1e-5);
  // Nothing outside the block is touched.
  EXPECT_EQ(big.row(0), Eigen::RowVectorXf::Constant(9, 123.0f));
  EXPECT_EQ(big.row(3), Eigen::RowVectorXf::Constant(9, 123.0f));
  EXPECT_EQ(big.block(1, 0, 2, 2), Eigen::MatrixXf::Constant(2, 2, 123.0f));
  EXPECT_EQ(big.block(1, 7, 2, 2), Eigen::MatrixXf::Constant(2, 2, 123.0f));
}

TEST(InferenceMlpTest, ForwardRejectsWrongInputRows) {
  const InferenceMlp mlp(RandomMlpParams(Spec(4, {8}, 1, Activation::kRelu), 1),
                         Normalizer::Identity(4));
  auto ws = mlp.MakeWorkspace(8);
  Eigen::MatrixXf y(1, 2);
  EXPECT_HAS(ErrorOf([&] { mlp.Forward(Eigen::MatrixXf::Zero(3, 2), ws, y); }),
             "inputs have 3 rows, expected 4");
  EXPECT_HAS(ErrorOf([&] { mlp.Forward(Eigen::MatrixXf::Zero(5, 2), ws, y); }),
             "inputs have 5 rows, expected 4");
}

TEST(InferenceMlpTest, ForwardRejectsABatchLargerThanTheWorkspace) {
  const InferenceMlp mlp(RandomMlpParams(Spec(4, {8}, 1, Activation::kRelu), 1),
                         Normalizer::Identity(4));
  auto ws = mlp.MakeWorkspace(8);
  Eigen::MatrixXf y(1, 9);
  EXPECT_HAS(ErrorOf([&] { mlp.Forward(Eigen::MatrixXf::Zero(4, 9), ws, y); }),
             "batch of 9 exceeds the workspace's max_batch 8");
  InferenceMlp::Workspace empty;  // default-constructed: max_batch 0
  EXPECT_EQ(empty.max_batch(), 0);
  Eigen::MatrixXf y1(1, 1);
  EXPECT_HAS(ErrorOf([&] { mlp.Forward(Eigen::MatrixXf::Zero(4, 1), empty, y1); }),
             "exceeds the workspace's max_batch 0");
}

TEST(InferenceMlpTest, ForwardRejectsWrongOutputShape) {
  const InferenceMlp mlp(RandomMlpParams(Spec(4, {8}, 2, Activation::kRelu), 1),
                         Normalizer::Identity(4));
  auto ws = mlp.MakeWorkspace(8);
  const Eigen::MatrixXf x = Eigen::MatrixXf::Zero(4, 3);
  Eigen::MatrixXf wrong_rows(1, 3), wrong_cols(2, 4), transposed(3, 2);
  EXPECT_HAS(ErrorOf([&] { mlp.Forward(x, ws, wrong_rows); }), "outputs are 1 x 3, expected 2 x 3");
  EXPECT_HAS(ErrorOf([&] { mlp.Forward(x, ws, wrong_cols); }), "outputs are 2 x 4, expected 2 x 3");
  EXPECT_HAS(ErrorOf([&] { mlp.Forward(x, ws, transposed); }), "expected 2 x 3");
}

TEST(InferenceMlpTest, ForwardOfADefaultConstructedModelThrows) {
  const InferenceMlp mlp;
  InferenceMlp::Workspace ws;
  Eigen::MatrixXf y(1, 1);
  EXPECT_HAS(ErrorOf([&] { mlp.Forward(Eigen::MatrixXf::Zero(1, 1), ws, y); }), "empty");
}

TEST(InferenceMlpTest, MakeWorkspaceRejectsNonPositiveMaxBatch) {
  const InferenceMlp mlp(RandomMlpParams(Spec(4, {8}, 1, Activation::kRelu), 1),
                         Normalizer::Identity(4));
  EXPECT_HAS(ErrorOf([&] { mlp.MakeWorkspace(0); }), "max_batch = 0");
  EXPECT_HAS(ErrorOf([&] { mlp.MakeWorkspace(-1); }), "max_batch = -1");
}

TEST(InferenceMlpTest, ConstructorRejectsAMismatchedNormalizer) {
  const MlpParams params = RandomMlpParams(Spec(4, {8}, 1, Activation::kRelu), 1);
  EXPECT_HAS(ErrorOf([&] { InferenceMlp mlp(params, Normalizer::Identity(3)); }),
             "normalizer has dimension 3, the network input is 4");
}

TEST(InferenceMlpTest, ConstructorRejectsInvalidParamsAndNormalizer) {
  MlpParams params = RandomMlpParams(Spec(4, {8}, 1, Activation::kRelu), 1);
  Normalizer bad_norm = Normalizer::Identity(4);
  bad_norm.scale[2] = 0.0f;
  EXPECT_HAS(ErrorOf([&] { InferenceMlp mlp(params, bad_norm); }), "scale[2] = 0");
  params.layers[0].weight(0, 0) = std::nanf("");
  EXPECT_HAS(ErrorOf([&] { InferenceMlp mlp(params, Normalizer::Identity(4)); }), "non-finite");
}

}  // namespace
}  // namespace secure::nn
