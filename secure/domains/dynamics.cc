#include "secure/domains/dynamics.h"

#include "secure/common/error.h"

namespace secure::domains {

void DynamicsModel::Step(const Eigen::Ref<const Eigen::VectorXf>& state,
                         const Eigen::Ref<const Eigen::MatrixXf>& actions,
                         Eigen::Ref<Eigen::MatrixXf> next_states) const {
  SECURE_CHECK(state.size() == state_dim(),
               Describe() << ": state has " << state.size() << " values, expected " << state_dim());
  SECURE_CHECK(actions.rows() == action_dim(), Describe() << ": actions have " << actions.rows()
                                                          << " rows, expected " << action_dim());
  SECURE_CHECK(next_states.rows() == state_dim() && next_states.cols() == actions.cols(),
               Describe() << ": next_states is " << next_states.rows() << " x "
                          << next_states.cols() << ", expected " << state_dim() << " x "
                          << actions.cols());
  DoStep(state, actions, next_states);
}

}  // namespace secure::domains
