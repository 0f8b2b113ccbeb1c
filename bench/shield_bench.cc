// One shielded decision (shield::Shield::Decide, Algorithm 1 with Algorithm 2's resampling), single
// thread, for the barrier sizes of the shield issue:
//
//   DI     BarrierNet 4-64-64-1 tanh (the double-integrator size), normaliser fit to the
//          paper's state box, exact double-integrator dynamics (dt = 0.1), action dim 2;
//   Derby  a per-obstacle barrier: one shared MLP 4-64-128-64-1 relu applied to 12 obstacles,
//          h = min over obstacles, all M x 12 inputs in ONE batched Forward (PerObstacleBarrier
//          below); 52-D state, 2-D action (DerbyDynamics below);
//   Panda  BarrierNet 9-32-128-128-256-256-256-256-128-128-32-1 tanh (paper Table 2), 9-D state,
//          3-D action (PandaDynamics below);
//   DITruth  the double integrator's analytic ground truth (no network): the cost of the shield
//          itself (sampling, dynamics, g, aggregation).
//
// Each with the three samplers of ShieldOptions::sampler (argument sampler: 0 iid, 1 antithetic,
// 2 qmc); BM_SamplingOnly times each sampler with a barrier and dynamics that cost ~nothing.
//
// M = 64 and 128, each in two regimes:
//   NoResampling  the first round has safe ratio > rho0 (iterations = 1): 1 + M + 1 barrier states
//                 per decision (h(s), the M next states, the re-check of the mean);
//   Resampling    the policy's sigma is narrow (0.05) and no sample of the first round is safe, so
//                 Algorithm 2 widens sigma (N = 64 probes per extra round) until the ratio
//                 exceeds rho0. DITruth uses the physical case s = (5, 7.4, 0, -1.5) heading into
//                 the obstacle with mu = (0, -3); for the nets (random weights, so no physics to
//                 exploit) the barrier seen by the shield is h(s) + c with c calibrated at set-up
//                 so that the narrow first round is unsafe and a widened one is ~20 % safe.
// The weights are random (nn::RandomMlpParams): the cost does not depend on them. The offset c is
// one add per evaluated state and changes nothing else; the NoResampling net cases use it too
// (to place the policy's samples on the safe side), and every case goes through the same
// counting wrapper (OffsetBarrier), offset 0 for the ground truth.
//
// Counters (all per decision; latencies are wall time of Decide() on the steady clock, every
// decision of the run recorded):
//   p50_us, p99_us     median and 99th percentile (nearest rank) of the decision latency;
//   p99_over_p50       tail ratio (the target: <= 1.5);
//   iterations         mean sampling rounds per decision (1 = no resampling);
//   status_safe_fraction  fraction of decisions returning kSafe or kSafeAfterResampling;
//   h_states           mean number of states the barrier evaluated per decision.
// Google Benchmark's own Time column is the mean over the run.
//
// Everything (nets, workspaces, shield buffers, the latency log) is built before the timed loop;
// 32 decisions are made as a warm-up, which also checks that the case is in its regime.
//
// bench/shield_torch_bench.cc includes this file with SECURE_SHIELD_BENCH_CASES_ONLY defined to
// reuse the cases (same nets, weights, states and dynamics) without registering these benchmarks.

#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <initializer_list>
#include <memory>
#include <string>
#include <vector>

#include "bench/bench_nets.h"
#include "domains/double_integrator/double_integrator.h"
#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/common/enum_strings.h"
#include "secure/common/rng.h"
#include "secure/domains/dynamics.h"
#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"
#include "secure/policy/airl_reward.h"
#include "secure/shield/shield.h"

