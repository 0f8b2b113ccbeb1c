#pragma once
// Fast batched MLP inference with Eigen: the path the shield and the grid validation use.
//
// Immutable model + mutable workspace (as MuJoCo's mjModel/mjData): an InferenceMlp is built
// once from trained parameters (input normalisation folded into the first layer) and can be
// shared by threads; each thread or shield owns an InferenceMlp::Workspace sized for its largest
// batch, which holds every activation buffer; Eigen's GEMM packing buffers come from the stack
// (EIGEN_STACK_ALLOCATION_LIMIT is raised to 1 MiB project-wide, see CMakeLists.txt), so Forward()
// does not allocate. The calling thread needs about 1 MiB of stack for the widest layers.

#include <Eigen/Core>
#include <vector>

#include "secure/nn/mlp.h"

namespace secure::nn {

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
  };

  InferenceMlp() = default;
  /// Folds `normalizer` into the first layer: W' = W diag(1/scale), b' = b - W' mean.
  InferenceMlp(const MlpParams& params, const Normalizer& normalizer);

  int input_dim() const { return spec_.input_dim; }
  int output_dim() const { return spec_.output_dim; }
  const MlpSpec& spec() const { return spec_; }

  /// A workspace for batches of up to `max_batch` samples.
  Workspace MakeWorkspace(int max_batch) const;

  /// outputs (output_dim x N) = MLP(inputs (input_dim x N)). N <= workspace.max_batch().
  /// @throws secure::Error if the dimensions do not match.
  void Forward(const Eigen::Ref<const Eigen::MatrixXf>& inputs, Workspace& workspace,
               Eigen::Ref<Eigen::MatrixXf> outputs) const;

 private:
  MlpSpec spec_;
  std::vector<DenseLayer> layers_;  // normalisation folded into layers_[0]
  int max_width_ = 0;
};

}  // namespace secure::nn
