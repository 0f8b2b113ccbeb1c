#pragma once
// A differentiable LibTorch forward of a CarBarrierNet (car_barrier.h), for training: used by
// TrainCarBarrier and by trainers that optimise a policy through a frozen barrier. This header
// includes <torch/torch.h>; include it only from translation units that train (link
// secure::cbf_train).
//
// Same semantics as the Eigen evaluator (CarBarrierEvaluator): per-car features
// (dx, dy, sqrt(dx^2 + dy^2 + eps) - r [, dvx, dvy]), cars with d > R ignored (NaN distances count
// as in range), h(s) = min(cap, min over in-range cars of h_j), cap when no car is in range. The
// result is differentiable w.r.t. the observations (the mask itself carries no gradient; the
// minimum passes its gradient to the arg-min car, and a state at the cap gets none).
//
//   // Frozen barrier inside a policy loss:
//   auto barrier = cbf::internal::CarBarrierTorch(net);   // copies the weights
//   barrier->Freeze();                                    // no gradients into the barrier
//   torch::Tensor obs = ...;                              // [N, obs_dim] float32, requires_grad
//   torch::Tensor h = barrier->forward(obs);              // [N]; h.sum().backward() reaches obs

#include <torch/torch.h>

#include "secure/cbf/car_barrier.h"
#include "secure/nn/torch_mlp.h"

namespace secure::cbf::internal {

/// Per-car features of observations `obs` [N, obs_dim] (float32): features [N, K, F] (raw, not
/// normalised; differentiable w.r.t. obs) and in_range [N, K] (bool).
struct CarFeatureTensors {
  torch::Tensor features;
  torch::Tensor in_range;
};
CarFeatureTensors CarFeaturesTorch(const CarFeatureSpec& spec, const torch::Tensor& obs);

/// h(s) [N] = min(cap, min over in-range j of entry_h[:, j]) from entry_h [N, K] and in_range
/// [N, K] (bool). NaN entries propagate.
torch::Tensor CappedMinTorch(const torch::Tensor& entry_h, const torch::Tensor& in_range,
                             double cap);

class CarBarrierTorchImpl : public torch::nn::Module {
 public:
  /// A copy of a trained (or loaded) net; its parameters are trainable until Freeze().
  explicit CarBarrierTorchImpl(const CarBarrierNet& net);
  /// A fresh network of architecture `mlp_spec` (input = input.feature_dim(), one output), with
  /// weights from LibTorch's global generator (seed it first), for training.
  CarBarrierTorchImpl(const CarFeatureSpec& input, const nn::MlpSpec& mlp_spec,
                      const nn::Normalizer& normalizer, double cap);

  /// obs [N, obs_dim] (float32) -> h(s) [N].
  torch::Tensor forward(const torch::Tensor& obs);
  /// Per-car values from (un-normalised) features [..., F] -> [...] (all cars, in range or not).
  torch::Tensor EntryValues(const torch::Tensor& features);
  /// Per-car features of obs (as CarFeaturesTorch with this net's spec).
  CarFeatureTensors Features(const torch::Tensor& obs) const;

  /// requires_grad(false) on every parameter: gradients still flow to the observations.
  void Freeze();

  /// The current weights as a CarBarrierNet (feature spec, cap, normalizer; empty features and
  /// provenance).
  CarBarrierNet ToNet() const;
  /// Copies the MLP weights of `params` in (architecture must match).
  void LoadMlpParams(const nn::MlpParams& params);
  nn::MlpParams MlpParams() const { return mlp_->ToParams(); }

  const CarFeatureSpec& input() const { return input_; }
  double cap() const { return cap_; }

 private:
  CarFeatureSpec input_;
  double cap_;
  nn::Normalizer normalizer_;
  nn::TorchMlp mlp_{nullptr};
  torch::Tensor mean_, inv_scale_;  // buffers [F]
};
TORCH_MODULE(CarBarrierTorch);

}  // namespace secure::cbf::internal
