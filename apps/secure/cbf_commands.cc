// secure cbf train | eval | predict | table1.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <iostream>
#include <memory>
#include <optional>
#include <tuple>

#include "cli_common.h"
#include "commands.h"
#include "secure/cbf/barrier_check.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/barrier_trainer.h"
#include "secure/cbf/query.h"
#include "secure/cbf/validation.h"
#include "secure/common/error.h"
#include "secure/common/progress.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/data/data.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/ground_truth_study.h"

namespace secure::cli {
namespace {

// The domain `name` (full profile) with a ground truth, its task options from `flags` and the
// config's ground-truth section. @throws secure::Error naming the domains with one if it has
// none.
std::unique_ptr<experiments::Domain> MakeGroundTruthDomain(const std::string& name,
                                                           const std::string& command,
                                                           const TaskFlags& flags,
                                                           const Config& config) {
  std::unique_ptr<experiments::Domain> d = experiments::DomainRegistry::Global().Make(name);
  RequireCapability(*d, name, kGroundTruth, command + ": ");
  flags.ApplyTo(d.get(), config);
  return d;
}

// Flags for BarrierTrainerOptions fields (shared by train and table1). Values land in
// `parsed`; ApplyTo() copies only the flags that were given onto a base (the general defaults or a
// domain preset, with the YAML config applied), so the precedence is base < config < flags.
class TrainerFlags {
 public:
  void Add(CLI::App* cmd, const cbf::BarrierTrainerOptions& shown_defaults) {
    parsed_ = shown_defaults;
    Bind(cmd, "--hidden", &Options::hidden, "hidden layer widths, e.g. 64,64,64")->delimiter(',');
    activation_ =
        cmd->add_option("--activation", activation_name_, "hidden activation: relu | tanh")
            ->default_str(ToString(nn::kActivationNames, shown_defaults.activation));
    Bind(cmd, "--epochs", &Options::max_epochs, "maximum epochs");
    Bind(cmd, "--batch-size", &Options::batch_size, "minibatch size");
    Bind(cmd, "--lr", &Options::learning_rate, "Adam learning rate (start of the cosine decay)");
    Bind(cmd, "--final-lr", &Options::final_learning_rate, "learning rate at the last epoch");
    Bind(cmd, "--weight-decay", &Options::weight_decay, "L2 weight decay");
    Bind(cmd, "--safe-margin", &Options::safe_margin, "hinge margin for safe states");
    Bind(cmd, "--unsafe-margin", &Options::unsafe_margin, "hinge margin for near-dangerous states");
    Bind(cmd, "--safe-weight", &Options::safe_weight, "weight of the safe term");
    Bind(cmd, "--unsafe-weight", &Options::unsafe_weight, "weight of the near-dangerous term");
    Bind(cmd, "--ensemble", &Options::ensemble,
         "K: train K barriers from different initialisations (member k's seed derived from "
         "--seed), h = min over them (model kind barrier_ensemble)");
    Bind(cmd, "--validation-fraction", &Options::validation_fraction,
         "fraction of each class held out for best-checkpoint selection");
    Bind(cmd, "--patience", &Options::patience, "early-stopping patience in epochs (0: off)");
    Bind(cmd, "--threads", &Options::threads, "LibTorch threads for training");
    CLI::Option* verbose =
        cmd->add_flag("--verbose", parsed_.verbose, "training progress on stderr");
    copies_.emplace_back(verbose,
                         [](const Options& from, Options* to) { to->verbose = from.verbose; });
  }

  /// How often the flag `name` was given (0: not given, or not a flag of these).
  std::size_t Given(const std::string& name) const {
    for (const auto& [option, copy] : copies_)
      if (option->check_lname(name.substr(2))) return option->count();
    return 0;
  }

  /// Copies the given flags onto `options`, then validates.
  void ApplyTo(cbf::BarrierTrainerOptions* options) const {
    for (const auto& [option, copy] : copies_)
      if (option->count() > 0) copy(parsed_, options);
    if (activation_->count() > 0)
      options->activation = FromString(nn::kActivationNames, activation_name_, "--activation");
    options->Validate();
  }

 private:
  using Options = cbf::BarrierTrainerOptions;
  template <typename T, typename C>  // C: Options or a base of it (cbf::TrainingSchedule)
  CLI::Option* Bind(CLI::App* cmd, const std::string& name, T C::*field,
                    const std::string& help) {
    CLI::Option* option = cmd->add_option(name, parsed_.*field, help)->capture_default_str();
    copies_.emplace_back(option,
                         [field](const Options& from, Options* to) { to->*field = from.*field; });
    return option;
  }

