// `secure reproduce` (secure/experiments/reproduce.h): the plan comes from the registry (every
// domain's declared studies, none named here); an experiment study run as two shards and then
// unsharded gives the result of `secure experiment` with the same preset, number for number but
// the timings; the whole quick profile runs and `secure report` makes one page of it.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <set>
#include <string>

#include "tests/apps/cli_run.h"
#include "tests/json_util.h"
#include "tests/test_util.h"

namespace {

namespace fs = std::filesystem;
using secure::test::CliResult;
using secure::test::RunCli;

fs::path Temp(const std::string& name) { return secure::test::CliTempDir() / name; }

std::string Slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// The domains' declared studies, from `secure domains --json` and `secure domains NAME --json`:
// the plan must hold exactly these (ground truth, participants, PaperExperiments are not in the
// listing, so the plan is checked against --list's own per-domain lines for consistency).
TEST(ReproduceTest, PlanListsEveryDomainsStudiesInOrderWithTheirDirectories) {
  const fs::path out = Temp("plan");
  const CliResult r = RunCli("reproduce --profile quick --list --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Every ground-truth domain has Table 1, every domain with participants Table 4.
  const nlohmann::json domains = nlohmann::json::parse(RunCli("domains --json").out)["domains"];
  for (const auto& d : domains) {
    const std::string name = d["name"], caps = d["capabilities"].dump();
    if (caps.find("ground truth") != std::string::npos)
      EXPECT_HAS(r.out, name + " ground-truth (Table 1) " + (out / name / "ground-truth").string());
    if (caps.find("participants") != std::string::npos)
      EXPECT_HAS(r.out, name + " user-study (Table 4) " + (out / name / "user-study").string());
  }
  EXPECT_FALSE(fs::exists(out));  // --list writes nothing
}

// An experiment study as two shards into one directory, then the unsharded run that merges:
// the same result.json as `secure experiment` on the preset (but timings and paths).
TEST(ReproduceTest, ShardsThenAnUnshardedRunGiveTheExperimentsResult) {
  const fs::path out = Temp("sharded"), ref = Temp("reference");
  const std::string args =
      "reproduce --profile quick --threads 1 --domain derby --study method-comparison --out " +
      out.string();
  CliResult r = RunCli(args + " --shard 0/2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "shard 0/2: computed seeds 0, reused none");
  r = RunCli(args + " --shard 1/2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "shard 1/2: computed seeds 1, reused none");
  EXPECT_FALSE(fs::exists(out / "derby/method-comparison/result.json"));
  r = RunCli(args);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("experiment method-comparison --domain derby --quick --threads 1 --out " +
             ref.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json ours = nlohmann::json::parse(Slurp(out / "derby/method-comparison/result.json"));
  nlohmann::json theirs = nlohmann::json::parse(Slurp(ref / "result.json"));
  // The run directory is recorded (models' curve paths); the methods' numbers must be equal.
  EXPECT_EQ(secure::test::WithoutTimings(ours["methods"]),
            secure::test::WithoutTimings(theirs["methods"]));
  EXPECT_EQ(ours["experiment"]["seeds"].size(), 2u);
}

// The whole quick profile: every declared study of every registered domain, then one page.
TEST(ReproduceTest, QuickProfileRunsEveryStudyAndTheReportShowsEveryTable) {
  const fs::path out = Temp("quick");
  const CliResult plan = RunCli("reproduce --profile quick --list --out " + out.string());
  ASSERT_EQ(plan.exit_code, 0) << plan.err;
  CliResult r = RunCli("reproduce --profile quick --json --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json doc = nlohmann::json::parse(r.out);
  std::size_t lines = 0;
  for (char c : plan.out) lines += c == '\n';
  ASSERT_EQ(doc["tasks"].size(), lines);
  std::set<std::string> studies;
  for (const auto& t : doc["tasks"]) {
    studies.insert(t["study"].get<std::string>());
    EXPECT_FALSE(t["table"].get<std::string>().empty()) << t.dump();
    EXPECT_TRUE(fs::exists(out / t["dir"].get<std::string>())) << t.dump();
  }
  for (const char* s : {"ground-truth", "method-comparison", "ablation", "sensitivity", "joint",
                        "user-study"})
    EXPECT_EQ(studies.count(s), 1u) << s << " is declared by no registered domain";
  // A rerun resumes: every one-task study is reused.
  r = RunCli("reproduce --profile quick --json --study ground-truth --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json rerun = nlohmann::json::parse(r.out);
  for (const auto& t : rerun["tasks"]) EXPECT_EQ(t["status"], "reused");
  r = RunCli("reproduce --profile quick --out " + out.string());  // the whole reproduce.json
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("report " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string html = Slurp(out / "report.html");
  for (const auto& t : doc["tasks"])
    EXPECT_HAS(html, t["paper"].get<std::string>() + ": " + t["study"].get<std::string>() +
                         " on " + t["domain"].get<std::string>());
}

}  // namespace
