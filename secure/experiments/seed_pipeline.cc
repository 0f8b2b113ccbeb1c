// One seed of the experiment driver (internal/seed_pipeline.h): its policies, per barrier-data
// variant its barrier and the barrier's pre-deployment check, the joint policy and the evaluation
// of every method. The closed-loop check's model selection is in closed_loop_check.cc.
#include "secure/experiments/internal/seed_pipeline.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <ostream>
#include <string>
#include <utility>

#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/timer.h"

namespace secure::experiments::internal {
namespace {

// A trainer's options for one seed's run: `options` with `seed`, quiet.
template <typename Options>
Options SeedRun(Options options, std::uint64_t seed) {
  options.seed = seed;
  options.verbose = false;
  return options;
}
// ... and (with a directory) the policy trainer's learning curve in `dir`/`curve`.
template <typename Options>
Options SeedRun(Options options, std::uint64_t seed, const std::string& dir,
                const std::string& curve) {
  options = SeedRun(std::move(options), seed);
  if (!dir.empty()) options.curve_path = dir + "/" + curve;
  return options;
}

// "prefix.ext" for the baseline variant, "prefix_<name>.ext" (name made file-safe) otherwise.
std::string VariantFile(const std::string& prefix, const BarrierDataVariant& variant,
                        const std::string& ext) {
  if (variant.name == "baseline") return prefix + ext;
  std::string name = variant.name;
  for (char& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return prefix + "_" + name + ext;
}

// The barrier check of one seed's barrier.
cbf::CheckReport CheckSeedBarrier(const Domain& domain, const ExperimentOptions& o,
                                  const SharedData& shared,
                                  const std::function<std::unique_ptr<cbf::Barrier>()>& factory) {
  std::unique_ptr<domains::DynamicsModel> dynamics;
  const cbf::BarrierCheckProblem problem = domain.MakeCheckProblem(
      o.shield, shared.check_safe, shared.check_near_dangerous, &dynamics);
  const std::unique_ptr<cbf::Barrier> barrier = factory();
  return cbf::CheckBarrier(*barrier, *dynamics, problem, o.check);
}

std::string CheckBrief(const cbf::CheckReport& r) {
  char line[256];
  std::snprintf(line, sizeof line, "%s (a %.3f, b %.3f, c %.3f; held-out accuracy %.3f / %.3f)",
                r.Verdict().c_str(), r.no_safe_action.rate(), r.near_dangerous.rate(),
                r.unsafe.rate(), r.accuracy_safe, r.accuracy_near_dangerous);
  return line;
}

}  // namespace

SeedPipeline::SeedPipeline(const Domain& domain, const ExperimentOptions& o,
                           const std::vector<eval::Method>& methods, int index,
                           const SharedData& shared, const domains::Environment& env,
                           Progress& progress)
    : domain_(domain),
      o_(o),
      methods_(methods),
      shared_(shared),
      env_(env),
      progress_(progress),
      seed_(o.first_seed + static_cast<std::uint64_t>(index)),
      tag_("[seed " + std::to_string(seed_) + "]"),
      dir_(o.output_dir.empty() ? "" : o.output_dir + "/seed-" + std::to_string(seed_)),
      needs_airl_(Any(methods, UsesAirlPolicy)),
      needs_joint_(Any(methods, eval::UsesJointPolicy)),
      needs_barrier_(Any(methods, NeedsBarrier)),
      // BC is a method, and the warm start of AIRL and the joint policy.
      needs_bc_(Any(methods, eval::UsesBcPolicy) ||
                ((needs_airl_ || needs_joint_) && o.airl_warm_start)) {}

SeedOutcome SeedPipeline::Run(const std::vector<BarrierDataVariant>& variants) {
  CreateDirectories(dir_);
  timings() = nlohmann::json::object();

  // With the closed-loop check: candidates until one passes (their files in candidate-K/), the
  // selected one's models and curves also under the usual names. Without it: the seed's own.
  training_seed_ = seed_;
  if (o_.closed_loop.enabled) {
    selected_barrier_ = SelectCandidate();
    training_seed_ =
        CandidateSeed(seed_, outcome_.summary["closed_loop"]["selected"].get<int>());
  } else {
    TrainPolicies(seed_, dir_, outcome_.summary);
  }

  // One barrier per data variant (only the baseline outside `sensitivity`), each followed by its
  // evaluation.
  outcome_.summary["barriers"] = nlohmann::json::object();
  for (const BarrierDataVariant& variant : variants) {
    const bool first = &variant == &variants.front();
    std::optional<SeedBarrier> barrier;
    if (needs_barrier_) barrier = VariantBarrier(variant, first);
    // The joint policy needs the (baseline) barrier.
    std::optional<policy::GaussianPolicy> joint;
    if (needs_joint_) {
      SECURE_INTERNAL_CHECK(barrier.has_value(), "the joint method trains a barrier");
      joint = TrainJoint(*barrier);
    }
    Evaluate(variant, variants.size() > 1, barrier ? &*barrier : nullptr,
             joint ? &*joint : nullptr);
  }
  timings()["barriers"] = barrier_seconds_;
  timings()["evaluation"] = evaluation_seconds_;
  return std::move(outcome_);
}

// BC then AIRL for one training seed; `files` is the directory of their curves and models ("":
// none).
void SeedPipeline::TrainPolicies(std::uint64_t training_seed, const std::string& files,
                                 nlohmann::json& record) {
  bc_.reset();
  airl_.reset();
  airl_reward_.reset();
  if (needs_bc_) TrainBcPolicy(training_seed, files, record);
  if (needs_airl_) TrainAirlPolicy(training_seed, files, record);
}

void SeedPipeline::TrainBcPolicy(std::uint64_t training_seed, const std::string& files,
                                 nlohmann::json& record) {
  const Stopwatch clock;
  const policy::BcOptions options = SeedRun(o_.bc, training_seed, files, "bc_curve.csv");
  policy::BcSummary summary;
  bc_ = policy::TrainBc(options, shared_.data.demonstrations, &summary);
  record["bc"] = summary.ToJson();
  timings()["bc"] = timings().value("bc", 0.0) + clock.Seconds();
  if (!files.empty()) bc_->Save(files + "/bc.model");
  progress_.Line([&](std::ostream& out) { out << tag_ << " " << summary.BriefReport(); });
  progress_.Advance();
}

void SeedPipeline::TrainAirlPolicy(std::uint64_t training_seed, const std::string& files,
                                   nlohmann::json& record) {
  const Stopwatch clock;
  const policy::AirlOptions options = SeedRun(o_.airl, training_seed, files, "airl_curve.csv");
  policy::AirlSummary summary;
  const int report_every = std::max(1, options.iterations / 4);
  long counted = 0;
  airl_ = policy::TrainAirl(
      options, shared_.data.demonstrations, env_, o_.airl_warm_start ? &*bc_ : nullptr, &summary,
      [&](const policy::AirlIterationStats& stats) {
        ++counted;
        progress_.Advance();
        if (stats.iteration % report_every == 0) {
          progress_.Line([&](std::ostream& out) {
            out << tag_ << " AIRL iteration " << stats.iteration << "/" << options.iterations
                << ": rollout success " << stats.success_rate << ", collisions "
                << stats.collision_rate << " (" << clock.Seconds() << " s)";
          });
        }
        return true;
      },
      &airl_reward_.emplace());
  progress_.Advance(options.iterations - counted);  // the units of a run stopped early
  record["airl"] = summary.ToJson();
  timings()["airl"] = timings().value("airl", 0.0) + clock.Seconds();
  if (!files.empty()) {
    airl_->Save(files + "/airl.model");
    airl_reward_->Save(files + "/airl_reward.model");
  }
  progress_.Line([&](std::ostream& out) { out << tag_ << " " << summary.BriefReport(); });
}

// The variant's barrier (the closed-loop check's selected one for the baseline), recorded in
// summary["barriers"][variant], then its pre-deployment check.
std::optional<SeedBarrier> SeedPipeline::VariantBarrier(const BarrierDataVariant& variant,
                                                        bool first) {
  const Stopwatch clock;
  std::optional<SeedBarrier> barrier;
  data::StateSet safe = shared_.data.safe, near_dangerous = shared_.data.near_dangerous;
  ApplyBarrierDataVariant(variant, seed_, &safe, &near_dangerous);
  std::string brief;
  if (selected_barrier_ && first) {
    barrier = std::move(selected_barrier_);  // trained and checked by SelectCandidate
    selected_barrier_.reset();
    brief = "the closed-loop check's selected candidate";
  } else {
    barrier = TrainSeedBarrier(o_, training_seed_, safe, near_dangerous, &brief);
  }
  nlohmann::json& record = outcome_.summary["barriers"][variant.name];
  record = {{"safe_states", safe.size()},
            {"near_dangerous_states", near_dangerous.size()},
            {"training", barrier->summary}};
  if (o_.closed_loop.enabled) record["training_seed"] = training_seed_;
  barrier_seconds_ += clock.Seconds();
  if (!dir_.empty()) barrier->Save(dir_ + "/" + VariantFile("barrier", variant, ".model"));
  progress_.Line([&](std::ostream& out) {
    out << tag_ << " barrier (" << variant.name << ", " << safe.size() << " safe + "
        << near_dangerous.size() << " near-dangerous): " << brief << " (" << clock.Seconds()
        << " s)";
  });
  progress_.Advance();
  if (shared_.check)
    CheckVariantBarrier(variant, first, safe, near_dangerous, brief, barrier, record);
  return barrier;
}

// The pre-deployment check (its own streams; nothing before or after depends on it), and with
// augment_flagged one retraining round with the counterexamples as near-dangerous states.
void SeedPipeline::CheckVariantBarrier(const BarrierDataVariant& variant, bool first,
                                       const data::StateSet& safe,
                                       data::StateSet& near_dangerous, std::string& brief,
                                       std::optional<SeedBarrier>& barrier,
                                       nlohmann::json& record) {
  const Stopwatch check_clock;
  cbf::CheckReport report =
      CheckSeedBarrier(domain_, o_, shared_, barrier->Factory(domain_, env_));
  record["check"] = report.ToJson();
  record["check"]["seconds"] = check_clock.Seconds();
  if (!dir_.empty()) report.WriteCsv(dir_ + "/" + VariantFile("check", variant, ".csv"));
  progress_.Line([&](std::ostream& out) {
    out << tag_ << " barrier check (" << variant.name << "): " << CheckBrief(report) << " ("
        << check_clock.Seconds() << " s)";
  });
  if (o_.augment_flagged && report.flagged && !report.worst.empty()) {
    const Stopwatch augment_clock;
    const long added = static_cast<long>(report.worst.size());
    Eigen::MatrixXf states(near_dangerous.states.rows(), near_dangerous.size() + added);
    states.leftCols(near_dangerous.size()) = near_dangerous.states;
    for (long i = 0; i < added; ++i)
      states.col(near_dangerous.size() + i) = report.worst[static_cast<std::size_t>(i)].state;
    near_dangerous.states = std::move(states);
    barrier = TrainSeedBarrier(o_, training_seed_, safe, near_dangerous, &brief);
    cbf::CheckReport after =
        CheckSeedBarrier(domain_, o_, shared_, barrier->Factory(domain_, env_));
    record["augmented"] = {{"added_near_dangerous_states", added},
                           {"training", barrier->summary},
                           {"check", after.ToJson()},
                           {"seconds", augment_clock.Seconds()}};
    progress_.Line([&](std::ostream& out) {
      out << tag_ << " barrier retrained with " << added
          << " counterexamples as near-dangerous states: " << brief << "; check "
          << CheckBrief(after) << " (" << augment_clock.Seconds() << " s)";
    });
    if (!dir_.empty())
      barrier->Save(dir_ + "/" + VariantFile("barrier", variant, "_augmented.model"));
  }
  progress_.Advance();
  if (first) {
    outcome_.summary["check"] = record["check"];
    if (record.contains("augmented"))
      outcome_.summary["check_augmented"] = record["augmented"]["check"];
  }
}

// The joint policy (AIRL with the CBF loss of `barrier`), warm-started from BC when AIRL is.
policy::GaussianPolicy SeedPipeline::TrainJoint(const SeedBarrier& barrier) {
  const Stopwatch clock;
  const policy::AirlOptions options = SeedRun(o_.airl, seed_, dir_, "joint_curve.csv");
  policy::AirlSummary summary;
  const policy::GaussianPolicy* start = o_.airl_warm_start ? &*bc_ : nullptr;
  long counted = 0;
  const policy::AirlCallback count = [&](const policy::AirlIterationStats&) {
    ++counted;
    progress_.Advance();
    return true;
  };
  const data::TrajectorySet& demos = shared_.data.demonstrations;
  policy::GaussianPolicy joint =
      barrier.per_obstacle
          ? policy::TrainAirlJoint(options, o_.joint, *barrier.per_obstacle, env_.ShieldModel(),
                                   demos, env_, start, &summary, count)
          : policy::TrainAirlJoint(options, o_.joint, *barrier.flat, env_.ShieldModel(), demos,
                                   env_, start, &summary, count);
  progress_.Advance(options.iterations - counted);
  outcome_.summary["joint"] = summary.ToJson();
  timings()["joint"] = clock.Seconds();
  if (!dir_.empty()) joint.Save(dir_ + "/joint.model");
  progress_.Line([&](std::ostream& out) {
    out << tag_ << " joint (AIRL + CBF loss): " << summary.BriefReport() << " ("
        << clock.Seconds() << " s)";
  });
  return joint;
}

// Every method on the seed's evaluation episodes (common random numbers across methods).
void SeedPipeline::Evaluate(const BarrierDataVariant& variant, bool several_variants,
                            const SeedBarrier* barrier, const policy::GaussianPolicy* joint) {
  const Stopwatch clock;
  eval::SeedModels models;
  models.bc = bc_ ? &*bc_ : nullptr;
  models.airl = airl_ ? &*airl_ : nullptr;
  models.airl_reward = airl_reward_ ? &*airl_reward_ : nullptr;
  models.joint = joint;
  if (barrier != nullptr) models.make_barrier = barrier->Factory(domain_, env_);
  outcome_.results.push_back(eval::EvaluateMethods(env_, methods_, models, o_.shield,
                                                   o_.episodes, eval::EvaluationSeed(seed_)));
  evaluation_seconds_ += clock.Seconds();
  progress_.Line([&](std::ostream& out) {
    out << tag_ << " evaluated";
    if (several_variants) out << " (" << variant.name << ")";
    out << ":";
    for (const auto& [method, r] : outcome_.results.back()) {
      out << " " << ToString(eval::kMethodNames, method) << " " << 100.0 * r.success_rate()
          << "%/" << 100.0 * r.dangerous_rate() << "%";
    }
    out << " (success/dangerous, " << clock.Seconds() << " s)";
  });
  progress_.Advance();
}

std::function<std::unique_ptr<cbf::Barrier>()> SeedBarrier::Factory(
    const Domain& domain, const domains::Environment& env) const {
  if (per_obstacle) return [this] { return per_obstacle->MakeEvaluator(256); };
  // Checked once here, so that a mismatch fails before any evaluation.
  const std::vector<std::string> features = env.ObservationFeatures();
  const std::string source = "the " + domain.name() + " domain's observations";
  cbf::FeatureRows(flat->features, features, source, "the flat barrier");
  return [this, features, source] {
    return flat->MakeEvaluatorFor(features, source, "the flat barrier", 256);
  };
}

void SeedBarrier::Save(const std::string& path) const {
  if (per_obstacle) per_obstacle->Save(path);
  if (flat) flat->Save(path);
}

SeedBarrier TrainSeedBarrier(const ExperimentOptions& o, std::uint64_t seed,
                             const data::StateSet& safe, const data::StateSet& near_dangerous,
                             std::string* brief) {
  SeedBarrier b;
  if (o.barrier_kind == BarrierKind::kPerObstacle) {
    cbf::CarBarrierTrainingSummary summary;
    b.per_obstacle = cbf::TrainCarBarrier(SeedRun(o.per_obstacle_barrier, seed), safe,
                                          near_dangerous, &summary);
    b.summary = summary.ToJson();
    *brief = summary.BriefReport();
  } else {
    cbf::BarrierTrainingSummary summary;
    b.flat = cbf::TrainBarrier(SeedRun(o.flat_barrier, seed), safe, near_dangerous, &summary);
    b.summary = summary.ToJson();
    *brief = summary.BriefReport();
  }
  return b;
}

long SeedUnits(const ExperimentOptions& o, const std::vector<eval::Method>& methods,
               const SharedData& shared, std::size_t variants) {
  const bool needs_airl = Any(methods, UsesAirlPolicy);
  const bool needs_joint = Any(methods, eval::UsesJointPolicy);
  const bool needs_barrier = Any(methods, NeedsBarrier);
  long units = 0;
  if (Any(methods, eval::UsesBcPolicy) || ((needs_airl || needs_joint) && o.airl_warm_start))
    ++units;
  if (needs_airl) units += o.airl.iterations;
  if (o.closed_loop.enabled) ++units;  // the first candidate's closed-loop check
  long per_variant = 1;
  if (needs_barrier) per_variant += shared.check ? 2 : 1;
  if (needs_joint) per_variant += o.airl.iterations;
  return units + per_variant * static_cast<long>(variants);
}

}  // namespace secure::experiments::internal
