#pragma once
// The domains the contract suites run over: every built-in plug-in
// (secure::plugins::RegisterBuiltinDomains) plus the tests' toy domain (tests/toy_domain), in the
// process-wide registry. A new plug-in under domains/ is picked up without touching the tests.
#include <Eigen/Core>
#include <string>
#include <vector>

#include "secure/common/rng.h"
#include "secure/experiments/domain.h"
#include "tests/toy_domain/toy_cart.h"

namespace secure::test {

/// Registers the built-in domains and the toy one (once) and returns every registered name.
inline std::vector<std::string> ContractDomainNames() {
  experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
  plugins::RegisterBuiltinDomains(registry);
  RegisterToyCart(registry);  // the one line a test needs for a domain of its own
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
