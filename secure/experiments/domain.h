#pragma once
// What a domain plug-in gives the generic experiments, and the registry the CLI (and any
// program) finds domains in.
//
// A domain is one folder under domains/ with one CMake target (secure_add_domain) and one
// registration line (add_subdirectory in domains/CMakeLists.txt); it implements this interface:
//   - its own options (task, expert, data generators), profile-dependent (full | quick), read from
//     a YAML mapping and recorded as JSON;
//   - factories: the Environment (which also owns the shield's dynamics model and the backup
//     action), the data an experiment learns from (task demonstrations, safe and near-dangerous
//     states), held-out states for the barrier check;
//   - the experiment preset: which barrier kind and which trainer settings, the shield, the
//     evaluation size (ExperimentOptions);
//   - optionally, capabilities (each a group of methods below with its Has...() test): the
//     barrier check's problem (region, unsafe test), the label check, participants for a user
//     study, the paper's numbers, an analytic ground truth (reference barrier, validation grid,
//     labelled-state sampler: what the ground-truth study, Table 1, needs), a closed-loop
//     shield run of a nominal policy, and the report's picture hints (report_hints.h).
// Generic modules and hosts (the CLI, the Python module) never include a concrete domain; they
// see domains through this interface (the build checks it: cmake/SecureArchitecture.cmake).
//
//   experiments::DomainRegistry& registry = experiments::DomainRegistry::Global();
//   std::unique_ptr<experiments::Domain> d = registry.Make("derby", experiments::Profile::kQuick);
//   experiments::ExperimentOptions o = d->Preset();
//   using experiments::ExperimentKind;
//   experiments::ExperimentResult r =
//       experiments::RunExperiment(ExperimentKind::kMethodComparison, *d, o, &std::cerr);
#include <cstdint>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_check.h"
#include "secure/cbf/barrier_trainer.h"
#include "secure/cbf/validation.h"
#include "secure/common/enum_strings.h"
#include "secure/data/data.h"
#include "secure/domains/dynamics.h"
#include "secure/domains/environment.h"
#include "secure/experiments/report_hints.h"
#include "secure/shield/shield.h"

namespace YAML {
class Node;
}

