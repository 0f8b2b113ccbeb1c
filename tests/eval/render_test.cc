// Rendering one evaluation episode (secure render): the episode is the one the evaluation plays
// for that seed and index, with a frame after Reset() and after every step.
#include "secure/eval/render.h"

#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <vector>

#include "domains/double_integrator/ground_truth_barrier.h"
#include "domains/double_integrator/reach_avoid.h"
#include "secure/domains/forwarding_environment.h"
#include "tests/eval/pd_policy.h"
#include "tests/test_util.h"

namespace secure::eval {
namespace {

namespace di = domains::double_integrator;
using test::ErrorOf;

// The reach-avoid task with a "renderer": the frame's first bytes are the current observation's
// floats, the rest a constant; so a frame says which state it shows.
class RenderableEnv final : public domains::ForwardingEnvironment {
 public:
  explicit RenderableEnv(std::unique_ptr<domains::Environment> inner)
      : ForwardingEnvironment(std::move(inner)), observation_(inner_->observation_dim()) {}
  std::string Describe() const override { return "renderable " + inner_->Describe(); }
  void Reset(Rng& rng, Eigen::Ref<Eigen::VectorXf> observation) override {
    inner_->Reset(rng, observation);
    observation_ = observation;
  }
  domains::StepOutcome Step(const Eigen::Ref<const Eigen::VectorXf>& action,
                            Eigen::Ref<Eigen::VectorXf> observation) override {
    const domains::StepOutcome outcome = inner_->Step(action, observation);
    observation_ = observation;
    return outcome;
  }
  std::unique_ptr<Environment> Clone() const override {
    return std::make_unique<RenderableEnv>(inner_->Clone());
  }
  bool CanRender() const override { return true; }
  void Render(int width, int height, domains::Frame* frame) override {
    frame->width = width;
    frame->height = height;
    frame->rgb.assign(3 * static_cast<std::size_t>(width) * static_cast<std::size_t>(height), 7);
    std::memcpy(frame->rgb.data(), observation_.data(), sizeof(float) * observation_.size());
  }

 private:
  Eigen::VectorXf observation_;
};

Eigen::VectorXf Decode(const domains::Frame& frame, int dim) {
  Eigen::VectorXf v(dim);
  std::memcpy(v.data(), frame.rgb.data(), sizeof(float) * dim);
  return v;
}

// What the evaluation saw in one of its episodes.
class EpisodeRecorder final : public StepObserver {
 public:
  explicit EpisodeRecorder(long episode) : episode_(episode) {}
  void OnEpisodeStart(long episode, const Eigen::VectorXf& observation) override {
    if (episode == episode_) observations.push_back(observation);
  }
  void OnStep(const StepView& step) override {
    if (step.episode != episode_) return;
    observations.push_back(step.observation);
    success = success || step.outcome.reached_goal;
    dangerous = dangerous || step.outcome.collided;
  }
  std::vector<Eigen::VectorXf> observations;
  bool success = false, dangerous = false;

