#pragma once
// A field table for ApplyYaml: each key of a YAML mapping bound to a field (read with
// YamlValue, so a wrong type names the source, key and value) or to a nested section; an unknown
// key is an error naming the source and listing the valid keys. Header-only; a target that
// includes it links yaml-cpp.
//
//   YamlFields()
//       .Field("safe_states", &o.safe_states)
//       .Section("task", [&](const YAML::Node& n, const std::string& where) { o.task.ApplyYaml(n, where); })
//       .Section("demonstrations", YamlFields().Field("episodes", &o.demonstrations.episodes))
//       .Apply(node, source);
#include <yaml-cpp/yaml.h>

#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/common/yaml_value.h"

namespace secure {

class YamlFields {
 public:
  using Handler = std::function<void(const YAML::Node& node, const std::string& where)>;

  /// `key` sets *field (its type decides how the value is read).
  template <typename T>
  YamlFields& Field(const std::string& key, T* field) {
    entries_.emplace_back(key, [key, field](const YAML::Node& node, const std::string& where) {
      *field = YamlValue<T>(node, key, where);
    });
    return *this;
  }
  /// `key` sets the enum *field by its name in `table` (an unknown name lists the valid ones).
  template <typename E, std::size_t N>
  YamlFields& Enum(const std::string& key, E* field, const EnumTable<E, N>& table) {
    entries_.emplace_back(
        key, [key, field, &table](const YAML::Node& node, const std::string& where) {
          *field =
              FromString(table, YamlValue<std::string>(node, key, where), where + " [" + key + "]");
        });
    return *this;
  }
  /// `key` is a nested mapping handled by `apply` (given the node and "source [key]").
  YamlFields& Section(const std::string& key, Handler apply) {
    entries_.emplace_back(key, [key, apply = std::move(apply)](const YAML::Node& node,
                                                               const std::string& where) {
      apply(node, where + " [" + key + "]");
    });
    return *this;
  }
  /// `key` is a nested mapping read with its own field table.
  YamlFields& Section(const std::string& key, YamlFields fields) {
    return Section(key, [fields = std::move(fields)](const YAML::Node& node,
                                                     const std::string& where) {
      fields.Apply(node, where);
    });
  }

  /// Applies every entry of the mapping `node`. @throws secure::Error naming `source` if `node`
  /// is not a mapping, a key is unknown (listing the valid keys) or a value has the wrong type.
  void Apply(const YAML::Node& node, const std::string& source) const {
    SECURE_CHECK(node.IsMap(), source << ": expected a mapping");
    for (const auto& item : node) {
      const std::string key = YamlKey(item.first, source);
      const Entry* entry = nullptr;
      for (const Entry& e : entries_)
        if (e.first == key) entry = &e;
      SECURE_CHECK(entry != nullptr,
                   source << ": unknown key '" << key << "' (valid: " << Keys() << ")");
      entry->second(item.second, source);
    }
  }

  /// "a, b, c": the keys in table order.
  std::string Keys() const {
    std::string keys;
    for (const Entry& e : entries_) keys += (keys.empty() ? "" : ", ") + e.first;
    return keys;
  }

 private:
  using Entry = std::pair<std::string, Handler>;
  std::vector<Entry> entries_;
};

}  // namespace secure
