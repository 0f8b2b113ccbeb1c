// secure demos check-labels --domain NAME: the data's labels against the domain's physics
// (experiments::Domain::CheckLabels).
#include <yaml-cpp/yaml.h>

#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>

#include "commands.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace secure::cli {
namespace {

struct CheckLabelsCommand {
  const Config* config = nullptr;
  std::string domain;
  bool quick = false, json = false;
  std::uint64_t seed = 0;
  long max_states = 300;
  CLI::Option* seed_option = nullptr;

  void Register(CLI::App& demos, const Config& cfg) {
    config = &cfg;
    CLI::App* cmd = demos.add_subcommand(
        "check-labels",
        "Check the safe and near-dangerous labels of a domain's data against its physics: "
        "simulate forward from each labelled state and count dangerous events");
    AddDomainOption(cmd, &domain, kLabelCheck)->required();
    cmd->add_flag("--quick", quick, "the domain's small profile");
    AddConfigFlag(cmd, cfg);  // the domain's options: section <domain's>, key `domain`
    seed_option = AddSeedOption(cmd, "--seed", &seed,
                                "data seed (default: the domain's experiment data seed)");
    cmd->add_option("--max-states", max_states, "states checked per row (default 300)");
    cmd->add_flag("--json", json, "print the rows as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    config->Check();
    CheckRange("--max-states", max_states, 1, 100000000);
    const std::unique_ptr<experiments::Domain> d = MakeConfiguredDomain(domain, quick, *config);
    RequireCapability(*d, domain, kLabelCheck, "",
                      "it cannot simulate forward from a labelled state; ");
    const std::uint64_t data_seed = seed_option->count() > 0 ? seed : d->Preset().data_seed;
    const std::vector<experiments::LabelCheckRow> rows = d->CheckLabels(data_seed, max_states);
    if (json) {
      nlohmann::json r = {{"command", "demos check-labels"},
                          {"domain", domain},
                          {"data_seed", data_seed},
                          {"procedure", d->LabelCheckDescription()},
                          {"domain_options", d->OptionsJson()},
                          {"rows", nlohmann::json::array()}};
      for (const auto& row : rows)
        r["rows"].push_back({{"set", row.set},
                             {"label", row.label},
                             {"states", row.states},
                             {"dangerous", row.dangerous},
                             {"skipped", row.skipped},
                             {"dangerous_fraction", row.DangerousFraction()}});
      PrintJson(r);
      return;
    }
    std::cout << "Labels of the " << domain << " data (seed " << data_seed
              << ") against physics: " << d->LabelCheckDescription() << "\n\n"
              << "| states | labelled | checked | out of reach | dangerous % |\n"
              << "|---|---|---|---|---|\n";
    for (const auto& row : rows) {
      std::ostringstream pct;
      pct << std::fixed << std::setprecision(1) << 100.0 * row.DangerousFraction();
      std::cout << "| " << row.set << " | " << row.label << " | " << row.states << " | "
                << row.skipped << " | " << pct.str() << " |\n";
    }
  }
};

}  // namespace

void RegisterLabelCheckCommand(CLI::App& demos, const Config& config) {
  static CheckLabelsCommand command;
  command.Register(demos, config);
}

}  // namespace secure::cli