  Options parsed_;
  std::string activation_name_;
  CLI::Option* activation_ = nullptr;
  std::vector<std::pair<CLI::Option*, std::function<void(const Options&, Options*)>>> copies_;
};

// A --features list: no name twice (a repeated name would silently stand for another column).
void CheckFeatureList(const std::vector<std::string>& names) {
  for (std::size_t k = 0; k < names.size(); ++k) {
    SECURE_CHECK(!names[k].empty(), "--features: entry " << k + 1 << " is empty");
    for (std::size_t i = 0; i < k; ++i)
      SECURE_CHECK(names[i] != names[k], "--features: feature '"
                                             << names[k] << "' is given twice (entries " << i + 1
                                             << " and " << k + 1 << ")");
  }
}

// `cbf train` from files stops early by default: after this many epochs without a better
// held-out score (the trainer's best-checkpoint score: balanced accuracy on the
// --validation-fraction split, then its loss), keeping the best epoch's weights. Only this
// command's default: the library's (BarrierTrainerOptions::patience), the domain presets and the
// experiment driver keep theirs (0), so their results do not change.
constexpr int kTrainFromFilesPatience = 50;

// ------------------------------------------------------------------------------------------
struct TrainCommand {
  YAML::Node trainer_yaml;  // the config's `trainer:` section, applied over the base options
  const Config* config = nullptr;
  cbf::BarrierTrainerOptions trainer;
  TrainerFlags trainer_flags;
  TaskFlags task_flags;
  std::string domain, safe_path, nd_path, features, out, augment_from;
  long n_safe = 800, n_unsafe = 800;
  std::uint64_t seed = 0;
  double test_fraction = 0.0;
  bool json = false;
  bool no_early_stopping = false;
  std::string progress = "auto";
  DeferredError config_error;  // thrown when this command runs, not at registration

  void Register(CLI::App& app, const Config& config) {
    CLI::App* cmd = app.add_subcommand(
        "train",
        "Learn a barrier h(s) from safe and near-dangerous states (Eq. 4). From files, early "
        "stopping is on: training stops after --patience (default " +
            std::to_string(kTrainFromFilesPatience) +
            ") epochs without a better held-out score (balanced accuracy on the "
            "--validation-fraction split, then its loss) and keeps the best epoch's weights; "
            "--no-early-stopping runs every --epochs. With --domain the domain's ground-truth "
            "preset applies (no early stopping)");
    this->config = &config;
    config_error.Capture([&] { trainer_yaml = config.Section("trainer"); });
    AddConfigFlag(cmd, config);
    cmd->add_option(
        "--domain", domain,
        "sample labelled states from a domain's ground truth: " + DomainsWith(kGroundTruth) +
            " (trainer options then start from the domain's ground-truth preset, "
            "`secure domains NAME`)");
    cmd->add_option("--safe-states", safe_path,
                    "safe states: a CSV (header row) or an HDF5 file (.h5, .hdf5; its set "
                    "safety/safe, or its only set)");
    cmd->add_option("--near-dangerous-states", nd_path,
                    "near-dangerous states: a CSV or an HDF5 file (safety/near_dangerous, or its "
                    "only set)");
    cmd->add_option("--features", features,
                    "comma-separated column names (HDF5: columns or obs keys) to use as state "
                    "features (default: all)");
    cmd->add_option("--safe", n_safe, "safe states to sample (with --domain)")
        ->capture_default_str();
    cmd->add_option("--unsafe", n_unsafe, "unsafe states to sample (with --domain)")
        ->capture_default_str();
    task_flags.AddGeometry(cmd);
    AddSeedOption(cmd, "--seed", &seed, "seed for sampling, weights and minibatches");
    cmd->add_option("--out", out, "model file to write")->required();
    cmd->add_option("--test-fraction", test_fraction,
                    "hold out this fraction of each class before training and report the "
                    "model's accuracy on it, in [0, 1)")
        ->capture_default_str();
    cmd->add_option("--augment-from", augment_from,
                    "a `cbf check` CSV (its states join the near-dangerous training states), or "
                    "a labelled `cbf query` CSV (its `label` column: 1 safe, 0 near-dangerous, "
                    "-1 skipped)");
    trainer_flags.Add(cmd, FromFilesDefaults());
    cmd->add_flag("--no-early-stopping", no_early_stopping,
                  "train for every --epochs (as --patience 0); the best epoch's weights are kept "
                  "either way");
    cmd->add_flag("--json", json, "print the result as JSON");
    AddProgressOption(cmd, &progress)
        ->description(
            "a live progress line on stderr (epochs done/max-epochs, elapsed, time left at most; "
            "early stopping may end sooner): auto (when stderr is a terminal), always, never");
    cmd->callback([this] {
      config_error.Rethrow();
      Run();
    });
  }

