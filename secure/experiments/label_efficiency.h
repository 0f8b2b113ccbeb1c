#pragma once
// How many labels SECURE needs, and which to ask for (issue 35; the paper's future work,
// Section 8): `secure experiment label-efficiency --domain NAME`, on a domain with a labeller
// (Domain::HasLabeller).
//
// Protocol, per seed and query strategy (cbf/query.h):
//   1. a pool of `pool` unlabelled candidate states (Domain::SampleQueryPool(pool, seed));
//   2. `initial_labels` pool states drawn at random and labelled by the domain's simulated person
//      (Domain::Label; more drawn, one at a time, until both classes are present) — the same
//      start for every strategy of the seed;
//   3. rounds 0 .. R: train a barrier on the labels so far (the domain's ground-truth trainer
//      preset where it has a ground truth, else the experiment preset's flat barrier trainer;
//      epochs scaled so that every training takes the preset's number of gradient steps on
//      `reference_states` states, so small label sets are not under-trained), measure it, then
//      (before round R) ask k more (k·g^r before round r with k_growth g > 1: rounds spaced
//      evenly in log(labels), as active-learning curves are drawn): the strategy's k states of
//      the still-unlabelled pool
//      (shield-relevant: of the states a shielded run with the current barrier visits, only on
//      a domain with a shield run (an error elsewhere); margin over the pool in a round whose
//      run visited fewer than k states;
//      disagreement: over `ensemble` barriers trained with different seeds on the same labels);
//      the person labels them (a -1, "cannot say", is asked but not used).
//   Measures each round: where the domain has a ground truth, Table 1's over-conservative
//   (predicted unsafe | truly safe) and under-conservative (predicted safe | truly unsafe) rates
//   on `eval_states` states of the domain's query-pool sampler from another stream (the double
//   integrator: uniform in the validation box, the grid's distribution), and at the last round on
//   the domain's validation grid (Table 1 itself); where the domain has a shield run, its
//   closed-loop dangerous and success rates over `episodes` episodes (`final_episodes` at the last
//   round), the same episodes for every strategy and round (common random numbers). A domain
//   without a ground truth but with a labeller can have the same two rates measured against the
//   labeller's answers (errors_from_labeller): the error against the person, not against physics.
//   With policies_from (a `secure experiment method-comparison --out` directory holding
//   seed-<seed>/airl.model and barrier.model for every seed), the closed loop is SECURE itself
//   instead of the domain's shield run: the run's AIRL policy of the seed under the domain
//   preset's shield over the round's barrier, on the first `episodes` (`final_episodes`) of the
//   run's own evaluation episodes (eval::EvaluationSeed(seed)); at the last round also AIRL
//   unshielded and SECURE over the run's barrier (the default's labels) on the same episodes,
//   written as `secure eval --json` documents closed-loop-<strategy>.json and
//   closed-loop-full-labels.json (`secure compare` pairs them by seed).
//   barrier_kind: the barrier trained on the labels, the trainer preset's flat MLP (`trainer`) or
//   the domain's per-obstacle barrier (`per_obstacle_trainer`, the domain preset's; Derby's
//   SECURE barrier).
//
// Each (seed, strategy) is a job on `threads` workers; results do not depend on their number.
// With output_dir every job writes seed-K/<strategy>.json atomically; a rerun into the same
// directory reuses every job file whose options equal this run's (threads and shard aside), so a
// killed run resumes and shards (`shard_index` of `shard_count`: the seeds with index = shard_index
// mod shard_count) merge by an unsharded rerun into the directory they wrote. The unsharded run
// writes result.json and curves.csv (one row per strategy, seed and round).

#include <cstdint>
#include <nlohmann/json.hpp>
#include <optional>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include "secure/cbf/barrier_trainer.h"
#include "secure/cbf/query.h"
#include "secure/cbf/validation.h"
#include "secure/cbf/car_barrier_trainer.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/experiment.h"

