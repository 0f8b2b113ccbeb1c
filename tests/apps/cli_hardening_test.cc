// End-to-end tests of the `secure` command-line tool (the cli_test program, cli_test.cc):
// hardening (one-line errors, bounded sizes, strict configs, "n/a" figures) and `policy train
// --config` with flags over the file.
#include <string>
#include <utility>
#include <vector>

#include "tests/apps/cli_test_util.h"

namespace {
using namespace secure::test::cli;  // NOLINT(google-build-using-namespace): the files' helpers

// ------------------------------------------------------------------------------------------
// Hardening (helper C): every error is one "secure: error: ..." line with exit code 1, sizes
// are bounded before any work, config files are checked strictly, undefined figures read "n/a".

TEST(CliHardeningTest, AnOutputDirectoryThatIsAFileIsAnErrorNotACrash) {
  const std::string file = Write("not_a_dir", "keep me\n");
  Result r = RunCli("demos generate --domain double-integrator --episodes 2 --out " + file);
  ExpectOneErrorLine(r, "cannot create directory '" + file + "': File exists (not a directory)");
  r = RunCli("demo --quick --seeds 1 --episodes 1 --methods bc --out " + file);
  ExpectOneErrorLine(r, "cannot create directory '" + file + "': File exists (not a directory)");
  EXPECT_EQ(r.err.find("[seed"), std::string::npos) << "failed only after the work: " << r.err;
  EXPECT_EQ(Slurp(file), "keep me\n");
  // A place where no directory can be made (even by root).
  r = RunCli("demos generate --domain double-integrator --episodes 2 --out /proc/secure-cli/x");
  ExpectOneErrorLine(r, "cannot create directory '/proc/secure-cli/x'");
}

TEST(CliHardeningTest, ImpossibleSizesAreRejectedBeforeAnyWork) {
  const std::string cfg = Write("huge_hidden.yaml", "trainer: {hidden: [2000000000]}\n");
  Result r = RunCli("cbf train --domain double-integrator --out " +
                    (TempDir() / "never.model").string() + " --config " + cfg);
  ExpectOneErrorLine(r, "hidden[0] = 2000000000, must be in [1, 10000]");
  EXPECT_FALSE(fs::exists(TempDir() / "never.model"));
  r = RunCli("demo --quick --episodes 2147483648");
  ExpectOneErrorLine(r, "--episodes = 2147483648, must be in [1, 1000000]");
  EXPECT_EQ(r.err.find("[seed"), std::string::npos) << r.err;
  // (command, the error it names)
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"cbf train --domain double-integrator --out x.model --hidden 64,20000",
       "hidden[1] = 20000, must be in [1, 10000]"},
      {"shield run --domain double-integrator --barrier ground-truth --episodes 2147483648",
       "--episodes = 2147483648, must be in [1, 1000000]"},
      {"eval --domain double-integrator --bc /nonexistent.model --episodes 2147483648",
       "--episodes = 2147483648, must be in [1, 1000000]"},
      {"demos generate --domain double-integrator --episodes 2147483648 --out " +
           (TempDir() / "never_dir").string(),
       "--episodes = 2147483648, must be in [1, 1000000]"},
      {"shield run --domain double-integrator --barrier ground-truth --samples 2000000000",
       "num_samples = 2000000000, must be in [1, 1000000]"},
      {"cbf table1 --seeds 0", "--seeds = 0, must be in [1, 10000]"},
      {"cbf train --domain double-integrator --out x.model --safe 100000000000",
       "--safe = 100000000000, must be in [1, 100000000]"},
  };
  for (const auto& [args, needle] : cases) {
    SCOPED_TRACE(args);
    ExpectOneErrorLine(RunCli(args), needle);
  }
  EXPECT_FALSE(fs::exists(TempDir() / "never_dir"));
}