namespace secure::bench {
namespace {

// ---------------------------------------------------------------------------------------------
// Nets and models.

/// The shield issue's double-integrator barrier: 4 -> 64 -> 64 -> 1, tanh (smaller than the
/// Table-1 net of bench_nets.h, which has three hidden layers).
nn::MlpSpec ShieldDoubleIntegratorSpec() { return {4, {64, 64}, 1, nn::Activation::kTanh}; }

inline constexpr int kDerbyObstacleDim = 4;                            // px, py, vx, vy
inline constexpr int kDerbyEgo = kDerbyObstacles * kDerbyObstacleDim;  // first ego row (48)
inline constexpr int kDerbyStateDim = kDerbyEgo + 4;                   // 52
inline constexpr float kDerbyRadius = 0.07f;                           // feature offset
inline constexpr int kPandaStateDim = 9;  // ee pos (3), ee vel (3), block pos (3)

/// A Barrier decorator used by every case: h(s) + offset, and a count of evaluated states.
class OffsetBarrier final : public cbf::Barrier {
 public:
  OffsetBarrier(cbf::Barrier& inner, float offset) : inner_(inner), offset_(offset) {}
  int state_dim() const override { return inner_.state_dim(); }
  std::string Describe() const override {
    return inner_.Describe() + " + " + std::to_string(offset_);
  }
  float offset() const { return offset_; }
  void set_offset(float offset) { offset_ = offset; }
  long states_evaluated() const { return states_evaluated_; }
  void ResetCount() { states_evaluated_ = 0; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    inner_.Evaluate(states, h);
    if (offset_ != 0.0f) h.array() += offset_;
    states_evaluated_ += states.cols();
  }

 private:
  cbf::Barrier& inner_;
  float offset_;
  long states_evaluated_ = 0;
};

/// Demolition-Derby-sized per-obstacle barrier. State (52): 12 obstacles x (px, py, vx, vy), then
/// the ego car (px, py, vx, vy). Per obstacle j the shared MLP sees
///   [ego_p - p_j (2), 0, ||ego_p - p_j|| - 0.07]
/// and h(s) = min_j MLP(features_j). All K x 12 feature columns of a batch of K states go through
/// ONE Forward; the feature buffer, the outputs and the MLP workspace are preallocated for
/// `max_states` states (larger batches are evaluated in chunks).
class PerObstacleBarrier final : public cbf::Barrier {
 public:
  PerObstacleBarrier(const nn::MlpParams& params, const nn::Normalizer& normalizer, int max_states)
      : mlp_(params, normalizer),
        max_states_(max_states),
        workspace_(mlp_.MakeWorkspace(kDerbyObstacles * max_states)),
        features_(Eigen::MatrixXf::Zero(kDerbyObstacleDim, kDerbyObstacles * max_states)),
        outputs_(1, kDerbyObstacles * max_states),
        description_("per-obstacle " + bench::Describe(params.spec) + " x " +
                     std::to_string(kDerbyObstacles) + ", min") {}
  int state_dim() const override { return kDerbyStateDim; }
  std::string Describe() const override { return description_; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    const Eigen::Index n = states.cols();
    for (Eigen::Index first = 0; first < n; first += max_states_) {
      const Eigen::Index k = std::min<Eigen::Index>(max_states_, n - first);
      for (Eigen::Index i = 0; i < k; ++i) {
        const auto s = states.col(first + i);
        const float ex = s[kDerbyEgo], ey = s[kDerbyEgo + 1];
        for (int j = 0; j < kDerbyObstacles; ++j) {
          const float dx = ex - s[kDerbyObstacleDim * j];
          const float dy = ey - s[kDerbyObstacleDim * j + 1];
          const Eigen::Index c = i * kDerbyObstacles + j;
          features_(0, c) = dx;
          features_(1, c) = dy;
          // row 2 stays 0 (set in the constructor)
          features_(3, c) = std::sqrt(dx * dx + dy * dy) - kDerbyRadius;
        }
      }
      const Eigen::Index cols = k * kDerbyObstacles;
      mlp_.Forward(features_.leftCols(cols), workspace_, outputs_.leftCols(cols));
      for (Eigen::Index i = 0; i < k; ++i)
        h[first + i] = outputs_.middleCols(i * kDerbyObstacles, kDerbyObstacles).minCoeff();
    }
  }

