#pragma once
// Training a learned dynamics ensemble (dynamics/ensemble.h) from transitions (LibTorch; this
// header does not include it).
//
//   K members, each an MLP (s, a) -> Δs on normalised inputs (the input normaliser is fitted on
//   the training split), trained to the normalised change (Δs − mean) / std, i.e. a squared error
//   per output scaled by that output's std of Δs, so a feature that barely moves weighs as much
//   as one that moves a lot. Adam over shuffled minibatches with a cosine learning rate
//   (nn::RunTrainingLoop); a random hold-out of the transitions (validation_fraction) selects
//   each member's best epoch and stops it early (patience). The members differ by their initial
//   weights and minibatch order (seeds derived from `seed`); they share the split.
//
// Deterministic for a seed (one LibTorch thread, nn::SetTorchThreads(1), as every trainer).

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "secure/dynamics/ensemble.h"
#include "secure/dynamics/transitions.h"
#include "secure/nn/mlp.h"

namespace secure::dynamics {

struct DynamicsTrainerOptions {
  int members = 5;                 // K
  std::vector<int> hidden = {64, 64};
  nn::Activation activation = nn::Activation::kTanh;
  double learning_rate = 1e-3;
  double final_learning_rate = 1e-5;
  int epochs = 200;                 // at most
  int batch_size = 256;
  int patience = 30;                // epochs without a better validation loss before stopping
                                    // (0: never)
  double validation_fraction = 0.1;  // held-out transitions (at least one when > 0)
  double weight_decay = 0.0;
  long min_transitions = 20;        // fewer is an error naming the file
  std::uint64_t seed = 0;
  bool verbose = false;             // one line per member on stderr

  /// @throws secure::Error naming the field ("DynamicsTrainerOptions::members = 0, must be ...").
  void Validate() const;
  nlohmann::json ToJson() const;
};

struct DynamicsTrainingSummary {
  long train_transitions = 0, validation_transitions = 0;
  std::vector<int> epochs, best_epochs;          // per member
  std::vector<double> validation_loss;           // per member, normalised MSE of the kept weights
  double ensemble_validation_loss = 0.0;         // the members' mean, normalised MSE
  double wall_seconds = 0.0;
  nlohmann::json ToJson() const;
  std::string BriefReport() const;
};

/// @throws secure::Error on invalid options, fewer than options.min_transitions transitions
///   (naming the file), or non-finite values (naming the file and line).
EnsembleDynamics TrainDynamics(const DynamicsTrainerOptions& options, const Transitions& data,
                               DynamicsTrainingSummary* summary = nullptr);

}  // namespace secure::dynamics