TEST(CliHardeningTest, ConfigFilesAreCheckedStrictly) {
  const std::string base = "cbf train --domain double-integrator --out " +
                           (TempDir() / "never.model").string() + " --config ";
  Result r = RunCli(base + Write("typo.yaml", "trainr:\n  max_epochs: 3\n"));
  ExpectOneErrorLine(
      r,
      "typo.yaml:1: unknown section 'trainr' (known sections: airl, bc, check, coffee_placing, "
      "derby, double_integrator, kitchen_cutting, panda_push, pipeline, toy_cart, trainer)");
  r = RunCli(base + Write("dup.yaml", "trainer:\n  max_epochs: 3\n  max_epochs: 4\n"));
  ExpectOneErrorLine(r, "dup.yaml:3: duplicate key 'max_epochs' (first at line 2)");
  r = RunCli(base + Write("dup_top.yaml", "trainer: {}\ndouble_integrator: {}\ntrainer: {}\n"));
  ExpectOneErrorLine(r, "dup_top.yaml:3: duplicate key 'trainer' (first at line 1)");
  fs::create_directories(TempDir() / "config_dir");
  r = RunCli(base + (TempDir() / "config_dir").string());
  ExpectOneErrorLine(r, "is a directory");
  r = RunCli(base + (TempDir() / "missing.yaml").string());
  ExpectOneErrorLine(r, "cannot open config file");
  EXPECT_FALSE(fs::exists(TempDir() / "never.model"));
}

TEST(CliHardeningTest, ABrokenSectionBreaksOnlyTheCommandsThatUseIt) {
  const std::string bad = Write("bad_trainer.yaml", "trainer:\n  epoch: 3\n");
  Result r = RunCli("--version --config " + bad);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("--help --config " + bad);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("cbf train --help --config " + bad);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  // shield run reads double_integrator:, not trainer:.
  r = RunCli("shield run --domain double-integrator --barrier ground-truth --episodes 2 --config " +
             bad);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("cbf train --domain double-integrator --out x.model --config " + bad);
  ExpectOneErrorLine(r, "unknown field 'epoch'");
  r = RunCli("cbf table1 --config " + bad);
  ExpectOneErrorLine(r, "unknown field 'epoch'");
  // A file that is not YAML at all still lets --version and --help run.
  const std::string garbage = Write("garbage.yaml", "trainer: [unclosed\n");
  EXPECT_EQ(RunCli("--version --config " + garbage).exit_code, 0);
  r = RunCli("shield run --domain double-integrator --barrier ground-truth --config " + garbage);
  ExpectOneErrorLine(r, "invalid YAML");
}

