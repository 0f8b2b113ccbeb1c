// secure shield run: the closed-loop check of the CBF shield on any domain that offers a shield
// run (experiments::Domain::HasShieldRun; the double integrator's: its shield_run.h). The domain
// gives the task, the nominal policy and the run's values (ShieldRunPreset); this command names
// no domain.
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/common/error.h"
#include "secure/experiments/domain.h"

namespace secure::cli {
namespace {

constexpr const char* kGroundTruthBarrier = "ground-truth";

// Warns on stderr when a model's recorded ground truth (the provenance of `cbf train --domain`,
// under the domain's GroundTruthSection) differs from the run's.
void WarnOnGroundTruthMismatch(const cbf::BarrierNet& net, const experiments::Domain& domain,
                               const std::string& path) {
  const std::string key = domain.GroundTruthSection();
  if (key.empty()) return;
  const auto it = net.provenance.find(key);
  if (it == net.provenance.end() || !it->is_object()) return;
  const nlohmann::json run = domain.GroundTruthJson();
  if (*it == run) return;
  std::cerr << "secure: warning: " << path << " was trained for " << it->dump()
            << ", the run uses " << run.dump() << "\n";
}

// ------------------------------------------------------------------------------------------
struct ShieldRunCommand {
  const Config* config = nullptr;
  experiments::ShieldRunRequest request;  // the flags' values; copied onto the preset if given
  shield::ShieldOptions shield;
  ShieldFlags shield_flags;
  TaskFlags task_flags;
  std::string domain, barrier;
  CLI::Option *episodes_flag = nullptr, *seed_flag = nullptr, *sigma_flag = nullptr;
  bool unshielded = false;
  bool json = false;

  void Register(CLI::App& app, const Config& cfg) {
    config = &cfg;
    CLI::App* cmd = app.add_subcommand(
        "run",
        "Closed-loop episodes of the domain's noisy nominal policy (the double integrator: "
        "goal-seeking past an obstacle), with the CBF shield in the loop (or --unshielded): "
        "collisions, successes, interventions, latency. Defaults marked =preset and the task "
        "flags' are the domain's (`secure domains NAME`)");
    AddConfigFlag(cmd, cfg);  // the domain's ground-truth section (double_integrator:)
    AddDomainOption(cmd, &domain, kShieldRun)->required();
    cmd->add_option("--barrier", barrier,
                    "the shield's barrier: 'ground-truth' (a domain with one) or a barrier model "
                    "file")
        ->required();
    episodes_flag = cmd->add_option("--episodes", request.episodes,
                                    "episodes, at most " + std::to_string(kMaxEpisodes))
                        ->default_str("preset");
    seed_flag = AddSeedOption(cmd, "--seed", &request.seed,
                              "seed for start states, shield and policy noise");
    cmd->add_flag("--unshielded", unshielded,
                  "apply the policy's sampled actions directly (the baseline)");
    task_flags.AddGeometry(cmd);
    task_flags.AddPair(cmd, "--goal", "goal", "goal X,Y");
    task_flags.AddNumber(cmd, "--max-steps", "max_steps", "steps per episode", true);
    sigma_flag = cmd->add_option("--policy-sigma", request.policy_sigma,
                                 "the policy's noise per action component")
                     ->default_str("preset");
    task_flags.AddNumber(cmd, "--accel-bound", "accel_bound",
                         "per-component acceleration bound (environment and policy)");
    shield_flags.Add(cmd, &shield, /*domain_preset=*/true);
    task_flags.AddNumber(cmd, "--dt", "dt",
                         "control period (environment step and the shield's dt)");
    cmd->add_flag("--json", json, "print the result as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
    const std::unique_ptr<experiments::Domain> d = registry.Make(domain);
    RequireCapability(*d, domain, kShieldRun);
    if (episodes_flag->count() > 0) CheckRange("--episodes", request.episodes, 1, kMaxEpisodes);
    task_flags.ApplyTo(d.get(), *config);
    // The run: the domain's values, then the flags given.
    experiments::ShieldRunRequest run = d->ShieldRunPreset();
    if (episodes_flag->count() > 0) run.episodes = request.episodes;
    if (seed_flag->count() > 0) run.seed = request.seed;
    if (sigma_flag->count() > 0) run.policy_sigma = request.policy_sigma;
    run.shield = OverlayShieldFlags(run.shield, shield_flags, &shield);
    run.shielded = !unshielded;

    std::unique_ptr<cbf::Barrier> evaluator;
    if (barrier == kGroundTruthBarrier) {
      evaluator = d->MakeGroundTruth();
      SECURE_CHECK(evaluator != nullptr,
                   "--barrier ground-truth: the " << domain << " domain has no ground truth");
    } else {
      const cbf::BarrierNet net = cbf::BarrierNet::Load(barrier);
      net.CheckFeatures(d->MakeEnvironment()->ObservationFeatures(), "the " + domain + " domain",
                        barrier);
      WarnOnGroundTruthMismatch(net, *d, barrier);
      evaluator = net.MakeEvaluator();
    }
    const experiments::ShieldRunReport report = d->RunShield(run, *evaluator);
    if (json) {
      nlohmann::json r = report.json;
      r["command"] = "shield run";
      r["barrier_source"] = barrier;
      PrintJson(r);
    } else {
      std::cout << report.table;
    }
  }
};

}  // namespace

void RegisterShieldCommands(CLI::App& app, const Config& config) {
  CLI::App* group = app.add_subcommand("shield", "Run and check the CBF shield");
  group->require_subcommand(1);
  static ShieldRunCommand run;
  run.Register(*group, config);
}

}  // namespace secure::cli
