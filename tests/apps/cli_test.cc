// End-to-end tests of the `secure` command-line tool: run the real binary, check exit codes,
// messages and --json documents.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/apps/cli_run.h"
#include "tests/test_util.h"

namespace {

namespace fs = std::filesystem;

using Result = secure::test::CliResult;
using secure::test::ExpectOneErrorLine;
using secure::test::RunCli;
fs::path TempDir() { return secure::test::CliTempDir(); }

std::string Write(const std::string& name, const std::string& content) {
  const fs::path p = TempDir() / name;
  std::ofstream(p) << content;
  return p.string();
}

// A separable 2-D data set: safe states have x > 0.2, near-dangerous x < -0.2.
void WriteToyData() {
  std::string safe = "x,y,extra\n", nd = "y,x\n";
  for (int i = 0; i < 60; ++i) {
    const double y = -1.0 + 2.0 * i / 59.0;
    safe += std::to_string(0.3 + 0.01 * i) + "," + std::to_string(y) + ",7\n";
    nd += std::to_string(y) + "," + std::to_string(-0.3 - 0.01 * i) + "\n";
  }
  Write("safe.csv", safe);
  Write("nd.csv", nd);
}

const std::string kFastTrain = " --epochs 30 --hidden 8,8 --lr 0.01 --final-lr 0.001";

TEST(CliTest, HelpListsTheCommands) {
  Result r = RunCli("--help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("cbf"), std::string::npos);
  EXPECT_NE(r.out.find("demo"), std::string::npos);
  r = RunCli("cbf --help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* sub : {"train", "eval", "predict", "table1"})
    EXPECT_NE(r.out.find(sub), std::string::npos) << sub;
  EXPECT_NE(RunCli("").exit_code, 0);  // a command is required
}

TEST(CliTest, TrainFromFilesThenPredict) {
  WriteToyData();
  const std::string model = (TempDir() / "toy.model").string();
  Result r = RunCli("cbf train --safe-states " + (TempDir() / "safe.csv").string() +
                    " --near-dangerous-states " + (TempDir() / "nd.csv").string() +
                    " --features x,y --out " + model + kFastTrain + " --test-fraction 0.2 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["features"], nlohmann::json({"x", "y"}));
  EXPECT_EQ(j["test"]["safe"], 12);
  EXPECT_EQ(j["test"]["near_dangerous"], 12);
  EXPECT_GE(j["test"]["accuracy"]["balanced"].get<double>(), 0.9);
  EXPECT_TRUE(j["context"].contains("git_sha"));

  // predict picks the model's features by name, in any column order.
  const std::string h = (TempDir() / "h.csv").string();
  r = RunCli("cbf predict --model " + model + " --states " + (TempDir() / "nd.csv").string() +
             " --out " + h + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto p = nlohmann::json::parse(r.out);
  EXPECT_EQ(p["rows"], 60);
  EXPECT_LE(p["predicted_safe"].get<int>(), 6);
  std::ifstream in(h);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header, "h,safe");
  int rows = 0;
  for (std::string line; std::getline(in, line);) ++rows;
  EXPECT_EQ(rows, 60);
}

// `trainer: {input_features: [...]}`: the barrier reads some columns of wider training states;
// the model records them, and `cbf predict` reads them by name from a CSV with more columns.
TEST(CliTest, InputFeaturesTrainOnSomeColumnsThenPredictOnWiderStates) {
  std::string safe = "extra,y,other,x\n", nd = "extra,y,other,x\n";
  for (int i = 0; i < 60; ++i) {
    const double y = -1.0 + 2.0 * i / 59.0;
    safe += std::to_string(i % 7) + "," + std::to_string(y) + ",5," + std::to_string(0.3 + 0.01 * i) +
            "\n";
    nd += std::to_string(i % 5) + "," + std::to_string(y) + ",5," +
          std::to_string(-0.3 - 0.01 * i) + "\n";
  }
  const std::string safe_csv = Write("wide_safe.csv", safe), nd_csv = Write("wide_nd.csv", nd);
  const std::string cfg = Write("input_features.yaml", "trainer:\n  input_features: [x, y]\n");
  const std::string model = (TempDir() / "input_features.model").string();
  Result r = RunCli("cbf train --safe-states " + safe_csv + " --near-dangerous-states " + nd_csv +
                    " --config " + cfg + " --out " + model + kFastTrain +
                    " --test-fraction 0.2 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["features"], nlohmann::json({"x", "y"}));
  EXPECT_EQ(j["options"]["input_features"], nlohmann::json({"x", "y"}));
  EXPECT_GE(j["test"]["accuracy"]["balanced"].get<double>(), 0.9);  // on the wide held-out states

  const std::string h = (TempDir() / "input_features_h.csv").string();
  r = RunCli("cbf predict --model " + model + " --states " + nd_csv + " --out " + h + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto p = nlohmann::json::parse(r.out);
  EXPECT_EQ(p["rows"], 60);
  EXPECT_LE(p["predicted_safe"].get<int>(), 6);

  const std::string missing = Write("missing_feature.yaml", "trainer: {input_features: [x, z]}\n");
  r = RunCli("cbf train --safe-states " + safe_csv + " --near-dangerous-states " + nd_csv +
             " --config " + missing + " --out " + model + " --epochs 1");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "has 4 features (extra, y, other, x), without 'z'");
}

// A double-integrator barrier whose inputs are the state's features in another order
// (input_features): `cbf eval` and `cbf check` evaluate it on the domain's states by name.
TEST(CliTest, ABarrierOnReorderedFeaturesIsEvaluatedOnTheDomainsStates) {
  const std::string cfg = Write("reordered.yaml", "trainer: {input_features: [vy, x, vx, y]}\n");
  const std::string model = (TempDir() / "reordered.model").string();
  Result r = RunCli("cbf train --domain double-integrator --safe 100 --unsafe 100 --out " + model +
                    " --config " + cfg + kFastTrain + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["features"], nlohmann::json({"vy", "x", "vx", "y"}));
  r = RunCli("cbf eval --model " + model + " --domain double-integrator --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_GT(nlohmann::json::parse(r.out)["safe_correct"].get<double>(), 0.5);
  r = RunCli("cbf check --model " + model +
             " --domain double-integrator --region-samples 100 --near-samples 100 --held-out 50 "
             "--json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["accuracy"]["held_out_safe"], 50);
}

TEST(CliTest, RejectsBadCsvWithFileLineColumnAndValue) {
  WriteToyData();
  const std::string bad = Write("bad.csv", "x,y\n1,2\n3,nan\n");
  const Result r = RunCli("cbf train --safe-states " + bad + " --near-dangerous-states " +
                          (TempDir() / "nd.csv").string() + " --features x,y --out " +
                          (TempDir() / "never.model").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("bad.csv:3"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("'y'"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("nan"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(TempDir() / "never.model"));
}

TEST(CliTest, RejectsAMissingFeatureColumn) {
  WriteToyData();
  const Result r = RunCli("cbf train --safe-states " + (TempDir() / "safe.csv").string() +
                          " --near-dangerous-states " + (TempDir() / "nd.csv").string() +
                          " --features x,z --out " + (TempDir() / "never.model").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("'z' not found"), std::string::npos) << r.err;
}

TEST(CliTest, RejectsACorruptModel) {
  const std::string model = Write("corrupt.model", "secure-model 1\n{\"kind\": \"barrier_mlp\"");
  const Result r =
      RunCli("cbf predict --model " + model + " --states " + (TempDir() / "nd.csv").string() +
             " --out " + (TempDir() / "h2.csv").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("corrupt.model"), std::string::npos) << r.err;
}

TEST(CliTest, RejectsImpossibleOptions) {
  Result r = RunCli("cbf train --domain double-integrator --out x.model --batch-size 0");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("batch_size = 0, must be > 0"), std::string::npos) << r.err;
  r = RunCli("cbf train --domain double-integrator --out x.model --activation sigmoid");
  EXPECT_NE(r.err.find("sigmoid"), std::string::npos) << r.err;
  r = RunCli("cbf train --domain double-integrator --out x.model --radius -1");
  EXPECT_NE(r.err.find("radius = -1"), std::string::npos) << r.err;
  r = RunCli("cbf train --domain pendulum --out x.model");
  EXPECT_NE(r.err.find("pendulum"), std::string::npos) << r.err;
  r = RunCli("cbf train --domain double-integrator --safe-states a.csv --out x.model");
  EXPECT_EQ(r.exit_code, 1);
  const std::string cfg = Write("bad.yaml", "trainer:\n  epoch: 3\n");
  r = RunCli("cbf train --domain double-integrator --out x.model --config " + cfg);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("unknown field 'epoch'"), std::string::npos) << r.err;
}

TEST(CliTest, ConfigFileIsOverriddenByFlags) {
  WriteToyData();
  const std::string cfg = Write("cfg.yaml", "trainer:\n  max_epochs: 3\n  hidden: [4]\n");
  const Result r = RunCli("cbf train --safe-states " + (TempDir() / "safe.csv").string() +
                          " --near-dangerous-states " + (TempDir() / "nd.csv").string() +
                          " --features x,y --out " + (TempDir() / "cfg.model").string() +
                          " --config " + cfg + " --epochs 2 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["options"]["max_epochs"], 2);                // flag wins
  EXPECT_EQ(j["options"]["hidden"], nlohmann::json({4}));  // from the file
  EXPECT_EQ(j["summary"]["epochs"], 2);
}

TEST(CliTest, DoubleIntegratorTrainEvalAndTable1Json) {
  const std::string model = (TempDir() / "di.model").string();
  Result r = RunCli("cbf train --domain double-integrator --safe 100 --unsafe 100 --out " + model +
                    kFastTrain + " --obstacle 3,7 --radius 1.2 --gamma 0.5");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("cbf eval --model " + model +
             " --domain double-integrator --obstacle 3,7 --radius 1.2 --gamma 0.5 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto e = nlohmann::json::parse(r.out);
  EXPECT_EQ(e["states"], 9000000);
  const double safe_correct = e["safe_correct"], over = e["over_conservative"];
  EXPECT_NEAR(safe_correct + over, 1.0, 1e-12);
  EXPECT_GT(safe_correct, 0.5);  // a real, if briefly trained, barrier

  r = RunCli("cbf table1 --seeds 2 --safe 60 --unsafe 60 --epochs 3 --hidden 8 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto t = nlohmann::json::parse(r.out);
  for (const char* key :
       {"over_conservative", "under_conservative", "safe_correct", "unsafe_correct"}) {
    const double mean = t[key]["mean"], std = t[key]["std"];
    EXPECT_GE(mean, 0.0) << key;
    EXPECT_LE(mean, 1.0) << key;
    EXPECT_GE(std, 0.0) << key;
  }
  EXPECT_EQ(t["per_seed"].size(), 2u);
  EXPECT_NEAR(
      t["safe_correct"]["mean"].get<double>() + t["over_conservative"]["mean"].get<double>(), 1.0,
      1e-12);
}

// The shipped configs parse, and configs/cbf_double_integrator.yaml states the built-in preset.
TEST(CliTest, ShippedConfigsLoadAndTheDoubleIntegratorOneIsThePreset) {
  const std::string cfg = std::string(SECURE_SOURCE_DIR) + "/configs/cbf_double_integrator.yaml";
  const std::string base =
      "cbf train --domain double-integrator --safe 20 --unsafe 20 --json --out " +
      (TempDir() / "preset.model").string();
  Result with = RunCli(base + " --config " + cfg);
  ASSERT_EQ(with.exit_code, 0) << with.err;
  Result without = RunCli(base);
  ASSERT_EQ(without.exit_code, 0) << without.err;
  EXPECT_EQ(nlohmann::json::parse(with.out)["options"],
            nlohmann::json::parse(without.out)["options"]);

  WriteToyData();
  const Result panda = RunCli("cbf train --config " + std::string(SECURE_SOURCE_DIR) +
                              "/configs/cbf_panda_push.yaml --epochs 2 --safe-states " +
                              (TempDir() / "safe.csv").string() + " --near-dangerous-states " +
                              (TempDir() / "nd.csv").string() + " --features x,y --out " +
                              (TempDir() / "p.model").string() + " --json");
  ASSERT_EQ(panda.exit_code, 0) << panda.err;
  EXPECT_DOUBLE_EQ(nlohmann::json::parse(panda.out)["options"]["validation_fraction"].get<double>(),
                   0.25);

  // The Panda 1 kHz shield: read by eval before its models (a missing model is the next error).
  const Result khz = RunCli("eval --domain panda-push --airl " + (TempDir() / "none.model").string() +
                            " --methods airl --config " + std::string(SECURE_SOURCE_DIR) +
                            "/configs/panda_push_1khz.yaml");
  EXPECT_EQ(khz.exit_code, 1);
  EXPECT_HAS(khz.err, "none.model");
  EXPECT_EQ(khz.err.find("panda_push_1khz.yaml"), std::string::npos) << khz.err;

  // The checked kitchen setting turns the closed-loop check on: with methods it cannot check,
  // the run stops before any work, naming the rule (so the file was read, section and keys).
  const Result kitchen = RunCli(
      "experiment method-comparison --domain kitchen-cutting --methods bc "
      "--config " +
      std::string(SECURE_SOURCE_DIR) + "/configs/kitchen_cutting_checked.yaml");
  EXPECT_EQ(kitchen.exit_code, 1);
  EXPECT_HAS(kitchen.err, "closed_loop.enabled checks SECURE");
}

TEST(CliTest, ShieldRunKeepsTheDoubleIntegratorOutOfTheObstacle) {
  Result r = RunCli(
      "shield run --domain double-integrator --barrier ground-truth --episodes 30 --seed 3 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["episodes"], 30);
  EXPECT_EQ(j["dangerous_episodes"], 0);
  EXPECT_GE(j["success_episodes"].get<int>(), 25);
  EXPECT_EQ(j["no_safe_action_decisions"], 0);
  EXPECT_GE(j["latency_us"]["p99"].get<double>(), j["latency_us"]["p50"].get<double>());
  // The same task without the shield does collide: the check is not vacuous.
  r = RunCli(
      "shield run --domain double-integrator --barrier ground-truth --episodes 30 --seed 3 "
      "--unshielded --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_GT(nlohmann::json::parse(r.out)["dangerous_episodes"].get<int>(), 0);
}

TEST(CliTest, ShieldRunRejectsBadInput) {
  Result r = RunCli("shield run --domain double-integrator --barrier /nonexistent.model");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "/nonexistent.model");
  r = RunCli("shield run --domain double-integrator --barrier ground-truth --samples 0");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "num_samples = 0");
  r = RunCli("shield run --domain double-integrator --barrier ground-truth --class-k quartic");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_HAS(r.err, "quartic");
}

TEST(CliTest, ShieldRunTakesTheSampler) {
  for (const char* sampler : {"iid", "antithetic", "qmc"}) {
    const Result r = RunCli(
        std::string("shield run --domain double-integrator --barrier ground-truth --episodes 3 "
                    "--seed 3 --json --sampler ") +
        sampler);
    ASSERT_EQ(r.exit_code, 0) << sampler << ": " << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["options"]["shield"]["sampler"], sampler);
    EXPECT_EQ(j["dangerous_episodes"], 0) << sampler;
  }
  // The default is iid, and it draws what it drew before the option existed.
  const Result plain = RunCli(
      "shield run --domain double-integrator --barrier ground-truth --episodes 3 --seed 3 --json");
  const Result iid = RunCli(
      "shield run --domain double-integrator --barrier ground-truth --episodes 3 --seed 3 --json "
      "--sampler iid");
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  const auto a = nlohmann::json::parse(plain.out), b = nlohmann::json::parse(iid.out);
  EXPECT_EQ(a["options"]["shield"]["sampler"], "iid");
  for (const char* key : {"steps", "interventions", "resampled_decisions", "success_episodes"})
    EXPECT_EQ(a[key], b[key]) << key;
  const Result bad =
      RunCli("shield run --domain double-integrator --barrier ground-truth --sampler sobol");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_HAS(bad.err, "sobol");
  EXPECT_HAS(bad.err, "--sampler");
}

// ------------------------------------------------------------------------------------------
// The SECURE pipeline and its stages.

TEST(CliTest, DemoQuickPrintsTheResultDocument) {
  const Result r = RunCli("demo --quick --seeds 2 --episodes 6 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.err, "[seed 1]");  // progress on stderr
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["command"], "demo");
  for (const char* method : {"bc", "airl", "secure", "secure-random-safe", "secure-no-resampling",
                             "bc+shield"}) {
    ASSERT_TRUE(j["methods"].contains(method)) << method;
    for (const char* metric : {"success_rate", "dangerous_rate"}) {
      const auto& m = j["methods"][method][metric];
      EXPECT_EQ(m["per_seed"].size(), 2u) << method;
      EXPECT_GE(m["mean"].get<double>(), 0.0);
      EXPECT_LE(m["mean"].get<double>(), 1.0);
      EXPECT_GE(m["std"].get<double>(), 0.0);
    }
  }
  EXPECT_TRUE(j["comparisons"]["secure_vs_airl"].contains("success_tost"));
}

TEST(CliTest, EveryStageRunsFromFiles) {
  const std::string dir = (TempDir() / "stages").string();
  Result r = RunCli("demos generate --domain double-integrator --episodes 12 --out " + dir +
                    " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["demonstrations"], 12);
  for (const char* f : {"/demos.csv", "/safe.csv", "/near_dangerous.csv"})
    EXPECT_TRUE(fs::exists(dir + f)) << f;
  r = RunCli("policy train --algo bc --demos " + dir + "/demos.csv --out " + dir +
             "/bc.model --epochs 3 --curve " + dir + "/bc_curve.csv --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir + "/bc_curve.csv"));
  r = RunCli("policy train --algo airl --demos " + dir + "/demos.csv --out " + dir +
             "/airl.model --iterations 2 --warm-start " + dir + "/bc.model --checkpoint " + dir +
             "/airl.ckpt --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(dir + "/airl.ckpt"));
  r = RunCli("cbf train --safe-states " + dir + "/safe.csv --near-dangerous-states " + dir +
             "/near_dangerous.csv --out " + dir + "/barrier.model" + kFastTrain);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("eval --domain double-integrator --bc " + dir + "/bc.model --airl " + dir +
             "/airl.model --barrier " + dir + "/barrier.model --seeds 2 --episodes 3 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["methods"].size(), 6u);
  EXPECT_EQ(j["methods"]["bc+shield"]["success_rate"]["per_seed"].size(), 2u);
  // The ground-truth barrier and a method subset.
  r = RunCli("eval --domain double-integrator --bc " + dir +
             "/bc.model --barrier ground-truth --methods bc+shield --seeds 1 --episodes 3 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["methods"].size(), 1u);
}

// `demos convert`: the double integrator's and Derby's demonstrations to HDF5 (and back to the
// same CSV bytes); BC from the HDF5 file gives the same losses as from the CSV, bit for bit. (The
// data's round trip through the library: tests/domains/expert_test.cc, derby_expert_test.cc.)
std::string FileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(CliTest, DemosConvertToHdf5TrainsIdentically) {
  for (const std::string domain : {"double-integrator", "derby"}) {
    SCOPED_TRACE(domain);
    const std::string dir = (TempDir() / ("h5-" + domain)).string();
    Result r = RunCli("demos generate --domain " + domain +
                      " --episodes 3 --safe-states 20 --near-dangerous 20 --out " + dir);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = RunCli("demos convert " + dir + "/demos.csv " + dir + "/demos.h5 --domain " + domain +
               " --json");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_EQ(nlohmann::json::parse(r.out)["demonstrations"], 3);
    if (domain == "double-integrator") {
      r = RunCli("demos convert " + dir + "/demos.h5 " + dir + "/demos_back.csv");
      ASSERT_EQ(r.exit_code, 0) << r.err;
      EXPECT_EQ(FileBytes(dir + "/demos_back.csv"), FileBytes(dir + "/demos.csv"));
    }
    nlohmann::json bc[2];
    for (int k = 0; k < 2; ++k) {
      r = RunCli("policy train --algo bc --domain " + domain + " --demos " + dir +
                 (k == 0 ? "/demos.csv" : "/demos.h5") + " --epochs 2 --out " + dir + "/bc" +
                 std::to_string(k) + ".model --json");
      ASSERT_EQ(r.exit_code, 0) << r.err;
      bc[k] = nlohmann::json::parse(r.out)["summary"];
      bc[k].erase("wall_seconds");
    }
    EXPECT_EQ(bc[0], bc[1]);
    EXPECT_GT(bc[0]["train_pairs"].get<long>(), 0);
  }
}

// A directory argument ending in '/' (or with "//", "/./") prints and records normalised paths:
// "data/demos.csv", not "data//demos.csv".
TEST(CliTest, DirectoryArgumentsGiveNormalisedPaths) {
  const std::string dir = (TempDir() / "normal").string();
  const std::string generate =
      "demos generate --domain double-integrator --episodes 2 --safe-states 10 "
      "--near-dangerous 10 --out " +
      dir + "/./";
  Result r = RunCli(generate + "/");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.find("//"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("/./"), std::string::npos) << r.out;
  EXPECT_HAS(r.out, " -> " + dir + "/demos.csv\n");
  EXPECT_HAS(r.out, " -> " + dir + "/near_dangerous.csv\n");
  r = RunCli(generate + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["files"],
            nlohmann::json({dir + "/demos.csv", dir + "/safe.csv", dir + "/near_dangerous.csv"}));
}

// `cbf train` from files stops early by default (patience 50 on the held-out score, the best
// epoch's weights kept); --no-early-stopping (= --patience 0) trains every epoch. With --domain,
// and with configs/cbf_panda_push.yaml (what docs/RESULTS.md ran), nothing changes: no early
// stopping, the same model bytes as before.
TEST(CliTest, CbfTrainFromFilesStopsEarlyByDefault) {
  WriteToyData();
  const std::string files = "cbf train --safe-states " + (TempDir() / "safe.csv").string() +
                            " --near-dangerous-states " + (TempDir() / "nd.csv").string() +
                            " --features x,y --hidden 8,8 --epochs 300 --json --out ";
  const auto train = [&](const std::string& name, const std::string& extra) {
    const Result r = RunCli(files + (TempDir() / name).string() + extra);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return r.exit_code == 0 ? nlohmann::json::parse(r.out) : nlohmann::json::object();
  };
  const nlohmann::json early = train("early.model", "");
  EXPECT_EQ(early["options"]["patience"], 50);
  EXPECT_EQ(early["summary"]["stop_reason"], "early_stopping");
  const int epochs = early["summary"]["epochs"].get<int>();
  EXPECT_LT(epochs, 300);
  EXPECT_EQ(epochs, early["summary"]["best_epoch"].get<int>() + 50);
  EXPECT_GE(early["summary"]["validation_accuracy"]["safe"].get<double>(), 0.9);

  const nlohmann::json all = train("all.model", " --no-early-stopping");
  EXPECT_EQ(all["options"]["patience"], 0);
  EXPECT_EQ(all["summary"]["stop_reason"], "max_epochs");
  EXPECT_EQ(all["summary"]["epochs"], 300);
  const nlohmann::json zero = train("zero.model", " --patience 0");
  EXPECT_EQ(zero["summary"]["epochs"], 300);
  EXPECT_EQ(FileBytes((TempDir() / "all.model").string()),
            FileBytes((TempDir() / "zero.model").string()));
  EXPECT_EQ(train("five.model", " --patience 5")["options"]["patience"], 5);

  Result r = RunCli(files + "x.model --no-early-stopping --patience 5");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "--no-early-stopping and --patience 5");
  r = RunCli("cbf train --help");
  EXPECT_HAS(r.out, "--no-early-stopping");
  EXPECT_HAS(r.out, "early stopping is on");

  // The double-integrator preset and the shipped Panda config: every epoch, as before.
  r = RunCli("cbf train --domain double-integrator --safe 30 --unsafe 30 --epochs 25 --json --out " +
             (TempDir() / "di.model").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["options"]["patience"], 0);
  EXPECT_EQ(j["summary"]["epochs"], 25);
  j = train("panda_cfg.model", " --config " + std::string(SECURE_SOURCE_DIR) +
                                   "/configs/cbf_panda_push.yaml");
  EXPECT_EQ(j["options"]["patience"], 0);
  EXPECT_EQ(j["summary"]["stop_reason"], "max_epochs");
  EXPECT_EQ(j["summary"]["epochs"], 300);
}

TEST(CliTest, Hdf5InputErrorsAreOneLineNamingTheFile) {
  const auto expect_error = [](const Result& r, const std::vector<std::string>& parts) {
    EXPECT_EQ(r.exit_code, 1) << r.out;
    for (const std::string& part : parts) EXPECT_HAS(r.err, part);
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  };
  const std::string text = Write("text.h5", "episode,step,x\n0,0,1\n");
  expect_error(RunCli("policy train --algo bc --demos " + text + " --out y.model"),
               {text, "not an HDF5 file"});
  expect_error(RunCli("cbf train --safe-states " + text + " --near-dangerous-states " + text +
                      " --out y.model"),
               {text, "not an HDF5 file"});
  const std::string csv =
      Write("xy_demos.csv", "episode,step,x,y,ax,ay\n0,0,1,2,0,0\n0,1,1,3,0,1\n");
  const std::string h5 = (TempDir() / "xy_demos.h5").string();
  // CSV demonstrations need their action columns named.
  expect_error(RunCli("demos convert " + csv + " " + h5), {csv, "--action-features"});
  const Result r = RunCli("demos convert " + csv + " " + h5 + " --action-features ax,ay");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // The double integrator's default features include vx, which this file lacks.
  expect_error(RunCli("policy train --algo bc --demos " + h5 + " --out y.model"),
               {h5, "data/demo_0/obs", "no key or column 'vx'", "the keys are: x, y"});
  expect_error(RunCli("demos convert " + h5 + " " + h5 + ".txt"), {".txt", "neither CSV"});
}

TEST(CliTest, PipelineStagesRejectBadInput) {
  Result r = RunCli("policy train --algo gail --demos x.csv --out y.model");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "--algo = 'gail'");
  r = RunCli("policy train --algo bc --demos /nonexistent/demos.csv --out y.model");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "/nonexistent/demos.csv");
  const std::string bad = Write("bad_demos.csv", "episode,step,x,y,vx,vy,ax,ay\n0,0,1,2,3,nan,0,0\n");
  r = RunCli("policy train --algo bc --demos " + bad + " --out y.model");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "vy");
  r = RunCli("eval --domain double-integrator");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "--run DIR");
  r = RunCli("eval --domain double-integrator --bc /nonexistent.model --methods bc");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "/nonexistent.model");
  r = RunCli("demo --quick --methods bc,foo");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "'foo'");
  r = RunCli("demos generate --domain panda --out x");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err,
             "unknown domain 'panda' (registered: coffee-placing | derby | double-integrator | "
             "kitchen-cutting | panda-push)");
  // A flag the domain does not have is rejected by name (Derby has no slowed copies).
  r = RunCli("demos generate --domain derby --slowed-copies 2 --out x");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "slowed_copies");
}

// Every command that takes --domain lists the registered domains in its help and its error.
TEST(CliTest, DomainCommandsListTheRegisteredDomains) {
  // (A command that needs a capability, e.g. `cbf validate` a ground truth, lists the domains
  // that offer it: cli_domains_test.cc.)
  for (const std::string command : {"experiment method-comparison", "experiment ablation", "eval",
                                    "demos generate", "policy train"}) {
    const Result help = RunCli(command + " --help");
    EXPECT_EQ(help.exit_code, 0) << command;
    EXPECT_HAS(help.out, "derby | double-integrator");
  }
  const Result r = RunCli("experiment method-comparison --domain unicycle --quick");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err,
             "unknown domain 'unicycle' (registered: coffee-placing | derby | double-integrator | "
             "kitchen-cutting | panda-push)");
  const Result v = RunCli("cbf validate --domain derby --model " + std::string(SECURE_CLI));
  EXPECT_EQ(v.exit_code, 1);
  EXPECT_HAS(v.err, "the derby domain has no ground truth");
}

TEST(CliTest, CheckLabelsSimulatesFromTheLabelledStates) {
  // panda-push simulates forward from each labelled state; rows name the set, its label and the
  // dangerous count. A domain without physics to simulate refuses in one line.
  const Result r = RunCli("demos check-labels --domain panda-push --quick --max-states 4 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["domain"], "panda-push");
  ASSERT_GE(j["rows"].size(), 4u);
  EXPECT_EQ(j["rows"][0]["label"], "safe");
  for (const auto& row : j["rows"]) {
    EXPECT_EQ(row["states"], 4);
    EXPECT_LE(row["dangerous"].get<long>() + row["skipped"].get<long>(), 4);
  }
  const Result di = RunCli("demos check-labels --domain double-integrator");
  EXPECT_EQ(di.exit_code, 1);
  EXPECT_HAS(di.err, "the double-integrator domain has no label check");
  const Result bad = RunCli("demos check-labels --domain panda-push --max-states 0");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_HAS(bad.err, "--max-states");
}

TEST(CliTest, EvalRenderAndCheckLabelsReadTheDomainsOptionsFromTheConfig) {
  // The domain's options come from its config section, key `domain`, in every command that makes
  // the domain (as `secure experiment` reads them): a bad value there stops each with one line
  // naming the file, the field and the value, before any model is read.
  const std::string cfg =
      Write("panda_rollout_bad.yaml", "panda_push:\n  domain:\n    shield_model: {kind: perfect}\n");
  for (const std::string& command :
       {std::string("eval --domain panda-push --airl none.model"),
        std::string("render --domain panda-push --method airl --policy none.model --frames-dir x"),
        std::string("demos check-labels --domain panda-push --quick --max-states 1")}) {
    const Result r = RunCli(command + " --config " + cfg);
    EXPECT_EQ(r.exit_code, 1) << command;
    EXPECT_HAS(r.err, "panda_rollout_bad.yaml");
    EXPECT_HAS(r.err, "kind");
    EXPECT_HAS(r.err, "perfect");
  }
  // A domain option outside `domain:` is rejected as `secure experiment` rejects it, not ignored.
  const std::string misplaced =
      Write("kitchen_misplaced.yaml", "kitchen_cutting:\n  near_dangerous: {p_stroke: 0.4}\n");
  for (const std::string& command :
       {std::string("demos check-labels --domain kitchen-cutting --quick --max-states 1"),
        std::string("experiment method-comparison --domain kitchen-cutting --quick")}) {
    const Result r = RunCli(command + " --config " + misplaced);
    EXPECT_EQ(r.exit_code, 1) << command;
    EXPECT_HAS(r.err, "kitchen_misplaced.yaml [kitchen_cutting]: unknown section 'near_dangerous'");
  }
}

TEST(CliTest, KitchenCuttingRunsTheMethodComparisonAndItsLabelCheck) {
  // The kitchen-cutting plug-in through the generic driver (--quick: small data, short training):
  // the three methods of Table 3 on its episodes, and its labels against physics.
  // One run (the quick profile's training is most of its time): the JSON document on stdout, the
  // task files in a directory that `experiment merge` turns into the text tables.
  const fs::path dir = TempDir() / "kitchen-quick";
  fs::remove_all(dir);
  const Result r = RunCli(
      "experiment method-comparison --domain kitchen-cutting --quick --seeds 1 --episodes 3 "
      "--json --out " + dir.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["experiment"]["domain"], "kitchen-cutting");
  EXPECT_EQ(j["experiment"]["kind"], "method-comparison");
  for (const char* method : {"bc", "airl", "secure"}) {
    ASSERT_TRUE(j["methods"].contains(method)) << method;
    EXPECT_EQ(j["methods"][method]["success_rate"]["per_seed"].size(), 1u);
  }
  // The paper's kitchen row comes with it (Domain::PaperReference), and in the text the run is
  // printed beside it in Table 3's form.
  ASSERT_TRUE(j.contains("paper"));
  ASSERT_EQ(j["paper"]["rows"].size(), 3u);
  EXPECT_EQ(j["paper"]["rows"][2]["method"], "secure");
  EXPECT_EQ(j["paper"]["rows"][2]["success"], 90.0);
  EXPECT_TRUE(j["paper"]["rows"][2]["success_std"].is_null());
  const Result text = RunCli("experiment merge " + dir.string());
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_HAS(text.out, "| Kitchen Cutting | BC | AIRL | SECURE | SECURE vs AIRL |");
  EXPECT_HAS(text.out, "| Success rate % (paper) | 70.0 | 80.0 | 90.0 | +10.0 points |");
  EXPECT_HAS(text.out, "| Dangerous rate % (paper) | 100.0 | 100.0 | 0.0 | -100.0 points |");
  EXPECT_HAS(text.out, "| Success rate % (this run) | ");
  const Result labels =
      RunCli("demos check-labels --domain kitchen-cutting --quick --max-states 4 --json");
  ASSERT_EQ(labels.exit_code, 0) << labels.err;
  const auto l = nlohmann::json::parse(labels.out);
  ASSERT_EQ(l["rows"].size(), 4u);  // safe, then the near-dangerous scenarios (a), (b), (c)
  EXPECT_EQ(l["rows"][0]["label"], "safe");
  for (std::size_t r = 1; r < 4; ++r) EXPECT_EQ(l["rows"][r]["label"], "near-dangerous") << r;
}

TEST(CliTest, UserStudyQuickPrintsTheConditionsBesideThePapersRatings) {
  // The user study of Section 7.2 on the simulated participants (the default domain: the first
  // one with participants, coffee-placing), quick profile: 3 participants x 3 episodes.
  const Result r = RunCli("experiment user-study --quick --json --spread 0,1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.err, "[spread 1.00] participant 2:");
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["command"], "experiment user-study");
  EXPECT_EQ(j["experiment"]["kind"], "user-study");
  EXPECT_EQ(j["experiment"]["domain"], "coffee-placing");
  ASSERT_EQ(j["spreads"].size(), 2u);
  for (const char* metric : {"success", "violations", "over_conservative", "time"}) {
    const auto& m = j["spreads"][1]["metrics"][metric];
    ASSERT_EQ(m["conditions"].size(), 4u) << metric;
    EXPECT_EQ(m["conditions"][0]["per_participant"].size(), 3u);
    EXPECT_EQ(m["posthoc"]["pairs"].size(), 6u);
  }
  EXPECT_EQ(j["paper"]["rows"][1]["values"][2], 35.4);
  const Result text = RunCli("experiment user-study --quick --participants 2 --episodes 1");
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_HAS(text.out, "| (policy, CBF) | (ind, ind) | (ind, grp) | (grp, ind) | (grp, grp) |");
  EXPECT_HAS(text.out, "| Task (paper, Likert rating) | 73.3 | 77.1 | 81.6 | 73.6 |");
  EXPECT_HAS(text.out, "Likert ratings, not rates");
  // Bad options: one line naming the option and the value, exit 1.
  Result bad = RunCli("experiment user-study --quick --spread 0,x");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_HAS(bad.err, "--spread '0,x': 'x' is not a number in [0, 1]");
  bad = RunCli("experiment user-study --quick --spread 1.5");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_HAS(bad.err, "'1.5' is not a number in [0, 1]");
  bad = RunCli("experiment user-study --quick --participants 1");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_HAS(bad.err, "--participants = 1, must be in [2, 1000]");
  bad = RunCli("experiment user-study --quick --domain derby");
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_HAS(bad.err, "--domain derby: the domain has no participants");
}

// ------------------------------------------------------------------------------------------
// The Demolition Derby experiments.

TEST(CliTest, DerbyExperimentQuickPrintsTheResultDocument) {
  const Result r = RunCli("experiment derby-table3 --quick --seeds 1 --episodes 3 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.err, "[seed 0]");
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["command"], "experiment derby-table3");
  EXPECT_EQ(j["experiment"]["kind"], "method-comparison");
  EXPECT_EQ(j["experiment"]["domain"], "derby");
  ASSERT_TRUE(j.contains("paper"));  // Derby gives its Table 3 row (Domain::PaperReference)
  EXPECT_EQ(j["paper"]["rows"][2]["dangerous"], 4.2);
  for (const char* method : {"bc", "airl", "secure"}) {
    ASSERT_TRUE(j["methods"].contains(method)) << method;
    EXPECT_EQ(j["methods"][method]["success_rate"]["per_seed"].size(), 1u);
  }
}

TEST(CliTest, DerbyExperimentRejectsBadOptions) {
  Result r = RunCli("experiment derby-table3 --quick --barrier convolutional");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "'convolutional'");
  r = RunCli("experiment derby-ablation --quick --episodes -3");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "episodes = -3");
  r = RunCli("experiment derby-everything");
  EXPECT_NE(r.exit_code, 0);
}

// ------------------------------------------------------------------------------------------
// `policy train`: flags of the other algorithm, --resume, corrupt checkpoints.

TEST(CliTest, PolicyTrainRejectsFlagsOfTheOtherAlgorithm) {
  // Checked before anything is read: the demonstrations file need not exist.
  const std::string base = "policy train --demos /nonexistent/demos.csv --out never.model ";
  for (const std::string flag :
       {"--checkpoint x.ckpt", "--checkpoint x.ckpt --resume", "--checkpoint-every 5",
        "--iterations 3", "--reward logit-d", "--warm-start bc.model", "--resume"}) {
    const Result r = RunCli(base + "--algo bc " + flag);
    EXPECT_EQ(r.exit_code, 1) << flag;
    EXPECT_HAS(r.err, flag.substr(0, flag.find(' ')) + " applies to --algo airl only");
  }
  for (const std::string flag :
       {"--epochs 3", "--state-features x,y,vx,vy", "--action-features ax,ay"}) {
    const Result r = RunCli(base + "--algo airl " + flag);
    EXPECT_EQ(r.exit_code, 1) << flag;
    EXPECT_HAS(r.err, flag.substr(0, flag.find(' ')) + " applies to --algo bc only");
  }
  const Result r = RunCli(base + "--algo airl --resume");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "--resume needs --checkpoint");
}

TEST(CliTest, PolicyTrainAirlResumeChecksTheCheckpoint) {
  const std::string dir = (TempDir() / "resume").string();
  Result r = RunCli("demos generate --domain double-integrator --episodes 4 --out " + dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string ckpt = dir + "/airl.ckpt";
  const std::string train = "policy train --algo airl --demos " + dir + "/demos.csv --out " + dir +
                            "/airl.model --checkpoint " + ckpt + " --json ";
  // --resume without a checkpoint yet starts from scratch and says so.
  r = RunCli(train + "--iterations 2 --resume");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.err, "no checkpoint yet");
  EXPECT_HAS(r.err, ckpt);
  EXPECT_FALSE(nlohmann::json::parse(r.out)["summary"]["resumed"].get<bool>());
  ASSERT_TRUE(fs::exists(ckpt));

  // Fewer --iterations than the checkpoint has completed: an error, not the longer run's policy.
  r = RunCli(train + "--iterations 1 --resume");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, ckpt + ": checkpoint has 2 completed iterations, more than iterations = 1");
  r = RunCli(train + "--iterations 2 --resume");  // as many: the checkpoint's policy
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(nlohmann::json::parse(r.out)["summary"]["resumed"].get<bool>());

  // One flipped byte in the middle of the checkpoint: an error naming it.
  std::string bytes;
  {
    std::ifstream in(ckpt, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  ASSERT_GT(bytes.size(), 1000u);
  bytes[bytes.size() / 2] = static_cast<char>(bytes[bytes.size() / 2] ^ 0x10);
  std::ofstream(ckpt, std::ios::binary) << bytes;
  r = RunCli(train + "--iterations 3 --resume");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, ckpt + ": checksum mismatch");
  // Truncated.
  std::ofstream(ckpt, std::ios::binary) << bytes.substr(0, bytes.size() - 3);
  r = RunCli(train + "--iterations 3 --resume");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, ckpt);
  EXPECT_HAS(r.err, "truncated");
}

// ------------------------------------------------------------------------------------------
// Output paths that are not plain files, and byte-identical model files for a seed.

std::string TrainToyArgs(const std::string& out) {
  WriteToyData();
  return "cbf train --safe-states " + (TempDir() / "safe.csv").string() +
         " --near-dangerous-states " + (TempDir() / "nd.csv").string() + " --features x,y" +
         kFastTrain + " --out " + out;
}

bool IsCharDevice(const fs::path& p) { return fs::is_character_file(fs::symlink_status(p)); }

TEST(CliTest, PredictToDevNullLeavesItACharacterDevice) {
  const std::string model = (TempDir() / "devnull_toy.model").string();
  Result r = RunCli(TrainToyArgs(model));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  ASSERT_TRUE(IsCharDevice("/dev/null"));
  r = RunCli("cbf predict --model " + model + " --states " + (TempDir() / "nd.csv").string() +
             " --out /dev/null --json");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(IsCharDevice("/dev/null"));
}

TEST(CliTest, TrainOutThroughASymlinkWritesTheTargetAndKeepsTheLink) {
  const fs::path dir = TempDir() / "symlink_out";
  fs::create_directories(dir / "models");
  fs::create_symlink("models/barrier.model", dir / "latest.model");  // dangling: created
  Result r = RunCli(TrainToyArgs((dir / "latest.model").string()));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::is_symlink(dir / "latest.model"));
  ASSERT_TRUE(fs::is_regular_file(fs::symlink_status(dir / "models" / "barrier.model")));
  // Again, now replacing the existing target through the link.
  const auto before = fs::last_write_time(dir / "models" / "barrier.model");
  r = RunCli(TrainToyArgs((dir / "latest.model").string()) + " --seed 5");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::is_symlink(dir / "latest.model"));
  EXPECT_TRUE(fs::is_regular_file(fs::symlink_status(dir / "models" / "barrier.model")));
  EXPECT_GE(fs::last_write_time(dir / "models" / "barrier.model"), before);
  r = RunCli("cbf predict --model " + (dir / "latest.model").string() + " --states " +
             (TempDir() / "nd.csv").string() + " --out " + (dir / "h.csv").string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(std::distance(fs::directory_iterator(dir / "models"), fs::directory_iterator()), 1);
}

TEST(CliTest, TrainOutToADirectoryOrAReaderlessFifoFailsNamingIt) {
  const fs::path dir = TempDir() / "bad_out";
  fs::create_directories(dir / "a_directory");
  Result r = RunCli(TrainToyArgs((dir / "a_directory").string()));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, (dir / "a_directory").string());
  EXPECT_HAS(r.err, "directory");
  EXPECT_TRUE(fs::is_empty(dir / "a_directory"));
  const fs::path fifo = dir / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  r = RunCli(TrainToyArgs(fifo.string()));  // must not hang waiting for a reader
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, fifo.string());
  EXPECT_TRUE(fs::is_fifo(fs::symlink_status(fifo)));
}

