// The evaluation harness: episodes of policies with and without the shield on the
// double-integrator reach-avoid task, and the across-seed summaries and tests.
#include "domains/double_integrator/ground_truth_barrier.h"
#include "secure/eval/policy_eval.h"

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <memory>
#include <string>

#include "secure/cbf/barrier.h"
#include "domains/double_integrator/reach_avoid.h"
#include "tests/eval/pd_policy.h"
#include "tests/test_util.h"

namespace secure::eval {
namespace {

namespace di = domains::double_integrator;
using test::ErrorOf;

using test::PdOnReachAvoid;
using test::PdPolicy;

// SeedModels::make_barrier for the scenario's task: its ground-truth barrier.
std::function<std::unique_ptr<cbf::Barrier>()> GroundTruthOf(const PdOnReachAvoid& s) {
  return [&s] { return std::make_unique<di::GroundTruthBarrier>(s.task.truth); };
}

TEST(PolicyEvalTest, ShieldWithGroundTruthPreventsTheCollisionsOfTheUnshieldedPolicy) {
  PdOnReachAvoid s(0.3);
  SeedModels models;
  models.airl = &s.pd;
  models.make_barrier = GroundTruthOf(s);
  const auto results = EvaluateMethods(s.env, {Method::kAirl, Method::kSecure}, models,
                                       shield::ShieldOptions{}, 40, 7);
  const SeedResult& plain = results.at(Method::kAirl);
  const SeedResult& shielded = results.at(Method::kSecure);
  EXPECT_EQ(plain.episodes, 40);
  EXPECT_GT(plain.dangerous, 30);  // the straight path crosses the obstacle
  EXPECT_EQ(plain.decisions, 0);
  EXPECT_EQ(shielded.dangerous, 0);
  EXPECT_EQ(shielded.collision_events, 0);
  EXPECT_GT(shielded.successes, 30);
  EXPECT_GT(shielded.interventions, 0);
  EXPECT_EQ(shielded.decisions, shielded.steps);
  EXPECT_EQ(shielded.latency_us.count, shielded.decisions);
  EXPECT_GT(shielded.interventions_per_episode(), 0.0);
}

// A ground truth that counts how it is evaluated: the shield's Evaluate calls, and the dense
// forwards (of how many states) that time the reference.
struct EvaluationCounts {
  long sparse_calls = 0, dense_calls = 0, dense_states = 0;
};
class CountingBarrier final : public cbf::Barrier {
 public:
  CountingBarrier(const di::ReachAvoidOptions& task, EvaluationCounts& counts)
      : inner_(task.truth), counts_(counts) {}
  int state_dim() const override { return inner_.state_dim(); }
  std::string Describe() const override { return "counting " + inner_.Describe(); }

 protected:
  void DoEvaluate(const Eigen::Ref<const Eigen::MatrixXf>& states,
                  Eigen::Ref<Eigen::VectorXf> h) override {
    ++counts_.sparse_calls;
    inner_.Evaluate(states, h);
  }
  void DoEvaluateDense(const Eigen::Ref<const Eigen::MatrixXf>& states,
                       Eigen::Ref<Eigen::VectorXf> h) override {
    ++counts_.dense_calls;
    counts_.dense_states += states.cols();
    inner_.EvaluateDense(states, h);
  }

