// The SECURE pipeline and its stages as commands:
//   secure demos generate         expert demonstrations + safe and near-dangerous states
//   secure policy train           BC or AIRL from a demonstrations CSV
//   secure eval                   saved models of any domain over seeds (every method)
// Every stage reads and writes files, so users can bring their own data at any stage.
#include <cmath>
#include <functional>
#include <iostream>
#include <limits>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "eval_models.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/atomic_file.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/progress.h"
#include "secure/common/timer.h"
#include "secure/data/data.h"
#include "secure/eval/episode_table.h"
#include "secure/eval/policy_eval.h"
#include "secure/experiments/experiment.h"
#include "secure/nn/model_file.h"
#include "secure/nn/torch_threads.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"

namespace secure::cli {
namespace {

// Safe-state augmentation: slowed copies per state (each multiplies the safe set).
constexpr long kMaxSlowedCopies = 100;

// ------------------------------------------------------------------------------------------
struct DemosGenerateCommand {
  std::string domain, out;
  // The data flags. Each given flag becomes one of the domain's own option keys (the table in
  // docs/ADDING_A_DOMAIN.md, "The data flags"); a domain without that key rejects it by name.
  // Flags not given leave the domain's values. Each flag's key is named once, in Register: its
  // help shows it and Run writes it.
  long episodes = 0, safe_states = 0, near_dangerous_count = 0;
  int slowed_copies = 0;
  double rho_min = 0, rho_max = 0;
  bool stop_at_goal = false;
  std::uint64_t seed = 1000;
  bool json = false;
  struct DataFlag {
    CLI::Option* option;
    std::string section, key;           // the option `section.key`, or `key` (no section)
    std::function<YAML::Node()> value;  // range-checked
  };
  std::vector<DataFlag> data_flags;

  // `--<flag>` for the domain option `path` ("section.key" or "key"). `preset`: every domain has
  // the key (the help says the default is the domain's), else a domain without it rejects the
  // flag. An integer is checked to lie in [lo, hi] when the flag is given.
  template <typename T>
  void AddDataFlag(CLI::App* cmd, const std::string& flag, T* value, const std::string& path,
                   const std::string& help, bool preset, long lo = 0, long hi = -1) {
    const std::string full_help =
        help + " (key " + path + "; " +
        (preset ? "default: the domain's" : "a domain without it rejects the flag") + ")";
    CLI::Option* option = nullptr;
    if constexpr (std::is_same_v<T, bool>) {
      option = cmd->add_flag(flag, *value, full_help);
    } else {
      option = cmd->add_option(flag, *value, full_help);
    }
    const std::size_t dot = path.find('.');
    data_flags.push_back({option, dot == std::string::npos ? "" : path.substr(0, dot),
                          path.substr(dot + 1), [flag, value, lo, hi] {
                            if constexpr (std::is_integral_v<T> && !std::is_same_v<T, bool>) {
                              if (lo <= hi) CheckRange(flag, *value, lo, hi);
                            }
                            return YAML::Node(*value);
                          }});
  }

