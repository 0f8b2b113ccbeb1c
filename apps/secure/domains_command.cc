// secure domains [NAME] [--quick] [--json]: the registered domains and what each offers; with a
// NAME, the values its preset gives the commands that take --domain (the shield flags shown as
// "=preset" in `eval`, `render` and `shield run` help, the experiment's seeds and episodes, the
// ground truth's trainer preset, the shield run's values) and its own options. Names no domain:
// everything comes from the registry.
#include <iostream>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/enum_strings.h"
#include "secure/common/strings.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace secure::cli {
namespace {

// The capabilities `d` offers, by the commands that use them.
std::vector<std::string> Capabilities(const experiments::Domain& d) {
  std::vector<std::string> c;
  if (d.HasCheck()) c.push_back("barrier check (cbf check)");
  if (d.HasLabelCheck()) c.push_back("label check (demos check-labels)");
  if (d.HasGroundTruth())
    c.push_back("ground truth (cbf validate, cbf train --domain, cbf table1, --barrier ground-truth)");
  if (d.HasShieldRun()) c.push_back("shield run (shield run)");
  if (d.HasPopulation()) c.push_back("participants (experiment user-study)");
  if (d.PaperReference()) c.push_back("the paper's Table 3 row (experiment method-comparison)");
  if (d.MakeReportHints()) c.push_back("report picture hints (report)");
  return c;
}

// The shield's options as the flags that set them, "--samples 64 --safe-ratio 0.1 ...": the
// ShieldFlags of a scratch command, their defaults captured from `options`.
std::vector<std::pair<std::string, std::string>> ShieldFlagValues(
    const shield::ShieldOptions& options) {
  CLI::App scratch;
  shield::ShieldOptions copy = options;
  ShieldFlags flags;
  flags.Add(&scratch, &copy);
  std::vector<std::pair<std::string, std::string>> values;
  for (const CLI::Option* o : scratch.get_options()) {
    if (o->get_name() == "--help") continue;
    values.emplace_back(o->get_name(), o->get_default_str());
  }
  return values;
}

std::string FlagLine(const std::vector<std::pair<std::string, std::string>>& values) {
  std::string line;
  for (const auto& [flag, value] : values) line += (line.empty() ? "" : " ") + flag + " " + value;
  return line;
}

struct DomainsCommand {
  std::string name;
  bool quick = false, json = false;

  void Register(CLI::App& app) {
    CLI::App* cmd = app.add_subcommand(
        "domains",
        "The registered domains and what each offers; with NAME, the values its preset gives "
        "the commands (the flags whose help shows =preset) and its options");
    cmd->add_option("name", name,
                    "a domain: " + experiments::DomainRegistry::Global().NameList());
    cmd->add_flag("--quick", quick, "the domain's small profile (as `secure experiment --quick`)");
    cmd->add_flag("--json", json, "print the result as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() const {
    const experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
    const experiments::Profile profile =
        quick ? experiments::Profile::kQuick : experiments::Profile::kFull;
    if (name.empty()) {
      nlohmann::json list = nlohmann::json::array();
      for (const std::string& n : registry.Names()) {
        const std::unique_ptr<experiments::Domain> d = registry.Make(n, profile);
        const std::vector<std::string> capabilities = Capabilities(*d);
        if (json) {
          list.push_back({{"name", n}, {"describe", d->Describe()}, {"capabilities", capabilities}});
        } else {
          std::cout << n << ": " << d->Describe() << "\n  offers: "
                    << (capabilities.empty() ? "nothing optional" : Join(capabilities, "; "))
                    << "\n";
        }
      }
      if (json) PrintJson({{"command", "domains"}, {"domains", list}});
      return;
    }
    const std::unique_ptr<experiments::Domain> d = registry.Make(name, profile);
    const experiments::ExperimentOptions preset = d->Preset();
    const std::unique_ptr<domains::Environment> env = d->MakeEnvironment();
    nlohmann::json r = {{"command", "domains"},
                        {"domain", name},
                        {"profile", quick ? "quick" : "full"},
                        {"describe", d->Describe()},
                        {"capabilities", Capabilities(*d)},
                        {"config_section", d->ConfigSection()},
                        {"observation_features", env->ObservationFeatures()},
                        {"action_features", env->ActionFeatures()},
                        {"options", d->OptionsJson()},
                        {"preset", preset.ToJson()}};
    const auto shield = ShieldFlagValues(preset.shield);
    if (d->HasGroundTruth()) {
      r["ground_truth"] = {{"parameters", d->GroundTruthJson()},
                           {"section", d->GroundTruthSection()},
                           {"trainer_preset", d->GroundTruthTrainerPreset().ToJson()}};
    }
    std::vector<std::pair<std::string, std::string>> run_shield;
    if (d->HasShieldRun()) {
      const experiments::ShieldRunRequest run = d->ShieldRunPreset();
      run_shield = ShieldFlagValues(run.shield);
      r["shield_run"] = {{"episodes", run.episodes},
                         {"seed", run.seed},
                         {"policy_sigma", run.policy_sigma},
                         {"shield", run.shield.ToJson()}};
    }
    if (json) {
      PrintJson(r);
      return;
    }
    std::cout << name << ": " << d->Describe() << "\n"
              << "offers: "
              << (Capabilities(*d).empty() ? "nothing optional" : Join(Capabilities(*d), "; "))
              << "\n"
              << "observation: " << Join(env->ObservationFeatures()) << "\n"
              << "action: " << Join(env->ActionFeatures()) << "\n"
              << "experiment preset (secure experiment; eval, render and cbf check start from it):"
              << " seeds " << preset.seeds << ", episodes " << preset.episodes << ", data_seed "
              << preset.data_seed << ", barrier "
              << ToString(experiments::kBarrierKindNames, preset.barrier_kind)
              << (preset.closed_loop.enabled
                      ? ", closed-loop check " + preset.closed_loop.ToJson().dump()
                      : std::string())
              << "\n"
              << "  shield (the =preset flags of eval and render): " << FlagLine(shield) << "\n";
    if (d->HasGroundTruth()) {
      std::cout << "ground truth: " << d->GroundTruthJson().dump()
                << (d->GroundTruthSection().empty()
                        ? std::string()
                        : " (config section " + d->GroundTruthSection() + ")")
                << "\n  trainer preset (cbf train --domain, cbf table1): "
                << d->GroundTruthTrainerPreset().ToJson().dump() << "\n";
    }
    if (d->HasShieldRun()) {
      const experiments::ShieldRunRequest run = d->ShieldRunPreset();
      std::cout << "shield run (the =preset flags of shield run): --episodes " << run.episodes
                << " --seed " << run.seed << " --policy-sigma " << run.policy_sigma << " "
                << FlagLine(run_shield) << "\n";
    }
    std::cout << "options (config section " << d->ConfigSection()
              << ", key domain; the task flags set task.*): " << d->OptionsJson().dump() << "\n";
  }
};

}  // namespace

void RegisterDomainsCommand(CLI::App& app) {
  static DomainsCommand command;
  command.Register(app);
}

}  // namespace secure::cli
