// The shield's gradient-based proposals (shield.h, Proposal): the linearisation of g at an action
// (the barrier's gradient at the predicted state and the model's action Jacobian), the CBF-QP
// projection of the policy's mean (proposal qp, qp-only) and the gradient refinement of the mean
// (proposal refine). The projection is Euclidean or in the policy's metric (qp_metric), onto the
// linearised boundary or the Gaussian's mean over the linearised half-space (qp_target); a line
// search (qp_line_search) and a bisection (qp_bisection) on the exact g along the projection's
// line mend a linearisation that fell short or overshot, and a last round on g's slope over the
// policy's scale (qp_smoothing) one that pointed the wrong way. Each checks what it returns with
// the exact g, as every sample is checked.
#include <algorithm>
#include <cmath>
#include <limits>

#include "secure/common/error.h"
#include "secure/shield/qp.h"
#include "secure/shield/shield.h"

namespace secure::shield {
namespace {

// The allowance for float rounding in g, per unit of (1 + |h(s)|) / dt: g's float h values are
// good to a few ulps, about 1e-6 of |h|; 1e-4 is far above that and far below any g that
// matters. Without it a projection exactly on the linearised boundary would fail the exact check
// half the time.
constexpr double kQpRoundingMargin = 1e-4;

double RoundingMargin(double h_state, double dt) {
  return kQpRoundingMargin * (1.0 + std::abs(h_state)) / dt;
}

// Records an exactly checked action (column 0 of `action`, its exact g) as the decision's;
// returns whether it is accepted (g >= 0; a NaN g never is).
bool Record(Decision& decision, const Eigen::MatrixXf& action, double g) {
  decision.action = action.col(0);
  decision.g = g;
  if (!(g >= 0.0)) return false;
  decision.qp = QpOutcome::kAccepted;
  return true;
}

}  // namespace

void Shield::SetNeighbours(int r, float step) {
  const float a0 = qp_actions_(r, 0);
  qp_actions_.col(1 + 2 * r) = qp_actions_.col(0);
  qp_actions_.col(2 + 2 * r) = qp_actions_.col(0);
  qp_actions_(r, 1 + 2 * r) = bounds_active() ? std::min(a0 + step, high_[r]) : a0 + step;
  qp_actions_(r, 2 + 2 * r) = bounds_active() ? std::max(a0 - step, low_[r]) : a0 - step;
}

double Shield::NeighbourWidth(int r) const {
  return static_cast<double>(qp_actions_(r, 1 + 2 * r)) - qp_actions_(r, 2 + 2 * r);
}

double Shield::Linearise(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state) {
  const int n = action_dim_;
  const double inv_dt = 1.0 / options_.dt;
  // The point and its 2n neighbours (central differences of T in each action, inside the box:
  // one-sided at a face), then grad h at the predicted state T(s, a0).
  for (int r = 0; r < n; ++r) SetNeighbours(r, 1e-2f * std::max(1.0f, std::abs(qp_actions_(r, 0))));
  dynamics_.Step(state, qp_actions_, qp_next_);
  barrier_.EvaluateGradient(qp_next_.leftCols(1), qp_h_, qp_gradient_);
  for (int r = 0; r < n; ++r) {
    const double width = NeighbourWidth(r);
    if (width > 0) {
      qp_jacobian_.col(r) =
          (qp_next_.col(1 + 2 * r).cast<double>() - qp_next_.col(2 + 2 * r).cast<double>()) /
          width;
    } else {
      qp_jacobian_.col(r).setZero();  // a box of zero width in this action
    }
  }
  // c = J^T grad h / dt: g(a) ~ g(a0) + c . (a - a0).
  for (int r = 0; r < n; ++r) {  // a loop: Eigen would cast the gradient into a temporary
    double dot = 0.0;
    for (int i = 0; i < state_dim_; ++i)
      dot += qp_jacobian_(i, r) * static_cast<double>(qp_gradient_(i, 0));
    qp_normal_[r] = dot * inv_dt;
  }
  // g at the point, as linearised: g0 = (h(T(s, a0)) - h(s)) / dt + alpha(h(s)).
  return (static_cast<double>(qp_h_[0]) - h_state) * inv_dt + ClassKValue(options_, h_state);
}

void Shield::LineariseSmoothed(const Eigen::Ref<const Eigen::VectorXf>& state,
                               const Eigen::Ref<const Eigen::VectorXf>& sigma, double h_state) {
  const int n = action_dim_;
  // a0 +- qp_smoothing sigma_r along each action (inside the box: shorter at a face), their exact
  // g in one batch, and the central difference of each pair.
  for (int r = 0; r < n; ++r)
    SetNeighbours(r, static_cast<float>(options_.qp_smoothing) * sigma[r]);
  EvaluateG(state, h_state, qp_actions_.rightCols(2 * n), qp_g_);
  for (int r = 0; r < n; ++r) {
    const double width = NeighbourWidth(r);
    // sigma_r = 0 (or a box of zero width): no slope along this action.
    qp_normal_[r] = width > 0 ? (qp_g_[2 * r] - qp_g_[2 * r + 1]) / width : 0.0;
  }
}

QpResult Shield::Project(const Eigen::Ref<const Eigen::VectorXf>& sigma, double offset) {
  if (options_.qp_metric == QpMetric::kPolicy) {
    for (int r = 0; r < action_dim_; ++r) qp_sigma_[r] = sigma[r];
    return ProjectInGaussianMetric(qp_mu_, qp_sigma_, qp_normal_, offset, qp_low_, qp_high_,
                                   qp_solution_, qp_metric_scratch_);
  }
  return ProjectOntoHalfSpaceAndBox(qp_mu_, qp_normal_, offset, qp_low_, qp_high_, qp_solution_,
                                    qp_scratch_);
}

bool Shield::ProposeQp(const Eigen::Ref<const Eigen::VectorXf>& state,
                       const Eigen::Ref<const Eigen::VectorXf>& mu,
                       const Eigen::Ref<const Eigen::VectorXf>& sigma, double h_state) {
  const int n = action_dim_;
  if (options_.qp_metric == QpMetric::kPolicy) {
    // Decide has rejected a negative or non-finite sigma (kInvalidInput); a zero has no metric.
    for (int r = 0; r < n; ++r)
      SECURE_CHECK(sigma[r] > 0, "Shield: qp_metric = policy needs the policy's sigma > 0 in "
                                 "every action, sigma["
                                     << r << "] = " << sigma[r]
                                     << " (a deterministic policy: use qp_metric = euclidean)");
  }
  const double inf = std::numeric_limits<double>::infinity();
  for (int r = 0; r < n; ++r) {
    qp_mu_[r] = mu[r];
    qp_low_[r] = bounds_active() ? static_cast<double>(low_[r]) : -inf;
    qp_high_[r] = bounds_active() ? static_cast<double>(high_[r]) : inf;
  }
  // The first linearisation point: mu as the actuator applies it.
  qp_actions_.col(0) = mu;
  if (ClipToBox(qp_actions_.leftCols(1))) decision_.bounded = true;
  // mu first, with the exact g (one model step, one barrier evaluation): at mu the linearisation
  // is g(mu) itself, so when g(mu) >= qp_margin the QP's answer is mu, and the Jacobian and the
  // gradient (2n + 1 model steps and a backward pass) are needed only when mu fails.
  one_action_.col(0) = qp_actions_.col(0);
  EvaluateG(state, h_state, one_action_, one_g_);
  const double g_mu = one_g_[0];
  if (g_mu >= options_.qp_margin && Record(decision_, one_action_, g_mu)) return true;
  double g_point = g_mu;  // the exact g at the linearisation point
  decision_.intervened = true;  // the policy's mean failed the condition
  for (int round = 0; round < options_.qp_iterations; ++round) {
    // The linearisation's own value at its point. In round 0 that is g(mu) up to rounding for a
    // hand-written model; under a learned model it is h at the members' mean, not the pessimistic
    // g(mu) above: with the slope taken there too, the half-space is consistent, and on Panda it
    // gave 17-20 % fewer rejected projections than the pessimistic value (docs/RESULTS.md).
    for (int r = 0; r < n; ++r) qp_point_[r] = qp_actions_(r, 0);
    const double g0 = Linearise(state, h_state);
    const QpRound end = ProjectAndCheck(state, sigma, h_state, g0, g_point);
    if (end == QpRound::kAccepted) return true;
    if (end == QpRound::kStop) break;
  }
  if (options_.qp_smoothing > 0 && options_.proposal == Proposal::kQp) {
    // One more round from mu on the slope of g over the policy's own scale (qp_smoothing).
    qp_actions_.col(0) = mu;
    ClipToBox(qp_actions_.leftCols(1));
    for (int r = 0; r < n; ++r) qp_point_[r] = qp_actions_(r, 0);
    LineariseSmoothed(state, sigma, h_state);
    g_point = g_mu;
    return ProjectAndCheck(state, sigma, h_state, g_mu, g_point) == QpRound::kAccepted;
  }
  return false;
}

Shield::QpRound Shield::ProjectAndCheck(const Eigen::Ref<const Eigen::VectorXf>& state,
                                        const Eigen::Ref<const Eigen::VectorXf>& sigma,
                                        double h_state, double g0, double& g_point) {
  const int n = action_dim_;
  // The half-space c . a >= c . a0 - g0 + margin, where the margin adds to qp_margin what float
  // rounding of h costs g.
  double offset = options_.qp_margin + RoundingMargin(h_state, options_.dt) - g0;
  for (int r = 0; r < n; ++r) offset += qp_normal_[r] * qp_actions_(r, 0);
  QpResult result;
  if (qp_normal_.allFinite() && std::isfinite(offset)) {
    if (options_.qp_target == QpTarget::kSafeMean) {
      // The half-space tightened so that its projection in the policy's metric is the mean of
      // N(mu, sigma^2) over c . a >= offset (qp.h).
      for (int r = 0; r < n; ++r) qp_sigma_[r] = sigma[r];
      offset = GaussianHalfSpaceMeanOffset(qp_mu_, qp_sigma_, qp_normal_, offset);
    }
    result = Project(sigma, offset);
  } else {
    // A non-finite gradient or value: nothing to project onto; mu (clipped) is checked as is.
    result.status = QpStatus::kInfeasible;
    for (int r = 0; r < n; ++r) qp_solution_[r] = qp_actions_(r, 0);
  }
  if (TrustRegionActive() && options_.qp_bisection == 0 &&
      result.status != QpStatus::kInfeasible &&
      (qp_solution_ - qp_mu_).norm() > options_.qp_max_step) {
    // Beyond the trust region: the QP with |a - mu| <= qp_max_step is infeasible, and
    // sampling decides (proposal qp only: the filters alone have nothing to fall back to).
    // With bisection the projection is checked and bisected first (AcceptWithinTrustRegion).
    decision_.qp = QpOutcome::kInfeasible;
    return QpRound::kStop;
  }
  one_action_.col(0) = qp_solution_.cast<float>();
  ClipToBox(one_action_);  // rounding to float stays in the box
  EvaluateG(state, h_state, one_action_, one_g_);
  if (Record(decision_, one_action_, one_g_[0])) {
    Bisect(state, h_state, 0.0, g_point, 1.0, one_g_[0]);
    return AcceptWithinTrustRegion() ? QpRound::kAccepted : QpRound::kStop;
  }
  decision_.qp =
      result.status == QpStatus::kInfeasible ? QpOutcome::kInfeasible : QpOutcome::kRejected;
  // The next linearisation point (qp_iterations > 1): the projection as checked.
  qp_actions_.col(0) = one_action_.col(0);
  const double g_solution = one_g_[0];
  if (result.status != QpStatus::kInfeasible &&
      LineSearch(state, h_state, g_point, g_solution)) {
    return QpRound::kAccepted;
  }
  g_point = g_solution;
  return QpRound::kContinue;
}

bool Shield::LineSearch(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state,
                        double g_point, double g_solution) {
  const int n = action_dim_;
  const double target = options_.qp_margin + RoundingMargin(h_state, options_.dt);
  // The line's last two points (t, exact g): a0 at t = 0 and the projection a* at t = 1.
  double t_prev = 0.0, g_prev = g_point;
  double t_last = 1.0, g_last = g_solution;
  for (int step = 0; step < options_.qp_line_search; ++step) {
    const double slope = (g_last - g_prev) / (t_last - t_prev);
    // g does not rise along the line (or is not finite): the secant points nowhere.
    if (!(slope > 0) || !std::isfinite(slope) || !std::isfinite(g_last)) return false;
    // Past the boundary by the deficit just seen: on a g that curves below its secant the step
    // to g = target alone falls short again by about as much.
    const double t = t_last + 2.0 * (target - g_last) / slope;
    PointOnLine(t);
    if (TrustRegionActive() && options_.qp_bisection == 0 &&
        (one_action_.col(0).cast<double>() - qp_mu_).norm() > options_.qp_max_step) {
      return false;  // beyond the trust region, as a projection there would be
    }
    EvaluateG(state, h_state, one_action_, one_g_);
    if (Record(decision_, one_action_, one_g_[0])) {
      Bisect(state, h_state, t_last, g_last, t, one_g_[0]);
      return AcceptWithinTrustRegion();
    }
    t_prev = t_last;
    g_prev = g_last;
    t_last = t;
    g_last = one_g_[0];
  }
  return false;
}

bool Shield::TrustRegionActive() const {
  return options_.qp_max_step > 0 && options_.proposal == Proposal::kQp;
}

bool Shield::AcceptWithinTrustRegion() {
  // Without bisection every point was checked against the region before its evaluation.
  if (!TrustRegionActive() || options_.qp_bisection == 0) return true;
  if ((decision_.action.cast<double>() - qp_mu_).norm() <= options_.qp_max_step) return true;
  decision_.qp = QpOutcome::kInfeasible;  // as a projection beyond it: sampling decides
  return false;
}

void Shield::PointOnLine(double t) {
  for (int r = 0; r < action_dim_; ++r)
    one_action_(r, 0) = static_cast<float>(qp_point_[r] + t * (qp_solution_[r] - qp_point_[r]));
  ClipToBox(one_action_);
}

void Shield::Bisect(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state,
                    double t_unsafe, double g_unsafe, double t_safe, double g_safe) {
  const double target = options_.qp_margin + RoundingMargin(h_state, options_.dt);
  // Only past an overshoot: where g is close to linear along the line the accepted point sits
  // near the target already, and the midpoints would all fail.
  if (!(g_safe > target + 0.1 * (target - g_unsafe))) return;
  for (int step = 0; step < options_.qp_bisection; ++step) {
    const double t = 0.5 * (t_unsafe + t_safe);
    PointOnLine(t);
    EvaluateG(state, h_state, one_action_, one_g_);
    if (one_g_[0] >= target) {
      Record(decision_, one_action_, one_g_[0]);
      t_safe = t;
    } else {
      t_unsafe = t;
    }
  }
}

bool Shield::RefineMean(const Eigen::Ref<const Eigen::VectorXf>& state,
                        const Eigen::Ref<const Eigen::VectorXf>& mu, double h_state) {
  const int n = action_dim_;
  const double target = options_.qp_margin + RoundingMargin(h_state, options_.dt);
  qp_actions_.col(0) = mu;
  if (ClipToBox(qp_actions_.leftCols(1))) decision_.bounded = true;
  decision_.qp = QpOutcome::kRejected;
  for (int step = 0;; ++step) {
    // The exact check of the iterate: the first one with g >= 0 is the decision.
    one_action_.col(0) = qp_actions_.col(0);
    EvaluateG(state, h_state, one_action_, one_g_);
    if (Record(decision_, one_action_, one_g_[0])) return true;
    decision_.intervened = true;  // the policy's mean failed the condition
    if (step == options_.refine_steps) return false;
    // One projected gradient step on the hinge max(0, target - g): a Polyak step along c = grad_a
    // g, of the length that reaches g = target on the linearisation, then onto the box. A
    // coordinate at a face of the box that c points out of is held (its part of c dropped), so
    // the step's length is that of the coordinates that can move: on a condition affine in a,
    // each step then reaches g = target or a new face.
    const double g0 = Linearise(state, h_state);
    double norm2 = 0.0;
    for (int r = 0; r < n; ++r) {
      const float a = qp_actions_(r, 0);
      if (bounds_active() && ((a >= high_[r] && qp_normal_[r] > 0) ||
                              (a <= low_[r] && qp_normal_[r] < 0))) {
        qp_normal_[r] = 0.0;
      }
      norm2 += qp_normal_[r] * qp_normal_[r];
    }
    if (!(norm2 > 0) || !std::isfinite(norm2) || !std::isfinite(g0)) {
      return false;  // no direction to move in (a flat or non-finite linearisation)
    }
    const double length = std::max(0.0, target - g0) / norm2;
    for (int r = 0; r < n; ++r)
      qp_actions_(r, 0) = static_cast<float>(qp_actions_(r, 0) + length * qp_normal_[r]);
    ClipToBox(qp_actions_.leftCols(1));
  }
}

}  // namespace secure::shield