 private:
  di::GroundTruthBarrier inner_;
  EvaluationCounts& counts_;
};

// The reference forward is timed once per seed with the dense evaluation (nothing skipped) on
// kReferenceBatch states, a warm-up and kReferenceRepeats timed; the decisions never use it.
TEST(PolicyEvalTest, TheReferenceForwardIsADenseForwardOfTheReferenceBatch) {
  PdOnReachAvoid s(0.3);
  SeedModels models;
  models.airl = &s.pd;
  EvaluationCounts counts;
  models.make_barrier = [&] { return std::make_unique<CountingBarrier>(s.task, counts); };
  EpisodeRunner runner(s.env);
  const SeedResult r = RunMethod(runner, Method::kSecure, models, shield::ShieldOptions{}, 3, 7);
  EXPECT_GT(r.reference_forward_latency_us, 0.0);
  EXPECT_EQ(counts.dense_calls, 1 + SeedResult::kReferenceRepeats);
  EXPECT_EQ(counts.dense_states, counts.dense_calls * SeedResult::kReferenceBatch);
  EXPECT_GT(r.decisions, 0);
  EXPECT_GE(counts.sparse_calls, r.decisions);  // h(s) of every decision, at least
  // Unshielded methods time no reference.
  EpisodeRunner plain_runner(s.env);
  EXPECT_EQ(RunMethod(plain_runner, Method::kAirl, models, shield::ShieldOptions{}, 3, 7)
                .reference_forward_latency_us,
            0.0);
}

TEST(PolicyEvalTest, SameSeedGivesTheSameEpisodes) {
  PdOnReachAvoid s(0.5);
  SeedModels models;
  models.bc = &s.pd;
  models.make_barrier = GroundTruthOf(s);
  const std::vector<Method> methods = {Method::kBc, Method::kBcShield};
  const auto a = EvaluateMethods(s.env, methods, models, shield::ShieldOptions{}, 10, 3);
  const auto b = EvaluateMethods(s.env, methods, models, shield::ShieldOptions{}, 10, 3);
  const auto c = EvaluateMethods(s.env, methods, models, shield::ShieldOptions{}, 10, 4);
  for (Method m : methods) {
    EXPECT_EQ(a.at(m).steps, b.at(m).steps);
    EXPECT_EQ(a.at(m).successes, b.at(m).successes);
    EXPECT_EQ(a.at(m).interventions, b.at(m).interventions);
    EXPECT_EQ(a.at(m).mean_steps_to_goal, b.at(m).mean_steps_to_goal);
  }
  EXPECT_NE(a.at(Method::kBcShield).steps, c.at(Method::kBcShield).steps);
}

TEST(PolicyEvalTest, MissingModelsAreNamed) {
  PdOnReachAvoid s(0.3);
  SeedModels models;
  models.bc = &s.pd;
  EXPECT_HAS(ErrorOf([&] {
               EvaluateMethods(s.env, {Method::kAirl}, models, shield::ShieldOptions{}, 1, 0);
             }),
             "method 'airl' needs a AIRL policy");
  EXPECT_HAS(ErrorOf([&] {
               EvaluateMethods(s.env, {Method::kBcShield}, models, shield::ShieldOptions{}, 1, 0);
             }),
             "method 'bc+shield' needs a barrier");
  EXPECT_HAS(ErrorOf([&] {
               EvaluateMethods(s.env, {Method::kJoint}, models, shield::ShieldOptions{}, 1, 0);
             }),
             "method 'joint' needs a joint policy");
}

TEST(PolicyEvalTest, TheJointPolicyIsUsedUnshielded) {
  PdOnReachAvoid s(0.3);
  SeedModels models;
  models.joint = &s.pd;
  const auto r = EvaluateMethods(s.env, {Method::kJoint}, models, shield::ShieldOptions{}, 3, 7);
  EXPECT_EQ(r.at(Method::kJoint).episodes, 3);
  EXPECT_EQ(r.at(Method::kJoint).decisions, 0);  // no shield
  EXPECT_FALSE(IsShielded(Method::kJoint));
  EXPECT_TRUE(IsShielded(Method::kSecureMyopic));
}

TEST(PolicyEvalTest, ParseMethods) {
  EXPECT_EQ(ParseMethods("bc, airl,secure"),
            (std::vector<Method>{Method::kBc, Method::kAirl, Method::kSecure}));
  EXPECT_EQ(ParseMethods("secure-random-safe,secure-no-resampling,bc+shield").size(), 3u);
  EXPECT_EQ(ParseMethods("secure-myopic,joint"),
            (std::vector<Method>{Method::kSecureMyopic, Method::kJoint}));
  EXPECT_HAS(ErrorOf([] { ParseMethods("bc,gail"); }), "'gail'");
  EXPECT_HAS(ErrorOf([] { ParseMethods("bc,bc"); }), "listed twice");
  EXPECT_HAS(ErrorOf([] { ParseMethods(""); }), "no method");
}

TEST(PolicyEvalTest, ShieldOptionsForAppliesExactlyTheAblation) {
  shield::ShieldOptions base;
  base.num_samples = 32;
  const shield::ShieldOptions a = ShieldOptionsFor(Method::kSecureRandomSafe, base);
  EXPECT_EQ(a.aggregation, shield::Aggregation::kRandomSafe);
  EXPECT_EQ(a.resampling, base.resampling);
  const shield::ShieldOptions b = ShieldOptionsFor(Method::kSecureNoResampling, base);
  EXPECT_EQ(b.resampling, shield::Resampling::kNone);
  EXPECT_EQ(b.aggregation, base.aggregation);
  EXPECT_EQ(ShieldOptionsFor(Method::kSecure, base).ToJson(), base.ToJson());
  EXPECT_EQ(a.num_samples, 32);
  // The myopic test: alpha dt = 1, whatever class-K function the base had.
  base.class_k = shield::ClassK::kCubic;
  base.class_k_gain = 3.0;
  base.dt = 0.05;
  const shield::ShieldOptions m = ShieldOptionsFor(Method::kSecureMyopic, base);
  EXPECT_EQ(m.class_k, shield::ClassK::kLinear);
  EXPECT_DOUBLE_EQ(m.class_k_gain * m.dt, 1.0);
  EXPECT_EQ(m.resampling, base.resampling);
  EXPECT_EQ(m.aggregation, base.aggregation);
}

TEST(PolicyEvalTest, TheMyopicShieldAcceptsExactlyTheActionsWithNonNegativeNextH) {
  // With alpha(h) = h / dt, g(a) = h(T(s, a)) / dt: g >= 0 iff h(T(s, a)) >= 0.
  const di::ReachAvoidOptions task;
  di::ReachAvoidEnv env(task);
  domains::double_integrator::GroundTruthBarrier barrier(task.truth);
  shield::ShieldOptions base;
  base.dt = task.dt;
  shield::Shield shield(ShieldOptionsFor(Method::kSecureMyopic, base), barrier, env.ShieldModel());
  const Eigen::Vector4f state(3.2f, 5.0f, 1.0f, 0.0f);
  Eigen::MatrixXf actions(2, 3);
  actions << -3.0f, 0.0f, 3.0f, 0.5f, 0.0f, -0.5f;
  Eigen::VectorXd g(3);
  const double h = shield.EvaluateH(state);
  shield.EvaluateG(state, h, actions, g);
  Eigen::MatrixXf next(4, 3);
  env.ShieldModel().Step(state, actions, next);
  Eigen::VectorXf h_next(3);
  barrier.Evaluate(next, h_next);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(g[i], h_next[i] / task.dt, 1e-4) << i;
}

SeedResult Synthetic(long successes, long dangerous) {
  SeedResult r;
  r.episodes = 100;
  r.successes = successes;
  r.dangerous = dangerous;
  return r;
}

TEST(PolicyEvalTest, EvaluationSummarisesSeedsAndComparesSecureWithAirl) {
  Evaluation evaluation;
  const std::vector<long> airl_success = {80, 85, 78, 90, 83};
  const std::vector<long> secure_success = {82, 84, 80, 88, 86};
  const std::vector<long> airl_danger = {20, 25, 18, 22, 30};
  for (std::size_t k = 0; k < 5; ++k) {
    evaluation.Add(Method::kAirl, Synthetic(airl_success[k], airl_danger[k]));
    evaluation.Add(Method::kSecure, Synthetic(secure_success[k], 0));
  }
  evaluation.Finish();
  const nlohmann::json j = evaluation.ToJson();
  const nlohmann::json& s = j["methods"]["secure"];
  EXPECT_NEAR(s["success_rate"]["mean"].get<double>(), 0.84, 1e-12);
  EXPECT_EQ(s["success_rate"]["per_seed"].size(), 5u);
  EXPECT_NEAR(s["success_rate"]["per_seed"][3].get<double>(), 0.88, 1e-12);
  EXPECT_EQ(s["dangerous_rate"]["mean"].get<double>(), 0.0);
  EXPECT_EQ(s["dangerous_rate"]["std"].get<double>(), 0.0);
  // Sample std (n - 1) of the AIRL dangerous rates.
  EXPECT_NEAR(j["methods"]["airl"]["dangerous_rate"]["std"].get<double>(),
              stats::Summarize({0.20, 0.25, 0.18, 0.22, 0.30}).std, 1e-12);
  // SECURE never dangerous, AIRL always: complete separation, U = 0 (SECURE's zeros are ties,
  // so the p-value is the asymptotic one).
  const nlohmann::json& c = j["comparisons"]["secure_vs_airl"];
  EXPECT_EQ(c["dangerous_mann_whitney"]["u"].get<double>(), 0.0);
  EXPECT_EQ(c["dangerous_mann_whitney"]["method"], "asymptotic");
  EXPECT_NEAR(c["dangerous_mann_whitney"]["p_value"].get<double>(),
              stats::MannWhitneyU({0, 0, 0, 0, 0}, {0.20, 0.25, 0.18, 0.22, 0.30}).p_value, 1e-12);
  EXPECT_LT(c["dangerous_mann_whitney"]["p_value"].get<double>(), 0.01);
  EXPECT_NEAR(c["success_tost"]["difference"].get<double>(), 0.84 - 0.832, 1e-12);
  EXPECT_LT(c["success_tost"]["p_value"].get<double>(), 0.05);
  const std::string table = evaluation.Table();
  EXPECT_HAS(table, "| secure | 84.0 (");
  EXPECT_HAS(table, "| airl | 83.2 (");
  EXPECT_HAS(table, "equivalent");
}

// 0 % success on every seed for both methods (a quick run): TOST's standard error is 0 and its
// p-value 0, which says nothing; the table must not call that "equivalent".
TEST(PolicyEvalTest, ConstantSuccessOnBothSidesIsNotCalledEquivalent) {
  Evaluation evaluation;
  for (long k = 0; k < 3; ++k) {
    evaluation.Add(Method::kAirl, Synthetic(0, 10 + k));
    evaluation.Add(Method::kSecure, Synthetic(0, k));
  }
  evaluation.Finish();
  const std::string table = evaluation.Table();
  EXPECT_HAS(table, "not informative: each method's success is constant over the seeds (0.0 % "
                    "and 0.0 %)");
  EXPECT_EQ(table.find("equivalent"), std::string::npos) << table;
}

TEST(PolicyEvalTest, AblationsAreComparedWithKruskalWallisAndDunn) {
  Evaluation evaluation;
  for (long k = 0; k < 4; ++k) {
    evaluation.Add(Method::kSecure, Synthetic(90 + k, 0));
    evaluation.Add(Method::kSecureRandomSafe, Synthetic(70 + k, 1 + k));
    evaluation.Add(Method::kSecureNoResampling, Synthetic(50 + k, 40 + k));
  }
  evaluation.Finish();
  const nlohmann::json a = evaluation.ToJson()["comparisons"]["ablations"];
  EXPECT_EQ(a["methods"].size(), 3u);
  EXPECT_LT(a["success_rate"]["kruskal_wallis"]["p_value"].get<double>(), 0.05);
  EXPECT_EQ(a["success_rate"]["dunn"]["pairs"].size(), 3u);
  EXPECT_HAS(evaluation.Table(), "Kruskal-Wallis H =");
}

TEST(PolicyEvalTest, EvaluationRejectsUnequalSeedCounts) {
  Evaluation evaluation;
  evaluation.Add(Method::kBc, Synthetic(1, 0));
  evaluation.Add(Method::kBc, Synthetic(2, 0));
  evaluation.Add(Method::kAirl, Synthetic(1, 0));
  EXPECT_HAS(ErrorOf([&] { evaluation.Finish(); }), "has 1 seeds");
  Evaluation empty;
  EXPECT_HAS(ErrorOf([&] { empty.Finish(); }), "no results");
}

}  // namespace
}  // namespace secure::eval

