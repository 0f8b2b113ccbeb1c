// The closed loop of `secure experiment label-efficiency --policies-from RUN`
// (internal/label_efficiency_closed_loop.h).
#include "secure/experiments/internal/label_efficiency_closed_loop.h"

#include <cstdio>
#include <filesystem>
#include <sstream>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/enum_strings.h"
#include "secure/common/error.h"
#include "secure/experiments/internal/task_store.h"
#include "secure/nn/model_file.h"

namespace secure::experiments::internal {
namespace {

std::string ModelPath(const std::string& run_dir, std::uint64_t seed, const char* name) {
  const std::string path = SeedDir(run_dir, seed) + "/" + name + ".model";
  SECURE_CHECK(std::filesystem::is_regular_file(path),
               "label-efficiency --policies-from " << run_dir << ": no " << path
                                                   << " (a run of `secure experiment "
                                                      "method-comparison --out` with this seed)");
  return path;
}

}  // namespace

std::unique_ptr<cbf::Barrier> BarrierOn(const SeedBarrier& barrier,
                                        const std::vector<std::string>& features,
                                        const std::string& source) {
  if (barrier.per_obstacle) {
    barrier.per_obstacle->CheckFeatures(features, source, "the per-obstacle barrier");
    return barrier.per_obstacle->MakeEvaluator(4096);
  }
  SECURE_CHECK(barrier.flat.has_value(), "label-efficiency: a barrier of neither kind");
  return barrier.flat->MakeEvaluatorFor(features, source);
}

RunPolicyLoop::RunPolicyLoop(const Domain& domain, const std::string& run_dir, std::uint64_t seed)
    : domain_(domain), seed_(seed), shield_(domain.Preset().shield),
      airl_(policy::GaussianPolicy::Load(ModelPath(run_dir, seed, "airl"))) {
  const std::unique_ptr<domains::Environment> env = domain.MakeEnvironment();
  SECURE_CHECK(airl_.observation_features == env->ObservationFeatures() &&
                   airl_.action_features == env->ActionFeatures(),
               ModelPath(run_dir, seed, "airl") << ": the policy's features do not match the "
                                                << domain.name() << " domain's");
  if (shield_.aggregation == shield::Aggregation::kTopQ) {
    const std::string path = ModelPath(run_dir, seed, "airl_reward");
    airl_reward_ = policy::AirlRewardModel::Load(path);
    SECURE_CHECK(airl_reward_->observation_features == env->ObservationFeatures(),
                 path << ": the reward model's features do not match the " << domain.name()
                      << " domain's");
  }
  const std::string barrier = ModelPath(run_dir, seed, "barrier");
  if (nn::ReadModelFile(barrier).kind == cbf::kCarBarrierModelKind)
    run_barrier_.per_obstacle = cbf::CarBarrierNet::Load(barrier);
  else
    run_barrier_.flat = cbf::BarrierNet::Load(barrier);
  BarrierOn(run_barrier_, env->ObservationFeatures(), barrier);  // fails here on a mismatch
}

eval::SeedResult RunPolicyLoop::Run(eval::Method method, const SeedBarrier* barrier,
                                    long episodes) const {
  const std::unique_ptr<domains::Environment> env = domain_.MakeEnvironment();
  eval::SeedModels models;
  models.airl = &airl_;
  models.airl_reward = airl_reward_ ? &*airl_reward_ : nullptr;
  if (barrier != nullptr) models.make_barrier = barrier->Factory(domain_, *env);
  eval::EpisodeRunner runner(*env);
  return eval::RunMethod(runner, method, models, shield_, episodes,
                         eval::EvaluationSeed(seed_));
}

eval::SeedResult RunPolicyLoop::Secure(const SeedBarrier& barrier, long episodes) const {
  return Run(eval::Method::kSecure, &barrier, episodes);
}
eval::SeedResult RunPolicyLoop::Airl(long episodes) const {
  return Run(eval::Method::kAirl, nullptr, episodes);
}
eval::SeedResult RunPolicyLoop::SecureFullLabels(long episodes) const {
  return Run(eval::Method::kSecure, &run_barrier_, episodes);
}

nlohmann::json ClosedLoopEvalJson(const std::string& domain, std::uint64_t first_seed,
                                  const std::vector<const nlohmann::json*>& closed_loops,
                                  const std::string& secure_key, long episodes,
                                  const nlohmann::json& shield, const std::string& run_dir,
                                  const std::string& barrier) {
  eval::Evaluation evaluation;
  for (const nlohmann::json* c : closed_loops) {
    evaluation.Add(eval::Method::kAirl, SeedResultFromJson(c->at("airl")));
    evaluation.Add(eval::Method::kSecure, SeedResultFromJson(c->at(secure_key)));
  }
  evaluation.Finish();
  nlohmann::json r = evaluation.ToJson();
  r["command"] = "eval";
  r["domain"] = domain;
  r["run"] = run_dir;
  r["models"] = {{"airl", run_dir + "/seed-<k>/airl.model"}, {"barrier", barrier}};
  r["first_seed"] = first_seed;
  r["seeds_evaluated"] = closed_loops.size();
  r["episodes"] = episodes;
  r["shield"] = shield;
  return r;
}

std::vector<std::pair<std::string, nlohmann::json>> ClosedLoopEvaluations(
    const std::vector<LabelEfficiencyCurve>& curves, const Domain& domain,
    const LabelEfficiencyOptions& options) {
  const nlohmann::json shield = domain.Preset().shield.ToJson();
  const auto over_seeds = [&](const std::string& strategy) {
    std::vector<const nlohmann::json*> loops;
    for (const LabelEfficiencyCurve& c : curves)
      if (c.strategy == strategy) {
        SECURE_CHECK(c.closed_loop.is_object(), "label-efficiency: seed "
                                                    << c.seed << ", " << strategy
                                                    << ": no closed loop at the last round");
        loops.push_back(&c.closed_loop);
      }
    return loops;
  };
  std::vector<std::pair<std::string, nlohmann::json>> out;
  std::string first;
  for (cbf::QueryStrategy s : options.strategies) {
    const std::string name = ToString(cbf::kQueryStrategyNames, s);
    if (first.empty()) first = name;
    out.emplace_back(name, ClosedLoopEvalJson(domain.name(), options.first_seed, over_seeds(name),
                                              "secure", options.final_episodes, shield,
                                              options.policies_from,
                                              "label-efficiency " + name + ", last round"));
  }
  out.emplace_back("full-labels",
                   ClosedLoopEvalJson(domain.name(), options.first_seed, over_seeds(first),
                                      "secure_full_labels", options.final_episodes, shield,
                                      options.policies_from,
                                      options.policies_from + "/seed-<k>/barrier.model"));
  return out;
}

std::string ClosedLoopTable(const std::vector<std::pair<std::string, nlohmann::json>>& docs) {
  std::ostringstream out;
  const auto rate = [](const nlohmann::json& doc, const char* method, const char* metric) {
    const nlohmann::json& r = doc.at("methods").at(method).at(metric);
    char buf[48];
    std::snprintf(buf, sizeof buf, "%.1f (%.1f)", 100 * r.at("mean").get<double>(),
                  100 * r.at("std").get<double>());
    return std::string(buf);
  };
  out << "Closed loop at the last round: SECURE (the run's AIRL policies, shielded) and AIRL on the "
         "same episodes, mean (std) over seeds, %; TOST of SECURE's success against AIRL's\n\n"
      << "| barrier | SECURE success | SECURE dangerous | AIRL success | AIRL dangerous | TOST p "
         "(bound) |\n|---|---:|---:|---:|---:|---:|\n";
  for (const auto& [name, doc] : docs) {
    const nlohmann::json& tost = doc.at("comparisons").at("secure_vs_airl").at("success_tost");
    char p[48];
    std::snprintf(p, sizeof p, "%.3g (%.0f points)", tost.at("p_value").get<double>(),
                  100 * tost.at("bound").get<double>());
    out << "| " << name << " | " << rate(doc, "secure", "success_rate") << " | "
        << rate(doc, "secure", "dangerous_rate") << " | " << rate(doc, "airl", "success_rate")
        << " | " << rate(doc, "airl", "dangerous_rate") << " | " << p << " |\n";
  }
  return out.str();
}

}  // namespace secure::experiments::internal
