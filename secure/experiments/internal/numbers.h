#pragma once
// Small formatting and reading helpers of the experiment driver's files (options, tables, task
// files). INTERNAL: include only from secure/experiments/*.cc.
#include <cmath>
#include <cstdio>
#include <string>

#include <nlohmann/json.hpp>

namespace secure::experiments::internal {

/// "25%" for 0.25 (%g: as short as the number allows).
inline std::string Percent(double fraction) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%g%%", 100.0 * fraction);
  return buffer;
}

/// A number of a result document: null (how nlohmann writes NaN) reads as NaN, a missing key as
/// `otherwise`.
inline double Number(const nlohmann::json& j, const char* key, double otherwise = 0.0) {
  const auto it = j.find(key);
  if (it == j.end()) return otherwise;
  if (it->is_null()) return std::nan("");
  return it->get<double>();
}

}  // namespace secure::experiments::internal
