#pragma once
// ToString / FromString for enums from one table, shared by the CLI, config files and reports.
//
//   enum class Activation { kRelu, kTanh };
//   inline constexpr EnumTable<Activation, 2> kActivationNames{{
//       {Activation::kRelu, "relu"}, {Activation::kTanh, "tanh"}}};
//   ToString(kActivationNames, a);  FromString(kActivationNames, "tanh", "activation");
//   NameOf(kActivationNames, a);  // the same name as a const char*

#include <array>
#include <string>
#include <string_view>
#include <utility>

#include "secure/common/error.h"

namespace secure {

template <typename E, std::size_t N>
using EnumTable = std::array<std::pair<E, std::string_view>, N>;

template <typename E, std::size_t N>
std::string ToString(const EnumTable<E, N>& table, E value) {
  for (const auto& [v, name] : table)
    if (v == value) return std::string(name);
  SECURE_INTERNAL_CHECK(false, "enum value missing from its name table");
}

/// The name of `value` as a C string (the table's names are string literals), or `unknown` if the
/// table lacks it: for names kept as `const char*` (reports, labels, benchmarks).
template <typename E, std::size_t N>
const char* NameOf(const EnumTable<E, N>& table, E value, const char* unknown = "?") {
  for (const auto& [v, name] : table)
    if (v == value) return name.data();
  return unknown;
}

/// Parses `text`; `what` names the field in the error ("activation = 'sigmoid', must be one of
/// relu, tanh").
template <typename E, std::size_t N>
E FromString(const EnumTable<E, N>& table, std::string_view text, std::string_view what) {
  for (const auto& [v, name] : table)
    if (name == text) return v;
  std::string choices;
  for (const auto& entry : table)
    choices += (choices.empty() ? "" : ", ") + std::string(entry.second);
  SECURE_THROW(what << " = '" << text << "', must be one of " << choices);
}

}  // namespace secure