  // The general trainer defaults with this command's early stopping.
  static cbf::BarrierTrainerOptions FromFilesDefaults() {
    cbf::BarrierTrainerOptions o;
    o.patience = kTrainFromFilesPatience;
    return o;
  }

  void Run() {
    const bool from_domain = !domain.empty();
    SECURE_CHECK(std::isfinite(test_fraction) && test_fraction >= 0 && test_fraction < 1,
                 "--test-fraction = " << test_fraction << ", must be in [0, 1)");
    std::unique_ptr<experiments::Domain> d;
    if (from_domain) d = MakeGroundTruthDomain(domain, "cbf train --domain", task_flags, *config);
    trainer = d ? d->GroundTruthTrainerPreset() : FromFilesDefaults();
    if (trainer_yaml.IsMap()) trainer.ApplyYaml(trainer_yaml, config->path);
    trainer_flags.ApplyTo(&trainer);
    if (no_early_stopping) {
      SECURE_CHECK(trainer_flags.Given("--patience") == 0 || trainer.patience == 0,
                   "cbf train: --no-early-stopping and --patience " << trainer.patience
                                                                   << " contradict each other");
      trainer.patience = 0;
    }
    trainer.seed = seed;
    data::StateSet safe, nd;
    const bool from_files = !safe_path.empty() || !nd_path.empty();
    SECURE_CHECK(from_domain != from_files,
                 "cbf train: give either --domain or both --safe-states and "
                 "--near-dangerous-states");
    const std::vector<std::string> names = data::SplitList(features);
    CheckFeatureList(names);
    if (from_domain) {
      CheckRange("--safe", n_safe, 1, kMaxStates);
      CheckRange("--unsafe", n_unsafe, 1, kMaxStates);
      experiments::GroundTruthSample sampled = d->SampleGroundTruth(n_safe, n_unsafe, seed);
      safe = std::move(sampled.safe);
      nd = std::move(sampled.unsafe);
    } else {
      SECURE_CHECK(!safe_path.empty() && !nd_path.empty(),
                   "cbf train: --safe-states and --near-dangerous-states go together");
      safe = data::ReadStateSet(safe_path, names, data::kSafeLabel);
      nd = data::ReadStateSet(nd_path, names, data::kNearDangerousLabel);
    }
    // Held-out test split per class, drawn before training from its own stream.
    data::StateSet safe_test, nd_test;
    if (test_fraction > 0) {
      Rng rng(seed ^ 0x7e57'0000'0000'0000ULL);
      std::tie(safe, safe_test) = data::SplitStateSet(safe, test_fraction, rng);
      std::tie(nd, nd_test) = data::SplitStateSet(nd, test_fraction, rng);
    }
    long augmented = 0;  // after the test split: the test set stays the original data
    const auto append = [](data::StateSet* to, const data::StateSet& extra) {
      const long n = to->size();
      to->states.conservativeResize(Eigen::NoChange, n + extra.size());
      to->states.rightCols(extra.size()) = extra.states;
    };
    if (!augment_from.empty()) {
      if (cbf::HasLabelColumn(augment_from)) {  // labelled queries (cbf query, cbf label)
        const cbf::LabelledStates extra = cbf::ReadLabelledStates(augment_from, nd.features);
        augmented = extra.safe.size() + extra.near_dangerous.size();
        append(&safe, extra.safe);
        append(&nd, extra.near_dangerous);
      } else {  // a check CSV: every row near-dangerous
        const data::StateSet extra = cbf::ReadCheckStates(augment_from, nd.features);
        augmented = extra.size();
        append(&nd, extra);
      }
    }
    cbf::BarrierTrainingSummary summary;
    ProgressLine line(&std::cerr, ProgressIsLive(progress));
    line.Install();  // the --verbose lines print above the live line
    line.Start(trainer.max_epochs, "barrier epochs");
    cbf::BarrierNet net =
        cbf::TrainBarrier(trainer, safe, nd, &summary, [&line](int, double, double) {
          line.Advance();
          return true;
        });
    line.Finish();
    if (!augment_from.empty())
      net.provenance["augmented_from"] = {{"file", augment_from}, {"states", augmented}};
    std::optional<cbf::ClassAccuracy> test;
    // The accuracy of a class with no held-out state is undefined: null in JSON, n/a in text.
    const auto accuracy_json = [](long n, double accuracy) {
      return n > 0 ? nlohmann::json(accuracy) : nlohmann::json(nullptr);
    };
    if (test_fraction > 0) {
      // The test sets keep all the data's features; the model reads its own by name.
      test = cbf::EvaluateAccuracy(
          *net.MakeEvaluatorFor(safe_test.features, "the held-out states", out), safe_test.states,
          nd_test.states);
      net.provenance["test"] = {
          {"fraction", test_fraction},
          {"safe", safe_test.size()},
          {"near_dangerous", nd_test.size()},
          {"accuracy_safe", accuracy_json(safe_test.size(), test->safe)},
          {"accuracy_near_dangerous", accuracy_json(nd_test.size(), test->near_dangerous)}};
    }
    // The ground truth the states came from (the double integrator: its geometry), under the
    // domain's section name, which `shield run` compares with its own.
    if (d && !d->GroundTruthSection().empty())
      net.provenance[d->GroundTruthSection()] = d->GroundTruthJson();
    net.Save(out);
    if (json) {
      nlohmann::json r{{"command", "cbf train"},
                       {"model", out},
                       {"features", net.features},
                       {"options", trainer.ToJson()},
                       {"summary", summary.ToJson()}};
      if (test) {
        const bool both = safe_test.size() > 0 && nd_test.size() > 0;
        r["test"] = {
            {"safe", safe_test.size()},
            {"near_dangerous", nd_test.size()},
            {"accuracy",
             {{"safe", accuracy_json(safe_test.size(), test->safe)},
              {"near_dangerous", accuracy_json(nd_test.size(), test->near_dangerous)},
              {"balanced", both ? nlohmann::json(test->Balanced()) : nlohmann::json(nullptr)}}}};
      }
      PrintJson(r);
    } else {
      std::cout << "trained " << net.MakeEvaluator()->Describe() << " on " << safe.size()
                << " safe + " << nd.size() << " near-dangerous states -> " << out << "\n"
                << summary.FullReport();
      if (test) {
        const auto figure = [](long n, double accuracy) {
          if (n == 0) return std::string("n/a (no held-out states)");
          char buf[32];
          std::snprintf(buf, sizeof buf, "%.4f", accuracy);
          return std::string(buf);
        };
        const long both = std::min(safe_test.size(), nd_test.size());
        std::cout << "held-out test: " << safe_test.size() << " safe, " << nd_test.size()
                  << " near-dangerous; accuracy safe " << figure(safe_test.size(), test->safe)
                  << ", near-dangerous " << figure(nd_test.size(), test->near_dangerous)
                  << ", balanced " << figure(both, test->Balanced()) << "\n";
      }
    }
  }
};

// ------------------------------------------------------------------------------------------
struct ValidateCommand {
  const Config* config = nullptr;
  TaskFlags task_flags;
  std::string model, domain;
  cbf::GridValidationOptions validation;
  bool json = false;
  std::string name;

