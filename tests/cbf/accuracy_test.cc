// The accuracy targets of the barrier learner, measured for real (slow: ~30 s; label
// "accuracy", skip with `ctest -LE accuracy`).
#include <gtest/gtest.h>

#include <filesystem>

#include "domains/double_integrator/domain.h"
#include "secure/cbf/barrier_trainer.h"
#include "secure/common/rng.h"
#include "secure/data/data.h"
#include "secure/experiments/ground_truth_study.h"

namespace secure::cbf {
namespace {

// The paper's Table 1 (1.9% over-, 4.1% under-conservative); our targets are 1.0% and 2.0%,
// as means over 5 training seeds with 800 + 800 states, on the 9M-state grid.
TEST(AccuracyTest, Table1MeetsTheTargetsOnTheDefaultObstacle) {
  const domains::double_integrator::DoubleIntegratorDomain domain;
  experiments::GroundTruthStudyOptions options;  // seeds 0-4
  options.trainer = domain.GroundTruthTrainerPreset();  // the double-integrator preset
  options.progress = false;
  const experiments::GroundTruthStudyResult r = experiments::RunGroundTruthStudy(domain, options);
  ASSERT_EQ(r.per_seed.size(), 5u);
  EXPECT_EQ(r.per_seed[0].total(), 9'000'000);
  EXPECT_LE(r.over_conservative.mean, 0.010);
  EXPECT_LE(r.under_conservative.mean, 0.020);
  RecordProperty("over_conservative_mean", std::to_string(r.over_conservative.mean));
  RecordProperty("under_conservative_mean", std::to_string(r.under_conservative.mean));
}

// The authors' Panda data: safe = the 246 demonstration states, near-dangerous = their 4381
// synthesised states, first 9 observation columns. Stratified 60/20/20 split; the authors'
// model reached 0.9099 balanced held-out accuracy, our target is 0.93.
TEST(AccuracyTest, PandaHeldOutBalancedAccuracy) {
  const std::string dir = std::string(SECURE_SHARED_DIR) + "/data/panda_push";
  if (!std::filesystem::exists(dir + "/task_demos.csv")) GTEST_SKIP() << dir << " not present";
  const std::vector<std::string> features = {"ee_x",  "ee_y",    "ee_z",    "ee_vx",  "ee_vy",
                                             "ee_vz", "block_x", "block_y", "block_z"};
  const data::StateSet safe = data::ReadStateSet(dir + "/task_demos.csv", features);
  const data::StateSet nd = data::ReadStateSet(dir + "/near_dangerous_states.csv", features);
  ASSERT_EQ(safe.size(), 246);
  ASSERT_EQ(nd.size(), 4381);
  for (std::uint64_t seed : {0, 1}) {
    Rng rng(seed);
    auto [safe_fit, safe_test] = data::SplitStateSet(safe, 0.2, rng);
    auto [nd_fit, nd_test] = data::SplitStateSet(nd, 0.2, rng);
    BarrierTrainerOptions options;  // the general defaults
    options.seed = seed;
    options.validation_fraction = 0.25;  // 20% of the whole
    BarrierTrainingSummary summary;
    const BarrierNet net = TrainBarrier(options, safe_fit, nd_fit, &summary);
    const ClassAccuracy test =
        EvaluateAccuracy(*net.MakeEvaluator(), safe_test.states, nd_test.states);
    EXPECT_EQ(safe_test.size(), 49);
    EXPECT_EQ(nd_test.size(), 876);
    EXPECT_GE(test.Balanced(), 0.93)
        << "seed " << seed << ": safe " << test.safe << ", near-dangerous " << test.near_dangerous;
  }
}

}  // namespace
}  // namespace secure::cbf
