#pragma once
// The Demolition Derby experiments of the paper (Section 6, Figure 9, Section 6.3, and the
// joint-optimisation baseline of Section 4.1), one command each (`secure experiment <name>`):
//
//   derby-table3       BC, AIRL and SECURE (the Table 3 row): mean (std) over seeds, Mann–Whitney
//                      U and TOST of SECURE against AIRL
//   derby-joint        the joint-optimisation baseline (AIRL whose PPO loss also carries the
//                      barrier's derivative condition, unshielded) next to AIRL and SECURE
//   derby-ablation     SECURE, its two ablations (random safe action; no adaptive resampling;
//                      Kruskal–Wallis + Dunn across the three) and the myopic shield test
//                      h(T(s, a)) >= 0 (alpha dt = 1, requirement R3 of Section 4.2)
//   derby-sensitivity  SECURE with barriers learned from reduced data (100 %, 10 %, 1 %),
//                      imbalanced data (safe : near-dangerous 1:1, 1:2, 1:4, 1:8) and flipped
//                      labels (0, 10, 30, 50 %)
//
// Protocol (shared by all four):
//   1. data, once, from data_seed: expert demonstrations (privileged expert, collisions
//      discarded), `safe_states` demonstration observations and `near_dangerous.count`
//      near-dangerous observations (official-code-facts.md §1.7; paper Table 2: 1024 + 1024);
//   2. per seed (the seed covers all training and the evaluation): the barrier(s), BC, AIRL
//      warm-started from BC (with the BC regulariser, airl.bc_weight = 1), and for derby-joint
//      the joint policy; then every method of the experiment on the same `episodes` episodes
//      (common random numbers);
//   3. across seeds: eval::Evaluation (one per sensitivity configuration).
// Seeds run in parallel on `threads` workers; results do not depend on the number of workers.
#include <cstdint>
#include <iosfwd>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "secure/cbf/barrier_check.h"
#include "secure/cbf/barrier_trainer.h"
#include "secure/cbf/car_barrier_trainer.h"
#include "secure/common/enum_strings.h"
#include "domains/derby/derby.h"
#include "domains/derby/expert.h"
#include "secure/eval/policy_eval.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"
#include "secure/shield/shield.h"

namespace YAML {
class Node;
}

namespace secure::experiments {

enum class DerbyExperiment { kTable3, kJoint, kAblation, kSensitivity };
inline constexpr EnumTable<DerbyExperiment, 4> kDerbyExperimentNames{{
    {DerbyExperiment::kTable3, "derby-table3"},
    {DerbyExperiment::kJoint, "derby-joint"},
    {DerbyExperiment::kAblation, "derby-ablation"},
    {DerbyExperiment::kSensitivity, "derby-sensitivity"},
}};

/// Which barrier SECURE learns: the permutation-invariant per-car network (cbf::CarBarrierNet,
/// the released architecture) or a plain MLP on the flat 52-number observation (cbf::BarrierNet).
enum class DerbyBarrierKind { kPerCar, kFlat };
inline constexpr EnumTable<DerbyBarrierKind, 2> kDerbyBarrierKindNames{{
    {DerbyBarrierKind::kPerCar, "per-car"},
    {DerbyBarrierKind::kFlat, "flat"},
}};

/// One barrier-data variant of the sensitivity study (Section 6.3).
struct BarrierDataVariant {
  std::string name;            // "data 10%", "imbalance 1:4", "label noise 30%"; the unmodified
                               // data is "baseline"
  double data_fraction = 1.0;  // keep this fraction of both classes (their ratio preserved)
  int imbalance = 1;           // keep 1/imbalance of the near-dangerous states (safe : nd = 1:k)
  double label_noise = 0.0;    // move this fraction of each class into the other class

