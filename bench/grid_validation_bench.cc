// The paper's Table 1 validation: one pass of cbf::ValidateOnGrid over the 9,000,000-state
// double-integrator grid (100 x 100 x 30 x 30), for a DI-sized barrier net (4-64-64-64-1 tanh,
// random weights: the cost does not depend on them) with 1 and 2 worker threads.
//
// One iteration is one full pass (seconds); run with --benchmark_repetitions=N for a spread.
// Real time is measured (the workers are threads of ValidateOnGrid, not of the benchmark).
//
// Counters:
//   seconds           wall time of one full-grid validation.
//   items_per_second  grid states validated per second.
//   states            grid size (9e6), and the confusion counts of the last pass as a check that
//                     every state was counted (they do not depend on the thread count).
//
// GridValidation/GroundTruth times the same pass with the analytic ground truth as the "barrier":
// the cost of everything except the network (grid fill, double-precision truth, counting).

#include <benchmark/benchmark.h>

#include <memory>
#include <string>

#include "bench/bench_nets.h"
#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/validation.h"
#include "domains/double_integrator/double_integrator.h"
#include "secure/nn/mlp.h"

namespace secure::bench {
namespace {

namespace di = domains::double_integrator;

cbf::BarrierNet MakeDoubleIntegratorNet() {
  cbf::BarrierNet net;
  net.mlp = nn::RandomMlpParams(DoubleIntegratorSpec(), /*seed=*/7);
  // The normaliser a net trained on the state box would carry (uniform box: std = width/sqrt(12)).
  net.normalizer.mean.resize(di::kStateDim);
  net.normalizer.mean << 5.0f, 5.0f, 0.0f, 0.0f;
  net.normalizer.scale.resize(di::kStateDim);
  net.normalizer.scale << 2.8868f, 2.8868f, 0.86603f, 0.86603f;
  net.features = di::StateFeatures();
  net.Validate("benchmark net");
  return net;
}

void ReportGrid(benchmark::State& state, const di::Grid& grid, const cbf::Confusion& c) {
  const double states = static_cast<double>(grid.size());
  state.SetItemsProcessed(state.iterations() * grid.size());
  state.counters["seconds"] = benchmark::Counter(
      1.0, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["states"] = states;
  state.counters["counted"] = static_cast<double>(c.total());
  state.counters["unsafe_as_safe"] = static_cast<double>(c.unsafe_as_safe);
  state.counters["safe_as_unsafe"] = static_cast<double>(c.safe_as_unsafe);
}

// One full-grid pass per iteration with state.range(0) worker threads (the other options the
// defaults) and the barrier from `make_barrier(truth)` (one per worker); the counters, and
// `label`.
template <typename MakeBarrier>
void RunGridValidation(benchmark::State& state, MakeBarrier&& make_barrier,
                       const std::string& label) {
  const di::GroundTruth truth;
  const di::Grid grid;
  cbf::GridValidationOptions options;
  options.threads = static_cast<int>(state.range(0));
  cbf::Confusion c;
  for (auto _ : state) {
    c = di::ValidateAgainstGroundTruth([&] { return make_barrier(truth); }, truth, grid, options);
    benchmark::DoNotOptimize(c);
  }
  ReportGrid(state, grid, c);
  state.SetLabel(label);
}

// state.range(0): worker threads.
void BM_GridValidation_Net(benchmark::State& state) {
  const cbf::BarrierNet net = MakeDoubleIntegratorNet();
  RunGridValidation(state, [&](const di::GroundTruth&) { return net.MakeEvaluator(); },
                    Describe(net.mlp.spec) + ", chunk " +
                        std::to_string(cbf::GridValidationOptions{}.chunk));
}
BENCHMARK(BM_GridValidation_Net)
    ->ArgName("threads")
    ->Arg(1)
    ->Arg(2)
    ->Iterations(1)
    ->UseRealTime()
    ->Unit(benchmark::kSecond);

void BM_GridValidation_GroundTruth(benchmark::State& state) {
  RunGridValidation(
      state,
      [](const di::GroundTruth& truth) { return std::make_unique<di::GroundTruthBarrier>(truth); },
      "analytic ground truth (no network)");
}
BENCHMARK(BM_GridValidation_GroundTruth)
    ->ArgName("threads")
    ->Arg(1)
    ->Iterations(1)
    ->UseRealTime()
    ->Unit(benchmark::kSecond);

}  // namespace
}  // namespace secure::bench
