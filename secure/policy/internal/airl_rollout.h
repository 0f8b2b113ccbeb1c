#pragma once
// AIRL's rollout collection: fixed-horizon episodes of the current policy in lock-step, one
// batched Eigen mean evaluation per time step (no LibTorch). INTERNAL: include it only from
// secure/policy/*.cc.

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "secure/common/rng.h"
#include "secure/domains/environment.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/gaussian_policy.h"

namespace secure::policy::internal {

/// One iteration's transitions, (dim x episodes * horizon), episode-major: column
/// e * horizon + t is step t of episode e.
struct RolloutBuffer {
  Eigen::MatrixXf obs, next_obs, actions;
  // The columns of steps taken before the goal was reached, in order (every column unless
  // absorbing_goal froze some): the discriminator's policy transitions.
  std::vector<long> live;

  void Resize(int obs_dim, int act_dim, long columns) {
    obs.resize(obs_dim, columns);
    next_obs.resize(obs_dim, columns);
    actions.resize(act_dim, columns);
    live.reserve(static_cast<size_t>(columns));
  }
};

/// Runs one episode of `horizon` steps in each of `envs` (never stopped early) with `policy`'s
/// sampled actions into `buffer` (sized for envs.size() * horizon columns); episode e draws its
/// start and noise from the e-th of envs.size() streams split off `rng`. With `absorbing_goal`,
/// the steps after the one that reached the goal record the goal observation frozen (obs =
/// next_obs, no environment step; the action is still drawn) and are left out of buffer.live.
/// Sets the rollout fields of `stats` (episodes, success_rate, collision_rate,
/// mean_collisions).
void CollectRollout(const GaussianPolicy& policy,
                    std::vector<std::unique_ptr<domains::Environment>>& envs, int horizon,
                    bool absorbing_goal, Rng& rng, RolloutBuffer& buffer,
                    AirlIterationStats& stats);

}  // namespace secure::policy::internal