TEST(CliTest, SameSeedGivesByteIdenticalModelFilesTimingStaysInTheJson) {
  auto slurp = [](const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  };
  const fs::path dir = TempDir() / "same_seed";
  fs::create_directories(dir);
  for (const char* name : {"a.model", "b.model"}) {
    const Result r = RunCli(TrainToyArgs((dir / name).string()) + " --seed 3 --json");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_TRUE(nlohmann::json::parse(r.out)["summary"].contains("wall_seconds"));
  }
  EXPECT_TRUE(slurp(dir / "a.model") == slurp(dir / "b.model")) << "cbf train --seed 3";

  Result r = RunCli("demos generate --domain double-integrator --episodes 6 --out " +
                    dir.string() + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* name : {"bc_a.model", "bc_b.model"}) {
    r = RunCli("policy train --algo bc --demos " + (dir / "demos.csv").string() + " --out " +
               (dir / name).string() + " --epochs 2 --seed 3 --json");
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  EXPECT_TRUE(slurp(dir / "bc_a.model") == slurp(dir / "bc_b.model")) << "policy train --algo bc";
}

// ------------------------------------------------------------------------------------------
// Hardening (helper C): every error is one "secure: error: ..." line with exit code 1, sizes
// are bounded before any work, config files are checked strictly, undefined figures read "n/a".

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// `secure compare`: two `secure eval --json` results of the same episodes, paired by seed.
TEST(CliTest, CompareTwoShieldSettingsOnTheSameEpisodes) {
  const std::string dir = (TempDir() / "compare").string();
  Result r = RunCli("demos generate --domain double-integrator --episodes 12 --out " + dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("policy train --algo bc --demos " + dir + "/demos.csv --out " + dir +
             "/bc.model --epochs 3");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto eval = [&](const std::string& name, const std::string& flags) {
    const Result e = RunCli("eval --domain double-integrator --bc " + dir +
                            "/bc.model --barrier ground-truth --methods bc,bc+shield --seeds 3 "
                            "--json " +
                            flags);
    EXPECT_EQ(e.exit_code, 0) << e.err;
    return Write(name, e.out);
  };
  const std::string iid = eval("iid.json", "--episodes 4 --samples 32");
  const std::string qmc = eval("qmc.json", "--episodes 4 --samples 16 --sampler qmc");
  const std::string longer = eval("longer.json", "--episodes 5 --samples 32");

  r = RunCli("compare " + qmc + " " + iid + " --tost-bound 0.5 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["seeds"], 3);
  EXPECT_EQ(j["episodes"], 4);
  const std::vector<std::string> differences = j["differences"];
  EXPECT_EQ(differences, (std::vector<std::string>{"shield.num_samples: 16 vs 32",
                                                   "shield.sampler: \"qmc\" vs \"iid\""}));
  for (const char* method : {"bc", "bc+shield"}) {
    const auto& m = j["methods"][method]["success_rate"];
    EXPECT_NEAR(m["difference"].get<double>(),
                m["a_mean"].get<double>() - m["b_mean"].get<double>(), 1e-12);
    if (m["tost"]["se"] == 0.0) {  // equal differences on every seed: exact
      EXPECT_TRUE(m["tost"]["df"].is_null()) << method;
    } else {
      EXPECT_EQ(m["tost"]["df"], 2.0) << method;  // paired: seeds - 1
    }
  }
  // The unshielded policy plays the same episodes: its rates are identical, exactly equivalent.
  EXPECT_EQ(j["methods"]["bc"]["success_rate"]["difference"], 0.0);
  EXPECT_EQ(j["methods"]["bc"]["success_rate"]["equivalent"], true);
  for (const char* method : {"bc", "bc+shield"})  // the policy query, or the whole decision
    for (const char* key : {"a_p50", "b_p50", "a_p99", "b_p99"})
      EXPECT_GT(j["methods"][method]["latency_us"][key].get<double>(), 0.0) << method << key;
  // The table names both files and the settings that differ.
  r = RunCli("compare " + qmc + " " + iid);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "A = " + qmc);
  EXPECT_HAS(r.out, "shield.sampler: \"qmc\" vs \"iid\"");
  EXPECT_HAS(r.out, "| bc+shield | dangerous |");

  // Not the same episodes, not an eval result, not a file: one line each.
  ExpectOneErrorLine(RunCli("compare " + longer + " " + iid),
                     "are not of the same episodes: field 'episodes' is 5 and 4");
  ExpectOneErrorLine(RunCli("compare " + dir + " " + iid), dir + ": not a regular file");
  ExpectOneErrorLine(RunCli("compare " + Write("broken.json", "{\"command\": ") + " " + iid),
                     "broken.json: malformed JSON");
  ExpectOneErrorLine(
      RunCli("compare " + Write("other.json", "{\"command\": \"demo\"}") + " " + iid),
      "other.json: not a `secure eval --json` result");
  ExpectOneErrorLine(RunCli("compare " +
                            Write("old.json",
                                  "{\"command\": \"eval\", \"domain\": "
                                  "\"derby\"}") +
                            " " + iid),
                     "old.json: no field 'first_seed'");
  {  // Edited rates out of [0, 1] (issue 34: 7.0 and -3.0 gave "200.0 %").
    std::ifstream in(iid);
    nlohmann::json edited = nlohmann::json::parse(in);
    for (auto& [method, m] : edited["methods"].items()) {
      for (auto& v : m["success_rate"]["per_seed"]) v = 7.0;
      break;
    }
    ExpectOneErrorLine(RunCli("compare " + Write("edited.json", edited.dump()) + " " + iid),
                       "per_seed' holds 7.0, must be a rate in [0, 1]");
  }
  ExpectOneErrorLine(RunCli("compare " + qmc + " " + iid + " --tost-bound 0"),
                     "--tost-bound = 0, must be in (0, 1)");

  // eval's shield: the domain's preset, then the config's `shield:` key, then the flags.
  const std::string cfg = Write("compare_shield.yaml", "pipeline:\n  shield: {num_samples: 24}\n");
  const std::string base = "eval --domain double-integrator --bc " + dir +
                           "/bc.model --barrier ground-truth --methods bc+shield --seeds 1 "
                           "--episodes 1 --json --config " + cfg;
  r = RunCli(base);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["shield"]["num_samples"], 24);
  r = RunCli(base + " --samples 12");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["shield"]["num_samples"], 12);
  const std::string bad = Write("compare_bad.yaml", "pipeline:\n  shield: {sampler: sobol}\n");
  ExpectOneErrorLine(RunCli("eval --domain double-integrator --bc x.model --config " + bad),
                     "compare_bad.yaml [pipeline] [shield]");
}

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
  r = RunCli("cbf train --domain double-integrator --out x.model --hidden 64,20000");
  ExpectOneErrorLine(r, "hidden[1] = 20000, must be in [1, 10000]");
  r = RunCli("shield run --domain double-integrator --barrier ground-truth --episodes 2147483648");
  ExpectOneErrorLine(r, "--episodes = 2147483648, must be in [1, 1000000]");
  r = RunCli("eval --domain double-integrator --bc /nonexistent.model --episodes 2147483648");
  ExpectOneErrorLine(r, "--episodes = 2147483648, must be in [1, 1000000]");
  r = RunCli("demo --quick --episodes 2147483648");
  ExpectOneErrorLine(r, "--episodes = 2147483648, must be in [1, 1000000]");
  EXPECT_EQ(r.err.find("[seed"), std::string::npos) << r.err;
  r = RunCli("demos generate --domain double-integrator --episodes 2147483648 --out " +
             (TempDir() / "never_dir").string());
  ExpectOneErrorLine(r, "--episodes = 2147483648, must be in [1, 1000000]");
  EXPECT_FALSE(fs::exists(TempDir() / "never_dir"));
  r = RunCli("shield run --domain double-integrator --barrier ground-truth --samples 2000000000");
  ExpectOneErrorLine(r, "num_samples = 2000000000, must be in [1, 1000000]");
  r = RunCli("cbf table1 --seeds 0");
  ExpectOneErrorLine(r, "--seeds = 0, must be in [1, 10000]");
  r = RunCli("cbf train --domain double-integrator --out x.model --safe 100000000000");
  ExpectOneErrorLine(r, "--safe = 100000000000, must be in [1, 100000000]");
}

