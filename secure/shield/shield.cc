#include "secure/shield/shield.h"

#include <algorithm>
#include <boost/math/distributions/normal.hpp>
#include <boost/math/policies/policy.hpp>
#include <boost/random/sobol.hpp>
#include <cmath>
#include <limits>

#include "secure/common/error.h"
#include "secure/common/timer.h"

namespace secure::shield {
namespace {

constexpr double kNegInf = -std::numeric_limits<double>::infinity();

// The inverse normal CDF in double precision throughout (Boost.Math's default policy promotes
// double to long double internally, which costs x87 arithmetic for no gain at float output).
using NormalPolicy = boost::math::policies::policy<boost::math::policies::promote_double<false>>;
const boost::math::normal_distribution<double, NormalPolicy> kStandardNormal(0.0, 1.0);

// The Sobol generator: 64-bit integers, points left-aligned (the first coordinate of point 1 is
// 2^63, i.e. 0.5).
using SobolEngine = boost::random::sobol_engine<std::uint64_t, 64>;

}  // namespace

int MaxQmcDimension() {
  return static_cast<int>(boost::random::default_sobol_table::max_dimension);
}

namespace detail {

double QmcUniform(std::uint64_t word) {
  // The top 52 bits and half a step: in [2^-53, 1 - 2^-53], both exact in double, so the inverse
  // normal CDF never sees 0 or 1 (|z| <= 8.1).
  return (static_cast<double>(word >> 12) + 0.5) * 0x1.0p-52;
}

double QmcNormal(std::uint64_t word) {
  return boost::math::quantile(kStandardNormal, QmcUniform(word));
}

}  // namespace detail

Shield::Shield(const ShieldOptions& options, cbf::Barrier& barrier,
               const domains::DynamicsModel& dynamics)
    : options_(options),
      barrier_(barrier),
      dynamics_(dynamics),
      state_dim_(dynamics.state_dim()),
      action_dim_(dynamics.action_dim()),
      rng_(options.seed) {
  options_.Validate(action_dim_);
  SECURE_CHECK(barrier.state_dim() == state_dim_,
               "Shield: " << barrier.Describe() << " takes " << barrier.state_dim()
                          << "-dimensional states, " << dynamics.Describe() << " produces "
                          << state_dim_);
  const int m = options_.num_samples, batch = std::max(options_.num_samples, options_.num_probes);
  decision_.action = Eigen::VectorXf::Zero(action_dim_);
  backup_ = Eigen::VectorXf::Zero(action_dim_);
  mu_.resize(action_dim_);
  sigma_.resize(action_dim_);
  samples_.resize(action_dim_, m);
  probes_.resize(action_dim_, options_.num_probes);
  next_states_.resize(state_dim_, batch);
  h_next_.resize(batch);
  g_.resize(batch);
  one_action_.resize(action_dim_, 1);
  one_g_.resize(1);
  best_action_.resize(action_dim_);
  state_column_.resize(state_dim_, 1);
  h_one_.resize(1);
  d_sigma_.resize(action_dim_);
  q_.resize(m);
  step_scratch_.resize(state_dim_, 1);
  order_.resize(static_cast<std::size_t>(m));
  rejected_.assign(static_cast<std::size_t>(m), 0);
  applied_.resize(action_dim_, batch);
  if (options_.proposal != Proposal::kNone) {
    qp_actions_.resize(action_dim_, 2 * action_dim_ + 1);
    qp_next_.resize(state_dim_, 2 * action_dim_ + 1);
    qp_h_.resize(1);
    qp_gradient_.resize(state_dim_, 1);
    qp_jacobian_.resize(state_dim_, action_dim_);
    qp_g_.resize(2 * action_dim_);
    qp_normal_.resize(action_dim_);
    qp_mu_.resize(action_dim_);
    qp_low_.resize(action_dim_);
    qp_high_.resize(action_dim_);
    qp_solution_.resize(action_dim_);
    qp_point_.resize(action_dim_);
    qp_scratch_.reserve(static_cast<std::size_t>(2 * action_dim_));
    if (options_.qp_metric == QpMetric::kPolicy) {
      qp_sigma_.resize(action_dim_);
      qp_metric_scratch_.Resize(action_dim_);
    }
  }
  low_ = Eigen::VectorXf::Constant(action_dim_, -std::numeric_limits<float>::infinity());
  high_ = Eigen::VectorXf::Constant(action_dim_, std::numeric_limits<float>::infinity());
  if (options_.sampler == Sampler::kQmc) {
    // Point 0 is the origin (Boost's engine skips it), points 1 .. M - 1 follow: for M = 2^k the
    // columns are a (t, k, d)-net, and a digital shift keeps them one.
    sobol_.setZero(action_dim_, m);
    SobolEngine engine(static_cast<std::size_t>(action_dim_));
    for (int c = 1; c < m; ++c)
      for (int r = 0; r < action_dim_; ++r) sobol_(r, c) = engine();
  }
}

void Shield::SetBackupAction(const Eigen::Ref<const Eigen::VectorXf>& action) {
  SECURE_CHECK(action.size() == action_dim_, "Shield: backup action has " << action.size()
                                                                          << " values, expected "
                                                                          << action_dim_);
  SECURE_CHECK(action.allFinite(), "Shield: backup action has a non-finite value");
  for (int r = 0; r < action_dim_; ++r) {
    SECURE_CHECK(!has_bounds_ || (action[r] >= low_[r] && action[r] <= high_[r]),
                 "Shield: backup action[" << r << "] = " << action[r]
                                          << " lies outside the action bounds [" << low_[r]
                                          << ", " << high_[r] << "]");
  }
  backup_ = action;
  has_backup_ = true;
}

void Shield::SetActionBounds(const Eigen::Ref<const Eigen::VectorXf>& low,
                             const Eigen::Ref<const Eigen::VectorXf>& high) {
  SECURE_CHECK(low.size() == action_dim_ && high.size() == action_dim_,
               "Shield: action bounds have " << low.size() << " and " << high.size()
                                             << " values, expected " << action_dim_);
  for (int r = 0; r < action_dim_; ++r) {
    SECURE_CHECK(!std::isnan(low[r]) && !std::isnan(high[r]) && low[r] <= high[r],
                 "Shield: action bounds [" << low[r] << ", " << high[r] << "] of action " << r
                                           << ": need low <= high, no NaN");
    SECURE_CHECK(!has_backup_ || (backup_[r] >= low[r] && backup_[r] <= high[r]),
                 "Shield: the backup action[" << r << "] = " << backup_[r]
                                              << " lies outside the action bounds [" << low[r]
                                              << ", " << high[r] << "]");
  }
  low_ = low;
  high_ = high;
  has_bounds_ = true;
}

void Shield::SetActionBounds(const domains::Environment& env) {
  SECURE_CHECK(env.action_dim() == action_dim_, "Shield: " << env.Describe() << " has "
                                                           << env.action_dim()
                                                           << "-dimensional actions, expected "
                                                           << action_dim_);
  Eigen::VectorXf low(action_dim_), high(action_dim_);
  env.ActionBounds(low, high);
  SetActionBounds(low, high);
}

bool Shield::ClipToBox(Eigen::Ref<Eigen::MatrixXf> actions) const {
  if (!bounds_active()) return false;
  bool moved = false;
  for (Eigen::Index c = 0; c < actions.cols(); ++c) {
    for (int r = 0; r < action_dim_; ++r) {
      const float a = actions(r, c), clipped = std::clamp(a, low_[r], high_[r]);
      if (clipped != a) {
        actions(r, c) = clipped;
        moved = true;
      }
    }
  }
  return moved;
}

bool Shield::BoundRound() {
  if (!bounds_active()) return false;
  const int m = options_.num_samples;
  bool any = false;
  for (int c = 0; c < m; ++c) {
    const bool inside = ((samples_.col(c).array() >= low_.array()) &&
                         (samples_.col(c).array() <= high_.array()))
                            .all();
    rejected_[static_cast<std::size_t>(c)] = inside ? 0 : 1;
    any = any || !inside;
  }
  return any;
}

Eigen::Ref<const Eigen::MatrixXf> Shield::Applied(const Eigen::Ref<const Eigen::MatrixXf>& actions) {
  if (!bounds_active()) return actions;
  auto out = applied_.leftCols(actions.cols());
  out = actions;
  ClipToBox(out);
  return out;
}

double Shield::EvaluateH(const Eigen::Ref<const Eigen::VectorXf>& state) {
  state_column_.col(0) = state;
  barrier_.Evaluate(state_column_, h_one_);
  return h_one_[0];
}

void Shield::EvaluateG(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state,
                       const Eigen::Ref<const Eigen::MatrixXf>& actions,
                       Eigen::Ref<Eigen::VectorXd> g) {
  const Eigen::Index k = actions.cols();
  SECURE_CHECK(k <= next_states_.cols(), "Shield::EvaluateG: " << k << " actions exceed the "
                                                               << next_states_.cols()
                                                               << " the shield was sized for");
  SECURE_CHECK(g.size() == k,
               "Shield::EvaluateG: g has " << g.size() << " entries for " << k << " actions");
  auto next = next_states_.leftCols(k);
  dynamics_.Step(state, actions, next);
  // lookahead_steps > 1: the action held for H periods, T^H(s, a), one model step per sample
  // and period (each sample's state differs from the second step on).
  for (int step = 1; step < options_.lookahead_steps; ++step) {
    for (Eigen::Index i = 0; i < k; ++i) {
      dynamics_.Step(next.col(i), actions.col(i), step_scratch_);
      next.col(i) = step_scratch_.col(0);
    }
  }
  barrier_.Evaluate(next, h_next_.head(k));
  const double inv_dt = 1.0 / options_.dt;
  if (options_.lookahead_steps == 1) {
    // g(a) = (h(T(s, a)) - h(s)) / dt + alpha(h(s)); a NaN h(T(s, a)) gives a NaN g, never safe.
    const double alpha = ClassKValue(options_, h_state);
    for (Eigen::Index i = 0; i < k; ++i)
      g[i] = (static_cast<double>(h_next_[i]) - h_state) * inv_dt + alpha;
    return;
  }
  // g_H(a) = (h(T^H(s, a)) - b_H) / dt with b_{j+1} = b_j - dt alpha(b_j), b_0 = h(s).
  double bound = h_state;
  for (int step = 0; step < options_.lookahead_steps; ++step)
    bound -= options_.dt * ClassKValue(options_, bound);
  for (Eigen::Index i = 0; i < k; ++i) g[i] = (static_cast<double>(h_next_[i]) - bound) * inv_dt;
}

void Shield::DrawRound() {
  const int m = options_.num_samples;
  switch (options_.sampler) {
    case Sampler::kIid:
      for (int c = 0; c < m; ++c)
        for (int r = 0; r < action_dim_; ++r)
          samples_(r, c) = mu_[r] + sigma_[r] * static_cast<float>(rng_.Normal());
      break;
    case Sampler::kAntithetic:
      // Columns 2k and 2k + 1 are mu + sigma z and mu - sigma z (exact mirrors about mu); with
      // odd M the last column is mu + sigma z alone.
      for (int c = 0; c < m; c += 2) {
        for (int r = 0; r < action_dim_; ++r) {
          const float step = sigma_[r] * static_cast<float>(rng_.Normal());
          samples_(r, c) = mu_[r] + step;
          if (c + 1 < m) samples_(r, c + 1) = mu_[r] - step;
        }
      }
      break;
    case Sampler::kQmc:
      // A fresh digital shift per round and dimension, then z = Phi^-1(u).
      for (int r = 0; r < action_dim_; ++r) {
        const std::uint64_t shift = rng_.NextU64();
        for (int c = 0; c < m; ++c)
          samples_(r, c) =
              mu_[r] + sigma_[r] * static_cast<float>(detail::QmcNormal(sobol_(r, c) ^ shift));
      }
      break;
  }
}

int Shield::ScoreRound(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state) {
  const int m = options_.num_samples;
  // Each sample is checked as the actuator applies it (clipped onto the box, when one is set).
  EvaluateG(state, h_state, Applied(samples_), g_.head(m));
  if (bounds_active() && options_.action_bounds == ActionBounds::kReject) {
    // A sample the actuator cannot apply is never safe, never aggregated, never the fallback.
    for (int i = 0; i < m; ++i)
      if (rejected_[static_cast<std::size_t>(i)]) g_[i] = kNegInf;
  }
  int num_safe = 0;
  for (int i = 0; i < m; ++i) {
    if (g_[i] >= 0.0) ++num_safe;
    if (g_[i] > best_g_) {  // false for NaN
      best_g_ = g_[i];
      best_action_ = samples_.col(i);
      ClipToBox(best_action_);  // the action its g belongs to
    }
  }
  return num_safe;
}

void Shield::AdaptSigma(const Eigen::Ref<const Eigen::VectorXf>& state,
                        const Eigen::Ref<const Eigen::VectorXf>& mu) {
  const int n = options_.num_probes;
  const double extent = options_.probe_extent;
  for (int c = 0; c < n; ++c)
    for (int r = 0; r < action_dim_; ++r)
      probes_(r, c) = mu[r] + static_cast<float>(rng_.Uniform(-extent, extent));
  // h(T(s, a_j)) for the probes as the actuator applies them (clipped onto the box, when one is
  // set); their g also competes for the fallback (they are evaluated).
  EvaluateG(state, decision_.h, Applied(probes_), g_.head(n));
  d_sigma_.setZero();
  for (int j = 0; j < n; ++j) {
    const double weight = std::max(0.0, -static_cast<double>(h_next_[j]));  // NaN -> 0
    if (weight > 0) d_sigma_ += static_cast<float>(weight) * (probes_.col(j) - mu);
    if (g_[j] > best_g_) {
      best_g_ = g_[j];
      best_action_ = probes_.col(j);
      ClipToBox(best_action_);
    }
  }
  // d_sigma = |a_unsafe| / ||a_unsafe||_2; isotropic when no probe is unsafe.
  const float norm = d_sigma_.norm();
  if (norm > 0 && std::isfinite(norm)) {
    d_sigma_ = d_sigma_.cwiseAbs() / norm;
  } else {
    d_sigma_.setConstant(1.0f / std::sqrt(static_cast<float>(action_dim_)));
  }
  sigma_ += static_cast<float>(options_.sigma_step) * d_sigma_;
}

void Shield::Aggregate(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state,
                       int num_safe) {
  const int m = options_.num_samples;
  if (options_.aggregation == Aggregation::kRandomSafe ||
      options_.aggregation == Aggregation::kFirstSafe) {
    // Ablation 1: one safe sample, uniformly at random; the first-safe sampler: the first one.
    long pick = options_.aggregation == Aggregation::kFirstSafe
                    ? 0
                    : static_cast<long>(rng_.UniformIndex(static_cast<std::uint64_t>(num_safe)));
    for (int i = 0; i < m; ++i) {
      if (g_[i] >= 0.0 && pick-- == 0) {
        decision_.action = samples_.col(i);
        ClipToBox(decision_.action);  // its g is that of the clipped action
        decision_.g = g_[i];
        return;
      }
    }
    SECURE_INTERNAL_CHECK(false, "safe sample count does not match");
  }
  int count = 0;
  for (int i = 0; i < m; ++i)
    if (g_[i] >= 0.0) order_[static_cast<std::size_t>(count++)] = i;
  SECURE_INTERNAL_CHECK(count == num_safe, "safe sample count does not match");
  if (options_.aggregation == Aggregation::kTopQ) {
    // ScoreRound was the round's last EvaluateG: next_states_ holds T(s, a_i) of its samples.
    action_value_->Evaluate(state, next_states_.leftCols(m), q_);
    const int keep =
        std::clamp(static_cast<int>(std::ceil(options_.top_q_fraction * count)), 1, count);
    // Descending Q, NaN last, ties by index: a strict weak order, so the selection is
    // deterministic; then the kept indices ascending, so that the mean sums in a fixed order.
    auto key = [&](int i) { return std::isnan(q_[i]) ? kNegInf : q_[i]; };
    const auto first = order_.begin();
    std::nth_element(first, first + (keep - 1), first + count, [&](int a, int b) {
      const double qa = key(a), qb = key(b);
      return qa != qb ? qa > qb : a < b;
    });
    std::sort(first, first + keep);
    count = keep;
  }
  AggregateMean(state, h_state, count);
}

void Shield::AggregateMean(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state,
                           int count) {
  // Algorithm 1, lines 6-9: the mean of the samples, if it is safe itself ...
  one_action_.setZero();
  for (int k = 0; k < count; ++k) one_action_.col(0) += samples_.col(order_[k]);
  one_action_ /= static_cast<float>(count);
  // g_ holds the round's values; evaluating the mean reuses the shared buffers, so keep the
  // nearest-sample search ahead of it. With a box, the mean of the drawn samples is clipped
  // after the search and checked as applied, and the nearest sample is returned clipped (its g
  // was evaluated so): where the shield model clips as the actuator does, every decision is
  // then the one without a box, clipped.
  int nearest = -1;
  float nearest_distance = std::numeric_limits<float>::infinity();
  for (int k = 0; k < count; ++k) {
    const int i = order_[k];
    const float d = (samples_.col(i) - one_action_.col(0)).squaredNorm();
    if (d < nearest_distance) {
      nearest_distance = d;
      nearest = i;
    }
  }
  const double nearest_g = g_[nearest];
  ClipToBox(one_action_);
  EvaluateG(state, h_state, one_action_, one_g_);
  if (one_g_[0] >= 0.0) {
    decision_.action = one_action_.col(0);
    decision_.g = one_g_[0];
  } else {
    // ... else the sample nearest to the mean.
    decision_.action = samples_.col(nearest);
    ClipToBox(decision_.action);
    decision_.g = nearest_g;
  }
}

Status Shield::SafeStatus() const {
  return decision_.iterations == 1 ? Status::kSafe : Status::kSafeAfterResampling;
}

void Shield::FinishInvalid() {
  decision_.status = Status::kInvalidInput;
  if (has_backup_) {
    decision_.action = backup_;
  } else {
    decision_.action.setZero();
  }
  decision_.g = std::numeric_limits<double>::quiet_NaN();
}

// Decide: one function of about 165 lines, on purpose: it is the shield's hot path (Algorithms 1
// and 2 per control step), and its early returns and the order of its random draws (the policy's
// draw or mean first, the rounds, the fallbacks) are the behaviour the tests pin bit for bit;
// read in one place they can be checked against the paper's algorithms line by line.
const Decision& Shield::Decide(const Eigen::Ref<const Eigen::VectorXf>& state,
                               const Eigen::Ref<const Eigen::VectorXf>& mu,
                               const Eigen::Ref<const Eigen::VectorXf>& sigma) {
  const Stopwatch clock;
  SECURE_CHECK(state.size() == state_dim_,
               "Shield::Decide: state has " << state.size() << " values, expected " << state_dim_);
  SECURE_CHECK(mu.size() == action_dim_,
               "Shield::Decide: mu has " << mu.size() << " values, expected " << action_dim_);
  SECURE_CHECK(sigma.size() == action_dim_,
               "Shield::Decide: sigma has " << sigma.size() << " values, expected " << action_dim_);
  SECURE_CHECK(options_.aggregation != Aggregation::kTopQ || action_value_ != nullptr,
               "Shield::Decide: aggregation = top-q needs a task value (Shield::SetActionValue)");
  decision_.status = Status::kInvalidInput;
  decision_.g = 0.0;
  decision_.h = std::numeric_limits<double>::quiet_NaN();
  decision_.iterations = 0;
  decision_.safe_ratio = 0.0;
  decision_.intervened = false;
  decision_.distance_to_mean = 0.0;
  decision_.bounded = false;
  decision_.fallback = Fallback::kNone;
  decision_.qp = QpOutcome::kNotTried;

  // NaN/Inf anywhere: report it, return a finite action, check nothing.
  if (!state.allFinite() || !mu.allFinite() || !sigma.allFinite() || (sigma.array() < 0).any()) {
    FinishInvalid();
    decision_.seconds = clock.Seconds();
    return decision_;
  }
  const double h_state = EvaluateH(state);
  decision_.h = h_state;
  if (!std::isfinite(h_state)) {
    FinishInvalid();
    decision_.seconds = clock.Seconds();
    return decision_;
  }

  if (options_.proposal != Proposal::kNone) {
    // The CBF-QP projection of mu (or its gradient refinement) first: the decision if its exact
    // g >= 0.
    const bool refine = options_.proposal == Proposal::kRefine;
    if (refine ? RefineMean(state, mu, h_state) : ProposeQp(state, mu, sigma, h_state)) {
      decision_.status = Status::kSafe;
      decision_.safe_ratio = 1.0;
      decision_.distance_to_mean = (decision_.action - mu).norm();
      decision_.seconds = clock.Seconds();
      return decision_;
    }
    if (options_.proposal == Proposal::kQpOnly || refine) {
      // The CBF-QP filter (or the refinement) alone: its projection (last iterate), unsafe.
      decision_.status = Status::kNoSafeAction;
      decision_.fallback = refine ? Fallback::kRefinedMean : Fallback::kQpProjection;
      decision_.distance_to_mean = (decision_.action - mu).norm();
      decision_.seconds = clock.Seconds();
      return decision_;
    }
    // Algorithms 1-2, unchanged (the projection drew no random numbers).
    decision_.intervened = false;
    decision_.bounded = false;
  }

  mu_ = mu;
  sigma_ = sigma;
  best_g_ = kNegInf;
  best_action_ = mu;  // the fallback when nothing evaluated is finite: in the box, too
  ClipToBox(best_action_);
  const int m = options_.num_samples;
  const bool first_safe = options_.aggregation == Aggregation::kFirstSafe;
  int num_safe = 0;
  bool enough = false;
  for (int iteration = 1; iteration <= options_.max_iterations; ++iteration) {
    if (iteration > 1 && options_.resampling == Resampling::kAdaptive) AdaptSigma(state, mu);
    DrawRound();
    const bool round_bounded = BoundRound();
    decision_.iterations = iteration;
    if (iteration == 1 && (options_.aggregation == Aggregation::kPolicyDraw || first_safe) &&
        !(bounds_active() && options_.action_bounds == ActionBounds::kReject && rejected_[0])) {
      // The policy's own draw alone first: if it is safe it is the decision, and the other
      // samples need no evaluation. Otherwise the round is scored as a whole, as for kMean.
      EvaluateG(state, h_state, Applied(samples_.leftCols(1)), one_g_);
      if (one_g_[0] >= 0.0) {
        decision_.safe_ratio = 1.0;
        decision_.action = samples_.col(0);
        decision_.bounded = ClipToBox(decision_.action);  // as applied, and so checked
        decision_.g = one_g_[0];
        decision_.status = Status::kSafe;
        decision_.distance_to_mean = (decision_.action - mu).norm();
        decision_.seconds = clock.Seconds();
        return decision_;
      }
    }
    if (iteration == 1 && options_.aggregation == Aggregation::kPolicyMean) {
      // The policy's mean alone first (after the round's draws, so that the random stream is
      // the same as kMean's): if it is safe it is the decision. Otherwise the round is scored as
      // for kMean, and the decision counts as an intervention (the policy's action was unsafe).
      one_action_.col(0) = mu;
      if (ClipToBox(one_action_)) decision_.bounded = true;  // what the actuator would apply
      EvaluateG(state, h_state, one_action_, one_g_);
      if (one_g_[0] >= 0.0) {
        decision_.safe_ratio = 1.0;
        decision_.action = one_action_.col(0);
        decision_.g = one_g_[0];
        decision_.status = Status::kSafe;
        decision_.distance_to_mean = (decision_.action - mu).norm();
        decision_.seconds = clock.Seconds();
        return decision_;
      }
    }
    num_safe = ScoreRound(state, h_state);
    if (round_bounded) decision_.bounded = true;  // the box cut into a round that was scored
    if (iteration == 1) {
      // The policy's own action: its draw (round 1's first sample), or its mean for kPolicyMean.
      decision_.intervened =
          options_.aggregation == Aggregation::kPolicyMean || !(g_[0] >= 0.0);
    }
    decision_.safe_ratio = static_cast<double>(num_safe) / m;
    if (decision_.safe_ratio > options_.safe_ratio || (first_safe && num_safe > 0)) {
      enough = true;
      break;
    }
    if (options_.time_budget_us > 0 && clock.Microseconds() >= options_.time_budget_us) break;
  }

  if (!enough && options_.resampling == Resampling::kNone && !first_safe) {
    // Ablation 2 at its limit: a random sample of the last round, unchecked. Its status follows
    // its g, so an unsafe one is never reported as safe.
    const int i = static_cast<int>(rng_.UniformIndex(static_cast<std::uint64_t>(m)));
    decision_.action = samples_.col(i);
    ClipToBox(decision_.action);  // clip: its g is that of the clipped action
    decision_.g = g_[i];
    if (bounds_active() && options_.action_bounds == ActionBounds::kReject &&
        rejected_[static_cast<std::size_t>(i)]) {
      // Rejected (outside the box): return it clipped, with the g of what is returned.
      one_action_.col(0) = samples_.col(i);
      ClipToBox(one_action_);
      EvaluateG(state, h_state, one_action_, one_g_);
      decision_.action = one_action_.col(0);
      decision_.g = one_g_[0];
    }
    decision_.fallback = Fallback::kRandomSample;
    decision_.status = decision_.g >= 0.0 ? SafeStatus() : Status::kNoSafeAction;
  } else if (num_safe > 0) {
    // Enough safe samples, or the budget ran out with some: aggregate the last round's.
    Aggregate(state, h_state, num_safe);
    decision_.status = SafeStatus();
  } else {
    // No safe sample in the last round: the best evaluated action (a sample or probe of any
    // round), or the backup action if its g is larger.
    decision_.action = best_action_;
    decision_.g = best_g_;
    decision_.fallback = Fallback::kBestSample;
    if (has_backup_) {
      one_action_.col(0) = backup_;
      EvaluateG(state, h_state, one_action_, one_g_);
      if (one_g_[0] > best_g_) {  // a NaN g never wins; best_g_ is -inf if nothing was finite
        decision_.action = backup_;
        decision_.g = one_g_[0];
        decision_.fallback = Fallback::kBackupAction;
      }
    }
    decision_.status = decision_.g >= 0.0 ? SafeStatus() : Status::kNoSafeAction;
  }
  decision_.distance_to_mean = (decision_.action - mu).norm();
  decision_.seconds = clock.Seconds();
  return decision_;
}

}  // namespace secure::shield
