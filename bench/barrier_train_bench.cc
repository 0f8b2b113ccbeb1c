// One Table-1 training run: sample 800 safe + 800 unsafe double-integrator states (seed 0) and
// train a barrier with cbf::DoubleIntegratorTrainerPreset(), the settings `secure cbf table1` uses
// (4-64-64-64-1 tanh, Adam, 200 epochs, batch 128, one LibTorch thread). Sampling is done once,
// outside the timed region.
//
// One iteration is one full training run; run with --benchmark_repetitions=N for a spread.
//
// Counters:
//   seconds          wall time of TrainBarrier (as timed by the benchmark).
//   train_seconds    the trainer's own wall_seconds (summary).
//   epochs           epochs run; best_epoch the one kept; steps the optimizer steps.
//   steps_per_second optimizer steps per second of benchmark time.
//   train_accuracy   balanced training accuracy of the kept weights (a sanity check; the preset
//                    holds out no validation split).

#include <benchmark/benchmark.h>

#include "secure/cbf/barrier_net.h"
#include "secure/cbf/barrier_trainer.h"
#include "domains/double_integrator/table1.h"
#include "domains/double_integrator/double_integrator.h"

namespace secure::bench {
namespace {

namespace di = domains::double_integrator;

void BM_BarrierTrain_Table1(benchmark::State& state) {
  constexpr std::uint64_t kSeed = 0;
  const cbf::DoubleIntegratorData data =
      cbf::SampleDoubleIntegratorData(di::GroundTruth{}, di::StateBox{}, 800, 800, kSeed);
  cbf::BarrierTrainerOptions options = cbf::DoubleIntegratorTrainerPreset();  // as in Table 1
  options.seed = kSeed;
  cbf::BarrierTrainingSummary summary;
  for (auto _ : state) {
    cbf::BarrierNet net = cbf::TrainBarrier(options, data.safe, data.unsafe, &summary);
    benchmark::DoNotOptimize(net);
  }
  state.counters["seconds"] = benchmark::Counter(
      1.0, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["train_seconds"] = summary.wall_seconds;
  state.counters["epochs"] = summary.epochs;
  state.counters["best_epoch"] = summary.best_epoch;
  state.counters["steps"] = static_cast<double>(summary.iterations);
  state.counters["steps_per_second"] = benchmark::Counter(
      static_cast<double>(summary.iterations), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["train_accuracy"] = summary.train_accuracy.Balanced();
  state.SetLabel("stop: " + summary.stop_reason);
}
BENCHMARK(BM_BarrierTrain_Table1)->Iterations(1)->UseRealTime()->Unit(benchmark::kSecond);

}  // namespace
}  // namespace secure::bench
