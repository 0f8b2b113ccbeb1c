#pragma once
// The training loop shared by the trainers (cbf::TrainBarrier, cbf::TrainCarBarrier,
// policy::TrainBc): epochs of shuffled minibatches, a cosine learning-rate schedule, the best
// checkpoint, early stopping and a per-epoch callback that continues, stops or aborts. It knows
// nothing of LibTorch: the trainer supplies the steps (one optimiser step on a minibatch, the
// evaluation after an epoch, saving and restoring the best weights) as std::functions.
//
//   nn::TrainingLoopOptions loop{options.max_epochs, n_train, options.batch_size,
//                                options.even_batches, options.patience, options.learning_rate,
//                                options.final_learning_rate, "cbf::TrainBarrier"};
//   nn::TrainingSteps<Score> steps;
//   steps.set_learning_rate = [&](double lr) { ... };
//   steps.train_batch = [&](const std::int64_t* idx, long m) { ...; return loss; };
//   steps.evaluate = [&](int epoch) { return Evaluate(model, val); };
//   steps.better = [](const Score& a, const Score& b) { return a.loss < b.loss; };
//   steps.save_best = [&] { best = model->ToParams(); };
//   steps.restore_best = [&] { model->LoadParams(best); };
//   const nn::TrainingLoopResult r = nn::RunTrainingLoop(loop, rng, steps);
//
// Per epoch, in this order: the learning rate of the epoch; a Fisher–Yates shuffle (secure::Rng,
// the caller's stream) of the sample order, which carries over from epoch to epoch; minibatches
// of batch_size samples in that order (the last one smaller; or, with even_batches, as many
// minibatches of near-equal sizes); the epoch's evaluation and best
// checkpoint; on_epoch; the patience check. After the last epoch the best checkpoint is restored.
// The same inputs and seed give the same calls in the same order, so the numbers of a trainer
// built on it are a function of its options and data only.

#include <algorithm>
#include <cstdint>
#include <functional>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

#include "secure/common/rng.h"

namespace secure::nn {

/// What on_epoch wants after an epoch: go on, stop (the best checkpoint is kept), or abort
/// (RunTrainingLoop throws a secure::Error naming the epoch; nothing is restored).
enum class EpochDecision { kContinue, kStop, kAbort };

enum class StopReason { kMaxEpochs, kEarlyStopping, kCallback };
/// "max_epochs", "early_stopping", "callback" (the trainers' summaries record these).
const char* ToString(StopReason reason);

struct TrainingLoopOptions {
  int max_epochs = 1;    // > 0
  long num_samples = 0;  // training samples (indices 0 .. num_samples - 1), >= 0
  int batch_size = 1;    // samples per optimiser step, > 0
  // false: minibatches of batch_size, the last one smaller (n = 260, batch_size = 128: 128, 128,
  // 4). true: the same ceil(n / batch_size) minibatches, of near-equal sizes (87, 87, 86): no
  // optimiser step on a handful of samples (BatchSizes).
  bool even_batches = false;
  int patience = 0;      // stop after this many epochs in a row without a better score
                         // (0: never)
  // Cosine decay of the learning rate from learning_rate (epoch 1) to final_learning_rate (the
  // last epoch), given to TrainingSteps::set_learning_rate when that is set.
  double learning_rate = 0.0;
  double final_learning_rate = 0.0;
  std::string name = "training";  // names the trainer in errors ("cbf::TrainBarrier")

