// secure experiment model-source --domain NAME --run RUN: SECURE with the domain's hand-written
// shield model against SECURE with a learned dynamics ensemble (issue 36), on the same seeds,
// barriers, policies and episodes; paired statistics of the success and dangerous rates.
// (Registered under `secure experiment` by RegisterDynamicsCommands; the driver for the other
// kinds, secure/experiments, is not involved: this one trains nothing but the dynamics model.)
#include <CLI/CLI.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "eval_models.h"
#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/limits.h"
#include "secure/data/data.h"
#include "secure/dynamics/ensemble.h"
#include "secure/dynamics/learned_environment.h"
#include "secure/dynamics/trainer.h"
#include "secure/dynamics/transitions.h"
#include "secure/eval/policy_eval.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"
#include "secure/nn/torch_threads.h"
#include "secure/stats/statistics.h"

namespace secure::cli {
namespace {

struct PairedDifference {
  double mean_a = 0, mean_b = 0, difference = 0, lower = 0, upper = 0;  // 90 % interval
  stats::TostResult tost;
};

PairedDifference Paired(const std::vector<double>& a, const std::vector<double>& b,
                        double bound) {
  PairedDifference p;
  p.tost = stats::TostPaired(a, b, bound);
  p.mean_a = stats::Summarize(a).mean;
  p.mean_b = stats::Summarize(b).mean;
  p.difference = p.tost.difference;
  double half = 0.0;
  if (p.tost.se > 0 && std::isfinite(p.tost.df)) {
    const boost::math::students_t t(p.tost.df);
    half = boost::math::quantile(t, 0.95) * p.tost.se;
  }
  p.lower = p.difference - half;
  p.upper = p.difference + half;
  return p;
}

nlohmann::json ToJson(const PairedDifference& p) {
  return {{"mean_a", p.mean_a},         {"mean_b", p.mean_b},   {"difference", p.difference},
          {"interval_90", {p.lower, p.upper}}, {"tost", p.tost.ToJson()}};
}

struct ModelSourceCommand {
  std::string domain, run_dir, dynamics_path, transitions, out;
  int seeds = 10;
  long episodes = 100;
  std::uint64_t first_seed = 0;
  double tost_bound = 0.02;
  dynamics::DynamicsTrainerOptions trainer;
  shield::ShieldOptions shield;
  ShieldFlags shield_flags;
  PessimismFlags pessimism_flags;
  bool json = false;
  const Config* config = nullptr;

