#pragma once
// A generic linear dynamics model T(s, a) = A s + B a, e.g. a linearised or identified plant, for
// a shield on a system without a domain plug-in (the Python module's `Dynamics.linear(A, B)`).
//
//   Eigen::MatrixXf a(4, 4), b(4, 2);  // ...
//   domains::LinearDynamics model(a, b);
//   shield::Shield shield(options, barrier, model);
//
// Step() allocates nothing (the product A s goes into a buffer made here), so, like every
// DynamicsModel, one object is used by one thread at a time.
#include <Eigen/Core>
#include <string>

#include "secure/domains/dynamics.h"

namespace secure::domains {

class LinearDynamics final : public DynamicsModel {
 public:
  /// `a` is (d x d), `b` is (d x n), d, n >= 1, every entry finite.
  /// @throws secure::Error naming the matrix and its shape or the first non-finite entry.
  LinearDynamics(const Eigen::Ref<const Eigen::MatrixXf>& a,
                 const Eigen::Ref<const Eigen::MatrixXf>& b);

  int state_dim() const override { return static_cast<int>(a_.rows()); }
  int action_dim() const override { return static_cast<int>(b_.cols()); }
  /// "linear dynamics s' = A s + B a (state 4, action 2)".
  std::string Describe() const override;
  const Eigen::MatrixXf& a() const { return a_; }
  const Eigen::MatrixXf& b() const { return b_; }

 protected:
  void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
              const Eigen::Ref<const Eigen::MatrixXf>& actions,
              Eigen::Ref<Eigen::MatrixXf> next_states) const override;

 private:
  Eigen::MatrixXf a_, b_;
  mutable Eigen::VectorXf as_;  // A s, the same for every action of a batch
};

}  // namespace secure::domains
