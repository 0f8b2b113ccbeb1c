#pragma once
// The fixtures of the shield_test files (shield_test.cc, shield_robustness_test.cc,
// shield_ablation_test.cc): hand-made systems with analytically known safe sets (on
// IntegratorDynamics and FunctionBarrier, tests/shield/shield_test_util.h), the double
// integrator, the shield's sampling replicated, and readable enum values in failure messages.
// Each file: #include "tests/shield/shield_test_fixtures.h", then `using namespace test;` in
// secure::shield.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <functional>
#include <iterator>
#include <limits>
#include <ostream>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "domains/double_integrator/double_integrator.h"
#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/common/error.h"
#include "secure/common/rng.h"
#include "secure/nn/mlp.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"
#include "tests/test_util.h"

namespace secure::shield {

// Readable enum values in failure messages (internal linkage: other test files may add theirs).
[[maybe_unused]] static void PrintTo(Status status, std::ostream* os) {
  *os << ToString(kStatusNames, status);
}
[[maybe_unused]] static void PrintTo(Fallback fallback, std::ostream* os) {
  *os << ToString(kFallbackNames, fallback);
}

namespace test {

using secure::test::ErrorOf;
namespace di = domains::double_integrator;

inline constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
inline constexpr float kInf = std::numeric_limits<float>::infinity();

/// Replicates the shield's sampling: `rounds` consecutive rounds of M actions drawn column by
/// column from N(mu, sigma) with the shield's generator (valid while no probe is drawn between
/// the rounds, i.e. for round 1 or for resampling == kNone). `rng` is left after the draws.
inline Eigen::MatrixXf DrawRounds(Rng& rng, const Eigen::VectorXf& mu,
                                  const Eigen::VectorXf& sigma, int m, int rounds = 1) {
  Eigen::MatrixXf samples(mu.size(), static_cast<Eigen::Index>(m) * rounds);
  for (Eigen::Index c = 0; c < samples.cols(); ++c)
    for (Eigen::Index r = 0; r < mu.size(); ++r)
      samples(r, c) = mu[r] + sigma[r] * static_cast<float>(rng.Normal());
  return samples;
}


/// Index of a column of `samples` equal (bit for bit) to `action`, or -1.
inline int ColumnIndex(const Eigen::MatrixXf& samples, const Eigen::VectorXf& action) {
  for (Eigen::Index c = 0; c < samples.cols(); ++c)
    if (BitEqual(samples.col(c), action)) return static_cast<int>(c);
  return -1;
}

inline void ExpectSameDecision(const Decision& a, const Decision& b) {
  EXPECT_EQ(a.status, b.status);
  EXPECT_TRUE(BitEqual(a.action, b.action))
      << a.action.transpose() << " vs " << b.action.transpose();
  EXPECT_EQ(std::memcmp(&a.g, &b.g, sizeof(double)), 0) << a.g << " vs " << b.g;
  EXPECT_EQ(a.h, b.h);
  EXPECT_EQ(a.iterations, b.iterations);
  EXPECT_EQ(a.safe_ratio, b.safe_ratio);
  EXPECT_EQ(a.intervened, b.intervened);
  EXPECT_EQ(a.distance_to_mean, b.distance_to_mean);
  EXPECT_EQ(a.fallback, b.fallback);
}

/// 1-D: x' = x + 0.1 a, h(x) = 1 - x; with dt = 0.1 and alpha = k h,
/// g(a) = -a + k (1 - x), so the safe actions are exactly a <= k (1 - x).
struct HalfLine {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "1 - x",
                          [](const Eigen::Ref<const Eigen::VectorXf>& s) { return 1.0 - s[0]; }};
};

/// HalfLine with a count of the barrier's evaluations (not copyable: the barrier refers to it).
struct CountedHalfLine {
  CountedHalfLine() = default;
  CountedHalfLine(const CountedHalfLine&) = delete;
  CountedHalfLine& operator=(const CountedHalfLine&) = delete;
  long evaluated = 0;
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "1 - x, counted", [this](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            ++evaluated;
                            return 1.0 - s[0];
                          }};
};

/// 1-D: x' = x + 0.1 a, h(x) = x^2 - 1 at x = 0, dt = 0.1, alpha = 0.1 h:
/// g(a) = 0.1 (a^2 - 1), safe iff |a| >= 1 (two disjoint intervals).
struct TwoIntervals {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "x^2 - 1", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            return static_cast<double>(s[0]) * s[0] - 1.0;
                          }};
};

/// 1-D: h(x) = -1 - x^2 everywhere negative; at x = 0 with dt = 0.1, alpha = k h:
/// g(a) = -0.1 a^2 - k < 0 for every a, largest (-k) at a = 0.
struct NowhereSafe {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "-1 - x^2", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            return -1.0 - static_cast<double>(s[0]) * s[0];
                          }};
};

struct DoubleIntegrator {
  di::Dynamics dynamics{0.1};
  domains::double_integrator::GroundTruthBarrier barrier{di::GroundTruth{}};
  domains::double_integrator::GroundTruthBarrier independent{di::GroundTruth{}};  // for re-evaluation
};

}  // namespace test
}  // namespace secure::shield
