#pragma once
// The Adam half of nn::RunTrainingLoop's steps, shared by the trainers (cbf::TrainBarrier,
// cbf::TrainCarBarrier, policy::TrainBc, dynamics::TrainDynamics): the epoch's learning rate on
// every parameter group, and one optimiser step on a minibatch given its loss. This header
// includes <torch/torch.h>: include it only from translation units that train.
//
//   nn::TrainingSteps<Score> steps;
//   nn::UseAdam(optimizer, [&](const torch::Tensor& idx) {
//     return HingeLoss(model->forward(x.index_select(0, idx)), ...);
//   }, &steps);

#include <torch/torch.h>

#include <cstdint>
#include <functional>
#include <utility>

#include "secure/nn/training_loop.h"

namespace secure::nn {

/// The loss of a minibatch, given its sample indices as an (m) int64 tensor.
using MinibatchLoss = std::function<torch::Tensor(const torch::Tensor& indices)>;

/// Sets the learning rate of every parameter group of an Adam optimiser.
void SetAdamLearningRate(torch::optim::Adam& optimizer, double learning_rate);

/// One optimiser step on the samples indices[0 .. count): zero the gradients, back-propagate
/// loss(indices), step. Returns the loss.
double AdamStep(torch::optim::Adam& optimizer, const MinibatchLoss& loss,
                const std::int64_t* indices, long count);

/// Sets steps->set_learning_rate (SetAdamLearningRate) and steps->train_batch (AdamStep with
/// `loss`). `optimizer` must outlive the steps.
template <class Score>
void UseAdam(torch::optim::Adam& optimizer, MinibatchLoss loss, TrainingSteps<Score>* steps) {
  steps->set_learning_rate = [&optimizer](double lr) { SetAdamLearningRate(optimizer, lr); };
  steps->train_batch = [&optimizer, loss = std::move(loss)](const std::int64_t* indices,
                                                            long count) {
    return AdamStep(optimizer, loss, indices, count);
  };
}

}  // namespace secure::nn
