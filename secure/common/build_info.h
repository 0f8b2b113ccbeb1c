#pragma once
#include <nlohmann/json.hpp>

namespace secure {

/// The toolkit version ("0.1.0").
const char* Version();
/// The git commit the binary was configured from ("unknown" outside a checkout).
const char* GitSha();
/// {"version", "git_sha", "build_type"}: the context block of every --json result.
nlohmann::json BuildContext();

}  // namespace secure
