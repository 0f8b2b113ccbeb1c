// The paper's Demolition Derby experiments as commands (experiments/derby_experiments.h):
//   secure experiment derby-table3       BC, AIRL, SECURE (Table 3 row)
//   secure experiment derby-joint        the joint-optimisation baseline (Section 4.1)
//   secure experiment derby-ablation     random-safe, no-resampling and myopic ablations
//   secure experiment derby-sensitivity  barrier data size, imbalance and label noise
// Each prints a Markdown table (or, with --json, the result document in the format of
// `secure eval --json`); --quick is the small profile used by the tests.
#include <iostream>
#include <string>

#include "cli_common.h"
#include "commands.h"
#include "secure/common/enum_strings.h"
#include "secure/common/filesystem.h"
#include "secure/experiments/derby_experiments.h"

namespace secure::cli {
namespace {

struct ExperimentCommand {
  experiments::DerbyExperiment experiment = experiments::DerbyExperiment::kTable3;
  bool quick = false;
  bool json = false;
  int seeds = 0;
  long episodes = 0;
  std::uint64_t first_seed = 0;
  int threads = 2;
  std::string barrier = "per-car";
  std::string out;
  YAML::Node config_section;
  std::string config_path;
  CLI::Option* seeds_option = nullptr;
  CLI::Option* episodes_option = nullptr;
  DeferredError config_error;

  void Register(CLI::App& parent, const Config& config, experiments::DerbyExperiment which,
                const std::string& description) {
    experiment = which;
    CLI::App* cmd =
        parent.add_subcommand(ToString(experiments::kDerbyExperimentNames, which), description);
    config_error.Capture([&] { config_section = config.Section("derby"); });
    config_path = config.path;
    AddConfigFlag(cmd, config);
    cmd->add_flag("--quick", quick, "a small profile for tests (2 seeds x 10 episodes, short "
                                    "training)");
    seeds_option = cmd->add_option(
        "--seeds", seeds,
        "seeds, at most " + std::to_string(kMaxSeeds) + " (default: 10; --quick: 2)");
    episodes_option = cmd->add_option("--episodes", episodes,
                                      "episodes per method and seed, at most " +
                                          std::to_string(kMaxEpisodes) + " (default: 100)");
    AddSeedOption(cmd, "--first-seed", &first_seed, "seeds first-seed, first-seed + 1, ...");
    cmd->add_option("--threads", threads, "seeds run in parallel")->capture_default_str();
    cmd->add_option("--barrier", barrier,
                    "per-car (the permutation-invariant per-car network) or flat (an MLP on the "
                    "52-number observation)")
        ->capture_default_str();
    cmd->add_option("--out", out, "directory for the data, per-seed models, result.json");
    cmd->add_flag("--json", json, "print the result document (as `secure eval --json`)");
    cmd->callback([this] {
      config_error.Rethrow();
      Run();
    });
  }

  void Run() {
    // A given --seeds / --episodes must be usable (0 is not "the default").
    if (seeds_option->count() > 0) CheckRange("--seeds", seeds, 1, kMaxSeeds);
    if (episodes_option->count() > 0) CheckRange("--episodes", episodes, 1, kMaxEpisodes);
    experiments::DerbyExperimentOptions options =
        quick ? experiments::DerbyExperimentOptions::Quick()
              : experiments::DerbyExperimentOptions::Default();
    if (config_section.IsMap()) options.ApplyYaml(config_section, config_path + " [derby]");
    if (seeds_option->count() > 0) options.seeds = seeds;
    if (episodes_option->count() > 0) options.episodes = episodes;
    options.first_seed = first_seed;
    options.threads = threads;
    options.output_dir = out;
    options.barrier_kind = FromString(experiments::kDerbyBarrierKindNames, barrier, "--barrier");
    options.Validate();      // before the first line of progress
    CreateDirectories(out);  // (also done by the run) an unusable --out fails before any output
    const std::string name = ToString(experiments::kDerbyExperimentNames, experiment);
    std::cerr << "secure experiment " << name << ": " << options.seeds << " seeds x "
              << options.episodes << " episodes on " << options.threads << " threads"
              << (out.empty() ? "" : ", writing to " + out) << "\n";
    const experiments::DerbyExperimentResult result =
        experiments::RunDerbyExperiment(experiment, options, &std::cerr);
    if (json) {
      nlohmann::json r = result.ToJson();
      r["command"] = "experiment " + name;
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
  static ExperimentCommand table3, joint, ablation, sensitivity;
  CLI::App* cmd = app.add_subcommand(
      "experiment", "The paper's experiments on the Demolition Derby domain (Section 6)");
  cmd->require_subcommand(1);
  using experiments::DerbyExperiment;
  table3.Register(*cmd, config, DerbyExperiment::kTable3,
                  "Table 3 row: BC, AIRL and SECURE over seeds; Mann-Whitney U and TOST of "
                  "SECURE against AIRL");
  joint.Register(*cmd, config, DerbyExperiment::kJoint,
                 "The joint-optimisation baseline (AIRL with the barrier's derivative condition "
                 "as an extra loss) next to AIRL and SECURE");
  ablation.Register(*cmd, config, DerbyExperiment::kAblation,
                    "Figure 9: SECURE, random safe action, no adaptive resampling "
                    "(Kruskal-Wallis + Dunn), and the myopic test h(T(s, a)) >= 0");
  sensitivity.Register(*cmd, config, DerbyExperiment::kSensitivity,
                       "Section 6.3: SECURE with barriers from reduced, imbalanced and "
                       "label-flipped data");
}

}  // namespace secure::cli
