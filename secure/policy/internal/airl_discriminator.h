#pragma once
// AIRL's discriminator (reward) training and its data: the expert transitions. INTERNAL:
// includes <torch/torch.h>; include it only from secure/policy/*.cc.

#include <torch/torch.h>

#include <cstdint>
#include <vector>

#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/nn/mlp.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/internal/torch_policy.h"

namespace secure::policy::internal {

/// The expert transitions (s_t, a_t, s_{t+1}): consecutive rows within each demonstration
/// episode (each episode's last row has no successor and is dropped). Used by the
/// discriminator (label 1) and by PPO's behaviour-cloning term.
class ExpertTransitions {
 public:
  explicit ExpertTransitions(const data::TrajectorySet& demos);

  /// (Re)builds the tensors with `normalizer` (x, next: the state rows `rows`, all if empty,
  /// normalised; a raw) and the fixed random subset of up to 2048 transitions of the D-on-expert
  /// statistic, shuffled with `subset_seed`.
  void Build(const nn::Normalizer& normalizer, const std::vector<int>& rows,
             std::uint64_t subset_seed);

  long count() const { return count_; }
  const torch::Tensor& x() const { return x_; }        // (count x obs), normalised s_t
  const torch::Tensor& next() const { return next_; }  // (count x obs), normalised s_{t+1}
  const torch::Tensor& a() const { return a_; }        // (count x act), a_t
  const torch::Tensor& stat_index() const { return stat_index_; }  // the statistic's subset

 private:
  const data::TrajectorySet& demos_;
  long count_ = 0;
  std::vector<long> cols_, next_cols_;
  torch::Tensor x_, next_, a_, stat_index_;
};

/// `o.discriminator_updates` Adam steps of the discriminator's cross-entropy on minibatches of
/// `o.discriminator_batch` expert and as many policy transitions (x, x_next normalised, a; one
/// row per transition), drawn uniformly with replacement from `rng`, log pi from the current
/// `policy`. Sets stats.discriminator_loss (mean over the updates) and stats.d_expert (mean D on
/// the expert statistic's subset after the updates).
void UpdateDiscriminator(const AirlOptions& o, AirlDiscriminator& disc,
                         torch::optim::Adam& optimizer, TorchGaussian& policy,
                         const ExpertTransitions& expert, const torch::Tensor& x,
                         const torch::Tensor& x_next, const torch::Tensor& a, Rng& rng,
                         AirlIterationStats& stats);

}  // namespace secure::policy::internal
