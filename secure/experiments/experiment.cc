#include "secure/experiments/experiment.h"

#include <boost/crc.hpp>

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <ostream>
#include <sstream>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/atomic_file.h"
#include "secure/common/build_info.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/limits.h"
#include "secure/common/option_check.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/common/yaml_fields.h"
#include "secure/common/yaml_value.h"
#include "secure/experiments/internal/seed_runner.h"
#include "secure/nn/torch_threads.h"

namespace secure::experiments {
namespace {

using internal::Progress;

constexpr const char* kOptions = "ExperimentOptions";


std::string Percent(double fraction) {
  char buffer[32];
  std::snprintf(buffer, sizeof buffer, "%g%%", 100.0 * fraction);
  return buffer;
}

bool Any(const std::vector<eval::Method>& methods, bool (*predicate)(eval::Method)) {
  return std::any_of(methods.begin(), methods.end(), predicate);
}
// Methods that run the AIRL policy (AIRL itself and every SECURE variant).
bool UsesAirlPolicy(eval::Method m) { return !eval::UsesBcPolicy(m) && !eval::UsesJointPolicy(m); }
bool NeedsBarrier(eval::Method m) { return eval::IsShielded(m) || eval::UsesJointPolicy(m); }

// "prefix.ext" for the baseline variant, "prefix_<name>.ext" (name made file-safe) otherwise.
std::string VariantFile(const std::string& prefix, const BarrierDataVariant& variant,
                        const std::string& ext) {
  if (variant.name == "baseline") return prefix + ext;
  std::string name = variant.name;
  for (char& c : name)
    if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
  return prefix + "_" + name + ext;
}

// A learned barrier of either kind, with a factory of evaluators for the shields.
struct SeedBarrier {
  std::optional<cbf::CarBarrierNet> per_obstacle;
  std::optional<cbf::BarrierNet> flat;
  nlohmann::json summary;

  // Evaluators on the domain's observations (`env`): a flat barrier that reads a subset of them
  // (BarrierTrainerOptions::input_features) gets its rows picked by name.
  std::function<std::unique_ptr<cbf::Barrier>()> Factory(const Domain& domain,
                                                         const domains::Environment& env) const {
    if (per_obstacle) return [this] { return per_obstacle->MakeEvaluator(256); };
    // Checked once here, so that a mismatch fails before any evaluation.
    const std::vector<std::string> features = env.ObservationFeatures();
    const std::string source = "the " + domain.name() + " domain's observations";
    cbf::FeatureRows(flat->features, features, source, "the flat barrier");
    return [this, features, source] {
      return flat->MakeEvaluatorFor(features, source, "the flat barrier", 256);
    };
  }
  void Save(const std::string& path) const {
    if (per_obstacle) per_obstacle->Save(path);
    if (flat) flat->Save(path);
  }
};

SeedBarrier TrainSeedBarrier(const ExperimentOptions& o, std::uint64_t seed,
                             const data::StateSet& safe, const data::StateSet& near_dangerous,
                             std::string* brief) {
  SeedBarrier b;
  if (o.barrier_kind == BarrierKind::kPerObstacle) {
    cbf::CarBarrierTrainerOptions options = o.per_obstacle_barrier;
    options.seed = seed;
    options.verbose = false;
    cbf::CarBarrierTrainingSummary summary;
    b.per_obstacle = cbf::TrainCarBarrier(options, safe, near_dangerous, &summary);
    b.summary = summary.ToJson();
    *brief = summary.BriefReport();
  } else {
    cbf::BarrierTrainerOptions options = o.flat_barrier;
    options.seed = seed;
    options.verbose = false;
    cbf::BarrierTrainingSummary summary;
    b.flat = cbf::TrainBarrier(options, safe, near_dangerous, &summary);
    b.summary = summary.ToJson();
    *brief = summary.BriefReport();
  }
  return b;
}

// Everything one seed produces: per variant, the method results.
struct SeedOutcome {
  std::vector<std::map<eval::Method, eval::SeedResult>> results;  // per variant
  nlohmann::json summary = nlohmann::json::object();
};

struct SharedData {
  DomainData data;
  bool check = false;
  data::StateSet check_safe, check_near_dangerous;  // held-out, for the barrier check
};

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

// The closed-loop check's counterexamples: in each episode with a dangerous step, the
// observations from which the `lookback` steps up to and including the first dangerous one were
// taken (fewer if the episode is shorter), with their episode and step indices. The observation
// of a step is the one before it: the start observation for step 0, else the previous step's.
class DangerPrecursors final : public eval::StepObserver {
 public:
  explicit DangerPrecursors(int lookback) : lookback_(lookback) {}
  void OnEpisodeStart(long episode, const Eigen::VectorXf& observation) override {
    history_.clear();
    history_.push_back(observation);
    episode_ = episode;
    done_ = false;
  }
  void OnStep(const eval::StepView& step) override {
    if (done_) return;
    if (step.outcome.collided) {
      // history_.back() is the observation the dangerous step started from.
      const int n = std::min<int>(lookback_, static_cast<int>(history_.size()));
      for (int i = n - 1; i >= 0; --i) {
        states_.push_back(history_[history_.size() - 1 - static_cast<std::size_t>(i)]);
        episodes_.push_back(episode_);
        steps_.push_back(step.step - i);
      }
      done_ = true;
      return;
    }
    history_.push_back(step.observation);
    if (static_cast<int>(history_.size()) > lookback_) history_.pop_front();
  }
  // The counterexamples as columns (observation_dim x count); empty if none.
  const Eigen::MatrixXf& states() {
    if (matrix_.cols() != static_cast<Eigen::Index>(states_.size())) {
      matrix_.resize(states_.empty() ? 0 : states_.front().size(),
                     static_cast<Eigen::Index>(states_.size()));
      for (std::size_t i = 0; i < states_.size(); ++i)
        matrix_.col(static_cast<Eigen::Index>(i)) = states_[i];
    }
    return matrix_;
  }
  // CSV (docs/FILE_FORMATS.md, "closed-loop counterexamples"): episode, step, then the
  // observation's features; `secure cbf train --augment-from` reads its feature columns.
  void WriteCsv(const std::string& path, const std::vector<std::string>& features) {
    const Eigen::MatrixXf& s = states();
    std::vector<std::string> columns = {"episode", "step"};
    columns.insert(columns.end(), features.begin(), features.end());
    Eigen::MatrixXd values(static_cast<Eigen::Index>(columns.size()), s.cols());
    for (Eigen::Index i = 0; i < s.cols(); ++i) {
      values(0, i) = static_cast<double>(episodes_[static_cast<std::size_t>(i)]);
      values(1, i) = steps_[static_cast<std::size_t>(i)];
      values.col(i).tail(s.rows()) = s.col(i).cast<double>();
    }
    data::WriteCsv(path, columns, values);
  }