 private:
  nn::InferenceMlp mlp_;
  int max_states_;
  nn::InferenceMlp::Workspace workspace_;
  Eigen::MatrixXf features_;  // (4 x 12 max_states)
  Eigen::MatrixXf outputs_;   // (1 x 12 max_states)
  std::string description_;
};

/// Derby dynamics, dt = 0.1: the ego car is a double integrator stepped with semi-implicit Euler
/// (v' = v + a dt, p' = p + v' dt; plain explicit Euler would make p', and so h(T(s, a)), not
/// depend on a at all); the obstacles are extrapolated at constant velocity. Action: ego (ax, ay).
class DerbyDynamics final : public domains::DynamicsModel {
 public:
  explicit DerbyDynamics(float dt = 0.1f) : dt_(dt) {}
  int state_dim() const override { return kDerbyStateDim; }
  int action_dim() const override { return 2; }
  std::string Describe() const override { return "derby (12 obstacles, semi-implicit Euler)"; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next) const override {
    const Eigen::Index k = actions.cols();
    if (k == 0) return;
    for (int j = 0; j < kDerbyObstacles; ++j) {  // the same for every action: column 0, copied
      const int r = kDerbyObstacleDim * j;
      next(r, 0) = state[r] + state[r + 2] * dt_;
      next(r + 1, 0) = state[r + 1] + state[r + 3] * dt_;
      next(r + 2, 0) = state[r + 2];
      next(r + 3, 0) = state[r + 3];
    }
    for (Eigen::Index i = 1; i < k; ++i) next.col(i).head(kDerbyEgo) = next.col(0).head(kDerbyEgo);
    for (Eigen::Index i = 0; i < k; ++i) {
      const float vx = state[kDerbyEgo + 2] + actions(0, i) * dt_;
      const float vy = state[kDerbyEgo + 3] + actions(1, i) * dt_;
      next(kDerbyEgo, i) = state[kDerbyEgo] + vx * dt_;
      next(kDerbyEgo + 1, i) = state[kDerbyEgo + 1] + vy * dt_;
      next(kDerbyEgo + 2, i) = vx;
      next(kDerbyEgo + 3, i) = vy;
    }
  }

