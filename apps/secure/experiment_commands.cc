// The experiments as commands, on any registered domain (secure/experiments/experiment.h):
//   secure experiment KIND --domain NAME   KIND: method-comparison | joint | ablation | sensitivity
//   secure experiment derby-table3 | derby-joint | derby-ablation | derby-sensitivity
//                                          aliases: KIND on the derby domain
//   secure demo                            the main job: the method comparison on the double
//                                          integrator with every method (BC, AIRL, SECURE, the
//                                          two shield ablations, BC + shield)
// Each prints a Markdown table (or, with --json, the result document in the format of
// `secure eval --json`); --quick is the domain's small profile, used by the tests.
#include <iostream>
#include <memory>
#include <string>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/enum_strings.h"
#include "secure/common/filesystem.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace secure::cli {
namespace {

using experiments::ExperimentKind;

struct ExperimentCommand {
  std::string command_name;  // "demo", "experiment ablation", ...
  ExperimentKind kind = ExperimentKind::kMethodComparison;
  std::string domain;        // fixed for the aliases, else from --domain
  bool all_methods = false;  // demo: every method of eval::AllMethods()
  bool quick = false;
  bool json = false;
  int seeds = 0;
  long episodes = 0;
  std::uint64_t first_seed = 0;
  int threads = 2;
  std::string barrier, methods, out;
  const Config* config = nullptr;
  CLI::Option* seeds_option = nullptr;
  CLI::Option* episodes_option = nullptr;

  CLI::App* Register(CLI::App& parent, const Config& cfg, const std::string& name,
                     const std::string& description, ExperimentKind which,
                     const std::string& fixed_domain) {
    kind = which;
    domain = fixed_domain;
    config = &cfg;
    command_name = (parent.get_name() == "experiment" ? "experiment " : "") + name;
    CLI::App* cmd = parent.add_subcommand(name, description);
    AddConfigFlag(cmd, cfg);
    const experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
    if (fixed_domain.empty()) {
      cmd->add_option("--domain", domain, "the domain: " + registry.NameList())->required();
    }
    cmd->add_flag("--quick", quick,
                  "the domain's small profile (2 seeds, few episodes, short training)");
    seeds_option = cmd->add_option(
        "--seeds", seeds,
        "seeds, at most " + std::to_string(kMaxSeeds) + " (default: the domain's; 10)");
    episodes_option = cmd->add_option("--episodes", episodes,
                                      "episodes per method and seed, at most " +
                                          std::to_string(kMaxEpisodes) + " (default: 100)");
    AddSeedOption(cmd, "--first-seed", &first_seed, "seeds first-seed, first-seed + 1, ...");
    cmd->add_option("--threads", threads, "seeds run in parallel")->capture_default_str();
    cmd->add_option("--barrier", barrier,
                    "flat (an MLP on the whole state) or per-obstacle (alias per-car: one MLP "
                    "per obstacle, the minimum over those in range) (default: the domain's)");
    cmd->add_option("--methods", methods,
                    "comma-separated subset of bc, airl, secure, secure-random-safe, "
                    "secure-no-resampling, bc+shield, secure-myopic, joint (default: the "
                    "experiment's)");
    cmd->add_option("--out", out,
                    "directory for the data, per-seed models and learning curves, result.json");
    cmd->add_flag("--json", json, "print the result document (as `secure eval --json`)");
    cmd->callback([this] { Run(); });
    return cmd;
  }

