#pragma once
// The CBF shield of SECURE (paper Section 4.2, Algorithm 1) with adaptive resampling (Section 4.3,
// Algorithm 2). Given a state s, the policy's Gaussian N(mu, diag(sigma^2)), a barrier h and a
// dynamics model T, it returns an action a whose discrete-time CBF condition
//
//   g(a) = (h(T(s, a)) - h(s)) / dt + alpha(h(s)) >= 0          (paper Eq. 5, requirement R3)
//
// holds, where alpha is a class-K function (strictly increasing, alpha(0) = 0). Algorithm 1:
//   1. draw M actions from N(mu, sigma) (i.i.d. by default; ShieldOptions::sampler also offers
//      antithetic pairs and randomised quasi-Monte Carlo);
//   2. while the safe ratio rho = #{g >= 0} / M is <= rho0: widen sigma along unsafe directions
//      (Algorithm 2, below) and draw M new actions;
//   3. a_bar = mean of the safe actions; return a_bar if g(a_bar) >= 0, else the safe action
//      nearest to a_bar.
// Algorithm 2: draw N probe actions uniformly in the box [-R, R]^n around mu, weight each by
// max(0, -h(T(s, a_j))), a_unsafe = sum_j w_j (a_j - mu), d_sigma = |a_unsafe| / ||a_unsafe||_2
// (element-wise absolute value), sigma <- sigma + alpha_sigma * d_sigma; mu stays unchanged.
//
// Deviations from the paper, each deliberate (docs/SHIELD.md has the full list):
//  - a_bar averages over the safe actions (the paper's formula divides by M, which shrinks a_bar
//    toward 0; its text and the authors' code average the safe ones);
//  - a budget (iterations and/or wall time). When it runs out without a safe action the decision
//    says kNoSafeAction and returns the fallback with the largest g (the best evaluated action,
//    or the caller's backup action): an unchecked action is never reported as safe;
//  - probes are centred on mu (so they explore the actions the policy is about to take; with a
//    symmetric action box and mu = 0 this is the paper's origin-centred probe), and an isotropic
//    step is taken when no probe is unsafe.
//
// Usage (one Shield per control loop; construct once, then Decide() allocates nothing):
//   shield::ShieldOptions options;            // M = 64, rho0 = 0.1, alpha(h) = 1.0 h, dt = 0.1
//   shield::Shield shield(options, barrier, dynamics);
//   const shield::Decision& d = shield.Decide(state, mu, sigma);
//   if (d.status == shield::Status::kInvalidInput) { ... }  else apply(d.action);

#include <Eigen/Core>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"
#include "secure/common/enum_strings.h"
#include "secure/common/rng.h"
#include "secure/domains/dynamics.h"
#include "secure/domains/environment.h"
#include "secure/shield/qp.h"

namespace YAML {
class Node;
}  // namespace YAML

