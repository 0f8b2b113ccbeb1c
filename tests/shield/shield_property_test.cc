// Property-based tests of the shield (RapidCheck): random policies, options and seeds over every
// barrier type and dynamics model (the double integrator with its ground truth or a random barrier
// network, Derby's shield model with a random per-car barrier). Case counts: RapidCheck's default
// (100) in shield_test; 10^4 in the ctest entry shield_properties_10k and 10^6 under the `long`
// label (tests/CMakeLists.txt; RC_PARAMS sets them).

#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/shield/shield.h"
#include "tests/shield/shield_test_util.h"

#include <gtest/gtest.h>
#include <rapidcheck.h>
#include <rapidcheck/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>

#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "domains/derby/derby.h"
#include "domains/derby/domain.h"
#include "secure/common/enum_strings.h"
#include "secure/common/rng.h"
#include "domains/double_integrator/double_integrator.h"
#include "secure/nn/mlp.h"

namespace secure::shield {
namespace {

using test::BitEqual;
using test::FirstRound;
using test::IndependentG;

namespace di = domains::double_integrator;
namespace derby = domains::derby;

/// Uniform in [lo, hi] on a grid of 100001 points, whatever RapidCheck's size parameter.
rc::Gen<double> UniformIn(double lo, double hi) {
  return rc::gen::map(rc::gen::resize(100, rc::gen::inRange<int>(0, 100001)),
                      [lo, hi](int i) { return lo + (hi - lo) * (i / 100000.0); });
}

Eigen::VectorXf RandomVector(int n, double lo, double hi) {
  Eigen::VectorXf v(n);
  for (int i = 0; i < n; ++i) v[i] = static_cast<float>(*UniformIn(lo, hi));
  return v;
}

/// The system of a case: a barrier (with a second, independent evaluator for re-checking) and
/// the dynamics model the shield looks ahead with. Every barrier type and dynamics model the
/// library has: the double integrator with its ground truth or a random barrier network, and
/// Demolition Derby's constant-velocity shield model with a random per-car barrier.
enum class SystemKind { kDoubleIntegratorTruth, kDoubleIntegratorNet, kDerbyCarNet };

constexpr EnumTable<SystemKind, 3> kSystemKindNames{{
    {SystemKind::kDoubleIntegratorTruth, "double integrator, ground truth"},
    {SystemKind::kDoubleIntegratorNet, "double integrator, barrier net"},
    {SystemKind::kDerbyCarNet, "derby, per-car barrier"},
}};
const char* Name(SystemKind kind) { return NameOf(kSystemKindNames, kind); }

struct System {
  std::unique_ptr<cbf::BarrierNet> net;
  std::unique_ptr<cbf::CarBarrierNet> car_net;
  std::unique_ptr<cbf::Barrier> shield_barrier;
  std::unique_ptr<cbf::Barrier> independent;
  std::unique_ptr<domains::DynamicsModel> dynamics;
  bool learned = false;
};

System MakeSystem(SystemKind kind, unsigned long long net_seed) {
  System b;
  switch (kind) {
    case SystemKind::kDoubleIntegratorNet:
      b.net = std::make_unique<cbf::BarrierNet>();
      b.net->mlp = nn::RandomMlpParams(nn::MlpSpec{4, {8}, 1, nn::Activation::kTanh}, net_seed);
      b.net->normalizer = nn::Normalizer::Identity(4);
      b.net->features = di::StateFeatures();
      b.shield_barrier = b.net->MakeEvaluator(256);
      b.independent = b.net->MakeEvaluator(256);
      b.dynamics = std::make_unique<di::Dynamics>(0.1);
      b.learned = true;
      break;
    case SystemKind::kDoubleIntegratorTruth:
      b.shield_barrier = std::make_unique<domains::double_integrator::GroundTruthBarrier>(di::GroundTruth{});
      b.independent = std::make_unique<domains::double_integrator::GroundTruthBarrier>(di::GroundTruth{});
      b.dynamics = std::make_unique<di::Dynamics>(0.1);
      break;
    case SystemKind::kDerbyCarNet: {
      b.car_net = std::make_unique<cbf::CarBarrierNet>();
      b.car_net->input.layout = derby::ObstacleLayoutOfObservation();
      b.car_net->input.use_velocity = (net_seed & 1) != 0;
      const int f = b.car_net->input.feature_dim();
      b.car_net->mlp = nn::RandomMlpParams({f, {16, 8}, 1, nn::Activation::kRelu}, net_seed);
      b.car_net->normalizer = nn::Normalizer::Identity(f);
      b.shield_barrier = b.car_net->MakeEvaluator(256);
      b.independent = b.car_net->MakeEvaluator(256);
      const derby::DerbyOptions task;
      b.dynamics = std::make_unique<derby::DerbyShieldModel>(task.dt, task.accel_bound,
                                                             task.lookahead_steps);
      b.learned = true;
      break;
    }
  }
  return b;
}

/// A Derby observation: a random episode start, then up to 30 steps of random accelerations.
Eigen::VectorXf RandomDerbyState(std::uint64_t seed) {
  derby::DerbyEnv env;
  Rng rng(seed);
  Eigen::VectorXf obs(env.observation_dim());
  env.Reset(rng, obs);
  const int steps = static_cast<int>(rng.UniformIndex(31));
  Eigen::VectorXf action(env.action_dim());
  for (int t = 0; t < steps; ++t) {
    for (Eigen::Index i = 0; i < action.size(); ++i)
      action[i] = static_cast<float>(rng.Uniform(-3.0, 3.0));
    const domains::StepOutcome outcome = env.Step(action, obs);
    if (outcome.reached_goal) break;
  }
  return obs;
}

ShieldOptions RandomOptions() {
  ShieldOptions o;
  o.num_samples = *rc::gen::resize(100, rc::gen::inRange(8, 129));
  o.safe_ratio = *UniformIn(0.0, 0.5);
  o.class_k = *rc::gen::element(ClassK::kLinear, ClassK::kCubic);
  o.class_k_gain = *UniformIn(0.10005, 5.0);
  o.aggregation = *rc::gen::element(Aggregation::kMean, Aggregation::kRandomSafe,
                                    Aggregation::kPolicyDraw, Aggregation::kPolicyMean);
  o.resampling = *rc::gen::element(Resampling::kAdaptive, Resampling::kNone);
  o.max_iterations = *rc::gen::resize(100, rc::gen::inRange(1, 11));
  o.seed = *rc::gen::arbitrary<std::uint64_t>();
  return o;
}

bool CloseRelative(double a, double b, double tolerance) {
  return std::abs(a - b) <= tolerance * std::max(1.0, std::max(std::abs(a), std::abs(b)));
}

/// |a - b| within `ulps` float ulps of the larger magnitude (for float results that the shield
/// and the test compute by different expressions: -march=native may vectorise, contract into FMAs
/// or reduce in another order on another CPU, so such values agree only to a few ulps).
bool CloseFloatUlps(double a, double b, int ulps) {
  return std::abs(a - b) <=
         ulps * std::numeric_limits<float>::epsilon() * std::max(std::abs(a), std::abs(b));
}


bool SameDecision(const Decision& a, const Decision& b) {
  return a.status == b.status && BitEqual(a.action, b.action) &&
         std::memcmp(&a.g, &b.g, sizeof(double)) == 0 && a.h == b.h &&
         a.iterations == b.iterations && a.safe_ratio == b.safe_ratio &&
         a.intervened == b.intervened && a.distance_to_mean == b.distance_to_mean &&
         a.fallback == b.fallback;
}


/// A random decision problem of a random system: a state in or near the double integrator's box,
/// or a Derby observation.
struct Problem {
  SystemKind kind = SystemKind::kDoubleIntegratorTruth;
  Eigen::VectorXf state, mu, sigma;
  ShieldOptions options;
  unsigned long long net_seed = 0;
  bool with_backup = false;
  Eigen::VectorXf backup;
};

Problem RandomProblem() {
  Problem p;
  p.kind = *rc::gen::element(SystemKind::kDoubleIntegratorTruth, SystemKind::kDoubleIntegratorNet,
                             SystemKind::kDerbyCarNet);
  if (p.kind == SystemKind::kDerbyCarNet) {
    p.state = RandomDerbyState(*rc::gen::arbitrary<std::uint64_t>());
  } else {
    p.state.resize(4);
    p.state.head(2) = RandomVector(2, -1.0, 11.0);
    p.state.tail(2) = RandomVector(2, -2.0, 2.0);
  }
  p.mu = RandomVector(2, -5.0, 5.0);
  p.sigma = RandomVector(2, 0.01, 2.0);
  p.options = RandomOptions();
  p.net_seed = *rc::gen::arbitrary<unsigned long long>();
  p.with_backup = *rc::gen::arbitrary<bool>();
  p.backup = RandomVector(2, -5.0, 5.0);
  return p;
}

// 1. Whenever the shield says safe, an independent evaluation of g(action) is >= 0 and equals the
//    reported g.
//
// The ground truth is evaluated column by column, so the re-evaluation is exact. A barrier network
// is evaluated by a batched float GEMM whose summation order depends on the batch size: a sample
// that the shield evaluated in a batch of M gives h(T(s, a)) a few float ulps away when evaluated
// alone, so g agrees only to ~1e-6 (observed: 1.8e-6 for g = 0.76) and "g >= 0" is reproducible
// only up to that margin.
double GTolerance(bool learned, double g, double h_state, const ShieldOptions& options) {
  if (!learned) return 1e-6 * std::max(1.0, std::abs(g));
  const double h_next = std::abs((g - ClassKValue(options, h_state)) * options.dt + h_state);
  return 1e-6 * std::max(1.0, std::abs(g)) + 64 * std::numeric_limits<float>::epsilon() *
                                                 (1.0 + h_next + std::abs(h_state)) / options.dt;
}

RC_GTEST_PROP(ShieldProperty, SafeDecisionsSatisfyTheCbfConditionIndependently, ()) {
  const Problem p = RandomProblem();
  System system = MakeSystem(p.kind, p.net_seed);
  const domains::DynamicsModel& dynamics = *system.dynamics;
  Shield shield(p.options, *system.shield_barrier, dynamics);
  if (p.with_backup) shield.SetBackupAction(p.backup);
  const Decision& d = shield.Decide(p.state, p.mu, p.sigma);
  RC_TAG(ToString(kStatusNames, d.status), Name(p.kind));
  if (!d.safe()) return;

  const double tolerance = GTolerance(system.learned, d.g, d.h, p.options);
  Shield checker(p.options, *system.independent, dynamics);
  Eigen::MatrixXf column = d.action;
  Eigen::VectorXd g(1);
  checker.EvaluateG(p.state, checker.EvaluateH(p.state), column, g);
  RC_LOG() << "g: shield " << d.g << ", re-evaluated " << g[0] << ", tolerance " << tolerance
           << "; " << d.ToJson().dump() << "\n";
  RC_ASSERT(std::abs(g[0] - d.g) <= tolerance);
  if (system.learned) {
    RC_ASSERT(g[0] >= -tolerance);
  } else {
    RC_ASSERT(g[0] >= 0.0);
  }
  const double formula =
      IndependentG(*system.independent, dynamics, p.options, p.state, d.action);
  RC_ASSERT(std::abs(formula - d.g) <= tolerance);
  RC_ASSERT(formula >= (system.learned ? -tolerance : 0.0));
}

// 2. The action is always finite and the status agrees with g.
RC_GTEST_PROP(ShieldProperty, ActionIsFiniteAndStatusAgreesWithG, ()) {
  const Problem p = RandomProblem();
  System system = MakeSystem(p.kind, p.net_seed);
  Shield shield(p.options, *system.shield_barrier, *system.dynamics);
  if (p.with_backup) shield.SetBackupAction(p.backup);
  const Decision& d = shield.Decide(p.state, p.mu, p.sigma);
  RC_TAG(ToString(kStatusNames, d.status), ToString(kFallbackNames, d.fallback), Name(p.kind));

  RC_ASSERT(d.action.size() == 2);
  RC_ASSERT(d.action.allFinite());
  RC_ASSERT(d.status != Status::kInvalidInput);  // all inputs are finite, sigma > 0
  RC_ASSERT(std::isfinite(d.h));
  if (d.status == Status::kNoSafeAction) RC_ASSERT(d.g < 0.0);
  if (d.safe()) RC_ASSERT(d.g >= 0.0);
  if (d.fallback == Fallback::kNone) RC_ASSERT(d.safe());
  if (d.fallback == Fallback::kBackupAction) {
    RC_ASSERT(p.with_backup);
    RC_ASSERT(BitEqual(d.action, p.backup));
  }
  RC_ASSERT(d.iterations >= 1);
  RC_ASSERT(d.iterations <= p.options.max_iterations);
  RC_ASSERT(d.safe_ratio >= 0.0 && d.safe_ratio <= 1.0);
  RC_ASSERT(CloseRelative(d.distance_to_mean, (d.action - p.mu).norm(), 1e-5));
}

// 2a. With an actuator box, every decision (any status, aggregation, resampling, sampler start,
//     fallback) lies in it, its g is that of the action returned, and a safe one satisfies the
//     condition independently. The box is random: it may exclude mu, the safe set or the backup's
//     spot (the backup is then moved into it), and a side may be unbounded.
RC_GTEST_PROP(ShieldProperty, DecisionsStayInTheActionBox, ()) {
  Problem p = RandomProblem();
  p.options.action_bounds = *rc::gen::element(ActionBounds::kClip, ActionBounds::kReject);
  Eigen::VectorXf low(2), high(2);
  for (int r = 0; r < 2; ++r) {
    const double a = *UniformIn(-4.0, 4.0), b = *UniformIn(-4.0, 4.0);
    low[r] = static_cast<float>(std::min(a, b));
    high[r] = static_cast<float>(std::max(a, b));
    if (*rc::gen::inRange(0, 8) == 0) low[r] = -std::numeric_limits<float>::infinity();
    if (*rc::gen::inRange(0, 8) == 0) high[r] = std::numeric_limits<float>::infinity();
  }
  p.backup = p.backup.cwiseMax(low).cwiseMin(high);
  System system = MakeSystem(p.kind, p.net_seed);
  Shield shield(p.options, *system.shield_barrier, *system.dynamics);
  shield.SetActionBounds(low, high);
  if (p.with_backup) shield.SetBackupAction(p.backup);
  const Decision& d = shield.Decide(p.state, p.mu, p.sigma);
  RC_TAG(ToString(kActionBoundsNames, p.options.action_bounds),
         ToString(kStatusNames, d.status), d.bounded ? "bounded" : "not bounded");
  RC_LOG() << "box [" << low.transpose() << "] .. [" << high.transpose() << "]; "
           << d.ToJson().dump() << "\n";
  RC_ASSERT(d.action.allFinite());
  RC_ASSERT(((d.action.array() >= low.array()) && (d.action.array() <= high.array())).all());
  if (d.safe()) RC_ASSERT(d.g >= 0.0);
  if (d.status == Status::kNoSafeAction) RC_ASSERT(d.g < 0.0);
  // The reported g is the returned action's (the same evaluation path: exact for the ground
  // truth; a learned barrier's batch GEMM rounds by batch size, hence GTolerance).
  Shield checker(p.options, *system.independent, *system.dynamics);
  Eigen::MatrixXf column = d.action;
  Eigen::VectorXd g(1);
  checker.EvaluateG(p.state, checker.EvaluateH(p.state), column, g);
  if (std::isfinite(d.g))
    RC_ASSERT(std::abs(g[0] - d.g) <= GTolerance(system.learned, d.g, d.h, p.options));
}

// 2b. Non-finite inputs never produce a non-finite action.
RC_GTEST_PROP(ShieldProperty, NonFiniteInputsGiveInvalidInputAndAFiniteAction, ()) {
  Problem p = RandomProblem();
  const float bad = *rc::gen::element(std::numeric_limits<float>::quiet_NaN(),
                                      std::numeric_limits<float>::infinity(),
                                      -std::numeric_limits<float>::infinity(), -0.5f);
  const int n = static_cast<int>(p.state.size());
  const int where = *rc::gen::inRange(0, n + 4);  // n state, 2 mu, 2 sigma entries
  const bool negative_only = std::isfinite(bad);  // a negative value is bad only in sigma
  if (negative_only) {
    p.sigma[where % 2] = bad;
  } else if (where < n) {
    p.state[where] = bad;
  } else if (where < n + 2) {
    p.mu[where - n] = bad;
  } else {
    p.sigma[where - n - 2] = bad;
  }
  System system = MakeSystem(p.kind, p.net_seed);
  Shield shield(p.options, *system.shield_barrier, *system.dynamics);
  if (p.with_backup) shield.SetBackupAction(p.backup);
  const Decision& d = shield.Decide(p.state, p.mu, p.sigma);
  RC_ASSERT(d.status == Status::kInvalidInput);
  RC_ASSERT(d.action.allFinite());
  const bool expected_action = p.with_backup ? BitEqual(d.action, p.backup) : d.action.isZero(0.0f);
  RC_ASSERT(expected_action);
  RC_ASSERT(!d.safe());
}

/// A problem far from the obstacle with a policy moving away from it: every round-1 sample is
/// (almost surely) safe, so no resampling is needed.
Problem FarProblem() {
  Problem p;
  p.state.resize(4);
  p.state.head(2) = RandomVector(2, 0.0, 1.5);
  p.state.tail(2) = RandomVector(2, -0.5, 0.0);
  p.mu = RandomVector(2, -1.0, -0.3);
  p.sigma = RandomVector(2, 0.01, 0.3);
  p.options = RandomOptions();
  return p;
}

// 3a. Aggregation ablation: with the same seed and inputs and no resampling needed, kMean returns
//     the mean of the safe samples (or the nearest safe sample when the mean is unsafe),
//     kRandomSafe one of the samples; the first round is the same for both.
RC_GTEST_PROP(ShieldProperty, AggregationAblationChangesOnlyTheAggregation, ()) {
  Problem p = FarProblem();
  const di::Dynamics dynamics(0.1);
  domains::double_integrator::GroundTruthBarrier barrier{di::GroundTruth{}}, independent{di::GroundTruth{}};
  p.options.aggregation = Aggregation::kMean;
  Shield mean_shield(p.options, barrier, dynamics);
  const Decision mean = mean_shield.Decide(p.state, p.mu, p.sigma);
  p.options.aggregation = Aggregation::kRandomSafe;
  Shield random_shield(p.options, barrier, dynamics);
  const Decision random = random_shield.Decide(p.state, p.mu, p.sigma);

  RC_ASSERT(mean.iterations == 1);
  RC_ASSERT(random.iterations == 1);
  RC_ASSERT(mean.status == Status::kSafe);
  RC_ASSERT(random.status == Status::kSafe);
  RC_ASSERT(mean.safe_ratio > p.options.safe_ratio);
  RC_ASSERT(mean.safe_ratio == random.safe_ratio);
  RC_ASSERT(mean.intervened == random.intervened);
  RC_ASSERT(mean.h == random.h);

  // The round, outside the shield.
  const int m = p.options.num_samples;
  const Eigen::MatrixXf samples = FirstRound(p.options.seed, p.mu, p.sigma, m);
  Shield checker(p.options, independent, dynamics);
  const double h = checker.EvaluateH(p.state);
  Eigen::VectorXd g(m);
  checker.EvaluateG(p.state, h, samples, g);
  Eigen::VectorXf sum = Eigen::VectorXf::Zero(2);
  int num_safe = 0;
  for (int i = 0; i < m; ++i) {
    if (g[i] >= 0.0) {
      sum += samples.col(i);
      ++num_safe;
    }
  }
  RC_ASSERT(mean.safe_ratio == static_cast<double>(num_safe) / m);

  // kRandomSafe: exactly one of the safe samples, at that sample's distance from mu.
  int column = -1;
  for (int i = 0; i < m && column < 0; ++i)
    if (BitEqual(samples.col(i), random.action)) column = i;
  RC_ASSERT(column >= 0);
  RC_ASSERT(g[column] >= 0.0);
  RC_ASSERT(random.g == g[column]);  // the same EvaluateG on the same batch: bit for bit
  // The shield's norm of (action - mu) and Eigen's norm of (column - mu) here are different
  // expressions of the same 2-norm (the sum of squares may be fused or vectorised differently
  // under -march=native): equal to a few float ulps, not bit for bit.
  RC_ASSERT(CloseFloatUlps(random.distance_to_mean, (samples.col(column) - p.mu).norm(), 4));

  // kMean: the mean of the safe samples if it is safe, else the safe sample nearest to it.
  Eigen::MatrixXf mean_column = sum / static_cast<float>(num_safe);
  Eigen::VectorXd g_mean(1);
  checker.EvaluateG(p.state, h, mean_column, g_mean);
  RC_TAG(g_mean[0] >= 0.0 ? "mean safe" : "mean unsafe");
  if (g_mean[0] >= 0.0) {
    RC_ASSERT((mean.action - mean_column.col(0)).cwiseAbs().maxCoeff() <= 1e-5f);
  } else {
    // The action is one of the safe samples, and (up to rounding) the nearest to the mean: the
    // shield's squared distances and these are different expressions (FMA contraction and
    // vectorisation differ with -march=native), so two samples at almost the same distance may
    // rank either way; the picked one must be within a few ulps of the nearest distance.
    const auto distance = [&](int i) {
      return (samples.col(i) - mean_column.col(0)).squaredNorm();
    };
    int nearest = -1;
    for (int i = 0; i < m; ++i)
      if (g[i] >= 0.0 && (nearest < 0 || distance(i) < distance(nearest))) nearest = i;
    int picked = -1;
    for (int i = 0; i < m && picked < 0; ++i)
      if (BitEqual(samples.col(i), mean.action)) picked = i;
    RC_ASSERT(picked >= 0);
    RC_ASSERT(g[picked] >= 0.0);
    const float slack = 1.0f + 8 * std::numeric_limits<float>::epsilon();
    RC_ASSERT(picked == nearest || distance(picked) <= distance(nearest) * slack);
    RC_ASSERT(mean.g == g[picked]);  // the round's g, from the same EvaluateG batch
  }
  RC_ASSERT(mean.g >= 0.0);
}

// 3b. Resampling ablation: when the first round has enough safe samples, kNone and kAdaptive give
//     identical decisions (far case, and any random case where that happens).
RC_GTEST_PROP(ShieldProperty, ResamplingAblationIsIdenticalWithoutResampling, ()) {
  const bool far = *rc::gen::arbitrary<bool>();
  Problem p = far ? FarProblem() : RandomProblem();
  System system = MakeSystem(p.kind, p.net_seed);
  p.options.resampling = Resampling::kAdaptive;
  Shield adaptive_shield(p.options, *system.shield_barrier, *system.dynamics);
  const Decision adaptive = adaptive_shield.Decide(p.state, p.mu, p.sigma);
  p.options.resampling = Resampling::kNone;
  Shield none_shield(p.options, *system.shield_barrier, *system.dynamics);
  const Decision none = none_shield.Decide(p.state, p.mu, p.sigma);

  const bool enough = adaptive.iterations == 1 && adaptive.safe_ratio > p.options.safe_ratio;
  if (far) RC_ASSERT(enough);
  RC_TAG(enough ? "no resampling needed" : "resampling needed", Name(p.kind));
  if (enough) {
    RC_ASSERT(SameDecision(adaptive, none));
  } else {
    // The first rounds agree; only what follows differs.
    RC_ASSERT(adaptive.intervened == none.intervened);
    RC_ASSERT(none.iterations == p.options.max_iterations ||
              none.safe_ratio > p.options.safe_ratio);
  }
}

}  // namespace
}  // namespace secure::shield
