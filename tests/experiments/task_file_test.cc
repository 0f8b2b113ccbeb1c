// Task files (seed-K/task.json) are checked when read (issue 34, defect 8): an edited
// `successes = 99` of 3 episodes gave a table with "841.7 %". A task file carries a checksum of
// its content, which a rerun and a merge check; and its counts must be in range even when the
// checksum was recomputed.
#include <boost/crc.hpp>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "domains/double_integrator/domain.h"
#include "secure/common/atomic_file.h"
#include "secure/experiments/experiment.h"
#include "tests/test_util.h"

namespace secure::experiments {
namespace {

using test::ErrorOf;

class TaskFileTest : public test::TempDirTest {
 protected:
  ExperimentOptions Options() const {
    static const domains::double_integrator::DoubleIntegratorDomain domain(Profile::kQuick);
    ExperimentOptions o = domain.Preset();
    o.methods = {eval::Method::kBc};
    o.seeds = 1;
    o.episodes = 3;
    o.bc.epochs = 2;
    o.verbose = false;
    o.output_dir = PathOf("run");
    return o;
  }
  ExperimentResult Run() const {
    static const domains::double_integrator::DoubleIntegratorDomain domain(Profile::kQuick);
    return RunExperiment(ExperimentKind::kMethodComparison, domain, Options(), nullptr);
  }
  std::string Task() const { return PathOf("run/seed-0/task.json"); }
};

std::string Crc(const nlohmann::json& task) {
  nlohmann::json content = task;
  content.erase("checksum");
  const std::string text = content.dump();
  boost::crc_32_type crc;
  crc.process_bytes(text.data(), text.size());
  char hex[9];
  std::snprintf(hex, sizeof hex, "%08x", static_cast<unsigned>(crc.checksum()));
  return std::string("crc32:") + hex;
}

TEST_F(TaskFileTest, AnEditedTaskFileIsRefusedByARerunAndAMerge) {
  Run();
  nlohmann::json task = nlohmann::json::parse(ReadFile(Task()));
  ASSERT_TRUE(task.contains("checksum"));
  EXPECT_EQ(task["checksum"], Crc(task));
  // A rerun reuses the untouched file.
  Run();
  task["results"][0]["bc"]["successes"] = 99;
  WriteFileAtomically(Task(), task.dump(2));
  std::string message = ErrorOf([&] { Run(); });
  EXPECT_HAS(message, Task() + ": checksum");
  EXPECT_HAS(message, "does not match its content");
  EXPECT_HAS(message, "remove it to recompute the seed");
  message = ErrorOf([&] { MergeExperiment({PathOf("run")}); });
  EXPECT_HAS(message, "does not match its content");
  // With the checksum recomputed, the range check still refuses it.
  task["checksum"] = Crc(task);
  WriteFileAtomically(Task(), task.dump(2));
  message = ErrorOf([&] { MergeExperiment({PathOf("run")}); });
  EXPECT_HAS(message, Task() + ": results[0].bc.successes = 99, must be in [0, episodes = 3]");
  task["results"][0]["bc"]["successes"] = -3;
  task["checksum"] = Crc(task);
  WriteFileAtomically(Task(), task.dump(2));
  EXPECT_HAS(ErrorOf([&] { Run(); }), "successes = -3, must be in [0, episodes = 3]");
  // Without a checksum (an older version's file, or one edited by hand).
  task.erase("checksum");
  WriteFileAtomically(Task(), task.dump(2));
  EXPECT_HAS(ErrorOf([&] { Run(); }), Task() + ": no checksum");
}

// Per-episode outcomes (issue 30) travel in the task file: a rerun that reuses it and a merge
// write the same <run>/episodes.csv; edited outcomes that no longer sum to the seed's counts are
// refused; a task file from before they were recorded is still reused, and episodes.csv is then
// not written (and the reason given), never written incomplete.
TEST_F(TaskFileTest, EpisodeOutcomesAreKeptInTheTaskFileAndWrittenAsEpisodesCsv) {
  const ExperimentResult first = Run();
  ASSERT_TRUE(first.HasEpisodeOutcomes());
  const std::string csv = ReadFile(PathOf("run/episodes.csv"));
  EXPECT_EQ(csv, first.EpisodesCsv());
  EXPECT_EQ(csv.substr(0, csv.find('\n')),
            "method,seed,episode,success,dangerous,steps,first_dangerous_step,collision_events,"
            "interventions,no_safe_action_decisions");
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 1 + 3);  // bc, seed 0, 3 episodes
  std::filesystem::remove(PathOf("run/episodes.csv"));
  Run();  // reused from the task file
  EXPECT_EQ(ReadFile(PathOf("run/episodes.csv")), csv);
  EXPECT_EQ(MergeExperiment({PathOf("run")}).EpisodesCsv(), csv);

  nlohmann::json task = nlohmann::json::parse(ReadFile(Task()));
  nlohmann::json& steps = task["results"][0]["bc"]["episode_outcomes"]["steps"];
  ASSERT_EQ(steps.size(), 3u);
  steps[0] = steps[0].get<long>() + 1;
  task["checksum"] = Crc(task);
  WriteFileAtomically(Task(), task.dump(2));
  EXPECT_HAS(ErrorOf([&] { MergeExperiment({PathOf("run")}); }),
             Task() + ": results[0].bc: episode_outcomes.steps sum to");

  task["results"][0]["bc"].erase("episode_outcomes");
  task["checksum"] = Crc(task);
  WriteFileAtomically(Task(), task.dump(2));
  std::filesystem::remove(PathOf("run/episodes.csv"));
  const ExperimentResult old = Run();
  EXPECT_FALSE(old.HasEpisodeOutcomes());
  EXPECT_FALSE(std::filesystem::exists(PathOf("run/episodes.csv")));
  EXPECT_HAS(WriteEpisodesFile(old, PathOf("run")), "episodes.csv not written");
  EXPECT_HAS(ErrorOf([&] { old.EpisodesCsv(); }), "no per-episode outcomes");
}

// Issue 34, item 11: a task.json that is a directory, and a seed-K that is a dangling symbolic
// link, are named as what they are (not a JSON "unexpected end of input", not "File exists").
TEST_F(TaskFileTest, ATaskFileThatIsADirectoryAndADanglingSeedLinkAreNamed) {
  std::filesystem::create_directories(Task());
  std::string message = ErrorOf([&] { Run(); });
  EXPECT_HAS(message, Task());
  EXPECT_HAS(message, "is a directory, not a regular file");
  message = ErrorOf([&] { MergeExperiment({PathOf("run")}); });
  EXPECT_HAS(message, Task());
  EXPECT_HAS(message, "is a directory, not a regular file");
  std::filesystem::remove_all(PathOf("run"));
  std::filesystem::create_directories(PathOf("run"));
  std::filesystem::create_directory_symlink(PathOf("elsewhere"), PathOf("run/seed-0"));
  message = ErrorOf([&] { Run(); });
  EXPECT_HAS(message, PathOf("run/seed-0"));
  EXPECT_HAS(message, "dangling symbolic link");
  EXPECT_EQ(message.find('\n'), std::string::npos) << message;
}

}  // namespace
}  // namespace secure::experiments
