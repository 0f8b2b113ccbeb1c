// secure cbf check: the pre-deployment check of a learned barrier (cbf/barrier_check.h) on a
// domain. The library check is generic; this file holds the glue of each domain (its state
// region, unsafe test, action box and the shield's dynamics model):
//   double-integrator  region: the validation box (x, y in [0, 10), v in [-1.5, 1.5)), moves
//                      clamped to it; unsafe test: the analytic ground truth h*(s) < 0;
//                      dynamics: the clipped exact step (dt, --accel-bound); held-out and
//                      near-dangerous states: --safe-states / --near-dangerous-states, or drawn
//                      from the ground truth with the check's seed;
//   derby              derby::MakeDerbyCheckProblem (perturbed safe / near-dangerous
//                      observations, the collision test, DerbyShieldModel); held-out states:
//                      the files, or those of `secure experiment` (data_seed 2000), so that a
//                      saved seed's barrier gets the check its experiment recorded.
#include <cstdio>
#include <functional>
#include <iostream>
#include <memory>
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
#include "domains/derby/derby.h"
#include "domains/double_integrator/double_integrator.h"
#include "domains/derby/domain.h"
#include "secure/nn/model_file.h"

namespace secure::cli {
namespace {

namespace di = domains::double_integrator;
namespace derby = domains::derby;

constexpr const char* kDerbyDomain = "derby";
const std::vector<std::string>& KnownCheckDomains() {
  static const std::vector<std::string> known = {kDoubleIntegratorDomain, kDerbyDomain};
  return known;
}

struct CheckCommand {
  std::string model, domain, safe_path, nd_path, out;
  bool json = false;
  long held_out = 256;
  std::uint64_t data_seed = 0;  // 0: the check's seed (double integrator) / 2000 (derby)
  // Overrides (applied only when given, over the domain's defaults and the `check:` section).
  cbf::BarrierCheckOptions parsed;
  std::vector<std::pair<CLI::Option*, std::function<void(cbf::BarrierCheckOptions*)>>> copies;
  std::string class_k;
  double class_k_gain = 0, dt = 0, accel_bound = 3.0;
  CLI::Option *class_k_opt = nullptr, *gain_opt = nullptr, *dt_opt = nullptr;
  di::GroundTruth truth;
  std::vector<double> obstacle;
  YAML::Node check_yaml;
  std::string config_path;
  DeferredError config_error;  // thrown when this command runs, not at registration

  // A flag whose value lands in `parsed` and is copied onto the options only when given.
  template <typename Field>
  CLI::Option* Bind(CLI::App* cmd, const std::string& name, Field field, const std::string& help) {
    CLI::Option* option = cmd->add_option(name, field(parsed), help);
    copies.emplace_back(
        option, [this, field](cbf::BarrierCheckOptions* to) { field(*to) = field(parsed); });
    return option;
  }