  nlohmann::json ToJson() const;
};

/// The baseline and the variants of the sensitivity study, in table order.
std::vector<BarrierDataVariant> SensitivityVariants(const std::vector<double>& data_fractions,
                                                    const std::vector<int>& imbalance_ratios,
                                                    const std::vector<double>& label_noise);

/// Applies `variant` to the barrier data (deterministic for `seed`; the subsets and flipped
/// states are drawn at random). @throws secure::Error if a class would become empty.
void ApplyBarrierDataVariant(const BarrierDataVariant& variant, std::uint64_t seed,
                             data::StateSet* safe, data::StateSet* near_dangerous);

struct DerbyExperimentOptions {
  // The task, the expert and the data (generated once, from data_seed).
  domains::derby::DerbyOptions task;
  domains::derby::DerbyExpertOptions expert;
  domains::derby::DerbyDemonstrationOptions demonstrations;
  domains::derby::DerbyNearDangerousOptions near_dangerous;
  long safe_states = 1024;  // demonstration observations used as the safe class (Table 2)
  std::uint64_t data_seed = 2000;

  // Learning (each seed overrides the seeds inside these).
  DerbyBarrierKind barrier_kind = DerbyBarrierKind::kPerCar;
  cbf::CarBarrierTrainerOptions car_barrier;
  cbf::BarrierTrainerOptions flat_barrier;
  policy::BcOptions bc;
  policy::AirlOptions airl;
  bool airl_warm_start = true;    // AIRL (and the joint policy) start from the seed's BC policy
  policy::JointCbfOptions joint;  // derby-joint only

  // Evaluation.
  shield::ShieldOptions shield;
  eval::EvaluationOptions evaluation;
  int seeds = 10;
  long episodes = 100;
  std::uint64_t first_seed = 0;  // seeds first_seed, first_seed + 1, ...

  // The pre-deployment barrier check (cbf/barrier_check.h) of every seed's barrier(s), recorded
  // in the seed's summary ("barriers": {variant: {"check": ...}}, and "check" for the first
  // variant) and in Table(). Its own streams: held-out states from the demonstrations with an Rng
  // seeded data_seed ^ 0xc4ec4da7a, the search from check.seed; the experiment's numbers do not
  // depend on it.
  bool check_enabled = true;
  long check_held_out = 256;  // held-out safe and near-dangerous states (each) for the check
  cbf::BarrierCheckOptions check = DerbyCheckDefaults();
  // If a seed's barrier is flagged: add its counterexamples (the check's worst examples, all
  // kinds) to the near-dangerous states, retrain the barrier once (same seed), check it again,
  // and evaluate SECURE with the retrained barrier. Off by default (it changes the numbers of
  // the flagged seeds).
  bool augment_flagged = false;

  // derby-sensitivity.
  std::vector<double> data_fractions = {1.0, 0.1, 0.01};
  std::vector<int> imbalance_ratios = {1, 2, 4, 8};
  std::vector<double> label_noise = {0.0, 0.1, 0.3, 0.5};

  int threads = 2;         // seeds trained and evaluated in parallel
  std::string output_dir;  // if set: data CSVs, per-seed models, result.json
  bool verbose = true;     // progress lines on the progress stream

  /// The check's Derby defaults: cbf::BarrierCheckOptions with 2000 region and 2000
  /// near-dangerous samples (about 1 s per per-car barrier).
  static cbf::BarrierCheckOptions DerbyCheckDefaults();
  /// The defaults (the full protocol).
  static DerbyExperimentOptions Default();
  /// A small profile for tests and smoke runs (2 seeds x 10 episodes, short training).
  static DerbyExperimentOptions Quick();