TEST(CliHardeningTest, ConfigFilesAreCheckedStrictly) {
  const std::string base = "cbf train --domain double-integrator --out " +
                           (TempDir() / "never.model").string() + " --config ";
  Result r = RunCli(base + Write("typo.yaml", "trainr:\n  max_epochs: 3\n"));
  ExpectOneErrorLine(
      r,
      "typo.yaml:1: unknown section 'trainr' (known sections: airl, bc, check, coffee_placing, "
      "derby, double_integrator, kitchen_cutting, panda_push, pipeline, trainer)");
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
  WriteToyData();
  const std::string model = (TempDir() / "predict.model").string();
  Result r = RunCli("cbf train --safe-states " + (TempDir() / "safe.csv").string() +
                    " --near-dangerous-states " + (TempDir() / "nd.csv").string() +
                    " --features x,y --out " + model + kFastTrain + " --activation relu");
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

// ------------------------------------------------------------------------------------------
// secure cbf check (the pre-deployment barrier check) and cbf train --augment-from.

TEST(CliCbfCheckTest, ChecksASmallTrainedModelWritesTheCsvAndAugmentsTraining) {
  const std::string model = (TempDir() / "check_di.model").string();
  Result r = RunCli(
      "cbf train --domain double-integrator --safe 200 --unsafe 200 --epochs 20 "
      "--hidden 16,16 --out " +
      model);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string csv = (TempDir() / "check.csv").string();
  r = RunCli("cbf check --model " + model +
             " --domain double-integrator --region-samples 300 "
             "--near-samples 300 --held-out 100 --out " +
             csv + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["command"], "cbf check");
  EXPECT_TRUE(j["verdict"] == "pass" || j["verdict"] == "flagged") << j["verdict"];
  EXPECT_EQ(j["kinds"]["unsafe"]["checked"].get<long>() > 0, true);
  EXPECT_EQ(j["accuracy"]["held_out_safe"], 100);
  EXPECT_DOUBLE_EQ(j["kinds"]["no_safe_action"]["threshold"].get<double>(), 0.01);
  std::ifstream in(csv);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header, "kind,found_by,x,y,vx,vy,h,objective");
  long rows = 0;
  for (std::string line; std::getline(in, line);) ++rows;
  long expected_rows = 0;
  for (const char* kind : {"no_safe_action", "near_dangerous", "unsafe"})
    expected_rows += j["kinds"][kind]["examples"].get<long>();
  EXPECT_EQ(rows, expected_rows);

  // Thresholds from flags and from a `check:` section; the text report names the verdict.
  const std::string config = Write("check.yaml", "check:\n  thresholds:\n    unsafe: 1.0\n");
  r = RunCli("cbf check --config " + config + " --model " + model +
             " --domain double-integrator --region-samples 200 --near-samples 200 "
             "--held-out 50 --max-rate-b 1 --max-rate-a 1 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto k = nlohmann::json::parse(r.out);
  EXPECT_DOUBLE_EQ(k["kinds"]["unsafe"]["threshold"].get<double>(), 1.0);
  EXPECT_DOUBLE_EQ(k["kinds"]["near_dangerous"]["threshold"].get<double>(), 1.0);
  EXPECT_EQ(k["verdict"], "pass");
  r = RunCli("cbf check --model " + model +
             " --domain double-integrator --region-samples 100 "
             "--near-samples 100 --held-out 50");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "verdict: ");

  // The counterexamples as extra near-dangerous training states.
  const std::string augmented = (TempDir() / "check_di_aug.model").string();
  r = RunCli(
      "cbf train --domain double-integrator --safe 200 --unsafe 200 --epochs 5 "
      "--hidden 8 --augment-from " +
      csv + " --out " + augmented);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "200 safe + " + std::to_string(200 + rows) + " near-dangerous");
}

