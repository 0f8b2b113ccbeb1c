// The CLI reaches domains only through the registry and their capabilities (docs/ARCHITECTURE.md,
// "Domains are plug-ins"): a command that needs a capability works for every registered domain
// that offers it, lists them in its help, refuses another naming them; the help shows "=preset"
// where a domain's preset applies, and `secure domains NAME` lists those values. Runs the real
// binary; the domains and their capabilities are read from `secure domains --json`, not assumed.
#include <gtest/gtest.h>

#include <algorithm>
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

// The registered domains and their capabilities, as `secure domains --json` lists them.
nlohmann::json Domains() {
  const Result r = RunCli("domains --json");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return nlohmann::json::parse(r.out)["domains"];
}

bool Offers(const nlohmann::json& domain, const std::string& capability) {
  for (const auto& c : domain["capabilities"])
    if (c.get<std::string>().rfind(capability, 0) == 0) return true;
  return false;
}

// "a, b" of the domains offering `capability`, or of those lacking it.
std::vector<std::string> Names(const nlohmann::json& domains, const std::string& capability,
                               bool offering) {
  std::vector<std::string> names;
  for (const auto& d : domains)
    if (Offers(d, capability) == offering) names.push_back(d["name"]);
  return names;
}

std::string Join(const std::vector<std::string>& names) {
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

TEST(CliDomainsTest, ListsEveryDomainWithItsCapabilities) {
  const nlohmann::json domains = Domains();
  ASSERT_GE(domains.size(), 5u);
  for (const char* name :
       {"coffee-placing", "derby", "double-integrator", "kitchen-cutting", "panda-push"}) {
    EXPECT_TRUE(std::any_of(domains.begin(), domains.end(),
                            [&](const nlohmann::json& d) { return d["name"] == name; }))
        << name;
  }
  // What the plug-ins offer today (each domain's README; the example plug-in examples/toy_domain
  // has a ground truth too).
  EXPECT_EQ(Join(Names(domains, "ground truth", true)), "double-integrator, toy-cart");
  EXPECT_EQ(Join(Names(domains, "shield run", true)), "double-integrator");
  EXPECT_EQ(Names(domains, "barrier check", false).size(), 0u);
  const Result text = RunCli("domains");
  ASSERT_EQ(text.exit_code, 0) << text.err;
  EXPECT_HAS(text.out, "double-integrator: ");
  ExpectOneErrorLine(RunCli("domains pendulum"), "unknown domain 'pendulum' (registered: ");
}

// The shield flags of eval and render start from the chosen domain's preset: the help says
// "=preset", not the general default, and `secure domains NAME` prints the values it applies.
TEST(CliDomainsTest, HelpShowsThePresetWhereADomainIsChosen) {
  for (const char* command : {"eval", "render", "shield run"}) {
    const Result r = RunCli(std::string(command) + " --help");
    ASSERT_EQ(r.exit_code, 0) << command;
    EXPECT_HAS(r.out, "--class-k-gain FLOAT=preset");
    EXPECT_HAS(r.out, "--samples INT=preset");
    EXPECT_EQ(r.out.find("FLOAT=1 "), std::string::npos) << command << ":\n" << r.out;
  }
  Result r = RunCli("domains panda-push");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_HAS(r.out, "--class-k-gain 20 ");
  EXPECT_HAS(r.out, "--aggregation policy-mean ");
  EXPECT_HAS(r.out, "--qp-line-search 1 ");  // the gradient-first shield's preset
  EXPECT_HAS(r.out, "--qp-bisection 5 ");
  EXPECT_HAS(r.out, "--qp-max-step 0.5 ");
  EXPECT_HAS(r.out, "--qp-smoothing 2 ");
  r = RunCli("domains panda-push --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_DOUBLE_EQ(j["preset"]["shield"]["class_k_gain"].get<double>(), 20.0);
  EXPECT_FALSE(j.contains("shield_run"));
  EXPECT_EQ(j["observation_features"][0], "ee_x");
  // Panda's preset runs the closed-loop check before deployment (its full profile); --closed-loop
  // 0 turns it off, so the repair that needs it is refused.
  EXPECT_EQ(j["preset"]["closed_loop"]["enabled"], true) << j["preset"].dump();
  EXPECT_EQ(j["preset"]["closed_loop"]["max_candidates"], 4);
  EXPECT_HAS(RunCli("domains panda-push").out, ", closed-loop check {");
  EXPECT_EQ(RunCli("domains derby").out.find("closed-loop check"), std::string::npos);
  const std::string never = (TempDir() / "never_closed_loop").string();
  ExpectOneErrorLine(RunCli("experiment method-comparison --domain panda-push --closed-loop 0 "
                            "--closed-loop-repair 1 --out " + never),
                     "--closed-loop-repair needs the closed-loop check");
  ExpectOneErrorLine(RunCli("experiment method-comparison --domain panda-push --closed-loop -1 "
                            "--out " + never),
                     "--closed-loop = -1, must be in [0, 64]");
  EXPECT_FALSE(fs::exists(never));
  // The double integrator's shield run and ground truth, as `shield run` and `cbf table1` use them.
  r = RunCli("domains double-integrator --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto di = nlohmann::json::parse(r.out);
  EXPECT_EQ(di["shield_run"]["episodes"], 1000);
  EXPECT_EQ(di["ground_truth"]["section"], "double_integrator");
  EXPECT_DOUBLE_EQ(di["ground_truth"]["parameters"]["radius"].get<double>(), 2.0);
  EXPECT_EQ(di["ground_truth"]["trainer_preset"]["max_epochs"], 200);
  // No help names the double integrator's defaults as everyone's.
  for (const char* command : {"cbf check", "cbf train", "cbf validate", "shield run"}) {
    r = RunCli(std::string(command) + " --help");
    EXPECT_EQ(r.out.find("default 5,5"), std::string::npos) << command;
    EXPECT_EQ(r.out.find("double-integrator | derby"), std::string::npos) << command;
  }
}

// A command that needs a capability names the domains that offer it, in its help and in the
// error for one that does not.
TEST(CliDomainsTest, ACapabilityCommandNamesTheDomainsOfferingIt) {
  const nlohmann::json domains = Domains();
  const std::string truth = Join(Names(domains, "ground truth", true));
  const std::string runs = Join(Names(domains, "shield run", true));
  EXPECT_HAS(RunCli("shield run --help").out, "a domain with a shield run: " + runs);
  EXPECT_HAS(RunCli("cbf table1 --help").out, "a domain with a ground truth: " + truth);
  EXPECT_HAS(RunCli("cbf validate --help").out, "a domain with a ground truth: " + truth);
  EXPECT_HAS(RunCli("cbf train --help").out, "a domain's ground truth: " + truth);
  const std::string model = (TempDir() / "m.model").string();
  ASSERT_EQ(RunCli("cbf train --domain double-integrator --safe 30 --unsafe 30 --epochs 1 "
                   "--hidden 4 --out " + model)
                .exit_code,
            0);
  for (const std::string& other : Names(domains, "shield run", false)) {
    ExpectOneErrorLine(RunCli("shield run --domain " + other + " --barrier ground-truth"),
                       "the " + other + " domain has no shield run (domains with one: " + runs +
                           ")");
  }
  const std::vector<std::string> without = Names(domains, "ground truth", false);
  ASSERT_FALSE(without.empty());
  for (const std::string& other : without) {
    ExpectOneErrorLine(RunCli("cbf table1 --domain " + other),
                       "cbf table1: the " + other +
                           " domain has no ground truth (domains with one: " + truth + ")");
  }
  const std::string lacks =
      "the " + without[0] + " domain has no ground truth (domains with one: " + truth + ")";
  ExpectOneErrorLine(RunCli("cbf train --domain " + without[0] + " --out " + model + ".x"),
                     "cbf train --domain: " + lacks);
  ExpectOneErrorLine(RunCli("cbf validate --model " + model + " --domain " + without[0]),
                     "cbf validate: " + lacks);
  EXPECT_FALSE(fs::exists(model + ".x"));
  // The ground-truth section holds only the ground truth's parameters.
  const fs::path cfg = TempDir() / "gt.yaml";
  std::ofstream(cfg) << "double_integrator:\n  radius: 1.5\n  accel_bound: 2\n";
  ExpectOneErrorLine(RunCli("cbf train --domain double-integrator --out " + model +
                            ".y --config " + cfg.string()),
                     "gt.yaml:3: unknown field 'accel_bound' in section double_integrator "
                     "(valid: gamma, obstacle, radius)");
}

// `cbf check --domain NAME` works on every registered domain with a check, found through the
// registry: a small model on two of the domain's observation features (by name), the domain's
// quick profile, a small search.
TEST(CliDomainsTest, CbfCheckRunsOnEveryDomainWithACheck) {
  const nlohmann::json domains = Domains();
  for (const std::string& name : Names(domains, "barrier check", true)) {
    SCOPED_TRACE(name);
    Result r = RunCli("domains " + name + " --json");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto features = nlohmann::json::parse(r.out)["observation_features"];
    ASSERT_GE(features.size(), 2u);
    const std::string a = features[0], b = features[1];
    std::ofstream safe(TempDir() / "safe.csv"), nd(TempDir() / "nd.csv");
    safe << a << "," << b << "\n";
    nd << b << "," << a << "\n";
    for (int i = 0; i < 40; ++i) {
      safe << 0.3 + 0.01 * i << "," << 0.5 << "\n";
      nd << 0.5 << "," << -0.3 - 0.01 * i << "\n";
    }
    safe.close();
    nd.close();
    const std::string model = (TempDir() / (name + ".model")).string();
    r = RunCli("cbf train --safe-states " + (TempDir() / "safe.csv").string() +
               " --near-dangerous-states " + (TempDir() / "nd.csv").string() + " --features " +
               a + "," + b + " --epochs 2 --hidden 4 --out " + model);
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = RunCli("cbf check --model " + model + " --domain " + name +
               " --quick --held-out 10 --region-samples 30 --near-samples 30 --search-starts 1 "
               "--search-steps 1 --json");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j["domain"], name);
    EXPECT_EQ(j["accuracy"]["held_out_safe"], 10);
    EXPECT_TRUE(j["verdict"] == "pass" || j["verdict"] == "flagged") << j["verdict"];
  }
}

}  // namespace