  void Register(CLI::App& app, const Config& config, const std::string& command) {
    name = command;
    CLI::App* cmd = app.add_subcommand(
        command, command == "validate"
                     ? "Confusion matrix of a barrier against a domain's ground truth on the "
                       "domain's validation grid"
                     : "Alias of `cbf validate`");
    this->config = &config;
    AddConfigFlag(cmd, config);  // the domain's ground-truth section (double_integrator:)
    cmd->add_option("--model", model, "barrier model file")->required()->check(CLI::ExistingFile);
    AddDomainOption(cmd, &domain, kGroundTruth)->required();
    task_flags.AddGeometry(cmd);
    cmd->add_option("--threads", validation.threads, "worker threads")->capture_default_str();
    cmd->add_flag("--json", json, "print the result as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    // The geometry flags and the domain's ground-truth section are its task options; a domain
    // without them rejects them by name.
    const std::unique_ptr<experiments::Domain> d =
        MakeGroundTruthDomain(domain, "cbf " + name, task_flags, *config);
    const std::optional<cbf::StateSource> grid = d->ValidationGrid();
    SECURE_CHECK(grid.has_value(),
                 "cbf " << name << ": the " << domain << " domain has no validation grid");
    const cbf::BarrierNet net = cbf::BarrierNet::Load(model);
    const std::vector<std::string> features = d->MakeEnvironment()->ObservationFeatures();
    const std::string where = "the " + domain + " domain";
    cbf::FeatureRows(net.features, features, where, model);  // fails here on a mismatch
    const Stopwatch clock;
    const cbf::Confusion c = cbf::ValidateOnGrid(
        [&] { return net.MakeEvaluatorFor(features, where, model); },
                                                 [&] { return d->MakeGroundTruth(); }, *grid,
                                                 validation);
    const double seconds = clock.Seconds();
    if (json) {
      nlohmann::json r = c.ToJson();
      r["command"] = "cbf " + name;
      r["domain"] = domain;
      r["model"] = model;
      r["seconds"] = seconds;
      PrintJson(r);
    } else {
      std::printf("| predicted \\ ground truth | safe | unsafe |\n|---|---:|---:|\n");
      std::printf("| safe | %.3f%% | %.3f%% |\n", 100 * c.SafeCorrect(),
                  100 * c.UnderConservative());
      std::printf("| unsafe | %.3f%% | %.3f%% |\n", 100 * c.OverConservative(),
                  100 * c.UnsafeCorrect());
      std::printf("%ld grid states (%ld truly safe, %ld truly unsafe) in %.2f s\n", c.total(),
                  c.truly_safe(), c.truly_unsafe(), seconds);
    }
  }
};

// ------------------------------------------------------------------------------------------
struct PredictCommand {
  std::string model, states, out;
  bool json = false;