 private:
  int lookback_;
  std::deque<Eigen::VectorXf> history_;
  long episode_ = 0;
  bool done_ = false;
  std::vector<Eigen::VectorXf> states_;
  std::vector<long> episodes_;
  std::vector<int> steps_;
  Eigen::MatrixXf matrix_;
};

// The closed-loop check with model selection (ClosedLoopCheckOptions): trains candidates (BC and
// AIRL through `train_policies`, the barrier on the baseline data) until one passes its held-out
// shielded episodes, leaves the selected candidate's policies in `bc` and `airl`, records every
// candidate in summary["closed_loop"] and returns the selected barrier. Files: candidate k's
// curves and models in <dir>/candidate-k/, the selected one's policies and curves also under the
// usual names in <dir> (its barrier is saved by the caller).
using TrainPolicies = std::function<void(std::uint64_t, const std::string&, nlohmann::json&)>;
SeedBarrier SelectCandidate(const Domain& domain, const ExperimentOptions& o, std::uint64_t seed,
                            const std::string& tag, const std::string& dir,
                            const SharedData& shared, const domains::Environment& env,
                            const TrainPolicies& train_policies,
                            std::optional<policy::GaussianPolicy>& bc,
                            std::optional<policy::GaussianPolicy>& airl,
                            std::optional<policy::AirlRewardModel>& airl_reward,
                            long candidate_units, Progress& progress, nlohmann::json& summary) {
  const ClosedLoopCheckOptions& c = o.closed_loop;
  struct Kept {
    int index = 0;
    std::optional<policy::GaussianPolicy> bc, airl;
    std::optional<policy::AirlRewardModel> airl_reward;
    std::optional<SeedBarrier> barrier;
    nlohmann::json record;
    int failed = 0;
    double score = 0.0;
  };
  std::optional<Kept> best;
  nlohmann::json candidates = nlohmann::json::array();
  for (int k = 0; k < c.max_candidates; ++k) {
    // Candidate 0's units are in SeedUnits (its barrier is the variant loop's unit).
    if (k > 0) progress.AddTotal(candidate_units);
    const std::uint64_t training_seed = CandidateSeed(seed, k);
    const std::string files = dir.empty() ? "" : dir + "/candidate-" + std::to_string(k);
    CreateDirectories(files);
    nlohmann::json record = {{"candidate", k}, {"training_seed", training_seed}};
    train_policies(training_seed, files, record);
    SECURE_INTERNAL_CHECK(airl.has_value(), "the closed-loop check needs the AIRL policy");
    std::string brief;
    SeedBarrier barrier =
        TrainSeedBarrier(o, training_seed, shared.data.safe, shared.data.near_dangerous, &brief);
    record["barrier"] = barrier.summary;
    if (!files.empty()) barrier.Save(files + "/barrier.model");
    if (k > 0) progress.Advance();

    // The candidate's held-out shielded episodes. With repair_rounds: while it fails with
    // dangerous episodes, the states before each one's first dangerous step join the
    // near-dangerous states, the barrier is retrained (same training seed, same policies) and
    // the candidate checked again on the same episodes.
    data::StateSet near_dangerous = shared.data.near_dangerous;
    nlohmann::json repairs = nlohmann::json::array();
    nlohmann::json failed;
    double success = 0.0, dangerous = 0.0;
    for (int round = 0;; ++round) {
      const Stopwatch clock;
      eval::SeedModels models;
      models.airl = &*airl;
      models.airl_reward = airl_reward ? &*airl_reward : nullptr;
      models.make_barrier = barrier.Factory(domain, env);
      const std::unique_ptr<domains::Environment> check_env = env.Clone();
      eval::EpisodeRunner runner(*check_env);
      DangerPrecursors precursors(c.repair_lookback);
      const eval::SeedResult result =
          eval::RunMethod(runner, eval::Method::kSecure, models, o.shield, c.episodes,
                          ClosedLoopCheckSeed(seed), &precursors);
      progress.Advance();
      success = result.success_rate();
      dangerous = result.dangerous_rate();
      failed = nlohmann::json::array();
      if (success < c.min_success) failed.push_back("success");
      if (dangerous > c.max_dangerous) failed.push_back("dangerous");
      nlohmann::json& at = round == 0 ? record : repairs.back();
      at["success_rate"] = success;
      at["dangerous_rate"] = dangerous;
      at["passed"] = failed.empty();
      at["failed_criteria"] = failed;
      at["seconds"] = clock.Seconds() + at.value("seconds", 0.0);
      if (round == 0) record["episodes"] = c.episodes;
      progress.Line([&](std::ostream& out) {
        out << tag << " closed-loop check, candidate " << k << " (training seed " << training_seed
            << ")" << (round > 0 ? ", repair " + std::to_string(round) : "") << ": SECURE "
            << 100.0 * success << "% success, " << 100.0 * dangerous << "% dangerous over "
            << c.episodes << " held-out episodes: "
            << (failed.empty() ? "passes" : "fails (" + failed.dump() + ")");
      });
      if (failed.empty() || round == c.repair_rounds || precursors.states().cols() == 0) break;

      // Repair: the counterexamples (observations) join the near-dangerous states.
      SECURE_CHECK(near_dangerous.features == env.ObservationFeatures(),
                   "closed_loop.repair_rounds: the near-dangerous states of the "
                       << domain.name()
                       << " domain are not its observations (their features differ), so the "
                          "closed-loop counterexamples cannot join them");
      const Stopwatch repair_clock;
      progress.AddTotal(2);
      const Eigen::MatrixXf& added = precursors.states();
      Eigen::MatrixXf states(near_dangerous.states.rows(), near_dangerous.size() + added.cols());
      states << near_dangerous.states, added;
      near_dangerous.states = std::move(states);
      const std::string tag_r = "repair_" + std::to_string(round + 1);
      if (!files.empty())
        precursors.WriteCsv(files + "/counterexamples_" + std::to_string(round + 1) + ".csv",
                            near_dangerous.features);
      std::string repair_brief;
      barrier = TrainSeedBarrier(o, training_seed, shared.data.safe, near_dangerous, &repair_brief);
      if (!files.empty()) barrier.Save(files + "/barrier_" + tag_r + ".model");
      progress.Advance();
      repairs.push_back({{"round", round + 1},
                         {"counterexamples", added.cols()},
                         {"near_dangerous_states", near_dangerous.size()},
                         {"barrier", barrier.summary},
                         {"seconds", repair_clock.Seconds()}});
      progress.Line([&](std::ostream& out) {
        out << tag << " closed-loop repair " << round + 1 << " of candidate " << k << ": "
            << added.cols() << " states before dangerous steps join the near-dangerous states ("
            << near_dangerous.size() << "); barrier " << repair_brief;
      });
    }
    if (!repairs.empty()) {
      record["unrepaired"] = {{"success_rate", record["success_rate"]},
                              {"dangerous_rate", record["dangerous_rate"]},
                              {"failed_criteria", record["failed_criteria"]}};
      record["repairs"] = repairs;
      record["passed"] = failed.empty();
      record["failed_criteria"] = failed;
      record["success_rate"] = success;
      record["dangerous_rate"] = dangerous;
    }
    candidates.push_back(record);
    const int failures = static_cast<int>(failed.size());
    const double score = success - dangerous;
    if (!best || failures < best->failed || (failures == best->failed && score > best->score)) {
      best = Kept{k,
                  std::move(bc),
                  std::move(airl),
                  std::move(airl_reward),
                  std::move(barrier),
                  record,
                  failures,
                  score};
    }
    if (failures == 0) break;
  }
  SECURE_INTERNAL_CHECK(best.has_value(), "max_candidates >= 1");
  bc = std::move(best->bc);
  airl = std::move(best->airl);
  airl_reward = std::move(best->airl_reward);
  const bool passed = best->failed == 0;
  summary["closed_loop"] = {{"candidates", candidates},
                            {"selected", best->index},
                            {"verdict", passed ? "pass" : "failed"},
                            {"options", c.ToJson()}};
  if (best->record.contains("bc")) summary["bc"] = best->record["bc"];
  if (best->record.contains("airl")) summary["airl"] = best->record["airl"];
  if (!dir.empty()) {
    const std::string files = dir + "/candidate-" + std::to_string(best->index);
    if (bc) bc->Save(dir + "/bc.model");
    if (airl) airl->Save(dir + "/airl.model");
    if (airl_reward) airl_reward->Save(dir + "/airl_reward.model");
    for (const char* curve : {"bc_curve.csv", "airl_curve.csv"}) {
      const std::string from = files + "/" + curve;
      if (std::filesystem::is_regular_file(from))
        WriteFileAtomically(dir + "/" + curve, ReadFile(from));
    }
  }
  progress.Line([&](std::ostream& out) {
    out << tag << " closed-loop check: candidate " << best->index << " selected"
        << (passed ? "" : " although it FAILS the check (the best of " +
                              std::to_string(candidates.size()) + " candidates)");
  });
  return std::move(*best->barrier);
}

SeedOutcome RunSeed(const Domain& domain, const ExperimentOptions& o,
                    const std::vector<eval::Method>& methods, int index, const SharedData& shared,
                    const domains::Environment& env,
                    const std::vector<BarrierDataVariant>& variants, Progress& progress) {
  const std::uint64_t seed = o.first_seed + static_cast<std::uint64_t>(index);
  const std::string tag = "[seed " + std::to_string(seed) + "]";
  const std::string dir =
      o.output_dir.empty() ? "" : o.output_dir + "/seed-" + std::to_string(seed);
  CreateDirectories(dir);
  const data::TrajectorySet& demos = shared.data.demonstrations;
  SeedOutcome outcome;
  nlohmann::json& timings = outcome.summary["seconds"];
  timings = nlohmann::json::object();
  const bool needs_airl = Any(methods, UsesAirlPolicy);
  const bool needs_joint = Any(methods, eval::UsesJointPolicy);
  const bool needs_barrier = Any(methods, NeedsBarrier);

  // BC (a method, and the warm start of AIRL and the joint policy), then AIRL, for one training
  // seed; `files` is the directory of their curves and models ("": none).
  const bool needs_bc =
      Any(methods, eval::UsesBcPolicy) || ((needs_airl || needs_joint) && o.airl_warm_start);
  std::optional<policy::GaussianPolicy> bc, airl;
  std::optional<policy::AirlRewardModel> airl_reward;  // AIRL's g and V (top-q aggregation)
  auto train_policies = [&](std::uint64_t training_seed, const std::string& files,
                            nlohmann::json& record) {
    bc.reset();
    airl.reset();
    airl_reward.reset();
    if (needs_bc) {
      const Stopwatch clock;
      policy::BcOptions options = o.bc;
      options.seed = training_seed;
      options.verbose = false;
      if (!files.empty()) options.curve_path = files + "/bc_curve.csv";
      policy::BcSummary summary;
      bc = policy::TrainBc(options, demos, &summary);
      record["bc"] = summary.ToJson();
      timings["bc"] = timings.value("bc", 0.0) + clock.Seconds();
      if (!files.empty()) bc->Save(files + "/bc.model");
      progress.Line([&](std::ostream& out) { out << tag << " " << summary.BriefReport(); });
      progress.Advance();
    }
    if (needs_airl) {
      const Stopwatch clock;
      policy::AirlOptions options = o.airl;
      options.seed = training_seed;
      options.verbose = false;
      if (!files.empty()) options.curve_path = files + "/airl_curve.csv";
      policy::AirlSummary summary;
      const int report_every = std::max(1, options.iterations / 4);
      long counted = 0;
      airl = policy::TrainAirl(
          options, demos, env, o.airl_warm_start ? &*bc : nullptr, &summary,
          [&](const policy::AirlIterationStats& stats) {
            ++counted;
            progress.Advance();
            if (stats.iteration % report_every == 0) {
              progress.Line([&](std::ostream& out) {
                out << tag << " AIRL iteration " << stats.iteration << "/" << options.iterations
                    << ": rollout success " << stats.success_rate << ", collisions "
                    << stats.collision_rate << " (" << clock.Seconds() << " s)";
              });
            }
            return true;
          },
          &airl_reward.emplace());
      progress.Advance(options.iterations - counted);  // the units of a run stopped early
      record["airl"] = summary.ToJson();
      timings["airl"] = timings.value("airl", 0.0) + clock.Seconds();
      if (!files.empty()) {
        airl->Save(files + "/airl.model");
        airl_reward->Save(files + "/airl_reward.model");
      }
      progress.Line([&](std::ostream& out) { out << tag << " " << summary.BriefReport(); });
    }
  };

  // With the closed-loop check: candidates until one passes (their files in candidate-K/), the
  // selected one's models and curves also under the usual names. Without it: the seed's own.
  std::optional<SeedBarrier> selected_barrier;
  std::uint64_t training_seed = seed;  // the selected candidate's (other variants' barriers too)
  if (o.closed_loop.enabled) {
    const long candidate_units =
        (needs_bc ? 1 : 0) + (needs_airl ? o.airl.iterations : 0) + 2;  // + barrier, check
    selected_barrier =
        SelectCandidate(domain, o, seed, tag, dir, shared, env, train_policies, bc, airl,
                        airl_reward, candidate_units, progress, outcome.summary);
    training_seed = CandidateSeed(seed, outcome.summary["closed_loop"]["selected"].get<int>());
  } else {
    train_policies(seed, dir, outcome.summary);
  }

  // One barrier per data variant (only the baseline outside `sensitivity`), each followed by its
  // evaluation.
  outcome.summary["barriers"] = nlohmann::json::object();
  double barrier_seconds = 0.0, evaluation_seconds = 0.0;
  for (const BarrierDataVariant& variant : variants) {
    Stopwatch clock;
    std::optional<SeedBarrier> barrier;
    if (needs_barrier) {
      data::StateSet safe = shared.data.safe, near_dangerous = shared.data.near_dangerous;
      ApplyBarrierDataVariant(variant, seed, &safe, &near_dangerous);
      std::string brief;
      if (selected_barrier && &variant == &variants.front()) {
        barrier = std::move(selected_barrier);  // trained and checked by SelectCandidate
        selected_barrier.reset();
        brief = "the closed-loop check's selected candidate";
      } else {
        barrier = TrainSeedBarrier(o, training_seed, safe, near_dangerous, &brief);
      }
      nlohmann::json& record = outcome.summary["barriers"][variant.name];
      record = {{"safe_states", safe.size()},
                {"near_dangerous_states", near_dangerous.size()},
                {"training", barrier->summary}};
      if (o.closed_loop.enabled) record["training_seed"] = training_seed;
      barrier_seconds += clock.Seconds();
      if (!dir.empty()) barrier->Save(dir + "/" + VariantFile("barrier", variant, ".model"));
      progress.Line([&](std::ostream& out) {
        out << tag << " barrier (" << variant.name << ", " << safe.size() << " safe + "
            << near_dangerous.size() << " near-dangerous): " << brief << " (" << clock.Seconds()
            << " s)";
      });
      progress.Advance();

      // The pre-deployment check (its own streams; nothing above or below depends on it), and
      // with augment_flagged one retraining round with the counterexamples as near-dangerous
      // states.
      if (shared.check) {
        const Stopwatch check_clock;
        cbf::CheckReport report = CheckSeedBarrier(domain, o, shared, barrier->Factory(domain, env));
        record["check"] = report.ToJson();
        record["check"]["seconds"] = check_clock.Seconds();
        if (!dir.empty()) report.WriteCsv(dir + "/" + VariantFile("check", variant, ".csv"));
        progress.Line([&](std::ostream& out) {
          out << tag << " barrier check (" << variant.name << "): " << CheckBrief(report) << " ("
              << check_clock.Seconds() << " s)";
        });
        if (o.augment_flagged && report.flagged && !report.worst.empty()) {
          const Stopwatch augment_clock;
          const long added = static_cast<long>(report.worst.size());
          Eigen::MatrixXf states(near_dangerous.states.rows(), near_dangerous.size() + added);
          states.leftCols(near_dangerous.size()) = near_dangerous.states;
          for (long i = 0; i < added; ++i)
            states.col(near_dangerous.size() + i) = report.worst[static_cast<std::size_t>(i)].state;
          near_dangerous.states = std::move(states);
          barrier = TrainSeedBarrier(o, training_seed, safe, near_dangerous, &brief);
          cbf::CheckReport after = CheckSeedBarrier(domain, o, shared, barrier->Factory(domain, env));
          record["augmented"] = {{"added_near_dangerous_states", added},
                                 {"training", barrier->summary},
                                 {"check", after.ToJson()},
                                 {"seconds", augment_clock.Seconds()}};
          progress.Line([&](std::ostream& out) {
            out << tag << " barrier retrained with " << added
                << " counterexamples as near-dangerous states: " << brief << "; check "
                << CheckBrief(after) << " (" << augment_clock.Seconds() << " s)";
          });
          if (!dir.empty())
            barrier->Save(dir + "/" + VariantFile("barrier", variant, "_augmented.model"));
        }
        progress.Advance();
        if (&variant == &variants.front()) {
          outcome.summary["check"] = record["check"];
          if (record.contains("augmented"))
            outcome.summary["check_augmented"] = record["augmented"]["check"];
        }
      }
    }

    // The joint policy needs the (baseline) barrier.
    std::optional<policy::GaussianPolicy> joint;
    if (needs_joint) {
      SECURE_INTERNAL_CHECK(barrier.has_value(), "the joint method trains a barrier");
      clock.Restart();
      policy::AirlOptions options = o.airl;
      options.seed = seed;
      options.verbose = false;
      if (!dir.empty()) options.curve_path = dir + "/joint_curve.csv";
      policy::AirlSummary summary;
      const policy::GaussianPolicy* start = o.airl_warm_start ? &*bc : nullptr;
      long counted = 0;
      const policy::AirlCallback count = [&](const policy::AirlIterationStats&) {
        ++counted;
        progress.Advance();
        return true;
      };
      joint = barrier->per_obstacle
                  ? policy::TrainAirlJoint(options, o.joint, *barrier->per_obstacle,
                                           env.ShieldModel(), demos, env, start, &summary, count)
                  : policy::TrainAirlJoint(options, o.joint, *barrier->flat, env.ShieldModel(),
                                           demos, env, start, &summary, count);
      progress.Advance(options.iterations - counted);
      outcome.summary["joint"] = summary.ToJson();
      timings["joint"] = clock.Seconds();
      if (!dir.empty()) joint->Save(dir + "/joint.model");
      progress.Line([&](std::ostream& out) {
        out << tag << " joint (AIRL + CBF loss): " << summary.BriefReport() << " ("
            << clock.Seconds() << " s)";
      });
    }

    clock.Restart();
    eval::SeedModels models;
    models.bc = bc ? &*bc : nullptr;
    models.airl = airl ? &*airl : nullptr;
    models.airl_reward = airl_reward ? &*airl_reward : nullptr;
    models.joint = joint ? &*joint : nullptr;
    if (barrier) models.make_barrier = barrier->Factory(domain, env);
    outcome.results.push_back(eval::EvaluateMethods(env, methods, models, o.shield, o.episodes,
                                                    eval::EvaluationSeed(seed)));
    evaluation_seconds += clock.Seconds();
    progress.Line([&](std::ostream& out) {
      out << tag << " evaluated";
      if (variants.size() > 1) out << " (" << variant.name << ")";
      out << ":";
      for (const auto& [method, r] : outcome.results.back()) {
        out << " " << ToString(eval::kMethodNames, method) << " " << 100.0 * r.success_rate()
            << "%/" << 100.0 * r.dangerous_rate() << "%";
      }
      out << " (success/dangerous, " << clock.Seconds() << " s)";
    });
    progress.Advance();
  }
  timings["barriers"] = barrier_seconds;
  timings["evaluation"] = evaluation_seconds;
  return outcome;
}

// The work units of one seed, as RunSeed advances them: BC 1, an AIRL or joint policy one per
// iteration, per variant a barrier 1 (its check and retraining 1), an evaluation 1.
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

long RoundedCount(double fraction, long n) {
  return std::max<long>(1, static_cast<long>(std::lround(fraction * static_cast<double>(n))));
}

// ---------------------------------------------------------------------------------------------
// Task files: seed-K/task.json, one per finished seed.

constexpr const char* kTaskFile = "task.json";
constexpr int kTaskFormat = 1;

std::string SeedDir(const std::string& run_dir, std::uint64_t seed) {
  return run_dir + "/seed-" + std::to_string(seed);
}

// A number of a result document: null (how nlohmann writes NaN) reads as NaN, a missing key as
// `otherwise`.
double Number(const nlohmann::json& j, const char* key, double otherwise = 0.0) {
  const auto it = j.find(key);
  if (it == j.end()) return otherwise;
  if (it->is_null()) return std::nan("");
  return it->get<double>();
}

nlohmann::json SeedResultJson(const eval::SeedResult& r) { return r.ToJson(); }

eval::SeedResult SeedResultFromJson(const nlohmann::json& j) {
  eval::SeedResult r;
  r.episodes = j.at("episodes").get<long>();
  r.successes = j.at("successes").get<long>();
  r.dangerous = j.at("dangerous").get<long>();
  r.collision_events = j.at("collision_events").get<long>();
  r.steps = j.at("steps").get<long>();
  r.mean_steps_to_goal = Number(j, "mean_steps_to_goal");
  r.decisions = j.at("decisions").get<long>();
  r.interventions = j.at("interventions").get<long>();
  r.resampled_decisions = j.at("resampled_decisions").get<long>();
  r.no_safe_action_decisions = j.at("no_safe_action_decisions").get<long>();
  r.invalid_input_decisions = j.at("invalid_input_decisions").get<long>();
  r.mean_iterations = Number(j, "mean_iterations");
  r.qp_tried = static_cast<long>(Number(j, "qp_tried"));
  r.qp_decisions = static_cast<long>(Number(j, "qp_decisions"));
  r.qp_rejected = static_cast<long>(Number(j, "qp_rejected"));
  const nlohmann::json& l = j.at("latency_us");
  r.latency_us.count = l.at("count").get<long>();
  r.latency_us.p50 = Number(l, "p50");
  r.latency_us.p90 = Number(l, "p90");
  r.latency_us.p99 = Number(l, "p99");
  r.latency_us.max = Number(l, "max");
  r.latency_us.mean = Number(l, "mean");
  r.seconds = Number(j, "seconds");
  return r;
}

// A JSON value for a message: its dump, cut at 80 characters.
std::string Quote(const nlohmann::json& j) {
  std::string text = j.dump();
  if (text.size() > 80) text = text.substr(0, 77) + "...";
  return text;
}

// The first difference between `a` and `b` as "path: A vs B" ("" if they are equal).
std::string FirstDifference(const nlohmann::json& a, const nlohmann::json& b,
                            const std::string& path) {
  if (a == b) return "";
  const std::string where = path.empty() ? "(the whole document)" : path;
  if (a.is_object() && b.is_object()) {
    for (const auto& [key, value] : a.items()) {
      const std::string sub = path.empty() ? key : path + "." + key;
      if (!b.contains(key)) return sub + ": " + Quote(value) + " vs (missing)";
      std::string d = FirstDifference(value, b.at(key), sub);
      if (!d.empty()) return d;
    }
    for (const auto& [key, value] : b.items())
      if (!a.contains(key))
        return (path.empty() ? key : path + "." + key) + ": (missing) vs " + Quote(value);
  }
  if (a.is_array() && b.is_array() && a.size() == b.size()) {
    for (std::size_t i = 0; i < a.size(); ++i) {
      std::string d = FirstDifference(a[i], b[i], path + "[" + std::to_string(i) + "]");
      if (!d.empty()) return d;
    }
  }
  return where + ": " + Quote(a) + " vs " + Quote(b);
}

// What makes two task files tasks of the same experiment (everything that determines a seed's
// numbers): version, kind, domain and its options, methods, variants, options but `threads`,
// and the data's counts.
nlohmann::json ExperimentIdentity(const ExperimentResult& r) {
  nlohmann::json options = r.options_json;
  options.erase("threads");
  nlohmann::json method_names = nlohmann::json::array();
  for (eval::Method m : r.methods) method_names.push_back(ToString(eval::kMethodNames, m));
  nlohmann::json variants = nlohmann::json::array();
  for (const BarrierDataVariant& v : r.variants) variants.push_back(v.ToJson());
  return {
      {"format", kTaskFormat},
      {"version", Version()},
      {"kind", ToString(kExperimentKindNames, r.kind)},
      {"domain", r.domain},
      {"domain_title", r.domain_title},
      {"domain_options", r.domain_options},
      {"methods", method_names},
      {"variants", variants},
      {"options", options},
      // Not in options.ToJson() (so not in result.json), but the tests across seeds use it.
      {"evaluation",
       {{"tost_bound", r.options.evaluation.tost_bound}, {"alpha", r.options.evaluation.alpha}}},
      {"data",
       {{"demonstrations", r.demonstrations},
        {"discarded_demonstrations", r.discarded_demonstrations},
        {"demonstration_steps", r.demonstration_steps},
        {"safe_states", r.safe_states},
        {"near_dangerous_states", r.near_dangerous_states}}}};
}

// A task file's checksum (issue 34: an edited successes = 99 of 3 episodes gave "841.7 %"):
// "crc32:" + the CRC-32 of the compact JSON of every other field. It catches edits and damage,
// not a forger who recomputes it.
std::string TaskChecksum(const nlohmann::json& task) {
  nlohmann::json content = task;
  content.erase("checksum");
  boost::crc_32_type crc;
  const std::string text = content.dump();
  crc.process_bytes(text.data(), text.size());
  char hex[9];
  std::snprintf(hex, sizeof hex, "%08x", static_cast<unsigned>(crc.checksum()));
  return std::string("crc32:") + hex;
}

nlohmann::json TaskJson(const nlohmann::json& identity, std::uint64_t seed, int threads,
                        double data_seconds, const SeedOutcome& outcome) {
  nlohmann::json results = nlohmann::json::array();
  for (const auto& per_variant : outcome.results) {
    nlohmann::json methods = nlohmann::json::object();
    for (const auto& [method, r] : per_variant)
      methods[ToString(eval::kMethodNames, method)] = SeedResultJson(r);
    results.push_back(std::move(methods));
  }
  nlohmann::json task = {{"experiment", identity},
                         {"seed", seed},
                         {"threads", threads},
                         {"data_seconds", data_seconds},
                         {"results", std::move(results)},
                         {"summary", outcome.summary}};
  task["checksum"] = TaskChecksum(task);
  return task;
}

// A task file's content (parsed); an error naming the file if it is not one.
nlohmann::json ReadTaskFile(const std::string& path) {
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(ReadFile(path));
  } catch (const nlohmann::json::exception& e) {
    SECURE_THROW(path << ": not a task file (" << e.what() << "); remove it to recompute the seed");
  }
  SECURE_CHECK(j.is_object() && j.contains("experiment") && j.contains("seed") &&
                   j.contains("results") && j.contains("summary") &&
                   j["seed"].is_number_unsigned() && j["results"].is_array(),
               path << ": not a task file (expected an object with experiment, seed, results and "
                       "summary); remove it to recompute the seed");
  SECURE_CHECK(j.contains("checksum") && j["checksum"].is_string(),
               path << ": no checksum (a task file of an older version, or edited); remove it to "
                       "recompute the seed");
  const std::string want = TaskChecksum(j);
  SECURE_CHECK(j["checksum"].get<std::string>() == want,
               path << ": checksum " << j["checksum"].get<std::string>() << " does not match its "
                    << "content (" << want << "): the file was edited or damaged; remove it to "
                    << "recompute the seed");
  return j;
}

SeedOutcome OutcomeFromTask(const nlohmann::json& task, const std::string& path,
                            std::size_t variants) {
  SECURE_CHECK(task["results"].size() == variants, path << ": " << task["results"].size()
                                                        << " variants of results, expected "
                                                        << variants);
  SeedOutcome outcome;
  try {
    for (const nlohmann::json& per_variant : task["results"]) {
      std::map<eval::Method, eval::SeedResult> methods;
      for (const auto& [name, r] : per_variant.items())
        methods[FromString(eval::kMethodNames, name, "method")] = SeedResultFromJson(r);
      outcome.results.push_back(std::move(methods));
    }
  } catch (const nlohmann::json::exception& e) {
    SECURE_THROW(path << ": malformed results (" << e.what() << ")");
  }
  // Counts in range: a rate is a count of episodes (or decisions) over episodes (decisions).
  for (std::size_t v = 0; v < outcome.results.size(); ++v) {
    for (const auto& [method, r] : outcome.results[v]) {
      const std::string where = path + ": results[" + std::to_string(v) + "]." +
                                std::string(ToString(eval::kMethodNames, method));
      SECURE_CHECK(r.episodes >= 0, where << ".episodes = " << r.episodes << ", must be >= 0");
      for (const auto& [name, count] : {std::pair<const char*, long>{"successes", r.successes},
                                        {"dangerous", r.dangerous}})
        SECURE_CHECK(count >= 0 && count <= r.episodes,
                     where << "." << name << " = " << count << ", must be in [0, episodes = "
                           << r.episodes << "]");
      for (const auto& [name, count] :
           {std::pair<const char*, long>{"interventions", r.interventions},
            {"resampled_decisions", r.resampled_decisions},
            {"no_safe_action_decisions", r.no_safe_action_decisions},
            {"invalid_input_decisions", r.invalid_input_decisions}})
        SECURE_CHECK(count >= 0 && count <= r.decisions,
                     where << "." << name << " = " << count << ", must be in [0, decisions = "
                           << r.decisions << "]");
      SECURE_CHECK(r.steps >= 0 && r.decisions >= 0 && r.collision_events >= 0,
                   where << ": negative steps, decisions or collision events");
    }
  }
  outcome.summary = task["summary"];
  return outcome;
}

// The seed's task file when there is one for this experiment (nullopt when there is none); an
// error naming the file and the first difference when it is a task of another experiment.
std::optional<SeedOutcome> ReusableTask(const std::string& run_dir, std::uint64_t seed,
                                        const nlohmann::json& identity, std::size_t variants) {
  if (run_dir.empty()) return std::nullopt;
  const std::string path = SeedDir(run_dir, seed) + "/" + kTaskFile;
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) return std::nullopt;
  const nlohmann::json task = ReadTaskFile(path);
  SECURE_CHECK(task["seed"].get<std::uint64_t>() == seed, path << ": the task of seed "
                                                               << task["seed"].get<std::uint64_t>()
                                                               << ", expected seed " << seed);
  const std::string difference = FirstDifference(task["experiment"], identity, "");
  SECURE_CHECK(difference.empty(),
               path << ": the task of a different experiment (" << difference
                    << "; the file's vs this run's): remove it (or the run directory) to "
                       "recompute, or write to another --out");
  return OutcomeFromTask(task, path, variants);
}