namespace secure::shield {

/// The class-K function alpha(h).
enum class ClassK {
  kLinear,  // alpha(h) = k h
  kCubic,   // alpha(h) = k h^3
};
inline constexpr EnumTable<ClassK, 2> kClassKNames{{
    {ClassK::kLinear, "linear"},
    {ClassK::kCubic, "cubic"},
}};

/// How the returned action is formed from the safe samples.
enum class Aggregation {
  kMean,        // Algorithm 1: mean of the safe samples, re-checked, else the nearest safe sample
  kRandomSafe,  // ablation 1 (paper Section 6.2): one safe sample chosen at random
  // Not in the paper: the policy's own draw (round 1's first sample, mu + sigma z) when its g >= 0,
  // else as kMean. The shield then changes the policy's behaviour only where its draw is unsafe,
  // instead of executing about the policy's mean at every step (docs/SHIELD.md). A safe draw is
  // the only sample evaluated: such a decision costs two barrier evaluations, h(s) and h(T(s, a)).
  kPolicyDraw,
  // Task-aware (the authors' code, official-code-facts.md §4.5, methods 2 and 5; not in the
  // paper): rank the safe samples by a task value Q(s, a) of their predicted next state
  // (Shield::SetActionValue; e.g. AIRL's g(s) + gamma V(T(s, a))), take the mean of the best
  // ceil(top_q_fraction x #safe) of them, re-checked as in Algorithm 1, else the one of them
  // nearest that mean. The mean of all safe samples follows the safe set's centre; this one
  // follows the side of it that makes progress on the task.
  kTopQ,
  // Not in the paper: the policy's mean mu itself when g(mu) >= 0, else as kMean (same draws,
  // same resampling). The minimally invasive filter (a CBF-QP also returns mu when mu satisfies
  // the condition): the shield changes the policy's action only where it is unsafe, and never
  // moves a safe mean toward the centre of the safe samples. Such a decision costs two barrier
  // evaluations, h(s) and h(T(s, mu)) (docs/SHIELD.md).
  kPolicyMean,
  // Not in the paper: the first-safe sampler (CRABS-style; method first-safe). The policy's own
  // draw (round 1's first sample) when its g >= 0, else the first sample of the round, in draw
  // order, whose g >= 0: no mean, no re-check. A round with one safe sample is enough (safe_ratio
  // is not used); with no safe sample the next round is drawn (resampling as set; the method uses
  // none, i.e. the policy's own Gaussian), up to the budget, and then the fallback as for kMean
  // (status kNoSafeAction, Fallback::kBestSample or kBackupAction; never a random sample).
  kFirstSafe,
};
inline constexpr EnumTable<Aggregation, 6> kAggregationNames{{
    {Aggregation::kMean, "mean"},
    {Aggregation::kRandomSafe, "random-safe"},
    {Aggregation::kPolicyDraw, "policy-draw"},
    {Aggregation::kTopQ, "top-q"},
    {Aggregation::kPolicyMean, "policy-mean"},
    {Aggregation::kFirstSafe, "first-safe"},
}};

/// What happens while too few samples are safe.
enum class Resampling {
  kAdaptive,  // Algorithm 2: widen sigma along unsafe directions, then resample
  kNone,      // ablation 2: resample with the policy's own sigma; at the iteration limit return a
              // random sample of the last batch (its status follows its g: kNoSafeAction if g < 0)
};
inline constexpr EnumTable<Resampling, 2> kResamplingNames{{
    {Resampling::kAdaptive, "adaptive"},
    {Resampling::kNone, "none"},
}};

/// How a round's M standard-normal vectors z (the samples are mu + sigma * z) are drawn. Every
/// round draws afresh (resampling rounds use the widened sigma); the adaptive step's probes are
/// uniform whatever the sampler. docs/SHIELD.md compares them.
enum class Sampler {
  kIid,         // M independent normal vectors (Box–Muller), column by column
  kAntithetic,  // ceil(M/2) normal vectors z, each used as the adjacent pair mu + sigma z,
                // mu - sigma z (columns 2k, 2k + 1); with odd M the last column is unpaired
  kQmc,         // randomised quasi-Monte Carlo: the first M points of the Sobol sequence in
                // action_dim dimensions (Boost.Random, Joe–Kuo directions, the origin included),
                // a fresh random digital shift per round (XOR with a random 64-bit word per
                // dimension), then the inverse normal CDF
};
inline constexpr EnumTable<Sampler, 3> kSamplerNames{{
    {Sampler::kIid, "iid"},
    {Sampler::kAntithetic, "antithetic"},
    {Sampler::kQmc, "qmc"},
}};

/// What the shield does with the actuator box [low, high] (Shield::SetActionBounds; the experiment
/// driver, `secure eval` and Python's run_episodes give it the environment's box). With a box,
/// every action the shield evaluates as a candidate, and so every action it returns (aggregate,
/// nearest sample, fallback), lies in the box: g is checked on the action the actuator will apply.
/// Without a box (none set) the option has no effect.
enum class ActionBounds {
  kClip,    // each action is checked as the actuator applies it, clipped onto the box (samples,
            // probes, the policy's mean); the aggregate (the mean of the safe draws) is clipped
            // and checked, and a returned sample is returned clipped. Where the shield model
            // clips as the actuator does, a decision is then the unbounded one, clipped
  kReject,  // a drawn sample outside the box counts as unsafe (g = -inf; a truncated Gaussian);
            // the policy's mean outside the box is clipped before policy-mean checks it
  kIgnore,  // the box is not used (earlier releases): the returned action may leave it, and the
            // actuator then clips an action whose g was checked unclipped
};
inline constexpr EnumTable<ActionBounds, 3> kActionBoundsNames{{
    {ActionBounds::kClip, "clip"},
    {ActionBounds::kReject, "reject"},
    {ActionBounds::kIgnore, "ignore"},
}};

/// Whether a decision first tries the CBF-QP's projection of the policy's mean (docs/SHIELD.md,
/// "CBF-QP and the gradient-first shield"). mu itself is checked first with the exact g: if g(mu)
/// >= qp_margin it is the QP's answer, with one model step and one barrier evaluation. Otherwise
/// the projection linearises g at mu, with the barrier's
/// gradient at the predicted state s+ = T(s, mu) and the model's action Jacobian J at mu (central
/// differences of T, exact up to rounding for a model affine in the action):
///   g(a) ~ g(mu) + (grad h(s+) . J (a - mu)) / dt >= 0,
/// solves min ||a - mu||^2 (or, qp_metric = policy, min (a - mu)^T diag(sigma)^-2 (a - mu)) over
/// that half-space and the actuator box (qp.h), and checks the
/// result with the exact g (the shield model and the barrier, as every sample is checked).
enum class Proposal {
  kNone,    // Algorithms 1-2 only (the paper)
  kQp,      // gradient-first: the projection is the decision when its exact g >= 0, otherwise
            // Algorithms 1-2 run unchanged (Decision::qp says which path decided)
  kQpOnly,  // the CBF-QP filter alone (method cbf-qp): the projection is the decision; when its
            // exact g < 0 (the linearisation misled it, or the half-space misses the box) the
            // status is kNoSafeAction with Fallback::kQpProjection. No sampling
  // Gradient refinement of the mean alone (MACBF-style; method cbf-grad): from mu (clipped onto
  // the box), up to refine_steps projected gradient steps on the hinge max(0, m - g(a)), with m
  // = qp_margin plus the rounding allowance: a <- clip(a + (m - g(a)) / |c|^2 c), c = grad_a g
  // = J^T grad h(T(s, a)) / dt linearised at a as above, without the coordinates held at a face
  // of the box that c points out of (a Polyak step: on a condition affine in a it lands on g = m
  // or on a new face). Every iterate is checked with the exact g; the first with
  // g >= 0 is the decision. When none is, the status is kNoSafeAction with
  // Fallback::kRefinedMean (the last iterate). No sampling
  kRefine,
};
inline constexpr EnumTable<Proposal, 4> kProposalNames{{
    {Proposal::kNone, "none"},
    {Proposal::kQp, "qp"},
    {Proposal::kQpOnly, "qp-only"},
    {Proposal::kRefine, "refine"},
}};

/// What the CBF-QP projection (or, proposal = refine, the gradient refinement) of a decision did
/// (Decision::qp).
enum class QpOutcome {
  kNotTried,    // proposal = none, or the input was invalid
  kAccepted,    // its exact g >= 0: it is the decision
  kRejected,    // its exact g < 0: the linearisation misled it (refine: no iterate had g >= 0)
  kInfeasible,  // the linearised half-space misses the box (the QP returned the box point of
                // largest linearised g); its exact g < 0
};
inline constexpr EnumTable<QpOutcome, 4> kQpOutcomeNames{{
    {QpOutcome::kNotTried, "not_tried"},
    {QpOutcome::kAccepted, "accepted"},
    {QpOutcome::kRejected, "rejected"},
    {QpOutcome::kInfeasible, "infeasible"},
}};

/// The largest action dimension Sampler::kQmc supports (Boost.Random's Sobol tables).
int MaxQmcDimension();

namespace detail {
/// Sampler::kQmc's map from a (shifted) 64-bit Sobol coordinate to (0, 1): never 0 or 1.
double QmcUniform(std::uint64_t word);
/// The standard normal quantile of QmcUniform(word) (Boost.Math), always finite.
double QmcNormal(std::uint64_t word);
}  // namespace detail

/// The metric in which the CBF-QP projects the policy's mean (proposal qp and qp-only; qp.h).
enum class QpMetric {
  kEuclidean,  // min ||a - mu||^2: every action axis alike (the textbook CBF-QP)
  // min (a - mu)^T diag(sigma)^-2 (a - mu), sigma the policy's (Decide's sigma): the change of
  // the action least unlikely under the policy's Gaussian; it moves along the policy's sure axes
  // (small sigma) least, as SECURE's draws from N(mu, sigma) do. Needs every sigma_i > 0: a zero
  // entry makes Decide throw (a deterministic policy has no such metric; use euclidean).
  kPolicy,
};
inline constexpr EnumTable<QpMetric, 2> kQpMetricNames{{
    {QpMetric::kEuclidean, "euclidean"},
    {QpMetric::kPolicy, "policy"},
}};

/// Where the CBF-QP's projection lands (proposal qp and qp-only; qp.h).
enum class QpTarget {
  kBoundary,  // on the linearised boundary g = qp_margin: the least change (the textbook CBF-QP)
  // The mean of the policy's Gaussian N(mu, diag(sigma^2)) over the linearised safe half-space,
  // in closed form (qp.h, GaussianHalfSpaceMeanOffset): what Algorithm 1's average of the safe
  // draws estimates on the first round, without drawing. It lies inside the half-space by
  // |sigma o c| (lambda(beta) - beta) in g's units, more the nearer mu is to the boundary, and
  // moves along sigma^2 o c. Needs qp_metric = policy (the projection onto the tightened half-space
  // is in that metric) and every sigma_i > 0.
  kSafeMean,
};
inline constexpr EnumTable<QpTarget, 2> kQpTargetNames{{
    {QpTarget::kBoundary, "boundary"},
    {QpTarget::kSafeMean, "safe-mean"},
}};

/// The largest ShieldOptions::lookahead_steps.
inline constexpr int kMaxLookaheadSteps = 100;
/// The largest ShieldOptions::qp_iterations.
inline constexpr int kMaxQpIterations = 10;
/// The largest ShieldOptions::qp_line_search.
inline constexpr int kMaxQpLineSearch = 10;
/// The largest ShieldOptions::qp_bisection.
inline constexpr int kMaxQpBisection = 30;
/// The largest ShieldOptions::refine_steps.
inline constexpr int kMaxRefineSteps = 50;

struct ShieldOptions {
  int num_samples = 64;     // M: actions drawn per iteration
  double safe_ratio = 0.1;  // rho0: resample while #safe / M <= rho0
  double dt = 0.1;          // dt in g(a)
  ClassK class_k = ClassK::kLinear;
  double class_k_gain = 1.0;  // k in alpha(h); keep alpha'(0) * dt < 1, else g >= 0 reduces
                              // to the myopic h(T(s, a)) >= 0 (linear: k dt = 1 exactly)
  Aggregation aggregation = Aggregation::kMean;
  Resampling resampling = Resampling::kAdaptive;
  int num_probes = 64;              // N: probe actions per adaptive step
  double probe_extent = 1.0;        // R: probes are uniform in mu + [-R, R]^n
  double sigma_step = 0.5;          // alpha_sigma: sigma <- sigma + alpha_sigma * d_sigma
  int max_iterations = 20;          // K: sampling rounds per decision (the first one included)
  double time_budget_us = 0.0;      // wall-time budget per decision; 0: none (iterations only)
  std::uint64_t seed = 0;           // the shield's random stream (deterministic per seed)
  Sampler sampler = Sampler::kIid;  // how each round's M actions are drawn
  double top_q_fraction = 0.3;      // aggregation = top-q: the fraction of the safe samples
                                    // averaged, those of highest Q (the authors' code: 30 %)
  // H: the CBF condition looks H control periods ahead with the action held,
  //   g_H(a) = (h(T^H(s, a)) - b_H) / dt,   b_0 = h(s), b_{j+1} = b_j - dt alpha(b_j),
  // the discrete condition h(s_{t+1}) >= h(s_t) - dt alpha(h(s_t)) iterated H times (H = 1 is
  // g(a) exactly). A danger that approaches fast (a moving person) is then seen H - 1 periods
  // earlier, at the price of H model steps per sample (docs/SHIELD.md).
  int lookahead_steps = 1;
  // What the actuator box does to the samples (ActionBounds; used only when a box is set).
  ActionBounds action_bounds = ActionBounds::kClip;
  // Whether the CBF-QP's projection of mu is tried first (Proposal; needs lookahead_steps = 1).
  Proposal proposal = Proposal::kNone;
  // Linearisations per decision: when the projection's exact g < 0, re-linearise at it and
  // project mu again, up to this many times in all (1: the textbook CBF-QP).
  int qp_iterations = 1;
  // Exact checks along a rejected projection's line (proposal qp and qp-only; 0: none). The
  // projection lands on the linearised boundary, and where g curves away from its tangent the
  // exact g there is a little below 0. Each step is a secant step on the exact g along the line
  // from the linearisation point a0 through the projection a*, a(t) = a0 + t (a* - a0), clipped
  // to the box: from the last two points it aims past the boundary by the deficit it just saw
  // (g = target + (target - g_last)), and the first a(t) with g >= 0 is the decision; a secant
  // that does not rise, or a point beyond qp_max_step (proposal qp), ends it. One model step and
  // one barrier evaluation per step (docs/SHIELD.md).
  int qp_line_search = 0;
  // Bisection steps on the exact g along the same line after an accepted point that overshot
  // (proposal qp and qp-only; 0: none). Where g is far from linear in the action (a contact that
  // the shield model switches on within a small move), the linearised boundary can lie far beyond
  // the exact one, and the projection lands deep in the safe set, at the box's corner even, where
  // the nearest safe action was close to mu. When the accepted point's exact g exceeds the target
  // (qp_margin plus the rounding allowance) by more than a tenth of the gap between the target and
  // the g of the line's last rejected point (a0, or the line search's), each step checks the
  // midpoint of the two and keeps it as the decision when its g >= the target: the least change
  // along the line to within its length / 2^K. One model step and one barrier evaluation per
  // step, only on such decisions (docs/SHIELD.md).
  int qp_bisection = 0;
  // The linearised condition the projection asks for is g >= qp_margin (>= 0, in g's units): a
  // buffer against the linearisation's error on a curved barrier or model. (A fixed 1e-4 (1 +
  // |h(s)|) / dt is always added, against float rounding.) The exact check is g >= 0 whatever
  // the margin.
  double qp_margin = 0.0;
  // proposal = qp: the trust region of the projection. A projection farther than this from mu
  // (Euclidean, in action units) is not taken: the QP with the constraint |a - mu| <= qp_max_step
  // is infeasible, and Algorithms 1-2 decide. With qp_bisection > 0 the region bounds the
  // decision instead: a projection beyond it is checked and bisected back first, and the result
  // must lie within it. 0: no limit. Ignored by the other proposals
  // (qp-only and refine have no sampling to fall back to). On Panda the projection's step was
  // 2.6-3.3x the sampling shield's correction; capping it removed at most 1.4 points of the
  // extra danger there (docs/RESULTS.md, issue 37), so it is off by default.
  double qp_max_step = 0.0;
  // proposal = qp: when every projection above failed its exact check (or left the trust
  // region), one more round from mu on the slope of g over the policy's own scale before
  // Algorithms 1-2: the normal is the central difference of the exact g at mu +- qp_smoothing
  // sigma_r along each action (inside the box), then the same projection, check, bisection and
  // line search. The barrier's gradient at T(s, mu) sees only how h bends right there; a barrier
  // that curves on the scale of the policy's spread can point it away from the safe actions
  // within sigma (on Panda 25 % of the sampling shield's draws were safe where the projection
  // failed). 2n model steps and barrier evaluations in one batch, only on such decisions; along
  // an action with sigma = 0 the slope is 0. 0: off. Ignored by qp-only (the filter alone: on
  // Panda it stalled the arm where the failed projection had let it through) and the other
  // proposals (docs/SHIELD.md).
  double qp_smoothing = 0.0;
  // proposal = qp or qp-only: the metric of the projection (QpMetric). Accepted with any
  // proposal, as qp_max_step is (a config sets it for every method); refine and none ignore it.
  // ToJson writes it only when it is policy.
  QpMetric qp_metric = QpMetric::kEuclidean;
  // proposal = qp or qp-only: where the projection lands (QpTarget). ToJson writes it only when
  // it is safe-mean.
  QpTarget qp_target = QpTarget::kBoundary;
  // proposal = refine: gradient steps per decision at most (each a linearisation, a step and an
  // exact check).
  int refine_steps = 5;

