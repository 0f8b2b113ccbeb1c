// End-to-end tests of the `secure` command-line tool (the cli_test program, cli_test.cc):
// `cbf check` and `cbf train --augment-from`, config keys, render of a domain without a
// renderer, --progress.
#include "tests/apps/cli_test_util.h"

namespace {
using namespace secure::test::cli;  // NOLINT(google-build-using-namespace): the files' helpers

// ------------------------------------------------------------------------------------------
// secure cbf check (the pre-deployment barrier check) and cbf train --augment-from.

TEST(CliCbfCheckTest, ChecksASmallTrainedModelWritesTheCsvAndAugmentsTraining) {
  const std::string model = (TempDir() / "check_di.model").string();
  ASSERT_NO_FATAL_FAILURE(
      TrainDoubleIntegratorBarrier("--safe 200 --unsafe 200 --epochs 20 --hidden 16,16", model));
  Result r;
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
  ASSERT_NO_FATAL_FAILURE(
      TrainDoubleIntegratorBarrier("--safe 50 --unsafe 50 --epochs 2 --hidden 4", model));
  Result r;
  // Every built-in domain has a check (Domain::HasCheck), listed from the registry.
  r = RunCli("cbf check --model " + model + " --domain panda");
  ExpectOneErrorLine(
      r,
      "--domain = 'panda', must be one of: coffee-placing, derby, double-integrator, "
      "kitchen-cutting, panda-push, toy-cart");
  EXPECT_HAS(RunCli("cbf check --help").out,
             "a domain with a barrier check: coffee-placing, derby, double-integrator, "
             "kitchen-cutting, panda-push, toy-cart");
  // A model for other features than the domain's observation.
  r = RunCli("cbf check --model " + model + " --domain derby");
  ExpectOneErrorLine(r, "without 'x', which " + model + " reads");
  // The double integrator's task flags are the domain's options: given another domain, that
  // domain rejects them by name; a bad value is the option's error.
  r = RunCli("cbf check --model " + model + " --domain kitchen-cutting --quick --obstacle 3,7");
  ExpectOneErrorLine(r, "unknown key 'obstacle'");
  r = RunCli("cbf check --model " + model + " --domain double-integrator --radius -1");
  ExpectOneErrorLine(r, "ReachAvoidOptions::truth.radius = -1");
  ExpectRejected("cbf check --model " + model + " --domain double-integrator --max-rate-a nan",
                 "no_safe_action = nan");
  const std::string bad = Write("bad_check.csv", "kind,found_by,x,y\nunsafe,sample,1,2\n");
  ExpectRejected(
      "cbf train --domain double-integrator --safe 50 --unsafe 50 --epochs 2 --hidden 4 "
      "--augment-from " +
          bad + " --out " + model,
      "vx");
}

// The obstacle flags and --accel-bound reach the double integrator's check as its task options:
// the ground truth (c) and the action box (the dynamics' description) follow them.
TEST(CliCbfCheckTest, TheDoubleIntegratorsFlagsSetItsTaskOptions) {
  const std::string model = (TempDir() / "check_di_flags.model").string();
  ASSERT_NO_FATAL_FAILURE(
      TrainDoubleIntegratorBarrier("--safe 100 --unsafe 100 --epochs 5 --hidden 8 ", model));
  Result r;
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
  ExpectRejected("cbf train --config " + config + " --safe-states " +
                     (TempDir() / "safe.csv").string() + " --near-dangerous-states " +
                     (TempDir() / "nd.csv").string() + " --out never.model",
                 config + ":2: a key must be a plain name, not a sequence");
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

  ExpectRejected("policy train --algo airl --demos x.csv --out y.model --progress sometimes",
                 "--progress");
}

}  // namespace
