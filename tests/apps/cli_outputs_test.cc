// End-to-end tests of the `secure` command-line tool (the cli_test program, cli_test.cc):
// `policy train` (flags of the other algorithm, --resume), output paths that are not plain files,
// byte-identical model files for a seed, `secure compare`.
#include "tests/apps/cli_test_util.h"

#include <map>
#include <sstream>

namespace {
using namespace secure::test::cli;  // NOLINT(google-build-using-namespace): the files' helpers

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
  ExpectRejected(base + "--algo airl --resume", "--resume needs --checkpoint");
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
  ExpectRejected(train + "--iterations 1 --resume",
                 ckpt + ": checkpoint has 2 completed iterations, more than iterations = 1");
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
  ExpectRejected(train + "--iterations 3 --resume", ckpt + ": checksum mismatch");
  // Truncated.
  std::ofstream(ckpt, std::ios::binary) << bytes.substr(0, bytes.size() - 3);
  r = ExpectRejected(train + "--iterations 3 --resume", ckpt);
  EXPECT_HAS(r.err, "truncated");
}

// ------------------------------------------------------------------------------------------
// Output paths that are not plain files, and byte-identical model files for a seed.

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
  Result r =
      ExpectRejected(TrainToyArgs((dir / "a_directory").string()), (dir / "a_directory").string());
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
// `secure compare`: two `secure eval --json` results of the same episodes, paired by seed.

// A BC policy on the double integrator: 12 demonstrations and DIR/bc.model.
void TrainDoubleIntegratorBc(const std::string& dir, int epochs) {
  Result r = RunCli("demos generate --domain double-integrator --episodes 12 --out " + dir);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("policy train --algo bc --demos " + dir + "/demos.csv --out " + dir +
             "/bc.model --epochs " + std::to_string(epochs));
  ASSERT_EQ(r.exit_code, 0) << r.err;
}

TEST(CliTest, CompareTwoShieldSettingsOnTheSameEpisodes) {
  const std::string dir = (TempDir() / "compare").string();
  ASSERT_NO_FATAL_FAILURE(TrainDoubleIntegratorBc(dir, 3));
  Result r;
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

// ------------------------------------------------------------------------------------------
// `secure eval --episodes-out` (issue 30): one row per method, seed and episode, summing to the
// reported counts; the text output lists the dangerous and failed episodes with a render command.

TEST(CliTest, EvalEpisodesOutHasARowPerEpisodeAndTheListsNameThem) {
  const std::string dir = (TempDir() / "episodes_out").string();
  ASSERT_NO_FATAL_FAILURE(TrainDoubleIntegratorBc(dir, 2));
  Result r;
  const std::string base = "eval --domain double-integrator --bc " + dir +
                           "/bc.model --barrier ground-truth --methods bc,bc+shield --seeds 2 "
                           "--first-seed 5 --episodes 4 --samples 16";
  const std::string csv_path = dir + "/episodes.csv";
  r = RunCli(base + " --json --episodes-out " + csv_path);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  std::ifstream in(csv_path);
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  EXPECT_EQ(line, "method,seed,episode,success,dangerous,steps,first_dangerous_step,"
                  "collision_events,interventions,no_safe_action_decisions");
  std::map<std::string, std::vector<long>> successes, dangerous;  // "method/seed" -> episodes
  int rows = 0;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream row(line);
    for (std::string cell; std::getline(row, cell, ',');) cells.push_back(cell);
    ASSERT_EQ(cells.size(), 10u) << line;
    const std::string key = cells[0] + "/" + cells[1];
    if (cells[3] == "1") successes[key].push_back(std::stol(cells[2]));
    if (cells[4] == "1") dangerous[key].push_back(std::stol(cells[2]));
    ++rows;
  }
  EXPECT_EQ(rows, 2 * 2 * 4);
  long listed = 0;
  for (const char* method : {"bc", "bc+shield"}) {
    for (int k = 0; k < 2; ++k) {
      const nlohmann::json& seed = j["methods"][method]["seeds"][k];
      const std::string key = std::string(method) + "/" + std::to_string(5 + k);
      EXPECT_EQ(static_cast<long>(successes[key].size()), seed["successes"].get<long>()) << key;
      EXPECT_EQ(dangerous[key], seed["dangerous_episodes"].get<std::vector<long>>()) << key;
      EXPECT_EQ(static_cast<long>(seed["failed_episodes"].size()),
                4 - seed["successes"].get<long>());
      listed += static_cast<long>(seed["failed_episodes"].size() + dangerous[key].size());
    }
  }
  // The text output: after the table, a line per seed with dangerous or failed episodes.
  r = RunCli(base);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  if (listed > 0) {
    EXPECT_HAS(r.out, "Dangerous and failed episodes:");
    EXPECT_HAS(r.out, "(render one: secure render --domain double-integrator --policy " + dir +
                          "/bc.model --barrier ground-truth --samples 16 --seed ");
  } else {
    EXPECT_EQ(r.out.find("Dangerous and failed episodes"), std::string::npos);
  }

  // A directory, a file as a directory, a missing directory: one line naming the flag and value,
  // before any episode is played.
  ExpectOneErrorLine(RunCli(base + " --episodes-out " + dir),
                     "--episodes-out = '" + dir + "': a directory, not a file");
  ExpectOneErrorLine(RunCli(base + " --episodes-out " + csv_path + "/x.csv"),
                     "--episodes-out = '" + csv_path + "/x.csv': '" + csv_path +
                         "' is not a directory");
  ExpectOneErrorLine(RunCli(base + " --episodes-out " + dir + "/no/such/x.csv"),
                     "'" + dir + "/no/such' does not exist");
  if (::geteuid() != 0) {  // root may write anywhere
    std::filesystem::create_directories(dir + "/ro");
    std::filesystem::permissions(dir + "/ro", std::filesystem::perms::owner_read |
                                                  std::filesystem::perms::owner_exec);
    ExpectOneErrorLine(RunCli(base + " --episodes-out " + dir + "/ro/x.csv"),
                       "cannot write in '" + dir + "/ro'");
  }
}

