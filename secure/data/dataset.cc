// State sets, trajectories and splits built on the CSV reader (see data.h for the contract).

#include "secure/data/data.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <filesystem>
#include <numeric>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "secure/common/error.h"
#include "secure/common/random_order.h"
#include "secure/common/rng.h"

namespace secure::data {
namespace {

// Formats a value read from a file as it most likely appeared there (shortest round trip).
std::string Shown(double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

// Rows [first, first + count) of `table`, converted to float. A value that is finite as a double
// can still overflow float (e.g. 1e300), which would put an infinity into training data.
Eigen::MatrixXf ToFloatRows(const NumericTable& table, Eigen::Index first, Eigen::Index count) {
  const Eigen::MatrixXd& values = table.values;
  Eigen::MatrixXf out = values.middleRows(first, count).cast<float>();
  for (Eigen::Index row = 0; row < out.cols(); ++row) {
    for (Eigen::Index j = 0; j < out.rows(); ++j) {
      SECURE_CHECK(std::isfinite(out(j, row)),
                   table.source << ":" << table.lines[static_cast<std::size_t>(row)] << ": column '"
                                << table.columns[static_cast<std::size_t>(first + j)]
                                << "': value '" << Shown(values(first + j, row))
                                << "' is out of the float range");
    }
  }
  return out;
}

// A header with a repeated name would not read back (ReadCsv rejects it).
void CheckDistinct(const std::string& path, const std::vector<std::string>& columns) {
  std::unordered_map<std::string, std::size_t> first_of;
  for (std::size_t j = 0; j < columns.size(); ++j) {
    const auto [it, inserted] = first_of.emplace(columns[j], j);
    SECURE_CHECK(inserted, "cannot write '" << path << "': column " << j + 1 << " '" << columns[j]
                                            << "' repeats column " << it->second + 1);
  }
}

}  // namespace

StateSet ReadStateSet(const std::string& path, const std::vector<std::string>& features,
                      const std::string& hdf5_label) {
  if (IsHdf5Path(path)) return internal::ReadHdf5StateSet(path, features, hdf5_label);
  NumericTable table = ReadCsv(path, features);
  StateSet set;
  set.source = path;
  set.states = ToFloatRows(table, 0, table.values.rows());
  set.features = std::move(table.columns);
  // ReadCsv already rejects a file without rows; kept so the contract does not hinge on it.
  SECURE_CHECK(set.size() > 0, path << ": 0 states");
  return set;
}

TrajectorySet ReadTrajectories(const std::string& path,
                               const std::vector<std::string>& state_features,
                               const std::vector<std::string>& action_features,
                               const std::string& episode_column) {
  if (IsHdf5Path(path))
    return internal::ReadHdf5Trajectories(path, state_features, action_features);
  SECURE_CHECK(!state_features.empty(), path << ": no state features selected");
  std::vector<std::string> select;
  select.reserve(1 + state_features.size() + action_features.size());
  select.push_back(episode_column);
  select.insert(select.end(), state_features.begin(), state_features.end());
  select.insert(select.end(), action_features.begin(), action_features.end());
  const NumericTable table = ReadCsv(path, select);

  TrajectorySet set;
  set.source = path;
  set.state_features = state_features;
  set.action_features = action_features;
  const auto state_dim = static_cast<Eigen::Index>(state_features.size());
  const auto action_dim = static_cast<Eigen::Index>(action_features.size());
  set.states = ToFloatRows(table, 1, state_dim);
  set.actions = ToFloatRows(table, 1 + state_dim, action_dim);

  // Episode ids must be exact integers: 2^53 bounds the doubles that hold integers exactly.
  constexpr double kMaxExactInteger = 9007199254740992.0;
  std::unordered_map<long long, long> end_line_of;  // episode id -> line of its last row
  long long current = 0;
  const long num_rows = static_cast<long>(table.values.cols());
  for (long row = 0; row < num_rows; ++row) {
    const double value = table.values(0, row);
    const long line = table.lines[static_cast<std::size_t>(row)];
    SECURE_CHECK(std::floor(value) == value && std::abs(value) <= kMaxExactInteger,
                 path << ":" << line << ": column '" << episode_column << "': value '"
                      << Shown(value) << "' is not an integer episode id");
    const auto id = static_cast<long long>(value);
    if (row == 0 || id != current) {
      const auto previous = end_line_of.find(id);
      SECURE_CHECK(previous == end_line_of.end(),
                   path << ":" << line << ": column '" << episode_column << "': episode " << id
                        << " reappears after episode " << current << " (it ended on line "
                        << previous->second << "); the rows of an episode must be adjacent");
      set.episode_begin.push_back(row);
      current = id;
    }
    end_line_of[id] = line;
  }
  set.episode_begin.push_back(num_rows);
  return set;
}

void WriteStateSet(const std::string& path, const StateSet& set, const std::string& hdf5_label) {
  if (IsHdf5Path(path)) {
    const std::string label =
        hdf5_label.empty() ? std::filesystem::path(path).stem().string() : hdf5_label;
    WriteHdf5(path, nullptr, {{label, &set}});
    return;
  }
  SECURE_CHECK(set.states.rows() == set.dim(), "cannot write '" << path << "': the states have "
                                                                << set.states.rows() << " rows but "
                                                                << set.dim() << " feature names");
  SECURE_CHECK(set.size() > 0, "cannot write '" << path << "': 0 states (would not read back)");
  CheckDistinct(path, set.features);
  WriteCsv(path, set.features, set.states.cast<double>());
}

void WriteTrajectories(const std::string& path, const TrajectorySet& set,
                       const std::string& episode_column) {
  if (IsHdf5Path(path)) {
    WriteHdf5(path, &set, {});
    return;
  }
  const auto state_dim = static_cast<Eigen::Index>(set.state_features.size());
  const auto action_dim = static_cast<Eigen::Index>(set.action_features.size());
  const Eigen::Index steps = set.states.cols();
  SECURE_CHECK(state_dim > 0, "cannot write '" << path << "': no state features");
  SECURE_CHECK(set.states.rows() == state_dim,
               "cannot write '" << path << "': the states have " << set.states.rows()
                                << " rows but " << state_dim << " state feature names");
  SECURE_CHECK(set.actions.rows() == action_dim,
               "cannot write '" << path << "': the actions have " << set.actions.rows()
                                << " rows but " << action_dim << " action feature names");
  SECURE_CHECK(set.actions.cols() == steps, "cannot write '" << path << "': " << steps
                                                             << " states but " << set.actions.cols()
                                                             << " actions");
  SECURE_CHECK(steps > 0, "cannot write '" << path << "': 0 steps (would not read back)");
  const std::vector<long>& begin = set.episode_begin;
  SECURE_CHECK(begin.size() >= 2 && begin.front() == 0 && begin.back() == steps,
               "cannot write '" << path << "': episode_begin must start at 0 and end at " << steps
                                << " (the number of steps); it has " << begin.size() << " entries"
                                << (begin.empty() ? std::string()
                                                  : ", from " + std::to_string(begin.front()) +
                                                        " to " + std::to_string(begin.back())));
  for (std::size_t k = 0; k + 1 < begin.size(); ++k) {
    SECURE_CHECK(begin[k] < begin[k + 1],
                 "cannot write '" << path << "': episode " << k << " is empty or reversed ("
                                  << "episode_begin[" << k << "] = " << begin[k]
                                  << ", episode_begin[" << k + 1 << "] = " << begin[k + 1]
                                  << "); empty episodes would not read back");
  }

  std::vector<std::string> columns;
  columns.reserve(static_cast<std::size_t>(2 + state_dim + action_dim));
  columns.push_back(episode_column);
  columns.push_back("step");
  columns.insert(columns.end(), set.state_features.begin(), set.state_features.end());
  columns.insert(columns.end(), set.action_features.begin(), set.action_features.end());
  CheckDistinct(path, columns);

  Eigen::MatrixXd values(static_cast<Eigen::Index>(columns.size()), steps);
  for (std::size_t k = 0; k + 1 < begin.size(); ++k) {
    for (long t = begin[k]; t < begin[k + 1]; ++t) {
      values(0, t) = static_cast<double>(k);
      values(1, t) = static_cast<double>(t - begin[k]);
    }
  }
  values.middleRows(2, state_dim) = set.states.cast<double>();
  if (action_dim > 0) values.bottomRows(action_dim) = set.actions.cast<double>();
  WriteCsv(path, columns, values);
}

void CheckNonEmptyFinite(const StateSet& set, const std::string& what) {
  const std::string name = set.source.empty() ? what : what + " (" + set.source + ")";
  SECURE_CHECK(set.states.rows() == set.dim(), name << ": states have " << set.states.rows()
                                                    << " rows but " << set.dim()
                                                    << " feature names");
  SECURE_CHECK(set.size() > 0, name << ": 0 states; each class needs at least one");
  for (Eigen::Index i = 0; i < set.states.cols(); ++i) {
    for (Eigen::Index j = 0; j < set.states.rows(); ++j) {
      SECURE_CHECK(std::isfinite(set.states(j, i)),
                   name << ": state " << i << " (0-based), feature '"
                        << set.features[static_cast<std::size_t>(j)] << "' is " << set.states(j, i)
                        << "; states must be finite");
    }
  }
}

IndexSplit SplitForValidation(long n, double fraction, Rng& rng) {
  IndexSplit split;
  long n_val = fraction > 0 ? std::lround(fraction * static_cast<double>(n)) : 0;
  if (fraction > 0 && n >= 2) n_val = std::clamp(n_val, 1L, n - 1);
  if (n < 2) n_val = 0;
  const std::vector<long> order = RandomPermutation(std::max(n, 0L), rng);
  split.validation.assign(order.begin(), order.begin() + n_val);
  split.train.assign(order.begin() + n_val, order.end());
  return split;
}

std::pair<IndexSplit, IndexSplit> SplitTwoClassesForValidation(long n_a, long n_b,
                                                               double fraction, Rng& rng) {
  IndexSplit a = SplitForValidation(n_a, fraction, rng);
  IndexSplit b = SplitForValidation(n_b, fraction, rng);
  if (a.validation.empty() || b.validation.empty()) {
    for (IndexSplit* s : {&a, &b}) {
      s->train.insert(s->train.end(), s->validation.begin(), s->validation.end());
      s->validation.clear();
    }
  }
  return {std::move(a), std::move(b)};
}

std::vector<std::vector<long>> RandomSplit(long n, const std::vector<double>& fractions, Rng& rng) {
  SECURE_CHECK(n >= 0, "random split: the number of items is " << n << ", must be >= 0");
  SECURE_CHECK(!fractions.empty(), "random split: no fractions given");
  double sum = 0.0;
  for (std::size_t k = 0; k < fractions.size(); ++k) {
    SECURE_CHECK(std::isfinite(fractions[k]) && fractions[k] > 0.0,
                 "random split: fraction " << k + 1 << " is " << fractions[k] << ", must be > 0");
    sum += fractions[k];
  }
  SECURE_CHECK(std::abs(sum - 1.0) <= 1e-9,
               "random split: fractions sum to " << sum << ", must sum to 1");

  std::vector<long> order(static_cast<std::size_t>(n));
  std::iota(order.begin(), order.end(), 0L);
  Shuffle(order.begin(), order.end(), rng);

  std::vector<std::vector<long>> parts(fractions.size());
  long begin = 0;
  for (std::size_t k = 0; k < fractions.size(); ++k) {
    long size = n - begin;  // the last part takes the rest
    if (k + 1 < fractions.size()) {
      // The epsilon keeps e.g. 0.29 * 100 = 28.999999999999996 from rounding down to 28.
      const auto wanted =
          static_cast<long>(std::floor(static_cast<double>(n) * fractions[k] + 1e-9));
      size = std::min(wanted, n - begin);
    }
    parts[k].assign(order.begin() + begin, order.begin() + begin + size);
    begin += size;
  }
  return parts;
}

namespace {
// The check SelectColumns and SelectRows share: every index in [0, size), else the first that is
// not is named ("<what>: index 7 (entry 2) is outside [0, 5)").
template <class Index>
void CheckSelection(const std::vector<Index>& indices, Eigen::Index size, const char* what) {
  for (std::size_t k = 0; k < indices.size(); ++k) {
    const Index index = indices[k];
    SECURE_CHECK(index >= 0 && index < size,
                 what << ": index " << index << " (entry " << k << ") is outside [0, " << size
                      << ")");
  }
}
}  // namespace

Eigen::MatrixXf SelectColumns(const Eigen::Ref<const Eigen::MatrixXf>& states,
                              const std::vector<long>& indices) {
  CheckSelection(indices, states.cols(), "select columns");
  Eigen::MatrixXf out(states.rows(), static_cast<Eigen::Index>(indices.size()));
  for (std::size_t k = 0; k < indices.size(); ++k)
    out.col(static_cast<Eigen::Index>(k)) = states.col(indices[k]);
  return out;
}

Eigen::MatrixXf SelectRows(const Eigen::Ref<const Eigen::MatrixXf>& states,
                           const std::vector<int>& indices) {
  CheckSelection(indices, states.rows(), "select rows");
  Eigen::MatrixXf out(static_cast<Eigen::Index>(indices.size()), states.cols());
  for (std::size_t k = 0; k < indices.size(); ++k)
    out.row(static_cast<Eigen::Index>(k)) = states.row(indices[k]);
  return out;
}

std::vector<std::string> SplitList(const std::string& text) {
  const auto is_blank = [](char c) { return c == ' ' || c == '\t'; };
  std::vector<std::string> items;
  if (std::all_of(text.begin(), text.end(), is_blank)) return items;
  // Empty items ("a,,b") are kept, so that a typo surfaces as an error about the name ''.
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = text.find(',', start);
    const std::size_t end = comma == std::string::npos ? text.size() : comma;
    std::size_t first = start;
    std::size_t last = end;
    while (first < last && is_blank(text[first])) ++first;
    while (last > first && is_blank(text[last - 1])) --last;
    items.push_back(text.substr(first, last - first));
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return items;
}

std::pair<StateSet, StateSet> SplitStateSet(const StateSet& set, double second_fraction, Rng& rng) {
  SECURE_CHECK(std::isfinite(second_fraction) && second_fraction >= 0 && second_fraction < 1,
               "split fraction = " << second_fraction << ", must be in [0, 1)");
  const long n = set.size();
  long n_second = static_cast<long>(std::floor(second_fraction * static_cast<double>(n) + 1e-9));
  if (second_fraction > 0 && n >= 2) n_second = std::max(n_second, 1L);
  std::vector<long> order(static_cast<std::size_t>(n));
  for (long i = 0; i < n; ++i) order[static_cast<std::size_t>(i)] = i;
  Shuffle(order.begin(), order.end(), rng);
  const std::vector<long> second(order.begin(), order.begin() + n_second);
  const std::vector<long> first(order.begin() + n_second, order.end());
  return {StateSet{set.source + " [split 1/2]", set.features, SelectColumns(set.states, first)},
          StateSet{set.source + " [split 2/2]", set.features, SelectColumns(set.states, second)}};
}

}  // namespace secure::data
