// ShieldOptions::lookahead_steps: the CBF condition H periods ahead with the action held,
// g_H(a) = (h(T^H(s, a)) - b_H) / dt, b_0 = h(s), b_{j+1} = b_j - dt alpha(b_j) (shield.h).
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdint>
#include <string>

#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"
#include "tests/test_util.h"

namespace secure::shield {
namespace {

using secure::test::ErrorOf;
using test::FunctionBarrier;
using test::IntegratorDynamics;
using test::Vec;

// 1-D: x' = x + 0.1 a, h(x) = 1 - x, dt = 0.1, alpha = k h with k = 1, at x = 0:
//   H = 1: g = -a + 1, safe iff a <= 1;
//   H = 3: T^3 = 0.3 a, b_3 = 0.9^3 = 0.729, g_3 = (1 - 0.3 a - 0.729) / 0.1, safe iff
//          a <= 0.271 / 0.3 = 0.9033.
struct HalfLine {
  IntegratorDynamics dynamics{1, 0.1};
  FunctionBarrier barrier{1, "1 - x",
                          [](const Eigen::Ref<const Eigen::VectorXf>& s) { return 1.0 - s[0]; }};
};

TEST(ShieldLookaheadTest, EvaluateGIsTheIteratedConditionWithTheActionHeld) {
  HalfLine sys;
  const Eigen::VectorXf state = Vec({0.0f});
  Eigen::MatrixXf actions(1, 4);
  actions << -1.0f, 0.5f, 0.9f, 1.0f;
  for (int h : {1, 2, 3, 7}) {
    SCOPED_TRACE("H = " + std::to_string(h));
    ShieldOptions options;
    options.lookahead_steps = h;
    Shield shield(options, sys.barrier, sys.dynamics);
    Eigen::VectorXd g(4);
    shield.EvaluateG(state, 1.0, actions, g);
    const double bound = std::pow(0.9, h);
    for (int i = 0; i < 4; ++i) {
      const double next_h = 1.0 - 0.1 * h * actions(0, i);
      EXPECT_NEAR(g[i], (next_h - bound) / 0.1, 1e-5) << "a = " << actions(0, i);
    }
  }
}

TEST(ShieldLookaheadTest, ALongerLookaheadNarrowsTheSafeActionsAndDecidesWithinThem) {
  HalfLine sys;
  const Eigen::VectorXf state = Vec({0.0f}), mu = Vec({0.95f}), sigma = Vec({0.3f});
  for (std::uint64_t seed = 0; seed < 10; ++seed) {
    ShieldOptions one, three;
    one.seed = three.seed = seed;
    three.lookahead_steps = 3;
    Shield a(one, sys.barrier, sys.dynamics), b(three, sys.barrier, sys.dynamics);
    const Decision da = a.Decide(state, mu, sigma), db = b.Decide(state, mu, sigma);
    ASSERT_TRUE(da.safe() && db.safe()) << da.ToJson().dump() << db.ToJson().dump();
    EXPECT_LE(da.action[0], 1.0f + 1e-5f);
    EXPECT_LE(db.action[0], 0.271f / 0.3f + 1e-5f);
    EXPECT_LT(db.action[0], da.action[0]);
  }
}

TEST(ShieldLookaheadTest, OneStepIsTheDefaultAndOptionsAreChecked) {
  ShieldOptions options;
  EXPECT_EQ(options.lookahead_steps, 1);
  EXPECT_FALSE(options.ToJson().contains("lookahead_steps"));  // identity of other shields kept
  options.ApplyYaml(YAML::Load("{lookahead_steps: 4}"), "test.yaml");
  EXPECT_EQ(options.ToJson()["lookahead_steps"], 4);
  for (int bad : {0, -2, kMaxLookaheadSteps + 1}) {
    ShieldOptions o;
    o.lookahead_steps = bad;
    EXPECT_HAS(ErrorOf([&] { o.Validate(); }),
               "ShieldOptions::lookahead_steps = " + std::to_string(bad) + ", must be in [1, 100]");
  }
}

}  // namespace
}  // namespace secure::shield
