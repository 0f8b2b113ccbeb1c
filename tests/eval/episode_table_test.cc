// Per-episode outcomes (SeedResult::episode_outcomes, eval/episode_table.h): they sum to the
// seed's counts, the CSV has one row per method, seed and episode, the lists name the dangerous
// episodes (render_test.cc: replaying a listed episode alone reproduces its outcome).
#include "secure/eval/episode_table.h"

#include <gtest/gtest.h>

#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "domains/double_integrator/ground_truth_barrier.h"
#include "domains/double_integrator/reach_avoid.h"
#include "tests/eval/pd_policy.h"
#include "tests/test_util.h"

namespace secure::eval {
namespace {

namespace di = domains::double_integrator;
using test::ErrorOf;

// The PD policy straight through the obstacle, unshielded (airl) and under a shield whose barrier
// is the ground truth of an obstacle half the real one's radius: it lets the policy into the
// outer ring, so some SECURE episodes are dangerous too, after interventions.
struct Fixture {
  di::ReachAvoidOptions task;
  di::GroundTruth too_small = task.truth;
  policy::GaussianPolicy pd = test::PdPolicy(task, 0.4);
  SeedModels models;
  Fixture() {
    too_small.radius = 0.5 * task.truth.radius;
    models.airl = &pd;
    models.make_barrier = [this] { return std::make_unique<di::GroundTruthBarrier>(too_small); };
  }
  // Seeds first_seed.. of the methods, `episodes` each.
  Evaluation Evaluate(std::uint64_t first_seed, int seeds, long episodes) const {
    Evaluation evaluation;
    const di::ReachAvoidEnv env(task);
    for (int k = 0; k < seeds; ++k) {
      const auto results = EvaluateMethods(env, {Method::kAirl, Method::kSecure}, models,
                                           shield::ShieldOptions{}, episodes,
                                           EvaluationSeed(first_seed + k));
      for (const auto& [method, r] : results) evaluation.Add(method, r);
    }
    evaluation.Finish();
    return evaluation;
  }
};

TEST(EpisodeOutcomesTest, EveryEpisodeIsRecordedAndTheySumToTheSeedsCounts) {
  const Fixture f;
  const Evaluation evaluation = f.Evaluate(3, 2, 12);
  long dangerous_secure = 0, interventions = 0;
  for (const auto& [method, summary] : evaluation.methods()) {
    for (const SeedResult& r : summary.per_seed) {
      SCOPED_TRACE(ToString(kMethodNames, method));
      ASSERT_TRUE(r.has_episode_outcomes());
      long successes = 0, dangerous = 0, steps = 0, events = 0, interv = 0, no_safe = 0;
      for (std::size_t i = 0; i < r.episode_outcomes.size(); ++i) {
        const EpisodeOutcome& e = r.episode_outcomes[i];
        EXPECT_EQ(e.episode, static_cast<long>(i));
        successes += e.success;
        dangerous += e.dangerous;
        steps += e.steps;
        events += e.collision_events;
        interv += e.interventions;
        no_safe += e.no_safe_action_decisions;
        // A dangerous episode's first collision is one of its steps; a safe one has none.
        if (e.dangerous) {
          EXPECT_GE(e.first_dangerous_step, 0);
          EXPECT_LT(e.first_dangerous_step, e.steps);
          EXPECT_GE(e.collision_events, 1);
        } else {
          EXPECT_EQ(e.first_dangerous_step, -1);
          EXPECT_EQ(e.collision_events, 0);
        }
      }
      EXPECT_EQ(successes, r.successes);
      EXPECT_EQ(dangerous, r.dangerous);
      EXPECT_EQ(steps, r.steps);
      EXPECT_EQ(events, r.collision_events);
      EXPECT_EQ(interv, r.interventions);
      EXPECT_EQ(no_safe, r.no_safe_action_decisions);
      if (method == Method::kSecure) {
        dangerous_secure += r.dangerous;
        interventions += r.interventions;
      } else {
        EXPECT_EQ(interv, 0);
      }
      // The JSON lists the same episodes.
      const nlohmann::json j = r.ToJson();
      EXPECT_EQ(j.at("dangerous_episodes").get<std::vector<long>>(), r.DangerousEpisodes());
      EXPECT_EQ(j.at("failed_episodes").get<std::vector<long>>(), r.FailedEpisodes());
      EXPECT_EQ(static_cast<long>(r.DangerousEpisodes().size()), r.dangerous);
      EXPECT_EQ(static_cast<long>(r.FailedEpisodes().size()), r.episodes - r.successes);
    }
  }
  // The fixture does what it says: the shield intervenes and still lets some episodes through.
  EXPECT_GT(dangerous_secure, 0);
  EXPECT_GT(interventions, 0);
}

// The CSV: a header, one row per (method, seed, episode) in order, and per method and seed the
// columns sum to the reported counts (so the rates follow).
TEST(EpisodeOutcomesTest, TheCsvHasOneRowPerMethodSeedAndEpisodeSummingToTheRates) {
  const Fixture f;
  const Evaluation evaluation = f.Evaluate(7, 3, 9);
  const std::string csv = EpisodeCsv(evaluation, 7);
  std::istringstream in(csv);
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  EXPECT_EQ(line + "\n", EpisodeCsvHeader());
  std::map<std::pair<std::string, std::uint64_t>, std::vector<long>> sums;  // 6 summed columns
  std::vector<std::string> keys;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) cells.push_back(cell);
    ASSERT_EQ(cells.size(), 10u) << line;
    keys.push_back(cells[0] + "/" + cells[1] + "/" + cells[2]);
    std::vector<long>& s = sums[{cells[0], std::stoull(cells[1])}];
    s.resize(6);
    const int summed[6] = {3, 4, 5, 7, 8, 9};  // all but first_dangerous_step
    for (int j = 0; j < 6; ++j) s[static_cast<std::size_t>(j)] += std::stol(cells[summed[j]]);
  }
  std::vector<std::string> want;
  for (const char* m : {"airl", "secure"})
    for (int seed = 7; seed < 10; ++seed)
      for (int e = 0; e < 9; ++e)
        want.push_back(std::string(m) + "/" + std::to_string(seed) + "/" + std::to_string(e));
  EXPECT_EQ(keys, want);
  for (const auto& [method, summary] : evaluation.methods()) {
    for (std::size_t k = 0; k < summary.per_seed.size(); ++k) {
      const SeedResult& r = summary.per_seed[k];
      const std::vector<long>& s = sums.at({ToString(kMethodNames, method), 7 + k});
      EXPECT_EQ(s, (std::vector<long>{r.successes, r.dangerous, r.steps, r.collision_events,
                                      r.interventions, r.no_safe_action_decisions}));
      EXPECT_DOUBLE_EQ(double(s[0]) / 9.0, r.success_rate());
      EXPECT_DOUBLE_EQ(double(s[1]) / 9.0, r.dangerous_rate());
    }
  }
  // Deterministic: the same evaluation gives the same bytes.
  EXPECT_EQ(EpisodeCsv(f.Evaluate(7, 3, 9), 7), csv);
}