// The shared state of a run: validated options, the data (written to output_dir), the result's
// header and the experiment's identity.
struct Prepared {
  ExperimentResult result;
  SharedData shared;
  std::unique_ptr<domains::Environment> env;
  nlohmann::json identity;
};

void Prepare(ExperimentKind kind, const Domain& domain, const ExperimentOptions& o,
             const std::vector<int>& indices, Progress& progress, const Stopwatch& clock,
             Prepared* p) {
  ExperimentResult& result = p->result;
  const std::vector<eval::Method>& methods = result.methods;
  result.kind = kind;
  result.domain = domain.name();
  result.domain_title = domain.Title();
  result.domain_options = domain.OptionsJson();
  result.options = o;
  result.options_json = o.ToJson();

  // 1. Data.
  SharedData& shared = p->shared;
  shared.data = domain.GenerateData(o.data_seed);
  shared.check = o.check_enabled && domain.HasCheck() && Any(methods, NeedsBarrier);
  if (shared.check) {
    domain.CheckHeldOut(o.data_seed, o.check_held_out, &shared.check_safe,
                        &shared.check_near_dangerous);
  }
  const DomainData& data = shared.data;
  result.demonstrations = data.demonstrations.num_episodes();
  result.discarded_demonstrations = data.discarded_demonstrations;
  result.demonstration_steps = data.demonstrations.num_steps();
  result.safe_states = data.safe.size();
  result.near_dangerous_states = data.near_dangerous.size();
  result.data_seconds = clock.Seconds();
  result.variants = kind == ExperimentKind::kSensitivity
                        ? SensitivityVariants(o.data_fractions, o.imbalance_ratios, o.label_noise)
                        : std::vector<BarrierDataVariant>{{"baseline", 1.0, 1, 0.0}};
  p->env = domain.MakeEnvironment();
  p->identity = ExperimentIdentity(result);
  // Task files of another experiment fail before anything is written.
  for (int i : indices)
    ReusableTask(o.output_dir, o.first_seed + static_cast<std::uint64_t>(i), p->identity,
                 result.variants.size());
  // The data, by one shard only: shards may share the directory (on several hosts).
  if (!o.output_dir.empty() && o.shard == 0) {
    data::WriteTrajectories(o.output_dir + "/demos.csv", data.demonstrations);
    data::WriteStateSet(o.output_dir + "/safe.csv", data.safe);
    data::WriteStateSet(o.output_dir + "/near_dangerous.csv", data.near_dangerous);
    if (shared.check) {
      data::WriteStateSet(o.output_dir + "/check_safe.csv", shared.check_safe);
      data::WriteStateSet(o.output_dir + "/check_near_dangerous.csv", shared.check_near_dangerous);
    }
  }
  progress.Line([&](std::ostream& line) {
    line << "data: " << result.demonstrations << " expert demonstrations ("
         << result.discarded_demonstrations << " discarded), " << result.demonstration_steps
         << " steps; " << result.safe_states << " safe and " << result.near_dangerous_states
         << " near-dangerous states (" << clock.Seconds() << " s)";
  });
}

