#include "secure/nn/inference_mlp.h"

#include <libxsmm.h>

#include <algorithm>
#include <cstdlib>
#include <mutex>
#include <type_traits>

#include "secure/common/error.h"

namespace secure::nn {
namespace {

// Bias, then activation, as two passes over a block: Eigen 3.4 does not vectorise tanh of a fused
// (z.colwise() + bias) expression (measured 3.9 ns vs 0.46 ns per element, AVX2).
template <typename Block>
void BiasActivation(Block&& z, const Eigen::VectorXf& bias, bool relu) {
  z.colwise() += bias;
  if (relu) {
    z = z.cwiseMax(0.0f);
  } else {
    z.array() = z.array().tanh();
  }
}

// The output layer (one or a few rows): an Eigen product on either backend.
void OutputLayer(const DenseLayer& head, const Eigen::Ref<const Eigen::MatrixXf>& in,
                 Eigen::Ref<Eigen::MatrixXf> outputs) {
  outputs.noalias() = head.weight * in;
  outputs.colwise() += head.bias;
}

}  // namespace

InferenceMlp::InferenceMlp(const MlpParams& params, const Normalizer& normalizer,
                           MatmulBackend backend)
    : spec_(params.spec), layers_(params.layers) {
  params.Validate();
  normalizer.Validate();
  SECURE_CHECK(normalizer.dim() == spec_.input_dim,
               "InferenceMlp: normalizer has dimension "
                   << normalizer.dim() << ", the network input is " << spec_.input_dim);
  // Fold x' = (x - mean) / scale into the first layer: W x' + b = (W / scale) x + (b - W' mean).
  // Computed in double so that folding adds no rounding beyond the final cast.
  const Eigen::MatrixXd w = params.layers[0].weight.cast<double>();
  const Eigen::VectorXd inv_scale = normalizer.scale.cast<double>().cwiseInverse();
  const Eigen::MatrixXd w_folded = w * inv_scale.asDiagonal();
  layers_[0].weight = w_folded.cast<float>();
  layers_[0].bias =
      (params.layers[0].bias.cast<double>() - w_folded * normalizer.mean.cast<double>())
          .cast<float>();
  for (int width : spec_.hidden) max_width_ = std::max(max_width_, width);
  max_width_ = std::max(max_width_, spec_.output_dim);

  if (backend == MatmulBackend::kAuto) backend = ForcedBackend();
  if (backend == MatmulBackend::kEigen) {
    backend_ = MatmulBackend::kEigen;
    return;
  }
  BuildKernels();
  if (!kernels_.empty() || spec_.hidden.empty()) {
    backend_ = MatmulBackend::kLibxsmm;
    return;
  }
  SECURE_CHECK(backend == MatmulBackend::kAuto,
               "InferenceMlp: LIBXSMM generated no kernel for the "
                   << ToString(kMatmulBackendNames, backend)
                   << " backend on this CPU (libxsmm target '" << libxsmm_get_target_arch()
                   << "'); use the eigen backend");
  backend_ = MatmulBackend::kEigen;
}

MatmulBackend InferenceMlp::ForcedBackend() {
  const char* value = std::getenv("SECURE_MATMUL_BACKEND");
  if (value == nullptr || *value == '\0') return MatmulBackend::kAuto;
  return FromString(kMatmulBackendNames, value, "environment variable SECURE_MATMUL_BACKEND");
}

const char* InferenceMlp::LibxsmmTarget() {
  InitLibxsmm();
  return libxsmm_get_target_arch();
}

void InferenceMlp::InitLibxsmm() {
  static std::once_flag init;
  std::call_once(init, [] { libxsmm_init(); });
}

void InferenceMlp::BuildKernels() {
  InitLibxsmm();
  static_assert(std::is_same_v<SmmKernel, libxsmm_smmfunction>,
                "InferenceMlp::SmmKernel must match libxsmm_smmfunction");
  std::vector<LayerKernels> all;
  const float alpha = 1.0f, beta = 0.0f;  // C = A B: the destination is never read
  const int flags = LIBXSMM_GEMM_FLAGS('N', 'N');
  const int prefetch = LIBXSMM_GEMM_PREFETCH_NONE;
  for (std::size_t l = 0; l + 1 < layers_.size(); ++l) {
    const auto& weight = layers_[l].weight;
    const libxsmm_blasint width = weight.rows(), in = weight.cols();
    // A = W (width x in, column-major), B = activations of the previous layer, C = this layer's.
    const libxsmm_blasint lda = width, ldb = (l == 0 ? spec_.input_dim : max_width_),
                          ldc = max_width_;
    LayerKernels k;
    k.row_block = static_cast<int>(std::min<libxsmm_blasint>(width, kRowBlock));
    k.row_blocks = static_cast<int>(width / k.row_block);
    k.row_rest = static_cast<int>(width % k.row_block);
    for (int t = 0; t < kTails; ++t) {
      const libxsmm_blasint cols = kColumnBlock >> t;
      k.kernels[t][0] = libxsmm_smmdispatch(k.row_block, cols, in, &lda, &ldb, &ldc, &alpha,
                                            &beta, &flags, &prefetch);
      if (k.kernels[t][0] == nullptr) return;  // no JIT for this CPU or shape: kernels_ empty
      if (k.row_rest > 0) {
        k.kernels[t][1] = libxsmm_smmdispatch(k.row_rest, cols, in, &lda, &ldb, &ldc, &alpha,
                                              &beta, &flags, &prefetch);
        if (k.kernels[t][1] == nullptr) return;
      }
    }
    all.push_back(k);
  }
  kernels_ = std::move(all);
}

InferenceMlp::Workspace InferenceMlp::MakeWorkspace(int max_batch) const {
  SECURE_CHECK(max_batch > 0,
               "InferenceMlp::MakeWorkspace: max_batch = " << max_batch << ", must be > 0");
  Workspace ws;
  ws.max_batch_ = max_batch;
  ws.a_.resize(max_width_, max_batch);
  ws.b_.resize(max_width_, max_batch);
  if (backend_ == MatmulBackend::kLibxsmm) ws.x_.resize(spec_.input_dim, max_batch);
  return ws;
}

void InferenceMlp::Forward(const Eigen::Ref<const Eigen::MatrixXf>& inputs, Workspace& workspace,
                           Eigen::Ref<Eigen::MatrixXf> outputs) const {
  const Eigen::Index n = inputs.cols();
  SECURE_CHECK(!layers_.empty(), "InferenceMlp::Forward: network is empty");
  SECURE_CHECK(inputs.rows() == spec_.input_dim, "InferenceMlp::Forward: inputs have "
                                                     << inputs.rows() << " rows, expected "
                                                     << spec_.input_dim);
  SECURE_CHECK(outputs.rows() == spec_.output_dim && outputs.cols() == n,
               "InferenceMlp::Forward: outputs are " << outputs.rows() << " x " << outputs.cols()
                                                     << ", expected " << spec_.output_dim << " x "
                                                     << n);
  SECURE_CHECK(n <= workspace.max_batch_, "InferenceMlp::Forward: batch of "
                                              << n << " exceeds the workspace's max_batch "
                                              << workspace.max_batch_);
  if (backend_ == MatmulBackend::kLibxsmm) {
    SECURE_CHECK(workspace.x_.rows() == spec_.input_dim,
                 "InferenceMlp::Forward: the workspace was made by a model with another backend");
  }
  // One column: Eigen's matrix-vector products are as fast (Panda net, one state: 10.5 vs 11.8
  // us; DI net 0.36 vs 0.35 us), so a policy's single-state forward stays on Eigen. From two
  // columns on LIBXSMM (docs/PERFORMANCE.md, "Small batches").
  if (backend_ == MatmulBackend::kLibxsmm && n >= kMinLibxsmmBatch) {
    ForwardLibxsmm(inputs, workspace, outputs);
  } else {
    ForwardEigen(inputs, workspace, outputs);
  }
}

void InferenceMlp::ForwardEigen(const Eigen::Ref<const Eigen::MatrixXf>& inputs,
                                Workspace& workspace, Eigen::Ref<Eigen::MatrixXf> outputs) const {
  const Eigen::Index n = inputs.cols();
  const bool relu = spec_.activation == Activation::kRelu;
  const std::size_t last = layers_.size() - 1;
  Eigen::MatrixXf* in = &workspace.a_;
  Eigen::MatrixXf* out = &workspace.b_;
  for (std::size_t l = 0; l < last; ++l) {
    const DenseLayer& layer = layers_[l];
    auto z = out->topLeftCorner(layer.weight.rows(), n);
    if (l == 0) {
      z.noalias() = layer.weight * inputs;
    } else {
      z.noalias() = layer.weight * in->topLeftCorner(layer.weight.cols(), n);
    }
    BiasActivation(z, layer.bias, relu);
    std::swap(in, out);
  }
  if (last == 0) {
    OutputLayer(layers_[last], inputs, outputs);
  } else {
    OutputLayer(layers_[last], in->topLeftCorner(layers_[last].weight.cols(), n), outputs);
  }
}

void InferenceMlp::ForwardLibxsmm(const Eigen::Ref<const Eigen::MatrixXf>& inputs,
                                  Workspace& workspace, Eigen::Ref<Eigen::MatrixXf> outputs) const {
  const Eigen::Index n = inputs.cols();
  const bool relu = spec_.activation == Activation::kRelu;
  const std::size_t last = layers_.size() - 1;
  // The first layer's kernels were generated for contiguous inputs (leading dimension input_dim).
  const float* x = inputs.data();
  if (n > 1 && inputs.outerStride() != spec_.input_dim) {
    workspace.x_.leftCols(n) = inputs;
    x = workspace.x_.data();
  }
  const Eigen::Index ld_in0 = spec_.input_dim, ld = max_width_;
  Eigen::MatrixXf* in = &workspace.a_;
  Eigen::MatrixXf* out = &workspace.b_;
  for (std::size_t l = 0; l < last; ++l) {
    const DenseLayer& layer = layers_[l];
    const LayerKernels& k = kernels_[l];
    const float* w = layer.weight.data();
    const float* b = (l == 0) ? x : in->data();
    const Eigen::Index ldb = (l == 0) ? ld_in0 : ld;
    float* c = out->data();
    // One column block: every row block of the layer, then bias and activation while it is hot.
    auto block = [&](Eigen::Index col, int t) {
      const float* bb = b + col * ldb;
      float* cc = c + col * ld;
      for (int r = 0; r < k.row_blocks; ++r)
        k.kernels[t][0](w + r * k.row_block, bb, cc + r * k.row_block);
      if (k.row_rest > 0) {
        const int r0 = k.row_blocks * k.row_block;
        k.kernels[t][1](w + r0, bb, cc + r0);
      }
      BiasActivation(out->block(0, col, layer.weight.rows(), kColumnBlock >> t), layer.bias,
                     relu);
    };
    Eigen::Index col = 0;
    for (; col + kColumnBlock <= n; col += kColumnBlock) block(col, 0);
    for (int t = 1; t < kTails; ++t) {
      if ((n - col) & (kColumnBlock >> t)) {
        block(col, t);
        col += kColumnBlock >> t;
      }
    }
    std::swap(in, out);
  }
  if (last == 0) {
    OutputLayer(layers_[last], inputs, outputs);
  } else {
    OutputLayer(layers_[last], in->topLeftCorner(layers_[last].weight.cols(), n), outputs);
  }
}

}  // namespace secure::nn