  /// Throws secure::Error naming the field, value and rule.
  void Validate() const;
  /// Sections of a YAML mapping: barrier (per-car trainer), flat_barrier, bc, airl, joint
  /// (policy::JointCbfOptions, e.g. `joint: {weight: 10}`), check (cbf::BarrierCheckOptions
  /// plus `enabled`, `held_out` and `augment` for the three fields above); unknown sections are
  /// an error naming `source`.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
};

/// The barrier check's inputs on Demolition Derby (the domain glue of cbf::CheckBarrier):
///  - dynamics: the shield's model, DerbyShieldModel(task.dt, task.accel_bound,
///    task.lookahead_steps); action box [-accel_bound, accel_bound]^2; dt, class-K and gain from
///    `shield`;
///  - region: a state of `safe` or of `near_dangerous` (each with probability 1/2), perturbed:
///    ego velocity + N(0, 0.1^2) per axis, every observed car's relative position + N(0, 0.03^2)
///    and relative velocity + N(0, 0.05^2) per axis (the goal offset unchanged);
///  - unsafe test (c): some observed car within task.collision_radius of the ego (the 12
///    observed cars; the observation has no others);
///  - (b) and the held-out accuracy: `near_dangerous` and `safe`.
/// `safe` and `near_dangerous` must be observations (kObservationDim rows); the returned problem
/// keeps copies. The dynamics model is returned through `dynamics` (it must outlive the check).
cbf::BarrierCheckProblem MakeDerbyCheckProblem(const domains::derby::DerbyOptions& task,
                                               const shield::ShieldOptions& shield,
                                               const data::StateSet& safe,
                                               const data::StateSet& near_dangerous,
                                               std::unique_ptr<domains::DynamicsModel>* dynamics);

/// The held-out states of the experiment's barrier check: `check_held_out` safe states
/// (demonstration observations) and near-dangerous states (the domain's generator), drawn from
/// the demonstrations of data_seed with an Rng seeded data_seed ^ 0xc4ec4da7a (so they differ
/// from the training states, drawn from data_seed + 1). The second form regenerates the
/// demonstrations first (0.3 s for 1000), so a CLI run reproduces the experiment's check.
void DerbyCheckHeldOut(const DerbyExperimentOptions& o,
                       const domains::derby::DerbyDemonstrations& demonstrations,
                       data::StateSet* safe, data::StateSet* near_dangerous);
void DerbyCheckHeldOut(const DerbyExperimentOptions& o, data::StateSet* safe,
                       data::StateSet* near_dangerous);

/// The methods an experiment evaluates, in table order.
std::vector<eval::Method> DerbyMethods(DerbyExperiment experiment);

struct DerbyExperimentResult {
  DerbyExperiment experiment = DerbyExperiment::kTable3;
  /// (name, evaluation): one ("main") for table3/joint/ablation; one per barrier-data variant for
  /// derby-sensitivity (SecureMethod only).
  std::vector<std::pair<std::string, eval::Evaluation>> evaluations;
  std::vector<BarrierDataVariant> variants;  // derby-sensitivity: the variants, in order
  long demonstrations = 0, discarded_demonstrations = 0, demonstration_steps = 0;
  long safe_states = 0, near_dangerous_states = 0;
  std::vector<nlohmann::json> seed_summaries;  // per seed: training summaries and timings
  double data_seconds = 0.0;
  double seconds = 0.0;
  DerbyExperimentOptions options;

  /// One evaluation: its eval::Evaluation::ToJson() (the format of `secure eval`) plus
  /// "experiment": {name, data counts, per-seed summaries, options}. Sensitivity: "variants":
  /// {name: {"variant": ..., evaluation JSON}} plus "experiment".
  nlohmann::json ToJson() const;
  /// Markdown: the method table(s) with the tests (sensitivity: one row per variant), then, when
  /// the barrier check ran, one row per seed: its verdict, rates and SECURE's dangerous rate.
  std::string Table() const;
  /// The per-seed barrier-check table of Table() (empty when the check did not run).
  std::string CheckTable() const;
};

/// Runs one experiment; progress lines go to `progress` when options.verbose (may be null).
/// @throws secure::Error on invalid options, or if any stage fails (naming the seed and stage).
DerbyExperimentResult RunDerbyExperiment(DerbyExperiment experiment,
                                         const DerbyExperimentOptions& options,
                                         std::ostream* progress);

}  // namespace secure::experiments
