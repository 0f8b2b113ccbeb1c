#pragma once
// Feature-name helpers shared by the policy module's model files (gaussian_policy.cc,
// airl_reward.cc), and the metadata they share. INTERNAL: include it only from secure/policy/*.cc.
// No LibTorch.

#include <algorithm>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/common/error.h"
#include "secure/nn/model_file.h"

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

/// A model file of `kind` with the metadata both model files open with: observation_features,
/// input_features (only when not empty: the network reads the whole observation otherwise, and
/// such files keep their bytes) and provenance.
inline nn::ModelFile FeatureModelFile(const std::string& kind,
                                      const std::vector<std::string>& observation_features,
                                      const std::vector<std::string>& input_features,
                                      const nlohmann::json& provenance) {
  nn::ModelFile file;
  file.kind = kind;
  file.metadata["observation_features"] = observation_features;
  if (!input_features.empty()) file.metadata["input_features"] = input_features;
  file.metadata["provenance"] = provenance;
  return file;
}

/// The row of `name` in `features`, or -1.
inline int RowOf(const std::vector<std::string>& features, const std::string& name) {
  const auto it = std::find(features.begin(), features.end(), name);
  return it == features.end() ? -1 : static_cast<int>(it - features.begin());
}

}  // namespace secure::policy::internal
