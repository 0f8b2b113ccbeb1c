#pragma once
// AIRL's generator step: the policy reward from the discriminator, its running normalisation,
// GAE and the PPO update (with the optional behaviour-cloning, entropy and joint-CBF terms).
// INTERNAL: includes <torch/torch.h>; include it only from secure/policy/*.cc.

#include <torch/torch.h>

#include <cmath>
#include <vector>

#include "secure/common/rng.h"
#include "secure/nn/torch_mlp.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/internal/airl_discriminator.h"
#include "secure/policy/internal/joint_cbf_term.h"
#include "secure/policy/internal/torch_policy.h"

namespace secure::policy::internal {

/// Running mean and variance (Chan et al.'s parallel merge), for reward normalisation.
struct RunningStat {
  double count = 0.0, mean = 0.0, m2 = 0.0;

  void AddBatch(const std::vector<double>& xs);
  double Std() const { return count > 1 ? std::sqrt(m2 / count) : 1.0; }
};

/// The networks and optimisers PPO updates, and the (frozen) discriminator it takes rewards
/// from.
struct PpoNets {
  TorchGaussian& policy;
  nn::TorchMlp& value;
  AirlDiscriminator& disc;
  torch::optim::Adam& policy_opt;
  torch::optim::Adam& value_opt;
};

/// One PPO update on a rollout of `episodes` x `horizon` transitions (x, x_next normalised, a;
/// episode-major rows): rewards (o.reward) from `nets.disc`, divided by the running std of the
/// discounted return in `reward_stat` (o.normalize_rewards), GAE(gamma, lambda) with the
/// value bootstrapped at the horizon, then o.ppo_epochs passes of shuffled minibatches from
/// `rng`. `joint` (may be null; prepared for this rollout) adds its weighted L_cbf to every
/// policy loss. Sets stats.d_policy, mean_reward, policy_loss, value_loss, bc_nll, approx_kl,
/// clip_fraction, entropy and mean_sigma.
void PpoUpdate(const AirlOptions& o, int episodes, int horizon, const PpoNets& nets,
               const ExpertTransitions& expert, JointCbfTerm* joint, RunningStat& reward_stat,
               const torch::Tensor& x, const torch::Tensor& x_next, const torch::Tensor& a,
               Rng& rng, AirlIterationStats& stats);

}  // namespace secure::policy::internal
