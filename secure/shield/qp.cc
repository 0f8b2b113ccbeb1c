#include "secure/shield/qp.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "secure/common/error.h"

namespace secure::shield {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// c . clip(mu + lambda c) for lambda >= 0 (finite).
double Phi(const Eigen::Ref<const Eigen::VectorXd>& mu, const Eigen::Ref<const Eigen::VectorXd>& c,
           const Eigen::Ref<const Eigen::VectorXd>& low,
           const Eigen::Ref<const Eigen::VectorXd>& high, double lambda) {
  double phi = 0.0;
  for (Eigen::Index i = 0; i < mu.size(); ++i) {
    if (c[i] == 0.0) continue;
    phi += c[i] * std::clamp(mu[i] + lambda * c[i], low[i], high[i]);
  }
  return phi;
}

// d phi / d lambda just after lambda: the sum of c_i^2 over the coordinates strictly inside (or
// moving into) their interval.
double Slope(const Eigen::Ref<const Eigen::VectorXd>& mu, const Eigen::Ref<const Eigen::VectorXd>& c,
             const Eigen::Ref<const Eigen::VectorXd>& low,
             const Eigen::Ref<const Eigen::VectorXd>& high, double lambda) {
  double slope = 0.0;
  for (Eigen::Index i = 0; i < mu.size(); ++i) {
    if (c[i] == 0.0) continue;
    const double x = mu[i] + lambda * c[i];
    // Moving up (c > 0) it grows while below high and at or above low; down symmetric.
    const bool free = c[i] > 0 ? (x >= low[i] && x < high[i]) : (x <= high[i] && x > low[i]);
    if (free) slope += c[i] * c[i];
  }
  return slope;
}

// The checks both solvers share: mu, c, d finite; low <= high without NaN. `who` names the caller.
void CheckProblem(const char* who, const Eigen::Ref<const Eigen::VectorXd>& mu,
                  const Eigen::Ref<const Eigen::VectorXd>& c, double d,
                  const Eigen::Ref<const Eigen::VectorXd>& low,
                  const Eigen::Ref<const Eigen::VectorXd>& high) {
  SECURE_CHECK(mu.allFinite() && c.allFinite() && std::isfinite(d),
               who << ": mu, c and d must be finite");
  for (Eigen::Index i = 0; i < mu.size(); ++i)
    SECURE_CHECK(!std::isnan(low[i]) && !std::isnan(high[i]) && low[i] <= high[i],
                 who << ": box [" << low[i] << ", " << high[i] << "] of coordinate " << i
                     << ": need low <= high, no NaN");
}

}  // namespace

QpResult ProjectOntoHalfSpaceAndBox(const Eigen::Ref<const Eigen::VectorXd>& mu,
                                    const Eigen::Ref<const Eigen::VectorXd>& c, double d,
                                    const Eigen::Ref<const Eigen::VectorXd>& low,
                                    const Eigen::Ref<const Eigen::VectorXd>& high,
                                    Eigen::Ref<Eigen::VectorXd> a, std::vector<double>& scratch) {
  const Eigen::Index n = mu.size();
  SECURE_CHECK(c.size() == n && low.size() == n && high.size() == n && a.size() == n,
               "ProjectOntoHalfSpaceAndBox: sizes " << n << ", " << c.size() << ", " << low.size()
                                                    << ", " << high.size() << ", " << a.size()
                                                    << " differ");
  CheckProblem("ProjectOntoHalfSpaceAndBox", mu, c, d, low, high);
  QpResult result;
  // lambda = 0: the box projection of mu, if it satisfies the half-space.
  if (Phi(mu, c, low, high, 0.0) >= d) {
    for (Eigen::Index i = 0; i < n; ++i) a[i] = std::clamp(mu[i], low[i], high[i]);
    return result;
  }
  // The supremum of phi: each coordinate at the end of its interval in c's direction.
  double sup = 0.0;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (c[i] > 0) sup += c[i] * high[i];
    if (c[i] < 0) sup += c[i] * low[i];
  }
  if (sup < d) {  // +inf never is; NaN cannot occur (bounds are not NaN, c finite)
    for (Eigen::Index i = 0; i < n; ++i) {
      a[i] = c[i] > 0 ? high[i] : c[i] < 0 ? low[i] : std::clamp(mu[i], low[i], high[i]);
    }
    result.status = QpStatus::kInfeasible;
    result.multiplier = kInf;
    return result;
  }
  // The breakpoints: where mu_i + lambda c_i reaches low_i or high_i, for lambda > 0.
  scratch.clear();
  for (Eigen::Index i = 0; i < n; ++i) {
    if (c[i] == 0.0) continue;
    for (const double bound : {low[i], high[i]}) {
      if (!std::isfinite(bound)) continue;
      const double lambda = (bound - mu[i]) / c[i];
      if (lambda > 0 && std::isfinite(lambda)) scratch.push_back(lambda);
    }
  }
  std::sort(scratch.begin(), scratch.end());
  // Walk the segments [lo, hi] of phi's linear pieces until phi(hi) >= d; the root is in it.
  double lo = 0.0, phi_lo = Phi(mu, c, low, high, 0.0);
  double lambda = kInf;
  for (const double hi : scratch) {
    if (hi <= lo) continue;
    const double phi_hi = Phi(mu, c, low, high, hi);
    if (phi_hi >= d) {
      // Linear between lo and hi.
      lambda = phi_hi > phi_lo ? lo + (d - phi_lo) * (hi - lo) / (phi_hi - phi_lo) : hi;
      lambda = std::clamp(lambda, lo, hi);
      break;
    }
    lo = hi;
    phi_lo = phi_hi;
  }
  if (!std::isfinite(lambda)) {
    // Past the last breakpoint phi keeps growing (an unbounded side) at a constant slope.
    const double slope = Slope(mu, c, low, high, lo);
    SECURE_INTERNAL_CHECK(slope > 0, "ProjectOntoHalfSpaceAndBox: phi stalls below its supremum");
    lambda = lo + (d - phi_lo) / slope;
  }
  for (Eigen::Index i = 0; i < n; ++i) a[i] = std::clamp(mu[i] + lambda * c[i], low[i], high[i]);
  result.multiplier = lambda;
  return result;
}

