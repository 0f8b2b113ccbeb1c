// The user-study driver (experiments/user_study.h) on the coffee-placing plug-in's simulated
// participants, quick profile and smaller: it runs, is deterministic and independent of the
// number of threads, evaluates the four conditions on identical episodes, and prints the paper's
// columns beside the paper's ratings.
#include <gtest/gtest.h>

#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "domains/coffee_placing/domain.h"
#include "secure/common/error.h"
#include "secure/domains/forwarding_environment.h"
#include "secure/experiments/domain.h"
#include "secure/experiments/user_study.h"

namespace secure::experiments {
namespace {

using domains::coffee_placing::CoffeePlacingDomain;

UserStudyOptions Tiny(const Domain& d) {
  UserStudyOptions o = UserStudyOptions::From(d.Preset(), Profile::kQuick);
  o.participants = 3;
  o.episodes = 2;
  o.seed = 5;
  o.verbose = false;
  return o;
}

nlohmann::json WithoutTimes(nlohmann::json j) {
  j["experiment"].erase("seconds");
  return j;
}

TEST(UserStudy, QuickRunIsDeterministicAndIndependentOfThreads) {
  const CoffeePlacingDomain domain(Profile::kQuick);
  UserStudyOptions o = Tiny(domain);
  o.spreads = {0.0, 1.0};
  o.threads = 1;
  const UserStudyResult a = RunUserStudy(domain, o, nullptr);
  o.threads = 2;
  const UserStudyResult b = RunUserStudy(domain, o, nullptr);
  EXPECT_EQ(WithoutTimes(a.ToJson()), WithoutTimes(b.ToJson()));
  ASSERT_EQ(a.spreads.size(), 2u);
  for (const UserStudySpreadResult& r : a.spreads) {
    ASSERT_EQ(r.participants.size(), 3u);
    ASSERT_EQ(r.metrics.size(), 4u);
    for (const UserStudyMetric& m : r.metrics) {
      ASSERT_EQ(m.values.size(), 3u);
      for (const auto& row : m.values) ASSERT_EQ(row.size(), 4u);
      EXPECT_EQ(m.posthoc.pairs.size(), 6u);  // every pair of the four conditions
      EXPECT_EQ(m.posthoc.adjustment, "holm");
    }
  }
  // Spread 0: every participant has the mean thresholds; spread 1: they differ.
  EXPECT_EQ(a.spreads[0].participants[0]["comfort_distance"],
            a.spreads[0].participants[1]["comfort_distance"]);
  EXPECT_NE(a.spreads[1].participants[0]["comfort_distance"],
            a.spreads[1].participants[1]["comfort_distance"]);
  // Another seed: other participants.
  o.seed = 6;
  const UserStudyResult c = RunUserStudy(domain, o, nullptr);
  EXPECT_NE(c.spreads[1].participants[0], a.spreads[1].participants[0]);
}

// A population whose environments record the start of every episode, per participant and
// environment (one environment per participant and condition).
struct StartLog {
  std::mutex mutex;
  std::map<int, std::vector<std::shared_ptr<std::vector<Eigen::VectorXf>>>> starts;
};

class RecordingEnv final : public domains::ForwardingEnvironment {
 public:
  RecordingEnv(std::unique_ptr<domains::Environment> inner,
               std::shared_ptr<std::vector<Eigen::VectorXf>> log)
      : ForwardingEnvironment(std::move(inner)), log_(std::move(log)) {}
  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override {
    inner_->Reset(rng, observation);
    log_->push_back(observation);
  }
  std::unique_ptr<domains::Environment> Clone() const override {
    return std::make_unique<RecordingEnv>(inner_->Clone(), log_);
  }

 private:
  std::shared_ptr<std::vector<Eigen::VectorXf>> log_;
};

class RecordingPopulation final : public Population {
 public:
  RecordingPopulation(std::unique_ptr<Population> inner, StartLog* log)
      : inner_(std::move(inner)), log_(log) {}
  int size() const override { return inner_->size(); }
  nlohmann::json Participant(int p) const override { return inner_->Participant(p); }
  DomainData GenerateData(int p, std::uint64_t seed) const override {
    return inner_->GenerateData(p, seed);
  }
  std::unique_ptr<domains::Environment> MakeEnvironment(int p) const override {
    auto starts = std::make_shared<std::vector<Eigen::VectorXf>>();
    {
      std::lock_guard<std::mutex> lock(log_->mutex);
      log_->starts[p].push_back(starts);
    }
    return std::make_unique<RecordingEnv>(inner_->MakeEnvironment(p), starts);
  }
  bool HeldWithMargin(int p, const Eigen::Ref<const Eigen::VectorXf>& o) const override {
    return inner_->HeldWithMargin(p, o);
  }
  std::string Describe() const override { return inner_->Describe(); }

