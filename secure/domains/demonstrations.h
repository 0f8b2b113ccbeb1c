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
//
// RecordEpisode runs one episode of a demonstrator into a collector: the step loop with its
// stops (a collision; the goal, if the generator stops there) that the generators share.
// KeepReachingEpisodes is the two CBF-QP experts' attempt loop around it, AttemptRng the stream
// of one attempt.
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/domains/environment.h"
#include "secure/domains/filtering_expert.h"

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

/// How a recorded episode ended.
struct RecordedEpisode {
  bool collided = false;  // a step collided (the episode stopped there)
  int reached_at = 0;     // the first step (1, 2, ...) whose outcome reached the goal; 0 = never
};

/// What the generators that keep only the episodes that reached the goal without a dangerous
/// event do with an attempt: true to keep it; otherwise it is counted in *discarded_dangerous
/// (it had a dangerous event: a collision, a topple, a violation) or else in *discarded_failed
/// (it never reached the goal).
bool KeepOrCountDiscarded(bool dangerous, bool reached_goal, long* discarded_dangerous,
                          long* discarded_failed);
/// The same for a recorded episode (collided; reached_at > 0).
inline bool KeepOrCountDiscarded(const RecordedEpisode& episode, long* discarded_dangerous,
                                 long* discarded_failed) {
  return KeepOrCountDiscarded(episode.collided, episode.reached_at > 0, discarded_dangerous,
                              discarded_failed);
}

/// The expert generators' require_all check: @throws secure::Error "<generator>: kept K of
/// <option> = N demonstrations after A attempts (C collided, G never reached the goal)" if
/// `kept` < `wanted`.
void CheckAllKept(const std::string& generator, const std::string& option, long kept, long wanted,
                  long attempted, long discarded_collisions, long discarded_no_goal);

/// Records one episode of a demonstrator in `collector` (BeginEpisode first), from `observation`
/// (the environment's state after its Reset; updated in place): for step = 1, ..., horizon,
/// `act(observation, action, recorded)` sets the action to step with and the one to record (the
/// action the environment applies, e.g. clipped; it may be `action` itself), then Record, Step,
/// and `after_step(outcome)`. Stops at a collision, and with stop_at_goal at the first step that
/// reaches the goal. The demonstrator, its noise and what to keep stay the caller's.
template <typename Env, typename Observation, typename Action, typename Act, typename AfterStep>
RecordedEpisode RecordEpisode(Env& environment, DemonstrationCollector& collector, int horizon,
                              bool stop_at_goal, Observation& observation, Action& action,
                              Action& recorded, Act&& act, AfterStep&& after_step) {
  collector.BeginEpisode();
  RecordedEpisode episode;
  for (int step = 1; step <= horizon; ++step) {
    act(observation, action, recorded);
    collector.Record(observation, recorded);
    const StepOutcome outcome = environment.Step(action, observation);
    after_step(outcome);
    if (outcome.collided) {
      episode.collided = true;
      break;
    }
    if (outcome.reached_goal && episode.reached_at == 0) {
      episode.reached_at = step;
      if (stop_at_goal) break;
    }
  }
  return episode;
}

/// The stream of attempt `attempt` (0, 1, ...) of a demonstration run with `seed`: the seed and
/// the index mixed (Rng::Seed runs splitmix64 over the result), then xor `salt` (a generator's
/// own, so that two generators with one seed draw different worlds).
Rng AttemptRng(std::uint64_t seed, long attempt, std::uint64_t salt = 0);

/// How many demonstrations an expert generator keeps, in how many attempts, and what a shortfall
/// says (CheckAllKept's generator and option names).
struct AttemptPlan {
  std::string generator;  // "GenerateDemonstrations"
  std::string option;     // "DemonstrationOptions::episodes"
  long episodes = 0;      // to keep
  long max_attempts = 0;  // attempts at most
  bool require_all = true;
};

/// The CBF-QP experts' attempt loop: until plan.episodes are kept or plan.max_attempts made,
/// `run(attempt)` records attempt `attempt` (0, 1, ...; counted in counts.attempted) in
/// `collector` and returns how it ended. An attempt is kept if it reached the goal without a
/// collision (KeepOrCountDiscarded into counts); a kept one adds its first step in the goal to
/// counts.steps_to_goal, calls `on_keep(attempt)` and keeps the collector's episode. Then, with
/// plan.require_all, CheckAllKept. Returns the episodes kept.
template <typename Run, typename OnKeep>
long KeepReachingEpisodes(const AttemptPlan& plan, DemonstrationCollector& collector,
                          ExpertDemonstrationCounts& counts, Run&& run, OnKeep&& on_keep) {
  long kept = 0;
  while (kept < plan.episodes && counts.attempted < plan.max_attempts) {
    const long attempt = counts.attempted++;
    const RecordedEpisode episode = run(attempt);
    // Kept: reached the goal (its first step there: reached_at) without a collision (which
    // stopped the episode).
    if (!KeepOrCountDiscarded(episode, &counts.discarded_collisions, &counts.discarded_no_goal))
      continue;
    ++kept;
    counts.steps_to_goal.push_back(episode.reached_at);
    on_keep(attempt);
    collector.KeepEpisode();
  }
  if (plan.require_all)
    CheckAllKept(plan.generator, plan.option, kept, plan.episodes, counts.attempted,
                 counts.discarded_collisions, counts.discarded_no_goal);
  return kept;
}

}  // namespace secure::domains
