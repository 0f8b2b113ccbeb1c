// The CBF-QP's projection in the policy's metric (qp.h ProjectInGaussianMetric; the shield's
// qp_metric = policy): against a brute-force grid in the weighted metric on random half-spaces and
// boxes (RapidCheck, the fixed seed of every ctest run of shield_test), equal sigma against the
// Euclidean projection, the closed form without a box, bad input; in the shield, the closed form
// on a linear barrier, a sigma with a zero entry, and the option's YAML, JSON and checks.

#include <gtest/gtest.h>
#include <rapidcheck.h>
#include <rapidcheck/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <limits>
#include <memory>
#include <vector>

#include "secure/shield/qp.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"
#include "tests/test_util.h"

namespace secure::shield {
namespace {

using secure::test::ErrorOf;
using test::FunctionBarrier;
using test::IntegratorDynamics;
using test::Vec;

constexpr double kInf = std::numeric_limits<double>::infinity();

rc::Gen<double> UniformIn(double lo, double hi) {
  return rc::gen::map(rc::gen::inRange<int>(0, 10001),
                      [lo, hi](int i) { return lo + (hi - lo) * (i / 10000.0); });
}

Eigen::VectorXd RandomVector(int n, double lo, double hi) {
  Eigen::VectorXd v(n);
  for (int i = 0; i < n; ++i) v[i] = *UniformIn(lo, hi);
  return v;
}

QpResult SolveInMetric(const Eigen::VectorXd& mu, const Eigen::VectorXd& sigma,
                       const Eigen::VectorXd& c, double d, const Eigen::VectorXd& low,
                       const Eigen::VectorXd& high, Eigen::VectorXd* a) {
  GaussianMetricScratch scratch;
  scratch.Resize(mu.size());
  a->resize(mu.size());
  return ProjectInGaussianMetric(mu, sigma, c, d, low, high, *a, scratch);
}

QpResult SolveEuclidean(const Eigen::VectorXd& mu, const Eigen::VectorXd& c, double d,
                        const Eigen::VectorXd& low, const Eigen::VectorXd& high,
                        Eigen::VectorXd* a) {
  std::vector<double> scratch;
  a->resize(mu.size());
  return ProjectOntoHalfSpaceAndBox(mu, c, d, low, high, *a, scratch);
}

// h(s) = w . s + 0.5, w = (1, -2).
std::unique_ptr<FunctionBarrier> LinearBarrier() {
  return std::make_unique<FunctionBarrier>(2, "linear",
                                           [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                                             return static_cast<double>(s[0] - 2.0f * s[1]) + 0.5;
                                           });
}

// sum_i ((a_i - mu_i) / sigma_i)^2
double Weighted(const Eigen::VectorXd& a, const Eigen::VectorXd& mu, const Eigen::VectorXd& sigma) {
  return (a - mu).cwiseQuotient(sigma).squaredNorm();
}

// In 1 to 3 dimensions, sigma per axis from 0.05 to 2 (ratios up to 40, as Panda's policy has
// 0.04 against 0.19): the answer lies in the box and the half-space, no grid point of the box
// (`steps` per axis) that satisfies the half-space is closer to mu in the weighted metric, and
// infeasibility is reported exactly when no point of the box satisfies the half-space.
RC_GTEST_PROP(QpMetricProperty, MatchesABruteForceGridInTheWeightedMetric, ()) {
  const int n = *rc::gen::inRange(1, 4);
  const Eigen::VectorXd low = RandomVector(n, -3, 0);
  Eigen::VectorXd high = low;
  for (int i = 0; i < n; ++i) high[i] += *UniformIn(0.0, 4.0);  // width 0 allowed
  const Eigen::VectorXd mu = RandomVector(n, -5, 5);
  const Eigen::VectorXd sigma = RandomVector(n, 0.05, 2.0);
  Eigen::VectorXd c = RandomVector(n, -2, 2);
  if (*rc::gen::inRange(0, 5) == 0) c[*rc::gen::inRange(0, n)] = 0.0;  // an axis c ignores
  const double d = *UniformIn(-6, 6);
  Eigen::VectorXd a;
  const QpResult result = SolveInMetric(mu, sigma, c, d, low, high, &a);
  for (int i = 0; i < n; ++i) RC_ASSERT(a[i] >= low[i] && a[i] <= high[i]);
  double box_max = 0.0;
  for (int i = 0; i < n; ++i) box_max += c[i] > 0 ? c[i] * high[i] : c[i] * low[i];
  if (result.status == QpStatus::kInfeasible) {
    RC_ASSERT(box_max < d + 1e-9 * (1 + std::abs(d)));
    RC_ASSERT(std::abs(c.dot(a) - box_max) <= 1e-9 * (1 + std::abs(box_max)));
    return;
  }
  RC_ASSERT(box_max >= d - 1e-9 * (1 + std::abs(d)));
  RC_ASSERT(c.dot(a) >= d - 1e-9 * (1 + std::abs(d)));
  const double best = Weighted(a, mu, sigma);
  const int steps = n == 1 ? 2001 : n == 2 ? 201 : 41;
  Eigen::VectorXi index = Eigen::VectorXi::Zero(n);
  for (;;) {
    Eigen::VectorXd p(n);
    for (int i = 0; i < n; ++i) p[i] = low[i] + (high[i] - low[i]) * index[i] / (steps - 1);
    if (c.dot(p) >= d) RC_ASSERT(Weighted(p, mu, sigma) >= best - 1e-9 * (1 + best));
    int k = 0;
    while (k < n && ++index[k] == steps) index[k++] = 0;
    if (k == n) break;
  }
  // The metric matters: with sigma not all equal the Euclidean answer is no better in it.
  Eigen::VectorXd e;
  if (SolveEuclidean(mu, c, d, low, high, &e).status == QpStatus::kOptimal)
    RC_ASSERT(Weighted(e, mu, sigma) >= best - 1e-9 * (1 + best));
}

// sigma = s (1, ..., 1) for any s > 0 is the Euclidean metric scaled: the same answer, status
// and multiplier (lambda s^2 = the Euclidean lambda), box or no box.
RC_GTEST_PROP(QpMetricProperty, EqualSigmaGivesTheEuclideanAnswer, ()) {
  const int n = *rc::gen::inRange(1, 6);
  const bool boxed = *rc::gen::arbitrary<bool>();
  Eigen::VectorXd low = Eigen::VectorXd::Constant(n, -kInf);
  Eigen::VectorXd high = Eigen::VectorXd::Constant(n, kInf);
  if (boxed) {
    low = RandomVector(n, -3, 0);
    high = low;
    for (int i = 0; i < n; ++i) high[i] += *UniformIn(0.0, 4.0);
  }
  const Eigen::VectorXd mu = RandomVector(n, -5, 5);
  const Eigen::VectorXd c = RandomVector(n, -2, 2);
  const double d = *UniformIn(-6, 6);
  const double s = *rc::gen::element(0.04, 0.3, 1.0, 7.0);
  Eigen::VectorXd a, e;
  const QpResult weighted =
      SolveInMetric(mu, Eigen::VectorXd::Constant(n, s), c, d, low, high, &a);
  const QpResult euclidean = SolveEuclidean(mu, c, d, low, high, &e);
  RC_LOG() << "weighted " << a.transpose() << ", euclidean " << e.transpose() << "\n";
  RC_ASSERT((a - e).norm() <= 1e-9 * (1 + e.norm()));
  if (weighted.status != euclidean.status) {
    // Only where the half-space just touches the box (max of c . a over it = d), which the
    // generator's grid of values can hit exactly: rounding decides there.
    double box_max = 0.0;
    for (int i = 0; i < n; ++i) box_max += c[i] > 0 ? c[i] * high[i] : c[i] * low[i];
    RC_ASSERT(std::abs(box_max - d) <= 1e-9 * (1 + std::abs(d)));
    return;
  }
  if (euclidean.status == QpStatus::kOptimal && euclidean.multiplier > 0) {
    RC_ASSERT(std::abs(weighted.multiplier * s * s - euclidean.multiplier) <=
              1e-9 * (1 + euclidean.multiplier));
  }
}

// Without a box: a = mu + max(0, d - c . mu) / (c^T S c) S c, S = diag(sigma^2).
RC_GTEST_PROP(QpMetricProperty, WithoutABoxIsTheClosedForm, ()) {
  const int n = *rc::gen::inRange(1, 6);
  const Eigen::VectorXd mu = RandomVector(n, -5, 5);
  const Eigen::VectorXd sigma = RandomVector(n, 0.05, 2.0);
  Eigen::VectorXd c = RandomVector(n, -2, 2);
  c[0] += c[0] >= 0 ? 0.1 : -0.1;  // c != 0
  const double d = *UniformIn(-6, 6);
  Eigen::VectorXd a;
  const QpResult result = SolveInMetric(mu, sigma, c, d, Eigen::VectorXd::Constant(n, -kInf),
                                        Eigen::VectorXd::Constant(n, kInf), &a);
  RC_ASSERT(result.status == QpStatus::kOptimal);
  const Eigen::VectorXd sc = sigma.cwiseProduct(sigma).cwiseProduct(c);
  const Eigen::VectorXd expected = mu + std::max(0.0, d - c.dot(mu)) / c.dot(sc) * sc;
  RC_ASSERT((a - expected).norm() <= 1e-9 * (1 + expected.norm()));
}

TEST(QpMetricTest, TheSureAxisMovesLeast) {
  // mu = 0, c = (1, 1), d = 1, sigma = (1, 0.1): a = lambda (1, 0.01), lambda = 1 / 1.01; the
  // Euclidean answer is (0.5, 0.5).
  Eigen::VectorXd a;
  const QpResult r = SolveInMetric(Eigen::Vector2d(0, 0), Eigen::Vector2d(1, 0.1),
                                   Eigen::Vector2d(1, 1), 1.0, Eigen::Vector2d(-kInf, -kInf),
                                   Eigen::Vector2d(kInf, kInf), &a);
  EXPECT_EQ(r.status, QpStatus::kOptimal);
  EXPECT_NEAR(a[0], 1.0 / 1.01, 1e-12);
  EXPECT_NEAR(a[1], 0.01 / 1.01, 1e-12);
  EXPECT_NEAR(r.multiplier, 1.0 / 1.01, 1e-12);
  // A box face on the loose axis: a0 stops at 0.6, the sure axis takes the rest.
  const QpResult boxed = SolveInMetric(Eigen::Vector2d(0, 0), Eigen::Vector2d(1, 0.1),
                                       Eigen::Vector2d(1, 1), 1.0, Eigen::Vector2d(-1, -1),
                                       Eigen::Vector2d(0.6, 1), &a);
  EXPECT_EQ(boxed.status, QpStatus::kOptimal);
  EXPECT_NEAR(a[0], 0.6, 1e-12);
  EXPECT_NEAR(a[1], 0.4, 1e-12);
  // Infeasible: the box maximiser, as in the Euclidean metric.
  const QpResult none = SolveInMetric(Eigen::Vector2d(0, 0), Eigen::Vector2d(1, 0.1),
                                      Eigen::Vector2d(1, 1), 5.0, Eigen::Vector2d(-1, -1),
                                      Eigen::Vector2d(0.6, 1), &a);
  EXPECT_EQ(none.status, QpStatus::kInfeasible);
  EXPECT_EQ(a, Eigen::Vector2d(0.6, 1));
}

TEST(QpMetricTest, BadInputIsRejected) {
  Eigen::VectorXd a;
  const Eigen::Vector2d mu(0, 0), c(1, 1), low(-1, -1), high(1, 1);
  for (const double bad : {0.0, -0.5, std::nan(""), kInf}) {
    const std::string error =
        ErrorOf([&] { SolveInMetric(mu, Eigen::Vector2d(1, bad), c, 0.5, low, high, &a); });
    EXPECT_HAS(error, "sigma[1] = ");
    EXPECT_HAS(error, "must be finite and > 0");
  }
  EXPECT_HAS(ErrorOf([&] { SolveInMetric(mu, Eigen::Vector3d(1, 1, 1), c, 0.5, low, high, &a); }),
             "differ");
  EXPECT_HAS(ErrorOf([&] {
               SolveInMetric(mu, Eigen::Vector2d(1, 1), c, 0.5, Eigen::Vector2d(1, -1),
                             Eigen::Vector2d(0, 1), &a);
             }),
             "box [1, 0] of coordinate 0: need low <= high");
  GaussianMetricScratch small;
  small.Resize(1);
  a.resize(2);
  EXPECT_HAS(ErrorOf([&] {
               ProjectInGaussianMetric(mu, Eigen::Vector2d(1, 1), c, 0.5, low, high, a, small);
             }),
             "scratch 1");
}

// The shield, on h(s) = w . s + 0.5 (w = (1, -2)) with the integrator s' = s + 0.1 a and
// alpha(h) = 2 h: g(a) = w . a + 0.2, exactly affine. The CBF-QP filter in the policy's metric
// returns mu + lambda S w, S = diag(sigma^2), lambda = (-0.2 - w . mu) / (w^T S w); the
// Euclidean one mu + (-0.2 - w . mu) / |w|^2 w.
TEST(QpMetricShieldTest, TheFilterReturnsTheProjectionInThePolicysMetric) {
  const IntegratorDynamics dynamics(2, 0.1);
  const Eigen::Vector2d w(1, -2);
  const Eigen::VectorXf state = Vec({0.2f, 0.3f});    // h = 0.1
  const Eigen::VectorXf mu = Vec({-1.0f, 1.0f});      // g = -2.8
  const Eigen::VectorXf sigma = Vec({0.14f, 0.04f});  // Panda's x and y
  ShieldOptions o;
  o.proposal = Proposal::kQpOnly;
  o.class_k_gain = 2.0;
  o.qp_metric = QpMetric::kPolicy;
  const auto b1 = LinearBarrier(), b2 = LinearBarrier();
  Shield policy(o, *b1, dynamics);
  o.qp_metric = QpMetric::kEuclidean;
  Shield euclidean(o, *b2, dynamics);
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

TEST(QpMetricShieldTest, ASigmaWithAZeroEntryIsAClearError) {
  const IntegratorDynamics dynamics(2, 0.1);
  for (const Proposal proposal : {Proposal::kQp, Proposal::kQpOnly}) {
    ShieldOptions o;
    o.proposal = proposal;
    o.qp_metric = QpMetric::kPolicy;
    const auto b = LinearBarrier();
    Shield shield(o, *b, dynamics);
    const std::string error =
        ErrorOf([&] { shield.Decide(Vec({0.2f, 0.3f}), Vec({-1.0f, 1.0f}), Vec({0.1f, 0.0f})); });
    EXPECT_HAS(error, "qp_metric = policy needs the policy's sigma > 0");
    EXPECT_HAS(error, "sigma[1] = 0");
    // A negative or NaN sigma stays what it was: invalid input, nothing checked.
    EXPECT_EQ(shield.Decide(Vec({0.2f, 0.3f}), Vec({-1.0f, 1.0f}), Vec({0.1f, -1.0f})).status,
              Status::kInvalidInput);
    // The Euclidean metric takes it (a deterministic policy).
    o.qp_metric = QpMetric::kEuclidean;
    const auto b2 = LinearBarrier();
    Shield plain(o, *b2, dynamics);
    EXPECT_TRUE(plain.Decide(Vec({0.2f, 0.3f}), Vec({-1.0f, 1.0f}), Vec({0.1f, 0.0f})).safe());
  }
  // proposal none and refine ignore the option: no error.
  for (const Proposal proposal : {Proposal::kNone, Proposal::kRefine}) {
    ShieldOptions o;
    o.proposal = proposal;
    o.qp_metric = QpMetric::kPolicy;
    const auto b = LinearBarrier();
    Shield shield(o, *b, dynamics);
    EXPECT_NE(shield.Decide(Vec({0.2f, 0.3f}), Vec({1.0f, 0.0f}), Vec({0.1f, 0.0f})).status,
              Status::kInvalidInput);
  }
}

TEST(QpMetricShieldTest, TheOptionIsReadWrittenOnlyWhereItActsAndChecked) {
  ShieldOptions o;
  EXPECT_EQ(o.qp_metric, QpMetric::kEuclidean);
  o.qp_metric = QpMetric::kPolicy;
  EXPECT_FALSE(o.ToJson().contains("qp_metric"));  // proposal none: no projection
  for (const Proposal proposal : {Proposal::kQp, Proposal::kQpOnly}) {
    o.proposal = proposal;
    EXPECT_EQ(o.ToJson()["qp_metric"], "policy");
  }
  o.proposal = Proposal::kRefine;
  EXPECT_FALSE(o.ToJson().contains("qp_metric"));
  // The default writes nothing: the options (and run directories) of every existing shield keep
  // their bytes.
  ShieldOptions plain;
  plain.proposal = Proposal::kQp;
  EXPECT_FALSE(plain.ToJson().contains("qp_metric"));
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

}  // namespace
}  // namespace secure::shield