void GaussianMetricScratch::Resize(Eigen::Index n) {
  origin = Eigen::VectorXd::Zero(n);
  normal.resize(n);
  low.resize(n);
  high.resize(n);
  z.resize(n);
  breakpoints.reserve(static_cast<std::size_t>(2 * n));
}

QpResult ProjectInGaussianMetric(const Eigen::Ref<const Eigen::VectorXd>& mu,
                                 const Eigen::Ref<const Eigen::VectorXd>& sigma,
                                 const Eigen::Ref<const Eigen::VectorXd>& c, double d,
                                 const Eigen::Ref<const Eigen::VectorXd>& low,
                                 const Eigen::Ref<const Eigen::VectorXd>& high,
                                 Eigen::Ref<Eigen::VectorXd> a, GaussianMetricScratch& scratch) {
  const Eigen::Index n = mu.size();
  SECURE_CHECK(sigma.size() == n && c.size() == n && low.size() == n && high.size() == n &&
                   a.size() == n && scratch.z.size() == n,
               "ProjectInGaussianMetric: sizes "
                   << n << ", " << sigma.size() << ", " << c.size() << ", " << low.size() << ", "
                   << high.size() << ", " << a.size() << ", scratch " << scratch.z.size()
                   << " differ");
  CheckProblem("ProjectInGaussianMetric", mu, c, d, low, high);
  for (Eigen::Index i = 0; i < n; ++i)
    SECURE_CHECK(std::isfinite(sigma[i]) && sigma[i] > 0, "ProjectInGaussianMetric: sigma["
                                                              << i << "] = " << sigma[i]
                                                              << ", must be finite and > 0");
  // The problem in z = (a - mu) / sigma. An infinite bound stays infinite; a finite one over a
  // tiny sigma may overflow to +-inf, which is the same box in z.
  double offset = d;
  for (Eigen::Index i = 0; i < n; ++i) {
    scratch.normal[i] = sigma[i] * c[i];
    scratch.low[i] = (low[i] - mu[i]) / sigma[i];
    scratch.high[i] = (high[i] - mu[i]) / sigma[i];
    offset -= c[i] * mu[i];
  }
  const QpResult result =
      ProjectOntoHalfSpaceAndBox(scratch.origin, scratch.normal, offset, scratch.low, scratch.high,
                                 scratch.z, scratch.breakpoints);
  for (Eigen::Index i = 0; i < n; ++i)
    a[i] = std::clamp(mu[i] + sigma[i] * scratch.z[i], low[i], high[i]);
  return result;
}

double InverseMillsRatio(double x) {
  SECURE_CHECK(std::isfinite(x), "InverseMillsRatio: x = " << x << ", must be finite");
  // 1 - Phi(x) = erfc(x / sqrt(2)) / 2 keeps full relative precision up to x ~ 37 (then
  // underflows); from x = 25 the series x + 1/x - 2/x^3 + 10/x^5 - 74/x^7 is good to a relative
  // 1e-11.
  if (x > 25.0) {
    const double r = 1.0 / (x * x);
    return x + (1.0 / x) * (1.0 - r * (2.0 - r * (10.0 - 74.0 * r)));
  }
  constexpr double kInvSqrt2Pi = 0.39894228040143267794;
  constexpr double kInvSqrt2 = 0.70710678118654752440;
  const double tail = 0.5 * std::erfc(x * kInvSqrt2);
  return kInvSqrt2Pi * std::exp(-0.5 * x * x) / tail;
}

double GaussianHalfSpaceMeanOffset(const Eigen::Ref<const Eigen::VectorXd>& mu,
                                   const Eigen::Ref<const Eigen::VectorXd>& sigma,
                                   const Eigen::Ref<const Eigen::VectorXd>& c, double d) {
  const Eigen::Index n = mu.size();
  SECURE_CHECK(sigma.size() == n && c.size() == n,
               "GaussianHalfSpaceMeanOffset: sizes " << n << ", " << sigma.size() << ", "
                                                     << c.size() << " differ");
  SECURE_CHECK(mu.allFinite() && sigma.allFinite() && c.allFinite() && std::isfinite(d),
               "GaussianHalfSpaceMeanOffset: a non-finite mu, sigma, c or d (d = " << d << ")");
  double cmu = 0.0, s2 = 0.0;
  for (Eigen::Index i = 0; i < n; ++i) {
    cmu += c[i] * mu[i];
    s2 += (sigma[i] * c[i]) * (sigma[i] * c[i]);
  }
  const double s = std::sqrt(s2);
  if (!(s > 0)) return d;
  return cmu + s * InverseMillsRatio((d - cmu) / s);
}

}  // namespace secure::shield
