// The CBF-QP projection in the shield (ShieldOptions::proposal): the gradient-first mode (qp),
// the CBF-QP filter alone (qp-only) and the gradient refinement of the mean (refine)
// (the projection's metric and target: shield_qp_metric_test.cc; the smoothed round:
// shield_qp_smoothing_test.cc). Properties with RapidCheck over the double integrator (its
// ground truth, whose gradient is by finite differences, and a random barrier network) and Derby
// (a random per-car barrier and its shield model); exact cases on an integrator.

#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"

#include <gtest/gtest.h>
#include <rapidcheck.h>
#include <rapidcheck/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cmath>
#include <limits>
#include <memory>
#include <string>

#include "domains/derby/derby.h"
#include "domains/derby/domain.h"
#include "domains/double_integrator/double_integrator.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/rng.h"
#include "secure/nn/mlp.h"
#include "tests/test_util.h"

namespace secure::shield {
namespace {

using secure::test::ErrorOf;
using test::BitEqual;
using test::FunctionBarrier;
using test::HalfSpace;
using test::IntegratorDynamics;
using test::Vec;

namespace di = domains::double_integrator;
namespace derby = domains::derby;

rc::Gen<double> UniformIn(double lo, double hi) {
  return rc::gen::map(rc::gen::inRange<int>(0, 100001),
                      [lo, hi](int i) { return lo + (hi - lo) * (i / 100000.0); });
}

Eigen::VectorXf RandomVector(int n, double lo, double hi) {
  Eigen::VectorXf v(n);
  for (int i = 0; i < n; ++i) v[i] = static_cast<float>(*UniformIn(lo, hi));
  return v;
}

struct System {
  std::unique_ptr<cbf::BarrierNet> net;
  std::unique_ptr<cbf::CarBarrierNet> car_net;
  std::unique_ptr<cbf::Barrier> barrier, barrier2, independent;
  std::unique_ptr<domains::DynamicsModel> dynamics;
  Eigen::VectorXf state;
  bool learned = false;
};

System RandomSystem() {
  System s;
  const int kind = *rc::gen::inRange(0, 3);
  const auto seed = *rc::gen::arbitrary<std::uint64_t>();
  if (kind == 0 || kind == 1) {
    s.dynamics = std::make_unique<di::Dynamics>(0.1);
    s.state.resize(4);
    s.state.head(2) = RandomVector(2, -1.0, 11.0);
    s.state.tail(2) = RandomVector(2, -2.0, 2.0);
    if (kind == 0) {
      s.barrier = std::make_unique<di::GroundTruthBarrier>(di::GroundTruth{});
      s.barrier2 = std::make_unique<di::GroundTruthBarrier>(di::GroundTruth{});
      s.independent = std::make_unique<di::GroundTruthBarrier>(di::GroundTruth{});
    } else {
      s.net = std::make_unique<cbf::BarrierNet>();
      s.net->mlp = nn::RandomMlpParams({4, {16, 16}, 1, nn::Activation::kTanh}, seed);
      s.net->normalizer = nn::Normalizer::Identity(4);
      s.net->features = di::StateFeatures();
      s.barrier = s.net->MakeEvaluator(256);
      s.barrier2 = s.net->MakeEvaluator(256);
      s.independent = s.net->MakeEvaluator(256);
      s.learned = true;
    }
  } else {
    s.car_net = std::make_unique<cbf::CarBarrierNet>();
    s.car_net->input.layout = derby::ObstacleLayoutOfObservation();
    s.car_net->input.use_velocity = (seed & 1) != 0;
    const int f = s.car_net->input.feature_dim();
    s.car_net->mlp = nn::RandomMlpParams({f, {16, 8}, 1, nn::Activation::kRelu}, seed);
    s.car_net->normalizer = nn::Normalizer::Identity(f);
    s.barrier = s.car_net->MakeEvaluator(256);
    s.barrier2 = s.car_net->MakeEvaluator(256);
    s.independent = s.car_net->MakeEvaluator(256);
    const derby::DerbyOptions task;
    s.dynamics = std::make_unique<derby::DerbyShieldModel>(task.dt, task.accel_bound,
                                                           task.lookahead_steps);
    derby::DerbyEnv env;
    Rng rng(seed);
    s.state.resize(env.observation_dim());
    env.Reset(rng, s.state);
    s.learned = true;
  }
  return s;
}

ShieldOptions RandomOptions() {
  ShieldOptions o;
  o.num_samples = *rc::gen::inRange(8, 65);
  o.class_k_gain = *UniformIn(0.1, 5.0);
  o.aggregation = *rc::gen::element(Aggregation::kMean, Aggregation::kPolicyMean);
  o.max_iterations = *rc::gen::inRange(1, 6);
  o.seed = *rc::gen::arbitrary<std::uint64_t>();
  o.qp_iterations = *rc::gen::inRange(1, 4);
  o.qp_line_search = *rc::gen::inRange(0, 4);
  o.qp_bisection = *rc::gen::element(0, 0, 3, 8);
  o.qp_max_step = *rc::gen::element(0.0, 0.0, 1.0, 4.0);
  o.qp_smoothing = *rc::gen::element(0.0, 0.0, 1.0, 2.0);
  o.qp_margin = *rc::gen::element(0.0, 0.1);
  o.action_bounds = *rc::gen::element(ActionBounds::kClip, ActionBounds::kReject);
  o.qp_metric = *rc::gen::element(QpMetric::kEuclidean, QpMetric::kPolicy);  // sigma > 0 here
  return o;
}

double Tolerance(bool learned, double g) {
  // A learned barrier evaluated alone vs in a batch differs by float rounding (see the shield's
  // property test): g agrees to about 1e-4 at dt = 0.1.
  return learned ? 1e-4 * std::max(1.0, std::abs(g)) : 1e-9;
}

double IndependentG(System& s, const ShieldOptions& o, const Eigen::VectorXf& action) {
  return test::IndependentG(*s.independent, *s.dynamics, o, s.state, action);
}

// The gradient-first shield either decides by the projection, which then satisfies the exact
// CBF condition, or runs Algorithms 1-2 unchanged: its decision is then the sampling shield's, bit
// for bit. So it never returns an action with g < 0 where the sampling shield finds a safe one,
// and it says so in its status whenever it returns one with g < 0.
RC_GTEST_PROP(QpShieldProperty, GradientFirstIsTheProjectionOrTheSamplingShieldsDecision, ()) {
  System s = RandomSystem();
  ShieldOptions o = RandomOptions();
  const Eigen::VectorXf mu = RandomVector(2, -5, 5), sigma = RandomVector(2, 0.05, 2.0);
  const bool boxed = *rc::gen::arbitrary<bool>();
  ShieldOptions sampling = o;
  o.proposal = Proposal::kQp;
  Shield first(o, *s.barrier, *s.dynamics);
  Shield plain(sampling, *s.barrier2, *s.dynamics);
  if (boxed) {
    first.SetActionBounds(Vec({-3, -3}), Vec({3, 3}));
    plain.SetActionBounds(Vec({-3, -3}), Vec({3, 3}));
  }
  const Decision& d = first.Decide(s.state, mu, sigma);
  RC_TAG(ToString(kQpOutcomeNames, d.qp));
  RC_ASSERT(d.qp != QpOutcome::kNotTried);
  RC_ASSERT(d.action.allFinite());
  if (boxed) RC_ASSERT((d.action.array().abs() <= 3.0f).all());
  if (d.qp == QpOutcome::kAccepted) {
    RC_ASSERT(d.status == Status::kSafe);
    RC_ASSERT(d.iterations == 0);
    const double g = IndependentG(s, o, d.action);
    RC_LOG() << d.ToJson().dump() << " independent g " << g << "\n";
    RC_ASSERT(g >= -Tolerance(s.learned, g));
    RC_ASSERT(std::abs(g - d.g) <= Tolerance(s.learned, g));
    return;
  }
  const Decision& e = plain.Decide(s.state, mu, sigma);
  RC_LOG() << d.ToJson().dump() << "\n" << e.ToJson().dump() << "\n";
  RC_ASSERT(d.status == e.status);
  RC_ASSERT(BitEqual(d.action, e.action));
  RC_ASSERT(d.g == e.g || (std::isnan(d.g) && std::isnan(e.g)));
  RC_ASSERT(d.iterations == e.iterations && d.fallback == e.fallback);
  RC_ASSERT(d.intervened == e.intervened && d.bounded == e.bounded);
}

// The CBF-QP filter alone (qp-only) or the gradient refinement alone (refine, method cbf-grad):
// safe exactly when its action's exact g >= 0; otherwise it says so (no_safe_action, fallback
// qp_projection or refined_mean, outcome rejected, or infeasible for qp-only), with g < 0. Its
// action stays in the box.
void CheckAFilterAlone(Proposal proposal) {
  System s = RandomSystem();
  ShieldOptions o = RandomOptions();
  o.proposal = proposal;
  const Eigen::VectorXf mu = RandomVector(2, -5, 5), sigma = RandomVector(2, 0.05, 2.0);
  if (proposal == Proposal::kRefine) o.refine_steps = *rc::gen::inRange(1, 8);
  Shield shield(o, *s.barrier, *s.dynamics);
  shield.SetActionBounds(Vec({-3, -3}), Vec({3, 3}));
  const Decision& d = shield.Decide(s.state, mu, sigma);
  RC_TAG(ToString(kQpOutcomeNames, d.qp));
  RC_ASSERT(d.iterations == 0);
  RC_ASSERT((d.action.array().abs() <= 3.0f).all());
  const double g = IndependentG(s, o, d.action);
  RC_LOG() << d.ToJson().dump() << " independent g " << g << "\n";
  RC_ASSERT(std::abs(g - d.g) <= Tolerance(s.learned, g));
  if (d.safe()) {
    RC_ASSERT(d.qp == QpOutcome::kAccepted && d.fallback == Fallback::kNone);
    RC_ASSERT(d.g >= 0.0);
  } else {
    RC_ASSERT(d.status == Status::kNoSafeAction);
    RC_ASSERT(d.fallback == (proposal == Proposal::kRefine ? Fallback::kRefinedMean
                                                           : Fallback::kQpProjection));
    RC_ASSERT(d.qp == QpOutcome::kRejected ||
              (proposal == Proposal::kQpOnly && d.qp == QpOutcome::kInfeasible));
    RC_ASSERT(d.g < 0.0);
  }
}

RC_GTEST_PROP(QpShieldProperty, QpOnlyReportsTheExactCheck, ()) {
  CheckAFilterAlone(Proposal::kQpOnly);
}

RC_GTEST_PROP(QpShieldProperty, RefineReportsTheExactCheckAndStaysInTheBox, ()) {
  CheckAFilterAlone(Proposal::kRefine);
}

// h(s) = w . s + b with an integrator: the linearisation is exact, so the filter returns the
// closed-form projection of mu onto {g >= 0}, and mu itself where mu is safe.
// h(s) = w . s + 0.5 with w = (1, -2), and the integrator s' = s + 0.1 a.
TEST(QpShieldTest, LinearBarrierAndAffineModelGiveTheClosedFormProjection) {
  HalfSpace h;
  const Eigen::Vector2f& w = h.w;
  ShieldOptions o;
  o.proposal = Proposal::kQpOnly;
  o.dt = 0.1;
  o.class_k_gain = 2.0;
  Shield shield(o, h.barrier, h.dynamics);
  const Eigen::VectorXf state = Vec({0.2f, 0.3f});  // h = 0.2 - 0.6 + 0.5 = 0.1
  // g(a) = w . a + alpha(h) = w . a + 0.2: safe iff a0 - 2 a1 >= -0.2.
  const Eigen::VectorXf unsafe_mu = Vec({-1.0f, 1.0f});  // w . mu = -3
  const Decision& d = shield.Decide(state, unsafe_mu, Vec({0.1f, 0.1f}));
  EXPECT_EQ(d.status, Status::kSafe) << d.ToJson().dump();
  EXPECT_EQ(d.qp, QpOutcome::kAccepted);
  EXPECT_TRUE(d.intervened);
  EXPECT_EQ(d.iterations, 0);
  // mu + (0.2 - (-3 + 0.2)) ... the projection: mu + (-0.2 - w . mu) / |w|^2 w.
  const Eigen::Vector2f expected = unsafe_mu + (-0.2f - w.dot(unsafe_mu)) / w.squaredNorm() * w;
  EXPECT_NEAR(d.action[0], expected[0], 1e-3);
  EXPECT_NEAR(d.action[1], expected[1], 1e-3);
  EXPECT_NEAR(d.g, 0.0, 1e-2);  // the rounding allowance: 1e-4 (1 + h) / dt = 1.1e-3
  EXPECT_GE(d.g, 0.0);

  const Eigen::VectorXf safe_mu = Vec({1.0f, 0.0f});
  const Decision& e = shield.Decide(state, safe_mu, Vec({0.1f, 0.1f}));
  EXPECT_EQ(e.status, Status::kSafe);
  EXPECT_EQ(e.qp, QpOutcome::kAccepted);
  EXPECT_FALSE(e.intervened);
  EXPECT_TRUE(BitEqual(e.action, safe_mu));
  EXPECT_EQ(e.distance_to_mean, 0.0);

  // A box the half-space misses: infeasible, the box point of largest g, reported unsafe.
  shield.SetActionBounds(Vec({-1.0f, 0.5f}), Vec({-0.5f, 1.0f}));  // w . a <= -1.5
  const Decision& f = shield.Decide(state, unsafe_mu, Vec({0.1f, 0.1f}));
  EXPECT_EQ(f.status, Status::kNoSafeAction);
  EXPECT_EQ(f.qp, QpOutcome::kInfeasible);
  EXPECT_EQ(f.fallback, Fallback::kQpProjection);
  EXPECT_TRUE(BitEqual(f.action, Vec({-0.5f, 0.5f})));
  EXPECT_NEAR(f.g, -1.5 + 0.2, 1e-4);
  EXPECT_EQ(f.ToJson()["qp"], "infeasible");
}

// The projection's trust region (qp_max_step): a projection farther from mu than the limit is
// not taken, the outcome says infeasible, and Algorithms 1-2 decide; within the limit nothing
// changes.
TEST(QpShieldTest, AProjectionBeyondTheTrustRegionFallsBackToSampling) {
  HalfSpace h;
  const Eigen::Vector2f& w = h.w;
  const Eigen::VectorXf state = Vec({0.2f, 0.3f});
  const Eigen::VectorXf unsafe_mu = Vec({-1.0f, 1.0f});
  const Eigen::Vector2f projection =
      unsafe_mu + (-0.2f - w.dot(unsafe_mu)) / w.squaredNorm() * w;
  const double step = (projection - Eigen::Vector2f(unsafe_mu)).norm();  // 2.8 / sqrt(5) = 1.25
  ASSERT_NEAR(step, 2.8 / std::sqrt(5.0), 1e-5);
  ShieldOptions o;
  o.proposal = Proposal::kQp;
  o.dt = 0.1;
  o.class_k_gain = 2.0;
  o.qp_max_step = step + 0.05;  // just beyond: the projection is taken
  Shield within(o, h.barrier, h.dynamics);
  const Decision& d = within.Decide(state, unsafe_mu, Vec({0.5f, 0.5f}));
  EXPECT_EQ(d.qp, QpOutcome::kAccepted);
  EXPECT_EQ(d.iterations, 0);
  EXPECT_NEAR(d.action[0], projection[0], 1e-3);
  EXPECT_NEAR(d.action[1], projection[1], 1e-3);

  o.qp_max_step = step - 0.05;  // just short: sampling decides
  Shield capped(o, h.barrier, h.dynamics);
  const Decision& e = capped.Decide(state, unsafe_mu, Vec({0.5f, 0.5f}));
  EXPECT_EQ(e.qp, QpOutcome::kInfeasible) << e.ToJson().dump();
  EXPECT_GE(e.iterations, 1) << e.ToJson().dump();
  // Algorithms 1-2 find safe draws (after widening sigma): a safe status.
  EXPECT_TRUE(e.status == Status::kSafe || e.status == Status::kSafeAfterResampling)
      << e.ToJson().dump();
  EXPECT_GE(e.g, 0.0);
  EXPECT_GT((e.action - Eigen::VectorXf(projection)).norm(), 1e-3);
  EXPECT_EQ(e.ToJson()["qp"], "infeasible");

  // A mean that passes is never affected.
  const Decision& f = capped.Decide(state, Vec({1.0f, 0.0f}), Vec({0.5f, 0.5f}));
  EXPECT_EQ(f.qp, QpOutcome::kAccepted);
  EXPECT_FALSE(f.intervened);
}

// h(s) = 1 - |s|^2 (a disc: h concave) with the integrator s' = s + 0.1 a, at s = (0, 0.9), the
// policy's mean (3, 3) pointing outward and sideways.
struct Disc {
  FunctionBarrier barrier{2, "disc", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            return 1.0 - static_cast<double>(s.squaredNorm());
                          }};
  const IntegratorDynamics dynamics{2, 0.1};
  const Eigen::VectorXf state = Vec({0.0f, 0.9f});
  const Eigen::VectorXf mu = Vec({3.0f, 3.0f});
  static ShieldOptions QpOnly() {
    ShieldOptions o;
    o.proposal = Proposal::kQpOnly;
    return o;
  }
};

// A curved barrier (a disc, h concave): the tangent plane overestimates h, so the textbook
// projection lands just outside the safe set and the exact check rejects it; re-linearising at
// the projection (qp_iterations), a margin, or more refinement steps recover a safe action.
TEST(QpShieldTest, ACurvedBarrierMisleadsOneLinearisationAndTheStatusSaysSo) {
  Disc disc;
  FunctionBarrier& barrier = disc.barrier;
  const IntegratorDynamics& dynamics = disc.dynamics;
  const Eigen::VectorXf &state = disc.state, &mu = disc.mu;
  ShieldOptions o = disc.QpOnly();
  o.class_k_gain = 1.0;
  {
    Shield shield(o, barrier, dynamics);
    const Decision& d = shield.Decide(state, mu, Vec({0.1f, 0.1f}));
    EXPECT_EQ(d.qp, QpOutcome::kRejected) << d.ToJson().dump();
    EXPECT_EQ(d.status, Status::kNoSafeAction);
    EXPECT_EQ(d.fallback, Fallback::kQpProjection);
    EXPECT_LT(d.g, 0.0);
  }
  o.qp_iterations = 4;
  {
    Shield shield(o, barrier, dynamics);
    const Decision& d = shield.Decide(state, mu, Vec({0.1f, 0.1f}));
    EXPECT_EQ(d.qp, QpOutcome::kAccepted) << d.ToJson().dump();
    EXPECT_GE(d.g, 0.0);
  }
  // The gradient-first shield falls back to sampling, which finds a safe action.
  o.proposal = Proposal::kQp;
  o.qp_iterations = 1;
  {
    Shield shield(o, barrier, dynamics);
    const Decision& d = shield.Decide(state, mu, Vec({0.5f, 0.5f}));
    EXPECT_EQ(d.qp, QpOutcome::kRejected) << d.ToJson().dump();
    EXPECT_TRUE(d.safe()) << d.ToJson().dump();
    EXPECT_GE(d.iterations, 1);
  }
  // The gradient refinement: one step lands just outside as the projection does; the next ones,
  // re-linearised, reach g >= 0.
  o.proposal = Proposal::kRefine;
  for (int steps : {1, 5}) {
    o.refine_steps = steps;
    Shield shield(o, barrier, dynamics);
    const Decision& d = shield.Decide(state, mu, Vec({0.1f, 0.1f}));
    EXPECT_EQ(d.safe(), steps == 5) << d.ToJson().dump();
    EXPECT_EQ(d.fallback, steps == 5 ? Fallback::kNone : Fallback::kRefinedMean);
    if (steps == 1) EXPECT_LT(d.g, 0.0);
  }
}

// A constructed half-space (h(s) = w . s + b, an integrator: g affine in a): one Polyak step
// moves a violating mean onto g >= 0; with a box the clipped steps stay in it and still reach the
// half-space; a box the half-space misses is reported.
// The same disc: the textbook projection a* lands just outside; one secant step of the line
// search along mu + t (a* - mu), aimed past the boundary by the deficit g(a*), is accepted. The
// decision lies on that line beyond a*, at the t the secant gives, and the gradient-first shield
// then decides without sampling.
TEST(QpShieldTest, ALineSearchOnTheExactGRecoversARejectedProjection) {
  Disc disc;
  ShieldOptions o = Disc::QpOnly();
  Shield plain(o, disc.barrier, disc.dynamics);
  const Decision& rejected = plain.Decide(disc.state, disc.mu, Vec({0.1f, 0.1f}));
  ASSERT_EQ(rejected.qp, QpOutcome::kRejected);
  const Eigen::Vector2d a_star = rejected.action.cast<double>();
  const double g_star = rejected.g;
  ASSERT_LT(g_star, 0.0);
  // g(mu) exactly: h(s + 0.1 mu) - h(s) over dt, plus alpha(h(s)) = h(s).
  const Eigen::Vector2d s0 = disc.state.cast<double>(), m = disc.mu.cast<double>();
  const auto h = [](const Eigen::Vector2d& s) { return 1.0 - s.squaredNorm(); };
  const double g_mu = (h(s0 + 0.1 * m) - h(s0)) / 0.1 + h(s0);
  ASSERT_LT(g_mu, g_star);  // g rises along the line

  o.qp_line_search = 1;
  Shield searching(o, disc.barrier, disc.dynamics);
  const Decision& d = searching.Decide(disc.state, disc.mu, Vec({0.1f, 0.1f}));
  EXPECT_EQ(d.qp, QpOutcome::kAccepted) << d.ToJson().dump();
  EXPECT_EQ(d.fallback, Fallback::kNone);
  EXPECT_GE(d.g, 0.0);
  EXPECT_NEAR(d.g, (h(s0 + 0.1 * d.action.cast<double>()) - h(s0)) / 0.1 + h(s0), 1e-4);
  // On the line, beyond a*, at t = 1 + 2 (target - g*) / (g* - g(mu)) (target ~ 0 here: the
  // rounding margin 1e-4 (1 + |h(s)|) / dt).
  const double target = 1e-4 * (1.0 + std::abs(h(s0))) / 0.1;
  const double t = 1.0 + 2.0 * (target - g_star) / (g_star - g_mu);
  const Eigen::Vector2d expected = m + t * (a_star - m);
  EXPECT_NEAR(d.action[0], expected[0], 1e-4);
  EXPECT_NEAR(d.action[1], expected[1], 1e-4);

  // The gradient-first shield: the search decides, no sampling round runs.
  o.proposal = Proposal::kQp;
  Shield first(o, disc.barrier, disc.dynamics);
  const Decision& f = first.Decide(disc.state, disc.mu, Vec({0.5f, 0.5f}));
  EXPECT_EQ(f.qp, QpOutcome::kAccepted) << f.ToJson().dump();
  EXPECT_EQ(f.iterations, 0);
  EXPECT_TRUE(f.safe());
}

// g far from linear in the action: on an integrator (x' = x + 0.1 a, from x = 0) the barrier h(y)
// = 0.5 - tanh(20 (y - 0.1)) drops like a step where y = 0.1 a crosses 0.1, as a shield model's
// contact switches on; with alpha(h) = 5 h, g(a) = 10 h(0.1 a) - 7.32 >= 0 exactly for a <= a_b =
// 1 + atanh(-0.232) / 2 = 0.8818. From mu = 2.5, on the flat part of the step (g = -12.3, slope
// -0.2), the linearisation puts the boundary at a = -59.8: the projection lands there, and the
// exact g accepts it. Bisection on the exact g along the line brings it back to just inside a_b.
struct Step : test::Integrator1d {
  Step() : Integrator1d("step", [](double y) { return 0.5 - std::tanh(20.0 * (y - 0.1)); }) {}
  const Eigen::VectorXf mu = Vec({2.5f});
  static double G(double a) {
    const double h0 = 0.5 - std::tanh(-2.0);
    return (0.5 - std::tanh(20.0 * (0.1 * a - 0.1)) - h0) / 0.1 + 5.0 * h0;
  }
  static ShieldOptions Options(Proposal proposal, int bisection) {
    ShieldOptions o = Integrator1d::Options(proposal, 5.0);
    o.qp_bisection = bisection;
    return o;
  }
};

TEST(QpShieldTest, BisectionBringsAnOvershootingProjectionBackToTheExactBoundary) {
  Step step;
  const double a_b = 1.0 + std::atanh(-0.232) / 2.0;
  ASSERT_NEAR(Step::G(a_b), 0.0, 0.01);
  ASSERT_LT(Step::G(2.5), -12.0);
  Shield overshooting(Step::Options(Proposal::kQpOnly, 0), step.barrier, step.dynamics);
  const Decision& far = overshooting.Decide(step.state, step.mu, Vec({0.3f}));
  ASSERT_EQ(far.qp, QpOutcome::kAccepted) << far.ToJson().dump();
  EXPECT_LT(far.action[0], -50.0f);  // the linearised boundary, 60 action units away
  EXPECT_GT(far.g, 7.0);

  // 12 steps: the line from 2.5 to -59.8 to within 62.3 / 2^12 = 0.015, on the safe side.
  Shield bisecting(Step::Options(Proposal::kQpOnly, 12), step.barrier, step.dynamics);
  const Decision& d = bisecting.Decide(step.state, step.mu, Vec({0.3f}));
  ASSERT_EQ(d.qp, QpOutcome::kAccepted) << d.ToJson().dump();
  EXPECT_TRUE(d.safe());
  EXPECT_GE(d.g, 0.0);
  EXPECT_NEAR(d.g, Step::G(d.action[0]), 1e-3);
  EXPECT_LE(d.action[0], a_b + 1e-3);
  EXPECT_GE(d.action[0], a_b - 0.02);
  EXPECT_NEAR(d.distance_to_mean, 2.5 - d.action[0], 1e-5);

  // The gradient-first shield takes the bisected projection too; no sampling round runs.
  Shield first(Step::Options(Proposal::kQp, 12), step.barrier, step.dynamics);
  const Decision& f = first.Decide(step.state, step.mu, Vec({0.3f}));
  EXPECT_EQ(f.qp, QpOutcome::kAccepted);
  EXPECT_EQ(f.iterations, 0);
  EXPECT_TRUE(BitEqual(f.action, d.action));

  // With a trust region the bisected decision is what must lie in it: 1.62 from mu is inside
  // qp_max_step = 2 (the projection, 62 away, is not), outside 1.5, where sampling decides.
  ShieldOptions trusted = Step::Options(Proposal::kQp, 12);
  trusted.qp_max_step = 2.0;
  Shield within(trusted, step.barrier, step.dynamics);
  const Decision& w = within.Decide(step.state, step.mu, Vec({0.3f}));
  EXPECT_EQ(w.qp, QpOutcome::kAccepted);
  EXPECT_TRUE(BitEqual(w.action, d.action));
  trusted.qp_max_step = 1.5;
  Shield beyond(trusted, step.barrier, step.dynamics);
  const Decision& b = beyond.Decide(step.state, step.mu, Vec({0.3f}));
  EXPECT_EQ(b.qp, QpOutcome::kInfeasible) << b.ToJson().dump();
  EXPECT_GE(b.iterations, 1);  // Algorithms 1-2 decided
  Shield sampling(Step::Options(Proposal::kNone, 0), step.barrier, step.dynamics);
  const Decision& e = sampling.Decide(step.state, step.mu, Vec({0.3f}));
  EXPECT_TRUE(BitEqual(b.action, e.action));
  EXPECT_EQ(b.status, e.status);

  // Where g is linear along the line (an affine model under a linear barrier) the projection
  // lands on the boundary, nothing overshoots, and bisection leaves the decision as it was.
  ShieldOptions affine = Step::Options(Proposal::kQpOnly, 0);
  affine.class_k_gain = 2.0;
  ShieldOptions affine_bisected = affine;
  affine_bisected.qp_bisection = 12;
  test::ExpectTheSameAffineProjection(affine, affine_bisected);
}

TEST(QpShieldTest, RefinementMovesAViolatingMeanIntoTheHalfSpaceWithinTheBox) {
  HalfSpace h;
  const Eigen::Vector2f& w = h.w;
  FunctionBarrier& barrier = h.barrier;
  const IntegratorDynamics& dynamics = h.dynamics;
  ShieldOptions o;
  o.proposal = Proposal::kRefine;
  o.class_k_gain = 2.0;
  const Eigen::VectorXf state = Vec({0.2f, 0.3f});  // h = 0.1; g(a) = w . a + 0.2
  const Eigen::VectorXf mu = Vec({-1.0f, 1.0f});    // g = -2.8
  {
    o.refine_steps = 1;
    Shield shield(o, barrier, dynamics);
    const Decision& d = shield.Decide(state, mu, Vec({0.1f, 0.1f}));
    EXPECT_EQ(d.status, Status::kSafe) << d.ToJson().dump();
    EXPECT_EQ(d.qp, QpOutcome::kAccepted);
    EXPECT_TRUE(d.intervened);
    EXPECT_EQ(d.iterations, 0);
    EXPECT_GE(d.g, 0.0);
    EXPECT_NEAR(d.g, 0.0, 1e-2);  // on the boundary, plus the rounding allowance
    // Along the gradient w: the Euclidean projection of mu.
    const Eigen::Vector2f expected = mu + (-0.2f - w.dot(mu)) / w.squaredNorm() * w;
    EXPECT_NEAR(d.action[0], expected[0], 1e-3);
    EXPECT_NEAR(d.action[1], expected[1], 1e-3);
    EXPECT_EQ(d.ToJson()["qp"], "accepted");
    // A safe mean is returned as it is, unchecked by any step.
    const Decision& e = shield.Decide(state, Vec({1.0f, 0.0f}), Vec({0.1f, 0.1f}));
    EXPECT_EQ(e.status, Status::kSafe);
    EXPECT_FALSE(e.intervened);
    EXPECT_TRUE(BitEqual(e.action, Vec({1.0f, 0.0f})));
  }
  {
    // The box cuts the first step (to (-0.44, -0.12), below a1 >= 0.5): clipped to (-0.44, 0.5),
    // g = -1.24; the second step holds a1 at its face and moves a0 alone onto g = 0.
    o.refine_steps = 1;
    for (int steps : {1, 2}) {
      o.refine_steps = steps;
      Shield shield(o, barrier, dynamics);
      shield.SetActionBounds(Vec({-2.0f, 0.5f}), Vec({2.0f, 2.0f}));
      const Decision& d = shield.Decide(state, mu, Vec({0.1f, 0.1f}));
      EXPECT_EQ(d.safe(), steps == 2) << d.ToJson().dump();
      EXPECT_GE(d.action[0], -2.0f);
      EXPECT_LE(d.action[0], 2.0f);
      EXPECT_GE(d.action[1], 0.5f);
      EXPECT_LE(d.action[1], 2.0f);
      if (steps == 1) {
        EXPECT_NEAR(d.g, -1.24, 1e-3);
      } else {
        EXPECT_NEAR(d.action[0], 0.8, 1e-2);
        EXPECT_EQ(d.action[1], 0.5f);
        EXPECT_GE(d.g, 0.0);
      }
    }
  }
  {
    // A box the half-space misses (w . a <= -1.5 there): every step fails, and it says so.
    o.refine_steps = 5;
    Shield shield(o, barrier, dynamics);
    shield.SetActionBounds(Vec({-1.0f, 0.5f}), Vec({-0.5f, 1.0f}));
    const Decision& d = shield.Decide(state, mu, Vec({0.1f, 0.1f}));
    EXPECT_EQ(d.status, Status::kNoSafeAction) << d.ToJson().dump();
    EXPECT_EQ(d.fallback, Fallback::kRefinedMean);
    EXPECT_EQ(d.qp, QpOutcome::kRejected);
    EXPECT_TRUE(BitEqual(d.action, Vec({-0.5f, 0.5f})));  // the box corner of largest g
    EXPECT_NEAR(d.g, -1.5 + 0.2, 1e-4);
    EXPECT_EQ(d.ToJson()["fallback"], "refined_mean");
  }
}

TEST(QpShieldTest, OptionsAreCheckedReadAndWrittenOnlyWhereTheyAct) {
  ShieldOptions o;
  EXPECT_FALSE(o.ToJson().contains("proposal"));  // run directories keep their identity
  o.proposal = Proposal::kQp;
  EXPECT_EQ(o.ToJson()["proposal"], "qp");
  EXPECT_EQ(o.ToJson()["qp_iterations"], 1);
  o.lookahead_steps = 2;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "it needs lookahead_steps = 1, not 2");
  o.lookahead_steps = 1;
  o.qp_iterations = 0;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "qp_iterations = 0");
  o.qp_iterations = 1;
  // The step counts of the line search and the bisection: absent from the JSON unless set (runs
  // keep their identity), written when set, checked at both ends of their range.
  const auto check_count = [&](const std::string& name, int ShieldOptions::*field, int max) {
    EXPECT_FALSE(o.ToJson().contains(name));
    o.*field = 2;
    EXPECT_EQ(o.ToJson()[name], 2);
    for (int bad : {-1, max + 1}) {
      o.*field = bad;
      EXPECT_HAS(ErrorOf([&] { o.Validate(); }), name + " = " + std::to_string(bad));
    }
    o.*field = 0;
  };
  check_count("qp_line_search", &ShieldOptions::qp_line_search, kMaxQpLineSearch);
  check_count("qp_bisection", &ShieldOptions::qp_bisection, kMaxQpBisection);
  o.qp_margin = -1;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "qp_margin = -1");
  ShieldOptions y;
  y.ApplyYaml(YAML::Load("{proposal: qp-only, qp_iterations: 3, qp_margin: 0.25, "
                         "qp_line_search: 4, qp_bisection: 5}"),
              "s.yaml");
  EXPECT_EQ(y.qp_bisection, 5);
  EXPECT_EQ(y.proposal, Proposal::kQpOnly);
  EXPECT_EQ(y.qp_line_search, 4);
  EXPECT_EQ(y.qp_iterations, 3);
  EXPECT_EQ(y.qp_margin, 0.25);
  EXPECT_HAS(ErrorOf([&] { y.ApplyYaml(YAML::Load("{proposal: newton}"), "s.yaml"); }),
             "newton");
  o.qp_margin = 0;
  EXPECT_FALSE(o.ToJson().contains("qp_max_step"));  // absent unless set (runs keep identity)
  o.qp_max_step = 0.3;
  EXPECT_EQ(o.ToJson()["qp_max_step"], 0.3);
  o.qp_max_step = -1;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "qp_max_step = -1");
  o.qp_max_step = 0.3;
  o.proposal = Proposal::kQpOnly;  // accepted (a config may set it for every method), not written
  o.Validate();
  EXPECT_FALSE(o.ToJson().contains("qp_max_step"));
  y.ApplyYaml(YAML::Load("{proposal: qp, qp_max_step: 0.25}"), "s.yaml");
  EXPECT_EQ(y.qp_max_step, 0.25);
  o.qp_max_step = 0;
  o.proposal = Proposal::kRefine;
  EXPECT_EQ(o.ToJson()["refine_steps"], 5);
  EXPECT_FALSE(o.ToJson().contains("qp_iterations"));
  o.refine_steps = 0;
  EXPECT_HAS(ErrorOf([&] { o.Validate(); }), "refine_steps = 0");
  y.ApplyYaml(YAML::Load("{proposal: refine, refine_steps: 7}"), "s.yaml");
  EXPECT_EQ(y.proposal, Proposal::kRefine);
  EXPECT_EQ(y.refine_steps, 7);
  Decision d;
  EXPECT_FALSE(d.ToJson().contains("qp"));
}

// The shield, on h(s) = w . s + 0.5 (w = (1, -2)) with the integrator s' = s + 0.1 a and
// alpha(h) = 2 h: g(a) = w . a + 0.2, exactly affine. The CBF-QP filter in the policy's metric
// returns mu + lambda S w, S = diag(sigma^2), lambda = (-0.2 - w . mu) / (w^T S w); the
// Euclidean one mu + (-0.2 - w . mu) / |w|^2 w.
}  // namespace
}  // namespace secure::shield