  /// Throws secure::Error naming the field ("ShieldOptions::num_samples = 0, must be > 0").
  void Validate() const;
  /// Validate(), and the checks that depend on the action dimension (sampler = qmc supports at
  /// most MaxQmcDimension() dimensions). The Shield's constructor calls this one.
  void Validate(int action_dim) const;
  nlohmann::json ToJson() const;
  /// Sets the fields named in the mapping `node` (the keys of ToJson(); enums by name, as
  /// "class_k: cubic"). @throws secure::Error naming `source`, the key and the value on an
  /// unknown key or a value of the wrong type; Validate() checks the ranges.
  void ApplyYaml(const YAML::Node& node, const std::string& source);
};

enum class Status {
  kSafe,                 // g(action) >= 0, found without resampling
  kSafeAfterResampling,  // g(action) >= 0, found after one or more resampling rounds
  kNoSafeAction,         // budget spent with no safe sample: `action` is the fallback
  kInvalidInput,         // NaN/Inf in state, mu, sigma or h(s), or sigma < 0: `action` is the
                         // backup action if one was given, else zeros; nothing was checked
};
inline constexpr EnumTable<Status, 4> kStatusNames{{
    {Status::kSafe, "safe"},
    {Status::kSafeAfterResampling, "safe_after_resampling"},
    {Status::kNoSafeAction, "no_safe_action"},
    {Status::kInvalidInput, "invalid_input"},
}};

/// Which action a kNoSafeAction decision returned.
enum class Fallback {
  kNone,          // not a fallback decision
  kBestSample,    // the evaluated sample with the largest g
  kBackupAction,  // the caller's backup action (its g was larger)
  kRandomSample,  // ablation 2's random sample of the last batch
  kQpProjection,  // proposal = qp-only: the CBF-QP's projection, whose exact g < 0
  kRefinedMean,   // proposal = refine: the last gradient iterate, whose exact g < 0
};
inline constexpr EnumTable<Fallback, 6> kFallbackNames{{
    {Fallback::kNone, "none"},
    {Fallback::kBestSample, "best_sample"},
    {Fallback::kBackupAction, "backup_action"},
    {Fallback::kRandomSample, "random_sample"},
    {Fallback::kQpProjection, "qp_projection"},
    {Fallback::kRefinedMean, "refined_mean"},
}};

/// The outcome of one decision, with diagnostics. Owned by the Shield and overwritten by the
/// next Decide() (no allocation).
struct Decision {
  Status status = Status::kInvalidInput;
  Eigen::VectorXf action;         // (action_dim) the action to apply; never NaN
  double g = 0.0;                 // g(action) as evaluated (NaN only for kInvalidInput)
  double h = 0.0;                 // h(s)
  int iterations = 0;             // sampling rounds used (1 = no resampling)
  double safe_ratio = 0.0;        // #safe / M in the last round (1: a safe policy-draw, alone)
  bool intervened = false;        // the policy's own sample (the first draw) had g < 0
  double distance_to_mean = 0.0;  // ||action - mu||_2
  bool bounded = false;  // the actuator box cut into this decision: the policy's mean (policy-mean)
                         // or a drawn sample lay outside it and was clipped or rejected
  Fallback fallback = Fallback::kNone;
  QpOutcome qp = QpOutcome::kNotTried;  // the CBF-QP projection (proposal qp, qp-only)
  double seconds = 0.0;  // wall time of the decision

