#pragma once
// The complete SECURE pipeline on the double-integrator reach-avoid task (the toolkit's main
// job, `secure demo`): the paper's Table 3 protocol end to end.
//
//   1. data (once, from data_seed): expert task demonstrations (collisions discarded), the safe
//      states (demonstration states) and the near-dangerous states that wrap the obstacle;
//   2. per seed (the seed covers all training and the evaluation):
//        - the barrier h, learned from the safe and near-dangerous states (Eq. 4) -- not the
//          ground truth;
//        - BC on the demonstrations; AIRL (PPO generator), warm-started from BC by default;
//        - every method (bc, airl, secure, the two ablations, bc+shield) for `episodes`
//          episodes, all methods on the same start states;
//   3. across seeds: mean (std), Mann–Whitney U and TOST of SECURE against AIRL, Kruskal–Wallis
//      and Dunn across SECURE and its ablations (eval::Evaluation).
// Seeds run in parallel on `threads` workers; results do not depend on the number of workers.
//
//   experiments::PipelineOptions options;          // the defaults: 10 seeds x 100 episodes
//   experiments::PipelineResult r = experiments::RunDoubleIntegratorPipeline(options, &std::cerr);
//   std::cout << r.evaluation.Table();
#include <cstdint>
#include <iosfwd>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/cbf/barrier_trainer.h"
#include "domains/double_integrator/expert.h"
#include "domains/double_integrator/reach_avoid.h"
#include "secure/eval/policy_eval.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"
#include "secure/shield/shield.h"

namespace YAML {
class Node;
}

namespace secure::experiments {

struct PipelineOptions {
  // The task, the expert and the data (generated once, from data_seed).
  domains::double_integrator::ReachAvoidOptions task;
  domains::double_integrator::ExpertOptions expert;
  domains::double_integrator::DemonstrationOptions demonstrations;
  domains::double_integrator::NearDangerousOptions near_dangerous;
  long safe_states = 20000;  // demonstration states (up to the goal) used as the safe class;
                             // at random if there are more (100 demonstrations hold ~11,000)
  int slowed_copies = 1;     // safe-state augmentation (di::WithSlowedCopies)
  std::uint64_t data_seed = 1000;

  // Learning (each seed overrides the seeds inside these).
  cbf::BarrierTrainerOptions barrier;
  policy::BcOptions bc;
  policy::AirlOptions airl;
  bool airl_warm_start = true;  // initialise AIRL's policy from the seed's BC policy

  // Evaluation.
  shield::ShieldOptions shield;
  std::vector<eval::Method> methods = eval::AllMethods();
  eval::EvaluationOptions evaluation;
  int seeds = 10;
  long episodes = 100;
  std::uint64_t first_seed = 0;  // seeds first_seed, first_seed + 1, ...

  int threads = 2;          // seeds trained and evaluated in parallel
  std::string output_dir;   // if set: data CSVs, per-seed models and curves, result.json
  bool verbose = true;      // progress lines on the progress stream

  /// The defaults (the full protocol; about 5 minutes on 2 cores).
  static PipelineOptions Default();
  /// A small profile for tests and smoke runs (2 seeds x 20 episodes, short training).
  static PipelineOptions Quick();

  /// Throws secure::Error naming the field, value and rule.
  void Validate() const;
  /// Sections of a YAML mapping: barrier, bc, airl (the trainers' keys); unknown sections are
  /// an error naming `source`.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
  nlohmann::json ToJson() const;
};

struct PipelineSeedTimings {
  double barrier_seconds = 0.0;
  double bc_seconds = 0.0;
  double airl_seconds = 0.0;
  double evaluation_seconds = 0.0;
};

struct PipelineResult {
  eval::Evaluation evaluation;
  long demonstrations = 0;              // kept expert episodes
  long discarded_demonstrations = 0;    // collided or never reached the goal
  long safe_states = 0, near_dangerous_states = 0;
  std::vector<nlohmann::json> barrier_summaries;  // per seed
  std::vector<nlohmann::json> policy_summaries;   // per seed: {"bc": ..., "airl": ...}
  std::vector<PipelineSeedTimings> timings;       // per seed
  double seconds = 0.0;
  PipelineOptions options;

  /// evaluation.ToJson() plus "pipeline": {data counts, per-seed training summaries, timings,
  /// options}.
  nlohmann::json ToJson() const;
};

/// Runs the pipeline; progress lines go to `progress` when options.verbose (may be null).
/// @throws secure::Error on invalid options, or if any stage fails (naming the seed and stage).
PipelineResult RunDoubleIntegratorPipeline(const PipelineOptions& options, std::ostream* progress);

}  // namespace secure::experiments
