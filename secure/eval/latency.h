#pragma once
// Latency summaries of shield decisions and policy queries (nearest-rank percentiles).
#include <nlohmann/json.hpp>
#include <vector>

namespace secure::eval {

/// Latency percentiles (nearest rank) of the shield's decisions, in microseconds.
struct LatencySummary {
  long count = 0;
  double p50 = 0.0;
  double p90 = 0.0;
  double p99 = 0.0;
  double max = 0.0;
  double mean = 0.0;

  /// From unsorted values (all zeros when there are none).
  static LatencySummary Of(std::vector<double> values);
  nlohmann::json ToJson() const;
};

/// The nearest-rank percentile (0 < percent <= 100) of `sorted` (ascending, non-empty): the
/// smallest value with at least percent % of the values <= it.
double NearestRankPercentile(const std::vector<double>& sorted, double percent);

}  // namespace secure::eval
