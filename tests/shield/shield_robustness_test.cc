// The CBF shield (the shield_test program, shield_test.cc): invalid input and NaN barriers, and
// misuse (options, sizes, the backup action).
#include "tests/shield/shield_test_fixtures.h"

namespace secure::shield {
namespace {
using namespace test;  // NOLINT(google-build-using-namespace): the fixtures

// ------------------------------------------------------------------------------------------------
// Invalid input and NaN barriers.

TEST(ShieldTest, NonFiniteOrNegativeInputsGiveInvalidInputAndAFiniteAction) {
  DoubleIntegrator sys;
  ShieldOptions options;
  Shield shield(options, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({1.0f, 1.0f, 0.0f, 0.0f});
  const Eigen::VectorXf mu = Vec({0.1f, 0.1f}), sigma = Vec({0.5f, 0.5f});
  struct Case {
    const char* what;
    Eigen::VectorXf state, mu, sigma;
  };
  const std::vector<Case> cases = {
      {"NaN state", Vec({1.0f, kNan, 0.0f, 0.0f}), mu, sigma},
      {"Inf state", Vec({1.0f, 1.0f, -kInf, 0.0f}), mu, sigma},
      {"NaN mu", state, Vec({kNan, 0.0f}), sigma},
      {"Inf mu", state, Vec({0.0f, kInf}), sigma},
      {"NaN sigma", state, mu, Vec({0.5f, kNan})},
      {"Inf sigma", state, mu, Vec({kInf, 0.5f})},
      {"negative sigma", state, mu, Vec({0.5f, -0.01f})},
  };
  for (bool with_backup : {false, true}) {
    if (with_backup) shield.SetBackupAction(Vec({-1.0f, 2.0f}));
    for (const Case& c : cases) {
      SCOPED_TRACE(std::string(c.what) + (with_backup ? ", with backup" : ", no backup"));
      const Decision& d = shield.Decide(c.state, c.mu, c.sigma);
      EXPECT_EQ(d.status, Status::kInvalidInput);
      EXPECT_FALSE(d.safe());
      EXPECT_TRUE(d.action.allFinite());
      EXPECT_EQ(d.action.size(), 2);
      if (with_backup) {
        EXPECT_TRUE(BitEqual(d.action, Vec({-1.0f, 2.0f})));
      } else {
        EXPECT_TRUE(d.action.isZero(0.0f));
      }
      EXPECT_TRUE(std::isnan(d.g));
      EXPECT_EQ(d.iterations, 0);
      EXPECT_EQ(d.ToJson()["status"], "invalid_input");
    }
  }
  // Zero sigma is valid (the policy is deterministic).
  shield.ClearBackupAction();
  EXPECT_EQ(shield.Decide(state, mu, Vec({0.0f, 0.0f})).status, Status::kSafe);
}

TEST(ShieldTest, NanBarrierAtTheStateGivesInvalidInput) {
  IntegratorDynamics dynamics(1, 0.1);
  FunctionBarrier barrier(1, "NaN beyond 5", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
    return s[0] > 5.0f ? std::numeric_limits<double>::quiet_NaN() : 1.0;
  });
  ShieldOptions options;
  Shield shield(options, barrier, dynamics);
  const Decision& d = shield.Decide(Vec({6.0f}), Vec({0.0f}), Vec({1.0f}));
  EXPECT_EQ(d.status, Status::kInvalidInput);
  EXPECT_EQ(d.action[0], 0.0f);
  EXPECT_TRUE(std::isnan(d.h));
  shield.SetBackupAction(Vec({-0.5f}));
  const Decision& b = shield.Decide(Vec({6.0f}), Vec({0.0f}), Vec({1.0f}));
  EXPECT_EQ(b.status, Status::kInvalidInput);
  EXPECT_EQ(b.action[0], -0.5f);
}

TEST(ShieldTest, SamplesWithNanNextBarrierNeverCountAsSafe) {
  // h(x) = 1 - x for x < 0.05, NaN beyond. At x = 0 with k = 1: g = 1 - a for a < 0.5 (all safe),
  // NaN for a >= 0.5. mu = 0.5, sigma = 1: about half the samples have a NaN g.
  IntegratorDynamics dynamics(1, 0.1);
  FunctionBarrier barrier(
      1, "1 - x, NaN beyond 0.05", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
        return s[0] < 0.05f ? 1.0 - s[0] : std::numeric_limits<double>::quiet_NaN();
      });
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.5f}), sigma = Vec({1.0f});
  for (Aggregation aggregation : {Aggregation::kMean, Aggregation::kRandomSafe}) {
    for (std::uint64_t seed = 0; seed < 10; ++seed) {
      ShieldOptions options;
      options.seed = seed;
      options.aggregation = aggregation;
      Shield shield(options, barrier, dynamics);
      const Decision& d = shield.Decide(state, mu, sigma);
      SCOPED_TRACE("seed " + std::to_string(seed) + ", " +
                   ToString(kAggregationNames, aggregation));
      ASSERT_TRUE(d.safe());
      EXPECT_EQ(d.iterations, 1);
      EXPECT_LT(0.1f * d.action[0], 0.05f);
      EXPECT_GE(d.g, 0.0);
      EXPECT_FALSE(std::isnan(d.g));
      // The safe ratio counts only the finite-g samples.
      Rng rng(seed);
      const Eigen::MatrixXf samples = DrawRounds(rng, mu, sigma, options.num_samples);
      int finite = 0;
      for (int i = 0; i < options.num_samples; ++i)
        if (0.0f + 0.1f * samples(0, i) < 0.05f) ++finite;
      EXPECT_LT(finite, options.num_samples);
      EXPECT_DOUBLE_EQ(d.safe_ratio, static_cast<double>(finite) / options.num_samples);
    }
  }
}

