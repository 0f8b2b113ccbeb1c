#pragma once
// LibTorch mirror of an MlpSpec, for training. This header includes <torch/torch.h>: include
// it only from translation units that train (cbf/barrier_trainer.cc, policy trainers, tests).
//
// Tensors here are (N x dim), one sample per row — the transpose of the Eigen convention, which
// makes the conversion a plain copy of the column-major Eigen buffer.
//
// Initial weights come from an explicit seed, never from LibTorch's process-wide generator:
// TorchMlp(spec, seed) draws torch::nn::Linear's default initialisation from a generator of its
// own, so concurrent trainings in several threads need no lock and leave the global generator
// alone (its values equal what torch::manual_seed(seed) followed by torch::nn::Linear layers
// gave: model files trained before this change are reproduced bit for bit).

#include <torch/torch.h>

#include <cstdint>

#include "secure/nn/mlp.h"

namespace secure::nn {

/// y = x W^T + b, as torch::nn::Linear (parameters "weight" (out x in) and "bias" (out)), but
/// constructed without touching any random generator: the weights are uninitialised until
/// TorchMlpImpl fills them.
class TorchLinearImpl : public torch::nn::Module {
 public:
  TorchLinearImpl(std::int64_t in_features, std::int64_t out_features);
  torch::Tensor forward(const torch::Tensor& x);

  torch::Tensor weight, bias;
};
TORCH_MODULE(TorchLinear);

class TorchMlpImpl : public torch::nn::Module {
 public:
  /// Weights of torch::nn::Linear's default initialisation (Kaiming uniform with a = sqrt(5);
  /// bias U(-1/sqrt(fan_in), 1/sqrt(fan_in))), layer by layer, weight then bias, drawn from a
  /// CPU generator seeded with `seed` — the values LibTorch's global generator gives after
  /// torch::manual_seed(seed). The global generator is not used. (Callers that load weights
  /// right away may leave the seed at 0.)
  explicit TorchMlpImpl(const MlpSpec& spec, std::uint64_t seed = 0);
  /// A copy of `params` (validated); no random draws.
  explicit TorchMlpImpl(const MlpParams& params);

  /// x: (N x input_dim) -> (N x output_dim).
  torch::Tensor forward(torch::Tensor x);

  /// Copies the current weights out / in (shapes checked against the spec).
  MlpParams ToParams() const;
  void LoadParams(const MlpParams& params);

  const MlpSpec& spec() const { return spec_; }

 private:
  // Registers the layers "layer0", "layer1", ... with uninitialised weights.
  void Build();

  MlpSpec spec_;
  std::vector<TorchLinear> layers_;
};
TORCH_MODULE(TorchMlp);

/// (dim x N) Eigen matrix -> (N x dim) float tensor (a copy).
torch::Tensor ToTensor(const Eigen::Ref<const Eigen::MatrixXf>& samples);
/// (N x dim) float tensor -> (dim x N) Eigen matrix (a copy).
Eigen::MatrixXf ToEigen(const torch::Tensor& tensor);

}  // namespace secure::nn
