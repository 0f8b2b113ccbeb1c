#include "secure/nn/training_loop.h"
#include "tests/test_util.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

#include "secure/common/error.h"
#include "secure/common/rng.h"

namespace secure::nn {
namespace {

using secure::test::ErrorOf;

// A fake trainer: the "weights" are the number of the last epoch trained, the score of epoch e
// is scores[e - 1] (lower is better), and every call is recorded.
struct Fake {
  std::vector<double> scores;
  int weights = 0;      // epoch whose minibatches ran last
  int checkpoint = -1;  // weights saved by save_best (-1: never)
  int saves = 0, restores = 0;
  std::vector<std::vector<std::vector<std::int64_t>>> batches;  // [epoch][batch] -> indices
  std::vector<double> learning_rates;
  std::vector<int> reported_best_epochs;

  TrainingSteps<double> Steps() {
    TrainingSteps<double> s;
    s.set_learning_rate = [this](double lr) {
      learning_rates.push_back(lr);
      batches.emplace_back();
      ++weights;
    };
    s.train_batch = [this](const std::int64_t* idx, long m) {
      batches.back().emplace_back(idx, idx + m);
      return static_cast<double>(m);  // the epoch loss is then sum(m^2) / n
    };
    s.evaluate = [this](int epoch) {
      EXPECT_EQ(epoch, weights);
      return scores.at(static_cast<std::size_t>(epoch - 1));
    };
    s.better = [](double a, double b) { return a < b; };
    s.save_best = [this] {
      checkpoint = weights;
      ++saves;
    };
    s.restore_best = [this] {
      weights = checkpoint;
      ++restores;
    };
    return s;
  }
};

TrainingLoopOptions Options(int max_epochs, long n, int batch_size, int patience = 0) {
  TrainingLoopOptions o;
  o.max_epochs = max_epochs;
  o.num_samples = n;
  o.batch_size = batch_size;
  o.patience = patience;
  o.learning_rate = 1e-2;
  o.final_learning_rate = 1e-4;
  o.name = "test trainer";
  return o;
}

TEST(TrainingLoopTest, PatienceStopsAtTheRightEpochAndRestoresTheBest) {
  Fake f;
  f.scores = {5, 4, 3, 3.5, 3.2, 3.1, 1, 1, 1, 1};
  Rng rng(1);
  const TrainingLoopResult r = RunTrainingLoop(Options(10, 7, 3, /*patience=*/3), rng, f.Steps());
  // Epoch 3 is the best; epochs 4, 5 and 6 do not beat it: stop after epoch 6.
  EXPECT_EQ(r.epochs, 6);
  EXPECT_EQ(r.best_epoch, 3);
  EXPECT_EQ(r.stop_reason, StopReason::kEarlyStopping);
  EXPECT_STREQ(ToString(r.stop_reason), "early_stopping");
  EXPECT_EQ(r.steps, 6 * 3);  // batches of 3, 3, 1
  EXPECT_EQ(f.saves, 3);
  EXPECT_EQ(f.restores, 1);
  EXPECT_EQ(f.weights, 3);  // the best epoch's weights are restored
}

TEST(TrainingLoopTest, WithoutPatienceRunsEveryEpochAndKeepsTheBest) {
  Fake f;
  f.scores = {5, 1, 3, 2, 4};
  Rng rng(2);
  const TrainingLoopResult r = RunTrainingLoop(Options(5, 4, 4), rng, f.Steps());
  EXPECT_EQ(r.epochs, 5);
  EXPECT_EQ(r.best_epoch, 2);
  EXPECT_EQ(r.stop_reason, StopReason::kMaxEpochs);
  EXPECT_STREQ(ToString(r.stop_reason), "max_epochs");
  EXPECT_EQ(f.weights, 2);
  EXPECT_EQ(f.restores, 1);
}

TEST(TrainingLoopTest, TiesDoNotReplaceTheBest) {
  Fake f;
  f.scores = {2, 2, 2};
  Rng rng(3);
  const TrainingLoopResult r = RunTrainingLoop(Options(3, 2, 1, 2), rng, f.Steps());
  EXPECT_EQ(r.best_epoch, 1);
  EXPECT_EQ(r.epochs, 3);
  EXPECT_EQ(r.stop_reason, StopReason::kEarlyStopping);
  EXPECT_EQ(f.weights, 1);
}

TEST(TrainingLoopTest, ABaselineNobodyBeatsKeepsTheInitialCheckpoint) {
  Fake f;
  f.scores = {NAN, 7, 8};
  f.checkpoint = 0;  // the caller's initial weights
  TrainingSteps<double> steps = f.Steps();
  steps.baseline = 6.0;
  Rng rng(4);
  const TrainingLoopResult r = RunTrainingLoop(Options(3, 3, 2), rng, steps);
  EXPECT_EQ(r.best_epoch, 0);
  EXPECT_EQ(f.saves, 0);
  EXPECT_EQ(f.restores, 1);
  EXPECT_EQ(f.weights, 0);
  // Beaten at epoch 2: that epoch is kept.
  Fake g;
  g.scores = {NAN, 5, 8};
  steps = g.Steps();
  steps.baseline = 6.0;
  EXPECT_EQ(RunTrainingLoop(Options(3, 3, 2), rng, steps).best_epoch, 2);
  EXPECT_EQ(g.weights, 2);
}

TEST(TrainingLoopTest, OnEpochSeesTheEpochAndCanStop) {
  Fake f;
  f.scores = {3, 1, 2, 0};
  TrainingSteps<double> steps = f.Steps();
  std::vector<int> epochs;
  steps.on_epoch = [&](const EpochReport<double>& r) {
    epochs.push_back(r.epoch);
    EXPECT_EQ(*r.score, f.scores[r.epoch - 1]);
    EXPECT_EQ(r.improved, r.epoch != 3);
    EXPECT_EQ(r.best_epoch, r.epoch == 3 ? 2 : r.epoch);
    EXPECT_EQ(*r.best, f.scores[r.best_epoch - 1]);
    EXPECT_DOUBLE_EQ(r.train_loss, (4.0 * 4 + 4 * 4 + 2 * 2) / 10.0);  // sizes 4, 4, 2
    return r.epoch == 3 ? EpochDecision::kStop : EpochDecision::kContinue;
  };
  Rng rng(5);
  const TrainingLoopResult r = RunTrainingLoop(Options(4, 10, 4, 1), rng, steps);
  // The callback's stop comes before the patience check of the same epoch.
  EXPECT_EQ(r.stop_reason, StopReason::kCallback);
  EXPECT_STREQ(ToString(r.stop_reason), "callback");
  EXPECT_EQ(r.epochs, 3);
  EXPECT_EQ(r.best_epoch, 2);
  EXPECT_EQ(epochs, (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(f.weights, 2);
}

TEST(TrainingLoopTest, OnEpochAbortThrowsNamingTheEpochAndRestoresNothing) {
  Fake f;
  f.scores = {3, 2, 1, 0};
  TrainingSteps<double> steps = f.Steps();
  steps.on_epoch = [](const EpochReport<double>& r) {
    return r.epoch == 3 ? EpochDecision::kAbort : EpochDecision::kContinue;
  };
  Rng rng(6);
  EXPECT_EQ(ErrorOf([&] { RunTrainingLoop(Options(10, 5, 2), rng, steps); }),
            "test trainer: aborted by the epoch callback after epoch 3 of 10");
  EXPECT_EQ(f.restores, 0);
  EXPECT_EQ(f.weights, 3);
}

TEST(TrainingLoopTest, ShufflingIsAPermutationPerEpochAndAFunctionOfTheSeed) {
  auto run = [](std::uint64_t seed) {
    Fake f;
    f.scores.assign(4, 1.0);
    Rng rng(seed);
    RunTrainingLoop(Options(4, 10, 4), rng, f.Steps());
    return f.batches;
  };
  const auto a = run(7), b = run(7), c = run(8);
  EXPECT_EQ(a, b);
  EXPECT_NE(a, c);
  ASSERT_EQ(a.size(), 4u);
  std::vector<std::int64_t> all(10);
  std::iota(all.begin(), all.end(), std::int64_t{0});
  for (const auto& epoch : a) {
    ASSERT_EQ(epoch.size(), 3u);
    EXPECT_EQ(epoch[0].size(), 4u);
    EXPECT_EQ(epoch[1].size(), 4u);
    EXPECT_EQ(epoch[2].size(), 2u);
    std::vector<std::int64_t> seen;
    for (const auto& batch : epoch) seen.insert(seen.end(), batch.begin(), batch.end());
    std::sort(seen.begin(), seen.end());
    EXPECT_EQ(seen, all);
  }
  EXPECT_NE(a[0], a[1]);  // a new order every epoch

  // The order is Fisher–Yates with the caller's stream, carried over from epoch to epoch.
  Rng rng(7);
  std::vector<std::int64_t> order(all);
  for (const auto& epoch : a) {
    Shuffle(order.begin(), order.end(), rng);
    std::vector<std::int64_t> got;
    for (const auto& batch : epoch) got.insert(got.end(), batch.begin(), batch.end());
    EXPECT_EQ(got, order);
  }
}

// Even batches: the same number of optimiser steps per epoch, none on a small remainder (the
// label-efficiency experiment's 260 labels in batches of 128 left every third step on 4 states).
TEST(TrainingLoopTest, EvenBatchesSplitTheEpochIntoNearEqualMinibatches) {
  EXPECT_EQ(BatchSizes(260, 128, false), (std::vector<long>{128, 128, 4}));
  EXPECT_EQ(BatchSizes(260, 128, true), (std::vector<long>{87, 87, 86}));
  EXPECT_EQ(BatchSizes(256, 128, true), (std::vector<long>{128, 128}));  // a multiple: unchanged
  EXPECT_EQ(BatchSizes(5, 128, true), (std::vector<long>{5}));
  EXPECT_TRUE(BatchSizes(0, 4, true).empty());
  for (long n = 1; n <= 300; ++n) {
    for (int b : {1, 3, 7, 128}) {
      const std::vector<long> even = BatchSizes(n, b, true), plain = BatchSizes(n, b, false);
      ASSERT_EQ(even.size(), plain.size()) << n << " " << b;
      EXPECT_EQ(std::accumulate(even.begin(), even.end(), 0L), n);
      const auto [lo, hi] = std::minmax_element(even.begin(), even.end());
      EXPECT_LE(*hi, b);
      EXPECT_LE(*hi - *lo, 1) << n << " " << b;
    }
  }

  auto run = [](bool even) {
    Fake f;
    f.scores.assign(3, 1.0);
    Rng rng(5);
    TrainingLoopOptions o = Options(3, 10, 4);
    o.even_batches = even;
    const TrainingLoopResult r = RunTrainingLoop(o, rng, f.Steps());
    EXPECT_EQ(r.steps, 3 * 3);
    return f.batches;
  };
  const auto even = run(true), plain = run(false);
  ASSERT_EQ(even.size(), 3u);
  for (std::size_t e = 0; e < even.size(); ++e) {
    ASSERT_EQ(even[e].size(), 3u);
    EXPECT_EQ(even[e][0].size(), 4u);  // 4, 3, 3 instead of 4, 4, 2
    EXPECT_EQ(even[e][1].size(), 3u);
    EXPECT_EQ(even[e][2].size(), 3u);
    // The same shuffled order, cut at other places.
    std::vector<std::int64_t> a, b;
    for (const auto& batch : even[e]) a.insert(a.end(), batch.begin(), batch.end());
    for (const auto& batch : plain[e]) b.insert(b.end(), batch.begin(), batch.end());
    EXPECT_EQ(a, b);
  }
}

TEST(TrainingLoopTest, CosineLearningRatePerEpoch) {
  Fake f;
  f.scores.assign(5, 1.0);
  Rng rng(9);
  RunTrainingLoop(Options(5, 3, 3), rng, f.Steps());
  ASSERT_EQ(f.learning_rates.size(), 5u);
  EXPECT_EQ(f.learning_rates.front(), 1e-2);
  EXPECT_DOUBLE_EQ(f.learning_rates[2], 0.5 * (1e-2 + 1e-4));
  EXPECT_DOUBLE_EQ(f.learning_rates.back(), 1e-4);
  for (int e = 1; e <= 5; ++e)
    EXPECT_EQ(f.learning_rates[e - 1], CosineLearningRate(1e-2, 1e-4, e, 5));
  EXPECT_EQ(CosineLearningRate(3e-3, 3e-5, 1, 1), 3e-3);  // one epoch: the initial rate
}

TEST(TrainingLoopTest, RejectsBadOptionsAndMissingSteps) {
  Fake f;
  f.scores.assign(2, 1.0);
  Rng rng(1);
  EXPECT_EQ(ErrorOf([&] { RunTrainingLoop(Options(0, 3, 1), rng, f.Steps()); }),
            "TrainingLoopOptions::max_epochs = 0, must be > 0");
  EXPECT_EQ(ErrorOf([&] { RunTrainingLoop(Options(2, 3, 0), rng, f.Steps()); }),
            "TrainingLoopOptions::batch_size = 0, must be > 0");
  EXPECT_EQ(ErrorOf([&] { RunTrainingLoop(Options(2, -1, 1), rng, f.Steps()); }),
            "TrainingLoopOptions::num_samples = -1, must be >= 0");
  EXPECT_EQ(ErrorOf([&] { RunTrainingLoop(Options(2, 3, 1, -1), rng, f.Steps()); }),
            "TrainingLoopOptions::patience = -1, must be >= 0");
  TrainingSteps<double> steps = f.Steps();
  steps.save_best = nullptr;
  EXPECT_EQ(ErrorOf([&] { RunTrainingLoop(Options(2, 3, 1), rng, steps); }),
            "test trainer: the training loop needs the step 'save_best'");
}

}  // namespace
}  // namespace secure::nn
