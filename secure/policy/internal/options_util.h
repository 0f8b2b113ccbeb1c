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
using secure::YamlWidths;

inline std::vector<std::string> YamlStrings(const YAML::Node& node, const std::string& key,
                                            const std::string& source) {
  return YamlList<std::string>(node, key, source, "names");
}

inline std::string WidthsString(const std::vector<int>& widths) {
  std::string s = "[";
  for (std::size_t i = 0; i < widths.size(); ++i) s += (i ? ", " : "") + std::to_string(widths[i]);
  return s + "]";
}

}  // namespace secure::policy::internal
