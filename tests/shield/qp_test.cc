// The CBF-QP's projection (qp.h) against a brute-force grid on random half-spaces and boxes
// (RapidCheck, with the fixed seed every ctest run of shield_test uses), and its special cases;
// the same in the metric of a diagonal Gaussian (ProjectInGaussianMetric, the shield's qp_metric
// = policy): the grid in the weighted metric, equal sigma against the Euclidean answer, the
// closed form without a box, bad input; the mean of the Gaussian over a half-space
// (GaussianHalfSpaceMeanOffset, the shield's qp_target = safe-mean) against the inverse Mills
// ratio's known values and against the average of the draws that satisfy the half-space.

#include "secure/shield/qp.h"

#include <gtest/gtest.h>
#include <rapidcheck.h>
#include <rapidcheck/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "tests/test_util.h"

namespace secure::shield {
namespace {

using secure::test::ErrorOf;

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

QpResult Solve(const Eigen::VectorXd& mu, const Eigen::VectorXd& c, double d,
               const Eigen::VectorXd& low, const Eigen::VectorXd& high, Eigen::VectorXd* a) {
  std::vector<double> scratch;
  scratch.reserve(static_cast<std::size_t>(2 * mu.size()));
  a->resize(mu.size());
  return ProjectOntoHalfSpaceAndBox(mu, c, d, low, high, *a, scratch);
}

// In 1 to 3 dimensions: the answer lies in the box and the half-space, every grid point of the
// box (`steps` per axis) that satisfies the half-space is no closer to mu, and infeasibility is reported exactly when no point of the box satisfies
// the half-space (the box's maximiser of c . a decides, the grid holds the corners).
RC_GTEST_PROP(QpProperty, MatchesABruteForceGrid, ()) {
  const int n = *rc::gen::inRange(1, 4);
  const Eigen::VectorXd low = RandomVector(n, -3, 0);
  Eigen::VectorXd high = low;
  for (int i = 0; i < n; ++i) high[i] += *UniformIn(0.0, 4.0);  // width 0 allowed
  const Eigen::VectorXd mu = RandomVector(n, -5, 5);
  Eigen::VectorXd c = RandomVector(n, -2, 2);
  if (*rc::gen::inRange(0, 5) == 0) c[*rc::gen::inRange(0, n)] = 0.0;  // an axis c ignores
  const double d = *UniformIn(-6, 6);
  Eigen::VectorXd a;
  const QpResult result = Solve(mu, c, d, low, high, &a);
  // In the box always.
  for (int i = 0; i < n; ++i) RC_ASSERT(a[i] >= low[i] && a[i] <= high[i]);
  double box_max = 0.0;
  for (int i = 0; i < n; ++i) box_max += c[i] > 0 ? c[i] * high[i] : c[i] * low[i];
  if (result.status == QpStatus::kInfeasible) {
    RC_ASSERT(box_max < d);
    RC_ASSERT(std::abs(c.dot(a) - box_max) <= 1e-9 * (1 + std::abs(box_max)));
    return;
  }
  RC_ASSERT(box_max >= d);
  RC_ASSERT(c.dot(a) >= d - 1e-9 * (1 + std::abs(d)));
  const double best = (a - mu).squaredNorm();
  // The grid: no feasible point is closer than the answer (up to rounding).
  const int steps = n == 1 ? 2001 : n == 2 ? 201 : 41;
  Eigen::VectorXi index = Eigen::VectorXi::Zero(n);
  double grid_best = kInf;
  for (;;) {
    Eigen::VectorXd p(n);
    for (int i = 0; i < n; ++i) p[i] = low[i] + (high[i] - low[i]) * index[i] / (steps - 1);
    if (c.dot(p) >= d) {
      const double dist = (p - mu).squaredNorm();
      RC_ASSERT(dist >= best - 1e-9 * (1 + best));
      grid_best = std::min(grid_best, dist);
    }
    int k = 0;
    while (k < n && ++index[k] == steps) index[k++] = 0;
    if (k == n) break;
  }
  // Together with its feasibility: optimal among the grid's points (and no grid point of the
  // half-space is missed: the box's corners are grid points).
  RC_ASSERT(!std::isfinite(grid_best) || grid_best >= best - 1e-9 * (1 + best));
}

// Unbounded sides (infinite box bounds) and the plain projection onto a half-space.
RC_GTEST_PROP(QpProperty, WithoutABoxIsTheHalfSpaceProjection, ()) {
  const int n = *rc::gen::inRange(1, 6);
  const Eigen::VectorXd mu = RandomVector(n, -5, 5);
  Eigen::VectorXd c = RandomVector(n, -2, 2);
  c[0] += c[0] >= 0 ? 0.1 : -0.1;  // c != 0
  const double d = *UniformIn(-6, 6);
  const Eigen::VectorXd low = Eigen::VectorXd::Constant(n, -kInf);
  const Eigen::VectorXd high = Eigen::VectorXd::Constant(n, kInf);
  Eigen::VectorXd a;
  const QpResult result = Solve(mu, c, d, low, high, &a);
  RC_ASSERT(result.status == QpStatus::kOptimal);
  const double violation = std::max(0.0, d - c.dot(mu));
  const Eigen::VectorXd expected = mu + violation / c.squaredNorm() * c;
  RC_ASSERT((a - expected).norm() <= 1e-9 * (1 + expected.norm()));
}

TEST(QpTest, AFeasibleMeanIsReturnedClipped) {
  Eigen::VectorXd a;
  const QpResult r = Solve(Eigen::Vector2d(3, 0.5), Eigen::Vector2d(1, 0), -10,
                           Eigen::Vector2d(-1, -1), Eigen::Vector2d(1, 1), &a);
  EXPECT_EQ(r.status, QpStatus::kOptimal);
  EXPECT_EQ(r.multiplier, 0.0);
  EXPECT_EQ(a, Eigen::Vector2d(1, 0.5));
}

TEST(QpTest, TheMultiplierCrossesABreakpoint) {
  // mu = (0, 0), c = (1, 1), d = 1.5, box [-1, 0.5] x [-1, 2]: a = (lambda, lambda) until x hits
  // 0.5 at lambda = 0.5 (c . a = 1), then only y moves: y = 1.
  Eigen::VectorXd a;
  const QpResult r = Solve(Eigen::Vector2d(0, 0), Eigen::Vector2d(1, 1), 1.5,
                           Eigen::Vector2d(-1, -1), Eigen::Vector2d(0.5, 2), &a);
  EXPECT_EQ(r.status, QpStatus::kOptimal);
  EXPECT_NEAR(a[0], 0.5, 1e-12);
  EXPECT_NEAR(a[1], 1.0, 1e-12);
  EXPECT_NEAR(r.multiplier, 1.0, 1e-12);
}

TEST(QpTest, InfeasibleGivesTheBoxMaximiser) {
  Eigen::VectorXd a;
  const QpResult r = Solve(Eigen::Vector3d(0, 0, 0.25), Eigen::Vector3d(1, -1, 0), 5,
                           Eigen::Vector3d(-1, -1, -1), Eigen::Vector3d(1, 1, 1), &a);
  EXPECT_EQ(r.status, QpStatus::kInfeasible);
  EXPECT_TRUE(std::isinf(r.multiplier));
  EXPECT_EQ(a, Eigen::Vector3d(1, -1, 0.25));
  // c = 0: feasible iff d <= 0.
  EXPECT_EQ(Solve(Eigen::Vector2d(2, 0), Eigen::Vector2d::Zero(), 0.5, Eigen::Vector2d(-1, -1),
                  Eigen::Vector2d(1, 1), &a)
                .status,
            QpStatus::kInfeasible);
  EXPECT_EQ(a, Eigen::Vector2d(1, 0));
  EXPECT_EQ(Solve(Eigen::Vector2d(2, 0), Eigen::Vector2d::Zero(), -0.5, Eigen::Vector2d(-1, -1),
                  Eigen::Vector2d(1, 1), &a)
                .status,
            QpStatus::kOptimal);
}

TEST(QpTest, BadInputIsRejected) {
  Eigen::VectorXd a;
  EXPECT_HAS(ErrorOf([&] {
               Solve(Eigen::Vector2d(0, 0), Eigen::Vector2d(1, 1), 0, Eigen::Vector2d(1, -1),
                     Eigen::Vector2d(0, 1), &a);
             }),
             "box [1, 0] of coordinate 0: need low <= high");
  EXPECT_HAS(ErrorOf([&] {
               Solve(Eigen::Vector2d(0, std::nan("")), Eigen::Vector2d(1, 1), 0,
                     Eigen::Vector2d(-1, -1), Eigen::Vector2d(1, 1), &a);
             }),
             "mu, c and d must be finite");
}

// ---------------------------------------------------------------------------------------------
// In the metric of N(mu, diag(sigma^2)).

QpResult SolveInMetric(const Eigen::VectorXd& mu, const Eigen::VectorXd& sigma,
                       const Eigen::VectorXd& c, double d, const Eigen::VectorXd& low,
                       const Eigen::VectorXd& high, Eigen::VectorXd* a) {
  GaussianMetricScratch scratch;
  scratch.Resize(mu.size());
  a->resize(mu.size());
  return ProjectInGaussianMetric(mu, sigma, c, d, low, high, *a, scratch);
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
  if (Solve(mu, c, d, low, high, &e).status == QpStatus::kOptimal)
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
  const QpResult euclidean = Solve(mu, c, d, low, high, &e);
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

// The ratio phi(x) / (1 - Phi(x)) as written, for x where 1 - Phi(x) is representable.
double DirectMillsRatio(double x) {
  return std::exp(-0.5 * x * x) / std::sqrt(2 * M_PI) / (0.5 * std::erfc(x / std::sqrt(2.0)));
}

TEST(GaussianHalfSpaceMeanTest, TheInverseMillsRatioHasItsKnownValues) {
  EXPECT_NEAR(InverseMillsRatio(0.0), std::sqrt(2 / M_PI), 1e-15);  // E[Z | Z >= 0]
  // Deep in the tail: the asymptotic branch (x > 25) against the ratio as written.
  for (const double x : {25.5, 26.0, 30.0, 35.0})
    EXPECT_NEAR(InverseMillsRatio(x) / DirectMillsRatio(x), 1.0, 1e-11) << x;
  // Continuous across the switch, where the slope is lambda (lambda - x) ~ 1.
  const double below = InverseMillsRatio(25.0), above = InverseMillsRatio(25.0 + 1e-7);
  EXPECT_NEAR(above - below, 1e-7, 1e-9);
  // Far on the safe side it vanishes; it always exceeds max(x, 0) and grows with x.
  EXPECT_LT(InverseMillsRatio(-40.0), 1e-300);
  double previous = 0.0;
  for (double x = -10; x <= 60; x += 0.5) {
    const double value = InverseMillsRatio(x);
    EXPECT_GT(value, std::max(x, 0.0)) << x;
    EXPECT_GT(value, previous) << x;
    previous = value;
  }
  EXPECT_HAS(ErrorOf([] { InverseMillsRatio(std::nan("")); }), "x = nan, must be finite");
}

// The projection onto the tightened half-space is the mean of the draws of N(mu, diag(sigma^2))
// that satisfy c . a >= d: 400,000 draws with a fixed seed, within 5 standard errors per axis,
// for a mean outside the half-space, on its boundary and inside it.
TEST(GaussianHalfSpaceMeanTest, TheProjectionIsTheMeanOfTheDrawsThatSatisfyTheHalfSpace) {
  const Eigen::Vector3d mu(0.3, -0.2, 0.5), sigma(0.5, 0.1, 0.2), c(1.0, -2.0, 0.5);
  std::mt19937_64 engine(7);
  std::normal_distribution<double> normal;
  for (const double beta : {1.5, 0.0, -1.0}) {
    const double s = sigma.cwiseProduct(c).norm();
    const double d = c.dot(mu) + beta * s;
    Eigen::VectorXd a;
    const double offset = GaussianHalfSpaceMeanOffset(mu, sigma, c, d);
    EXPECT_GE(offset, d);
    SolveInMetric(mu, sigma, c, offset, Eigen::Vector3d::Constant(-kInf),
                  Eigen::Vector3d::Constant(kInf), &a);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum2 = Eigen::Vector3d::Zero();
    int kept = 0;
    for (int i = 0; i < 400000; ++i) {
      Eigen::Vector3d x;
      for (int r = 0; r < 3; ++r) x[r] = mu[r] + sigma[r] * normal(engine);
      if (c.dot(x) < d) continue;
      sum += x;
      sum2 += x.cwiseProduct(x);
      ++kept;
    }
    ASSERT_GT(kept, 1000);
    const Eigen::Vector3d mean = sum / kept;
    for (int r = 0; r < 3; ++r) {
      const double stderr_r = std::sqrt((sum2[r] / kept - mean[r] * mean[r]) / kept);
      EXPECT_NEAR(a[r], mean[r], 5 * stderr_r) << "beta " << beta << " axis " << r;
    }
  }
}

TEST(GaussianHalfSpaceMeanTest, NoSpreadAlongTheNormalKeepsTheHalfSpaceAndBadInputIsRejected) {
  // sigma o c = 0: every draw has the same c . a, nothing to average.
  EXPECT_EQ(GaussianHalfSpaceMeanOffset(Eigen::Vector2d(1, 2), Eigen::Vector2d(0.5, 0.0),
                                        Eigen::Vector2d(0.0, 3.0), 4.25),
            4.25);
  EXPECT_HAS(ErrorOf([] {
               GaussianHalfSpaceMeanOffset(Eigen::Vector2d(1, 2), Eigen::Vector3d(1, 1, 1),
                                           Eigen::Vector2d(1, 1), 0.0);
             }),
             "sizes 2, 3, 2 differ");
  EXPECT_HAS(ErrorOf([] {
               GaussianHalfSpaceMeanOffset(Eigen::Vector2d(1, 2), Eigen::Vector2d(1, 1),
                                           Eigen::Vector2d(1, 1), kInf);
             }),
             "non-finite mu, sigma, c or d (d = inf)");
}

}  // namespace
}  // namespace secure::shield
