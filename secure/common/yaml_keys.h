#pragma once
// Structural checks of a YAML document that yaml-cpp does not make: it accepts a mapping with a
// key twice (the last one wins when read), which would let a typo'd or pasted section silently
// override another. Header-only; a target that includes it links yaml-cpp (secure::common does
// not).
#include <yaml-cpp/yaml.h>

#include <map>
#include <string>

#include "secure/common/error.h"
#include "secure/common/excerpt.h"

namespace secure {

/// The key of a mapping entry as text (a scalar's value; otherwise its YAML form).
inline std::string YamlKeyText(const YAML::Node& key) {
  return key.IsScalar() ? key.Scalar() : YAML::Dump(key);
}

/// Throws "SOURCE:LINE: duplicate key 'k' (first at line N)" for the first key that occurs twice
/// in one mapping, at any depth of `node` (mappings inside sequences included). Lines are
/// 1-based (yaml-cpp's Mark().line + 1).
inline void CheckNoDuplicateKeys(const YAML::Node& node, const std::string& source) {
  if (node.IsSequence()) {
    for (const auto& item : node) CheckNoDuplicateKeys(item, source);
  } else if (node.IsMap()) {
    std::map<std::string, int> first_line;
    for (const auto& item : node) {
      const int line = item.first.Mark().line + 1;
      const std::string key = YamlKeyText(item.first);
      const auto [it, inserted] = first_line.emplace(key, line);
      SECURE_CHECK(inserted, source << ":" << line << ": duplicate key '" << Excerpt(key)
                                    << "' (first at line " << it->second << ")");
      CheckNoDuplicateKeys(item.second, source);
    }
  }
}

}  // namespace secure
