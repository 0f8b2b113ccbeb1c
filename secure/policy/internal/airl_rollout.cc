#include "secure/policy/internal/airl_rollout.h"

#include <algorithm>

namespace secure::policy::internal {

void CollectRollout(const GaussianPolicy& policy,
                    std::vector<std::unique_ptr<domains::Environment>>& envs, int horizon,
                    bool absorbing_goal, Rng& rng, RolloutBuffer& buffer,
                    AirlIterationStats& stats) {
  const int episodes = static_cast<int>(envs.size());
  const int obs_dim = static_cast<int>(buffer.obs.rows());
  const int act_dim = static_cast<int>(buffer.actions.rows());
  PolicyEvaluator evaluator(policy, std::max(1, episodes));
  const Eigen::VectorXf sigma = evaluator.sigma();
  std::vector<Rng> episode_rngs;
  for (int e = 0; e < episodes; ++e) episode_rngs.push_back(rng.Split());
  Eigen::MatrixXf current_obs(obs_dim, episodes), mus(act_dim, episodes);
  Eigen::VectorXf action(act_dim), next(obs_dim);
  std::vector<char> reached(episodes, 0), collided(episodes, 0);
  std::vector<int> live_steps(episodes, 0);  // each episode's steps before it was absorbed
  long collision_events = 0;
  for (int e = 0; e < episodes; ++e) envs[e]->Reset(episode_rngs[e], current_obs.col(e));
  for (int t = 0; t < horizon; ++t) {
    evaluator.Means(current_obs, mus);
    for (int e = 0; e < episodes; ++e) {
      const long column = static_cast<long>(e) * horizon + t;
      for (int i = 0; i < act_dim; ++i)
        action[i] = mus(i, e) + sigma[i] * static_cast<float>(episode_rngs[e].Normal());
      buffer.obs.col(column) = current_obs.col(e);
      buffer.actions.col(column) = action;
      if (absorbing_goal && reached[e]) {  // absorbed: the goal observation, frozen
        buffer.next_obs.col(column) = current_obs.col(e);
        continue;
      }
      const domains::StepOutcome outcome = envs[e]->Step(action, next);
      buffer.next_obs.col(column) = next;
      current_obs.col(e) = next;
      ++live_steps[e];
      reached[e] |= outcome.reached_goal;
      collided[e] |= outcome.collided;
      collision_events += outcome.collisions;
    }
  }
  // An episode's live steps are a prefix of its columns (once absorbed, it stays absorbed).
  buffer.live.clear();
  for (int e = 0; e < episodes; ++e)
    for (int t = 0; t < live_steps[e]; ++t)
      buffer.live.push_back(static_cast<long>(e) * horizon + t);
  stats.episodes = episodes;
  stats.success_rate =
      std::count(reached.begin(), reached.end(), 1) / static_cast<double>(episodes);
  stats.collision_rate =
      std::count(collided.begin(), collided.end(), 1) / static_cast<double>(episodes);
  stats.mean_collisions = static_cast<double>(collision_events) / episodes;
}

}  // namespace secure::policy::internal
