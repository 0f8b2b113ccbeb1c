#pragma once
// The domains the contract suites run over: every plug-in of the build
// (secure::plugins::RegisterBuiltinDomains: the built-ins under domains/ and the example plug-in
// examples/toy_domain), in the process-wide registry. A new plug-in is picked up without touching
// the tests.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "secure/common/rng.h"
#include "secure/experiments/domain.h"

namespace secure::test {

/// Registers the plug-ins (once) and returns every registered name.
inline std::vector<std::string> ContractDomainNames() {
  experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
  plugins::RegisterBuiltinDomains(registry);
  return registry.Names();
}

/// A deterministic action sequence: uniform in [-2, 2] per component (inside every domain's
/// actuator bounds, or clipped to them).
inline void DrawAction(Rng& rng, Eigen::Ref<Eigen::VectorXf> action) {
  for (Eigen::Index i = 0; i < action.size(); ++i)
    action[i] = static_cast<float>(rng.Uniform(-2.0, 2.0));
}

/// "double-integrator" -> "double_integrator" (gtest parameter names).
inline std::string ParamName(const std::string& name) {
  std::string s = name;
  for (char& c : s)
    if (c == '-') c = '_';
  return s;
}

}  // namespace secure::test
