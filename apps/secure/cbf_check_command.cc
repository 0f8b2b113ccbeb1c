// secure cbf check: the pre-deployment check of a learned barrier (cbf/barrier_check.h) on any
// registered domain with a check (experiments::Domain::HasCheck). The check is generic and so is
// this command: the domain gives the held-out states (CheckHeldOut), the region, the unsafe test,
// the action box and the shield's dynamics model (MakeCheckProblem); the experiment options it
// starts from are the domain's preset with its `--config` section (as `secure experiment` reads
// it), so that a saved seed's barrier gets the check its experiment recorded (same data_seed,
// held-out count, shield and check options). No domain is named here.
#include <yaml-cpp/yaml.h>

#include <cstdio>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "cli_common.h"
#include "commands.h"
#include "secure/cbf/barrier_check.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/common/timer.h"
#include "secure/data/data.h"
#include "secure/experiments/config_section.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"
#include "secure/nn/model_file.h"

namespace secure::cli {
namespace {

// The registered domains whose experiments train a per-obstacle barrier (the kind of a
// `car_barrier` model file).
std::string PerObstacleDomainList() {
  const experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
  std::string list;
  for (const std::string& name : registry.Names())
    if (registry.Make(name, experiments::Profile::kQuick)->Preset().barrier_kind ==
        experiments::BarrierKind::kPerObstacle)
      list += (list.empty() ? "" : ", ") + name;
  return list.empty() ? "none" : list;
}

struct CheckCommand {
  const Config* config = nullptr;
  std::string model, domain, safe_path, nd_path, out;
  bool json = false, quick = false;
  long held_out = 256;
  std::uint64_t data_seed = 0;
  CLI::Option *held_out_opt = nullptr, *data_seed_opt = nullptr;
  // Overrides (applied only when given, over the domain's defaults and the `check:` section).
  cbf::BarrierCheckOptions parsed;
  std::vector<std::pair<CLI::Option*, std::function<void(cbf::BarrierCheckOptions*)>>> copies;
  std::string class_k;
  double class_k_gain = 0, dt = 0;
  CLI::Option *class_k_opt = nullptr, *gain_opt = nullptr, *dt_opt = nullptr;
  // Task options of the domain (its `task:` keys obstacle, radius, gamma, accel_bound: the
  // double integrator's geometry and action bound), from the flags and the domain's ground-truth
  // section (`double_integrator:`); a domain without such a key rejects it by name.
  TaskFlags task_flags;
  YAML::Node check_yaml;
  DeferredError config_error;  // thrown when this command runs, not at registration

  // A flag whose value lands in `parsed` and is copied onto the options only when given.
  template <typename Field>
  CLI::Option* Bind(CLI::App* cmd, const std::string& name, Field field, const std::string& help) {
    CLI::Option* option = cmd->add_option(name, field(parsed), help);
    copies.emplace_back(
        option, [this, field](cbf::BarrierCheckOptions* to) { field(*to) = field(parsed); });
    return option;
  }
  // The same for a plain field of the options.
  template <typename T>
  CLI::Option* Bind(CLI::App* cmd, const std::string& name, T cbf::BarrierCheckOptions::*member,
                    const std::string& help) {
    return Bind(
        cmd, name, [member](cbf::BarrierCheckOptions& o) -> T& { return o.*member; }, help);
  }
  // ... and for a threshold.
  CLI::Option* Bind(CLI::App* cmd, const std::string& name, double cbf::CheckThresholds::*member,
                    const std::string& help) {
    return Bind(
        cmd, name,
        [member](cbf::BarrierCheckOptions& o) -> double& { return o.thresholds.*member; }, help);
  }