  void Register(CLI::App& parent) {
    CLI::App* cmd = parent.add_subcommand(
        "generate",
        "Expert task demonstrations (collisions discarded) and safety demonstrations of any "
        "domain: demos.csv, safe.csv, near_dangerous.csv in --out");
    AddDomainOption(cmd, &domain)->required();
    cmd->add_option("--out", out, "output directory")->required()->transform(DirectoryPath());
    AddDataFlag(cmd, "--episodes", &episodes, "demonstrations.episodes",
                "expert episodes to keep, at most " + std::to_string(kMaxEpisodes), true, 1,
                kMaxEpisodes);
    AddDataFlag(cmd, "--safe-states", &safe_states, "safe_states",
                "demonstration states kept as safe states, at random", true, 1, kMaxStates);
    AddDataFlag(cmd, "--slowed-copies", &slowed_copies, "slowed_copies",
                "safe-state augmentation, copies of each safe state with its velocity scaled by "
                "U[0, 1)",
                false, 0, kMaxSlowedCopies);
    AddDataFlag(cmd, "--near-dangerous", &near_dangerous_count, "near_dangerous.count",
                "near-dangerous states", true, 1, kMaxStates);
    AddDataFlag(cmd, "--rho-min", &rho_min, "near_dangerous.rho_min",
                "near-dangerous band from this distance to the obstacle's edge, negative: inside",
                false);
    AddDataFlag(cmd, "--rho-max", &rho_max, "near_dangerous.rho_max",
                "near-dangerous band to this distance", false);
    AddDataFlag(cmd, "--stop-at-goal", &stop_at_goal, "demonstrations.stop_at_goal",
                "end each demonstration at the goal, not after the full horizon", false);
    AddSeedOption(cmd, "--seed", &seed, "seed of all the data");
    cmd->add_flag("--json", json, "print counts as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    const std::unique_ptr<experiments::Domain> d =
        experiments::DomainRegistry::Global().Make(domain);
    YAML::Node options;
    for (const DataFlag& f : data_flags) {
      if (f.option->count() == 0) continue;
      if (f.section.empty()) {
        options[f.key] = f.value();
      } else {
        options[f.section][f.key] = f.value();
      }
    }
    if (options.size() > 0) d->ApplyYaml(options, "demos generate flags");
    d->Validate();
    // Before the work: an unusable --out (a file, a read-only place) fails at once.
    CreateDirectories(out);
    const experiments::DomainData data = d->GenerateData(seed);
    data::WriteTrajectories(out + "/demos.csv", data.demonstrations);
    data::WriteStateSet(out + "/safe.csv", data.safe);
    data::WriteStateSet(out + "/near_dangerous.csv", data.near_dangerous);
    const nlohmann::json r = {
        {"command", "demos generate"},
        {"domain", domain},
        {"demonstrations", data.demonstrations.num_episodes()},
        {"steps", data.demonstrations.num_steps()},
        {"discarded", data.discarded_demonstrations},
        {"safe_states", data.safe.size()},
        {"near_dangerous_states", data.near_dangerous.size()},
        {"files", {out + "/demos.csv", out + "/safe.csv", out + "/near_dangerous.csv"}},
        {"domain_options", d->OptionsJson()}};
    if (json) {
      PrintJson(r);
    } else {
      std::cout << data.demonstrations.num_episodes() << " demonstrations ("
                << data.discarded_demonstrations << " expert episodes discarded for a collision "
                << "or for not reaching the goal), " << data.demonstrations.num_steps()
                << " steps -> " << out << "/demos.csv\n"
                << data.safe.size() << " safe states -> " << out << "/safe.csv\n"
                << data.near_dangerous.size() << " near-dangerous states -> " << out
                << "/near_dangerous.csv\n";
    }
  }
};

// ------------------------------------------------------------------------------------------
struct PolicyTrainCommand {
  std::string algo, demos_path, out, domain = "double-integrator", warm_start, reward;
  std::string state_features, action_features;
  policy::BcOptions bc;
  policy::AirlOptions airl;
  bool json = false;
  std::string progress = "auto";
  // --seed and --curve serve both algorithms: copied onto the chosen one's options if given.
  std::uint64_t seed = 0;
  std::string curve;
  CLI::Option* seed_flag = nullptr;
  CLI::Option* curve_flag = nullptr;
  // Flags that apply to one algorithm only: giving one with the other --algo is an error.
  std::vector<CLI::Option*> bc_only, airl_only;
  DeferredError config_error;