  /// Throws secure::Error naming the field and value.
  void Validate() const;
};

/// The sizes of one epoch's minibatches, in order: ceil(num_samples / batch_size) of them; with
/// even_batches the first num_samples % count have one sample more than the others, else all
/// but the last have batch_size. Empty when num_samples is 0.
std::vector<long> BatchSizes(long num_samples, int batch_size, bool even_batches);

/// The learning rate of epoch `epoch` (1-based) of `max_epochs`:
/// final + 0.5 (initial - final) (1 + cos(pi p)), p = (epoch - 1) / max(1, max_epochs - 1).
double CosineLearningRate(double initial, double final_rate, int epoch, int max_epochs);

/// What on_epoch sees after an epoch (after the best checkpoint was updated).
template <class Score>
struct EpochReport {
  int epoch = 0;                 // 1-based
  double train_loss = 0.0;       // mean minibatch loss, weighted by minibatch size
  const Score* score = nullptr;  // this epoch's evaluation
  const Score* best = nullptr;   // the best so far (== *score when improved); the baseline if
                                 // no epoch has beaten it
  int best_epoch = 0;            // 0: no epoch has beaten the baseline
  bool improved = false;         // this epoch became the best
};

template <class Score>
struct TrainingSteps {
  /// Optional: applies the epoch's learning rate (CosineLearningRate) before its minibatches.
  std::function<void(double learning_rate)> set_learning_rate;
  /// One optimiser step on the samples indices[0 .. count); returns the minibatch's mean loss.
  std::function<double(const std::int64_t* indices, long count)> train_batch;
  /// The score of the current weights after epoch `epoch` (e.g. on the validation split).
  std::function<Score(int epoch)> evaluate;
  /// Whether `candidate` is better than `best`.
  std::function<bool(const Score& candidate, const Score& best)> better;
  /// Optional: a score the first epochs must beat to become the best (its weights are the
  /// caller's initial checkpoint). Without one, epoch 1 is always the best so far.
  std::optional<Score> baseline;
  /// Checkpoint the current weights as the best / load that checkpoint (once, at the end).
  std::function<void()> save_best;
  std::function<void()> restore_best;
  /// Optional: called after every epoch.
  std::function<EpochDecision(const EpochReport<Score>&)> on_epoch;
};

struct TrainingLoopResult {
  int epochs = 0;      // epochs run
  int best_epoch = 0;  // 1-based epoch whose weights were restored (0: the baseline's)
  long steps = 0;      // optimiser steps (train_batch calls)
  StopReason stop_reason = StopReason::kMaxEpochs;
};

namespace internal {
[[noreturn]] void ThrowTrainingAborted(const TrainingLoopOptions& options, int epoch);
[[noreturn]] void ThrowMissingStep(const TrainingLoopOptions& options, const char* step);
}  // namespace internal

/// Runs the loop (see the top of this file). `rng` continues the caller's stream (e.g. after
/// its validation split). Exceptions of the steps propagate.
/// @throws secure::Error on invalid options, a missing required step, or an abort by on_epoch
///   ("cbf::TrainBarrier: aborted by the epoch callback after epoch 3 of 10").
template <class Score>
TrainingLoopResult RunTrainingLoop(const TrainingLoopOptions& options, Rng& rng,
                                   const TrainingSteps<Score>& steps) {
  options.Validate();
  if (!steps.train_batch) internal::ThrowMissingStep(options, "train_batch");
  if (!steps.evaluate) internal::ThrowMissingStep(options, "evaluate");
  if (!steps.better) internal::ThrowMissingStep(options, "better");
  if (!steps.save_best) internal::ThrowMissingStep(options, "save_best");
  if (!steps.restore_best) internal::ThrowMissingStep(options, "restore_best");

  TrainingLoopResult result;
  std::optional<Score> best = steps.baseline;
  int epochs_since_best = 0;
  const long n = options.num_samples;
  std::vector<std::int64_t> order(static_cast<std::size_t>(n));
  std::iota(order.begin(), order.end(), std::int64_t{0});
  const std::vector<long> batches = BatchSizes(n, options.batch_size, options.even_batches);
  for (int epoch = 1; epoch <= options.max_epochs; ++epoch) {
    if (steps.set_learning_rate)
      steps.set_learning_rate(CosineLearningRate(options.learning_rate, options.final_learning_rate,
                                                 epoch, options.max_epochs));
    Shuffle(order.begin(), order.end(), rng);
    double epoch_loss = 0.0;
    long first = 0;
    for (const long m : batches) {
      epoch_loss += steps.train_batch(order.data() + first, m) * static_cast<double>(m);
      first += m;
      ++result.steps;
    }
    epoch_loss /= static_cast<double>(n);
    result.epochs = epoch;

    const Score score = steps.evaluate(epoch);
    const bool improved = !best.has_value() || steps.better(score, *best);
    if (improved) {
      best = score;
      steps.save_best();
      result.best_epoch = epoch;
      epochs_since_best = 0;
    } else {
      ++epochs_since_best;
    }
    if (steps.on_epoch) {
      EpochReport<Score> report;
      report.epoch = epoch;
      report.train_loss = epoch_loss;
      report.score = &score;
      report.best = &*best;
      report.best_epoch = result.best_epoch;
      report.improved = improved;
      const EpochDecision decision = steps.on_epoch(report);
      if (decision == EpochDecision::kAbort) internal::ThrowTrainingAborted(options, epoch);
      if (decision == EpochDecision::kStop) {
        result.stop_reason = StopReason::kCallback;
        break;
      }
    }
    if (options.patience > 0 && epochs_since_best >= options.patience) {
      result.stop_reason = StopReason::kEarlyStopping;
      break;
    }
  }
  steps.restore_best();
  return result;
}

}  // namespace secure::nn
