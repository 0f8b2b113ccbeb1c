// secure experiment label-efficiency --domain NAME: how many labels SECURE needs, and which to ask
// for (experiments/label_efficiency.h).
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/cbf/query.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/label_efficiency.h"

namespace secure::cli {
namespace {

struct LabelEfficiencyCommand {
  std::string domain, strategies, out, shard, barrier = "flat", policies_from;
  bool quick = false, json = false, errors_from_labeller = false;
  int seeds = 0, rounds = -1, threads = 2;
  long k = 0, initial_labels = 0, pool = 0, episodes = -1, final_episodes = -1, eval_states = -1;
  double radius = -1, k_growth = -1;
  std::uint64_t first_seed = 0;

  const Config* config = nullptr;

  void Register(CLI::App& parent, const Config& cfg) {
    config = &cfg;
    CLI::App* cmd = parent.add_subcommand(
        "label-efficiency",
        "Active label queries: from a few random labels, R rounds of k queries per strategy, "
        "labelled by the domain's simulated person, retraining each round; Table 1's errors "
        "(with a ground truth) and closed-loop dangerous / success rates (with a shield run) "
        "against labels used. Domains with a labeller: " +
            DomainsWith(kLabeller));
    AddConfigFlag(cmd, cfg);  // its `trainer:` section: the --barrier kind's trainer options
    cmd->add_option("--domain", domain, "the domain")->required();
    cmd->add_flag("--quick", quick, "the small profile (2 seeds, 2 rounds of 10, small pool)");
    cmd->add_option("--strategies", strategies,
                    "comma-separated: random, margin, disagreement, diversity, shield-relevant "
                    "(default: all the domain supports; shield-relevant needs a domain with a "
                    "shield run)");
    cmd->add_option("--seeds", seeds, "seeds (default 5; quick 2)");
    AddSeedOption(cmd, "--first-seed", &first_seed, "seed i is first-seed + i");
    cmd->add_option("--rounds", rounds, "query rounds (default 8; quick 2)");
    cmd->add_option("--k", k, "queries per round (default 20; quick 10)");
    cmd->add_option("--k-growth", k_growth,
                    "round r asks round(k * k-growth^r) states (default 1: k every round; 2: "
                    "labels doubling, a curve even in log(labels))");
    cmd->add_option("--initial-labels", initial_labels, "random labels to start from (default 20)");
    cmd->add_option("--pool", pool, "unlabelled candidate states per seed (default 20000)");
    cmd->add_option("--radius", radius, "diversity radius of every strategy's batch but random's");
    cmd->add_option("--episodes", episodes, "closed-loop episodes per round (default 20)");
    cmd->add_option("--final-episodes", final_episodes,
                    "closed-loop episodes at the last round (default 100)");
    cmd->add_option("--eval-states", eval_states,
                    "states of each round's error estimate (default 200000; quick 20000; 0: none)");
    cmd->add_flag("--errors-from-labeller", errors_from_labeller,
                  "without a ground truth: the errors against the labeller's answers on the "
                  "estimate states (asks the labeller --eval-states times per seed)");
    cmd->add_option("--barrier", barrier,
                    "the barrier the labels train: flat (the trainer preset's MLP) | per-obstacle "
                    "(the domain's per-obstacle barrier, Derby's SECURE barrier)")
        ->capture_default_str();
    cmd->add_option("--policies-from", policies_from,
                    "a `secure experiment method-comparison --out` directory with "
                    "seed-<k>/airl.model and barrier.model for every seed: the closed loop is "
                    "SECURE (that AIRL policy shielded by the round's barrier) on the run's "
                    "evaluation episodes, beside AIRL and SECURE over the run's barrier at the "
                    "last round (closed-loop-*.json, for `secure compare`)")
        ->check(CLI::ExistingDirectory);
    cmd->add_option("--threads", threads, "parallel jobs (seed x strategy)")->capture_default_str();
    cmd->add_option("--shard", shard, "k/N: run the seeds with index = k mod N (no result.json); "
                                      "an unsharded rerun into the same --out merges");
    cmd->add_option("--out", out, "run directory (job files, result.json, curves.csv); a rerun "
                                  "resumes")
        ->transform(DirectoryPath());
    cmd->add_flag("--json", json, "print the result document");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    const std::unique_ptr<experiments::Domain> d = experiments::DomainRegistry::Global().Make(
        domain, quick ? experiments::Profile::kQuick : experiments::Profile::kFull);
    RequireCapability(*d, domain, kLabeller, "experiment label-efficiency: ");
    experiments::LabelEfficiencyOptions o = experiments::LabelEfficiencyOptions::For(
        *d, quick ? experiments::Profile::kQuick : experiments::Profile::kFull);
    config->Check();
    o.barrier_kind = FromString(experiments::kBarrierKindNames, barrier, "--barrier");
    const YAML::Node trainer = config->Section("trainer");
    if (trainer.IsMap() && o.barrier_kind == experiments::BarrierKind::kPerObstacle)
      o.per_obstacle_trainer.ApplyYaml(trainer, config->path + " [trainer]");
    else if (trainer.IsMap())
      o.trainer.ApplyYaml(trainer, config->path + " [trainer]");
    o.policies_from = policies_from;
    if (!strategies.empty()) {
      o.strategies.clear();
      std::stringstream in(strategies);
      for (std::string item; std::getline(in, item, ',');)
        o.strategies.push_back(FromString(cbf::kQueryStrategyNames, item, "--strategies"));
    } else if (!d->HasShieldRun()) {  // the default: every strategy the domain supports
      o.strategies.erase(std::remove(o.strategies.begin(), o.strategies.end(),
                                     cbf::QueryStrategy::kShieldRelevant),
                         o.strategies.end());
    }
    if (seeds > 0) o.seeds = seeds;
    o.first_seed = first_seed;
    if (rounds >= 0) o.rounds = rounds;
    if (k > 0) o.k = k;
    if (k_growth != -1) o.k_growth = k_growth;
    if (initial_labels > 0) o.initial_labels = initial_labels;
    if (pool > 0) o.pool = pool;
    if (radius >= 0) o.radius = radius;
    if (episodes >= 0) o.episodes = episodes;
    if (final_episodes >= 0) o.final_episodes = final_episodes;
    if (eval_states >= 0) o.eval_states = eval_states;
    o.errors_from_labeller = errors_from_labeller;
    o.threads = threads;
    o.output_dir = out;
    if (!shard.empty()) {
      int a = -1, b = 0;
      char slash = 0, extra = 0;
      std::istringstream s(shard);
      SECURE_CHECK((s >> a >> slash >> b) && slash == '/' && !(s >> extra) && b >= 1 && a >= 0 &&
                       a < b,
                   "--shard '" << shard << "': expected k/N with 0 <= k < N");
      o.shard_index = a;
      o.shard_count = b;
    }
    o.Validate();
    CreateDirectories(out);
    // The banner is RunLabelEfficiency's, after its input checks: an error is then one line.
    const experiments::LabelEfficiencyResult r =
        experiments::RunLabelEfficiency(*d, o, &std::cerr);
    if (json) {
      nlohmann::json j = r.ToJson();
      j["command"] = "experiment label-efficiency";
      PrintJson(j);
    } else {
      std::cout << r.Table() << "\nTotal " << r.seconds << " s.\n";
    }
  }
};

}  // namespace

void RegisterLabelEfficiencyCommand(CLI::App& experiment, const Config& config) {
  static LabelEfficiencyCommand command;
  command.Register(experiment, config);
}

}  // namespace secure::cli
