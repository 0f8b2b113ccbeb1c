#pragma once
// Datasets read from and written to CSV files with a header row, or to HDF5 files in robomimic's
// layout (by extension: .h5 / .hdf5; see docs/FILE_FORMATS.md).
//
// Conventions: a set of states is an Eigen matrix (dim x N), one state per column, with the
// feature names of its rows. Readers validate everything and throw secure::Error with a message
// that names the file, the line (1-based, the header is line 1), the column name and the value;
// for HDF5, the file, the dataset path, the row and the column.

#include <Eigen/Core>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "secure/common/rng.h"

namespace secure::data {

/// A numeric CSV table. values is (columns x rows): column j of the matrix is data row j.
struct NumericTable {
  std::string source;                // file path, for messages
  std::vector<std::string> columns;  // selected column names, in selection order
  Eigen::MatrixXd values;            // (columns.size() x rows)
  std::vector<long> lines;           // 1-based file line of each data row
};

/// Reads a CSV file with a header row. `select` picks and orders columns by name (empty: all
/// columns in file order). Every data row must have as many cells as the header; every selected
/// cell must parse completely as a finite number.
/// @throws secure::Error on: missing/unreadable file, a directory ("is a directory"), empty file
///   (no header), header with an empty or duplicate name, a name selected twice, a selected name
///   not in the header (the message lists the header), a row with the wrong number of cells, a
///   non-numeric, NaN or infinite selected cell, and a file with no data rows. File content
///   quoted in a message is cut at 80 characters ("…") with control bytes escaped (Excerpt).
NumericTable ReadCsv(const std::string& path, const std::vector<std::string>& select = {});

/// Writes a CSV with a header row; `values` is (columns x rows) as in NumericTable. Atomic.
/// Numbers are written in shortest round-trip form (std::to_chars); non-finite values are an
/// error naming the column and row.
void WriteCsv(const std::string& path, const std::vector<std::string>& columns,
              const Eigen::Ref<const Eigen::MatrixXd>& values);

/// A set of states with named features, e.g. the safe or the near-dangerous states.
struct StateSet {
  std::string source;
  std::vector<std::string> features;
  Eigen::MatrixXf states;  // (features.size() x N)

  int dim() const { return static_cast<int>(features.size()); }
  long size() const { return static_cast<long>(states.cols()); }
};

/// The labels of the safety demonstrations in an HDF5 file (groups safety/<label>).
inline constexpr const char* kSafeLabel = "safe";
inline constexpr const char* kNearDangerousLabel = "near_dangerous";

/// True if `path` names an HDF5 file: its extension is .h5 or .hdf5 (any case). Every reader and
/// writer below dispatches on it; anything else is CSV.
bool IsHdf5Path(const std::string& path);

/// Reads a state set; `features` selects columns by name (empty: all columns).
/// HDF5: `features` name columns ("<key>" of a one-column obs key, "<key>[j]" of a wider one) or
/// whole obs keys (all their columns, in order). The states are those of group
/// safety/<hdf5_label> if present, else of the file's only state set whatever its label; a file
/// without a safety/ group gives every step of its demonstrations (as a demonstrations CSV
/// read as states does).
/// @throws secure::Error as ReadCsv, and if the file holds zero states; for HDF5 also on a file
///   that is not HDF5, a missing group, key or dataset, a wrong rank or shape, non-float data, a
///   NaN or infinity (naming the dataset, row and column), keys of different lengths, and a
///   label that matches none of several sets.
StateSet ReadStateSet(const std::string& path, const std::vector<std::string>& features = {},
                      const std::string& hdf5_label = "");

/// Task demonstrations: state/action pairs grouped into episodes, as rows of one CSV file.
struct TrajectorySet {
  std::string source;
  std::vector<std::string> state_features;
  std::vector<std::string> action_features;
  Eigen::MatrixXf states;           // (state dim x T) all steps of all episodes, in file order
  Eigen::MatrixXf actions;          // (action dim x T)
  std::vector<long> episode_begin;  // start column of each episode, plus T at the end