namespace secure::experiments {

struct ExperimentOptions;

/// The size of a domain's data and of the experiment preset: the paper's protocol, or a small
/// profile for tests and smoke runs.
enum class Profile { kFull, kQuick };

/// The data an experiment learns from, generated once from a data seed.
struct DomainData {
  data::TrajectorySet demonstrations;   // the expert's task demonstrations (collisions dropped)
  data::StateSet safe, near_dangerous;  // the barrier's training data
  long discarded_demonstrations = 0;    // expert episodes dropped (collided, or missed the goal)
};

/// The paper's own numbers for a domain's Table 3 row (Domain::PaperTable3), printed by the CLI
/// beside a method comparison in the paper's form. Rates in %; a std the paper does not give is
/// NaN.
struct PaperTable3Row {
  std::string method;  // "bc" | "airl" | "secure"
  double success = 0, success_std = 0, dangerous = 0, dangerous_std = 0;
};
struct PaperTable3 {
  std::string source;  // where the numbers come from ("Table 3, real robot, 10 episodes")
  std::vector<PaperTable3Row> rows;
  std::string comparison;  // the paper's "SECURE comparison with AIRL" column, in words
};

/// One row of a label check (Domain::CheckLabels): a labelled set of states and how many of them
/// lead to a dangerous event when the motion they show continues in the domain's physics.
struct LabelCheckRow {
  std::string set;     // "near-dangerous (upper part)"
  std::string label;   // "safe" | "near-dangerous": what the data claims
  long states = 0;     // checked
  long dangerous = 0;  // ended in a dangerous event
  long skipped = 0;    // could not be simulated (e.g. out of the robot's reach)
  double DangerousFraction() const {
    return states > skipped ? double(dangerous) / double(states - skipped) : 0.0;
  }
};

/// The participants of a user study (experiments/user_study.h): simulated people who each
/// demonstrate the task, label states by their own thresholds, and judge the robot by them. A
/// domain offers one through Domain::MakePopulation; its methods are const and thread-safe.
struct PopulationOptions {
  int participants = 12;
  std::uint64_t seed = 0;         // the participants' constants (deterministic)
  double threshold_spread = 1.0;  // scales the spread of the personal thresholds about their mean
                                  // (0: every participant has the mean thresholds)
};

/// The paper's own numbers of a user study (Table 4), per condition in the user study's order
/// ((policy, barrier) = (individual, individual), (individual, grouped), (grouped, individual),
/// (grouped, grouped)).
struct PaperUserStudy {
  std::string source;  // "Table 4, 12 participants, Likert ratings (not rates)"
  std::vector<std::pair<std::string, std::vector<double>>> rows;  // (what, 4 values)
};

/// States drawn and labelled by a domain's ground truth (Domain::SampleGroundTruth).
struct GroundTruthSample {
  data::StateSet safe;    // h*(s) >= 0
  data::StateSet unsafe;  // h*(s) < 0
};

/// The paper's numbers for the ground-truth study (Table 1: a barrier learned from labelled
/// states against the ground truth on the validation grid), in %.
struct PaperGroundTruthStudy {
  double over_conservative = 0, over_conservative_std = 0;    // predicted unsafe | truly safe
  double under_conservative = 0, under_conservative_std = 0;  // predicted safe | truly unsafe
};

/// A closed-loop shield run (Domain::RunShield): episodes of the domain's nominal policy (with
/// Gaussian noise) in its task, with the shield over a given barrier in the loop or without it.
/// Domain::ShieldRunPreset() gives the domain's values; a caller overrides fields.
struct ShieldRunRequest {
  long episodes = 1000;
  std::uint64_t seed = 0;     // start states, shield samples and policy noise
  double policy_sigma = 0.3;  // the nominal policy's noise per action component
  shield::ShieldOptions shield;
  bool shielded = true;       // false: the policy's draws are applied unchecked (the baseline)
  long record_states = 0;     // keep up to this many visited states in ShieldRunReport::visited
};
/// What a shield run reports: its JSON document and a Markdown table.
struct ShieldRunReport {
  nlohmann::json json;
  std::string table;
  data::StateSet visited;  // with record_states > 0: states the run visited (observation features)
};

class Population {
 public:
  virtual ~Population() = default;
  /// The number of participants.
  virtual int size() const = 0;
  /// Participant p's constants, for the report.
  virtual nlohmann::json Participant(int p) const = 0;
  /// Participant p's data from `data_seed` (deterministic): their task demonstrations, and the
  /// states they label safe (`safe`) and unsafe (`near_dangerous`) by their own thresholds.
  virtual DomainData GenerateData(int p, std::uint64_t data_seed) const = 0;
  /// The task environment as participant p judges it: StepOutcome::collided is a violation of
  /// p's thresholds; success is the task's.
  virtual std::unique_ptr<domains::Environment> MakeEnvironment(int p) const = 0;
  /// Whether p's thresholds hold with margin at `observation` (so that a shield changing the
  /// action there is over-conservative).
  virtual bool HeldWithMargin(int p, const Eigen::Ref<const Eigen::VectorXf>& observation) const = 0;
  /// What a violation and "with margin" are, in one sentence (for reports).
  virtual std::string Describe() const = 0;
  /// The length of an environment step in seconds (task times are reported in seconds), or 0
  /// (in steps).
  virtual double StepSeconds() const { return 0.0; }
  /// The paper's numbers for this study, if it has them.
  virtual std::optional<PaperUserStudy> PaperReference() const { return std::nullopt; }
};

class Domain {
 public:
  virtual ~Domain() = default;

  /// The registry name ("double-integrator").
  virtual std::string name() const = 0;
  /// One line for reports ("Demolition Derby: 16 cars, ...").
  virtual std::string Describe() const = 0;
  /// A short title for tables ("the double-integrator reach-avoid task").
  virtual std::string Title() const { return name(); }
  /// The config-file section (`--config`) whose keys ExperimentOptions::ApplyYaml reads for this
  /// domain's experiments (for example "derby").
  virtual std::string ConfigSection() const = 0;

  /// The domain's own options (a mapping; unknown keys are an error naming `source`).
  virtual void ApplyYaml(const YAML::Node& node, const std::string& source) = 0;
  /// @throws secure::Error naming the field, value and rule.
  virtual void Validate() const = 0;
  virtual nlohmann::json OptionsJson() const = 0;

  /// A new environment with the domain's options.
  virtual std::unique_ptr<domains::Environment> MakeEnvironment() const = 0;
  /// The experiment's data from `data_seed` (deterministic).
  virtual DomainData GenerateData(std::uint64_t data_seed) const = 0;

  /// Checks experiment options against what is particular to the domain (none by default); called
  /// by CheckExperimentOptions, which checks first what every domain shares (shield.dt = the
  /// environment's control period). @throws secure::Error naming the field.
  virtual void CheckExperiment(const ExperimentOptions& options) const {}

  /// The experiment options this domain's experiments start from (barrier kind and trainer
  /// settings, shield, seeds and episodes), for the domain's profile.
  virtual ExperimentOptions Preset() const = 0;

