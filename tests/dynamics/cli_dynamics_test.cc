// `secure dynamics collect | train | validate` end to end on the double integrator, and the
// learned model's pessimism flags on `secure eval --dynamics` (issue 36).
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>
#include <string>

#include "tests/apps/cli_run.h"

namespace secure::test {
namespace {

std::string P(const std::string& name) { return (CliTempDir() / name).string(); }

TEST(CliDynamicsTest, CollectTrainValidateAndThePessimismFlags) {
  CliResult r = RunCli("dynamics collect --domain double-integrator --episodes 4 --seed 3 --out " +
                       P("di_explore.csv") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("dynamics train --domain double-integrator --transitions " + P("di_explore.csv") +
             " --members 3 --hidden 16 --epochs 20 --out " + P("di_dyn.model") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCli("dynamics validate --model " + P("di_dyn.model") + " --transitions " +
             P("di_explore.csv") + " --horizon 2 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["members"], 3);
  ASSERT_EQ(j["features"].size(), 4u);
  // Three members from different initialisations disagree: a positive spread per feature.
  for (const auto& f : j["features"]) {
    EXPECT_GT(f["spread"].get<double>(), 0.0) << f["feature"];
    EXPECT_GE(f["rmse"].get<double>(), 0.0) << f["feature"];
  }
  for (const auto& g : j["groups"]) EXPECT_GT(g["relative_spread"].get<double>(), 0.0);

  // The pessimism flags: bad values are one-line errors naming the flag and the value.
  const std::string eval = "eval --domain double-integrator --airl " + P("none.model") +
                           " --dynamics " + P("di_dyn.model") + " --seeds 1 --episodes 1";
  ExpectOneErrorLine(RunCli(eval + " --pessimism max"),
                     "--pessimism = 'max', must be min | mean-std");
  ExpectOneErrorLine(RunCli(eval + " --pessimism mean-std --pessimism-kappa -1"),
                     "--pessimism-kappa = -1, must be finite and >= 0");
  ExpectOneErrorLine(RunCli(eval + " --dynamics-hold 0"),
                     "--dynamics-hold = 0, must be in [1, 20]");
}

}  // namespace
}  // namespace secure::test