  void Register(CLI::App& app, const Config& config) {
    CLI::App* cmd = app.add_subcommand(
        "check",
        "Check a learned barrier before deployment: held-out accuracy and a counterexample "
        "search for (a) h >= 0 with no admissible action, (b) h >= 0 near near-dangerous "
        "states, (c) h >= 0 where the domain's own test says unsafe; verdict by thresholds");
    config_error.Capture([&] {
      check_yaml = config.Section("check");
      ApplyGroundTruthYaml(config.Section("double_integrator"), config.path, &truth);
    });
    config_path = config.path;
    AddConfigFlag(cmd, config);
    cmd->add_option("--model", model, "barrier model file (barrier_mlp or car_barrier)")
        ->required()
        ->check(CLI::ExistingFile);
    cmd->add_option("--domain", domain, "the domain: double-integrator | derby")->required();
    cmd->add_option("--safe-states", safe_path,
                    "labelled safe states (CSV or HDF5) for the accuracy (default: drawn by the "
                    "domain's generators with a seed other than training's)");
    cmd->add_option("--near-dangerous-states", nd_path,
                    "labelled near-dangerous states (CSV or HDF5), for the accuracy and (b)");
    cmd->add_option("--held-out", held_out, "states per class drawn when no CSV is given")
        ->capture_default_str();
    AddSeedOption(cmd, "--data-seed", &data_seed,
                  "seed of the drawn states (0: double-integrator the check's seed XOR a "
                  "constant, derby the experiments' data_seed 2000)");
    cmd->add_option("--out", out, "CSV of the worst counterexamples (docs/FILE_FORMATS.md)");
    Bind(
        cmd, "--seed", [](cbf::BarrierCheckOptions & o) -> auto& { return o.seed; },
        "seed of the check's sampling and search")
        ->check(NonNegativeSeed());
    Bind(
        cmd, "--region-samples",
        [](cbf::BarrierCheckOptions & o) -> auto& { return o.region_samples; },
        "states sampled from the region");
    Bind(
        cmd, "--near-samples", [](cbf::BarrierCheckOptions & o) -> auto& { return o.near_samples; },
        "states sampled near near-dangerous ones");
    Bind(
        cmd, "--near-radius", [](cbf::BarrierCheckOptions & o) -> auto& { return o.near_radius; },
        "(b): half-width of the box around a near-dangerous state, in per-feature std units");
    Bind(
        cmd, "--action-grid", [](cbf::BarrierCheckOptions & o) -> auto& { return o.action_grid; },
        "max_a g: grid points per action dimension");
    Bind(
        cmd, "--action-samples",
        [](cbf::BarrierCheckOptions & o) -> auto& { return o.action_samples; },
        "max_a g: random actions (and per refinement round)");
    Bind(
        cmd, "--search-starts",
        [](cbf::BarrierCheckOptions & o) -> auto& { return o.search_starts; },
        "local search starts per kind");
    Bind(
        cmd, "--search-steps", [](cbf::BarrierCheckOptions & o) -> auto& { return o.search_steps; },
        "local search iterations per start");
    Bind(
        cmd, "--worst", [](cbf::BarrierCheckOptions & o) -> auto& { return o.worst_examples; },
        "counterexamples kept per kind");
    Bind(
        cmd, "--max-rate-a",
        [](cbf::BarrierCheckOptions & o) -> auto& { return o.thresholds.no_safe_action; },
        "threshold tau_a on rate (a) (default 0.01)");
    Bind(
        cmd, "--max-rate-b",
        [](cbf::BarrierCheckOptions & o) -> auto& { return o.thresholds.near_dangerous; },
        "threshold tau_b on rate (b) (default 0.05)");
    Bind(
        cmd, "--max-rate-c",
        [](cbf::BarrierCheckOptions & o) -> auto& { return o.thresholds.unsafe; },
        "threshold tau_c on rate (c) (default 0.01)");
    class_k_opt = cmd->add_option("--class-k", class_k,
                                  "the shield's class-K function: linear | cubic (default: the "
                                  "domain's shield)");
    gain_opt = cmd->add_option("--class-k-gain", class_k_gain,
                               "k in alpha(h) (default: double-integrator 1, derby 2)");
    dt_opt = cmd->add_option("--dt", dt, "dt in g (default 0.1)");
    cmd->add_option("--accel-bound", accel_bound,
                    "double-integrator: per-axis action bound (the action box)")
        ->capture_default_str();
    AddGroundTruthFlags(cmd, &truth, &obstacle);
    cmd->add_flag("--json", json, "print the report as JSON");
    cmd->callback([this] {
      config_error.Rethrow();
      Run();
    });
  }

