#pragma once
// The dynamics model T(s, a) the shield uses to look one step ahead, evaluated for a batch of
// actions from one state (the shield's cost is dominated by h on the M next states, so batch).
//
// Implementations must not allocate in Step() (the shield runs inside a control loop) and must be
// safe to call from one thread at a time per object.

#include <Eigen/Core>
#include <string>

namespace secure::domains {

class DynamicsModel {
 public:
  virtual ~DynamicsModel() = default;
  virtual int state_dim() const = 0;
  virtual int action_dim() const = 0;
  virtual std::string Describe() const = 0;

  /// next_states (state_dim x M) = T(state, actions (action_dim x M)), column by column.
  /// @throws secure::Error on a dimension mismatch.
  void Step(const Eigen::Ref<const Eigen::VectorXf>& state,
            const Eigen::Ref<const Eigen::MatrixXf>& actions,
            Eigen::Ref<Eigen::MatrixXf> next_states) const;

 protected:
  /// Called with checked dimensions.
  virtual void DoStep(const Eigen::Ref<const Eigen::VectorXf>& state,
                      const Eigen::Ref<const Eigen::MatrixXf>& actions,
                      Eigen::Ref<Eigen::MatrixXf> next_states) const = 0;
};

}  // namespace secure::domains