  void Register(CLI::App& parent, const Config& config) {
    CLI::App* cmd = parent.add_subcommand(
        "train", "Train a Gaussian policy from demonstrations: behaviour cloning or AIRL (PPO)");
    // The config's sections are applied now, before the flags are parsed, so that flags override
    // them (an error is raised only if this command runs).
    config_error.Capture([&] {
      const YAML::Node bc_yaml = config.Section("bc"), airl_yaml = config.Section("airl");
      if (bc_yaml.IsMap()) bc.ApplyYaml(bc_yaml, config.path + " [bc]");
      if (airl_yaml.IsMap()) airl.ApplyYaml(airl_yaml, config.path + " [airl]");
    });
    AddConfigFlag(cmd, config);
    cmd->add_option("--algo", algo, "bc | airl")->required();
    cmd->add_option("--demos", demos_path,
                    "demonstrations: a CSV (episode, state and action columns) or an HDF5 file "
                    "in robomimic's layout (.h5, .hdf5)")
        ->required();
    cmd->add_option("--out", out, "output policy model file")->required();
    AddDomainOption(cmd, &domain, "domain the demonstrations come from (AIRL rolls out in it)")
        ->capture_default_str();
    bc_only.push_back(
        cmd->add_option("--state-features", state_features,
                        "BC only: comma-separated state columns, or HDF5 obs keys (default: the "
                        "domain's)"));
    bc_only.push_back(
        cmd->add_option("--action-features", action_features,
                        "BC only: comma-separated action columns (default: the domain's)"));
    seed_flag = AddSeedOption(cmd, "--seed", &seed, "seed of the training (default: the config's, else 0)");
    bc_only.push_back(
        cmd->add_option("--epochs", bc.epochs, "BC only: epochs")->capture_default_str());
    airl_only.push_back(cmd->add_option("--iterations", airl.iterations,
                                        "AIRL only: iterations in total (with --resume: "
                                        "including the checkpoint's; fewer is an error)")
                            ->capture_default_str());
    reward = ToString(policy::kAirlRewardNames, airl.reward);
    airl_only.push_back(
        cmd->add_option("--reward", reward,
                        "AIRL only: policy reward: logit-d (log D - log(1-D), the paper) | "
                        "state-reward (g(s), the released code)")
            ->capture_default_str());
    airl_only.push_back(cmd->add_option("--warm-start", warm_start,
                                        "AIRL only: initialise the policy from this model"));
    curve_flag = cmd->add_option("--curve", curve, "write the learning curve to this CSV");
    airl_only.push_back(cmd->add_option(
        "--checkpoint", airl.checkpoint_path,
        "AIRL only: checkpoint file (checksummed), written every --checkpoint-every "
        "iterations and at the end"));
    airl_only.push_back(cmd->add_option("--checkpoint-every", airl.checkpoint_every,
                                        "AIRL only: iterations between checkpoints")
                            ->capture_default_str());
    airl_only.push_back(cmd->add_flag(
        "--resume", airl.resume,
        "AIRL only: continue from --checkpoint (needs it); if that file does not exist yet, "
        "training starts from scratch (a note on stderr says so), so a crashed run can be "
        "restarted with the same command. A corrupt checkpoint, one from other options or "
        "data, or one with more iterations than --iterations is an error"));
    cmd->add_flag("--json", json, "print the training summary as JSON");
    AddProgressOption(cmd, &progress)
        ->description(
            "AIRL: a live progress line on stderr (iterations done/total, elapsed, time left): "
            "auto (when stderr is a terminal), always, never");
    cmd->callback([this] {
      config_error.Rethrow();
      Run();
    });
  }

