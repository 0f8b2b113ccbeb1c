#pragma once
// Helpers shared by the nn tests.

#include <gtest/gtest.h>
#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "secure/common/rng.h"
#include "secure/nn/mlp.h"

namespace secure::nn::test {

inline MlpSpec Spec(int in, std::vector<int> hidden, int out = 1,
                    Activation a = Activation::kTanh) {
  MlpSpec spec;
  spec.input_dim = in;
  spec.hidden = std::move(hidden);
  spec.output_dim = out;
  spec.activation = a;
  return spec;
}

/// The hidden widths of the paper's Panda barrier (Table 2).
inline const std::vector<int> kPandaHidden{32, 128, 128, 256, 256, 256, 256, 128, 128, 32};

/// (dim x n) inputs, uniform in [lo, hi) per feature, seeded.
inline Eigen::MatrixXf RandomInputs(int dim, int n, std::uint64_t seed, double lo = -3.0,
                                    double hi = 3.0) {
  Rng rng(seed);
  Eigen::MatrixXf x(dim, n);
  for (int c = 0; c < n; ++c)
    for (int r = 0; r < dim; ++r) x(r, c) = static_cast<float>(rng.Uniform(lo, hi));
  return x;
}

/// `loaded` holds `saved`'s spec, weights and normaliser, bit for bit (a model file's round trip).
inline void ExpectSameMlp(const MlpParams& loaded, const Normalizer& loaded_normalizer,
                          const MlpParams& saved, const Normalizer& saved_normalizer) {
  EXPECT_TRUE(loaded.spec == saved.spec);
  ASSERT_EQ(loaded.layers.size(), saved.layers.size());
  for (std::size_t l = 0; l < saved.layers.size(); ++l) {
    EXPECT_EQ(loaded.layers[l].weight, saved.layers[l].weight) << "layer " << l;
    EXPECT_EQ(loaded.layers[l].bias, saved.layers[l].bias) << "layer " << l;
  }
  EXPECT_EQ(loaded_normalizer.mean, saved_normalizer.mean);
  EXPECT_EQ(loaded_normalizer.scale, saved_normalizer.scale);
}

/// A named architecture for the tests that run over several.
struct Case {
  std::string name;
  MlpSpec spec;
};

/// The architectures the inference and LibTorch tests check, with either activation: linear
/// (no hidden layer, 2 outputs), the double integrator's, Derby's, Panda's, and a narrow-wide
/// net with 3 outputs.
inline std::vector<Case> Architectures() {
  std::vector<Case> cases;
  for (Activation a : {Activation::kRelu, Activation::kTanh}) {
    const std::string act = secure::ToString(kActivationNames, a);
    cases.push_back({"linear_" + act, Spec(3, {}, 2, a)});
    cases.push_back({"di_" + act, Spec(4, {64, 64, 64}, 1, a)});
    cases.push_back({"derby_" + act, Spec(4, {64, 128, 64}, 1, a)});
    cases.push_back({"panda_" + act, Spec(9, kPandaHidden, 1, a)});
    cases.push_back({"narrow_wide_multi_out_" + act, Spec(5, {3, 40, 7}, 3, a)});
  }
  return cases;
}

}  // namespace secure::nn::test