TEST(CliCbfCheckTest, RejectsAnUnknownDomainAndMismatchedInputs) {
  const std::string model = (TempDir() / "check_bad.model").string();
  Result r = RunCli(
      "cbf train --domain double-integrator --safe 50 --unsafe 50 --epochs 2 "
      "--hidden 4 --out " +
      model);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Every built-in domain has a check (Domain::HasCheck), listed from the registry.
  r = RunCli("cbf check --model " + model + " --domain panda");
  ExpectOneErrorLine(
      r,
      "--domain = 'panda', must be one of: coffee-placing, derby, double-integrator, "
      "kitchen-cutting, panda-push");
  EXPECT_HAS(RunCli("cbf check --help").out,
             "a domain with a barrier check: coffee-placing, derby, double-integrator, "
             "kitchen-cutting, panda-push");
  // A model for other features than the domain's observation.
  r = RunCli("cbf check --model " + model + " --domain derby");
  ExpectOneErrorLine(r, "without 'x', which " + model + " reads");
  // The double integrator's task flags are the domain's options: given another domain, that
  // domain rejects them by name; a bad value is the option's error.
  r = RunCli("cbf check --model " + model + " --domain kitchen-cutting --quick --obstacle 3,7");
  ExpectOneErrorLine(r, "unknown key 'obstacle'");
  r = RunCli("cbf check --model " + model + " --domain double-integrator --radius -1");
  ExpectOneErrorLine(r, "ReachAvoidOptions::truth.radius = -1");
  r = RunCli("cbf check --model " + model + " --domain double-integrator --max-rate-a nan");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "no_safe_action = nan");
  const std::string bad = Write("bad_check.csv", "kind,found_by,x,y\nunsafe,sample,1,2\n");
  r = RunCli(
      "cbf train --domain double-integrator --safe 50 --unsafe 50 --epochs 2 --hidden 4 "
      "--augment-from " +
      bad + " --out " + model);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "vx");
}