  void Run() {
    const std::unique_ptr<experiments::Domain> d =
        experiments::DomainRegistry::Global().Make(domain);
    SECURE_CHECK(algo == "bc" || algo == "airl", "--algo = '" << algo << "', must be bc or airl");
    for (const CLI::Option* option : algo == "bc" ? airl_only : bc_only) {
      SECURE_CHECK(option->count() == 0,
                   option->get_name() << " applies to --algo " << (algo == "bc" ? "airl" : "bc")
                                      << " only (this run: --algo " << algo << ")");
    }
    if (seed_flag->count() > 0) bc.seed = airl.seed = seed;
    if (curve_flag->count() > 0) bc.curve_path = airl.curve_path = curve;
    if (algo == "airl") {
      SECURE_CHECK(!airl.resume || !airl.checkpoint_path.empty(),
                   "--resume needs --checkpoint FILE (the checkpoint to continue from)");
    }
    nn::SetTorchThreads(1);
    const std::unique_ptr<domains::Environment> environment = d->MakeEnvironment();
    const domains::Environment& env = *environment;
    std::vector<std::string> states = env.ObservationFeatures(), actions = env.ActionFeatures();
    if (!state_features.empty()) states = data::SplitList(state_features);
    if (!action_features.empty()) actions = data::SplitList(action_features);
    const data::TrajectorySet demos = data::ReadTrajectories(demos_path, states, actions);
    const Stopwatch clock;
    nlohmann::json summary_json;
    std::string brief;
    policy::GaussianPolicy trained;
    if (algo == "bc") {
      bc.verbose = !json;
      policy::BcSummary summary;
      trained = policy::TrainBc(bc, demos, &summary);
      summary_json = summary.ToJson();
      brief = summary.BriefReport();
    } else {
      airl.reward = FromString(policy::kAirlRewardNames, reward, "--reward");
      airl.verbose = !json;
      std::optional<policy::GaussianPolicy> start;
      if (!warm_start.empty()) start = policy::GaussianPolicy::Load(warm_start);
      if (airl.resume && !std::filesystem::exists(airl.checkpoint_path))
        std::cerr << "policy train: --resume: no checkpoint yet at " << airl.checkpoint_path
                  << ": starting from scratch\n";
      policy::AirlSummary summary;
      // The live line counts this run's iterations (a resumed run starts at its checkpoint's);
      // the "[airl] it" status lines print above it.
      ProgressLine line(&std::cerr, ProgressIsLive(progress));
      line.Install();
      bool started = false;
      trained =
          policy::TrainAirl(airl, demos, env, start ? &*start : nullptr, &summary,
                            [&](const policy::AirlIterationStats& stats) {
                              if (!started) {
                                line.Start(airl.iterations, "AIRL iterations", stats.iteration - 1);
                                started = true;
                              }
                              line.Advance();
                              return true;
                            });
      line.Finish();
      summary_json = summary.ToJson();
      brief = summary.BriefReport();
    }
    trained.Save(out);
    if (json) {
      PrintJson({{"command", "policy train"},
                 {"algo", algo},
                 {"demos", demos_path},
                 {"out", out},
                 {"summary", summary_json},
                 {"seconds", clock.Seconds()}});
    } else {
      std::cout << algo << ": " << brief << "\nsaved " << out << "\n";
    }
  }
};

// ------------------------------------------------------------------------------------------
struct EvalCommand {
  std::string domain, run_dir, airl_path, bc_path, joint_path, barrier_path, airl_reward_path,
      methods, dynamics_path;
  int seeds = 10;
  long episodes = 100;
  std::uint64_t first_seed = 0;
  CLI::Option* methods_option = nullptr;
  shield::ShieldOptions shield;
  ShieldFlags shield_flags;
  PessimismFlags pessimism_flags;  // with --dynamics
  double tost_bound = 0.10;
  bool json = false;
  std::string episodes_out;
  CLI::App* command = nullptr;

  const Config* config = nullptr;

