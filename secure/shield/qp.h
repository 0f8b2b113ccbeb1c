#pragma once
// The CBF-QP's quadratic program: the Euclidean projection of a point onto one half-space
// intersected with a box,
//
//   min ||a - mu||^2   subject to   c . a >= d,   low <= a <= high,
//
// solved exactly (no iteration tolerance) in O(n^2) for n = dim(a), without allocation. The
// KKT conditions give a(lambda) = clip(mu + lambda c, low, high) with a multiplier lambda >= 0:
// lambda = 0 when clip(mu) satisfies the half-space, else the root of phi(lambda) = c . a(lambda)
// = d. phi is piecewise linear and nondecreasing, with at most 2n breakpoints (each coordinate
// enters and leaves its box interval once): the solver sorts them, finds the segment where phi
// crosses d and solves the linear piece there. OSQP and qpOASES (the usual solvers of CBF-QP
// filters) are not in Debian 12; with one constraint and a box this is all they would do.
//
// Infeasible (max over the box of c . a < d): the result is that maximiser (the box point of
// largest c . a: high where c > 0, low where c < 0, clip(mu) where c = 0), with kInfeasible.
//
// ProjectInGaussianMetric solves the same problem in the metric of a diagonal Gaussian
// N(mu, diag(sigma^2)) (the shield's qp_metric = policy):
//
//   min sum_i ((a_i - mu_i) / sigma_i)^2   subject to   c . a >= d,   low <= a <= high,
//
// by the change of variables a = mu + sigma o z (o: element-wise): min ||z||^2 subject to
// (sigma o c) . z >= d - c . mu and (low - mu) / sigma <= z <= (high - mu) / sigma, which is the
// problem above projecting z = 0; then a = mu + sigma o z (clipped onto the box against rounding).
// Its solution is a = clip(mu + lambda sigma^2 o c): a coordinate moves in proportion to its
// variance, so the policy's sure directions (small sigma) move least.
//
// GaussianHalfSpaceMeanOffset gives the half-space whose projection in that metric is the mean of
// the Gaussian restricted to c . a >= d (the shield's qp_target = safe-mean): with s = |sigma o c|
// and beta = (d - c . mu) / s, E[a | c . a >= d] = mu + lambda(beta) sigma^2 o c / s, where
// lambda(beta) = phi(beta) / (1 - Phi(beta)) is the inverse Mills ratio (> max(beta, 0)); that is
// the projection onto c . a >= d' with d' = c . mu + s lambda(beta) >= d. Without a box the
// projection is that mean exactly; with one it is the nearest box point of the tightened
// half-space.

#include <Eigen/Core>
#include <vector>

#include "secure/common/enum_strings.h"

namespace secure::shield {

enum class QpStatus {
  kOptimal,     // the projection; c . a >= d up to rounding
  kInfeasible,  // the half-space misses the box: `a` is the box point of largest c . a
};
inline constexpr EnumTable<QpStatus, 2> kQpStatusNames{{
    {QpStatus::kOptimal, "optimal"},
    {QpStatus::kInfeasible, "infeasible"},
}};

struct QpResult {
  QpStatus status = QpStatus::kOptimal;
  double multiplier = 0.0;  // lambda (+inf when infeasible)
};

/// Solves the problem above into `a` (n). `low`/`high` may hold -inf/+inf (unbounded sides);
/// low <= high, everything else finite. `scratch` holds the breakpoints: give it a capacity of
/// 2n (reserve) and no call allocates.
/// @throws secure::Error on mismatched sizes, NaN, or low > high.
QpResult ProjectOntoHalfSpaceAndBox(const Eigen::Ref<const Eigen::VectorXd>& mu,
                                    const Eigen::Ref<const Eigen::VectorXd>& c, double d,
                                    const Eigen::Ref<const Eigen::VectorXd>& low,
                                    const Eigen::Ref<const Eigen::VectorXd>& high,
                                    Eigen::Ref<Eigen::VectorXd> a, std::vector<double>& scratch);

/// The scratch of ProjectInGaussianMetric: the transformed problem. Resize(n) once, and no call
/// allocates.
struct GaussianMetricScratch {
  Eigen::VectorXd origin, normal, low, high, z;  // (n) the problem in z = (a - mu) / sigma
  std::vector<double> breakpoints;               // capacity 2n
  void Resize(Eigen::Index n);
};

/// The projection in the metric of N(mu, diag(sigma^2)) (above) into `a`; the status and the
/// multiplier are those of the problem in z (the same lambda as in a = clip(mu + lambda sigma^2 o
/// c)). @throws secure::Error as ProjectOntoHalfSpaceAndBox, and on a sigma of the wrong size or
/// with an entry that is not finite and > 0 (the metric needs every sigma_i > 0).
QpResult ProjectInGaussianMetric(const Eigen::Ref<const Eigen::VectorXd>& mu,
                                 const Eigen::Ref<const Eigen::VectorXd>& sigma,
                                 const Eigen::Ref<const Eigen::VectorXd>& c, double d,
                                 const Eigen::Ref<const Eigen::VectorXd>& low,
                                 const Eigen::Ref<const Eigen::VectorXd>& high,
                                 Eigen::Ref<Eigen::VectorXd> a, GaussianMetricScratch& scratch);

/// The inverse Mills ratio of the standard normal, phi(x) / (1 - Phi(x)), for any finite x:
/// E[Z | Z >= x] for Z ~ N(0, 1). Exact through erfc where 1 - Phi(x) is representable, its
/// asymptotic series beyond x = 25 (relative error < 1e-11 there).
double InverseMillsRatio(double x);

/// d' above: the offset whose ProjectInGaussianMetric (without a box) is E[a | c . a >= d] under
/// N(mu, diag(sigma^2)). Returns d when sigma o c = 0 (no spread along c: nothing to average).
/// @throws secure::Error on mismatched sizes or a non-finite input.
double GaussianHalfSpaceMeanOffset(const Eigen::Ref<const Eigen::VectorXd>& mu,
                                   const Eigen::Ref<const Eigen::VectorXd>& sigma,
                                   const Eigen::Ref<const Eigen::VectorXd>& c, double d);

}  // namespace secure::shield