  bool safe() const { return status == Status::kSafe || status == Status::kSafeAfterResampling; }
  nlohmann::json ToJson() const;
};

/// A task value of actions for Aggregation::kTopQ: Q(s, a) from the state and the shield model's
/// predicted next state s+ = T(s, a) (the authors' code: AIRL's g(s) + 0.99 V(s+);
/// policy::AirlActionValue). Called from Decide() once per aggregated round with the round's M
/// predicted next states; it must not allocate there (size its scratch for max(M, N) columns).
class ActionValue {
 public:
  virtual ~ActionValue() = default;
  /// q (K) = Q(state, a_k) for the predicted next states `next_states` (state_dim x K). A NaN Q
  /// ranks last.
  virtual void Evaluate(const Eigen::Ref<const Eigen::VectorXf>& state,
                        const Eigen::Ref<const Eigen::MatrixXf>& next_states,
                        Eigen::Ref<Eigen::VectorXd> q) = 0;
  virtual std::string Describe() const = 0;
};

/// alpha(h) for the given options.
double ClassKValue(const ShieldOptions& options, double h);

class Shield {
 public:
  /// `barrier` and `dynamics` must outlive the shield and agree on the state dimension; the
  /// barrier is evaluated from this shield only (it owns scratch memory). Buffers for M samples
  /// and N probes are allocated here.
  Shield(const ShieldOptions& options, cbf::Barrier& barrier,
         const domains::DynamicsModel& dynamics);

