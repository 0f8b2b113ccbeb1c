// Policy training on the double-integrator reach-avoid task (4-D states, 2-D actions, 300-step
// episodes) with the default expert demonstrations (100 episodes x 300 steps, generated once,
// outside the timed region). One LibTorch and one OpenBLAS thread per training thread
// (nn::SetTorchThreads(1)), as the SECURE pipeline runs its trainers.
//
// Cases (one iteration = one training run; wall time):
//   BM_Bc_20kPairs          TrainBc, default options, on the first 67 episodes (20,100 pairs).
//   BM_Bc_Defaults          TrainBc, default options, on all 100 episodes (30,000 pairs).
//   BM_Airl_Defaults/...    TrainAirl, default options, reward logit-d or state-reward, cold
//                           start or warm-started from the BM_Bc_Defaults policy (trained once,
//                           outside the timed region).
//   BM_Airl_TwoConcurrent   two TrainAirl runs (default options, seeds 1 and 2) in two
//                           std::threads, as the pipeline runs them: wall time of the pair.
//
// Counters:
//   seconds          wall time of the timed training (benchmark real time).
//   train_seconds    the trainer's own wall_seconds (summary; BM_Airl_TwoConcurrent: _a, _b).
//   pairs, epochs, best_epoch            BC.
//   iterations, env_steps, iterations_per_second, env_steps_per_second,
//   rollout_seconds, discriminator_seconds, ppo_seconds                    AIRL.
//   success, collision, depth  of the trained policy over 200 evaluation episodes (seed 7) with
//                    sampled actions; mean_success, mean_collision, mean_depth with the mean
//                    action. success = goal reached within 300 steps, collision = the obstacle
//                    entered at least once, depth = mean over episodes of the deepest
//                    penetration into the obstacle. Evaluation is outside the timed region.
//
// Environment (reduced or altered AIRL runs, e.g. for a quick check):
//   SECURE_ITERATIONS=N       AIRL iterations (default: AirlOptions' 100).
//   SECURE_AIRL_YAML='{...}'  extra AIRL options as inline YAML,
//                             e.g. '{discriminator_updates: 20}'.

#include <benchmark/benchmark.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>
#include <thread>

#include "domains/double_integrator/expert.h"
#include "domains/double_integrator/reach_avoid.h"
#include "secure/common/rng.h"
#include "secure/nn/torch_threads.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"