  void Register(CLI::App& app, const Config& config) {
    CLI::App* cmd = app.add_subcommand(
        "predict", "h(s) for every row of a CSV (columns picked by the model's feature names)");
    cmd->add_option("--model", model, "barrier model file")->required()->check(CLI::ExistingFile);
    cmd->add_option("--states", states,
                    "states: a CSV with a header row, or an HDF5 file (its only state set, or "
                    "its demonstrations' steps)")
        ->required();
    cmd->add_option("--out", out, "CSV to write: columns h, safe (1 if h >= 0)")->required();
    cmd->add_flag("--json", json, "print a summary as JSON");
    cmd->callback([this] { Run(); });
  }

  void Run() {
    const cbf::BarrierNet net = cbf::BarrierNet::Load(model);
    const data::StateSet set = data::ReadStateSet(states, net.features);
    Eigen::VectorXf h(set.size());
    net.MakeEvaluator()->Evaluate(set.states, h);
    for (Eigen::Index i = 0; i < h.size(); ++i) {
      if (std::isfinite(h[i])) continue;
      // Name the input line (the data rows' lines, from the reader, only on this error path);
      // an HDF5 file's state by its index.
      std::string where = " state " + std::to_string(i) + " (0-based)";
      if (!data::IsHdf5Path(states)) {
        const data::NumericTable table = data::ReadCsv(states, net.features);
        where = std::to_string(table.lines[static_cast<std::size_t>(i)]);
      }
      SECURE_THROW(states << ":" << where << ": the model " << model << " gives h = "
                          << (std::isnan(h[i]) ? "nan"
                              : h[i] > 0       ? "inf"
                                               : "-inf")
                          << " for this state (not finite; its values are extreme for the "
                             "model)");
    }
    Eigen::MatrixXd table(2, set.size());
    table.row(0) = h.cast<double>().transpose();
    table.row(1) = (h.array() >= 0.0f).cast<double>().matrix().transpose();
    data::WriteCsv(out, {"h", "safe"}, table);
    const long n_safe = static_cast<long>(table.row(1).sum());
    if (json) {
      PrintJson({{"command", "cbf predict"},
                 {"model", model},
                 {"states", states},
                 {"out", out},
                 {"rows", set.size()},
                 {"predicted_safe", n_safe}});
    } else {
      std::cout << "wrote h for " << set.size() << " states to " << out << " (" << n_safe
                << " predicted safe)\n";
    }
  }
};

// ------------------------------------------------------------------------------------------
// The ground-truth study (the paper's Table 1) on any domain with a ground truth
// (experiments/ground_truth_study.h).
struct Table1Command {
  const Config* config = nullptr;
  experiments::GroundTruthStudyOptions options;
  YAML::Node trainer_yaml;
  TrainerFlags trainer_flags;
  TaskFlags task_flags;
  std::string domain;
  bool json = false;
  DeferredError config_error;

