// secure cbf query / cbf label / cbf train --augment-from: the active-query round trip on the
// double integrator (query uncertain states, the domain's simulated person labels them, the
// labelled file goes back into training) and its errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "secure/common/atomic_file.h"
#include "secure/common/rng.h"
#include "tests/apps/cli_run.h"
#include "tests/test_util.h"

namespace secure::test {
namespace {

std::string P(const std::string& name) { return (CliTempDir() / name).string(); }

// The double integrator's ground truth with its default geometry (obstacle (5, 5), r 2, gamma 1).
double Truth(double x, double y, double vx, double vy) {
  const double dx = x - 5, dy = y - 5;
  return dx * dx + dy * dy - 4 + 2 * (dx * vx + dy * vy);
}

// Uniform states in the validation box; `labelled`: only those of one class (truth >= 0 or < 0).
void WriteStates(const std::string& path, long n, std::uint64_t seed, int only = -1) {
  Rng rng(seed);
  std::ofstream out(path);
  out << "x,y,vx,vy\n";
  for (long written = 0; written < n;) {
    const double x = rng.Uniform(0, 10), y = rng.Uniform(0, 10), vx = rng.Uniform(-1.5, 1.5),
                 vy = rng.Uniform(-1.5, 1.5);
    const int safe = Truth(x, y, vx, vy) >= 0 ? 1 : 0;
    if (only >= 0 && safe != only) continue;
    out << x << "," << y << "," << vx << "," << vy << "\n";
    ++written;
  }
}

std::vector<std::vector<double>> ReadRows(const std::string& path, std::vector<std::string>* header) {
  std::ifstream in(path);
  std::string line, cell;
  std::getline(in, line);
  std::stringstream hs(line);
  header->clear();
  while (std::getline(hs, cell, ',')) header->push_back(cell);
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    std::stringstream ls(line);
    rows.emplace_back();
    while (std::getline(ls, cell, ',')) rows.back().push_back(std::stod(cell));
  }
  return rows;
}

long Column(const std::vector<std::string>& header, const std::string& name) {
  for (std::size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return static_cast<long>(i);
  ADD_FAILURE() << "no column " << name;
  return 0;
}

// The fraction of rows of `labelled` (with a label column) whose h from `model` has the label's
// sign.
double Agreement(const std::string& model, const std::string& labelled) {
  const std::string h = P("agree_h.csv");
  const CliResult r = RunCli("cbf predict --model " + model + " --states " + labelled + " --out " + h);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  std::vector<std::string> hh, lh;
  const auto hs = ReadRows(h, &hh), ls = ReadRows(labelled, &lh);
  const long label = Column(lh, "label");
  long agree = 0;
  for (std::size_t i = 0; i < hs.size(); ++i)
    agree += ((hs[i][0] >= 0) == (ls[i][static_cast<std::size_t>(label)] == 1));
  return double(agree) / double(hs.size());
}

const char* kFast = " --epochs 60 --batch-size 32 --no-early-stopping --hidden 32,32";

TEST(CliQueryTest, QueryLabelAugmentRetrain) {
  WriteStates(P("safe.csv"), 40, 1, 1);
  WriteStates(P("nd.csv"), 40, 2, 0);
  WriteStates(P("pool.csv"), 3000, 3);
  CliResult r = RunCli("cbf train --safe-states " + P("safe.csv") + " --near-dangerous-states " +
                       P("nd.csv") + " --out " + P("m0.model") + kFast);
  ASSERT_EQ(r.exit_code, 0) << r.err;

  r = RunCli("cbf query --model " + P("m0.model") + " --pool " + P("pool.csv") +
             " --k 60 --strategy margin --radius 0.1 --out " + P("q.csv") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["proposed"], 60);
  std::vector<std::string> header;
  auto rows = ReadRows(P("q.csv"), &header);
  ASSERT_EQ(rows.size(), 60u);
  EXPECT_EQ(header, (std::vector<std::string>{"query", "pool_row", "x", "y", "vx", "vy", "h",
                                              "spread", "score"}));
  std::set<double> pool_rows;
  for (const auto& row : rows) pool_rows.insert(row[1]);
  EXPECT_EQ(pool_rows.size(), 60u);  // distinct pool states
  // Margin: the proposed states are near the model's boundary (|h| small) compared with the pool.
  for (const auto& row : rows) EXPECT_LT(std::abs(row[6]), 1.0);

  // The simulated person (the ground truth) labels them.
  r = RunCli("cbf label --domain double-integrator --states " + P("q.csv") + " --out " +
             P("ql.csv") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  rows = ReadRows(P("ql.csv"), &header);
  ASSERT_EQ(rows.size(), 60u);
  const long label = Column(header, "label");
  long safe = 0;
  for (const auto& row : rows) {
    const int want = Truth(row[2], row[3], row[4], row[5]) >= 0 ? 1 : 0;
    EXPECT_EQ(row[static_cast<std::size_t>(label)], want);
    safe += want;
  }
  const auto lj = nlohmann::json::parse(r.out);
  EXPECT_EQ(lj["safe"], safe);
  EXPECT_EQ(lj["near_dangerous"], 60 - safe);

  // Back into training: each row joins its class.
  r = RunCli("cbf train --safe-states " + P("safe.csv") + " --near-dangerous-states " +
             P("nd.csv") + " --augment-from " + P("ql.csv") + " --out " + P("m1.model") + kFast);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "on " + std::to_string(40 + safe) + " safe + " +
                        std::to_string(40 + 60 - safe) + " near-dangerous states");
  // The retrained barrier agrees with the person on the states asked about more than before.
  const double before = Agreement(P("m0.model"), P("ql.csv"));
  const double after = Agreement(P("m1.model"), P("ql.csv"));
  EXPECT_GT(after, before + 0.1) << before << " -> " << after;
}

TEST(CliQueryTest, EveryStrategyAndTheShieldRelevantPool) {
  WriteStates(P("safe2.csv"), 30, 4, 1);
  WriteStates(P("nd2.csv"), 30, 5, 0);
  WriteStates(P("pool2.csv"), 500, 6);
  for (const char* seed : {"1", "2"})
    ASSERT_EQ(RunCli(std::string("cbf train --safe-states ") + P("safe2.csv") +
                     " --near-dangerous-states " + P("nd2.csv") + " --seed " + seed + " --out " +
                     P(std::string("e") + seed + ".model") + kFast)
                  .exit_code,
              0);
  const std::string ensemble = " --model " + P("e1.model") + " --model " + P("e2.model");
  for (const std::string s : {"margin", "disagreement", "diversity", "random"}) {
    const std::string models = s == "disagreement" ? ensemble : " --model " + P("e1.model");
    const CliResult r = RunCli("cbf query" + models + " --pool " + P("pool2.csv") +
                               " --k 25 --strategy " + s + " --out " + P("q_" + s + ".csv") +
                               " --json");
    ASSERT_EQ(r.exit_code, 0) << s << ": " << r.err;
    const auto rows = nlohmann::json::parse(r.out)["pool_rows"].get<std::vector<long>>();
    EXPECT_EQ(std::set<long>(rows.begin(), rows.end()).size(), 25u) << s;
  }
  // shield-relevant: the pool is what a shielded run of the domain visits.
  const CliResult r = RunCli("cbf query --model " + P("e1.model") +
                             " --domain double-integrator --episodes 5 --k 10 --strategy "
                             "shield-relevant --out " + P("q_shield.csv") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto sj = nlohmann::json::parse(r.out);
  EXPECT_EQ(sj["proposed"], 10);
  EXPECT_GT(sj["pool_states"].get<long>(), 10);
}

TEST(CliQueryTest, ErrorsAreOneLine) {
  WriteStates(P("pool3.csv"), 20, 7);
  ExpectOneErrorLine(RunCli("cbf query --pool " + P("pool3.csv") +
                            " --k 5 --strategy nearest --out " + P("x.csv")),
                     "--strategy = 'nearest', must be one of margin");
  ExpectOneErrorLine(RunCli("cbf query --pool " + P("pool3.csv") + " --k 5 --out " + P("x.csv")),
                     "margin takes one barrier, got 0");
  ExpectOneErrorLine(RunCli("cbf query --pool " + P("pool3.csv") +
                            " --k 50 --strategy random --out " + P("x.csv")),
                     "--k 50 exceeds the 20 states");
  ExpectOneErrorLine(RunCli("cbf label --domain toy-cart --states " + P("pool3.csv") +
                            " --out " + P("x.csv")),
                     "the toy-cart domain has no labeller");
  // A label that is neither 1, 0 nor -1, named with its file and line.
  {
    std::ofstream out(P("bad_label.csv"));
    out << "x,y,vx,vy,label\n1,1,0,0,1\n2,2,0,0,2\n";
  }
  WriteStates(P("s3.csv"), 10, 8, 1);
  WriteStates(P("n3.csv"), 10, 9, 0);
  ExpectOneErrorLine(RunCli("cbf train --safe-states " + P("s3.csv") + " --near-dangerous-states " +
                            P("n3.csv") + " --augment-from " + P("bad_label.csv") + " --out " +
                            P("x.model") + kFast),
                     "bad_label.csv:3: label = 2, must be 1 (safe), 0 (near-dangerous) or -1");
}

// The quick label-efficiency run (slow label): the same curves on 1 or 2 threads, from a resumed
// directory, and from two shards merged by an unsharded rerun; a job file of another experiment
// is an error naming it.
TEST(CliQueryTest, LabelEfficiencyQuickIsDeterministicResumesAndMergesShards) {
  const std::string base =
      "experiment label-efficiency --domain double-integrator --quick --strategies "
      "random,margin,disagreement --json";
  const auto curves = [](const CliResult& r) {
    EXPECT_EQ(r.exit_code, 0) << r.err;
    nlohmann::json c = nlohmann::json::parse(r.out)["curves"];
    for (auto& x : c) x.erase("seconds");
    return c;
  };
  const nlohmann::json one = curves(RunCli(base + " --threads 1 --out " + P("le1")));
  ASSERT_EQ(one.size(), 6u);  // 2 seeds x 3 strategies
  for (const auto& c : one) {
    ASSERT_EQ(c["points"].size(), 3u);  // rounds 0, 1, 2
    EXPECT_EQ(c["points"][2]["labels"], 30);
    EXPECT_GE(c["points"][0]["over_conservative"].get<double>(), 0.0);
    EXPECT_GE(c["points"][2]["dangerous"].get<double>(), 0.0);
  }
  // Every strategy starts from the same labels.
  EXPECT_EQ(one[0]["points"][0], one[1]["points"][0]);
  EXPECT_EQ(curves(RunCli(base + " --threads 2 --out " + P("le2"))), one);
  EXPECT_EQ(curves(RunCli(base + " --threads 1 --out " + P("le1"))), one);  // reused
  EXPECT_TRUE(std::filesystem::exists(P("le1/curves.csv")));
  ASSERT_EQ(RunCli(base + " --shard 0/2 --out " + P("le3")).exit_code, 0);
  EXPECT_FALSE(std::filesystem::exists(P("le3/result.json")));
  ASSERT_EQ(RunCli(base + " --shard 1/2 --out " + P("le3")).exit_code, 0);
  EXPECT_EQ(curves(RunCli(base + " --out " + P("le3"))), one);
  // (after the run's banner line on stderr)
  const CliResult other = RunCli(base + " --k 9 --out " + P("le1"));
  EXPECT_EQ(other.exit_code, 1);
  EXPECT_HAS(other.err, "secure: error: " + P("le1") +
                            "/seed-0/random.json: a job file of another label-efficiency "
                            "experiment");
}

// Derby has no ground truth: its errors are measured only with --errors-from-labeller, then
// against the simulated person's answers (rates in [0, 100]; -1, not measured, without it).
TEST(CliQueryTest, LabelEfficiencyErrorsFromTheLabellerWithoutAGroundTruth) {
  const std::string base =
      "experiment label-efficiency --domain derby --quick --seeds 1 --rounds 1 --strategies "
      "random --eval-states 2000 --threads 1 --json";
  const CliResult plain = RunCli(base);
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  const nlohmann::json p0 = nlohmann::json::parse(plain.out)["curves"][0]["points"][1];
  EXPECT_EQ(p0["over_conservative"].get<double>(), -1.0);
  EXPECT_EQ(p0["under_conservative"].get<double>(), -1.0);
  const CliResult r = RunCli(base + " --errors-from-labeller");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json doc = nlohmann::json::parse(r.out);
  EXPECT_EQ(doc["options"]["errors_from_labeller"], true);
  for (const auto& p : doc["curves"][0]["points"])
    for (const char* m : {"over_conservative", "under_conservative"}) {
      EXPECT_GE(p[m].get<double>(), 0.0) << m;
      EXPECT_LE(p[m].get<double>(), 100.0) << m;
    }
  // The same labels and barriers: only the measure differs.
  EXPECT_EQ(doc["curves"][0]["points"][1]["near_dangerous_labels"], p0["near_dangerous_labels"]);
}

// Derby in closed loop (slow label): the label-efficiency barriers shield a quick method
// comparison's AIRL policies on that run's own evaluation episodes. SECURE over the run's barrier
// and AIRL reproduce the run's per-seed rates exactly (the same models and episodes); every
// document is a `secure eval --json` result that `secure compare` pairs by seed.
TEST(CliQueryTest, LabelEfficiencyDerbyClosedLoopOnARunsPolicies) {
  const CliResult mc = RunCli("experiment method-comparison --domain derby --quick --methods "
                              "airl,secure --threads 1 --out " + P("le_mc"));
  ASSERT_EQ(mc.exit_code, 0) << mc.err;
  const std::string base =
      "experiment label-efficiency --domain derby --quick --barrier per-obstacle --strategies "
      "random,margin --threads 1 --policies-from " + P("le_mc");
  const CliResult r = RunCli(base + " --json --out " + P("le_cl"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json doc = nlohmann::json::parse(r.out);
  EXPECT_EQ(doc["options"]["barrier_kind"], "per-obstacle");
  for (const auto& c : doc["curves"]) {
    for (const auto& p : c["points"]) {
      EXPECT_GE(p["dangerous"].get<double>(), 0.0);
      EXPECT_GE(p["success"].get<double>(), 0.0);
    }
    EXPECT_EQ(c["closed_loop"]["secure"]["episodes"], 10);
  }
  const nlohmann::json run = nlohmann::json::parse(ReadFile(P("le_mc/result.json")));
  for (const char* name : {"random", "margin", "full-labels"}) {
    const std::string path = P("le_cl/closed-loop-") + name + ".json";
    ASSERT_TRUE(std::filesystem::exists(path)) << path;
    const nlohmann::json e = nlohmann::json::parse(ReadFile(path));
    EXPECT_EQ(e["command"], "eval");
    EXPECT_EQ(e["seeds_evaluated"], 2);
    EXPECT_EQ(e["episodes"], 10);
    EXPECT_EQ(e["methods"]["airl"]["success_rate"]["per_seed"],
              run["methods"]["airl"]["success_rate"]["per_seed"]) << name;
    EXPECT_EQ(doc["closed_loop"][name]["methods"]["secure"]["success_rate"],
              e["methods"]["secure"]["success_rate"]);
  }
  const nlohmann::json full = nlohmann::json::parse(ReadFile(P("le_cl/closed-loop-full-labels.json")));
  for (const char* rate : {"success_rate", "dangerous_rate"})
    EXPECT_EQ(full["methods"]["secure"][rate]["per_seed"], run["methods"]["secure"][rate]["per_seed"]);
  const CliResult cmp = RunCli("compare " + P("le_cl/closed-loop-margin.json") + " " +
                               P("le_cl/closed-loop-full-labels.json"));
  EXPECT_EQ(cmp.exit_code, 0) << cmp.err;
  EXPECT_HAS(cmp.out, "secure");
  // A rerun reuses the job files and writes the same documents.
  const std::string margin = ReadFile(P("le_cl/closed-loop-margin.json"));
  ASSERT_EQ(RunCli(base + " --out " + P("le_cl")).exit_code, 0);
  EXPECT_EQ(ReadFile(P("le_cl/closed-loop-margin.json")), margin);
}

// The closed loop's bad input: a run without the seed's policy, a per-obstacle barrier on a
// domain without obstacles, a strategy the domain cannot serve.
TEST(CliQueryTest, LabelEfficiencyClosedLoopErrorsNameTheFileOrField) {
  std::filesystem::create_directories(P("le_empty_run"));
  // (the check runs before the experiment's banner line: the error is the only line)
  ExpectOneErrorLine(
      RunCli("experiment label-efficiency --domain derby --quick --seeds 1 --rounds 0 "
             "--strategies random --threads 1 --policies-from " + P("le_empty_run")),
      "label-efficiency --policies-from " + P("le_empty_run") + ": no " + P("le_empty_run") +
          "/seed-0/airl.model");
  ExpectOneErrorLine(RunCli("experiment label-efficiency --domain double-integrator --quick "
                            "--barrier per-obstacle"),
                     "barrier_kind = per-obstacle");
  ExpectOneErrorLine(RunCli("experiment label-efficiency --domain derby --quick --barrier round"),
                     "--barrier");
  // shield-relevant needs the domain's shielded loop; Derby's driver has none to run.
  ExpectOneErrorLine(RunCli("experiment label-efficiency --domain derby --quick --strategies "
                            "margin,shield-relevant"),
                     "the derby domain has no shield run");
}

}  // namespace
}  // namespace secure::test