  cbf::BarrierCheckOptions Options(const cbf::BarrierCheckOptions& base) const {
    cbf::BarrierCheckOptions o = base;
    if (check_yaml.IsMap()) o.ApplyYaml(check_yaml, config_path + " [check]");
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

  void Run() {
    bool known = false;
    std::string list;
    for (const std::string& d : KnownCheckDomains()) {
      known = known || d == domain;
      list += (list.empty() ? "" : ", ") + d;
    }
    SECURE_CHECK(known, "--domain = '" << domain << "', must be one of: " << list);
    SECURE_CHECK(safe_path.empty() == nd_path.empty(),
                 "cbf check: --safe-states and --near-dangerous-states go together");
    CheckRange("--held-out", held_out, 1, kMaxStates);

    // The barrier, by the model file's kind.
    const std::string kind = nn::ReadModelFile(model).kind;
    std::unique_ptr<cbf::Barrier> barrier;
    std::optional<cbf::BarrierNet> flat;
    std::optional<cbf::CarBarrierNet> per_car;
    const std::vector<std::string>& features =
        domain == kDerbyDomain ? derby::ObservationFeatures() : di::StateFeatures();
    if (kind == cbf::kBarrierModelKind) {
      flat = cbf::BarrierNet::Load(model);
      barrier = flat->MakeEvaluatorFor(features, "the " + domain + " domain", model);
    } else if (kind == cbf::kCarBarrierModelKind) {
      SECURE_CHECK(domain == kDerbyDomain, model << " is a per-car barrier (kind '" << kind
                                                 << "'), which needs --domain derby");
      per_car = cbf::CarBarrierNet::Load(model);
      per_car->CheckFeatures(features, "the derby domain", model);
      barrier = per_car->MakeEvaluator(256);
    } else {
      SECURE_THROW(model << ": kind '" << kind << "' is not a barrier (expected "
                         << cbf::kBarrierModelKind << " or " << cbf::kCarBarrierModelKind << ")");
    }

    const Stopwatch clock;
    cbf::BarrierCheckOptions options;
    cbf::BarrierCheckProblem problem;
    std::unique_ptr<domains::DynamicsModel> dynamics;
    if (domain == kDerbyDomain) {
      options = Options(derby::DerbyCheckDefaults());
      const derby::DerbyDomain d;
      experiments::ExperimentOptions e = d.Preset();
      if (data_seed != 0) e.data_seed = data_seed;
      ApplyShieldFlags(&e.shield);
      data::StateSet safe, nd;
      if (!safe_path.empty()) {
        safe = data::ReadStateSet(safe_path, features, data::kSafeLabel);
        nd = data::ReadStateSet(nd_path, features, data::kNearDangerousLabel);
      } else {
        d.CheckHeldOut(e.data_seed, held_out, &safe, &nd);
      }
      problem = d.MakeCheckProblem(e.shield, safe, nd, &dynamics);
    } else {
      options = Options(cbf::BarrierCheckOptions{});
      FinishGroundTruth(obstacle, &truth);
      truth.Validate();
      shield::ShieldOptions s;
      ApplyShieldFlags(&s);
      problem = DoubleIntegratorProblem(s, features, options.seed);
      dynamics = std::make_unique<di::ClippedDoubleIntegrator>(s.dt, accel_bound);
    }
    const cbf::CheckReport report = cbf::CheckBarrier(*barrier, *dynamics, problem, options);
    const double seconds = clock.Seconds();
    if (!out.empty()) report.WriteCsv(out);
    if (json) {
      nlohmann::json r = report.ToJson();
      r["command"] = "cbf check";
      r["model"] = model;
      r["domain"] = domain;
      r["out"] = out;
      r["seconds"] = seconds;
      PrintJson(r);
    } else {
      std::cout << "checked " << report.barrier << " on " << domain << " (" << report.dynamics
                << ", alpha " << report.class_k << ", dt " << report.dt << ")\n"
                << report.Summary();
      if (!out.empty())
        std::cout << "wrote " << report.worst.size() << " counterexamples to " << out << "\n";
      std::printf("%.2f s\n", seconds);
    }
  }

  // The double integrator's glue: the validation box, the ground truth, sampled labelled states.
  cbf::BarrierCheckProblem DoubleIntegratorProblem(const shield::ShieldOptions& s,
                                                   const std::vector<std::string>& features,
                                                   std::uint64_t check_seed) const {
    cbf::BarrierCheckProblem p;
    p.action_lo = Eigen::VectorXf::Constant(di::kActionDim, -float(accel_bound));
    p.action_hi = Eigen::VectorXf::Constant(di::kActionDim, float(accel_bound));
    p.dt = s.dt;
    p.class_k = [s](double h) { return shield::ClassKValue(s, h); };
    p.class_k_description =
        ToString(shield::kClassKNames, s.class_k) + ", k = " + std::to_string(s.class_k_gain);
    const di::StateBox box;
    p.sample_region = [box](Rng& rng, Eigen::Ref<Eigen::VectorXf> state) {
      for (int i = 0; i < di::kStateDim; ++i)
        state[i] = static_cast<float>(rng.Uniform(box.lo[i], box.hi[i]));
    };
    p.project = [box](Eigen::Ref<Eigen::VectorXf> state) {
      for (int i = 0; i < di::kStateDim; ++i)
        state[i] = std::clamp(state[i], float(box.lo[i]), float(box.hi[i]));
    };
    const di::GroundTruth t = truth;
    p.is_unsafe = [t](const Eigen::Ref<const Eigen::VectorXf>& x) {
      return t.H(x[0], x[1], x[2], x[3]) < 0;
    };
    p.is_unsafe_description = "ground truth h*(s) < 0";
    p.region_description = "the validation box x, y in [0, 10), vx, vy in [-1.5, 1.5)";
    if (!safe_path.empty()) {
      p.held_out_safe = data::ReadStateSet(safe_path, features, data::kSafeLabel);
      p.held_out_near_dangerous = data::ReadStateSet(nd_path, features, data::kNearDangerousLabel);
    } else {
      Rng rng(data_seed != 0 ? data_seed : check_seed ^ 0x5a3b1e0d7ULL);
      di::LabelledStates l = di::SampleLabelled(t, box, held_out, held_out, rng);
      p.held_out_safe = data::StateSet{"drawn safe states", features, std::move(l.safe)};
      p.held_out_near_dangerous =
          data::StateSet{"drawn unsafe states", features, std::move(l.unsafe)};
    }
    p.near_dangerous = *p.held_out_near_dangerous;
    return p;
  }
};

}  // namespace

void RegisterCbfCheckCommand(CLI::App& cbf, const Config& config) {
  static CheckCommand check;
  check.Register(cbf, config);
}

}  // namespace secure::cli