  void Register(CLI::App& parent, const Config& cfg) {
    config = &cfg;
    CLI::App* cmd = parent.add_subcommand(
        "model-source",
        "SECURE with the domain's hand-written shield model vs a learned dynamics ensemble "
        "(pessimistic over its members), on a run's models (same seeds, barriers, policies, "
        "episodes); paired TOST of the success and dangerous rates");
    AddDomainOption(cmd, &domain)->required();
    AddConfigFlag(cmd, cfg);
    cmd->add_option("--run", run_dir,
                    "a `secure experiment method-comparison --out` directory (seed-<k>/"
                    "{airl,barrier}.model, demos.csv)")
        ->required()
        ->transform(DirectoryPath());
    cmd->add_option("--dynamics", dynamics_path,
                    "the learned model (default: trained here from --transitions)");
    cmd->add_option("--transitions", transitions,
                    "comma-separated transitions files to train the model from (default: the "
                    "run's demos.csv)");
    cmd->add_option("--out", out, "where the model and the two evaluations go (default: "
                                  "RUN/model-source)")
        ->transform(DirectoryPath());
    cmd->add_option("--seeds", seeds)->capture_default_str();
    AddSeedOption(cmd, "--first-seed", &first_seed, "first seed");
    cmd->add_option("--episodes", episodes)->capture_default_str();
    cmd->add_option("--tost-bound", tost_bound, "TOST equivalence bound (fraction)")
        ->capture_default_str();
    cmd->add_option("--members", trainer.members, "K of a model trained here")
        ->capture_default_str();
    AddSeedOption(cmd, "--dynamics-seed", &trainer.seed, "seed of a model trained here");
    shield_flags.Add(cmd, &shield, /*domain_preset=*/true);
    pessimism_flags.Add(cmd);
    cmd->add_flag("--json", json, "print every number as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    CheckRange("--seeds", seeds, 2, kMaxSeeds);
    CheckRange("--episodes", episodes, 1, kMaxEpisodes);
    SECURE_CHECK(std::isfinite(tost_bound) && tost_bound > 0,
                 "--tost-bound = " << tost_bound << ", must be > 0");
    experiments::ExperimentOptions section;
    const std::unique_ptr<experiments::Domain> d =
        MakeConfiguredDomain(domain, false, *config, &section);
    const shield::ShieldOptions shield_options =
        OverlayShieldFlags(section.shield, shield_flags, &shield);
    shield_options.Validate();
    const dynamics::PessimismOptions pessimism = pessimism_flags.Options();
    if (out.empty()) out = run_dir + "/model-source";
    CreateDirectories(out);
    const std::unique_ptr<domains::Environment> hand = d->MakeEnvironment();

    // The learned model: given, or trained from the transitions (default: the run's demos).
    std::string model_path = dynamics_path;
    nlohmann::json training;
    if (model_path.empty()) {
      const std::string files = transitions.empty() ? run_dir + "/demos.csv" : transitions;
      dynamics::Transitions data;
      for (const std::string& f : data::SplitList(files))
        dynamics::Append(dynamics::ReadTransitions(f, hand->ObservationFeatures(),
                                                   hand->ActionFeatures()),
                         &data);
      nn::SetTorchThreads(1);
      trainer.verbose = !json;
      dynamics::DynamicsTrainingSummary summary;
      const dynamics::EnsembleDynamics model = dynamics::TrainDynamics(trainer, data, &summary);
      model_path = out + "/dynamics.model";
      model.Save(model_path);
      training = {{"transitions", data.size()},
                  {"source", files},
                  {"options", trainer.ToJson()},
                  {"summary", summary.ToJson()}};
      if (!json) std::cerr << "dynamics: " << summary.BriefReport() << " -> " << model_path << "\n";
    }
    const std::unique_ptr<domains::Environment> learned =
        MakeLearnedModelEnvironment(hand->Clone(), model_path, shield_options, pessimism);

    const std::string hand_name = hand->ShieldModelIsExact() ? "exact" : "hand-written";
    const std::vector<eval::Method> methods{eval::Method::kSecure};
    struct Source {
      std::string name;
      const domains::Environment* env;
      eval::Evaluation evaluation;
      std::vector<double> success, dangerous;
    };
    std::vector<Source> sources;
    sources.push_back({hand_name, hand.get(), eval::Evaluation({tost_bound, 0.05}), {}, {}});
    sources.push_back({"learned", learned.get(), eval::Evaluation({tost_bound, 0.05}), {}, {}});
    for (int k = 0; k < seeds; ++k) {
      const std::uint64_t seed = first_seed + static_cast<std::uint64_t>(k);
      for (Source& s : sources) {
        const SeedModelSet models(ModelSources{run_dir, "", "", "", "", ""}, *d, domain, *s.env,
                                  methods, seed, shield_options);
        const auto results = eval::EvaluateMethods(*s.env, methods, models.models(),
                                                   shield_options, episodes,
                                                   eval::EvaluationSeed(seed));
        const eval::SeedResult& r = results.at(eval::Method::kSecure);
        s.evaluation.Add(eval::Method::kSecure, r);
        s.success.push_back(static_cast<double>(r.successes) / static_cast<double>(r.episodes));
        s.dangerous.push_back(static_cast<double>(r.dangerous) / static_cast<double>(r.episodes));
      }
      if (!json)
        std::cerr << "seed " << seed << ": success " << sources[0].success.back() << " / "
                  << sources[1].success.back() << ", dangerous " << sources[0].dangerous.back()
                  << " / " << sources[1].dangerous.back() << " (" << hand_name << " / learned)\n";
    }
    // Each source as a `secure eval --json` result (`secure compare` reads them).
    for (Source& s : sources) {
      s.evaluation.Finish();
      nlohmann::json r = s.evaluation.ToJson();
      r["command"] = "eval";
      r["domain"] = domain;
      r["run"] = run_dir;
      r["config"] = config->path;
      r["models"] = {{"airl", ""}, {"bc", ""}, {"joint", ""}, {"barrier", ""}};
      if (s.name == "learned") {
        r["models"]["dynamics"] = model_path;
        r["pessimism"] = pessimism.Describe();
      }
      r["first_seed"] = first_seed;
      r["seeds_evaluated"] = seeds;
      r["episodes"] = episodes;
      r["shield"] = shield_options.ToJson();
      WriteFileAtomically(out + "/" + s.name + ".json", r.dump(1) + "\n");
    }
    const PairedDifference success =
        Paired(sources[1].success, sources[0].success, tost_bound);
    const PairedDifference dangerous =
        Paired(sources[1].dangerous, sources[0].dangerous, tost_bound);
    // The targets: no worse than the hand-written model (dangerous within +1 point,
    // success within -3 points), read on the 90 % interval of the paired difference.
    const bool no_worse = dangerous.upper <= 0.01 && success.lower >= -0.03;
    if (json) {
      PrintJson({{"command", "experiment model-source"},
                 {"domain", domain},
                 {"run", run_dir},
                 {"out", out},
                 {"model", model_path},
                 {"pessimism", pessimism.Describe()},
                 {"training", training},
                 {"seeds", seeds},
                 {"first_seed", first_seed},
                 {"episodes", episodes},
                 {"baseline", hand_name},
                 {"tost_bound", tost_bound},
                 {"success", ToJson(success)},
                 {"dangerous", ToJson(dangerous)},
                 {"no_worse", no_worse}});
      return;
    }
    std::ostringstream t;
    t << std::fixed << std::setprecision(1);
    t << "| shield model | success % | dangerous % |\n|---|---:|---:|\n";
    t << "| " << hand_name << " | " << 100 * success.mean_b << " | " << 100 * dangerous.mean_b
      << " |\n";
    t << "| learned (" << model_path << ", " << pessimism.Describe() << ") | " << 100 * success.mean_a << " | "
      << 100 * dangerous.mean_a << " |\n\n";
    t << "| learned - " << hand_name << " | points | 90 % interval | TOST p (±"
      << 100 * tost_bound << ") |\n|---|---:|---|---:|\n";
    for (const auto& [name, p] : {std::pair<const char*, const PairedDifference&>{"success", success},
                                  {"dangerous", dangerous}}) {
      t << "| " << name << " | " << 100 * p.difference << " | [" << 100 * p.lower << ", "
        << 100 * p.upper << "] | " << std::setprecision(3) << p.tost.p_value
        << std::setprecision(1) << " |\n";
    }
    t << "\nno worse than " << hand_name << " (dangerous <= +1 point, success >= -3 points on the "
      << "90 % interval): " << (no_worse ? "yes" : "no") << "\n"
      << "evaluations: " << out << "/" << hand_name << ".json, " << out
      << "/learned.json (secure compare)\n";
    std::cout << t.str();
  }
};

}  // namespace

void RegisterModelSourceCommand(CLI::App& experiment, const Config& config) {
  static ModelSourceCommand command;
  command.Register(experiment, config);
}

}  // namespace secure::cli
