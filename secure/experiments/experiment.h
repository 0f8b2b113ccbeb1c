#pragma once
// The experiment driver: the paper's experiments on any registered domain (domain.h).
//
//   kind                 methods (default)                     paper
//   method-comparison    bc, airl, secure                      Table 3 (Mann-Whitney U, TOST)
//   joint                airl, secure, joint                   Section 4.1's baseline
//   ablation             secure, secure-random-safe,           Figure 9 (Kruskal-Wallis + Dunn),
//                        secure-no-resampling, secure-myopic   requirement R3 of Section 4.2
//   sensitivity          secure, with barriers from reduced,   Section 6.3
//                        imbalanced and label-flipped data
//
// Protocol (every kind, every domain):
//   1. data, once, from data_seed (Domain::GenerateData): the expert's task demonstrations, the
//      safe and near-dangerous states; with the barrier check on, held-out states for it;
//   2. per seed (the seed covers all training and the evaluation): BC (a method, and the warm
//      start of AIRL and the joint policy), AIRL, then per barrier-data variant (one outside
//      `sensitivity`) the barrier (flat MLP or per-obstacle network), its check, the joint policy
//      (kind `joint`), and every method on the same `episodes` episodes (common random numbers,
//      eval::EvaluationSeed(seed));
//   3. across seeds: eval::Evaluation (one per variant).
// Only what the methods need is trained. Seeds run in parallel on `threads` workers; the results
// do not depend on the number of workers.
#include <cstdint>
#include <iosfwd>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "secure/cbf/barrier_check.h"
#include "secure/cbf/barrier_trainer.h"
#include "secure/cbf/car_barrier_trainer.h"
#include "secure/common/enum_strings.h"
#include "secure/common/progress.h"
#include "secure/data/data.h"
#include "secure/eval/policy_eval.h"
#include "secure/experiments/domain.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"
#include "secure/shield/shield.h"

namespace YAML {
class Node;
}