// Validation shared by RunExperiment and RunExperimentShard; returns the methods.
std::vector<eval::Method> CheckRun(ExperimentKind kind, const Domain& domain,
                                   const ExperimentOptions& o) {
  domain.Validate();
  o.Validate();
  CheckExperimentOptions(domain, o);
  const std::vector<eval::Method> methods = o.methods.empty() ? DefaultMethods(kind) : o.methods;
  SECURE_CHECK(
      kind != ExperimentKind::kSensitivity ||
          std::find(methods.begin(), methods.end(), eval::Method::kSecure) != methods.end(),
      "the sensitivity experiment reports SECURE: its methods must include secure");
  SECURE_CHECK(!o.closed_loop.enabled || (Any(methods, UsesAirlPolicy) && Any(methods, NeedsBarrier)),
               "closed_loop.enabled checks SECURE (the AIRL policy under the shield): the methods "
               "must include AIRL and a shielded method");
  // Before any work, so that an unusable --out (a file, a read-only place) fails at once.
  CreateDirectories(o.output_dir);
  return methods;
}

// 2. The seeds of `indices`, on `threads` workers taking the next one: each reused from its task
// file, or computed and its task file written. Returns the outcomes in the order of `indices`.
std::vector<SeedOutcome> RunSeeds(const Domain& domain, const ExperimentOptions& o,
                                  const Prepared& p, const std::vector<int>& indices,
                                  Progress& progress, ShardReport* report) {
  std::vector<SeedOutcome> outcomes(indices.size());
  std::vector<char> reused(indices.size(), 0);
  const int count = static_cast<int>(indices.size());
  const long seed_units = SeedUnits(o, p.result.methods, p.shared, p.result.variants.size());
  progress.Start(count * seed_units, "experiment");
  // RunJobsInParallel labels failures by index: run over positions and name the seed here.
  internal::RunJobsInParallel(
      count, o.threads,
      [&](int k) {
        const std::size_t at = static_cast<std::size_t>(k);
        const std::uint64_t seed = o.first_seed + static_cast<std::uint64_t>(indices[at]);
        try {
          if (std::optional<SeedOutcome> done =
                  ReusableTask(o.output_dir, seed, p.identity, p.result.variants.size())) {
            outcomes[at] = std::move(*done);
            reused[at] = 1;
            progress.Line([&](std::ostream& out) {
              out << "[seed " << seed << "] done before: reused " << SeedDir(o.output_dir, seed)
                  << "/" << kTaskFile;
            });
            progress.Advance(seed_units);
            return;
          }
          outcomes[at] = RunSeed(domain, o, p.result.methods, indices[at], p.shared, *p.env,
                                 p.result.variants, progress);
          if (!o.output_dir.empty()) {
            WriteFileAtomically(
                SeedDir(o.output_dir, seed) + "/" + kTaskFile,
                TaskJson(p.identity, seed, o.threads, p.result.data_seconds, outcomes[at]).dump(2) +
                    "\n");
          }
        } catch (const std::exception& e) {
          SECURE_THROW("seed " << seed << ": " << e.what());
        }
      },
      nullptr, 0);  // the job's errors name the seed
  progress.Finish();
  if (report != nullptr) {
    for (std::size_t k = 0; k < indices.size(); ++k) {
      const std::uint64_t seed = o.first_seed + static_cast<std::uint64_t>(indices[k]);
      (reused[k] ? report->reused : report->computed).push_back(seed);
    }
  }
  return outcomes;
}

