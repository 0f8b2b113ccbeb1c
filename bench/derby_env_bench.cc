// Demolition Derby environment throughput (secure::domains::derby::DerbyEnv), one thread.
//
// BM_DerbyEnvStep: Step() with a fixed action, Reset() every max_steps steps (its cost, mostly
// generating 16 car trajectories of 105 frames, amortised over the episode, as in evaluation
// and AIRL rollouts). items_per_second = env steps per second.
// BM_DerbyShieldModel: the shield's look-ahead model on M = 64 actions (items = predictions).
// BM_DerbyDemonstrations: GenerateDerbyDemonstrations(1000 episodes) once per iteration
// (seconds per run; counter episodes_per_second).
//
//   derby_env_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true

#include <benchmark/benchmark.h>

#include <Eigen/Core>

#include "secure/common/rng.h"
#include "domains/derby/derby.h"
#include "domains/derby/expert.h"

namespace secure::domains::derby {
namespace {

void BM_DerbyEnvStep(benchmark::State& state) {
  DerbyEnv env;
  Rng rng(1);
  Eigen::VectorXf obs(kObservationDim);
  const Eigen::Vector2f action(0.7f, 0.6f);
  env.Reset(rng, obs);
  int t = 0;
  for (auto _ : state) {
    if (t == env.max_steps()) {
      env.Reset(rng, obs);
      t = 0;
    }
    const StepOutcome out = env.Step(action, obs);
    benchmark::DoNotOptimize(out);
    benchmark::DoNotOptimize(obs.data());
    ++t;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_DerbyEnvStep);

void BM_DerbyShieldModel(benchmark::State& state) {
  DerbyEnv env;
  Rng rng(1);
  Eigen::VectorXf obs(kObservationDim);
  env.Reset(rng, obs);
  const int m = static_cast<int>(state.range(0));
  const Eigen::MatrixXf actions = Eigen::MatrixXf::Random(2, m) * 4.0f;
  Eigen::MatrixXf next(kObservationDim, m);
  for (auto _ : state) {
    env.ShieldModel().Step(obs, actions, next);
    benchmark::DoNotOptimize(next.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * m);
}
BENCHMARK(BM_DerbyShieldModel)->Arg(64);

void BM_DerbyDemonstrations(benchmark::State& state) {
  DerbyDemonstrationOptions demo;
  demo.episodes = state.range(0);
  long kept = 0;
  for (auto _ : state) {
    const DerbyDemonstrations d = GenerateDerbyDemonstrations({}, {}, demo);
    kept += d.trajectories.num_episodes();
    state.counters["kept_fraction"] =
        static_cast<double>(d.trajectories.num_episodes()) / static_cast<double>(d.attempted);
  }
  state.counters["episodes_per_second"] =
      benchmark::Counter(static_cast<double>(kept), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_DerbyDemonstrations)->Arg(1000)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace
}  // namespace secure::domains::derby
