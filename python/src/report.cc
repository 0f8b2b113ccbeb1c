// secure.paper_reference and secure.report_hints: what tools/report asks of a domain, through the
// registry (experiments/report_hints.h), so that the report names no domain.
#include <memory>
#include <string>

#include "python/src/common.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/report_hints.h"

namespace secure::python {

SECURE_PYTHON_TYPE(OptionalHints, "Optional[Dict[str, Any]]");

void RegisterReport(py::module_& m) {
  m.def(
      "paper_reference",
      [](const std::string& domain, const std::string& profile, py::kwargs options) -> JsonDict {
        const std::unique_ptr<experiments::Domain> d = MakeDomain(domain, profile, options);
        return ToPython(experiments::PaperReferenceJson(*d));
      },
      py::arg("domain"), py::arg("profile") = "full", R"doc(
The paper's numbers for a domain (with its options), a dict with the keys it has: 'table3'
({'source', 'rows': [{'method', 'success', 'success_std', 'dangerous', 'dangerous_std'}] in %,
None where the paper gives none, 'comparison'}), 'ground_truth_study' (Table 1, %),
'user_study' ({'source', 'rows': [{'what', 'values'}]}). {} if the paper has none.)doc");
  m.def(
      "report_hints",
      [](const std::string& domain, const std::string& profile,
         py::kwargs options) -> OptionalHints {
        const std::unique_ptr<experiments::Domain> d = MakeDomain(domain, profile, options);
        const nlohmann::json hints = experiments::ReportHintsJson(*d);
        return hints.is_null() ? py::none() : ToPython(hints);
      },
      py::arg("domain"), py::arg("profile") = "full", R"doc(
How the report draws a domain (with its options): {'barrier': dict or None, 'trajectories':
dict or None} (the schema: tools/report/README.md, "Report hints"), or None if the domain gives
no hints.)doc");
}

}  // namespace secure::python
