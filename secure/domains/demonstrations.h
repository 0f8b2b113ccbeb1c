#pragma once
// What every domain's demonstration generator shares (the double integrator's and Derby's
// experts, the Franka plug-ins' scripted demonstrators): the steps of the episode under way,
// dropped unless the episode is kept (the generator decides: reached the goal, no collision, ...),
// and the kept episodes in order as one data::TrajectorySet. The demonstrator, its noise and what
// makes an episode worth keeping stay the domain's.
//
//   DemonstrationCollector c("expert demonstrations (seed 7)", StateFeatures(), ActionFeatures());
//   for (...) {                       // attempts
//     c.BeginEpisode();
//     ... c.Record(observation, applied_action); ...
//     if (good) c.KeepEpisode();
//   }
//   data::TrajectorySet set = c.Finish();
#include <Eigen/Core>
#include <string>
#include <vector>

#include "secure/data/data.h"

namespace secure::domains {

class DemonstrationCollector {
 public:
  /// The set's source (one line) and its columns' names (their counts are the dimensions).
  /// `reserve_steps`: kept steps to make room for at once.
  DemonstrationCollector(std::string source, std::vector<std::string> state_features,
                         std::vector<std::string> action_features, long reserve_steps = 0);

  /// Starts an episode: the steps of one not kept are dropped.
  void BeginEpisode();
  /// One step of the episode: the state the action was taken in, and the action applied.
  /// @throws secure::Error if a dimension differs from the features'.
  void Record(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::VectorXf>& action);
  /// Steps recorded in the episode so far.
  long episode_steps() const;
  /// Keeps the episode (and starts the next). Returns the column of its first step in the set.
  long KeepEpisode();
  /// Steps in the kept episodes.
  long kept_steps() const;
  /// The kept episodes in order.
  data::TrajectorySet Finish() const;

 private:
  data::TrajectorySet set_;  // source, features, episode_begin
  Eigen::Index state_dim_ = 0, action_dim_ = 0;
  std::vector<float> states_, actions_;                  // kept, column-major
  std::vector<float> episode_states_, episode_actions_;  // the episode under way
};

}  // namespace secure::domains