 private:
  long episode_;
};

TEST(RenderEpisodeTest, DrawsTheEpisodeTheEvaluationPlays) {
  const di::ReachAvoidOptions task;
  const policy::GaussianPolicy pd = test::PdPolicy(task, 0.4);
  SeedModels models;
  models.airl = &pd;
  models.make_barrier = [&] { return std::make_unique<di::GroundTruthBarrier>(task.truth); };
  const std::uint64_t seed = EvaluationSeed(5);
  const long episode = 3;
  bool saw_dangerous = false;
  for (Method method : {Method::kAirl, Method::kSecure}) {
    SCOPED_TRACE(ToString(kMethodNames, method));
    // The evaluation: episodes 0..5, recording episode 3.
    RenderableEnv evaluated(std::make_unique<di::ReachAvoidEnv>(task));
    EpisodeRunner runner(evaluated);
    EpisodeRecorder recorder(episode);
    RunMethod(runner, method, models, shield::ShieldOptions{}, 6, seed, &recorder);
    ASSERT_GT(recorder.observations.size(), 1u);

    RenderableEnv env(std::make_unique<di::ReachAvoidEnv>(task));
    std::vector<domains::Frame> frames;
    const RenderedEpisode r =
        RenderEpisode(env, method, models, shield::ShieldOptions{}, seed, episode, 6, 4,
                      [&](const domains::Frame& f) { frames.push_back(f); });
    ASSERT_EQ(frames.size(), recorder.observations.size());
    EXPECT_EQ(r.frames, static_cast<long>(frames.size()));
    EXPECT_EQ(r.steps, r.frames - 1);
    EXPECT_EQ(r.success, recorder.success);
    EXPECT_EQ(r.dangerous, recorder.dangerous);
    saw_dangerous = saw_dangerous || r.dangerous;
    for (std::size_t i = 0; i < frames.size(); ++i) {
      EXPECT_EQ(frames[i].width, 6);
      EXPECT_EQ(frames[i].height, 4);
      EXPECT_EQ(Decode(frames[i], 4), recorder.observations[i]) << "frame " << i;
    }
  }
  EXPECT_TRUE(saw_dangerous);  // the unshielded straight path crosses the obstacle
}

// Issue 30: a dangerous episode that the evaluation lists (SeedResult::DangerousEpisodes, `secure
// eval`'s lists and --episodes-out), played alone with its seed and index as `secure render`
// plays it, has the listed outcome: dangerous, the same steps and collisions, and its first
// collision in the frame after the listed first dangerous step.
TEST(RenderEpisodeTest, ReplayingAListedDangerousEpisodeReproducesIt) {
  // The PD policy straight through the obstacle, unshielded (airl) and under a shield whose
  // barrier is the ground truth of an obstacle half the real one's radius: some SECURE episodes
  // are dangerous too.
  const di::ReachAvoidOptions task;
  di::GroundTruth too_small = task.truth;
  too_small.radius = 0.5 * task.truth.radius;
  const policy::GaussianPolicy pd = test::PdPolicy(task, 0.4);
  SeedModels models;
  models.airl = &pd;
  models.make_barrier = [&] { return std::make_unique<di::GroundTruthBarrier>(too_small); };
  const std::uint64_t seed = 4;
  Evaluation evaluation;
  for (const auto& [method, r] :
       EvaluateMethods(di::ReachAvoidEnv(task), {Method::kAirl, Method::kSecure}, models,
                       shield::ShieldOptions{}, 12, EvaluationSeed(seed)))
    evaluation.Add(method, r);
  evaluation.Finish();
  int replayed = 0;
  for (Method method : {Method::kAirl, Method::kSecure}) {
    SCOPED_TRACE(ToString(kMethodNames, method));
    const SeedResult& r = evaluation.methods().at(method).per_seed[0];
    ASSERT_GT(r.dangerous, 0);
    for (long episode : r.DangerousEpisodes()) {
      const EpisodeOutcome& listed = r.episode_outcomes[static_cast<std::size_t>(episode)];
      RenderableEnv env(std::make_unique<di::ReachAvoidEnv>(task));
      long first_collision_frame = -1;
      const RenderedEpisode replay = RenderEpisode(
          env, method, models, shield::ShieldOptions{}, EvaluationSeed(seed), episode, 4, 2,
          [&](domains::Frame&, const FrameInfo& info) {
            if (info.collided && first_collision_frame < 0) first_collision_frame = info.step;
          });
      EXPECT_TRUE(replay.dangerous) << "episode " << episode;
      EXPECT_EQ(replay.success, listed.success);
      EXPECT_EQ(replay.steps, listed.steps);
      EXPECT_EQ(replay.collision_events, listed.collision_events);
      // Frame k shows the state after step k - 1 (0-based): the first dangerous step's frame.
      EXPECT_EQ(first_collision_frame, listed.first_dangerous_step + 1);
      ++replayed;
    }
  }
  EXPECT_GT(replayed, 1);
}

// What each frame shows (for the overlay): the step, h of the state shown from the method's
// barrier (unshielded methods too), the decision that led there (shielded only), the outcome.
TEST(RenderEpisodeTest, FrameInfoDescribesTheStateShown) {
  const di::ReachAvoidOptions task;
  const policy::GaussianPolicy pd = test::PdPolicy(task, 0.4);
  SeedModels models;
  models.airl = &pd;
  models.make_barrier = [&] { return std::make_unique<di::GroundTruthBarrier>(task.truth); };
  di::GroundTruthBarrier truth(task.truth);
  for (Method method : {Method::kAirl, Method::kSecure}) {
    SCOPED_TRACE(ToString(kMethodNames, method));
    RenderableEnv env(std::make_unique<di::ReachAvoidEnv>(task));
    long expected_step = 0, decisions = 0, interventions = 0;
    bool collided = false;
    const RenderedEpisode r = RenderEpisode(
        env, method, models, shield::ShieldOptions{}, EvaluationSeed(5), 3, 6, 4,
        [&](domains::Frame& frame, const FrameInfo& info) {
          EXPECT_EQ(info.step, expected_step++);
          const Eigen::VectorXf s = Decode(frame, 4);
          Eigen::VectorXf h(1);
          truth.Evaluate(s, h);
          ASSERT_TRUE(info.h.has_value());
          EXPECT_NEAR(*info.h, h[0], 1e-6);
          if (info.step == 0 || method == Method::kAirl) {
            EXPECT_EQ(info.decision, nullptr);
          } else {
            ASSERT_NE(info.decision, nullptr);
            ++decisions;
            interventions += info.decision->intervened;
          }
          collided = collided || info.collided;
          frame.rgb[0] = 1;  // the callback may draw into the frame
        });
    EXPECT_EQ(expected_step, r.frames);
    EXPECT_EQ(collided, r.dangerous);
    if (method == Method::kSecure) {
      EXPECT_EQ(decisions, r.steps);
      EXPECT_GT(interventions, 0);  // the straight path needs the shield
    }
  }
  // Without a barrier, h is unknown.
  SeedModels no_barrier;
  no_barrier.airl = &pd;
  RenderableEnv env(std::make_unique<di::ReachAvoidEnv>(task));
  RenderEpisode(env, Method::kAirl, no_barrier, shield::ShieldOptions{}, 1, 0, 6, 4,
                [](domains::Frame&, const FrameInfo& info) { EXPECT_FALSE(info.h.has_value()); });
}

TEST(RenderEpisodeTest, AnEnvironmentThatCannotRenderIsAnError) {
  const di::ReachAvoidOptions task;
  di::ReachAvoidEnv env(task);
  EXPECT_FALSE(env.CanRender());
  domains::Frame frame;
  EXPECT_HAS(ErrorOf([&] { env.Render(4, 4, &frame); }), "cannot render");
  const policy::GaussianPolicy pd = test::PdPolicy(task, 0.4);
  SeedModels models;
  models.airl = &pd;
  EXPECT_HAS(ErrorOf([&] {
               RenderEpisode(env, Method::kAirl, models, shield::ShieldOptions{}, 1, 0, 4, 4,
                             [](const domains::Frame&) {});
             }),
             "cannot render (no offscreen renderer)");
}

TEST(EpisodeRunnerTest, ANegativeFirstEpisodeIsAnError) {
  di::ReachAvoidEnv env(di::ReachAvoidOptions{});
  EpisodeRunnerOptions options;
  options.first_episode = -1;
  EXPECT_HAS(ErrorOf([&] { EpisodeRunner runner(env, options); }), "first_episode = -1");
}

}  // namespace
}  // namespace secure::eval
