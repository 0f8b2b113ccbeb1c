#pragma once
// Fast batched MLP inference on the CPU: the path the shield, the policies and the grid
// validation use.
//
// Immutable model + mutable workspace (as MuJoCo's mjModel/mjData): an InferenceMlp is built
// once from trained parameters (input normalisation folded into the first layer) and can be
// shared by threads; each thread or shield owns an InferenceMlp::Workspace sized for its largest
// batch, which holds every activation buffer. Forward() does not allocate.
//
// Matrix products. By default the hidden layers run on LIBXSMM's JIT-generated small-GEMM
// kernels (Debian libxsmm-dev): every kernel a layer can need is generated in the constructor
// (64-column blocks, then 32/16/8/4/2/1-column tails), so Forward() only calls them. On the
// project machine they run the shield's layer shapes 1.3-2x faster than Eigen's GEMM
// (docs/PERFORMANCE.md). Bias and activation are applied per 64-column block while it is in
// cache. The output layer (one or a few rows) and single columns (a policy's single-state
// forward) stay Eigen products (a matrix-vector product, as fast there). Batches of 2-7 columns
// (a learned model's K members, a linearisation's 2n + 1 points) take LIBXSMM's tails: Eigen's
// GEMM repacks the weights on every call, 2.0-3.4x slower there on the Panda barrier.
// MatmulBackend::kEigen selects Eigen's GEMM for every layer (the reference, and the A/B
// baseline of the benchmarks); kAuto uses LIBXSMM when it can generate code for this CPU and
// Eigen otherwise, and backend() says which one a model uses. Both compute the same function;
// results differ by float rounding (~1e-6 relative).
//
// Forcing a path (tests, A/B runs): the environment variable SECURE_MATMUL_BACKEND=eigen|libxsmm
// replaces kAuto in every constructor of the process (an explicit kEigen or kLibxsmm is kept), and
// LIBXSMM's own LIBXSMM_TARGET (e.g. hsw = AVX2, skx = AVX-512) picks the instruction set its
// kernels are generated for. `ctest -L dispatch` runs the inference and shield tests under each
// path the CPU supports (tests/dispatch/), so a result that holds on one path only is found on
// any machine.
//
// Eigen's GEMM packing buffers come from the stack (EIGEN_STACK_ALLOCATION_LIMIT is raised to
// 1 MiB project-wide, see CMakeLists.txt): the calling thread needs about 1 MiB of stack for the
// widest layers on the Eigen path.

#include <Eigen/Core>
#include <vector>

#include "secure/common/enum_strings.h"
#include "secure/nn/mlp.h"

namespace secure::nn {

enum class MatmulBackend {
  kAuto,     // LIBXSMM if it generates kernels for this CPU, else Eigen (backend() tells)
  kLibxsmm,  // LIBXSMM; the constructor throws if it cannot generate a kernel
  kEigen,    // Eigen's GEMM for every layer
};
inline constexpr EnumTable<MatmulBackend, 3> kMatmulBackendNames{{
    {MatmulBackend::kAuto, "auto"},
    {MatmulBackend::kLibxsmm, "libxsmm"},
    {MatmulBackend::kEigen, "eigen"},
}};

class InferenceMlp {
 public:
  class Workspace {
   public:
    Workspace() = default;
    int max_batch() const { return max_batch_; }

   private:
    friend class InferenceMlp;
    int max_batch_ = 0;
    Eigen::MatrixXf a_, b_;  // ping-pong activations (max_width x max_batch)
    Eigen::MatrixXf x_;      // contiguous copy of strided inputs (input_dim x max_batch)
  };

  /// The buffers of ForwardGradient for batches of up to max_batch() samples: every hidden
  /// layer's activations (kept for the backward pass) and two back-propagated blocks. Separate
  /// from Workspace, so Forward's buffers and results are untouched by the gradient path.
  class GradientWorkspace {
   public:
    GradientWorkspace() = default;
    int max_batch() const { return max_batch_; }

   private:
    friend class InferenceMlp;
    int max_batch_ = 0;
    std::vector<Eigen::MatrixXf> activations_;  // per hidden layer (width x max_batch)
    Eigen::MatrixXf delta_a_, delta_b_;         // ping-pong (max_width x max_batch)
  };

