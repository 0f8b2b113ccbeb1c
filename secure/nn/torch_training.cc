#include "secure/nn/torch_training.h"

namespace secure::nn {

void SetAdamLearningRate(torch::optim::Adam& optimizer, double learning_rate) {
  for (auto& group : optimizer.param_groups())
    static_cast<torch::optim::AdamOptions&>(group.options()).lr(learning_rate);
}

double AdamStep(torch::optim::Adam& optimizer, const MinibatchLoss& loss,
                const std::int64_t* indices, long count) {
  const torch::Tensor idx =
      torch::from_blob(const_cast<std::int64_t*>(indices), {count}, torch::kInt64);
  const torch::Tensor value = loss(idx);
  optimizer.zero_grad();
  value.backward();
  optimizer.step();
  return value.item<double>();
}

}  // namespace secure::nn