// The obstacle flags and --accel-bound reach the double integrator's check as its task options:
// the ground truth (c) and the action box (the dynamics' description) follow them.
TEST(CliCbfCheckTest, TheDoubleIntegratorsFlagsSetItsTaskOptions) {
  const std::string model = (TempDir() / "check_di_flags.model").string();
  Result r = RunCli(
      "cbf train --domain double-integrator --safe 100 --unsafe 100 --epochs 5 --hidden 8 "
      "--out " +
      model);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string check = "cbf check --model " + model +
                            " --domain double-integrator --region-samples 200 --near-samples 100 "
                            "--held-out 50 --json";
  r = RunCli(check);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto base = nlohmann::json::parse(r.out);
  EXPECT_HAS(base["dynamics"].get<std::string>(), "[-3, 3]");
  EXPECT_EQ(base["data_seed"], 1000);  // the domain's experiment data seed
  const std::string config = Write("check_di_truth.yaml", "double_integrator:\n  radius: 3.5\n");
  r = RunCli(check + " --obstacle 5,5 --accel-bound 2 --config " + config);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto moved = nlohmann::json::parse(r.out);
  EXPECT_HAS(moved["dynamics"].get<std::string>(), "[-2, 2]");
  // A larger disc: more of the same region samples are unsafe by the ground truth.
  EXPECT_GT(moved["kinds"]["unsafe"]["checked"].get<long>(),
            base["kinds"]["unsafe"]["checked"].get<long>());
  const std::string bad = Write("check_di_bad.yaml", "double_integrator:\n  goal: [1, 2]\n");
  ExpectOneErrorLine(RunCli(check + " --config " + bad), "unknown field 'goal'");
}

