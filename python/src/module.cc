// The extension module secure._secure (the package python/secure/ re-exports it).
#include "python/src/common.h"

PYBIND11_MODULE(_secure, m) {
  using namespace secure::python;
  m.doc() = "SECURE: learned control barrier functions and the CBF shield (C++ library binding)";
  // The domain plug-ins of this build, as the CLI registers them.
  secure::plugins::RegisterBuiltinDomains(secure::experiments::DomainRegistry::Global());
  RegisterCommon(m);
  RegisterBarrier(m);
  RegisterDynamics(m);
  RegisterShield(m);
  RegisterPolicy(m);
  RegisterEnvironment(m);
}
