#include "secure/policy/internal/airl_discriminator.h"

#include <algorithm>
#include <limits>
#include <numeric>

#include "secure/nn/torch_mlp.h"

namespace secure::policy::internal {
namespace {

// Expert transitions in the D-on-expert statistic (a fixed random subset).
constexpr long kExpertStatTransitions = 2048;

}  // namespace

ExpertTransitions::ExpertTransitions(const data::TrajectorySet& demos) : demos_(demos) {
  for (long ep = 0; ep < demos.num_episodes(); ++ep)
    for (long c = demos.episode_begin[ep]; c + 1 < demos.episode_begin[ep + 1]; ++c) {
      cols_.push_back(c);
      next_cols_.push_back(c + 1);
    }
  count_ = static_cast<long>(cols_.size());
}

void ExpertTransitions::Build(const nn::Normalizer& normalizer, const std::vector<int>& rows,
                              std::uint64_t subset_seed) {
  x_ =
      nn::ToTensor(normalizer.Apply(PolicyInputs(data::SelectColumns(demos_.states, cols_), rows)));
  next_ = nn::ToTensor(
      normalizer.Apply(PolicyInputs(data::SelectColumns(demos_.states, next_cols_), rows)));
  a_ = nn::ToTensor(data::SelectColumns(demos_.actions, cols_));
  // A fixed random subset for the D-on-expert statistic.
  std::vector<std::int64_t> all(count_);
  std::iota(all.begin(), all.end(), std::int64_t{0});
  Rng rng(subset_seed);
  Shuffle(all.begin(), all.end(), rng);
  all.resize(std::min<long>(count_, kExpertStatTransitions));
  std::sort(all.begin(), all.end());
  stat_index_ = IndexTensor(all);
}

void UpdateDiscriminator(const AirlOptions& o, AirlDiscriminator& disc,
                         torch::optim::Adam& optimizer, TorchGaussian& policy,
                         const ExpertTransitions& expert, const torch::Tensor& x,
                         const torch::Tensor& x_next, const torch::Tensor& a, Rng& rng,
                         AirlIterationStats& stats) {
  const long n_policy = x.size(0);
  const int b = o.discriminator_batch;
  std::vector<std::int64_t> ie(b), ip(b);
  double loss_sum = 0.0;
  for (int k = 0; k < o.discriminator_updates; ++k) {
    for (int i = 0; i < b; ++i) ie[i] = static_cast<std::int64_t>(rng.UniformIndex(expert.count()));
    for (int i = 0; i < b; ++i) ip[i] = static_cast<std::int64_t>(rng.UniformIndex(n_policy));
    const torch::Tensor te = IndexTensor(ie), tp = IndexTensor(ip);
    const torch::Tensor xe = expert.x().index_select(0, te), xp = x.index_select(0, tp);
    torch::Tensor log_pi_e, log_pi_p;
    {
      torch::NoGradGuard no_grad;
      log_pi_e = policy->LogProb(xe, expert.a().index_select(0, te));
      log_pi_p = policy->LogProb(xp, a.index_select(0, tp));
    }
    const torch::Tensor fe = disc->F(xe, expert.next().index_select(0, te));
    const torch::Tensor fp = disc->F(xp, x_next.index_select(0, tp));
    // Mean cross-entropy over the 2b samples: expert label 1, policy label 0.
    const torch::Tensor loss = -0.5 * (LogD(fe, log_pi_e).mean() + Log1mD(fp, log_pi_p).mean());
    optimizer.zero_grad();
    loss.backward();
    optimizer.step();
    loss_sum += loss.item<double>();
  }
  stats.discriminator_loss = o.discriminator_updates > 0 ? loss_sum / o.discriminator_updates
                                                         : std::numeric_limits<double>::quiet_NaN();
  // D on a fixed subset of the expert transitions (a statistic; all of them would cost a
  // policy forward pass over the whole demonstration set every iteration).
  torch::NoGradGuard no_grad;
  const torch::Tensor xs = expert.x().index_select(0, expert.stat_index());
  const torch::Tensor fe = disc->F(xs, expert.next().index_select(0, expert.stat_index()));
  const torch::Tensor log_pi = policy->LogProb(xs, expert.a().index_select(0, expert.stat_index()));
  stats.d_expert = torch::exp(LogD(fe, log_pi)).mean().item<double>();
}

}  // namespace secure::policy::internal