// `cbf check` on each Franka domain (quick profile: its held-out states drawn by its own
// generators): the report has the documented structure, and a small barrier trained on the
// domain's data with the labels swapped (it calls the near-dangerous states safe) is flagged. On
// panda-push also the barrier trained the right way round, which is more accurate.
nlohmann::json CheckReportOf(const std::string& domain, const std::string& model,
                             std::uint64_t data_seed) {
  const Result r = RunCli("cbf check --domain " + domain +
                          " --quick --region-samples 300 --near-samples 300 --held-out 64 "
                          "--json --model " +
                          model);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["command"], "cbf check");
  EXPECT_EQ(j["domain"], domain);
  EXPECT_EQ(j["profile"], "quick");
  EXPECT_EQ(j["data_seed"], data_seed);  // the domain's experiment data seed
  EXPECT_TRUE(j["verdict"] == "pass" || j["verdict"] == "flagged") << j["verdict"];
  EXPECT_EQ(j["accuracy"]["held_out_safe"], 64);
  EXPECT_EQ(j["accuracy"]["held_out_near_dangerous"], 64);
  for (const char* field : {"barrier", "dynamics", "region", "unsafe_test", "class_k"})
    EXPECT_FALSE(j[field].get<std::string>().empty()) << field;
  for (const char* kind : {"no_safe_action", "near_dangerous", "unsafe"}) {
    EXPECT_TRUE(j["kinds"][kind]["available"].get<bool>()) << kind;
    EXPECT_GE(j["kinds"][kind]["rate"].get<double>(), 0.0) << kind;
  }
  EXPECT_EQ(j["kinds"]["near_dangerous"]["checked"], 300);
  EXPECT_EQ(j["options"]["action_grid"], 5);      // the domain's default (its Preset().check)
  EXPECT_DOUBLE_EQ(j["dt"].get<double>(), 0.04);  // its shield's: the control period
  return j;
}

