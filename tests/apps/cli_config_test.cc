// End-to-end tests of the `secure` command-line tool (the cli_test program, cli_test.cc): one
// reader of a domain's config section (experiments::ReadSection). One file gives the same shield
// to `secure experiment`, `eval` and `cbf check`, and a flag given overrides the file in each.
#include <string>
#include <utility>
#include <vector>

#include "tests/apps/cli_test_util.h"

namespace {
using namespace secure::test::cli;  // NOLINT(google-build-using-namespace): the files' helpers

// The double integrator's models for eval and check, trained once: a BC policy and a barrier.
struct Models {
  std::string dir, bc, barrier;
};
const Models& TrainedModels() {
  static const Models models = [] {
    Models m;
    m.dir = (TempDir() / "config_section").string();
    Result r = RunCli("demos generate --domain double-integrator --episodes 6 --out " + m.dir);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    m.bc = m.dir + "/bc.model";
    r = RunCli("policy train --algo bc --demos " + m.dir + "/demos.csv --epochs 2 --out " + m.bc);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    m.barrier = m.dir + "/barrier.model";
    r = RunCli("cbf train --domain double-integrator --safe 100 --unsafe 100 --epochs 5 "
               "--hidden 8 --out " + m.barrier);
    EXPECT_EQ(r.exit_code, 0) << r.err;
    return m;
  }();
  return models;
}

// The shield each command used, from its --json document: {class_k_gain, num_samples} where the
// command reports them (cbf check reports the class-K function as text, "linear, k = 5.000000").
struct ShieldSeen {
  double class_k_gain = 0;
  long num_samples = -1;  // -1: not reported
};

ShieldSeen Experiment(const std::string& args) {
  const Result r = RunCli(
      "experiment method-comparison --domain double-integrator --quick --seeds 1 --episodes 1 "
      "--methods bc --json" + args);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json shield = nlohmann::json::parse(r.out)["experiment"]["options"]["shield"];
  return {shield["class_k_gain"].get<double>(), shield["num_samples"].get<long>()};
}

ShieldSeen Eval(const std::string& args) {
  const Models& m = TrainedModels();
  const Result r = RunCli("eval --domain double-integrator --bc " + m.bc + " --barrier " +
                          m.barrier + " --methods bc+shield --seeds 1 --episodes 1 --json" + args);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json shield = nlohmann::json::parse(r.out)["shield"];
  return {shield["class_k_gain"].get<double>(), shield["num_samples"].get<long>()};
}

ShieldSeen Check(const std::string& args) {
  const Models& m = TrainedModels();
  const Result r = RunCli("cbf check --domain double-integrator --model " + m.barrier +
                          " --region-samples 50 --near-samples 20 --held-out 20 --json" + args);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const std::string class_k = nlohmann::json::parse(r.out)["class_k"].get<std::string>();
  const std::size_t at = class_k.find("k = ");
  EXPECT_NE(at, std::string::npos) << class_k;
  return {at == std::string::npos ? 0.0 : std::stod(class_k.substr(at + 4)), -1};
}

// Each command's shield given `args`, by command name.
std::vector<std::pair<std::string, ShieldSeen>> EveryCommand(const std::string& args) {
  return {{"experiment", Experiment(args)}, {"eval", Eval(args)}, {"cbf check", Check(args)}};
}

TEST(CliConfigTest, OneSectionGivesTheSameShieldToExperimentEvalAndCheck) {
  // The double integrator's section is `pipeline` (Domain::ConfigSection).
  const std::string config =
      Write("one_section.yaml", "pipeline:\n  shield: {class_k_gain: 5, num_samples: 48}\n");
  // Without the file every command starts from the same preset (which the file changes).
  const auto presets = EveryCommand("");
  const double preset = presets.front().second.class_k_gain;
  ASSERT_NE(preset, 5.0);
  for (const auto& [command, seen] : presets) EXPECT_EQ(seen.class_k_gain, preset) << command;
  for (const auto& [command, seen] : EveryCommand(" --config " + config)) {
    EXPECT_EQ(seen.class_k_gain, 5.0) << command;
    if (seen.num_samples >= 0) EXPECT_EQ(seen.num_samples, 48) << command;
  }
}

TEST(CliConfigTest, AFlagGivenOverridesTheFileInEachCommand) {
  const std::string config =
      Write("overridden.yaml", "pipeline:\n  shield: {class_k_gain: 5, num_samples: 48}\n");
  for (const auto& [command, seen] : EveryCommand(" --config " + config + " --class-k-gain 3")) {
    EXPECT_EQ(seen.class_k_gain, 3.0) << command;
    // A field whose flag is not given keeps the file's value.
    if (seen.num_samples >= 0) EXPECT_EQ(seen.num_samples, 48) << command;
  }
}

TEST(CliConfigTest, HelpSaysTheDomainsPresetWhereItGivesTheDefault) {
  // The shield flags' defaults come from the chosen domain's preset (`secure domains NAME`), not
  // the general ShieldOptions defaults: the help says so instead of showing a number.
  for (const char* command : {"eval", "experiment method-comparison", "render", "shield run"}) {
    const Result r = RunCli(std::string(command) + " --help");
    ASSERT_EQ(r.exit_code, 0) << command << ": " << r.err;
    const std::size_t at = r.out.find("--class-k-gain");
    ASSERT_NE(at, std::string::npos) << command;
    const std::string line = r.out.substr(at, r.out.find('\n', at) - at);
    EXPECT_EQ(line.find("=1 "), std::string::npos) << command << ": " << line;
    EXPECT_HAS(line, "preset") << command;
  }
}

}  // namespace
