#pragma once
// A field table for an options struct: each key of a YAML mapping bound to a field (read with
// YamlValue, so a wrong type names the source, key and value) or to a nested section; an unknown
// key is an error naming the source and listing the valid keys. The same table writes the JSON
// object (ToJson: each field under its key, an enum by its name, a nested table as an object), so
// that a struct declares its keys once for reading and writing:
//
//   YamlFields Options::Fields() { return YamlFields().Field("a", &a).Field("b", &b); }
//   SECURE_YAML_JSON_FROM_FIELDS(Options)  // ApplyYaml and ToJson from Fields()
//
// Header-only; a target that includes it links yaml-cpp.
//
//   YamlFields()
//       .Field("safe_states", &o.safe_states)
//       .Part("task", &o.task)
//       .Section("demonstrations", YamlFields().Field("episodes", &o.demonstrations.episodes))
//       .Apply(node, source);
#include <yaml-cpp/yaml.h>

#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
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
  /// Writes a section's JSON value (an entry without one is left out of ToJson).
  using Writer = std::function<nlohmann::json()>;

  /// `key` sets *field (its type decides how the value is read); ToJson writes *field.
  template <typename T>
  YamlFields& Field(const std::string& key, T* field) {
    entries_.push_back({key,
                        [key, field](const YAML::Node& node, const std::string& where) {
                          *field = YamlValue<T>(node, key, where);
                        },
                        [field] { return nlohmann::json(*field); }});
    return *this;
  }
  /// `key` sets the enum *field by its name in `table` (an unknown name lists the valid ones).
  /// ToJson writes the name.
  template <typename E, std::size_t N>
  YamlFields& Enum(const std::string& key, E* field, const EnumTable<E, N>& table) {
    entries_.push_back({key,
                        [key, field, &table](const YAML::Node& node, const std::string& where) {
                          *field = FromString(table, YamlValue<std::string>(node, key, where),
                                              where + " [" + key + "]");
                        },
                        [field, &table] { return nlohmann::json(ToString(table, *field)); }});
    return *this;
  }
  /// `key` read by `read(node, key, source)` with the reader's own rules and messages (e.g. a
  /// list of layer widths); ToJson writes write() under `key` (without `write`, the key is read
  /// only).
  using Reader = std::function<void(const YAML::Node& node, const std::string& key,
                                    const std::string& source)>;
  YamlFields& Custom(const std::string& key, Reader read, Writer write = nullptr) {
    entries_.push_back(
        {key,
         [key, read = std::move(read)](const YAML::Node& node, const std::string& where) {
           read(node, key, where);
         },
         std::move(write)});
    return *this;
  }
  /// `key` is a nested mapping handled by `apply` (given the node and "source [key]"); ToJson
  /// writes write() under `key` (without `write`, the owner writes that key itself).
  YamlFields& Section(const std::string& key, Handler apply, Writer write = nullptr) {
    entries_.push_back(
        {key,
         [key, apply = std::move(apply)](const YAML::Node& node, const std::string& where) {
           apply(node, where + " [" + key + "]");
         },
         std::move(write)});
    return *this;
  }
  /// `key` is a nested mapping read and written with its own field table.
  YamlFields& Section(const std::string& key, YamlFields fields) {
    auto shared = std::make_shared<const YamlFields>(std::move(fields));
    return Section(
        key,
        [shared](const YAML::Node& node, const std::string& where) { shared->Apply(node, where); },
        [shared] { return shared->ToJson(); });
  }

  /// `key` is a nested options struct read by its ApplyYaml and written by its ToJson.
  template <typename Options>
  YamlFields& Part(const std::string& key, Options* part) {
    return Section(
        key,
        [part](const YAML::Node& node, const std::string& where) { part->ApplyYaml(node, where); },
        [part] { return part->ToJson(); });
  }

  /// Names the options in Apply's errors, which then are ForEachYamlField's (the wording of the
  /// hand-written readers a table replaced): "expected a mapping of <what>" and "unknown field
  /// 'k' in the <what> (valid: ...)", the keys in sorted order.
  YamlFields& Named(std::string what) {
    what_ = std::move(what);
    return *this;
  }

  /// The JSON object of the fields' current values, each under its key (sections without a
  /// writer left out).
  nlohmann::json ToJson() const {
    nlohmann::json json = nlohmann::json::object();
    for (const Entry& e : entries_)
      if (e.write) json[e.key] = e.write();
    return json;
  }

  /// Applies every entry of the mapping `node`. @throws secure::Error naming `source` if `node`
  /// is not a mapping, a key is unknown (listing the valid keys) or a value has the wrong type.
  void Apply(const YAML::Node& node, const std::string& source) const {
    if (!what_.empty()) {
      std::set<std::string> known;
      for (const Entry& e : entries_) known.insert(e.key);
      ForEachYamlField(node, known, what_, source,
                       [&](const std::string& key, const YAML::Node& v) {
                         Find(key)->read(v, source);
                       });
      return;
    }
    SECURE_CHECK(node.IsMap(), source << ": expected a mapping");
    for (const auto& item : node) {
      const std::string key = YamlKey(item.first, source);
      const Entry* entry = Find(key);
      SECURE_CHECK(entry != nullptr,
                   source << ": unknown key '" << key << "' (valid: " << Keys() << ")");
      entry->read(item.second, source);
    }
  }

  /// "a, b, c": the keys in table order.
  std::string Keys() const {
    std::string keys;
    for (const Entry& e : entries_) keys += (keys.empty() ? "" : ", ") + e.key;
    return keys;
  }

 private:
  struct Entry {
    std::string key;
    Handler read;
    Writer write;
  };
  // The entry of `key` (the last one, should a key be bound twice), or null.
  const Entry* Find(const std::string& key) const {
    const Entry* entry = nullptr;
    for (const Entry& e : entries_)
      if (e.key == key) entry = &e;
    return entry;
  }
  std::vector<Entry> entries_;
  std::string what_;  // Named(); empty: the generic wording
};

/// The JSON object of `options`' field table (its member `YamlFields Fields()`, which binds the
/// fields of a non-const object: a copy's, read only here).
template <typename Options>
nlohmann::json TableJson(const Options& options) {
  Options copy = options;
  return copy.Fields().ToJson();
}

}  // namespace secure

/// Defines `void Options::ApplyYaml(node, source)` (Fields().Apply) and `nlohmann::json
/// Options::ToJson() const` (TableJson) for a struct that declares the three members: its keys
/// are then written once, in Fields().
#define SECURE_YAML_JSON_FROM_FIELDS(Options)                                  \
  void Options::ApplyYaml(const YAML::Node& node, const std::string& source) { \
    Fields().Apply(node, source);                                              \
  }                                                                            \
  nlohmann::json Options::ToJson() const { return ::secure::TableJson(*this); }
