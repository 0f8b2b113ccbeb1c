#include "secure/policy/internal/airl_ppo.h"

#include <algorithm>
#include <cstdint>
#include <limits>
#include <numeric>

namespace secure::policy::internal {

void RunningStat::AddBatch(const std::vector<double>& xs) {
  if (xs.empty()) return;
  double bm = 0.0;
  for (double x : xs) bm += x;
  bm /= static_cast<double>(xs.size());
  double bm2 = 0.0;
  for (double x : xs) bm2 += (x - bm) * (x - bm);
  const double bn = static_cast<double>(xs.size());
  const double delta = bm - mean;
  const double total = count + bn;
  mean += delta * bn / total;
  m2 += bm2 + delta * delta * count * bn / total;
  count = total;
}

void PpoUpdate(const AirlOptions& o, int episodes, int horizon, const PpoNets& nets,
               const ExpertTransitions& expert, JointCbfTerm* joint, RunningStat& reward_stat,
               const torch::Tensor& x, const torch::Tensor& x_next, const torch::Tensor& a,
               Rng& rng, AirlIterationStats& stats) {
  const long n = x.size(0);
  const int act_dim = static_cast<int>(a.size(1));
  torch::Tensor old_log_pi, rewards, values, last_values;
  {
    torch::NoGradGuard no_grad;
    old_log_pi = nets.policy->LogProb(x, a);
    const torch::Tensor f = nets.disc->F(x, x_next);
    stats.d_policy = torch::exp(LogD(f, old_log_pi)).mean().item<double>();
    rewards =
        AirlPolicyReward(o.reward, f, nets.disc->G(x), old_log_pi).to(torch::kFloat64).contiguous();
    values = nets.value->forward(x).squeeze(1).to(torch::kFloat64).contiguous();
    // V of the state after each episode's last step: the bootstrap at the time limit.
    std::vector<std::int64_t> last(episodes);
    for (int e = 0; e < episodes; ++e) last[e] = static_cast<std::int64_t>(e + 1) * horizon - 1;
    last_values = nets.value->forward(x_next.index_select(0, IndexTensor(last)))
                      .squeeze(1)
                      .to(torch::kFloat64)
                      .contiguous();
  }
  const double* r = rewards.data_ptr<double>();
  const double* v = values.data_ptr<double>();
  const double* v_last = last_values.data_ptr<double>();
  stats.mean_reward = rewards.mean().item<double>();

  // Reward scale: running std of the discounted return within each episode.
  double scale = 1.0;
  if (o.normalize_rewards) {
    std::vector<double> returns(n);
    for (int e = 0; e < episodes; ++e) {
      double ret = 0.0;
      for (int t = 0; t < horizon; ++t) {
        const long i = static_cast<long>(e) * horizon + t;
        ret = o.gamma * ret + r[i];
        returns[i] = ret;
      }
    }
    reward_stat.AddBatch(returns);
    scale = 1.0 / std::max(reward_stat.Std(), 1e-8);
  }

  // GAE(gamma, lambda) per episode; the episode is truncated, not terminated, at the horizon.
  std::vector<float> advantages(n), targets(n);
  for (int e = 0; e < episodes; ++e) {
    double gae = 0.0;
    for (int t = horizon - 1; t >= 0; --t) {
      const long i = static_cast<long>(e) * horizon + t;
      const double next_value = t == horizon - 1 ? v_last[e] : v[i + 1];
      const double delta = r[i] * scale + o.gamma * next_value - v[i];
      gae = delta + o.gamma * o.gae_lambda * gae;
      advantages[i] = static_cast<float>(gae);
      targets[i] = static_cast<float>(gae + v[i]);
    }
  }
  double mean = 0.0, var = 0.0;
  for (float adv : advantages) mean += adv;
  mean /= static_cast<double>(n);
  for (float adv : advantages) var += (adv - mean) * (adv - mean);
  const double sd = std::sqrt(var / static_cast<double>(n)) + 1e-8;
  for (float& adv : advantages) adv = static_cast<float>((adv - mean) / sd);
  const torch::Tensor adv_t = torch::from_blob(advantages.data(), {n}, torch::kFloat32).clone();
  const torch::Tensor target_t = torch::from_blob(targets.data(), {n}, torch::kFloat32).clone();

  std::vector<std::int64_t> order(n);
  std::iota(order.begin(), order.end(), std::int64_t{0});
  const std::vector<torch::Tensor> policy_params = nets.policy->parameters();
  const std::vector<torch::Tensor> value_params = nets.value->parameters();
  double policy_loss_sum = 0.0, value_loss_sum = 0.0, kl_sum = 0.0, clipped_sum = 0.0;
  double bc_nll_sum = 0.0;
  long batches = 0, last_epoch_samples = 0;
  for (int epoch = 0; epoch < o.ppo_epochs; ++epoch) {
    const bool last_epoch = epoch + 1 == o.ppo_epochs;
    Shuffle(order.begin(), order.end(), rng);
    const torch::Tensor perm = torch::from_blob(order.data(), {n}, torch::kInt64);
    for (long first = 0; first < n; first += o.minibatch_size) {
      const long m = std::min<long>(o.minibatch_size, n - first);
      const torch::Tensor idx = perm.slice(0, first, first + m);
      const torch::Tensor xb = x.index_select(0, idx);
      const torch::Tensor adv = adv_t.index_select(0, idx);
      const torch::Tensor log_ratio =
          nets.policy->LogProb(xb, a.index_select(0, idx)) - old_log_pi.index_select(0, idx);
      const torch::Tensor ratio = torch::exp(log_ratio);
      const torch::Tensor surrogate =
          -torch::min(ratio * adv, torch::clamp(ratio, 1.0 - o.clip, 1.0 + o.clip) * adv).mean();
      torch::Tensor policy_loss = surrogate;
      if (joint != nullptr && joint->options().weight > 0) {
        Eigen::MatrixXf eps(act_dim, m);
        for (long c = 0; c < m; ++c)
          for (int k = 0; k < act_dim; ++k) eps(k, c) = static_cast<float>(rng.Normal());
        const torch::Tensor sampled =
            nets.policy->Mean(xb) + torch::exp(nets.policy->LogStd()) * nn::ToTensor(eps);
        policy_loss = policy_loss + joint->options().weight * joint->Loss(idx, sampled);
      }
      if (o.bc_weight > 0) {
        std::vector<std::int64_t> ie(static_cast<std::size_t>(m));
        for (auto& k : ie) k = static_cast<std::int64_t>(rng.UniformIndex(expert.count()));
        const torch::Tensor te = IndexTensor(ie);
        const torch::Tensor bc_nll =
            -nets.policy->LogProb(expert.x().index_select(0, te), expert.a().index_select(0, te))
                 .mean();
        policy_loss = policy_loss + o.bc_weight * bc_nll;
        bc_nll_sum += bc_nll.item<double>();
      }
      if (o.entropy_coef > 0)
        policy_loss = policy_loss - o.entropy_coef * GaussianEntropy(nets.policy->LogStd());
      nets.policy_opt.zero_grad();
      policy_loss.backward();
      if (o.max_grad_norm > 0) torch::nn::utils::clip_grad_norm_(policy_params, o.max_grad_norm);
      nets.policy_opt.step();

      const torch::Tensor value_loss =
          (nets.value->forward(xb).squeeze(1) - target_t.index_select(0, idx)).pow(2).mean();
      nets.value_opt.zero_grad();
      value_loss.backward();
      if (o.max_grad_norm > 0) torch::nn::utils::clip_grad_norm_(value_params, o.max_grad_norm);
      nets.value_opt.step();

      policy_loss_sum += surrogate.item<double>();
      value_loss_sum += value_loss.item<double>();
      ++batches;
      if (last_epoch) {
        torch::NoGradGuard no_grad;
        const torch::Tensor lr = log_ratio.detach();
        kl_sum += ((torch::exp(lr) - 1.0) - lr).sum().item<double>();
        clipped_sum +=
            ((torch::exp(lr) - 1.0).abs() > o.clip).to(torch::kFloat64).sum().item<double>();
        last_epoch_samples += m;
      }
    }
  }
  stats.policy_loss = policy_loss_sum / std::max(1L, batches);
  stats.bc_nll = o.bc_weight > 0 ? bc_nll_sum / std::max(1L, batches)
                                 : std::numeric_limits<double>::quiet_NaN();
  stats.value_loss = value_loss_sum / std::max(1L, batches);
  stats.approx_kl = kl_sum / std::max(1L, last_epoch_samples);
  stats.clip_fraction = clipped_sum / std::max(1L, last_epoch_samples);
  torch::NoGradGuard no_grad;
  const torch::Tensor log_std = nets.policy->LogStd();
  stats.entropy = GaussianEntropy(log_std).item<double>();
  stats.mean_sigma = torch::exp(log_std).mean().item<double>();
}

}  // namespace secure::policy::internal
