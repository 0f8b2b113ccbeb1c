// The per-car barrier (cbf::CarBarrierNet, released 3-64-128-64-1 ReLU) evaluated through its
// Eigen evaluator on shield-sized batches of Demolition Derby observations (52 values, 12 cars):
// feature gather + one InferenceMlp forward over all in-range cars + per-state min.
//
// Scenes:
//   all_in_range  every car within the sensing radius (12 network inputs per state: worst case)
//   typical       cars uniform in a 3 x 3 square around the ego (~ 30 % within R = 1: the
//                 gather skips the rest)
// Counters:
//   us_per_call   time per Evaluate() of the whole batch, microseconds
//   cars_per_state  in-range cars per state, i.e. network inputs per state
//
// The evaluator is built before the timed loop; Evaluate() allocates nothing.

#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "domains/derby/domain.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/rng.h"
#include "secure/nn/mlp.h"
#include "tests/cbf/synthetic_derby_observations.h"

namespace secure::bench {
namespace {

Eigen::MatrixXf Observations(int n, double half_width, std::uint64_t seed) {
  Rng rng(seed);
  Eigen::MatrixXf obs(test::kObs, n);
  for (int i = 0; i < n; ++i) {
    const auto draw_car = [&](int) -> test::SyntheticCar {
      return {static_cast<float>(rng.Uniform(-half_width, half_width)),
              static_cast<float>(rng.Uniform(-half_width, half_width)),
              static_cast<float>(rng.Uniform(-0.5, 0.5)), static_cast<float>(rng.Uniform(-0.5, 0.5))};
    };
    test::WriteSyntheticObservation(rng, draw_car, obs.col(i));
  }
  return obs;
}

void BM_CarBarrier(benchmark::State& state, bool all_in_range) {
  const int m = static_cast<int>(state.range(0));
  cbf::CarBarrierNet net;
  net.input.layout = secure::domains::derby::ObstacleLayoutOfObservation();
  net.mlp = nn::RandomMlpParams({3, {64, 128, 64}, 1, nn::Activation::kRelu}, 42);
  net.normalizer = nn::Normalizer::Identity(3);
  // all in range: |dx|, |dy| <= 0.7 gives d <= 0.99 < R.
  const Eigen::MatrixXf obs = Observations(m, all_in_range ? 0.7 : 1.5, 7);
  auto evaluator = std::make_unique<cbf::CarBarrierEvaluator>(net, m);
  Eigen::VectorXf h(m);
  for (int i = 0; i < 10; ++i) evaluator->Evaluate(obs, h);
  for (auto _ : state) {
    evaluator->Evaluate(obs, h);
    benchmark::DoNotOptimize(h.data());
    benchmark::ClobberMemory();
  }
  state.counters["us_per_call"] = benchmark::Counter(
      1e-6, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["cars_per_state"] =
      static_cast<double>(evaluator->last_entries()) / static_cast<double>(m);
  state.SetItemsProcessed(state.iterations() * m);
  state.SetLabel(net.Describe());
}

BENCHMARK_CAPTURE(BM_CarBarrier, all_in_range, true)->ArgName("M")->Arg(1)->Arg(64)->Arg(128);
BENCHMARK_CAPTURE(BM_CarBarrier, typical, false)->ArgName("M")->Arg(1)->Arg(64)->Arg(128);

}  // namespace
}  // namespace secure::bench
