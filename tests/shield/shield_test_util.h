#pragma once
// Small systems and helpers shared by the shield tests.

#include <Eigen/Core>
#include <gtest/gtest.h>
#include <cstdint>
#include <cstring>
#include <functional>
#include <initializer_list>
#include <string>
#include <utility>

#include "secure/cbf/barrier.h"
#include "secure/common/rng.h"
#include "secure/domains/dynamics.h"
#include "secure/shield/shield.h"

namespace secure::shield::test {

/// Whether two vectors are equal bit for bit (for the same code path reproducing itself).
inline bool BitEqual(const Eigen::VectorXf& a, const Eigen::VectorXf& b) {
  return a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), sizeof(float) * static_cast<std::size_t>(a.size())) == 0;
}

/// Round 1 of the shield's i.i.d. sampler, replicated: M columns drawn column by column (rows
/// within a column) from N(mu, sigma) with the shield's generator seeded by `seed`.
inline Eigen::MatrixXf FirstRound(std::uint64_t seed, const Eigen::VectorXf& mu,
                                  const Eigen::VectorXf& sigma, int m) {
  Rng rng(seed);
  Eigen::MatrixXf samples(mu.size(), m);
  for (int c = 0; c < m; ++c)
    for (Eigen::Index r = 0; r < mu.size(); ++r)
      samples(r, c) = mu[r] + sigma[r] * static_cast<float>(rng.Normal());
  return samples;
}

/// x' = x + a * dt in `dim` dimensions (state_dim == action_dim == dim); allocation-free.
class IntegratorDynamics final : public domains::DynamicsModel {
 public:
  IntegratorDynamics(int dim, double dt) : dim_(dim), dt_(static_cast<float>(dt)) {}
  int state_dim() const override { return dim_; }
  int action_dim() const override { return dim_; }
  std::string Describe() const override { return "integrator-" + std::to_string(dim_) + "d"; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override {
    for (Eigen::Index i = 0; i < actions.cols(); ++i)
      next_states.col(i) = state + dt_ * actions.col(i);
  }

 private:
  int dim_;
  float dt_;
};

/// h(s) = fn(s), evaluated column by column.
class FunctionBarrier final : public cbf::Barrier {
 public:
  using Fn = std::function<double(const Eigen::Ref<const Eigen::VectorXf>&)>;
  FunctionBarrier(int dim, std::string name, Fn fn)
      : dim_(dim), name_(std::move(name)), fn_(std::move(fn)) {}
  int state_dim() const override { return dim_; }
  std::string Describe() const override { return name_; }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    for (Eigen::Index i = 0; i < states.cols(); ++i) h[i] = static_cast<float>(fn_(states.col(i)));
  }

 private:
  int dim_;
  std::string name_;
  Fn fn_;
};

/// Q(s, a) = w . T(s, a), a linear task value of the predicted next state (allocation-free);
/// counts its calls and the columns it was given.
class LinearActionValue final : public ActionValue {
 public:
  explicit LinearActionValue(Eigen::VectorXf w) : w_(std::move(w)) {}
  void Evaluate(const Eigen::Ref<const Eigen::VectorXf>& /*state*/,
                const Eigen::Ref<const Eigen::MatrixXf>& next_states,
                Eigen::Ref<Eigen::VectorXd> q) override {
    ++calls;
    columns += next_states.cols();
    for (Eigen::Index i = 0; i < next_states.cols(); ++i)
      q[i] = static_cast<double>(w_.dot(next_states.col(i)));
  }
  std::string Describe() const override { return "linear task value"; }
  long calls = 0, columns = 0;

 private:
  Eigen::VectorXf w_;
};

inline Eigen::VectorXf Vec(std::initializer_list<float> values) {
  Eigen::VectorXf v(static_cast<Eigen::Index>(values.size()));
  Eigen::Index i = 0;
  for (float x : values) v[i++] = x;
  return v;
}

/// 2-D: an integrator (dt 0.1) under the linear barrier h(s) = w . s + 0.5, w = (1, -2): with a
/// linear class-K function of gain k, g(a) = w . a + k h(s) exactly, affine in the action.
struct HalfSpace {
  const Eigen::Vector2f w{1.0f, -2.0f};
  FunctionBarrier barrier{2, "linear", [](const Eigen::Ref<const Eigen::VectorXf>& s) {
                            return static_cast<double>(s[0] - 2.0f * s[1]) + 0.5;
                          }};
  const IntegratorDynamics dynamics{2, 0.1};
};


/// On HalfSpace, where g is affine in the action and the first projection is exact and accepted,
/// the shields of `options` and of `mended` (the same with an option that mends a projection)
/// decide the same, bit for bit.
inline void ExpectTheSameAffineProjection(const ShieldOptions& options,
                                          const ShieldOptions& mended) {
  HalfSpace h1, h2;
  Shield plain(options, h1.barrier, h1.dynamics), other(mended, h2.barrier, h2.dynamics);
  const Eigen::VectorXf state = Vec({0.2f, 0.3f}), mu = Vec({-1.0f, 1.0f});
  const Decision& p = plain.Decide(state, mu, Vec({0.1f, 0.1f}));
  const Decision& m = other.Decide(state, mu, Vec({0.1f, 0.1f}));
  ASSERT_EQ(p.qp, QpOutcome::kAccepted) << p.ToJson().dump();
  EXPECT_TRUE(BitEqual(p.action, m.action));
  EXPECT_EQ(p.g, m.g);
}

/// 1-D: an integrator (y' = y + 0.1 a) from y = 0 under the barrier h(y) = fn(y), and the options
/// of a projection proposal with alpha(h) = gain h; the exact cases of the CBF-QP's mending
/// options build on it.
struct Integrator1d {
  Integrator1d(std::string name, std::function<double(double)> fn)
      : barrier(1, std::move(name), [fn](const Eigen::Ref<const Eigen::VectorXf>& s) {
          return fn(static_cast<double>(s[0]));
        }) {}
  static ShieldOptions Options(Proposal proposal, double gain) {
    ShieldOptions o;
    o.proposal = proposal;
    o.class_k_gain = gain;
    return o;
  }
  FunctionBarrier barrier;
  const IntegratorDynamics dynamics{1, 0.1};
  const Eigen::VectorXf state = Vec({0.0f});
};

/// g(action) computed outside the shield, from the barrier and the dynamics (same float path).
inline double IndependentG(cbf::Barrier& barrier, const domains::DynamicsModel& dynamics,
                           const ShieldOptions& options, const Eigen::VectorXf& state,
                           const Eigen::VectorXf& action) {
  Eigen::MatrixXf s = state;
  Eigen::VectorXf h_s(1), h_next(1);
  barrier.Evaluate(s, h_s);
  Eigen::MatrixXf next(dynamics.state_dim(), 1);
  dynamics.Step(state, action, next);
  barrier.Evaluate(next, h_next);
  return (static_cast<double>(h_next[0]) - h_s[0]) * (1.0 / options.dt) +
         ClassKValue(options, h_s[0]);
}

}  // namespace secure::shield::test