namespace secure::experiments {

struct LabelEfficiencyOptions {
  std::vector<cbf::QueryStrategy> strategies = {
      cbf::QueryStrategy::kRandom, cbf::QueryStrategy::kMargin, cbf::QueryStrategy::kDisagreement,
      cbf::QueryStrategy::kDiversity, cbf::QueryStrategy::kShieldRelevant};
  int seeds = 5;
  std::uint64_t first_seed = 0;
  long pool = 20000;
  long initial_labels = 20;
  int rounds = 8;
  long k = 20;
  double k_growth = 1.0;       // round r asks QueriesIn(r) = round(k · k_growth^r) states
  int ensemble = 3;            // barriers of the disagreement strategy
  double radius = 0.0;         // diversity radius of every strategy's batch but random's
  long eval_states = 200000;   // ground-truth error estimate per round (0: none)
  bool final_grid = true;      // Table 1 on the validation grid at the last round
  // Without a ground truth: over/under against the simulated person's answers on eval_states
  // states (states the person cannot say are skipped). Opt-in: it asks the labeller eval_states
  // times per seed (Derby's distance rule is cheap; Panda's physics check is not).
  bool errors_from_labeller = false;
  long episodes = 20;          // closed-loop episodes per round (0: none)
  long final_episodes = 100;   // at the last round
  long shield_pool_states = 20000;  // shield-relevant: visited states kept per round
  long shield_pool_episodes = 20;   // shield-relevant: episodes gathering them
  cbf::BarrierTrainerOptions trainer;
  BarrierKind barrier_kind = BarrierKind::kFlat;     // which barrier the labels train
  cbf::CarBarrierTrainerOptions per_obstacle_trainer;  // barrier_kind per-obstacle
  std::string policies_from;  // a method-comparison run directory: SECURE's closed loop (above)
  long reference_states = 1600;  // scale epochs to the preset's gradient steps on this many
  int max_epochs = 4000;         // cap of the scaled epochs
  int threads = 2;
  bool verbose = true;           // one stderr line per job
  int shard_index = 0, shard_count = 1;
  std::string output_dir;

  /// The domain's values for a profile (quick: 2 seeds, 3 rounds, small pool, few episodes).
  static LabelEfficiencyOptions For(const Domain& domain, Profile profile);
  /// @throws secure::Error naming the field and value.
  void Validate() const;
  /// Everything that changes a result (not threads, verbose, shard, output_dir; k_growth only
  /// where it is not 1, so that the runs of before it keep their task identity).
  nlohmann::json ToJson() const;
  /// The states asked before round `round` (0-based): round(k · k_growth^round).
  long QueriesIn(int round) const;
  /// The labels of the last round: initial_labels plus every round's queries (in double: an
  /// impossible schedule is a large number, not an overflow).
  double LabelsAtTheEnd() const;
};

struct LabelEfficiencyPoint {
  int round = 0;
  long labels = 0;                  // states asked so far (initial ones included)
  long safe_labels = 0, near_dangerous_labels = 0;
  double over = -1, under = -1;     // %, ground-truth estimate; -1 without a ground truth
  double dangerous = -1, success = -1;  // % of episodes; -1 without a shield run
  long episodes = 0;
  nlohmann::json ToJson() const;
};

struct LabelEfficiencyCurve {
  std::string strategy;
  std::uint64_t seed = 0;
  std::vector<LabelEfficiencyPoint> points;
  std::optional<cbf::Confusion> final_grid;  // Table 1 at the last round
  // With policies_from, the last round's closed loop as eval::SeedResult documents: "secure"
  // (the last barrier), "airl" and "secure_full_labels" (the run's barrier); null without.
  nlohmann::json closed_loop;
  // shield-relevant: the rounds whose shielded run visited fewer than k states, so that margin
  // over the pool asked instead (written for shield-relevant only; the table reports it).
  int margin_rounds = 0;
  double seconds = 0;
  nlohmann::json ToJson() const;
  static LabelEfficiencyCurve FromJson(const nlohmann::json& j);
};

struct LabelEfficiencyResult {
  std::string domain;
  nlohmann::json options;
  std::string labeller;
  std::vector<LabelEfficiencyCurve> curves;  // seed-major, strategies in options order
  std::optional<PaperGroundTruthStudy> paper;
  // With policies_from and at least 2 seeds, once every job is done: per strategy, then "full
  // labels", the last round's closed loop as a `secure eval --json` document.
  std::vector<std::pair<std::string, nlohmann::json>> closed_loop;
  double seconds = 0;
  /// Per strategy and round: labels, over, under (mean (std) over seeds), dangerous, success;
  /// the final grid's Table 1; labels each strategy needs to reach the paper's Table 1 errors.
  std::string Table() const;
  nlohmann::json ToJson() const;
};

/// Runs the experiment (see above). `progress` (null: none): a line naming the experiment once
/// its inputs are checked (the job files to resume, --policies-from's models), then one per job.
/// @throws secure::Error if the domain has no labeller, on invalid options, or a job file of
///   another experiment in output_dir (naming it).
LabelEfficiencyResult RunLabelEfficiency(const Domain& domain,
                                         const LabelEfficiencyOptions& options,
                                         std::ostream* progress);

}  // namespace secure::experiments
