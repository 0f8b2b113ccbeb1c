#pragma once
// LibTorch pieces shared by the BC and AIRL trainers (and their test): a Gaussian policy module,
// Gaussian log-densities, the AIRL discriminator and reward. INTERNAL: includes <torch/torch.h>;
// include it only from secure/policy/*.cc (the trainers and their internal/ parts) and
// tests/policy/trainers_test.cc.
//
// Tensors are (N x dim), one sample per row; networks take *normalised* observations (the
// normaliser is applied once on the Eigen side, nn::Normalizer::Apply, before ToTensor).
#include <torch/torch.h>

#include <cmath>
#include <cstdint>

#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/nn/torch_mlp.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/gaussian_policy.h"

namespace secure::policy::internal {

/// log N(actions; mu, diag(exp(log_std)^2)) per row: mu, actions (N x d), log_std (d) -> (N).
inline torch::Tensor GaussianLogProb(const torch::Tensor& mu, const torch::Tensor& log_std,
                                     const torch::Tensor& actions) {
  const torch::Tensor z = (actions - mu) * torch::exp(-log_std);
  return (-0.5 * z * z - log_std).sum(1) - 0.5 * std::log(2.0 * M_PI) * mu.size(1);
}

/// Entropy of N(., diag(exp(log_std)^2)): sum(log_std) + d/2 (1 + log 2 pi).
inline torch::Tensor GaussianEntropy(const torch::Tensor& log_std) {
  return log_std.sum() + 0.5 * (1.0 + std::log(2.0 * M_PI)) * log_std.size(0);
}

/// A Gaussian policy for training: the mean MLP (registered as "mean") and a log_std parameter
/// ("log_std"), clamped below at min_log_std when used.
class TorchGaussianImpl : public torch::nn::Module {
 public:
  TorchGaussianImpl(const nn::MlpParams& mean_params, const Eigen::VectorXf& log_std_init,
                    double min_log_std)
      : mean(register_module("mean", nn::TorchMlp(mean_params))), min_log_std_(min_log_std) {
    SECURE_INTERNAL_CHECK(log_std_init.size() == mean_params.spec.output_dim, "log_std size");
    log_std =
        register_parameter("log_std", torch::from_blob(const_cast<float*>(log_std_init.data()),
                                                       {log_std_init.size()}, torch::kFloat32)
                                          .clone());
  }

  /// Mean actions of normalised observations (N x obs_dim) -> (N x act_dim).
  torch::Tensor Mean(const torch::Tensor& x) { return mean->forward(x); }
  /// log_std clamped to >= min_log_std (the gradient is zero below the clamp).
  torch::Tensor LogStd() { return torch::clamp_min(log_std, min_log_std_); }
  torch::Tensor LogProb(const torch::Tensor& x, const torch::Tensor& actions) {
    return GaussianLogProb(Mean(x), LogStd(), actions);
  }

  /// The current weights as a GaussianPolicy (log_std clamped); features and provenance empty.
  GaussianPolicy Export(const nn::Normalizer& input) {
    torch::NoGradGuard no_grad;
    GaussianPolicy p;
    p.mean = mean->ToParams();
    p.input = input;
    const torch::Tensor ls = LogStd().detach().contiguous();
    p.log_std = Eigen::Map<const Eigen::VectorXf>(ls.data_ptr<float>(), ls.size(0));
    return p;
  }

  nn::TorchMlp mean{nullptr};
  torch::Tensor log_std;

 private:
  double min_log_std_;
};
TORCH_MODULE(TorchGaussian);

/// The AIRL discriminator's f(s, s') = g(s) + discount V(s') - V(s) on normalised observations
/// (N x obs_dim) -> (N). Submodules "reward" (g) and "shaping" (V).
class AirlDiscriminatorImpl : public torch::nn::Module {
 public:
  AirlDiscriminatorImpl(const nn::MlpParams& reward_params, const nn::MlpParams& shaping_params,
                        double discount)
      : reward(register_module("reward", nn::TorchMlp(reward_params))),
        shaping(register_module("shaping", nn::TorchMlp(shaping_params))),
        discount_(discount) {}

  torch::Tensor G(const torch::Tensor& x) { return reward->forward(x).squeeze(1); }
  torch::Tensor F(const torch::Tensor& x, const torch::Tensor& x_next) {
    return G(x) + discount_ * shaping->forward(x_next).squeeze(1) - shaping->forward(x).squeeze(1);
  }

  nn::TorchMlp reward{nullptr}, shaping{nullptr};

 private:
  double discount_;
};
TORCH_MODULE(AirlDiscriminator);

/// log D and log(1 - D) for D = exp(f) / (exp(f) + pi), computed without overflow.
inline torch::Tensor LogD(const torch::Tensor& f, const torch::Tensor& log_pi) {
  return f - torch::logaddexp(f, log_pi);
}
inline torch::Tensor Log1mD(const torch::Tensor& f, const torch::Tensor& log_pi) {
  return log_pi - torch::logaddexp(f, log_pi);
}

/// The policy reward: kLogitD: log D - log(1 - D) (= f - log pi); kStateReward: g(s).
inline torch::Tensor AirlPolicyReward(AirlReward kind, const torch::Tensor& f,
                                      const torch::Tensor& g, const torch::Tensor& log_pi) {
  if (kind == AirlReward::kStateReward) return g;
  return LogD(f, log_pi) - Log1mD(f, log_pi);
}

/// Parameters for `spec` drawn from secure::Rng (Glorot-uniform weights, nn::RandomMlpParams).
inline nn::MlpParams InitialParams(const nn::MlpSpec& spec, std::uint64_t seed,
                                   double last_layer_scale = 1.0, bool zero_last_bias = false) {
  nn::MlpParams p = nn::RandomMlpParams(spec, seed);
  p.layers.back().weight *= static_cast<float>(last_layer_scale);
  if (zero_last_bias) p.layers.back().bias.setZero();
  return p;
}

/// Independent seeds for the parts of a run from one user seed.
inline std::uint64_t DeriveSeed(std::uint64_t seed, std::uint64_t salt) {
  Rng rng(seed ^ (0x9e3779b97f4a7c15ULL * (salt + 1)));
  return rng.NextU64();
}

/// (N) int64 tensor of indices (a copy).
inline torch::Tensor IndexTensor(const std::vector<std::int64_t>& indices) {
  return torch::tensor(indices, torch::kInt64);
}

}  // namespace secure::policy::internal