// --qp-metric and the config's `shield: {qp_metric: ...}` (eval: the domain's preset, then the
// file, then the flags): written into the shield's options when set, the default writing
// nothing; a bad value is one line naming the flag or the file.
TEST(CliTest, EvalAndShieldRunTakeTheProjectionOptions) {
  const std::string dir = (TempDir() / "qp_metric").string();
  ASSERT_NO_FATAL_FAILURE(TrainDoubleIntegratorBc(dir, 2));
  const std::string cfg = Write("qp_metric.yaml", "pipeline:\n  shield: {qp_metric: policy}\n");
  const std::string base = "eval --domain double-integrator --bc " + dir +
                           "/bc.model --barrier ground-truth --methods bc+shield --seeds 1 "
                           "--episodes 2 --proposal qp-only --json";
  const auto shield_of = [](const Result& r) {
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return r.exit_code == 0 ? nlohmann::json::parse(r.out)["shield"] : nlohmann::json::object();
  };
  EXPECT_FALSE(shield_of(RunCli(base)).contains("qp_metric"));
  EXPECT_EQ(shield_of(RunCli(base + " --config " + cfg))["qp_metric"], "policy");
  EXPECT_EQ(shield_of(RunCli(base + " --qp-metric policy"))["qp_metric"], "policy");
  // The flag wins over the file.
  EXPECT_FALSE(shield_of(RunCli(base + " --config " + cfg + " --qp-metric euclidean"))
                   .contains("qp_metric"));
  // shield run takes the flag too (its double integrator's noisy policy: sigma > 0).
  const Result run = RunCli(
      "shield run --domain double-integrator --barrier ground-truth --episodes 3 --seed 3 --json "
      "--proposal qp-only --qp-metric policy");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  EXPECT_EQ(nlohmann::json::parse(run.out)["options"]["shield"]["qp_metric"], "policy");
  ExpectOneErrorLine(RunCli(base + " --qp-metric mahalanobis"),
                     "--qp-metric = 'mahalanobis', must be one of euclidean, policy");
  const std::string bad =
      Write("qp_metric_bad.yaml", "pipeline:\n  shield: {qp_metric: mahalanobis}\n");
  ExpectOneErrorLine(RunCli(base + " --config " + bad),
                     "qp_metric_bad.yaml [pipeline] [shield] [qp_metric] = 'mahalanobis'");
  // --qp-line-search the same way (flag and file, the flag winning), and checked.
  const std::string search =
      Write("qp_line_search.yaml", "pipeline:\n  shield: {qp_line_search: 2}\n");
  EXPECT_FALSE(shield_of(RunCli(base)).contains("qp_line_search"));
  EXPECT_EQ(shield_of(RunCli(base + " --config " + search))["qp_line_search"], 2);
  EXPECT_EQ(
      shield_of(RunCli(base + " --config " + search + " --qp-line-search 1"))["qp_line_search"], 1);
  ExpectOneErrorLine(RunCli(base + " --qp-line-search 11"), "qp_line_search = 11");
  // --qp-bisection, --qp-smoothing and --qp-target likewise.
  const std::string bisect =
      Write("qp_bisection.yaml", "pipeline:\n  shield: {qp_bisection: 6}\n");
  EXPECT_FALSE(shield_of(RunCli(base)).contains("qp_bisection"));
  EXPECT_EQ(shield_of(RunCli(base + " --config " + bisect))["qp_bisection"], 6);
  EXPECT_EQ(shield_of(RunCli(base + " --config " + bisect + " --qp-bisection 2"))["qp_bisection"],
            2);
  ExpectOneErrorLine(RunCli(base + " --qp-bisection 31"), "qp_bisection = 31");
  // (--qp-smoothing acts with proposal qp only, and is written only there.)
  const std::string first = base.substr(0, base.find("--proposal")) + "--json --proposal qp";
  const std::string smooth =
      Write("qp_smoothing.yaml", "pipeline:\n  shield: {qp_smoothing: 1.5}\n");
  EXPECT_FALSE(shield_of(RunCli(first)).contains("qp_smoothing"));
  EXPECT_FALSE(shield_of(RunCli(base + " --config " + smooth)).contains("qp_smoothing"));
  EXPECT_EQ(shield_of(RunCli(first + " --config " + smooth))["qp_smoothing"], 1.5);
  EXPECT_EQ(shield_of(RunCli(first + " --config " + smooth + " --qp-smoothing 2"))["qp_smoothing"],
            2.0);
  ExpectOneErrorLine(RunCli(base + " --qp-smoothing -1"), "qp_smoothing = -1");
  EXPECT_EQ(shield_of(RunCli(base + " --qp-metric policy --qp-target safe-mean"))["qp_target"],
            "safe-mean");
  ExpectOneErrorLine(RunCli(base + " --qp-target safe-mean"),
                     "qp_target = safe-mean is the mean of the policy's Gaussian");
}

}  // namespace