  /// An action to return when nothing better is known (e.g. braking); it competes on g with the
  /// best sample when no safe action is found. Must have action_dim entries, all finite.
  void SetBackupAction(const Eigen::Ref<const Eigen::VectorXf>& action);
  void ClearBackupAction() { has_backup_ = false; }

  /// The actuator box (action_dim each; -inf / +inf where a component is unbounded, low <= high).
  /// Decisions then stay inside it as ShieldOptions::action_bounds says. A backup action must lie
  /// inside it. @throws secure::Error on a wrong size, NaN, low > high, or a backup outside.
  void SetActionBounds(const Eigen::Ref<const Eigen::VectorXf>& low,
                       const Eigen::Ref<const Eigen::VectorXf>& high);
  /// The environment's actuator box (domains::Environment::ActionBounds), as the experiment driver,
  /// `secure eval` and Python's run_episodes set it.
  void SetActionBounds(const domains::Environment& env);
  void ClearActionBounds() { has_bounds_ = false; }
  bool has_action_bounds() const { return has_bounds_; }
  const Eigen::VectorXf& action_low() const { return low_; }    // -inf where no box
  const Eigen::VectorXf& action_high() const { return high_; }  // +inf where no box
  /// Whether a box is set and used (set, and action_bounds is not ignore).
  bool bounds_active() const {
    return has_bounds_ && options_.action_bounds != ActionBounds::kIgnore;
  }

