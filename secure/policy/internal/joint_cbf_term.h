#pragma once
// The joint-optimisation term of TrainAirlJoint (airl_trainer.h, JointCbfOptions): the
// barrier's derivative condition as a loss on reparameterised policy actions, through a frozen
// differentiable barrier and the shield's dynamics model linearised in the action. INTERNAL:
// includes <torch/torch.h>; include it only from secure/policy/*.cc (and the policy tests).

#include <torch/torch.h>

#include <Eigen/Core>

#include "secure/cbf/differentiable_barrier.h"
#include "secure/domains/dynamics.h"
#include "secure/policy/airl_trainer.h"

namespace secure::policy::internal {

class JointCbfTerm {
 public:
  /// `barrier` and `model` must outlive the term; their dimensions are the caller's to check.
  JointCbfTerm(const JointCbfOptions& options, const cbf::DifferentiableBarrier& barrier,
               const domains::DynamicsModel& model)
      : options_(options), barrier_(&barrier), model_(&model) {}

  /// For the rollout states `states` (raw observations, obs x n): T(s, 0), dT/da (by unit
  /// actions: exact for models affine in the action) and h(s), without gradient. Resets the
  /// loss statistic.
  void Prepare(const Eigen::MatrixXf& states, int action_dim);

  /// L_cbf (a scalar) on the prepared rows `idx` (int64, m) for actions `actions` (m x act,
  /// differentiable, e.g. reparameterised samples of the policy); adds it to the statistic.
  torch::Tensor Loss(const torch::Tensor& idx, const torch::Tensor& actions);

  const JointCbfOptions& options() const { return options_; }
  /// Mean L_cbf over the Loss() calls since Prepare() (0 if none).
  double MeanLoss() const { return batches_ > 0 ? loss_sum_ / batches_ : 0.0; }

 private:
  JointCbfOptions options_;
  const cbf::DifferentiableBarrier* barrier_;
  const domains::DynamicsModel* model_;
  torch::Tensor base_, jacobian_, h_state_;  // (n x obs), (n x act x obs), (n)
  double loss_sum_ = 0.0;
  long batches_ = 0;
};

}  // namespace secure::policy::internal
