// Panda Arm Push environment throughput (secure::domains::panda_push::PandaPushEnv, MuJoCo), one
// thread.
//
// BM_PandaPushStep: Step() of a scripted push (descend, approach, push along +x; the block slides,
// so contacts are live), Reset() every 60 steps. items_per_second = control steps per second
// (each is `substeps` physics steps plus one IK step). Arg: substeps (20 = the default 2 ms).
// BM_PandaPushShieldModel: the shield's approximate model on M = 128 actions.
// BM_PandaPushRender: one 640 x 480 frame offscreen (OSMesa, software OpenGL).
//
//   panda_push_env_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true

#include <benchmark/benchmark.h>

#include <Eigen/Core>

#include "domains/panda_push/panda_push.h"
#include "secure/common/rng.h"

namespace secure::domains::panda_push {
namespace {

Eigen::Vector3f ScriptedPush(const Eigen::VectorXf& o) {
  Eigen::Vector3f a = Eigen::Vector3f::Zero();
  if (o[kEePos + 2] > 0.035 && o[kEePos] < 0.2) {
    a[2] = -0.6f;
  } else {
    a[2] = 0.5f * (0.03f - o[kEePos + 2]) / 0.05f;
    a[0] = o[kBlockPos] - o[kEePos] > 0.11f ? 0.5f : 0.12f;
  }
  return a;
}

void BM_PandaPushStep(benchmark::State& state) {
  PandaPushOptions options;
  options.tracking.substeps = static_cast<int>(state.range(0));
  PandaPushEnv env(options, PandaPushShieldModelOptions{});
  Rng rng(1);
  Eigen::VectorXf obs(kObservationDim);
  env.Reset(rng, obs);
  int t = 0;
  for (auto _ : state) {
    if (t == 60) {
      env.Reset(rng, obs);
      t = 0;
    }
    const StepOutcome out = env.Step(ScriptedPush(obs), obs);
    benchmark::DoNotOptimize(out);
    ++t;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_PandaPushStep)->Arg(20)->Arg(10)->Unit(benchmark::kMicrosecond);

void BM_PandaPushShieldModel(benchmark::State& state) {
  PandaPushShieldModel model(PandaPushShieldModelOptions{});
  Eigen::VectorXf s = Eigen::VectorXf::Zero(kObservationDim);
  s[kEePos] = 0.33f;
  s[kBlockPos] = 0.41f;
  Rng rng(2);
  Eigen::MatrixXf actions(kActionDim, 128), next(kObservationDim, 128);
  for (long i = 0; i < actions.size(); ++i) actions.data()[i] = float(rng.Uniform(-1, 1));
  for (auto _ : state) {
    model.Step(s, actions, next);
    benchmark::DoNotOptimize(next.data());
  }
  state.SetItemsProcessed(state.iterations() * actions.cols());
}
BENCHMARK(BM_PandaPushShieldModel);

void BM_PandaPushRender(benchmark::State& state) {
  PandaPushEnv env(PandaPushOptions{}, PandaPushShieldModelOptions{});
  Rng rng(1);
  Eigen::VectorXf obs(kObservationDim);
  env.Reset(rng, obs);
  Frame frame;
  env.Render(640, 480, &frame);  // the context is made on the first call
  for (auto _ : state) {
    env.Render(640, 480, &frame);
    benchmark::DoNotOptimize(frame.rgb.data());
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_PandaPushRender)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace secure::domains::panda_push
