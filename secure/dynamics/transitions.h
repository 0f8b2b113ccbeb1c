#pragma once
// One-step transitions (s, a, s') with feature names: what dynamics::TrainDynamics learns from
// and `secure dynamics validate` scores against.
//
// Files (by extension, as every reader in secure/data):
//  - CSV with a header row, either
//      explicit triples: the state columns, the action columns and next_<f> for each state
//        feature f (any further columns are ignored), one transition per row; or
//      trajectories: an `episode` column (and the state and action columns), as `secure demos
//        generate` writes demos.csv: each step with a successor in its episode is a transition
//        (s_t, a_t, s_{t+1}); an episode's last step has none.
//  - HDF5 in robomimic's layout (data/demo_<k>): the demonstrations' obs and actions, paired
//    as the trajectories above (next_obs is obs shifted by one step).
// Every value must be finite; a message names the file, line and column.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "secure/data/data.h"

namespace secure::dynamics {

struct Transitions {
  std::string source;
  std::vector<std::string> state_features, action_features;
  Eigen::MatrixXf states;       // (state dim x N)
  Eigen::MatrixXf actions;      // (action dim x N)
  Eigen::MatrixXf next_states;  // (state dim x N)
  std::vector<long> lines;      // the file line (CSV, 1-based) or step (HDF5) of each s
  // Trajectories only: the start column of each run of consecutive transitions (an episode),
  // plus N at the end; empty for explicit triples (k-step errors need runs).
  std::vector<long> run_begin;

  long size() const { return static_cast<long>(states.cols()); }
  int state_dim() const { return static_cast<int>(state_features.size()); }
  int action_dim() const { return static_cast<int>(action_features.size()); }
};

/// The prefix of a next-state column: next_<feature>.
inline constexpr const char* kNextPrefix = "next_";

/// Reads transitions of the given state and action features (neither may be empty).
/// @throws secure::Error naming the file (and line and column) on a missing file or column, a
///   non-finite or non-numeric value, no transition, or a file with neither next_<f> columns nor
///   an episode column.
Transitions ReadTransitions(const std::string& path, const std::vector<std::string>& state_features,
                            const std::vector<std::string>& action_features);

/// The transitions of trajectories: (s_t, a_t, s_{t+1}) within each episode.
Transitions FromTrajectories(const data::TrajectorySet& demos);

/// Appends `more` to `all` (same features, else an error naming both sources).
void Append(const Transitions& more, Transitions* all);

/// Writes explicit triples as CSV (state columns, action columns, next_<f> columns), atomically.
void WriteTransitions(const std::string& path, const Transitions& transitions);

}  // namespace secure::dynamics
