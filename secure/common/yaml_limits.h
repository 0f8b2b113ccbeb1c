#pragma once
// The size of a YAML document as its readers see it (issue 34): yaml-cpp resolves an alias to
// the node it names, so a few lines of nested aliases ("billion laughs") make a document whose
// walk visits 9^9 nodes. CheckYamlLimits walks it once, aliases expanded, and stops at the
// stated limits (secure/common/input_limits.h: nodes, depth). Header-only; a target that
// includes it links yaml-cpp (secure::common does not).
#include <yaml-cpp/yaml.h>

#include <string>

#include "secure/common/error.h"
#include "secure/common/input_limits.h"

namespace secure {

namespace internal {
inline void WalkYamlLimits(const YAML::Node& node, int depth, long* nodes,
                           const InputLimits& limits, const std::string& source) {
  SECURE_CHECK(++*nodes <= limits.max_config_nodes,
               source << ": more than " << limits.max_config_nodes
                      << " YAML nodes with aliases expanded (an alias bomb?; raise the limit "
                         "with SECURE_MAX_CONFIG_NODES or --max-config-nodes)");
  SECURE_CHECK(depth <= limits.max_config_depth,
               source << ":" << node.Mark().line + 1 << ": nested more than "
                      << limits.max_config_depth
                      << " levels deep (raise the limit with SECURE_MAX_CONFIG_DEPTH)");
  if (node.IsSequence()) {
    for (const auto& item : node) WalkYamlLimits(item, depth + 1, nodes, limits, source);
  } else if (node.IsMap()) {
    for (const auto& item : node) {
      WalkYamlLimits(item.first, depth + 1, nodes, limits, source);
      WalkYamlLimits(item.second, depth + 1, nodes, limits, source);
    }
  }
}
}  // namespace internal

/// Throws "SOURCE: more than N YAML nodes with aliases expanded (...)" or "SOURCE:LINE: nested
/// more than D levels deep (...)" if `node` exceeds the limits in force.
inline void CheckYamlLimits(const YAML::Node& node, const std::string& source) {
  long nodes = 0;
  internal::WalkYamlLimits(node, 0, &nodes, GetInputLimits(), source);
}

/// The deepest nesting of flow collections ([ and {, outside quotes and comments) and of
/// compact block sequences ("- - - x") in YAML text, so that a document too deep for the
/// parser's recursion is refused before yaml-cpp parses it. Block nesting by indentation is
/// bounded by the line's indentation, checked after parsing.
inline void CheckYamlTextDepth(const std::string& text, const std::string& source) {
  const int limit = GetInputLimits().max_config_depth;
  int flow = 0, line = 1;
  bool line_start = true;
  int dashes = 0;
  char quote = 0;
  for (std::size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '\n') {
      ++line;
      line_start = true;
      dashes = 0;
      continue;
    }
    if (quote != 0) {
      if (c == '\\' && quote == '"') ++i;
      else if (c == quote) quote = 0;
      continue;
    }
    if (c == '#' && (i == 0 || text[i - 1] == ' ' || text[i - 1] == '\t' ||
                     text[i - 1] == '\n')) {
      while (i + 1 < text.size() && text[i + 1] != '\n') ++i;
      continue;
    }
    if (line_start) {
      if (c == ' ' || c == '\t') continue;
      if (c == '-' && (i + 1 == text.size() || text[i + 1] == ' ' || text[i + 1] == '\n')) {
        ++dashes;
        SECURE_CHECK(dashes + flow <= limit, source << ":" << line << ": nested more than "
                                                    << limit
                                                    << " levels deep (raise the limit with "
                                                       "SECURE_MAX_CONFIG_DEPTH)");
        continue;
      }
      line_start = false;
    }
    const char before = i == 0 ? '\n' : text[i - 1];
    if ((c == '"' || c == '\'') && (before == ' ' || before == '\t' || before == '\n' ||
                                    before == '[' || before == '{' || before == ',' ||
                                    before == ':' || before == '-')) {
      quote = c;
    } else if (c == '[' || c == '{') {
      SECURE_CHECK(++flow + dashes <= limit, source << ":" << line << ": nested more than "
                                                    << limit
                                                    << " levels deep (raise the limit with "
                                                       "SECURE_MAX_CONFIG_DEPTH)");
    } else if ((c == ']' || c == '}') && flow > 0) {
      --flow;
    }
  }
}

}  // namespace secure
