// One active-query round (cbf::SelectQueries, secure/cbf/query.h) over a pool of N unlabelled
// states, single thread: the barrier forwards over the whole pool (batched InferenceMlp, chunks
// of 1024) and the selection of k = 50. Issue 35's target: <= 1 s for margin and ensemble
// disagreement at N = 100,000 on one core (label-efficiency's ensemble is K = 3; K = 2 and 5
// shown beside it). The diversity cases (k-centre, and margin with
// a radius) show what the O(N k d) batch selection adds.
//
// Counters: us_per_state (time per pool state), states.

#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <memory>
#include <vector>

#include "bench/bench_nets.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/query.h"

namespace secure::bench {
namespace {

cbf::BarrierNet Net(const nn::MlpSpec& spec, unsigned long long seed) {
  cbf::BarrierNet net;
  net.mlp = nn::RandomMlpParams(spec, seed);
  net.normalizer = nn::Normalizer::Identity(spec.input_dim);
  for (int i = 0; i < spec.input_dim; ++i) net.features.push_back("f" + std::to_string(i));
  return net;
}

void BM_QueryRound(benchmark::State& state, cbf::QueryStrategy strategy, int members,
                   double radius, bool panda) {
  const nn::MlpSpec spec = panda ? PandaSpec() : DoubleIntegratorSpec();
  const long n = state.range(0);
  std::vector<cbf::BarrierNet> nets;
  std::vector<std::unique_ptr<cbf::Barrier>> evaluators;
  std::vector<cbf::Barrier*> barriers;
  for (int m = 0; m < members; ++m) {
    nets.push_back(Net(spec, 42 + m));
    evaluators.push_back(nets.back().MakeEvaluator());
    barriers.push_back(evaluators.back().get());
  }
  const Eigen::MatrixXf pool = Eigen::MatrixXf::Random(spec.input_dim, n);
  cbf::QueryOptions options;
  options.strategy = strategy;
  options.k = 50;
  options.diversity_radius = radius;
  for (auto _ : state) {
    cbf::QueryResult r = cbf::SelectQueries(barriers, pool, options);
    benchmark::DoNotOptimize(r.indices.data());
  }
  state.counters["us_per_state"] = benchmark::Counter(
      static_cast<double>(n) * 1e-6, benchmark::Counter::kIsIterationInvariantRate |
                                         benchmark::Counter::kInvert);
  state.counters["states"] = static_cast<double>(n);
}

// The pool forward alone (EvaluatePool) of one Panda net over 100,000 states, by chunk (the
// evaluator's workspace and EvaluatePool's chunk): whether the 4096-state chunk's activations
// (up to 256 x 4096 floats, 4 MiB per layer) cost against chunks that stay in cache.
void BM_PandaPoolForwardByChunk(benchmark::State& state) {
  const nn::MlpSpec spec = PandaSpec();
  const long n = 100000;
  const int chunk = static_cast<int>(state.range(0));
  const cbf::BarrierNet net = Net(spec, 42);
  std::unique_ptr<cbf::Barrier> evaluator = net.MakeEvaluator(chunk);
  std::vector<cbf::Barrier*> barriers{evaluator.get()};
  const Eigen::MatrixXf pool = Eigen::MatrixXf::Random(spec.input_dim, n);
  for (auto _ : state) {
    Eigen::MatrixXf h = cbf::EvaluatePool(barriers, pool, chunk);
    benchmark::DoNotOptimize(h.data());
  }
  state.counters["us_per_state"] = benchmark::Counter(
      static_cast<double>(n) * 1e-6, benchmark::Counter::kIsIterationInvariantRate |
                                         benchmark::Counter::kInvert);
}

BENCHMARK(BM_PandaPoolForwardByChunk)->Arg(256)->Arg(1024)->Arg(4096)->Unit(benchmark::kMillisecond);

BENCHMARK_CAPTURE(BM_QueryRound, margin_di, cbf::QueryStrategy::kMargin, 1, 0.0, false)
    ->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_QueryRound, disagreement5_di, cbf::QueryStrategy::kDisagreement, 5, 0.0,
                  false)
    ->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_QueryRound, margin_radius_di, cbf::QueryStrategy::kMargin, 1, 0.1, false)
    ->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_QueryRound, diversity_di, cbf::QueryStrategy::kDiversity, 0, 0.0, false)
    ->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_QueryRound, margin_panda, cbf::QueryStrategy::kMargin, 1, 0.0, true)
    ->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_QueryRound, disagreement5_panda, cbf::QueryStrategy::kDisagreement, 5, 0.0,
                  true)
    ->Arg(100000)->Unit(benchmark::kMillisecond);
// The Panda ensembles that fit one core's second (K = 5 needs about twice its FP32 peak).
BENCHMARK_CAPTURE(BM_QueryRound, disagreement2_panda, cbf::QueryStrategy::kDisagreement, 2, 0.0,
                  true)
    ->Arg(100000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_QueryRound, disagreement3_panda, cbf::QueryStrategy::kDisagreement, 3, 0.0,
                  true)
    ->Arg(100000)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace secure::bench