  /// The task value Aggregation::kTopQ ranks the safe samples by (it must outlive the shield, or
  /// be replaced first; null clears it). Decide() with aggregation = top-q and no value throws.
  void SetActionValue(ActionValue* value) { action_value_ = value; }

  /// Re-seeds the shield's random stream.
  void Seed(std::uint64_t seed) { rng_.Seed(seed); }

  /// One shielded decision. `mu` and `sigma` (action_dim) are the policy's Gaussian at `state`.
  /// @throws secure::Error only on misuse: wrong dimensions, or (qp_metric = policy with proposal
  /// qp or qp-only) a sigma with a zero entry; other bad numbers give kInvalidInput.
  const Decision& Decide(const Eigen::Ref<const Eigen::VectorXf>& state,
                         const Eigen::Ref<const Eigen::VectorXf>& mu,
                         const Eigen::Ref<const Eigen::VectorXf>& sigma);

  /// g for each column of `actions` (action_dim x K, K <= max(M, N)) at `state`, using h(s) =
  /// `h_state` (g_H with lookahead_steps = H > 1): the same computation Decide() uses, exposed
  /// for tests and tools.
  void EvaluateG(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state,
                 const Eigen::Ref<const Eigen::MatrixXf>& actions, Eigen::Ref<Eigen::VectorXd> g);