namespace secure::eval {
namespace {

shield::ShieldOptions IgnoreTheBox() {
  shield::ShieldOptions o;
  o.action_bounds = shield::ActionBounds::kIgnore;
  return o;
}

// The counts of EvaluateMethods for a fixed run, recorded before the episode runner took
// EpisodePolicy, step observers and runner options: the existing path must not change (the
// numbers of `secure demo` and the experiments depend on it). Recorded with the actuator box
// ignored (as it was then); with the box (clip, the default since 2026-12-03) the shielded
// counts are the same: the double integrator's shield model clips as its actuator does.
TEST(PolicyEvalTest, EvaluateMethodsResultsArePinned) {
  PdOnReachAvoid s(0.4);
  SeedModels models;
  models.bc = &s.pd;
  models.airl = &s.pd;
  models.make_barrier = GroundTruthOf(s);
  for (const shield::ShieldOptions& options : {IgnoreTheBox(), shield::ShieldOptions{}}) {
    SCOPED_TRACE(options.ToJson().dump());
    const auto r = EvaluateMethods(
        s.env, {Method::kAirl, Method::kSecure, Method::kSecureNoResampling, Method::kSecureMyopic},
        models, options, 25, 0x5eed);
    const SeedResult& airl = r.at(Method::kAirl);
    EXPECT_EQ(airl.steps, 2883);
    EXPECT_EQ(airl.successes, 25);
    EXPECT_EQ(airl.dangerous, 25);
    EXPECT_EQ(airl.collision_events, 679);  // the episodes go on through the obstacle
    const SeedResult& secure = r.at(Method::kSecure);
    EXPECT_EQ(secure.steps, 4435);
    EXPECT_EQ(secure.successes, 25);
    EXPECT_EQ(secure.dangerous, 0);
    EXPECT_EQ(secure.interventions, 2192);
    EXPECT_EQ(secure.resampled_decisions, 1968);
    const SeedResult& no_resampling = r.at(Method::kSecureNoResampling);
    EXPECT_EQ(no_resampling.steps, 2679);
    EXPECT_EQ(no_resampling.collision_events, 670);
    EXPECT_EQ(no_resampling.no_safe_action_decisions, 724);
    const SeedResult& myopic = r.at(Method::kSecureMyopic);
    EXPECT_EQ(myopic.steps, 3607);
    EXPECT_EQ(myopic.interventions, 1162);
  }
}

TEST(EvaluationSeedTest, IsTheTrainingSeedWithTheEvaluationSalt) {
  static_assert(EvaluationSeed(0) == 0x5ec07e5eed5ULL, "the salt of every published evaluation");
  EXPECT_EQ(EvaluationSeed(3), 3ULL ^ 0x5ec07e5eed5ULL);
  EXPECT_NE(EvaluationSeed(1), 1ULL);
  EXPECT_NE(EvaluationSeed(1), EvaluationSeed(2));
}

// Records what a StepObserver sees.
class Recorder final : public StepObserver {
 public:
  explicit Recorder(const di::ReachAvoidEnv& env) : env_(env) {}
  void OnEpisodeStart(long episode, const Eigen::VectorXf& observation) override {
    EXPECT_EQ(episode, starts);
    EXPECT_EQ(ends, starts);  // the previous episode was closed
    ++starts;
    start_observations.push_back(observation);
    next_step = 0;
  }
  void OnStep(const StepView& v) override {
    EXPECT_EQ(v.episode, starts - 1);
    EXPECT_EQ(v.step, next_step++);
    EXPECT_EQ(v.observation, Eigen::VectorXf(env_.state()));  // after the step
    EXPECT_TRUE(v.action.allFinite());
    ++steps;
    if (v.decision != nullptr) {
      ++decisions;
      EXPECT_EQ(v.action, v.decision->action);  // the shield's action is applied
    }
    if (v.outcome.collided) ++collisions;
    last_collided = v.outcome.collided;
    last_reached_goal = v.outcome.reached_goal;
  }
  void OnEpisodeEnd(long episode) override {
    EXPECT_EQ(episode, starts - 1);
    ++ends;
    episode_ended_by_collision += last_collided ? 1 : 0;
    episode_lengths.push_back(next_step);
    if (!last_collided && !last_reached_goal) ++timeouts;
  }