namespace secure::bench {
namespace {

namespace di = domains::double_integrator;
using policy::AirlOptions;
using policy::AirlReward;
using policy::AirlSummary;
using policy::BcOptions;
using policy::BcSummary;
using policy::GaussianPolicy;

// The default demonstrations, generated once per process.
const di::Demonstrations& Demos() {
  static const di::Demonstrations demos =
      di::GenerateDemonstrations(di::ReachAvoidOptions{}, di::ExpertOptions{}, {});
  return demos;
}

// The BC policy with default options on all demonstrations (the AIRL warm start), trained once.
const GaussianPolicy& BcPolicy() {
  static const GaussianPolicy bc = [] {
    nn::SetTorchThreads(1);
    return policy::TrainBc(BcOptions{}, Demos().trajectories);
  }();
  return bc;
}

int EnvInt(const char* name, int fallback) {
  const char* v = std::getenv(name);
  return v ? std::atoi(v) : fallback;
}

// The first `episodes` episodes of a demonstration set.
data::TrajectorySet FirstEpisodes(const data::TrajectorySet& all, long episodes) {
  data::TrajectorySet d = all;
  const long end = all.episode_begin[episodes];
  d.states = all.states.leftCols(end);
  d.actions = all.actions.leftCols(end);
  d.episode_begin.resize(episodes + 1);
  return d;
}

struct Rates {
  double success = 0, collision = 0, depth = 0;  // depth: mean max penetration of the obstacle
};

Rates Evaluate(const GaussianPolicy& pi, const domains::Environment& proto, int episodes,
               std::uint64_t seed, bool sample) {
  const di::GroundTruth truth;
  auto env = proto.Clone();
  policy::PolicyEvaluator ev(pi);
  Rng rng(seed);
  Eigen::VectorXf o(env->observation_dim()), a(env->action_dim()), next(env->observation_dim());
  Rates r;
  for (int e = 0; e < episodes; ++e) {
    env->Reset(rng, o);
    bool collided = false, reached = false;
    double depth = 0;
    for (int t = 0; t < env->max_steps() && !reached; ++t) {
      if (sample)
        ev.Sample(o, rng, a);
      else
        ev.Mean(o, a);
      depth = std::max(depth,
                       truth.radius - std::hypot(o[0] - truth.obstacle_x, o[1] - truth.obstacle_y));
      const auto out = env->Step(a, next);
      collided |= out.collided;
      reached |= out.reached_goal;
      o = next;
    }
    r.success += reached;
    r.collision += collided;
    r.depth += depth;
  }
  r.depth /= episodes;
  r.success /= episodes;
  r.collision /= episodes;
  return r;
}

void SecondsCounter(benchmark::State& state) {
  state.counters["seconds"] = benchmark::Counter(
      1.0, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

// The task rates of `pi` (200 episodes, seed 7), sampled and mean actions, as counters.
void RateCounters(benchmark::State& state, const GaussianPolicy& pi) {
  const di::ReachAvoidEnv env(di::ReachAvoidOptions{});
  const Rates sampled = Evaluate(pi, env, 200, 7, true);
  const Rates mean = Evaluate(pi, env, 200, 7, false);
  state.counters["success"] = sampled.success;
  state.counters["collision"] = sampled.collision;
  state.counters["depth"] = sampled.depth;
  state.counters["mean_success"] = mean.success;
  state.counters["mean_collision"] = mean.collision;
  state.counters["mean_depth"] = mean.depth;
}

void BcCounters(benchmark::State& state, const BcSummary& s) {
  SecondsCounter(state);
  state.counters["train_seconds"] = s.wall_seconds;
  state.counters["pairs"] = static_cast<double>(s.train_pairs + s.validation_pairs);
  state.counters["epochs"] = s.epochs;
  state.counters["best_epoch"] = s.best_epoch;
}

void RunBc(benchmark::State& state, long episodes) {
  nn::SetTorchThreads(1);
  const data::TrajectorySet demos = FirstEpisodes(Demos().trajectories, episodes);
  BcSummary summary;
  GaussianPolicy pi;
  for (auto _ : state) {
    pi = policy::TrainBc(BcOptions{}, demos, &summary);
    benchmark::DoNotOptimize(pi);
  }
  BcCounters(state, summary);
  RateCounters(state, pi);
  state.SetLabel(summary.BriefReport());
}

// BC with the default options on ~20k pairs (67 episodes x 300 steps).
void BM_Bc_20kPairs(benchmark::State& state) { RunBc(state, 67); }
BENCHMARK(BM_Bc_20kPairs)->Iterations(1)->UseRealTime()->Unit(benchmark::kSecond);

// BC with the default options on all 100 episodes.
void BM_Bc_Defaults(benchmark::State& state) { RunBc(state, Demos().trajectories.num_episodes()); }
BENCHMARK(BM_Bc_Defaults)->Iterations(1)->UseRealTime()->Unit(benchmark::kSecond);

AirlOptions DefaultAirl() {
  AirlOptions o;
  o.iterations = EnvInt("SECURE_ITERATIONS", o.iterations);
  if (const char* yaml = std::getenv("SECURE_AIRL_YAML"))
    o.ApplyYaml(YAML::Load(yaml), "SECURE_AIRL_YAML");
  return o;
}

void AirlCounters(benchmark::State& state, const AirlSummary& s) {
  SecondsCounter(state);
  state.counters["train_seconds"] = s.wall_seconds;
  state.counters["iterations"] = s.iterations;
  state.counters["env_steps"] = static_cast<double>(s.env_steps);
  state.counters["iterations_per_second"] = s.iterations_per_second;
  state.counters["env_steps_per_second"] = s.env_steps_per_second;
  state.counters["rollout_seconds"] = s.rollout_seconds;
  state.counters["discriminator_seconds"] = s.discriminator_seconds;
  state.counters["ppo_seconds"] = s.ppo_seconds;
}

// AIRL with the default options: reward range(0) (0 logit-d, 1 state-reward), warm start from
// the default BC policy if range(1) is 1.
void BM_Airl_Defaults(benchmark::State& state) {
  nn::SetTorchThreads(1);
  AirlOptions o = DefaultAirl();
  o.reward = state.range(0) == 0 ? AirlReward::kLogitD : AirlReward::kStateReward;
  const bool warm = state.range(1) != 0;
  const GaussianPolicy* warm_start = warm ? &BcPolicy() : nullptr;
  const di::ReachAvoidEnv env(di::ReachAvoidOptions{});
  const data::TrajectorySet& demos = Demos().trajectories;
  AirlSummary summary;
  GaussianPolicy pi;
  for (auto _ : state) {
    pi = policy::TrainAirl(o, demos, env, warm_start, &summary);
    benchmark::DoNotOptimize(pi);
  }
  AirlCounters(state, summary);
  RateCounters(state, pi);
  state.SetLabel(ToString(policy::kAirlRewardNames, o.reward) + (warm ? ", BC warm start" : "") +
                 "; " + summary.BriefReport());
}
BENCHMARK(BM_Airl_Defaults)
    ->ArgNames({"state_reward", "warm"})
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->Iterations(1)
    ->UseRealTime()
    ->Unit(benchmark::kSecond);

// Two AIRL trainers (default options, seeds 1 and 2) in two std::threads: wall time of the pair.
void BM_Airl_TwoConcurrent(benchmark::State& state) {
  AirlOptions a = DefaultAirl(), b = DefaultAirl();
  a.seed = 1;
  b.seed = 2;
  const di::ReachAvoidEnv env(di::ReachAvoidOptions{});
  const data::TrajectorySet& demos = Demos().trajectories;
  AirlSummary sa, sb;
  for (auto _ : state) {
    std::thread ta([&] {
      nn::SetTorchThreads(1);
      policy::TrainAirl(a, demos, env, nullptr, &sa);
    });
    std::thread tb([&] {
      nn::SetTorchThreads(1);
      policy::TrainAirl(b, demos, env, nullptr, &sb);
    });
    ta.join();
    tb.join();
  }
  SecondsCounter(state);
  state.counters["train_seconds_a"] = sa.wall_seconds;
  state.counters["train_seconds_b"] = sb.wall_seconds;
  state.counters["env_steps"] = static_cast<double>(sa.env_steps + sb.env_steps);
  state.SetLabel(sa.BriefReport() + " | " + sb.BriefReport());
}
BENCHMARK(BM_Airl_TwoConcurrent)->Iterations(1)->UseRealTime()->Unit(benchmark::kSecond);

}  // namespace
}  // namespace secure::bench
