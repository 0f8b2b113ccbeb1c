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

 protected:
  /// Called with checked dimensions.
  virtual void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                          Eigen::Ref<Eigen::VectorXf> h) = 0;
};

}  // namespace secure::cbf