  long starts = 0, ends = 0, steps = 0, decisions = 0, collisions = 0, timeouts = 0;
  long episode_ended_by_collision = 0;
  int next_step = 0;
  bool last_collided = false, last_reached_goal = false;
  std::vector<Eigen::VectorXf> start_observations;
  std::vector<int> episode_lengths;

 private:
  const di::ReachAvoidEnv& env_;
};

TEST(EpisodeRunnerTest, TheObserverSeesEveryEpisodeAndStep) {
  PdOnReachAvoid s(0.4);
  policy::PolicyEvaluator evaluator(s.pd);
  EpisodeRunner runner(s.env);
  Recorder plain(s.env);
  const SeedResult a = runner.Run(evaluator, nullptr, 6, 11, &plain);
  EXPECT_EQ(plain.starts, 6);
  EXPECT_EQ(plain.ends, 6);
  EXPECT_EQ(plain.steps, a.steps);
  EXPECT_EQ(plain.decisions, 0);
  EXPECT_EQ(plain.collisions, a.collision_events);
  // The observer does not change the run.
  const SeedResult unobserved = runner.Run(evaluator, nullptr, 6, 11);
  EXPECT_EQ(unobserved.steps, a.steps);
  EXPECT_EQ(unobserved.collision_events, a.collision_events);

  di::GroundTruthBarrier barrier(s.task.truth);
  shield::Shield shield(shield::ShieldOptions{}, barrier, s.env.ShieldModel());
  Recorder shielded(s.env);
  const SeedResult b = runner.Run(evaluator, &shield, 4, 11, &shielded);
  EXPECT_EQ(shielded.ends, 4);
  EXPECT_EQ(shielded.steps, b.steps);
  EXPECT_EQ(shielded.decisions, b.decisions);
  EXPECT_EQ(shielded.decisions, b.steps);
  // Common random numbers: the same seed starts the same episodes, shielded or not.
  for (int i = 0; i < 4; ++i)
    EXPECT_EQ(shielded.start_observations[i], plain.start_observations[i]) << i;
}

TEST(EpisodeRunnerTest, StopOnCollisionEndsTheEpisodeAtTheFirstCollision) {
  PdOnReachAvoid s(0.4);
  policy::PolicyEvaluator evaluator(s.pd);
  EpisodeRunner going_on(s.env);
  const SeedResult a = going_on.Run(evaluator, nullptr, 10, 5);
  ASSERT_GT(a.collision_events, a.dangerous);  // default: the episodes continue
  EXPECT_FALSE(going_on.options().stop_on_collision);

  EpisodeRunnerOptions options;
  options.stop_on_collision = true;
  EpisodeRunner stopping(s.env, options);
  Recorder recorder(s.env);
  const SeedResult b = stopping.Run(evaluator, nullptr, 10, 5, &recorder);
  EXPECT_EQ(b.dangerous, a.dangerous);         // the same episodes collide (same streams)...
  EXPECT_EQ(b.collision_events, b.dangerous);  // ...and end there
  EXPECT_EQ(recorder.episode_ended_by_collision, b.dangerous);
  EXPECT_EQ(b.successes + b.dangerous + recorder.timeouts, b.episodes);
  EXPECT_LT(b.steps, a.steps);
}

// The PD controller of PdPolicy written by hand, with the default Sample().
class HandPd final : public EpisodePolicy {
 public:
  explicit HandPd(policy::PolicyEvaluator& evaluator) : evaluator_(evaluator) {}
  int observation_dim() const override { return 4; }
  int action_dim() const override { return 2; }
  void Mean(const Eigen::Ref<const Eigen::VectorXf>& o, Eigen::Ref<Eigen::VectorXf> mu) override {
    ++calls;
    evaluator_.Mean(o, mu);
  }
  const Eigen::VectorXf& sigma() const override { return evaluator_.sigma(); }
  long calls = 0;