// 3. Across seeds (all of them, in order), one evaluation per variant.
void Assemble(std::vector<SeedOutcome> outcomes, ExperimentResult* result) {
  for (std::size_t v = 0; v < result->variants.size(); ++v) {
    eval::Evaluation evaluation(result->options.evaluation);
    for (const SeedOutcome& outcome : outcomes)
      for (const auto& [method, r] : outcome.results[v]) evaluation.Add(method, r);
    evaluation.Finish();
    result->evaluations.emplace_back(
        result->kind == ExperimentKind::kSensitivity ? result->variants[v].name : "main",
        std::move(evaluation));
  }
  for (SeedOutcome& outcome : outcomes)
    result->seed_summaries.push_back(std::move(outcome.summary));
}

}  // namespace

// ---------------------------------------------------------------------------------------------
nlohmann::json BarrierDataVariant::ToJson() const {
  return {{"name", name},
          {"data_fraction", data_fraction},
          {"imbalance", imbalance},
          {"label_noise", label_noise}};
}

std::vector<BarrierDataVariant> SensitivityVariants(const std::vector<double>& data_fractions,
                                                    const std::vector<int>& imbalance_ratios,
                                                    const std::vector<double>& label_noise) {
  std::vector<BarrierDataVariant> variants = {{"baseline", 1.0, 1, 0.0}};
  for (double f : data_fractions)
    if (f != 1.0) variants.push_back({"data " + Percent(f), f, 1, 0.0});
  for (int k : imbalance_ratios)
    if (k != 1) variants.push_back({"imbalance 1:" + std::to_string(k), 1.0, k, 0.0});
  for (double p : label_noise)
    if (p != 0.0) variants.push_back({"label noise " + Percent(p), 1.0, 1, p});
  return variants;
}

