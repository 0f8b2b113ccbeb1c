// secure shield run: the closed-loop check of the CBF shield
// (domains/double_integrator/shield_run.h).
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "domains/double_integrator/shield_run.h"

namespace secure::cli {
namespace {

namespace di = domains::double_integrator;

constexpr const char* kGroundTruthBarrier = "ground-truth";

// Warns on stderr when a model's recorded training geometry differs from the run's.
void WarnOnGeometryMismatch(const cbf::BarrierNet& net, const di::GroundTruth& truth,
                            const std::string& path) {
  const auto it = net.provenance.find("double_integrator");
  if (it == net.provenance.end() || !it->is_object()) return;
  try {
    const auto obstacle = it->at("obstacle").get<std::vector<double>>();
    const double radius = it->at("radius").get<double>(), gamma = it->at("gamma").get<double>();
    if (obstacle.size() == 2 && obstacle[0] == truth.obstacle_x &&
        obstacle[1] == truth.obstacle_y && radius == truth.radius && gamma == truth.gamma)
      return;
    std::cerr << "secure: warning: " << path << " was trained for " << it->dump()
              << ", the run uses obstacle (" << truth.obstacle_x << ", " << truth.obstacle_y
              << "), radius " << truth.radius << ", gamma " << truth.gamma << "\n";
  } catch (const nlohmann::json::exception&) {
    // An unexpected provenance layout is not an error: the record is informational.
  }
}

// ------------------------------------------------------------------------------------------
struct ShieldRunCommand {
  eval::ShieldRunOptions options;
  std::vector<double> obstacle, goal;
  std::string domain, barrier;
  ShieldFlags shield_flags;
  bool unshielded = false;
  bool json = false;
  DeferredError config_error;

  void Register(CLI::App& app, const Config& config) {
    CLI::App* cmd = app.add_subcommand(
        "run",
        "Closed-loop episodes of a noisy goal-seeking policy past an obstacle, with the CBF "
        "shield in the loop (or --unshielded): collisions, successes, interventions, latency");
    config_error.Capture([&] {
      ApplyGroundTruthYaml(config.Section("double_integrator"), config.path, &options.task.truth);
    });
    AddConfigFlag(cmd, config);
    cmd->add_option("--domain", domain, "domain: double-integrator")->required();
    cmd->add_option("--barrier", barrier,
                    "the shield's barrier: 'ground-truth' or a barrier model file")
        ->required();
    cmd->add_option("--episodes", options.episodes,
                    "episodes, at most " + std::to_string(kMaxEpisodes))
        ->capture_default_str();
    AddSeedOption(cmd, "--seed", &options.seed, "seed for start states, shield and policy noise");
    cmd->add_flag("--unshielded", unshielded,
                  "apply the policy's sampled actions directly (the baseline)");
    AddGroundTruthFlags(cmd, &options.task.truth, &obstacle);
    std::ostringstream goal_default;
    goal_default << options.task.goal_x << "," << options.task.goal_y;
    cmd->add_option("--goal", goal, "goal X,Y")
        ->delimiter(',')
        ->expected(2)
        ->default_str(goal_default.str());
    cmd->add_option("--max-steps", options.task.max_steps, "steps per episode")
        ->capture_default_str();
    cmd->add_option("--policy-sigma", options.policy_sigma, "the policy's noise per axis")
        ->capture_default_str();
    cmd->add_option("--accel-bound", options.task.accel_bound,
                    "per-component acceleration bound (environment and policy)")
        ->capture_default_str();
    shield_flags.Add(cmd, &options.shield);
    cmd->add_option("--dt", options.task.dt,
                    "control period (environment step and the shield's dt)")
        ->capture_default_str();
    cmd->add_flag("--json", json, "print the result as JSON");
    cmd->callback([this] {
      config_error.Rethrow();
      Run();
    });
  }

  void Run() {
    CheckDoubleIntegratorDomain(domain);
    CheckRange("--episodes", options.episodes, 1, kMaxEpisodes);
    FinishGroundTruth(obstacle, &options.task.truth);
    if (goal.size() == 2) {
      options.task.goal_x = goal[0];
      options.task.goal_y = goal[1];
    }
    shield::ShieldOptions& so = options.shield;
    shield_flags.ApplyTo(&so);
    so.dt = options.task.dt;
    options.Validate();

    std::unique_ptr<cbf::Barrier> evaluator;
    if (barrier == kGroundTruthBarrier) {
      evaluator =
          std::make_unique<domains::double_integrator::GroundTruthBarrier>(options.task.truth);
    } else {
      const cbf::BarrierNet net = cbf::BarrierNet::Load(barrier);
      net.CheckFeatures(di::StateFeatures(), "the double-integrator domain", barrier);
      WarnOnGeometryMismatch(net, options.task.truth, barrier);
      evaluator = net.MakeEvaluator();
    }
    const eval::ShieldRunResult result =
        eval::RunDoubleIntegratorShield(options, *evaluator, !unshielded);
    if (json) {
      nlohmann::json r = result.ToJson();
      r["command"] = "shield run";
      r["barrier_source"] = barrier;
      PrintJson(r);
    } else {
      std::cout << result.Table();
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