TEST(EpisodeOutcomesTest, TheListsNameEachSeedsDangerousEpisodesAndHowToRenderOne) {
  const Fixture f;
  const Evaluation evaluation = f.Evaluate(3, 2, 12);
  const std::string lists = EpisodeLists(
      evaluation, 3,
      [](Method m, std::uint64_t seed, long episode) {
        return "render " + ToString(kMethodNames, m) + " " + std::to_string(seed) + " " +
               std::to_string(episode);
      },
      3);
  const SeedResult& r = evaluation.methods().at(Method::kSecure).per_seed[1];
  ASSERT_GT(r.dangerous, 0);
  const std::vector<long> d = r.DangerousEpisodes();
  std::ostringstream want;
  want << "secure seed 4: dangerous episodes";
  for (std::size_t i = 0; i < d.size() && i < 3; ++i) want << " " << d[i];
  want << (d.size() > 3 ? " ..." : "") << " (" << d.size() << ")";
  EXPECT_NE(lists.find(want.str()), std::string::npos) << lists;
  EXPECT_NE(lists.find("(render one: render secure 4 " + std::to_string(d.front()) + ")"),
            std::string::npos)
      << lists;
  // Without a render command: the lists alone.
  EXPECT_EQ(EpisodeLists(evaluation, 3, nullptr).find("render one"), std::string::npos);
}

TEST(EpisodeOutcomesTest, AResultWithoutOutcomesIsNamed) {
  SeedResult r;
  r.episodes = 2;  // read back from an old task file: counts, no outcomes
  Evaluation evaluation;
  evaluation.Add(Method::kSecure, r);
  evaluation.Finish();
  EXPECT_FALSE(HasEpisodeOutcomes(evaluation));
  EXPECT_EQ(ErrorOf([&] { EpisodeCsv(evaluation, 5); }),
            "method 'secure', seed 5: no per-episode outcomes (0 of 2 episodes recorded)");
  EXPECT_EQ(EpisodeLists(evaluation, 5, nullptr), "");
  const std::string bad = "a,b";
  std::string csv;
  EXPECT_NE(ErrorOf([&] { AppendEpisodeCsvRows(evaluation, 5, &bad, &csv); }).find("comma"),
            std::string::npos);
}

}  // namespace
}  // namespace secure::eval
