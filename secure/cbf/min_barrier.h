#pragma once
// A barrier that is the minimum over member barriers: h(s) = min_k h_k(s). An ensemble of
// barriers trained from different initialisations on the same labels (BarrierNet with
// `more_members`, model kind "barrier_ensemble") is evaluated through it: where the members
// disagree, the most pessimistic one decides.

#include <memory>
#include <string>
#include <vector>

#include "secure/cbf/barrier.h"

namespace secure::cbf {

class MinBarrier final : public SkippingBarrier {
 public:
  /// Members of one state_dim; scratch for `chunk` states is allocated here (larger batches go
  /// in chunks), so Evaluate, EvaluateDense and the analytic EvaluateGradient allocate nothing.
  /// @throws secure::Error if there is no member, a member is null or of another state_dim, or
  ///   chunk < 1.
  explicit MinBarrier(std::vector<std::unique_ptr<Barrier>> members, int chunk = 4096);

  int state_dim() const override { return state_dim_; }
  /// "min of K <first member's description>" (e.g. "min of 3 barrier_mlp 9-64-64-1 tanh"); if
  /// the members' descriptions differ: "min of K barriers (<d0>; <d1>; ...)".
  std::string Describe() const override { return description_; }
  /// True when every member's gradient is analytic: the gradient is then the arg-min member's
  /// (the first of least h on ties). Otherwise central differences of the minimum.
  bool analytic_gradient() const override { return analytic_; }
  int members() const { return static_cast<int>(members_.size()); }

 protected:
  /// The least member h, chunk by chunk (member 0 writes h, the others the scratch); dense:
  /// with every member's EvaluateDense.
  void DoEvaluateStates(const Eigen::Ref<const Eigen::MatrixXf>& states,
                        Eigen::Ref<Eigen::VectorXf> h, bool dense) override;
  /// The arg-min member's h and gradient (analytic members), else central differences.
  void DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                          Eigen::Ref<Eigen::VectorXf> h,
                          Eigen::Ref<Eigen::MatrixXf> gradients) override;

 private:
  std::vector<std::unique_ptr<Barrier>> members_;
  int state_dim_ = 0;
  bool analytic_ = true;
  std::string description_;
  Eigen::VectorXf scratch_h_;           // (chunk)
  Eigen::MatrixXf scratch_gradients_;   // (state_dim x chunk) when analytic, else empty
};

}  // namespace secure::cbf