  void Register(CLI::App& app, const Config& cfg) {
    config = &cfg;
    CLI::App* cmd = app.add_subcommand(
        "check",
        "Check a learned barrier before deployment: held-out accuracy and a counterexample "
        "search for (a) h >= 0 with no admissible action, (b) h >= 0 near near-dangerous "
        "states, (c) h >= 0 where the domain's own test says unsafe; verdict by thresholds");
    config_error.Capture([&] { check_yaml = cfg.Section("check"); });
    AddConfigFlag(cmd, cfg);  // `check:`, the domain's section and its ground-truth section
    cmd->add_option("--model", model,
                    "barrier model file (barrier_mlp; car_barrier on a domain whose barrier is "
                    "per-obstacle: " +
                        PerObstacleDomainList() + ")")
        ->required()
        ->check(CLI::ExistingFile);
    AddDomainOption(cmd, &domain, kBarrierCheck)->required();
    cmd->add_flag("--quick", quick,
                  "the domain's small profile (its data sizes and preset, as `secure experiment "
                  "--quick`: the check of a quick experiment's barrier)");
    cmd->add_option("--safe-states", safe_path,
                    "labelled safe states (CSV or HDF5) for the accuracy (default: drawn by the "
                    "domain's generators on a stream other than training's)");
    cmd->add_option("--near-dangerous-states", nd_path,
                    "labelled near-dangerous states (CSV or HDF5), for the accuracy and (b)");
    held_out_opt = cmd->add_option("--held-out", held_out,
                                   "states per class drawn when no file is given (default: the "
                                   "domain's experiment's check.held_out, `secure domains "
                                   "NAME`)");
    data_seed_opt = AddSeedOption(cmd, "--data-seed", &data_seed,
                                  "data seed of the drawn states (default: the domain's "
                                  "experiment data_seed, so that a saved seed's barrier gets "
                                  "the check its experiment recorded)");
    cmd->add_option("--out", out, "CSV of the worst counterexamples (docs/FILE_FORMATS.md)");
    Bind(cmd, "--seed", &cbf::BarrierCheckOptions::seed, "seed of the check's sampling and search")
        ->check(NonNegativeSeed());
    Bind(cmd, "--region-samples", &cbf::BarrierCheckOptions::region_samples,
         "states sampled from the region");
    Bind(cmd, "--near-samples", &cbf::BarrierCheckOptions::near_samples,
         "states sampled near near-dangerous ones");
    Bind(cmd, "--near-radius", &cbf::BarrierCheckOptions::near_radius,
         "(b): half-width of the box around a near-dangerous state, in per-feature std units");
    Bind(cmd, "--action-grid", &cbf::BarrierCheckOptions::action_grid,
         "max_a g: grid points per action dimension");
    Bind(cmd, "--action-samples", &cbf::BarrierCheckOptions::action_samples,
         "max_a g: random actions (and per refinement round)");
    Bind(cmd, "--search-starts", &cbf::BarrierCheckOptions::search_starts,
         "local search starts per kind");
    Bind(cmd, "--search-steps", &cbf::BarrierCheckOptions::search_steps,
         "local search iterations per start");
    Bind(cmd, "--worst", &cbf::BarrierCheckOptions::worst_examples,
         "counterexamples kept per kind");
    Bind(cmd, "--max-rate-a", &cbf::CheckThresholds::no_safe_action,
         "threshold tau_a on rate (a) (default 0.01)");
    Bind(cmd, "--max-rate-b", &cbf::CheckThresholds::near_dangerous,
         "threshold tau_b on rate (b) (default 0.05)");
    Bind(cmd, "--max-rate-c", &cbf::CheckThresholds::unsafe,
         "threshold tau_c on rate (c) (default 0.01)");
    class_k_opt = cmd->add_option("--class-k", class_k,
                                  "the shield's class-K function: linear | cubic (default: the "
                                  "domain's shield)");
    gain_opt = cmd->add_option("--class-k-gain", class_k_gain,
                               "k in alpha(h) (default: the domain's shield)");
    dt_opt = cmd->add_option("--dt", dt,
                             "dt in g (default: the domain's shield, its control "
                             "period)");
    task_flags.AddGeometry(cmd);
    task_flags.AddNumber(cmd, "--accel-bound", "accel_bound",
                         "per-axis action bound, the check's action box and the shield model's "
                         "clip");
    cmd->add_flag("--json", json, "print the report as JSON");
    cmd->callback([this] {
      config_error.Rethrow();
      Run();
    });
  }

  cbf::BarrierCheckOptions Options(const cbf::BarrierCheckOptions& base) const {
    cbf::BarrierCheckOptions o = base;
    if (check_yaml.IsMap()) o.ApplyYaml(check_yaml, config->path + " [check]");
    for (const auto& [option, copy] : copies)
      if (option->count() > 0) copy(&o);
    o.Validate();
    return o;
  }

  void ApplyShieldFlags(shield::ShieldOptions* s) const {
    if (class_k_opt->count() > 0)
      s->class_k = FromString(shield::kClassKNames, class_k, "--class-k");
    if (gain_opt->count() > 0) s->class_k_gain = class_k_gain;
    if (dt_opt->count() > 0) s->dt = dt;
    s->Validate();
  }

