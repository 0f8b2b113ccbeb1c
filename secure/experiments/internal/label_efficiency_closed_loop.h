#pragma once
// The closed loop of `secure experiment label-efficiency --policies-from RUN`
// (label_efficiency.h): SECURE as the method comparison runs it -- a trained run's AIRL policy of
// the seed under the domain preset's shield -- with the barrier learned from the labels so far,
// on the run's own evaluation episodes; and, on the same episodes, AIRL unshielded and SECURE over
// the run's barrier (the default's labels). INTERNAL: include only from secure/experiments/*.cc.
#include <cstdint>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "secure/eval/policy_eval.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/internal/seed_pipeline.h"
#include "secure/experiments/label_efficiency.h"
#include "secure/policy/airl_reward.h"
#include "secure/policy/gaussian_policy.h"

namespace secure::experiments::internal {

/// An evaluator of a label-efficiency barrier on states whose rows are `features` (`source`
/// names them in errors): a flat barrier picks its rows by name; a per-obstacle barrier needs
/// exactly its features.
std::unique_ptr<cbf::Barrier> BarrierOn(const SeedBarrier& barrier,
                                        const std::vector<std::string>& features,
                                        const std::string& source);

/// One seed's models from a run directory of `secure experiment --out` (method comparison):
/// seed-<seed>/airl.model, seed-<seed>/barrier.model and, when the preset's shield aggregates
/// top-q, seed-<seed>/airl_reward.model.
class RunPolicyLoop {
 public:
  /// @throws secure::Error naming the file when one is missing, malformed, or not of the
  ///   domain's features.
  RunPolicyLoop(const Domain& domain, const std::string& run_dir, std::uint64_t seed);
  RunPolicyLoop(const RunPolicyLoop&) = delete;
  RunPolicyLoop& operator=(const RunPolicyLoop&) = delete;

  /// The first `episodes` episodes of the run's evaluation (eval::EvaluationSeed(seed), the
  /// episodes its result.json reports): SECURE over `barrier`, AIRL unshielded, SECURE over the
  /// run's barrier.
  eval::SeedResult Secure(const SeedBarrier& barrier, long episodes) const;
  eval::SeedResult Airl(long episodes) const;
  eval::SeedResult SecureFullLabels(long episodes) const;

 private:
  eval::SeedResult Run(eval::Method method, const SeedBarrier* barrier, long episodes) const;

  const Domain& domain_;
  std::uint64_t seed_;
  shield::ShieldOptions shield_;
  policy::GaussianPolicy airl_;
  std::optional<policy::AirlRewardModel> airl_reward_;
  SeedBarrier run_barrier_;
};

/// A `secure eval --json` document (`secure compare` reads it) of the last round's closed loop
/// over seeds: methods airl and secure, where secure is `secure_key` ("secure": the strategy's
/// last barrier; "secure_full_labels": the run's) of each curve's closed_loop, in seed order.
nlohmann::json ClosedLoopEvalJson(const std::string& domain, std::uint64_t first_seed,
                                  const std::vector<const nlohmann::json*>& closed_loops,
                                  const std::string& secure_key, long episodes,
                                  const nlohmann::json& shield, const std::string& run_dir,
                                  const std::string& barrier);

/// Per strategy (in options order), then "full-labels": ClosedLoopEvalJson over the seeds of
/// `curves` (every curve must have its closed_loop).
std::vector<std::pair<std::string, nlohmann::json>> ClosedLoopEvaluations(
    const std::vector<LabelEfficiencyCurve>& curves, const Domain& domain,
    const LabelEfficiencyOptions& options);

/// The last round's closed loop in Markdown: per document SECURE's and AIRL's success and
/// dangerous rates (mean (std) over seeds, %) and the TOST of SECURE's success against AIRL's.
std::string ClosedLoopTable(const std::vector<std::pair<std::string, nlohmann::json>>& docs);

}  // namespace secure::experiments::internal
