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

  void Resize(int obs_dim, int act_dim, long columns) {
    obs.resize(obs_dim, columns);
    next_obs.resize(obs_dim, columns);
    actions.resize(act_dim, columns);
  }
};

/// Runs one episode of `horizon` steps in each of `envs` (never stopped early) with `policy`'s
/// sampled actions into `buffer` (sized for envs.size() * horizon columns); episode e draws its
/// start and noise from the e-th of envs.size() streams split off `rng`. Sets the rollout
/// fields of `stats` (episodes, success_rate, collision_rate, mean_collisions).
void CollectRollout(const GaussianPolicy& policy,
                    std::vector<std::unique_ptr<domains::Environment>>& envs, int horizon, Rng& rng,
                    RolloutBuffer& buffer, AirlIterationStats& stats);

}  // namespace secure::policy::internal
