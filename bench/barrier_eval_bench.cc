// Batched barrier evaluation h(s) with the inference path (nn::InferenceMlp), the kernel behind
// the shield and the grid validation, for the three network sizes secure uses, with the default
// LIBXSMM layer products and, for comparison in the same run, Eigen's GEMM (the *_eigen cases).
//
// Counters:
//   GFLOPS        2 * MultiplyAddsPerSample * states / time, in units of 1e9 FLOP/s (compare with
//                 peak_bench's single-core sgemm figure). Activations and biases are not counted.
//   us_per_state  time per evaluated state, in microseconds.
//   states        network inputs per Forward() call (for Derby: M x 12 obstacles).
//   items_per_second  states per second.
//
// The model and its workspace are built before the timed loop; Forward() itself allocates no
// buffers (Eigen's GEMM packing buffers come from the stack, see nn/inference_mlp.h).

#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <string>

#include "bench/bench_nets.h"
#include "secure/nn/inference_mlp.h"
#include "secure/nn/mlp.h"

namespace secure::bench {
namespace {

enum class Net { kDoubleIntegrator, kDerby, kPanda };

nn::MlpSpec SpecOf(Net net) {
  switch (net) {
    case Net::kDoubleIntegrator:
      return DoubleIntegratorSpec();
    case Net::kDerby:
      return DerbySpec();
    case Net::kPanda:
      return PandaSpec();
  }
  return {};
}

// state.range(0) is the batch of states, except for Derby where it is the number of agent states
// M and the network sees M x kDerbyObstacles inputs.
void BM_BarrierEval(benchmark::State& state, Net net, nn::MatmulBackend backend) {
  const nn::MlpSpec spec = SpecOf(net);
  const int batch = static_cast<int>(state.range(0)) * (net == Net::kDerby ? kDerbyObstacles : 1);
  const nn::MlpParams params = nn::RandomMlpParams(spec, /*seed=*/42);
  const nn::InferenceMlp mlp(params, nn::Normalizer::Identity(spec.input_dim), backend);
  nn::InferenceMlp::Workspace workspace = mlp.MakeWorkspace(batch);
  Eigen::MatrixXf inputs = Eigen::MatrixXf::Random(spec.input_dim, batch);  // uniform [-1, 1]
  Eigen::MatrixXf outputs(spec.output_dim, batch);

  for (int i = 0; i < 10; ++i) mlp.Forward(inputs, workspace, outputs);  // warm caches

  for (auto _ : state) {
    mlp.Forward(inputs, workspace, outputs);
    benchmark::DoNotOptimize(outputs.data());
    benchmark::ClobberMemory();
  }

  const double macs = static_cast<double>(spec.MultiplyAddsPerSample());
  state.counters["GFLOPS"] =
      benchmark::Counter(2.0 * macs * batch * 1e-9, benchmark::Counter::kIsIterationInvariantRate,
                         benchmark::Counter::kIs1000);
  state.counters["us_per_state"] = benchmark::Counter(
      batch * 1e-6, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["states"] = batch;
  state.SetItemsProcessed(state.iterations() * batch);
  state.SetLabel(Describe(spec) + ", " + std::to_string(spec.MultiplyAddsPerSample()) +
                 " MAC/state, " + ToString(nn::kMatmulBackendNames, mlp.backend()));
}

constexpr nn::MatmulBackend kDefault = nn::MatmulBackend::kAuto;
constexpr nn::MatmulBackend kEigen = nn::MatmulBackend::kEigen;
BENCHMARK_CAPTURE(BM_BarrierEval, DI, Net::kDoubleIntegrator, kDefault)
    ->ArgName("batch")->Arg(1)->Arg(2)->Arg(6)->Arg(64)->Arg(128)->Arg(1024)->Arg(4096);
BENCHMARK_CAPTURE(BM_BarrierEval, DI_eigen, Net::kDoubleIntegrator, kEigen)
    ->ArgName("batch")->Arg(1)->Arg(2)->Arg(6)->Arg(64)->Arg(128)->Arg(1024)->Arg(4096);
// Derby: M agent states x 12 obstacles; M = 1 is one shield step, M = 64, 128 the batched cases
// (768 and 1536 network inputs).
BENCHMARK_CAPTURE(BM_BarrierEval, Derby, Net::kDerby, kDefault)->ArgName("M")->Arg(1)->Arg(2)->Arg(6)->Arg(64)->Arg(128);
BENCHMARK_CAPTURE(BM_BarrierEval, Derby_eigen, Net::kDerby, kEigen)
    ->ArgName("M")->Arg(1)->Arg(2)->Arg(6)->Arg(64)->Arg(128);
BENCHMARK_CAPTURE(BM_BarrierEval, Panda, Net::kPanda, kDefault)
    ->ArgName("batch")->Arg(1)->Arg(2)->Arg(6)->Arg(64)->Arg(128)->Arg(1024)->Arg(4096);
BENCHMARK_CAPTURE(BM_BarrierEval, Panda_eigen, Net::kPanda, kEigen)
    ->ArgName("batch")->Arg(1)->Arg(2)->Arg(6)->Arg(64)->Arg(128)->Arg(1024)->Arg(4096);

}  // namespace
}  // namespace secure::bench
