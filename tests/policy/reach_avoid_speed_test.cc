// Manual measurement (not part of the default test run): BC and AIRL with their default
// options on the double-integrator reach-avoid task (4-D states, 2-D actions, 300-step
// episodes), single-threaded. Run:
//   ./tests/policy_speed_test --gtest_also_run_disabled_tests
// Single-threaded (one LibTorch intra-op thread). Reports training time, iterations per second, and
// the success / collision rates of the trained policies (sampled actions, 200 episodes).
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>

#include "secure/common/timer.h"
#include "domains/double_integrator/expert.h"
#include "domains/double_integrator/reach_avoid.h"
#include "secure/policy/airl_trainer.h"
#include "secure/policy/bc_trainer.h"
#include "tests/policy/single_thread.h"

namespace secure::policy {
namespace {

namespace di = domains::double_integrator;

// One LibTorch and one OpenBLAS thread (the trainers never change either).
const bool kOneThread = test::UseOneTrainingThread();

struct Rates {
  double success = 0, collision = 0, depth = 0;  // depth: mean max penetration of the obstacle
};

Rates Evaluate(const GaussianPolicy& pi, const domains::Environment& proto, int episodes,
               std::uint64_t seed, bool sample = true) {
  const di::GroundTruth truth;
  auto env = proto.Clone();
  PolicyEvaluator ev(pi);
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

// BC with the default options on ~20k pairs (67 episodes x 300 steps): the budget is 5 s.
TEST(ReachAvoidSpeed, DISABLED_BcDefaults20kPairs) {
  const di::Demonstrations demos =
      di::GenerateDemonstrations(di::ReachAvoidOptions{}, di::ExpertOptions{}, {});
  const data::TrajectorySet subset = FirstEpisodes(demos.trajectories, 67);
  BcOptions options;
  BcSummary summary;
  const Stopwatch clock;
  TrainBc(options, subset, &summary);
  std::printf("BC on %ld pairs: %.2f s\n%s\n", subset.num_steps(), clock.Seconds(),
              summary.BriefReport().c_str());
}

TEST(ReachAvoidSpeed, DISABLED_BcAndAirlDefaults) {
  const di::ReachAvoidOptions task;
  di::DemonstrationOptions demo_options;
  const di::Demonstrations demos =
      di::GenerateDemonstrations(task, di::ExpertOptions{}, demo_options);
  const di::ReachAvoidEnv env(task);
  std::printf("demos: %ld episodes, %ld steps\n", demos.trajectories.num_episodes(),
              demos.trajectories.num_steps());

  BcOptions bc_options;
  bc_options.verbose = true;
  BcSummary bc_summary;
  const GaussianPolicy bc = TrainBc(bc_options, demos.trajectories, &bc_summary);
  std::printf("%s\n", bc_summary.BriefReport().c_str());
  const Rates bc_rates = Evaluate(bc, env, 200, 7);
  const Rates bc_mean = Evaluate(bc, env, 200, 7, false);
  std::printf("BC policy: success %.3f collision %.3f depth %.3f; mean action: %.3f %.3f %.3f\n",
              bc_rates.success, bc_rates.collision, bc_rates.depth, bc_mean.success,
              bc_mean.collision, bc_mean.depth);

  for (int reward = 0; reward < 2; ++reward) {
    if (EnvInt("SECURE_REWARD", -1) >= 0 && EnvInt("SECURE_REWARD", -1) != reward) continue;
    AirlOptions o;
    o.reward = reward == 0 ? AirlReward::kLogitD : AirlReward::kStateReward;
    o.iterations = EnvInt("SECURE_ITERATIONS", o.iterations);
    // Extra options as inline YAML, e.g. SECURE_AIRL_YAML='{discriminator_updates: 20}'.
    if (const char* yaml = std::getenv("SECURE_AIRL_YAML"))
      o.ApplyYaml(YAML::Load(yaml), "SECURE_AIRL_YAML");
    o.verbose = true;
    AirlSummary s;
    const bool warm = EnvInt("SECURE_WARM", 0) != 0;
    const GaussianPolicy pi = TrainAirl(o, demos.trajectories, env, warm ? &bc : nullptr, &s);
    std::printf("%s\n%s\n", ToString(kAirlRewardNames, o.reward).c_str(), s.BriefReport().c_str());
    const Rates rates = Evaluate(pi, env, 200, 7);
    std::printf("options %s\n", o.ToJson().dump().c_str());
    const Rates mean_rates = Evaluate(pi, env, 200, 7, false);
    std::printf(
        "AIRL policy (%s%s): success %.3f collision %.3f depth %.3f; mean action: %.3f "
        "%.3f %.3f\n",
        ToString(kAirlRewardNames, o.reward).c_str(), warm ? ", warm start" : "", rates.success,
        rates.collision, rates.depth, mean_rates.success, mean_rates.collision, mean_rates.depth);
  }
}

// Two AIRL trainers (default options, seeds 1 and 2) in two std::threads, as the pipeline runs
// them: wall time of the pair.
TEST(ReachAvoidSpeed, DISABLED_TwoConcurrentAirlDefaults) {
  const di::ReachAvoidOptions task;
  const di::Demonstrations demos = di::GenerateDemonstrations(task, di::ExpertOptions{}, {});
  const di::ReachAvoidEnv env(task);
  AirlOptions a, b;
  a.seed = 1;
  b.seed = 2;
  AirlSummary sa, sb;
  const Stopwatch clock;
  std::thread ta([&] { TrainAirl(a, demos.trajectories, env, nullptr, &sa); });
  std::thread tb([&] { TrainAirl(b, demos.trajectories, env, nullptr, &sb); });
  ta.join();
  tb.join();
  std::printf("two concurrent AIRL runs: %.2f s wall\n%s\n%s\n", clock.Seconds(),
              sa.BriefReport().c_str(), sb.BriefReport().c_str());
}

}  // namespace
}  // namespace secure::policy