  // The barrier of the model file, evaluated on the domain's observations (by feature name).
  std::unique_ptr<cbf::Barrier> LoadBarrier(const experiments::ExperimentOptions& e,
                                            const std::vector<std::string>& features,
                                            std::optional<cbf::BarrierNet>* flat,
                                            std::optional<cbf::CarBarrierNet>* per_obstacle) const {
    const std::string kind = nn::ReadModelFile(model).kind;
    const std::string where = "the " + domain + " domain";
    if (cbf::IsFlatBarrierKind(kind)) {
      *flat = cbf::BarrierNet::Load(model);
      return (*flat)->MakeEvaluatorFor(features, where, model);
    }
    if (kind == cbf::kCarBarrierModelKind) {
      SECURE_CHECK(e.barrier_kind == experiments::BarrierKind::kPerObstacle,
                   model << " is a per-obstacle barrier (kind '" << kind << "'), but the " << domain
                         << " domain's barrier is "
                         << ToString(experiments::kBarrierKindNames, e.barrier_kind)
                         << " (domains with a per-obstacle barrier: " << PerObstacleDomainList()
                         << ")");
      *per_obstacle = cbf::CarBarrierNet::Load(model);
      (*per_obstacle)->CheckFeatures(features, where, model);
      return (*per_obstacle)->MakeEvaluator(256);
    }
    SECURE_THROW(model << ": kind '" << kind << "' is not a barrier (expected "
                       << cbf::kBarrierModelKind << ", " << cbf::kBarrierEnsembleModelKind
                       << " or " << cbf::kCarBarrierModelKind << ")");
  }

  void Run() {
    config->Check();
    experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
    SECURE_CHECK(registry.Has(domain),
                 "--domain = '" << domain << "', must be one of: " << DomainsWith(kBarrierCheck));
    SECURE_CHECK(safe_path.empty() == nd_path.empty(),
                 "cbf check: --safe-states and --near-dangerous-states go together");
    if (held_out_opt->count() > 0) CheckRange("--held-out", held_out, 1, kMaxStates);

    // The domain and the experiment options its check starts from: its `--config` section as
    // every command reads it (experiments::ReadSection: the `domain:` key, the preset, the
    // shield, check.held_out and the check options), then the task flags and the shield flags
    // given.
    const std::unique_ptr<experiments::Domain> d =
        registry.Make(domain, quick ? experiments::Profile::kQuick : experiments::Profile::kFull);
    RequireCapability(*d, domain, kBarrierCheck);
    experiments::ExperimentOptions e = experiments::ReadSection(config->root, config->path, *d);
    task_flags.ApplyTo(d.get(), *config);  // the ground-truth section, the task flags; Validate
    ApplyShieldFlags(&e.shield);
    const cbf::BarrierCheckOptions options = Options(e.check);

    const std::vector<std::string> features = d->MakeEnvironment()->ObservationFeatures();
    std::optional<cbf::BarrierNet> flat;
    std::optional<cbf::CarBarrierNet> per_obstacle;
    const std::unique_ptr<cbf::Barrier> barrier = LoadBarrier(e, features, &flat, &per_obstacle);

    const Stopwatch clock;
    data::StateSet safe, nd;
    const std::uint64_t seed = data_seed_opt->count() > 0 ? data_seed : e.data_seed;
    if (!safe_path.empty()) {
      safe = data::ReadStateSet(safe_path, features, data::kSafeLabel);
      nd = data::ReadStateSet(nd_path, features, data::kNearDangerousLabel);
    } else {
      d->CheckHeldOut(seed, held_out_opt->count() > 0 ? held_out : e.check_held_out, &safe, &nd);
    }
    std::unique_ptr<domains::DynamicsModel> dynamics;
    const cbf::BarrierCheckProblem problem = d->MakeCheckProblem(e.shield, safe, nd, &dynamics);
    const Stopwatch check_clock;
    const cbf::CheckReport report = cbf::CheckBarrier(*barrier, *dynamics, problem, options);
    const double check_seconds = check_clock.Seconds(), seconds = clock.Seconds();
    if (!out.empty()) report.WriteCsv(out);
    if (json) {
      nlohmann::json r = report.ToJson();
      r["command"] = "cbf check";
      r["model"] = model;
      r["domain"] = domain;
      r["profile"] = quick ? "quick" : "full";
      r["held_out_sources"] = {{"safe", safe.source}, {"near_dangerous", nd.source}};
      if (safe_path.empty()) r["data_seed"] = seed;
      r["out"] = out;
      r["seconds"] = seconds;
      r["check_seconds"] = check_seconds;
      PrintJson(r);
    } else {
      std::cout << "checked " << report.barrier << " on " << domain << " (" << report.dynamics
                << ", alpha " << report.class_k << ", dt " << report.dt << ")\n"
                << "region: " << report.region << "\n"
                << "unsafe test: " << (report.unsafe_test.empty() ? "none" : report.unsafe_test)
                << "\n"
                << report.Summary();
      if (!out.empty())
        std::cout << "wrote " << report.worst.size() << " counterexamples to " << out << "\n";
      std::printf("%.2f s\n", seconds);
    }
  }
};

}  // namespace

void RegisterCbfCheckCommand(CLI::App& cbf, const Config& config) {
  static CheckCommand check;
  check.Register(cbf, config);
}

}  // namespace secure::cli