namespace secure::experiments {

enum class ExperimentKind { kMethodComparison, kJoint, kAblation, kSensitivity };
inline constexpr EnumTable<ExperimentKind, 4> kExperimentKindNames{{
    {ExperimentKind::kMethodComparison, "method-comparison"},
    {ExperimentKind::kJoint, "joint"},
    {ExperimentKind::kAblation, "ablation"},
    {ExperimentKind::kSensitivity, "sensitivity"},
}};

/// The methods a kind evaluates by default, in table order.
std::vector<eval::Method> DefaultMethods(ExperimentKind kind);

/// Which barrier SECURE learns: a plain MLP on the whole state (cbf::BarrierNet), or the
/// permutation-invariant per-obstacle network (cbf::CarBarrierNet: one MLP per obstacle, the
/// minimum over the obstacles in range; the released Derby architecture).
enum class BarrierKind { kPerObstacle, kFlat };
inline constexpr EnumTable<BarrierKind, 2> kBarrierKindNames{{
    {BarrierKind::kPerObstacle, "per-obstacle"},
    {BarrierKind::kFlat, "flat"},
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

/// The closed-loop check before deployment, with model selection (config section
/// `closed_loop`; every kind). Held-out accuracy cannot see a seed whose
/// shielded policy stalls or whose barrier lets dangerous events through, so each seed's SECURE
/// (its AIRL policy, barrier and shield) first runs `episodes` shielded episodes from held-out
/// starts: their own stream, ClosedLoopCheckSeed(seed), never the evaluation's. A candidate
/// passes when its success rate there is at least `min_success` and its dangerous rate at most
/// `max_dangerous`. A failing candidate is replaced by one trained from another initialisation
/// (candidate k of seed s trains BC, AIRL and the barrier with seed CandidateSeed(s, k); the data
/// are the same), up to `max_candidates` in all. Every method of the seed is then evaluated with
/// the selected candidate, on the seed's usual evaluation episodes, so comparisons stay paired
/// (the joint policy starts from its BC policy and barrier; the sensitivity study's other
/// barrier-data variants train with its training seed).
/// If no candidate passes, the best one (fewest failed criteria, then the highest success minus
/// dangerous rate) is evaluated and the seed is reported as failed: in its summary
/// ("closed_loop"), in Table() and on the progress stream; it is never used silently.
///
/// Repair (`repair_rounds` > 0): before a failing candidate is replaced, it is repaired with its
/// own counterexamples, up to `repair_rounds` times. In each held-out episode with a dangerous
/// step, the observations from which the last `repair_lookback` steps up to and including the
/// first dangerous one started join the near-dangerous states; the barrier is retrained on them
/// (the candidate's training seed; the policies stay) and the candidate is checked again on the
/// same episodes. A candidate that fails only by success (a stall) has no counterexamples and is
/// not repaired. The counterexamples are written to candidate-K/counterexamples_R.csv (episode,
/// step, the observation's features; `secure cbf train --augment-from` reads them), each
/// repaired barrier to candidate-K/barrier_repair_R.model.
struct ClosedLoopCheckOptions {
  bool enabled = false;
  long episodes = 50;           // held-out shielded episodes per candidate
  double min_success = 0.85;    // required held-out success rate
  double max_dangerous = 0.02;  // allowed held-out dangerous rate
  int max_candidates = 4;       // initialisations tried per seed (1: check and report only)
  int repair_rounds = 0;        // counterexample repairs of a failing candidate (0: none)
  int repair_lookback = 3;      // steps before (and including) a dangerous one, as counterexamples

  /// Throws secure::Error naming the field, value and rule.
  void Validate() const;
  /// Keys: enabled, episodes, min_success, max_dangerous, max_candidates, repair_rounds,
  /// repair_lookback (the last two in ToJson() only when repair_rounds > 0).
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
};

/// The training seed of candidate `candidate` (0-based) of experiment seed `seed`: the seed itself
/// for the first, seed + candidate * 2^32 after it (no other seed of an experiment uses those).
constexpr std::uint64_t CandidateSeed(std::uint64_t seed, int candidate) {
  return seed + (static_cast<std::uint64_t>(candidate) << 32);
}
/// The stream of the closed-loop check's episodes for experiment seed `seed` (every candidate of
/// the seed is checked on the same episodes), distinct from eval::EvaluationSeed's.
constexpr std::uint64_t ClosedLoopCheckSeed(std::uint64_t seed) {
  return seed ^ 0xc105ed100bc4ecULL;
}

/// Everything an experiment needs besides the domain. Domains give their defaults through
/// Domain::Preset(); a config file's section and the CLI's flags override them.
struct ExperimentOptions {
  std::uint64_t data_seed = 1000;  // the data (Domain::GenerateData)

  // Learning (each seed overrides the seeds inside these).
  BarrierKind barrier_kind = BarrierKind::kFlat;
  cbf::BarrierTrainerOptions flat_barrier;
  cbf::CarBarrierTrainerOptions per_obstacle_barrier;
  policy::BcOptions bc;
  policy::AirlOptions airl;
  bool airl_warm_start = true;    // AIRL (and the joint policy) start from the seed's BC policy
  policy::JointCbfOptions joint;  // kind `joint` only

  // Evaluation.
  shield::ShieldOptions shield;
  eval::EvaluationOptions evaluation;
  std::vector<eval::Method> methods;  // empty: DefaultMethods(kind)
  int seeds = 10;
  long episodes = 100;
  std::uint64_t first_seed = 0;  // seeds first_seed, first_seed + 1, ...

  // The pre-deployment barrier check (cbf/barrier_check.h) of every seed's barrier(s), on domains
  // that have one (Domain::HasCheck), recorded in the seed's summary ("barriers": {variant:
  // {"check": ...}}, and "check" for the first variant) and in Table(). Its own streams
  // (Domain::CheckHeldOut, check.seed); the experiment's numbers do not depend on it.
  bool check_enabled = true;
  long check_held_out = 256;  // held-out safe and near-dangerous states (each)
  cbf::BarrierCheckOptions check;
  // If a seed's barrier is flagged: add its counterexamples to the near-dangerous states, retrain
  // the barrier once (same seed), check it again, and evaluate with the retrained barrier.
  bool augment_flagged = false;
  // The closed-loop check with model selection (off by default; part of ToJson() only when on,
  // so that results without it keep their bytes).
  ClosedLoopCheckOptions closed_loop;

  // Kind `sensitivity`.
  std::vector<double> data_fractions = {1.0, 0.1, 0.01};
  std::vector<int> imbalance_ratios = {1, 2, 4, 8};
  std::vector<double> label_noise = {0.0, 0.1, 0.3, 0.5};

  int threads = 2;         // seeds trained and evaluated in parallel
  std::string output_dir;  // if set: data CSVs, per-seed models, curves and task files
                           // (seed-K/task.json), result.json
  bool verbose = true;     // progress lines on the progress stream

  // Sharding (RunExperimentShard): this process runs the seeds whose index (0-based, from
  // first_seed) is congruent to `shard` modulo `shards`. Like threads, output_dir and verbose it
  // is not part of ToJson(): the results do not depend on it.
  int shard = 0;
  int shards = 1;

  /// Throws secure::Error naming the field, value and rule.
  void Validate() const;
  /// Sections of a YAML mapping: barrier (the trainer of the current barrier_kind),
  /// flat_barrier, per_obstacle_barrier, bc, airl, joint (policy::JointCbfOptions), check
  /// (cbf::BarrierCheckOptions plus `enabled`, `held_out` and `augment`), domain (the domain's
  /// own options: Domain::ApplyYaml, when `domain` is given); unknown sections are an error
  /// naming `source`.
  void ApplyYaml(const YAML::Node& node, const std::string& source, Domain* domain = nullptr);
  nlohmann::json ToJson() const;
};

struct ExperimentResult {
  ExperimentKind kind = ExperimentKind::kMethodComparison;
  std::string domain;        // Domain::name()
  std::string domain_title;  // Domain::Title()
  nlohmann::json domain_options;
  /// (name, evaluation): one ("main") outside `sensitivity`; one per barrier-data variant there
  /// (SECURE only).
  std::vector<std::pair<std::string, eval::Evaluation>> evaluations;
  std::vector<BarrierDataVariant> variants;  // in order
  std::vector<eval::Method> methods;
  long demonstrations = 0, discarded_demonstrations = 0, demonstration_steps = 0;
  long safe_states = 0, near_dangerous_states = 0;
  std::vector<nlohmann::json> seed_summaries;  // per seed: training summaries and timings
  double data_seconds = 0.0;
  double seconds = 0.0;
  ExperimentOptions options;    // in a merged result only barrier_kind, seeds, episodes,
                                // first_seed and threads are set: the rest is in options_json
  nlohmann::json options_json;  // options.ToJson(): what ToJson() and Table() report

  /// Outside `sensitivity`: the evaluation's eval::Evaluation::ToJson() (the format of
  /// `secure eval`) plus "experiment": {kind, domain, data counts, per-seed summaries, options}.
  /// `sensitivity`: "variants": {name: {"variant": ..., evaluation JSON}} plus "experiment".
  nlohmann::json ToJson() const;
  /// Markdown: a title line, the method table(s) with the tests (sensitivity: one row per
  /// variant), then, when the barrier check ran, one row per seed.
  std::string Table() const;
  /// The per-seed barrier-check table of Table() (empty when the check did not run).
  std::string CheckTable() const;
  /// The per-seed closed-loop check of Table(): candidates tried, the selected one, its held-out
  /// rates and the verdict, and how many seeds were replaced or failed (empty when it was off).
  std::string ClosedLoopTable() const;
  /// Whether every seed's results hold their per-episode outcomes (eval::SeedResult::
  /// episode_outcomes; a seed reused from a task file written before they were recorded has none).
  bool HasEpisodeOutcomes() const;
  /// The per-episode outcomes, <output_dir>/episodes.csv: the CSV of `secure eval --episodes-out`
  /// (secure/eval/episode_table.h; seed = the training seed, episode = the index `secure render
  /// --episode` takes); kind sensitivity prefixes a column `variant`. The same bytes for a run
  /// and for the merge of its shards. @throws secure::Error if !HasEpisodeOutcomes().
  std::string EpisodesCsv() const;
};

/// The name of the per-episode outcomes file in a run directory.
constexpr const char* kEpisodesFile = "episodes.csv";

/// Writes result.EpisodesCsv() to <dir>/episodes.csv and returns "" or, when a seed has no
/// per-episode outcomes, writes nothing and returns why (for the progress stream).
std::string WriteEpisodesFile(const ExperimentResult& result, const std::string& dir);

/// Runs one experiment of `kind` on `domain`; progress lines go to `progress` when
/// options.verbose (may be null). @throws secure::Error on invalid options, or if any stage fails
/// (naming the seed and stage).
///
/// Tasks. Every seed (with all its barrier-data variants, which share the seed's BC and AIRL
/// policies) is one task. With output_dir set, a finished seed's results are written atomically
/// to output_dir/seed-K/task.json (the task file: the experiment it belongs to -- version, kind,
/// domain and its options, methods, variants, options but `threads` -- the seed, its per-method
/// results and its summary). A rerun into the same directory reuses every task file whose
/// experiment and seed match instead of recomputing the seed (so a killed run, or a killed shard,
/// resumes); a task file of another experiment is an error naming the file and the first
/// difference. options.shards must be 1.
ExperimentResult RunExperiment(ExperimentKind kind, const Domain& domain,
                               const ExperimentOptions& options, std::ostream* progress);
/// The same, with the progress on `progress` (common/progress.h): milestone lines as above (when
/// options.verbose) and, when it is live, a line counting the work units of all seeds (BC, each
/// AIRL / joint iteration, each barrier, check and evaluation), cleared before returning.
ExperimentResult RunExperimentWithProgress(ExperimentKind kind, const Domain& domain,
                                           const ExperimentOptions& options,
                                           ProgressLine& progress);

/// What one shard did: the seeds it computed and the seeds whose task files it reused.
struct ShardReport {
  std::vector<std::uint64_t> computed, reused;
  double seconds = 0.0;
};

/// Runs the tasks (seeds) of shard options.shard of options.shards (output_dir required): the
/// data (every shard generates it; only shard 0 writes the data files, since shards may share
/// output_dir), then each of the shard's seeds (index = shard mod shards), reused from its task
/// file or computed and written to it. Writes no result.json: MergeExperiment does. Shards
/// never communicate; their seed directories are disjoint.
ShardReport RunExperimentShard(ExperimentKind kind, const Domain& domain,
                               const ExperimentOptions& options, std::ostream* progress);

/// The result of an experiment from the task files its shards wrote into `run_dirs` (several
/// shard directories, or one directory all shards wrote into): checks that every task file
/// belongs to the same experiment (else an error naming the files and the first difference) and
/// that every seed is there exactly once (else an error naming the seed and files), then
/// assembles the result exactly as RunExperiment does: ToJson() and Table() equal an unsharded
/// run's but for the timing fields (`seconds`, `data_seconds`: here the largest data time of the
/// task files and the data time plus the sum of the seeds' times) and options.threads (the first
/// task file's). Writes nothing.
ExperimentResult MergeExperiment(const std::vector<std::string>& run_dirs);

}  // namespace secure::experiments
