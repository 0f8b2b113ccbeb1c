#pragma once
// What the Franka plug-ins' experiments::Domain classes share: the description (the
// environment's own), the barrier check that every one of them offers (HasCheck, and
// MakeCheckProblem: franka::ArmCheckProblem on the plug-in's CheckSpec()), and the label check's
// rows (one per set checked; the near-dangerous states split by their generator's scenario). The
// environment, the data, the held-out states and the check's noise and unsafe test stay the
// plug-in's. MuJoCo-free, so the plug-ins' public headers (domain.h) may include it.
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "domains/franka/arm_check.h"
#include "secure/data/data.h"
#include "secure/experiments/options_domain.h"

namespace secure::domains::franka {

/// The base of a Franka plug-in's Domain: OptionsDomain<Options> with Describe() from the
/// plug-in's MakeEnvironment() and the barrier check offered.
template <typename Options>
class ArmDomain : public experiments::OptionsDomain<Options> {
 public:
  /// The environment's description (MakeEnvironment()->Describe()).
  std::string Describe() const override { return this->MakeEnvironment()->Describe(); }
  bool HasCheck() const override { return true; }
  /// The options validated, then ArmCheckProblem (arm_check.h) on CheckSpec() (its `domain`
  /// set to name()) with MakeEnvironment()'s shield model.
  cbf::BarrierCheckProblem MakeCheckProblem(
      const shield::ShieldOptions& shield, const data::StateSet& safe,
      const data::StateSet& near_dangerous,
      std::unique_ptr<DynamicsModel>* dynamics) const override {
    this->options_.Validate();
    ArmCheckSpec spec = CheckSpec();
    spec.domain = this->name();
    return ArmCheckProblem(spec, this->MakeEnvironment(), shield, safe, near_dangerous, dynamics);
  }

 protected:
  using experiments::OptionsDomain<Options>::OptionsDomain;
  /// The plug-in's part of its barrier check (perturbation, projection, unsafe test and their
  /// descriptions), from valid options.
  virtual ArmCheckSpec CheckSpec() const = 0;
};

/// A label check's row: `states` checked of the set `set` (labelled `label` by the data),
/// `dangerous` of them ended in a dangerous event, `skipped` could not be simulated.
experiments::LabelCheckRow LabelRow(const std::string& set, const std::string& label, long states,
                                    long dangerous, long skipped);

/// The columns `columns` of `from`, with its features and source.
data::StateSet SelectStates(const data::StateSet& from, const std::vector<long>& columns);

/// For each scenario of `order` that `kinds` (the scenario of each column of `near`) holds:
/// add("near-dangerous (<ScenarioName(scenario)>)", "near-dangerous", its columns of `near`).
template <typename Scenario, typename Add>
void AddScenarioRows(const data::StateSet& near, const std::vector<Scenario>& kinds,
                     std::initializer_list<Scenario> order, Add&& add) {
  for (Scenario k : order) {
    std::vector<long> columns;
    for (long i = 0; i < static_cast<long>(kinds.size()); ++i)
      if (kinds[static_cast<std::size_t>(i)] == k) columns.push_back(i);
    if (columns.empty()) continue;
    add(std::string("near-dangerous (") + ScenarioName(k) + ")", "near-dangerous",
        SelectStates(near, columns));
  }
}

}  // namespace secure::domains::franka
