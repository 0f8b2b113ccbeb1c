#pragma once
// A trained barrier h(s) as a differentiable LibTorch function, for *training* code that
// optimises something else through a frozen barrier (policy::TrainAirlJoint's joint term). The
// barrier's own parameters are frozen; gradients flow to the states only.
//
// This header includes <torch/torch.h>, unlike every other public header of the library: it is
// part of the secure::cbf_train target and meant only for translation units that train (the
// policy trainers, tests). Evaluation code (the shield, validation, the CLI) uses cbf::Barrier.
//
// Implemented for both learned barrier models, with the same semantics as their Eigen
// evaluators (values agree to float rounding):
//   BarrierNet     the flat MLP on the whole (normalised) state;
//   CarBarrierNet  the per-car network, min over cars in range, capped (internal/
//                  car_barrier_torch.h: the mask carries no gradient, the minimum passes its
//                  gradient to the arg-min car, a state at the cap gets none).
//
//   std::unique_ptr<cbf::DifferentiableBarrier> h = cbf::MakeDifferentiableBarrier(net);
//   torch::Tensor states = ...;            // [N, h->state_dim()] float32, requires_grad
//   torch::Tensor values = h->Forward(states);   // [N]; values.sum().backward() reaches states
//
// Forward() changes no state, so one object may be shared by threads that only call it.

#include <torch/torch.h>

#include <memory>
#include <string>
#include <vector>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"

namespace secure::cbf {

class DifferentiableBarrier {
 public:
  virtual ~DifferentiableBarrier() = default;

  /// Number of values a state has.
  virtual int state_dim() const = 0;
  /// Short description for messages ("barrier_mlp 52-64-1 tanh (differentiable)").
  virtual std::string Describe() const = 0;

  /// h of every row of `states` [N, state_dim()] (float32) -> [N] (float32), differentiable
  /// w.r.t. `states`.
  /// @throws secure::Error on another shape or dtype.
  torch::Tensor Forward(const torch::Tensor& states) const;

 protected:
  /// Called with a checked [N, state_dim()] float32 tensor; returns [N].
  virtual torch::Tensor DoForward(const torch::Tensor& states) const = 0;
};

/// A copy of `net` (validated) as a frozen differentiable barrier.
std::unique_ptr<DifferentiableBarrier> MakeDifferentiableBarrier(const BarrierNet& net);
/// A copy of `net` (validated) as a frozen differentiable barrier.
std::unique_ptr<DifferentiableBarrier> MakeDifferentiableBarrier(const CarBarrierNet& net);
/// As BarrierNet::MakeEvaluatorFor: `net` on states whose rows are `state_features`, reading its
/// own features by name (the plain MakeDifferentiableBarrier(net) if they are equal).
/// @throws secure::Error as BarrierNet::MakeEvaluatorFor.
std::unique_ptr<DifferentiableBarrier> MakeDifferentiableBarrierFor(
    const BarrierNet& net, const std::vector<std::string>& state_features,
    const std::string& source, const std::string& model_name = "the model");

}  // namespace secure::cbf