  long num_episodes() const { return static_cast<long>(episode_begin.size()) - 1; }
  long num_steps() const { return static_cast<long>(states.cols()); }
};

/// Reads trajectories: rows with the same value in `episode_column` that are adjacent form one
/// episode (a value that reappears after another episode is an error naming the line).
/// HDF5: the episodes are data/demo_<i> in order of i; `state_features` select obs columns or
/// keys as in ReadStateSet (empty: all, in file order); `action_features` select columns of
/// `actions` by the names our writer stores (attribute data/action_features), else "actions[j]"
/// ("actions" for all); `episode_column` is unused.
/// @throws secure::Error as ReadCsv, if the episode column holds a non-integer, or if the file
///   holds no rows; for HDF5 as ReadStateSet, and on an empty demo, obs and actions of different
///   lengths or a num_samples attribute that disagrees with the data.
TrajectorySet ReadTrajectories(const std::string& path,
                               const std::vector<std::string>& state_features,
                               const std::vector<std::string>& action_features,
                               const std::string& episode_column = "episode");

/// Writes `set` as a CSV file (columns: the feature names; one row per state), atomically (via
/// WriteCsv). Reads back bit-exactly with ReadStateSet.
/// HDF5: a file holding safety/<hdf5_label> (empty label: the file name's stem), see WriteHdf5.
/// @throws secure::Error if the set holds no states, its matrix and feature names disagree, a
///   feature name is unusable as a CSV column (see WriteCsv) or repeated, or a value is not finite.
void WriteStateSet(const std::string& path, const StateSet& set,
                   const std::string& hdf5_label = "");

/// Writes trajectories as a CSV file, atomically (via WriteCsv), with the columns
///   <episode_column>, step, <state features...>, <action features...>
/// one row per step: episode k (0-based, in order) holds the columns [episode_begin[k],
/// episode_begin[k + 1]) and step counts 0, 1, ... within it. Reads back bit-exactly with
/// ReadTrajectories(path, state_features, action_features, episode_column).
/// @throws secure::Error if there are no steps, the matrices, feature names and episode_begin
///   disagree (episode_begin must run strictly increasing from 0 to num_steps(): an empty episode
///   would not read back), a column name is repeated or unusable, or a value is not finite.
/// HDF5: as WriteHdf5(path, &set, {}) (`episode_column` unused).
void WriteTrajectories(const std::string& path, const TrajectorySet& set,
                       const std::string& episode_column = "episode");

/// A state set with the label of its HDF5 group safety/<label>.
struct LabelledStateSet {
  std::string label;
  const StateSet* set = nullptr;
};

/// Writes demonstrations (if `demos` is not null) and labelled state sets to one HDF5 file in
/// robomimic's layout, atomically:
///   data                 attributes total (steps), env_args (JSON string), action_features
///   data/demo_<k>        episode k; attribute num_samples
///     obs/<key>          (T, n) float64: feature names "<key>[0]" .. "<key>[n-1]" (n >= 2) form
///                        one key; any other name is a (T, 1) key of its own
///     next_obs/<key>     as obs/<key>, row t the observation of step t + 1 (the last row
///                        repeats the last observation: the one after the last action is not
///                        recorded)
///     actions            (T, n_a) float64
///     dones, rewards     (T,) int64 (1 at the last step) and float64 (zeros)
///     states             (T, state dim) float64: the obs columns in feature order
///   mask/train, mask/valid  robomimic's filter keys: (n,) fixed-length byte strings, the demo
///                        names of each split (IsValidationDemo)
///   safety/<label>       a state set; attribute num_samples
///     obs/<key>          (N, n) float64, keys as above
/// Groups keep creation order and no time stamps: the same data give the same bytes, and keys
/// read back in the order written. Reads back bit-exactly (float32 values in float64).
/// @throws secure::Error on what WriteTrajectories and WriteStateSet reject, a name that is no
///   HDF5 name (empty, ".", containing '/'), an action name with a comma, or two sets with one
///   label.
void WriteHdf5(const std::string& path, const TrajectorySet* demos,
               const std::vector<LabelledStateSet>& sets);

/// The train/valid split of the filter keys WriteHdf5 writes (mask/valid), deterministic: demo
/// `index` (0-based) of `demos` is a validation demo if index % 10 == 9 (every tenth: 10 % of the
/// demos rounded down, robomimic's split_train_val.py ratio), or, with 2 to 9 demos, if it is
/// the last one; one demo is a training demo.
bool IsValidationDemo(long index, long demos);

/// What an HDF5 data file holds.
struct Hdf5Contents {
  bool has_demonstrations = false;
  std::vector<std::string> observation_features;  // the first demo's obs columns, in file order
  std::vector<std::string> unreadable_obs_keys;   // its obs keys that are no (T,) or (T, k)
                                                  // float dataset (robomimic's images)
  std::vector<std::string> action_features;
  std::vector<std::string> state_sets;  // labels under safety/, in file order
};
/// Says what a file holds from the first demo's keys and the actions' shape and types (no values
/// are read; ReadTrajectories checks every demo).
/// @throws secure::Error on a file that is not HDF5, holds neither data/ nor safety/, a data/
///   without demos, a demo without obs keys, or actions that are no (T,) or (T, k) float dataset.
Hdf5Contents InspectHdf5(const std::string& path);

/// HDF5 files are read in a child process (fork) under a memory limit (InputLimits::
/// max_hdf5_memory_bytes; default 1 GiB + 8 times the file's size): libhdf5 1.10 itself crashes
/// or allocates gigabytes on some malformed files. The child's death by a signal, or its
/// memory limit, is one secure::Error naming the file; the decoded arrays come back through a
/// pipe. Writing stays in this process.
namespace internal {
TrajectorySet ReadHdf5Trajectories(const std::string& path,
                                   const std::vector<std::string>& state_features,
                                   const std::vector<std::string>& action_features);
StateSet ReadHdf5StateSet(const std::string& path, const std::vector<std::string>& features,
                          const std::string& label);
// The same readers in this process, without the guard: for the guard's child, and the HDF5
// fuzzer's in-process mode. A malformed file can crash the process.
Hdf5Contents InspectHdf5InProcess(const std::string& path);
TrajectorySet ReadHdf5TrajectoriesInProcess(const std::string& path,
                                            const std::vector<std::string>& state_features,
                                            const std::vector<std::string>& action_features);
StateSet ReadHdf5StateSetInProcess(const std::string& path,
                                   const std::vector<std::string>& features,
                                   const std::string& label);
// The guard's child process with `work` in place of a reader (tests of the guard itself): what
// `work` appends to its argument comes back; its exceptions and death are the readers' errors.
std::string RunInHdf5ReaderProcess(const std::string& path,
                                   const std::function<void(std::string*)>& work);
}  // namespace internal

/// Checks that a set has at least one state and only finite values; `what` names it in the
/// message ("near-dangerous states (file.csv): 0 states; each class needs at least one").
void CheckNonEmptyFinite(const StateSet& set, const std::string& what);

/// Splits {0..n-1} at random into consecutive parts with the given fractions (which must be
/// > 0 and sum to 1 within 1e-9); part sizes are rounded down except the last, which takes the
/// rest. Deterministic for a given Rng state.
std::vector<std::vector<long>> RandomSplit(long n, const std::vector<double>& fractions, Rng& rng);

/// A random hold-out of {0..n-1} for best-checkpoint selection (the barrier trainers split each
/// class with it): round(fraction n) indices go to `validation`, at least one and at most n - 1
/// when fraction > 0 and n >= 2; none when fraction <= 0 or n < 2. Deterministic for a given
/// Rng state.
struct IndexSplit {
  std::vector<long> train, validation;
};
IndexSplit SplitForValidation(long n, double fraction, Rng& rng);

/// A stratified hold-out of two classes (the barrier trainers' safe and near-dangerous states):
/// SplitForValidation of class a, then of class b, from the same Rng; if either class holds out
/// nothing, neither does (every index goes to train), so validation always sees both classes.
std::pair<IndexSplit, IndexSplit> SplitTwoClassesForValidation(long n_a, long n_b,
                                                               double fraction, Rng& rng);

/// Splits a state set at random into (first, second), `second_fraction` of the states (rounded
/// down, but at least one when the set has two or more) going to `second`; e.g. a held-out test
/// set. Sources are suffixed " [split 1/2]" / " [split 2/2]". Deterministic for a given Rng state.
/// @throws secure::Error unless 0 <= second_fraction < 1.
std::pair<StateSet, StateSet> SplitStateSet(const StateSet& set, double second_fraction, Rng& rng);

/// The columns `indices` of `states`, in that order.
Eigen::MatrixXf SelectColumns(const Eigen::Ref<const Eigen::MatrixXf>& states,
                              const std::vector<long>& indices);

/// The rows `indices` of `states`, in that order.
Eigen::MatrixXf SelectRows(const Eigen::Ref<const Eigen::MatrixXf>& states,
                           const std::vector<int>& indices);

/// Splits "a,b,c" at commas, trimming spaces; empty input gives an empty list.
std::vector<std::string> SplitList(const std::string& text);

}  // namespace secure::data
