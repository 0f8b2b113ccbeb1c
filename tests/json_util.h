#pragma once
// JSON helpers for tests that compare result documents of runs made at different times.
#include <nlohmann/json.hpp>
#include <set>
#include <string>

namespace secure::test {

/// `j` without what measures time: every key (at any depth) that contains "second" (seconds,
/// data_seconds, ...) or "latency" (the decision latencies), and the keys in `also`.
inline nlohmann::json WithoutTimings(const nlohmann::json& j, const std::set<std::string>& also = {}) {
  if (j.is_object()) {
    nlohmann::json out = nlohmann::json::object();
    for (const auto& [key, value] : j.items()) {
      // (A task file's checksum covers its timings too.)
      if (key.find("second") != std::string::npos || key.find("latency") != std::string::npos ||
          key == "checksum" || also.count(key) > 0)
        continue;
      out[key] = WithoutTimings(value, also);
    }
    return out;
  }
  if (j.is_array()) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& value : j) out.push_back(WithoutTimings(value, also));
    return out;
  }
  return j;
}

}  // namespace secure::test