TEST(ShieldTest, AllNanNextBarrierGivesNoSafeActionWithAFiniteAction) {
  IntegratorDynamics dynamics(1, 0.1);
  FunctionBarrier barrier(1, "finite only at 0", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
    return s[0] == 0.0f ? 1.0 : std::numeric_limits<double>::quiet_NaN();
  });
  ShieldOptions options;
  options.max_iterations = 3;
  Shield shield(options, barrier, dynamics);
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({1.0f}), sigma = Vec({0.3f});
  const Decision d = shield.Decide(state, mu, sigma);
  EXPECT_EQ(d.status, Status::kNoSafeAction);
  EXPECT_FALSE(d.g >= 0.0);
  EXPECT_TRUE(d.action.allFinite());
  // A backup with a finite (here: safe) g wins over actions whose g is unknown.
  shield.SetBackupAction(Vec({0.0f}));
  const Decision b = shield.Decide(state, mu, sigma);
  EXPECT_EQ(b.fallback, Fallback::kBackupAction);
  EXPECT_EQ(b.action[0], 0.0f);
  EXPECT_NEAR(b.g, 1.0, 1e-9);  // g(0) = alpha(h(0)) = 1
  EXPECT_TRUE(b.safe());
}

// A backup action whose g is NaN (h(T(s, backup)) is NaN) must not replace a best sample with a
// finite g: the backup competes on g, and g is NaN only for invalid input.
TEST(ShieldTest, BackupWithNanGDoesNotReplaceABestSampleWithFiniteG) {
  IntegratorDynamics dynamics(1, 0.1);
  FunctionBarrier barrier(
      1, "-1 - x^2 for |x| <= 0.5, NaN beyond", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
        return std::abs(s[0]) <= 0.5f ? -1.0 - static_cast<double>(s[0]) * s[0]
                                      : std::numeric_limits<double>::quiet_NaN();
      });
  ShieldOptions options;
  options.max_iterations = 2;
  Shield shield(options, barrier, dynamics);
  shield.SetBackupAction(Vec({10.0f}));  // x' = 1: h is NaN, so g(backup) is NaN
  const Decision& d = shield.Decide(Vec({0.0f}), Vec({0.0f}), Vec({0.5f}));
  EXPECT_EQ(d.status, Status::kNoSafeAction);
  EXPECT_EQ(d.fallback, Fallback::kBestSample) << d.ToJson().dump();
  EXPECT_FALSE(std::isnan(d.g)) << "g is NaN for a " << ToString(kStatusNames, d.status)
                                << " decision";
  EXPECT_LT(d.g, 0.0);
}

// ------------------------------------------------------------------------------------------------
// Misuse.

TEST(ShieldTest, OptionsValidateNamesFieldValueAndRule) {
  const auto message = [](auto mutate) {
    ShieldOptions options;
    mutate(options);
    return ErrorOf([&] { options.Validate(); });
  };
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_samples = 0; }),
             "ShieldOptions::num_samples = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_samples = -3; }),
             "ShieldOptions::num_samples = -3, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_samples = 2000000000; }),
             "ShieldOptions::num_samples = 2000000000, must be in [1, 1000000]");
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_probes = 1000001; }),
             "ShieldOptions::num_probes = 1000001, must be in [1, 1000000]");
  EXPECT_HAS(message([](ShieldOptions& o) { o.safe_ratio = 1.0; }),
             "ShieldOptions::safe_ratio = 1, must be in [0, 1)");
  EXPECT_HAS(message([](ShieldOptions& o) { o.safe_ratio = -0.5; }),
             "ShieldOptions::safe_ratio = -0.5, must be in [0, 1)");
  EXPECT_HAS(message([](ShieldOptions& o) { o.safe_ratio = std::nan(""); }),
             "ShieldOptions::safe_ratio = nan");
  EXPECT_HAS(message([](ShieldOptions& o) { o.dt = 0.0; }), "ShieldOptions::dt = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.dt = std::numeric_limits<double>::infinity(); }),
             "ShieldOptions::dt = inf, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.class_k_gain = 0.0; }),
             "ShieldOptions::class_k_gain = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.class_k_gain = -1.0; }),
             "ShieldOptions::class_k_gain = -1, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.num_probes = 0; }),
             "ShieldOptions::num_probes = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.probe_extent = 0.0; }),
             "ShieldOptions::probe_extent = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.sigma_step = -0.5; }),
             "ShieldOptions::sigma_step = -0.5, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.max_iterations = 0; }),
             "ShieldOptions::max_iterations = 0, must be > 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.time_budget_us = -1.0; }),
             "ShieldOptions::time_budget_us = -1, must be >= 0");
  EXPECT_HAS(message([](ShieldOptions& o) { o.time_budget_us = std::nan(""); }),
             "ShieldOptions::time_budget_us = nan");

  ShieldOptions fine;
  fine.safe_ratio = 0.0;
  fine.max_iterations = 1;
  fine.num_samples = 1;
  fine.num_probes = 1;
  fine.Validate();  // boundaries that are allowed

  // The constructor validates.
  HalfLine sys;
  ShieldOptions bad;
  bad.num_probes = 0;
  EXPECT_HAS(ErrorOf([&] { Shield shield(bad, sys.barrier, sys.dynamics); }),
             "ShieldOptions::num_probes = 0, must be > 0");
}