  /// h(s) of one state.
  double EvaluateH(const Eigen::Ref<const Eigen::VectorXf>& state);

  const ShieldOptions& options() const { return options_; }
  int action_dim() const { return action_dim_; }
  int state_dim() const { return state_dim_; }

 private:
  // One round: draw M samples from N(mu, sigma_) into samples_ (with options_.sampler), evaluate
  // g_, count the safe ones.
  // Draws a round's M samples (samples_) from mu_, sigma_.
  void DrawRound();
  // g of every sample of the round (g_), the best one so far; returns the number of safe ones.
  int ScoreRound(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state);
  // Algorithm 2: widen sigma_ along unsafe directions around mu.
  void AdaptSigma(const Eigen::Ref<const Eigen::VectorXf>& state,
                  const Eigen::Ref<const Eigen::VectorXf>& mu);
  // Aggregates the safe samples of the current round into decision_.action.
  void Aggregate(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state, int num_safe);
  // Algorithm 1, lines 6-9, over the round's samples order_[0 .. count) (ascending, all safe):
  // their mean if it is safe, else the one of them nearest to it.
  void AggregateMean(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state, int count);
  void FinishInvalid();
  // Marks the round's samples outside the box (rejected_[c]; bounds_active()). Returns whether
  // one was outside.
  bool BoundRound();
  // `actions` as the actuator applies them: clipped onto the box (a copy in applied_) when
  // bounds_active(), else `actions` itself.
  Eigen::Ref<const Eigen::MatrixXf> Applied(const Eigen::Ref<const Eigen::MatrixXf>& actions);
  // The CBF-QP projection of mu (proposal != none) into decision_ (action, g, qp); returns whether
  // its exact g >= 0. h_state = h(s), finite.
  // `sigma` (finite, >= 0) is the policy's, for qp_metric = policy.
  bool ProposeQp(const Eigen::Ref<const Eigen::VectorXf>& state,
                 const Eigen::Ref<const Eigen::VectorXf>& mu,
                 const Eigen::Ref<const Eigen::VectorXf>& sigma, double h_state);
  // The projection of qp_mu_ onto the half-space c . a >= offset (c = qp_normal_) and the box,
  // in the metric qp_metric, into qp_solution_.
  QpResult Project(const Eigen::Ref<const Eigen::VectorXf>& sigma, double offset);
  // The linearisation of g at a0 = qp_actions_.col(0) (in the box): T at a0 and its 2n
  // neighbours (qp_next_), h and grad h at T(s, a0), the Jacobian, and the normal c = J^T grad h
  // / dt (qp_normal_). Returns g(a0) from that h.
  double Linearise(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state);
  // Columns 1 + 2r and 2 + 2r of qp_actions_: a0 = qp_actions_.col(0) moved by +step and -step
  // along action r, inside the box (shorter at a face).
  void SetNeighbours(int r, float step);
  // The width of that pair along action r (0 where the box leaves no room).
  double NeighbourWidth(int r) const;
  // qp_smoothing's linearisation at a0 = qp_actions_.col(0): the normal c (qp_normal_) from
  // central differences of the exact g at a0 +- qp_smoothing sigma_r along each action (inside
  // the box), 2n exact g in one batch.
  void LineariseSmoothed(const Eigen::Ref<const Eigen::VectorXf>& state,
                         const Eigen::Ref<const Eigen::VectorXf>& sigma, double h_state);
  // How one projection round ended: accepted (recorded in decision_), stopped (beyond the trust
  // region: no further analytic round), or rejected with the next linearisation point in
  // qp_actions_.col(0).
  enum class QpRound { kAccepted, kStop, kContinue };
  // One round: the projection of qp_mu_ onto the half-space of the linearisation (qp_normal_,
  // value g0 at qp_actions_.col(0)), its exact check, bisection and line search. g_point is the
  // exact g at the linearisation point; on kContinue it becomes the projection's.
  QpRound ProjectAndCheck(const Eigen::Ref<const Eigen::VectorXf>& state,
                          const Eigen::Ref<const Eigen::VectorXf>& sigma, double h_state,
                          double g0, double& g_point);
  // qp_line_search's secant steps on the exact g along a0 + t (a* - a0) (a0 = qp_point_ with
  // exact g g_point, a* = qp_solution_ with exact g g_solution); returns whether a point's g >= 0
  // (then it is recorded in decision_).
  bool LineSearch(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state, double g_point,
                  double g_solution);
  // qp_bisection's steps on the same line between a rejected t_unsafe (exact g g_unsafe) and the
  // accepted t_safe (g_safe, recorded in decision_), when g_safe overshot the target: each
  // midpoint whose exact g >= the target becomes the decision and the new safe end.
  void Bisect(const Eigen::Ref<const Eigen::VectorXf>& state, double h_state, double t_unsafe,
              double g_unsafe, double t_safe, double g_safe);
  // a0 + t (a* - a0) (qp_point_, qp_solution_) into one_action_, clipped onto the box.
  void PointOnLine(double t);
  // qp_max_step acts (proposal qp).
  bool TrustRegionActive() const;
  // With qp_bisection, the accepted decision (after bisection) must lie within qp_max_step of
  // mu: returns false (outcome infeasible, sampling decides) when it does not.
  bool AcceptWithinTrustRegion();
  // proposal = refine: the gradient refinement of mu into decision_ (action, g, qp); returns
  // whether an iterate's exact g >= 0 (shield_refine.cc).
  bool RefineMean(const Eigen::Ref<const Eigen::VectorXf>& state,
                  const Eigen::Ref<const Eigen::VectorXf>& mu, double h_state);
  // Clips the columns of `actions` onto the box (bounds_active()); returns whether one moved.
  bool ClipToBox(Eigen::Ref<Eigen::MatrixXf> actions) const;
  // kSafe after one round, kSafeAfterResampling after more.
  Status SafeStatus() const;

