#include "secure/domains/demonstrations.h"

#include <utility>

#include "secure/common/error.h"

namespace secure::domains {

DemonstrationCollector::DemonstrationCollector(std::string source,
                                               std::vector<std::string> state_features,
                                               std::vector<std::string> action_features,
                                               long reserve_steps) {
  set_.source = std::move(source);
  set_.state_features = std::move(state_features);
  set_.action_features = std::move(action_features);
  set_.episode_begin.push_back(0);
  state_dim_ = static_cast<Eigen::Index>(set_.state_features.size());
  action_dim_ = static_cast<Eigen::Index>(set_.action_features.size());
  if (reserve_steps > 0) {
    states_.reserve(static_cast<std::size_t>(reserve_steps * state_dim_));
    actions_.reserve(static_cast<std::size_t>(reserve_steps * action_dim_));
  }
}

void DemonstrationCollector::BeginEpisode() {
  episode_states_.clear();
  episode_actions_.clear();
}

void DemonstrationCollector::Record(const Eigen::Ref<const Eigen::VectorXf>& state,
                                    const Eigen::Ref<const Eigen::VectorXf>& action) {
  SECURE_CHECK(state.size() == state_dim_ && action.size() == action_dim_,
               set_.source << ": a step of " << state.size() << " state and " << action.size()
                           << " action values, expected " << state_dim_ << " and " << action_dim_);
  episode_states_.insert(episode_states_.end(), state.data(), state.data() + state_dim_);
  episode_actions_.insert(episode_actions_.end(), action.data(), action.data() + action_dim_);
}

long DemonstrationCollector::episode_steps() const {
  return state_dim_ > 0 ? static_cast<long>(episode_states_.size() / state_dim_) : 0;
}

long DemonstrationCollector::kept_steps() const { return set_.episode_begin.back(); }

long DemonstrationCollector::KeepEpisode() {
  const long first = kept_steps();
  const long steps = episode_steps();
  states_.insert(states_.end(), episode_states_.begin(), episode_states_.end());
  actions_.insert(actions_.end(), episode_actions_.begin(), episode_actions_.end());
  set_.episode_begin.push_back(first + steps);
  BeginEpisode();
  return first;
}

data::TrajectorySet DemonstrationCollector::Finish() const {
  data::TrajectorySet out = set_;
  const Eigen::Index steps = kept_steps();
  out.states = Eigen::Map<const Eigen::MatrixXf>(states_.data(), state_dim_, steps);
  out.actions = Eigen::Map<const Eigen::MatrixXf>(actions_.data(), action_dim_, steps);
  return out;
}

bool KeepOrCountDiscarded(bool dangerous, bool reached_goal, long* discarded_dangerous,
                          long* discarded_failed) {
  if (dangerous) {
    ++*discarded_dangerous;
    return false;
  }
  if (!reached_goal) {
    ++*discarded_failed;
    return false;
  }
  return true;
}

Rng AttemptRng(std::uint64_t seed, long attempt, std::uint64_t salt) {
  return Rng(seed ^ (0xd1b54a32d192ed03ULL * static_cast<std::uint64_t>(attempt + 1)) ^ salt);
}

void CheckAllKept(const std::string& generator, const std::string& option, long kept, long wanted,
                  long attempted, long discarded_collisions, long discarded_no_goal) {
  SECURE_CHECK(kept == wanted, generator << ": kept " << kept << " of " << option << " = "
                                         << wanted << " demonstrations after " << attempted
                                         << " attempts (" << discarded_collisions << " collided, "
                                         << discarded_no_goal << " never reached the goal)");
}

}  // namespace secure::domains
