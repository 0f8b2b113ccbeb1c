// The first-safe sampler (aggregation first-safe; method first-safe, CRABS-style): the policy's
// draw when it passes, else the first passing draw in draw order, round after round up to the
// budget, else the status says no safe action. The draws are replayed here from the shield's
// seed (i.i.d. sampler: mu + sigma z, column by column), so the test knows which draw is first.

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "secure/common/rng.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"

namespace secure::shield {
namespace {

using test::BitEqual;
using test::FunctionBarrier;
using test::IntegratorDynamics;
using test::Vec;

// h(s) = s0 + s1 - 1 (safe above the line), integrator s' = s + 0.1 a, alpha = 1:
// g(a) = (0.1 (a0 + a1)) / 0.1 + h(s) = a0 + a1 + h(s).
struct LineSystem {
  FunctionBarrier barrier{2, "line", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            return static_cast<double>(s[0] + s[1]) - 1.0;
                          }};
  IntegratorDynamics dynamics{2, 0.1};
};

// The draws of `rounds` rounds of M samples from N(mu, sigma) with `seed`, as Shield draws them.
std::vector<Eigen::VectorXf> Replay(std::uint64_t seed, int m, int rounds,
                                    const Eigen::VectorXf& mu, const Eigen::VectorXf& sigma) {
  Rng rng(seed);
  std::vector<Eigen::VectorXf> draws;
  for (int k = 0; k < m * rounds; ++k) {
    Eigen::VectorXf a(mu.size());
    for (int r = 0; r < mu.size(); ++r) a[r] = mu[r] + sigma[r] * static_cast<float>(rng.Normal());
    draws.push_back(a);
  }
  return draws;
}

ShieldOptions FirstSafeOptions(std::uint64_t seed) {
  ShieldOptions o;
  o.aggregation = Aggregation::kFirstSafe;
  o.resampling = Resampling::kNone;  // the policy's own Gaussian in every round
  o.num_samples = 8;
  o.max_iterations = 20;
  o.seed = seed;
  return o;
}

TEST(FirstSafeTest, ReturnsThePoliciesDrawWhenItPasses) {
  LineSystem sys;
  const Eigen::VectorXf state = Vec({1.0f, 1.0f});  // h = 1: g = a0 + a1 + 1
  const Eigen::VectorXf mu = Vec({0.0f, 0.0f}), sigma = Vec({0.1f, 0.1f});
  for (std::uint64_t seed = 0; seed < 20; ++seed) {
    ShieldOptions o = FirstSafeOptions(seed);
    Shield shield(o, sys.barrier, sys.dynamics);
    const Decision& d = shield.Decide(state, mu, sigma);
    const std::vector<Eigen::VectorXf> draws = Replay(seed, o.num_samples, 1, mu, sigma);
    ASSERT_EQ(d.status, Status::kSafe) << d.ToJson().dump();
    EXPECT_TRUE(BitEqual(d.action, draws[0])) << d.ToJson().dump();
    EXPECT_FALSE(d.intervened);
    EXPECT_EQ(d.iterations, 1);
    EXPECT_EQ(d.safe_ratio, 1.0);  // the policy's draw alone was evaluated
  }
}

// A mean below the line with a wide sigma: some draws pass, most do not. The decision is the
// first passing draw over the rounds, whatever round it falls in; the status follows the round.
TEST(FirstSafeTest, ReturnsTheFirstPassingDrawInDrawOrder) {
  LineSystem sys;
  const Eigen::VectorXf state = Vec({0.5f, 0.5f});  // h = 0: g = a0 + a1
  const Eigen::VectorXf mu = Vec({-1.2f, -1.2f}), sigma = Vec({1.0f, 1.0f});
  int later_rounds = 0;
  for (std::uint64_t seed = 0; seed < 40; ++seed) {
    const ShieldOptions o = FirstSafeOptions(seed);
    Shield shield(o, sys.barrier, sys.dynamics);
    const Decision& d = shield.Decide(state, mu, sigma);
    const std::vector<Eigen::VectorXf> draws =
        Replay(seed, o.num_samples, o.max_iterations, mu, sigma);
    int first = -1;
    for (int k = 0; k < static_cast<int>(draws.size()) && first < 0; ++k)
      if (draws[k][0] + draws[k][1] >= 0.0f) first = k;
    SCOPED_TRACE("seed " + std::to_string(seed) + ": " + d.ToJson().dump());
    if (first < 0) {  // P(a0 + a1 >= 0) = 4.5 %: no pass in 160 draws has odds 6e-4
      EXPECT_EQ(d.status, Status::kNoSafeAction);
      continue;
    }
    EXPECT_TRUE(d.safe());
    EXPECT_TRUE(BitEqual(d.action, draws[first]));
    EXPECT_GE(d.g, 0.0);
    EXPECT_NEAR(d.g, draws[first][0] + draws[first][1], 1e-5);
    EXPECT_EQ(d.iterations, first / o.num_samples + 1);
    EXPECT_EQ(d.status, d.iterations == 1 ? Status::kSafe : Status::kSafeAfterResampling);
    EXPECT_EQ(d.intervened, first != 0);
    EXPECT_EQ(d.fallback, Fallback::kNone);
    if (d.iterations > 1) ++later_rounds;
  }
  EXPECT_GT(later_rounds, 5);  // the test covers the resampled rounds
}

// No draw passes within the budget: the status says so, with the best evaluated draw (or the
// backup action when its g is larger); never a random sample.
TEST(FirstSafeTest, SaysNoSafeActionWhenNoDrawPasses) {
  LineSystem sys;
  const Eigen::VectorXf state = Vec({0.5f, 0.5f});
  const Eigen::VectorXf mu = Vec({-5.0f, -5.0f}), sigma = Vec({0.1f, 0.1f});
  ShieldOptions o = FirstSafeOptions(3);
  o.max_iterations = 4;
  Shield shield(o, sys.barrier, sys.dynamics);
  const Decision& d = shield.Decide(state, mu, sigma);
  EXPECT_EQ(d.status, Status::kNoSafeAction) << d.ToJson().dump();
  EXPECT_EQ(d.fallback, Fallback::kBestSample);
  EXPECT_EQ(d.iterations, 4);
  EXPECT_LT(d.g, 0.0);
  // The best of the 32 draws.
  const std::vector<Eigen::VectorXf> draws = Replay(3, o.num_samples, 4, mu, sigma);
  float best = -1e9f;
  for (const Eigen::VectorXf& a : draws) best = std::max(best, a[0] + a[1]);
  EXPECT_NEAR(d.g, best, 1e-5);
  shield.SetBackupAction(Vec({1.0f, 1.0f}));  // g = 2: the backup is returned, and it is safe
  const Decision& e = shield.Decide(state, mu, sigma);
  EXPECT_EQ(e.fallback, Fallback::kBackupAction);
  EXPECT_TRUE(e.safe());
  EXPECT_TRUE(BitEqual(e.action, Vec({1.0f, 1.0f})));
}

// With adaptive resampling (the shield's default) instead of the policy's own sigma, the widened
// rounds find a passing draw where the policy's Gaussian alone does not; the decision is still a
// single draw that passes, not a mean.
TEST(FirstSafeTest, AdaptiveResamplingWidensTheSearch) {
  LineSystem sys;
  const Eigen::VectorXf state = Vec({0.5f, 0.5f});
  const Eigen::VectorXf mu = Vec({-1.5f, -1.5f}), sigma = Vec({0.05f, 0.05f});
  ShieldOptions o = FirstSafeOptions(5);
  o.resampling = Resampling::kAdaptive;
  o.sigma_step = 1.0;
  o.probe_extent = 4.0;
  Shield shield(o, sys.barrier, sys.dynamics);
  const Decision& d = shield.Decide(state, mu, sigma);
  EXPECT_TRUE(d.safe()) << d.ToJson().dump();
  EXPECT_GT(d.iterations, 1);
  EXPECT_GE(d.g, 0.0);
  EXPECT_NEAR(d.g, d.action[0] + d.action[1], 1e-5);
  o.resampling = Resampling::kNone;
  Shield own(o, sys.barrier, sys.dynamics);
  EXPECT_EQ(own.Decide(state, mu, sigma).status, Status::kNoSafeAction);
}

}  // namespace
}  // namespace secure::shield
