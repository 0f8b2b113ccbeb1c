// The proof of one folder: the example plug-in, added to the build by one add_subdirectory line
// and changing no other file, is reached by every host through the registry. The real `secure`
// binary lists it (`secure domains`, `--help` texts), takes its config section, checks a barrier
// on it (`cbf check --domain toy-cart`), runs an experiment on it (`secure experiment`), plans
// and runs it in `secure reproduce`, and `secure report` draws the run.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <string>

#include "tests/apps/cli_run.h"
#include "tests/test_util.h"

namespace {

namespace fs = std::filesystem;
using secure::test::CliResult;
using secure::test::ExpectOneErrorLine;
using secure::test::RunCli;

fs::path Temp(const std::string& name) { return secure::test::CliTempDir() / name; }

nlohmann::json ReadJson(const fs::path& path) {
  std::ifstream in(path);
  return nlohmann::json::parse(in);
}

TEST(ToyCartCli, ListedWithItsCapabilitiesAndConfigSection) {
  CliResult r = RunCli("domains --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  bool listed = false;
  const nlohmann::json domains = nlohmann::json::parse(r.out)["domains"];
  for (const auto& d : domains) {
    if (d["name"] != "toy-cart") continue;
    listed = true;
    const std::string capabilities = d["capabilities"].dump();
    EXPECT_HAS(capabilities, "barrier check (cbf check)");
    EXPECT_HAS(capabilities, "ground truth");
  }
  EXPECT_TRUE(listed) << r.out;
  r = RunCli("domains toy-cart --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["config_section"], "toy_cart");
  // The help texts list it from the registry.
  EXPECT_HAS(RunCli("experiment method-comparison --help").out, "toy-cart");
  EXPECT_HAS(RunCli("cbf check --help").out, "toy-cart");
  EXPECT_HAS(RunCli("eval --help").out, "toy-cart");
}

TEST(ToyCartCli, CbfCheckRunsOnABarrierTrainedOnItsGroundTruth) {
  const std::string model = Temp("toy.model").string();
  CliResult r = RunCli("cbf train --domain toy-cart --safe 200 --unsafe 200 --epochs 20 "
                       "--hidden 16 --out " + model);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("cbf check --domain toy-cart --model " + model + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json check = nlohmann::json::parse(r.out);
  EXPECT_HAS(check.dump(), "ground truth h < 0");
  // A model of other features is refused naming them.
  const std::string other = Temp("di.model").string();
  ASSERT_EQ(RunCli("cbf train --domain double-integrator --safe 50 --unsafe 50 --epochs 2 "
                   "--hidden 4 --out " + other).exit_code, 0);
  ExpectOneErrorLine(RunCli("cbf check --domain toy-cart --model " + other), other);
}

TEST(ToyCartCli, ExperimentReadsItsConfigSectionAndTheReportDrawsTheRun) {
  const fs::path config = Temp("toy.yaml"), out = Temp("toy-run");
  std::ofstream(config) << "toy_cart:\n  domain: {demonstrations: 12}\n";
  CliResult r = RunCli("experiment method-comparison --domain toy-cart --quick --seeds 1 "
                       "--episodes 4 --methods bc --json --config " + config.string() +
                       " --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json result = nlohmann::json::parse(r.out);
  EXPECT_EQ(result["experiment"]["domain"], "toy-cart");
  EXPECT_EQ(result["experiment"]["demonstrations"], 12);
  ASSERT_TRUE(fs::exists(out / "result.json"));
  // An unknown key of its section is refused naming the file and the key.
  std::ofstream(config) << "toy_cart:\n  domain: {no_such_key: 1}\n";
  ExpectOneErrorLine(RunCli("experiment method-comparison --domain toy-cart --quick --config " +
                            config.string()),
                     "no_such_key");
  r = RunCli("report " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(out / "report.html"));
}

// `secure reproduce` plans the toy's study of the paper (Table 1: it has a ground truth), runs it
// as a shard, reuses it unsharded, and `secure report` puts its table on the reproduce page.
TEST(ToyCartCli, ReproduceRunsItsStudyShardedResumedAndReported) {
  const fs::path out = Temp("reproduce");
  const std::string args = "reproduce --profile quick --domain toy-cart --out " + out.string();
  CliResult r = RunCli(args + " --list");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out, "toy-cart ground-truth (Table 1) " + (out / "toy-cart/ground-truth").string() +
                       "\n");
  auto status = [](const CliResult& run) {
    EXPECT_EQ(run.exit_code, 0) << run.err;
    return nlohmann::json::parse(run.out)["tasks"].at(0)["status"].get<std::string>();
  };
  EXPECT_EQ(status(RunCli(args + " --shard 1/2 --json")), "other shard");
  EXPECT_FALSE(fs::exists(out / "reproduce.json"));  // only an unsharded run writes it
  EXPECT_EQ(status(RunCli(args + " --shard 0/2 --json")), "computed");
  r = RunCli(args + " --json");
  EXPECT_EQ(status(r), "reused");
  EXPECT_HAS(nlohmann::json::parse(r.out)["tasks"][0]["table"].get<std::string>(),
             "over-conservative");
  ASSERT_TRUE(fs::exists(out / "reproduce.json"));
  EXPECT_EQ(ReadJson(out / "reproduce.json")["tasks"][0]["dir"], "toy-cart/ground-truth");
  r = RunCli("report " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream page(out / "report.html");
  const std::string html((std::istreambuf_iterator<char>(page)), {});
  EXPECT_HAS(html, "Table 1: ground-truth on toy-cart");
  EXPECT_HAS(html, "over-conservative");
  // A study no domain of the filter declares, and an unknown study, are one-line errors.
  ExpectOneErrorLine(RunCli(args + " --study joint"), "no registered domain declares");
  ExpectOneErrorLine(RunCli(args + " --study table9"), "--study 'table9', must be one of");
}

}  // namespace