  void Register(CLI::App& app, const Config& cfg, const std::string& name,
                const std::string& description) {
    config = &cfg;
    CLI::App* cmd = app.add_subcommand(name, description);
    config_error.Capture([&] { trainer_yaml = cfg.Section("trainer"); });
    AddConfigFlag(cmd, cfg);
    // The default: the first registered domain with a ground truth (the double integrator).
    const experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
    for (const std::string& d : registry.Names()) {
      if (registry.Make(d, experiments::Profile::kQuick)->HasGroundTruth()) {
        domain = d;
        break;
      }
    }
    AddDomainOption(cmd, &domain, kGroundTruth)->capture_default_str();
    cmd->add_option("--seeds", options.seeds, "number of training seeds")->capture_default_str();
    AddSeedOption(cmd, "--first-seed", &options.first_seed, "seed of the first run");
    cmd->add_option("--safe", options.n_safe, "safe training states")->capture_default_str();
    cmd->add_option("--unsafe", options.n_unsafe, "unsafe training states")->capture_default_str();
    task_flags.AddGeometry(cmd);
    cmd->add_option("--grid-threads", options.validation.threads, "threads for grid validation")
        ->capture_default_str();
    // Shown: the default domain's ground-truth preset (a trainer flag not given keeps the
    // chosen domain's value).
    trainer_flags.Add(cmd, domain.empty() ? cbf::BarrierTrainerOptions{}
                                          : registry.Make(domain)->GroundTruthTrainerPreset());
    cmd->add_flag("--json", json, "print the result as JSON");
    cmd->callback([this] {
      config_error.Rethrow();
      Run();
    });
  }

  void Run() {
    CheckRange("--seeds", options.seeds, 1, kMaxSeeds);
    CheckRange("--safe", options.n_safe, 1, kMaxStates);
    CheckRange("--unsafe", options.n_unsafe, 1, kMaxStates);
    SECURE_CHECK(!domain.empty(), "cbf table1: no registered domain has a ground truth");
    const std::unique_ptr<experiments::Domain> d =
        MakeGroundTruthDomain(domain, "cbf table1", task_flags, *config);
    // The trainer: the domain's ground-truth preset, the config's `trainer:`, then the flags.
    options.trainer = d->GroundTruthTrainerPreset();
    if (trainer_yaml.IsMap()) options.trainer.ApplyYaml(trainer_yaml, config->path);
    trainer_flags.ApplyTo(&options.trainer);
    const experiments::GroundTruthStudyResult result = experiments::RunGroundTruthStudy(*d, options);
    if (json) {
      nlohmann::json r = result.ToJson();
      r["command"] = "cbf table1";
      nlohmann::json o = {{"seeds", options.seeds},
                          {"first_seed", options.first_seed},
                          {"safe", options.n_safe},
                          {"unsafe", options.n_unsafe},
                          {"trainer", options.trainer.ToJson()}};
      const nlohmann::json parameters = d->GroundTruthJson();  // the ground truth's geometry
      for (const auto& [key, value] : parameters.items()) o[key] = value;
      r["options"] = o;
      PrintJson(r);
    } else {
      std::cout << result.Table();
    }
  }
};

}  // namespace

void RegisterCbfCommands(CLI::App& app, const Config& config) {
  CLI::App* cbf = app.add_subcommand("cbf", "Learn, check and use control barrier functions");
  cbf->require_subcommand(1);
  static TrainCommand train;
  static ValidateCommand validate, eval;
  static PredictCommand predict;
  static Table1Command table1;
  train.Register(*cbf, config);
  validate.Register(*cbf, config, "validate");
  eval.Register(*cbf, config, "eval");
  predict.Register(*cbf, config);
  table1.Register(*cbf, config, "table1",
                  "The paper's Table 1 on a domain with a ground truth (default: the double "
                  "integrator): learn a CBF from states labelled by the ground truth over seeds, "
                  "validate it on the domain's grid (the double integrator's: 9M states)");
  RegisterCbfCheckCommand(*cbf, config);
  RegisterCbfQueryCommands(*cbf, config);
}

}  // namespace secure::cli
