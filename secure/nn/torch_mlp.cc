#include "secure/nn/torch_mlp.h"
#include "secure/nn/torch_threads.h"

#include <ATen/CPUGeneratorImpl.h>
#include <dlfcn.h>

#include <cmath>
#include <cstdint>
#include <mutex>

#include "secure/common/error.h"

namespace secure::nn {

TorchLinearImpl::TorchLinearImpl(std::int64_t in_features, std::int64_t out_features) {
  weight = register_parameter("weight", torch::empty({out_features, in_features}));
  bias = register_parameter("bias", torch::empty({out_features}));
}

torch::Tensor TorchLinearImpl::forward(const torch::Tensor& x) {
  return torch::linear(x, weight, bias);  // what torch::nn::Linear computes
}

namespace {

// torch::nn::Linear::reset_parameters of LibTorch 1.13 (nn/modules/linear.cpp, nn/init.cpp),
// with the same arithmetic, drawing from `generator` instead of the global one:
//   weight: kaiming_uniform_(a = sqrt(5), fan_in, leaky_relu) = U(-bound, bound),
//           bound = sqrt(3) * gain / sqrt(fan_in), gain = sqrt(2 / (1 + a^2));
//   bias:   U(-1 / sqrt(fan_in), 1 / sqrt(fan_in)).
// TorchMlpTest.SeededInitialisationEqualsLinearAfterManualSeed checks the values bit for bit.
void LinearDefaultInit(TorchLinearImpl& layer, const at::Generator& generator) {
  torch::NoGradGuard no_grad;
  const std::int64_t fan_in = layer.weight.size(1);
  const double a = std::sqrt(5);
  const double gain = std::sqrt(2.0 / (1 + std::pow(a, 2)));
  const double std_dev = gain / std::sqrt(fan_in);
  const double bound = std::sqrt(3.0) * std_dev;
  layer.weight.uniform_(-bound, bound, generator);
  const double bias_bound = 1 / std::sqrt(fan_in);
  layer.bias.uniform_(-bias_bound, bias_bound, generator);
}

}  // namespace

TorchMlpImpl::TorchMlpImpl(const MlpSpec& spec, std::uint64_t seed) : spec_(spec) {
  Build();
  const at::Generator generator = at::make_generator<at::CPUGeneratorImpl>(seed);
  for (auto& layer : layers_) LinearDefaultInit(*layer, generator);
}

TorchMlpImpl::TorchMlpImpl(const MlpParams& params) : spec_(params.spec) {
  Build();
  LoadParams(params);
}

void TorchMlpImpl::Build() {
  spec_.Validate();
  const auto widths = spec_.Widths();
  for (std::size_t i = 0; i + 1 < widths.size(); ++i) {
    layers_.push_back(
        register_module("layer" + std::to_string(i), TorchLinear(widths[i], widths[i + 1])));
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

namespace {

// OpenBLAS's thread-count functions, found at run time, so that the reference BLAS (no such
// symbols) still works; null without OpenBLAS.
using SetBlasThreadsFn = void (*)(int);
using GetBlasThreadsFn = int (*)();
SetBlasThreadsFn SetBlasThreadsSymbol() {
  static const auto fn =
      reinterpret_cast<SetBlasThreadsFn>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  return fn;
}
GetBlasThreadsFn GetBlasThreadsSymbol() {
  static const auto fn =
      reinterpret_cast<GetBlasThreadsFn>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
  return fn;
}

}  // namespace

void SetTorchThreads(int threads) {
  SECURE_CHECK(threads > 0, "SetTorchThreads: threads = " << threads << ", must be > 0");
  torch::set_num_threads(threads);
  // LibTorch's CPU matrix products go to the system BLAS, which keeps its own thread pool:
  // torch::set_num_threads does not limit it, and two trainers on two threads would each start
  // a BLAS pool per call and fight over the cores (measured: 10-20x slower).
  if (const SetBlasThreadsFn set = SetBlasThreadsSymbol()) set(threads);
}

int TorchThreads() { return torch::get_num_threads(); }

int BlasThreads() {
  const GetBlasThreadsFn get = GetBlasThreadsSymbol();
  return get != nullptr ? get() : 0;
}

// OpenBLAS's count is process-wide, so concurrent scopes (trainers on several std::threads) share
// one setting: the first scope saves the count and sets it, later ones join it, the last one to
// leave restores it. Before, each scope restored what it had seen on entry, so a trainer that
// finished first put the count back under one still running, whose products then ran on
// another number of BLAS threads and rounded differently (seen on AMD Zen 5:
// car_barrier_train_test's concurrent trainings gave other model bytes than solo ones).
namespace {
std::mutex blas_scope_mutex;
int blas_scopes = 0;         // scopes alive, on any thread
int blas_scope_threads = 0;  // the count they hold
int blas_saved = 0;          // the count before the first of them
}  // namespace

ScopedTorchThreads::ScopedTorchThreads(int threads) : previous_torch_(TorchThreads()) {
  SECURE_CHECK(threads > 0, "ScopedTorchThreads: threads = " << threads << ", must be > 0");
  const std::lock_guard<std::mutex> lock(blas_scope_mutex);
  SECURE_CHECK(blas_scopes == 0 || threads == blas_scope_threads,
               "ScopedTorchThreads: " << threads << " threads asked while a concurrent training "
                                      << "holds OpenBLAS's process-wide count at "
                                      << blas_scope_threads
                                      << "; concurrent trainings need one thread count");
  torch::set_num_threads(threads);  // this thread's (OpenMP backend)
  if (blas_scopes == 0) {
    blas_saved = BlasThreads();
    if (const SetBlasThreadsFn set = SetBlasThreadsSymbol()) set(threads);
    blas_scope_threads = threads;
  }
  ++blas_scopes;
}

ScopedTorchThreads::~ScopedTorchThreads() {
  torch::set_num_threads(previous_torch_);
  const std::lock_guard<std::mutex> lock(blas_scope_mutex);
  if (--blas_scopes == 0 && blas_saved > 0) {
    if (const SetBlasThreadsFn set = SetBlasThreadsSymbol()) set(blas_saved);
  }
}

}  // namespace secure::nn
