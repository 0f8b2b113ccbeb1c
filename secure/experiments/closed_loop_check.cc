// The closed-loop check with model selection (SeedPipeline::SelectCandidate, seed_pipeline.h): a
// seed's candidates (BC, AIRL and a barrier per training seed), each run on held-out shielded
// episodes and, with repair_rounds, repaired with the states before its dangerous steps, until
// one passes.
#include <deque>
#include <filesystem>
#include <ostream>

#include "secure/common/atomic_file.h"
#include "secure/common/error.h"
#include "secure/common/filesystem.h"
#include "secure/common/timer.h"
#include "secure/experiments/internal/seed_pipeline.h"

namespace secure::experiments::internal {
namespace {

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

// What a candidate's check found: the criteria it fails ([] when it passes) and its rates.
struct CandidateVerdict {
  nlohmann::json failed;
  double success = 0.0, dangerous = 0.0;
};

// Candidate k's held-out shielded episodes. With repair_rounds: while it fails with dangerous
// episodes, the states before each one's first dangerous step join the near-dangerous states,
// the barrier is retrained (same training seed, same policies) and the candidate checked again
// on the same episodes. Updates `barrier` and the candidate's `record`.
CandidateVerdict CheckCandidate(const Domain& domain, const ExperimentOptions& o,
                                std::uint64_t seed, int k, std::uint64_t training_seed,
                                const std::string& tag, const std::string& files,
                                const SharedData& shared, const domains::Environment& env,
                                const policy::GaussianPolicy& airl,
                                const policy::AirlRewardModel* airl_reward, SeedBarrier& barrier,
                                Progress& progress, nlohmann::json& record) {
  const ClosedLoopCheckOptions& c = o.closed_loop;
  data::StateSet near_dangerous = shared.data.near_dangerous;
  nlohmann::json repairs = nlohmann::json::array();
  CandidateVerdict v;
  for (int round = 0;; ++round) {
    const Stopwatch clock;
    eval::SeedModels models;
    models.airl = &airl;
    models.airl_reward = airl_reward;
    models.make_barrier = barrier.Factory(domain, env);
    const std::unique_ptr<domains::Environment> check_env = env.Clone();
    eval::EpisodeRunner runner(*check_env);
    DangerPrecursors precursors(c.repair_lookback);
    const eval::SeedResult result =
        eval::RunMethod(runner, eval::Method::kSecure, models, o.shield, c.episodes,
                        ClosedLoopCheckSeed(seed), &precursors);
    progress.Advance();
    v.success = result.success_rate();
    v.dangerous = result.dangerous_rate();
    v.failed = nlohmann::json::array();
    if (v.success < c.min_success) v.failed.push_back("success");
    if (v.dangerous > c.max_dangerous) v.failed.push_back("dangerous");
    nlohmann::json& at = round == 0 ? record : repairs.back();
    at["success_rate"] = v.success;
    at["dangerous_rate"] = v.dangerous;
    at["passed"] = v.failed.empty();
    at["failed_criteria"] = v.failed;
    at["seconds"] = clock.Seconds() + at.value("seconds", 0.0);
    if (round == 0) record["episodes"] = c.episodes;
    progress.Line([&](std::ostream& out) {
      out << tag << " closed-loop check, candidate " << k << " (training seed " << training_seed
          << ")" << (round > 0 ? ", repair " + std::to_string(round) : "") << ": SECURE "
          << 100.0 * v.success << "% success, " << 100.0 * v.dangerous << "% dangerous over "
          << c.episodes << " held-out episodes: "
          << (v.failed.empty() ? "passes" : "fails (" + v.failed.dump() + ")");
    });
    if (v.failed.empty() || round == c.repair_rounds || precursors.states().cols() == 0) break;

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
    record["passed"] = v.failed.empty();
    record["failed_criteria"] = v.failed;
    record["success_rate"] = v.success;
    record["dangerous_rate"] = v.dangerous;
  }
  return v;
}

// The selected candidate's policies and curves also under the usual names in `dir`.
void SaveSelected(const std::string& dir, int index,
                  const std::optional<policy::GaussianPolicy>& bc,
                  const std::optional<policy::GaussianPolicy>& airl,
                  const std::optional<policy::AirlRewardModel>& airl_reward) {
  if (dir.empty()) return;
  const std::string files = dir + "/candidate-" + std::to_string(index);
  if (bc) bc->Save(dir + "/bc.model");
  if (airl) airl->Save(dir + "/airl.model");
  if (airl_reward) airl_reward->Save(dir + "/airl_reward.model");
  for (const char* curve : {"bc_curve.csv", "airl_curve.csv"}) {
    const std::string from = files + "/" + curve;
    if (std::filesystem::is_regular_file(from))
      WriteFileAtomically(dir + "/" + curve, ReadFile(from));
  }
}

}  // namespace

SeedBarrier SeedPipeline::SelectCandidate() {
  const ExperimentOptions& o = o_;
  const long candidate_units =
      (needs_bc_ ? 1 : 0) + (needs_airl_ ? o.airl.iterations : 0) + 2;  // + barrier, check
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
    if (k > 0) progress_.AddTotal(candidate_units);
    const std::uint64_t training_seed = CandidateSeed(seed_, k);
    const std::string files = dir_.empty() ? "" : dir_ + "/candidate-" + std::to_string(k);
    CreateDirectories(files);
    nlohmann::json record = {{"candidate", k}, {"training_seed", training_seed}};
    TrainPolicies(training_seed, files, record);
    SECURE_INTERNAL_CHECK(airl_.has_value(), "the closed-loop check needs the AIRL policy");
    std::string brief;
    SeedBarrier barrier =
        TrainSeedBarrier(o, training_seed, shared_.data.safe, shared_.data.near_dangerous, &brief);
    record["barrier"] = barrier.summary;
    if (!files.empty()) barrier.Save(files + "/barrier.model");
    if (k > 0) progress_.Advance();

    const CandidateVerdict verdict =
        CheckCandidate(domain_, o, seed_, k, training_seed, tag_, files, shared_, env_, *airl_,
                       airl_reward_ ? &*airl_reward_ : nullptr, barrier, progress_, record);
    candidates.push_back(record);
    const int failures = static_cast<int>(verdict.failed.size());
    const double score = verdict.success - verdict.dangerous;
    if (!best || failures < best->failed || (failures == best->failed && score > best->score)) {
      best = Kept{k,
                  std::move(bc_),
                  std::move(airl_),
                  std::move(airl_reward_),
                  std::move(barrier),
                  record,
                  failures,
                  score};
    }
    if (failures == 0) break;
  }
  SECURE_INTERNAL_CHECK(best.has_value(), "max_candidates >= 1");
  bc_ = std::move(best->bc);
  airl_ = std::move(best->airl);
  airl_reward_ = std::move(best->airl_reward);
  const bool passed = best->failed == 0;
  nlohmann::json& summary = outcome_.summary;
  summary["closed_loop"] = {{"candidates", candidates},
                            {"selected", best->index},
                            {"verdict", passed ? "pass" : "failed"},
                            {"options", c.ToJson()}};
  if (best->record.contains("bc")) summary["bc"] = best->record["bc"];
  if (best->record.contains("airl")) summary["airl"] = best->record["airl"];
  SaveSelected(dir_, best->index, bc_, airl_, airl_reward_);
  progress_.Line([&](std::ostream& out) {
    out << tag_ << " closed-loop check: candidate " << best->index << " selected"
        << (passed ? "" : " although it FAILS the check (the best of " +
                              std::to_string(candidates.size()) + " candidates)");
  });
  return std::move(*best->barrier);
}

}  // namespace secure::experiments::internal
