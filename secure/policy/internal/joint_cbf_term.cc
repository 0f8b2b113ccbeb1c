#include "secure/policy/internal/joint_cbf_term.h"

#include "secure/nn/torch_mlp.h"

namespace secure::policy::internal {

void JointCbfTerm::Prepare(const Eigen::MatrixXf& states, int action_dim) {
  const long n = states.cols();
  const long d = states.rows();
  Eigen::MatrixXf actions = Eigen::MatrixXf::Zero(action_dim, action_dim + 1);
  for (int k = 0; k < action_dim; ++k) actions(k, k + 1) = 1.0f;
  Eigen::MatrixXf next(d, action_dim + 1);
  Eigen::MatrixXf base_m(d, n);
  Eigen::MatrixXf jac_m(d, n * action_dim);  // column i * action_dim + k: dT/da_k at state i
  for (long i = 0; i < n; ++i) {
    model_->Step(states.col(i), actions, next);
    base_m.col(i) = next.col(0);
    for (int k = 0; k < action_dim; ++k)
      jac_m.col(i * action_dim + k) = next.col(k + 1) - next.col(0);
  }
  base_ = nn::ToTensor(base_m);
  jacobian_ = nn::ToTensor(jac_m).reshape({n, action_dim, d});
  torch::NoGradGuard no_grad;
  h_state_ = barrier_->Forward(nn::ToTensor(states)).reshape({n});
  loss_sum_ = 0.0;
  batches_ = 0;
}

torch::Tensor JointCbfTerm::Loss(const torch::Tensor& idx, const torch::Tensor& actions) {
  const torch::Tensor next =
      base_.index_select(0, idx) +
      torch::bmm(actions.unsqueeze(1), jacobian_.index_select(0, idx)).squeeze(1);
  const torch::Tensor h = h_state_.index_select(0, idx);
  const torch::Tensor h_next = barrier_->Forward(next).reshape({-1});
  const torch::Tensor deriv = h_next - h + options_.dt * options_.class_k_gain * h;
  const torch::Tensor loss =
      torch::where(h >= 0, torch::relu(-deriv),
                   options_.unsafe_weight * torch::relu(-deriv + options_.unsafe_margin))
          .mean();
  loss_sum_ += loss.item<double>();
  ++batches_;
  return loss;
}

}  // namespace secure::policy::internal
