// The extension module secure._secure (the package python/secure/ re-exports it).
#include "python/src/common.h"

namespace secure::python {
void RegisterQuery(py::module_& m);  // query.cc: secure.query, secure.label
void RegisterReport(py::module_& m);  // report.cc: secure.paper_reference, secure.report_hints
// arg_bounds.cc: every function's arguments within the config limits before pybind11 sees them
// (its error message would repr() a value of 9^9 shared references without end).
void BoundArgumentSizes(py::module_& m, const char* any_function);
}  // namespace secure::python

PYBIND11_MODULE(_secure, m) {
  using namespace secure::python;
  m.doc() = "SECURE: learned control barrier functions and the CBF shield (C++ library binding)";
  // The domain plug-ins of this build, as the CLI registers them.
  secure::plugins::RegisterBuiltinDomains(secure::experiments::DomainRegistry::Global());
  // Classes before the functions that take or return them, so that signatures name them
  // (help(), the stub python/secure/_secure.pyi): the shield takes an AirlReward (policy.cc).
  RegisterCommon(m);
  RegisterBarrier(m);
  RegisterPolicy(m);
  RegisterDynamics(m);
  RegisterShield(m);
  RegisterEnvironment(m);
  RegisterRender(m);
  RegisterQuery(m);
  RegisterReport(m);
  BoundArgumentSizes(m, "domains");  // last: every function is defined
}