  /// The barrier check (cbf/barrier_check.h) on this domain: whether it has one.
  virtual bool HasCheck() const { return false; }
  /// `count` held-out safe and near-dangerous states for the check, drawn from streams other than
  /// the training data's (deterministic for `data_seed`). Only if HasCheck().
  virtual void CheckHeldOut(std::uint64_t data_seed, long count, data::StateSet* safe,
                            data::StateSet* near_dangerous) const;
  /// The check's problem for a barrier used under `shield` with the given labelled states; the
  /// dynamics model is returned through `dynamics` (it must outlive the check). Only if
  /// HasCheck().
  virtual cbf::BarrierCheckProblem MakeCheckProblem(
      const shield::ShieldOptions& shield, const data::StateSet& safe,
      const data::StateSet& near_dangerous,
      std::unique_ptr<domains::DynamicsModel>* dynamics) const;

  /// Whether CheckLabels works (the domain can simulate forward from a labelled state).
  virtual bool HasLabelCheck() const { return false; }
  /// Checks the labels of the data from `data_seed` against the domain's physics, at most
  /// `max_states` states per row; what "the motion continues" means is the domain's (documented
  /// there). Only if HasLabelCheck(). Deterministic.
  virtual std::vector<LabelCheckRow> CheckLabels(std::uint64_t data_seed, long max_states) const;
  /// What CheckLabels simulates, in one sentence (for reports).
  virtual std::string LabelCheckDescription() const { return ""; }

  /// Whether the domain has participants for a user study (MakePopulation).
  virtual bool HasPopulation() const { return false; }
  /// The participants drawn with `options` (only if HasPopulation()). @throws secure::Error
  /// otherwise, or on invalid options.
  virtual std::unique_ptr<Population> MakePopulation(const PopulationOptions& options) const;

  /// The paper's Table 3 numbers for this domain, if the paper has a row for it (printed beside
  /// a method comparison by `secure experiment`; nothing by default).
  virtual std::optional<PaperTable3> PaperReference() const { return std::nullopt; }
  /// The paper's experiments on this domain (ExperimentKind names) that `secure reproduce` runs
  /// (experiments/reproduce.h): any of "method-comparison" (a Table 3 row; implied by
  /// PaperReference), "ablation" (Figure 9), "sensitivity" (Section 6.3) and "joint" (the joint
  /// optimisation of Section 4.1). Table 1 and the user study follow from the capabilities
  /// (ground truth, population). None by default.
  virtual std::vector<std::string> PaperExperiments() const { return {}; }

  /// How the report draws this domain's barrier and trajectories (report_hints.h), or nothing:
  /// the report then says "no picture hints".
  virtual std::optional<ReportHints> MakeReportHints() const { return std::nullopt; }

  // The ground truth (optional): an analytic barrier h*, the states to validate a learned
  // barrier on, and a sampler of labelled states (`cbf validate`, `cbf train --domain`, the
  // ground-truth study `cbf table1`, `--barrier ground-truth`).
  /// Whether the domain has a ground truth (MakeGroundTruth() is not null).
  bool HasGroundTruth() const { return MakeGroundTruth() != nullptr; }
  /// An analytic ground-truth barrier, or null if the domain has none.
  virtual std::unique_ptr<cbf::Barrier> MakeGroundTruth() const { return nullptr; }
  /// The states to validate a barrier on against the ground truth (only with a ground truth);
  /// valid while the domain lives.
  virtual std::optional<cbf::StateSource> ValidationGrid() const { return std::nullopt; }
  /// `n_safe` states with h* >= 0 and `n_unsafe` with h* < 0, drawn by the domain from its state
  /// box (deterministic for `seed`; a stream independent of a trainer's with the same seed).
  /// Only with a ground truth. @throws secure::Error otherwise, or on bad counts.
  virtual GroundTruthSample SampleGroundTruth(long n_safe, long n_unsafe,
                                              std::uint64_t seed) const;
  /// The trainer settings for a barrier learned from SampleGroundTruth's states (`cbf train
  /// --domain`, the ground-truth study); the general defaults unless the domain tuned its own.
  virtual cbf::BarrierTrainerOptions GroundTruthTrainerPreset() const { return {}; }
  /// The ground truth's parameters, recorded with a barrier trained on its samples and in the
  /// study's options (the double integrator: {"obstacle": [x, y], "radius": r, "gamma": g});
  /// each is a `task:` option of the domain of the same name.
  virtual nlohmann::json GroundTruthJson() const { return nlohmann::json::object(); }
  /// The top-level config section holding those parameters (its keys are the domain's `task:`
  /// options), also the key of their record in a model's provenance ("double_integrator"), or ""
  /// for none.
  virtual std::string GroundTruthSection() const { return ""; }
  /// The paper's numbers for the ground-truth study on this domain, if the paper has them.
  virtual std::optional<PaperGroundTruthStudy> PaperGroundTruthReference() const {
    return std::nullopt;
  }

