#pragma once
// A multilayer perceptron as plain data (no LibTorch): the form in which trained networks are
// stored, loaded and evaluated. Training converts to and from LibTorch (torch_mlp.h, internal).
//
// Conventions used throughout secure: a batch of inputs is an Eigen matrix (input_dim x N),
// one sample per column; layer weights are (out x in), so a layer computes  y = act(W x + b).
// Hidden layers apply the activation; the output layer is linear.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "secure/common/enum_strings.h"

namespace secure::nn {

enum class Activation { kRelu, kTanh };
inline constexpr EnumTable<Activation, 2> kActivationNames{{
    {Activation::kRelu, "relu"},
    {Activation::kTanh, "tanh"},
}};

/// Architecture of an MLP: input_dim -> hidden[0] -> ... -> hidden[k-1] -> output_dim.
struct MlpSpec {
  int input_dim = 0;
  std::vector<int> hidden;
  int output_dim = 1;
  Activation activation = Activation::kTanh;

  /// Throws secure::Error naming the field ("MlpSpec::hidden[2] = 0, must be > 0").
  void Validate() const;
  /// Multiply-adds per sample (sum of in*out over layers); 2x this is the FLOP count.
  long MultiplyAddsPerSample() const;
  /// Layer widths including input and output: {input_dim, hidden..., output_dim}.
  std::vector<int> Widths() const;
  bool operator==(const MlpSpec& other) const;
};

struct DenseLayer {
  Eigen::MatrixXf weight;  // (out x in)
  Eigen::VectorXf bias;    // (out)
};

/// An MLP's architecture and weights. layers.size() == spec.hidden.size() + 1.
struct MlpParams {
  MlpSpec spec;
  std::vector<DenseLayer> layers;

  /// Checks the layer shapes against spec and that every weight is finite; `what` prefixes the
  /// message (e.g. the file name).
  void Validate(const std::string& what = "MLP") const;
};

/// Per-feature affine input normalisation x' = (x - mean) / scale, stored with a model.
struct Normalizer {
  Eigen::VectorXf mean;   // (dim)
  Eigen::VectorXf scale;  // (dim), > 0

  /// mean and std of the columns of `samples` (dim x N); a feature whose std is below 1e-8
  /// (constant in the data) gets scale 1 so that it passes through unscaled.
  static Normalizer Fit(const Eigen::Ref<const Eigen::MatrixXf>& samples);
  static Normalizer Identity(int dim);
  int dim() const { return static_cast<int>(mean.size()); }
  void Validate(const std::string& what = "normalizer") const;
  /// Applies x' = (x - mean) / scale to every column.
  Eigen::MatrixXf Apply(const Eigen::Ref<const Eigen::MatrixXf>& samples) const;
};

/// Fresh weights for `spec` (uniform Glorot), seeded; used by tests and benchmarks.
MlpParams RandomMlpParams(const MlpSpec& spec, unsigned long long seed);

/// Reference forward pass, column by column in double precision: slow, for tests only.
Eigen::MatrixXd ReferenceForward(const MlpParams& params, const Normalizer& normalizer,
                                 const Eigen::Ref<const Eigen::MatrixXf>& inputs);

}  // namespace secure::nn
