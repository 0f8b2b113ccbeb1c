#pragma once
// One seed of the experiment driver (seed_pipeline.cc, closed_loop_check.cc): the data all seeds
// share, a seed's learned barrier and its outcome, and SeedPipeline, the steps that train, check
// and evaluate them. INTERNAL: include only from secure/experiments/*.cc.
#include <algorithm>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/experiments/experiment.h"
#include "secure/experiments/internal/seed_runner.h"

namespace secure::experiments::internal {

inline bool Any(const std::vector<eval::Method>& methods, bool (*predicate)(eval::Method)) {
  return std::any_of(methods.begin(), methods.end(), predicate);
}
/// Methods that run the AIRL policy (AIRL itself and every SECURE variant).
inline bool UsesAirlPolicy(eval::Method m) {
  return !eval::UsesBcPolicy(m) && !eval::UsesJointPolicy(m);
}
inline bool NeedsBarrier(eval::Method m) { return eval::IsShielded(m) || eval::UsesJointPolicy(m); }

/// A learned barrier of either kind, with a factory of evaluators for the shields.
struct SeedBarrier {
  std::optional<cbf::CarBarrierNet> per_obstacle;
  std::optional<cbf::BarrierNet> flat;
  nlohmann::json summary;

  /// Evaluators on the domain's observations (`env`): a flat barrier that reads a subset of them
  /// (BarrierTrainerOptions::input_features) gets its rows picked by name.
  std::function<std::unique_ptr<cbf::Barrier>()> Factory(const Domain& domain,
                                                         const domains::Environment& env) const;
  void Save(const std::string& path) const;
};

/// Everything one seed produces: per variant, the method results.
struct SeedOutcome {
  std::vector<std::map<eval::Method, eval::SeedResult>> results;  // per variant
  nlohmann::json summary = nlohmann::json::object();
};

/// The data every seed shares.
struct SharedData {
  DomainData data;
  bool check = false;
  data::StateSet check_safe, check_near_dangerous;  // held-out, for the barrier check
};

/// The barrier of the experiment's kind trained with `seed` (BriefReport() in `brief`).
SeedBarrier TrainSeedBarrier(const ExperimentOptions& o, std::uint64_t seed,
                             const data::StateSet& safe, const data::StateSet& near_dangerous,
                             std::string* brief);

/// The work units of one seed, as SeedPipeline advances them: BC 1, an AIRL or joint policy one
/// per iteration, per variant a barrier 1 (its check and retraining 1), an evaluation 1.
long SeedUnits(const ExperimentOptions& o, const std::vector<eval::Method>& methods,
               const SharedData& shared, std::size_t variants);

/// The seed with index `index` (seed first_seed + index), step by step: its policies (through the
/// closed-loop check's candidates when it is enabled), then per barrier-data variant its barrier
/// (and check), the joint policy when a method needs it, and every method evaluated; models and
/// curves to output_dir/seed-K when there is one. The members are what the steps share: the
/// seed's inputs, the policies trained so far and the outcome being filled in. The steps are in
/// seed_pipeline.cc, the closed-loop check's (SelectCandidate) in closed_loop_check.cc.
class SeedPipeline {
 public:
  SeedPipeline(const Domain& domain, const ExperimentOptions& o,
               const std::vector<eval::Method>& methods, int index, const SharedData& shared,
               const domains::Environment& env, Progress& progress);

  SeedOutcome Run(const std::vector<BarrierDataVariant>& variants);

 private:
  void TrainPolicies(std::uint64_t training_seed, const std::string& files,
                     nlohmann::json& record);
  void TrainBcPolicy(std::uint64_t training_seed, const std::string& files,
                     nlohmann::json& record);
  void TrainAirlPolicy(std::uint64_t training_seed, const std::string& files,
                       nlohmann::json& record);
  // The closed-loop check with model selection (ClosedLoopCheckOptions): trains candidates (BC
  // and AIRL through TrainPolicies, the barrier on the baseline data) until one passes its
  // held-out shielded episodes, leaves the selected candidate's policies in bc_ and airl_,
  // records every candidate in summary["closed_loop"] and returns the selected barrier. Files:
  // candidate k's curves and models in <dir>/candidate-k/, the selected one's policies and
  // curves also under the usual names in <dir> (its barrier is saved by the caller).
  SeedBarrier SelectCandidate();
  std::optional<SeedBarrier> VariantBarrier(const BarrierDataVariant& variant, bool first);
  void CheckVariantBarrier(const BarrierDataVariant& variant, bool first,
                           const data::StateSet& safe, data::StateSet& near_dangerous,
                           std::string& brief, std::optional<SeedBarrier>& barrier,
                           nlohmann::json& record);
  policy::GaussianPolicy TrainJoint(const SeedBarrier& barrier);
  void Evaluate(const BarrierDataVariant& variant, bool several_variants,
                const SeedBarrier* barrier, const policy::GaussianPolicy* joint);
  nlohmann::json& timings() { return outcome_.summary["seconds"]; }

  const Domain& domain_;
  const ExperimentOptions& o_;
  const std::vector<eval::Method>& methods_;
  const SharedData& shared_;
  const domains::Environment& env_;
  Progress& progress_;
  const std::uint64_t seed_;
  const std::string tag_, dir_;
  const bool needs_airl_, needs_joint_, needs_barrier_, needs_bc_;

  std::optional<policy::GaussianPolicy> bc_, airl_;
  std::optional<policy::AirlRewardModel> airl_reward_;  // AIRL's g and V (top-q aggregation)
  // With the closed-loop check: the selected candidate's barrier (the baseline variant's) and
  // training seed (other variants' barriers too).
  std::optional<SeedBarrier> selected_barrier_;
  std::uint64_t training_seed_ = 0;
  double barrier_seconds_ = 0.0, evaluation_seconds_ = 0.0;
  SeedOutcome outcome_;
};

}  // namespace secure::experiments::internal