  // The labeller (optional): a simulated person who labels states as the domain's person would
  // (active label queries: `secure cbf label`, `secure experiment label-efficiency`).
  /// Whether Label works.
  virtual bool HasLabeller() const { return false; }
  /// The label of each column of `states` (the domain's observation features): 1 safe, 0
  /// near-dangerous, -1 the person cannot say (e.g. out of the arm's reach). Deterministic for
  /// `seed` (label noise, where the person has some). Only if HasLabeller().
  virtual std::vector<int> Label(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                 std::uint64_t seed) const;
  /// Who labels and by what rule, in one sentence (for reports). Only if HasLabeller().
  virtual std::string LabellerDescription() const { return ""; }
  /// `count` unlabelled candidate states for queries (the domain's observation features),
  /// deterministic for `seed`. Default: the safe and near-dangerous states of GenerateData(seed),
  /// shuffled, the first `count` (fewer if there are fewer).
  virtual data::StateSet SampleQueryPool(long count, std::uint64_t seed) const;

  // The shield run (optional): the closed-loop check of the shield with the domain's nominal
  // policy (`secure shield run`).
  /// Whether RunShield works.
  virtual bool HasShieldRun() const { return false; }
  /// The run's values for this domain (episodes, seed, policy noise, shield). Only if
  /// HasShieldRun().
  virtual ShieldRunRequest ShieldRunPreset() const;
  /// Runs `request` with `barrier` as the shield's barrier (not evaluated unshielded).
  /// Deterministic per request.seed apart from latencies. Only if HasShieldRun(). @throws
  /// secure::Error on invalid options, or a barrier that does not take the domain's states.
  virtual ShieldRunReport RunShield(const ShieldRunRequest& request, cbf::Barrier& barrier) const;
};

/// Checks the states a labeller (Domain::Label) is given: `features.size()` rows (the domain's
/// observation features, named in the message) and finite values. @throws secure::Error, one
/// line naming `domain`, and the width or the state (column), feature and value.
void CheckLabellerStates(const std::string& domain, const Eigen::Ref<const Eigen::MatrixXf>& states,
                         const std::vector<std::string>& features);

/// Checks experiment options against `domain` before a run: first what every domain shares (the
/// shield looks ahead exactly one control period: shield.dt equals the control_period() of the
/// domain's environment, when it has a clock), then the domain's own CheckExperiment.
/// @throws secure::Error naming the field and both values.
void CheckExperimentOptions(const Domain& domain, const ExperimentOptions& options);

/// Makes a domain with its options for a profile.
using DomainFactory = std::function<std::unique_ptr<Domain>(Profile)>;

/// The registered domains, by name. Built-in domains are added by RegisterBuiltinDomains()
/// (generated from the plug-ins under domains/); programs and tests may add their own.
class DomainRegistry {
 public:
  /// The process-wide registry (built-in domains are not added automatically: call
  /// RegisterBuiltinDomains(), as the CLI does).
  static DomainRegistry& Global();

  /// Adds a domain. @throws secure::Error if the name is empty, malformed or taken.
  void Add(const std::string& name, const std::string& summary, DomainFactory factory);
  /// Adds the domain class D, made as D(profile) (a plug-in's registration:
  /// `registry.Add<MyDomain>("my-domain", "...")`). @throws secure::Error as Add above.
  template <class D>
  void Add(const std::string& name, const std::string& summary) {
    Add(name, summary, [](Profile profile) -> std::unique_ptr<Domain> {
      return std::make_unique<D>(profile);
    });
  }
  /// The domain `name` with its options for `profile`. @throws secure::Error naming `name` and
  /// listing the registered domains if there is none.
  std::unique_ptr<Domain> Make(const std::string& name, Profile profile = Profile::kFull) const;
  bool Has(const std::string& name) const;
  /// Registered names, sorted.
  std::vector<std::string> Names() const;
  /// "derby | double-integrator" for help texts and errors.
  std::string NameList() const;
  /// "  name  summary" lines, one per domain.
  std::string Summaries() const;
  /// The registered names (sorted) of the domains (quick profile) for which `offers` is true:
  /// those that offer a capability ("coffee-placing, derby" or "none"), for help texts and the
  /// error for a domain that lacks it.
  std::string ListOffering(const std::function<bool(const Domain&)>& offers) const;

 private:
  struct Entry {
    std::string name, summary;
    DomainFactory factory;
  };
  std::vector<Entry> entries_;
};

}  // namespace secure::experiments

namespace secure::plugins {
/// Adds every domain plug-in of this build to `registry` once (repeated calls do nothing);
/// generated by CMake from the folders under domains/ (cmake/SecureHelpers.cmake).
void RegisterBuiltinDomains(experiments::DomainRegistry& registry);
}  // namespace secure::plugins