TEST(CliHardeningTest, InvalidValuesAreRejected) {
  WriteToyData();
  const std::string files = "cbf train --safe-states " + (TempDir() / "safe.csv").string() +
                            " --near-dangerous-states " + (TempDir() / "nd.csv").string() +
                            " --out " + (TempDir() / "never.model").string();
  ExpectOneErrorLine(RunCli(files + " --test-fraction -0.1"),
                     "--test-fraction = -0.1, must be in [0, 1)");
  ExpectOneErrorLine(RunCli(files + " --test-fraction nan"), "--test-fraction = nan");
  ExpectOneErrorLine(RunCli(files + " --features x,x"),
                     "--features: feature 'x' is given twice (entries 1 and 2)");
  ExpectOneErrorLine(RunCli(files + " --features x,z"), "'z' not found");
  ExpectOneErrorLine(RunCli(files + " --lr nan"), "learning_rate = nan");
  ExpectOneErrorLine(RunCli(files + " --safe-margin inf"), "safe_margin = inf");
  EXPECT_FALSE(fs::exists(TempDir() / "never.model"));

  ExpectOneErrorLine(RunCli("demo --seeds 0"), "--seeds = 0, must be in [1, 10000]");
  ExpectOneErrorLine(RunCli("demo --episodes 0"), "--episodes = 0, must be in [1, 1000000]");
  ExpectOneErrorLine(RunCli("experiment derby-table3 --quick --seeds 0"), "--seeds = 0");
  ExpectOneErrorLine(RunCli("eval --domain double-integrator --bc x.model --first-seed "
                            "18446744073709551615 --seeds 2"),
                     "the last seed would wrap around to 0");
  ExpectOneErrorLine(RunCli("eval --domain double-integrator --bc x.model --methods ''"),
                     "no method given");
  ExpectOneErrorLine(
      RunCli("shield run --domain double-integrator --barrier ground-truth --policy-sigma nan"),
      "policy_sigma = nan");
  ExpectOneErrorLine(
      RunCli("shield run --domain double-integrator --barrier ground-truth --safe-ratio inf"),
      "safe_ratio = inf");
  ExpectOneErrorLine(RunCli("eval --domain double-integrator --bc x.model --tost-bound inf"),
                     "--tost-bound = inf");
  ExpectOneErrorLine(RunCli("eval --domain double-integrator --bc x.model --probe-extent nan"),
                     "probe_extent = nan");
  ExpectOneErrorLine(RunCli("demos generate --domain double-integrator --rho-max nan --out " +
                            (TempDir() / "never_dir").string()),
                     "rho_max");
  EXPECT_FALSE(fs::exists(TempDir() / "never_dir"));

  // A negative seed would wrap around to 2^64 - 1: every seed flag rejects it.
  for (const std::string& command :
       {files + " --seed -1", std::string("cbf table1 --first-seed -1"),
        std::string("shield run --domain double-integrator --barrier ground-truth --seed -1"),
        std::string("demo --quick --first-seed -1"),
        "demos generate --domain double-integrator --out " + (TempDir() / "never_dir").string() +
            " --seed -1",
        std::string("policy train --algo bc --demos x.csv --out y.model --seed -1"),
        std::string("eval --domain double-integrator --bc x.model --first-seed -1"),
        std::string("experiment derby-table3 --quick --first-seed -1")}) {
    const Result r = RunCli(command);
    EXPECT_EQ(r.exit_code, 1) << command;
    EXPECT_HAS(r.err, "secure: error: ");
    EXPECT_HAS(r.err, "-1 is negative");
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  }
  EXPECT_FALSE(fs::exists(TempDir() / "never_dir"));
}

TEST(CliHardeningTest, MessagesSayWhatIsWrong) {
  WriteToyData();
  const std::string out = " --out " + (TempDir() / "never.model").string();
  // A directory given as a CSV file.
  fs::create_directories(TempDir() / "states_dir");
  Result r = RunCli("cbf train --safe-states " + (TempDir() / "states_dir").string() +
                    " --near-dangerous-states " + (TempDir() / "nd.csv").string() + out);
  ExpectOneErrorLine(r, "states_dir': is a directory");
  EXPECT_EQ(r.err.find("empty"), std::string::npos) << r.err;
  // A binary file: the echoed header is bounded and printable, a NUL does not cut the message.
  std::string binary = "\x7f";
  binary += "ELF\x02\x01";
  binary += std::string(3, '\0') + std::string(20000, 'A') + "\n";
  const std::string bin = Write("binary.csv", binary);
  r = RunCli("cbf train --safe-states " + bin + " --near-dangerous-states " +
             (TempDir() / "nd.csv").string() + " --features x,y" + out);
  ExpectOneErrorLine(r, "binary.csv:1: header column 1 '\\x7FELF\\x02\\x01\\0\\0\\0AAA");
  EXPECT_HAS(r.err, "\u2026' contains a NUL byte");
  EXPECT_LT(r.err.size(), 300u) << r.err;
  EXPECT_FALSE(fs::exists(TempDir() / "never.model"));
}

