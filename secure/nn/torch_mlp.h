#pragma once
// LibTorch mirror of an MlpSpec, for training. This header includes <torch/torch.h>: include
// it only from translation units that train (cbf/barrier_trainer.cc, policy trainers, tests).
//
// Tensors here are (N x dim), one sample per row — the transpose of the Eigen convention, which
// makes the conversion a plain copy of the column-major Eigen buffer.

#include <torch/torch.h>

#include "secure/nn/mlp.h"

namespace secure::nn {

class TorchMlpImpl : public torch::nn::Module {
 public:
  explicit TorchMlpImpl(const MlpSpec& spec);

  /// x: (N x input_dim) -> (N x output_dim).
  torch::Tensor forward(torch::Tensor x);

  /// Copies the current weights out / in (shapes checked against the spec).
  MlpParams ToParams() const;
  void LoadParams(const MlpParams& params);

  const MlpSpec& spec() const { return spec_; }

 private:
  MlpSpec spec_;
  std::vector<torch::nn::Linear> layers_;
};
TORCH_MODULE(TorchMlp);

/// (dim x N) Eigen matrix -> (N x dim) float tensor (a copy).
torch::Tensor ToTensor(const Eigen::Ref<const Eigen::MatrixXf>& samples);
/// (N x dim) float tensor -> (dim x N) Eigen matrix (a copy).
Eigen::MatrixXf ToEigen(const torch::Tensor& tensor);

}  // namespace secure::nn