  void Run() {
    config->Check();
    // A given --seeds / --episodes must be usable (0 is not "the default").
    if (seeds_option->count() > 0) CheckRange("--seeds", seeds, 1, kMaxSeeds);
    if (episodes_option->count() > 0) CheckRange("--episodes", episodes, 1, kMaxEpisodes);
    const std::unique_ptr<experiments::Domain> d = experiments::DomainRegistry::Global().Make(
        domain, quick ? experiments::Profile::kQuick : experiments::Profile::kFull);
    experiments::ExperimentOptions options = d->Preset();
    if (all_methods) options.methods = eval::AllMethods();
    const std::string section = d->ConfigSection();
    const YAML::Node yaml = config->Section(section);
    if (yaml.IsMap()) options.ApplyYaml(yaml, config->path + " [" + section + "]", d.get());
    if (seeds_option->count() > 0) options.seeds = seeds;
    if (episodes_option->count() > 0) options.episodes = episodes;
    if (!methods.empty()) options.methods = eval::ParseMethods(methods);
    if (!barrier.empty()) {
      options.barrier_kind =
          barrier == "per-car" ? experiments::BarrierKind::kPerObstacle
                               : FromString(experiments::kBarrierKindNames, barrier, "--barrier");
    }
    options.first_seed = first_seed;
    options.threads = threads;
    options.output_dir = out;
    d->Validate();           // before the first line of progress
    options.Validate();
    d->CheckExperiment(options);
    CreateDirectories(out);  // (also done by the run) an unusable --out fails before any output
    std::cerr << "secure " << command_name << " on " << d->name() << ": " << options.seeds
              << " seeds x " << options.episodes << " episodes per method on "
              << options.threads << " threads" << (out.empty() ? "" : ", writing to " + out)
              << "\n";
    const experiments::ExperimentResult result =
        experiments::RunExperiment(kind, *d, options, &std::cerr);
    if (json) {
      nlohmann::json r = result.ToJson();
      r["command"] = command_name;
      PrintJson(r);
    } else {
      std::cout << "\n"
                << result.Table() << "\nData: " << result.demonstrations
                << " expert demonstrations (" << result.discarded_demonstrations
                << " discarded), " << result.safe_states << " safe + "
                << result.near_dangerous_states << " near-dangerous states. Total "
                << result.seconds << " s.\n";
    }
  }
};

}  // namespace

void RegisterExperimentCommands(CLI::App& app, const Config& config) {
  static ExperimentCommand demo;
  static ExperimentCommand kinds[4];
  static ExperimentCommand derby[4];
  demo.all_methods = true;
  demo.Register(app, config, "demo",
                "The main job: the complete SECURE pipeline on the double-integrator reach-avoid "
                "task (demonstrations, learned barrier, BC and AIRL, every method evaluated over "
                "seeds) and its results table",
                ExperimentKind::kMethodComparison, "double-integrator");

  CLI::App* cmd = app.add_subcommand(
      "experiment", "The paper's experiments (Section 6) on any domain: " +
                        experiments::DomainRegistry::Global().NameList());
  cmd->require_subcommand(1);
  const struct {
    ExperimentKind kind;
    const char* alias;
    const char* description;
  } table[4] = {
      {ExperimentKind::kMethodComparison, "derby-table3",
       "Table 3 row: BC, AIRL and SECURE over seeds; Mann-Whitney U and TOST of SECURE against "
       "AIRL"},
      {ExperimentKind::kJoint, "derby-joint",
       "The joint-optimisation baseline (AIRL with the barrier's derivative condition as an "
       "extra loss) next to AIRL and SECURE"},
      {ExperimentKind::kAblation, "derby-ablation",
       "Figure 9: SECURE, random safe action, no adaptive resampling (Kruskal-Wallis + Dunn), "
       "and the myopic test h(T(s, a)) >= 0"},
      {ExperimentKind::kSensitivity, "derby-sensitivity",
       "Section 6.3: SECURE with barriers from reduced, imbalanced and label-flipped data"},
  };
  for (int i = 0; i < 4; ++i) {
    kinds[i].Register(*cmd, config, ToString(experiments::kExperimentKindNames, table[i].kind),
                      table[i].description, table[i].kind, "");
    derby[i].Register(*cmd, config, table[i].alias,
                      std::string(table[i].description) + " (on the derby domain)",
                      table[i].kind, "derby");
  }
}

}  // namespace secure::cli