 private:
  policy::PolicyEvaluator& evaluator_;
};

TEST(EpisodeRunnerTest, AnEpisodePolicyRunsLikeTheGaussianPolicyItWraps) {
  PdOnReachAvoid s(0.4);
  policy::PolicyEvaluator evaluator(s.pd);
  EpisodeRunner runner(s.env);
  HandPd hand(evaluator);
  // Unshielded: the default Sample() draws one Normal per action dimension, in order, as
  // PolicyEvaluator::Sample does, so the episodes are the same.
  const SeedResult a = runner.Run(evaluator, nullptr, 8, 21);
  const SeedResult b = runner.Run(hand, nullptr, 8, 21);
  EXPECT_EQ(a.steps, b.steps);
  EXPECT_EQ(a.collision_events, b.collision_events);
  EXPECT_EQ(a.mean_steps_to_goal, b.mean_steps_to_goal);
  EXPECT_EQ(hand.calls, b.steps);
  // Shielded: (mu, sigma) go to the shield.
  di::GroundTruthBarrier barrier(s.task.truth);
  shield::Shield shield(shield::ShieldOptions{}, barrier, s.env.ShieldModel());
  const SeedResult c = runner.Run(evaluator, &shield, 4, 21);
  const SeedResult d = runner.Run(hand, &shield, 4, 21);
  EXPECT_EQ(c.steps, d.steps);
  EXPECT_EQ(c.interventions, d.interventions);
  EXPECT_EQ(c.dangerous, 0);
}

TEST(EpisodeRunnerTest, TheEpisodeSeedOptionChoosesTheStreams) {
  PdOnReachAvoid s(0.4);
  policy::PolicyEvaluator evaluator(s.pd);
  EpisodeRunnerOptions options;
  options.episode_seed = [](std::uint64_t seed, long) { return seed; };  // one stream for all
  EpisodeRunner same(s.env, options);
  Recorder r(s.env);
  same.Run(evaluator, nullptr, 3, 9, &r);
  EXPECT_EQ(r.start_observations[0], r.start_observations[1]);
  EXPECT_EQ(r.start_observations[0], r.start_observations[2]);
  EXPECT_EQ(r.episode_lengths[0], r.episode_lengths[2]);
  // The default: EpisodeSeed, a stream per episode.
  EpisodeRunner runner(s.env);
  Recorder d(s.env);
  runner.Run(evaluator, nullptr, 2, 9, &d);
  EXPECT_NE(d.start_observations[0], d.start_observations[1]);
  EXPECT_EQ(runner.options().episode_seed, &EpisodeSeed);

  options.episode_seed = nullptr;
  EXPECT_HAS(ErrorOf([&] { EpisodeRunner bad(s.env, options); }), "episode_seed = null");
}

// A policy whose sigma has the wrong size.
class BadSigma final : public EpisodePolicy {
 public:
  int observation_dim() const override { return 4; }
  int action_dim() const override { return 2; }
  void Mean(const Eigen::Ref<const Eigen::VectorXf>&, Eigen::Ref<Eigen::VectorXf> mu) override {
    mu.setZero();
  }
  const Eigen::VectorXf& sigma() const override { return sigma_; }

