#pragma once
// Helpers shared by the nn tests.

#include <Eigen/Core>
#include <cstdint>
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

}  // namespace secure::nn::test