void CheckArmDomain(const std::string& domain, const std::string& generate_flags,
                    const std::string& features, std::uint64_t data_seed, bool also_right) {
  const std::string dir = (TempDir() / ("check_" + domain)).string();
  Result r = RunCli("demos generate --domain " + domain + " --out " + dir + generate_flags);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string safe = dir + "/safe.csv", nd = dir + "/near_dangerous.csv";
  const std::string train = " --features " + features + " --hidden 16,16 --epochs 20" +
                            " --lr 0.01 --final-lr 0.001 --out ";
  const std::string swapped = dir + "/swapped.model";
  r = RunCli("cbf train --safe-states " + nd + " --near-dangerous-states " + safe + train +
             swapped);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json w = CheckReportOf(domain, swapped, data_seed);
  EXPECT_EQ(w["verdict"], "flagged") << w.dump();
  EXPECT_GT(w["kinds"]["near_dangerous"]["rate"].get<double>(),
            w["kinds"]["near_dangerous"]["threshold"].get<double>());
  EXPECT_LT(w["accuracy"]["near_dangerous"].get<double>(), 0.5);
  if (!also_right) return;
  const std::string model = dir + "/barrier.model";
  r = RunCli("cbf train --safe-states " + safe + " --near-dangerous-states " + nd + train + model);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = CheckReportOf(domain, model, data_seed);
  EXPECT_GT(j["kinds"]["no_safe_action"]["checked"].get<long>(), 0);
  EXPECT_GT(j["accuracy"]["near_dangerous"].get<double>(),
            w["accuracy"]["near_dangerous"].get<double>() + 0.3);
  EXPECT_LT(j["kinds"]["near_dangerous"]["rate"].get<double>(),
            w["kinds"]["near_dangerous"]["rate"].get<double>());
}

