#pragma once
#include <string>
#include <vector>

namespace secure {

/// "a, b, c": names joined for messages.
inline std::string Join(const std::vector<std::string>& parts,
                        const std::string& separator = ", ") {
  std::string out;
  for (std::size_t i = 0; i < parts.size(); ++i) {
    if (i > 0) out += separator;
    out += parts[i];
  }
  return out;
}

}  // namespace secure
