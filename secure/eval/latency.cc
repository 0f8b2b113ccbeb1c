#include "secure/eval/latency.h"

#include <algorithm>
#include <cmath>

#include "secure/common/error.h"

namespace secure::eval {

double NearestRankPercentile(const std::vector<double>& sorted, double percent) {
  SECURE_CHECK(!sorted.empty(), "NearestRankPercentile: no values");
  SECURE_CHECK(percent > 0 && percent <= 100,
               "NearestRankPercentile: percent = " << percent << ", must be in (0, 100]");
  const double n = static_cast<double>(sorted.size());
  // rank = ceil(p / 100 * n), 1-based; the small slack keeps e.g. 0.99 * 100 from rounding up.
  long rank = static_cast<long>(std::ceil(percent / 100.0 * n - 1e-9));
  rank = std::clamp(rank, 1L, static_cast<long>(sorted.size()));
  return sorted[static_cast<std::size_t>(rank - 1)];
}

LatencySummary LatencySummary::Of(std::vector<double> values) {
  LatencySummary s;
  s.count = static_cast<long>(values.size());
  if (values.empty()) return s;
  std::sort(values.begin(), values.end());
  s.p50 = NearestRankPercentile(values, 50);
  s.p90 = NearestRankPercentile(values, 90);
  s.p99 = NearestRankPercentile(values, 99);
  s.max = values.back();
  double sum = 0.0;
  for (double v : values) sum += v;
  s.mean = sum / static_cast<double>(values.size());
  return s;
}

nlohmann::json LatencySummary::ToJson() const {
  return {{"count", count}, {"p50", p50}, {"p90", p90}, {"p99", p99}, {"max", max}, {"mean", mean}};
}

}  // namespace secure::eval