void ApplyBarrierDataVariant(const BarrierDataVariant& v, std::uint64_t seed,
                             data::StateSet* safe, data::StateSet* near_dangerous) {
  SECURE_CHECK(v.data_fraction > 0 && v.data_fraction <= 1,
               "barrier data variant '" << v.name << "': data_fraction = " << v.data_fraction
                                        << ", must be in (0, 1]");
  SECURE_CHECK(v.imbalance >= 1, "barrier data variant '" << v.name << "': imbalance = "
                                                          << v.imbalance << ", must be >= 1");
  SECURE_CHECK(v.label_noise >= 0 && v.label_noise < 1,
               "barrier data variant '" << v.name << "': label_noise = " << v.label_noise
                                        << ", must be in [0, 1)");
  if (v.data_fraction == 1.0 && v.imbalance == 1 && v.label_noise == 0.0) return;
  Rng rng(seed ^ 0xda7a5e7ULL);
  auto shuffled = [&](const data::StateSet& set) {
    std::vector<long> order(static_cast<std::size_t>(set.size()));
    for (long i = 0; i < set.size(); ++i) order[static_cast<std::size_t>(i)] = i;
    Shuffle(order.begin(), order.end(), rng);
    return order;
  };
  std::vector<long> safe_order = shuffled(*safe), nd_order = shuffled(*near_dangerous);
  // Size and imbalance: keep a random subset of each class.
  const long n_safe = RoundedCount(v.data_fraction, safe->size());
  const long n_nd = RoundedCount(v.data_fraction / v.imbalance, near_dangerous->size());
  safe_order.resize(static_cast<std::size_t>(n_safe));
  nd_order.resize(static_cast<std::size_t>(n_nd));
  // Label noise: the first round(p n) of each (random) order change class.
  const long flip_safe = std::lround(v.label_noise * static_cast<double>(n_safe));
  const long flip_nd = std::lround(v.label_noise * static_cast<double>(n_nd));
  std::vector<long> new_safe(nd_order.begin(), nd_order.begin() + flip_nd);
  std::vector<long> new_nd(safe_order.begin(), safe_order.begin() + flip_safe);
  const std::vector<long> kept_safe(safe_order.begin() + flip_safe, safe_order.end());
  const std::vector<long> kept_nd(nd_order.begin() + flip_nd, nd_order.end());
  const Eigen::MatrixXf safe_states = safe->states, nd_states = near_dangerous->states;
  auto gather = [](const Eigen::MatrixXf& a, const std::vector<long>& ia, const Eigen::MatrixXf& b,
                   const std::vector<long>& ib) {
    Eigen::MatrixXf out(a.rows(), static_cast<long>(ia.size() + ib.size()));
    long c = 0;
    for (long i : ia) out.col(c++) = a.col(i);
    for (long i : ib) out.col(c++) = b.col(i);
    return out;
  };
  safe->states = gather(safe_states, kept_safe, nd_states, new_safe);
  near_dangerous->states = gather(nd_states, kept_nd, safe_states, new_nd);
  SECURE_CHECK(safe->size() > 0 && near_dangerous->size() > 0,
               "barrier data variant '" << v.name << "' leaves " << safe->size() << " safe and "
                                        << near_dangerous->size()
                                        << " near-dangerous states; both must be > 0");
}

std::vector<eval::Method> DefaultMethods(ExperimentKind kind) {
  using eval::Method;
  switch (kind) {
    case ExperimentKind::kMethodComparison: return {Method::kBc, Method::kAirl, Method::kSecure};
    case ExperimentKind::kJoint: return {Method::kAirl, Method::kSecure, Method::kJoint};
    case ExperimentKind::kAblation:
      return {Method::kSecure, Method::kSecureRandomSafe, Method::kSecureNoResampling,
              Method::kSecureMyopic};
    case ExperimentKind::kSensitivity: return {Method::kSecure};
  }
  SECURE_INTERNAL_CHECK(false, "unknown experiment kind");
  return {};
}

void ClosedLoopCheckOptions::Validate() const {
  constexpr const char* kOwner = "ClosedLoopCheckOptions";
  SECURE_CHECK_FIELD(episodes > 0 && episodes <= kMaxEpisodes, kOwner, "episodes", episodes,
                     "in [1, " << kMaxEpisodes << "]");
  SECURE_CHECK_FIELD(min_success >= 0 && min_success <= 1, kOwner, "min_success", min_success,
                     "in [0, 1]");
  SECURE_CHECK_FIELD(max_dangerous >= 0 && max_dangerous <= 1, kOwner, "max_dangerous",
                     max_dangerous, "in [0, 1]");
  SECURE_CHECK_FIELD(max_candidates >= 1 && max_candidates <= 64, kOwner, "max_candidates",
                     max_candidates, "in [1, 64]");
  SECURE_CHECK_FIELD(repair_rounds >= 0 && repair_rounds <= 16, kOwner, "repair_rounds",
                     repair_rounds, "in [0, 16]");
  SECURE_CHECK_FIELD(repair_lookback >= 1 && repair_lookback <= 1000, kOwner, "repair_lookback",
                     repair_lookback, "in [1, 1000]");
}

void ClosedLoopCheckOptions::ApplyYaml(const YAML::Node& node, const std::string& source) {
  YamlFields()
      .Field("enabled", &enabled)
      .Field("episodes", &episodes)
      .Field("min_success", &min_success)
      .Field("max_dangerous", &max_dangerous)
      .Field("max_candidates", &max_candidates)
      .Field("repair_rounds", &repair_rounds)
      .Field("repair_lookback", &repair_lookback)
      .Apply(node, source);
}

nlohmann::json ClosedLoopCheckOptions::ToJson() const {
  nlohmann::json j = {{"enabled", enabled},
                      {"episodes", episodes},
                      {"min_success", min_success},
                      {"max_dangerous", max_dangerous},
                      {"max_candidates", max_candidates}};
  // Only with repair, so that results without it keep their bytes.
  if (repair_rounds > 0) {
    j["repair_rounds"] = repair_rounds;
    j["repair_lookback"] = repair_lookback;
  }
  return j;
}

void ExperimentOptions::Validate() const {
  flat_barrier.Validate();
  per_obstacle_barrier.Validate();
  bc.Validate();
  airl.Validate();
  joint.Validate();
  shield.Validate();
  check.Validate();
  closed_loop.Validate();
  SECURE_CHECK_FIELD(seeds > 0 && seeds <= kMaxSeeds, kOptions, "seeds", seeds,
                     "in [1, " << kMaxSeeds << "]");
  SECURE_CHECK_FIELD(episodes > 0 && episodes <= kMaxEpisodes, kOptions, "episodes", episodes,
                     "in [1, " << kMaxEpisodes << "]");
  // Seeds run in parallel, one worker each: more workers than seeds only idle, and 10^8 of
  // them "ran" (issue 34). 1024 as the user study's --threads.
  SECURE_CHECK_FIELD(threads > 0 && threads <= 1024, kOptions, "threads", threads,
                     "in [1, 1024]");
  // The last seed, first_seed + seeds - 1, must not wrap around to 0.
  SECURE_CHECK_FIELD(first_seed <= std::numeric_limits<std::uint64_t>::max() -
                                       static_cast<std::uint64_t>(seeds - 1),
                     kOptions, "first_seed", first_seed,
                     "at most 2^64 - seeds (the last seed, first_seed + seeds - 1 with seeds = "
                         << seeds << ", must not wrap around)");
  SECURE_CHECK_FIELD(shards >= 1, kOptions, "shards", shards, ">= 1");
  SECURE_CHECK_FIELD(shard >= 0 && shard < shards, kOptions, "shard", shard,
                     "in [0, shards - 1] (shards = " << shards << ")");
  SECURE_CHECK_FIELD(std::isfinite(evaluation.tost_bound) && evaluation.tost_bound > 0, kOptions,
                     "evaluation.tost_bound", evaluation.tost_bound, "> 0");
  for (double f : data_fractions)
    SECURE_CHECK_FIELD(f > 0 && f <= 1, kOptions, "data_fractions[]", f, "in (0, 1]");
  for (int k : imbalance_ratios)
    SECURE_CHECK_FIELD(k >= 1, kOptions, "imbalance_ratios[]", k, ">= 1");
  for (double p : label_noise)
    SECURE_CHECK_FIELD(p >= 0 && p < 1, kOptions, "label_noise[]", p, "in [0, 1)");
  SECURE_CHECK_FIELD(check_held_out > 0 && check_held_out <= kMaxStates, kOptions,
                     "check_held_out", check_held_out, "in [1, " << kMaxStates << "]");
}

void ExperimentOptions::ApplyYaml(const YAML::Node& node, const std::string& source,
                                  Domain* domain) {
  SECURE_CHECK(node.IsMap(), source << ": the experiment configuration must be a mapping");
  for (const auto& entry : node) {
    const std::string key = YamlKey(entry.first, source);
    const std::string where = source + " [" + key + "]";
    if (key == "barrier") {
      if (barrier_kind == BarrierKind::kPerObstacle) {
        per_obstacle_barrier.ApplyYaml(entry.second, where);
      } else {
        flat_barrier.ApplyYaml(entry.second, where);
      }
    } else if (key == "flat_barrier") {
      flat_barrier.ApplyYaml(entry.second, where);
    } else if (key == "per_obstacle_barrier") {
      per_obstacle_barrier.ApplyYaml(entry.second, where);
    } else if (key == "bc") {
      bc.ApplyYaml(entry.second, where);
    } else if (key == "airl") {
      airl.ApplyYaml(entry.second, where);
    } else if (key == "joint") {
      joint.ApplyYaml(entry.second, where);
    } else if (key == "shield") {
      shield.ApplyYaml(entry.second, where);
    } else if (key == "check") {
      SECURE_CHECK(entry.second.IsMap(), where << ": expected a mapping of check options");
      YAML::Node rest(YAML::NodeType::Map);
      for (const auto& item : entry.second) {
        const std::string name = YamlKey(item.first, source);
        if (name == "enabled") {
          check_enabled = YamlValue<bool>(item.second, name, where);
        } else if (name == "held_out") {
          check_held_out = YamlValue<long>(item.second, name, where);
        } else if (name == "augment") {
          augment_flagged = YamlValue<bool>(item.second, name, where);
        } else {
          rest[name] = item.second;
        }
      }
      check.ApplyYaml(rest, where);
    } else if (key == "closed_loop") {
      closed_loop.ApplyYaml(entry.second, where);
    } else if (key == "domain" && domain != nullptr) {
      domain->ApplyYaml(entry.second, where);
    } else {
      SECURE_THROW(source << ": unknown section '" << key
                          << "' (valid: barrier, flat_barrier, per_obstacle_barrier, bc, airl, "
                             "joint, shield, check, closed_loop"
                          << (domain != nullptr ? ", domain" : "") << ")");
    }
  }
}