  void Register(CLI::App& app, const Config& cfg) {
    config = &cfg;
    CLI::App* cmd = app.add_subcommand(
        "eval",
        "Evaluate saved models on any domain: bc, airl, secure, the shield ablations, bc+shield, "
        "secure-myopic, joint, cbf-qp (the CBF-QP filter), secure-qp (the gradient-first shield), first-safe (the first-safe "
        "sampler), cbf-grad (gradient refinement of the mean); success and dangerous rates over seeds, Mann-Whitney U and TOST "
        "of SECURE vs AIRL, Kruskal-Wallis + Dunn across the ablations. The shield flags marked "
        "=preset default to the domain's preset (`secure domains NAME` lists it)");
    AddDomainOption(cmd, &domain)->required();
    AddConfigFlag(cmd, cfg);  // the domain's options: section <domain's>, key `domain`
    cmd->add_option("--run", run_dir,
                    "a `secure demo --out` or `secure experiment --out` directory: "
                    "seed-<k>/{bc,airl,joint,barrier}.model per training seed (the paper's "
                    "protocol: a seed covers training)")
        ->transform(DirectoryPath());
    cmd->add_option("--airl", airl_path, "AIRL policy model (instead of --run)");
    cmd->add_option("--bc", bc_path, "BC policy model (instead of --run)");
    cmd->add_option("--joint", joint_path, "joint-optimisation policy model (instead of --run)");
    cmd->add_option("--airl-reward", airl_reward_path,
                    "AIRL's reward model (airl_reward.model), the task value of the shield's "
                    "aggregation top-q (instead of --run)");
    cmd->add_option("--barrier", barrier_path,
                    "barrier model (flat or per-obstacle), or 'ground-truth' for a domain that "
                    "has one (instead of / overriding --run)");
    methods_option = cmd->add_option("--methods", methods,
                                     "comma-separated methods (default: those whose models "
                                     "are given)");
    cmd->add_option("--dynamics", dynamics_path,
                    "a learned dynamics model (`secure dynamics train`) as the shield model, "
                    "pessimistic over its members, instead of the domain's");
    pessimism_flags.Add(cmd);
    cmd->add_option("--seeds", seeds,
                    "evaluation seeds (with --run: the number of seed-<k> directories used)")
        ->capture_default_str();
    AddSeedOption(cmd, "--first-seed", &first_seed, "first seed");
    cmd->add_option("--episodes", episodes,
                    "episodes per method and seed, at most " + std::to_string(kMaxEpisodes))
        ->capture_default_str();
    cmd->add_option("--tost-bound", tost_bound, "TOST equivalence bound (fraction)")
        ->capture_default_str();
    shield_flags.Add(cmd, &shield, /*domain_preset=*/true);  // `secure domains NAME` lists it
    cmd->add_flag("--json", json,
                  "print every number as JSON (each seed's record lists its dangerous_episodes "
                  "and failed_episodes)");
    cmd->add_option("--episodes-out", episodes_out,
                    "also write the per-episode outcomes as CSV: one row per method, seed and "
                    "episode (success, dangerous, steps, first dangerous step, interventions, "
                    "...; secure/eval/episode_table.h); the text output lists each seed's "
                    "dangerous and failed episodes either way");
    command = cmd;
    cmd->callback([this] { Run(); });
  }

  // The `secure render` command line of one episode, with the flags of this evaluation that it
  // takes too ("" with --dynamics: render cannot replay an evaluation through a learned model).
  std::string RenderCommand(eval::Method method, std::uint64_t seed, long episode) const {
    if (!dynamics_path.empty()) return "";
    const std::string& policy = eval::UsesBcPolicy(method)      ? bc_path
                                : eval::UsesJointPolicy(method) ? joint_path
                                                                : airl_path;
    std::string line = "secure render --domain " + domain;
    if (!config->path.empty()) line += " --config " + config->path;
    if (!run_dir.empty()) line += " --run " + run_dir;
    if (!policy.empty()) line += " --policy " + policy;
    return line + GivenRenderFlags(*command) + " --seed " + std::to_string(seed) + " --episode " +
           std::to_string(episode) + " --method " + ToString(eval::kMethodNames, method) +
           " --frames-dir DIR";
  }

