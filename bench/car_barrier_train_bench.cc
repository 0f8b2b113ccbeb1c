// Per-car barrier training (cbf::TrainCarBarrier, LibTorch, one thread) on synthetic Demolition
// Derby observations, for a few optimisation settings: the released constants, our defaults,
// and one change to the defaults each. Each case is one training run, timed, with the held-out
// accuracy of what it trained as counters: the time and the accuracy together are what decides
// between settings (secure/cbf/README.md quotes both).
//
// Data (generated once, outside the timed region): 1024 safe + 1024 near-dangerous training
// observations (seeds 21, 22) and 2000 + 2000 held-out ones (seeds 23, 24), 52 values each
// (ego 4, then 12 cars x (dx, dy, dvx, dvy), nearest first). A harder variant than the unit
// tests' data, with overlapping classes: safe = every car farther than 0.12; near-dangerous = the
// nearest car within 0.14, the others farther than 0.12.
//
// Cases:
//   released          CarBarrierTrainerOptions::Released() (512 updates of 4 states)
//   defaults          CarBarrierTrainerOptions{} (lr 3e-3 cosine, batch 128, 30 epochs, margins
//                     0.05, best of a 10 % validation split)
//   epochs_10         defaults, max_epochs 10
//   lr_1e-3           defaults, learning_rate 1e-3, final_learning_rate 1e-5
//   batch_64          defaults, batch_size 64
//   no_normalisation  defaults, normalize_inputs false
//   margins_0.01      defaults, safe_margin = danger_margin = 0.01
//   use_velocity      defaults, input.use_velocity true
//
// Counters:
//   seconds              wall time of TrainCarBarrier (benchmark real time).
//   train_seconds        the trainer's own wall_seconds (summary).
//   epochs, best_epoch   epochs run and the one kept.
//   heldout_safe, heldout_nd        held-out per-state accuracy (safe / near-dangerous).
//   entries_safe, entries_danger    held-out per-entry (per-car) accuracy.

#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "domains/derby/domain.h"
#include "secure/cbf/car_barrier_trainer.h"
#include "secure/common/rng.h"
#include "tests/cbf/synthetic_derby_observations.h"

namespace secure::bench {
namespace {

using cbf::CarBarrierTrainerOptions;

using test::Synthetic;

struct Data {
  data::StateSet safe, nd, test_safe, test_nd;
};

const Data& SweepData() {
  static const Data d{Synthetic(false, 1024, 21, 0.12), Synthetic(true, 1024, 22, 0.12),
                      Synthetic(false, 2000, 23, 0.12), Synthetic(true, 2000, 24, 0.12)};
  return d;
}

CarBarrierTrainerOptions Released() { return CarBarrierTrainerOptions::Released(); }
CarBarrierTrainerOptions Defaults() { return {}; }
CarBarrierTrainerOptions Epochs10() {
  CarBarrierTrainerOptions o;
  o.max_epochs = 10;
  return o;
}
CarBarrierTrainerOptions Lr1e3() {
  CarBarrierTrainerOptions o;
  o.learning_rate = 1e-3;
  o.final_learning_rate = 1e-5;
  return o;
}
CarBarrierTrainerOptions Batch64() {
  CarBarrierTrainerOptions o;
  o.batch_size = 64;
  return o;
}
CarBarrierTrainerOptions NoNormalisation() {
  CarBarrierTrainerOptions o;
  o.normalize_inputs = false;
  return o;
}
CarBarrierTrainerOptions Margins001() {
  CarBarrierTrainerOptions o;
  o.safe_margin = 0.01;
  o.danger_margin = 0.01;
  return o;
}
CarBarrierTrainerOptions UseVelocity() {
  CarBarrierTrainerOptions o;
  o.input.use_velocity = true;
  return o;
}

void BM_CarBarrierTrain(benchmark::State& state, CarBarrierTrainerOptions (*make)()) {
  const Data& d = SweepData();
  // The synthetic data has the Demolition Derby observation layout (the plug-in gives it).
  CarBarrierTrainerOptions options = make();
  options.input.layout = domains::derby::ObstacleLayoutOfObservation();
  cbf::CarBarrierTrainingSummary summary;
  cbf::CarBarrierNet net;
  for (auto _ : state) {
    net = cbf::TrainCarBarrier(options, d.safe, d.nd, &summary);
    benchmark::DoNotOptimize(net);
  }
  const cbf::CarBarrierAccuracy test = cbf::EvaluateCarBarrier(net, d.test_safe, d.test_nd);
  state.counters["seconds"] = benchmark::Counter(
      1.0, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["train_seconds"] = summary.wall_seconds;
  state.counters["epochs"] = summary.epochs;
  state.counters["best_epoch"] = summary.best_epoch;
  state.counters["heldout_safe"] = test.states.safe;
  state.counters["heldout_nd"] = test.states.near_dangerous;
  state.counters["entries_safe"] = test.entries.safe;
  state.counters["entries_danger"] = test.entries.near_dangerous;
  state.SetLabel("stop: " + summary.stop_reason);
}

#define SECURE_CAR_BARRIER_CASE(name, make)         \
  BENCHMARK_CAPTURE(BM_CarBarrierTrain, name, make) \
      ->Iterations(1)                               \
      ->UseRealTime()                               \
      ->Unit(benchmark::kSecond)

// clang-format would split the names lr_1e-3 and margins_0.01.
// clang-format off
SECURE_CAR_BARRIER_CASE(released, Released);
SECURE_CAR_BARRIER_CASE(defaults, Defaults);
SECURE_CAR_BARRIER_CASE(epochs_10, Epochs10);
SECURE_CAR_BARRIER_CASE(lr_1e-3, Lr1e3);
SECURE_CAR_BARRIER_CASE(batch_64, Batch64);
SECURE_CAR_BARRIER_CASE(no_normalisation, NoNormalisation);
SECURE_CAR_BARRIER_CASE(margins_0.01, Margins001);
SECURE_CAR_BARRIER_CASE(use_velocity, UseVelocity);
// clang-format on

}  // namespace
}  // namespace secure::bench
