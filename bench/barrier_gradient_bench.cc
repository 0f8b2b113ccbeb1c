// The barrier's value and gradient at one state (cbf::Barrier::EvaluateGradient: the MLP's
// analytic backward pass; for the per-car barrier the forward over every car in range, then the
// backward pass of the active car), the cost the CBF-QP filter and the gradient-first shield pay
// per linearisation, against the same barrier's plain forward (Barrier::Evaluate) at 1 and 128
// states measured in the same process.
//
// Counters:
//   in_forwards_of_1    the gradient's time / one single-state forward (target: <= 3)
//   in_forwards_of_128  the gradient's time / one 128-state forward (the yardstick of the shield's
//                       decision latency, docs/PERFORMANCE.md)
//   forward_1_us, forward_128_us  the references, medians of 15 timed blocks
//
// Run: build/bench/barrier_gradient_bench --benchmark_repetitions=5 (docs/PERFORMANCE.md).

#include <benchmark/benchmark.h>

#include <Eigen/Core>
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "bench/bench_nets.h"
#include "secure/cbf/barrier.h"
#include "secure/cbf/barrier_net.h"
#include "secure/cbf/car_barrier.h"
#include "secure/common/rng.h"
#include "secure/common/timer.h"
#include "secure/nn/mlp.h"

namespace secure::bench {
namespace {

enum class Net { kDoubleIntegrator, kDerby, kPanda };

struct Setup {
  cbf::BarrierNet flat;
  cbf::CarBarrierNet car;
  std::unique_ptr<cbf::Barrier> barrier;
  Eigen::MatrixXf one, batch;  // 1 and 128 states
};

Setup Make(Net net) {
  Setup s;
  Rng rng(7);
  if (net == Net::kDerby) {
    // The released Derby barrier's shape (3 -> 64 -> 128 -> 64 -> 1, relu) over 12 cars, every
    // car in range (the costliest state).
    s.car.input.layout.obs_dim = 4 + 4 * kDerbyObstacles;
    s.car.input.layout.first_obstacle_offset = 4;
    s.car.input.layout.obstacle_stride = 4;
    s.car.input.layout.num_obstacles = kDerbyObstacles;
    s.car.input.layout.position_offset = 0;
    s.car.input.layout.velocity_offset = 2;
    s.car.mlp = nn::RandomMlpParams({3, {64, 128, 64}, 1, nn::Activation::kRelu}, 42);
    s.car.normalizer = nn::Normalizer::Identity(3);
    s.car.cap = 10.0;  // above every entry: the gradient path always has an active car
    s.barrier = s.car.MakeEvaluator(128);
    s.batch.resize(s.car.state_dim(), 128);
    for (int c = 0; c < 128; ++c)
      for (int r = 0; r < s.batch.rows(); ++r)
        s.batch(r, c) = static_cast<float>(rng.Uniform(-0.6, 0.6));
  } else {
    const nn::MlpSpec spec = net == Net::kPanda ? PandaSpec() : DoubleIntegratorSpec();
    s.flat.mlp = nn::RandomMlpParams(spec, 42);
    s.flat.normalizer = nn::Normalizer::Identity(spec.input_dim);
    for (int i = 0; i < spec.input_dim; ++i) s.flat.features.push_back("s" + std::to_string(i));
    s.barrier = s.flat.MakeEvaluator(128);
    s.batch.resize(spec.input_dim, 128);
    for (int c = 0; c < 128; ++c)
      for (int r = 0; r < spec.input_dim; ++r)
        s.batch(r, c) = static_cast<float>(rng.Uniform(-1.0, 1.0));
  }
  s.one = s.batch.leftCols(1);
  return s;
}

// Median over 15 blocks of the mean time of one Evaluate of `states`, in microseconds.
double ForwardMicros(cbf::Barrier& barrier, const Eigen::MatrixXf& states) {
  Eigen::VectorXf h(states.cols());
  const int reps = states.cols() == 1 ? 2000 : 50;
  for (int i = 0; i < reps; ++i) barrier.Evaluate(states, h);
  std::vector<double> blocks;
  for (int b = 0; b < 15; ++b) {
    const Stopwatch clock;
    for (int i = 0; i < reps; ++i) {
      barrier.Evaluate(states, h);
      benchmark::DoNotOptimize(h.data());
    }
    blocks.push_back(clock.Microseconds() / reps);
  }
  std::nth_element(blocks.begin(), blocks.begin() + 7, blocks.end());
  return blocks[7];
}

void BM_BarrierGradient(benchmark::State& state, Net net) {
  Setup s = Make(net);
  const double forward_1 = ForwardMicros(*s.barrier, s.one);
  const double forward_128 = ForwardMicros(*s.barrier, s.batch);
  Eigen::VectorXf h(1);
  Eigen::MatrixXf gradient(s.one.rows(), 1);
  for (int i = 0; i < 100; ++i) s.barrier->EvaluateGradient(s.one, h, gradient);
  for (auto _ : state) {
    s.barrier->EvaluateGradient(s.one, h, gradient);
    benchmark::DoNotOptimize(gradient.data());
    benchmark::ClobberMemory();
  }
  // Iteration-invariant rates inverted: seconds per iteration, divided by the reference.
  state.counters["in_forwards_of_1"] = benchmark::Counter(
      forward_1 * 1e-6, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["in_forwards_of_128"] =
      benchmark::Counter(forward_128 * 1e-6,
                         benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["forward_1_us"] = forward_1;
  state.counters["forward_128_us"] = forward_128;
  state.SetLabel(s.barrier->Describe());
}

// Wall time, as the references are timed.
BENCHMARK_CAPTURE(BM_BarrierGradient, DI, Net::kDoubleIntegrator)->UseRealTime();
BENCHMARK_CAPTURE(BM_BarrierGradient, Derby, Net::kDerby)->UseRealTime();
BENCHMARK_CAPTURE(BM_BarrierGradient, Panda, Net::kPanda)->UseRealTime();

}  // namespace
}  // namespace secure::bench