 private:
  float dt_;
};

/// Panda push model (action dim 3): ee_pos += 0.033 a, ee_vel = a / 5, and the block moves with
/// the end effector (block_pos += 0.033 a) while |ee_x - block_x| < 0.15.
class PandaDynamics final : public domains::DynamicsModel {
 public:
  int state_dim() const override { return kPandaStateDim; }
  int action_dim() const override { return 3; }
  std::string Describe() const override { return "panda push (ee + block)"; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next) const override {
    const float push = std::abs(state[0] - state[6]) < 0.15f ? 0.033f : 0.0f;
    for (Eigen::Index i = 0; i < actions.cols(); ++i) {
      for (int d = 0; d < 3; ++d) {
        const float a = actions(d, i);
        next(d, i) = state[d] + 0.033f * a;
        next(3 + d, i) = a * 0.2f;
        next(6 + d, i) = state[6 + d] + push * a;
      }
    }
  }
};

// ---------------------------------------------------------------------------------------------
// Cases.

// kPandaEnsemble3: the Panda net's case with an ensemble of 3 such nets (h = min over them,
// cbf::MinBarrier): the cost of BarrierTrainerOptions::ensemble = 3 per decision.
enum class Net { kDoubleIntegrator, kDerby, kPanda, kDoubleIntegratorTruth, kPandaEnsemble3 };
enum class Regime { kNoResampling, kResampling };

constexpr EnumTable<Net, 5> kNetNames{{
    {Net::kDoubleIntegrator, "DI"},
    {Net::kDerby, "Derby"},
    {Net::kPanda, "Panda"},
    {Net::kDoubleIntegratorTruth, "DITruth"},
    {Net::kPandaEnsemble3, "Panda ensemble"},
}};
const char* NetName(Net net) { return NameOf(kNetNames, net); }

/// Everything one decision needs, built outside the timed loop. Members are heap-held so that the
/// shield's references stay valid when a Case is moved.
struct Case {
  Net net = Net::kDoubleIntegrator;
  Regime regime = Regime::kNoResampling;
  shield::ShieldOptions options;
  nn::MlpParams params;       // the barrier MLP (empty for the ground truth)
  nn::Normalizer normalizer;  // its input normaliser
  std::unique_ptr<domains::DynamicsModel> dynamics;
  std::unique_ptr<cbf::Barrier> raw;       // the barrier without offset
  std::unique_ptr<OffsetBarrier> barrier;  // what the shield sees: raw + offset
  Eigen::VectorXf state, mu, sigma;
  std::string label;
};

/// A VectorXf from a list (fixed-size temporaries trip GCC 12's -Warray-bounds in Eigen's AVX
/// copy).
Eigen::VectorXf Vec(std::initializer_list<float> values) {
  Eigen::VectorXf v(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (float x : values) v[i++] = x;
  return v;
}

/// g without offset, g0(a) = (h(T(s, a)) - h(s)) / dt + alpha(h(s)), for `n` actions drawn from
/// N(mu, sigma); returns its q-quantile. With a linear class-K function (gain k) an offset c
/// added to h adds k c to every g.
double G0Quantile(cbf::Barrier& raw, const domains::DynamicsModel& dynamics,
                  const shield::ShieldOptions& options, const Eigen::VectorXf& state,
                  const Eigen::VectorXf& mu, const Eigen::VectorXf& sigma, double q,
                  std::uint64_t seed) {
  const int n = 2048;
  Rng rng(seed);
  Eigen::MatrixXf actions(mu.size(), n);
  for (int c = 0; c < n; ++c)
    for (Eigen::Index r = 0; r < mu.size(); ++r)
      actions(r, c) = mu[r] + sigma[r] * static_cast<float>(rng.Normal());
  Eigen::MatrixXf next(state.size(), n);
  dynamics.Step(state, actions, next);
  Eigen::VectorXf h_next(n), h_state(1);
  raw.Evaluate(next, h_next);
  raw.Evaluate(state, h_state);
  const double h0 = h_state[0];
  std::vector<double> g(n);
  for (int i = 0; i < n; ++i)
    g[i] = (h_next[i] - h0) / options.dt + shield::ClassKValue(options, h0);
  std::sort(g.begin(), g.end());
  const auto index = static_cast<std::size_t>(std::min<double>(n - 1, std::floor(q * (n - 1))));
  return g[index];
}

/// Builds a case. `m` is M (ShieldOptions::num_samples); the other options are the defaults
/// (rho0 = 0.1, linear alpha with k = 1, dt = 0.1, N = 64 probes, R = 1, alpha_sigma = 0.5,
/// K = 20 rounds, seed 0).
Case MakeCase(Net net, Regime regime, int m) {
  Case c;
  c.net = net;
  c.regime = regime;
  c.options.num_samples = m;
  const int batch = std::max(m, c.options.num_probes);  // the shield's largest barrier batch
  // Draws the states and the DI normaliser's data.
  Rng rng(7);
  switch (net) {
    case Net::kDoubleIntegrator:
    case Net::kDoubleIntegratorTruth: {
      c.dynamics = std::make_unique<domains::double_integrator::Dynamics>(0.1);
      if (net == Net::kDoubleIntegratorTruth) {
        c.raw = std::make_unique<domains::double_integrator::GroundTruthBarrier>(
            domains::double_integrator::GroundTruth{});
      } else {
        const nn::MlpSpec spec = ShieldDoubleIntegratorSpec();
        // Normaliser fit to states uniform in the paper's box (x, y in [0, 10), v in [-1.5, 1.5)).
        Eigen::MatrixXf box(4, 4096);
        for (int i = 0; i < box.cols(); ++i) {
          box(0, i) = static_cast<float>(rng.Uniform(0.0, 10.0));
          box(1, i) = static_cast<float>(rng.Uniform(0.0, 10.0));
          box(2, i) = static_cast<float>(rng.Uniform(-1.5, 1.5));
          box(3, i) = static_cast<float>(rng.Uniform(-1.5, 1.5));
        }
        cbf::BarrierNet bn;
        bn.mlp = nn::RandomMlpParams(spec, /*seed=*/42);
        bn.normalizer = nn::Normalizer::Fit(box);
        bn.features = domains::double_integrator::StateFeatures();
        c.params = bn.mlp;
        c.normalizer = bn.normalizer;
        c.raw = bn.MakeEvaluator(batch);
      }
      if (regime == Regime::kResampling && net == Net::kDoubleIntegratorTruth) {
        c.state = Vec({5.0f, 7.4f, 0.0f, -1.5f});  // heading into the obstacle
        c.mu = Vec({0.0f, -3.0f});
        c.sigma = Vec({0.05f, 0.05f});
      } else {
        c.state = Vec({1.0f, 1.0f, 0.3f, 0.2f});  // far from the obstacle at (5, 5)
        c.mu = Vec({0.2f, -0.1f});
        c.sigma = Vec({0.5f, 0.5f});
      }
      break;
    }
    case Net::kDerby: {
      const nn::MlpSpec spec = DerbySpec();
      c.params = nn::RandomMlpParams(spec, /*seed=*/42);
      c.normalizer = nn::Normalizer::Identity(spec.input_dim);
      c.raw = std::make_unique<PerObstacleBarrier>(c.params, c.normalizer, batch);
      c.dynamics = std::make_unique<DerbyDynamics>(0.1f);
      c.state.resize(kDerbyStateDim);
      for (int j = 0; j < kDerbyObstacles; ++j) {  // arena [-1, 1]^2
        c.state[4 * j] = static_cast<float>(rng.Uniform(-1.0, 1.0));
        c.state[4 * j + 1] = static_cast<float>(rng.Uniform(-1.0, 1.0));
        c.state[4 * j + 2] = static_cast<float>(rng.Uniform(-0.2, 0.2));
        c.state[4 * j + 3] = static_cast<float>(rng.Uniform(-0.2, 0.2));
      }
      c.state.tail(4) << 0.05f, -0.1f, 0.1f, 0.0f;
      c.mu = Vec({0.1f, -0.2f});
      c.sigma = Vec({0.5f, 0.5f});
      break;
    }
    case Net::kPanda:
    case Net::kPandaEnsemble3: {
      const nn::MlpSpec spec = PandaSpec();
      cbf::BarrierNet bn;
      bn.mlp = nn::RandomMlpParams(spec, /*seed=*/42);
      bn.normalizer = nn::Normalizer::Identity(spec.input_dim);
      for (int k = 1; net == Net::kPandaEnsemble3 && k < 3; ++k)
        bn.more_members.push_back({nn::RandomMlpParams(spec, 42 + k), bn.normalizer});
      for (int i = 0; i < spec.input_dim; ++i) bn.features.push_back("x" + std::to_string(i));
      c.params = bn.mlp;
      c.normalizer = bn.normalizer;
      c.raw = bn.MakeEvaluator(batch);
      c.dynamics = std::make_unique<PandaDynamics>();
      c.state.resize(kPandaStateDim);
      // ee at (0.5, 0, 0.2) at rest, block 0.1 ahead in x: within 0.15, so the block moves too.
      c.state << 0.5f, 0.0f, 0.2f, 0.0f, 0.0f, 0.0f, 0.6f, 0.05f, 0.02f;
      c.mu = Vec({0.1f, -0.1f, 0.05f});
      c.sigma = Vec({0.3f, 0.3f, 0.3f});
      break;
    }
  }

  // The offset c (nets only). k c is added to every g.
  float offset = 0.0f;
  if (net != Net::kDoubleIntegratorTruth) {
    const double k = c.options.class_k_gain;
    if (regime == Regime::kNoResampling) {
      // Every sample of the policy's distribution safe (margin: 10 % of the g spread).
      const double lo = G0Quantile(*c.raw, *c.dynamics, c.options, c.state, c.mu, c.sigma, 0.0, 1);
      const double hi = G0Quantile(*c.raw, *c.dynamics, c.options, c.state, c.mu, c.sigma, 1.0, 1);
      offset = static_cast<float>((-lo + 0.1 * (hi - lo) + 1e-3) / k);
    } else {
      // Narrow policy (sigma 0.05): nothing safe at first; 20 % of N(mu, 0.5^2) is safe, which
      // Algorithm 2 reaches after a round or two of widening (sigma grows by 0.5 per round).
      c.sigma = Eigen::VectorXf::Constant(c.mu.size(), 0.05f);
      const Eigen::VectorXf wide = Eigen::VectorXf::Constant(c.mu.size(), 0.5f);
      const double q80 = G0Quantile(*c.raw, *c.dynamics, c.options, c.state, c.mu, wide, 0.8, 1);
      offset = static_cast<float>(-q80 / k);
    }
  }
  c.barrier = std::make_unique<OffsetBarrier>(*c.raw, offset);
  c.label = std::string(NetName(net)) + ": " + c.raw->Describe() + ", " + c.dynamics->Describe();
  return c;
}

// ---------------------------------------------------------------------------------------------
// Latency log.

using Clock = std::chrono::steady_clock;

inline double MicrosecondsBetween(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::micro>(b - a).count();
}

/// Per-decision latencies in a buffer allocated (and touched) before the timed loop. Decisions
/// beyond the capacity are not recorded (the capacity covers several seconds of the fastest case).
class LatencyLog {
 public:
  explicit LatencyLog(std::size_t capacity = std::size_t{1} << 20) : us_(capacity, 0.0) {}
  void Add(double us) {
    if (n_ < us_.size()) us_[n_++] = us;
  }
  std::size_t size() const { return n_; }
  /// Nearest-rank percentile (p in (0, 100]); sorts the recorded values (after the loop).
  double Percentile(double p) {
    if (n_ == 0) return 0.0;
    std::sort(us_.begin(), us_.begin() + static_cast<std::ptrdiff_t>(n_));
    const auto rank = static_cast<std::size_t>(std::ceil(p / 100.0 * static_cast<double>(n_)));
    return us_[std::clamp<std::size_t>(rank, 1, n_) - 1];
  }

 private:
  std::vector<double> us_;
  std::size_t n_ = 0;
};

/// Warm-up decisions: returns the mean iterations and the fraction of safe decisions, so that the
/// caller can check the regime.
struct RegimeCheck {
  double iterations = 0;
  double safe_fraction = 0;
};
RegimeCheck WarmUp(shield::Shield& shield, const Case& c, int decisions = 32) {
  RegimeCheck r;
  for (int i = 0; i < decisions; ++i) {
    const shield::Decision& d = shield.Decide(c.state, c.mu, c.sigma);
    r.iterations += d.iterations;
    r.safe_fraction += d.safe() ? 1.0 : 0.0;
  }
  r.iterations /= decisions;
  r.safe_fraction /= decisions;
  return r;
}

/// An empty string if the warm-up matches the case's regime, else what is wrong.
std::string RegimeError(const Case& c, const RegimeCheck& r) {
  if (c.regime == Regime::kNoResampling && r.iterations != 1.0)
    return "no-resampling case resampled (mean iterations " + std::to_string(r.iterations) + ")";
  if (c.regime == Regime::kResampling && r.iterations <= 1.0)
    return "resampling case never resampled";
  if (r.safe_fraction < 1.0)
    return "not every warm-up decision was safe (" + std::to_string(r.safe_fraction) + ")";
  return "";
}

}  // namespace
}  // namespace secure::bench

#ifndef SECURE_SHIELD_BENCH_CASES_ONLY
namespace secure::bench {
namespace {

void BM_ShieldDecision(benchmark::State& st, Net net, Regime regime) {
  Eigen::setNbThreads(1);
  const int m = static_cast<int>(st.range(0));
  const auto sampler = static_cast<shield::Sampler>(st.range(1));
  Case c = MakeCase(net, regime, m);
  c.options.sampler = sampler;  // the case's calibration draws i.i.d. normals whatever the sampler
  shield::Shield shield(c.options, *c.barrier, *c.dynamics);
  const RegimeCheck check = WarmUp(shield, c);
  if (const std::string error = RegimeError(c, check); !error.empty()) {
    st.SkipWithError(error.c_str());
    return;
  }

  LatencyLog log;
  long decisions = 0, iterations = 0, safe = 0;
  c.barrier->ResetCount();
  for (auto _ : st) {
    const Clock::time_point t0 = Clock::now();
    const shield::Decision& d = shield.Decide(c.state, c.mu, c.sigma);
    const Clock::time_point t1 = Clock::now();
    benchmark::DoNotOptimize(d.action.data());
    log.Add(MicrosecondsBetween(t0, t1));
    ++decisions;
    iterations += d.iterations;
    safe += d.safe() ? 1 : 0;
  }

  const double p50 = log.Percentile(50.0), p99 = log.Percentile(99.0);
  st.counters["p50_us"] = p50;
  st.counters["p99_us"] = p99;
  st.counters["p99_over_p50"] = p50 > 0 ? p99 / p50 : 0.0;
  st.counters["iterations"] = static_cast<double>(iterations) / std::max(1L, decisions);
  st.counters["status_safe_fraction"] = static_cast<double>(safe) / std::max(1L, decisions);
  st.counters["h_states"] =
      static_cast<double>(c.barrier->states_evaluated()) / std::max(1L, decisions);
  st.SetLabel(c.label + ", sampler " + ToString(shield::kSamplerNames, sampler));
}

/// The sampling cost of each sampler, near alone: a decision (one round of M actions, action_dim
/// 2, 3 or 9) through a barrier and dynamics that cost almost nothing (h = 1 everywhere, next
/// state = the state). The time is the M x dim draws plus a fixed remainder (M + 2 trivial
/// evaluations, the mean, the bookkeeping), which is the same for every sampler, so differences
/// between samplers are differences in sampling cost. ns_per_normal = decision time / (M dim).
class ConstantBarrier final : public cbf::Barrier {
 public:
  explicit ConstantBarrier(int dim) : dim_(dim) {}
  int state_dim() const override { return dim_; }
  std::string Describe() const override { return "h = 1"; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>&,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    h.setOnes();
  }

