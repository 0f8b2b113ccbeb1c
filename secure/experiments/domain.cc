#include "secure/experiments/domain.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "secure/common/error.h"
#include "secure/common/option_check.h"
#include "secure/experiments/experiment.h"

namespace secure::experiments {

std::vector<LabelCheckRow> Domain::CheckLabels(std::uint64_t, long) const {
  SECURE_THROW("the " << name() << " domain has no label check (it cannot simulate forward from "
                         "a labelled state)");
}

std::unique_ptr<Population> Domain::MakePopulation(const PopulationOptions&) const {
  SECURE_THROW("the " << name() << " domain has no participants for a user study (domains with "
                         "one: those whose Domain::HasPopulation() is true)");
}

void Domain::CheckHeldOut(std::uint64_t, long, data::StateSet*, data::StateSet*) const {
  SECURE_THROW("the " << name() << " domain has no barrier check");
}

cbf::BarrierCheckProblem Domain::MakeCheckProblem(const shield::ShieldOptions&,
                                                  const data::StateSet&, const data::StateSet&,
                                                  std::unique_ptr<domains::DynamicsModel>*) const {
  SECURE_THROW("the " << name() << " domain has no barrier check");
}

GroundTruthSample Domain::SampleGroundTruth(long, long, std::uint64_t) const {
  SECURE_THROW("the " << name() << " domain has no ground truth to sample labelled states from");
}

ShieldRunRequest Domain::ShieldRunPreset() const {
  SECURE_THROW("the " << name() << " domain has no shield run");
}

ShieldRunReport Domain::RunShield(const ShieldRunRequest&, cbf::Barrier&) const {
  SECURE_THROW("the " << name() << " domain has no shield run");
}

void CheckExperimentOptions(const Domain& domain, const ExperimentOptions& options) {
  const double period = domain.MakeEnvironment()->control_period();
  SECURE_CHECK_FIELD(period <= 0.0 || std::abs(options.shield.dt - period) < 1e-12,
                     "ExperimentOptions", "shield.dt", options.shield.dt,
                     "the control period of the " << domain.name() << " environment (" << period
                                                  << " s): the shield's model looks one step ahead");
  domain.CheckExperiment(options);
}

DomainRegistry& DomainRegistry::Global() {
  static DomainRegistry registry;
  return registry;
}

void DomainRegistry::Add(const std::string& name, const std::string& summary,
                         DomainFactory factory) {
  const bool well_formed =
      !name.empty() && std::all_of(name.begin(), name.end(), [](char c) {
        return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-';
      });
  SECURE_CHECK(well_formed, "domain name '" << name
                                            << "': must be non-empty lower-case letters, digits "
                                               "and '-'");
  SECURE_CHECK(!Has(name), "domain '" << name << "' is registered twice");
  SECURE_CHECK(factory != nullptr, "domain '" << name << "': no factory");
  entries_.push_back({name, summary, std::move(factory)});
  std::sort(entries_.begin(), entries_.end(),
            [](const Entry& a, const Entry& b) { return a.name < b.name; });
}

bool DomainRegistry::Has(const std::string& name) const {
  return std::any_of(entries_.begin(), entries_.end(),
                     [&](const Entry& e) { return e.name == name; });
}

std::unique_ptr<Domain> DomainRegistry::Make(const std::string& name, Profile profile) const {
  for (const Entry& e : entries_) {
    if (e.name != name) continue;
    std::unique_ptr<Domain> domain = e.factory(profile);
    SECURE_CHECK(domain != nullptr && domain->name() == name,
                 "the factory of domain '" << name << "' made another domain");
    return domain;
  }
  SECURE_THROW("unknown domain '" << name << "' (registered: " << NameList() << ")");
}

std::vector<std::string> DomainRegistry::Names() const {
  std::vector<std::string> names;
  for (const Entry& e : entries_) names.push_back(e.name);
  return names;
}

std::string DomainRegistry::NameList() const {
  std::string list;
  for (const Entry& e : entries_) list += (list.empty() ? "" : " | ") + e.name;
  return list.empty() ? "none" : list;
}

std::string DomainRegistry::Summaries() const {
  std::ostringstream out;
  for (const Entry& e : entries_) out << "  " << e.name << "  " << e.summary << "\n";
  return out.str();
}

std::string DomainRegistry::ListOffering(
    const std::function<bool(const Domain&)>& offers) const {
  std::string list;
  for (const Entry& e : entries_)
    if (offers(*Make(e.name, Profile::kQuick))) list += (list.empty() ? "" : ", ") + e.name;
  return list.empty() ? "none" : list;
}

}  // namespace secure::experiments