TEST(CliHardeningTest, UndefinedFiguresReadNotApplicable) {
  // One safe state: the held-out test split of that class is empty, and with validation 0 there
  // is no validation split at all.
  std::string one_safe = "x,y\n0.5,0\n";
  Write("one_safe.csv", one_safe);
  WriteToyData();
  const std::string base = "cbf train --safe-states " + (TempDir() / "one_safe.csv").string() +
                           " --near-dangerous-states " + (TempDir() / "nd.csv").string() +
                           " --features x,y --out " + (TempDir() / "one.model").string() +
                           kFastTrain + " --validation-fraction 0 --test-fraction 0.2";
  Result r = RunCli(base);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "| validation | 0 | 0 | n/a | n/a (no held-out states)");
  EXPECT_HAS(r.out,
             "held-out test: 0 safe, 12 near-dangerous; accuracy safe n/a (no held-out "
             "states), near-dangerous ");
  EXPECT_EQ(r.out.find("nan"), std::string::npos) << r.out;
  r = RunCli(base + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_TRUE(j["test"]["accuracy"]["safe"].is_null());
  EXPECT_TRUE(j["test"]["accuracy"]["balanced"].is_null());
  EXPECT_TRUE(j["test"]["accuracy"]["near_dangerous"].is_number());
  EXPECT_TRUE(j["summary"]["validation_accuracy"].is_null());

  // No episode reaches the goal in 3 steps: there is no mean number of steps to it.
  r = RunCli(
      "shield run --domain double-integrator --barrier ground-truth --episodes 2 "
      "--max-steps 3");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "| mean steps to goal | n/a (no successful episode) |");
}

TEST(CliHardeningTest, ANonFinitePredictionNamesTheInputLine) {
  const std::string model = (TempDir() / "predict.model").string();
  Result r = RunCli(TrainToyArgs(model) + " --activation relu");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Values at the edge of the float range overflow inside the (unbounded, relu) network.
  const std::string states =
      Write("extreme.csv", "x,y\n0.5,0\n3e38,-3e38\n-3e38,3e38\n3e38,3e38\n-3e38,-3e38\n");
  const std::string h = (TempDir() / "h_never.csv").string();
  r = RunCli("cbf predict --model " + model + " --states " + states + " --out " + h);
  ExpectOneErrorLine(r, "extreme.csv:");
  EXPECT_HAS(r.err, "not finite");
  EXPECT_EQ(r.err.find("row"), std::string::npos) << r.err;  // the input line, not an output row
  EXPECT_FALSE(fs::exists(h));
}

// ------------------------------------------------------------------------------------------
// `policy train --config`: flags override the [bc] / [airl] sections, also when a flag's value
// equals the built-in default, and --seed / --curve reach the algorithm that runs.

// The training options recorded in a model file's provenance.
nlohmann::json ModelOptions(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string line;
  std::getline(in, line);  // format line
  std::getline(in, line);  // JSON header
  return nlohmann::json::parse(line)["metadata"]["provenance"]["options"];
}

TEST(CliTest, PolicyTrainFlagsOverrideTheConfigSections) {
  const std::string dir = (TempDir() / "precedence").string();
  Result r = RunCli("demos generate --domain double-integrator --episodes 4 --out " + dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string config =
      Write("precedence.yaml", "bc:\n  epochs: 3\n  seed: 9\nairl:\n  iterations: 1\n  seed: 9\n");
  const std::string base =
      "policy train --config " + config + " --demos " + dir + "/demos.csv --out " + dir;

  r = RunCli(base + "/bc1.model --algo bc");  // the config alone
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json o = ModelOptions(dir + "/bc1.model");
  EXPECT_EQ(o["epochs"], 3);
  EXPECT_EQ(o["seed"], 9);
  r = RunCli(base + "/bc2.model --algo bc --epochs 80 --seed 0");  // flags equal to the defaults
  ASSERT_EQ(r.exit_code, 0) << r.err;
  o = ModelOptions(dir + "/bc2.model");
  EXPECT_EQ(o["epochs"], 80);
  EXPECT_EQ(o["seed"], 0);

  r = RunCli(base + "/airl1.model --algo airl");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  o = ModelOptions(dir + "/airl1.model");
  EXPECT_EQ(o["iterations"], 1);
  EXPECT_EQ(o["seed"], 9);
  r = RunCli(base + "/airl2.model --algo airl --seed 4");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(ModelOptions(dir + "/airl2.model")["seed"], 4);
}

}  // namespace