 private:
  int dim_;
};
class StillDynamics final : public domains::DynamicsModel {
 public:
  explicit StillDynamics(int dim) : dim_(dim) {}
  int state_dim() const override { return dim_; }
  int action_dim() const override { return dim_; }
  std::string Describe() const override { return "next = state"; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>&,
              Eigen::Ref<Eigen::MatrixXf> next) const override {
    next.colwise() = state;
  }

 private:
  int dim_;
};

void BM_SamplingOnly(benchmark::State& st) {
  const int m = static_cast<int>(st.range(0));
  const auto sampler = static_cast<shield::Sampler>(st.range(1));
  const int dim = static_cast<int>(st.range(2));
  ConstantBarrier barrier(dim);
  StillDynamics dynamics(dim);
  shield::ShieldOptions options;
  options.num_samples = m;
  options.sampler = sampler;
  shield::Shield shield(options, barrier, dynamics);
  const Eigen::VectorXf state = Eigen::VectorXf::Zero(dim), mu = Eigen::VectorXf::Zero(dim),
                        sigma = Eigen::VectorXf::Constant(dim, 0.5f);
  for (auto _ : st) {
    const shield::Decision& d = shield.Decide(state, mu, sigma);
    benchmark::DoNotOptimize(d.action.data());
  }
  st.counters["ns_per_normal"] = benchmark::Counter(
      static_cast<double>(m) * dim * 1e-9,
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  st.SetLabel(std::string("sampler ") + ToString(shield::kSamplerNames, sampler));
}
BENCHMARK(BM_SamplingOnly)
    ->ArgNames({"M", "sampler", "dim"})
    ->ArgsProduct({{64, 128}, {0, 1, 2}, {2, 3, 9}})
    ->Unit(benchmark::kMicrosecond);

// Args: M (samples per round), sampler (0 iid, 1 antithetic, 2 qmc: shield::Sampler's order).
static_assert(static_cast<int>(shield::Sampler::kQmc) == 2, "the benchmark's sampler argument");
#define SECURE_SHIELD_CASE(name, net, regime)             \
  BENCHMARK_CAPTURE(BM_ShieldDecision, name, net, regime) \
      ->ArgNames({"M", "sampler"})                        \
      ->ArgsProduct({{64, 128}, {0, 1, 2}})               \
      ->Unit(benchmark::kMicrosecond)

SECURE_SHIELD_CASE(DI_NoResampling, Net::kDoubleIntegrator, Regime::kNoResampling);
SECURE_SHIELD_CASE(DI_Resampling, Net::kDoubleIntegrator, Regime::kResampling);
SECURE_SHIELD_CASE(Derby_NoResampling, Net::kDerby, Regime::kNoResampling);
SECURE_SHIELD_CASE(Derby_Resampling, Net::kDerby, Regime::kResampling);
SECURE_SHIELD_CASE(Panda_NoResampling, Net::kPanda, Regime::kNoResampling);
SECURE_SHIELD_CASE(Panda_Resampling, Net::kPanda, Regime::kResampling);
SECURE_SHIELD_CASE(PandaEnsemble3_NoResampling, Net::kPandaEnsemble3, Regime::kNoResampling);
SECURE_SHIELD_CASE(PandaEnsemble3_Resampling, Net::kPandaEnsemble3, Regime::kResampling);
SECURE_SHIELD_CASE(DITruth_NoResampling, Net::kDoubleIntegratorTruth, Regime::kNoResampling);
SECURE_SHIELD_CASE(DITruth_Resampling, Net::kDoubleIntegratorTruth, Regime::kResampling);

#undef SECURE_SHIELD_CASE

/// What top-q aggregation adds to a decision: the same case with aggregation mean (arg 0) and
/// top-q (arg 1), the task value an AIRL reward model of the released size (g and V: two 32-wide
/// ReLU layers) on the case's states. q_us_per_decision = the extra time per decision is the
/// difference of the two rows' p50 (one V batch over the round's M next states, one g(s), the
/// partial sort).
void BM_TopQDecision(benchmark::State& st, Net net, Regime regime) {
  Eigen::setNbThreads(1);
  const int m = static_cast<int>(st.range(0));
  const bool top_q = st.range(1) != 0;
  Case c = MakeCase(net, regime, m);
  c.options.sampler = shield::Sampler::kQmc;
  if (top_q) c.options.aggregation = shield::Aggregation::kTopQ;
  const int dim = static_cast<int>(c.state.size());
  policy::AirlRewardModel model;
  model.reward = nn::RandomMlpParams(nn::MlpSpec{dim, {32, 32}, 1, nn::Activation::kRelu}, 5);
  model.shaping = nn::RandomMlpParams(nn::MlpSpec{dim, {32, 32}, 1, nn::Activation::kRelu}, 6);
  model.input = nn::Normalizer::Identity(dim);
  for (int i = 0; i < dim; ++i) model.observation_features.push_back("s" + std::to_string(i));
  policy::AirlActionValue value(model, model.observation_features,
                                std::max(c.options.num_samples, c.options.num_probes));
  shield::Shield shield(c.options, *c.barrier, *c.dynamics);
  shield.SetActionValue(&value);
  const RegimeCheck check = WarmUp(shield, c);
  if (const std::string error = RegimeError(c, check); !error.empty()) {
    st.SkipWithError(error.c_str());
    return;
  }
  LatencyLog log;
  for (auto _ : st) {
    const Clock::time_point t0 = Clock::now();
    const shield::Decision& d = shield.Decide(c.state, c.mu, c.sigma);
    const Clock::time_point t1 = Clock::now();
    benchmark::DoNotOptimize(d.action.data());
    log.Add(MicrosecondsBetween(t0, t1));
  }
  st.counters["p50_us"] = log.Percentile(50.0);
  st.counters["p99_us"] = log.Percentile(99.0);
  st.SetLabel(c.label + (top_q ? ", aggregation top-q" : ", aggregation mean"));
}
BENCHMARK_CAPTURE(BM_TopQDecision, Panda_NoResampling, Net::kPanda, Regime::kNoResampling)
    ->ArgNames({"M", "top_q"})
    ->ArgsProduct({{32, 128}, {0, 1}})
    ->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_TopQDecision, DI_NoResampling, Net::kDoubleIntegrator, Regime::kNoResampling)
    ->ArgNames({"M", "top_q"})
    ->ArgsProduct({{32, 128}, {0, 1}})
    ->Unit(benchmark::kMicrosecond);

/// What an actuator box adds to a decision: the same case without a box (arg 0), with
/// action_bounds clip (1) and reject (2), the box mu +- sigma (about a third of the draws leave it
/// in each component, a heavier cut than the domains' boxes make). Where the rows use the same
/// rounds (iterations), the difference of their p50 is the box's cost: a copy and clip of each
/// round's actions, one pass marking those outside.
void BM_BoundedDecision(benchmark::State& st, Net net, Regime regime) {
  Eigen::setNbThreads(1);
  const int m = static_cast<int>(st.range(0));
  const int mode = static_cast<int>(st.range(1));
  Case c = MakeCase(net, regime, m);
  if (mode == 2) c.options.action_bounds = shield::ActionBounds::kReject;
  shield::Shield shield(c.options, *c.barrier, *c.dynamics);
  if (mode > 0) shield.SetActionBounds(c.mu - c.sigma, c.mu + c.sigma);
  LatencyLog log;
  long decisions = 0, bounded = 0, iterations = 0;
  for (auto _ : st) {
    const Clock::time_point t0 = Clock::now();
    const shield::Decision& d = shield.Decide(c.state, c.mu, c.sigma);
    const Clock::time_point t1 = Clock::now();
    benchmark::DoNotOptimize(d.action.data());
    log.Add(MicrosecondsBetween(t0, t1));
    ++decisions;
    bounded += d.bounded ? 1 : 0;
    iterations += d.iterations;
  }
  st.counters["p50_us"] = log.Percentile(50.0);
  st.counters["p99_us"] = log.Percentile(99.0);
  st.counters["bounded_fraction"] = static_cast<double>(bounded) / std::max(1L, decisions);
  // A box can also change the decision itself (more rounds where it cuts off the safe actions):
  // compare rows with equal iterations for the box's own cost.
  st.counters["iterations"] = static_cast<double>(iterations) / std::max(1L, decisions);
  st.SetLabel(c.label + (mode == 0 ? ", no box" : mode == 1 ? ", box clip" : ", box reject"));
}
BENCHMARK_CAPTURE(BM_BoundedDecision, Panda_NoResampling, Net::kPanda, Regime::kNoResampling)
    ->ArgNames({"M", "box"})
    ->ArgsProduct({{64}, {0, 1, 2}})
    ->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_BoundedDecision, DI_NoResampling, Net::kDoubleIntegrator,
                  Regime::kNoResampling)
    ->ArgNames({"M", "box"})
    ->ArgsProduct({{64}, {0, 1, 2}})
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace secure::bench
#endif  // SECURE_SHIELD_BENCH_CASES_ONLY