  ShieldOptions options_;
  cbf::Barrier& barrier_;
  const domains::DynamicsModel& dynamics_;
  int state_dim_;
  int action_dim_;
  Rng rng_;
  Decision decision_;
  bool has_backup_ = false;
  Eigen::VectorXf backup_;
  ActionValue* action_value_ = nullptr;
  bool has_bounds_ = false;
  Eigen::VectorXf low_, high_;  // (action_dim) the actuator box

  // Preallocated scratch (sized in the constructor).
  Eigen::VectorXf mu_, sigma_;   // the current sampling distribution
  Eigen::MatrixXf samples_;      // (action_dim x M)
  Eigen::MatrixXf probes_;       // (action_dim x N)
  Eigen::MatrixXf next_states_;  // (state_dim x max(M, N))
  Eigen::VectorXf h_next_;       // (max(M, N))
  Eigen::VectorXd g_;            // (max(M, N))
  Eigen::MatrixXf one_action_;   // (action_dim x 1)
  Eigen::VectorXd one_g_;        // (1)
  Eigen::VectorXf best_action_;  // best (largest g) evaluated sample so far
  double best_g_ = 0.0;
  Eigen::MatrixXf state_column_;  // (state_dim x 1) for h(s)
  Eigen::VectorXf h_one_;         // (1)
  Eigen::VectorXf d_sigma_;       // (action_dim)
  Eigen::VectorXd q_;             // (M) aggregation = top-q: Q of the round's samples
  Eigen::MatrixXf step_scratch_;  // (state_dim x 1) lookahead_steps > 1: one model step
  std::vector<int> order_;        // (M) indices of the samples being aggregated
  std::vector<char> rejected_;    // (M) the sample lies outside the box (bounds_active())
  Eigen::MatrixXf applied_;       // (action_dim x max(M, N)) the round's actions, clipped
  // Sampler::kQmc: the first M Sobol points as 64-bit integers, (action_dim x M), column c =
  // point c (built in the constructor; empty for the other samplers).
  Eigen::Matrix<std::uint64_t, Eigen::Dynamic, Eigen::Dynamic> sobol_;
  // proposal != none: the linearisation point, its 2 action_dim neighbours for the model's
  // Jacobian (central differences) and their next states; h and grad h at the predicted state;
  // the Jacobian, the half-space's normal and the projection (sized in the constructor).
  Eigen::MatrixXf qp_actions_;    // (action_dim x 2 action_dim + 1)
  Eigen::MatrixXf qp_next_;       // (state_dim x 2 action_dim + 1)
  Eigen::VectorXf qp_h_;          // (1)
  Eigen::MatrixXf qp_gradient_;   // (state_dim x 1)
  Eigen::MatrixXd qp_jacobian_;   // (state_dim x action_dim)
  Eigen::VectorXd qp_g_;          // (2 action_dim) qp_smoothing's exact g at a0 +- step
  Eigen::VectorXd qp_normal_, qp_mu_, qp_low_, qp_high_, qp_solution_;  // (action_dim)
  Eigen::VectorXd qp_point_;  // (action_dim) the linearisation point a0 (qp_line_search's line)
  std::vector<double> qp_scratch_;           // (4 action_dim + 2) the QP's breakpoints
  Eigen::VectorXd qp_sigma_;                 // (action_dim) qp_metric = policy: the policy's sigma
  GaussianMetricScratch qp_metric_scratch_;  // qp_metric = policy: the problem in z
};

}  // namespace secure::shield