nlohmann::json ExperimentOptions::ToJson() const {
  nlohmann::json method_names = nlohmann::json::array();
  for (eval::Method m : methods) method_names.push_back(ToString(eval::kMethodNames, m));
  nlohmann::json j = {{"data_seed", data_seed},
          {"barrier_kind", ToString(kBarrierKindNames, barrier_kind)},
          {"flat_barrier", flat_barrier.ToJson()},
          {"per_obstacle_barrier", per_obstacle_barrier.ToJson()},
          {"bc", bc.ToJson()},
          {"airl", airl.ToJson()},
          {"airl_warm_start", airl_warm_start},
          {"joint", joint.ToJson()},
          {"shield", shield.ToJson()},
          {"methods", method_names},
          {"seeds", seeds},
          {"episodes", episodes},
          {"first_seed", first_seed},
          {"data_fractions", data_fractions},
          {"imbalance_ratios", imbalance_ratios},
          {"label_noise", label_noise},
          {"check_enabled", check_enabled},
          {"check_held_out", check_held_out},
          {"check", check.ToJson()},
          {"augment_flagged", augment_flagged},
          {"threads", threads}};
  if (closed_loop.enabled) j["closed_loop"] = closed_loop.ToJson();
  return j;
}

// ---------------------------------------------------------------------------------------------
nlohmann::json ExperimentResult::ToJson() const {
  nlohmann::json method_names = nlohmann::json::array();
  for (eval::Method m : methods) method_names.push_back(ToString(eval::kMethodNames, m));
  nlohmann::json experiment_json = {
      {"kind", ToString(kExperimentKindNames, kind)},
      {"domain", domain},
      {"domain_options", domain_options},
      {"methods", method_names},
      {"demonstrations", demonstrations},
      {"discarded_demonstrations", discarded_demonstrations},
      {"demonstration_steps", demonstration_steps},
      {"safe_states", safe_states},
      {"near_dangerous_states", near_dangerous_states},
      {"seeds", seed_summaries},
      {"data_seconds", data_seconds},
      {"seconds", seconds},
      {"options", options_json.is_null() ? options.ToJson() : options_json}};
  if (kind != ExperimentKind::kSensitivity) {
    nlohmann::json j = evaluations.front().second.ToJson();
    j["experiment"] = std::move(experiment_json);
    return j;
  }
  nlohmann::json by_variant = nlohmann::json::object();
  for (std::size_t i = 0; i < evaluations.size(); ++i) {
    nlohmann::json e = evaluations[i].second.ToJson();
    e["variant"] = variants[i].ToJson();
    by_variant[evaluations[i].first] = std::move(e);
  }
  return {{"variants", std::move(by_variant)}, {"experiment", std::move(experiment_json)}};
}

std::string ExperimentResult::Table() const {
  std::ostringstream out;
  out << "SECURE on " << domain_title << ": " << ToString(kExperimentKindNames, kind) << " ("
      << ToString(kBarrierKindNames, options.barrier_kind) << " barrier from " << safe_states
      << " safe + " << near_dangerous_states << " near-dangerous states; " << demonstrations
      << " expert demonstrations)\n\n";
  if (kind != ExperimentKind::kSensitivity) {
    out << evaluations.front().second.Table();
    out << ClosedLoopTable();
    out << CheckTable();
    return out.str();
  }
  const std::size_t seeds = options.seeds;
  out << "SECURE with barriers learned from modified data, % mean (std) over " << seeds
      << " seeds x " << options.episodes << " episodes\n\n";
  out << "| barrier data | safe : near-dangerous states | success % | dangerous % | "
         "interventions / episode | no-safe-action |\n|---|---|---|---|---|---|\n";
  for (std::size_t i = 0; i < evaluations.size(); ++i) {
    const eval::MethodSummary& s = evaluations[i].second.methods().at(eval::Method::kSecure);
    long no_safe = 0;
    for (const eval::SeedResult& r : s.per_seed) no_safe += r.no_safe_action_decisions;
    const nlohmann::json& barrier = seed_summaries.front()["barriers"][evaluations[i].first];
    char line[512];
    std::snprintf(line, sizeof line, "| %s | %s | %.1f (%.1f) | %.1f (%.1f) | %.2f | %ld |\n",
                  evaluations[i].first.c_str(),
                  (std::to_string(barrier.value("safe_states", 0L)) + " : " +
                   std::to_string(barrier.value("near_dangerous_states", 0L)))
                      .c_str(),
                  100 * s.success_rate.mean, 100 * s.success_rate.std,
                  100 * s.dangerous_rate.mean, 100 * s.dangerous_rate.std,
                  s.interventions_per_episode.mean, no_safe);
    out << line;
  }
  out << CheckTable();
  return out.str();
}

std::string ExperimentResult::ClosedLoopTable() const {
  if (seed_summaries.empty() || !seed_summaries.front().contains("closed_loop")) return "";
  std::ostringstream out;
  const nlohmann::json& first = seed_summaries.front()["closed_loop"]["options"];
  out << "\nClosed-loop check per seed (SECURE on " << first.value("episodes", 0L)
      << " held-out episodes per candidate; passes with success >= "
      << Percent(first.value("min_success", 0.0))
      << " and dangerous <= " << Percent(first.value("max_dangerous", 0.0))
      << "; every method of a seed is evaluated "
      << "with its selected candidate)\n\n";
  // With repair: the selected candidate's repairs and its held-out dangerous rate before them.
  const bool repair = first.value("repair_rounds", 0) > 0;
  out << "| seed | candidates | selected | held-out success % | held-out dangerous % |"
      << (repair ? " repairs (dangerous % before) |" : "") << " verdict |\n|---|---|---|---|---|"
      << (repair ? "---|" : "") << "---|\n";
  long replaced = 0, failed = 0, repaired = 0;
  for (std::size_t i = 0; i < seed_summaries.size(); ++i) {
    const nlohmann::json& c = seed_summaries[i]["closed_loop"];
    const nlohmann::json& candidates = c["candidates"];
    const long selected = c.value("selected", 0L);
    const bool pass = c.value("verdict", "") == "pass";
    replaced += selected > 0;
    failed += !pass;
    const nlohmann::json& chosen = candidates.at(static_cast<std::size_t>(selected));
    std::string repairs;
    if (repair) {
      char cell[64] = "0 |";
      if (chosen.contains("repairs")) {
        ++repaired;
        std::snprintf(cell, sizeof cell, "%zu (%.1f) |", chosen["repairs"].size(),
                      100 * Number(chosen["unrepaired"], "dangerous_rate"));
      }
      repairs = std::string(" ") + cell;
    }
    char line[256];
    std::snprintf(line, sizeof line, "| %llu | %zu | %ld | %.1f | %.1f |%s %s |\n",
                  static_cast<unsigned long long>(options.first_seed + i), candidates.size(),
                  selected, 100 * Number(chosen, "success_rate"),
                  100 * Number(chosen, "dangerous_rate"), repairs.c_str(),
                  pass ? "pass" : "**failed**");
    out << line;
  }
  out << "\n"
      << replaced << " of " << seed_summaries.size()
      << " seeds evaluated with a replacement candidate; ";
  if (repair) out << repaired << " with a repaired barrier; ";
  out << failed << " failed the check with every candidate (their best candidate is evaluated).\n";
  return out.str();
}

std::string ExperimentResult::CheckTable() const {
  if (seed_summaries.empty() || !seed_summaries.front().contains("check")) return "";
  const auto& evaluated = evaluations.front().second.methods();
  const auto secure_it = evaluated.find(eval::Method::kSecure);
  std::ostringstream out;
  out << "\nBarrier check per seed (" << evaluations.front().first
      << " barrier; rates: (a) h >= 0 without an action with g >= 0, (b) near a near-dangerous "
         "state with h >= 0, (c) unsafe by the domain's own test with h >= 0)\n\n"
      << "| seed | check | rate (a) | rate (b) | rate (c) | held-out accuracy safe / nd | "
         "SECURE dangerous % |\n|---|---|---|---|---|---|---|\n";
  long flagged = 0;
  for (std::size_t i = 0; i < seed_summaries.size(); ++i) {
    const nlohmann::json& c = seed_summaries[i]["check"];
    const nlohmann::json& kinds = c["kinds"];
    const bool is_flagged = c.value("flagged", false);
    flagged += is_flagged;
    std::string dangerous = "-";
    if (secure_it != evaluated.end() && i < secure_it->second.per_seed.size()) {
      char buffer[32];
      std::snprintf(buffer, sizeof buffer, "%.1f",
                    100 * secure_it->second.per_seed[i].dangerous_rate());
      dangerous = buffer;
    }
    std::string verdict = is_flagged ? "**flagged**" : "pass";
    if (seed_summaries[i].contains("check_augmented"))
      verdict +=
          std::string(" -> retrained: ") +
          (seed_summaries[i]["check_augmented"].value("flagged", false) ? "flagged" : "pass");
    double acc_safe = 0, acc_nd = 0;
    if (c.contains("accuracy") && c["accuracy"].is_object()) {
      acc_safe = Number(c["accuracy"], "safe");
      acc_nd = Number(c["accuracy"], "near_dangerous");
    }
    char line[256];
    std::snprintf(line, sizeof line, "| %llu | %s | %.4f | %.4f | %.4f | %.3f / %.3f | %s |\n",
                  static_cast<unsigned long long>(options.first_seed + i), verdict.c_str(),
                  Number(kinds["no_safe_action"], "rate"), Number(kinds["near_dangerous"], "rate"),
                  Number(kinds["unsafe"], "rate"), acc_safe, acc_nd, dangerous.c_str());
    out << line;
  }
  out << "\n"
      << flagged << " of " << seed_summaries.size() << " seeds flagged (thresholds: "
      << (options_json.is_null() ? options.check.thresholds.ToJson()
                                 : options_json["check"]["thresholds"])
             .dump()
      << ").\n";
  return out.str();
}