namespace secure::nn {

InferenceMlp::GradientWorkspace InferenceMlp::MakeGradientWorkspace(int max_batch) const {
  SECURE_CHECK(max_batch > 0,
               "InferenceMlp::MakeGradientWorkspace: max_batch = " << max_batch << ", must be > 0");
  GradientWorkspace ws;
  ws.max_batch_ = max_batch;
  for (int width : spec_.hidden) ws.activations_.emplace_back(width, max_batch);
  ws.delta_a_.resize(max_width_, max_batch);
  ws.delta_b_.resize(max_width_, max_batch);
  return ws;
}

void InferenceMlp::ForwardGradient(const Eigen::Ref<const Eigen::MatrixXf>& inputs,
                                   GradientWorkspace& workspace,
                                   Eigen::Ref<Eigen::VectorXf> values,
                                   Eigen::Ref<Eigen::MatrixXf> gradients) const {
  const Eigen::Index n = inputs.cols();
  SECURE_CHECK(!layers_.empty(), "InferenceMlp::ForwardGradient: network is empty");
  SECURE_CHECK(spec_.output_dim == 1, "InferenceMlp::ForwardGradient: the network has "
                                          << spec_.output_dim
                                          << " outputs; the gradient needs exactly 1");
  SECURE_CHECK(inputs.rows() == spec_.input_dim, "InferenceMlp::ForwardGradient: inputs have "
                                                     << inputs.rows() << " rows, expected "
                                                     << spec_.input_dim);
  SECURE_CHECK(values.size() == n && gradients.rows() == spec_.input_dim && gradients.cols() == n,
               "InferenceMlp::ForwardGradient: values has "
                   << values.size() << " entries and gradients is " << gradients.rows() << " x "
                   << gradients.cols() << " for " << n << " inputs of dimension "
                   << spec_.input_dim);
  SECURE_CHECK(n <= workspace.max_batch_ &&
                   workspace.activations_.size() == spec_.hidden.size(),
               "InferenceMlp::ForwardGradient: batch of "
                   << n << " exceeds the gradient workspace's max_batch " << workspace.max_batch_
                   << " (or the workspace belongs to another network)");
  const bool relu = spec_.activation == Activation::kRelu;
  const std::size_t last = layers_.size() - 1;
  // Forward, keeping every hidden layer's activations y_l = act(W_l y_{l-1} + b_l).
  for (std::size_t l = 0; l < last; ++l) {
    const DenseLayer& layer = layers_[l];
    auto y = workspace.activations_[l].leftCols(n);
    if (l == 0) {
      y.noalias() = layer.weight * inputs;
    } else {
      y.noalias() = layer.weight * workspace.activations_[l - 1].leftCols(n);
    }
    BiasActivation(y, layer.bias, relu);
  }
  const DenseLayer& head = layers_[last];
  Eigen::Map<Eigen::RowVectorXf> row(values.data(), n);
  if (last == 0) {
    row.noalias() = head.weight * inputs;
  } else {
    row.noalias() = head.weight * workspace.activations_[last - 1].leftCols(n);
  }
  row.array() += head.bias[0];
  if (last == 0) {
    // A linear network: the gradient is the (folded) weight row, the same for every input.
    gradients = head.weight.transpose().replicate(1, n);
    return;
  }
  // Backward: delta_{last-1} = W_head^T (1 x width)^T for every column, times act'(z); then
  // delta_{l-1} = (W_l^T delta_l) * act'(z_{l-1}); finally d out / d input = W_0^T delta_0.
  Eigen::MatrixXf* delta = &workspace.delta_a_;
  Eigen::MatrixXf* next = &workspace.delta_b_;
  for (std::size_t l = last; l-- > 0;) {
    const int width = spec_.hidden[l];
    auto d = delta->topLeftCorner(width, n);
    if (l + 1 == last) {
      d = head.weight.transpose().replicate(1, n);
    } else {
      d.noalias() = layers_[l + 1].weight.transpose() *
                    next->topLeftCorner(layers_[l + 1].weight.rows(), n);
    }
    const auto y = workspace.activations_[l].leftCols(n);
    if (relu) {
      d.array() = (y.array() > 0.0f).select(d.array(), 0.0f);
    } else {
      d.array() *= 1.0f - y.array().square();
    }
    std::swap(delta, next);
  }
  // `next` now holds delta_0 (width_0 x n).
  gradients.noalias() = layers_[0].weight.transpose() * next->topLeftCorner(spec_.hidden[0], n);
}

}  // namespace secure::nn