  InferenceMlp() = default;
  /// Folds `normalizer` into the first layer: W' = W diag(1/scale), b' = b - W' mean.
  /// @throws secure::Error for kLibxsmm when LIBXSMM cannot generate a kernel on this CPU.
  InferenceMlp(const MlpParams& params, const Normalizer& normalizer,
               MatmulBackend backend = MatmulBackend::kAuto);

  int input_dim() const { return spec_.input_dim; }
  int output_dim() const { return spec_.output_dim; }
  const MlpSpec& spec() const { return spec_; }
  /// The backend in use: kLibxsmm or kEigen (never kAuto).
  MatmulBackend backend() const { return backend_; }

  /// What kAuto means in this process: kAuto, or the backend SECURE_MATMUL_BACKEND forces.
  /// @throws secure::Error naming the variable if its value is not auto, eigen or libxsmm.
  static MatmulBackend ForcedBackend();
  /// The instruction set LIBXSMM generates kernels for (its target name, e.g. "hsw", "skx").
  static const char* LibxsmmTarget();

  /// A workspace for batches of up to `max_batch` samples.
  Workspace MakeWorkspace(int max_batch) const;

  /// A gradient workspace for batches of up to `max_batch` samples.
  GradientWorkspace MakeGradientWorkspace(int max_batch) const;

  /// For a network with one output: values (N) = MLP(inputs (input_dim x N)) and gradients
  /// (input_dim x N) = d MLP / d input of every column, analytically (a forward pass that keeps
  /// each hidden layer's activations, then the backward pass: delta = W^T delta, times tanh'
  /// = 1 - y^2 or ReLU' = [y > 0], whose value at 0 is taken as 0, as LibTorch does). The input
  /// normalisation is folded into the first layer, so the gradient is with respect to the raw
  /// input. Eigen products on either backend, so `values` can differ from Forward()'s by float
  /// rounding (~1e-6 relative). No allocation. N <= workspace.max_batch().
  /// @throws secure::Error if output_dim != 1 or the dimensions do not match.
  void ForwardGradient(const Eigen::Ref<const Eigen::MatrixXf>& inputs,
                       GradientWorkspace& workspace, Eigen::Ref<Eigen::VectorXf> values,
                       Eigen::Ref<Eigen::MatrixXf> gradients) const;

  /// outputs (output_dim x N) = MLP(inputs (input_dim x N)). N <= workspace.max_batch().
  /// @throws secure::Error if the dimensions do not match.
  void Forward(const Eigen::Ref<const Eigen::MatrixXf>& inputs, Workspace& workspace,
               Eigen::Ref<Eigen::MatrixXf> outputs) const;

 private:
  // A LIBXSMM kernel C = A B (column-major, beta = 0); the signature of libxsmm_smmfunction, kept
  // here so that libxsmm.h stays out of this header.
  using SmmKernel = void (*)(const float* a, const float* b, float* c, ...);
  static constexpr int kColumnBlock = 64;  // columns per kernel call; tails use 32, 16, ..., 1
  static constexpr int kTails = 7;         // column counts 64, 32, 16, 8, 4, 2, 1
  static constexpr int kRowBlock = 64;     // output rows per kernel call
  static constexpr int kMinLibxsmmBatch = 2;  // one column takes the Eigen path
  struct LayerKernels {
    // kernels[t][0]: kRowBlock (or all) rows, kernels[t][1]: the remaining rows (or null), for
    // kColumnBlock >> t columns.
    SmmKernel kernels[kTails][2] = {};
    int row_block = 0;     // rows of kernels[.][0]
    int row_blocks = 0;    // full row blocks
    int row_rest = 0;      // rows of kernels[.][1]
  };

  static void InitLibxsmm();  // libxsmm_init(), once per process
  void BuildKernels();
  void ForwardEigen(const Eigen::Ref<const Eigen::MatrixXf>& inputs, Workspace& workspace,
                    Eigen::Ref<Eigen::MatrixXf> outputs) const;
  void ForwardLibxsmm(const Eigen::Ref<const Eigen::MatrixXf>& inputs, Workspace& workspace,
                      Eigen::Ref<Eigen::MatrixXf> outputs) const;

  MlpSpec spec_;
  std::vector<DenseLayer> layers_;  // normalisation folded into layers_[0]
  int max_width_ = 0;
  MatmulBackend backend_ = MatmulBackend::kEigen;
  std::vector<LayerKernels> kernels_;  // one per hidden layer (LIBXSMM backend)
};

}  // namespace secure::nn
