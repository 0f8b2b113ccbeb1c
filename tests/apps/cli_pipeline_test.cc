// End-to-end tests of the `secure` command-line tool (the cli_test program, cli_test.cc): the
// SECURE pipeline and its stages from files, HDF5 data, the domains' commands, the user study,
// the derby experiments.
#include "tests/apps/cli_test_util.h"

namespace {
using namespace secure::test::cli;  // NOLINT(google-build-using-namespace): the files' helpers

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
      EXPECT_EQ(Slurp(dir + "/demos_back.csv"), Slurp(dir + "/demos.csv"));
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
  EXPECT_EQ(Slurp((TempDir() / "all.model").string()),
            Slurp((TempDir() / "zero.model").string()));
  EXPECT_EQ(train("five.model", " --patience 5")["options"]["patience"], 5);

  Result r = ExpectRejected(files + "x.model --no-early-stopping --patience 5",
                            "--no-early-stopping and --patience 5");
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
  Result r =
      ExpectRejected("policy train --algo gail --demos x.csv --out y.model", "--algo = 'gail'");
  ExpectRejected("policy train --algo bc --demos /nonexistent/demos.csv --out y.model",
                 "/nonexistent/demos.csv");
  const std::string bad = Write("bad_demos.csv", "episode,step,x,y,vx,vy,ax,ay\n0,0,1,2,3,nan,0,0\n");
  ExpectRejected("policy train --algo bc --demos " + bad + " --out y.model", "vy");
  ExpectRejected("eval --domain double-integrator", "--run DIR");
  ExpectRejected("eval --domain double-integrator --bc /nonexistent.model --methods bc",
                 "/nonexistent.model");
  ExpectRejected("demo --quick --methods bc,foo", "'foo'");
  r = RunCli("demos generate --domain panda --out x");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_HAS(r.err,
             "unknown domain 'panda' (registered: coffee-placing | derby | double-integrator | "
             "kitchen-cutting | panda-push | toy-cart)");
  // A flag the domain does not have is rejected by name (Derby has no slowed copies).
  ExpectRejected("demos generate --domain derby --slowed-copies 2 --out x", "slowed_copies");
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
             "kitchen-cutting | panda-push | toy-cart)");
  ExpectRejected("cbf validate --domain derby --model " + std::string(SECURE_CLI),
                 "the derby domain has no ground truth");
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
  ExpectRejected("demos check-labels --domain double-integrator",
                 "the double-integrator domain has no label check");
  ExpectRejected("demos check-labels --domain panda-push --max-states 0", "--max-states");
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
  ExpectRejected("experiment user-study --quick --spread 0,x",
                 "--spread '0,x': 'x' is not a number in [0, 1]");
  ExpectRejected("experiment user-study --quick --spread 1.5", "'1.5' is not a number in [0, 1]");
  ExpectRejected("experiment user-study --quick --participants 1",
                 "--participants = 1, must be in [2, 1000]");
  ExpectRejected("experiment user-study --quick --domain derby",
                 "--domain derby: the domain has no participants");
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
  Result r =
      ExpectRejected("experiment derby-table3 --quick --barrier convolutional", "'convolutional'");
  ExpectRejected("experiment derby-ablation --quick --episodes -3", "episodes = -3");
  r = RunCli("experiment derby-everything");
  EXPECT_NE(r.exit_code, 0);
}

}  // namespace
