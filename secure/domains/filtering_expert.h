#pragma once
// What the two CBF-QP experts (the double integrator's and Derby's, domains/*/expert.h) share:
// their counts and the step after the nominal action (exploration noise, then the safety filter
// or clipping), and what their demonstration generators count. The nominal controller and the
// filter stay the domain's.
#include <Eigen/Core>
#include <vector>

#include "secure/common/rng.h"

namespace secure::domains {

/// Counts over a filtering expert's Act() calls since its construction or last ResetStats().
struct ExpertFilterStats {
  long steps = 0;
  long modified = 0;    // the filter changed the (clipped) nominal action
  long infeasible = 0;  // no action met the filter's condition (the expert's fallback was used)
};

/// What the two experts' demonstration generators report besides the trajectories (their
/// Demonstrations structs add their own): filled by KeepReachingEpisodes (demonstrations.h), the
/// filter's counts and the wall time by the generator.
struct ExpertDemonstrationCounts {
  long attempted = 0;
  long discarded_collisions = 0;  // collided at least once (the episode stopped there)
  long discarded_no_goal = 0;     // did not collide but never reached the goal
  // For each kept demonstration, the first step (1-based) whose state is in the goal.
  std::vector<int> steps_to_goal;
  ExpertFilterStats expert;  // the filter's counts over all attempts
  double seconds = 0.0;      // wall time
};

/// The step after the nominal action: `a` plus N(0, noise_sigma^2) per axis (drawn in axis
/// order), then, with use_filter, `filter(a, &info)` (the filtered action; info's `modified` and
/// `feasible` are counted in `stats`), else `a` clipped to [-bound, bound] per axis. Returns the
/// action.
template <typename Info, typename Vector, typename Filter>
Vector NoisyFilteredAction(Vector a, double noise_sigma, bool use_filter, double bound, Rng& rng,
                           ExpertFilterStats& stats, Filter&& filter) {
  for (Eigen::Index i = 0; i < a.size(); ++i) a[i] += noise_sigma * rng.Normal();
  ++stats.steps;
  if (!use_filter) return a.cwiseMax(-bound).cwiseMin(bound);
  Info info;
  const Vector filtered = filter(a, &info);
  if (info.modified) ++stats.modified;
  if (!info.feasible) ++stats.infeasible;
  return filtered;
}

}  // namespace secure::domains
