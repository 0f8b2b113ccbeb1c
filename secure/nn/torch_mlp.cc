#include "secure/nn/torch_mlp.h"
#include "secure/nn/torch_threads.h"

#include <dlfcn.h>

#include "secure/common/error.h"

namespace secure::nn {

TorchMlpImpl::TorchMlpImpl(const MlpSpec& spec) : spec_(spec) {
  spec_.Validate();
  const auto widths = spec_.Widths();
  for (std::size_t i = 0; i + 1 < widths.size(); ++i) {
    layers_.push_back(
        register_module("layer" + std::to_string(i), torch::nn::Linear(widths[i], widths[i + 1])));
  }
}

torch::Tensor TorchMlpImpl::forward(torch::Tensor x) {
  for (std::size_t i = 0; i < layers_.size(); ++i) {
    x = layers_[i]->forward(x);
    if (i + 1 < layers_.size()) {
      x = spec_.activation == Activation::kRelu ? torch::relu(x) : torch::tanh(x);
    }
  }
  return x;
}

MlpParams TorchMlpImpl::ToParams() const {
  torch::NoGradGuard no_grad;
  MlpParams params{spec_, {}};
  for (const auto& linear : layers_) {
    // Torch weights are (out x in) row-major; Eigen's default is column-major, so map the
    // buffer as row-major and let the assignment transpose the storage.
    const torch::Tensor w = linear->weight.detach().contiguous().to(torch::kFloat32);
    const torch::Tensor b = linear->bias.detach().contiguous().to(torch::kFloat32);
    using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    DenseLayer layer;
    layer.weight = Eigen::Map<const RowMajor>(w.data_ptr<float>(), w.size(0), w.size(1));
    layer.bias = Eigen::Map<const Eigen::VectorXf>(b.data_ptr<float>(), b.size(0));
    params.layers.push_back(std::move(layer));
  }
  return params;
}

void TorchMlpImpl::LoadParams(const MlpParams& params) {
  params.Validate();
  SECURE_CHECK(params.spec == spec_, "TorchMlp::LoadParams: architecture does not match");
  torch::NoGradGuard no_grad;
  for (std::size_t i = 0; i < layers_.size(); ++i) {
    using RowMajor = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    const RowMajor w = params.layers[i].weight;
    layers_[i]->weight.copy_(
        torch::from_blob(const_cast<float*>(w.data()), {w.rows(), w.cols()}, torch::kFloat32));
    layers_[i]->bias.copy_(torch::from_blob(const_cast<float*>(params.layers[i].bias.data()),
                                            {params.layers[i].bias.size()}, torch::kFloat32));
  }
}

torch::Tensor ToTensor(const Eigen::Ref<const Eigen::MatrixXf>& samples) {
  const Eigen::MatrixXf dense =
      samples;  // contiguous column-major (dim x N) == row-major (N x dim)
  return torch::from_blob(const_cast<float*>(dense.data()), {dense.cols(), dense.rows()},
                          torch::kFloat32)
      .clone();
}

Eigen::MatrixXf ToEigen(const torch::Tensor& tensor) {
  SECURE_CHECK(tensor.dim() == 2, "ToEigen: tensor has " << tensor.dim() << " dims, expected 2");
  const torch::Tensor t = tensor.detach().to(torch::kFloat32).contiguous();
  return Eigen::Map<const Eigen::MatrixXf>(t.data_ptr<float>(), t.size(1), t.size(0));
}

void SetTorchThreads(int threads) {
  SECURE_CHECK(threads > 0, "SetTorchThreads: threads = " << threads << ", must be > 0");
  torch::set_num_threads(threads);
  // LibTorch's CPU matrix products go to the system BLAS, which keeps its own thread pool:
  // torch::set_num_threads does not limit it, and two trainers on two threads would each start
  // a BLAS pool per call and fight over the cores (measured: 10-20x slower). OpenBLAS is found
  // at run time, so that the reference BLAS (no such symbol) still works.
  using SetBlasThreads = void (*)(int);
  static const auto set_blas_threads =
      reinterpret_cast<SetBlasThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  if (set_blas_threads != nullptr) set_blas_threads(threads);
}

int TorchThreads() { return torch::get_num_threads(); }

}  // namespace secure::nn
