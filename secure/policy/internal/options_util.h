#pragma once
// Helpers shared by the policy trainers' option files (bc_options.cc, airl_options.cc): typed
// YAML values with messages naming the source, the field and the value. No LibTorch.
#include <yaml-cpp/yaml.h>

#include <string>
#include <type_traits>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/yaml_value.h"

namespace secure::policy::internal {

using secure::YamlValue;

inline std::vector<int> YamlWidths(const YAML::Node& node, const std::string& key,
                                   const std::string& source) {
  SECURE_CHECK(node.IsSequence(),
               source << ": field '" << key << "' must be a list of layer widths");
  std::vector<int> widths;
  for (const auto& w : node) widths.push_back(YamlValue<int>(w, key, source));
  return widths;
}

inline std::vector<std::string> YamlStrings(const YAML::Node& node, const std::string& key,
                                            const std::string& source) {
  SECURE_CHECK(node.IsSequence(), source << ": field '" << key << "' must be a list of names");
  std::vector<std::string> names;
  for (const auto& n : node) names.push_back(YamlValue<std::string>(n, key, source));
  return names;
}

inline std::string WidthsString(const std::vector<int>& widths) {
  std::string s = "[";
  for (std::size_t i = 0; i < widths.size(); ++i) s += (i ? ", " : "") + std::to_string(widths[i]);
  return s + "]";
}

}  // namespace secure::policy::internal
