#pragma once
// Feature-name helpers shared by the policy module's model files (gaussian_policy.cc,
// airl_reward.cc). INTERNAL: include it only from secure/policy/*.cc. No LibTorch.

#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/common/error.h"

namespace secure::policy::internal {

/// metadata[field] as a list of strings; throws naming `path` and the field otherwise.
inline std::vector<std::string> StringList(const nlohmann::json& metadata, const std::string& field,
                                           const std::string& path) {
  SECURE_CHECK(metadata.contains(field) && metadata[field].is_array(),
               path << ": metadata field '" << field << "' is missing or not a list");
  std::vector<std::string> out;
  for (const auto& item : metadata[field]) {
    SECURE_CHECK(item.is_string(),
                 path << ": metadata field '" << field << "' holds a non-string: " << item.dump());
    out.push_back(item.get<std::string>());
  }
  return out;
}

/// The row of `name` in `features`, or -1.
inline int RowOf(const std::vector<std::string>& features, const std::string& name) {
  const auto it = std::find(features.begin(), features.end(), name);
  return it == features.end() ? -1 : static_cast<int>(it - features.begin());
}

}  // namespace secure::policy::internal
