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

}  // namespace secure::shield
