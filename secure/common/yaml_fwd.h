#pragma once
// Forward declarations of the types an options struct's public header names in its ApplyYaml
// and Fields declarations (YAML::Node, secure::YamlFields), so that the header includes neither
// yaml-cpp nor yaml_fields.h (like <iosfwd>). The struct's source includes both.

namespace YAML {
class Node;
}  // namespace YAML

namespace secure {
class YamlFields;
}  // namespace secure