TEST(CliCbfCheckTest, ChecksPandaPushBarriersAndFlagsOneWithSwappedLabels) {
  // 4 demonstrations: the default 1476 safe states are drawn from their states and copies
  // (3 gave 1470 with the DART brake rate 0.2).
  CheckArmDomain("panda-push", " --episodes 4 --near-dangerous 400",
                 "ee_x,ee_y,ee_z,ee_vx,ee_vy,ee_vz,block_x,block_y,block_z", 3000, true);
}

TEST(CliCbfCheckTest, FlagsAKitchenCuttingBarrierWithSwappedLabels) {
  CheckArmDomain("kitchen-cutting", "",
                 "blade_x,blade_y,blade_z,ee_vx,ee_vy,ee_vz,wrist_x,wrist_y,wrist_z,elbow_x,"
                 "elbow_y,elbow_z,hand_x,hand_y,hand_z,wrist_vx,wrist_vy,wrist_vz,elbow_vx,"
                 "elbow_vy,elbow_vz",
                 4000, false);
}

TEST(CliCbfCheckTest, FlagsACoffeePlacingBarrierWithSwappedLabels) {
  CheckArmDomain("coffee-placing", "",
                 "ee_x,ee_y,ee_z,ee_vx,ee_vy,ee_vz,tilt,wrist_x,wrist_y,wrist_z,hand_x,hand_y,"
                 "hand_z,wrist_vx,wrist_vy,wrist_vz,clearance",
                 5000, false);
}

// Found by yaml_options_fuzz: a key that is a sequence (`? [a, b]`) escaped as yaml-cpp's
// TypedBadConversion; now every options parser says which line holds it.
TEST(CliHardeningTest, AConfigKeyThatIsNotAPlainNameIsAnError) {
  const std::string config = Write("complex_key.yaml", "trainer:\n  ? [a, b]\n  : 1\n");
  WriteToyData();
  const Result r = RunCli("cbf train --config " + config + " --safe-states " +
                          (TempDir() / "safe.csv").string() + " --near-dangerous-states " +
                          (TempDir() / "nd.csv").string() + " --out never.model");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, config + ":2: a key must be a plain name, not a sequence");
}

// secure render: a domain without an offscreen renderer is refused before anything is loaded or
// written (the models named do not exist; no output file appears).
TEST(CliTest, RenderOfADomainThatCannotRenderIsAnError) {
  const std::string out = (TempDir() / "never.mp4").string();
  const std::string frames = (TempDir() / "never_frames").string();
  for (const char* domain : {"double-integrator", "derby"}) {
    const Result r = RunCli(std::string("render --domain ") + domain +
                            " --method secure --policy /nonexistent/airl.model --barrier "
                            "/nonexistent/barrier.model --out " + out + " --frames-dir " + frames);
    ExpectOneErrorLine(r, std::string("the ") + domain +
                              " domain cannot render (no offscreen renderer)");
  }
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(frames));
  const Result help = RunCli("render --help");
  EXPECT_EQ(help.exit_code, 0);
  for (const char* flag : {"--domain", "--method", "--run", "--seed", "--policy", "--barrier",
                           "--episode", "--out", "--frames-dir", "--width", "--height", "--fps",
                           "--no-overlay", "--no-panel"}) {
    EXPECT_HAS(help.out, flag);
  }
}

// --progress: a live line on stderr only when asked (or on a terminal); stdout and the milestone
// lines unchanged.
std::string WithoutDigits(const std::string& s) {
  std::string out;
  for (char c : s)
    if (!std::isdigit(static_cast<unsigned char>(c)) && c != '.' && c != 'e') out += c;
  return out;
}

// The lines a terminal keeps (the text after the last '\r' of each line), digits dropped; the
// live line after the last of them must be cleared.
std::vector<std::string> KeptLines(const std::string& err) {
  std::vector<std::string> lines;
  std::size_t start = 0;
  for (std::size_t nl = err.find('\n'); nl != std::string::npos; nl = err.find('\n', start)) {
    const std::string line = err.substr(start, nl - start);
    lines.push_back(WithoutDigits(
        line.substr(line.rfind('\r') == std::string::npos ? 0 : line.rfind('\r') + 1)));
    start = nl + 1;
  }
  // After the last milestone: nothing, or live lines ending "\r<blanks>\r" (cleared).
  const std::string rest = err.substr(start);
  if (!rest.empty()) {
    EXPECT_EQ(rest.back(), '\r') << rest;
    const std::size_t blank = rest.rfind('\r', rest.size() - 2);
    EXPECT_NE(blank, std::string::npos) << rest;
    if (blank != std::string::npos) {
      EXPECT_EQ(rest.substr(blank + 1, rest.size() - blank - 2).find_first_not_of(' '),
                std::string::npos)
          << rest;
    }
  }
  return lines;
}

TEST(CliTest, ProgressLineOnlyWhenAskedAndOutputOtherwiseUnchanged) {
  // The demo: not a terminal here, so the default is as --progress never.
  const std::string demo = "demo --quick --seeds 1 --episodes 3 --methods bc,airl,secure --json";
  const Result plain = RunCli(demo);
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  EXPECT_EQ(plain.err.find('\r'), std::string::npos);
  EXPECT_HAS(plain.err, "[seed 0] AIRL iteration ");
  EXPECT_HAS(plain.err, "[seed 0] evaluated: ");
  const Result live = RunCli(demo + " --progress always");
  ASSERT_EQ(live.exit_code, 0) << live.err;
  EXPECT_HAS(live.err, "\rexperiment: ");
  EXPECT_HAS(live.err, " elapsed, ");
  EXPECT_HAS(live.err, " left");
  // The same milestone lines (up to their timings) and the same results on stdout.
  EXPECT_EQ(KeptLines(live.err), KeptLines(plain.err));
  auto results = [](const std::string& out) {  // the rates (latencies and seconds are timings)
    nlohmann::json rates;
    const nlohmann::json doc = nlohmann::json::parse(out);  // alive through the loop
    for (const auto& [method, r] : doc.at("methods").items())
      for (const char* key : {"success_rate", "dangerous_rate", "interventions_per_episode"})
        rates[method][key] = r[key];
    return rates;
  };
  EXPECT_EQ(results(live.out), results(plain.out));

  // policy train --algo airl: --progress never keeps stderr as it was; always adds the line.
  const std::string dir = (TempDir() / "progress").string();
  Result r = RunCli("demos generate --domain double-integrator --episodes 4 --out " + dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string train = "policy train --algo airl --demos " + dir + "/demos.csv --out " + dir +
                            "/airl.model --iterations 2 ";
  r = RunCli(train + "--progress never");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err.find('\r'), std::string::npos);
  EXPECT_HAS(r.err, "[airl] it 2/2");
  const std::string never_out = r.out;
  r = RunCli(train + "--progress always");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.err, "\rAIRL iterations: 1/2 (50%), ");
  EXPECT_HAS(r.err, "\r[airl] it 2/2");
  EXPECT_EQ(WithoutDigits(r.out), WithoutDigits(never_out));  // the summary's timings aside
  KeptLines(r.err);                                           // cleared at the end

  r = RunCli("policy train --algo airl --demos x.csv --out y.model --progress sometimes");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err, "--progress");
}

}  // namespace
