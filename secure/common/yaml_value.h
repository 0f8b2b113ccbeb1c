#pragma once
// Typed reads of YAML scalars with errors that name the source file, the field and the value
// ("run.yaml [airl]: field 'iterations' has value 'many', which is not a valid integer").
// Header-only; a target that includes it links yaml-cpp (secure::common itself does not).
#include <yaml-cpp/yaml.h>

#include <set>
#include <string>
#include <type_traits>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/strings.h"

namespace secure {

/// The key of a mapping entry as a string. A key that is not a plain scalar (a sequence, a
/// mapping or null used as a key) is an error naming `source` and the line.
inline std::string YamlKey(const YAML::Node& key, const std::string& source) {
  SECURE_CHECK(key.IsScalar(), source << ":" << key.Mark().line + 1
                                      << ": a key must be a plain name, not "
                                      << (key.IsSequence() ? "a sequence"
                                          : key.IsMap()    ? "a mapping"
                                                           : "null"));
  return key.Scalar();
}

template <typename T>
T YamlValue(const YAML::Node& node, const std::string& key, const std::string& source) {
  try {
    return node.as<T>();
  } catch (const YAML::Exception&) {
    SECURE_THROW(source << ": field '" << key << "' has value '" << YAML::Dump(node)
                        << "', which is not a valid "
                        << (std::is_same_v<T, bool>       ? "boolean"
                            : std::is_integral_v<T>       ? "integer"
                            : std::is_floating_point_v<T> ? "number"
                                                          : "value"));
  }
}

/// A YAML sequence of T (e.g. layer widths, feature names); anything else is an error
/// "source: field 'key' must be a list of <what>".
template <typename T>
std::vector<T> YamlList(const YAML::Node& node, const std::string& key, const std::string& source,
                        const char* what) {
  SECURE_CHECK(node.IsSequence(), source << ": field '" << key << "' must be a list of " << what);
  std::vector<T> values;
  for (const auto& v : node) values.push_back(YamlValue<T>(v, key, source));
  return values;
}

/// An MLP's hidden layer widths: YamlList<int> "... must be a list of layer widths".
inline std::vector<int> YamlWidths(const YAML::Node& node, const std::string& key,
                                   const std::string& source) {
  return YamlList<int>(node, key, source, "layer widths");
}

/// Reads the mapping `node` of `what` (e.g. "reach-avoid task options") field by field:
/// apply(key, value) for each entry, in file order. Errors name `source`: "expected a mapping of
/// <what>" if `node` is not a mapping, and "unknown field 'k' in the <what> (valid: a, b, ...)"
/// (`known` in sorted order) for a key not in `known`.
template <typename Apply>
void ForEachYamlField(const YAML::Node& node, const std::set<std::string>& known,
                      const std::string& what, const std::string& source, Apply&& apply) {
  SECURE_CHECK(node.IsMap(), source << ": expected a mapping of " << what);
  for (const auto& item : node) {
    const std::string key = YamlKey(item.first, source);
    SECURE_CHECK(known.count(key),
                 source << ": unknown field '" << key << "' in the " << what << " (valid: "
                        << Join(std::vector<std::string>(known.begin(), known.end())) << ")");
    apply(key, item.second);
  }
}

}  // namespace secure