  void Run() {
    experiments::ExperimentOptions section;
    const std::unique_ptr<experiments::Domain> d =
        MakeConfiguredDomain(domain, false, *config, &section);
    // The shield: the domain's experiment preset, the config's `shield:` key, then the flags given.
    const shield::ShieldOptions shield_options =
        OverlayShieldFlags(section.shield, shield_flags, &shield);
    CheckRange("--seeds", seeds, 1, kMaxSeeds);
    CheckRange("--episodes", episodes, 1, kMaxEpisodes);
    SECURE_CHECK(std::isfinite(tost_bound) && tost_bound > 0,
                 "--tost-bound = " << tost_bound << ", must be > 0");
    shield_options.Validate();
    SECURE_CHECK(!run_dir.empty() || !airl_path.empty() || !bc_path.empty() || !joint_path.empty(),
                 "give --run DIR or at least one of --airl, --bc, --joint");
    if (!episodes_out.empty()) CheckOutputFile("--episodes-out", episodes_out);
    // The last seed, first_seed + seeds - 1, must not wrap around to 0.
    SECURE_CHECK(first_seed <= std::numeric_limits<std::uint64_t>::max() -
                                   static_cast<std::uint64_t>(seeds - 1),
                 "--first-seed = " << first_seed << " with --seeds " << seeds
                                   << ": the last seed would wrap around to 0");
    std::vector<eval::Method> list;
    if (methods_option->count() > 0) {  // '' is an error (no method), not the default
      list = eval::ParseMethods(methods);
    } else {
      const bool has_barrier = !barrier_path.empty() || !run_dir.empty();
      for (eval::Method m : eval::AllMethods()) {
        const bool has_policy = eval::UsesBcPolicy(m) ? (!bc_path.empty() || !run_dir.empty())
                                                      : (!airl_path.empty() || !run_dir.empty());
        if (has_policy && (!eval::IsShielded(m) || has_barrier)) list.push_back(m);
      }
      if (!joint_path.empty()) list.push_back(eval::Method::kJoint);
    }
    const std::unique_ptr<domains::Environment> env =
        dynamics_path.empty()
            ? d->MakeEnvironment()
            : MakeLearnedModelEnvironment(d->MakeEnvironment(), dynamics_path, shield_options,
                                          pessimism_flags.Options());
    eval::Evaluation evaluation(eval::EvaluationOptions{tost_bound, 0.05});
    for (int k = 0; k < seeds; ++k) {
      const std::uint64_t seed = first_seed + static_cast<std::uint64_t>(k);
      const SeedModelSet models(
          ModelSources{run_dir, bc_path, airl_path, joint_path, barrier_path, airl_reward_path}, *d,
          domain, *env, list, seed, shield_options);
      const auto results = eval::EvaluateMethods(*env, list, models.models(), shield_options,
                                                 episodes, eval::EvaluationSeed(seed));
      for (const auto& [method, r] : results) evaluation.Add(method, r);
      if (!json) std::cerr << "seed " << seed << " evaluated\n";
    }
    evaluation.Finish();
    if (!episodes_out.empty())
      WriteFileAtomically(episodes_out, eval::EpisodeCsv(evaluation, first_seed));
    if (json) {
      nlohmann::json r = evaluation.ToJson();
      r["command"] = "eval";
      r["domain"] = domain;
      // What makes two results comparable episode for episode (`secure compare`): the same
      // models, seeds and episodes.
      r["run"] = run_dir;
      r["config"] = config->path;
      r["models"] = {{"airl", airl_path}, {"bc", bc_path}, {"joint", joint_path},
                     {"barrier", barrier_path}};
      if (!dynamics_path.empty()) r["models"]["dynamics"] = dynamics_path;
      r["first_seed"] = first_seed;
      r["seeds_evaluated"] = seeds;
      r["episodes"] = episodes;
      r["shield"] = shield_options.ToJson();
      PrintJson(r);
    } else {
      std::cout << evaluation.Table();
      const std::string lists = eval::EpisodeLists(
          evaluation, first_seed,
          [this](eval::Method m, std::uint64_t s, long e) { return RenderCommand(m, s, e); });
      if (!lists.empty()) std::cout << "\nDangerous and failed episodes:\n" << lists;
      if (!episodes_out.empty()) std::cout << "\nper-episode outcomes: " << episodes_out << "\n";
    }
  }
};

}  // namespace

void RegisterPipelineCommands(CLI::App& app, const Config& config) {
  static DemosGenerateCommand generate;
  static PolicyTrainCommand train;
  static EvalCommand evaluate;
  CLI::App* demos = app.add_subcommand("demos", "Generate, convert and check demonstrations");
  demos->require_subcommand(1);
  generate.Register(*demos);
  RegisterLabelCheckCommand(*demos, config);
  RegisterConvertCommand(*demos);
  CLI::App* policy = app.add_subcommand("policy", "Learn policies from demonstrations");
  policy->require_subcommand(1);
  train.Register(*policy, config);
  evaluate.Register(app, config);
}

}  // namespace secure::cli
