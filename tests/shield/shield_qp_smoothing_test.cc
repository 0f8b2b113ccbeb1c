// The last projection round on g's slope over the policy's scale (ShieldOptions::qp_smoothing):
// a barrier whose gradient at the predicted state points away from the safe actions within sigma
// (a ripple on a linear trend), where the smoothed slope finds them (proposal qp; qp-only ignores
// it); sigma = 0; the affine case left unchanged; the option's checks, YAML and JSON.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <limits>

#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"
#include "tests/test_util.h"

namespace secure::shield {
namespace {

using secure::test::ErrorOf;
using test::BitEqual;
using test::Vec;

// On an integrator (y' = y + 0.1 a, from y = 0) the barrier h(y) = 0.83 - y + 0.003 sin(1000 y)
// gives, with alpha(h) = h, g(a) = 0.83 - a + 0.03 sin(100 a): a trend of slope -1 with a ripple
// of slope +-3. At mu = 0.32 pi (100 mu = 32 pi) g(mu) = -0.175 and the local slope is +2, so the
// linearisation at mu points to larger a, where g only falls: the projection (a = 1.09) fails its
// exact check. Over mu +- 1 (qp_smoothing 2, sigma 0.5) the slope is -1.015, and the projection
// lands at a = 0.832, where g = +0.027 (the safe set's edge below mu is at 0.8435).
struct Ripple : test::Integrator1d {
  Ripple()
      : Integrator1d("ripple", [](double y) { return 0.83 - y + 0.003 * std::sin(1000.0 * y); }) {}
  const Eigen::VectorXf mu = Vec({static_cast<float>(0.32 * M_PI)});
  const Eigen::VectorXf sigma = Vec({0.5f});
  static double G(double a) { return 0.83 - a + 0.03 * std::sin(100.0 * a); }
};

// The shield's options on Ripple: alpha(h) = h.
ShieldOptions Smoothed(Proposal proposal, double smoothing) {
  ShieldOptions o = test::Integrator1d::Options(proposal, 1.0);
  o.qp_smoothing = smoothing;
  return o;
}

TEST(QpSmoothingShieldTest, TheSlopeOverSigmaRecoversAProjectionTheLocalGradientMisled) {
  Ripple ripple;
  ASSERT_NEAR(Ripple::G(ripple.mu[0]), -0.175, 1e-3);
  // The analytic linearisation alone: its projection goes the wrong way and fails.
  Shield local(Smoothed(Proposal::kQpOnly, 0.0), ripple.barrier, ripple.dynamics);
  const Decision& l = local.Decide(ripple.state, ripple.mu, ripple.sigma);
  EXPECT_NE(l.qp, QpOutcome::kAccepted) << l.ToJson().dump();
  EXPECT_EQ(l.status, Status::kNoSafeAction);
  EXPECT_GT(l.action[0], ripple.mu[0]);
  EXPECT_LT(l.g, 0.0);

  // The gradient-first shield's last round before sampling: the projection on the smoothed
  // slope is the decision, with no sampling round.
  Shield smoothed(Smoothed(Proposal::kQp, 2.0), ripple.barrier, ripple.dynamics);
  const Decision& d = smoothed.Decide(ripple.state, ripple.mu, ripple.sigma);
  ASSERT_EQ(d.qp, QpOutcome::kAccepted) << d.ToJson().dump();
  EXPECT_EQ(d.iterations, 0);
  EXPECT_TRUE(d.safe());
  EXPECT_GE(d.g, 0.0);
  EXPECT_NEAR(d.g, Ripple::G(d.action[0]), 1e-3);
  EXPECT_NEAR(d.action[0], 0.832, 0.01);
  EXPECT_LE(d.action[0], 0.8435);  // no farther than the safe set's edge below mu, plus its ripple
  EXPECT_NEAR(d.distance_to_mean, ripple.mu[0] - d.action[0], 1e-5);

  // Without the option Algorithms 1-2 decide; the filter alone ignores it (its decision keeps
  // its bits).
  Shield sampling_decides(Smoothed(Proposal::kQp, 0.0), ripple.barrier, ripple.dynamics);
  const Decision& s = sampling_decides.Decide(ripple.state, ripple.mu, ripple.sigma);
  EXPECT_NE(s.qp, QpOutcome::kAccepted);
  EXPECT_GE(s.iterations, 1);
  Shield filter(Smoothed(Proposal::kQpOnly, 2.0), ripple.barrier, ripple.dynamics);
  const Decision& q = filter.Decide(ripple.state, ripple.mu, ripple.sigma);
  EXPECT_EQ(q.qp, l.qp);
  EXPECT_TRUE(BitEqual(q.action, l.action));

  // A trust region smaller than the step (0.17 from mu) sends it to sampling too.
  ShieldOptions trusted = Smoothed(Proposal::kQp, 2.0);
  trusted.qp_max_step = 0.1;
  Shield beyond(trusted, ripple.barrier, ripple.dynamics);
  const Decision& b = beyond.Decide(ripple.state, ripple.mu, ripple.sigma);
  EXPECT_EQ(b.qp, QpOutcome::kInfeasible) << b.ToJson().dump();
  EXPECT_GE(b.iterations, 1);
}

TEST(QpSmoothingShieldTest, ADeterministicPolicyHasNoSlopeToSmoothOver) {
  // sigma = 0: the smoothed slope is 0 in every action, the half-space g(mu) + 0 . (a - mu) >= 0
  // is empty, and Algorithms 1-2 decide.
  Ripple ripple;
  Shield smoothed(Smoothed(Proposal::kQp, 2.0), ripple.barrier, ripple.dynamics);
  const Decision& d = smoothed.Decide(ripple.state, ripple.mu, Vec({0.0f}));
  EXPECT_NE(d.qp, QpOutcome::kAccepted) << d.ToJson().dump();
  EXPECT_GE(d.iterations, 1);
}

TEST(QpSmoothingShieldTest, AnAcceptedFirstProjectionIsLeftAsItWas) {
  // g affine in the action: the first projection is exact and accepted, so the smoothed round
  // never runs and the decision keeps its bits.
  test::ExpectTheSameAffineProjection(Smoothed(Proposal::kQp, 0.0), Smoothed(Proposal::kQp, 1.0));
}

TEST(QpSmoothingShieldTest, TheOptionIsCheckedReadAndWrittenOnlyWhereItActs) {
  ShieldOptions o;
  o.qp_smoothing = 2.0;
  EXPECT_FALSE(o.ToJson().contains("qp_smoothing"));  // proposal none: runs keep their identity
  o.proposal = Proposal::kQp;
  EXPECT_EQ(o.ToJson()["qp_smoothing"], 2.0);
  o.proposal = Proposal::kQpOnly;  // accepted (a config sets it for every method), not written
  o.Validate();
  EXPECT_FALSE(o.ToJson().contains("qp_smoothing"));
  o.proposal = Proposal::kQp;
  o.qp_smoothing = 0.0;
  EXPECT_FALSE(o.ToJson().contains("qp_smoothing"));
  for (double bad : {-0.5, std::numeric_limits<double>::quiet_NaN(),
                     std::numeric_limits<double>::infinity()}) {
    o.qp_smoothing = bad;
    EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "qp_smoothing = ");
  }
  ShieldOptions y;
  y.ApplyYaml(YAML::Load("{proposal: qp, qp_smoothing: 1.5}"), "s.yaml");
  EXPECT_EQ(y.qp_smoothing, 1.5);
  EXPECT_HAS(ErrorOf([&] { y.ApplyYaml(YAML::Load("{qp_smoothing: wide}"), "s.yaml"); }),
             "qp_smoothing");
}

}  // namespace
}  // namespace secure::shield
