#pragma once
// The barrier interface: anything that maps a batch of states to h values. The shield, the
// validation code and the CLI work with any implementation — the learned BarrierNet, an
// analytic ground truth of a domain, and per-obstacle networks.
//
// A Barrier object is an *evaluator*: it may own scratch memory, so Evaluate() is non-const and
// one object must not be used by two threads at once. Make one per thread from the shared,
// immutable model (e.g. BarrierNet::MakeEvaluator()).

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

namespace secure::cbf {

class Barrier {
 public:
  virtual ~Barrier() = default;

  /// Number of rows a state has.
  virtual int state_dim() const = 0;
  /// Short description for reports ("barrier_mlp 4-64-64-1 tanh", "double-integrator ground
  /// truth").
  virtual std::string Describe() const = 0;

  /// h(s) for every column of `states` (state_dim x N) into h (N).
  /// @throws secure::Error if states.rows() != state_dim() or h.size() != N.
  void Evaluate(const Eigen::Ref<const Eigen::MatrixXf>& states, Eigen::Ref<Eigen::VectorXf> h);

  /// The same h as Evaluate, computed without skipping any of the network's work: a barrier
  /// that skips work by state (the per-obstacle barrier skips the obstacles out of range, which
  /// its mask would zero) evaluates everything here and applies the mask afterwards, as the
  /// authors' masked network does. The cost of a forward that owes nothing to the states, for
  /// timing references (`secure eval`'s reference forward); for every barrier that skips
  /// nothing it is Evaluate.
  /// @throws secure::Error as Evaluate.
  void EvaluateDense(const Eigen::Ref<const Eigen::MatrixXf>& states,
                     Eigen::Ref<Eigen::VectorXf> h);

  /// h(s) (N) and its gradient with respect to the state, gradients (state_dim x N) = dh/ds, for
  /// every column of `states` (the CBF-QP filter and the shield's `proposal: qp` linearise with
  /// it). The learned barriers compute it analytically (analytic_gradient()): the MLP's backward
  /// pass; the per-obstacle minimum passes the gradient of its active (arg-min, first on ties)
  /// entry, and a state at the cap gets 0. Any other barrier gets central finite differences of
  /// Evaluate, step 1e-3 max(1, |s_i|) per row (its buffers are sized at the first call; no
  /// allocation after it). h is Evaluate's up to float rounding (the analytic path runs Eigen
  /// products). @throws secure::Error on wrong shapes.
  void EvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                        Eigen::Ref<Eigen::VectorXf> h, Eigen::Ref<Eigen::MatrixXf> gradients);
  /// Whether EvaluateGradient is analytic (false: finite differences).
  virtual bool analytic_gradient() const { return false; }

 protected:
  /// Called with checked dimensions.
  virtual void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                          Eigen::Ref<Eigen::VectorXf> h) = 0;
  /// Called with checked dimensions; override only if DoEvaluate skips work by state.
  virtual void DoEvaluateDense(const Eigen::Ref<const Eigen::MatrixXf>& states,
                               Eigen::Ref<Eigen::VectorXf> h) {
    DoEvaluate(states, h);
  }
  /// Called with checked dimensions; the default is central finite differences of DoEvaluate.
  virtual void DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                  Eigen::Ref<Eigen::VectorXf> h,
                                  Eigen::Ref<Eigen::MatrixXf> gradients);

 private:
  void CheckShapes(const Eigen::Ref<const Eigen::MatrixXf>& states,
                   const Eigen::Ref<Eigen::VectorXf>& h) const;
  Eigen::MatrixXf fd_states_;  // (state_dim x 2 state_dim + 1) finite differences, one state
  Eigen::VectorXf fd_h_;
};

/// The row of each of `wanted` (names, in order) among `available` (the first row of that name).
/// @throws secure::Error naming the first missing name, `source` with its features and `reader`
///   with what it reads ("the panda domain has 18 features (…), without 'x', which m.model reads
///   (9: …)").
std::vector<int> FeatureRows(const std::vector<std::string>& wanted,
                             const std::vector<std::string>& available, const std::string& source,
                             const std::string& reader);

/// A barrier that may skip work by state: Evaluate and EvaluateDense both come to
/// DoEvaluateStates, with `dense` telling it not to skip (SelectRows, MinBarrier, the
/// per-obstacle evaluator, the dynamics ensemble's pessimistic barrier).
class SkippingBarrier : public Barrier {
 protected:
  /// h of `states` (checked dimensions); dense: skip no work by state (Barrier::EvaluateDense).
  virtual void DoEvaluateStates(const Eigen::Ref<const Eigen::MatrixXf>& states,
                                Eigen::Ref<Eigen::VectorXf> h, bool dense) = 0;
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) final {
    DoEvaluateStates(states, h, /*dense=*/false);
  }
  void DoEvaluateDense(const Eigen::Ref<const Eigen::MatrixXf>& states,
                       Eigen::Ref<Eigen::VectorXf> h) final {
    DoEvaluateStates(states, h, /*dense=*/true);
  }
};

/// A barrier on wider states: h(s) = inner(s[rows]), i.e. the inner barrier reads rows[k] of a
/// `state_dim`-row state as its k-th row. The rows are gathered into a buffer preallocated for
/// `chunk` states (larger batches go in chunks), so Evaluate allocates nothing. E.g. a barrier
/// trained on 9 of the 18 features of an observation, evaluated on whole observations
/// (BarrierNet::MakeEvaluatorFor).
class SelectRows final : public SkippingBarrier {
 public:
  /// @throws secure::Error if rows.size() != inner->state_dim(), a row is outside
  ///   [0, state_dim) or chunk < 1.
  SelectRows(std::unique_ptr<Barrier> inner, int state_dim, std::vector<int> rows,
             int chunk = 4096);

  int state_dim() const override { return state_dim_; }
  /// The inner description with the selection ("barrier_mlp 9-64-1 tanh on 9 of 18 state rows").
  std::string Describe() const override;
  /// The inner barrier's (its gradient is scattered to the selected rows, 0 elsewhere).
  bool analytic_gradient() const override { return inner_->analytic_gradient(); }

 protected:
  /// The inner barrier's h on the gathered rows.
  void DoEvaluateStates(const Eigen::Ref<const Eigen::MatrixXf>& states,
                        Eigen::Ref<Eigen::VectorXf> h, bool dense) override;
  void DoEvaluateGradient(const Eigen::Ref<const Eigen::MatrixXf>& states,
                          Eigen::Ref<Eigen::VectorXf> h,
                          Eigen::Ref<Eigen::MatrixXf> gradients) override;

 private:
  std::unique_ptr<Barrier> inner_;
  int state_dim_;
  std::vector<int> rows_;
  Eigen::MatrixXf buffer_;  // (rows_.size() x chunk)
  Eigen::MatrixXf gradient_buffer_;  // (rows_.size() x chunk), sized at the first gradient
};

}  // namespace secure::cbf