TEST(ShieldTest, OptionsToJsonHasEveryField) {
  ShieldOptions options;
  options.class_k = ClassK::kCubic;
  options.aggregation = Aggregation::kRandomSafe;
  options.resampling = Resampling::kNone;
  options.seed = 42;
  const nlohmann::json j = options.ToJson();
  EXPECT_EQ(j["num_samples"], 64);
  EXPECT_EQ(j["safe_ratio"], 0.1);
  EXPECT_EQ(j["class_k"], "cubic");
  EXPECT_EQ(j["aggregation"], "random-safe");
  EXPECT_EQ(j["resampling"], "none");
  EXPECT_EQ(j["seed"], 42u);
  for (const char* key : {"dt", "class_k_gain", "num_probes", "probe_extent", "sigma_step",
                          "max_iterations", "time_budget_us"})
    EXPECT_TRUE(j.contains(key)) << key;
}

TEST(ShieldTest, ConstructorRejectsBarrierOfAnotherStateDimension) {
  di::Dynamics dynamics(0.1);
  FunctionBarrier barrier(1, "one-dimensional barrier",
                          [](const Eigen::Ref<const Eigen::VectorXf>&) { return 1.0; });
  const std::string message = ErrorOf([&] { Shield shield(ShieldOptions{}, barrier, dynamics); });
  EXPECT_HAS(message, "one-dimensional barrier");
  EXPECT_HAS(message, "1-dimensional");
  EXPECT_HAS(message, dynamics.Describe());
  EXPECT_HAS(message, "produces 4");
}

TEST(ShieldTest, DecideThrowsOnWrongDimensions) {
  DoubleIntegrator sys;
  Shield shield(ShieldOptions{}, sys.barrier, sys.dynamics);
  const Eigen::VectorXf state = Vec({1.0f, 1.0f, 0.0f, 0.0f}), two = Vec({0.0f, 0.0f});
  EXPECT_HAS(ErrorOf([&] {
               shield.Decide(Vec({1.0f, 1.0f, 0.0f}), two, two);
             }),
             "state has 3 values, expected 4");
  EXPECT_HAS(ErrorOf([&] { shield.Decide(state, Vec({0.0f}), two); }),
             "mu has 1 values, expected 2");
  EXPECT_HAS(ErrorOf([&] {
               shield.Decide(state, two, Vec({1.0f, 1.0f, 1.0f}));
             }),
             "sigma has 3 values, expected 2");
  // Dimension errors win over bad numbers (misuse is reported, not hidden as invalid input).
  EXPECT_HAS(ErrorOf([&] { shield.Decide(Vec({kNan}), two, two); }), "state has 1 values");
  // The shield still works afterwards.
  EXPECT_EQ(shield.Decide(state, two, Vec({0.1f, 0.1f})).status, Status::kSafe);
}

TEST(ShieldTest, SetBackupActionRejectsNonFiniteOrWrongSize) {
  DoubleIntegrator sys;
  Shield shield(ShieldOptions{}, sys.barrier, sys.dynamics);
  EXPECT_HAS(ErrorOf([&] { shield.SetBackupAction(Vec({0.0f, kNan})); }), "non-finite");
  EXPECT_HAS(ErrorOf([&] { shield.SetBackupAction(Vec({kInf, 0.0f})); }), "non-finite");
  EXPECT_HAS(ErrorOf([&] {
               shield.SetBackupAction(Vec({0.0f, 0.0f, 0.0f}));
             }),
             "backup action has 3 values, expected 2");
  // A rejected backup is not installed: invalid input still returns zeros.
  const Decision& d =
      shield.Decide(Vec({kNan, 0.0f, 0.0f, 0.0f}), Vec({1.0f, 1.0f}), Vec({1.0f, 1.0f}));
  EXPECT_EQ(d.status, Status::kInvalidInput);
  EXPECT_TRUE(d.action.isZero(0.0f));
}

}  // namespace
}  // namespace secure::shield