 private:
  std::unique_ptr<Population> inner_;
  StartLog* log_;
};

class RecordingDomain final : public Domain {
 public:
  explicit RecordingDomain(StartLog* log) : log_(log) {}
  std::string name() const override { return "recording-coffee"; }
  std::string Describe() const override { return inner_.Describe(); }
  std::string ConfigSection() const override { return inner_.ConfigSection(); }
  void ApplyYaml(const YAML::Node& n, const std::string& s) override { (void)n, (void)s; }
  void Validate() const override { inner_.Validate(); }
  nlohmann::json OptionsJson() const override { return inner_.OptionsJson(); }
  std::unique_ptr<domains::Environment> MakeEnvironment() const override {
    return inner_.MakeEnvironment();
  }
  DomainData GenerateData(std::uint64_t seed) const override { return inner_.GenerateData(seed); }
  ExperimentOptions Preset() const override { return inner_.Preset(); }
  bool HasPopulation() const override { return true; }
  std::unique_ptr<Population> MakePopulation(const PopulationOptions& o) const override {
    return std::make_unique<RecordingPopulation>(inner_.MakePopulation(o), log_);
  }

 private:
  CoffeePlacingDomain inner_{Profile::kQuick};
  StartLog* log_;
};

TEST(UserStudy, TheFourConditionsRunOnIdenticalEpisodes) {
  StartLog log;
  const RecordingDomain domain(&log);
  UserStudyOptions o = Tiny(domain);
  o.episodes = 3;
  RunUserStudy(domain, o, nullptr);
  ASSERT_EQ(log.starts.size(), 3u);
  for (const auto& [p, envs] : log.starts) {
    ASSERT_EQ(envs.size(), 4u) << "participant " << p;  // one environment per condition
    ASSERT_EQ(envs[0]->size(), 3u);
    for (const auto& e : envs) {
      ASSERT_EQ(e->size(), envs[0]->size());
      for (std::size_t i = 0; i < e->size(); ++i) EXPECT_EQ((*e)[i], (*envs[0])[i]);
    }
  }
  // Different participants get different episodes.
  EXPECT_NE((*log.starts[0][0])[0], (*log.starts[1][0])[0]);
}

TEST(UserStudy, TheTableHasThePapersColumnsBesideItsRatings) {
  const CoffeePlacingDomain domain(Profile::kQuick);
  const UserStudyResult r = RunUserStudy(domain, Tiny(domain), nullptr);
  const std::string t = r.Table();
  EXPECT_NE(t.find("| (policy, CBF) | (ind, ind) | (ind, grp) | (grp, ind) | (grp, grp) |"),
            std::string::npos)
      << t;
  for (const char* row :
       {"| Task success % (this run) |", "| Episodes with a violation % (this run) |",
        "| Over-conservative steps % (this run) |", "| Task time s (this run) |",
        "| Task (paper, Likert rating) | 73.3 | 77.1 | 81.6 | 73.6 |",
        "| Safety (paper, Likert rating) | 31.3 | 33.3 | 35.4 | 35.3 |",
        "| Perceived safety (paper, Likert rating) | 33.2 | 35.4 | 36.4 | 35.8 |",
        "Likert ratings, not rates", "Holm-adjusted", "Verdict: "})
    EXPECT_NE(t.find(row), std::string::npos) << row << "\n" << t;
  const nlohmann::json j = r.ToJson();
  EXPECT_EQ(j["experiment"]["kind"], "user-study");
  EXPECT_EQ(j["spreads"][0]["metrics"]["violations"]["conditions"][2]["condition"], "(grp, ind)");
  EXPECT_EQ(j["paper"]["rows"][0]["values"][2], 81.6);
}

TEST(UserStudy, RejectsBadOptions) {
  const CoffeePlacingDomain domain(Profile::kQuick);
  UserStudyOptions o = Tiny(domain);
  o.spreads = {1.5};
  EXPECT_THROW(RunUserStudy(domain, o, nullptr), Error);
  o = Tiny(domain);
  o.participants = 1;
  EXPECT_THROW(RunUserStudy(domain, o, nullptr), Error);
}

}  // namespace
}  // namespace secure::experiments