 private:
  Eigen::VectorXf sigma_ = Eigen::VectorXf::Ones(3);
};

TEST(EpisodeRunnerTest, APolicyWhoseSigmaDoesNotFitIsAnError) {
  di::ReachAvoidEnv env;
  EpisodeRunner runner(env);
  BadSigma bad;
  EXPECT_HAS(ErrorOf([&] { runner.Run(bad, nullptr, 1, 0); }),
             "the policy's sigma has 3 values, expected 2");
}

// The PD policy (sigma 0.3) on the double integrator under the ground-truth barrier: 20 episodes,
// seed 7, the default shield.
std::map<Method, SeedResult> EvaluateWithTheGroundTruth(const std::vector<Method>& methods) {
  PdOnReachAvoid s(0.3);
  SeedModels models;
  models.airl = &s.pd;
  models.make_barrier = GroundTruthOf(s);
  return EvaluateMethods(s.env, methods, models, shield::ShieldOptions{}, 20, 7);
}

// SECURE and two other filters over 5 synthetic seeds (one 2 points lower in success with
// varying danger, one 1 point higher), finished.
Evaluation BesideSecure(Method lower, Method higher) {
  Evaluation evaluation;
  const std::vector<long> success = {80, 85, 78, 90, 83};
  for (std::size_t k = 0; k < 5; ++k) {
    evaluation.Add(Method::kSecure, Synthetic(success[k], 1));
    evaluation.Add(lower, Synthetic(success[k] - 2, long(k)));
    evaluation.Add(higher, Synthetic(success[k] + 1, 1));
  }
  evaluation.Finish();
  return evaluation;
}

// A shield method and what it changes in the shield's options.
struct ShieldMode {
  Method method;
  std::function<void(shield::ShieldOptions*)> apply;
};

// Each mode's method is the shield with the base options changed by `apply`, nothing else; it is
// shielded, and `names` parses to the modes' methods.
void ExpectShieldModes(const std::vector<ShieldMode>& modes, const std::string& names) {
  shield::ShieldOptions base;
  base.num_samples = 32;
  std::vector<Method> methods;
  for (const ShieldMode& mode : modes) {
    shield::ShieldOptions expected = base;
    mode.apply(&expected);
    EXPECT_EQ(ShieldOptionsFor(mode.method, base).ToJson(), expected.ToJson())
        << ToString(kMethodNames, mode.method);
    EXPECT_TRUE(IsShielded(mode.method)) << ToString(kMethodNames, mode.method);
    methods.push_back(mode.method);
  }
  EXPECT_EQ(ParseMethods(names), methods);
}

// The JSON and the table compare `lower` and `higher` with SECURE.
void ExpectComparedWithSecure(Method lower, Method higher) {
  const Evaluation evaluation = BesideSecure(lower, higher);
  const nlohmann::json j = evaluation.ToJson();
  for (Method m : {lower, higher}) {
    const std::string name = ToString(kMethodNames, m);
    ASSERT_TRUE(j["comparisons"].contains(name + "_vs_secure")) << name;
    EXPECT_TRUE(j["comparisons"][name + "_vs_secure"].contains("dangerous_mann_whitney")) << name;
    EXPECT_TRUE(j["comparisons"][name + "_vs_secure"].contains("success_tost")) << name;
    EXPECT_HAS(evaluation.Table(), name + " vs SECURE: dangerous Mann-Whitney U");
  }
}

// The CBF-QP filter and the gradient-first shield: the proposal, nothing else; on the double
// integrator with its ground truth the filter keeps the PD policy out of the obstacle as SECURE
// does, and the seed records count what the projection decided.
TEST(PolicyEvalTest, TheQpMethodsAreTheShieldWithAProposal) {
  ExpectShieldModes(
      {{Method::kCbfQp, [](shield::ShieldOptions* o) { o->proposal = shield::Proposal::kQpOnly; }},
       {Method::kSecureQp, [](shield::ShieldOptions* o) { o->proposal = shield::Proposal::kQp; }}},
      "cbf-qp,secure-qp");

  const auto results =
      EvaluateWithTheGroundTruth({Method::kSecure, Method::kCbfQp, Method::kSecureQp});
  for (Method m : {Method::kCbfQp, Method::kSecureQp}) {
    const SeedResult& r = results.at(m);
    EXPECT_EQ(r.qp_tried, r.decisions) << ToString(kMethodNames, m);
    EXPECT_GT(r.qp_decisions, r.decisions / 2) << ToString(kMethodNames, m);
    EXPECT_EQ(r.qp_decisions + r.qp_rejected, r.qp_tried);
    EXPECT_EQ(r.ToJson()["qp_decisions"], r.qp_decisions);
  }
  EXPECT_EQ(results.at(Method::kSecureQp).dangerous, 0);
  EXPECT_EQ(results.at(Method::kSecure).qp_tried, 0);
  EXPECT_FALSE(results.at(Method::kSecure).ToJson().contains("qp_tried"));
  // The sampling fallback keeps the gradient-first shield's decisions safe where the projection
  // fails: no decision without a safe action beyond SECURE's.
  EXPECT_LE(results.at(Method::kSecureQp).no_safe_action_decisions,
            results.at(Method::kSecure).no_safe_action_decisions);

  ExpectComparedWithSecure(Method::kCbfQp, Method::kSecureQp);
}

// The first-safe sampler and the gradient refinement: the shield with aggregation first-safe and
// the policy's own sigma, or with proposal refine; nothing else. On the double integrator with its
// ground truth both keep the PD policy's decisions checked, and the tables compare them with
// SECURE.
TEST(PolicyEvalTest, FirstSafeAndCbfGradAreTheShieldWithTheirModes) {
  ExpectShieldModes({{Method::kFirstSafe,
                      [](shield::ShieldOptions* o) {
                        o->aggregation = shield::Aggregation::kFirstSafe;
                        o->resampling = shield::Resampling::kNone;
                      }},
                     {Method::kCbfGrad,
                      [](shield::ShieldOptions* o) { o->proposal = shield::Proposal::kRefine; }}},
                    "first-safe,cbf-grad");

  const auto results =
      EvaluateWithTheGroundTruth({Method::kSecure, Method::kFirstSafe, Method::kCbfGrad});
  const SeedResult& grad = results.at(Method::kCbfGrad);
  EXPECT_EQ(grad.qp_tried, grad.decisions);
  EXPECT_GT(grad.qp_decisions, grad.decisions / 2);
  EXPECT_EQ(grad.qp_decisions + grad.qp_rejected, grad.qp_tried);
  EXPECT_EQ(grad.no_safe_action_decisions, grad.qp_rejected);
  const SeedResult& first = results.at(Method::kFirstSafe);
  EXPECT_EQ(first.qp_tried, 0);
  EXPECT_GT(first.decisions, 0);
  EXPECT_LE(first.mean_iterations, 20.0);

  ExpectComparedWithSecure(Method::kFirstSafe, Method::kCbfGrad);
}

}  // namespace
}  // namespace secure::eval
