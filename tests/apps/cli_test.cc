// End-to-end tests of the `secure` command-line tool: run the real binary, check exit codes,
// messages and --json documents. This file: help, cbf train / predict from files, configs and
// flags, the double integrator's stages, shield run. The other files of the cli_test program:
// cli_pipeline_test.cc, cli_outputs_test.cc, cli_hardening_test.cc, cli_check_test.cc.
#include "tests/apps/cli_test_util.h"

namespace {
using namespace secure::test::cli;  // NOLINT(google-build-using-namespace): the files' helpers

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
  const std::string model = (TempDir() / "toy.model").string();
  Result r = RunCli(TrainToyArgs(model) + " --test-fraction 0.2 --json");
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
  ExpectRejected("cbf train --safe-states " + safe_csv + " --near-dangerous-states " + nd_csv +
                     " --config " + missing + " --out " + model + " --epochs 1",
                 "has 4 features (extra, y, other, x), without 'z'");
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
  const Result khz =
      ExpectRejected("eval --domain panda-push --airl " + (TempDir() / "none.model").string() +
                         " --methods airl --config " + std::string(SECURE_SOURCE_DIR) +
                         "/configs/panda_push_1khz.yaml",
                     "none.model");
  EXPECT_EQ(khz.err.find("panda_push_1khz.yaml"), std::string::npos) << khz.err;

  // The checked kitchen setting turns the closed-loop check on: with methods it cannot check,
  // the run stops before any work, naming the rule (so the file was read, section and keys).
  ExpectRejected(
      "experiment method-comparison --domain kitchen-cutting --methods bc "
      "--config " +
          std::string(SECURE_SOURCE_DIR) + "/configs/kitchen_cutting_checked.yaml",
      "closed_loop.enabled checks SECURE");
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
  Result r = ExpectRejected("shield run --domain double-integrator --barrier /nonexistent.model",
                            "/nonexistent.model");
  ExpectRejected("shield run --domain double-integrator --barrier ground-truth --samples 0",
                 "num_samples = 0");
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

}  // namespace
