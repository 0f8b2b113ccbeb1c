// The CBF-QP projection's metric (ShieldOptions::qp_metric: euclidean or the policy's Gaussian)
// and target (qp_target: the linearised boundary or the Gaussian's mean over the linearised safe
// half-space) on an integrator under a linear barrier, where the linearisation is exact and the
// answers have closed forms; the options' checks, YAML and JSON.

#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <string>

#include "secure/shield/qp.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"
#include "tests/test_util.h"

namespace secure::shield {
namespace {

using secure::test::ErrorOf;
using test::HalfSpace;
using test::Vec;

TEST(QpMetricShieldTest, TheFilterReturnsTheProjectionInThePolicysMetric) {
  HalfSpace h1, h2;
  const Eigen::Vector2d w = h1.w.cast<double>();
  const Eigen::VectorXf state = Vec({0.2f, 0.3f});    // h = 0.1
  const Eigen::VectorXf mu = Vec({-1.0f, 1.0f});      // g = -2.8
  const Eigen::VectorXf sigma = Vec({0.14f, 0.04f});  // Panda's x and y
  ShieldOptions o;
  o.proposal = Proposal::kQpOnly;
  o.class_k_gain = 2.0;
  o.qp_metric = QpMetric::kPolicy;
  Shield policy(o, h1.barrier, h1.dynamics);
  o.qp_metric = QpMetric::kEuclidean;
  Shield euclidean(o, h2.barrier, h2.dynamics);
  const Decision d = policy.Decide(state, mu, sigma);
  const Decision e = euclidean.Decide(state, mu, sigma);
  ASSERT_EQ(d.status, Status::kSafe) << d.ToJson().dump();
  ASSERT_EQ(e.status, Status::kSafe) << e.ToJson().dump();
  const Eigen::Vector2d m = mu.cast<double>(), s2 = sigma.cast<double>().cwiseAbs2();
  const Eigen::Vector2d sw = s2.cwiseProduct(w);
  const Eigen::Vector2d expected = m + (-0.2 - w.dot(m)) / w.dot(sw) * sw;
  EXPECT_NEAR(d.action[0], expected[0], 2e-3);
  EXPECT_NEAR(d.action[1], expected[1], 2e-3);
  EXPECT_GE(d.g, 0.0);
  EXPECT_NEAR(d.g, 0.0, 1e-2);  // on the boundary, plus the rounding allowance
  // The policy's metric moves the sure axis (y, sigma 0.04) far less than the Euclidean one, and
  // x more: it is farther in action units and nearer in the policy's metric.
  EXPECT_LT(std::abs(d.action[1] - mu[1]), 0.5 * std::abs(e.action[1] - mu[1]));  // 0.34, 1.12
  EXPECT_GT(std::abs(d.action[0] - mu[0]), std::abs(e.action[0] - mu[0]));
  EXPECT_GT(d.distance_to_mean, e.distance_to_mean);
  const auto metric = [&](const Eigen::VectorXf& a) {
    return (a - mu).cwiseQuotient(sigma).squaredNorm();
  };
  EXPECT_LT(metric(d.action), metric(e.action));
  // Equal sigma: the two metrics agree.
  const Decision de = policy.Decide(state, mu, Vec({0.3f, 0.3f}));
  const Decision ee = euclidean.Decide(state, mu, Vec({0.3f, 0.3f}));
  EXPECT_NEAR((de.action - ee.action).norm(), 0.0, 1e-5);
}

// A sigma with a zero entry has no policy metric: a one-line error where the projection uses it
// (proposal qp, qp-only); the Euclidean metric and the other proposals take it. A negative sigma
// stays invalid input whatever the options.
TEST(QpMetricShieldTest, ASigmaWithAZeroEntryIsAClearError) {
  HalfSpace h;
  const Eigen::VectorXf state = Vec({0.2f, 0.3f}), mu = Vec({-1.0f, 1.0f});
  for (const Proposal proposal :
       {Proposal::kNone, Proposal::kQp, Proposal::kQpOnly, Proposal::kRefine}) {
    for (const QpMetric metric : {QpMetric::kEuclidean, QpMetric::kPolicy}) {
      ShieldOptions o;
      o.proposal = proposal;
      o.qp_metric = metric;
      Shield shield(o, h.barrier, h.dynamics);
      if (metric == QpMetric::kPolicy &&
          (proposal == Proposal::kQp || proposal == Proposal::kQpOnly)) {
        const std::string error = ErrorOf([&] { shield.Decide(state, mu, Vec({0.1f, 0.0f})); });
        EXPECT_HAS(error, "qp_metric = policy needs the policy's sigma > 0");
        EXPECT_HAS(error, "sigma[1] = 0");
        EXPECT_EQ(error.find('\n'), std::string::npos) << error;
      } else {
        EXPECT_NE(shield.Decide(state, mu, Vec({0.1f, 0.0f})).status, Status::kInvalidInput)
            << ToString(kProposalNames, proposal);
      }
      EXPECT_EQ(shield.Decide(state, mu, Vec({0.1f, -1.0f})).status, Status::kInvalidInput);
    }
  }
}

TEST(QpMetricShieldTest, TheOptionIsReadWrittenOnlyWhenSetAndChecked) {
  ShieldOptions o;
  EXPECT_EQ(o.qp_metric, QpMetric::kEuclidean);
  o.qp_metric = QpMetric::kPolicy;
  // Written whenever set, whatever the proposal (a config's options reach secure-qp and cbf-qp
  // through them, and a result says which metric its projections used).
  for (const Proposal proposal :
       {Proposal::kNone, Proposal::kQp, Proposal::kQpOnly, Proposal::kRefine}) {
    o.proposal = proposal;
    EXPECT_EQ(o.ToJson()["qp_metric"], "policy");
  }
  // The default writes nothing: the options (and run directories) of every existing shield keep
  // their bytes.
  for (const Proposal proposal :
       {Proposal::kNone, Proposal::kQp, Proposal::kQpOnly, Proposal::kRefine}) {
    ShieldOptions plain;
    plain.proposal = proposal;
    EXPECT_FALSE(plain.ToJson().contains("qp_metric"));
  }
  // YAML, both values, and back through ToJson.
  ShieldOptions y;
  y.ApplyYaml(YAML::Load("{proposal: qp, qp_metric: policy}"), "s.yaml");
  EXPECT_EQ(y.qp_metric, QpMetric::kPolicy);
  y.Validate();
  ShieldOptions z;
  z.ApplyYaml(YAML::Load(y.ToJson().dump()), "round-trip");
  EXPECT_EQ(z.qp_metric, QpMetric::kPolicy);
  EXPECT_EQ(z.ToJson(), y.ToJson());
  y.ApplyYaml(YAML::Load("{qp_metric: euclidean}"), "s.yaml");
  EXPECT_EQ(y.qp_metric, QpMetric::kEuclidean);
  const std::string error =
      ErrorOf([&] { y.ApplyYaml(YAML::Load("{qp_metric: mahalanobis}"), "s.yaml"); });
  EXPECT_HAS(error, "s.yaml");
  EXPECT_HAS(error, "qp_metric");
  EXPECT_HAS(error, "mahalanobis");
  EXPECT_EQ(error.find('\n'), std::string::npos) << error;
}

// qp_target = safe-mean on an exact half-space: the decision is the mean of N(mu, sigma^2) over
// the safe actions, in closed form, strictly inside (g > 0) where the boundary target lands on
// g = 0; a safe mean is still returned as it is.
TEST(QpTargetShieldTest, SafeMeanIsTheGaussiansMeanOverTheSafeActions) {
  HalfSpace h1, h2;
  const Eigen::Vector2d w = h1.w.cast<double>();
  const Eigen::VectorXf state = Vec({0.2f, 0.3f});  // h = 0.1; g(a) = w . a + 0.2
  const Eigen::VectorXf sigma = Vec({0.14f, 0.04f});
  ShieldOptions o;
  o.proposal = Proposal::kQpOnly;
  o.class_k_gain = 2.0;
  o.qp_metric = QpMetric::kPolicy;
  o.qp_target = QpTarget::kSafeMean;
  Shield safe_mean(o, h1.barrier, h1.dynamics);
  o.qp_target = QpTarget::kBoundary;
  Shield boundary(o, h2.barrier, h2.dynamics);
  const Eigen::Vector2d s2 = sigma.cast<double>().cwiseAbs2();
  const double spread = std::sqrt(w.dot(s2.cwiseProduct(w)));  // |sigma o w|
  // Far outside (beta = 20 spreads), just outside (beta = 0.5) and just inside (beta = -0.5).
  for (const double beta : {20.0, 0.5, -0.5}) {
    // w . mu = -0.2 - beta |sigma o w| along w's direction in the policy's metric.
    const Eigen::Vector2d dir = s2.cwiseProduct(w) / (spread * spread);
    const Eigen::Vector2d m = (-0.2 - beta * spread) * dir;
    const Eigen::VectorXf mu = m.cast<float>();
    const Decision d = safe_mean.Decide(state, mu, sigma);
    ASSERT_EQ(d.status, Status::kSafe) << d.ToJson().dump();
    if (beta < 0) {  // g(mu) = 0.5 spread > 0: mu itself, untouched
      EXPECT_FALSE(d.intervened);
      EXPECT_EQ(d.distance_to_mean, 0.0);
      continue;
    }
    EXPECT_TRUE(d.intervened);
    EXPECT_EQ(d.qp, QpOutcome::kAccepted);
    // E[a | w . a >= -0.2 + r] = mu + lambda(b) sigma^2 o w / |sigma o w|, b = beta + r / spread,
    // with r = 1e-4 (1 + h) / dt = 1.1e-3 the shield's allowance for rounding.
    const double b = beta + 1.1e-3 / spread, lambda = InverseMillsRatio(b);
    const Eigen::Vector2d expected = m + lambda * s2.cwiseProduct(w) / spread;
    EXPECT_NEAR(d.action[0], expected[0], 1e-4) << beta;
    EXPECT_NEAR(d.action[1], expected[1], 1e-4) << beta;
    // Inside by (lambda - beta) spreads in g's units, where the boundary target stops at 0.
    EXPECT_NEAR(d.g, (lambda - beta) * spread, 1e-3) << beta;
    const Decision e = boundary.Decide(state, mu, sigma);
    ASSERT_EQ(e.status, Status::kSafe);
    EXPECT_NEAR(e.g, 0.0, 1e-2);
    EXPECT_GT(d.g, e.g + 0.5 * (lambda - beta) * spread) << beta;
  }
}

TEST(QpTargetShieldTest, TheOptionIsReadWrittenOnlyWhenSetAndChecked) {
  ShieldOptions o;
  EXPECT_EQ(o.qp_target, QpTarget::kBoundary);
  EXPECT_FALSE(o.ToJson().contains("qp_target"));  // existing shields keep their bytes
  o.qp_target = QpTarget::kSafeMean;
  // The mean of the policy's Gaussian is a projection in its metric: a one-line error otherwise.
  const std::string error = ErrorOf([&] { o.Validate(); });
  EXPECT_HAS(error, "qp_target = safe-mean");
  EXPECT_HAS(error, "needs qp_metric = policy, not euclidean");
  EXPECT_EQ(error.find('\n'), std::string::npos) << error;
  o.qp_metric = QpMetric::kPolicy;
  o.Validate();
  EXPECT_EQ(o.ToJson()["qp_target"], "safe-mean");
  ShieldOptions y;
  y.ApplyYaml(YAML::Load("{proposal: qp, qp_metric: policy, qp_target: safe-mean}"), "s.yaml");
  EXPECT_EQ(y.qp_target, QpTarget::kSafeMean);
  ShieldOptions z;
  z.ApplyYaml(YAML::Load(y.ToJson().dump()), "round-trip");
  EXPECT_EQ(z.ToJson(), y.ToJson());
  const std::string bad =
      ErrorOf([&] { y.ApplyYaml(YAML::Load("{qp_target: centre}"), "s.yaml"); });
  EXPECT_HAS(bad, "s.yaml");
  EXPECT_HAS(bad, "qp_target");
  EXPECT_HAS(bad, "centre");
}

}  // namespace
}  // namespace secure::shield