ExperimentResult RunExperiment(ExperimentKind kind, const Domain& domain,
                               const ExperimentOptions& o, std::ostream* out) {
  ProgressLine line(out, /*live=*/false);
  return RunExperimentWithProgress(kind, domain, o, line);
}

ExperimentResult RunExperimentWithProgress(ExperimentKind kind, const Domain& domain,
                                           const ExperimentOptions& o, ProgressLine& line) {
  SECURE_CHECK(o.shards == 1, "RunExperiment runs every seed (shards = "
                                  << o.shards << "): use RunExperimentShard and MergeExperiment");
  const std::vector<eval::Method> methods = CheckRun(kind, domain, o);
  const Stopwatch clock;
  Progress progress(&line, o.verbose);
  nn::SetTorchThreads(1);  // parallelism comes from the seeds; 1 is fastest for small nets
  std::vector<int> all(static_cast<std::size_t>(o.seeds));
  for (int i = 0; i < o.seeds; ++i) all[static_cast<std::size_t>(i)] = i;
  Prepared p;
  p.result.methods = methods;
  Prepare(kind, domain, o, all, progress, clock, &p);
  std::vector<SeedOutcome> outcomes = RunSeeds(domain, o, p, all, progress, nullptr);
  ExperimentResult& result = p.result;
  Assemble(std::move(outcomes), &result);
  result.seconds = clock.Seconds();
  if (!o.output_dir.empty()) {
    WriteFileAtomically(o.output_dir + "/result.json", result.ToJson().dump(2) + "\n");
  }
  return std::move(p.result);
}

ShardReport RunExperimentShard(ExperimentKind kind, const Domain& domain,
                               const ExperimentOptions& o, std::ostream* out) {
  SECURE_CHECK_FIELD(!o.output_dir.empty(), kOptions, "output_dir", "(empty)",
                     "a directory: a shard writes its seeds' task files there");
  const std::vector<eval::Method> methods = CheckRun(kind, domain, o);
  const Stopwatch clock;
  ProgressLine line(out, /*live=*/false);
  Progress progress(&line, o.verbose);
  nn::SetTorchThreads(1);
  std::vector<int> mine;
  for (int i = o.shard; i < o.seeds; i += o.shards) mine.push_back(i);
  Prepared p;
  p.result.methods = methods;
  Prepare(kind, domain, o, mine, progress, clock, &p);
  ShardReport report;
  RunSeeds(domain, o, p, mine, progress, &report);
  report.seconds = clock.Seconds();
  return report;
}

ExperimentResult MergeExperiment(const std::vector<std::string>& run_dirs) {
  SECURE_CHECK(!run_dirs.empty(), "merge: no run directory given");
  // Every task file, by seed (a directory given twice counts once).
  std::vector<std::string> dirs;
  std::vector<std::filesystem::path> seen;
  for (const std::string& dir : run_dirs) {
    std::error_code ec;
    SECURE_CHECK(std::filesystem::is_directory(dir, ec),
                 "merge: '" << dir << "' is not a directory (a run directory of a shard)");
    const std::filesystem::path canonical = std::filesystem::canonical(dir, ec);
    if (std::find(seen.begin(), seen.end(), canonical) != seen.end()) continue;
    seen.push_back(canonical);
    dirs.push_back(dir);
  }
  std::map<std::uint64_t, std::pair<std::string, nlohmann::json>> tasks;  // seed -> (path, task)
  std::string first_path;
  nlohmann::json identity;
  for (const std::string& dir : dirs) {
    std::vector<std::string> paths;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      const std::string name = entry.path().filename().string();
      if (entry.is_directory() && name.rfind("seed-", 0) == 0 &&
          std::filesystem::exists(entry.path() / kTaskFile))
        paths.push_back((entry.path() / kTaskFile).string());
    }
    std::sort(paths.begin(), paths.end());
    for (const std::string& path : paths) {
      nlohmann::json task = ReadTaskFile(path);
      if (first_path.empty()) {
        first_path = path;
        identity = task["experiment"];
      } else {
        const std::string difference = FirstDifference(task["experiment"], identity, "");
        SECURE_CHECK(difference.empty(), "merge: " << path << " and " << first_path
                                                   << " are tasks of different experiments ("
                                                   << difference << ")");
      }
      const std::uint64_t seed = task["seed"].get<std::uint64_t>();
      const auto [it, inserted] = tasks.emplace(seed, std::make_pair(path, std::move(task)));
      // One file reached twice (a merged directory's seed-K links to a shard's) counts once.
      std::error_code ec;
      SECURE_CHECK(inserted || std::filesystem::equivalent(it->second.first, path, ec),
                   "merge: seed " << seed << " is there twice: " << it->second.first << " and "
                                  << path);
    }
  }
  SECURE_CHECK(!first_path.empty(), "merge: no task file (seed-K/"
                                        << kTaskFile << ") in " << dirs.front()
                                        << (dirs.size() > 1 ? " and the others" : "")
                                        << ": run the experiment's shards with --out first");
  SECURE_CHECK(identity.value("format", 0) == kTaskFormat,
               "merge: " << first_path << ": task format " << identity.value("format", 0)
                         << ", this version reads " << kTaskFormat);
  SECURE_CHECK(identity.value("version", std::string()) == Version(),
               "merge: " << first_path << " was written by secure "
                         << identity.value("version", std::string("?")) << ", this is "
                         << Version());

  ExperimentResult result;
  try {
    result.kind = FromString(kExperimentKindNames, identity.at("kind").get<std::string>(), "kind");
    result.domain = identity.at("domain").get<std::string>();
    result.domain_title = identity.at("domain_title").get<std::string>();
    result.domain_options = identity.at("domain_options");
    for (const nlohmann::json& m : identity.at("methods"))
      result.methods.push_back(FromString(eval::kMethodNames, m.get<std::string>(), "method"));
    for (const nlohmann::json& v : identity.at("variants"))
      result.variants.push_back({v.at("name").get<std::string>(),
                                 v.at("data_fraction").get<double>(), v.at("imbalance").get<int>(),
                                 v.at("label_noise").get<double>()});
    const nlohmann::json& data = identity.at("data");
    result.demonstrations = data.at("demonstrations").get<long>();
    result.discarded_demonstrations = data.at("discarded_demonstrations").get<long>();
    result.demonstration_steps = data.at("demonstration_steps").get<long>();
    result.safe_states = data.at("safe_states").get<long>();
    result.near_dangerous_states = data.at("near_dangerous_states").get<long>();
    const nlohmann::json& options = identity.at("options");
    result.options.barrier_kind = FromString(
        kBarrierKindNames, options.at("barrier_kind").get<std::string>(), "barrier_kind");
    result.options.seeds = options.at("seeds").get<int>();
    result.options.episodes = options.at("episodes").get<long>();
    result.options.first_seed = options.at("first_seed").get<std::uint64_t>();
    const nlohmann::json& evaluation = identity.at("evaluation");
    result.options.evaluation.tost_bound = evaluation.at("tost_bound").get<double>();
    result.options.evaluation.alpha = evaluation.at("alpha").get<double>();
  } catch (const nlohmann::json::exception& e) {
    SECURE_THROW("merge: " << first_path << ": malformed experiment record (" << e.what() << ")");
  }
  const std::pair<std::string, nlohmann::json>& first = tasks.begin()->second;
  result.options.threads = first.second.value("threads", 1);
  // options.ToJson()'s key order: `threads` is its last key.
  result.options_json = identity["options"];
  result.options_json["threads"] = result.options.threads;

  // Every seed exactly once.
  const std::uint64_t first_seed = result.options.first_seed;
  std::vector<std::uint64_t> missing;
  for (int i = 0; i < result.options.seeds; ++i)
    if (tasks.count(first_seed + static_cast<std::uint64_t>(i)) == 0)
      missing.push_back(first_seed + static_cast<std::uint64_t>(i));
  if (!missing.empty()) {
    std::ostringstream list;
    for (std::size_t i = 0; i < missing.size() && i < 20; ++i)
      list << (i ? ", " : "") << missing[i];
    if (missing.size() > 20) list << ", ...";
    SECURE_THROW("merge: " << missing.size() << " of " << result.options.seeds
                           << " seeds have no task file (seed " << list.str()
                           << "): rerun the shard(s) that own them");
  }
  for (const auto& [seed, entry] : tasks)
    SECURE_CHECK(
        seed >= first_seed && seed < first_seed + static_cast<std::uint64_t>(result.options.seeds),
        "merge: " << entry.first << " is the task of seed " << seed
                  << ", outside the experiment's seeds " << first_seed << " to "
                  << first_seed + static_cast<std::uint64_t>(result.options.seeds) - 1);

  std::vector<SeedOutcome> outcomes;
  double seed_seconds = 0.0;
  for (const auto& [seed, entry] : tasks) {
    outcomes.push_back(OutcomeFromTask(entry.second, entry.first, result.variants.size()));
    result.data_seconds = std::max(result.data_seconds, Number(entry.second, "data_seconds"));
    const nlohmann::json stages =
        entry.second["summary"].value("seconds", nlohmann::json::object());
    for (const auto& [stage, seconds] : stages.items())
      if (seconds.is_number()) seed_seconds += seconds.get<double>();
  }
  Assemble(std::move(outcomes), &result);
  result.seconds = result.data_seconds + seed_seconds;
  return result;
}

}  // namespace secure::experiments
